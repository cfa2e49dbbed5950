"""Time-resolved Lagrangian particle tracking (NumPy/SciPy, no renderer).

The particle image model and its calibration (:mod:`~mitpiv.tracking.otf`, Schanz et al.
2013), iterative particle reconstruction (:mod:`~mitpiv.tracking.ipr`, Wieneke 2013),
Shake-The-Box (:mod:`~mitpiv.tracking.stb`, Schanz, Gesemann & Schroeder 2016) and the
LPT Challenge's metrics (:mod:`~mitpiv.tracking.metrics`).
"""

from mitpiv.tracking.ipr import IPRResult, auto_threshold, detect_peaks, ipr, mm_per_px, shake, triangulate
from mitpiv.tracking.metrics import bin_tracks, particle_metrics, track_length_histogram, track_metrics
from mitpiv.tracking.otf import (
    OTF,
    add_particles,
    calibrate_otf,
    calibrate_otf_frames,
    project_particles,
    refine_otf,
    stamps,
)
from mitpiv.tracking.stb import Tracks, link_four, predict, predict_adaptive, regularise, stb

__all__ = [
    "OTF",
    "calibrate_otf",
    "calibrate_otf_frames",
    "refine_otf",
    "project_particles",
    "stamps",
    "IPRResult",
    "detect_peaks",
    "triangulate",
    "shake",
    "ipr",
    "auto_threshold",
    "mm_per_px",
    "add_particles",
    "Tracks",
    "link_four",
    "predict",
    "predict_adaptive",
    "regularise",
    "stb",
    "particle_metrics",
    "track_metrics",
    "track_length_histogram",
    "bin_tracks",
]
