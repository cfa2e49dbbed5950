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

__all__ = ["PROFILES", "sheet_profile", "check_profile", "profile_integral", "peak_irradiance", "NUMPY_OPS", "drjit_ops",
           "plane_box_section", "plane_basis", "clip_polygon", "polygon_points"]

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


# ---------------------------------------------------------------------- geometry of the mid-plane
def plane_box_section(point_mm, normal, lower_mm, upper_mm) -> np.ndarray:
    """The convex polygon where a plane (through ``point_mm``, normal ``normal``) cuts an
    axis-aligned box: (K, 3) vertices [mm] in order round the normal (K from 3 to 6), or an
    empty (0, 3) array where the plane misses the box."""
    p0, n = np.asarray(point_mm, float), np.asarray(normal, float)
    n = n / np.linalg.norm(n)
    lo, hi = np.asarray(lower_mm, float), np.asarray(upper_mm, float)
    corners = np.array([[(lo, hi)[(k >> i) & 1][i] for i in range(3)] for k in range(8)])
    d = (corners - p0) @ n
    pts = [corners[a] for a in range(8) if d[a] == 0]
    for a in range(8):
        for i in range(3):
            b = a | (1 << i)  # the 12 edges, each once (a < b)
            if b != a and d[a] * d[b] < 0:
                pts.append(corners[a] + (corners[b] - corners[a]) * d[a] / (d[a] - d[b]))
    return _ordered(np.array(pts).reshape(-1, 3), n)


def _ordered(pts, n, tol: float = 1e-9) -> np.ndarray:
    """Distinct coplanar points in order round the normal ``n`` (their convex polygon)."""
    if len(pts) == 0:
        return np.zeros((0, 3))
    keep = []
    scale = max(float(np.ptp(pts, axis=0).max()), 1.0)
    for p in pts:
        if all(np.linalg.norm(p - q) > tol * scale for q in keep):
            keep.append(p)
    pts = np.array(keep)
    if len(pts) < 3:
        return np.zeros((0, 3))
    u, v = plane_basis(n)
    c = pts.mean(axis=0)
    ang = np.arctan2((pts - c) @ v, (pts - c) @ u)
    return pts[np.argsort(ang)]


def plane_basis(normal) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors ``u, v`` with ``(u, v, n)`` right-handed and orthonormal."""
    n = np.asarray(normal, float) / np.linalg.norm(normal)
    a = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(a, n)
    u /= np.linalg.norm(u)
    return u, np.cross(n, u)


def clip_polygon(poly, point_mm, outward) -> np.ndarray:
    """The part of a convex polygon (K, 3) on the side ``(x - point) . outward <= 0`` of a
    plane (Sutherland-Hodgman); (0, 3) when nothing is left."""
    poly = np.asarray(poly, float)
    if len(poly) == 0:
        return poly.reshape(0, 3)
    d = (poly - np.asarray(point_mm, float)) @ np.asarray(outward, float)
    out = []
    for k in range(len(poly)):
        a, b, da, db = poly[k], poly[(k + 1) % len(poly)], d[k], d[(k + 1) % len(poly)]
        if da <= 0:
            out.append(a)
        if da * db < 0:
            out.append(a + (b - a) * da / (da - db))
    return np.array(out).reshape(-1, 3) if len(out) >= 3 else np.zeros((0, 3))


def polygon_points(poly, n: int = 32) -> np.ndarray:
    """Points (M, 3) on an ``n`` x ``n`` grid over a planar convex polygon (K, 3), those inside it."""
    poly = np.asarray(poly, float)
    if len(poly) < 3:
        return np.zeros((0, 3))
    normal = np.cross(poly[1] - poly[0], poly[2] - poly[0])
    for k in range(3, len(poly)):  # a longer cross product where the first three are nearly collinear
        c = np.cross(poly[k - 1] - poly[0], poly[k] - poly[0])
        normal = c if np.linalg.norm(c) > np.linalg.norm(normal) else normal
    if np.linalg.norm(normal) == 0:
        return np.zeros((0, 3))
    u, v = plane_basis(normal)
    c = poly.mean(axis=0)
    xy = np.stack([(poly - c) @ u, (poly - c) @ v], axis=-1)
    gx = np.linspace(xy[:, 0].min(), xy[:, 0].max(), n + 2)[1:-1]
    gy = np.linspace(xy[:, 1].min(), xy[:, 1].max(), n + 2)[1:-1]
    g = np.stack(np.meshgrid(gx, gy, indexing="ij"), axis=-1).reshape(-1, 2)
    e = np.roll(xy, -1, axis=0) - xy
    cross = e[None, :, 0] * (g[:, None, 1] - xy[None, :, 1]) - e[None, :, 1] * (g[:, None, 0] - xy[None, :, 0])
    inside = np.all(cross >= 0, axis=1) | np.all(cross <= 0, axis=1)
    g = g[inside]
    return c + g[:, :1] * u + g[:, 1:] * v
