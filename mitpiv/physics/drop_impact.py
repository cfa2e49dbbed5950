"""Secondary fragments of a water drop impacting a thin water film, the particle field of
the plenoptic vs digital in-line holography comparison (seed paper 003, ch. IV.A, Table 1).

Conditions (Table 1; water, rho = 1000 kg/m^3, sigma = 0.076 N/m as measured for the dyed
water; film 2.35 mm deep in a 50.8 mm o-ring)::

    We  = rho v0^2 d0 / sigma        (eq. 19)
    tau = t v0 / d0                  (eq. 20, t the time since impact)

Fragment model (hand-written: no library models a splash; vectorised over fragments).
Fragments leave the rim of the crown, whose base radius grows by the kinematic
discontinuity of Yarin & Weiss (1995, J. Fluid Mech. 283, 141-173), in the form that
Cossali et al. (2004, Exp. Fluids 36, 888-900) compared with their crown measurements::

    R_c(tau) / d0 = (2 / (3 H))^(1/4) sqrt(tau),      H = h_film / d0

so the rim moves outward at ``v_c / v0 = dR_c/dtau = (1/2) (2/(3H))^(1/4) tau^(-1/2)``,
a radial velocity that decays with tau as the seed paper (Fig. 28, right) and the DIH
measurements it compares with (Guildenbecher et al. 2014, Exp. Fluids 55:1670, its ref.
[27]) report. A fragment detaches at a time ``tau_e`` drawn uniformly between
``tau_start`` and the observation time and flies ballistically (no drag, no gravity over
the few ms) with the rim's radial velocity at ``tau_e`` and an upward component
``v_r tan(elevation)``; at time ``tau`` it sits at
``R_c(tau_e) + v_r (tau - tau_e) d0/v0`` from the axis. Diameters follow the seed paper's
power law (Fig. 28, left; the form [27] fitted to DIH data) ``mean d/d0 = q(We) tau^n(We)``,
log-normal about that mean.

The coefficients of [27]'s fits are not reproduced in the seed paper and the cited paper
was not available to this implementation: :data:`FRAGMENT_LAW` holds placeholders, each
documented, anchored on the one number the seed paper prints (a mean measured diameter of
0.199 mm at We 784, tau 5.1, i.e. d/d0 = 0.0603) with no time dependence (n = 0) until
[27]'s q and n are transcribed; pass ``q`` and ``n`` to use others. The number of fragments
defaults to the DIH count the seed paper quotes (196 per realisation at We 784, tau 5.1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mitpiv.errors import ConfigError, check_positive

__all__ = ["ImpactCondition", "TABLE_1", "SIGMA_N_M", "RHO_KG_M3", "FILM_MM", "weber", "tau_of", "time_of",
           "crown_radius_mm", "crown_speed_ratio", "FRAGMENT_LAW", "fragment_field", "condition"]

RHO_KG_M3 = 1000.0  # "rho is the drop density assumed to be 1000 kg/m^3"
SIGMA_N_M = 0.076  # surface tension measured for the dyed water
FILM_MM = 2.35  # film thickness = o-ring height
ORING_DIAMETER_MM = 50.8


def weber(d0_mm, v0_m_s, *, rho_kg_m3: float = RHO_KG_M3, sigma_n_m: float = SIGMA_N_M):
    """Impact Weber number, eq. 19: ``We = rho v0^2 d0 / sigma``."""
    return rho_kg_m3 * np.asarray(v0_m_s, dtype=np.float64) ** 2 * np.asarray(d0_mm, dtype=np.float64) * 1e-3 / sigma_n_m


def tau_of(t_s, d0_mm, v0_m_s):
    """Non-dimensional time, eq. 20: ``tau = t v0 / d0``."""
    return np.asarray(t_s, dtype=np.float64) * np.asarray(v0_m_s, dtype=np.float64) / (np.asarray(d0_mm) * 1e-3)


def time_of(tau, d0_mm, v0_m_s):
    """Time since impact [s] of ``tau`` (inverse of eq. 20)."""
    return np.asarray(tau, dtype=np.float64) * np.asarray(d0_mm, dtype=np.float64) * 1e-3 / np.asarray(v0_m_s)


@dataclass(frozen=True)
class ImpactCondition:
    """One row of Table 1: fall height [mm], d0 [mm], v0 [m/s], the three tau, We (printed)."""

    fall_height_mm: float
    d0_mm: float
    v0_m_s: float
    taus: tuple[float, float, float]
    we_paper: float

    @property
    def we(self) -> float:
        """eq. 19 from d0 and v0 (within a few of the printed value: d0, v0 are rounded)."""
        return float(weber(self.d0_mm, self.v0_m_s))


#: Table 1 of the seed paper, keyed by the printed Weber number.
TABLE_1: dict[int, ImpactCondition] = {
    624: ImpactCondition(600.0, 3.36, 3.74, (2.3, 4.6, 6.7), 624.0),
    784: ImpactCondition(900.0, 3.30, 4.24, (2.6, 5.1, 7.7), 784.0),
    1051: ImpactCondition(1250.0, 3.27, 4.92, (3.0, 6.0, 9.0), 1051.0),
}


def condition(we: int) -> ImpactCondition:
    """The Table 1 row of the printed Weber number ``we`` (624, 784 or 1051)."""
    if we not in TABLE_1:
        raise ConfigError(f"drop_impact: no Table 1 condition at We {we!r}; choose one of {sorted(TABLE_1)}.")
    return TABLE_1[we]


def crown_radius_mm(tau, d0_mm: float, *, film_mm: float = FILM_MM):
    """Crown base radius [mm] of Yarin & Weiss (1995): ``R/d0 = (2/(3H))^(1/4) sqrt(tau)``."""
    h = film_mm / d0_mm
    return d0_mm * (2.0 / (3.0 * h)) ** 0.25 * np.sqrt(np.maximum(np.asarray(tau, dtype=np.float64), 0.0))


def crown_speed_ratio(tau, d0_mm: float, *, film_mm: float = FILM_MM):
    """Radial speed of the crown over the impact speed, ``dR/dtau / d0 = (1/2)(2/(3H))^(1/4) tau^(-1/2)``."""
    h = film_mm / d0_mm
    return 0.5 * (2.0 / (3.0 * h)) ** 0.25 / np.sqrt(np.asarray(tau, dtype=np.float64))


#: Mean fragment diameter law ``d/d0 = q tau^n`` per printed Weber number: PLACEHOLDERS (see
#: the module notes): q = 0.199 / 3.30 = 0.0603 (the seed paper's mean at We 784, tau 5.1)
#: for every We, n = 0. Replace with Guildenbecher et al. (2014)'s fits when transcribed.
FRAGMENT_LAW: dict[int, dict] = {we: {"q": 0.199 / 3.30, "n": 0.0, "source": "placeholder: seed paper mean at We 784, "
                                      "tau 5.1; [27]'s q, n not transcribed"} for we in TABLE_1}


def fragment_field(we: float, tau: float, *, d0_mm: float, v0_m_s: float, n_fragments: int = 196,
                   q: float | None = None, n: float | None = None, sigma_ln: float = 0.5, tau_start: float = 1.0,
                   elevation_deg=(20.0, 60.0), film_mm: float = FILM_MM, d_min_mm: float = 0.0,
                   velocity_sd_mm_s: float = 0.0, seed: int = 0) -> dict:
    """Secondary fragments of one drop impact at time ``tau`` (see the module notes).

    Parameters
    ----------
    we : float
        Impact Weber number (selects :data:`FRAGMENT_LAW`'s nearest row when ``q``/``n`` are
        not given; also returned).
    tau : float
        Observation time, eq. 20 (> ``tau_start``).
    d0_mm, v0_m_s : float
        Drop diameter and impact speed (Table 1).
    n_fragments : int
        Fragments drawn (before ``d_min_mm``).
    q, n : float, optional
        The mean-diameter law ``d/d0 = q tau_e^n`` at the detachment time.
    sigma_ln : float
        Log-normal spread of the diameters about that mean.
    tau_start : float
        First detachment time.
    elevation_deg : (float, float)
        Range of the ejection angle above the film (uniform).
    d_min_mm : float
        Fragments below this diameter are dropped.
    velocity_sd_mm_s : float
        Standard deviation [mm/s] of a Gaussian velocity perturbation of each fragment in
        the film plane (x and z, independently; isotropic there, as the flow's symmetry
        wants), carried since detachment: the fragment sits ``dv (t - t_e)`` off the
        crown-model path. Real fragments scatter about the mean radial law (the seed paper's
        x model error, Fig. 25 and Table 2, is this scatter if x is measured without error).
        The vertical component is left alone, so no fragment flies into the film. 0 keeps
        the deterministic crown model.
    seed : int

    Returns
    -------
    dict: ``positions_mm`` (N, 3) at ``tau``, impact point at the origin, film normal +y
    (depth is z for a camera on the z axis); ``diameters_mm`` (N,); ``velocities_mm_s``
    (N, 3); ``tau_e`` (N,) detachment times; ``we``, ``tau``, ``t_s``.
    """
    tau = float(tau)
    d0_mm = check_positive("d0_mm", d0_mm, owner="fragment_field", unit="mm")
    v0_m_s = check_positive("v0_m_s", v0_m_s, owner="fragment_field", unit="m/s")
    if not (math.isfinite(tau) and tau > tau_start > 0):
        raise ConfigError(f"fragment_field: tau must exceed tau_start ({tau_start}) > 0, got tau = {tau!r}.")
    if isinstance(n_fragments, bool) or int(n_fragments) != n_fragments or n_fragments < 1:
        raise ConfigError(f"fragment_field: n_fragments must be a positive integer, got {n_fragments!r}.")
    lo_e, hi_e = (float(v) for v in elevation_deg)
    if not 0.0 <= lo_e <= hi_e < 90.0:
        raise ConfigError(f"fragment_field: elevation_deg must be (lo, hi) with 0 <= lo <= hi < 90, got {elevation_deg!r}.")
    velocity_sd_mm_s = float(velocity_sd_mm_s)
    if not (math.isfinite(velocity_sd_mm_s) and velocity_sd_mm_s >= 0.0):
        raise ConfigError(f"fragment_field: velocity_sd_mm_s must be a finite speed >= 0 [mm/s], got {velocity_sd_mm_s!r}.")
    if q is None or n is None:
        row = FRAGMENT_LAW[min(FRAGMENT_LAW, key=lambda w: abs(w - we))]
        q = row["q"] if q is None else q
        n = row["n"] if n is None else n
    q = check_positive("q", q, owner="fragment_field")
    rng = np.random.default_rng(seed)
    m = int(n_fragments)
    tau_e = rng.uniform(tau_start, tau, m)
    phi = rng.uniform(0.0, 2.0 * np.pi, m)
    elev = np.radians(rng.uniform(lo_e, hi_e, m))
    v0_mm_s = v0_m_s * 1e3
    vr = crown_speed_ratio(tau_e, d0_mm, film_mm=film_mm) * v0_mm_s
    vy = vr * np.tan(elev)
    dt_s = time_of(tau - tau_e, d0_mm, v0_m_s)
    r = crown_radius_mm(tau_e, d0_mm, film_mm=film_mm) + vr * dt_s
    h = vy * dt_s
    mean_d = q * tau_e ** float(n) * d0_mm
    # log-normal with this mean: median = mean exp(-sigma^2 / 2)
    d = mean_d * np.exp(sigma_ln * rng.standard_normal(m) - 0.5 * sigma_ln**2)
    pos = np.column_stack([r * np.cos(phi), h, r * np.sin(phi)])
    vel = np.column_stack([vr * np.cos(phi), vy, vr * np.sin(phi)])
    if velocity_sd_mm_s > 0.0:  # drawn after the rest: the deterministic part keeps its stream
        dv = np.zeros((m, 3))
        dv[:, [0, 2]] = velocity_sd_mm_s * rng.standard_normal((m, 2))
        vel = vel + dv
        pos = pos + dv * dt_s[:, None]
    keep = d >= d_min_mm
    return {"positions_mm": pos[keep], "diameters_mm": d[keep], "velocities_mm_s": vel[keep], "tau_e": tau_e[keep],
            "we": float(we), "tau": tau, "t_s": float(time_of(tau, d0_mm, v0_m_s))}
