"""One-call evaluations shared by the CLI and the experiment runner: a reconstructed volume
against the true volume or particles, and the numbers kept from a velocity-error result."""

from __future__ import annotations

from mitpiv.analysis.particles import MatchResult, find_particles, match
from mitpiv.analysis.quality import plane_snr, quality_q, quality_q_zero_mean, rank_correlations, truth_volume

VELOCITY_ERROR_KEYS = ("rms", "bias", "rms_vox", "bias_vox", "rms_magnitude", "n", "outlier_ratio", "units")
#: The keys of :func:`volume_quality`, in order.
VOLUME_QUALITY_KEYS = ("Q", "Q*", "Q'", "Q'_spearman", "SNR")


def volume_quality(volume, truth_volume) -> dict:
    """The quality block of a reconstruction against the true intensity volume.

    Parameters
    ----------
    volume : (n_z, n_y, n_x) array
        Reconstructed intensity volume.
    truth_volume : (n_z, n_y, n_x) array
        True intensity volume on the same grid (:func:`~mitpiv.analysis.truth_volume`).

    Returns
    -------
    dict
        ``"Q"`` (eq. 4.1), ``"Q*"`` (zero-mean Q), ``"Q'"`` (rank correlation, eq. 4.2,
        uncentred), ``"Q'_spearman"`` (Spearman's centred rank correlation, the Q' of
        mitpiv 0.1.0), ``"SNR"`` (eq. 4.3, z planes of ``volume``); floats. The
        normalised SNR (eq. 4.4) needs a reference configuration's SNR:
        :func:`~mitpiv.analysis.normalised_snr`.
    """
    q_rank, spearman = rank_correlations(volume, truth_volume)
    return {"Q": quality_q(volume, truth_volume), "Q*": quality_q_zero_mean(volume, truth_volume),
            "Q'": q_rank, "Q'_spearman": spearman, "SNR": plane_snr(volume)}


def evaluate_volume(volume, grid, truth_mm, *, method: str = "gauss3", threshold_rel: float = 0.1,
                    radius_voxels: float = 2.0, threshold_of: str = "robust") -> tuple[dict, MatchResult]:
    """:func:`volume_quality` against the truth blobs (:func:`~mitpiv.analysis.truth_volume`
    of ``truth_mm`` on ``grid``), and the particles found and matched:
    ({"Q", "Q*", "Q'", "Q'_spearman", "SNR", "particles": {...}}, MatchResult).

    ``"particles"`` is ``MatchResult.summary()`` plus the detection threshold that was
    used: ``threshold`` (absolute intensity), ``threshold_of`` and ``threshold_reference``
    (the intensity ``threshold_rel`` multiplied). ``threshold_of`` defaults to ``"robust"``
    (:func:`~mitpiv.analysis.find_particles`: a fraction of the 99.99th percentile of the
    local maxima, at least the 50th brightest, not of the single brightest voxel, so two
    frames of one run detect alike); ``"max"`` is the library's older rule."""
    tv = truth_volume(truth_mm, grid)
    found = find_particles(volume, grid, method=method, threshold_rel=threshold_rel, threshold_of=threshold_of)
    res = match(found, truth_mm, grid=grid, radius_voxels=radius_voxels)
    return {**volume_quality(volume, tv), "particles": {**res.summary(), **threshold_summary(found)}}, res


def threshold_summary(found) -> dict:
    """The detection threshold of :func:`~mitpiv.analysis.find_particles`' result ``found``:
    ``{"threshold", "threshold_of", "threshold_reference"}`` (floats and a string)."""
    ref = getattr(found, "reference", None)
    return {"threshold": float(found.threshold), "threshold_of": getattr(found, "threshold_of", "max"),
            "threshold_reference": None if ref is None else float(ref)}


def velocity_error_summary(result: dict) -> dict:
    """The scalar part of :func:`~mitpiv.analysis.velocity_error`'s result (no arrays)."""
    return {k: result[k] for k in VELOCITY_ERROR_KEYS}
