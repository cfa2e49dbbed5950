"""The absolute radiometry of a rendered particle image (docs/radiometry.md).

The summed image of one particle seen by a ``distorted_pinhole`` is

    sum V = E dC/dOmega(theta) / (r^2 Omega_pix)    [W mm^-2 sr^-1]

with E the sheet's irradiance at the particle [W/mm^2], dC/dOmega its differential
scattering cross-section toward the camera [mm^2/sr], r its distance from the pinhole [mm]
and Omega_pix = p^2 cos^3(alpha) / (f^2 |det J|) the solid angle of the pixel it is imaged
on [sr] (alpha: angle off the optical axis; J: the distortion's Jacobian). A thin lens
averages the same over its pupil: sum V = (f_px / z)^2 |det J| < E dC/dOmega(theta_a) / cos(alpha_a) >_a,
z the particle's depth; that is the pinhole formula up to the variation of dC/dOmega and of
1/cos over the pupil, O((D / 2r)^2), not a factor of the pupil's area.

Independent references, all float64 and written here: the Gaussian sheet profile, the
camera geometry (Mitsuba's look-at frame, the OpenCV pixel convention and Brown-Conrady
distortion with a finite-difference Jacobian), and dC/dOmega from miepython 3.3 (Wiscombe's
MIEV0 amplitudes, (|S1|^2 + |S2|^2) / (2 k^2); REFERENCE.md) or, for the isotropic phase,
Q_sca (pi d^2 / 4) / (4 pi). Both light-transport strategies are checked: particle tracing
(``particle_tracer``) and camera tracing (Mitsuba's ``direct`` integrator).
"""

import math
import os
import re
import shutil
from pathlib import Path

import mitsuba as mi
import numpy as np
import pytest

from mitpiv._numba import set_cache_dir
from mitpiv.io import write_particles_ply
from mitpiv.render.render import render_sensor
from mitpiv.render.scene import load_dict, load_scene

ROOT = Path(__file__).resolve().parents[2]

# ----------------------------------------------------------------------------- the set-up
WAVELENGTH_NM = 532.0
DIAMETER_UM = 1.0  # a 1 um droplet: the Mie table's interpolation error is <= 1e-4 here
INDEX = 1.45  # DEHS in air
Q_ISOTROPIC = 2.0  # tracer_particles' default scattering efficiency (isotropic phase)
E0 = 3.0  # peak irradiance [W/mm^2]
THICKNESS_MM = 2.0  # Gaussian sheet FWHM; the laser runs along +x, the sheet normal is +z
CENTRE_MM = np.array([0.25, -0.15, 0.5])  # off the mid-plane: E = 0.84 E0
CAM_DISTANCE_MM, CAM_AZ_DEG, CAM_EL_DEG = 400.0, 70.0, 40.0  # scattering angle 74.8 deg
OFF_AXIS_RAD = 0.07  # the camera looks past the particle: cos^3 = 0.993
FOCAL_MM, PITCH_UM, RES = 85.0, 10.0, 48
K1, P1 = 0.5, 2e-3  # the distorted case: |det J| = 1.010 where the particle is imaged
F_NUMBER_LENS = 2.0  # the thin-lens case: its pupil average is 5e-3 above the pinhole formula

# ----------------------------------------------------------------------------- tolerances
# The formula against a render, relative. What enters: float32 kernels (~1e-6); the mie
# table's linear interpolation at 1 um (2e-5 to 7e-5 measured at 59 and 121 deg); Monte Carlo
# noise, measured: camera tracing with the stratified sampler at CT_SPP and the CT_PROXY_MM
# proxy 5e-5 per render (pinhole) and 2e-4 (f/4); particle tracing through the pupil
# 1.7e-4 per 16k rays at f/4 (PT_PASSES x 4096 rays here); the proxy's finite size
# (R / r)^2 ~ 2e-6. Measured: at most 1.5e-4 (the f/2 case, particle tracing). Leaving out any
# factor of the formula moves the sum by more than 4x this (checked in
# test_every_factor_is_visible_at_the_tolerance).
FORMULA_RTOL = 1e-3
CT_SPP = 256  # stratified sampler (a square number of samples)
CT_RENDERS = 3  # seeds averaged
CT_PROXY_MM = 0.6  # a large proxy: the image is a uniformly bright disk of radius 13 px, so
# only its edge pixels are sampled noisily (the image does not depend on the proxy radius)
PT_PROXY_MM = 0.01
PT_RAYS, PT_PASSES = 4096, 16  # pupil samples of the thin lens
# miepython's amplitudes integrated over the sphere against its own Q_sca (the reading of
# its normalisation): Gauss-Legendre in cos(theta), converged to ~1e-12.
CROSS_SECTION_RTOL = 1e-9
# The doc's worked numbers (4 significant digits) against the demo scene's render and the
# formula: rounding (5e-5) plus the mie table's 1e-4.
DOC_NUMBER_RTOL = 1e-3


def _miepython():
    """miepython imported as mitpiv's Mie engine imports it (numba on, mitpiv's cache folder),
    so that importing it here first does not switch its JIT off for the rest of the session."""
    os.environ.setdefault("MIEPYTHON_USE_JIT", "1")
    set_cache_dir()
    import miepython

    return miepython


def dcs_mie(cos_theta, diameter_um=DIAMETER_UM, index=INDEX, wavelength_nm=WAVELENGTH_NM) -> np.ndarray:
    """Unpolarised differential scattering cross-section [mm^2/sr] at cos(theta), float64."""
    mp = _miepython()
    lam_mm = wavelength_nm * 1e-6
    x = math.pi * diameter_um * 1e-3 / lam_mm
    k = 2 * math.pi / lam_mm
    s1, s2 = mp.S1_S2(index, x, np.atleast_1d(np.asarray(cos_theta, float)), norm="wiscombe")
    return (np.abs(s1) ** 2 + np.abs(s2) ** 2) / (2 * k * k)


def dcs_isotropic(cos_theta) -> np.ndarray:
    """Isotropic phase: Q_sca (pi d^2 / 4) / (4 pi) [mm^2/sr]."""
    return np.full(np.shape(np.atleast_1d(cos_theta)), Q_ISOTROPIC * (DIAMETER_UM * 1e-3) ** 2 / 16.0)


def sheet_irradiance(p_mm) -> float:
    """Gaussian sheet: E0 exp(-4 ln 2 s^2 / t^2), s the distance from the mid-plane z = 0."""
    return E0 * math.exp(-4 * math.log(2) * (p_mm[2] / THICKNESS_MM) ** 2)


def look_at(origin, target, up) -> np.ndarray:
    """Mitsuba's look-at: columns (left, up, forward, origin); the camera looks along +z."""
    fwd = (target - origin) / np.linalg.norm(target - origin)
    left = np.cross(up, fwd)
    left /= np.linalg.norm(left)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = left, np.cross(fwd, left), fwd, origin
    return m


def brown_conrady(x, y, k1=0.0, p1=0.0):
    """OpenCV's distortion (k1, p1 only) of normalised coordinates (x right, y down)."""
    r2 = x * x + y * y
    return x * (1 + k1 * r2) + 2 * p1 * x * y, y * (1 + k1 * r2) + p1 * (r2 + 2 * y * y)


class Geometry:
    """The camera and the particle, float64: pose, local coordinates, pixel solid angle."""

    def __init__(self, k1=0.0, p1=0.0):
        az, el = math.radians(CAM_AZ_DEG), math.radians(CAM_EL_DEG)
        self.pos = CAM_DISTANCE_MM * np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        to_p = CENTRE_MM - self.pos
        side = np.cross(to_p, [0.0, 0.0, 1.0])
        target = CENTRE_MM + math.tan(OFF_AXIS_RAD) * np.linalg.norm(to_p) * side / np.linalg.norm(side)
        self.to_world = look_at(self.pos, target, np.array([0.0, 0.0, 1.0]))
        self.local = self.to_world[:3, :3].T @ to_p  # Mitsuba camera frame: x left, y up, z forward
        self.r = float(np.linalg.norm(self.local))
        self.z = float(self.local[2])
        self.cos_alpha = self.z / self.r
        self.f_px = FOCAL_MM / (PITCH_UM * 1e-3)
        xn, yn = -self.local[0] / self.z, -self.local[1] / self.z  # OpenCV: x right, y down
        self.k1, self.p1 = k1, p1
        xd, yd = brown_conrady(xn, yn, k1, p1)
        h = 1e-6
        a = (brown_conrady(xn + h, yn, k1, p1)[0] - brown_conrady(xn - h, yn, k1, p1)[0]) / (2 * h)
        b = (brown_conrady(xn, yn + h, k1, p1)[0] - brown_conrady(xn, yn - h, k1, p1)[0]) / (2 * h)
        c = (brown_conrady(xn + h, yn, k1, p1)[1] - brown_conrady(xn - h, yn, k1, p1)[1]) / (2 * h)
        e = (brown_conrady(xn, yn + h, k1, p1)[1] - brown_conrady(xn, yn - h, k1, p1)[1]) / (2 * h)
        self.det_j = abs(a * e - b * c)
        # the principal point that puts the particle's image near the film's centre
        self.cx = RES / 2 + 0.3 - self.f_px * xd
        self.cy = RES / 2 - 0.2 - self.f_px * yd
        # the pixel's solid angle seen from the pinhole where the particle is imaged [sr]
        self.omega_pix = (PITCH_UM * 1e-3) ** 2 * self.cos_alpha**3 / (FOCAL_MM**2 * self.det_j)

    def cos_theta(self, towards_mm) -> np.ndarray:
        """cos of the scattering angle (laser +x) toward world points ``towards_mm``."""
        w = np.atleast_2d(towards_mm) - CENTRE_MM
        return w[:, 0] / np.linalg.norm(w, axis=1)

    def pinhole_sum(self, dcs) -> float:
        """E dC/dOmega / (r^2 Omega_pix): the summed image [W mm^-2 sr^-1]."""
        return sheet_irradiance(CENTRE_MM) * dcs(self.cos_theta(self.pos))[0] / (self.r**2 * self.omega_pix)

    def pupil_sum(self, dcs, f_number, n_rho=24, n_phi=48) -> float:
        """Thin lens: (f_px / z)^2 |det J| < E dC/dOmega(theta_a) |p - a| / z > over the pupil
        (uniform in area; Gauss-Legendre in rho^2, midpoints in phi)."""
        radius = FOCAL_MM / (2 * f_number)
        xg, wg = np.polynomial.legendre.leggauss(n_rho)
        rho = radius * np.sqrt((xg + 1) / 2)
        phi = (np.arange(n_phi) + 0.5) * 2 * math.pi / n_phi
        a_local = np.stack([np.outer(rho, np.cos(phi)).ravel(), np.outer(rho, np.sin(phi)).ravel(),
                            np.zeros(rho.size * n_phi)], axis=1)
        weight = np.repeat(wg / 2, n_phi) / n_phi
        a_world = self.pos + a_local @ self.to_world[:3, :3].T
        dist = np.linalg.norm(self.local - a_local, axis=1)
        mean = np.sum(weight * dcs(self.cos_theta(a_world)) * dist / self.z)
        return (self.f_px / self.z) ** 2 * self.det_j * sheet_irradiance(CENTRE_MM) * mean


CASES = {  # sensor properties, phase, distortion
    "pinhole": ({}, "mie", {}),
    "pinhole_isotropic": ({}, "isotropic", {}),
    "distorted": ({"k1": K1, "p1": P1}, "mie", {"k1": K1, "p1": P1}),
    f"thin_lens_f{F_NUMBER_LENS:g}": ({"f_number": F_NUMBER_LENS}, "mie", {}),
}


def expected_sum(case: str) -> float:
    props, phase, dist = CASES[case]
    geo = Geometry(**dist)
    dcs = dcs_mie if phase == "mie" else dcs_isotropic
    return geo.pupil_sum(dcs, props["f_number"]) if "f_number" in props else geo.pinhole_sum(dcs)


def build_scene(tmp_path, case: str, strategy: str):
    props, phase, dist = CASES[case]
    geo = Geometry(**dist)
    proxy = CT_PROXY_MM if strategy == "camera" else PT_PROXY_MM
    ply = tmp_path / f"{case}_{strategy}.ply"
    write_particles_ply(ply, CENTRE_MM[None], DIAMETER_UM, proxy_radius_mm=proxy)
    sensor = {"type": "distorted_pinhole", "to_world": mi.ScalarTransform4f(geo.to_world),
              "focal_length_mm": FOCAL_MM, "pixel_pitch_um": PITCH_UM,
              "principal_point_x_px": geo.cx, "principal_point_y_px": geo.cy, **props,
              "sampler": {"type": "stratified", "sample_count": CT_SPP},
              "film": {"type": "hdrfilm", "width": RES, "height": RES, "pixel_format": "luminance",
                       "rfilter": {"type": "box"}}}
    if "f_number" in props:
        sensor["focus_distance_mm"] = geo.z  # in focus (the sum does not depend on it)
    emitter = {"type": "tracer_particles", "sheet": {"type": "ref", "id": "laser"}}
    if phase == "mie":
        emitter["phase"] = {"type": "mie", "index": INDEX}
    integrator = ({"type": "direct"} if strategy == "camera"
                  else {"type": "particle_tracer", "rays_per_particle": PT_RAYS})
    return load_dict({
        "type": "scene", "integrator": integrator, "sensor": sensor,
        "laser": {"type": "laser_sheet", "id": "laser", "thickness": THICKNESS_MM, "irradiance": E0,
                  "wavelength_nm": WAVELENGTH_NM},
        "particles": {"type": "ellipsoidsmesh", "filename": str(ply), "extent": 1.0,
                      "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}}, "emitter": emitter},
    })


def rendered_sum(tmp_path, case: str, strategy: str) -> float:
    sc = build_scene(tmp_path, case, strategy)
    if strategy == "camera":
        sums = []
        for seed in range(CT_RENDERS):
            img = np.array(mi.render(sc, spp=CT_SPP, seed=seed), dtype=np.float64)[..., 0]
            border = np.concatenate([img[0], img[-1], img[:, 0], img[:, -1]])
            assert img.max() > 0 and not border.any(), "the proxy's image must lie inside the film"
            sums.append(img.sum())
        return float(np.mean(sums))
    passes = PT_PASSES if "f_number" in CASES[case][0] else 1
    img = np.array(mi.render(sc, spp=passes, seed=1), dtype=np.float64)[..., 0]
    return float(img.sum())


# ----------------------------------------------------------------------------- tests
def test_reference_cross_section_integrates_to_csca():
    """The test's dC/dOmega (miepython, Wiscombe's amplitudes / 2k^2) integrates over the
    sphere to C_sca = Q_sca pi d^2 / 4 from miepython's efficiencies: the normalisation is read right."""
    mp = _miepython()
    mu, w = np.polynomial.legendre.leggauss(400)
    total = 2 * math.pi * np.sum(w * dcs_mie(mu))
    x = math.pi * DIAMETER_UM / (WAVELENGTH_NM * 1e-3)
    q_sca = mp.efficiencies_mx(INDEX, x)[1]
    assert total == pytest.approx(q_sca * math.pi * (DIAMETER_UM * 1e-3) ** 2 / 4, rel=CROSS_SECTION_RTOL)


def test_every_factor_is_visible_at_the_tolerance():
    """The set-up keeps the test able to fail: leaving out any factor of the formula (the sheet
    profile, cos^3, |det J|: more than 5 FORMULA_RTOL; the pupil average instead of the pinhole
    formula at f/2: more than 4) moves the sum beyond the tolerance."""
    geo = Geometry()
    assert 1 - sheet_irradiance(CENTRE_MM) / E0 > 5 * FORMULA_RTOL
    assert 1 - geo.cos_alpha**3 > 5 * FORMULA_RTOL
    assert abs(Geometry(k1=K1, p1=P1).det_j - 1) > 5 * FORMULA_RTOL
    assert geo.pupil_sum(dcs_mie, F_NUMBER_LENS) / geo.pinhole_sum(dcs_mie) - 1 > 4 * FORMULA_RTOL
    # the pupil's area is not a factor: f/2 collects 16x the light of f/8 in a real camera
    assert geo.pupil_sum(dcs_mie, F_NUMBER_LENS) / geo.pupil_sum(dcs_mie, 4 * F_NUMBER_LENS) < 1.01


@pytest.mark.parametrize("strategy", ["particle", "camera"])
@pytest.mark.parametrize("case", list(CASES))
def test_summed_image_is_the_absolute_formula(tmp_path, case, strategy):
    """sum V = E dC/dOmega / (r^2 Omega_pix) [W mm^-2 sr^-1] (thin lens: its pupil average),
    in both light-transport strategies."""
    got, want = rendered_sum(tmp_path, case, strategy), expected_sum(case)
    assert got == pytest.approx(want, rel=FORMULA_RTOL), (got / want - 1)


def _doc_table() -> dict:
    """The worked numbers of docs/radiometry.md: camera -> (theta [deg], dC/dOmega, sum V)."""
    text = (ROOT / "docs" / "radiometry.md").read_text()
    rows = re.findall(r"^\| `(cam\d)` \| ([\d.]+) \| ([\d.]+) \\times 10\^\{(-\d+)\} \| ([\d.]+) \\times 10\^\{(-\d+)\} \|",
                      text.replace("$", ""), re.M)
    return {r[0]: (float(r[1]), float(r[2]) * 10.0 ** int(r[3]), float(r[4]) * 10.0 ** int(r[5])) for r in rows}


def test_doc_worked_numbers_are_the_demo_scene(tmp_path):
    """The worked example of docs/radiometry.md: a 1 um DEHS droplet at the centre of the demo
    scene (scenes/tomo4: 1 W/mm^2, 85 mm lens, 10 um pixels, 1 m away, FFT PSF, Catmull-Rom
    film) renders the summed image the page states, and the formula gives it. Rendered at 160
    px: the f/16 PSF window (76 px) fits, so the PSF keeps the sum."""
    from mitpiv.imaging import SensorModel, apply_sensor
    from mitpiv.photometry import pixel_etendue
    from mitpiv.physics.sheet import peak_irradiance
    from mitpiv.render.render import sensor_model

    table = _doc_table()
    assert set(table) == {"cam0", "cam2"}, table
    found = re.search(r"`cam0` collects\s+about (\d+) photons from this droplet and `cam2` about (\d+)",
                      (ROOT / "docs" / "radiometry.md").read_text())
    photons = {"cam0": float(found[1]), "cam2": float(found[2])}
    shutil.copy(ROOT / "scenes" / "tomo4" / "scene.xml", tmp_path / "scene.xml")
    write_particles_ply(tmp_path / "particles_0.ply", np.zeros((1, 3)), DIAMETER_UM, proxy_radius_mm=0.02)
    sc = load_scene(tmp_path / "scene.xml", params={"resolution": 160})
    sensors = {s.id(): s for s in sc.sensors()}
    for cam, (theta_deg, dcs, total) in table.items():
        s = sensors[cam]
        pos = np.asarray(s.camera.position_mm, float)
        r = float(np.linalg.norm(pos))
        cos_theta = pos[0] / r  # laser along +x, particle at the origin on the optical axis
        assert math.degrees(math.acos(cos_theta)) == pytest.approx(theta_deg, abs=0.01)
        ref_dcs = dcs_mie(cos_theta)[0]
        assert dcs == pytest.approx(ref_dcs, rel=DOC_NUMBER_RTOL)
        omega_pix = (s.camera.pixel_pitch_um * 1e-3 / s.camera.focal_length_mm) ** 2
        assert total == pytest.approx(1.0 * ref_dcs / (r * r * omega_pix), rel=DOC_NUMBER_RTOL)
        img = render_sensor(sc, s).astype(np.float64)
        assert img.sum() == pytest.approx(total, rel=DOC_NUMBER_RTOL)
        # the page's photons: the render (at 1 W/mm^2) scaled to a 200 mJ, 5 ns pulse over the
        # 6 mm x 50 mm sheet, exposed through the f/16 pupil for 5 ns (aperture photometry)
        counts = apply_sensor(img, SensorModel(illumination_time_s=5e-9), etendue=pixel_etendue(sensor_model(s)),
                              wavelength_nm=532.0)
        assert counts.sum() * peak_irradiance(200.0, 5.0, 6.0, 50.0) == pytest.approx(photons[cam], rel=DOC_NUMBER_RTOL)
