"""Laser-sheet thickness profiles, shared by the ``laser_sheet`` plugin and NumPy code.

``s`` is the signed distance from the sheet mid-plane along the sheet normal [mm] and
``thickness`` the full width at half maximum (FWHM) [mm]. All profiles equal 1 on the
mid-plane and 1/2 at ``|s| = thickness/2``:

- ``gaussian``:       exp(-4 ln2 s^2 / t^2)
- ``supergaussian``:  ``2^(-(2|s|/t)^order)``  (order 2 is the Gaussian; large orders tend to
  the top hat)
- ``tophat``:         1 for ``|s| <= t/2``, else 0  (edge value 1/2 at exactly ``|s| = t/2`` is
  not represented; the FWHM is t).

The functions take an array namespace ``xp`` (``numpy`` or :data:`DRJIT_OPS`) so the same
formula is evaluated in float64 in tests and in float32 inside Mitsuba kernels.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from mitpiv.errors import ConfigError

__all__ = ["PROFILES", "sheet_profile", "check_profile", "profile_integral", "peak_irradiance", "NUMPY_OPS", "drjit_ops"]

PROFILES = ("gaussian", "tophat", "supergaussian")
LN2 = math.log(2.0)

NUMPY_OPS = SimpleNamespace(exp=np.exp, abs=np.abs, power=np.power, where=np.where)


def drjit_ops():
    """Array namespace for Dr.Jit arrays (imported lazily: physics/ imports no renderer)."""
    import drjit as dr

    return SimpleNamespace(exp=dr.exp, abs=dr.abs, power=dr.power, where=dr.select)


def check_profile(profile: str, order: float, *, owner: str = "laser_sheet") -> None:
    if profile not in PROFILES:
        raise ConfigError(
            f"{owner}: parameter 'profile' must be one of {', '.join(PROFILES)}, got {profile!r}."
        )
    if profile == "supergaussian" and not (order > 0 and math.isfinite(order)):
        raise ConfigError(f"{owner}: parameter 'order' must be > 0 for a super-Gaussian, got {order!r}.")


def sheet_profile(s, thickness: float, profile: str = "gaussian", order: float = 2.0, *, xp=NUMPY_OPS):
    """Relative irradiance (0..1) at signed distance ``s`` [mm] from the mid-plane."""
    q = s * (2.0 / thickness)
    if profile == "gaussian":
        return xp.exp(-LN2 * q * q)
    if profile == "supergaussian":
        return xp.exp(-LN2 * xp.power(xp.abs(q), float(order)))
    if profile == "tophat":
        return xp.where(xp.abs(q) <= 1.0, 1.0 + 0.0 * q, 0.0 * q)
    raise ConfigError(f"sheet_profile: unknown profile {profile!r}; use one of {PROFILES}.")


def profile_integral(thickness: float, profile: str = "gaussian", order: float = 2.0) -> float:
    """``integral of the profile over s`` [mm]: the sheet's effective thickness, peak
    irradiance x this x width = power. Gaussian ``t sqrt(pi / ln 2) / 2`` (1.064 t),
    super-Gaussian ``t Gamma(1 + 1/order) / ln2^(1/order)``, top hat ``t``."""
    check_profile(profile, order, owner="sheet")
    if profile == "tophat":
        return float(thickness)
    n = 2.0 if profile == "gaussian" else float(order)
    return float(thickness) * math.gamma(1.0 + 1.0 / n) / LN2 ** (1.0 / n)


def peak_irradiance(pulse_energy_mj: float, pulse_duration_ns: float, thickness_mm: float, width_mm: float,
                    profile: str = "gaussian", order: float = 2.0) -> float:
    """The peak irradiance [W/mm^2] (the ``laser_sheet``'s ``irradiance``) of a pulsed sheet:
    the pulse's mean power over its cross-section, ``E / (tau w integral g(s) ds)``, with the
    width ``w`` [mm] uniformly lit. With the pulse duration as the sensor model's
    ``illumination_time_s`` the counts are in photons (:mod:`mitpiv.photometry`)."""
    from mitpiv.errors import check_positive

    e = check_positive("pulse_energy_mj", pulse_energy_mj, owner="sheet", unit="mJ") * 1e-3
    tau = check_positive("pulse_duration_ns", pulse_duration_ns, owner="sheet", unit="ns") * 1e-9
    t = check_positive("thickness_mm", thickness_mm, owner="sheet", unit="mm")
    w = check_positive("width_mm", width_mm, owner="sheet", unit="mm")
    return e / (tau * w * profile_integral(t, profile, order))
