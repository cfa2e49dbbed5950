"""Mie scattering (mitpiv.physics.mie) against an independent library and closed forms.

References:
* scattnlay 2.4 (Pena & Pal 2009), an independent implementation (n + ik, Bohren & Huffman
  amplitudes, as ours). It loses Qext and S2 at x <~ 1e-3 to cancellation (measured: 60 %
  off at x = 1e-4 against the Rayleigh closed form), so it is used for x >= 1e-2 only.
* Closed forms: Rayleigh (small x), anomalous diffraction (van de Hulst, |m - 1| << 1,
  x >> 1), Rayleigh-Gans-Debye angular shape (|m - 1| << 1, 2x|m - 1| << 1).
* Conservation: the optical theorem, Qabs >= 0 (= 0 without absorption), the phase
  function integrating to 1 (Gauss-Legendre on panels 1/x wide), |g| <= 1.
* The phase tables: miepython called directly (tests/physics/mie_reference.py), at the deep
  minima located numerically on it.
"""

import math

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.physics import mie
from tests.physics.mie_reference import deep_minima, miepython_par_per

# the hard cases: water/DEHS/polystyrene/TiO2-like, bubble, near-1, absorbing, metal-like
INDICES = [1.33, 1.45, 1.59, 2.5, 0.75, 1.0001, 1.5 + 0.01j, 1.5 + 1j, 0.2 + 3j]
LAMBDA = 500.0

# Tolerances and their provenance. Identities of one float64 computation (S1 = S2 at 0 deg,
# Qext = Qsca + Qabs, the size parameter) stay inline at 1e-12.
# scattnlay 2.4 and ours both sum the Bohren & Huffman series to convergence (~1e-12); 1e-8
# leaves room for the two libraries' different term counts and recurrences at x <= 1e4.
EFFICIENCY_REL_TOL_VS_SCATTNLAY = 1e-8  # Qext, Qsca
EFFICIENCY_ABS_FLOOR = 1e-14  # Q ~ x^4 ~ 1e-8 at x = 0.01: an absolute floor far below it
G_ABS_TOL_VS_SCATTNLAY = 1e-8  # asymmetry parameter, |g| <= 1: the same series accuracy
# Qback and S(theta) are sums truncated at Wiscombe's term count N = x + 4.05 x^(1/3) + 2,
# which leaves up to ~1e-6 in Qback and S(180) (shared/REFERENCE.md, Mie section); 1e-5 is that
# error with a margin of 10. The same bound covers Qback = 4 |S(180)|^2 / x^2.
QBACK_REL_TOL = 1e-5
# S1, S2 at 7 angles vs scattnlay, absolute on the scale of the forward amplitude |S(0)|
# (backward amplitudes are orders of magnitude smaller, so a relative bound per angle would
# test the truncation error of the smallest values): the term-count error above with a margin.
AMPLITUDE_TOL_VS_SCATTNLAY = 2e-5  # x <= 1000, x |S(0)|
AMPLITUDE_TOL_VS_SCATTNLAY_X1E4 = 1e-5  # x = 1e4 (one index), x |S(0)|
# Rayleigh closed forms (Qsca = 8/3 x^4 |K|^2, ...): the next terms are O(x^2) relative, larger
# by ~|m|^2 for high or metal-like indices; tolerance = factor * x^2 * max(1, |m|^2).
RAYLEIGH_NEXT_ORDER_FACTOR = 10
# Extinction paradox Qext -> 2: the approach is ~x^(-2/3) (2.2e-3 at x = 1e4) times an O(1)
# edge-term coefficient, plus ripple; 0.02 is a margin of several on that estimate.
EXTINCTION_PARADOX_ABS_TOL = 0.02
# van de Hulst's anomalous diffraction Qext: its error is O(|m - 1|) + O(1/x), both <= 1e-3 in
# the cases tested; 5e-3 is that with a margin of 2.5-5.
ADT_REL_TOL = 5e-3
# Rayleigh-Gans-Debye angular shape at m = 1.0001: error O(2 x |m - 1|) <= 1.6e-3 at x = 8.
RGD_REL_TOL = 5e-3
# The phase function integrates to 1 (B&H normalisation); Gauss-Legendre on panels narrower
# than the 1/x ripple resolves the integral to far better than 1e-6.
NORMALISATION_ABS_TOL = 1e-6
# Optical theorem Qext = 4 Re S(0) / x^2 (Bohren & Huffman): the Qext series and the S(0) sum are
# two float64 sums of the same coefficients, equal to summation rounding.
OPTICAL_THEOREM_REL_TOL = 1e-9
# 1 um DEHS (m = 1.45) in air at 532 nm: shared/REFERENCE.md quotes Qsca 3.52, g 0.71,
# p(0)/p(180) ~ 96, p(0)/p(90) ~ 150 (unpolarised). miepython 3.3.0 gives 3.5198, 0.7097,
# 94.90, 148.15 (measured with miepython.efficiencies_mx and i_unpolarized). The efficiency
# bound is the 2-decimal rounding of the quoted values (+-0.005) with a margin of 2; the
# ratio bound covers the "~" of the quoted ratios (miepython: 1.1 % and 1.2 % below them).
DEHS_QSCA, DEHS_G, DEHS_P0_P180, DEHS_P0_P90 = 3.52, 0.71, 96.0, 150.0
DEHS_EFFICIENCY_ABS_TOL = 0.01
DEHS_RATIO_REL_TOL = 0.03
# mie.lognormal's trapezoid nodes (161 over +-6 sigma of ln d) against the closed-form moment
# E[d^2] = d_g^2 exp(2 s^2), s = ln(sigma_g): the trapezoid rule is spectrally accurate for a
# Gaussian and the tails cut beyond 6 sigma (shifted by 2 s for d^2) hold ~1e-8.
LOGNORMAL_MOMENT_REL_TOL = 1e-6
# The phase table against the float64 phase function: relative L1 error of the finest
# table (4096 nodes) at random angles, half of them in the 3/x forward peak; a resolution
# requirement (no external reference), the error falls with the node count.
PHASE_TABLE_L1_TOL = 0.01
# A fixed table holds the float64 phase function at its (float32) nodes: the same series at
# cosines that differ by the degree round trip (~1e-16 rad) times p's log-slope (~x <= 5000).
TABLE_NODE_REL_TOL = 1e-10
# The default table's stated accuracy (mie_phase docstring, mie.phase_table): relative, at
# every angle, the deep minima included, above an absolute floor of 1e-10 of the peak. The
# table is checked against miepython called here, not through mitpiv; no extra allowance:
# the interpolant is evaluated in float64 exactly as tabulated.
DEFAULT_TABLE_REL_TOL = mie.TABLE_TOLERANCE
DEFAULT_TABLE_FLOOR = mie.TABLE_FLOOR
# A minimum counts as deep when it is below 1e-2 of the largest value within two ripple
# periods (pi/x) around it; the former default (1024 angles) was 100 % off at such minima.
DEEP_MINIMUM_DEPTH = 1e-2


def diam(x, n_medium=1.0):
    """Diameter [um] for a size parameter at LAMBDA."""
    return x * LAMBDA / (math.pi * n_medium) * 1e-3


def scattnlay_ref(x, m, theta):
    from scattnlay import scattnlay

    _, qext, qsca, qabs, qback, _, g, _, s1, s2 = scattnlay(np.array([x]), np.array([complex(m)]), theta)
    return qext, qsca, qback, g, s1, s2


@pytest.mark.parametrize("m", INDICES, ids=str)
@pytest.mark.parametrize("x", [0.01, 0.3, 1.0, 10.0, 100.0, 1000.0])
def test_against_scattnlay(m, x):
    theta_deg = np.array([0.0, 10.0, 45.0, 90.0, 135.0, 170.0, 180.0])
    e = mie.efficiencies(diam(x), m, wavelength_nm=LAMBDA)
    s1, s2 = mie.amplitudes(diam(x), m, theta_deg, wavelength_nm=LAMBDA)
    qext, qsca, qback, g, r1, r2 = scattnlay_ref(x, m, np.radians(theta_deg))
    assert e.x == pytest.approx(x, rel=1e-12)
    # efficiencies: both series converge to ~1e-12; Qback and S carry Wiscombe's term-count error (~1e-6)
    assert e.qext == pytest.approx(qext, rel=EFFICIENCY_REL_TOL_VS_SCATTNLAY, abs=EFFICIENCY_ABS_FLOOR)
    assert e.qsca == pytest.approx(qsca, rel=EFFICIENCY_REL_TOL_VS_SCATTNLAY, abs=EFFICIENCY_ABS_FLOOR)
    assert e.g == pytest.approx(g, abs=G_ABS_TOL_VS_SCATTNLAY)
    assert e.qback == pytest.approx(qback, rel=QBACK_REL_TOL, abs=EFFICIENCY_ABS_FLOOR)
    scale = abs(r1[0])
    np.testing.assert_allclose(s1, r1, rtol=0, atol=AMPLITUDE_TOL_VS_SCATTNLAY * scale)
    np.testing.assert_allclose(s2, r2, rtol=0, atol=AMPLITUDE_TOL_VS_SCATTNLAY * scale)


def test_against_scattnlay_at_x_1e4():
    x, m = 1e4, 1.45 + 0.01j
    e = mie.efficiencies(diam(x), m, wavelength_nm=LAMBDA)
    qext, qsca, qback, g, r1, _ = scattnlay_ref(x, m, np.radians([0.0, 1.0, 90.0, 180.0]))
    s1, _ = mie.amplitudes(diam(x), m, [0.0, 1.0, 90.0, 180.0], wavelength_nm=LAMBDA)
    assert (e.qext, e.qsca, e.g) == pytest.approx((qext, qsca, g), rel=EFFICIENCY_REL_TOL_VS_SCATTNLAY)
    assert e.qback == pytest.approx(qback, rel=QBACK_REL_TOL)
    np.testing.assert_allclose(s1, r1, atol=AMPLITUDE_TOL_VS_SCATTNLAY_X1E4 * abs(r1[0]))


@pytest.mark.parametrize("m", INDICES, ids=str)
@pytest.mark.parametrize("x", [1e-4, 1e-3])
def test_rayleigh_limit(m, x):
    """Qsca = 8/3 x^4 |K|^2, Qabs = 4 x Im K, Qback = 4 x^4 |K|^2 and p = 3/(16 pi)(1 + cos^2),
    K = (m^2 - 1)/(m^2 + 2); next terms are O(x^2) relative (1e-6 at x = 1e-3)."""
    K = (m**2 - 1) / (m**2 + 2)
    e = mie.efficiencies(diam(x), m, wavelength_nm=LAMBDA)
    tol = RAYLEIGH_NEXT_ORDER_FACTOR * x**2 * max(1.0, abs(m) ** 2)
    assert e.qsca == pytest.approx(8 / 3 * x**4 * abs(K) ** 2, rel=tol)
    assert e.qback == pytest.approx(4 * x**4 * abs(K) ** 2, rel=tol)
    if complex(m).imag > 0:
        assert e.qabs == pytest.approx(4 * x * K.imag, rel=tol)
    th = np.linspace(0, 180, 13)
    mu = np.cos(np.radians(th))
    np.testing.assert_allclose(mie.phase_function(diam(x), m, th, wavelength_nm=LAMBDA), 3 / (16 * np.pi) * (1 + mu**2), rtol=tol)
    par, per = mie.polarized_intensities(diam(x), m, th, wavelength_nm=LAMBDA)
    np.testing.assert_allclose(per, 3 / (8 * np.pi), rtol=tol)
    np.testing.assert_allclose(par, 3 / (8 * np.pi) * mu**2, rtol=tol, atol=tol * 3 / (8 * np.pi))


@pytest.mark.parametrize("m", [1.33, 1.59, 2.5, 0.75, 1.5 + 0.01j, 1.5 + 1j, 0.2 + 3j], ids=str)
def test_large_particle_extinction_paradox(m):
    """Qext -> 2 (diffraction + geometric shadow); the approach is ~x^(-2/3)."""
    e = mie.efficiencies(diam(1e4), m, wavelength_nm=LAMBDA)
    assert abs(e.qext - 2) < EXTINCTION_PARADOX_ABS_TOL


@pytest.mark.parametrize("m, x", [(1.0001, 1e4), (1.001, 1000.0), (1.0003, 5000.0)])
def test_anomalous_diffraction_near_one(m, x):
    """van de Hulst: Qext = 2 - 4 sin(rho)/rho + 4 (1 - cos rho)/rho^2, rho = 2x(m-1),
    for |m - 1| << 1 and x >> 1; its error is O(|m-1|) + O(1/x)."""
    rho = 2 * x * (m - 1)
    adt = 2 - 4 / rho * math.sin(rho) + 4 / rho**2 * (1 - math.cos(rho))
    assert mie.efficiencies(diam(x), m, wavelength_nm=LAMBDA).qext == pytest.approx(adt, rel=ADT_REL_TOL)


@pytest.mark.parametrize("x", [0.5, 3.0, 8.0])
def test_rayleigh_gans_shape_near_one(x):
    """m = 1.0001: p(theta) ~ (1 + cos^2) G(u)^2, G = 3 (sin u - u cos u)/u^3, u = 2x sin(theta/2);
    relative error O(2x|m-1|) <= 2e-3."""
    m = 1.0001
    th = np.linspace(0.0, 180.0, 181)
    u = 2 * x * np.sin(np.radians(th) / 2)
    with np.errstate(invalid="ignore", divide="ignore"):
        G = np.where(u > 1e-3, 3 * (np.sin(u) - u * np.cos(u)) / u**3, 1 - u**2 / 10)
    ref = (1 + np.cos(np.radians(th)) ** 2) * G**2
    ours = mie.phase_function(diam(x), m, th, wavelength_nm=LAMBDA)
    ratio = ours / ours[0] / (ref / ref[0])
    keep = ref / ref[0] > 1e-3  # away from the zeros of G
    np.testing.assert_allclose(ratio[keep], 1.0, rtol=RGD_REL_TOL)


def _sphere_integral(x, m, panel_width=1.0, nodes=6):
    """Integral of the phase function over the sphere: Gauss-Legendre on panels narrower than
    the ripples (period ~ pi / x)."""
    npan = max(16, int(math.ceil(math.pi / (panel_width / max(x, 1.0)))))
    g, w = np.polynomial.legendre.leggauss(nodes)
    edges = np.linspace(0, math.pi, npan + 1)
    half = (edges[1:] - edges[:-1])[:, None] / 2
    th = ((edges[:-1, None] + edges[1:, None]) / 2 + half * g).ravel()
    ww = (half * w).ravel()
    p = mie.phase_function(diam(x), m, np.degrees(th), wavelength_nm=LAMBDA)
    return 2 * math.pi * np.sum(p * np.sin(th) * ww)


@pytest.mark.parametrize("m", INDICES, ids=str)
@pytest.mark.parametrize("x", [1e-4, 0.5, 5.0, 50.0, 500.0])
def test_phase_function_is_normalised(m, x):
    assert _sphere_integral(x, m) == pytest.approx(1.0, abs=NORMALISATION_ABS_TOL)


def test_phase_function_is_normalised_at_x_1e4():
    assert _sphere_integral(1e4, 1.33, panel_width=2.0, nodes=4) == pytest.approx(1.0, abs=NORMALISATION_ABS_TOL)


@pytest.mark.parametrize("m", INDICES, ids=str)
@pytest.mark.parametrize("x", [1e-4, 0.07, 0.1, 1.0, 10.0, 100.0, 1000.0, 1e4])
def test_conservation_and_exact_angles(m, x):
    """Optical theorem, Qabs >= 0, |g| <= 1, finite at exactly 0 and 180 deg, S1 = S2 at 0,
    S1 = -S2 at 180 (B&H), Qback = 4 |S(180)|^2 / x^2."""
    e = mie.efficiencies(diam(x), m, wavelength_nm=LAMBDA)
    s1, s2 = mie.amplitudes(diam(x), m, [0.0, 180.0], wavelength_nm=LAMBDA)
    vals = [e.qext, e.qsca, e.qabs, e.qback, e.g, *s1, *s2]
    assert np.all(np.isfinite(vals))
    assert e.qext == pytest.approx(4 / x**2 * s1[0].real, rel=OPTICAL_THEOREM_REL_TOL)
    assert e.qback == pytest.approx(4 / x**2 * abs(s1[1]) ** 2, rel=QBACK_REL_TOL)
    assert s1[0] == pytest.approx(s2[0], rel=1e-12)
    assert s1[1] == pytest.approx(-s2[1], rel=1e-12)
    assert e.qsca > 0 and e.qabs >= 0 and -1 <= e.g <= 1
    if complex(m).imag == 0:
        assert e.qabs == 0.0
    else:
        assert e.qext == pytest.approx(e.qsca + e.qabs, rel=1e-12)
    assert e.csca_mm2 == pytest.approx(e.qsca * math.pi / 4 * (diam(x) * 1e-3) ** 2, rel=1e-12)


def test_medium_and_wavelength_enter_through_x_and_m():
    """A polyamide particle (1.5) in water (1.333) is the relative index 1.125 at x = pi d n / lambda."""
    a = mie.efficiencies(2.0, 1.5, wavelength_nm=532, n_medium=1.333)
    b = mie.efficiencies(2.0 * 1.333, 1.5 / 1.333, wavelength_nm=532)
    assert a.x == pytest.approx(math.pi * 2000 * 1.333 / 532)
    assert (a.qext, a.qsca, a.g) == pytest.approx((b.qext, b.qsca, b.g), rel=1e-12)


def test_pivot_values_for_dehs():
    """1 um DEHS (1.45) in air at 532 nm, values from miepython's documentation-level facts in
    shared/REFERENCE.md: Qsca 3.52, g 0.71, p(0)/p(180) ~ 96, p(0)/p(90) ~ 150 (see DEHS_*)."""
    e = mie.efficiencies(1.0, 1.45, wavelength_nm=532)
    p = mie.phase_function(1.0, 1.45, [0.0, 90.0, 180.0], wavelength_nm=532)
    assert e.qsca == pytest.approx(DEHS_QSCA, abs=DEHS_EFFICIENCY_ABS_TOL)
    assert e.g == pytest.approx(DEHS_G, abs=DEHS_EFFICIENCY_ABS_TOL)
    assert p[0] / p[2] == pytest.approx(DEHS_P0_P180, rel=DEHS_RATIO_REL_TOL)
    assert p[0] / p[1] == pytest.approx(DEHS_P0_P90, rel=DEHS_RATIO_REL_TOL)


def test_size_distribution_averages():
    dist = mie.lognormal(1.0, 1.3)
    s = math.log(1.3)
    # quadrature reproduces the log-normal moments
    assert np.sum(dist.weights * dist.diameters_um**2) == pytest.approx(math.exp(2 * s * s), rel=LOGNORMAL_MOMENT_REL_TOL)
    e = mie.efficiencies(dist, 1.45, wavelength_nm=532)
    each = mie.efficiencies(dist.diameters_um, 1.45, wavelength_nm=532)
    assert e.csca_mm2 == pytest.approx(np.sum(dist.weights * each.csca_mm2), rel=1e-12)
    assert e.g == pytest.approx(np.sum(dist.weights * each.csca_mm2 * each.g) / e.csca_mm2, rel=1e-12)
    th = np.array([0.0, 30.0, 90.0, 150.0, 180.0])
    p = mie.phase_function(dist, 1.45, th, wavelength_nm=532)
    ref = sum(w * c * mie.phase_function(d, 1.45, th, wavelength_nm=532)
              for d, w, c in zip(dist.diameters_um, dist.weights, each.csca_mm2, strict=True)) / e.csca_mm2
    np.testing.assert_allclose(p, ref, rtol=1e-10)
    # the averaged phase function stays normalised
    assert _sphere_integral_dist(dist) == pytest.approx(1.0, abs=NORMALISATION_ABS_TOL)
    narrow = mie.SizeDistribution([1.0, 1.0], [0.3, 0.7])
    np.testing.assert_allclose(mie.phase_function(narrow, 1.45, th, wavelength_nm=532),
                               mie.phase_function(1.0, 1.45, th, wavelength_nm=532), rtol=1e-12)


def _sphere_integral_dist(dist):
    g, w = np.polynomial.legendre.leggauss(6)
    edges = np.linspace(0, math.pi, 201)
    half = (edges[1:] - edges[:-1])[:, None] / 2
    th = ((edges[:-1, None] + edges[1:, None]) / 2 + half * g).ravel()
    p = mie.phase_function(dist, 1.45, np.degrees(th), wavelength_nm=532)
    return 2 * math.pi * np.sum(p * np.sin(th) * (half * w).ravel())


@pytest.mark.parametrize("x", [5.0, 200.0, 5000.0])
def test_phase_table_interpolation_and_cache(x):
    """A fixed table holds the exact phase function at its nodes, its piecewise-linear
    interpolant converges to it (L1) and integrates to 1 ever more closely as the resolution
    grows, and tables are cached by their parameters."""
    d = diam(x)
    rng = np.random.default_rng(2)
    th = np.degrees(np.concatenate([rng.uniform(0, 3 / x, 200), rng.uniform(0, math.pi, 200)]))
    exact = mie.phase_function(d, 1.45, th, wavelength_nm=LAMBDA)
    errs, norm = [], []
    for n in (256, 1024, 4096):
        t = mie.phase_table(d, 1.45, wavelength_nm=LAMBDA, angles=n)
        assert t.angles == n and t.tolerance is None and np.isfinite(t.max_error)
        assert t.theta[-1] == 0.0 and t.theta[0] == pytest.approx(math.pi) and np.all(np.diff(t.mu) > 0)
        np.testing.assert_allclose(t.phase[0], mie.phase_function(d, 1.45, np.degrees(t.theta), wavelength_nm=LAMBDA),
                                   rtol=TABLE_NODE_REL_TOL)
        p = t.phase[0]  # the trapezoid rule over mu: the piecewise-linear interpolant's integral
        norm.append(abs(2 * math.pi * np.sum(0.5 * (p[1:] + p[:-1]) * np.diff(t.mu)) - 1.0))
        interp = np.interp(np.cos(np.radians(th)), t.mu, t.phase[0])
        errs.append(np.sum(np.abs(interp - exact)) / np.sum(exact))
        assert mie.phase_table(d, 1.45, wavelength_nm=LAMBDA, angles=n) is t
    assert errs[2] < errs[0] and errs[2] < PHASE_TABLE_L1_TOL, errs
    assert norm[2] < norm[0], norm


def table_rel_error(t, theta, d_um):
    """Largest relative error (floored) of the table's interpolants, linear in theta as the
    renderer evaluates them, against miepython at ``theta`` [rad]."""
    par, per = miepython_par_per(d_um, theta)
    floor = DEFAULT_TABLE_FLOOR * max(par.max(), per.max())
    asc = t.theta[::-1]
    e = [np.abs(np.interp(theta, asc, tab[0][::-1]) - ref) / (ref + floor) for tab, ref in ((t.p_par, par), (t.p_per, per))]
    return np.maximum(*e)


@pytest.mark.parametrize("d_um, n_deep", [(5.0, 8), (20.0, 24)], ids=["5um", "20um"])
def test_default_table_within_tolerance_at_every_angle_and_deep_minima(d_um, n_deep):
    """A 5 um and a 20 um DEHS droplet in air at 532 nm: the default table is within its
    stated relative tolerance of miepython on a dense grid and at (and around) every deep
    minimum of p_par and p_per, located numerically; the former default, 1024 fixed angles,
    misses the same minima by far more (so the check has teeth)."""
    minima = deep_minima(d_um, DEEP_MINIMUM_DEPTH)
    assert len(minima) >= n_deep, len(minima)
    t0, w = minima[:, 0], minima[:, 1]
    around = (t0[:, None] + w[:, None] * np.array([-3, -1, -0.3, 0, 0.3, 1, 3])).ravel()
    dense = np.linspace(0.0, math.pi, 200001)
    t = mie.phase_table(d_um, 1.45)
    assert t.tolerance == DEFAULT_TABLE_REL_TOL and t.max_error <= DEFAULT_TABLE_REL_TOL
    e_min, e_dense = table_rel_error(t, around, d_um), table_rel_error(t, dense, d_um)
    assert e_min.max() <= DEFAULT_TABLE_REL_TOL, (around[np.argmax(e_min)], e_min.max())
    assert e_dense.max() <= DEFAULT_TABLE_REL_TOL, (dense[np.argmax(e_dense)], e_dense.max())
    old = mie.phase_table(d_um, 1.45, angles=1024)
    assert table_rel_error(old, around, d_um).max() > 100 * DEFAULT_TABLE_REL_TOL


@pytest.mark.parametrize("tolerance", [1e-2, 1e-4])
def test_table_tolerance_is_the_knob(tolerance):
    """The node count follows x / sqrt(tolerance) (within the estimate used to refuse costly
    tables) and the error follows the tolerance, for a 5 um droplet."""
    t = mie.phase_table(5.0, 1.45, tolerance=tolerance)
    default = mie.phase_table(5.0, 1.45)
    assert (t.angles < default.angles) == (tolerance > DEFAULT_TABLE_REL_TOL)
    assert t.angles <= mie.adaptive_angles_estimate(mie.size_parameter(5.0), tolerance)
    dense = np.linspace(0.0, math.pi, 100001)
    assert table_rel_error(t, dense, 5.0).max() <= tolerance


def test_table_of_a_distribution_and_of_several_diameters():
    """A log-normal distribution's averaged row meets the tolerance against the number- and
    C_sca-weighted miepython average; a per-particle table takes the grid of its largest
    diameter, on which that row meets it."""
    dist = mie.lognormal(5.0, 1.05, nodes=21, span=3.0)
    t = mie.phase_table(dist, 1.45)
    th = np.linspace(0.0, math.pi, 50001)
    par, per, c = np.zeros_like(th), np.zeros_like(th), 0.0
    for d, w in zip(dist.diameters_um, dist.weights, strict=True):
        csca = mie.efficiencies(d, 1.45).csca_mm2  # C_sca weighting (the reference is miepython's p)
        a, b = miepython_par_per(d, th)
        par, per, c = par + w * csca * a, per + w * csca * b, c + w * csca
    par, per = par / c, per / c
    floor = DEFAULT_TABLE_FLOOR * par.max()
    asc = t.theta[::-1]
    for tab, ref in ((t.p_par, par), (t.p_per, per)):
        assert np.max(np.abs(np.interp(th, asc, tab[0][::-1]) - ref) / (ref + floor)) <= DEFAULT_TABLE_REL_TOL
    rows = mie.phase_table(np.array([3.0, 4.0, 5.0]), 1.45)
    single = mie.phase_table(5.0, 1.45)
    np.testing.assert_array_equal(rows.theta, single.theta)
    np.testing.assert_array_equal(rows.p_par[2], single.p_par[0])
    assert table_rel_error(single, th, 5.0).max() <= DEFAULT_TABLE_REL_TOL


@pytest.mark.parametrize(
    "kw, match",
    [
        ({"angles": 10**8}, r"'angles' must be an integer >= 16 and <= 4194304, got 100000000"),
        ({"angles": 4096.5}, r"'angles' must be an integer"),
        ({"angles": 1 << 22, "diameter_um": np.linspace(1.0, 3.0, 400)}, r"'angles' = 4194304 needs about .* GiB"),
        ({"tolerance": 0.0}, r"'tolerance' \(relative\) must lie in \[1e-06, 0.1\], got 0.0"),
        ({"tolerance": 1e-6, "diameter_um": 1000.0}, r"within the relative 'tolerance' 1e-06 needs about .* s to build"),
    ],
    ids=["absurd_angles", "fractional_angles", "too_much_memory", "zero_tolerance", "too_slow"],
)
def test_table_settings_refused_up_front(kw, match):
    """Absurd table settings are refused before anything is computed, naming the parameter,
    the value and the fix (the estimate: mie.table_cost)."""
    kw = {"diameter_um": 5.0, **kw}
    with pytest.raises(ConfigError, match=match):
        mie.phase_table(kw.pop("diameter_um"), 1.45, **kw)


@pytest.mark.parametrize(
    "call, match",
    [
        (lambda: mie.efficiencies(1.0, 1.5 - 0.01j), r"negative imaginary part.*n \+ ik"),
        (lambda: mie.efficiencies(1.0, 1.0000001), "within 1e-06 of 1"),
        (lambda: mie.efficiencies(1.0, 1.333, n_medium=1.333), "within 1e-06 of 1"),
        (lambda: mie.efficiencies(5000.0, 1.45), "size parameter.*outside the validated range"),
        (lambda: mie.efficiencies(-1.0, 1.45), "'diameter_um' must be positive"),
        (lambda: mie.efficiencies(1.0, 1.45, wavelength_nm=0.0), "'wavelength_nm' must be positive"),
        (lambda: mie.efficiencies(1.0, 1.45, n_medium=-1.0), "'n_medium' must be a positive real"),
        (lambda: mie.phase_function(1.0, 1.45, [190.0]), r"'theta_deg' must lie in \[0, 180\]"),
        (lambda: mie.phase_function(1.0, 1.45, [10.0], polarization="s"), "'polarization'"),
        (lambda: mie.lognormal(1.0, 0.5), "'geometric_std' must be > 1"),
        (lambda: mie.SizeDistribution([1.0, 2.0], [1.0]), "'weights'"),
        (lambda: mie.phase_table(1.0, 1.45, angles=4), "'angles' must be an integer >= 16"),
    ],
    ids=["k_negative", "index_near_one", "matched_medium", "x_too_large", "negative_diameter", "zero_wavelength",
         "negative_medium", "angle_range", "polarization_name", "lognormal_std", "weights_shape", "table_resolution"],
)
def test_bad_input(call, match):
    with pytest.raises(ConfigError, match=match):
        call()
