"""Optical phase of the shock waves of supersonic projectiles, seen by a collimated beam
(the DIH arm of seed paper 003's shotgun experiment, Figs. 30-31: "the vertical bands in
the DIH images are a result of shockwaves visible due to the use of collimated laser
light", absent from the plenoptic images recorded with diffuse white light).

Hand-written model (no library models this; vectorised over grid points, chunked over
pellets): each pellet moving at Mach ``M`` along a direction in the x-y plane (normal to
the beam, which travels along +z) carries a conical shock of half-angle
``mu = asin(1/M)`` (the Mach cone) with its apex at the pellet, opening behind it. The
compressed gas is a conical shell of radial thickness ``thickness_mm`` whose density
excess decays with the distance ``s`` behind the apex as Whitham's far field of a body of
revolution, ``(s / d)^(-3/4)``, from the normal-shock jump of the Rankine-Hugoniot relation
at the pellet, ``rho2/rho1 - 1 = (gamma+1) M^2 / ((gamma-1) M^2 + 2) - 1``. The beam's
phase is ``k (n - 1)_inf (drho/rho) L``, ``L`` the chord of the beam line through the shell
(annulus between ``R = s tan mu`` and ``R + t``): ``2 (sqrt((R+t)^2 - y^2) - sqrt(R^2 - y^2))``
(the second root 0 where ``|y| > R``), ``y`` the distance from the cone axis in the
x-y plane. (n - 1) of air from the Gladstone-Dale constant 2.26e-4 m^3/kg at 1.2 kg/m^3.
The model's shell thickness and decay are our choices (the paper quantifies no shock); the
observable the replication compares is qualitative: bands in DIH, none in plenoptic.
"""

from __future__ import annotations

import math

import numpy as np

from mitpiv.errors import ConfigError, check_positive

__all__ = ["AIR_N_MINUS_1", "normal_shock_density_ratio", "mach_angle_deg", "shock_phase"]

#: (n - 1) of air at 1.2 kg/m^3 (Gladstone-Dale K = 2.26e-4 m^3/kg).
AIR_N_MINUS_1 = 2.26e-4 * 1.2


def normal_shock_density_ratio(mach, gamma: float = 1.4):
    """Rankine-Hugoniot density ratio across a normal shock, ``(g+1) M^2 / ((g-1) M^2 + 2)``."""
    m2 = np.asarray(mach, dtype=np.float64) ** 2
    return (gamma + 1.0) * m2 / ((gamma - 1.0) * m2 + 2.0)


def mach_angle_deg(mach) -> float:
    """Mach-cone half-angle ``asin(1/M)`` [deg] (M > 1)."""
    m = float(mach)
    if not m > 1.0:
        raise ConfigError(f"mach_angle_deg: a Mach cone needs M > 1, got {mach!r}.")
    return math.degrees(math.asin(1.0 / m))


def shock_phase(x_mm, y_mm, pellets_xy_mm, *, diameter_mm: float, mach: float, wavelength_nm: float,
                direction=(-1.0, 0.0), thickness_mm: float | None = None, chunk: int = 8) -> np.ndarray:
    """Phase [rad] added to a beam along z at points (x, y) by the pellets' Mach cones.

    Parameters
    ----------
    x_mm, y_mm : arrays broadcasting to the grid shape
    pellets_xy_mm : (N, 2) pellet positions projected on the x-y plane
    diameter_mm, mach : pellet diameter and Mach number (> 1)
    wavelength_nm : beam wavelength
    direction : (2,) direction of flight in the x-y plane (the cone opens the other way)
    thickness_mm : radial thickness of the compressed shell (default a quarter diameter)
    """
    d = check_positive("diameter_mm", diameter_mm, owner="shock_phase", unit="mm")
    mu = math.radians(mach_angle_deg(mach))
    t = d / 4.0 if thickness_mm is None else check_positive("thickness_mm", thickness_mm, owner="shock_phase", unit="mm")
    k = 2.0 * math.pi / (check_positive("wavelength_nm", wavelength_nm, owner="shock_phase", unit="nm") * 1e-6)
    jump = float(normal_shock_density_ratio(mach)) - 1.0
    e = np.asarray(direction, dtype=np.float64)
    e = e / np.linalg.norm(e)
    x, y = np.broadcast_arrays(np.asarray(x_mm, dtype=np.float64), np.asarray(y_mm, dtype=np.float64))
    p = np.asarray(pellets_xy_mm, dtype=np.float64).reshape(-1, 2)
    out = np.zeros(x.shape)
    for b in range(0, p.shape[0], max(1, int(chunk))):
        q = p[b:b + chunk].reshape((-1, 2) + (1,) * x.ndim)
        dx = x[None] - q[:, 0]
        dy = y[None] - q[:, 1]
        s = -(dx * e[0] + dy * e[1])  # distance behind the apex along the cone axis
        r = np.abs(-dx * e[1] + dy * e[0])  # distance from the axis in the plane
        behind = s > 0
        big_r = np.where(behind, s, 0.0) * math.tan(mu)
        chord = 2.0 * (np.sqrt(np.clip((big_r + t) ** 2 - r * r, 0.0, None)) - np.sqrt(np.clip(big_r**2 - r * r, 0.0, None)))
        excess = jump * np.minimum(1.0, (np.maximum(s, 1e-12) / d) ** -0.75)
        out += np.sum(np.where(behind, k * AIR_N_MINUS_1 * excess * chord, 0.0), axis=0)
    return out
