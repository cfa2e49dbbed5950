"""PSF: Zernike conventions, the Airy limit, aberrations, sampling and bad input.

References are independent of the FFT path: Gauss-Legendre quadrature of the analytic Airy
pattern over each pixel, the closed-form encircled energy 1 - J0^2 - J1^2, the Airy zero
v = 3.8317 (r = 1.2197 lambda N), and the Strehl ratio as a pupil average.
"""

import math

import numpy as np
import pytest
from scipy import special

from mitpiv.errors import ConfigError
from mitpiv.physics import psf as P
from tests.data import read_table

WL = 0.532  # um
N = 2.8
LN = WL * N

# Tolerances and their provenance. Closed forms evaluated in float64 (Zernike polynomials,
# orthonormality under exact Gauss-Legendre quadrature, the Fourier shift of a tilt, mirror
# symmetries) are held to rounding (1e-9 .. 1e-14) inline.
# The FFT PSF against Gauss-Legendre quadrature of the Airy pattern over each pixel: 256 pupil
# samples leave 7e-5 of the peak (measured); 2e-4 of the peak is that with a margin of 3.
AIRY_PIXEL_TOL_OF_PEAK = 2e-4
# Physical pixels (10 um at f/2.8, 64-node quadrature): the centre pixel's and the first
# ring's energy, absolute fractions of the total energy.
AIRY_PIXEL_ENERGY_ABS_TOL = 1e-4
# Encircled energy against the closed form 1 - J0(v)^2 - J1(v)^2: the circle cuts pixels of
# lambda N / 16, whose inside fractions are estimated on 8 x 8 sub-samples.
ENCIRCLED_ENERGY_ABS_TOL = 2e-3
# First dark ring of the Airy pattern: v = 3.8317 (first zero of J1), r = v / pi lambda N.
AIRY_FIRST_ZERO_LN = 1.2197
# Its depth on pixels of lambda N / 40: the true intensity is 0, pixel averaging and the
# position on the pixel grid leave less than this fraction of the peak.
AIRY_DARK_RING_OF_PEAK = 1e-4
# The adaptive window holds at least the closed-form encircled energy of its inscribed circle,
# less this slack (the square window's pixels straddle the circle).
WINDOW_ENERGY_SLACK = 1e-4
# Centre-pixel ratio on pixels of lambda N / 20 against the Strehl ratio |<exp(2 pi i W)>|^2
# (a pupil average): the pixel's finite size makes the ratio an average over the pixel.
STREHL_REL_TOL = 2e-3
# Marechal's exp(-(2 pi sigma)^2) against the pupil-average Strehl ratio for sigma <= 0.05 wave:
# the approximation's error is 1.8e-5 at 0.02 and 7.0e-4 at 0.05 wave (measured).
MARECHAL_REL_TOL = 0.01


def _airy_pixels(size, p, *, f_number=N, offset=(0.0, 0.0), order=24):
    """Airy pattern integrated over each pixel by Gauss-Legendre quadrature (float64)."""
    g, w = np.polynomial.legendre.leggauss(order)
    xs = (np.arange(size) - size // 2) * p
    X = (xs[None, :, None, None] - offset[0] * p) + g[None, None, None, :] * p / 2
    Y = (xs[:, None, None, None] - offset[1] * p) + g[None, None, :, None] * p / 2
    vals = P.airy_intensity(np.hypot(X, Y), f_number=f_number)
    return np.einsum("yxij,i,j->yx", vals, w, w) * (p / 2) ** 2


def _index_table(convention):
    """j -> (n, m) of a published single-index ordering (tests/data/zernike_indices.csv)."""
    return {int(r["j"]): (int(r["n"]), int(r["m"])) for r in read_table("zernike_indices.csv")
            if r["convention"] == convention}


def test_noll_and_ansi_tables():
    noll = _index_table("noll")
    assert sorted(noll) == list(range(1, 16))
    assert {j: P.noll_to_nm(j) for j in noll} == noll
    ansi = _index_table("ansi")
    assert sorted(ansi) == list(range(13))
    assert {j: P.ansi_to_nm(j) for j in ansi} == ansi
    for j in range(200):
        n, m = P.ansi_to_nm(j)
        assert (n * (n + 2) + m) // 2 == j and abs(m) <= n and (n - m) % 2 == 0
    assert sorted(P.noll_to_nm(j) for j in range(1, 67)) == sorted(P.ansi_to_nm(j) for j in range(66))


def test_zernike_orthonormal_and_named_terms():
    # Gauss-Legendre in r (exact for these polynomials) and a uniform grid in theta.
    g, w = np.polynomial.legendre.leggauss(40)
    r = (g + 1) / 2
    wr = w / 2 * r
    t = np.arange(64) * 2 * np.pi / 64
    rr, tt = np.meshgrid(r, t, indexing="ij")
    z = np.stack([P.zernike(j, rr, tt) for j in range(1, 29)])
    gram = np.einsum("iab,jab,a->ij", z, z, wr) * (2 * np.pi / 64) / np.pi
    np.testing.assert_allclose(gram, np.eye(28), atol=1e-12)
    rho = np.linspace(0, 1, 11)
    sa = math.sqrt(5) * (6 * rho**4 - 6 * rho**2 + 1)
    np.testing.assert_allclose(P.zernike(11, rho, 0.3), sa, atol=1e-14)
    np.testing.assert_allclose(P.zernike(12, rho, 0.3, indexing="ansi"), sa, atol=1e-14)
    np.testing.assert_allclose(P.zernike(4, rho, 0.0), math.sqrt(3) * (2 * rho**2 - 1), atol=1e-14)
    # Noll 8 is x coma (cos), Noll 7 y coma (sin).
    np.testing.assert_allclose(P.zernike(8, 1.0, 0.0), math.sqrt(8), atol=1e-12)  # sqrt(8) (3 rho^3 - 2 rho)
    np.testing.assert_allclose(P.zernike(7, 1.0, math.pi / 2), math.sqrt(8), atol=1e-12)  # sqrt(8) (3 rho^3 - 2 rho)
    # A sequence starts at the first index of its convention.
    w1 = P.wavefront([0, 0, 0, 0.1], rho, 0.0)
    np.testing.assert_allclose(w1, 0.1 * P.zernike(4, rho, 0.0))
    np.testing.assert_allclose(P.wavefront([0, 0, 0, 0, 0.1], rho, 0.0, indexing="ansi"), w1)


def test_aberration_free_psf_is_the_pixel_integrated_airy_pattern():
    # Pixels of lambda N / 4 resolve the rings; 256 pupil samples leave 7e-5 of the peak.
    p = LN / 4
    ours = P.psf(f_number=N, pixel_pitch_um=p, size_px=41)
    ref = _airy_pixels(41, p)
    assert np.max(np.abs(ours - ref)) < AIRY_PIXEL_TOL_OF_PEAK * ref.max()
    # Sub-pixel position: the same, moved by (0.3, -0.45) px.
    ours = P.psf(f_number=N, pixel_pitch_um=p, size_px=41, offset_px=(0.3, -0.45))
    ref = _airy_pixels(41, p, offset=(0.3, -0.45))
    assert np.max(np.abs(ours - ref)) < AIRY_PIXEL_TOL_OF_PEAK * ref.max()
    # Physical pixels (10 um at f/2.8): the centre pixel's energy to 1e-4.
    ours = P.psf(f_number=N, pixel_pitch_um=10.0, size_px=5)
    ref = _airy_pixels(5, 10.0, order=64)
    np.testing.assert_allclose(ours, ref, atol=AIRY_PIXEL_ENERGY_ABS_TOL)


def test_encircled_energy_and_first_zero():
    p = LN / 16
    img = P.psf(f_number=N, pixel_pitch_um=p, size_px=141)
    # Fraction of each pixel inside the circle (8x8 sub-samples), float64.
    c = (np.arange(141) - 70) * p
    s = ((np.arange(8) + 0.5) / 8 - 0.5) * p
    X = c[None, :, None, None] + s[None, None, None, :]
    Y = c[:, None, None, None] + s[None, None, :, None]
    R = np.hypot(X, Y)
    for v in (special.jn_zeros(1, 1)[0], special.jn_zeros(1, 2)[1], 5.0, special.jn_zeros(1, 3)[2]):
        r = v * LN / math.pi
        frac = np.mean(R <= r, axis=(2, 3))
        ee = np.sum(img * frac)
        assert ee == pytest.approx(P.airy_encircled_energy(r, f_number=N), abs=ENCIRCLED_ENERGY_ABS_TOL), v
    # The first dark ring along the central row, with pixels of lambda N / 40.
    p = LN / 40
    img = P.psf(f_number=N, pixel_pitch_um=p, size_px=161)
    row = img[80, 80:]
    x = np.arange(row.size) * p
    sel = (x > 1.0 * LN) & (x < 1.5 * LN)
    r0 = x[sel][np.argmin(row[sel])]
    assert r0 == pytest.approx(AIRY_FIRST_ZERO_LN * LN, abs=p)  # one pixel: the sampling
    assert row[sel].min() < AIRY_DARK_RING_OF_PEAK * row[0]


def test_energy_normalisation_and_window():
    res = P.psf_details(f_number=N, pixel_pitch_um=10.0)
    assert res.captured_energy == pytest.approx(res.image.sum())
    # The window holds the energy inside it: at least EE of the inscribed circle.
    r_in = (res.size_px / 2) * 10.0
    assert res.captured_energy >= P.airy_encircled_energy(r_in, f_number=N) - WINDOW_ENERGY_SLACK
    assert res.captured_energy < 1.0
    big = P.psf(f_number=N, pixel_pitch_um=10.0, size_px=81)
    assert 0.999 < big.sum() < 1.0
    win = P.psf(f_number=N, pixel_pitch_um=10.0, normalize="window")
    assert win.sum() == pytest.approx(1.0, abs=1e-12)
    # Smaller tolerance, larger window.
    assert P.psf_details(f_number=N, pixel_pitch_um=10.0, energy_tolerance=1e-3).size_px > res.size_px


def test_tilt_moves_the_image_and_offset_is_a_shift():
    # W = c Z2 = 2 c rho cos(theta): stationary phase puts the image at x = 2 lambda N dW/drho = 4 c lambda N.
    p = LN / 4
    c = 0.25
    tilted = P.psf(f_number=N, pixel_pitch_um=p, size_px=41, zernike_coefficients={2: c})
    shifted = P.psf(f_number=N, pixel_pitch_um=p, size_px=41, offset_px=(4 * c * LN / p, 0.0))
    np.testing.assert_allclose(tilted, shifted, atol=1e-9 * shifted.max())
    tilted_y = P.psf(f_number=N, pixel_pitch_um=p, size_px=41, zernike_coefficients={3: c})
    np.testing.assert_allclose(tilted_y, shifted.T, atol=1e-9 * shifted.max())
    # A whole-pixel offset moves the array by one column / row.
    a = P.psf(f_number=N, pixel_pitch_um=2.0, size_px=31)
    b = P.psf(f_number=N, pixel_pitch_um=2.0, size_px=31, offset_px=(1.0, -2.0))
    np.testing.assert_allclose(b[:-2, 1:], a[2:, :-1], atol=1e-12)


def test_working_f_number_and_symmetry():
    a = P.psf(f_number=4.0, pixel_pitch_um=5.0, magnification=-1.0)
    b = P.psf(f_number=8.0, pixel_pitch_um=5.0)
    np.testing.assert_allclose(a, b, atol=1e-14)
    assert P.working_f_number(2.8, 0.25) == pytest.approx(3.5)
    # x coma (Noll 8): mirror symmetric about the x axis, not about the y axis.
    coma = P.psf(f_number=N, pixel_pitch_um=LN / 3, size_px=41, zernike_coefficients={8: 0.2})
    np.testing.assert_allclose(coma, coma[::-1, :], atol=1e-12 * coma.max())
    assert np.max(np.abs(coma - coma[:, ::-1])) > 0.05 * coma.max()
    # Rotationally symmetric terms: 90-degree rotation leaves the PSF unchanged.
    sym = P.psf(f_number=N, pixel_pitch_um=LN / 3, size_px=41, defocus_waves=0.3, spherical_waves=0.1)
    np.testing.assert_allclose(sym, np.rot90(sym), atol=1e-12 * sym.max())


@pytest.mark.parametrize("sa", [0.02, 0.05, 0.10])
def test_peak_follows_the_strehl_ratio(sa):
    # Tiny pixels: the centre pixel's energy ratio is the Strehl ratio |<exp(2 pi i W)>|^2.
    p = LN / 20
    a = P.psf(f_number=N, pixel_pitch_um=p, size_px=9, spherical_waves=sa)
    b = P.psf(f_number=N, pixel_pitch_um=p, size_px=9)
    assert a[4, 4] / b[4, 4] == pytest.approx(P.strehl_ratio(spherical_waves=sa), rel=STREHL_REL_TOL)
    # Marechal's approximation holds for small aberration.
    if sa <= 0.05:
        assert P.strehl_ratio(spherical_waves=sa) == pytest.approx(math.exp(-(2 * math.pi * sa) ** 2), rel=MARECHAL_REL_TOL)


def test_spherical_aberration_table_f2p8_10um():
    """Centre pixel and first/second rings for RMS spherical aberration 0-0.1 waves."""
    rows = [P.ring_energies(P.psf(f_number=2.8, pixel_pitch_um=10.0, spherical_waves=sa)) for sa in (0, 0.02, 0.05, 0.1)]
    centre = [r[0] for r in rows]
    ring1 = [r[1] for r in rows]
    assert centre == sorted(centre, reverse=True) and ring1 == sorted(ring1)
    # The aberration-free row against quadrature of the Airy pattern.
    ref = _airy_pixels(5, 10.0, order=64)
    assert rows[0][0] == pytest.approx(ref[2, 2], abs=AIRY_PIXEL_ENERGY_ABS_TOL)
    assert rows[0][1] == pytest.approx(ref[1:4, 1:4].sum() - ref[2, 2], abs=AIRY_PIXEL_ENERGY_ABS_TOL)
    # Energy moves out, not away: centre + rings change by less than the ring-2 tail.
    assert abs(sum(rows[3]) - sum(rows[0])) < 0.01


def test_hard_cases():
    # Tiny f-number: the PSF is far narrower than a pixel.
    tiny = P.psf(f_number=0.7, pixel_pitch_um=20.0)
    assert tiny[tiny.shape[0] // 2, tiny.shape[1] // 2] > 0.99
    # Huge f-number: the window grows to hold the pattern.
    huge = P.psf_details(f_number=64, pixel_pitch_um=5.0)
    assert huge.size_px > 200 and huge.captured_energy > 0.99
    # Large aberration: the pupil sampling adapts (1/8 wave per sample at most)...
    big = P.psf_details(f_number=N, pixel_pitch_um=10.0, spherical_waves=2.0)
    assert big.max_phase_step_waves <= 0.125 and big.pupil_samples > P.MIN_PUPIL_SAMPLES
    assert big.captured_energy > 0.99
    # ... or fails clearly when it would need too many samples.
    with pytest.raises(ConfigError, match="max_pupil_samples"):
        P.psf(f_number=N, pixel_pitch_um=10.0, spherical_waves=50.0)
    with pytest.raises(ConfigError, match="phase wraps"):
        P.psf(f_number=N, pixel_pitch_um=10.0, spherical_waves=5.0, pupil_samples=64)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"f_number": 0.0}, "f_number"),
        ({"pixel_pitch_um": -5.0}, "pixel_pitch_um"),
        ({"wavelength_nm": float("nan")}, "wavelength_nm"),
        ({"zernike_coefficients": {0: 0.1}}, "Noll indices start at 1"),
        ({"zernike_coefficients": {4: float("inf")}}, "finite"),
        ({"indexing": "zemax", "zernike_coefficients": {4: 0.1}}, "indexing"),
        ({"size_px": 0}, "size_px"),
        ({"offset_px": (1.0,)}, "offset_px"),
        ({"normalize": "peak"}, "normalize"),
        ({"magnification": float("nan")}, "magnification"),
        ({"energy_tolerance": 0.0}, "energy_tolerance"),
    ],
)
def test_bad_input(kwargs, match):
    args = {"f_number": N, "pixel_pitch_um": 10.0, **kwargs}
    with pytest.raises(ConfigError, match=match):
        P.psf(**args)
