"""Replications of the published studies mitpiv was designed from (REPLICATION.md), above the
experiment engine (:mod:`mitpiv.studies`), which never imports this package.

- :mod:`mitpiv.replications.frame`: what every replication shares: rows with kinds and
  intervals, curves, the resumable and code-versioned point cache, the writer of
  ``results.json`` and ``report.md``, ``mitpiv replicate``.
- One sub-package per paper (``sapiv_distortion``, ``channel_tomo``, ``multi_plenoptic``,
  ``lfpiv_vs_tomo``, ``drop_fragments``): ``model.py``, the paper's own image model (where
  it has one), ``study.py``, its rows, sweeps and report (``STUDY``), and a README of the
  paper's set-up and our readings.
- ``tracking_density``: mitpiv's own tracking study (tracking methods against particle
  density, beside the LPT Challenge's published limits), written from a finished sweep.

``MODULES`` maps the CLI name (``mitpiv replicate NAME``) to the module defining ``STUDY``,
imported on first use.
"""

#: study name -> module defining STUDY
MODULES: dict[str, str] = {
    "sapiv-distortion": "mitpiv.replications.sapiv_distortion.study",
    "channel-tomo": "mitpiv.replications.channel_tomo.study",
    "multi-plenoptic": "mitpiv.replications.multi_plenoptic.study",
    "drop-fragments": "mitpiv.replications.drop_fragments.study",
    "lfpiv-vs-tomo": "mitpiv.replications.lfpiv_vs_tomo.study",
}
