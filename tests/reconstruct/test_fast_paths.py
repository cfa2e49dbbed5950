"""Compiled fast paths of issue 26 against the code they replace: the pinhole projection,
Jacobian footprints and MLOS pass of MART against the generic NumPy path (camera methods),
weight reuse across frames, and the final-residual option."""

import numpy as np
import pytest

from mitpiv.physics.camera import PinholeCamera, scatter_arrangement
from mitpiv.physics.distortion import Distortion
from mitpiv.reconstruct import PinholeMapping, VoxelGrid, WeightCache, mart
from mitpiv.reconstruct._kernels import kernels
from mitpiv.reconstruct.tomo import (
    _build_weights,
    _build_weights_pinhole,
    _candidates,
    _candidates_pinhole,
    _footprints,
    _footprints_pinhole,
    _pinhole_rows,
)

# float32 storage of projections and footprints: relative rounding 6e-8; 1e-6 leaves room
# for the different summation order of the Jacobian product.
FOOTPRINT_RTOL = 1e-6
# MART volumes of the two paths: float32 output, weights from float32 footprints computed
# in another order (measured max difference 2e-6 of the maximum).
PATH_RTOL = 1e-4

GRID = VoxelGrid.from_bounds((-1.0, -1.0, -0.4), (1.0, 1.0, 0.4), 0.05)


class _Generic(PinholeMapping):
    """A PinholeMapping the fast path does not recognise: forces the generic NumPy path."""


def _cameras(res=48):
    arr = scatter_arrangement("symmetric", n=4, azimuth_deg=25, elevation_deg=55, distance_mm=200.0)
    dist = Distortion(k1=-0.08, k2=0.01, p1=1e-3, p2=-5e-4)
    return [PinholeCamera((res, res), 85.0, 10.0, rotation=a["rotation"], position_mm=a["position_mm"],
                          distortion=dist) for a in arr]


def _images(cams, n=25, seed=3):
    """Gaussian particle images (sigma 0.7 px), values below 1e-3 set to 0 (zero pixels prune)."""
    rng = np.random.default_rng(seed)
    pts = rng.uniform((-0.9, -0.9, -0.35), (0.9, 0.9, 0.35), (n, 3))
    out = []
    for c in cams:
        w, h = c.resolution
        yy, xx = np.mgrid[0:h, 0:w] + 0.5
        uv = c.project(pts)
        img = np.zeros((h, w))
        for u, v in uv:
            img += np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * 0.7**2))
        img[img < 1e-3] = 0.0
        out.append(img)
    return out


@pytest.mark.parametrize("model", ["circle", "gaussian"])
def test_compiled_footprints_match_numpy_camera_model(model):
    cams = _cameras()
    rows = _pinhole_rows([PinholeMapping(c) for c in cams])
    ids = np.random.default_rng(0).choice(GRID.n_voxels, 500, replace=False)
    pts = GRID.centres(ids)
    for c, row in zip(cams, rows, strict=True):
        u, v, fp = _footprints_pinhole(row, ids, GRID, model, 0.5)
        ref_uv = c.project(pts)
        ref_fp = _footprints(PinholeMapping(c), pts, GRID, model, 0.5)
        np.testing.assert_allclose(np.column_stack([u, v]), ref_uv, rtol=FOOTPRINT_RTOL)
        for got, ref in zip(fp, ref_fp, strict=True):
            np.testing.assert_allclose(got, ref, rtol=FOOTPRINT_RTOL, atol=1e-12)


@pytest.mark.parametrize("model", ["circle", "gaussian"])
def test_pinhole_weight_assembly_is_the_sorted_one(model):
    """The counting-sort assembly (image rows, compiled counting sort, footprints in bucket
    order) gives the same CSR matrix, entry for entry, as the argsort one it replaces, also
    for voxels that project above, below and outside the image."""
    cams = _cameras(40)
    rows = _pinhole_rows([PinholeMapping(c) for c in cams])
    ids = np.sort(np.random.default_rng(1).choice(GRID.n_voxels, 6000, replace=False))
    for row in rows:
        new = _build_weights_pinhole(row, ids, GRID, model, 0.5, (40, 40))
        u, v, fp = _footprints_pinhole(row, ids, GRID, model, 0.5)
        old = _build_weights(np.column_stack([u, v]), fp, model, (40, 40))
        v64, r64 = v.astype(np.float64), fp[0].astype(np.float64)
        assert new.span == old.span == int((np.floor(v64 + r64) - np.floor(v64 - r64)).max()) + 1
        assert len(new.data) > 1000
        for name in ("indptr", "indices", "data"):
            np.testing.assert_array_equal(getattr(new, name), getattr(old, name))


@pytest.mark.parametrize("model", ["circle", "gaussian"])
def test_fused_zero_pixel_pruning_is_the_array_one(model):
    """survives_pinhole (footprints computed in place, voxels far from every zero pixel
    skipped by the distance map) prunes exactly the voxels that survives prunes on the
    stored float32 footprints."""
    from scipy import ndimage

    cams = _cameras(40)
    rows = _pinhole_rows([PinholeMapping(c) for c in cams])
    ids = np.arange(GRID.n_voxels, dtype=np.int64)
    k = kernels()
    mcode = 0 if model == "circle" else 1
    for row, img in zip(rows, _images(cams), strict=True):
        fused = np.ones(ids.size, np.bool_)
        dist = ndimage.distance_transform_cdt(img > 0, metric="chessboard").astype(np.int32)
        k["survives_pinhole"](ids, GRID.x_mm, GRID.y_mm, GRID.z_mm, row, *GRID.voxel_mm, mcode, 0.25, img, dist, fused)
        u, v, fp = _footprints_pinhole(row, ids, GRID, model, 0.5)
        ref = np.ones(ids.size, np.bool_)
        k["survives"](u, v, *fp, mcode, img, ref)
        assert 0 < fused.sum() < ids.size
        np.testing.assert_array_equal(fused, ref)


def test_counting_order_is_the_stable_argsort():
    keys = np.random.default_rng(2).integers(0, 37, 5000).astype(np.int32)
    order, bucket = np.empty(keys.size, np.int64), np.empty(38, np.int64)
    kernels()["counting_order"](keys, 37, order, bucket)
    np.testing.assert_array_equal(order, np.argsort(keys, kind="stable"))
    np.testing.assert_array_equal(bucket, np.concatenate([[0], np.cumsum(np.bincount(keys, minlength=37))]))


@pytest.mark.parametrize("prune", [True, False])
def test_mlos_pass_engines_agree_with_the_generic_path(prune, monkeypatch):
    """The MLOS candidates and values of the Dr.Jit kernel (in blocks of planes, here 3
    planes per block and a shorter last block), the Numba kernel and the generic NumPy path
    (scipy map_coordinates sampling): same voxels, values to 1e-9 relative. All three work
    in float64, but in different operation orders (Dr.Jit contracts multiply-adds into fused
    ones; its log and exp are its own): the projections differ by ~1e-12 px, which the
    test images' steep Gaussian tails (log-slope up to ~20 per px) turn into up to 8e-11 of
    a value, still 700x below the float32 rounding of the stored volume. The grid reaches
    past the cameras' views, so the not-pruned candidates (seen by every camera) differ
    from the pruned ones (light in every camera)."""
    from mitpiv.reconstruct import _drjit

    if not _drjit.available():
        pytest.fail("Dr.Jit's LLVM backend is not initialised: scripts/setup.sh installs LLVM >= 16")
    cams = _cameras()
    imgs = _images(cams, n=60)
    grid = VoxelGrid.from_bounds((-1.6, -1.6, -0.5), (1.6, 1.6, 0.5), 0.08)
    maps = [PinholeMapping(c) for c in cams]
    rows = _pinhole_rows(maps)
    monkeypatch.setattr(_drjit, "BLOCK_VOXELS", 3 * grid.shape[1] * grid.shape[2])
    assert grid.shape[0] % 3 != 0
    i_d, v_d = _candidates_pinhole(imgs, rows, grid, prune, False, "t", engine="drjit")
    i_n, v_n = _candidates_pinhole(imgs, rows, grid, prune, False, "t", engine="numba")
    i_g, v_g, _ = _candidates(imgs, maps, grid, "linear", prune, False, "t")
    seen = _candidates_pinhole(imgs, rows, grid, False, False, "t", engine="drjit")[0]
    lit = _candidates_pinhole(imgs, rows, grid, True, False, "t", engine="drjit")[0]
    assert 0 < len(lit) < len(seen) < grid.n_voxels
    np.testing.assert_array_equal(i_d, i_n)
    np.testing.assert_array_equal(i_d, i_g)
    np.testing.assert_allclose(v_d, v_n, rtol=1e-9, atol=0)
    np.testing.assert_allclose(v_d, v_g, rtol=1e-9, atol=0)


def test_mlos_volume_fast_path_is_the_generic_one():
    """mlos() with pinhole cameras (the Dr.Jit kernel) against the generic per-plane path,
    exponents 1/N and 1; the float32 volumes agree to their rounding (tolerance as above)."""
    from mitpiv.reconstruct import mlos

    cams = _cameras()
    imgs = _images(cams, n=60)
    for e in (None, 1.0):
        fast = mlos(imgs, [PinholeMapping(c) for c in cams], GRID, exponent=e)
        slow = mlos(imgs, [_Generic(c) for c in cams], GRID, exponent=e)
        assert fast.dtype == slow.dtype == np.float32 and np.count_nonzero(fast) > 100
        np.testing.assert_allclose(fast, slow, rtol=2e-7, atol=0)


@pytest.mark.parametrize("smart", [False, True])
def test_fast_path_reconstructs_as_the_generic_path(smart):
    cams = _cameras()
    imgs = _images(cams)
    fast, i_fast = mart(imgs, [PinholeMapping(c) for c in cams], GRID, iterations=3, smart=smart, return_info=True)
    slow, i_slow = mart(imgs, [_Generic(c) for c in cams], GRID, iterations=3, smart=smart, return_info=True)
    assert i_fast["fast_path"] and not i_slow["fast_path"]
    assert i_fast["active_voxels"] == i_slow["active_voxels"] and i_fast["candidate_voxels"] == i_slow["candidate_voxels"]
    assert abs(i_fast["weight_entries"] - i_slow["weight_entries"]) <= 1e-4 * i_slow["weight_entries"]
    assert fast == pytest.approx(slow, rel=PATH_RTOL, abs=PATH_RTOL * float(slow.max()))


def test_weight_cache_reuses_weights_of_the_same_geometry():
    cams = _cameras()
    imgs = [im + 1e-3 for im in _images(cams)]  # no zero pixel: the same active voxels in both frames
    imgs_b = [im + 1e-3 for im in _images(cams, seed=4)]
    cache = WeightCache()
    a1, i1 = mart(imgs, cams, GRID, iterations=2, cache=cache, return_info=True)
    b1, i2 = mart(imgs_b, cams, GRID, iterations=2, cache=cache, return_info=True)
    b0 = mart(imgs_b, cams, GRID, iterations=2)
    assert not i1["weights_cached"] and i2["weights_cached"] and cache.hits == 1 and cache.nbytes > 0
    np.testing.assert_array_equal(b1, b0)  # reused weights give exactly the rebuilt result
    # a frame with other active voxels (zero pixels prune) rebuilds
    _, i3 = mart(_images(cams), cams, GRID, iterations=1, cache=cache, return_info=True)
    assert not i3["weights_cached"]


def test_final_residual_is_the_last_of_each():
    cams = _cameras(32)
    imgs = _images(cams)
    _, each = mart(imgs, cams, GRID, iterations=3, return_info=True)
    _, final = mart(imgs, cams, GRID, iterations=3, return_info=True, residuals="final")
    assert len(each["residuals"]) == 3 and final["residuals"] == [each["residuals"][-1]]


def test_circle_overlap_against_independent_forms():
    """The circle weight model's lens area against forms derived separately: containment
    (pi r^2 of the smaller circle), disjoint circles (0), the equal-radii lens
    2 r^2 acos(d / 2r) - (d / 2) sqrt(4 r^2 - d^2), and a 4000^2-point grid integration of
    an unequal pair (tolerance: the grid's cell area times its perimeter count, 2e-4)."""
    import math

    kernels()
    from mitpiv.reconstruct import _kernels as K

    ov = K.circle_overlap.py_func
    assert ov(0.1, 0.8, 0.3) == pytest.approx(math.pi * 0.09, rel=1e-14)
    assert ov(1.2, 0.5, 0.6) == 0.0
    for r, d in ((0.564, 0.3), (1.0, 1.5), (0.7, 0.01)):
        lens = 2 * r * r * math.acos(d / (2 * r)) - 0.5 * d * math.sqrt(4 * r * r - d * d)
        assert ov(d, r, r) == pytest.approx(lens, rel=1e-12)
    r1, r2, d = 0.8, 1.0 / math.sqrt(math.pi), 0.9
    n = 4000
    x = (np.arange(n) + 0.5) / n * 3.0 - 1.0
    xx, yy = np.meshgrid(x, (np.arange(n // 2) + 0.5) / n * 3.0)  # the upper half plane, y in [0, 1.5)
    inside = (xx**2 + yy**2 < r1 * r1) & ((xx - d) ** 2 + yy**2 < r2 * r2)
    area = 2 * inside.sum() * (3.0 / n) ** 2
    assert ov(d, r1, r2) == pytest.approx(area, abs=2e-4)
