"""Experiments: the runner that takes a TOML experiment from particles to an evaluated
reconstruction and vector field (:func:`run_experiment`)."""

from mitpiv.studies.experiment import STAGES, load_experiment, run_experiment

__all__ = ["run_experiment", "load_experiment", "STAGES"]
