"""3D particle detection, sub-voxel localisation and matching against exact synthetic truth."""

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment

from mitpiv.analysis import FoundParticles, find_particles, match, truth_volume
from mitpiv.analysis.particles import _gauss3, assign
from mitpiv.errors import ConfigError
from mitpiv.reconstruct import VoxelGrid

VOX = 0.05
GRID = VoxelGrid((0.0, 0.0, 0.0), (VOX, VOX, VOX), (40, 64, 64))

# Tolerances and their provenance; the reference is the exact position of each synthetic
# particle. Closed forms at rounding (1e-12) stay inline.
# Sub-voxel localisation of isolated sigma = 1 voxel blobs [voxel]: gauss3 and lsq are exact
# for a Gaussian up to voxel integration (< 0.01 voxel); a 3^3 centroid of such a blob is
# pulled towards the voxel centre.
SUBVOXEL_TOL_VOX = {"gauss3": 0.01, "lsq": 0.01, "centroid": 0.25}
LSQ_ANISOTROPIC_TOL_VOX = 0.02  # sigma = 1.6 voxel blobs: lsq fits them, the centroid does not
TOUCHING_PAIR_TOL_VOX = 0.2  # two blobs 2.6 voxels apart keep their positions
EDGE_TOL_VOX = 0.8  # cut by a face: the integer position on the cut axis
SATURATED_TOL_VOX = 0.35  # clipped plateaus: their centre
ASSIGNMENT_COST_ABS_TOL = 1e-9  # total cost vs scipy's linear_sum_assignment: float64 sums
# Match statistics of 800 particles with known Gaussian errors: the bias within N_SIGMA_BIAS
# standard errors of the mean; the sample standard deviation of ~640 matches has a relative
# standard error 1/sqrt(2n) = 2.8 %, so 10 % on u95 = 1.96 sigma is 3.5 of them.
N_SIGMA_BIAS = 4
U95_REL_TOL = 0.1


def lattice_particles(grid, spacing_vox=8, seed=0):
    """Isolated particles: a lattice with +-1 voxel jitter (no two blobs overlap)."""
    rng = np.random.default_rng(seed)
    nz, ny, nx = grid.shape
    c = [np.arange(6, n - 5, spacing_vox) for n in (nx, ny, nz)]
    xx, yy, zz = np.meshgrid(*c, indexing="ij")
    vox = np.stack([xx.ravel(), yy.ravel(), zz.ravel()], axis=1) + rng.uniform(-1, 1, (xx.size, 3))
    return np.asarray(grid.origin_mm) + (vox + 0.5) * np.asarray(grid.voxel_mm)


def test_gauss3_exact_for_sampled_gaussian_and_parabola_fallback():
    x0 = np.array([-0.43, -0.1, 0.0, 0.27, 0.49])
    s = 1.3
    g = [np.exp(-((k - x0) ** 2) / (2 * s * s)) for k in (-1, 0, 1)]
    np.testing.assert_allclose(_gauss3(*g), x0, atol=1e-12)
    # a neighbour <= 0: the parabola through the three samples (exact for a parabola)
    l, c, r = (1.0 - (k - x0) ** 2 - 1.3 for k in (-1, 0, 1))  # left < 0 for all x0 here
    assert np.all(l <= 0)
    np.testing.assert_allclose(_gauss3(l, c, r), x0, atol=1e-12)
    assert _gauss3(1.0, 1.0, 1.0) == 0.0  # flat top: no offset, no NaN


@pytest.mark.parametrize("method, tol", list(SUBVOXEL_TOL_VOX.items()))
def test_isolated_particles_subvoxel(method, tol):
    p = lattice_particles(GRID)
    vol = truth_volume(p, GRID, sigma_voxels=1.0)
    found = find_particles(vol, GRID, method=method)
    r = match(found, p, grid=GRID)
    assert r.detection_rate == 1.0 and r.ghost_fraction == 0.0
    assert np.all(np.median(np.abs(r.errors_mm), axis=0) / VOX < tol)
    assert np.all(np.abs(r.bias(voxels=True)) < tol)


def test_lsq_fits_anisotropic_blob_better_than_centroid():
    p = lattice_particles(GRID, seed=3)
    vol = truth_volume(p, GRID, sigma_voxels=1.6)
    err = {m: np.abs(match(find_particles(vol, GRID, method=m), p, grid=GRID).errors_mm).mean() / VOX
           for m in ("centroid", "lsq")}
    assert err["lsq"] < LSQ_ANISOTROPIC_TOL_VOX < err["centroid"]


def test_boundary_touching_and_saturated_particles():
    o, v = np.asarray(GRID.origin_mm), np.asarray(GRID.voxel_mm)
    edge = o + (np.array([[0.2, 30.3, 20.1], [63.0, 10.4, 39.0]]) + 0.5) * v  # on the x=0 face / a corner
    touching = o + (np.array([[30.0, 30.0, 20.0], [32.6, 30.0, 20.0]]) + 0.5) * v  # 2.6 voxels apart
    p = np.vstack([edge, touching])
    vol = truth_volume(p, GRID, sigma_voxels=0.7)
    found = find_particles(vol, GRID)
    r = match(found, p, radius_mm=1.5 * VOX)
    assert r.n_matched == 4 and len(found) == 4
    assert found.edge.sum() == 2
    e = np.abs(r.errors_mm) / VOX
    assert np.all(e[np.isin(r.pairs[:, 1], [2, 3])] < TOUCHING_PAIR_TOL_VOX)  # the touching pair
    assert np.all(e < EDGE_TOL_VOX)  # edge particles keep the integer position on the cut axis
    # saturated blobs: clip at half the weakest peak -> one particle per plateau, at its centre
    q = lattice_particles(GRID, seed=5)
    vol = truth_volume(q, GRID, sigma_voxels=1.0)
    peaks = find_particles(vol, GRID).peak
    sat = np.minimum(vol, 0.5 * peaks.min())
    found = find_particles(sat, GRID)
    r = match(found, q, grid=GRID)
    assert len(found) == len(q) and r.detection_rate == 1.0 and found.saturated.mean() > 0.9
    assert np.all(np.abs(r.errors_mm) / VOX < SATURATED_TOL_VOX)
    assert np.all(np.isfinite(found.positions_mm))


def test_empty_and_bad_volumes():
    found = find_particles(np.zeros(GRID.shape), GRID)
    assert isinstance(found, FoundParticles) and len(found) == 0
    r = match(found, lattice_particles(GRID), grid=GRID)
    assert r.detection_rate == 0.0 and np.isnan(r.ghost_fraction) and np.all(np.isnan(r.rms()))
    bad = np.zeros(GRID.shape)
    bad[3, 3, 3] = np.nan
    with pytest.raises(ConfigError, match="NaN"):
        find_particles(bad, GRID)
    with pytest.raises(ConfigError, match="method"):
        find_particles(np.zeros(GRID.shape), GRID, method="gauss")
    with pytest.raises(ConfigError, match="shape"):
        find_particles(np.zeros((4, 4, 4)), GRID)
    with pytest.raises(ConfigError, match="window"):
        find_particles(np.zeros(GRID.shape), GRID, method="centroid", window=4)
    with pytest.raises(ConfigError, match="radius"):
        match(np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(ConfigError, match="truth"):
        match(np.zeros((2, 3)), np.zeros((2, 2)), radius_mm=1.0)


def test_assignment_is_the_optimal_one_to_one_matching():
    rng = np.random.default_rng(7)
    for _ in range(20):
        a = rng.uniform(0, 1, (rng.integers(1, 12), 2))
        b = rng.uniform(0, 1, (rng.integers(1, 12), 2))
        R = 0.3
        pairs = assign(a, b, R)
        assert len(set(pairs[:, 0])) == len(pairs) and len(set(pairs[:, 1])) == len(pairs)
        d = np.linalg.norm(a[pairs[:, 0]] - b[pairs[:, 1]], axis=1)
        assert np.all(d <= R)
        # reference: dense assignment where "unmatched" costs R per point (2R per pair)
        D = np.linalg.norm(a[:, None] - b[None], axis=2)
        n, m = D.shape
        big = np.full((n + m, m + n), 1e9)
        big[:n, :m] = np.where(D <= R, D, 1e9)
        big[np.arange(n), m + np.arange(n)] = R
        big[n + np.arange(m), np.arange(m)] = R
        big[n:, m:] = np.where((D <= R).T, 0.0, 1e9)
        r, c = linear_sum_assignment(big)
        ref = big[r, c].sum()
        ours = d.sum() + R * (n - len(pairs)) + R * (m - len(pairs))
        assert ours == pytest.approx(ref, abs=ASSIGNMENT_COST_ABS_TOL)


def test_assignment_tiebreak_chooses_but_never_gates():
    """With a tie-break coordinate, the number of pairs is the largest the gate allows
    (checked against the brute-force maximum, and on a chain where a cheaper matching has
    one pair fewer), and among the largest matchings the one of least summed (gate +
    tie-break) cost is chosen (brute force over permutations); a tie-break distance however
    large rejects no pair."""
    import itertools

    rng = np.random.default_rng(5)
    R = 0.4
    for _ in range(30):
        n, m = rng.integers(1, 6), rng.integers(1, 6)
        a, b = rng.uniform(0, 1, (n, 2)), rng.uniform(0, 1, (m, 2))
        ta, tb = rng.uniform(-50, 50, (n, 1)), rng.uniform(-50, 50, (m, 1))
        pairs = assign(a, b, R, tiebreak=(ta, tb))
        D = np.linalg.norm(a[:, None] - b[None], axis=2)
        C = D + np.abs(ta - tb.T)
        best_k, best_cost = 0, 0.0
        for k in range(min(n, m), 0, -1):
            costs = [sum(C[i, j] for i, j in zip(rows, cols, strict=True))
                     for rows in itertools.combinations(range(n), k) for cols in itertools.permutations(range(m), k)
                     if all(D[i, j] <= R for i, j in zip(rows, cols, strict=True))]
            if costs:
                best_k, best_cost = k, min(costs)
                break
        assert len(pairs) == best_k
        assert C[pairs[:, 0], pairs[:, 1]].sum() == pytest.approx(best_cost, abs=1e-6)
    # a chain (found 0.6 apart, truth shifted by 0.6, radius 1): three pairs exist; depths
    # that favour the two shifted pairs must not cost the third
    f = np.array([[0.0, 0.0], [0.6, 0.0], [1.2, 0.0]])
    pairs = assign(f, f + [0.6, 0.0], 1.0, tiebreak=(np.array([[0.0], [10.0], [20.0]]), np.array([[10.0], [20.0], [30.0]])))
    assert len(pairs) == 3
    # two detections at the same image position, two particles behind each other: depth picks
    a = np.zeros((2, 2))
    pairs = assign(a, a + 0.01, R, tiebreak=(np.array([[0.0], [9.0]]), np.array([[10.0], [1.0]])))
    np.testing.assert_array_equal(pairs, [[0, 1], [1, 0]])


def test_match_statistics_and_grid_restriction(tmp_path):
    rng = np.random.default_rng(11)
    truth = rng.uniform((0.3, 0.3, 0.3), (2.9, 2.9, 1.7), (800, 3))
    sigma = np.array([0.004, 0.006, 0.012])
    bias = np.array([0.002, 0.0, -0.003])
    keep = rng.random(truth.shape[0]) < 0.8
    found = truth[keep] + bias + rng.normal(0, 1, (keep.sum(), 3)) * sigma
    ghosts = rng.uniform((0, 0, 0), (3.2, 3.2, 2.0), (200, 3))
    ghosts = ghosts[np.min(np.linalg.norm(ghosts[:, None] - truth[None], axis=2), axis=1) > 0.2]
    outside = np.array([[50.0, 50.0, 50.0]])
    r = match(np.vstack([found, ghosts]), np.vstack([truth, outside]), radius_mm=0.1, grid=GRID)
    assert r.n_truth == truth.shape[0]  # the particle outside the grid does not count
    assert r.detection_rate == pytest.approx(keep.mean(), abs=1e-12)
    assert r.ghost_fraction == pytest.approx(len(ghosts) / (keep.sum() + len(ghosts)), abs=1e-12)
    assert len(ghosts) > 50
    assert np.all(np.abs(r.bias() - bias) < N_SIGMA_BIAS * sigma / np.sqrt(keep.sum()))
    np.testing.assert_allclose(r.u95(), 1.96 * sigma, rtol=U95_REL_TOL)
    np.testing.assert_allclose(r.u95(voxels=True), 1.96 * sigma / VOX, rtol=U95_REL_TOL)
    s = r.summary()
    assert s["n_matched"] == keep.sum() and len(s["rms_vox"]) == 3
    r.plot(tmp_path / "pdf.png")
    assert (tmp_path / "pdf.png").stat().st_size > 10_000


def test_plateau_centres_are_ndimage_centres_of_mass():
    """Plateau sizes and centres come from the peak voxels alone: exactly what
    ndimage.sum_labels / center_of_mass give over the whole volume."""
    from scipy import ndimage

    q = lattice_particles(GRID, seed=7)
    vol = truth_volume(q, GRID, sigma_voxels=1.0)
    sat = np.minimum(vol, 0.4 * find_particles(vol, GRID).peak.min())
    found = find_particles(sat, GRID)
    peaks = (sat >= ndimage.maximum_filter(sat, size=3, mode="constant", cval=-np.inf)) & (sat > 0.1 * sat.max())
    labels, n = ndimage.label(peaks, structure=np.ones((3, 3, 3), bool))
    com = np.asarray(ndimage.center_of_mass(sat, labels, np.arange(1, n + 1)))[:, ::-1]
    size = ndimage.sum_labels(peaks, labels, np.arange(1, n + 1))
    assert found.saturated.sum() == (size > 1).sum() > 0
    ref = np.asarray(GRID.origin_mm) + (com[size > 1] + 0.5) * np.asarray(GRID.voxel_mm)
    np.testing.assert_array_equal(found.positions_mm[found.saturated], ref)


# Two synthetic volumes of 4000 log-normal particles each (other seeds, the same statistics),
# the second's brightest voxel raised to 1.6 x the first's (a hot voxel, as MART leaves one).
# Measured over 8 such volumes without the hot voxel: the detection rate at 0.1 of the robust
# level scatters with a standard deviation of 0.7 %, so a pair differs by < 3 % (3 sigma of a
# difference); at 0.1 of the max the hot voxel alone costs ~27 % of the detections.
ROBUST_DETECTION_AGREE = 0.03
MAX_DETECTION_DIFFER = 0.15
HOT_VOXEL = 1.6


def _speckled_volume(grid, seed):
    rng = np.random.default_rng(seed)
    lo = np.asarray(grid.origin_mm) + 0.2
    hi = np.asarray(grid.upper_mm) - 0.2
    p = rng.uniform(lo, hi, (4000, 3))
    v = truth_volume(p, grid, intensities=rng.lognormal(0.0, 0.6, len(p)))
    return v + rng.exponential(0.002, v.shape), p  # a positive background of noise maxima


def test_robust_threshold_ignores_one_bright_voxel():
    """threshold_of="robust": two volumes alike but for their brightest voxel (1.6 x apart)
    detect alike; threshold_of="max" (the default) does not: one voxel moves its threshold."""
    from mitpiv.analysis.particles import robust_peak_level

    grid = VoxelGrid.from_bounds((-8, -8, -2), (8, 8, 2), 0.1)
    (a, pa), (b, pb) = _speckled_volume(grid, 10), _speckled_volume(grid, 11)
    b[np.unravel_index(np.argmax(b), b.shape)] = HOT_VOXEL * a.max()
    assert b.max() == pytest.approx(HOT_VOXEL * a.max())
    rate = {}
    for of in ("max", "robust"):
        found = [find_particles(v, grid, threshold_rel=0.1, threshold_of=of) for v in (a, b)]
        rate[of] = [match(f, p, grid=grid, radius_voxels=2.0).detection_rate for f, p in zip(found, (pa, pb), strict=True)]
        for f, v in zip(found, (a, b), strict=True):
            assert f.threshold_of == of and f.threshold == pytest.approx(0.1 * f.reference)
            assert bool(f.reference == v.max()) is (of == "max") and np.all(f.peak > f.threshold)
    assert abs(rate["robust"][0] - rate["robust"][1]) < ROBUST_DETECTION_AGREE, rate
    assert rate["max"][0] - rate["max"][1] > MAX_DETECTION_DIFFER, rate
    # the level: the k-th brightest maximum, k = max(50, 0.01 % of them); ranks, not values
    h = np.arange(1.0, 1001.0)
    assert robust_peak_level(h) == 951.0
    assert robust_peak_level(np.r_[h, 1e9]) == 952.0
    assert robust_peak_level(np.arange(1.0, 1_000_001.0)) == 1_000_001.0 - 100
    assert robust_peak_level(np.arange(1.0, 11.0)) == 1.0 and robust_peak_level([0.0, -1.0]) == 0.0
    # an absolute threshold says so; a bad threshold_of is refused with the choices and the fix
    assert find_particles(a, grid, threshold=0.2).threshold_of == "absolute"
    with pytest.raises(ConfigError, match=r"threshold_of='median' is not one of \('max', 'robust'\); give 'max'"):
        find_particles(a, grid, threshold_of="median")


def test_match_nearest_is_the_papers_rule_and_has_no_gate():
    """``match_nearest`` against a brute-force float64 reading of the rule (each found particle
    to its nearest true one; each true particle keeps the nearest of the found that chose it),
    and the difference from a gated one-to-one match: a found particle 0.3 mm from its true
    one (6 voxels of 0.05 mm) counts with its whole error, where a 0.1 mm gate drops it."""
    from mitpiv.analysis import match_nearest

    rng = np.random.default_rng(5)
    truth = rng.uniform((0.3, 0.3, 0.3), (2.9, 2.9, 1.7), (300, 3))
    found = np.vstack([truth[:250] + rng.normal(0, 0.01, (250, 3)),  # 50 true particles missed
                       rng.uniform((0, 0, 0), (3.2, 3.2, 2.0), (120, 3))])  # ghosts
    # a true particle just outside the grid, nearer to a found one than its own true particle: not counted, not chosen
    outside = np.array([[found[0, 0], found[0, 1], -0.004]])
    found[0, 2] = 0.001
    r = match_nearest(found, np.vstack([truth, outside]), grid=GRID)
    assert truth.shape[0] not in r.pairs[:, 1]
    best = {}
    for i, q in enumerate(found):
        d = np.linalg.norm(truth - q, axis=1)
        j = int(np.argmin(d))
        if j not in best or d[j] < best[j][1]:
            best[j] = (i, d[j])
    want = sorted((i, j) for j, (i, _) in best.items())
    assert sorted(map(tuple, r.pairs.tolist())) == want
    assert r.n_truth == truth.shape[0] and np.isinf(r.radius_mm)
    assert r.detection_rate == pytest.approx(len(best) / truth.shape[0], abs=1e-12)
    np.testing.assert_allclose(r.errors_mm, found[r.pairs[:, 0]] - truth[r.pairs[:, 1]], atol=0)
    # one particle displaced by 0.3 mm and its true neighbours far: the gate drops it, the rule keeps it
    t2 = np.array([[1.0, 1.0, 1.0], [2.0, 2.0, 1.0]])
    f2 = np.array([[1.0, 1.0, 1.3], [2.0, 2.0, 1.0]])
    near, gated = match_nearest(f2, t2, grid=GRID), match(f2, t2, radius_mm=0.1, grid=GRID)
    assert near.n_matched == 2 and gated.n_matched == 1
    assert near.u95(voxels=True)[2] > 10 * max(gated.u95(voxels=True)[2], 1e-9)
    empty = match_nearest(np.zeros((0, 3)), truth, grid=GRID)
    assert empty.n_matched == 0 and empty.detection_rate == 0.0
