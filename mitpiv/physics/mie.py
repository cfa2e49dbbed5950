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
    "MieEfficiencies",
    "PhaseTable",
    "SizeDistribution",
    "amplitudes",
    "angle_grid",
    "differential_cross_section",
    "efficiencies",
    "lognormal",
    "phase_function",
    "phase_table",
    "polarized_intensities",
    "size_parameter",
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
def angle_grid(x: float, angles: int) -> np.ndarray:
    """Scattering angles [rad] of a phase table, ascending from 0 to pi.

    For small particles ``angles`` equally spaced nodes. When the forward peak (width
    about 1/x rad) is narrower than the coarse spacing, half of the nodes go equally spaced
    into ``[0, min(30/x, pi/2)]`` (the peak and its first diffraction rings) and half over
    the rest.
    """
    if int(angles) != angles or angles < 16:
        raise ConfigError(f"mie: table resolution 'angles' must be an integer >= 16, got {angles!r}.")
    n = int(angles)
    theta_f = min(30.0 / float(x), 0.5 * math.pi)
    if theta_f >= 0.5 * math.pi:  # x <= 19: the uniform grid already resolves the peak
        return np.linspace(0.0, math.pi, n)
    nf = n // 2
    return np.concatenate([np.linspace(0.0, theta_f, nf, endpoint=False), np.linspace(theta_f, math.pi, n - nf)])


@dataclass(frozen=True)
class PhaseTable:
    """Tabulated polarised phase functions on an angle grid, for the renderer.

    ``mu`` ascending (cosines of ``theta``); ``p_par``/``p_per`` have shape (D, A): one
    row per diameter in ``diameters_um`` (a single row for a distribution, which is then
    already averaged). Each row is normalised so that its piecewise-linear interpolant in
    ``mu`` integrates to exactly 1 over the sphere (so a renderer's eval, sample and pdf
    agree); ``csca_mm2`` (D,) the scattering cross-sections.
    """

    theta: np.ndarray
    mu: np.ndarray
    p_par: np.ndarray
    p_per: np.ndarray
    csca_mm2: np.ndarray
    diameters_um: np.ndarray
    x: np.ndarray

    @property
    def phase(self) -> np.ndarray:
        return 0.5 * (self.p_par + self.p_per)


def _trapz_mu(p, mu):
    return 2 * math.pi * np.sum(0.5 * (p[..., 1:] + p[..., :-1]) * np.diff(mu), axis=-1)


@functools.lru_cache(maxsize=64)
def _table_cached(key_d, m, wavelength_nm, n_medium, angles, dist_weights):
    d = np.array(key_d)
    x = size_parameter(d, wavelength_nm=wavelength_nm, n_medium=n_medium)
    theta = angle_grid(float(np.max(x)), angles)[::-1]  # mu ascending
    mu = np.cos(theta)
    mu[0], mu[-1] = -1.0, 1.0
    theta_deg = np.degrees(theta)
    if dist_weights is not None:
        dist = SizeDistribution(d, np.array(dist_weights))
        par, per, c = _pol(dist, m, theta_deg, wavelength_nm, n_medium)
        par, per, csca = par[None], per[None], np.array([c])
        d_out = np.array([dist.mean_um()])
    else:
        rows = [_pol(float(di), m, theta_deg, wavelength_nm, n_medium) for di in d]
        par = np.array([r[0] for r in rows])
        per = np.array([r[1] for r in rows])
        csca = np.array([r[2] for r in rows])
        d_out = d
    scale = 1.0 / _trapz_mu(0.5 * (par + per), mu)
    par, per = par * scale[:, None], per * scale[:, None]
    for a in (par, per, csca, mu, theta):
        a.setflags(write=False)
    return PhaseTable(theta, mu, par, per, csca, d_out, size_parameter(d_out, wavelength_nm=wavelength_nm, n_medium=n_medium))


def phase_table(diameter_um, m_particle, *, wavelength_nm: float = 532.0, n_medium: float = 1.0, angles: int = 1024) -> PhaseTable:
    """Tabulated (cached) polarised phase functions for one diameter, a list of diameters, or a distribution.

    ``diameter_um``: float (one row), 1-D array (one row per diameter: a per-particle
    lookup table), or :class:`SizeDistribution` (one C_sca-weighted average row).
    ``angles``: number of table nodes (see :func:`angle_grid`). Tables are cached by
    their parameters.
    """
    m = _check_inputs(m_particle, wavelength_nm, n_medium) * n_medium  # validated particle index
    if isinstance(diameter_um, SizeDistribution):
        key_d, w = tuple(diameter_um.diameters_um.tolist()), tuple(diameter_um.weights.tolist())
    else:
        d = np.atleast_1d(np.asarray(diameter_um, dtype=np.float64))
        if d.ndim != 1 or d.size == 0:
            raise ConfigError(f"mie: 'diameter_um' must be a number or a 1-D list, got {diameter_um!r}.")
        key_d, w = tuple(d.tolist()), None
    _check_x(size_parameter(np.array(key_d), wavelength_nm=wavelength_nm, n_medium=n_medium))
    return _table_cached(key_d, complex(m), float(wavelength_nm), float(n_medium), int(angles) if int(angles) == angles else angles, w)
