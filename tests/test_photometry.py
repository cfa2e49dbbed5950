"""Aperture photometry (mitpiv.photometry, the sensor model's ``photometry``): each camera's
counts follow the light its own aperture collects.

References, independent of the code under test: the pixel's solid angle from its four
back-projected corners (the exact spherical-quadrilateral area, float64), the pupil's area
pi (f / 2N)^2, the plenoptic camera's power through its main lens (the closed-form solid
angle of the aperture disk, 2 pi (1 - z / sqrt(z^2 + R^2))) and the photon energy h c / lambda.
"""

import math

import mitsuba as mi
import numpy as np
import pytest

from mitpiv.cli import main
from mitpiv.errors import ConfigError
from mitpiv.imaging import SensorModel, apply_sensor, apply_sensor_set, resolve_photometry
from mitpiv.io import read_exr, write_exr, write_particles_ply
from mitpiv.photometry import (
    LIGHT_SPEED_M_S,
    PLANCK_J_S,
    axis_etendue,
    cameras_from_metadata,
    photons_per_watt,
    pixel_etendue,
)
from mitpiv.physics.camera import PinholeCamera
from mitpiv.render.render import render_sensor, sensor_model
from mitpiv.render.scene import load_dict

from .lightfield.helpers import BASE as LF_BASE
from .lightfield.helpers import DIST as LF_DIST
from .lightfield.helpers import intensity as lf_intensity
from .lightfield.helpers import particle_scene as lf_particle_scene

# Tolerances.
# The étendue map against the corner-projected solid angle: the map takes cos^4 and |det J|
# at the pixel centre, the corners integrate them over the pixel; the midpoint rule's error
# is (p/f)^2 / 24 times their second derivatives (O(10) with k1 = 0.4), ~1e-5 for the
# 250 um pixels of an 85 mm lens used here to reach 10 deg off axis (measured 2.2e-6); the
# Newton undistortion converges to ~1e-15.
ETENDUE_RTOL = 2e-5
# f/4 against f/8: the rendered sums differ by the variation of 1/cos over the pupil,
# O((D/2r)^2) ~ 1e-4 here (docs/radiometry.md), plus particle tracing's Monte Carlo noise
# over the pupil (8 passes x 4096 rays: ~2e-4 per camera). 2e-3 is 5x their sum.
RATIO_RTOL = 2e-3
# A pinhole stated at f/4 against the f/4 thin lens: the same pupil area; only the pupil
# average (~1e-4) and the thin lens's Monte Carlo noise differ.
PINHOLE_EQUIV_RTOL = 2e-3
# Plenoptic against thin lens with the same main lens: the thin lens's étendue is paraxial
# (pi R^2 / z^2 on the axis, the sine condition's), the plenoptic render the exact disk
# solid angle; with <d_a / z> of the pupil average they differ by (1 + rho^2 / 4)(1 + 3 rho^2 / 4)
# - 1 ~ rho^2 = 1.3e-3 (rho = R / z = 0.036), predicted in float64 below; the renders' Monte
# Carlo noise is 2e-4 each (200 k rays through the main lens). PREDICTED_RTOL is 2.5x that
# noise; EQUAL_RTOL bounds the whole paraxial difference.
PREDICTED_RTOL = 1e-3
EQUAL_RTOL = 3e-3

FOCAL_MM, PITCH_UM, RES, DIST_MM = 50.0, 10.0, 64, 300.0


def _scene(tmp_path, sensors: dict):
    """Isotropic 2 um particles around the origin in a thick sheet, seen by ``sensors``
    (distorted_pinhole properties each) from +z, DIST_MM away."""
    rng = np.random.default_rng(4)
    pts = np.column_stack([rng.uniform(-1.5, 1.5, 12), rng.uniform(-1.5, 1.5, 12), rng.uniform(-0.5, 0.5, 12)])
    write_particles_ply(tmp_path / "p.ply", pts, 2.0, proxy_radius_mm=0.01)
    d = {"type": "scene", "integrator": {"type": "particle_tracer", "rays_per_particle": 4096},
         "laser": {"type": "laser_sheet", "id": "laser", "thickness": 50.0, "wavelength_nm": 532.0},
         "particles": {"type": "ellipsoidsmesh", "filename": str(tmp_path / "p.ply"), "extent": 1.0,
                       "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}},
                       "emitter": {"type": "tracer_particles", "sheet": {"type": "ref", "id": "laser"}}}}
    for sid, props in sensors.items():
        d[sid] = {"type": "distorted_pinhole", "id": sid, "focal_length_mm": FOCAL_MM, "pixel_pitch_um": PITCH_UM,
                  "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, DIST_MM], target=[0, 0, 0], up=[0, 1, 0]),
                  "film": {"type": "hdrfilm", "width": RES, "height": RES, "pixel_format": "luminance",
                           "rfilter": {"type": "box"}}, **props}
    return load_dict(d)


def _render_all(sc, passes=8):
    imgs, cams = {}, {}
    for s in sc.sensors():
        imgs[(s.id(), 0)] = render_sensor(sc, s, spp=passes, seed=3).astype(np.float64)
        cams[s.id()] = sensor_model(s)
    return imgs, cams


@pytest.fixture(scope="module")
def three_cameras(tmp_path_factory):
    """f/4 and f/8 thin lenses and a pinhole stated at f/4, one pose, one scene."""
    tmp = tmp_path_factory.mktemp("photometry")
    lens = {"focus_distance_mm": DIST_MM}
    sc = _scene(tmp, {"f4": {"f_number": 4.0, **lens}, "f8": {"f_number": 8.0, **lens},
                      "pin4": {"photometric_f_number": 4.0}})
    return _render_all(sc)


def test_f4_collects_four_times_the_light_of_f8(three_cameras):
    """One scene-wide exposure: two thin-lens cameras at f/4 and f/8 record counts 4 : 1,
    where the rendered images (pupil-averaged radiance) are 1 : 1 within the pupil average."""
    imgs, cams = three_cameras
    rendered = imgs[("f4", 0)].sum() / imgs[("f8", 0)].sum()
    assert rendered == pytest.approx(1.0, abs=RATIO_RTOL)  # the image alone carries no aperture
    res = apply_sensor_set(imgs, SensorModel(peak_photons=5000.0), seed=1, cameras=cams)
    assert res.photometry == "aperture"
    ratio = res.counts[("f4", 0)].sum() / res.counts[("f8", 0)].sum()
    assert ratio == pytest.approx(4.0, rel=RATIO_RTOL)
    assert res.etendue_axis["f4"] / res.etendue_axis["f8"] == pytest.approx(4.0, rel=1e-12)
    # with shot noise the summed counts keep 4 : 1 within their Poisson errors (5 sigma)
    noisy = apply_sensor_set(imgs, SensorModel(peak_photons=5000.0, shot_noise=True), seed=2, cameras=cams)
    a, b = (float(noisy.counts[(k, 0)].sum()) for k in ("f4", "f8"))
    assert abs(a / b - ratio) < 5 * ratio * math.sqrt(1 / a + 1 / b)
    # the rendered values exposed as they are ('image' photometry) lose the aperture
    flat = apply_sensor_set(imgs, SensorModel(peak_photons=5000.0, photometry="image"), seed=1, cameras=cams)
    assert flat.counts[("f4", 0)].sum() / flat.counts[("f8", 0)].sum() == pytest.approx(rendered, rel=1e-9)


def test_a_pinhole_stated_at_f4_collects_what_the_f4_lens_does(three_cameras):
    imgs, cams = three_cameras
    assert cams["pin4"]["photometric_f_number"] == 4.0 and cams["pin4"]["f_number"] is None
    res = apply_sensor_set(imgs, SensorModel(exposure=1e12), seed=1, cameras=cams)
    assert res.counts[("pin4", 0)].sum() / res.counts[("f4", 0)].sum() == pytest.approx(1.0, rel=PINHOLE_EQUIV_RTOL)


def test_photons_from_the_illumination_time(three_cameras):
    """illumination_time_s: photons = sum(V G) t lambda / (h c), V at the sheet's irradiance."""
    imgs, cams = three_cameras
    t = 7e-9
    res = apply_sensor_set(imgs, SensorModel(illumination_time_s=t), seed=1, cameras=cams, wavelength_nm=532.0)
    power = float((imgs[("f8", 0)] * pixel_etendue(cams["f8"])).sum())  # [W]
    photons = power * t / (PLANCK_J_S * LIGHT_SPEED_M_S / 532e-9)
    assert res.counts[("f8", 0)].sum() == pytest.approx(photons, rel=1e-9)
    assert photons_per_watt(t, 532.0) == pytest.approx(t * 532e-9 / (6.62607015e-34 * 299792458.0), rel=1e-15)
    meta = res.metadata(("f8", 0))
    assert meta["photometry"] == "aperture" and "per W" in meta["exposure_units"]
    with pytest.raises(ConfigError, match="wavelength"):
        apply_sensor_set(imgs, SensorModel(illumination_time_s=t), seed=1, cameras=cams)


def _corner_solid_angle(cam: PinholeCamera) -> np.ndarray:
    """Each pixel's solid angle [sr] seen from the pinhole: the spherical quadrilateral of its
    four back-projected corners, as two triangles (Van Oosterom & Strackee)."""
    w, h = cam.resolution
    v, u = np.mgrid[0 : h + 1, 0 : w + 1].astype(float)
    _, d = cam.pixel_to_ray(np.stack([u, v], -1), iterations=40)
    d = d @ cam.rotation.T  # back to the camera frame (only the angles matter)

    def tri(a, b, c):
        num = np.abs(np.einsum("...i,...i", a, np.cross(b, c)))
        den = 1 + np.einsum("...i,...i", a, b) + np.einsum("...i,...i", b, c) + np.einsum("...i,...i", c, a)
        return 2 * np.arctan2(num, den)

    p00, p10, p01, p11 = d[:-1, :-1], d[:-1, 1:], d[1:, :-1], d[1:, 1:]
    return tri(p00, p10, p11) + tri(p00, p11, p01)


@pytest.mark.parametrize("k1, p1", [(0.0, 0.0), (0.4, 3e-3)], ids=["pinhole", "brown_conrady"])
def test_pixel_etendue_is_the_pupil_area_times_the_pixel_solid_angle(k1, p1):
    """G = pi R^2 cos(alpha) Omega_pix at every pixel, Omega_pix from the pixel's corners."""
    from mitpiv.physics.distortion import Distortion

    cam = PinholeCamera((120, 90), 85.0, 250.0, principal_point_px=(54.3, 47.8), f_number=2.8,
                        focus_distance_mm=500.0, distortion=Distortion(k1=k1, p1=p1))
    meta = {"type": "distorted_pinhole", **cam.to_dict()}
    g = pixel_etendue(meta)
    omega = _corner_solid_angle(cam)
    v, u = np.mgrid[0:90, 0:120] + 0.5
    _, d = cam.pixel_to_ray(np.stack([u, v], -1), iterations=40)
    cos_a = (d @ cam.rotation.T)[..., 2]
    expected = math.pi * (85.0 / (2 * 2.8)) ** 2 * cos_a * omega
    np.testing.assert_allclose(g, expected, rtol=ETENDUE_RTOL)
    assert axis_etendue(meta) == pytest.approx(math.pi * 0.25**2 / (4 * 2.8**2), rel=1e-15)
    assert g.min() / g.max() < 0.95  # the field's corners are visibly darker (cos^4 of 12 deg, distortion)


def test_plenoptic_and_thin_lens_with_one_main_lens_collect_the_same_photons(tmp_path):
    """A plenoptic camera (50 mm f/2.8 focused at 250 mm, s_i = 62.5 mm) and a thin-lens
    camera with the same main lens (image distance 62.5 mm as its focal length, the same
    aperture D = 17.86 mm, the same focus) record the same photons from an on-axis particle,
    summed over the lenslet images."""
    pts = np.array([[0.0, 0.0, 0.0]])
    rays = 200_000
    pl = lf_particle_scene(tmp_path, pts, {"type": "particle_tracer", "rays_per_particle": rays})
    d_mm = LF_BASE["focal_length_mm"] / LF_BASE["f_number"]
    s_i = 1 / (1 / LF_BASE["focal_length_mm"] - 1 / LF_BASE["focus_distance_mm"])
    write_particles_ply(tmp_path / "t.ply", pts, 2.0, proxy_radius_mm=0.01)
    tl = load_dict({
        "type": "scene", "integrator": {"type": "particle_tracer", "rays_per_particle": rays},
        "sensor": {"type": "distorted_pinhole", "id": "thin", "focal_length_mm": s_i, "f_number": s_i / d_mm,
                   "focus_distance_mm": LF_DIST, "pixel_pitch_um": LF_BASE["pixel_pitch_um"],
                   "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, LF_DIST], target=[0, 0, 0], up=[0, 1, 0]),
                   "film": {"type": "hdrfilm", "width": 64, "height": 64, "pixel_format": "luminance",
                            "rfilter": {"type": "box"}}},
        "laser": {"type": "laser_sheet", "id": "laser", "thickness": 400.0, "origin": mi.ScalarPoint3f(0, 0, 0)},
        "particles": {"type": "ellipsoidsmesh", "filename": str(tmp_path / "t.ply"), "extent": 1.0,
                      "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}},
                      "emitter": {"type": "tracer_particles", "sheet": {"type": "ref", "id": "laser"}}},
    })
    imgs, cams = {}, {}
    for sc in (pl, tl):
        s = sc.sensors()[0]
        sid = s.id() if s.id() == "thin" else "plenoptic"
        imgs[(sid, 0)] = render_sensor(sc, s, spp=1, seed=5).astype(np.float64)
        cams[sid] = sensor_model(s)
    assert cams["plenoptic"]["aperture_diameter_mm"] == pytest.approx(d_mm, rel=1e-12)
    res = apply_sensor_set(imgs, SensorModel(illumination_time_s=1e-8), seed=1, cameras=cams, wavelength_nm=532.0)
    n_pl, n_tl = (float(res.counts[(k, 0)].sum()) for k in ("plenoptic", "thin"))
    assert n_tl / n_pl == pytest.approx(1.0, abs=EQUAL_RTOL)
    # the predicted paraxial difference, float64: thin lens I pi R^2 / z^2 <d_a / z>, plenoptic
    # I 2 pi (1 - z / sqrt(z^2 + R^2)) (power conserved through the lenslets)
    r_ap, z = d_mm / 2, LF_DIST
    xg, wg = np.polynomial.legendre.leggauss(32)
    rho = r_ap * np.sqrt((xg + 1) / 2)
    mean_da = np.sum(wg / 2 * np.hypot(z, rho) / z)
    thin = math.pi * r_ap**2 / z**2 * mean_da
    plen = 2 * math.pi * (1 - z / math.hypot(z, r_ap))
    assert n_tl / n_pl == pytest.approx(thin / plen, rel=PREDICTED_RTOL)
    # and absolutely: the plenoptic camera's photons are the power through its aperture
    photons = lf_intensity(pts)[0] * plen * photons_per_watt(1e-8, 532.0)
    assert n_pl == pytest.approx(photons, rel=PREDICTED_RTOL)


# ----------------------------------------------------------------------------- refusals
def _pin(f_number=None, **extra):
    cam = PinholeCamera((8, 6), 50.0, 10.0, f_number=f_number, focus_distance_mm=300.0 if f_number else None)
    return {"type": "distorted_pinhole", **cam.to_dict(), "psf": None, **extra}


def test_a_set_mixing_apertures_and_bare_pinholes_is_refused():
    cams = {"lens": _pin(4.0), "bare": _pin()}
    with pytest.raises(ConfigError, match=r"\['bare'\].*photometric_f_number"):
        resolve_photometry(SensorModel(), cams, ["lens", "bare"])
    # all bare pinholes: the rendered values are exposed, as before
    assert resolve_photometry(SensorModel(), {"a": _pin(), "b": _pin()}, ["a", "b"]) == ("image", {})
    with pytest.raises(ConfigError, match="no aperture"):
        resolve_photometry(SensorModel(photometry="aperture"), {"a": _pin()}, ["a"])
    with pytest.raises(ConfigError, match="photometric_f_number"):
        resolve_photometry(SensorModel(illumination_time_s=1e-8), {"a": _pin()}, ["a"])
    # a plenoptic camera's irradiance and a pinhole's radiance cannot share one exposure as values
    plen = {"type": "plenoptic", "pixel_pitch_um": 5.0, "resolution": [8, 6],
            "pixel_value": "sensor irradiance [W/mm^2] averaged over the pixel"}
    with pytest.raises(ConfigError, match="different quantities"):
        resolve_photometry(SensorModel(photometry="image"), {"p": plen, "a": _pin()}, ["p", "a"])
    # the psf's diffraction f-number is the pinhole's aperture
    assert axis_etendue(_pin(psf={"f_number": 8.0})) == pytest.approx(math.pi * 1e-4 / 256, rel=1e-12)


@pytest.mark.parametrize("kw, match", [
    ({"illumination_time_s": 1e-8, "peak_photons": 10.0}, "not both"),
    ({"illumination_time_s": 1e-8, "photometry": "image"}, "photometry"),
    ({"illumination_time_s": -1.0}, "illumination_time_s"),
    ({"photometry": "lens"}, "photometry"),
])
def test_bad_sensor_photometry_is_refused(kw, match):
    with pytest.raises(ConfigError, match=match):
        SensorModel(**kw)


def test_apply_sensor_takes_an_etendue():
    img = np.full((6, 8), 2.0)
    g = pixel_etendue(_pin(4.0))
    np.testing.assert_allclose(apply_sensor(img, exposure=1e9, etendue=g), 2e9 * g)
    with pytest.raises(ConfigError, match="etendue"):
        apply_sensor(img, exposure=1.0, photometry="aperture")
    with pytest.raises(ConfigError, match="shape"):
        apply_sensor(img, exposure=1.0, etendue=np.ones((3, 3)))


def test_a_thin_lens_refuses_a_photometric_f_number(tmp_path):
    with pytest.raises(ConfigError, match="photometric_f_number"):
        _scene(tmp_path, {"c": {"f_number": 4.0, "focus_distance_mm": DIST_MM, "photometric_f_number": 8.0}})


def test_cli_sensor_follows_each_camera_aperture(three_cameras, tmp_path, capsys):
    """mitpiv sensor on EXRs of bare pinholes: refused without an aperture when mixed with a
    lens, accepted with --photometric-f-number, and the counts follow the apertures."""
    imgs, cams = three_cameras
    bare = {**cams["pin4"], "photometric_f_number": None}
    files = []
    for sid, cam in (("f8", cams["f8"]), ("bare", bare)):
        f = tmp_path / f"{sid}.exr"
        write_exr(f, imgs[(sid if sid != "bare" else "pin4", 0)].astype(np.float32),
                  {"sensor_id": sid, "frame": 0, "camera": cam,
                   "illumination": [{"type": "laser_sheet", "wavelength_nm": 532.0}]})
        files.append(str(f))
    out = tmp_path / "out"
    assert main(["sensor", *files, "--out", str(out), "--format", "exr", "--peak-photons", "1000"]) == 2
    err = capsys.readouterr().err
    assert "['bare']" in err and "--photometric-f-number" in err
    assert not out.exists() or not any(out.iterdir())
    assert main(["sensor", *files, "--out", str(out), "--format", "exr", "--peak-photons", "1000",
                 "--photometric-f-number", "4", "--bit-depth", "16"]) == 0
    c8, m8 = read_exr(out / "f8.exr")
    cb, _ = read_exr(out / "bare.exr")
    assert m8["sensor_model"]["photometry"] == "aperture"
    assert cb.astype(float).sum() / c8.astype(float).sum() == pytest.approx(4.0, rel=0.01)  # 16-bit rounding
    assert cameras_from_metadata({"x": {"camera": bare}}, photometric_f_number=2.0)["x"]["photometric_f_number"] == 2.0


@pytest.mark.parametrize("profile, order", [("gaussian", 2.0), ("supergaussian", 6.0), ("tophat", 2.0)])
def test_peak_irradiance_spreads_the_pulse_over_the_sheet(profile, order):
    """E0 tau w integral(g) = pulse energy, the integral by scipy's adaptive quadrature of
    the profile the renderer uses (tolerance 1e-9: quad's error estimate is ~1e-12)."""
    from scipy.integrate import quad

    from mitpiv.physics.sheet import peak_irradiance, sheet_profile

    e0 = peak_irradiance(200.0, 5.0, 1.5, 40.0, profile, order)
    integral = quad(lambda s: float(sheet_profile(np.array(s), 1.5, profile, order)), -4, 4, points=[-0.75, 0.75],
                    epsabs=1e-13, limit=200)[0]
    assert e0 * 5e-9 * 40.0 * integral == pytest.approx(0.2, rel=1e-9)
    with pytest.raises(ConfigError, match="pulse_energy_mj"):
        peak_irradiance(-1.0, 5.0, 1.5, 40.0)
