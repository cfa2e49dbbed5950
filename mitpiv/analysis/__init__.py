"""Analysis of reconstructions (NumPy, no renderer): quality metrics, particles in volumes
and their matching to the truth, multi-pass 3D PIV, outlier detection and velocity errors."""

from mitpiv.analysis.particles import FoundParticles, MatchResult, find_particles, match, match_nearest
from mitpiv.analysis.piv3d import VectorField, curl, piv3d, plot_velocity_error, uod, velocity_error, vorticity
from mitpiv.analysis.quality import (
    normalised_snr,
    plane_snr,
    quality_q,
    quality_q_zero_mean,
    rank_correlation,
    truth_volume,
)
from mitpiv.analysis.summary import evaluate_volume, velocity_error_summary, volume_quality

__all__ = ["quality_q", "quality_q_zero_mean", "rank_correlation", "plane_snr", "normalised_snr", "truth_volume",
           "find_particles", "match", "match_nearest", "FoundParticles", "MatchResult",
           "piv3d", "uod", "velocity_error", "plot_velocity_error", "VectorField", "curl", "vorticity",
           "evaluate_volume", "volume_quality", "velocity_error_summary"]
