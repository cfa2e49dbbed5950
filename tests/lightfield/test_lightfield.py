"""mitpiv.lightfield: MLA calibration against the true lattice, decoding, refocusing depth
against the theoretical depth resolution, focal-stack streaming, hard cases, CLI."""

import numpy as np
import pytest

from mitpiv import lightfield as lfm
from mitpiv.errors import CalibrationError, ConfigError
from mitpiv.io import write_exr
from mitpiv.physics.plenoptic import PlenopticCamera
from mitpiv.render.render import sensor_model

from .helpers import particle_scene, render, white_scene

CASES = {
    "rect": {},
    "hex": {"mla_layout": "hex"},
    "rect_rot_pmr9.1": {"mla_pitch_um": 50.0, "mla_rotation_deg": 2.0, "mla_offset_x_um": 13.0},
    "hex_rot_pmr9.1": {"mla_layout": "hex", "mla_pitch_um": 50.0, "mla_rotation_deg": -4.0},
}

# Tolerances and their provenance. The thin-lens closed forms written afresh in float64 agree
# to rounding (1e-12, inline); the same for round trips of refocusing and streaming.
# MLA calibration against the true lattice: a near-integer PMR (10.03) aliases the spot windows
# with the pixel grid (up to 0.12 px measured); a non-integer PMR (9.09) gives 0.015 px.
CALIBRATION_TOL_PX_NEAR_INTEGER_PMR = 0.15
CALIBRATION_TOL_PX_PMR9_1 = 0.02
CALIBRATION_ROTATION_TOL_DEG = 0.01
WHITE_RATIO_ATOL = 1e-5  # a white image decoded with itself as the white: 1 where lit (float32)
# A perspective view's depth of field is ~n_u times the refocused one (n_u = 10 angular samples):
# a ratio of the two closed forms, close to n_u but not equal to it.
PERSPECTIVE_DOF_RATIO_RTOL = 0.35


@pytest.mark.parametrize("name", CASES)
def test_mla_calibration_finds_true_lattice(name):
    props = CASES[name]
    sc = white_scene(300, **props)
    img = render(sc, spp=128)
    cam = sc.sensors()[0].camera
    layout = props.get("mla_layout", "rect")
    rng = np.random.default_rng(2)
    for image in (img, rng.poisson(img / img.max() * 200) / 200.0):  # clean and shot noise (200 photons peak)
        cal = lfm.calibrate_mla(image, layout=layout)
        err = lfm.calibration_error(cal, cam)
        tol = CALIBRATION_TOL_PX_NEAR_INTEGER_PMR if "pmr9.1" not in name else CALIBRATION_TOL_PX_PMR9_1
        assert err["max_px"] < tol, err
        assert abs(err["rotation_error_deg"]) < CALIBRATION_ROTATION_TOL_DEG
        assert err["lenslets"] >= 0.9 * len(lfm.calibration_from_camera(cam).axial)


def test_calibration_rejects_bad_images():
    with pytest.raises(CalibrationError, match="all dark"):
        lfm.calibrate_mla(np.zeros((64, 64)), layout="rect")
    with pytest.raises(CalibrationError):
        lfm.calibrate_mla(np.ones((64, 64)), layout="rect")  # saturated / uniform: no lattice
    with pytest.raises(ConfigError, match="layout"):
        lfm.calibrate_mla(np.ones((64, 64)), layout="square")
    with pytest.raises(ConfigError, match="NaN"):
        lfm.calibrate_mla(np.full((64, 64), np.nan), layout="rect")


def test_alpha_z_mapping():
    kw = dict(focal_length_mm=50.0, magnification=0.25)
    assert lfm.alpha_from_z(0.0, **kw) == pytest.approx(1.0)
    z = np.array([-30.0, -5.0, 5.0, 40.0])
    a = lfm.alpha_from_z(z, **kw)
    assert np.all(np.diff(a) < 0) and a[2] < 1 < a[1]  # farther -> image closer to the lens
    np.testing.assert_allclose(lfm.z_from_alpha(a, **kw), z, rtol=1e-12)
    # thin-lens equation in float64: 1/f = 1/s_o + 1/s_i
    so = 250.0 + z
    np.testing.assert_allclose(1 / (a * 62.5) + 1 / so, 1 / 50.0, rtol=1e-12)
    with pytest.raises(ConfigError, match="z"):
        lfm.alpha_from_z(-210.0, **kw)


def test_design_calculators():
    sc = white_scene(200)
    cam = sc.sensors()[0].camera
    dz = lfm.depth_resolution(focal_length_mm=50, magnification=0.25, f_number=2.8, mla_pitch_um=55, angular_samples=10)
    assert dz == pytest.approx(cam.depth_resolution())
    # closed form p s_i n_u / (D (n_u - 1) M^2)
    assert dz == pytest.approx(0.055 * 62.5 * 10 / (50 / 2.8 * 9 * 0.0625), rel=1e-12)
    near, far = cam.depth_of_field()
    pnear, pfar = cam.depth_of_field("perspective")
    assert near < 0 < far and pnear < near and pfar > far  # a perspective view is ~n_u times deeper
    assert (pfar - pnear) / (far - near) == pytest.approx(cam.angular_samples, rel=PERSPECTIVE_DOF_RATIO_RTOL)
    b = cam.pixel_budget(particles_per_lenslet=0.05)
    assert b["mla_resolution"] == [20, 20] and b["ppp"] == pytest.approx(0.05 / 100.0, rel=0.01)
    with pytest.raises(ConfigError, match="angular_samples"):
        lfm.depth_resolution(focal_length_mm=50, magnification=0.25, f_number=2.8, mla_pitch_um=55, angular_samples=1)


@pytest.mark.parametrize("layout", ["rect", "hex"])
def test_focal_stack_finds_particle_depth(tmp_path, layout):
    """A single particle at depth z is found by the focal stack within the theoretical depth
    resolution over +-20 mm (multiplicative refocusing everywhere; additive outside the
    refocused depth of field, where one lenslet already holds the particle's light)."""
    zs = np.linspace(-25, 25, 101)
    props = {"mla_layout": layout, "mla_pitch_um": 50.0}  # PMR 9.09: lenslet and pixel grids out of phase
    for z in (-20.0, -9.0, -4.0, 0.0, 2.0, 7.0, 13.0, 20.0):
        sc = particle_scene(tmp_path, [[0.5, -0.4, -z]], {"type": "particle_tracer", "rays_per_particle": 100_000}, **props)
        cam = sc.sensors()[0].camera
        lf = lfm.decode(render(sc), optics=cam)
        near, far = cam.depth_of_field()
        for method in ("multiplicative", "additive"):
            st = lfm.focal_stack(lf, zs, method=method)
            found = zs[np.argmax(st.reshape(len(zs), -1).max(1))]
            if method == "multiplicative" or not 2 * near < z < 2 * far:
                assert abs(found - z) <= cam.depth_resolution(), (method, z, found)


def test_decode_white_devignettes_and_views(tmp_path):
    sc = white_scene(200)
    cam = sc.sensors()[0].camera
    white = render(sc, spp=256)
    for interp in ("nearest", "linear", "cubic"):
        lf = lfm.decode(white, optics=cam, white=white, interpolation=interp)
        s, t, u, v = lf.shape
        assert (u, v) == (10, 10) and lf.L.shape == (s, t, 10, 10)
        inner = lf.view_weights > 0.5 * lf.view_weights.max()
        vals = lf.data[inner][:, lf.valid]
        np.testing.assert_allclose(vals, 1.0, atol=WHITE_RATIO_ATOL)  # white / white where lit
    # no white: weights from the aperture geometry (the inscribed disk of the lenslet image)
    lf = lfm.decode(white, optics=cam)
    assert 60 <= (lf.view_weights > 0).sum() <= 100
    lf2 = lfm.decode(white, optics=cam, angular_oversample=2)
    assert lf2.shape[2] == 20


def test_decode_from_exr_metadata_and_calibration(tmp_path):
    sc = particle_scene(tmp_path, [[0.3, 0.2, -6.0]], {"type": "particle_tracer", "rays_per_particle": 50_000},
                        mla_layout="hex", mla_pitch_um=50.0, mla_rotation_deg=1.5)
    sens = sc.sensors()[0]
    raw = render(sc)
    path = write_exr(tmp_path / "raw.exr", raw.astype(np.float32), {"camera": sensor_model(sens)})
    a = lfm.decode(path)
    b = lfm.decode(raw, optics=sens.camera)
    np.testing.assert_array_equal(a.data, b.data)
    # a calibration from the rendered white image decodes (almost) the same light field
    wsc = white_scene(200, mla_layout="hex", mla_pitch_um=50.0, mla_rotation_deg=1.5)
    cal = lfm.calibrate_mla(render(wsc, spp=128), layout="hex")
    c = lfm.decode(raw, cal, optics=sens.camera)
    # the refocused particle lands where the camera model projects it (within a lenslet),
    # with the model's lattice and with the calibrated one
    loc = sens.camera.world_to_local(np.array([[0.3, 0.2, -6.0]]))[0]
    x_mla = -loc[:2] * sens.camera.image_distance_mm / loc[2]
    px = sens.camera.sensor_mm_to_px(x_mla * sens.camera.image_scale)
    for lf in (b, c):
        z = lfm.focal_stack(lf, [6.0], method="multiplicative")[0]  # world z = -6: 6 mm beyond focus
        t, s = np.unravel_index(np.argmax(z), z.shape)
        assert abs(lf.s_px[s] - px[0]) < 1.01 * 50 / 5.5 and abs(lf.t_px[t] - px[1]) < 1.01 * 50 / 5.5


def test_hard_cases_and_streaming(tmp_path):
    sc = white_scene(200)
    cam = sc.sensors()[0].camera
    dark = lfm.decode(np.zeros((200, 200)), optics=cam)
    for method in ("additive", "multiplicative"):
        out = lfm.refocus(dark, 1.0, method=method)
        assert np.all(out == 0)
    sat = lfm.decode(np.full((200, 200), 1e6, np.float32), optics=cam)
    for alpha in (0.999999, 1.0, 1.000001, 0.9, 1.1):
        for method in ("additive", "multiplicative"):
            out = lfm.refocus(sat, alpha, method=method)
            assert np.all(np.isfinite(out)) and out.max() <= 1e6 * (1 + 1e-5)
    # alpha -> 1 is continuous
    rng = np.random.default_rng(0)
    lf = lfm.decode(rng.uniform(0, 1, (200, 200)), optics=cam)
    np.testing.assert_allclose(lfm.refocus(lf, 1.0 + 1e-9), lfm.refocus(lf, 1.0), atol=1e-6)
    # streaming to disk equals the in-memory stack; 'constant' magnification differs only off focus
    z = np.linspace(-10, 10, 5)
    mem = lfm.focal_stack(lf, z)
    disk = lfm.focal_stack(lf, z, out=tmp_path / "stack.npy")
    np.testing.assert_array_equal(np.asarray(disk), mem)
    const = lfm.focal_stack(lf, z, magnification="constant")
    np.testing.assert_allclose(const[2], mem[2], atol=1e-6)
    assert not np.allclose(const[0], mem[0])
    # world-grid refocusing at the focal plane on the lenslet chief rays equals refocus(alpha=1)
    so, si = cam.focus_distance_mm, cam.image_distance_mm
    m = cam.to_world_mitsuba
    xs = (m[:3, :3] @ np.array([[-v * so / si, 0.0, so] for v in lf.s_mm]).T).T + m[:3, 3]  # chief rays -> focal plane
    ys = (m[:3, :3] @ np.array([[0.0, -v * so / si, so] for v in lf.t_mm]).T).T + m[:3, 3]
    vol = lfm.refocus_volume(lf, xs[:, 0], ys[:, 1], [0.0])
    np.testing.assert_allclose(vol[0], lfm.refocus(lf, 1.0), atol=1e-5)
    with pytest.raises(ConfigError, match="method"):
        lfm.refocus(lf, 1.0, method="max")
    with pytest.raises(ConfigError, match="alpha"):
        lfm.refocus(lf, -1.0)
    with pytest.raises(ConfigError, match="interpolation"):
        lfm.decode(np.zeros((200, 200)), optics=cam, interpolation="spline")
    with pytest.raises(ConfigError, match="200x200"):
        lfm.decode(np.zeros((100, 100)), optics=cam)
    with pytest.raises(ConfigError, match=".npy"):
        lfm.focal_stack(lf, z, out=tmp_path / "stack.txt")
    assert not (tmp_path / "stack.txt").exists()


def test_cli_decode_and_refocus(tmp_path):
    from mitpiv.cli import main

    sc = particle_scene(tmp_path, [[0.2, 0.1, -4.0]], {"type": "particle_tracer", "rays_per_particle": 20_000})
    sens = sc.sensors()[0]
    raw = write_exr(tmp_path / "raw.exr", render(sc).astype(np.float32), {"camera": sensor_model(sens)})
    white = write_exr(tmp_path / "white.exr", render(white_scene(200), spp=256).astype(np.float32), {"camera": sensor_model(sens)})
    assert main(["decode", str(raw), "--white", str(white), "--calibrate", "--out", str(tmp_path / "lf.npz")]) == 0
    assert (tmp_path / "lf.png").is_file()
    lf = lfm.LightField.load(tmp_path / "lf.npz")
    assert lf.optics is not None and lf.info["devignetted"]
    assert main(["refocus", str(tmp_path / "lf.npz"), "--z-range", "-10", "10", "11", "--method", "multiplicative",
                 "--out", str(tmp_path / "stack.npy")]) == 0
    st = np.load(tmp_path / "stack.npy")
    assert st.shape[0] == 11 and np.argmax(st.reshape(11, -1).max(1)) == 7  # world z = -4: 4 mm beyond focus
    assert main(["refocus", str(tmp_path / "lf.npz"), "--out", str(tmp_path / "x.npy")]) == 2  # no depths given


def test_focal_stack_blocks_equal_single_plane_refocus():
    """The blocked, table-driven focal stack equals refocus() plane by plane (the per-sample
    kernel) exactly, for both methods, both interpolations and both magnifications."""
    cam = PlenopticCamera((200, 200), pixel_pitch_um=5.5, focal_length_mm=50.0, f_number=2.8,
                          focus_distance_mm=250.0, mla_pitch_um=55.0)
    lf = lfm.decode(np.random.default_rng(2).uniform(0, 1, (200, 200)), optics=cam)
    z = np.linspace(-12, 12, 19)  # two blocks
    alphas = lfm.alpha_from_z(z, focal_length_mm=50.0, magnification=cam.magnification)
    for kw in ({}, {"method": "multiplicative"}, {"interpolation": "nearest"}):
        st = lfm.focal_stack(lf, z, **kw)
        np.testing.assert_array_equal(st, np.stack([lfm.refocus(lf, a, **kw) for a in alphas]))
    const = lfm.focal_stack(lf, z[:3], magnification="constant")
    np.testing.assert_array_equal(const[1], lfm.refocus(lf, alphas[1], magnification="constant"))
