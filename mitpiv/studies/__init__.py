"""Experiments and studies: the runner that takes a TOML experiment from particles to an
evaluated reconstruction and vector field (:func:`run_experiment`), and parameter sweeps
over experiments on Dask (:func:`run_sweep`)."""

from mitpiv.studies.experiment import STAGES, load_experiment, run_experiment
from mitpiv.studies.sweep import load_study, plot_sweep, run_sweep

__all__ = ["run_experiment", "load_experiment", "STAGES", "run_sweep", "load_study", "plot_sweep"]
