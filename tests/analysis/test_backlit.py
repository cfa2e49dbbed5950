"""Backlit plenoptic particle tracking and sizing: hybrid detection (minimum intensity +
Tenengrad), dot-card polynomial dewarping, two-frame matching; on analytic stacks and on
scenes rendered by the plenoptic camera through Mitsuba's direct integrator.

Camera: 5.5 um pixels, 55 um lenslets (PMR 10), 50 mm f/2.8 focused at 100 mm (|M| = 1:
55 um per refocused pixel, theoretical depth resolution 0.34 mm), 600 px.
"""

import mitsuba as mi
import numpy as np
import pytest
from scipy import ndimage

from mitpiv.analysis.backlit import evaluate_detections, fit_dewarp, hybrid_detect, match_frames, tenengrad
from mitpiv.calibrate import calibrate_dewarp
from mitpiv.errors import ConfigError
from mitpiv.lightfield import decode, focal_stack
from mitpiv.lightfield.refocus import stack_pixels
from mitpiv.physics.droplets import drop_impact_field, pellet_field
from mitpiv.render.backlit import render_backlit

RES = 600

# Tolerances and their provenance; the reference is the exact synthetic truth (disk centres,
# depths and diameters; droplet positions and velocities). Exact fits (a polynomial dewarp
# recovered to 1e-9) stay inline.
# Analytic stack: symmetric disks give their centres; depth to a quarter plane spacing
# (0.1 mm planes); diameter from the pixel-count area, half a pixel.
STACK_CENTRE_TOL_PX = 0.05
STACK_DEPTH_TOL_MM = 0.025
STACK_DIAMETER_TOL_PX = 0.5
DEWARP_RMS_MM = 0.005  # dot card: 245 dots at 5 depths, fit residual below 0.1 refocused px (0.055 mm)
# Rendered droplets (measured: lateral 0.02 d, size RMS 0.011 mm = 0.2 refocused px, depth RMS
# 0.44 d = 0.13 mm). The depth bound is the drop-fragments study's finding (paper file
# 003_c92dce90627d9ea9.txt, Munz, section "Depth Uncertainty"): a z uncertainty of about 0.75
# mean particle diameters for the plenoptic camera (0.72 for DIH, 1-2 in the wider literature
# it cites), i.e. "about one diameter".
LATERAL_RMS_DIAMETERS = 0.1
SIZE_RMS_MM = 0.25 * 0.055  # a quarter of a refocused pixel (55 um at |M| = 1)
DEPTH_RMS_DIAMETERS = 1.0
# Two-frame velocities: in-plane, two lateral errors of ~0.006 mm (0.02 d) plus the perspective
# shift of a depth error -> < 0.02 mm of displacement (0.36 refocused px); depth RMS limited by
# the depth uncertainty of both frames.
VELOCITY_INPLANE_TOL_MM = 0.02  # of displacement, divided by dt
VELOCITY_DEPTH_RMS_MM = 0.25  # of displacement
PELLET_SIZE_BIAS_MM = 0.1  # 2 mm pellets at |M| = 0.25: under half a refocused pixel (0.22 mm)


def sensor(focus_mm=100.0):
    return {"type": "plenoptic", "pixel_pitch_um": 5.5, "focal_length_mm": 50.0, "f_number": 2.8,
            "focus_distance_mm": focus_mm, "mla_pitch_um": 55.0,
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, focus_mm], target=[0, 0, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": RES, "height": RES, "pixel_format": "luminance", "rfilter": {"type": "box"}}}


def synthetic_stack(centres_px, diam_px, z0, z, shape=(64, 64), blur_per_mm=3.0):
    """Opaque disks (1 = background) blurred by a Gaussian growing with |z - z0|."""
    rows, cols = np.indices(shape) + 0.0
    st = np.ones((z.size,) + shape)
    for (cu, cv), d, zc in zip(centres_px, diam_px, z0, strict=True):
        # supersampled disk coverage
        sub = (np.arange(4) + 0.5) / 4 - 0.5
        cov = np.zeros(shape)
        for a in sub:
            for b in sub:
                cov += ((cols + a - cu) ** 2 + (rows + b - cv) ** 2 <= (d / 2) ** 2) / 16
        for k, zk in enumerate(z):
            st[k] -= ndimage.gaussian_filter(cov, 0.3 + blur_per_mm * abs(zk - zc))
    return np.clip(st, 0, 1)


def test_hybrid_detection_on_an_analytic_stack():
    z = np.linspace(-2, 2, 41)
    centres = [(15.3, 20.7), (45.0, 18.2), (30.6, 47.5)]
    diam = [6.0, 9.0, 4.0]
    z0 = [-0.83, 0.4, 1.27]
    det = hybrid_detect(synthetic_stack(centres, diam, z0, z), z, background=1.0)
    assert len(det) == 3
    order = np.argsort(det.uv_px[:, 1] * 100 + det.uv_px[:, 0])
    ref = np.argsort(np.array(centres)[:, 1] * 100 + np.array(centres)[:, 0])
    np.testing.assert_allclose(det.uv_px[order], np.array(centres)[ref], atol=STACK_CENTRE_TOL_PX)
    np.testing.assert_allclose(det.z_stack_mm[order], np.array(z0)[ref], atol=STACK_DEPTH_TOL_MM)
    np.testing.assert_allclose(det.diameter_px[order], np.array(diam)[ref], atol=STACK_DIAMETER_TOL_PX)
    assert np.all(det.aspect < 1.2)


def test_tenengrad_and_bad_inputs():
    img = np.zeros((9, 9))
    img[:, 5:] = 1.0  # vertical step: Sobel x = 4 across the edge (kernel sum 1 + 2 + 1)
    t = tenengrad(img)
    assert t[4, 4] == pytest.approx(16.0) and t[4, 5] == pytest.approx(16.0) and t[4, 1] == 0.0
    st = np.ones((3, 8, 8))
    with pytest.raises(ConfigError, match="one depth per plane"):
        hybrid_detect(st, [0.0, 1.0])
    with pytest.raises(ConfigError, match="monotonic"):
        hybrid_detect(st, [0.0, 1.0, 0.5])
    with pytest.raises(ConfigError, match="threshold"):
        hybrid_detect(st, [0.0, 1.0, 2.0], threshold=1.5)
    with pytest.raises(ConfigError, match="background"):
        hybrid_detect(st, [0.0, 1.0, 2.0], background=0.0)
    assert len(hybrid_detect(st, [0.0, 1.0, 2.0], background=1.0)) == 0  # empty scene


def test_dewarp_recovers_a_polynomial_and_refuses_degenerate_cards():
    rng = np.random.default_rng(0)
    uvz = np.column_stack([rng.uniform(0, 600, 300), rng.uniform(0, 600, 300), rng.choice([-1.0, 0.0, 1.0], 300)])
    u, v, z = uvz.T
    xyz = np.column_stack([1e-3 * u * (1 + 0.01 * z) + 1e-8 * u**2 * v, -1e-3 * v * (1 + 0.01 * z) + 2e-9 * v**3, -z])
    dw = fit_dewarp(uvz, xyz)
    assert dw.rms_mm < 1e-10
    np.testing.assert_allclose(dw([[300.0, 200.0, 0.5]]), [[0.3 * 1.005 + 1e-8 * 9e4 * 200, -0.2 * 1.005 + 2e-9 * 8e6, -0.5]],
                               atol=1e-9)
    with pytest.raises(ConfigError, match="depths"):
        fit_dewarp(uvz[uvz[:, 2] == 0], xyz[uvz[:, 2] == 0])
    with pytest.raises(ConfigError, match="markers"):
        fit_dewarp(uvz[:40], xyz[:40])


@pytest.fixture(scope="module")
def optics():
    s = sensor()
    dewarp, obs = calibrate_dewarp(s, [-1.5, -0.75, 0.0, 0.75, 1.5], spp=16)
    white = render_backlit(s, np.zeros((0, 3)), [], spp=16)
    cam = mi.load_dict({"type": "scene", "sensor": s}).sensors()[0].camera
    return s, dewarp, white, cam


def detect(optics, positions, diameters, z=np.linspace(-2.5, 2.5, 101)):
    s, dewarp, white, cam = optics
    raw = render_backlit(s, positions, diameters, spp=16)
    lf = decode(raw, optics=cam, white=white)
    bg = focal_stack(decode(white, optics=cam, white=white), z)
    return hybrid_detect(focal_stack(lf, z), z, background=bg, dewarp=dewarp,
                         pixel_to_stack=lambda u, v: stack_pixels(lf, u, v))


def sparse_droplets(seed=0):
    rng = np.random.default_rng(seed)
    gx, gy = np.meshgrid(np.linspace(-1.0, 1.0, 4), np.linspace(-1.0, 1.0, 4))
    p = np.column_stack([gx.ravel(), gy.ravel(), rng.uniform(-1.5, 1.5, 16)]) + rng.uniform(-0.05, 0.05, (16, 3))
    return p, rng.uniform(0.2, 0.4, 16)


def test_rendered_droplets_depth_and_size(optics):
    _, dewarp, _, cam = optics
    assert dewarp.rms_mm < DEWARP_RMS_MM
    p, d = sparse_droplets()
    det = detect(optics, p, d)
    ev = evaluate_detections(det, p, d, axis=(0, 0, -1))
    assert ev["detected_fraction"] == 1.0 and ev["n_found"] == 16
    assert ev["lateral_rms_diameters"] < LATERAL_RMS_DIAMETERS
    assert ev["size_rms_mm"] < SIZE_RMS_MM
    assert ev["depth_rms_diameters"] < DEPTH_RMS_DIAMETERS
    depth_rms_mm = np.sqrt(np.mean((ev["depth_error_diameters"] * d[ev["pairs"][:, 1]]) ** 2))
    assert depth_rms_mm < cam.depth_resolution()  # better than the geometric depth resolution (0.34 mm)


def test_two_frames_give_three_component_velocities(optics):
    p, d = sparse_droplets(seed=1)
    v = np.array([400.0, -250.0, 1500.0])  # mm/s
    dt = 2e-4
    a = detect(optics, p, d)
    b = detect(optics, p + v * dt, d)
    m = match_frames(a, b, dt_s=dt, radius_mm=0.8)  # displacement 0.32 mm plus the depth errors of both frames
    assert m["pairs"].shape[0] == 16
    err = m["velocity_mm_s"] - v
    assert np.all(np.abs(err[:, :2]) < VELOCITY_INPLANE_TOL_MM / dt)
    assert np.sqrt(np.mean(err[:, 2] ** 2)) * dt < VELOCITY_DEPTH_RMS_MM
    with pytest.raises(ConfigError, match="dt_s"):
        match_frames(a, b, dt_s=0.0, radius_mm=0.4)


def _dets(pos):
    from mitpiv.analysis.backlit import BacklitDetections

    n = len(pos)
    z = np.zeros(n)
    return BacklitDetections(uv_px=np.zeros((n, 2)), z_stack_mm=z, area_px=z + 1, diameter_px=z + 1, aspect=z + 1,
                             darkness=z + 1, positions_mm=np.asarray(pos, dtype=float), diameters_mm=z + 0.1)


def test_match_frames_in_the_image_plane_leaves_depth_free():
    """A single-view technique's depth errors (here +-5 mm, as DIH's for small droplets)
    break 3D matching; matching normal to the viewing axis pairs the right particles and
    keeps the depth difference in the displacement."""
    rng = np.random.default_rng(0)
    n = 40
    grid = np.stack(np.meshgrid(np.arange(8), np.arange(5)), -1).reshape(-1, 2) * 2.0  # 2 mm apart
    a = np.column_stack([grid, rng.uniform(-5, 5, n)])
    shift = np.array([0.3, -0.1, 0.0])
    b = a + shift
    b[:, 2] = rng.uniform(-5, 5, n)  # depth re-measured with a large error
    perm = rng.permutation(n)
    da, db = _dets(a), _dets(b[perm])
    m3 = match_frames(da, db, dt_s=1.0, radius_mm=0.6)
    assert m3["pairs"].shape[0] < n // 2
    m = match_frames(da, db, dt_s=1.0, radius_mm=0.6, axis=(0, 0, 2.0))
    assert m["pairs"].shape[0] == n
    np.testing.assert_array_equal(perm[m["pairs"][:, 1]], m["pairs"][:, 0])
    np.testing.assert_allclose(m["velocity_mm_s"][:, :2], np.broadcast_to(shift[:2], (n, 2)), atol=1e-12)
    np.testing.assert_allclose(m["velocity_mm_s"][:, 2], b[m["pairs"][:, 0], 2] - a[m["pairs"][:, 0], 2], atol=1e-12)
    with pytest.raises(ConfigError, match="axis"):
        match_frames(da, db, dt_s=1.0, radius_mm=0.6, axis=(0, 0, 0))


def test_evaluate_detections_picks_among_overlapping_particles_by_depth():
    """Two particles nearly on one line of sight (depth 0 and 8 mm, 0.04 mm apart in the
    image) and a third beside them, each detected 0.1 mm deep of itself with a 0.035 mm
    image-plane error towards the other: by the image plane alone each detection is nearer
    the wrong particle and is scored 8 mm (40 d) off; with the depth tie-break each is
    scored against its own particle (0.1 mm = 0.5 d). A detection with no particle within
    the image-plane radius stays unmatched however close in depth."""
    t = np.array([[0.0, 0.0, 0.0], [0.04, 0.0, 8.0], [3.0, 0.0, 4.0]])
    d = np.full(3, 0.2)
    det = _dets(np.array([[0.005, 0.0, 8.1], [0.035, 0.0, 0.1], [3.0, 0.0, 4.1]]))  # of t1, t0, t2
    det.diameters_mm = np.full(3, 0.2)
    ev = evaluate_detections(det, t, d, axis=(0, 0, 1))
    assert ev["n_matched"] == 3
    np.testing.assert_array_equal(ev["pairs"], [[0, 1], [1, 0], [2, 2]])
    np.testing.assert_allclose(ev["depth_error_diameters"], 0.5, atol=1e-9)
    plane = evaluate_detections(det, t, d, axis=(0, 0, 1), depth_tiebreak=False)
    np.testing.assert_array_equal(plane["pairs"], [[0, 0], [1, 1], [2, 2]])
    np.testing.assert_allclose(np.abs(plane["depth_error_diameters"][:2]), [40.5, 39.5], atol=1e-9)
    far = _dets(np.array([[1.0, 1.0, 0.0]]))
    far.diameters_mm = np.full(1, 0.2)
    assert evaluate_detections(far, t, d, axis=(0, 0, 1))["n_matched"] == 0


def test_edge_cut_and_overlapping_droplets(optics):
    # one droplet cut by the field edge (1.65 mm half-width), two overlapping in projection
    p = np.array([[1.62, 0.0, 0.0], [0.0, 0.0, -0.5], [0.2, 0.0, 0.6], [-0.9, -0.9, 0.0]])
    d = np.array([0.3, 0.3, 0.3, 0.3])
    det = detect(optics, p, d)
    assert len(det) == 2  # the cut one is dropped, the overlapping pair merges into one region
    ev = evaluate_detections(det, p, d, axis=(0, 0, -1))
    assert ev["n_matched"] == 2 and np.all(np.isfinite(det.positions_mm))
    assert det.aspect.max() > 1.3  # the merged pair is elongated


def test_pellets_and_drop_impact_fields():
    f = pellet_field(8, diameter_mm=2.0, box_mm=((-5, 5), (-5, 5), (-4, 4)), velocity_mm_s=(0, 0, -1e5), seed=3)
    p = f["positions_mm"]
    gap = np.linalg.norm(p[:, None] - p[None], axis=2) + np.eye(len(p)) * 99
    assert len(p) == 8 and gap.min() >= 2.5
    h = pellet_field(8, view_axis=(0, 0, 1), seed=3)["positions_mm"][:, :2]
    assert (np.linalg.norm(h[:, None] - h[None], axis=2) + np.eye(8) * 99).min() >= 2.5  # silhouettes apart
    g = drop_impact_field(200, seed=1)
    d = g["diameters_mm"]
    assert d.min() >= 0.05 and d.max() <= 0.5 and 100 < len(d) <= 200
    dist = np.linalg.norm(g["positions_mm"][:, None] - g["positions_mm"][None], axis=2) + np.eye(len(d)) * 99
    assert np.all(dist >= 0.5 * (d[:, None] + d[None]) - 1e-12)
    assert np.all(g["velocities_mm_s"][:, 1] > 0)  # ejected upwards
    with pytest.raises(ConfigError, match="d_min_mm"):
        drop_impact_field(10, d_min_mm=0.6)
    with pytest.raises(ConfigError, match="box_mm"):
        pellet_field(3, box_mm=((0, 1), (0, 1)))


def test_rendered_pellets_at_quarter_magnification():
    s = sensor(250.0)  # |M| = 0.25: 0.22 mm per refocused pixel, 13 mm field
    f = pellet_field(6, diameter_mm=2.0, box_mm=((-4.5, 4.5), (-4.5, 4.5), (-3, 3)), view_axis=(0, 0, 1), seed=4)
    dewarp, _ = calibrate_dewarp(s, [-4.0, -2.0, 0.0, 2.0, 4.0], spp=8)
    white = render_backlit(s, np.zeros((0, 3)), [], spp=8)
    cam = mi.load_dict({"type": "scene", "sensor": s}).sensors()[0].camera
    det = detect((s, dewarp, white, cam), f["positions_mm"], f["diameters_mm"], z=np.linspace(-6, 6, 61))
    ev = evaluate_detections(det, f["positions_mm"], f["diameters_mm"], axis=(0, 0, -1))
    assert ev["detected_fraction"] == 1.0
    assert abs(ev["size_bias_mm"]) < PELLET_SIZE_BIAS_MM and ev["depth_rms_diameters"] < DEPTH_RMS_DIAMETERS


def test_hybrid_detect_streams_a_memory_mapped_stack(tmp_path):
    """A float32 stack and background stack as memory maps (focal_stack(out=...)) give the
    very same detections as in memory: the planes are read one at a time, not copied whole."""
    nz, h, w = 15, 60, 70
    z = np.linspace(-1.5, 1.5, nz)
    yy, xx = np.mgrid[0:h, 0:w]
    st = np.ones((nz, h, w), np.float32)
    for cx, cy, cz, r in ((18, 20, 0.4, 4), (48, 38, -0.8, 5)):
        for k in range(nz):
            blur = 1 + 2 * abs(z[k] - cz)
            st[k] *= 1 - 0.9 * np.clip((r + blur - np.hypot(xx - cx, yy - cy)) / (2 * blur), 0, 1) ** 1.5
    bg = np.full_like(st, 1.0)
    np.save(tmp_path / "s.npy", st)
    np.save(tmp_path / "b.npy", bg)
    ref = hybrid_detect(st, z, background=bg)
    got = hybrid_detect(np.load(tmp_path / "s.npy", mmap_mode="r"), z, background=np.load(tmp_path / "b.npy", mmap_mode="r"))
    assert len(ref) == 2
    for f in ("uv_px", "z_stack_mm", "diameter_px", "area_px"):
        assert np.array_equal(getattr(ref, f), getattr(got, f))
    assert abs(ref.z_stack_mm[np.argmin(ref.uv_px[:, 0])] - 0.4) < 0.25  # the sharpest plane of the first disk
