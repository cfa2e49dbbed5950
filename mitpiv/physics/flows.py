"""Analytic and gridded flows as callables ``u = flow(p_world_mm, t_s)`` in mm/s.

Every flow takes points of shape (N, 3) [mm] and a time [s] and returns velocities of
shape (N, 3) [mm/s], vectorised. ``flow.to_dict()`` / :func:`flow_from_dict` let a truth
file rebuild the flow, so it can be evaluated at any query point later.

Axisymmetric flows are defined in a frame with origin ``center`` and symmetry axis
``axis``; ``r`` is the distance from the axis and ``z`` the coordinate along it.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from scipy.interpolate import RegularGridInterpolator

from mitpiv.errors import ConfigError, FileFormatError, check_positive
from mitpiv.physics.flow_base import Flow
from mitpiv.physics.jet import NearFieldJet

__all__ = [
    "FLOW_KINDS",
    "Flow",
    "Uniform",
    "SolidBody",
    "LambOseen",
    "Burgers",
    "HillVortex",
    "VortexRing",
    "ABC",
    "RoundJet",
    "GridFlow",
    "Channel",
    "flow_from_dict",
]


def _unit(v, name: str) -> np.ndarray:
    a = np.asarray(v, dtype=float).reshape(3)
    n = np.linalg.norm(a)
    if n == 0:
        raise ConfigError(f"flow: '{name}' must be a non-zero vector, got {a.tolist()}.")
    return a / n


class _Axisymmetric(Flow):
    def __init__(self, center, axis):
        self.center = np.asarray(center, dtype=float).reshape(3)
        self.axis = _unit(axis, "axis")

    def _cyl(self, p, center=None):
        c = self.center if center is None else center
        rel = p - c
        z = rel @ self.axis
        radial = rel - z[:, None] * self.axis
        r = np.linalg.norm(radial, axis=1)
        safe = np.where(r > 0, r, 1.0)
        e_r = radial / safe[:, None]
        e_t = np.cross(self.axis, e_r)
        return r, z, e_r, e_t


class Uniform(Flow):
    """Uniform translation ``u = velocity_mm_s``.

    Parameters
    ----------
    velocity_mm_s : (float, float, float)
        The velocity of every point, at every time [mm/s]; default (1, 0, 0).
    """

    kind = "uniform"

    def __init__(self, velocity_mm_s=(1.0, 0.0, 0.0)):
        self.velocity_mm_s = np.asarray(velocity_mm_s, dtype=float).reshape(3)

    def velocity(self, p, t):
        return np.broadcast_to(self.velocity_mm_s, p.shape).copy()


class SolidBody(_Axisymmetric):
    """Solid-body rotation ``u = omega axis x (p - center)``, omega [rad/s].

    Parameters
    ----------
    omega_rad_s : float
        Angular velocity omega [rad/s]: the speed at distance ``r`` from the axis is
        ``omega r``; positive turns right-handed about ``axis``.
    center : (float, float, float)
        A point on the rotation axis [mm]; default the origin.
    axis : (float, float, float)
        Direction of the rotation axis (any non-zero length; normalised); default +z.
    """

    kind = "solid_body"

    def __init__(self, omega_rad_s=1.0, center=(0, 0, 0), axis=(0, 0, 1)):
        super().__init__(center, axis)
        self.omega_rad_s = float(omega_rad_s)

    def velocity(self, p, t):
        return self.omega_rad_s * np.cross(self.axis, p - self.center)


class LambOseen(_Axisymmetric):
    """Lamb-Oseen vortex: ``u_theta = G / (2 pi r) (1 - exp(-r^2 / rc^2))``.

    A straight, steady vortex with a Gaussian core: vorticity ``G / (pi rc^2) exp(-r^2 / rc^2)``
    along ``axis``, no radial or axial velocity.

    Parameters
    ----------
    circulation_mm2_s : float
        Total circulation G [mm^2/s]: the line integral of the velocity round a circle far
        outside the core (there ``u_theta = G / (2 pi r)``); positive turns right-handed about
        ``axis``.
    core_radius_mm : float
        Core radius rc [mm] (> 0): the e-folding radius of the Gaussian vorticity; the
        azimuthal speed peaks at ``r = 1.121 rc``.
    center : (float, float, float)
        A point on the vortex axis [mm]; default the origin.
    axis : (float, float, float)
        Direction of the vortex axis (any non-zero length; normalised); default +z.
    """

    kind = "lamb_oseen"

    def __init__(self, circulation_mm2_s=1000.0, core_radius_mm=1.0, center=(0, 0, 0), axis=(0, 0, 1)):
        super().__init__(center, axis)
        self.circulation_mm2_s = float(circulation_mm2_s)
        self.core_radius_mm = check_positive("core_radius_mm", core_radius_mm, owner="LambOseen", unit="mm")

    def _u_theta(self, r, rc2):
        g = self.circulation_mm2_s
        # (1 - exp(-x)) / r computed stably near the axis.
        x = r * r / rc2
        return g / (2 * math.pi) * np.where(r > 1e-12, -np.expm1(-x) / np.where(r > 0, r, 1.0), 0.0)

    def velocity(self, p, t):
        r, z, e_r, e_t = self._cyl(p)
        return self._u_theta(r, self.core_radius_mm**2)[:, None] * e_t


class Burgers(LambOseen):
    """Burgers vortex: ``u_r = -a r / 2``, ``u_z = a z``,
    ``u_theta = G / (2 pi r) (1 - exp(-a r^2 / (4 nu)))``.

    ``r`` and ``z`` are measured from ``center`` (the stagnation point). The axial strain
    stretches the vortex and balances its viscous spreading: a steady Lamb-Oseen core of
    radius ``sqrt(4 nu / a)``.

    Parameters
    ----------
    circulation_mm2_s : float
        Total circulation G [mm^2/s] (far from the core ``u_theta = G / (2 pi r)``); positive
        turns right-handed about ``axis``.
    strain_rate_1_s : float
        Axial strain rate a [1/s] (> 0) of the stretching flow: inflow ``u_r = -a r / 2``,
        outflow ``u_z = a z`` along the axis.
    viscosity_mm2_s : float
        Kinematic viscosity nu [mm^2/s] (> 0; water 1, air 15); with ``a`` it sets the core
        radius ``sqrt(4 nu / a)`` [mm].
    center : (float, float, float)
        The stagnation point on the vortex axis (``u = 0`` there) [mm]; default the origin.
    axis : (float, float, float)
        Direction of the vortex axis, along which the fluid flows out (any non-zero length;
        normalised); default +z.
    """

    kind = "burgers"

    def __init__(self, circulation_mm2_s=1000.0, strain_rate_1_s=1.0, viscosity_mm2_s=1.0, center=(0, 0, 0), axis=(0, 0, 1)):
        _Axisymmetric.__init__(self, center, axis)
        self.circulation_mm2_s = float(circulation_mm2_s)
        self.strain_rate_1_s = check_positive("strain_rate_1_s", strain_rate_1_s, owner="Burgers", unit="1/s")
        self.viscosity_mm2_s = check_positive("viscosity_mm2_s", viscosity_mm2_s, owner="Burgers", unit="mm^2/s")

    def to_dict(self) -> dict:
        d = super().to_dict()
        d.pop("core_radius_mm", None)
        return d

    def velocity(self, p, t):
        a = self.strain_rate_1_s
        r, z, e_r, e_t = self._cyl(p)
        ut = self._u_theta(r, 4 * self.viscosity_mm2_s / a)
        return (-0.5 * a * r)[:, None] * e_r + (a * z)[:, None] * self.axis + ut[:, None] * e_t


class HillVortex(_Axisymmetric):
    """Hill's spherical vortex of radius ``radius_mm`` translating at ``speed_mm_s``.

    In the vortex frame (free stream ``-U`` along ``axis``), with ``R^2 = r^2 + z^2``:
    inside ``u_z = 1.5 U (1 - (2 r^2 + z^2) / a^2)``, ``u_r = 1.5 U r z / a^2``; outside
    ``u_z = U [(a/R)^5 (2 z^2 - r^2) / (2 a^2) - 1]``, ``u_r = 1.5 U (r z / a^2) (a/R)^5``.
    With ``frame="lab"`` (default) ``U`` is added along the axis (fluid at rest far away)
    and the vortex centre moves as ``center + U t axis``.

    Parameters
    ----------
    radius_mm : float
        Radius a of the spherical vortex [mm] (> 0).
    speed_mm_s : float
        Translation speed U of the vortex along ``axis`` [mm/s] (the free-stream speed in the
        vortex frame); the fluid inside moves at up to 2.5 U in the lab frame.
    center : (float, float, float)
        Centre of the sphere at ``t = 0`` [mm] (in the lab frame it moves with ``U``);
        default the origin.
    axis : (float, float, float)
        Direction of travel, the symmetry axis (any non-zero length; normalised); default +z.
    frame : {'lab', 'vortex'}
        ``"lab"``: fluid at rest far away, the vortex moves; ``"vortex"``: the steady field
        in the frame moving with the vortex (a uniform stream ``-U axis`` far away).
        Default ``"lab"``.
    """

    kind = "hill_vortex"

    def __init__(self, radius_mm=5.0, speed_mm_s=100.0, center=(0, 0, 0), axis=(0, 0, 1), frame="lab"):
        super().__init__(center, axis)
        self.radius_mm = check_positive("radius_mm", radius_mm, owner="HillVortex", unit="mm")
        self.speed_mm_s = float(speed_mm_s)
        if frame not in ("lab", "vortex"):
            raise ConfigError(f"HillVortex: 'frame' must be 'lab' or 'vortex', got {frame!r}.")
        self.frame = frame

    def velocity(self, p, t):
        a, u0 = self.radius_mm, self.speed_mm_s
        c = self.center + (u0 * t * self.axis if self.frame == "lab" else 0.0)
        r, z, e_r, _ = self._cyl(p, c)
        big_r2 = r * r + z * z
        inside = big_r2 <= a * a
        f5 = (a * a / np.maximum(big_r2, a * a)) ** 2.5  # only used outside (R > a)
        uz = np.where(inside, 1.5 * u0 * (1 - (2 * r * r + z * z) / a**2), u0 * (f5 * (2 * z * z - r * r) / (2 * a * a) - 1))
        ur = np.where(inside, 1.5 * u0 * r * z / a**2, 1.5 * u0 * r * z / a**2 * f5)
        if self.frame == "lab":
            uz = uz + u0
        return ur[:, None] * e_r + uz[:, None] * self.axis


class VortexRing(_Axisymmetric):
    """Thin vortex ring with a smooth (Rosenhead-Moore) core, translating along ``axis``.

    The velocity is the Biot-Savart integral of a circular filament of radius
    ``ring_radius_mm`` and circulation ``circulation_mm2_s`` with the regularised kernel
    ``dl x (p - x') / (|p - x'|^2 + a^2)^(3/2)`` (``a = core_radius_mm``), which is the
    curl of a vector potential and hence exactly divergence-free; the filament is split
    into ``segments`` pieces. The ring moves at ``speed_mm_s``, by default Kelvin's
    self-induced speed ``G / (4 pi R) (ln(8 R / a) - 1/4)``.

    Parameters
    ----------
    ring_radius_mm : float
        Radius R of the ring's centreline (the filament) [mm] (> 0, larger than
        ``core_radius_mm``).
    circulation_mm2_s : float
        Circulation G of the ring's core [mm^2/s]; positive: the fluid moves through the
        ring along ``+axis`` and the ring travels along ``+axis``.
    core_radius_mm : float
        Core radius a [mm] (> 0): the smoothing length of the Rosenhead-Moore kernel, which
        keeps the velocity finite on the filament.
    center : (float, float, float)
        Centre of the ring at ``t = 0`` [mm]; it moves as ``center + speed_mm_s t axis``.
        Default the origin.
    axis : (float, float, float)
        Normal of the ring's plane, the direction of travel (any non-zero length;
        normalised); default +z.
    speed_mm_s : float, optional
        Translation speed along ``axis`` [mm/s]; left out (None): Kelvin's self-induced
        speed above.
    segments : int
        Number of straight pieces of the filament in the Biot-Savart sum (>= 1; the cost
        grows linearly with it).
    """

    kind = "vortex_ring"

    def __init__(
        self,
        ring_radius_mm=5.0,
        circulation_mm2_s=5000.0,
        core_radius_mm=1.0,
        center=(0, 0, 0),
        axis=(0, 0, 1),
        speed_mm_s=None,
        segments=256,
    ):
        super().__init__(center, axis)
        self.ring_radius_mm = check_positive("ring_radius_mm", ring_radius_mm, owner="VortexRing", unit="mm")
        self.core_radius_mm = check_positive("core_radius_mm", core_radius_mm, owner="VortexRing", unit="mm")
        if self.core_radius_mm >= self.ring_radius_mm:
            raise ConfigError(
                f"VortexRing: core_radius_mm={core_radius_mm} must be smaller than "
                f"ring_radius_mm={ring_radius_mm}."
            )
        self.circulation_mm2_s = float(circulation_mm2_s)
        if speed_mm_s is None:
            big_r, a = self.ring_radius_mm, self.core_radius_mm
            speed_mm_s = self.circulation_mm2_s / (4 * math.pi * big_r) * (math.log(8 * big_r / a) - 0.25)
        self.speed_mm_s = float(speed_mm_s)
        if isinstance(segments, bool) or int(segments) != segments or segments < 1:
            raise ConfigError(f"VortexRing: 'segments' (pieces of the ring filament) must be a whole number >= 1, got "
                              f"{segments!r}; use e.g. 256 (the default).")
        self.segments = int(segments)
        # Ring frame: two unit vectors orthogonal to the axis.
        helper = np.array([1.0, 0, 0]) if abs(self.axis[0]) < 0.9 else np.array([0, 1.0, 0])
        e1 = np.cross(self.axis, helper)
        self._e1 = e1 / np.linalg.norm(e1)
        self._e2 = np.cross(self.axis, self._e1)

    def velocity(self, p, t):
        big_r, a2 = self.ring_radius_mm, self.core_radius_mm**2
        c = self.center + self.speed_mm_s * t * self.axis
        phi = (np.arange(self.segments) + 0.5) * (2 * math.pi / self.segments)
        xs = c + big_r * (np.cos(phi)[:, None] * self._e1 + np.sin(phi)[:, None] * self._e2)
        dl = (2 * math.pi * big_r / self.segments) * (-np.sin(phi)[:, None] * self._e1 + np.cos(phi)[:, None] * self._e2)
        pts = np.ascontiguousarray(p, dtype=np.float64)
        out = np.empty_like(pts)
        if pts.shape[0] * self.segments < 50_000:  # small calls: NumPy, no kernel to load
            rel = pts[:, None, :] - xs[None, :, :]
            den = (np.einsum("nmk,nmk->nm", rel, rel) + a2) ** 1.5
            out[:] = np.einsum("nmk,nm->nk", np.cross(dl[None], rel), 1.0 / den)
        else:  # compiled sum over the segments, parallel over points (same terms, same order)
            _biot_savart_kernel()(pts, np.ascontiguousarray(xs), np.ascontiguousarray(dl), float(a2), out)
        return out * (self.circulation_mm2_s / (4 * math.pi))


_BIOT_SAVART = []


def _biot_savart_kernel():
    """Compiled regularised Biot-Savart sum of :class:`VortexRing` (Numba, cached on disk):
    ``out[n] = sum_m dl_m x (p_n - x_m) / (|p_n - x_m|^2 + a^2)^(3/2)``. 16x the NumPy
    einsum/cross version on 2 cores (20000 points: 0.057 s vs 0.91 s) (the demo's velocity-error reference: 21 s -> ~1 s);
    the power as ``r2 * sqrt(r2)`` instead of ``r2 ** 1.5`` (a pow call): 3.8x again (25000 points, the demo's ring:
    17.5 ms vs 66 ms per call, results equal to 3e-16 relative)."""
    if _BIOT_SAVART:
        return _BIOT_SAVART[0]
    from mitpiv._numba import numba

    nb = numba()

    @nb.njit(parallel=True, cache=True, fastmath=False)
    def biot_savart(p, xs, dl, a2, out):
        for n in nb.prange(p.shape[0]):
            ux = uy = uz = 0.0
            for m in range(xs.shape[0]):
                rx, ry, rz = p[n, 0] - xs[m, 0], p[n, 1] - xs[m, 1], p[n, 2] - xs[m, 2]
                r2 = rx * rx + ry * ry + rz * rz + a2
                inv = 1.0 / (r2 * math.sqrt(r2))  # r2^-1.5 without pow(): 2-3x faster
                ux += (dl[m, 1] * rz - dl[m, 2] * ry) * inv
                uy += (dl[m, 2] * rx - dl[m, 0] * rz) * inv
                uz += (dl[m, 0] * ry - dl[m, 1] * rx) * inv
            out[n, 0], out[n, 1], out[n, 2] = ux, uy, uz

    _BIOT_SAVART.append(biot_savart)
    return biot_savart


class ABC(Flow):
    """Arnold-Beltrami-Childress flow, scaled to millimetres:
    ``u = U0 (A sin(z/L) + C cos(y/L), B sin(x/L) + A cos(z/L), C sin(y/L) + B cos(x/L))``.

    A steady, divergence-free Beltrami field (vorticity parallel to velocity), periodic over
    ``2 pi L`` along each world axis, with chaotic streamlines for A, B, C all non-zero.

    Parameters
    ----------
    A, B, C : float
        Dimensionless amplitudes of the three Beltrami modes (A varies along z, B along x,
        C along y).
    length_mm : float
        Length scale L [mm] (> 0); the period is ``2 pi L``.
    speed_mm_s : float
        Velocity scale U0 [mm/s] multiplying the amplitudes.
    """

    kind = "abc"

    def __init__(self, A=1.0, B=1.0, C=1.0, length_mm=1.0, speed_mm_s=1.0):
        self.A, self.B, self.C = float(A), float(B), float(C)
        self.length_mm = check_positive("length_mm", length_mm, owner="ABC", unit="mm")
        self.speed_mm_s = float(speed_mm_s)

    def velocity(self, p, t):
        x, y, z = (p / self.length_mm).T
        u = self.A * np.sin(z) + self.C * np.cos(y)
        v = self.B * np.sin(x) + self.A * np.cos(z)
        w = self.C * np.sin(y) + self.B * np.cos(x)
        return self.speed_mm_s * np.stack([u, v, w], axis=1)


class RoundJet(_Axisymmetric):
    """Laminar round jet (Schlichting's similarity solution, an exact solution of the
    boundary-layer equations): with ``z`` measured along ``axis`` from the virtual origin
    ``center``, ``xi = gamma r / z`` and ``gamma = sqrt(3 K / (16 pi)) / nu``,

    ``u_z = 3 K / (8 pi nu z) / (1 + xi^2/4)^2``,
    ``u_r = sqrt(3 K / (16 pi)) / z (xi - xi^3/4) / (1 + xi^2/4)^2``.

    It derives from the Stokes stream function ``psi = nu z xi^2 / (1 + xi^2/4)`` and is
    therefore exactly divergence-free; the kinematic momentum flux ``2 pi int u_z^2 r dr``
    equals ``K`` at every ``z`` and the volume flux ``8 pi nu z`` grows by entrainment.
    momentum_flux_mm4_s2: K = J / rho [mm^4/s^2]; viscosity_mm2_s: nu [mm^2/s] (water 1,
    air 15). For a centreline speed ``U`` at distance ``z`` give ``K = 8 pi nu z U / 3``
    (:meth:`from_centerline`). Points at or upstream of the virtual origin (``z <= 0``) are
    outside the solution and raise :class:`ConfigError`.

    Parameters
    ----------
    momentum_flux_mm4_s2 : float
        Kinematic momentum flux K = J / rho [mm^4/s^2] (> 0), ``2 pi int u_z^2 r dr``; for
        a centreline speed U at distance z, ``K = 8 pi nu z U / 3``.
    viscosity_mm2_s : float
        Kinematic viscosity nu [mm^2/s] (> 0; water 1, air 15).
    center : (float, float, float)
        The jet's virtual origin [mm]; every evaluated point must lie downstream of it
        (``z > 0``). Default the origin.
    axis : (float, float, float)
        Direction of the jet (any non-zero length; normalised); default +z.
    """

    kind = "round_jet"

    def __init__(self, momentum_flux_mm4_s2=1.0e5, viscosity_mm2_s=1.0, center=(0, 0, 0), axis=(0, 0, 1)):
        super().__init__(center, axis)
        self.momentum_flux_mm4_s2 = check_positive(
            "momentum_flux_mm4_s2", momentum_flux_mm4_s2, owner="RoundJet", unit="mm^4/s^2")
        self.viscosity_mm2_s = check_positive("viscosity_mm2_s", viscosity_mm2_s, owner="RoundJet", unit="mm^2/s")

    @classmethod
    def from_centerline(cls, speed_mm_s, distance_mm, viscosity_mm2_s=1.0, center=(0, 0, 0), axis=(0, 0, 1)):
        """The jet whose centreline speed is ``speed_mm_s`` at ``distance_mm`` from ``center``."""
        check_positive("speed_mm_s", speed_mm_s, owner="RoundJet", unit="mm/s")
        check_positive("distance_mm", distance_mm, owner="RoundJet", unit="mm")
        k = 8 * math.pi * viscosity_mm2_s * distance_mm * speed_mm_s / 3
        return cls(k, viscosity_mm2_s, center, axis)

    def velocity(self, p, t):
        r, z, e_r, _ = self._cyl(p)
        if np.any(z <= 0):
            bad = p[z <= 0][0]
            raise ConfigError(
                f"RoundJet: {int(np.sum(z <= 0))} point(s) lie at or upstream of the virtual origin "
                f"center={self.center.tolist()} along axis={self.axis.tolist()}, e.g. {bad.tolist()}; "
                f"move 'center' upstream of the measurement volume."
            )
        k, nu = self.momentum_flux_mm4_s2, self.viscosity_mm2_s
        a = math.sqrt(3 * k / (16 * math.pi))
        xi = (a / nu) * r / z
        den = (1 + 0.25 * xi * xi) ** 2
        uz = 3 * k / (8 * math.pi * nu * z) / den
        ur = a / z * (xi - 0.25 * xi**3) / den
        return ur[:, None] * e_r + uz[:, None] * self.axis


class GridFlow(Flow):
    """A user velocity field on a regular grid, trilinearly interpolated (steady).

    The NPZ file holds 1D axes ``x``, ``y``, ``z`` [mm] (strictly increasing) and arrays
    ``u``, ``v``, ``w`` [mm/s] of shape (len(x), len(y), len(z)). Points outside the grid
    raise :class:`ConfigError` unless ``outside="zero"``.

    Parameters
    ----------
    path : str
        The NPZ file (a relative path is taken from the current working directory).
    outside : {'error', 'zero'}
        Points outside the grid: ``"error"`` raises :class:`ConfigError`, ``"zero"`` gives
        them zero velocity. Default ``"error"``.
    """

    kind = "grid"

    def __init__(self, path, outside="error"):
        self.path = str(path)
        if outside not in ("error", "zero"):
            raise ConfigError(f"GridFlow: 'outside' must be 'error' or 'zero', got {outside!r}.")
        self.outside = outside
        p = Path(path)
        if not p.is_file():
            raise ConfigError(f"GridFlow: flow file {str(p)!r} does not exist.")
        import zipfile

        try:  # physics sits below io: the .npz is read here, without pickle
            with np.load(p, allow_pickle=False) as data:
                axes = [np.asarray(data[k], float) for k in ("x", "y", "z")]
                comps = [np.asarray(data[k], float) for k in ("u", "v", "w")]
        except (KeyError, ValueError, TypeError, OSError, EOFError, AttributeError, zipfile.BadZipFile) as e:
            raise FileFormatError(
                f"GridFlow: {str(p)!r} must be an NPZ with arrays x, y, z, u, v, w ({e})."
            ) from None
        shape = tuple(len(a) for a in axes)
        for name, c in zip("uvw", comps, strict=True):
            if c.shape != shape:
                raise FileFormatError(f"GridFlow: array '{name}' has shape {c.shape}, expected {shape}.")
        for name, a in zip("xyz", axes, strict=True):
            if a.size < 2 or np.any(np.diff(a) <= 0):
                raise FileFormatError(f"GridFlow: axis '{name}' must be strictly increasing with >= 2 points.")
        self._interp = RegularGridInterpolator(
            axes, np.stack(comps, axis=-1), method="linear", bounds_error=False, fill_value=np.nan
        )
        self._lo = np.array([a[0] for a in axes])
        self._hi = np.array([a[-1] for a in axes])

    def velocity(self, p, t):
        out = self._interp(p)
        bad = np.isnan(out[:, 0])
        if bad.any():
            if self.outside == "error":
                raise ConfigError(
                    f"GridFlow: {bad.sum()} point(s) lie outside the grid "
                    f"[{self._lo.tolist()}, {self._hi.tolist()}] mm, e.g. {p[bad][0].tolist()}. "
                    f"Extend the grid or use outside='zero'."
                )
            out[bad] = 0.0
        return out


class Channel(Flow):
    """Turbulent channel flow at Re_tau = 934 in wall units: DNS mean profile plus
    divergence-free synthetic turbulence (:mod:`mitpiv.physics.channel`), frozen in time.

    The local frame: ``streamwise`` and ``wall_normal`` unit vectors (spanwise =
    streamwise x wall_normal); the world point ``center_mm`` sits at wall distance
    ``center_y_plus`` wall units, so the wall is the plane through
    ``center_mm - center_y_plus * l_nu * wall_normal``. Wall units come from
    ``friction_velocity_mm_s`` (u_tau) and the fluid's ``viscosity_mm2_s`` (nu; air 15.1,
    water 1.0): ``l_nu = nu / u_tau`` [mm]; the channel half-height is ``Re_tau * l_nu``.
    ``u = u_tau (U+(y+) e_streamwise + u'+(x+))``. The fluctuations reproduce the DNS
    Reynolds-stress tensor at every y+ in ``y_plus_range`` (default
    ``(max(60, y_c/2), min(Re_tau, 2 y_c))``); points outside it raise ConfigError.
    ``modes`` Fourier modes (cost is linear in it), ``seed`` the realisation.

    Parameters
    ----------
    friction_velocity_mm_s : float
        Friction velocity u_tau [mm/s] (> 0): the velocity scale (``u = u_tau U+``) and, with
        ``viscosity_mm2_s``, the viscous length ``l_nu = nu / u_tau``.
    viscosity_mm2_s : float
        Kinematic viscosity nu [mm^2/s] (> 0; air 15.1, water 1.0).
    center_y_plus : float
        Wall distance y_c of ``center_mm`` in wall units (> 0, inside ``y_plus_range``),
        where the turbulence's length scales and anisotropy are taken.
    center_mm : (float, float, float)
        The world point [mm] at wall distance ``center_y_plus``, origin of the streamwise and
        spanwise coordinates. Default the origin.
    streamwise : (float, float, float)
        Direction of the mean flow (any non-zero length; normalised); default +x.
    wall_normal : (float, float, float)
        Direction from the wall into the channel, perpendicular to ``streamwise`` (any
        non-zero length; normalised); default +z.
    modes : int
        Number of random Fourier modes of the synthetic turbulence (>= 16; the cost is linear
        in it).
    seed : int
        The turbulence's realisation (seeds its wavevector directions, amplitudes and
        phases).
    y_plus_range : (float, float), optional
        Wall distances y+ (wall units) where the field may be evaluated; the stress fit spans
        them. Default ``(max(60, y_c / 2), min(Re_tau, 2 y_c))``.
    profile : str
        The shipped DNS profile table (mean velocity and Reynolds stresses;
        :data:`mitpiv.physics.channel.PROFILES`). Default ``"delalamo2004_re934"`` (del Alamo
        et al. 2004, Re_tau = 934).
    """

    kind = "channel"

    def __init__(self, friction_velocity_mm_s: float = 500.0, viscosity_mm2_s: float = 15.1,
                 center_y_plus: float = 150.0, center_mm=(0.0, 0.0, 0.0), streamwise=(1.0, 0.0, 0.0),
                 wall_normal=(0.0, 0.0, 1.0), modes: int = 1000, seed: int = 0,
                 y_plus_range: tuple[float, float] | None = None, profile: str = "delalamo2004_re934"):
        from mitpiv.physics.channel import SyntheticTurbulence, load_channel_profile

        self.friction_velocity_mm_s = check_positive("friction_velocity_mm_s", friction_velocity_mm_s,
                                                     owner="Channel", unit="mm/s")
        self.viscosity_mm2_s = check_positive("viscosity_mm2_s", viscosity_mm2_s, owner="Channel", unit="mm^2/s")
        self.center_y_plus = check_positive("center_y_plus", center_y_plus, owner="Channel")
        self.center_mm = np.asarray(center_mm, dtype=float).reshape(3)
        self.streamwise = _unit(streamwise, "streamwise")
        self.wall_normal = _unit(wall_normal, "wall_normal")
        if abs(self.streamwise @ self.wall_normal) > 1e-9:
            raise ConfigError(f"Channel: 'streamwise' {self.streamwise.tolist()} and 'wall_normal' "
                              f"{self.wall_normal.tolist()} must be perpendicular.")
        self.modes, self.seed, self.profile = int(modes), int(seed), str(profile)
        self.y_plus_range = None if y_plus_range is None else [float(v) for v in y_plus_range]
        self._profile = load_channel_profile(self.profile)
        self._turb = SyntheticTurbulence(self._profile, center_y_plus=self.center_y_plus, modes=self.modes,
                                         seed=self.seed, y_plus_range=self.y_plus_range)
        self._frame = np.stack([self.streamwise, self.wall_normal, np.cross(self.streamwise, self.wall_normal)])

    @property
    def viscous_length_mm(self) -> float:
        """``l_nu = nu / u_tau`` [mm]."""
        return self.viscosity_mm2_s / self.friction_velocity_mm_s

    @property
    def re_tau(self) -> float:
        """Friction Reynolds number of the profile table."""
        return self._profile.re_tau

    @property
    def half_height_mm(self) -> float:
        """Channel half-height ``Re_tau l_nu`` [mm]."""
        return self.re_tau * self.viscous_length_mm

    @property
    def frame(self) -> np.ndarray:
        """(3, 3) rows: the streamwise, wall-normal and spanwise unit vectors (world)."""
        return self._frame.copy()

    @property
    def profile_table(self):
        """The :class:`~mitpiv.physics.channel.ChannelProfile` used."""
        return self._profile

    @property
    def turbulence(self):
        """The :class:`~mitpiv.physics.channel.SyntheticTurbulence` generator."""
        return self._turb

    def to_plus(self, p_mm) -> np.ndarray:
        """World points (N, 3) [mm] -> local wall-unit coordinates (N, 3): (x+, y+, z+) with
        y+ the wall distance and x+, z+ streamwise and spanwise from ``center_mm``."""
        x = (np.asarray(p_mm, float) - self.center_mm) @ self._frame.T / self.viscous_length_mm
        x[:, 1] += self.center_y_plus
        return x

    def wall_distance_plus(self, p_mm) -> np.ndarray:
        """Wall distance y+ of world points (N, 3) [mm]."""
        return self.to_plus(np.asarray(p_mm, float).reshape(-1, 3))[:, 1]

    def velocity_plus(self, x_plus) -> np.ndarray:
        """Velocity in wall units in the local frame at local wall-unit points (N, 3)."""
        u = self._turb.fluctuation_plus(x_plus)
        u[:, 0] += self._profile.mean_plus(x_plus[:, 1])
        return u

    def velocity(self, p, t):
        return self.friction_velocity_mm_s * (self.velocity_plus(self.to_plus(p)) @ self._frame)

    def window_average(self, p_mm, window_mm, *, y_nodes: int = 24) -> np.ndarray:
        """Velocity [mm/s] (N, 3) averaged over a box ``window_mm`` (w_x, w_y, w_z) [mm] along
        the world axes centred on each point ``p_mm`` (N, 3): the fair reference for a PIV
        vector from a cubic interrogation window (the paper's "averaged DNS").

        The channel's axes must be world axes (up to sign). Along the streamwise and spanwise
        axes the average is exact (per-mode sinc factors); along the wall normal it is a
        ``y_nodes``-point Gauss-Legendre quadrature of the mean profile and fluctuations.
        """
        p = np.asarray(p_mm, dtype=float).reshape(-1, 3)
        win = np.broadcast_to(np.asarray(window_mm, dtype=float), (3,))
        if np.any(win < 0):
            raise ConfigError(f"Channel.window_average: window_mm must be >= 0, got {win.tolist()}.")
        a = np.abs(self._frame)
        if not np.allclose(a, np.round(a), atol=1e-12):
            raise ConfigError("Channel.window_average: the channel's streamwise and wall_normal axes must be "
                              f"world axes (got {self.streamwise.tolist()}, {self.wall_normal.tolist()}).")
        lx, ly, lz = (a @ win) / self.viscous_length_mm  # window sides along the local axes, wall units
        t, w = np.polynomial.legendre.leggauss(int(y_nodes))
        x = self.to_plus(p)
        acc = np.zeros_like(x)
        for tk, wk in zip(t, w, strict=True):  # a handful of nodes; each one vectorised over points
            xk = x + np.array([0.0, 0.5 * ly * tk, 0.0])
            uk = self._turb.fluctuation_plus(xk, box_plus=(lx, lz))
            uk[:, 0] += self._profile.mean_plus(xk[:, 1])
            acc += 0.5 * wk * uk
        return self.friction_velocity_mm_s * (acc @ self._frame)


#: Every flow kind by its name (the ``kind`` of a [flow] table and of a truth file's flow); the
#: turbulent near-field round jet lives in its own module (:mod:`mitpiv.physics.jet`).
FLOW_KINDS = {c.kind: c for c in (Uniform, SolidBody, LambOseen, Burgers, HillVortex, VortexRing, ABC, RoundJet,
                                  GridFlow, Channel, NearFieldJet)}
_KINDS = FLOW_KINDS


def flow_from_dict(d: dict) -> Flow:
    """Rebuild a flow from :meth:`Flow.to_dict` output (e.g. stored in a truth file)."""
    d = dict(d)
    kind = d.pop("kind", None)
    if kind not in _KINDS:
        raise ConfigError(f"flow: unknown kind {kind!r}; known: {sorted(_KINDS)}.")
    return _KINDS[kind](**d)
