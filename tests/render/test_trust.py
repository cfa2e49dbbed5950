"""Results a user can trust (issue 30): sensors that differ only in id both render, same-seed
renders are bit-identical, cameras and frames draw independent Monte Carlo noise, and both
transport strategies agree at the edge of a strongly distorted field of view."""

import mitsuba as mi
import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.io import read_exr, write_particles_ply
from mitpiv.render import scene as scenes
from mitpiv.render.render import render_scene
from mitpiv.render.scene import load_dict, load_scene

from .helpers import particle_scene_xml, sensor_xml

THIN_LENS = '<float name="f_number" value="2"/><float name="focus_distance_mm" value="560"/>'


def _xml(tmp_path, cams, *, n=60, res=32, lens=THIN_LENS, rfilter="box", rays=8, same_frames=False):
    rng = np.random.default_rng(8)
    pts = rng.uniform(-1.5, 1.5, (n, 3))
    for k in (0, 1):
        write_particles_ply(tmp_path / f"particles_{k}.ply", pts if same_frames else rng.uniform(-1.5, 1.5, (n, 3)),
                            1.5, proxy_radius_mm=0.01)
    sensors = "".join(sensor_xml(s, az, lens=lens, res=res, rfilter=rfilter) for s, az in cams)
    xml = particle_scene_xml(sensors, integrator=f'<integrator type="particle_tracer"><integer '
                                                 f'name="rays_per_particle" value="{rays}"/></integrator>')
    path = tmp_path / "scene.xml"
    path.write_text(xml)
    return path


# ------------------------------------------------------------------ item 6: sensors differing only in id
def test_two_sensors_differing_only_in_id_both_render(tmp_path):
    xml = _xml(tmp_path, [("camA", 30), ("camB", 30)])
    sc = load_scene(xml)
    assert [s.id() for s in sc.sensors()] == ["camA", "camB"]
    assert sc.sensors()[0] is not sc.sensors()[1]
    files = render_scene(xml, out_dir=tmp_path / "out", frames=(0,), seed=2, progress=False)
    assert sorted(p.name for p in files) == ["camA_frame000.exr", "camB_frame000.exr"]
    a, b = (read_exr(p)[0] for p in sorted(files))
    # the same view with its own stream each: equal totals within noise, different noise
    assert a.sum() > 0 and b.sum() > 0 and not np.array_equal(a, b)
    # scene dictionaries too
    s = {"type": "perspective", "fov": 30.0, "film": {"type": "hdrfilm", "width": 8, "height": 8}}
    d = load_dict({"type": "scene", "c0": {**s, "id": "c0"}, "c1": {**s, "id": "c1"}})
    assert scenes.check_sensor_ids(d) == ["c0", "c1"]


def test_sensors_merged_by_mitsuba_are_refused(tmp_path):
    xml = _xml(tmp_path, [("camA", 30), ("camB", 30)])
    merged = mi.load_file(str(xml), frame="0")  # Mitsuba's default parser merges the two
    with pytest.raises(ConfigError, match="not distinct"):
        scenes.check_sensor_ids(merged)


# ------------------------------------------------------------------ item 4: determinism and streams
# Monte Carlo checks: N_SIGMA standard errors (two-sided p 5.7e-7 for a normal statistic).
N_SIGMA = 5


def _many_particles_scene(tmp_path, rfilter):
    from .helpers import camera, scene

    rng = np.random.default_rng(3)
    pts = np.column_stack([rng.uniform(-2.0, 2.0, (2000, 2)), rng.uniform(-1.0, 1.0, 2000)])
    # 2000 particles x 16 rays = 32k lanes: several threads splat into the same pixels
    return scene(tmp_path, pts, cam=camera(res=(96, 96)), sensor_props={"f_number": 4.0, "focus_distance_mm": 490.0},
                 integrator={"type": "particle_tracer", "rays_per_particle": 16}, rfilter={"type": rfilter})


@pytest.mark.parametrize("rfilter", ["box", "gaussian"])
def test_same_seed_particle_tracing_is_bit_identical(tmp_path, rfilter):
    from .helpers import render

    sc = _many_particles_scene(tmp_path, rfilter)
    first = render(sc, spp=2, seed=5)
    assert first.sum() > 0
    for _ in range(3):
        np.testing.assert_array_equal(render(sc, spp=2, seed=5), first)
    assert not np.array_equal(render(sc, spp=2, seed=6), first)


def _r(a, b):
    """Pearson r over the pixels where either field is non-zero, and that pixel count."""
    m = (a != 0) | (b != 0)
    return float(np.corrcoef(a[m], b[m])[0, 1]), int(m.sum())


def test_cameras_and_frames_draw_uncorrelated_noise(tmp_path):
    # Two cameras with one view (they differ only in id), the same particles in frames 0 and 1:
    # the expected images are equal, so shared random streams would give equal noise (r = 1).
    # A noise field is the difference of two independent renders of one image; the sample r
    # of independent fields has standard deviation about 1/sqrt(n), n the pixels with noise
    # (neighbouring pixels share rays, so the bound uses n / 9, a 3x3 px neighbourhood).
    xml = _xml(tmp_path, [("camA", 30), ("camB", 30)], n=300, res=48, same_frames=True)
    images = {}
    for seed in (1, 2):
        for p in render_scene(xml, out_dir=tmp_path / f"s{seed}", frames=(0, 1), seed=seed, progress=False):
            img, m = read_exr(p)
            images[seed, m["sensor_id"], m["frame"]] = img.astype(np.float64)
    noise = {k: images[1, *k] - images[2, *k] for k in [("camA", 0), ("camB", 0), ("camA", 1)]}
    for a, b in [(("camA", 0), ("camB", 0)), (("camA", 0), ("camA", 1))]:
        r, n = _r(noise[a], noise[b])
        assert n > 200 and abs(r) < N_SIGMA / np.sqrt(n / 9), (a, b, r, n)
    # one seed passed to mi.render for both cameras: the particle tracer still draws each
    # camera's own samples (its stream hashes the sensor id)
    sc = load_scene(xml, frame=0)
    a, b = (np.array(mi.render(sc, sensor=i, seed=7), dtype=np.float64)[..., 0] for i in (0, 1))
    a2, b2 = (np.array(mi.render(sc, sensor=i, seed=8), dtype=np.float64)[..., 0] for i in (0, 1))
    r, n = _r(a - a2, b - b2)
    assert not np.array_equal(a, b) and abs(r) < N_SIGMA / np.sqrt(n / 9), (r, n)


def _camera_traced(rfilter):
    rng = np.random.default_rng(4)
    tex = rng.uniform(0.1, 1.0, (64, 64, 1)).astype(np.float32)
    return load_dict({
        "type": "scene", "integrator": {"type": "direct"},
        "sensor": {"type": "perspective", "fov": 40.0, "to_world": mi.ScalarTransform4f().look_at(
                   origin=[0, 0, 2.0], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 128, "height": 128, "pixel_format": "luminance",
                            "rfilter": {"type": rfilter}}},
        "card": {"type": "rectangle", "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}},
                 "emitter": {"type": "area", "radiance": {"type": "bitmap", "bitmap": mi.Bitmap(tex), "raw": True}}},
    })


def test_same_seed_camera_tracing_is_bit_identical_with_a_box_filter_and_bounded_otherwise():
    from mitpiv.render.render import filter_rounding_bound

    for rfilter, radius in (("box", 0.5), ("gaussian", 2.0)):
        sc = _camera_traced(rfilter)
        imgs = [np.array(mi.render(sc, spp=4, seed=3), dtype=np.float64)[..., 0] for _ in range(3)]
        assert imgs[0].min() > 0
        for img in imgs[1:]:
            if rfilter == "box":
                np.testing.assert_array_equal(img, imgs[0])
            else:  # the documented limit: float32 rounding of each pixel's sum and weight
                assert np.all(np.abs(img - imgs[0]) <= filter_rounding_bound(4, radius) * imgs[0])


# ------------------------------------------------------------------ item 5: distortion beyond the fold
# 14 % barrel distortion (accepted: the radial map still rises 3 % past the image corner):
# a point 2.4 corner radii out folds back to half the corner radius under the forward model.
DISTORTION = {"distortion_percent": 14.0}
N_CT_SEEDS = 6  # independent camera-tracing renders: their spread gives the standard error
# |difference| / standard error, Student t with N_CT_SEEDS-1 dof, family-wise alpha 1e-3 over 4 particles
Z_MAX = float(__import__("scipy.stats").stats.t.ppf(1 - 1e-3 / 8, N_CT_SEEDS - 1))


def _world(cam, xy_norm, depth_mm=500.0):
    """World points at ``depth_mm`` whose undistorted normalised coordinates are ``xy_norm``."""
    xy = np.asarray(xy_norm, float)
    pc = np.column_stack([xy * depth_mm, np.full(len(xy), depth_mm)])
    return cam.position_mm + pc @ cam.rotation


def test_particles_beyond_the_fold_are_seen_by_neither_strategy_nor_the_mapping(tmp_path):
    from mitpiv.physics.distortion import undistort
    from mitpiv.reconstruct.mapping import PinholeMapping

    from .helpers import render, scene

    probe = scene(tmp_path, np.zeros((1, 3)), sensor_props=DISTORTION, name="probe.ply").sensors()[0].camera
    f, (cx, cy) = probe.focal_px, probe.principal_point_px
    # inside: principal pre-images of pixels 2-4 px from the border; outside: beyond the fold
    uv_in = np.array([[3.0, 24.0], [45.2, 20.0], [24.0, 2.5], [5.0, 5.5]])
    x_in = np.column_stack(undistort((uv_in[:, 0] - cx) / f, (uv_in[:, 1] - cy) / f, probe.distortion, iterations=60))
    r_out = 2.4 * probe.corner_radius
    ang = np.radians([10.0, 100.0, 200.0, 300.0])
    x_out = r_out * np.column_stack([np.cos(ang), np.sin(ang)])
    assert r_out > 1 / np.sqrt(-3 * probe.distortion.k1)  # the radial map r (1 + k1 r^2) peaks there
    pts_in, pts_out = _world(probe, x_in), _world(probe, x_out)
    uv_out = probe.project(pts_out)
    assert np.all((uv_out > 4) & (uv_out < 44))  # the forward model lands them on the image
    np.testing.assert_allclose(probe.project(pts_in), uv_in, atol=1e-6)
    mapping = PinholeMapping(probe)
    assert mapping.visible(pts_in).all() and not mapping.visible(pts_out).any()

    pts = np.vstack([pts_in, pts_out])
    pt = render(scene(tmp_path, pts, sensor_props=DISTORTION), seed=1)
    ct = [render(scene(tmp_path, pts, sensor_props=DISTORTION, integrator={"type": "direct"}), spp=512, seed=s)
          for s in range(N_CT_SEEDS)]

    def sums(img, uv, half=2):
        yy, xx = np.mgrid[0:img.shape[0], 0:img.shape[1]] + 0.5
        return np.array([img[(np.abs(xx - u) <= half) & (np.abs(yy - v) <= half)].sum() for u, v in uv])

    assert np.all(sums(pt, uv_out) == 0)  # particle tracing: not drawn
    assert all(np.all(sums(c, uv_out) == 0) for c in ct)
    # near the edge the two strategies agree within camera tracing's standard error
    pt_sums = sums(pt, uv_in)
    ct_sums = np.array([sums(c, uv_in) for c in ct])
    mean, se = ct_sums.mean(0), ct_sums.std(0, ddof=1) / np.sqrt(N_CT_SEEDS)
    assert np.all(pt_sums > 0) and (np.abs(mean - pt_sums) / se).max() < Z_MAX, (mean, pt_sums, se)
    assert abs(np.mean([c.sum() for c in ct]) - pt.sum()) < Z_MAX * np.std([c.sum() for c in ct], ddof=1) / np.sqrt(N_CT_SEEDS)


def test_fold_radius_is_where_the_radial_map_peaks():
    from mitpiv.physics.distortion import Distortion, fold_radius

    assert fold_radius(Distortion(k1=-3.0)) == pytest.approx(1 / 3.0, rel=1e-12)  # 1 - 9 r^2 = 0
    assert fold_radius(Distortion(k1=2.0)) == float("inf") and fold_radius(Distortion()) == float("inf")
    # with k2: the smallest positive root of 1 + 3 k1 s + 5 k2 s^2, by the quadratic formula
    k1, k2 = -1.0, 0.05
    s = (-3 * k1 - np.sqrt(9 * k1**2 - 20 * k2)) / (10 * k2)
    assert fold_radius(Distortion(k1=k1, k2=k2)) == pytest.approx(np.sqrt(s), rel=1e-9)


# ------------------------------------------------------------------ item 8: black images are reported
_LOOKAT = """    <sensor type="distorted_pinhole" id="{sid}">
        <transform name="to_world"><lookat origin="{origin}" target="{target}" up="0, 0, 1"/></transform>
        <float name="focal_length_mm" value="85"/>
        <float name="pixel_pitch_um" value="20"/>
        {extra}
        <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="32"/>
            <string name="pixel_format" value="luminance"/></film>
    </sensor>
"""


@pytest.mark.parametrize("case", ["principal_point", "inside_box"])
def test_a_black_render_warns_and_says_why(tmp_path, case):
    from mitpiv.errors import MitpivWarning

    rng = np.random.default_rng(5)
    pts = np.column_stack([rng.uniform(-5, 5, (60, 2)), rng.uniform(-1.0, 1.0, 60)])
    write_particles_ply(tmp_path / "particles_0.ply", pts, 1.5, proxy_radius_mm=0.01)
    if case == "principal_point":  # looks at the particles, but the optical axis lands 500 px off the image
        sensor = _LOOKAT.format(sid="cam0", origin="0, -400, 300", target="0, 0, 0",
                                extra='<float name="principal_point_x_px" value="500"/>')
        words = "principal point"
    else:  # inside the seeding box, looking along it past every particle
        sensor = _LOOKAT.format(sid="cam0", origin="0.01, 0.02, 0.05", target="0.01, 400, 300", extra="")
        words = "inside the particles' bounding box"
    (tmp_path / "scene.xml").write_text(particle_scene_xml(sensor))
    with pytest.warns(MitpivWarning, match="rendered black") as rec:
        (path,) = render_scene(tmp_path / "scene.xml", out_dir=tmp_path / "out", frames=(0,), progress=False)
    assert words in str(rec[0].message)
    img, meta = read_exr(path)
    assert not img.any() and words in meta["warnings"][0]


def test_a_microlens_array_off_the_sensor_is_refused(tmp_path):
    """An MLA shifted beyond half the sensor put no microlens image on it (a black render);
    the plenoptic sensor now refuses the offset when the scene loads, naming it."""
    from mitpiv.errors import ConfigError

    write_particles_ply(tmp_path / "particles_0.ply", np.random.default_rng(5).uniform(-0.5, 0.5, (30, 3)), 1.5,
                        proxy_radius_mm=0.005)
    sensor = """<sensor type="plenoptic" id="plen0">
        <float name="azimuth_deg" value="0"/><float name="elevation_deg" value="75"/>
        <float name="distance_mm" value="100"/><float name="focal_length_mm" value="10"/>
        <float name="f_number" value="2"/><float name="focus_distance_mm" value="100"/>
        <float name="pixel_pitch_um" value="1.4"/><float name="mla_pitch_um" value="14"/>
        <float name="mla_focal_length_um" value="28"/><string name="mla_layout" value="rect"/>
        <integer name="mla_count_x" value="6"/><integer name="mla_count_y" value="6"/>
        <float name="mla_offset_x_um" value="500"/>
        <film type="hdrfilm"><integer name="width" value="60"/><integer name="height" value="60"/>
            <string name="pixel_format" value="luminance"/><rfilter type="box"/></film></sensor>"""
    (tmp_path / "scene.xml").write_text(particle_scene_xml(
        sensor, integrator='<integrator type="particle_tracer"><integer name="rays_per_particle" value="200"/></integrator>'))
    with pytest.raises(ConfigError, match=r"mla_offset_um.*below half the sensor"):
        render_scene(tmp_path / "scene.xml", out_dir=tmp_path / "out", frames=(0,), progress=False)
