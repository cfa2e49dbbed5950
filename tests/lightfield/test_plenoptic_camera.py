"""The ``plenoptic`` sensor: ray geometry against an independent float64 ray-transfer-matrix
model, power conservation against the closed-form aperture solid angle, camera vs particle
tracing, crosstalk, presets, metadata and bad input."""

import math

import mitsuba as mi
import numpy as np
import pytest
import scipy.stats

from mitpiv.errors import ConfigError
from mitpiv.physics.plenoptic import PRESETS, PlenopticCamera, preset

from .helpers import BASE, DIST, intensity, particle_scene, render, sensor

# Tolerances and their provenance.
# The sensor's rays against float64 ray-transfer matrices (rtm_trace): the kernel runs in
# float32 (eps 6e-8) over distances up to s_i = 62.5 mm, ~4e-6 mm = 7e-4 of a 5.5 um pixel.
RTM_ATOL_PX = 1e-3
# Power on the sensor against the closed-form aperture solid angle 2 pi (1 - z / sqrt(z^2 + R^2)):
# Monte Carlo over the aperture (200000 rays per particle) and float32.
POWER_REL_TOL = 2e-4
# Camera vs particle tracing, whole images: N_SIGMA standard errors of the mean of 8 seeds.
N_SIGMA = 5
# Rect cells with matched f-numbers: the inscribed aperture disk covers pi/4 of a cell, so the
# vignetted fraction is about 1 - pi/4 = 0.21 (bounds round it).
VIGNETTED_FRACTION_RANGE = (0.15, 0.3)
ON_AXIS_IRRADIANCE_RTOL = 0.02  # E = L A_cell / g^2 = 1 / N_mla^2 on the axis (16 spp of a white scene)


def rtm_trace(p_mm, t_s, c_mm, g, fm, si, f):
    """Float64 ray-transfer matrices in tangent space (x, t): free space [[1, d], [0, 1]],
    thin lens [[1, 0], [-1/f, 1]], off-axis lenslet = lens + prism (t += c / f_m)."""
    free = lambda d: np.array([[1.0, d], [0.0, 1.0]])  # noqa: E731
    lens = lambda fl: np.array([[1.0, 0.0], [-1.0 / fl, 1.0]])  # noqa: E731
    out = []
    for axis in range(2):
        s = np.stack([p_mm[:, axis], t_s[:, axis]])
        at_mla = free(g) @ s
        after = lens(fm) @ at_mla
        after[1] += c_mm[:, axis] / fm  # prism of the off-axis lenslet
        at_lens = free(si) @ after
        obj = lens(f) @ at_lens
        out.append((at_mla[0], at_lens[0], obj[1]))
    return [np.column_stack([o[k] for o in out]) for k in range(3)]


@pytest.mark.parametrize("props", [{}, {"mla_layout": "hex", "mla_rotation_deg": 3.0, "mla_offset_x_um": 9.0},
                                   {"mla_gap_um": 150.0, "mla_pitch_um": 50.0}], ids=["rect", "hex_rotated", "gap_pmr9.1"])
def test_rays_match_float64_ray_transfer_matrices(props):
    sens = mi.load_dict(sensor(200, **props))
    cam = sens.camera
    rng = np.random.default_rng(3)
    n = 4000
    uv = rng.uniform(20, 180, (n, 2)).astype(np.float32).astype(np.float64)  # the kernel's own inputs
    sm = rng.uniform(0, 1, (n, 2))
    r = sens.trace_camera(uv, sm, rng.uniform(0, 1, n))
    pp = cam.pixel_pitch_um * 1e-3
    p_mm = cam.px_to_sensor_mm(uv)
    m = np.column_stack([r["mx"], r["my"]]).astype(np.float64)
    c = cam.origin_mm + r["i"][:, None] * cam.basis_mm[0] + r["j"][:, None] * cam.basis_mm[1]
    g, fm = cam.gap_mm, cam.mla_focal_length_um * 1e-3
    at_mla, at_lens, t_obj = rtm_trace(p_mm, (m - p_mm) / g, c, g, fm, cam.image_distance_mm, cam.focal_length_mm)
    np.testing.assert_allclose(np.column_stack([r["px"], r["py"]]) / pp, p_mm / pp, atol=RTM_ATOL_PX)
    np.testing.assert_allclose(m / pp, at_mla / pp, atol=RTM_ATOL_PX)
    # Lens plane and object side: the rays that pass the aperture (the vignetted ones carry
    # no light); positions in sensor-pixel units, tangents as the shift they make over s_i.
    ins = r["inside"]
    assert ins.mean() > 0.5
    np.testing.assert_allclose(np.column_stack([r["lx"], r["ly"]])[ins] / pp, at_lens[ins] / pp, atol=RTM_ATOL_PX)
    np.testing.assert_allclose(np.column_stack([r["t3x"], r["t3y"]])[ins] * cam.image_distance_mm / pp,
                               t_obj[ins] * cam.image_distance_mm / pp, atol=RTM_ATOL_PX)
    # the chosen lenslet's cell holds m (nearest lattice point), and vignetting follows the aperture
    d_all = np.linalg.norm(cam.lenslet_centres_mm().reshape(-1, 2)[None] - m[:, None], axis=2)
    assert np.allclose(d_all.min(1)[r["valid"]], np.linalg.norm(m - c, axis=1)[r["valid"]], atol=1e-6)
    assert np.array_equal(r["inside"], np.hypot(*at_lens.T) <= cam.aperture_radius_mm + 1e-9) or \
        np.mean(r["inside"] != (np.hypot(*at_lens.T) <= cam.aperture_radius_mm)) < 1e-3

    # particle path, object side first: ray X -> aperture point a, then (reversed) main lens,
    # free space to the MLA, the lenslet (lens + prism), free space to the sensor
    pts = np.column_stack([rng.uniform(-2, 2, (n, 2)), rng.uniform(-20, 20, n)])
    q = sens.trace_particles(pts, rng.uniform(0, 1, (n, 2)))
    ok = q["valid"]
    assert ok.mean() > 0.5
    a = np.column_stack([q["ax"], q["ay"]]).astype(np.float64)[ok]
    loc = cam.world_to_local(pts[ok])
    si, f = cam.image_distance_mm, cam.focal_length_mm
    back = lambda d: np.array([[1.0, -d], [0.0, 1.0]])  # noqa: E731  (propagation towards -z)
    unlens = lambda fl: np.array([[1.0, 0.0], [1.0 / fl, 1.0]])  # noqa: E731
    cc = cam.origin_mm + q["i"][ok, None] * cam.basis_mm[0] + q["j"][ok, None] * cam.basis_mm[1]
    m_ref, p_ref = [], []
    for axis in range(2):
        st = unlens(f) @ np.stack([a[:, axis], (loc[:, axis] - a[:, axis]) / loc[:, 2]])
        at_mla = back(si) @ st
        m_ref.append(at_mla[0])
        after = at_mla.copy()
        after[1] += (at_mla[0] - cc[:, axis]) / fm  # inverse of the lenslet (lens + prism)
        p_ref.append((back(g) @ after)[0])
    np.testing.assert_allclose(np.column_stack([q["mx"], q["my"]])[ok] / pp, np.column_stack(m_ref) / pp, atol=RTM_ATOL_PX)
    np.testing.assert_allclose(np.column_stack([q["px"], q["py"]])[ok] / pp, np.column_stack(p_ref) / pp, atol=RTM_ATOL_PX)


def test_particle_tracing_conserves_power(tmp_path):
    """An on-axis point of intensity I puts I * 2 pi (1 - z / sqrt(z^2 + R^2)) on the sensor."""
    for z in (0.0, 12.0):
        pts = np.array([[0.0, 0.0, -z]])
        img = render(particle_scene(tmp_path, pts, {"type": "particle_tracer", "rays_per_particle": 200_000}))
        dist = DIST + z
        r_ap = BASE["focal_length_mm"] / BASE["f_number"] / 2
        power = intensity(pts)[0] * 2 * math.pi * (1 - dist / math.hypot(dist, r_ap))
        assert img.sum() * (5.5e-3) ** 2 == pytest.approx(power, rel=POWER_REL_TOL)


@pytest.mark.parametrize("props", [{}, {"mla_layout": "hex"}, {"f_number": 1.6}],
                         ids=["rect", "hex", "crosstalk_f1.6"])
def test_camera_and_particle_tracing_agree(tmp_path, props):
    """Block sums (10x10 px) of camera-traced renders (8 seeds) against particle tracing:
    Student t, family-wise alpha 1e-3."""
    # (off the lenslet boundaries: the camera-traced 0.01 mm proxy would straddle two cells)
    pts = np.array([[0.061, 0.037, 0.0], [0.5, -0.3, -8.0], [-0.6, 0.4, 10.0]])
    pt = render(particle_scene(tmp_path, pts, {"type": "particle_tracer", "rays_per_particle": 400_000}, **props))
    seeds = 8
    ct = np.array([render(particle_scene(tmp_path, pts, {"type": "direct"}, **props), spp=128, seed=s) for s in range(seeds)])
    blocks = lambda a: a.reshape(*a.shape[:-2], 20, 10, 20, 10).sum(axis=(-1, -3))  # noqa: E731
    b_ct, b_pt = blocks(ct), blocks(pt)
    lit = b_pt > 0.02 * b_pt.max()
    assert lit.sum() >= 10
    se = b_ct.std(0, ddof=1) / math.sqrt(seeds)
    z = np.abs(b_ct.mean(0) - b_pt)[lit] / np.maximum(se[lit], 1e-3 * b_pt.max())
    assert z.max() < scipy.stats.t.ppf(1 - 1e-3 / (2 * lit.sum()), seeds - 1), z.max()
    tot = ct.sum(axis=(1, 2))
    assert abs(tot.mean() - pt.sum()) < N_SIGMA * tot.std(ddof=1) / math.sqrt(seeds)
    if props.get("f_number") == 1.6:  # a faster main lens lights the neighbours' images: crosstalk is modelled
        sc = particle_scene(tmp_path, pts, {"type": "direct"}, **props)
        assert len(sc.sensors()[0].camera.crosstalk_offsets()) > 1


def test_focal_plane_particle_lights_one_lenslet(tmp_path):
    """A point on the nominal focal plane sends all its light through one lenslet; its image
    fills that lenslet's aperture image and nothing else."""
    pt = np.array([[0.021, 0.013, 0.0]])
    sc = particle_scene(tmp_path, pt, {"type": "particle_tracer", "rays_per_particle": 100_000})
    sens = sc.sensors()[0]
    cam = sens.camera
    rng = np.random.default_rng(5)
    q = sens.trace_particles(np.repeat(pt, 20_000, axis=0), rng.uniform(0, 1, (20_000, 2)))
    assert q["valid"].all()
    assert len({(int(i), int(j)) for i, j in zip(q["i"], q["j"], strict=True)}) == 1
    img = render(sc)
    yy, xx = np.indices(img.shape) + 0.5
    c = cam.sensor_mm_to_px(cam.origin_mm + q["i"][0] * cam.basis_mm[0] + q["j"][0] * cam.basis_mm[1]) * 1.0
    centre = cam.sensor_mm_to_px(cam.px_to_sensor_mm(c) * cam.image_scale)
    r_img = cam.image_region_radius_mm / (cam.pixel_pitch_um * 1e-3)
    lit = img > 0
    assert np.all(np.hypot(xx - centre[0], yy - centre[1])[lit] <= r_img + 0.75)  # + half a pixel diagonal
    assert lit.sum() > 0.6 * math.pi * (r_img - 1) ** 2  # the whole aperture image is lit


def test_vignetting_is_counted():
    from .helpers import white_scene

    sc = white_scene(100)
    sens = sc.sensors()[0]
    sens.reset_ray_stats()
    img = render(sc, spp=16)
    st = sens.ray_stats()
    assert st["rays"] == 100 * 100 * 16
    # rect cells with matched f-numbers: the inscribed aperture disk covers pi/4 of a cell
    assert VIGNETTED_FRACTION_RANGE[0] < st["vignetted_fraction"] < VIGNETTED_FRACTION_RANGE[1]
    assert img.max() == pytest.approx(1 / sens.camera.mla_f_number**2, rel=ON_AXIS_IRRADIANCE_RTOL)


def test_presets():
    lytro = preset("lytro_like")
    assert lytro.pmr == pytest.approx(10.0)
    assert lytro.mla_count == (328, 328) and lytro.mla_f_number == pytest.approx(2.0)
    for n in (800, 1600):
        for pmr in (7, 14, 28):
            cam = preset(f"lfpiv_hex_{n}_pmr{pmr}")
            assert cam.mla_layout == "hex" and cam.pmr == pytest.approx(pmr)
            assert cam.mla_f_number == pytest.approx(cam.image_f_number)  # f-number matching
            assert cam.mla_count[0] * cam.mla_pitch_um <= n * cam.pixel_pitch_um
    s = sensor(800, preset="lfpiv_hex_800_pmr14")
    for k in BASE:
        s.pop(k)
    sens = mi.load_dict(s)
    assert sens.describe()["preset"] == "lfpiv_hex_800_pmr14" and sens.camera.pmr == pytest.approx(14)


def test_metadata_round_trip():
    sens = mi.load_dict(sensor(200, mla_layout="hex", mla_rotation_deg=2.0))
    d = sens.describe()
    cam = PlenopticCamera.from_dict(d)
    np.testing.assert_allclose(cam.image_centres_px(), sens.camera.image_centres_px(), atol=1e-9)
    assert d["type"] == "plenoptic" and d["image_distance_mm"] == pytest.approx(62.5)


@pytest.mark.parametrize("props, match", [
    ({"mla_pitch_um": 0.0}, "mla_pitch_um"),
    ({"mla_pitch_um": 2000.0}, "larger than the sensor"),
    ({"mla_pitch_um": 8.0}, "at least 2 pixels"),
    ({"f_number": 0.5, "mla_focal_length_um": 192.5}, "f-number mismatch"),
    ({"focus_distance_mm": 40.0}, "focus_distance_mm"),
    ({"mla_layout": "triangle"}, "mla_layout"),
    ({"mla_count_x": 1000, "mla_count_y": 1000}, "mla_count"),
    ({"mla_count_x": 10}, "mla_count_y"),
    ({"preset": "lytro_like"}, "3280x3280"),
    ({"preset": "nope"}, "unknown preset"),
    ({"rfilter_typo": 1.0}, "unknown parameter"),
])
def test_bad_parameters(props, match):
    from mitpiv.render.scene import load_dict

    with pytest.raises(ConfigError, match=match):
        load_dict(sensor(200, **props))


def test_presets_are_complete():
    assert set(PRESETS) == ({"lytro_like", "multiplenoptic_paper", "paper003_drop_impact", "paper003_pellets"}
                            | {f"lfpiv_hex_{n}_pmr{p}" for n in (800, 1600) for p in (7, 14, 28)})
