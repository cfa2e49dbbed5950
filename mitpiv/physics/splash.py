"""Secondary droplets of a drop splashing on a wetted wall: the Bai & Gosman splash model, an
independent source of the fragment count, sizes and speeds for the drop-impact study (issue
49: the study's count, mean size and velocity scatter were the seed paper's own results).

The model (Bai & Gosman 1995, SAE 950283; Bai, Rusche & Gosman 2002, Atomization and Sprays
12, 1-27), as OpenFOAM's ``ThermoSurfaceFilm`` splash interaction states it (read, not
copied; hand-written here because no Python library models a splash), for a drop of
diameter ``d``, density ``rho``, surface tension ``sigma`` and viscosity ``mu`` hitting a
wetted wall with normal speed ``v``::

    La  = rho sigma d / mu^2                     Laplace number
    We  = rho v^2 d / sigma                      Weber number
    We_c = A La^(-0.183)                         splash threshold (A = 1320 wet, 2630 dry)
    regimes (wet wall): We < 1 stick, < 20 bounce, < We_c spread, else splash
    m_s / m ~ U(0.2, 1.1) (wet), U(0.2, 0.8) (dry)   splashed mass over the drop's
    N_s = 5 (We / We_c - 1)                      secondary droplets per impact
    p(d_i) ~ exp(-d_i / d_bar) on [d_min, d_max] a truncated exponential, with
    d_bar = d (m_s / (6 m N_s))^(1/3)            (the untruncated law conserves the mass)
    d_max = 0.9 d (m_s / m)^(1/3), d_min = d_max / 10
    E_ks = E_k + sigma pi d^2 - sigma pi sum d_i^2 - E_d,   E_d = max(0.8 E_k, We_c sigma pi d^2 / 12)
    |u_i| proportional to |ln(d_i / d)|, scaled so that sum m_i u_i^2 / 2 = E_ks
    directions: 5-50 deg from the wall normal, uniform azimuth

Its validity for this study's drops (3.3 mm water drops on a 2.35 mm film, We 624-1051) is
not established: it is a spray model calibrated on small drops, and it ignores the film's
depth (Bai et al. 2002 give no calibration range). Two stored checks bound it: it predicts
18 / 24 / 33 droplets at the seed paper's three conditions, against about 15 / 22 / 31 from
the linear law of *Science* 155:1112 (1967; "about 25 spray droplets" for a 3 mm drop falling
100 cm, growing linearly with the fall height from 10 to 200 cm: :func:`science_1967_count`);
both count droplets an experiment resolves, so fine droplets below their resolution are
missing from both (the seed paper's holography found 196 per realisation). Neither gives a
time dependence of the sizes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mitpiv.errors import ConfigError, check_positive

__all__ = ["A_WET", "A_DRY", "laplace_number", "splash_threshold", "regime", "SplashModel", "bai_gosman",
           "science_1967_count"]

#: splash threshold coefficients of We_c = A La^-0.183 (Bai et al. 2002: wet, dry wall)
A_WET = 1320.0
A_DRY = 2630.0
#: viscosity of water at 20 deg C [Pa s] (the seed paper does not state it)
MU_WATER_PA_S = 1.0e-3


def laplace_number(d_mm, *, rho_kg_m3: float = 1000.0, sigma_n_m: float = 0.076, mu_pa_s: float = MU_WATER_PA_S):
    """``La = rho sigma d / mu^2`` (d in mm)."""
    return rho_kg_m3 * sigma_n_m * np.asarray(d_mm, dtype=np.float64) * 1e-3 / mu_pa_s**2


def splash_threshold(la, *, wet: bool = True):
    """Critical Weber number ``We_c = A La^-0.183`` (A = :data:`A_WET` or :data:`A_DRY`)."""
    return (A_WET if wet else A_DRY) * np.asarray(la, dtype=np.float64) ** -0.183


def regime(we: float, la: float, *, wet: bool = True) -> str:
    """Bai-Gosman regime of an impact: "stick", "bounce", "spread" or "splash" (a dry wall:
    "adhere" below We_c, else "splash")."""
    wec = float(splash_threshold(la, wet=wet))
    if not wet:
        return "adhere" if we < wec else "splash"
    if we < 1.0:
        return "stick"
    if we < 20.0:
        return "bounce"
    return "spread" if we < wec else "splash"


@dataclass(frozen=True)
class SplashModel:
    """The Bai-Gosman splash of one drop (SI units inside, mm and m/s outside)."""

    d_mm: float
    v_m_s: float
    rho_kg_m3: float = 1000.0
    sigma_n_m: float = 0.076
    mu_pa_s: float = MU_WATER_PA_S
    wet: bool = True

    def __post_init__(self):
        for name in ("d_mm", "v_m_s", "rho_kg_m3", "sigma_n_m", "mu_pa_s"):
            check_positive(name, getattr(self, name), owner="SplashModel")

    @property
    def we(self) -> float:
        from mitpiv.physics.drop_impact import weber

        return float(weber(self.d_mm, self.v_m_s, rho_kg_m3=self.rho_kg_m3, sigma_n_m=self.sigma_n_m))

    @property
    def la(self) -> float:
        return float(laplace_number(self.d_mm, rho_kg_m3=self.rho_kg_m3, sigma_n_m=self.sigma_n_m,
                                    mu_pa_s=self.mu_pa_s))

    @property
    def we_c(self) -> float:
        return float(splash_threshold(self.la, wet=self.wet))

    @property
    def mass_ratio_range(self) -> tuple[float, float]:
        return (0.2, 1.1) if self.wet else (0.2, 0.8)

    @property
    def n_splash(self) -> float:
        """Secondary droplets per impact, ``5 (We / We_c - 1)`` (0 below the threshold)."""
        return max(5.0 * (self.we / self.we_c - 1.0), 0.0)

    def size_law(self, mass_ratio: float) -> tuple[float, float, float]:
        """``(d_bar, d_min, d_max)`` [mm] of the truncated exponential at a splashed mass ratio."""
        ns = self.n_splash
        if ns <= 0:
            raise ConfigError(f"SplashModel: We {self.we:.4g} is below the splash threshold We_c {self.we_c:.4g}; "
                              "no secondary droplets.")
        d_bar = self.d_mm * (mass_ratio / (6.0 * ns)) ** (1.0 / 3.0)
        d_max = 0.9 * self.d_mm * mass_ratio ** (1.0 / 3.0)
        return d_bar, 0.1 * d_max, d_max

    def mean_diameter_mm(self, mass_ratio: float) -> float:
        """Mean of the truncated exponential on [d_min, d_max] (closed form)."""
        b, lo, hi = self.size_law(mass_ratio)
        ea, eb = math.exp(-lo / b), math.exp(-hi / b)
        return b + (lo * ea - hi * eb) / (ea - eb)

    def sample(self, rng: np.random.Generator, *, count: int | None = None) -> dict:
        """One splash: the mass ratio, the droplets' diameters [mm] (inverse-CDF draws of the
        truncated exponential), speeds [m/s] from the energy balance and unit directions
        (y the wall normal, 5-50 deg from it). ``count`` defaults to ``N_s`` rounded
        stochastically (its integer part, plus one with the fractional part's probability)."""
        ns = self.n_splash
        if ns <= 0:
            raise ConfigError(f"SplashModel: We {self.we:.4g} is below the splash threshold We_c {self.we_c:.4g}.")
        lo_m, hi_m = self.mass_ratio_range
        mr = float(rng.uniform(lo_m, hi_m))
        if count is None:
            count = int(math.floor(ns)) + int(rng.random() < ns - math.floor(ns))
        count = max(int(count), 1)
        b, lo, hi = self.size_law(mr)
        y = rng.random(count)
        k = math.exp(-lo / b) - math.exp(-hi / b)
        d = -b * np.log(math.exp(-lo / b) - y * k)
        d_m, di_m = self.d_mm * 1e-3, d * 1e-3
        mass = self.rho_kg_m3 * math.pi / 6.0 * d_m**3
        ek = 0.5 * mass * self.v_m_s**2
        e_d = max(0.8 * ek, self.we_c / 12.0 * math.pi * self.sigma_n_m * d_m**2)
        eks = ek + self.sigma_n_m * math.pi * (d_m**2 - float(np.sum(di_m**2))) - e_d
        mi = self.rho_kg_m3 * math.pi / 6.0 * di_m**3
        shape = np.abs(np.log(di_m / d_m))
        norm = float(np.sum(mi * shape**2))
        speed = np.sqrt(max(2.0 * eks, 0.0) / norm) * shape if norm > 0 else np.zeros(count)
        theta = np.radians(rng.uniform(5.0, 50.0, count))
        phi = rng.uniform(0.0, 2.0 * math.pi, count)
        direction = np.column_stack([np.sin(theta) * np.cos(phi), np.cos(theta), np.sin(theta) * np.sin(phi)])
        return {"mass_ratio": mr, "diameters_mm": d, "speeds_m_s": speed, "directions": direction,
                "splash_energy_j": eks, "kinetic_energy_in_j": ek}


def bai_gosman(d_mm: float, v_m_s: float, **kw) -> SplashModel:
    """:class:`SplashModel` of a drop of ``d_mm`` hitting a wetted wall at ``v_m_s``."""
    return SplashModel(d_mm=d_mm, v_m_s=v_m_s, **kw)


def science_1967_count(fall_height_mm):
    """Spray droplets of a 3 mm water drop splashing on water after falling ``fall_height_mm``
    (*Science* 155:1112, 1967: linear in the fall height over 10-200 cm, about 25 at 100 cm)."""
    h = np.asarray(fall_height_mm, dtype=np.float64)
    if np.any((h < 100.0) | (h > 2000.0)):
        raise ConfigError(f"science_1967_count: fall_height_mm must lie in the law's 100-2000 mm, got {fall_height_mm!r}.")
    return 25.0 * h / 1000.0
