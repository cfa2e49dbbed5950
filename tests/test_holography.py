"""Digital in-line holography: hologram formation against analytic disk diffraction
(Fresnel quadrature in float64, Fraunhofer closed form), propagation identities, sampling
checks, reconstruction and the hybrid detection, and plenoptic vs DIH on one field."""

import math

import numpy as np
import pytest
from scipy import integrate, special

from mitpiv import holography as ho
from mitpiv.errors import ConfigError, MitpivWarning
from mitpiv.imaging import SensorModel

WL = 532e-6  # mm
K = 2 * np.pi / WL

# Tolerances and their provenance. Identities of the angular-spectrum propagator (a unitary
# transfer function: energy and round trips to rounding, 1e-10 .. 1e-12) stay inline.
# Hologram of a disk against Fresnel quadrature (float64, scipy.integrate.quad): the disk's
# edge on the 0.5 um simulation grid; measured < 6e-4 of the unit background.
FRESNEL_ABS_TOL = 2e-3
# Against the Fraunhofer closed form: the far-field form neglects k a^2 / 2z = 0.07 rad of
# phase across the disk (Fresnel number 0.023).
FRAUNHOFER_ABS_TOL = 1e-2
# Padded (linear) propagation there and back: what leaves the window or the band is lost,
# nothing grows (a bound on the loss, of the unit field).
PADDED_ROUND_TRIP_ABS_TOL = 0.05
# The focal stack (complex64) against plain NumPy in complex128.
COMPLEX64_ATOL = 2e-5
# One disk refocused and detected: one 4 um pixel in the plane, two diameters in depth
# (against d^2 / lambda = 12 mm of depth of focus), its diameter to 2 pixels.
DISK_LATERAL_TOL_MM = 0.004
DISK_DEPTH_TOL_MM = 0.16
DISK_SIZE_TOL_MM = 0.008
# 16 droplets against the exact synthetic truth: 2 pixels of 3 um in size (measured 1 um RMS),
# 0.1 diameter laterally, depth RMS one diameter (measured 0.43 with 0.02 mm planes; the
# drop-fragments study, paper file 003_c92dce90627d9ea9.txt, measured 0.72 mean diameters for
# DIH and cites 1-2 diameters); every depth error within the d^2 / lambda depth of focus (the
# closed form, checked per droplet).
DROPLET_SIZE_RMS_MM = 0.006
DROPLET_LATERAL_RMS_DIAMETERS = 0.1
DROPLET_DEPTH_RMS_DIAMETERS = 1.0
# Mean of a hologram against 1 - (blocked area / sensor area) (opaque) and 1 (phase object):
# light diffracted outside the sensor, a few 1e-3 of the mean.
BEAM_ENERGY_ABS_TOL = 5e-3


def fresnel_intensity(rho, a, z):
    """Paraxial (Fresnel) intensity behind an opaque disk of radius a in a unit plane wave:
    U = 1 - (k / i z) exp(i k rho^2 / 2z) int_0^a J0(k rho r / z) exp(i k r^2 / 2z) r dr."""
    f = lambda r: special.j0(K * rho * r / z) * np.exp(1j * K * r * r / (2 * z)) * r  # noqa: E731
    re = integrate.quad(lambda r: f(r).real, 0, a, limit=200)[0]
    im = integrate.quad(lambda r: f(r).imag, 0, a, limit=200)[0]
    return abs(1 - (K / (1j * z)) * np.exp(1j * K * rho * rho / (2 * z)) * (re + 1j * im)) ** 2


def pixel_average(fn, x, y, p):
    g, w = np.polynomial.legendre.leggauss(3)
    return sum(wi * wj * fn(np.hypot(x + gi * p / 2, y + gj * p / 2)) for gi, wi in zip(g, w, strict=True) for gj, wj in zip(g, w, strict=True)) / 4


def test_disk_hologram_matches_fresnel_quadrature():
    a, z = 0.05, 20.0  # Fresnel number 0.23; paraxial phase error < 2e-3 rad within rho 0.3 mm
    h = ho.record(np.array([[0.0, 0.0, -z]]), 2 * a, sensor_z_mm=0.0, pixel_um=2.0, resolution=(400, 400),
                  oversample=4, guard_mm=0.3)
    x, y = h.pixel_to_world(np.arange(400), 200)
    for c in (200, 215, 230, 260, 300, 350):
        ref = pixel_average(lambda r: fresnel_intensity(r, a, z), x[c], y, 0.002)
        assert h.image[200, c] == pytest.approx(ref, abs=FRESNEL_ABS_TOL)


def test_disk_hologram_matches_fraunhofer_far_field():
    a, z = 0.025, 50.0  # Fresnel number 0.023
    h = ho.record(np.array([[0.0, 0.0, -z]]), 2 * a, sensor_z_mm=0.0, pixel_um=4.0, resolution=(320, 320),
                  oversample=2, guard_mm=2.0)
    x, y = h.pixel_to_world(np.arange(320), 160)
    beta = np.pi * a * a / (WL * z)

    def fraunhofer(rho):
        v = np.maximum(K * a * rho / z, 1e-12)
        A = 2 * special.j1(v) / v
        return 1 - 2 * beta * A * np.sin(K * rho * rho / (2 * z)) + beta**2 * A**2

    for c in (160, 180, 200, 240, 280, 310):
        assert h.image[160, c] == pytest.approx(pixel_average(fraunhofer, x[c], y, 0.004), abs=FRAUNHOFER_ABS_TOL)


def band_limited_field(n=256, dx_mm=0.002, seed=0):
    rng = np.random.default_rng(seed)
    spec = np.zeros((n, n), complex)
    f = np.fft.fftfreq(n, d=dx_mm)
    keep = (np.abs(f)[:, None] < 30) & (np.abs(f)[None, :] < 30)  # well inside 1/lambda and the band limit
    spec[keep] = rng.normal(size=keep.sum()) + 1j * rng.normal(size=keep.sum())
    return np.fft.ifft2(spec)


def test_propagation_conserves_energy_and_returns():
    u = band_limited_field()
    e0 = np.sum(np.abs(u) ** 2)
    v = ho.propagate(u, 3.0, pixel_um=2.0, wavelength_nm=532, pad=False)
    assert np.sum(np.abs(v) ** 2) == pytest.approx(e0, rel=1e-12)
    w = ho.propagate(v, -3.0, pixel_um=2.0, wavelength_nm=532, pad=False)
    np.testing.assert_allclose(w, u, atol=1e-12 * np.abs(u).max())
    # padded (linear convolution): a compact field round-trips in its own support
    c = np.zeros((128, 128), complex)
    c[40:80, 50:70] = 1.0
    back = ho.propagate(ho.propagate(c, 0.5, pixel_um=2.0, wavelength_nm=532), -0.5, pixel_um=2.0, wavelength_nm=532)
    assert np.abs(back - c).max() < PADDED_ROUND_TRIP_ABS_TOL


def test_evanescent_components_are_dropped_not_amplified():
    n, dx = 128, 0.0002  # 0.2 um grid: frequencies up to 2500 /mm > 1/lambda = 1880 /mm
    rng = np.random.default_rng(1)
    u = rng.normal(size=(n, n)) + 1j * rng.normal(size=(n, n))
    f = np.fft.fftfreq(n, d=dx)
    prop = (f[:, None] ** 2 + f[None, :] ** 2) < 1 / WL**2
    U = np.fft.fft2(u)
    e_prop = np.sum(np.abs(U[prop]) ** 2) / u.size
    v = ho.propagate(u, 0.01, pixel_um=0.2, wavelength_nm=532, pad=False, band_limit=False)
    assert np.sum(np.abs(v) ** 2) == pytest.approx(e_prop, rel=1e-10)
    w = ho.propagate(v, -0.02, pixel_um=0.2, wavelength_nm=532, pad=False, band_limit=False)
    assert np.sum(np.abs(w) ** 2) == pytest.approx(e_prop, rel=1e-10)  # back-propagation does not blow up


def test_sampling_checks_and_bad_inputs():
    p = np.array([[0.0, 0.0, -10.0]])
    with pytest.raises(ConfigError, match="oversample"):
        ho.record(p, 0.005, sensor_z_mm=0.0, pixel_um=5.5, resolution=(64, 64), oversample=1)
    with pytest.warns(MitpivWarning, match="alias on the sensor"):
        ho.record(p, 0.008, sensor_z_mm=0.0, pixel_um=5.5, resolution=(64, 64), oversample=4, guard_mm=1.0)
    with pytest.warns(MitpivWarning, match="guard_mm"):
        ho.record(p, 0.05, sensor_z_mm=0.0, pixel_um=5.5, resolution=(64, 64), guard_mm=0.01)
    with pytest.raises(ConfigError, match="before the sensor"):
        ho.record(np.array([[0.0, 0.0, 1.0]]), 0.05, sensor_z_mm=0.0, pixel_um=5.5, resolution=(64, 64))
    with pytest.raises(ConfigError, match="guard_mm"):
        ho.record(p, 0.05, sensor_z_mm=0.0, guard_mm=-1.0)
    with pytest.raises(ConfigError, match="resolution"):
        ho.record(p, 0.05, sensor_z_mm=0.0, resolution=512)
    with pytest.raises(ConfigError, match="plane_tolerance_mm"):
        ho.record(p, 0.05, sensor_z_mm=0.0, plane_tolerance_mm=-0.1)
    with pytest.raises(ConfigError, match="diameters_mm"):
        ho.record(p, None, sensor_z_mm=0.0)
    with pytest.raises(ConfigError, match="wavelength_nm"):
        ho.propagate(np.ones((8, 8)), 1.0, pixel_um=1.0, wavelength_nm=-1)
    with pytest.raises(ConfigError, match="finite"):
        ho.propagate(np.full((8, 8), np.nan), 1.0, pixel_um=1.0, wavelength_nm=532)
    with pytest.raises(ConfigError, match="pixel_um"):
        ho.focal_stack(np.ones((8, 8)), [1.0])
    assert ho.critical_distance_mm(1024, 7.4, 532) == pytest.approx(1024 * 0.0074**2 / WL)
    assert ho.depth_of_focus_mm(0.1, 532) == pytest.approx(0.01 / WL)


def test_focal_stack_against_plain_numpy_and_refocus_of_a_disk():
    h = ho.record(np.array([[0.1, -0.05, -8.0]]), 0.08, sensor_z_mm=0.0, pixel_um=4.0, resolution=(256, 256))
    z = np.linspace(6.0, 10.0, 21)
    st = ho.focal_stack(h, z)
    # plain NumPy: the forward FFT and the full transfer function recomputed per plane
    for k in (0, 10, 20):
        ref = np.abs(np.fft.ifft2(np.fft.fft2(h.image / h.background)
                                  * ho.transfer_function(h.shape, 0.004, -z[k], WL)))
        np.testing.assert_allclose(st[k], ref, atol=COMPLEX64_ATOL)
    det = ho.detect(h, np.arange(6.0, 10.0, 0.02))
    assert len(det) == 1
    err = np.abs(det.positions_mm[0] - [0.1, -0.05, -8.0])
    assert np.all(err[:2] < DISK_LATERAL_TOL_MM) and err[2] < DISK_DEPTH_TOL_MM
    assert det.diameters_mm[0] == pytest.approx(0.08, abs=DISK_SIZE_TOL_MM)


@pytest.fixture(scope="module")
def droplet_hologram():
    rng = np.random.default_rng(3)
    gx, gy = np.meshgrid(np.linspace(-0.6, 0.6, 4), np.linspace(-0.6, 0.6, 4))
    pos = np.column_stack([gx.ravel(), gy.ravel(), -rng.uniform(5, 9, 16)]) + rng.uniform(-0.03, 0.03, (16, 3))
    d = rng.uniform(0.05, 0.12, 16)
    return pos, d, ho.record(pos, d, sensor_z_mm=0.0, pixel_um=3.0, resolution=(600, 600), oversample=2)


def test_droplets_detected_sized_and_depth_against_d2_over_lambda(droplet_hologram):
    from mitpiv.analysis.backlit import evaluate_detections

    pos, d, h = droplet_hologram
    z = np.arange(4.0, 10.0, 0.05)
    det = ho.detect(h, z)
    ev = evaluate_detections(det, pos, d, axis=(0, 0, 1))
    assert ev["detected_fraction"] == 1.0 and ev["n_found"] == 16
    assert ev["size_rms_mm"] < DROPLET_SIZE_RMS_MM
    assert ev["lateral_rms_diameters"] < DROPLET_LATERAL_RMS_DIAMETERS
    # depth: within the d^2 / lambda depth of focus (3-27 mm here), measured ~1 diameter
    err_mm = np.abs(ev["depth_error_diameters"] * d[ev["pairs"][:, 1]])
    assert np.all(err_mm < ho.depth_of_focus_mm(d[ev["pairs"][:, 1]], 532))
    assert ev["depth_rms_diameters"] < DROPLET_DEPTH_RMS_DIAMETERS


def test_sensor_model_edge_cut_and_overlap(droplet_hologram):
    pos, d, h = droplet_hologram
    counts = ho.record(pos, d, sensor_z_mm=0.0, pixel_um=3.0, resolution=(600, 600), oversample=2,
                       sensor=SensorModel(peak_photons=3000, shot_noise=True, gain_e_per_count=12.0, bit_depth=8), seed=1)
    assert counts.image.dtype == np.uint8 and 100 < counts.background < 255
    det = ho.detect(counts, np.arange(4.0, 10.0, 0.1))
    assert len(det) == 16  # the 8-bit noisy hologram still gives every droplet
    # a particle cut by the field edge (0.9 mm half-width) and an overlapping pair
    p2 = np.array([[0.89, 0.0, -6.0], [0.0, 0.0, -6.0], [0.05, 0.0, -7.0]])
    h2 = ho.record(p2, 0.1, sensor_z_mm=0.0, pixel_um=3.0, resolution=(600, 600), oversample=2)
    det2 = ho.detect(h2, np.arange(4.0, 9.0, 0.1))
    assert np.all(np.isfinite(det2.positions_mm))
    assert np.min(np.abs(det2.positions_mm[:, 0] - 0.89)) > 0.05  # the cut one is not reported as whole
    near_pair = np.hypot(det2.positions_mm[:, 0] - 0.025, det2.positions_mm[:, 1]) < 0.1
    assert 1 <= near_pair.sum() <= 2  # the overlapping pair: one merged silhouette or both, no fragments


def test_focal_stack_streams_to_npy(tmp_path, droplet_hologram):
    _, _, h = droplet_hologram
    z = np.linspace(5.0, 6.0, 4)
    mm = ho.focal_stack(h, z, out=tmp_path / "stack.npy")
    np.testing.assert_allclose(np.asarray(mm), ho.focal_stack(h, z), rtol=1e-6)
    with pytest.raises(ConfigError, match="background"):
        ho.focal_stack(h, z, background=0.0)


def test_dih_finds_more_small_droplets_than_plenoptic():
    """Published comparison: DIH resolves more small droplets than a plenoptic camera of the
    same sensor (in-plane resolution of a pixel vs a lenslet). Same field, 3.3 mm sensor."""
    import mitsuba as mi

    from mitpiv.analysis.backlit import evaluate_detections, hybrid_detect
    from mitpiv.lightfield import decode
    from mitpiv.lightfield import focal_stack as lf_stack
    from mitpiv.render.backlit import render_backlit

    rng = np.random.default_rng(5)
    gx, gy = np.meshgrid(np.linspace(-1.2, 1.2, 4), np.linspace(-1.2, 1.2, 4))
    pos = np.column_stack([gx.ravel(), gy.ravel(), rng.uniform(-1.0, 1.0, 16)])
    d = rng.uniform(0.04, 0.09, 16)  # below two refocused plenoptic pixels (110 um)
    h = ho.record(pos - [0, 0, 10.0], d, sensor_z_mm=0.0, pixel_um=5.5, resolution=(600, 600), oversample=3)
    dih = evaluate_detections(ho.detect(h, np.arange(8.0, 12.0, 0.05)), pos - [0, 0, 10.0], d, axis=(0, 0, 1))
    s = {"type": "plenoptic", "pixel_pitch_um": 5.5, "focal_length_mm": 50.0, "f_number": 2.8, "focus_distance_mm": 100.0,
         "mla_pitch_um": 55.0, "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 100], target=[0, 0, 0], up=[0, 1, 0]),
         "film": {"type": "hdrfilm", "width": 600, "height": 600, "pixel_format": "luminance", "rfilter": {"type": "box"}}}
    cam = mi.load_dict({"type": "scene", "sensor": s}).sensors()[0].camera
    white = render_backlit(s, np.zeros((0, 3)), [], spp=16)
    z = np.linspace(-2.0, 2.0, 81)
    lf = decode(render_backlit(s, pos, d, spp=16), optics=cam, white=white)
    st = lf_stack(lf, z)
    bg = lf_stack(decode(white, optics=cam, white=white), z)
    plen = hybrid_detect(st, z, background=bg)
    assert dih["detected_fraction"] >= 0.9
    assert len(plen) < dih["n_matched"]
    assert math.isfinite(dih["depth_rms_diameters"])


def test_weak_phase_objects_conserve_the_beam_energy():
    p = np.array([[0.0, 0.0, -5.0]])
    kw = dict(sensor_z_mm=0.0, pixel_um=2.0, resolution=(256, 256), oversample=2, guard_mm=0.3)
    opaque = ho.record(p, 0.1, **kw).image
    weak = ho.record(p, 0.1, phase_index=1.0005, **kw).image  # k (n - 1) d = 0.59 rad at the centre
    blocked = np.pi * 0.05**2 / (0.512**2)  # disk area over the sensor area
    assert opaque.mean() == pytest.approx(1 - blocked, abs=BEAM_ENERGY_ABS_TOL)
    assert weak.mean() == pytest.approx(1.0, abs=BEAM_ENERGY_ABS_TOL)  # |t| = 1: nothing absorbed
    # a weak phase object leaves a weaker hologram than the opaque disk (contrast ~ 2 x phase)
    assert 0.05 < np.abs(weak - 1).max() < 2 * 0.59 + 0.1
