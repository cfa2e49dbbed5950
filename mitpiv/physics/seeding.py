"""Seeding tracer particles in a box.

Positions in world millimetres, diameters in micrometres. Every function takes ``seed``
(an int or a :class:`numpy.random.Generator`); the same seed gives the same particles.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from mitpiv.errors import ConfigError, check_positive

__all__ = ["Particles", "seed_box", "count_for_ppp", "sample_diameters"]


@dataclass
class Particles:
    """Particle positions ``p_world`` [mm], shape (N, 3), and diameters [um], shape (N,)."""

    positions_mm: np.ndarray
    diameters_um: np.ndarray

    def __post_init__(self) -> None:
        self.positions_mm = np.asarray(self.positions_mm, dtype=np.float64).reshape(-1, 3)
        self.diameters_um = np.asarray(self.diameters_um, dtype=np.float64).reshape(-1)
        if self.diameters_um.shape[0] != self.positions_mm.shape[0]:
            raise ConfigError(
                f"Particles: {self.positions_mm.shape[0]} positions but "
                f"{self.diameters_um.shape[0]} diameters."
            )

    def __len__(self) -> int:
        return self.positions_mm.shape[0]


def _rng(seed) -> np.random.Generator:
    return seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)


def sample_diameters(
    n: int,
    *,
    diameter_um: float = 1.0,
    distribution: str = "monodisperse",
    geometric_std: float = 1.5,
    seed=0,
) -> np.ndarray:
    """Particle diameters [um].

    ``distribution="monodisperse"`` gives ``diameter_um`` for all; ``"lognormal"`` gives
    a log-normal with median ``diameter_um`` and geometric standard deviation
    ``geometric_std`` (> 1).
    """
    d = check_positive("diameter_um", diameter_um, owner="seeding", unit="um")
    if distribution == "monodisperse":
        return np.full(n, d)
    if distribution == "lognormal":
        if not geometric_std > 1.0:
            raise ConfigError(
                f"seeding: 'geometric_std' of a log-normal must be > 1, got {geometric_std!r}."
            )
        return np.exp(_rng(seed).normal(np.log(d), np.log(geometric_std), n))
    raise ConfigError(
        f"seeding: 'distribution' must be 'monodisperse' or 'lognormal', got {distribution!r}."
    )


def count_for_ppp(ppp: float, camera, box_min, box_max, *, samples: int = 200_000, seed=0) -> int:
    """Particle count giving ``ppp`` particles per pixel in ``camera`` for a uniform box.

    The fraction of the box that projects into the image is estimated with ``samples``
    uniform points (a camera that sees part of the box needs more particles in all).
    """
    ppp = check_positive("ppp", ppp, owner="seeding")
    lo, hi = np.asarray(box_min, float), np.asarray(box_max, float)
    pts = _rng(seed).uniform(lo, hi, size=(samples, 3))
    uv = camera.project(pts)
    w, h = camera.resolution
    z = camera.world_to_camera(pts)[:, 2]
    inside = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
    frac = inside.mean()
    if frac == 0:
        raise ConfigError("seeding: the camera sees no part of the seeding box; cannot target a ppp.")
    return int(round(ppp * w * h / frac))


def seed_box(
    box_min,
    box_max,
    *,
    count: int | None = None,
    concentration_per_mm3: float | None = None,
    ppp: float | None = None,
    camera=None,
    diameter_um: float = 1.0,
    distribution: str = "monodisperse",
    geometric_std: float = 1.5,
    min_separation_mm: float | None = None,
    seed=0,
) -> Particles:
    """Uniformly seed particles in an axis-aligned box [mm].

    Give exactly one of ``count``, ``concentration_per_mm3`` (particles per mm^3) or
    ``ppp`` (particles per pixel, with ``camera``: a :class:`~mitpiv.physics.camera.PinholeCamera`).
    With ``min_separation_mm`` no two centres are closer than that distance (rejection
    of one particle of each close pair and re-drawing, vectorised).
    """
    lo, hi = np.asarray(box_min, float).reshape(3), np.asarray(box_max, float).reshape(3)
    if np.any(hi <= lo):
        raise ConfigError(
            f"seeding: box_max {hi.tolist()} must exceed box_min {lo.tolist()} on every axis."
        )
    given = [v is not None for v in (count, concentration_per_mm3, ppp)]
    if sum(given) != 1:
        raise ConfigError("seeding: give exactly one of 'count', 'concentration_per_mm3' or 'ppp'.")
    rng = _rng(seed)
    if count is not None:
        if int(count) != count or count < 0:
            raise ConfigError(f"seeding: 'count' must be a non-negative integer, got {count!r}.")
        n = int(count)
    elif concentration_per_mm3 is not None:
        c = check_positive("concentration_per_mm3", concentration_per_mm3, owner="seeding", unit="1/mm^3")
        n = int(round(c * np.prod(hi - lo)))
    else:
        if camera is None:
            raise ConfigError("seeding: 'ppp' needs a 'camera' to count pixels.")
        n = count_for_ppp(ppp, camera, lo, hi, seed=rng)
    pos = rng.uniform(lo, hi, size=(n, 3))
    if min_separation_mm is not None and n > 1:
        dmin = check_positive("min_separation_mm", min_separation_mm, owner="seeding", unit="mm")
        # Volume fraction of exclusion spheres: beyond ~0.3 random sequential addition stalls.
        phi = n * (np.pi / 6) * dmin**3 / np.prod(hi - lo)
        if phi > 0.3:
            raise ConfigError(
                f"seeding: min_separation_mm={dmin} is too large for {n} particles in this box "
                f"(exclusion volume fraction {phi:.2f} > 0.3). Lower the separation or the count."
            )
        for _ in range(1000):
            pairs = cKDTree(pos).query_pairs(dmin, output_type="ndarray")
            if pairs.size == 0:
                break
            bad = np.unique(pairs[:, 1])
            pos[bad] = rng.uniform(lo, hi, size=(bad.size, 3))
        else:
            raise ConfigError("seeding: could not satisfy min_separation_mm in 1000 rounds.")
    diam = sample_diameters(n, diameter_um=diameter_um, distribution=distribution, geometric_std=geometric_std, seed=rng)
    return Particles(pos, diam)
