"""Plenoptic reconstructions on rendered light fields: volumetric refocus (additive vs
multiplicative), two-camera fusion at +-25 deg, DRT-MART and its ray-traced weights.

Cameras as in tests/lightfield (5.5 um pixels, 55 um lenslets, 50 mm f/2.8 focused at
250 mm), 240 px, looking at the origin from 250 mm at 0 and +-25 deg about the y axis.
Grid: pixel:voxel 2:2:10 of the object-space pixel (0.022 mm).
"""

import math

import mitsuba as mi
import numpy as np
import pytest

from mitpiv.analysis import quality_q_zero_mean, truth_volume
from mitpiv.errors import ConfigError
from mitpiv.lightfield import decode
from mitpiv.reconstruct import VoxelGrid, drt_mart, drt_weights, fuse, plenoptic_volume
from tests.lightfield.helpers import particle_scene, render, white_scene

RES = 240
GRID = VoxelGrid.for_camera((-2, -2, -3.5), (2, 2, 3.5), pixel_size_mm=0.022, ratio=(2, 2, 10))

# Tolerances and their provenance. Quality comparisons (multiplicative beats additive, two
# cameras beat one) are orderings and stay inline.
# fuse() on float32 volumes against its formula written afresh in float64.
FUSE_RTOL, FUSE_ATOL = 1e-5, 1e-7
# DRT weights against the light rendered by particle tracing (docstring: 256 rays and 8 samples
# per slab find > 95 %, 64 rays and 2 samples 83 %).
DRT_LIGHT_FRACTION = 0.95


def pose(angle_deg):
    a = math.radians(angle_deg)
    return {"to_world": mi.ScalarTransform4f().look_at(origin=[250 * math.sin(a), 0, 250 * math.cos(a)],
                                                      target=[0, 0, 0], up=[0, 1, 0])}


@pytest.fixture(scope="module")
def views(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("plen")
    pts = np.random.default_rng(1).uniform([-1.5, -1.5, -3], [1.5, 1.5, 3], (15, 3))
    out = {}
    for ang in (0, 25, -25):
        sc = particle_scene(tmp, pts, {"type": "particle_tracer", "rays_per_particle": 20000}, res=RES, **pose(ang))
        raw = render(sc)
        cam = sc.sensors()[0].camera
        white = render(white_scene(RES, **pose(ang)), spp=64)
        out[ang] = (raw, cam, decode(raw, optics=cam, white=white))
    return pts, out, truth_volume(pts, GRID)


def z_error(vol, pts, grid):
    """RMS depth error [mm] of the brightest voxel in a +-2 voxel column around each particle."""
    q = np.rint(grid.to_voxel(pts)).astype(int)
    err = []
    for (i, j, _), p in zip(q, pts, strict=True):
        col = vol[:, max(j - 2, 0) : j + 3, max(i - 2, 0) : i + 3]
        err.append(grid.z_mm[np.unravel_index(np.argmax(col), col.shape)[0]] - p[2])
    return float(np.sqrt(np.mean(np.square(err))))


def test_grid_follows_pixel_voxel_ratio():
    assert GRID.voxel_mm == pytest.approx((0.044, 0.044, 0.22))


def test_multiplicative_beats_additive(views):
    pts, v, truth = views
    lf = v[0][2]
    add = plenoptic_volume(lf, GRID, method="additive")
    mult = plenoptic_volume(lf, GRID, method="multiplicative")
    assert quality_q_zero_mean(mult, truth) > quality_q_zero_mean(add, truth) + 0.02
    # the rescaling exponent sharpens the product further without changing where the light is
    sharp = plenoptic_volume(lf, GRID, method="multiplicative", exponent=2.0)
    assert sharp == pytest.approx(mult.astype(np.float64) ** 2, rel=1e-5, abs=1e-30)


def test_two_cameras_beat_one_on_quality_and_depth(views):
    pts, v, truth = views
    vols = {a: plenoptic_volume(v[a][2], GRID, method="multiplicative") for a in (25, -25)}
    fused = fuse([vols[25], vols[-25]])
    q_fused = quality_q_zero_mean(fused, truth)
    z_fused = z_error(fused, pts, GRID)
    for a in (25, -25):
        assert q_fused > quality_q_zero_mean(vols[a], truth) + 0.1
        assert z_fused < 0.5 * z_error(vols[a], pts, GRID)


def test_fuse_normalises_brightness_and_keeps_zeros():
    rng = np.random.default_rng(2)
    a, b = rng.random((4, 5, 6)) ** 3, rng.random((4, 5, 6)) ** 3
    f = fuse([a, b])
    assert fuse([1e-20 * a, 1e6 * b]) == pytest.approx(f, rel=1e-5)  # per-camera brightness drops out
    mu, sd = a.mean(), a.std()
    ref = np.sqrt(np.maximum(a - mu, 0) / sd * np.maximum(b - b.mean(), 0) / b.std())
    assert f == pytest.approx(ref, rel=FUSE_RTOL, abs=FUSE_ATOL)
    b[0] = 0.0
    assert not np.any(fuse([a, b])[0])
    assert not np.any(fuse([a, np.zeros_like(a)]))  # a camera with an empty volume
    with pytest.raises(ConfigError, match="shape"):
        fuse([a, a[:2]])
    with pytest.raises(ConfigError, match="normalise"):
        fuse([a, b], normalise="zscore")


def test_drt_weights_follow_the_rendered_light(tmp_path):
    """One particle, rendered by particle tracing: the pixels whose traced ray bundles cross the
    particle's voxel receive >= 95 % of its light (the weights are built by camera tracing).
    At 25 deg the rays cross the voxel slabs obliquely: 64 rays and 2 samples per slab find
    83 % (pixels whose bundles graze the voxel are missed), 256 rays and 8 samples > 95 %."""
    p = np.array([[0.3, -0.4, 1.5]])
    sc = particle_scene(tmp_path, p, {"type": "particle_tracer", "rays_per_particle": 20000}, res=RES, **pose(25))
    raw = render(sc)
    cam = sc.sensors()[0].camera
    grid = VoxelGrid.from_bounds(p[0] - 0.5, p[0] + 0.5, (0.1, 0.1, 0.25))
    vox = np.ravel_multi_index(tuple(np.floor(grid.to_voxel(p)[0] + 0.5).astype(int)[::-1]), grid.shape)
    lit = np.flatnonzero(raw.ravel() > 0)
    w = drt_weights(cam, grid, pixels=lit, rays_per_pixel=256, substeps=8)
    crossing = np.flatnonzero(w[:, vox].toarray().ravel() > 0)
    assert raw.ravel()[crossing].sum() > DRT_LIGHT_FRACTION * raw.sum()
    assert w.shape == (RES * RES, grid.n_voxels) and w[np.setdiff1d(np.arange(RES * RES), lit)].nnz == 0


def test_drt_mart_reconstructs(views):
    pts, v, truth = views
    raw, cam, lf = v[0]
    vol, info = drt_mart(raw, cam, GRID, iterations=3, return_info=True)
    q = quality_q_zero_mean(vol, truth)
    assert np.all(np.isfinite(vol)) and q > 0.5 * quality_q_zero_mean(plenoptic_volume(lf, GRID), truth)
    assert info["active_voxels"] < info["voxels_seen"] and info["voxel_updates_per_s"] > 0
    # strict zero-pixel pruning removes voxels that hold particles (the reason for the default)
    strict = drt_mart(raw, cam, GRID, iterations=3, prune_fraction=0.0, dark_floor=0.0)
    assert quality_q_zero_mean(strict, truth) < q
    with pytest.raises(ConfigError, match="'raw' has shape"):
        drt_mart(raw[:-1], cam, GRID)
    with pytest.raises(ConfigError, match="prune_fraction"):
        drt_mart(raw, cam, GRID, prune_fraction=2.0)
    with pytest.raises(ConfigError, match="rays_per_pixel"):
        drt_weights(cam, GRID, rays_per_pixel=0)


def test_drt_mart_drops_the_voxels_at_the_edge_of_the_field():
    """min_coverage: a grid cropped to the sensor's field (Shi et al.'s 800 px PMR-14 camera,
    a 2.4 x 3 mm crop) has voxels on its lateral edge whose ray cones the sensor catches about
    half of (coverage ~0.5-0.7 in the focal plane); those, and only voxels near the edge, are
    dropped at 0.75. A grid well inside the field keeps its voxels (a few in 10^4 fall below
    0.75 by the rays' sampling noise). Bad values are refused by name."""
    from mitpiv.reconstruct.plenoptic import coverage
    from mitpiv.replications.lfpiv_vs_tomo import model as S

    case = S.LFCase("low", 14, 2.4, 3.0)
    cam, grid = S.lf_camera(case), case.grid()
    a = drt_weights(cam, grid, rays_per_pixel=8, substeps=2, seed=1)
    total = np.bincount(a.indices, weights=a.data, minlength=grid.n_voxels)
    c = coverage(total, cam, grid).reshape(grid.shape)
    mid = grid.shape[0] // 2  # the focal plane
    lenslet_vox = 14 * 0.015 / grid.voxel_mm[0]  # 7 voxels
    assert np.median(c[mid, :, 0]) < 0.75 and np.median(c[mid, :, -1]) < 0.75
    assert np.median(c[mid, 20:-20, 20:-20]) == pytest.approx(1.0, abs=0.05)
    dropped = np.argwhere(c[mid] < 0.75)  # (y, x)
    ny, nx = grid.shape[1:]
    edge_dist = np.minimum.reduce([dropped[:, 0], ny - 1 - dropped[:, 0], dropped[:, 1], nx - 1 - dropped[:, 1]])
    assert len(dropped) and edge_dist.max() <= lenslet_vox
    rng = np.random.default_rng(2)
    raw = rng.random(cam.resolution[::-1]) * (rng.random(cam.resolution[::-1]) < 0.05)
    vol, info = drt_mart(raw, cam, grid, iterations=2, matrix=a, min_coverage=0.75, return_info=True)
    assert info["edge_voxels_dropped"] > 0 and np.all(vol.reshape(-1)[c.reshape(-1) < 0.75] == 0)
    inner = VoxelGrid(origin_mm=tuple(np.asarray(grid.origin_mm) + [0.6, 0.75, 0.0]), voxel_mm=grid.voxel_mm,
                      shape=(grid.shape[0], grid.shape[1] // 2, grid.shape[2] // 2))
    ai = drt_weights(cam, inner, rays_per_pixel=8, substeps=2, seed=1)
    ci = coverage(np.bincount(ai.indices, weights=ai.data, minlength=inner.n_voxels), cam, inner)
    assert np.mean(ci < 0.75) < 1e-3
    for bad in (0.0, 1.0, 1.5, True, "0.5"):
        with pytest.raises(ConfigError, match="min_coverage"):
            drt_mart(raw, cam, grid, iterations=1, matrix=a, min_coverage=bad)


def test_drt_cost_counts_the_weights_before_they_are_built(views):
    """drt_cost: drt_weights traced for 1024 random pixels and scaled to the sensor predicts
    the entries the whole matrix holds (within 10 %: the sample's relative noise is ~3 %) for
    the head-on camera and the one at 25 deg, while pixels x rays x slabs alone would be off by
    half (this camera's rays are vignetted); the memory check refuses a light-field grid the
    voxel count alone would let through, naming the fix."""
    from mitpiv import costs
    from mitpiv.reconstruct.plenoptic import drt_cost

    _, v, _ = views
    for ang in (0, 25):
        cam = v[ang][1]
        nnz = drt_weights(cam, GRID, rays_per_pixel=4, substeps=2).nnz
        est = drt_cost(cam, GRID, rays_per_pixel=4, iterations=10)
        entries = (est.memory_bytes - 13.0 * GRID.n_voxels) / costs.DRT_BYTES_PER_ENTRY
        assert entries == pytest.approx(nnz, rel=0.10), ang
        assert nnz < 0.75 * RES * RES * 4 * GRID.shape[0]  # the plain product would be far off
    # the replica's light-field arm on a third of its sensor (2200 x 1466 px, 1100 x 733 x 182
    # voxels): 1.9 GB by the voxels, 113 GB by the weights
    c = costs.drt_mart_cost(2200 * 1466, 8, 182, iterations=400, n_voxels=1100 * 733 * 182)
    assert costs.reconstruction_cost(1100 * 733 * 182, iterations=400, method="drt-mart").memory_bytes < 2e9
    assert c.memory_bytes > 1e11
    with pytest.raises(ConfigError, match="rays_per_pixel"):
        costs.check_memory(c, what="[reconstruction] drt-mart", fix="use fewer rays_per_pixel or a crop",
                           available=24 * 2**30)
