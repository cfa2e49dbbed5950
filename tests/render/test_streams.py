"""Render seeds and spp: each sensor and frame of render_scene gets its own derived seed (in
its metadata), a subset of sensors renders the same images, and the particle tracer honours
spp (independent passes: the Monte Carlo variance falls as 1 / spp) and records what it used.
"""

import mitsuba as mi
import numpy as np
import pytest

from mitpiv import streams
from mitpiv.io import read_exr, write_particles_ply
from mitpiv.render.render import render_scene
from mitpiv.render.scene import load_scene

from .helpers import camera, particle_scene_xml, render, scene, sensor_xml

THIN_LENS = '<float name="f_number" value="2"/><float name="focus_distance_mm" value="560"/>'
# Monte Carlo checks: N_SIGMA standard errors (two-sided p 5.7e-7 for a normal statistic).
N_SIGMA = 5


def _xml(tmp_path, lens=THIN_LENS):
    rng = np.random.default_rng(8)
    for k in (0, 1):
        write_particles_ply(tmp_path / f"particles_{k}.ply", rng.uniform(-1.5, 1.5, (40, 3)), 1.5, proxy_radius_mm=0.01)
    sensors = "".join(sensor_xml(s, az, lens=lens) for s, az in (("camA", 30), ("camB", -40)))
    xml = particle_scene_xml(sensors, integrator='<integrator type="particle_tracer"><integer '
                                               'name="rays_per_particle" value="8"/></integrator>')
    path = tmp_path / "scene.xml"
    path.write_text(xml)
    return path


def test_each_sensor_and_frame_renders_with_its_own_seed(tmp_path):
    xml = _xml(tmp_path)
    files = render_scene(xml, out_dir=tmp_path / "all", frames=(0, 1), seed=11, progress=False)
    metas = {(m["sensor_id"], m["frame"]): (img, m) for img, m in map(read_exr, files)}
    seeds = {k: m["render_seed"] for k, (_, m) in metas.items()}
    assert len(set(seeds.values())) == 4  # two sensors x two frames
    for (sid, f), (img, m) in metas.items():
        assert m["seed"] == 11 and m["render_seed"] == streams.render_seed(11, sid, f)
        # the image is the scene rendered with that derived seed
        sc = load_scene(xml, frame=f)
        k = [s.id() for s in sc.sensors()].index(sid)
        np.testing.assert_array_equal(img, np.array(mi.render(sc, sensor=k, seed=m["render_seed"]))[..., 0])
    # a thin lens draws aperture samples: the two seeds give different noise
    a = metas[("camA", 0)][0]
    sc = load_scene(xml, frame=0)
    assert not np.array_equal(a, np.array(mi.render(sc, sensor=0, seed=11))[..., 0])
    # rendering one sensor alone gives the same image as in the full render
    (only,) = render_scene(xml, out_dir=tmp_path / "one", frames=(0,), seed=11, progress=False, sensors=["camB"])
    np.testing.assert_array_equal(read_exr(only)[0], metas[("camB", 0)][0])


def test_spp_is_recorded_as_used(tmp_path):
    xml = _xml(tmp_path)
    (f,) = render_scene(xml, out_dir=tmp_path / "a", frames=(0,), seed=1, spp=4, sensors=["camA"], progress=False)
    m = read_exr(f)[1]
    assert m["spp"] == 4 and m["spp_requested"] == 4
    assert m["integrator"]["passes"] == 4 and m["integrator"]["rays_per_particle"] == 8
    assert m["integrator"]["samples_per_particle"] == 32
    (f,) = render_scene(xml, out_dir=tmp_path / "b", frames=(0,), seed=1, sensors=["camA"], progress=False)
    m = read_exr(f)[1]
    assert m["spp"] == 1 and m["spp_requested"] is None and m["integrator"]["samples_per_particle"] == 8
    # a pinhole has one direction to each particle: one exact pass whatever spp asks
    (tmp_path / "p").mkdir()
    xml = _xml(tmp_path / "p", lens="")
    (f,) = render_scene(xml, out_dir=tmp_path / "c", frames=(0,), seed=1, spp=4, sensors=["camA"], progress=False)
    m = read_exr(f)[1]
    assert m["spp"] == 1 and m["spp_requested"] == 4 and m["integrator"]["samples_per_particle"] == 1
    assert m["integrator"]["rays_per_particle_setting"] == 8


def test_particle_tracer_noise_falls_as_one_over_spp(tmp_path):
    rng = np.random.default_rng(3)
    pts = np.column_stack([rng.uniform(-2.0, 2.0, (300, 2)), rng.uniform(-1.0, 1.0, 300)])
    # f/4 focused at 490 mm, particles at ~500 mm: ~9 px defocus disks on a 96 px film
    sc = scene(tmp_path, pts, cam=camera(res=(96, 96)), sensor_props={"f_number": 4.0, "focus_distance_mm": 490.0},
               integrator={"type": "particle_tracer", "rays_per_particle": 16})
    d2 = {}
    for spp in (1, 16):
        d = render(sc, spp=spp, seed=5) - render(sc, spp=spp, seed=6)  # two independent estimates
        d2[spp] = (d**2).ravel()
        assert sc.integrator().last_stats["passes"] == spp
    # E[sum d^2] is proportional to 1 / (rays_per_particle * spp): the ratio is 16. Tolerance:
    # 5 standard errors of the ratio, from the per-pixel spread of d^2 (relative errors of the
    # two sums in quadrature).
    rel = [np.sqrt(v.size) * v.std() / v.sum() for v in d2.values()]
    ratio = d2[1].sum() / d2[16].sum()
    assert ratio == pytest.approx(16.0, rel=N_SIGMA * np.hypot(*rel)), (ratio, rel)
    # unbiased: the image totals at spp 1 and 16 agree within 5 standard errors; the variance
    # of a total is at most the sum of the pixel variances (ray counts in different pixels are
    # negatively correlated), and a pixel's variance is E[d^2] / 2.
    tot = [render(sc, spp=s, seed=7).sum() for s in (1, 16)]
    assert abs(tot[0] - tot[1]) < N_SIGMA * np.sqrt((d2[1].sum() + d2[16].sum()) / 2)


@pytest.mark.parametrize("batch_rays", [1024, 2048, 3000])
def test_batched_tracing_gives_the_same_image(tmp_path, batch_rays):
    """batch_rays only bounds memory: the rays keep their random sequences and their splats
    are summed in the same order and vector packets, so the image is bit-identical to one
    batch. 60 particles x 100 rays: every batch boundary falls inside a particle's rays;
    3000 is rounded down to 2048; two passes check the pass offset of the sequences."""
    rng = np.random.default_rng(4)
    pts = np.column_stack([rng.uniform(-2.0, 2.0, (60, 2)), rng.uniform(-1.0, 1.0, 60)])
    props = {"f_number": 4.0, "focus_distance_mm": 490.0}
    one = scene(tmp_path, pts, name="one.ply", cam=camera(res=(48, 48)), sensor_props=props,
                integrator={"type": "particle_tracer", "rays_per_particle": 100})
    many = scene(tmp_path, pts, name="many.ply", cam=camera(res=(48, 48)), sensor_props=props,
                 integrator={"type": "particle_tracer", "rays_per_particle": 100, "batch_rays": batch_rays})
    ref = render(one, spp=2, seed=3)
    img = render(many, spp=2, seed=3)
    assert one.integrator().last_stats["batches"] == 2
    assert many.integrator().last_stats["batches"] == 2 * -(-6000 // (batch_rays // 1024 * 1024))
    assert ref.max() > 0
    np.testing.assert_array_equal(img, ref)


def test_batched_sequences_match_the_flat_ray_index():
    from mitpiv.render.plugins.particle_tracer import batches

    for n, rays, batch in ((5, 3, 4), (3, 10, 4), (4, 4, 100), (1, 1, 1), (2, 2**31, 2**24)):
        got = list(batches(n, rays, batch))
        assert sum(c for *_, c in got) == n * rays
        start = 0
        for p0, r0, c in got:  # contiguous, in order, each at most batch rays
            assert p0 * rays + r0 == start and 0 <= r0 < rays and 0 < c <= batch
            start += c


def test_batch_rays_must_be_positive(tmp_path):
    from mitpiv.errors import ConfigError

    with pytest.raises(ConfigError, match="batch_rays"):
        scene(tmp_path, np.zeros((1, 3)), cam=camera(res=(8, 8)),
              integrator={"type": "particle_tracer", "batch_rays": 1000})
