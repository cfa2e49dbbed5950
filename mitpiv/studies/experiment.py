"""Deprecated module (kept for one release): the experiment runner now lives in
:mod:`mitpiv.studies.runner`, the particle-image experiment in
:mod:`mitpiv.studies.kinds.tomo`. The names scripts used still import from here."""

from mitpiv.studies.kinds.tomo import STAGES
from mitpiv.studies.runner import load_experiment, run_config, run_experiment
from mitpiv.studies.schema import read_toml, set_dotted

__all__ = ["STAGES", "load_experiment", "run_config", "run_experiment", "read_toml", "set_dotted"]
