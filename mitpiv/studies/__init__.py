"""Experiments and studies: the runner (:mod:`~mitpiv.studies.runner`) that validates an
experiment TOML against its kind's schema and takes it through the kind's stages
(:func:`run_experiment`), the kinds (:mod:`~mitpiv.studies.kinds`: ``tomo``, ``backlit``,
``tracking``; what several of them share, and the protocol they declare, in
:mod:`~mitpiv.studies.shared`), reports (:mod:`~mitpiv.studies.report`), exports
(:mod:`~mitpiv.studies.export`), and parameter sweeps over experiments on Dask
(:func:`run_sweep`)."""

from mitpiv.studies.kinds.tomo import STAGES
from mitpiv.studies.runner import RunResult, check_experiment, load_experiment, run_config, run_experiment
from mitpiv.studies.sweep import load_study, run_sweep


def __getattr__(name):
    if name == "plot_sweep":
        from mitpiv.studies.report import plot_sweep

        return plot_sweep
    raise AttributeError(name)


__all__ = ["run_experiment", "run_config", "load_experiment", "check_experiment", "RunResult", "STAGES", "run_sweep",
           "load_study", "plot_sweep"]
