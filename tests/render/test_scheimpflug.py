"""Tilted plane of focus (Scheimpflug) in the thin-lens distorted_pinhole, and camera arrangements.

A point on the plane of focus images to a single point whatever the aperture sample, so
with a box filter its energy lands in one pixel; off the plane it spreads. Camera and
particle tracing must agree with the tilted-plane importance Jacobian (statistical test).
"""

import mitsuba as mi
import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.physics.camera import (
    PinholeCamera,
    place_camera,
    planar_array,
    ring_arrangement,
    scatter_arrangement,
    scheimpflug,
)
from mitpiv.render.render import render_sensor

from .helpers import scene, window_stats

ROT, POS = place_camera(azimuth_deg=0.0, elevation_deg=45.0, distance_mm=400.0)
CAM = PinholeCamera((96, 96), 50.0, 10.0, rotation=ROT, position_mm=POS)
RNG = np.random.default_rng(5)
PTS = np.column_stack([RNG.uniform(-3.0, 3.0, (10, 2)), np.zeros(10)])  # on the sheet mid-plane z = 0
SHEET = {"origin": mi.ScalarPoint3f(0.0, 0.0, 0.0)}

# Tolerances and their provenance. Arrangement geometry (closed forms in float64) is held to
# rounding (1e-9 .. 1e-12) inline.
# A point on the tilted plane of focus images to one point whatever the aperture sample: with a
# box filter all its energy lands in one pixel (float32 ray positions at pixel edges aside).
IN_FOCUS_PIXEL_FRACTION = 0.999
SAME_LIGHT_RTOL = 0.03  # window sums with and without the tilt (256 rays per particle)
# Camera vs particle tracing: N_SIGMA standard errors of the pooled ratio (10 particles x 4
# seeds, the per-particle spread), or the floor when the spread is tiny.
N_SIGMA = 5
TRACING_RATIO_FLOOR = 0.005
JACOBIAN_FD_RTOL = 2e-3  # the importance Jacobian per ray: float32 kernels, central differences (h = 1e-3)


def lens(tilted):
    sp = scheimpflug(ROT, POS, focal_length_mm=50.0, plane_point_mm=(0, 0, 0), plane_normal=(0, 0, 1))
    props = {"f_number": 2.0, "focus_distance_mm": sp["focus_distance_mm"]}
    if tilted:
        props["focus_plane_normal"] = mi.ScalarVector3f(*sp["focus_plane_normal"])
    return props


def energy_in_brightest_pixel(img, uv):
    out = []
    for u, v in uv:
        i, j = int(v), int(u)
        win = img[max(i - 4, 0):i + 5, max(j - 4, 0):j + 5]
        out.append(win.max() / win.sum())
    return np.array(out)


def test_scheimpflug_helper():
    sp = scheimpflug(ROT, POS, focal_length_mm=50.0, plane_point_mm=(0, 0, 0), plane_normal=(0, 0, 1))
    assert sp["focus_distance_mm"] == pytest.approx(400.0)
    assert sp["object_tilt_deg"] == pytest.approx(45.0)
    assert sp["magnification"] == pytest.approx(50.0 / 350.0)
    assert sp["sensor_tilt_deg"] == pytest.approx(np.degrees(np.arctan(50.0 / 350.0)))  # tan(beta) = M tan(45)
    with pytest.raises(ConfigError, match="parallel"):
        scheimpflug(ROT, POS, focal_length_mm=50.0, plane_point_mm=(0, 0, 0), plane_normal=np.cross(ROT[2], ROT[0]))


def test_tilted_plane_of_focus_keeps_the_sheet_sharp(tmp_path):
    uv = CAM.project(PTS)
    sharp = render_sensor(sc := scene(tmp_path, PTS, cam=CAM, sensor_props=lens(True), sheet=SHEET,
                                      integrator={"type": "particle_tracer", "rays_per_particle": 256}), sc.sensors()[0])
    blurred = render_sensor(sc := scene(tmp_path, PTS, cam=CAM, sensor_props=lens(False), sheet=SHEET,
                                        integrator={"type": "particle_tracer", "rays_per_particle": 256}), sc.sensors()[0])
    assert np.all(energy_in_brightest_pixel(sharp, uv) > IN_FOCUS_PIXEL_FRACTION)
    # Without the tilt, particles 2-4 mm off the axis are 1.4-2.8 mm out of focus: blur of a few px.
    far = np.abs(PTS[:, 0]) > 2.0
    assert np.all(energy_in_brightest_pixel(blurred, uv)[far] < 0.7)
    # Same light either way (the Jacobian moves it, it does not create it).
    np.testing.assert_allclose(window_stats(sharp, uv, 6)[:, 0], window_stats(blurred, uv, 6)[:, 0], rtol=SAME_LIGHT_RTOL)


def test_tilted_focus_camera_and_particle_tracing_agree(tmp_path):
    uv = CAM.project(PTS)
    pt = render_sensor(sc := scene(tmp_path, PTS, cam=CAM, sensor_props=lens(True), sheet=SHEET), sc.sensors()[0])
    ref = window_stats(pt, uv, 4)[:, 0]
    sc = scene(tmp_path, PTS, cam=CAM, sensor_props=lens(True), sheet=SHEET, integrator={"type": "direct"}, proxy=0.05)
    ratios = np.array([window_stats(render_sensor(sc, sc.sensors()[0], spp=2048, seed=s), uv, 4)[:, 0] / ref for s in range(4)])
    # Pooled over 10 particles x 4 seeds; the per-particle spread gives the standard error.
    se = ratios.std(ddof=1) / np.sqrt(ratios.size)
    assert abs(ratios.mean() - 1.0) < max(N_SIGMA * se, TRACING_RATIO_FLOOR)


def test_bad_focus_plane(tmp_path):
    with pytest.raises(ConfigError, match="thin lens"):
        scene(tmp_path, PTS, cam=CAM, sensor_props={"focus_plane_normal": mi.ScalarVector3f(0, 0, 1)})
    side = mi.ScalarVector3f(*np.cross(ROT[2], ROT[0]).tolist())  # contains the optical axis
    with pytest.raises(ConfigError, match="containing the optical axis"):
        scene(tmp_path, PTS, cam=CAM, sensor_props={**lens(False), "focus_plane_normal": side})


def test_arrangements():
    for kind, lo, hi in (("forward", 0, 90), ("backward", 90, 180)):
        cams = scatter_arrangement(kind, n=4, azimuth_deg=30, elevation_deg=20, distance_mm=600)
        angles = [c["scattering_angle_deg"] for c in cams]
        expected = np.degrees(np.arccos(np.cos(np.radians(20)) * np.cos(np.radians(30))))
        assert all(lo < a < hi for a in angles)
        np.testing.assert_allclose(angles, expected if kind == "forward" else 180 - expected, atol=1e-9)
    sym = scatter_arrangement("symmetric", n=4, azimuth_deg=25, elevation_deg=55, distance_mm=1000)
    assert [round(c["azimuth_deg"]) for c in sym] == [25, -25, 155, -155]  # scenes/tomo4's pyramid
    ring = ring_arrangement(6, distance_mm=500, elevation_deg=30)
    for c in ring:
        assert np.linalg.norm(c["position_mm"]) == pytest.approx(500)
        assert c["position_mm"][2] == pytest.approx(500 * np.sin(np.radians(30)))
        # aimed at the target: the optical axis (row 2 of R) points from the camera to the origin
        np.testing.assert_allclose(c["rotation"][2], -c["position_mm"] / 500, atol=1e-12)
    arr = planar_array(5, 5, spacing_mm=153.0, distance_mm=1000.0)
    pos = np.array([c["position_mm"] for c in arr])
    np.testing.assert_allclose(pos[:, 2], 1000.0)
    np.testing.assert_allclose(np.unique(np.round(pos[:, 0], 6)), 153.0 * np.arange(-2, 3))
    for c in arr:
        np.testing.assert_allclose(c["rotation"][2], -c["position_mm"] / np.linalg.norm(c["position_mm"]), atol=1e-12)
    with pytest.raises(ConfigError, match="'n' must be 2 or 4"):
        scatter_arrangement("forward", n=3, distance_mm=500)
    with pytest.raises(ConfigError, match="kind"):
        scatter_arrangement("sideways", distance_mm=500)


def test_tilted_focus_jacobian_matches_finite_differences(tmp_path):
    # The importance Jacobian |d(x, y)/d(xi, eta)| averages to ~1 over a symmetric aperture
    # (first-order terms cancel), so images cannot test it: check it per ray.
    sc = scene(tmp_path, PTS, cam=CAM, sensor_props=lens(True), sheet=SHEET)
    s = sc.sensors()[0]
    rng = np.random.default_rng(2)
    ax, ay = rng.uniform(-10, 10, (2, 50))
    xi, eta = rng.uniform(-0.05, 0.05, (2, 50))

    def image(xi_, eta_):
        a = mi.Point3f(mi.Float(ax), mi.Float(ay), mi.Float(0.0))
        x, y, jac = s._tilted_focus(a, mi.Vector3f(mi.Float(xi_), mi.Float(eta_), mi.Float(1.0)))
        return np.array(x, dtype=float), np.array(y, dtype=float), np.array(jac, dtype=float)

    h = 1e-3
    x1, y1, _ = image(xi + h, eta)
    x0, y0, _ = image(xi - h, eta)
    x3, y3, _ = image(xi, eta + h)
    x2, y2, _ = image(xi, eta - h)
    fd = np.abs((x1 - x0) * (y3 - y2) - (x3 - x2) * (y1 - y0)) / (2 * h) ** 2
    _, _, jac = image(xi, eta)
    np.testing.assert_allclose(jac, fd, rtol=JACOBIAN_FD_RTOL)
    assert np.ptp(jac) > 0.01  # it is not trivially 1
