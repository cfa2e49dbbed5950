"""An independent Mie reference for the table and rendering tests: miepython called directly
in float64 (not through mitpiv.physics.mie), and deep minima located numerically on it.

miepython 3.3.0 agrees with Wiscombe's MIEV0 tables and with a 40-digit mpmath reference to
<= 1e-11 on efficiencies for x up to 1e4 (shared/REFERENCE.md, Mie section). It writes the
index as n - ik; the indices used here are real.
"""

import math

import numpy as np

from mitpiv.physics import mie


def miepython_par_per(d_um, theta_rad, m=1.45, wavelength_nm=532.0):
    """p_par, p_per [1/sr] for linearly polarised light: |S2|^2 and |S1|^2 over pi x^2 Qsca,
    x = pi d / lambda in air, from miepython directly (float64)."""
    mie._engine()  # imports miepython with numba on; the pure-Python path takes minutes here
    import miepython

    x = math.pi * d_um * 1e3 / wavelength_nm
    _, qsca, _, _ = miepython.efficiencies_mx(m, x)
    s1, s2 = miepython.S1_S2(m, x, np.cos(np.atleast_1d(np.asarray(theta_rad, dtype=np.float64))), norm="wiscombe")
    k = math.pi * x * x * qsca
    return np.abs(s2) ** 2 / k, np.abs(s1) ** 2 / k


def refine_minimum(d_um, k, lo, hi, m=1.45):
    """Angle [rad], value and width [rad] of the minimum of p_par (k = 0) or p_per (k = 1) in
    [lo, hi] (bounded scalar minimisation); the width w from the curvature,
    p ~ a^2 ((t - t0)^2 + w^2)."""
    from scipy.optimize import minimize_scalar

    def f(t):
        return miepython_par_per(d_um, [t], m)[k][0]

    r = minimize_scalar(f, bounds=(lo, hi), method="bounded", options={"xatol": 1e-10})
    h = 1e-6
    f2 = (f(r.x + h) + f(r.x - h) - 2 * r.fun) / h**2
    return r.x, r.fun, math.sqrt(2 * r.fun / f2)


def deep_minima(d_um, depth_max, m=1.45):
    """Minima of p_par and p_per below ``depth_max`` times the largest value within two ripple
    periods (pi/x) around them: rows (angle [rad], width [rad], depth, k) with k = 0 for
    p_par and 1 for p_per, located on a dense scan and refined."""
    x = math.pi * d_um * 1e3 / 532.0
    th = np.linspace(1e-4, math.pi - 1e-4, 40001)
    out = []
    for k, f in enumerate(miepython_par_per(d_um, th, m)):
        for i in np.flatnonzero((f[1:-1] < f[:-2]) & (f[1:-1] < f[2:])) + 1:
            t0, p0, w = refine_minimum(d_um, k, th[i - 1], th[i + 1], m)
            depth = p0 / f[np.abs(th - t0) < 2 * math.pi / x].max()
            if depth < depth_max:
                out.append((t0, w, depth, k))
    return np.array(out)
