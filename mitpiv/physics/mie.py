"""Mie scattering by homogeneous spheres: efficiencies, amplitudes, phase functions.

Conventions (stated once, converted at the boundary):

* Complex particle index ``m_particle = n + i k`` with absorption ``k >= 0`` (Bohren &
  Huffman). The medium index ``n_medium`` is real. The relative index is
  ``m = m_particle / n_medium`` and the size parameter ``x = pi d n_medium / lambda``
  with ``lambda`` the vacuum wavelength.
* Amplitudes ``S1`` (perpendicular) and ``S2`` (parallel) follow Bohren & Huffman
  (unnormalised: ``Qext = 4 Re S(0) / x^2``, ``Qback = 4 |S(180)|^2 / x^2``). Wiscombe's
  and miepython's amplitudes are their complex conjugates.
* The phase function is per steradian and integrates to 1 over the sphere:
  ``p = (|S1|^2 + |S2|^2) / (2 pi x^2 Qsca)``. For linearly polarised incident light
  ``p_par = |S2|^2 / (pi x^2 Qsca)`` (field in the scattering plane) and
  ``p_per = |S1|^2 / (pi x^2 Qsca)``; ``(p_par + p_per) / 2 = p``.
* The differential scattering cross-section is ``dC/dOmega = C_sca p`` [mm^2/sr]; a
  particle in irradiance E [W/mm^2] radiates ``I = E dC/dOmega`` [W/sr].

Engine: miepython 3 with its numba backend (``MIEPYTHON_USE_JIT=1``, set here before its
lazy import). It reproduces Wiscombe's MIEV0 test cases, and in our tests it agrees with
scattnlay (an independent implementation) and closed forms over x = 1e-4 ... 1e4 (see
``tests/physics/test_mie.py``). Two measured limits are enforced rather than returned as
garbage: ``|m - 1| < 1e-6`` (miepython returns exactly 0 below 1e-8 and loses relative
accuracy as ``|m - 1|`` shrinks) and ``x > 2e4`` (beyond the validated range).

Polydisperse seeding: pass a :class:`SizeDistribution` (e.g. :func:`lognormal`) instead of
a diameter; averages are number-weighted, the phase function weighted by C_sca.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass, field

import numpy as np

from mitpiv._numba import set_cache_dir
from mitpiv.errors import ConfigError, MitpivError

__all__ = [
    "MIN_INDEX_CONTRAST",
    "MAX_SIZE_PARAMETER",
    "TABLE_TOLERANCE",
    "MieEfficiencies",
    "PhaseTable",
    "SizeDistribution",
    "amplitudes",
    "adaptive_angles_estimate",
    "angle_grid",
    "check_table_settings",
    "differential_cross_section",
    "efficiencies",
    "lognormal",
    "phase_function",
    "phase_table",
    "polarized_intensities",
    "size_parameter",
    "table_cost",
]

MIN_INDEX_CONTRAST = 1e-6  # |m - 1| below this is rejected (see module docstring)
MAX_SIZE_PARAMETER = 2e4  # validated up to 1e4; miepython's own tests go to 1e4 as well
MIN_SIZE_PARAMETER = 1e-6


# ----------------------------------------------------------------------------- engine
@functools.cache
def _engine():
    """Import miepython with numba switched on (first import compiles: seconds, then cached)."""
    os.environ.setdefault("MIEPYTHON_USE_JIT", "1")
    set_cache_dir()
    import miepython

    return miepython


# ----------------------------------------------------------------------------- inputs
@dataclass(frozen=True)
class SizeDistribution:
    """Discrete size distribution: diameters [um] and number weights (normalised to 1).

    Parameters
    ----------
    diameters_um : (K,) array
    weights : (K,) array, optional
        Relative number of particles of each diameter (default: equal).
    """

    diameters_um: np.ndarray
    weights: np.ndarray = field(default=None)

    def __post_init__(self):
        d = np.atleast_1d(np.asarray(self.diameters_um, dtype=np.float64))
        if d.ndim != 1 or d.size == 0 or not np.all(np.isfinite(d)) or np.any(d <= 0):
            raise ConfigError(f"SizeDistribution: 'diameters_um' must be a non-empty list of positive diameters, got {self.diameters_um!r}.")
        w = np.ones_like(d) if self.weights is None else np.atleast_1d(np.asarray(self.weights, dtype=np.float64))
        if w.shape != d.shape or not np.all(np.isfinite(w)) or np.any(w < 0) or w.sum() <= 0:
            raise ConfigError(
                f"SizeDistribution: 'weights' must be {d.size} non-negative numbers with a positive sum, got {self.weights!r}."
            )
        object.__setattr__(self, "diameters_um", d)
        object.__setattr__(self, "weights", w / w.sum())

    def mean_um(self) -> float:
        return float(np.sum(self.weights * self.diameters_um))


def lognormal(median_um: float, geometric_std: float, *, nodes: int = 161, span: float = 6.0) -> SizeDistribution:
    """Log-normal number distribution (as :func:`mitpiv.physics.seeding.sample_diameters`).

    ``ln d`` is normal with mean ``ln median_um`` and standard deviation ``ln geometric_std``;
    it is discretised with ``nodes`` equally spaced nodes in ``ln d`` over +-``span`` standard
    deviations (trapezoid weights), fine enough to average over Mie ripples.
    """
    if not (np.isfinite(median_um) and median_um > 0):
        raise ConfigError(f"lognormal: 'median_um' must be positive, got {median_um!r}.")
    if not (np.isfinite(geometric_std) and geometric_std > 1):
        raise ConfigError(f"lognormal: 'geometric_std' must be > 1, got {geometric_std!r}; use a single diameter for monodisperse seeding.")
    if int(nodes) != nodes or nodes < 3:
        raise ConfigError(f"lognormal: 'nodes' must be an integer >= 3, got {nodes!r}.")
    s = math.log(geometric_std)
    z = np.linspace(-span, span, int(nodes))
    w = np.exp(-0.5 * z**2)
    w[[0, -1]] *= 0.5
    return SizeDistribution(median_um * np.exp(s * z), w)


#: Largest absorption index k of a particle index n + ik (metals in the far infrared).
MAX_ABSORPTION_INDEX = 100.0


def _check_inputs(m_particle, wavelength_nm, n_medium):
    m_particle = complex(m_particle)
    if not (np.isfinite(m_particle.real) and np.isfinite(m_particle.imag)) or m_particle.real <= 0:
        raise ConfigError(f"mie: 'm_particle' must have a positive real part, got {m_particle!r}.")
    if m_particle.imag < 0:
        raise ConfigError(
            f"mie: 'm_particle' = {m_particle!r} has a negative imaginary part. mitpiv writes the index as "
            f"n + ik with absorption k >= 0 (Bohren & Huffman); for an n - ik value (Wiscombe, miepython) "
            f"use {m_particle.conjugate()!r}."
        )
    if m_particle.imag > MAX_ABSORPTION_INDEX:
        raise ConfigError(
            f"mie: 'm_particle' = {m_particle!r} has an absorption index k = {m_particle.imag:g} > "
            f"{MAX_ABSORPTION_INDEX:g}; no material absorbs that strongly (metals reach k ~ 10 in the visible, "
            f"~100 in the far infrared). Check the imaginary part (n + ik).")
    if not (np.isfinite(wavelength_nm) and wavelength_nm > 0):
        raise ConfigError(f"mie: 'wavelength_nm' must be positive (vacuum wavelength in nm), got {wavelength_nm!r}.")
    if not (np.isfinite(n_medium) and n_medium > 0) or isinstance(n_medium, complex):
        raise ConfigError(f"mie: 'n_medium' must be a positive real index, got {n_medium!r}.")
    m = m_particle / float(n_medium)
    if abs(m - 1) < MIN_INDEX_CONTRAST:
        raise ConfigError(
            f"mie: relative index m = {m!r} is within {MIN_INDEX_CONTRAST:g} of 1 (particle {m_particle!r}, "
            f"medium {n_medium!r}): the particle scatters almost nothing (Qsca ~ |m-1|^2 x^4) and the "
            f"series loses accuracy. Check the particle and medium indices."
        )
    return m


def _check_x(x):
    x = np.asarray(x, dtype=np.float64)
    bad = ~np.isfinite(x) | (x < MIN_SIZE_PARAMETER) | (x > MAX_SIZE_PARAMETER)
    if np.any(bad):
        v = x[bad].ravel()[0]
        raise ConfigError(
            f"mie: size parameter x = pi d n_medium / lambda = {v:g} is outside the validated range "
            f"[{MIN_SIZE_PARAMETER:g}, {MAX_SIZE_PARAMETER:g}]. Check 'diameter_um' (micrometres) and "
            f"'wavelength_nm' (nanometres); for x > {MAX_SIZE_PARAMETER:g} geometric optics applies."
        )
    return x


def size_parameter(diameter_um, *, wavelength_nm: float = 532.0, n_medium: float = 1.0):
    """Size parameter ``x = pi d n_medium / lambda`` (d in um, lambda in nm, vacuum)."""
    d = np.asarray(diameter_um, dtype=np.float64)
    if np.any(~np.isfinite(d)) or np.any(d <= 0):
        raise ConfigError(f"mie: 'diameter_um' must be positive, got {diameter_um!r}.")
    if not (np.isfinite(wavelength_nm) and wavelength_nm > 0):
        raise ConfigError(f"mie: 'wavelength_nm' must be positive (vacuum wavelength in nm), got {wavelength_nm!r}.")
    return math.pi * d * 1e3 * float(n_medium) / float(wavelength_nm)


def _finite(name, arrays, x, m):
    for a in arrays:
        if not np.all(np.isfinite(a)):
            raise MitpivError(f"mie: {name} is not finite for x = {np.ravel(x)[0]:g}, m = {m!r}; please report this case.")


# ----------------------------------------------------------------------------- efficiencies
@dataclass(frozen=True)
class MieEfficiencies:
    """Efficiencies [-], asymmetry g [-] and cross-sections [mm^2]: floats for a scalar
    diameter, else arrays shaped like the diameters.

    For a :class:`SizeDistribution` the fields are number-weighted averages of the
    cross-sections; the efficiencies are those averages divided by the mean geometric
    cross-section, and ``g`` is weighted by C_sca.
    """

    x: np.ndarray
    qext: np.ndarray
    qsca: np.ndarray
    qabs: np.ndarray
    qback: np.ndarray
    g: np.ndarray
    cext_mm2: np.ndarray
    csca_mm2: np.ndarray
    cabs_mm2: np.ndarray
    cback_mm2: np.ndarray


def _raw_efficiencies(x, m):
    mp = _engine()
    xx = np.atleast_1d(x)
    qext, qsca, qback, g = (np.asarray(a, dtype=np.float64).reshape(np.shape(x)) for a in mp.efficiencies_mx(np.conj(m), xx))
    if m.imag == 0:
        qsca = qext.copy()  # no absorption: exactly (the two sums differ by rounding only)
    _finite("the efficiencies", (qext, qsca, qback, g), x, m)
    return qext, qsca, qback, g


def efficiencies(diameter_um, m_particle, *, wavelength_nm: float = 532.0, n_medium: float = 1.0) -> MieEfficiencies:
    """Mie efficiencies and cross-sections of spheres.

    Parameters
    ----------
    diameter_um : float, array, or SizeDistribution
        Diameter(s) [um].
    m_particle : complex
        Particle index ``n + ik`` (k >= 0).
    wavelength_nm : float
        Vacuum wavelength [nm].
    n_medium : float
        Real index of the surrounding medium.

    Returns
    -------
    MieEfficiencies
    """
    m = _check_inputs(m_particle, wavelength_nm, n_medium)
    dist = diameter_um if isinstance(diameter_um, SizeDistribution) else None
    d = dist.diameters_um if dist else np.asarray(diameter_um, dtype=np.float64)
    x = _check_x(size_parameter(d, wavelength_nm=wavelength_nm, n_medium=n_medium))
    qext, qsca, qback, g = _raw_efficiencies(x, m)
    geo = math.pi / 4 * (d * 1e-3) ** 2  # mm^2
    c = {k: q * geo for k, q in (("ext", qext), ("sca", qsca), ("back", qback))}
    c["abs"] = np.maximum(c["ext"] - c["sca"], 0.0)
    if dist is None:
        out = (x, qext, qsca, c["abs"] / geo, qback, g, c["ext"], c["sca"], c["abs"], c["back"])
        if np.ndim(d) == 0:  # a scalar diameter gives floats
            out = tuple(float(v) for v in out)
        return MieEfficiencies(*out)
    w = dist.weights
    avg = {k: float(np.sum(w * v)) for k, v in c.items()}
    geo_mean = float(np.sum(w * geo))
    g_avg = float(np.sum(w * c["sca"] * g) / avg["sca"])
    x_mean = float(np.sum(w * x))
    return MieEfficiencies(x_mean, avg["ext"] / geo_mean, avg["sca"] / geo_mean, avg["abs"] / geo_mean,
                           avg["back"] / geo_mean, g_avg, avg["ext"], avg["sca"], avg["abs"], avg["back"])


# ----------------------------------------------------------------------------- amplitudes
def _theta(theta_deg):
    t = np.asarray(theta_deg, dtype=np.float64)
    if np.any(~np.isfinite(t)) or np.any(t < 0) or np.any(t > 180):
        raise ConfigError(f"mie: scattering angles 'theta_deg' must lie in [0, 180] degrees, got {theta_deg!r}.")
    return t


def _mu(theta_deg):
    t = _theta(theta_deg)
    mu = np.cos(np.radians(t))
    mu[t == 0] = 1.0  # exact ends: cos(pi) is -1 in float64 already, but keep both explicit
    mu[t == 180] = -1.0
    return mu


def _raw_amplitudes(x, m, mu):
    """B&H amplitudes S1, S2 at cosines mu for one size parameter."""
    mp = _engine()
    s1, s2 = mp.S1_S2(np.conj(m), float(x), np.atleast_1d(mu), norm="wiscombe")
    s1, s2 = np.conj(np.asarray(s1, dtype=np.complex128)), np.conj(np.asarray(s2, dtype=np.complex128))
    _finite("S1/S2", (s1, s2), x, m)
    return s1, s2


def amplitudes(diameter_um: float, m_particle, theta_deg, *, wavelength_nm: float = 532.0, n_medium: float = 1.0):
    """Amplitude functions ``S1(theta)``, ``S2(theta)`` (Bohren & Huffman convention).

    Parameters
    ----------
    diameter_um : float
        Diameter [um].
    m_particle : complex
        Particle index ``n + ik``.
    theta_deg : array
        Scattering angles [deg], 0 = forward.

    Returns
    -------
    S1, S2 : complex arrays shaped like ``theta_deg``
    """
    m = _check_inputs(m_particle, wavelength_nm, n_medium)
    x = float(_check_x(size_parameter(float(diameter_um), wavelength_nm=wavelength_nm, n_medium=n_medium)))
    shape = np.shape(theta_deg)
    s1, s2 = _raw_amplitudes(x, m, _mu(theta_deg).ravel())
    return s1.reshape(shape), s2.reshape(shape)


def _pol_single(x, m, mu, qsca):
    s1, s2 = _raw_amplitudes(x, m, mu)
    norm = math.pi * x * x * qsca
    return np.abs(s2) ** 2 / norm, np.abs(s1) ** 2 / norm


def _pol(diameter_um, m_particle, theta_deg, wavelength_nm, n_medium):
    """(p_par, p_per, C_sca [mm^2]) for a diameter or a distribution."""
    m = _check_inputs(m_particle, wavelength_nm, n_medium)
    mu = _mu(theta_deg).ravel()
    dist = diameter_um if isinstance(diameter_um, SizeDistribution) else SizeDistribution([float(diameter_um)])
    d = dist.diameters_um
    x = _check_x(size_parameter(d, wavelength_nm=wavelength_nm, n_medium=n_medium))
    _, qsca, _, _ = _raw_efficiencies(x, m)
    csca = qsca * math.pi / 4 * (d * 1e-3) ** 2
    par = np.zeros_like(mu)
    per = np.zeros_like(mu)
    for xi, qi, wi, ci in zip(x, qsca, dist.weights, csca, strict=True):  # sizes of a distribution (tens)
        a, b = _pol_single(xi, m, mu, qi)
        par += wi * ci * a
        per += wi * ci * b
    c_mean = float(np.sum(dist.weights * csca))
    return par / c_mean, per / c_mean, c_mean


def polarized_intensities(diameter_um, m_particle, theta_deg, *, wavelength_nm: float = 532.0, n_medium: float = 1.0):
    """Normalised intensities [1/sr] for linearly polarised light, parallel and perpendicular.

    ``p_par = |S2|^2 / (pi x^2 Qsca)`` (incident field in the scattering plane) and
    ``p_per = |S1|^2 / (pi x^2 Qsca)``; each integrates to 1 over the sphere and their mean
    is :func:`phase_function`. Light polarised at azimuth ``phi`` to the scattering plane
    scatters ``p_par cos^2(phi) + p_per sin^2(phi)``.
    """
    shape = np.shape(theta_deg)
    par, per, _ = _pol(diameter_um, m_particle, theta_deg, wavelength_nm, n_medium)
    return par.reshape(shape), per.reshape(shape)


def phase_function(diameter_um, m_particle, theta_deg, *, wavelength_nm: float = 532.0, n_medium: float = 1.0,
                   polarization: str = "unpolarized"):
    """Normalised phase function [1/sr] at scattering angles ``theta_deg`` (integral over the sphere = 1).

    ``polarization``: ``"unpolarized"`` (default), ``"parallel"`` or ``"perpendicular"``
    (incident field relative to the scattering plane).
    """
    if polarization not in ("unpolarized", "parallel", "perpendicular"):
        raise ConfigError(f"mie: 'polarization' must be 'unpolarized', 'parallel' or 'perpendicular', got {polarization!r}.")
    par, per = polarized_intensities(diameter_um, m_particle, theta_deg, wavelength_nm=wavelength_nm, n_medium=n_medium)
    return {"unpolarized": 0.5 * (par + per), "parallel": par, "perpendicular": per}[polarization]


def differential_cross_section(diameter_um, m_particle, theta_deg, *, wavelength_nm: float = 532.0, n_medium: float = 1.0,
                               polarization: str = "unpolarized"):
    """``dC_sca/dOmega = C_sca p(theta)`` [mm^2/sr]; times the irradiance it is the radiant intensity."""
    p = phase_function(diameter_um, m_particle, theta_deg, wavelength_nm=wavelength_nm, n_medium=n_medium,
                       polarization=polarization)
    return efficiencies(diameter_um, m_particle, wavelength_nm=wavelength_nm, n_medium=n_medium).csca_mm2 * p


# ----------------------------------------------------------------------------- tables
#: Default relative tolerance of a phase table: the piecewise-linear interpolant in theta that
#: the renderer evaluates differs from the phase function by at most this fraction of the local
#: value, at every angle (see :func:`phase_table`).
TABLE_TOLERANCE = 1e-3
#: Accepted range of ``tolerance``.
TABLE_TOLERANCE_RANGE = (1e-6, 0.1)
#: Below this fraction of a row's largest value the tolerance is absolute: an exact zero (a
#: Rayleigh particle's parallel intensity at 90 deg) cannot be met relatively.
TABLE_FLOOR = 1e-10
#: Largest table resolution (nodes in the scattering angle) accepted.
MAX_TABLE_ANGLES = 1 << 22
#: Estimated memory and build time above which a table is refused before it is built.
MAX_TABLE_BYTES = 1 << 32
MAX_TABLE_SECONDS = 300.0
# An interval is split while its midpoint error exceeds this fraction of the tolerance: the
# midpoint estimates the largest error of a linear interpolant to second order; the margin
# covers the rest (the tests measure the error on dense grids and at the minima).
_SAFETY = 0.5
# Build cost: miepython's S1/S2 (numba) per angle and series term (16-26 ns measured on the
# 2-core machine for x = 0.6 ... 1e4), and bytes per table entry (float64 par/per, the
# cross-section copies, the float32 upload).
_SECONDS_PER_TERM = 25e-9
_BYTES_PER_ENTRY = 48


def angle_grid(x: float, angles: int) -> np.ndarray:
    """Scattering angles [rad] of a fixed-resolution phase table, ascending from 0 to pi.

    For small particles ``angles`` equally spaced nodes. When the forward peak (width
    about 1/x rad) is narrower than the coarse spacing, half of the nodes go equally spaced
    into ``[0, min(30/x, pi/2)]`` (the peak and its first diffraction rings) and half over
    the rest. Used when a table's ``angles`` are given; by default :func:`phase_table`
    chooses its nodes for a tolerance instead.
    """
    _check_angles(angles)
    n = int(angles)
    theta_f = min(30.0 / float(x), 0.5 * math.pi)
    if theta_f >= 0.5 * math.pi:  # x <= 19: the uniform grid already resolves the peak
        return np.linspace(0.0, math.pi, n)
    nf = n // 2
    return np.concatenate([np.linspace(0.0, theta_f, nf, endpoint=False), np.linspace(theta_f, math.pi, n - nf)])


def _check_angles(angles):
    try:
        ok = not isinstance(angles, bool) and int(angles) == angles and 16 <= angles <= MAX_TABLE_ANGLES
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        raise ConfigError(
            f"mie: table resolution 'angles' must be an integer >= 16 and <= {MAX_TABLE_ANGLES}, got {angles!r}. "
            f"Leave it out for a table chosen for the relative 'tolerance' (default {TABLE_TOLERANCE:g}).")


def _check_tolerance(tolerance):
    lo, hi = TABLE_TOLERANCE_RANGE
    if isinstance(tolerance, bool) or not (isinstance(tolerance, (int, float)) and lo <= tolerance <= hi):
        raise ConfigError(f"mie: table 'tolerance' (relative) must lie in [{lo:g}, {hi:g}], got {tolerance!r}; "
                          f"the default is {TABLE_TOLERANCE:g}; 1e-2 needs a third of its nodes.")


def check_table_settings(angles=None, tolerance=None) -> tuple[int | None, float | None]:
    """Validate a table's ``angles`` (a fixed grid) or ``tolerance`` (nodes chosen for it).

    Returns ``(angles, None)`` or ``(None, tolerance)``, the tolerance defaulting to
    :data:`TABLE_TOLERANCE`; raises :class:`ConfigError` naming the parameter for an invalid
    value or when both are given.
    """
    if angles is not None:
        if tolerance is not None:
            raise ConfigError(f"mie: give either 'angles' (a fixed table) or 'tolerance' (a table chosen for it), "
                              f"not both (got angles={angles!r}, tolerance={tolerance!r}).")
        _check_angles(angles)
        return int(angles), None
    tolerance = TABLE_TOLERANCE if tolerance is None else tolerance
    _check_tolerance(tolerance)
    return None, float(tolerance)


def _series_terms(x):
    """Wiscombe's number of series terms (the cost of one amplitude evaluation)."""
    x = np.asarray(x, dtype=np.float64)
    return x + 4.05 * np.cbrt(x) + 2.0


def adaptive_angles_estimate(x: float, tolerance: float = TABLE_TOLERANCE) -> int:
    """Estimated number of nodes :func:`phase_table` chooses for size parameter ``x``.

    Fitted above the measured counts (``bench/bench_mie.py``: 3.7-5.1 ``x / sqrt(tolerance)``
    for x = 6 ... 300 and tolerances 1e-4 ... 1e-2); used to refuse a table too costly to
    build before building it.
    """
    return int(5.0 * x / math.sqrt(tolerance) + 8.0 * x + 128)


def table_cost(x, nodes: int, *, distribution: bool = False) -> tuple[float, float]:
    """Estimated memory [bytes] and build time [s] of a phase table of ``nodes`` angles.

    ``x``: the size parameters of its diameters: one row each (a per-particle table), or,
    with ``distribution``, the nodes of one averaged row. The grid is chosen on one row (the
    largest diameter, or the distribution's average), which is evaluated at the nodes and at
    their midpoints; the other rows once at the nodes.
    """
    x = np.atleast_1d(np.asarray(x, dtype=np.float64))
    terms = _series_terms(x)
    rows = 1 if distribution else x.size
    evaluations = 2.0 * terms.sum() if distribution else terms.sum() + terms.max()
    return float(rows) * nodes * _BYTES_PER_ENTRY, nodes * evaluations * _SECONDS_PER_TERM


def _check_cost(x, nodes, distribution, *, what, fix):
    nbytes, seconds = table_cost(x, nodes, distribution=distribution)
    if nbytes > MAX_TABLE_BYTES or seconds > MAX_TABLE_SECONDS:
        rows = 1 if distribution else np.size(x)
        raise ConfigError(
            f"mie: {what} needs about {nodes:,} angles x {rows:,} diameter row(s) (size parameter up to "
            f"{float(np.max(x)):.4g}): about {nbytes / 2**30:.2f} GiB and {seconds:.0f} s to build, over the limits "
            f"of {MAX_TABLE_BYTES / 2**30:.0f} GiB and {MAX_TABLE_SECONDS:.0f} s. {fix}")


@dataclass(frozen=True)
class PhaseTable:
    """Tabulated polarised phase functions on an angle grid, for the renderer.

    ``mu`` ascending (cosines of ``theta``, so ``theta`` descends from pi to 0);
    ``p_par``/``p_per`` [1/sr] have shape (D, A): one row per diameter in ``diameters_um``
    (a single row for a distribution, which is then already averaged), the exact values at
    the nodes (each integrates to 1 over the sphere; the renderer's phase plugin normalises
    its own interpolant). ``csca_mm2`` (D,) the scattering cross-sections.

    The renderer interpolates linearly in ``theta`` (``p_par``, ``p_per``, and
    ``sin(theta) p`` for the phase plugin's pdf). ``tolerance`` is the relative tolerance
    the nodes were chosen for (None for a fixed ``angles`` grid); ``max_error`` the largest
    relative error of those interpolants at the midpoints between nodes (where the error
    of a linear interpolant peaks), on the row the grid was chosen on: the only row, a
    distribution's average, or a per-particle table's largest diameter.
    """

    theta: np.ndarray
    mu: np.ndarray
    p_par: np.ndarray
    p_per: np.ndarray
    csca_mm2: np.ndarray
    diameters_um: np.ndarray
    x: np.ndarray
    tolerance: float | None = None
    max_error: float = float("nan")

    @property
    def phase(self) -> np.ndarray:
        return 0.5 * (self.p_par + self.p_per)

    @property
    def angles(self) -> int:
        return int(self.theta.size)


def _f32(t):
    """Angles rounded to float32: the renderer's nodes are float32, so the table's values
    belong to exactly those angles."""
    return np.asarray(t, dtype=np.float64).astype(np.float32).astype(np.float64)


def _mu_of(theta):
    mu = np.cos(theta)
    mu[theta <= 0.0] = 1.0
    mu[theta >= math.pi] = -1.0
    return mu


def _row_evaluator(key_d, m, wavelength_nm, n_medium, dist_weights):
    """``evaluate(mu, rows=None) -> (par, per)`` of shape (rows, len(mu)) (all rows, or the
    given row indices), the rows' C_sca [mm^2] and diameters, and every size parameter.
    ``m`` is the relative index."""
    d = np.array(key_d)
    x = size_parameter(d, wavelength_nm=wavelength_nm, n_medium=n_medium)
    _, qsca, _, _ = _raw_efficiencies(x, m)
    csca = qsca * math.pi / 4 * (d * 1e-3) ** 2
    if dist_weights is not None:
        w = np.array(dist_weights)
        c_mean = float(np.sum(w * csca))
        scale = w * csca / c_mean

        def evaluate(mu, rows=None):
            par, per = np.zeros_like(mu), np.zeros_like(mu)
            for xi, qi, si in zip(x, qsca, scale, strict=True):
                a, b = _pol_single(xi, m, mu, qi)
                par += si * a
                per += si * b
            return par[None], per[None]

        return evaluate, np.array([c_mean]), np.array([SizeDistribution(d, w).mean_um()]), x

    def evaluate(mu, rows=None):
        out = [_pol_single(x[j], m, mu, qsca[j]) for j in (range(x.size) if rows is None else rows)]
        return np.array([r[0] for r in out]), np.array([r[1] for r in out])

    return evaluate, csca, d, x


def _midpoint_error(theta, par, per, i, tm, pm, qm, floor):
    """Relative error at ``tm`` in [theta[i], theta[i+1]] of the renderer's linear
    interpolants in theta: ``par`` and ``per`` (tracer_particles) and ``sin(theta) p`` (the
    mie phase plugin's pdf); the largest over the three and over the rows."""
    t = (tm - theta[i]) / (theta[i + 1] - theta[i])

    def lerp(v):
        return v[:, i] + t * (v[:, i + 1] - v[:, i])

    def low(v, vm):  # the interval's smallest value: where the relative error peaks when v varies a lot
        return np.minimum(np.minimum(v[:, i], v[:, i + 1]), vm)

    e = np.abs(lerp(par) - pm) / (low(par, pm) + floor)
    e = np.maximum(e, np.abs(lerp(per) - qm) / (low(per, qm) + floor))
    s, sm = np.sin(theta), np.sin(tm)
    g, gm = 0.5 * (par + per) * s, 0.5 * (pm + qm) * sm
    e = np.maximum(e, np.abs(lerp(g) - gm) / (np.maximum(low(g, gm), 0.5 * gm) + sm * floor))
    return e.max(axis=0)


def _refine(evaluate, x_max, tolerance):
    """Nodes in theta (ascending, float32 values, 0 and pi exact) where the linear
    interpolants of every row ``evaluate`` returns are within ``tolerance``: start at 8
    nodes per ripple period (pi/x) and bisect every interval whose midpoint error exceeds
    ``_SAFETY * tolerance`` (near the deep minima the nodes crowd geometrically). Returns
    the nodes, the rows' values there and the largest midpoint error of the final grid."""
    n0 = int(max(65, math.ceil(8.0 * x_max) + 1))
    theta = _f32(np.linspace(0.0, math.pi, n0))
    theta[-1] = math.pi
    par, per = evaluate(_mu_of(theta))
    floor = TABLE_FLOOR * np.maximum(par.max(axis=1), per.max(axis=1))[:, None]
    pending = np.ones(n0 - 1, dtype=bool)
    worst = 0.0
    while pending.any():
        i = np.flatnonzero(pending)
        tm = _f32(0.5 * (theta[i] + theta[i + 1]))
        ok = (tm > theta[i]) & (tm < theta[i + 1])  # else float32 neighbours: as fine as the renderer gets
        i, tm = i[ok], tm[ok]
        if i.size == 0:
            break
        pm, qm = evaluate(_mu_of(tm))
        err = _midpoint_error(theta, par, per, i, tm, pm, qm, floor)
        split = err > _SAFETY * tolerance
        if theta.size + np.count_nonzero(split) > MAX_TABLE_ANGLES:
            worst = max(worst, float(err.max()))
            break
        worst = max(worst, float(err[~split].max(initial=0.0)))
        if not split.any():
            break
        n_old = theta.size
        order = np.argsort(np.concatenate([theta, tm[split]]), kind="stable")
        theta = np.concatenate([theta, tm[split]])[order]
        par = np.concatenate([par, pm[:, split]], axis=1)[:, order]
        per = np.concatenate([per, qm[:, split]], axis=1)[:, order]
        is_new = (np.arange(theta.size) >= n_old)[order]
        pending = is_new[:-1] | is_new[1:]
    return theta, par, per, worst


def _grid_error(evaluate, theta, par, per):
    """Largest midpoint error of the linear interpolants on a given grid."""
    floor = TABLE_FLOOR * np.maximum(par.max(axis=1), per.max(axis=1))[:, None]
    tm = 0.5 * (theta[:-1] + theta[1:])
    pm, qm = evaluate(_mu_of(tm))
    return float(_midpoint_error(theta, par, per, np.arange(theta.size - 1), tm, pm, qm, floor).max())


@functools.lru_cache(maxsize=64)
def _table_cached(key_d, m, wavelength_nm, n_medium, angles, tolerance, dist_weights):
    evaluate, csca, d_out, x = _row_evaluator(key_d, m, wavelength_nm, n_medium, dist_weights)
    # The grid is chosen (and its error measured) on one row: the only row, a distribution's
    # average, or for a per-particle table the largest diameter, whose ripple is the finest.
    ref = int(np.argmax(x)) if dist_weights is None else 0
    rows = len(d_out)

    def evaluate_ref(mu):
        return evaluate(mu, [ref])

    if angles is None:
        theta, par, per, worst = _refine(evaluate_ref, float(np.max(x)), tolerance)
        if worst > tolerance:
            import warnings

            from mitpiv.errors import MitpivWarning

            warnings.warn(f"mie: the phase table reached {theta.size} angles (the limit) with a relative error of "
                          f"{worst:.2g} > the tolerance {tolerance:g}; loosen 'tolerance'.", MitpivWarning, stacklevel=4)
    else:
        theta = _f32(angle_grid(float(np.max(x)), angles))
        theta[-1] = math.pi
        par, per = evaluate_ref(_mu_of(theta))
        worst = _grid_error(evaluate_ref, theta, par, per)
    if rows > 1:
        par, per = evaluate(_mu_of(theta))
    theta, par, per = theta[::-1].copy(), par[:, ::-1].copy(), per[:, ::-1].copy()  # mu ascending
    mu = _mu_of(theta)
    for a in (par, per, csca, mu, theta):
        a.setflags(write=False)
    return PhaseTable(theta, mu, par, per, csca, d_out, size_parameter(d_out, wavelength_nm=wavelength_nm, n_medium=n_medium),
                      None if angles is not None else tolerance, worst)


def phase_table(diameter_um, m_particle, *, wavelength_nm: float = 532.0, n_medium: float = 1.0, angles: int | None = None,
                tolerance: float = TABLE_TOLERANCE) -> PhaseTable:
    """Tabulated (cached) polarised phase functions for one diameter, a list of diameters, or a distribution.

    Parameters
    ----------
    diameter_um : float, (D,) array, or SizeDistribution
        One row for a float; one row per diameter for an array (a per-particle lookup
        table); one C_sca-weighted average row for a :class:`SizeDistribution`.
    m_particle : complex
        Particle index ``n + ik`` (k >= 0).
    wavelength_nm, n_medium : float
        Vacuum wavelength [nm] and the medium's real index.
    angles : int, optional
        A fixed grid of this many nodes (:func:`angle_grid`). By default (None) the nodes
        are chosen for ``tolerance``.
    tolerance : float, default TABLE_TOLERANCE (1e-3)
        Relative tolerance of the linear interpolants in theta the renderer evaluates
        (``p_par``, ``p_per`` and ``sin(theta) p``): at every angle and for every row,
        ``|interpolant - p| <= tolerance (p + TABLE_FLOOR max p)``, near the deep minima
        too. The nodes start at 8 per ripple period pi/x and are bisected where the error
        at an interval's midpoint exceeds half the tolerance; the count grows as
        ``x / sqrt(tolerance)`` (:func:`adaptive_angles_estimate`). This holds for a
        single row (one diameter, or a distribution's average). A per-particle table
        (several diameters) takes the grid of its largest diameter, whose ripple is the
        finest: its other rows are resolved away from their own deep minima, where (as
        between rows) the spacing of the diameters sets the error.

    Returns
    -------
    PhaseTable
        With ``max_error``, the largest relative error at the nodes' midpoints of the row
        the grid was chosen on.

    Raises
    ------
    ConfigError
        For an invalid ``angles`` or ``tolerance``, or when the estimated memory or build
        time (:func:`table_cost`) exceeds ``MAX_TABLE_BYTES`` or ``MAX_TABLE_SECONDS``
        (checked before anything is computed).
    """
    m = _check_inputs(m_particle, wavelength_nm, n_medium)
    if isinstance(diameter_um, SizeDistribution):
        key_d, w = tuple(diameter_um.diameters_um.tolist()), tuple(diameter_um.weights.tolist())
    else:
        d = np.atleast_1d(np.asarray(diameter_um, dtype=np.float64))
        if d.ndim != 1 or d.size == 0:
            raise ConfigError(f"mie: 'diameter_um' must be a number or a 1-D list, got {diameter_um!r}.")
        key_d, w = tuple(d.tolist()), None
    x = _check_x(size_parameter(np.array(key_d), wavelength_nm=wavelength_nm, n_medium=n_medium))
    if angles is not None:
        _check_angles(angles)
        angles = int(angles)
        _check_cost(x, angles, w is not None, what=f"'angles' = {angles}",
                    fix="Give fewer 'angles' (1024-65536 are usual), or leave it out for a table chosen for the tolerance.")
        tolerance = None
    else:
        _check_tolerance(tolerance)
        tolerance = float(tolerance)
        nodes = adaptive_angles_estimate(float(np.max(x)), tolerance)
        _check_cost(x, nodes, w is not None, what=f"a table within the relative 'tolerance' {tolerance:g}",
                    fix="Loosen 'tolerance' (e.g. 1e-2), give a fixed 'angles', or (per-particle diameters) a coarser "
                        "'size_step'.")
    return _table_cached(key_d, complex(m), float(wavelength_nm), float(n_medium), angles, tolerance, w)
