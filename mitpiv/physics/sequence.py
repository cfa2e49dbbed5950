"""Time-resolved particle sequences: particles seeded in a box and advected through a flow
over many frames, each with a persistent identity, the box kept at a constant particle
count (particles that leave are dropped, as many enter).

Integration: classical fourth-order Runge-Kutta (:func:`rk4`, the same scheme as
:func:`mitpiv.physics.advection.advect`) in ``substeps`` equal steps per frame, vectorised
over particles. Velocities are the flow's at the recorded positions; accelerations the
material derivative ``Du/Dt`` by a central difference along the pathline (two RK4 steps of
``+-h`` with ``h = dt / (16 substeps)``: error ``O(h^2)``).

Inflow: after each frame the particles outside the box are dropped and as many enter. With
``reseed = "inflow"`` (default) the new ones are points of the box at the new time whose
position one frame earlier (integrated backward) lies outside it, i.e. particles that
crossed the boundary during the frame: for an incompressible flow they are uniformly
distributed over the fluid that entered, so the density stays uniform. Candidates are drawn
uniformly in a shell along the box faces as thick as the largest displacement over a frame
(times 1.5); should too few of them qualify (a flow with almost no inflow), the rest are
drawn uniformly in the box and a warning says so. ``reseed = "uniform"``: new particles
anywhere in the box (simpler, not physical).

Hand-written (NumPy): SciPy's ``solve_ivp`` integrates one system at a time and would need
the particles packed into one long vector with a shared adaptive step; a fixed-step RK4 on
the (N, 3) array is simpler, vectorised and accurate to the ``substeps**-4`` law.
"""

from __future__ import annotations

import logging
import warnings
from dataclasses import dataclass

import numpy as np

from mitpiv.errors import ConfigError, MitpivWarning, check_positive

__all__ = ["Sequence", "advect_sequence", "rk4"]

log = logging.getLogger(__name__)

RESEED = ("inflow", "uniform")


def rk4(positions_mm, flow, *, t0_s: float, dt_s: float, substeps: int) -> np.ndarray:
    """Positions (N, 3) [mm] after ``dt_s`` (may be negative: backward) of RK4 in
    ``substeps`` equal steps from time ``t0_s`` (:func:`mitpiv.physics.advection.rk4_steps`)."""
    from mitpiv.physics.advection import rk4_steps

    return rk4_steps(positions_mm, flow, t0_s=t0_s, dt_s=dt_s, substeps=substeps)


@dataclass
class Sequence:
    """Particles over ``F`` frames; particle ``j`` (column) is one identity throughout.

    Attributes
    ----------
    positions_mm, velocities_mm_s, accelerations_mm_s2 : (F, N, 3) arrays, NaN where
        particle ``j`` is not in the box at frame ``f``.
    times_s : (F,) frame times [s].
    diameters_um : (N,) particle diameters [um].
    ids : (N,) int64 particle identities (``arange(N)``: the order of first appearance).
    """

    positions_mm: np.ndarray
    velocities_mm_s: np.ndarray
    accelerations_mm_s2: np.ndarray
    times_s: np.ndarray
    diameters_um: np.ndarray
    ids: np.ndarray

    @property
    def present(self) -> np.ndarray:
        """(F, N) True where the particle is in the box."""
        return np.all(np.isfinite(self.positions_mm), axis=2)

    def frame(self, f: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The particles of frame ``f``: (positions (K, 3), diameters (K,), ids (K,))."""
        m = self.present[f]
        return self.positions_mm[f, m], self.diameters_um[m], self.ids[m]


def _inside(p, lo, hi):
    return np.all((p >= lo) & (p <= hi), axis=1) & np.all(np.isfinite(p), axis=1)


def _material_derivative(flow, p, t, h, substeps):
    """Du/Dt at (p, t): central difference of the velocity along the pathline."""
    if p.shape[0] == 0:
        return np.zeros((0, 3))
    fwd = rk4(p, flow, t0_s=t, dt_s=h, substeps=1)
    bwd = rk4(p, flow, t0_s=t, dt_s=-h, substeps=1)
    return (flow(fwd, t + h) - flow(bwd, t - h)) / (2 * h)


def _shell_points(rng, n, lo, hi, shell):
    """``n`` points uniform in the box within ``shell`` [mm] of a face (rejection, vectorised)."""
    out = []
    got = 0
    while got < n:
        q = rng.uniform(lo, hi, (max(4 * (n - got), 256), 3))
        near = np.any((q - lo < shell) | (hi - q < shell), axis=1)
        out.append(q[near])
        got += int(near.sum())
    return np.concatenate(out)[:n]


def _entering(rng, k, flow, t_new, dt, lo, hi, shell, substeps, max_tries=20):
    """``k`` points in the box at ``t_new`` that were outside it at ``t_new - dt``."""
    got, tries = [], 0
    need = k
    # the fraction of shell points that entered is about (inflow area x u dt) / shell volume
    while need > 0 and tries < max_tries:
        cand = _shell_points(rng, max(64, 8 * need), lo, hi, shell)
        back = rk4(cand, flow, t0_s=t_new, dt_s=-dt, substeps=substeps)
        ok = ~_inside(back, lo, hi)
        take = cand[ok][:need]
        got.append(take)
        need -= take.shape[0]
        tries += 1
    new = np.concatenate(got) if got else np.zeros((0, 3))
    return new, need


def advect_sequence(flow, *, box_min_mm, box_max_mm, n_frames: int, dt_s: float, count: int | None = None,
                    initial_mm=None, diameter_um: float = 1.0, distribution: str = "monodisperse",
                    geometric_std: float = 1.5, substeps: int = 8, reseed: str = "inflow", t0_s: float = 0.0,
                    seed=0, progress=None) -> Sequence:
    """Seed a box and advect its particles over ``n_frames`` frames ``dt_s`` apart.

    Parameters
    ----------
    flow : callable ``flow(p_mm (N, 3), t_s) -> (N, 3)`` [mm/s] (:mod:`mitpiv.physics.flows`).
    box_min_mm, box_max_mm : (3,) the box [mm]; particles outside it are dropped.
    n_frames : number of frames F >= 1.
    dt_s : time between frames [s].
    count : particles seeded uniformly at the first frame (and kept in the box); or
    initial_mm : (N, 3) start positions [mm] instead (their count is kept).
    diameter_um, distribution, geometric_std : particle diameters
        (:func:`mitpiv.physics.seeding.sample_diameters`).
    substeps : RK4 steps per frame (the error falls as ``substeps**-4``).
    reseed : "inflow" or "uniform": where entering particles appear (module notes).
    t0_s : time of the first frame [s].
    seed : int or numpy Generator: positions, diameters and inflow.
    progress : see :mod:`mitpiv.progress` (one step per frame).

    Returns
    -------
    :class:`Sequence`.
    """
    from mitpiv.physics.seeding import sample_diameters
    from mitpiv.progress import bar

    lo = np.asarray(box_min_mm, dtype=np.float64).reshape(3)
    hi = np.asarray(box_max_mm, dtype=np.float64).reshape(3)
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))) or np.any(hi <= lo):
        raise ConfigError(f"advect_sequence: box_max_mm {hi.tolist()} must exceed box_min_mm {lo.tolist()} on every "
                          "axis (finite values, mm).")
    if isinstance(n_frames, bool) or int(n_frames) != n_frames or n_frames < 1:
        raise ConfigError(f"advect_sequence: 'n_frames' must be an integer >= 1, got {n_frames!r}.")
    if isinstance(substeps, bool) or int(substeps) != substeps or substeps < 1:
        raise ConfigError(f"advect_sequence: 'substeps' must be an integer >= 1, got {substeps!r}.")
    if reseed not in RESEED:
        raise ConfigError(f"advect_sequence: 'reseed' must be one of {RESEED}, got {reseed!r}.")
    dt = check_positive("dt_s", dt_s, owner="advect_sequence", unit="s")
    n_frames, substeps = int(n_frames), int(substeps)
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    if (count is None) == (initial_mm is None):
        raise ConfigError("advect_sequence: give exactly one of 'count' or 'initial_mm'.")
    if initial_mm is not None:
        p = np.array(initial_mm, dtype=np.float64).reshape(-1, 3)
        if not np.all(_inside(p, lo, hi)):
            raise ConfigError(f"advect_sequence: {int((~_inside(p, lo, hi)).sum())} of the 'initial_mm' positions lie "
                              f"outside the box {lo.tolist()} - {hi.tolist()} mm (or are not finite).")
    else:
        if isinstance(count, bool) or int(count) != count or count < 0:
            raise ConfigError(f"advect_sequence: 'count' must be a non-negative integer, got {count!r}.")
        p = rng.uniform(lo, hi, (int(count), 3))
    n_target = p.shape[0]

    def diameters(n):
        return sample_diameters(n, diameter_um=diameter_um, distribution=distribution, geometric_std=geometric_std,
                                seed=rng)

    ids = np.arange(n_target, dtype=np.int64)
    diam = [np.asarray(diameters(n_target), dtype=np.float64).reshape(-1)]
    next_id = n_target
    h = dt / (16 * substeps)
    rec_p, rec_v, rec_a, rec_id = [], [], [], []
    short = 0
    with bar(n_frames, desc="advect", progress=progress, unit="frame") as b:
        for f in range(n_frames):
            t = t0_s + f * dt
            rec_p.append(p)
            rec_v.append(flow(p, t) if p.shape[0] else np.zeros((0, 3)))
            rec_a.append(_material_derivative(flow, p, t, h, substeps))
            rec_id.append(ids)
            b.update()
            if f == n_frames - 1:
                break
            q = rk4(p, flow, t0_s=t, dt_s=dt, substeps=substeps) if p.shape[0] else p
            keep = _inside(q, lo, hi)
            p, ids = q[keep], ids[keep]
            k = n_target - p.shape[0]
            if k > 0:
                if reseed == "inflow":
                    disp = np.linalg.norm(q - rec_p[-1], axis=1)
                    shell = max(1.5 * float(disp.max()) if disp.size else 0.0, 1e-9 * float(np.max(hi - lo)))
                    new, missing = _entering(rng, k, flow, t + dt, dt, lo, hi, shell, substeps)
                    if missing:
                        short += missing
                        new = np.concatenate([new, rng.uniform(lo, hi, (missing, 3))])
                else:
                    new = rng.uniform(lo, hi, (k, 3))
                p = np.concatenate([p, new])
                ids = np.concatenate([ids, np.arange(next_id, next_id + k, dtype=np.int64)])
                diam.append(np.asarray(diameters(k), dtype=np.float64).reshape(-1))
                next_id += k
    if short:
        warnings.warn(f"advect_sequence: {short} entering particle(s) could not be placed at the inflow (too few "
                      "candidate points crossed the box boundary during a frame) and were seeded uniformly in the box.",
                      MitpivWarning, stacklevel=2)
    n_total = next_id
    shape = (n_frames, n_total, 3)
    pos, vel, acc = np.full(shape, np.nan), np.full(shape, np.nan), np.full(shape, np.nan)
    for f in range(n_frames):
        pos[f, rec_id[f]] = rec_p[f]
        vel[f, rec_id[f]] = rec_v[f]
        acc[f, rec_id[f]] = rec_a[f]
    return Sequence(pos, vel, acc, t0_s + dt * np.arange(n_frames, dtype=np.float64), np.concatenate(diam),
                    np.arange(n_total, dtype=np.int64))
