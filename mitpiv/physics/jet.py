"""Near-field turbulent round jet: the annular shear layer one or two diameters from the
nozzle, as a mean profile with published self-similar statistics plus divergence-free
synthetic turbulence (for the LF-PIV vs Tomo-PIV replication, whose DNS jet we do not have).

Model (hand-written: no maintained Python package generates it):

* Mean axial velocity (Michalke 1984, J. Fluid Mech.'s "hyperbolic-tangent" near-nozzle
  round-jet profile, written with the vorticity thickness)::

      U(r, x) = U_j / 2 (1 + tanh(2 (R - r) / delta_w(x))),   delta_w(x) = S_w x

  with ``R = D / 2`` and the spreading rate of the self-similar plane mixing layer into
  fluid at rest, ``S_w = d delta_w / dx = 0.18`` (Brown & Roshko 1974, J. Fluid Mech. 64;
  0.181 (U_1 - U_2) / (U_1 + U_2) with U_2 = 0). ``delta_w = U_j / max|dU/dr|``. The radial
  velocity is the one that makes the mean field divergence-free:
  ``V(r, x) = -(1/r) int_0^r r' dU/dx dr'`` (evaluated by Gauss-Legendre quadrature).
* Turbulence intensity: the self-similar mixing layer's r.m.s. profiles (Bell & Mehta 1990,
  AIAA J. 28; Pope 2000, Fig. 5.24): peaks ``u'/U_j = 0.18``, ``v'/U_j = 0.14``,
  ``w'/U_j = 0.15`` at the layer's centre, Gaussian in ``eta = (r - R) / delta_w`` with an
  e-folding half width of 0.5 (the profiles fall to ~5 % of their peaks at
  ``|eta| = 0.9``). The synthetic field is isotropic with the mean of the three
  variances, ``q(eta) = q_0 exp(-(eta / 0.5)^2)`` with ``q_0 = sqrt((0.18^2 + 0.14^2 +
  0.15^2) / 3) U_j = 0.158 U_j``, times ``envelope``: the curl of ``q(eta) psi(x)`` with
  ``psi`` a random-Fourier-mode vector potential whose curl is unit-variance isotropic
  turbulence of a von Karman spectrum (integral scale ``L11 = 0.4 delta_w``, the mixing
  layer's large eddies span about half the layer; a choice, stated), frozen at a reference
  station ``reference_x_mm`` (default 1 D):

      u' = curl(q psi) = q curl(psi) + grad(q) x psi,

  exactly divergence-free. Frozen in time (the second frame comes from advection).

The sum over the modes runs in one Numba kernel over the points (in parallel, no
``points x modes`` temporaries): NumPy's ``cos``/``sin`` of the ``(N, modes)`` phase array
and two matrix products took 1.9-2.6x longer on 2 cores (20 000-400 000 points,
``bench/bench_jet.py``; the results agree to 1e-14 relative).
"""

from __future__ import annotations

import math

import numpy as np

from mitpiv._numba import numba
from mitpiv.errors import ConfigError, check_positive
from mitpiv.physics.flow_base import Flow

__all__ = ["NearFieldJet", "BROWN_ROSHKO_SPREADING", "MIXING_LAYER_RMS", "RMS_HALF_WIDTH"]

#: d delta_w / dx of a mixing layer into fluid at rest (Brown & Roshko 1974)
BROWN_ROSHKO_SPREADING = 0.18
#: peak r.m.s. fluctuations / Delta U of the self-similar mixing layer (Bell & Mehta 1990;
#: Pope 2000, Fig. 5.24): axial, radial, azimuthal
MIXING_LAYER_RMS = (0.18, 0.14, 0.15)
#: e-folding half width of the r.m.s. profiles in eta = (r - R) / delta_w
RMS_HALF_WIDTH = 0.5


class NearFieldJet(Flow):
    """Round jet of diameter ``diameter_mm`` and exit speed ``exit_velocity_mm_s`` issuing
    from ``nozzle_mm`` along ``axis`` (unit), near field (``x/D`` about 0.5-3). Callable:
    ``jet.velocity(p_mm (N, 3), t_s) -> (N, 3) mm/s``. ``modes`` Fourier modes, ``seed``
    the realisation, ``envelope`` scales the fluctuations (0: the mean flow only).

    Parameters
    ----------
    diameter_mm : float
        Nozzle diameter D [mm] (> 0); the shear layer sits at radius ``D / 2``.
    exit_velocity_mm_s : float
        Exit velocity U_j [mm/s] (> 0), the speed of the potential core.
    nozzle_mm : (float, float, float)
        Centre of the nozzle exit [mm]; the axial distance x is measured from it and every
        evaluated point must lie downstream (``x > 0``). Default the origin.
    axis : (float, float, float)
        Direction of the jet (any non-zero length; normalised); default +x.
    spreading : float
        Growth rate ``S_w = d delta_w / dx`` of the shear layer's vorticity thickness
        (dimensionless, > 0). Default 0.18 (Brown & Roshko 1974).
    envelope : float
        Factor on the turbulent fluctuations (dimensionless, >= 0): 1 gives the published
        r.m.s. profile (peak 0.158 U_j per component), 0 the mean flow only.
    integral_scale_over_delta : float
        Longitudinal integral scale L11 of the synthetic turbulence over the vorticity
        thickness at ``reference_x_mm`` (dimensionless, > 0).
    reference_x_mm : float, optional
        Axial distance from the nozzle [mm] (> 0) at which the turbulence's length scale is
        frozen; default one diameter.
    modes : int
        Number of random Fourier modes of the turbulence (>= 8).
    seed : int
        The turbulence's realisation (seeds its directions, amplitudes and phases).
    """

    kind = "near_field_jet"

    def __init__(self, diameter_mm: float = 40.0, exit_velocity_mm_s: float = 62.5, *, nozzle_mm=(0.0, 0.0, 0.0),
                 axis=(1.0, 0.0, 0.0), spreading: float = BROWN_ROSHKO_SPREADING, envelope: float = 1.0,
                 integral_scale_over_delta: float = 0.4, reference_x_mm: float | None = None, modes: int = 400,
                 seed: int = 0):
        self.diameter_mm = check_positive("diameter_mm", diameter_mm, owner="NearFieldJet", unit="mm")
        self.exit_velocity_mm_s = check_positive("exit_velocity_mm_s", exit_velocity_mm_s, owner="NearFieldJet",
                                                 unit="mm/s")
        self.spreading = check_positive("spreading", spreading, owner="NearFieldJet")
        self.nozzle_mm = np.asarray(nozzle_mm, dtype=float).reshape(3)
        a = np.asarray(axis, dtype=float).reshape(3)
        if not np.linalg.norm(a) > 0:
            raise ConfigError(f"NearFieldJet: 'axis' must be a non-zero vector, got {a.tolist()}.")
        self.axis = a / np.linalg.norm(a)
        if not (math.isfinite(envelope) and envelope >= 0):
            raise ConfigError(f"NearFieldJet: 'envelope' must be finite and >= 0, got {envelope!r}.")
        self.envelope = float(envelope)
        self.integral_scale_over_delta = check_positive("integral_scale_over_delta", integral_scale_over_delta,
                                                        owner="NearFieldJet")
        if int(modes) != modes or modes < 8:
            raise ConfigError(f"NearFieldJet: 'modes' must be an integer >= 8, got {modes!r}.")
        self.modes, self.seed = int(modes), int(seed)
        rng = np.random.default_rng(self.seed)
        # unit-variance isotropic base field from a von Karman spectrum E ~ k^4 / (1 + k^2)^(17/6)
        # (k in units of 1/L_e; L11 = 0.747 L_e for this spectrum), log-spaced shells
        k = np.geomspace(0.05, 40.0, self.modes + 1)
        km = np.sqrt(k[:-1] * k[1:])
        e = km**4 / (1 + km**2) ** (17 / 6) * np.diff(k)
        c2 = 6.0 * e / e.sum()  # <|u|^2> = sum c^2 / 2 = 3: unit variance per component
        # longitudinal integral scale of this spectrum in units of L_e (Pope 2000, eqs. 6.209, 6.212)
        kk = np.geomspace(1e-4, 1e4, 20001)
        ee = kk**4 / (1 + kk**2) ** (17 / 6)
        l11_per_le = 0.75 * math.pi * np.trapezoid(ee, np.log(kk)) / np.trapezoid(ee * kk, np.log(kk))
        self.reference_x_mm = float(self.diameter_mm if reference_x_mm is None else
                                    check_positive("reference_x_mm", reference_x_mm, owner="NearFieldJet", unit="mm"))
        self._length_scale_mm = self.integral_scale_over_delta * self.spreading * self.reference_x_mm / l11_per_le
        d = rng.normal(size=(self.modes, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        s = np.cross(d, rng.normal(size=(self.modes, 3)))
        s /= np.linalg.norm(s, axis=1, keepdims=True)
        self._khat, self._kmag_le = d, km
        self._l11_per_le = float(l11_per_le)
        self._amp = np.sqrt(c2)[:, None] * s  # amplitude of curl(psi) for each mode, perpendicular to k
        self._phase = rng.uniform(0.0, 2 * math.pi, self.modes)
        e1 = np.cross(self.axis, [0.0, 0.0, 1.0] if abs(self.axis[2]) < 0.9 else [1.0, 0.0, 0.0])
        self._e1 = e1 / np.linalg.norm(e1)
        self._e2 = np.cross(self.axis, self._e1)

    # ------------------------------------------------------------------ geometry
    @property
    def length_scale_mm(self) -> float:
        """The spectrum's scale L_e [mm] (von Karman), frozen at ``reference_x_mm``."""
        return self._length_scale_mm

    @property
    def radius_mm(self) -> float:
        return 0.5 * self.diameter_mm

    def vorticity_thickness_mm(self, x_mm) -> np.ndarray:
        """``delta_w = S_w x`` [mm] at axial distance ``x_mm`` from the nozzle (> 0)."""
        x = np.asarray(x_mm, dtype=float)
        if np.any(x <= 0):
            raise ConfigError(f"NearFieldJet: points must lie downstream of the nozzle (x > 0), got min x = "
                              f"{float(np.min(x)):.4g} mm.")
        return self.spreading * x

    def _cyl(self, p):
        rel = np.asarray(p, dtype=float) - self.nozzle_mm
        x = rel @ self.axis
        radial = rel - x[:, None] * self.axis
        r = np.linalg.norm(radial, axis=1)
        er = np.where(r[:, None] > 0, radial / np.where(r > 0, r, 1.0)[:, None], self._e1)
        return x, r, er

    # ------------------------------------------------------------------ mean flow
    def mean_axial(self, x_mm, r_mm) -> np.ndarray:
        """Mean axial velocity U(r, x) [mm/s] (tanh profile)."""
        dw = self.vorticity_thickness_mm(x_mm)
        return 0.5 * self.exit_velocity_mm_s * (1.0 + np.tanh(2.0 * (self.radius_mm - np.asarray(r_mm)) / dw))

    def _dudx(self, x, r):
        dw = self.spreading * x
        arg = 2.0 * (self.radius_mm - r) / dw
        return 0.5 * self.exit_velocity_mm_s / np.cosh(arg) ** 2 * (-arg / x)

    def mean_radial(self, x_mm, r_mm, nodes: int = 48) -> np.ndarray:
        """Mean radial velocity V(r, x) [mm/s] from continuity, ``-(1/r) int_0^r r' dU/dx dr'``."""
        x = np.atleast_1d(np.asarray(x_mm, dtype=float))
        r = np.atleast_1d(np.asarray(r_mm, dtype=float))
        x, r = np.broadcast_arrays(x, r)
        t, w = np.polynomial.legendre.leggauss(int(nodes))
        rr = 0.5 * r[..., None] * (t + 1.0)
        integ = np.sum(0.5 * r[..., None] * w * rr * self._dudx(x[..., None], rr), axis=-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(r > 0, -integ / np.where(r > 0, r, 1.0), 0.0)

    def mean_velocity(self, p_mm) -> np.ndarray:
        """Mean velocity (N, 3) [mm/s] at points (N, 3) [mm]."""
        x, r, er = self._cyl(p_mm)
        return self.mean_axial(x, r)[:, None] * self.axis + self.mean_radial(x, r)[:, None] * er

    # ------------------------------------------------------------------ turbulence
    @property
    def rms_peak_mm_s(self) -> float:
        """Peak r.m.s. of each component of the isotropic synthetic field [mm/s]."""
        return math.sqrt(sum(v * v for v in MIXING_LAYER_RMS) / 3.0) * self.exit_velocity_mm_s * self.envelope

    def rms_profile(self, x_mm, r_mm) -> np.ndarray:
        """Target r.m.s. per component q(eta) [mm/s] (the Gaussian envelope)."""
        eta = (np.asarray(r_mm) - self.radius_mm) / self.vorticity_thickness_mm(x_mm)
        return self.rms_peak_mm_s * np.exp(-((eta / RMS_HALF_WIDTH) ** 2))

    def _psi_and_curl(self, p, le):
        """Vector potential psi (N, 3) [mm] and its curl (N, 3) (unit variance) at points [mm]:
        ``curl = sum_n amp_n cos(theta_n)``, ``psi = sum_n b_n sin(theta_n)`` with
        ``theta_n = k_n . (p - nozzle) + phase_n`` (:func:`_mode_sums`)."""
        kv = self._khat * (self._kmag_le / le)[:, None]  # wavevectors [1/mm]
        # psi_n = (amp x k) / |k|^2 sin(theta): curl(psi_n) = k x (amp x k)/|k|^2 cos = amp cos
        b = np.cross(self._amp, kv) / np.sum(kv * kv, axis=1)[:, None]
        rel = np.ascontiguousarray(np.asarray(p, dtype=np.float64) - self.nozzle_mm)
        return _mode_sums(rel, np.ascontiguousarray(kv), np.ascontiguousarray(self._phase, dtype=np.float64),
                          np.ascontiguousarray(self._amp), np.ascontiguousarray(b))

    def fluctuation(self, p_mm, chunk: int = 20000) -> np.ndarray:
        """Fluctuation u' (N, 3) [mm/s] = curl(q(eta) psi): divergence-free."""
        p = np.asarray(p_mm, dtype=float).reshape(-1, 3)
        out = np.zeros_like(p)
        if self.envelope == 0:
            return out
        for s in range(0, len(p), chunk):
            ps = p[s : s + chunk]
            x, r, er = self._cyl(ps)
            dw = self.vorticity_thickness_mm(x)
            psi, curl = self._psi_and_curl(ps, self.length_scale_mm)
            q = self.rms_profile(x, r)
            eta = (r - self.radius_mm) / dw
            dq_deta = q * (-2.0 * eta / RMS_HALF_WIDTH**2)
            # grad q = dq/deta (d eta/dr e_r + d eta/dx e_x), d eta/dr = 1/dw, d eta/dx = -eta/x
            grad = dq_deta[:, None] * (er / dw[:, None] - (eta / x)[:, None] * self.axis)
            out[s : s + chunk] = q[:, None] * curl + np.cross(grad, psi)
        return out

    def velocity(self, p_mm, t_s: float = 0.0) -> np.ndarray:
        """Mean + fluctuation (N, 3) [mm/s] (frozen: ``t_s`` is ignored)."""
        p = np.asarray(p_mm, dtype=float).reshape(-1, 3)
        return self.mean_velocity(p) + self.fluctuation(p)

    def box_average(self, p_mm, window_mm, nodes: int = 4) -> np.ndarray:
        """Velocity averaged over boxes ``window_mm`` (w_x, w_y, w_z) [mm] along the world axes
        centred on ``p_mm`` (N, 3): ``nodes ** 3`` Gauss-Legendre points (the window-filtered truth)."""
        p = np.asarray(p_mm, dtype=float).reshape(-1, 3)
        win = np.broadcast_to(np.asarray(window_mm, dtype=float), (3,))
        t, w = np.polynomial.legendre.leggauss(int(nodes))
        g = np.stack(np.meshgrid(t, t, t, indexing="ij"), -1).reshape(-1, 3) * 0.5 * win
        wt = (w[:, None, None] * w[None, :, None] * w[None, None, :]).ravel() / 8.0
        acc = np.zeros_like(p)
        for off, ww in zip(g, wt, strict=True):
            acc += ww * self.velocity(p + off)
        return acc


_KERNELS: dict = {}


def _mode_sums(rel, kv, phase, amp, b):
    """``(sum_n b_n sin(theta_n), sum_n amp_n cos(theta_n))``, each (N, 3), with
    ``theta_n = rel . kv_n + phase_n``: one pass over the modes per point, points in parallel."""
    if not _KERNELS:
        nb = numba()

        @nb.njit(parallel=True, fastmath=False, cache=True)
        def mode_sums(rel, kv, phase, amp, b):
            n, m = rel.shape[0], kv.shape[0]
            psi = np.empty((n, 3))
            curl = np.empty((n, 3))
            for i in nb.prange(n):
                x, y, z = rel[i, 0], rel[i, 1], rel[i, 2]
                s0 = s1 = s2 = c0 = c1 = c2 = 0.0
                for k in range(m):
                    th = x * kv[k, 0] + y * kv[k, 1] + z * kv[k, 2] + phase[k]
                    c, s = math.cos(th), math.sin(th)
                    c0 += c * amp[k, 0]
                    c1 += c * amp[k, 1]
                    c2 += c * amp[k, 2]
                    s0 += s * b[k, 0]
                    s1 += s * b[k, 1]
                    s2 += s * b[k, 2]
                psi[i, 0], psi[i, 1], psi[i, 2] = s0, s1, s2
                curl[i, 0], curl[i, 1], curl[i, 2] = c0, c1, c2
            return psi, curl

        _KERNELS["mode_sums"] = mode_sums
    return _KERNELS["mode_sums"](rel, kv, phase, amp, b)
