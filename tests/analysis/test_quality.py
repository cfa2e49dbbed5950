"""Reconstruction-quality metrics: Q, Q*, rank Q', plane SNR and the true intensity volume.

References: the definitions recomputed here in float64 (eq. 4.2 of the SAPIV study written
afresh on scipy.stats.rankdata average ranks), and scipy.stats.spearmanr / pearsonr (peer
implementations) for Spearman's rank and the zero-mean correlations.
"""

import numpy as np
import pytest
from scipy.stats import pearsonr, rankdata, spearmanr

from mitpiv.analysis import (
    evaluate_volume,
    normalised_snr,
    plane_snr,
    quality_q,
    quality_q_zero_mean,
    rank_correlation,
    truth_volume,
    volume_quality,
)
from mitpiv.errors import ConfigError
from mitpiv.reconstruct import VoxelGrid

GRID = VoxelGrid.from_bounds((0, 0, 0), (40, 40, 20), 1.0)
LO, HI = (0, 0, 0), (40, 40, 20)

# Tolerances and their provenance. The definitions recomputed here in float64 agree to
# rounding (1e-12, inline).
# scipy.stats.pearsonr / spearmanr (peer implementations): float64 with another centring and
# summation order over 32000 voxels.
SCIPY_REL_TOL = 1e-9
# The blank-reconstruction floor of eq. 4.2 against its large-N limit sqrt(3 / (4 - z^3))
# (z the fraction of tied zeros): O(1/N) off at N = 32000.
RANK_FLOOR_LIMIT_ABS_TOL = 1e-3
# Plane SNR of uniform noise against 1 / (0.5 + 1/sqrt(12)): 20 planes of 1600 voxels spread
# by 2.1e-3 relative (standard deviation over 200 seeds, measured; mean bias -3e-4), so 0.01
# is ~5 standard deviations.
UNIFORM_NOISE_SNR_REL_TOL = 0.01
# Voxel-integrated blobs on a support of at least +-4 sigma: the total keeps at least
# 1 - 3 x 6.3e-5 (three axes); the centroid is exact up to the support's asymmetry; the discrete
# variance is sigma^2 + voxel^2 / 12 (Sheppard's correction) less the cut tails. Measured on
# this test's cases: totals within 3e-5, centroids within 1.1e-5 mm, variances within 3e-4.
BLOB_TOTAL_REL_TOL = 2e-4
BLOB_CENTROID_ABS_TOL_MM = 1e-4
BLOB_VARIANCE_REL_TOL = 1e-3
HALF_OUTSIDE_ABS_TOL = 0.01  # a particle centred on the grid's face keeps half its intensity


def blobs(n, seed):
    return truth_volume(np.random.default_rng(seed).uniform(LO, HI, (n, 3)), GRID)


def test_truth_with_itself_is_one():
    t = blobs(100, 0)
    assert quality_q(t, t) == pytest.approx(1.0, abs=1e-12)
    assert quality_q_zero_mean(t, t) == pytest.approx(1.0, abs=1e-12)
    assert rank_correlation(t, t) == pytest.approx(1.0, abs=1e-12)


def test_metrics_against_float64_formulas_and_scipy():
    rng = np.random.default_rng(1)
    a, b = blobs(80, 2), blobs(80, 2) + 0.05 * rng.random(GRID.shape)
    assert quality_q(a, b) == pytest.approx(np.sum(a * b) / np.sqrt(np.sum(a * a) * np.sum(b * b)), rel=1e-12)
    assert quality_q_zero_mean(a, b) == pytest.approx(pearsonr(a.ravel(), b.ravel())[0], rel=SCIPY_REL_TOL)
    # many tied zeros in `a`: average ranks, as scipy's spearmanr
    assert rank_correlation(a, b, centred=True) == pytest.approx(spearmanr(a.ravel(), b.ravel())[0], rel=SCIPY_REL_TOL)
    assert rank_correlation(a, b) == pytest.approx(_eq_4_2(a, b), rel=1e-12)


def _eq_4_2(rec, truth):
    """Q' of the SAPIV study (eq. 4.2): Q of the average-rank volumes, uncentred."""
    g_r = rankdata(np.asarray(rec, dtype=np.float64).ravel(), method="average")
    g_s = rankdata(np.asarray(truth, dtype=np.float64).ravel(), method="average")
    return float(np.sum(g_r * g_s) / np.sqrt(np.sum(g_r**2) * np.sum(g_s**2)))


def test_rank_correlation_eq_4_2_differs_from_spearman_on_sparse_particles():
    """On a sparse particle volume (most voxels tied at zero) the uncentred eq. 4.2 sits near
    its floor while Spearman's coefficient reads the mismatch of displaced particles and
    ghosts; the issue measured 0.99 (eq. 4.2) vs 0.39 (Spearman) on a SAPIV volume."""
    rng = np.random.default_rng(11)
    p = rng.uniform(LO, HI, (40, 3))
    cut = lambda v: np.where(v > 0.01 * v.max(), v, 0.0)  # noqa: E731  (blob tails cut: 95 % zeros)
    t = cut(truth_volume(p, GRID))
    # particles displaced by 0.8 voxel RMS, and as many ghosts at half the intensity
    rec = cut(truth_volume(p + rng.normal(0, 0.8, p.shape), GRID) + 0.5 * truth_volume(rng.uniform(LO, HI, (40, 3)), GRID))
    q, sp = rank_correlation(rec, t), rank_correlation(rec, t, centred=True)
    assert q == pytest.approx(_eq_4_2(rec, t), rel=1e-12)
    assert sp == pytest.approx(spearmanr(rec.ravel(), t.ravel())[0], rel=SCIPY_REL_TOL)
    assert q > 0.95 and sp < 0.6, (q, sp)  # measured 0.966 and 0.491
    # the floor: a blank reconstruction scores sum G_S / sqrt(N sum G_S^2); for a fraction z
    # of tied zeros it tends to sqrt(3 / (4 - z^3)) (N = 32000 here: O(1/N) off)
    z = np.mean(t == 0)
    g_s = rankdata(t.ravel())
    floor = np.sum(g_s) / np.sqrt(t.size * np.sum(g_s**2))
    assert rank_correlation(np.zeros(GRID.shape), t) == pytest.approx(floor, rel=1e-12)
    assert floor == pytest.approx(np.sqrt(3 / (4 - z**3)), abs=RANK_FLOOR_LIMIT_ABS_TOL)


def test_q_star_falls_with_ghosts_while_q_stays_high_at_dense_seeding():
    """Ghost particles (false blobs) added at a 0.5x, 1x, 2x ratio: Q* falls steadily; at dense
    seeding (0.06 particles per voxel) Q stays above 0.8 with twice as many ghosts as particles."""
    for n, q_floor in ((50, None), (2000, 0.8)):
        t = blobs(n, 3)
        qs, qstars = [], []
        for ratio in (0, 0.5, 1, 2):
            rec = t + (blobs(int(ratio * n), 4 + int(2 * ratio)) if ratio else 0)
            qs.append(quality_q(rec, t))
            qstars.append(quality_q_zero_mean(rec, t))
        assert np.all(np.diff(qstars) < -0.05), qstars
        if q_floor:
            assert qs[-1] > q_floor and qs[-1] - qstars[-1] > 0.2, (qs, qstars)


def test_rank_correlation_is_invariant_to_monotonic_maps():
    t = blobs(60, 5)
    rec = t + 0.1 * blobs(30, 6)
    r0 = rank_correlation(rec, t)
    for f in (np.sqrt, lambda x: np.exp(3 * x), lambda x: x**3 + 2 * x):
        assert rank_correlation(f(rec), t) == pytest.approx(r0, abs=1e-12)
        assert rank_correlation(rec, f(t)) == pytest.approx(r0, abs=1e-12)
    assert abs(quality_q(rec**3, t) - quality_q(rec, t)) > 0.01  # Q is not invariant


def test_plane_snr_noise_versus_particles():
    rng = np.random.default_rng(7)
    noise = rng.random(GRID.shape)
    # uniform noise: max / (mean + std) -> 1 / (0.5 + 1/sqrt(12)) = 1.268 per plane
    assert plane_snr(noise) == pytest.approx(1 / (0.5 + 1 / np.sqrt(12)), rel=UNIFORM_NOISE_SNR_REL_TOL)
    parts = blobs(100, 8) + 0.01 * noise
    s = plane_snr(parts)
    assert s > 5 * plane_snr(noise)
    assert plane_snr(parts, reference=noise) == pytest.approx(s / plane_snr(noise), rel=1e-12)
    assert plane_snr(parts, reference=2.0) == pytest.approx(s / 2.0)
    # planes along another axis
    assert plane_snr(np.moveaxis(parts, 0, 2), axis=2) == pytest.approx(s, rel=1e-12)


def test_plane_snr_and_nsnr_follow_eqs_4_3_and_4_4():
    rng = np.random.default_rng(12)
    v = blobs(100, 13) + 0.02 * rng.random(GRID.shape)
    # eq. 4.3 afresh: mean over z planes of max / (mu + sigma), the normal fit's MLE mu, sigma
    ref = np.mean([pl.max() / (pl.mean() + pl.std(ddof=0)) for pl in v])
    assert plane_snr(v) == pytest.approx(ref, rel=1e-12)
    # eq. 4.4: SNR of a configuration over the reference configuration's SNR
    blurred = 0.5 * (v + np.roll(v, 1, axis=2))
    assert normalised_snr(plane_snr(blurred), plane_snr(v)) == pytest.approx(plane_snr(blurred) / ref, rel=1e-12)
    assert plane_snr(blurred, reference=v) == pytest.approx(plane_snr(blurred) / ref, rel=1e-12)
    assert normalised_snr(plane_snr(v), plane_snr(v)) == 1.0
    with pytest.raises(ConfigError, match="reference"):
        normalised_snr(1.0, 0.0)


def test_volume_quality_is_the_evaluation_block():
    rng = np.random.default_rng(14)
    p = rng.uniform((2, 2, 2), (38, 38, 18), (60, 3))
    t = truth_volume(p, GRID)
    rec = truth_volume(p + rng.normal(0, 0.3, p.shape), GRID)
    m = volume_quality(rec, t)
    assert list(m) == ["Q", "Q*", "Q'", "Q'_spearman", "SNR"]
    assert m == {"Q": quality_q(rec, t), "Q*": quality_q_zero_mean(rec, t), "Q'": rank_correlation(rec, t),
                 "Q'_spearman": rank_correlation(rec, t, centred=True), "SNR": plane_snr(rec)}
    ev, res = evaluate_volume(rec, GRID, p)
    assert {k: ev[k] for k in m} == m and {k: ev["particles"][k] for k in res.summary()} == res.summary()
    assert ev["particles"]["threshold_of"] == "robust"
    assert ev["particles"]["threshold"] == pytest.approx(0.1 * ev["particles"]["threshold_reference"])
    with pytest.raises(ConfigError, match="volume_quality|shape"):
        volume_quality(rec, t[:-1])


def test_truth_volume_conserves_intensity_and_centroid():
    """Voxel-integrated blobs: total = intensity, centroid = position, and the discrete variance
    = sigma^2 + 1/12 voxel^2 (Sheppard's correction), per axis on an anisotropic grid."""
    g = VoxelGrid.from_bounds((-3, -3, -6), (3, 3, 6), (0.2, 0.3, 0.5))
    p = np.array([[0.137, -0.211, 0.73]])
    for sig in (0.7, (0.7, 1.0, 1.5)):
        v = truth_volume(p, g, sigma_voxels=sig, intensities=[2.5])
        assert v.sum() == pytest.approx(2.5, rel=BLOB_TOTAL_REL_TOL)
        s = np.broadcast_to(sig, (3,))
        for axis, coords, d, si in ((2, g.x_mm, 0.2, s[0]), (1, g.y_mm, 0.3, s[1]), (0, g.z_mm, 0.5, s[2])):
            prof = v.sum(axis=tuple(a for a in range(3) if a != axis))
            mean = np.sum(prof * coords) / prof.sum()
            var = np.sum(prof * (coords - mean) ** 2) / prof.sum()
            assert mean == pytest.approx(p[0, 2 - axis], abs=BLOB_CENTROID_ABS_TOL_MM)
            assert var == pytest.approx((si * d) ** 2 + d**2 / 12, rel=BLOB_VARIANCE_REL_TOL)
    # a particle half outside the grid keeps only its inside half
    edge = truth_volume(np.array([[-3.0, 0.0, 0.0]]), g)
    assert edge.sum() == pytest.approx(0.5, abs=HALF_OUTSIDE_ABS_TOL)


def test_empty_volumes_give_zero_not_nan():
    z = np.zeros(GRID.shape)
    t = blobs(10, 9)
    spearman = lambda a, b: rank_correlation(a, b, centred=True)  # noqa: E731
    for f in (quality_q, quality_q_zero_mean, spearman):
        assert f(z, t) == 0.0
        assert f(np.full(GRID.shape, 3.0), t) == (pytest.approx(quality_q(np.ones(GRID.shape), t)) if f is quality_q else 0.0)
    # eq. 4.2 is defined for a constant volume (all ranks equal): its floor, not 0
    for c in (z, np.full(GRID.shape, 3.0)):
        assert rank_correlation(c, t) == pytest.approx(_eq_4_2(c, t), rel=1e-12)
    assert plane_snr(z) == 0.0


def test_bad_input():
    t = blobs(5, 10)
    with pytest.raises(ConfigError, match="shape"):
        quality_q(t, t[:-1])
    bad = t.copy()
    bad[0, 0, 0] = np.nan
    with pytest.raises(ConfigError, match="NaN"):
        quality_q_zero_mean(bad, t)
    with pytest.raises(ConfigError, match="sigma_voxels"):
        truth_volume(np.zeros((1, 3)), GRID, sigma_voxels=0)
    with pytest.raises(ConfigError, match="positions"):
        truth_volume(np.zeros((2, 5, 3)), GRID)
    with pytest.raises(ConfigError, match="reference"):
        plane_snr(t, reference=np.zeros(GRID.shape))
    with pytest.raises(ConfigError, match="upper_mm"):
        VoxelGrid.from_bounds((0, 0, 0), (1, -1, 1), 0.1)
    with pytest.raises(ConfigError, match="voxel_mm"):
        VoxelGrid((0, 0, 0), (0.1, 0, 0.1), (2, 2, 2))


@pytest.mark.parametrize("case", ["ties", "distinct", "zeros_and_ties", "constant", "negative_minimum", "one"])
def test_average_ranks_equal_scipy_rankdata(case):
    """The ranking behind Q' (minimum-value ties taken without sorting, the rest sorted)
    against scipy.stats.rankdata's average method: exactly equal."""
    from scipy.stats import rankdata

    from mitpiv.analysis.quality import average_ranks

    rng = np.random.default_rng(11)
    x = {"ties": rng.integers(0, 5, 2000).astype(float), "distinct": rng.random(2000),
         "zeros_and_ties": np.r_[np.zeros(1000), rng.integers(1, 4, 600), rng.random(400)],
         "constant": np.full(10, 3.0), "negative_minimum": np.array([-1.0, -1.0, 2, 2, -5, 0, 0]),
         "one": np.array([2.5])}[case]
    rng.shuffle(x)
    np.testing.assert_array_equal(average_ranks(x), rankdata(x))
    np.testing.assert_array_equal(average_ranks(x.reshape(-1, 1)), rankdata(x))  # any shape, ravelled
    # float32 takes the packed-key sort: the same ranks as rankdata of its values
    np.testing.assert_array_equal(average_ranks(x.astype(np.float32)), rankdata(x.astype(np.float32)))


def test_float32_packed_argsort_orders_signs_zeros_and_extremes():
    """_argsort_float32 sorts like np.sort across negative values, -0.0 beside 0.0 (equal,
    so tied in rankdata), subnormals and the largest finite values."""
    from scipy.stats import rankdata

    from mitpiv.analysis.quality import _argsort_float32, average_ranks

    tiny, big = np.float32(1e-45), np.float32(3e38)
    x = np.array([0.0, -0.0, 1.0, -1.0, -0.5, 2.0, -0.0, tiny, -tiny, big, -big, 0.0], np.float32)
    x = np.concatenate([x, np.random.default_rng(4).normal(size=500).astype(np.float32)])
    np.testing.assert_array_equal(x[_argsort_float32(x)], np.sort(x))
    np.testing.assert_array_equal(average_ranks(x), rankdata(x))
