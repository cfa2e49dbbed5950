"""Rendering with mitpiv's plugins: both transport strategies, the ideal-model equality,
proxy independence, float32 precision, the laser sheet on surfaces, variants, bad input.

Independent references: the float64 camera model (mitpiv.physics.camera, checked against
its own closed forms), the closed-form intensity I = E C_sca / (4 pi) of an isotropic
particle, and Mitsuba's own `perspective` sensor.
"""

import math

import mitsuba as mi
import numpy as np
import pytest

import mitpiv
from mitpiv.errors import ConfigError
from mitpiv.physics.sheet import sheet_profile

from .helpers import camera, render, scene, window_stats

RNG = np.random.default_rng(11)
PTS = np.column_stack([RNG.uniform(-1.0, 1.0, (12, 2)), RNG.uniform(-1.5, 1.5, 12)])  # inside the 2.8 mm field
N_SEEDS = 10  # independent camera-tracing renders: their spread gives the standard error
# |difference| / standard error, Student t with N_SEEDS-1 dof, family-wise alpha 1e-3 over 12 particles
Z_MAX = float(__import__("scipy.stats").stats.t.ppf(1 - 1e-3 / 24, N_SEEDS - 1))
# Particle tracing (deterministic for a pinhole) against the closed form I f_px^2 / (d^2 cos^3):
# float32 kernels. With a box filter each particle's centroid is its pixel's centre.
CLOSED_FORM_RTOL = 2e-4
BOX_CENTROID_ATOL_PX = 1e-6
# The distorted_pinhole with every effect off against Mitsuba's own perspective sensor, same
# samples (spp 64, seed 3): two float32 ray generators, different operation order.
PERSPECTIVE_RTOL = 1e-3
PERSPECTIVE_ATOL_OF_PEAK = 1e-6
CENTROID_TOL_PX = 0.05  # a 2 um particle 500 mm away against the float64 projection (docstring)
# A diffuse wall lit by the sheet, L = rho / pi E(z): pixel-averaged against point-sampled
# profile, curvature error < 2 % for 1.8 mm pixels against the 10 mm FWHM.
WALL_PROFILE_RTOL = 0.02


def analytic_totals(cam, pts, d_um=2.0, thickness=4.0, q=2.0):
    """Sum of pixel values of each particle: I f_px^2 |det J| / (d^2 cos^3) (ideal pinhole)."""
    e = sheet_profile(pts[:, 2] - (cam.position_mm[2] - 500), thickness)
    intensity = e * q * math.pi / 4 * (d_um * 1e-3) ** 2 / (4 * math.pi)
    rel = pts - cam.position_mm
    dist = np.linalg.norm(rel, axis=1)
    cos = np.abs(cam.world_to_camera(pts)[:, 2]) / dist
    return intensity * cam.focal_px**2 / (dist**2 * cos**3)


def test_particle_tracer_matches_closed_form(tmp_path):
    cam = camera()
    sc = scene(tmp_path, PTS, cam=cam)
    stats = window_stats(render(sc), cam.project(PTS), half=2)
    np.testing.assert_allclose(stats[:, 0], analytic_totals(cam, PTS), rtol=CLOSED_FORM_RTOL)
    # box filter: each particle lands in the pixel that contains its projection
    np.testing.assert_allclose(stats[:, 1:], np.floor(cam.project(PTS)) + 0.5, atol=BOX_CENTROID_ATOL_PX)


def test_effects_off_equals_mitsuba_perspective(tmp_path):
    ours = render(scene(tmp_path, PTS, integrator={"type": "direct"}), spp=64, seed=3)
    ref = render(scene(tmp_path, PTS, sensor="perspective", integrator={"type": "direct"}), spp=64, seed=3)
    assert ref.max() > 0
    np.testing.assert_allclose(ours, ref, rtol=PERSPECTIVE_RTOL, atol=PERSPECTIVE_ATOL_OF_PEAK * ref.max())


@pytest.mark.parametrize(
    "props",
    [{}, {"distortion_percent": 2.0, "p1": 1e-3}, {"f_number": 4.0, "focus_distance_mm": 500.0}],
    ids=["pinhole", "distorted", "thin_lens"],
)
def test_camera_and_particle_tracing_agree(tmp_path, props):
    cam = camera()
    pts = PTS.copy()
    ct = [render(scene(tmp_path, pts, sensor_props=props, integrator={"type": "direct"}), spp=512, seed=s) for s in range(N_SEEDS)]
    pt = render(scene(tmp_path, pts, sensor_props=props, integrator={"type": "particle_tracer", "rays_per_particle": 4096}))
    sc = scene(tmp_path, pts, sensor_props=props)
    uv = np.array([sc.sensors()[0].camera.project(p[None])[0] for p in pts]) if props else cam.project(pts)
    half = 5
    ct_sums = np.array([window_stats(c, uv, half)[:, 0] for c in ct])
    pt_sums = window_stats(pt, uv, half)[:, 0]
    mean, se = ct_sums.mean(0), ct_sums.std(0, ddof=1) / np.sqrt(len(ct))
    z = np.abs(mean - pt_sums) / se
    assert z.max() < Z_MAX, (mean, pt_sums, se)
    # whole images: same total power within the standard error
    totals = np.array([c.sum() for c in ct])
    assert abs(totals.mean() - pt.sum()) < Z_MAX * totals.std(ddof=1) / np.sqrt(len(totals))


def test_image_does_not_depend_on_proxy_radius(tmp_path):
    """Camera tracing with a 5x larger proxy gives the same particle totals, and both match
    the closed form. The hit count per particle is binomial with about the same relative
    spread for every particle, so the relative variance is pooled over the 12 particles
    (108 degrees of freedom): a per-particle estimate from 10 renders is itself too noisy.
    """
    cam = camera()
    uv = cam.project(PTS)
    ref = analytic_totals(cam, PTS)
    res = {}
    for proxy in (0.004, 0.02):
        imgs = [render(scene(tmp_path, PTS, proxy=proxy, integrator={"type": "direct"}, name=f"p{proxy}.ply"), spp=512, seed=s)
                for s in range(N_SEEDS)]
        rel = np.array([window_stats(i, uv, 3)[:, 0] for i in imgs]) / ref
        res[proxy] = (rel.mean(0), np.sqrt(rel.var(0, ddof=1).mean() / N_SEEDS))
    z_max = float(__import__("scipy.stats").stats.t.ppf(1 - 1e-3 / 24, len(PTS) * (N_SEEDS - 1)))
    (m1, s1), (m2, s2) = res[0.004], res[0.02]
    assert 0.01 < s2 < s1 < 0.2  # the smaller proxy is hit less often: noisier, but informative
    assert (np.abs(m1 - m2) / np.hypot(s1, s2)).max() < z_max
    for m, s in res.values():
        assert (np.abs(m - 1) / s).max() < z_max
        assert abs(m.mean() - 1) < z_max * s / np.sqrt(len(PTS))  # all particles together: ~2 % resolution


@pytest.mark.parametrize("offset", [(0.0, 0.0, 0.0), (7000.0, -5000.0, 5000.0)], ids=["origin", "10m_offset"])
@pytest.mark.parametrize("integrator", ["particle_tracer", "direct"])
def test_single_particle_centroid_precision(tmp_path, offset, integrator):
    """A 2 um particle 500 mm away: centroid within 0.05 px of the float64 projection."""
    cam = camera(res=(32, 32), offset=offset)
    p = np.array([[0.137, -0.089, 0.0]]) + offset
    sc = scene(tmp_path, p, cam=cam, integrator={"type": integrator}, rfilter={"type": "gaussian", "stddev": 0.7})
    img = render(sc, spp=4096 if integrator == "direct" else 1)
    uv = cam.project(p)
    stats = window_stats(img, uv, half=5)
    assert np.hypot(*(stats[0, 1:] - uv[0])) < CENTROID_TOL_PX


def test_occlusion(tmp_path):
    cam = camera()
    near, far = np.array([0.3, 0.2, 1.0]), None
    far = cam.position_mm + (near - cam.position_mm) * 1.002  # same line of sight, 1 mm behind
    both = np.array([near, far])
    on = render(scene(tmp_path, both, proxy=0.01, integrator={"type": "particle_tracer", "occlusion": True}))
    off = render(scene(tmp_path, both, proxy=0.01, integrator={"type": "particle_tracer", "occlusion": False}))
    single = render(scene(tmp_path, near[None], proxy=0.01, integrator={"type": "particle_tracer", "occlusion": True}))
    np.testing.assert_allclose(on, single, rtol=1e-6)  # the far one is hidden, the near one not by itself
    assert off.sum() > 1.5 * on.sum()


def test_laser_sheet_lights_a_surface(tmp_path):
    """A diffuse wall facing the laser: L = rho / pi * E(z), with the Gaussian sheet profile."""
    res = (16, 64)
    from mitpiv.physics.camera import PinholeCamera, look_at_rotation
    from mitpiv.render.scene import load_dict

    pos = np.array([-300.0, 0.0, 0.0])
    cam = PinholeCamera(res, 50.0, 40.0, rotation=look_at_rotation(pos, [0, 0, 0], up=[0, 0, 1]), position_mm=pos)
    wall = mi.ScalarTransform4f().rotate([0, 1, 0], -90).scale([100, 100, 1])  # plane x = 0, normal -x
    sc = load_dict({
        "type": "scene", "integrator": {"type": "direct"},
        "sensor": {"type": "distorted_pinhole", "to_world": mi.ScalarTransform4f(cam.to_world_mitsuba()),
                   "focal_length_mm": 50.0, "pixel_pitch_um": 40.0,
                   "film": {"type": "hdrfilm", "width": res[0], "height": res[1], "pixel_format": "luminance",
                            "rfilter": {"type": "box"}}},
        "laser": {"type": "laser_sheet", "thickness": 10.0, "irradiance": 2.0},
        "wall": {"type": "rectangle", "to_world": wall, "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.5}}},
    })
    img = render(sc, spp=64)
    v = np.arange(res[1]) + 0.5
    _, d = cam.pixel_to_ray(np.column_stack([np.full_like(v, res[0] / 2), v]))
    z = (pos + d * (-pos[0] / d[:, 0])[:, None])[:, 2]
    expect = 0.5 / math.pi * 2.0 * sheet_profile(z, 10.0)
    col = img[:, res[0] // 2]
    big = expect > 0.05 * expect.max()
    np.testing.assert_allclose(col[big], expect[big], rtol=WALL_PROFILE_RTOL)


def test_variant_switch_reregisters_and_renders(tmp_path):
    import mitpiv.render.plugins.distorted_pinhole as dp

    before = dp.DistortedPinhole
    mi.set_variant("llvm_ad_rgb")
    dp._VARIANT = "stale"  # pretend the classes were built for another variant
    assert mitpiv.set_variant("llvm_ad_mono") == "llvm_ad_mono"
    import mitpiv.render.plugins.distorted_pinhole as dp2

    assert dp2.DistortedPinhole is not before and dp2._VARIANT == "llvm_ad_mono"
    img = render(scene(tmp_path, PTS))
    assert img.sum() > 0
    with pytest.raises(ConfigError, match="not supported"):
        mitpiv.set_variant("scalar_rgb")


@pytest.mark.parametrize(
    "where, props, match",
    [
        ("sensor", {"focal_length_mm": -85.0}, "focal_length_mm"),
        ("sensor", {"pixel_pitch_um": 0.0}, "pixel_pitch_um"),
        ("sensor", {"f_number": -2.0, "focus_distance_mm": 500.0}, "f_number"),
        ("sensor", {"k1": -1e5}, "folds over"),
        ("sensor", {"focal_lenght_mm": 85.0}, "unknown parameter.*focal_lenght_mm"),
        ("laser", {"thickness": 0.0}, "thickness"),
        ("laser", {"profile": "gauss"}, "profile"),
        ("laser", {"colour": "green"}, "unknown parameter.*colour"),
    ],
)
def test_bad_plugin_parameters(tmp_path, where, props, match):
    with pytest.raises(ConfigError, match=match):
        scene(tmp_path, PTS, sensor_props=props if where == "sensor" else None, sheet=props if where == "laser" else None)
