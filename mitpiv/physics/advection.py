"""Advection of particles through a flow with classical fourth-order Runge-Kutta."""

from __future__ import annotations

import numpy as np

from mitpiv.errors import ConfigError, check_positive

__all__ = ["advect", "rk4_steps"]


def advect(positions_mm, flow, *, dt_s: float, t0_s: float = 0.0, substeps: int = 10) -> np.ndarray:
    """Positions after ``dt_s`` seconds of RK4 integration in ``substeps`` equal steps.

    Parameters
    ----------
    positions_mm : (N, 3) array
        Start positions [mm] at time ``t0_s``.
    flow : callable
        ``flow(p_mm, t_s) -> (N, 3)`` velocity [mm/s].
    dt_s : float
        Time between frames [s].
    substeps : int
        RK4 steps per ``dt_s``; the error falls as ``substeps**-4``.
    """
    dt = check_positive("dt_s", dt_s, owner="advect", unit="s")
    if int(substeps) != substeps or substeps < 1:
        raise ConfigError(f"advect: 'substeps' must be a positive integer, got {substeps!r}.")
    return rk4_steps(positions_mm, flow, t0_s=t0_s, dt_s=dt, substeps=int(substeps))


def rk4_steps(positions_mm, flow, *, t0_s: float, dt_s: float, substeps: int) -> np.ndarray:
    """Positions (N, 3) [mm] after ``dt_s`` (may be negative: backward in time) of classical
    RK4 in ``substeps`` equal steps from time ``t0_s``; no argument checks (see :func:`advect`)."""
    p = np.array(positions_mm, dtype=np.float64).reshape(-1, 3)
    h = float(dt_s) / int(substeps)
    t = float(t0_s)
    for _ in range(int(substeps)):
        k1 = flow(p, t)
        k2 = flow(p + 0.5 * h * k1, t + 0.5 * h)
        k3 = flow(p + 0.5 * h * k2, t + 0.5 * h)
        k4 = flow(p + h * k3, t + h)
        p = p + (h / 6.0) * (k1 + 2 * k2 + 2 * k3 + k4)
        t += h
    return p
