"""Analysis of reconstructions (NumPy, no renderer): quality metrics, particles in volumes
and their matching to the truth, multi-pass 3D PIV, outlier detection and velocity errors."""

from mitpiv.analysis.particles import FoundParticles, MatchResult, find_particles, match
from mitpiv.analysis.piv3d import VectorField, piv3d, plot_velocity_error, uod, velocity_error
from mitpiv.analysis.quality import plane_snr, quality_q, quality_q_zero_mean, rank_correlation, truth_volume
from mitpiv.analysis.summary import evaluate_volume, velocity_error_summary

__all__ = ["quality_q", "quality_q_zero_mean", "rank_correlation", "plane_snr", "truth_volume",
           "find_particles", "match", "FoundParticles", "MatchResult",
           "piv3d", "uod", "velocity_error", "plot_velocity_error", "VectorField",
           "evaluate_volume", "velocity_error_summary"]
