"""Tomographic and synthetic-aperture reconstruction: weights, MLOS, MART/SMART against
float64 NumPy references written here, end-to-end checks on rendered images, hard cases.

End-to-end scenes (tests/reconstruct/helpers.py): 128 px pinhole cameras rendered by the
particle tracer with a diffraction PSF, 1 voxel per pixel, truth volumes of 0.7-voxel blobs.
"""

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from mitpiv.analysis import quality_q, truth_volume
from mitpiv.cli import main
from mitpiv.errors import ConfigError, MitpivWarning
from mitpiv.io import write_exr, write_truth
from mitpiv.physics.camera import PinholeCamera
from mitpiv.reconstruct import VoxelGrid, mart, mlos, preprocess_images, sapiv_refocus, voxel_weights
from tests.reconstruct.helpers import GRID, HALF, cameras, particles, render_views

SMALL = VoxelGrid.from_bounds((-0.5, -0.5, -0.2), (0.5, 0.5, 0.2), (0.1, 0.1, 0.1))

# Tolerances and their provenance. Reconstruction quality floors (Q > 0.75, orderings) are
# acceptance thresholds, not reference tolerances, and stay inline.
# Circle weights against Monte Carlo overlap of 2e6 points in the pixel disk: the binomial
# standard error of a fraction is <= 3.5e-4 (the docstring's "1e-3" is loose), so 3e-3 is
# >= 8.5 of them.
OVERLAP_ABS_TOL = 3e-3
# Gaussian weights sum to the projected voxel area (Poisson summation error < 1e-5) less the
# 3-sigma truncation e^-4.5; circle weights only approximate it (pixel circles do not tile).
GAUSSIAN_AREA_RTOL = 5e-3
CIRCLE_AREA_RTOL = 0.05
# MLOS against a float64 product of independent bilinear samples: float32 volume.
MLOS_RTOL, MLOS_ATOL = 1e-5, 1e-7
MART_RTOL = 1e-4  # MART/SMART against the dense float64 reference: float32 output, sums in another order


def small_cams(res=24):
    return cameras(2, res=res)


@pytest.fixture(scope="module")
def low(tmp_path_factory):
    pts = particles(0.01, seed=0)
    cams = cameras(4)
    return pts, cams, render_views(tmp_path_factory.mktemp("low"), pts, cams), truth_volume(pts, GRID)


@pytest.fixture(scope="module")
def dense(tmp_path_factory):
    pts = particles(0.1, seed=1)
    cams = cameras(4)
    return pts, cams, render_views(tmp_path_factory.mktemp("dense"), pts, cams), truth_volume(pts, GRID)


# ---------------------------------------------------------------------- weights
def test_circle_weights_match_monte_carlo_overlap():
    """w = |voxel circle n pixel circle| / pixel area, voxel circle of the projected voxel's
    area (convex hull of its 8 projected corners here) - checked by sampling the pixel disk
    (2e6 points: 1e-3 standard error)."""
    cam = cameras(1, res=32)[0]
    grid = VoxelGrid.from_bounds((-0.1, -0.1, -0.1), (0.1, 0.1, 0.1), (0.06, 0.05, 0.08))
    vox = 13
    w = voxel_weights(cam, grid, [vox]).tocoo()
    rv = np.sqrt(_projected_area(cam, grid, vox) / np.pi)
    uv = cam.project(grid.centres([vox])[0])
    rng = np.random.default_rng(0)
    rp = 1 / np.sqrt(np.pi)
    r, th = rp * np.sqrt(rng.random(2_000_000)), 2 * np.pi * rng.random(2_000_000)
    assert w.nnz >= 4
    for pix, val in zip(w.row, w.data, strict=True):
        centre = np.array([pix % 32 + 0.5, pix // 32 + 0.5])
        pts = centre + np.stack([r * np.cos(th), r * np.sin(th)], -1)
        frac = np.mean(np.sum((pts - uv) ** 2, -1) < rv**2)
        assert val == pytest.approx(frac, abs=OVERLAP_ABS_TOL)


def _projected_area(cam, grid, vox):
    """Area [px^2] of the convex hull of a voxel's 8 projected corners."""
    c = grid.centres([vox])[0]
    corners = c + 0.5 * np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * grid.voxel_mm
    return ConvexHull(cam.project(corners)).volume


def test_weights_carry_the_projected_voxel_area():
    """Gaussian model: the pixel sum of a >= 0.8 px Gaussian equals its integral (Poisson
    summation error ~exp(-2 pi^2 sigma^2) < 1e-5), less the 3-sigma truncation (e^-4.5): the
    projected area to 0.5 %. Circle model: pixel circles do not tile the plane, so the sum
    only approximates the area (within 5 %)."""
    cam = cameras(1, res=64)[0]
    grid = VoxelGrid.from_bounds((-0.3, -0.3, -0.3), (0.3, 0.3, 0.3), (0.1, 0.1, 0.3))
    ids = np.arange(grid.n_voxels)
    area = np.array([_projected_area(cam, grid, v) for v in ids])
    wg = np.asarray(voxel_weights(cam, grid, ids, weights="gaussian", psf_sigma_px=0.8).sum(axis=0)).ravel()
    wc = np.asarray(voxel_weights(cam, grid, ids, weights="circle").sum(axis=0)).ravel()
    assert wg == pytest.approx(area * (1 - np.exp(-4.5)), rel=GAUSSIAN_AREA_RTOL)
    assert wc == pytest.approx(area, rel=CIRCLE_AREA_RTOL)


# ---------------------------------------------------------------------- references
def _bilinear(img, u, v):
    """Independent bilinear interpolation at pixel coordinates (centres at i + 0.5), 0 outside."""
    h, w = img.shape
    x, y = u - 0.5, v - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = x - x0, y - y0
    out = np.zeros_like(u)
    for dx, dy, wt in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        xi, yi = x0 + dx, y0 + dy
        ok = (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
        out[ok] += wt[ok] * img[yi[ok], xi[ok]]
    return out


def test_mlos_matches_product_of_bilinear_samples():
    cams = small_cams(32)
    rng = np.random.default_rng(2)
    imgs = [rng.random((32, 32)) ** 4 for _ in cams]
    pts = SMALL.centres(np.arange(SMALL.n_voxels))
    s = [_bilinear(im, *c.project(pts).T) for im, c in zip(imgs, cams, strict=True)]
    ref = np.sqrt(s[0] * s[1]).reshape(SMALL.shape)
    assert mlos(imgs, cams, SMALL) == pytest.approx(ref, rel=MLOS_RTOL, abs=MLOS_ATOL)
    assert mlos(imgs, cams, SMALL, exponent=1.0) == pytest.approx((s[0] * s[1]).reshape(SMALL.shape), rel=MLOS_RTOL,
                                                                  abs=MLOS_ATOL)
    cubic = mlos(imgs, cams, SMALL, interpolation="cubic")
    assert np.all(cubic >= 0) and 0.5 < quality_q(cubic, ref) < 1.0


def _reference_mart(imgs, cams, grid, iterations, mu, span, smart):
    """MART / SMART in float64 NumPy on dense weights, pixel order of the row classes."""
    ids = np.arange(grid.n_voxels)
    pts = grid.centres(ids)
    seen = np.all([(lambda uv: (uv[:, 0] >= 0) & (uv[:, 0] <= 24) & (uv[:, 1] >= 0) & (uv[:, 1] <= 24))(c.project(pts))
                   for c in cams], axis=0)
    ids = ids[seen]
    mats = [voxel_weights(c, grid, ids).toarray().astype(np.float64) for c in cams]
    e = np.ones(len(ids))
    for _ in range(iterations):
        if smart:
            num, den = np.zeros(len(ids)), np.zeros(len(ids))
            for a, im in zip(mats, imgs, strict=True):
                p = a @ e
                lr = np.where(p > 0, np.log(np.where(p > 0, im.ravel(), 1) / np.where(p > 0, p, 1)), 0.0)
                num += a.T @ lr
                den += a.sum(axis=0)
            e = np.where(den > 0, e * np.exp(mu * num / np.where(den > 0, den, 1)), e)
            continue
        for a, im, sp in zip(mats, imgs, span, strict=True):
            h, w = im.shape
            order = [r * w + c for col in range(sp) for r in range(col, h, sp) for c in range(w)]
            for i in order:
                row = a[i]
                nz = row > 0
                if not nz.any():
                    continue
                p = row @ e
                if p > 0:
                    e[nz] *= (im.ravel()[i] / p) ** (mu * row[nz])
    out = np.zeros(grid.n_voxels)
    out[ids] = e
    return out.reshape(grid.shape)


@pytest.mark.parametrize("smart", [False, True])
def test_mart_matches_dense_float64_reference(smart):
    cams = small_cams()
    rng = np.random.default_rng(3)
    imgs = [0.1 + rng.random((24, 24)) for _ in cams]
    vol, info = mart(imgs, cams, SMALL, iterations=3, mu=0.8, smart=smart, init="uniform", prune=False, return_info=True)
    ref = _reference_mart(imgs, cams, SMALL, 3, 0.8, info["row_span"], smart)
    assert vol == pytest.approx(ref, rel=MART_RTOL)
    assert np.all(np.diff(info["residuals"]) < 0)  # the image residual falls


def test_zero_pixels_prune_the_voxels_they_see():
    cams = small_cams()
    imgs = [np.ones((24, 24)) for _ in cams]
    imgs[0][10:14, :] = 0.0
    full = mart(imgs, cams, SMALL, iterations=1, prune=False, init="uniform")
    pruned, info = mart(imgs, cams, SMALL, iterations=1, init="uniform", return_info=True)
    assert info["active_voxels"] < info["candidate_voxels"]
    # MART's zero-pixel rule zeroes exactly the voxels pruning leaves out (pruned up front, they
    # also stop disturbing the other pixels' projections, so the rest differs slightly)
    assert np.array_equal(pruned == 0, full == 0) and np.any(full == 0) and np.any(full > 0)


# ---------------------------------------------------------------------- end to end
def test_mart_reconstructs_low_density_scene(low):
    pts, cams, imgs, truth = low
    vol = mart(imgs, cams, GRID, iterations=5)
    assert quality_q(vol, truth) > 0.75
    assert quality_q(mart(imgs, cams, GRID, iterations=5, smart=True), truth) > 0.75
    assert quality_q(mlos(imgs, cams, GRID), truth) < quality_q(vol, truth)  # MART improves on its MLOS start


def test_quality_falls_with_density(low, dense):
    q = [quality_q(mart(d[2], d[1], GRID, iterations=5), d[3]) for d in (low, dense)]
    assert q[1] < q[0] - 0.05, q


def test_more_cameras_help(low):
    _, cams, imgs, truth = low
    q = [quality_q(mart(imgs[:n], cams[:n], GRID, iterations=5), truth) for n in (2, 3, 4)]
    assert q[0] < q[1] < q[2], q


def test_sapiv_quality_falls_with_uncompensated_distortion(tmp_path):
    """3 x 3 array; images rendered with 0, 1, 2 % radial distortion at the image corner (1.8 px
    on these 128 px images; particles, inside the corners, move up to ~1 px), refocused with the
    distortion-free mappings: Q falls monotonically; with the true (distorted) mappings it does
    not fall."""
    pts = particles(0.01, seed=4)
    truth = truth_volume(pts, GRID)
    ideal = cameras(array=(3, 3), distance=450.0)  # the volume fills ~90 % of each image
    q, q_comp = {}, {}
    for pct in (0.0, 1.0, 2.0):
        true_cams = cameras(array=(3, 3), distortion_percent=pct, distance=450.0)
        imgs = render_views(tmp_path, pts, true_cams, name=f"p{pct}.ply")
        q[pct] = quality_q(sapiv_refocus(imgs, ideal, GRID, method="multiplicative"), truth)
        q_comp[pct] = quality_q(sapiv_refocus(imgs, true_cams, GRID, method="multiplicative"), truth)
        if pct == 0.0:
            add = quality_q(sapiv_refocus(imgs, ideal, GRID), truth)
            raw = sapiv_refocus(imgs, ideal, GRID, threshold_k=None)
            thr = sapiv_refocus(imgs, ideal, GRID)
    assert q[0.0] > 0.7 and q[0.0] > q[1.0] + 1e-3 > q[2.0] + 2e-3, q
    assert q_comp[2.0] > q[2.0] + 0.5 * (q[0.0] - q[2.0]), (q_comp, q)  # the mapping's distortion recovers most
    assert add < q[0.0] - 0.05  # multiplicative suppresses the out-of-focus light additive keeps
    assert np.count_nonzero(raw) > 10 * np.count_nonzero(thr)  # thresholding at mean + 3 sigma


def test_preprocessing_trades_quality_for_pruning(low):
    """A 5 % background with 1 % noise: subtracting the histogram background (k = 0) makes most
    pixels zero (those below the mode), prunes > 90 % of the voxels and keeps Q within 0.05; a higher threshold also
    cuts the particle images' wings, which MART's zero-pixel rule turns into lost voxels: Q
    falls as k rises (the cost of the knob, see bench/bench_reconstruct.py)."""
    _, cams, imgs, truth = low
    rng = np.random.default_rng(5)
    noisy = [im + im.max() * (0.05 + 0.01 * rng.standard_normal(im.shape)) for im in imgs]
    assert all(np.mean(c == 0) > 0.4 for c in preprocess_images(noisy, k=0.0))  # below the mode
    kept = preprocess_images(imgs)[0]  # noise-free: keeps its light
    assert np.all(kept <= imgs[0]) and kept.sum() > 0.98 * imgs[0].sum()
    q_raw = quality_q(mart(noisy, cams, GRID, iterations=5), truth)
    q, active = [], []
    for k in (0.0, 1.0, 2.0):
        vol, info = mart(noisy, cams, GRID, iterations=5, preprocess=k, return_info=True)
        q.append(quality_q(vol, truth))
        active.append(info["active_voxels"])
    assert active[0] < 0.1 * GRID.n_voxels and q[0] > q_raw - 0.05, (q_raw, q, active)
    assert np.all(np.diff(q) < 0) and np.all(np.diff(active) < 0), (q, active)


def test_floor_prunes_voxels_behind_particle_tails(low):
    """Rendered particle images have tails that fade without reaching zero (here: 52 % of the
    pixels > 0 at 0.01 ppp), which MLOS cannot prune. A floor at 1e-3 of each image's maximum
    (about a 10-bit camera's range) zeroes them: measured 41 % fewer active voxels at the same
    Q (0.8003 vs 0.8000); at 3e-2 the floor cuts into the particle images and Q falls to 0.38.
    Asserted: >= 25 % fewer voxels and Q within 0.01 at 1e-3, Q lower by > 0.1 at 3e-2. The
    floor itself zeroes exactly the pixels below it and leaves the others unchanged."""
    _, cams, imgs, truth = low
    floored = preprocess_images(imgs, k=None, floor_rel=1e-3)
    for a, b in zip(imgs, floored, strict=True):
        below = a < 1e-3 * a.max()
        assert below.sum() > 0.1 * a.size
        assert np.all(b[below] == 0) and np.array_equal(b[~below], a[~below])
    res = {}
    for f in (0.0, 1e-3, 3e-2):
        vol, info = mart(imgs, cams, GRID, iterations=5, floor_rel=f, return_info=True)
        res[f] = (quality_q(vol, truth), info["active_voxels"])
    assert res[1e-3][1] < 0.75 * res[0.0][1], res
    assert abs(res[1e-3][0] - res[0.0][0]) < 0.01, res
    assert res[3e-2][0] < res[0.0][0] - 0.1, res
    for bad in (-0.1, 1.0, float("nan")):
        with pytest.raises(ConfigError, match="floor_rel"):
            preprocess_images(imgs, k=None, floor_rel=bad)


def test_smoothing_keeps_particles_that_clipped_noise_would_zero(low):
    """8-bit images with zero-mean noise at 10 % of the peak, clipped at 0 by the ADC: noise
    clips pixels of the particle images' wings to 0, and MART's multiplicative update zeroes
    every voxel that sees one, leaving each particle its brightest voxel or nothing (the
    channel-tomo replication's lost PIV). A Gaussian smoothing of 0.7 px before the
    threshold (preprocess_images smooth_px) keeps the particles: more active voxels than
    particles again, and a higher Q."""
    pts, cams, imgs, truth = low
    rng = np.random.default_rng(7)
    peak = max(float(im.max()) for im in imgs)
    eight = [np.clip(np.rint(150.0 * im / peak + rng.normal(0.0, 15.0, im.shape)), 0, 255) for im in imgs]
    sm = preprocess_images(eight, k=None, smooth_px=0.7)
    assert sm[0].sum() == pytest.approx(eight[0].sum(), rel=1e-3)  # a normalised kernel (reflecting edges)
    runs = {}
    for s_px in (0.0, 0.7):
        vol, info = mart(eight, cams, GRID, iterations=5, smart=True, preprocess=0.0, smooth_px=s_px, return_info=True)
        runs[s_px] = (quality_q(vol, truth), info["active_voxels"])
    (q0, n0), (q1, n1) = runs[0.0], runs[0.7]
    assert n1 > 3 * n0 and n1 > len(pts), runs
    assert q1 > q0 + 0.1, runs
    with pytest.raises(ConfigError, match="smooth_px"):
        preprocess_images(eight, smooth_px=-1.0)


# ---------------------------------------------------------------------- hard cases
def test_tiny_values_in_multiplicative_forms_scale_exactly():
    """Log-space products: images at 1e-30 (a product of two is 1e-60, below float32's range,
    but the geometric mean is 1e-30)."""
    cams = small_cams()
    rng = np.random.default_rng(6)
    imgs = [0.1 + rng.random((24, 24)) for _ in cams]
    tiny = [1e-30 * im for im in imgs]
    ref = mlos(imgs, cams, SMALL).astype(np.float64)
    assert mlos(tiny, cams, SMALL).astype(np.float64) / 1e-30 == pytest.approx(ref, rel=1e-5)
    assert mlos([1e-20 * im for im in imgs], cams, SMALL).astype(np.float64) / 1e-20 == pytest.approx(ref, rel=1e-5)
    a = mart(imgs, cams, SMALL, iterations=3)
    b = mart(tiny, cams, SMALL, iterations=3)
    assert np.all(np.isfinite(b)) and b / 1e-30 == pytest.approx(a, rel=1e-4, abs=1e-12)
    s = sapiv_refocus(tiny, cams, SMALL, method="multiplicative", threshold_k=None)
    assert s / 1e-30 == pytest.approx(sapiv_refocus(imgs, cams, SMALL, method="multiplicative", threshold_k=None), rel=1e-4)


def test_empty_and_saturated_images():
    cams = small_cams()
    zero = [np.zeros((24, 24)) for _ in cams]
    with pytest.warns(MitpivWarning, match="dark"):
        v = mart(zero, cams, SMALL, iterations=2)
    assert not np.any(v) and quality_q(v, np.ones(SMALL.shape)) == 0.0
    with pytest.warns(MitpivWarning, match="dark"):
        assert not np.any(mlos(zero, cams, SMALL))
    assert not np.any(sapiv_refocus(zero, cams, SMALL))
    sat = [np.full((24, 24), 65535.0) for _ in cams]
    for smart in (False, True):
        v = mart(sat, cams, SMALL, iterations=5, smart=smart)
        assert np.all(np.isfinite(v)) and v.max() > 0
    assert np.all(np.isfinite(sapiv_refocus(sat, cams, SMALL)))


def test_camera_that_sees_nothing():
    cams = small_cams()
    away = PinholeCamera((24, 24), 85.0, 10.0, position_mm=[0, 0, 500.0])  # looks along +z, away from the grid
    imgs = [np.ones((24, 24))] * 3
    for f in (mlos, mart, sapiv_refocus):
        with pytest.raises(ConfigError, match="camera 2 sees none of the voxel grid"):
            f(imgs, [*cams, away], SMALL)
    dark = [np.ones((24, 24)), np.zeros((24, 24))]
    with pytest.warns(MitpivWarning, match="image 1 is entirely dark"):
        assert not np.any(mart(dark, cams, SMALL, iterations=2))


def test_bad_input():
    cams = small_cams()
    imgs = [np.ones((24, 24))] * 2
    with pytest.raises(ConfigError, match="2 images but 1 mappings"):
        mart(imgs, cams[:1], SMALL)
    with pytest.raises(ConfigError, match="images\\[1\\] is 20x24 px but mappings\\[1\\] is for 24x24"):
        mlos([imgs[0], np.ones((24, 20))], cams, SMALL)
    with pytest.raises(ConfigError, match="'mu'"):
        mart(imgs, cams, SMALL, mu=2.0)
    with pytest.raises(ConfigError, match="'iterations'"):
        mart(imgs, cams, SMALL, iterations=-1)
    with pytest.raises(ConfigError, match="'weights'"):
        mart(imgs, cams, SMALL, weights="sphere")
    with pytest.raises(ConfigError, match="'grid' must be a VoxelGrid"):
        mlos(imgs, cams, (10, 10, 10))
    with pytest.raises(ConfigError, match="'exponent'"):
        sapiv_refocus(imgs, cams, SMALL, exponent=0.0)
    with pytest.raises(ConfigError, match="NaN"):
        mlos([np.full((24, 24), np.nan), imgs[1]], cams, SMALL)
    with pytest.raises(ConfigError, match="'init' has shape"):
        mart(imgs, cams, SMALL, init=np.ones((2, 2, 2)))
    with pytest.raises(ConfigError, match="mappings\\[0\\] is a str"):
        mlos(imgs, ["cam0", cams[1]], SMALL)


# ---------------------------------------------------------------------- CLI
def test_cli_reconstruct(tmp_path, low, capsys):
    pts, cams, imgs, _ = low
    files = []
    for i, (im, c) in enumerate(zip(imgs, cams, strict=True)):
        files.append(str(write_exr(tmp_path / f"cam{i}.exr", im.astype(np.float32), {"camera": c.to_dict()})))
    write_truth(tmp_path / "truth.npz", positions_mm=[pts], times_s=[0.0], diameters_um=2.0)
    lo, hi = -HALF, HALF
    bounds = [str(v) for pair in zip(lo, hi, strict=True) for v in pair]
    out = tmp_path / "vol.npz"
    assert main(["reconstruct", *files, "--out", str(out), "--bounds", *bounds, "--voxel", "0.05",
                 "--truth", str(tmp_path / "truth.npz")]) == 0
    with np.load(out) as z:
        assert z["volume"].shape == GRID.shape
    q = float(capsys.readouterr().out.split("Q ")[1].split()[0])
    assert q > 0.75
    bad = tmp_path / "vol.txt"
    assert main(["reconstruct", *files, "--out", str(bad), "--bounds", *bounds, "--voxel", "0.05"]) == 2
    assert not bad.exists()
