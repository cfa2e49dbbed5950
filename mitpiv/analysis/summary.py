"""One-call evaluations shared by the CLI and the experiment runner: a reconstructed volume
against the true particles, and the numbers kept from a velocity-error result."""

from __future__ import annotations

from mitpiv.analysis.particles import MatchResult, find_particles, match
from mitpiv.analysis.quality import plane_snr, quality_q, quality_q_zero_mean, rank_correlation, truth_volume

VELOCITY_ERROR_KEYS = ("rms", "bias", "rms_vox", "bias_vox", "rms_magnitude", "n", "outlier_ratio", "units")


def evaluate_volume(volume, grid, truth_mm, *, method: str = "gauss3", threshold_rel: float = 0.1,
                    radius_voxels: float = 2.0) -> tuple[dict, MatchResult]:
    """Q, Q*, Q' and SNR against the truth blobs, and the particles found and matched:
    ({"Q", "Q*", "Q'", "SNR", "particles": MatchResult.summary()}, MatchResult)."""
    tv = truth_volume(truth_mm, grid)
    found = find_particles(volume, grid, method=method, threshold_rel=threshold_rel)
    res = match(found, truth_mm, grid=grid, radius_voxels=radius_voxels)
    return {"Q": quality_q(volume, tv), "Q*": quality_q_zero_mean(volume, tv), "Q'": rank_correlation(volume, tv),
            "SNR": plane_snr(volume), "particles": res.summary()}, res


def velocity_error_summary(result: dict) -> dict:
    """The scalar part of :func:`~mitpiv.analysis.velocity_error`'s result (no arrays)."""
    return {k: result[k] for k in VELOCITY_ERROR_KEYS}
