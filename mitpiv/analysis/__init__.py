"""Analysis of reconstructions (NumPy, no renderer): quality metrics against the truth."""

from mitpiv.analysis.quality import plane_snr, quality_q, quality_q_zero_mean, rank_correlation, truth_volume

__all__ = ["quality_q", "quality_q_zero_mean", "rank_correlation", "plane_snr", "truth_volume"]
