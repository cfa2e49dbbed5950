"""Seeding tracer particles in a box, and seeding densities that target an image density.

Positions in world millimetres, diameters in micrometres. Every function takes ``seed``
(an int or a :class:`numpy.random.Generator`); the same seed gives the same particles.
:func:`visible_fraction` and :func:`count_for_density` work for any camera of the camera
contract (:class:`mitpiv.physics.camera.Camera`: pinhole or plenoptic).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from mitpiv.errors import ConfigError, check_positive

__all__ = ["Particles", "seed_box", "visible_fraction", "count_for_density", "count_for_ppp", "sample_diameters"]


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


def _box(box_min_mm, box_max_mm, owner: str) -> tuple[np.ndarray, np.ndarray]:
    try:
        lo = np.asarray(box_min_mm, dtype=float).reshape(3)
        hi = np.asarray(box_max_mm, dtype=float).reshape(3)
    except (TypeError, ValueError):
        raise ConfigError(f"{owner}: box_min_mm and box_max_mm must be three numbers (x, y, z) [mm], got "
                          f"{box_min_mm!r} and {box_max_mm!r}.") from None
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(hi > lo)):
        raise ConfigError(f"{owner}: box_max_mm {hi.tolist()} must exceed box_min_mm {lo.tolist()} on every axis "
                          f"(finite values) [mm].")
    return lo, hi


def visible_fraction(camera, box_min_mm, box_max_mm, *, samples: int = 200_000, seed=0) -> float:
    """Fraction of a uniformly seeded box that images onto a camera's sensor.

    Monte Carlo: ``samples`` points drawn uniformly in the box (``seed``), counted where
    ``camera.visible`` (in front of the camera and projected onto the sensor; for a
    plenoptic camera the chief ray through the main-lens centre onto the microlens plane,
    scaled to the sensor). Its standard error is ``sqrt(f (1 - f) / samples)`` (0.0011 at
    the default 200 000 samples and f = 0.5).

    Parameters
    ----------
    camera : Camera
        Any camera of the camera contract (:class:`~mitpiv.physics.camera.PinholeCamera`,
        :class:`~mitpiv.physics.plenoptic.PlenopticCamera`, a reconstruction mapping with a
        resolution); :func:`mitpiv.io.camera_from_metadata` builds one from an image.
    box_min_mm, box_max_mm : (3,) float
        Opposite corners of the axis-aligned seeding box [mm, world].
    samples : int
        Number of Monte Carlo points.
    seed : int or numpy.random.Generator

    Returns
    -------
    float in [0, 1]
    """
    lo, hi = _box(box_min_mm, box_max_mm, "visible_fraction")
    if isinstance(samples, bool) or int(samples) != samples or samples < 1:
        raise ConfigError(f"visible_fraction: 'samples' must be a positive integer, got {samples!r}.")
    pts = _rng(seed).uniform(lo, hi, size=(int(samples), 3))
    return float(np.mean(camera.visible(pts)))


def count_for_density(
    camera,
    box_min_mm,
    box_max_mm,
    *,
    ppp: float | None = None,
    particles_per_microlens: float | None = None,
    samples: int = 200_000,
    seed=0,
) -> int:
    """Particle count that gives a target image density in ``camera`` for a uniform box.

    ``ppp``: particles per pixel of the image (``W H`` pixels); ``particles_per_microlens``:
    particles per lenslet of a plenoptic camera (``camera.n_lenslets``). The particles
    that image onto the sensor are a fraction :func:`visible_fraction` of the box's, so
    ``count = density * (pixels or lenslets) / fraction``: a camera that sees part of the
    box needs more particles in all.

    Give one of the two densities, or both: then the camera picks, per microlens for a
    plenoptic camera (one with ``n_lenslets``), per pixel for any other (so one seeding
    table serves whichever camera sets the density).

    Parameters
    ----------
    camera : Camera
        Any camera of the camera contract (see :func:`visible_fraction`).
    box_min_mm, box_max_mm : (3,) float
        Seeding box [mm, world].
    ppp, particles_per_microlens : float, optional
        Target densities (> 0).
    samples : int
        Monte Carlo points of :func:`visible_fraction`.
    seed : int or numpy.random.Generator
        Seed of :func:`visible_fraction`'s points.

    Returns
    -------
    int

    Raises
    ------
    ConfigError
        Neither density given, a density not > 0, ``particles_per_microlens`` for a camera
        without lenslets, or a camera that sees no part of the box.
    """
    for v, name in ((ppp, "ppp"), (particles_per_microlens, "particles_per_microlens")):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int | float | np.integer | np.floating)
                              or not np.isfinite(v) or not v > 0):
            raise ConfigError(f"count_for_density: '{name}' must be a finite number > 0, got {v!r}.")
    lenslets = getattr(camera, "n_lenslets", None)
    if ppp is None and particles_per_microlens is None:
        raise ConfigError("count_for_density: give 'ppp' (particles per pixel) or 'particles_per_microlens' "
                          "(plenoptic cameras), or both (the camera picks).")
    if ppp is not None and particles_per_microlens is not None:  # both: the camera's kind picks
        ppp, particles_per_microlens = (None, particles_per_microlens) if lenslets is not None else (ppp, None)
    if particles_per_microlens is not None and lenslets is None:
        raise ConfigError(f"count_for_density: 'particles_per_microlens' needs a plenoptic camera (one with "
                          f"lenslets); got a {type(camera).__name__}. Use 'ppp' for pinhole cameras.")
    what = "ppp" if ppp is not None else "particles_per_microlens"
    frac = visible_fraction(camera, box_min_mm, box_max_mm, samples=samples, seed=seed)
    if frac == 0:
        raise ConfigError(f"count_for_density: the camera sees no part of the seeding box {np.asarray(box_min_mm).tolist()}"
                          f" .. {np.asarray(box_max_mm).tolist()} mm; cannot target a {what}. Move the box into the "
                          f"camera's view or choose another camera.")
    if ppp is not None:
        w, h = camera.resolution
        return int(round(ppp * w * h / frac))
    return int(round(particles_per_microlens * int(lenslets) / frac))


def count_for_ppp(ppp: float, camera, box_min, box_max, *, samples: int = 200_000, seed=0) -> int:
    """Particle count giving ``ppp`` particles per pixel in ``camera`` for a uniform box:
    ``count_for_density(camera, box_min, box_max, ppp=ppp, samples=samples, seed=seed)``
    (kept for scripts; see :func:`count_for_density`)."""
    ppp = check_positive("ppp", ppp, owner="seeding")
    return count_for_density(camera, box_min, box_max, ppp=ppp, samples=samples, seed=seed)


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
    ``ppp`` (particles per pixel, with ``camera``: any camera of the camera contract, see
    :func:`count_for_density`).
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
        n = count_for_density(camera, lo, hi, ppp=check_positive("ppp", ppp, owner="seeding"), seed=rng)
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
