"""The multi-plenoptic paper's system (Fahringer & Thurow, Table 1) and its paraxial
ray-transfer optics (eqs. 1-4), written afresh here in float64, against mitpiv's
physically based plenoptic camera (:meth:`PlenopticCamera.trace_to_sensor`, the geometry of
the ``plenoptic`` Mitsuba sensor, which tests/lightfield/test_plenoptic_camera.py checks
against tangent-space matrices).

The paper's state vector is ``(x, y, theta, phi)`` with *angles*; ours propagates exact ray
tangents through ideal thin lenses. The two agree in the paraxial limit: the lenslet index
and the sub-aperture (main-lens) coordinate of every ray agree, and the sensor positions
differ by ``O(theta^3)``.
"""

import math

import numpy as np
import pytest

from mitpiv.physics.plenoptic import PRESETS, PlenopticCamera, preset

# Tolerances and their provenance.
# Paraxial limit: rays scaled to 1e-3 of the paper's aperture and field; the angle/tangent
# difference theta - tan(theta) ~ theta^3 / 3 with theta <= 1e-4 rad over s_i = 13.3 mm is
# < 1e-11 mm; float64 round-off over ~50 mm of path is ~1e-14 mm. 1e-9 mm = 1e-6 pixel.
PARAXIAL_ATOL_MM = 1e-9
# Sub-aperture coordinate: a lenslet focused at infinity images the main lens, so the
# sensor offset from the lenslet-image centre is -a g / s_i up to the ray's position within
# the lenslet, g (x_m - c) / s_i <= g (p / sqrt 2) / s_i = 0.021 um = 0.015 px (derived in
# the test); the paper: "each pixel under an individual lenslet corresponds to one (u, v)".
SUBAPERTURE_ATOL_PX = 0.016


def paper_matrices(d, f):
    """Eqs. 1-2: free space of length d and a thin lens of focal length f, acting on
    (x, y, theta, phi)."""
    t = np.eye(4)
    t[0, 2] = t[1, 3] = d
    r = np.eye(4)
    r[2, 0] = r[3, 1] = -1.0 / f
    return t, r


def paper_trace(x, y, z, theta, phi, *, f_m, s_i, f_l, g, pitch, origin):
    """Eq. 4: L_s = T_LS (R_L T_ML R_M T_EM L + S_L), the lenslet (eq. 3: lens + prism)
    chosen after propagating to the array; returns sensor (x, y) and the lenslet index."""
    L = np.array([x, y, theta, phi], dtype=np.float64)
    t_em, _ = paper_matrices(z, 1.0)
    _, r_m = paper_matrices(0.0, f_m)
    t_ml, _ = paper_matrices(s_i, 1.0)
    t_ls, r_l = paper_matrices(g, f_l)
    at_mla = t_ml @ r_m @ t_em @ L
    idx = np.floor((at_mla[:2] - origin) / pitch + 0.5)
    s = origin + idx * pitch  # lenslet centre (s_x, s_y) on the rectilinear grid
    s_l = np.array([0.0, 0.0, s[0] / f_l, s[1] / f_l])
    out = t_ls @ (r_l @ at_mla + s_l)
    return out[:2], idx.astype(int)


def test_paper_table_1_system():
    cam = preset("multiplenoptic_paper")
    assert cam.focal_length_mm == 10.0 and cam.aperture_diameter_mm == pytest.approx(5.0)
    assert cam.mla_focal_length_um == 28.0 and cam.mla_pitch_um == 14.0 and cam.mla_f_number == 2.0
    assert cam.mla_count == (328, 328) and cam.resolution == (3280, 3280)
    # 3280 pixels span the 328 lenslets: 1.4 um pixels (Table 1's "14 um" sensor pitch would
    # make the sensor ten times wider than the array; the OCR dropped the decimal point)
    assert cam.resolution[0] * cam.pixel_pitch_um == pytest.approx(cam.mla_count[0] * cam.mla_pitch_um)
    assert cam.mla_gap_um == cam.mla_focal_length_um  # lenslets focused at infinity
    assert cam.focus_distance_mm / cam.aperture_diameter_mm == pytest.approx(8.0)  # S_o / p_M = 8
    s_i = 1.0 / (1.0 / 10.0 - 1.0 / 40.0)  # thin-lens equation, written afresh
    assert cam.image_distance_mm == pytest.approx(s_i, rel=1e-12)


@pytest.mark.parametrize("scale", [1e-3, 1e-2])
def test_paraxial_limit_matches_paper_ray_transfer(scale):
    cam = preset("multiplenoptic_paper")
    rng = np.random.default_rng(5)
    n = 400
    so = cam.focus_distance_mm
    # points near the axis around the focal plane (depth +-2 mm), rays through the aperture,
    # everything lateral scaled by `scale` towards the axis
    p = np.column_stack([rng.uniform(-1, 1, (n, 2)) * 2.0 * scale, so + rng.uniform(-2, 2, n)])
    r = cam.aperture_radius_mm * np.sqrt(rng.uniform(0, 1, n)) * scale
    ang = rng.uniform(0, 2 * math.pi, n)
    a = np.column_stack([r * np.cos(ang), r * np.sin(ang)])
    xs, idx, ok = cam.trace_to_sensor(p, a)
    assert ok.all()
    pitch = cam.mla_pitch_um * 1e-3
    origin = cam.origin_mm
    worst = 0.0
    for k in range(n):
        # the paper's angles of the physical ray from the point to the lens point
        theta = math.atan((a[k, 0] - p[k, 0]) / p[k, 2])
        phi = math.atan((a[k, 1] - p[k, 1]) / p[k, 2])
        ps, pi = paper_trace(p[k, 0], p[k, 1], p[k, 2], theta, phi, f_m=cam.focal_length_mm, s_i=cam.image_distance_mm,
                             f_l=cam.mla_focal_length_um * 1e-3, g=cam.gap_mm, pitch=pitch, origin=origin)
        assert tuple(pi) == tuple(idx[k])
        worst = max(worst, float(np.max(np.abs(ps - xs[k]))))
    # the angle/tangent difference is O(theta^3): s_i theta^3 with theta <= 1.2e-4 (scale 1e-3)
    # or 1.2e-3 (scale 1e-2) rad is < 3e-11 or < 3e-8 mm
    assert worst < (PARAXIAL_ATOL_MM if scale <= 1e-3 else 1e3 * PARAXIAL_ATOL_MM)


def test_off_axis_difference_is_third_order():
    """At the full aperture the paper's angles and our tangents part by ~ s_i theta^3 / 3: the
    paraxial model's own error, shrinking as the cube of the ray angle."""
    cam = preset("multiplenoptic_paper")
    so, si = cam.focus_distance_mm, cam.image_distance_mm
    errs = []
    # a point in focus imaged on the centre of a lenslet (the axis lies between lenslets)
    x0 = -(cam.origin_mm[0] + 164 * cam.mla_pitch_um * 1e-3) * so / si
    for s in (0.25, 0.5, 1.0):
        a = np.array([[cam.aperture_radius_mm * s, 0.0]])
        p = np.array([[x0, 0.0, so]])
        xs, idx, _ = cam.trace_to_sensor(p, a)
        theta = math.atan((a[0, 0] - x0) / so)
        ps, _ = paper_trace(x0, 0.0, so, theta, 0.0, f_m=cam.focal_length_mm, s_i=si, f_l=cam.mla_focal_length_um * 1e-3,
                            g=cam.gap_mm, pitch=cam.mla_pitch_um * 1e-3, origin=cam.origin_mm)
        errs.append(abs(ps[0] - xs[0, 0]))
    # halving the angle divides the difference by 8 (third order), within 5 %
    assert errs[1] / errs[0] == pytest.approx(8.0, rel=0.05) and errs[2] / errs[1] == pytest.approx(8.0, rel=0.05)


def test_subaperture_coordinate_and_camera_rays_round_trip():
    """Each pixel under a lenslet sees one main-lens point (the paper's (u, v)): the sensor
    offset from the lenslet-image centre is -a g / s_i; and the camera path
    (:meth:`PlenopticCamera.camera_rays`) from that sensor point through the same lenslet
    point returns to the lens point the forward ray came from."""
    cam = PlenopticCamera(**{**PRESETS["multiplenoptic_paper"], "resolution": (480, 480), "mla_count": (48, 48)})
    rng = np.random.default_rng(2)
    n = 2000
    so = cam.focus_distance_mm
    p = np.column_stack([rng.uniform(-1.5, 1.5, (n, 2)), so + rng.uniform(-3, 3, n)])
    r = cam.aperture_radius_mm * np.sqrt(rng.uniform(0, 1, n))
    ang = rng.uniform(0, 2 * math.pi, n)
    a = np.column_stack([r * np.cos(ang), r * np.sin(ang)])
    xs, idx, ok = cam.trace_to_sensor(p, a)
    b = cam.basis_mm
    c = cam.origin_mm + idx[:, 0:1] * b[0] + idx[:, 1:2] * b[1]
    pp = cam.pixel_pitch_um * 1e-3
    off_px = (xs - c * cam.image_scale) / pp
    expect_px = -a * cam.gap_mm / cam.image_distance_mm / pp
    assert np.max(np.abs(off_px - expect_px)[ok]) < SUBAPERTURE_ATOL_PX
    # round trip: the MLA point of the forward ray as the camera path's cell point
    si = cam.image_distance_mm
    t1 = (a - p[:, :2]) / p[:, 2:3]
    xm = a + si * (t1 - a / cam.focal_length_mm)
    cell = np.linalg.solve(b.T, (xm - c).T).T + 0.5
    uv = cam.sensor_mm_to_px(xs)
    inside = ok & (np.abs(off_px) < 4.5).all(axis=1)  # own lenslet image (no crosstalk)
    o, d, ok2 = cam.camera_rays(uv[inside], cell[inside])
    assert ok2.all()
    lens_local = cam.world_to_local(o)[:, :2]
    np.testing.assert_allclose(lens_local, a[inside], atol=1e-9)
