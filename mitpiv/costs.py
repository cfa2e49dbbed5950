"""Up-front cost estimates of the expensive knobs: the memory and time a reconstruction
(voxels x cameras x iterations), a focal stack (planes), 3D PIV (vectors) or a seeding
(particles) will take, checked before any work starts.

A run whose *certain* memory (the arrays it must hold at once: a lower bound) exceeds the
memory available now is refused with a :class:`~mitpiv.errors.ConfigError` that names the
knob, the estimate and the fix; the rest is logged (``mitpiv.costs``) so that a long run
says up front how long it will take. The time figures are rough orders of magnitude
(throughputs measured on a 2-core development machine, written below with each model);
they guide, they do not promise.

Hand-written: a handful of formulas; the available memory comes from psutil when it is
installed, else ``/proc/meminfo`` (Linux) or ``os.sysconf``.
"""

from __future__ import annotations

import logging
import math
import os
import shutil
from dataclasses import dataclass
from pathlib import Path

from mitpiv.errors import ConfigError

__all__ = ["Cost", "available_memory_bytes", "check_memory", "check_disk", "human_bytes", "human_seconds",
           "reconstruction_cost", "drt_mart_cost", "focal_stack_cost", "piv_cost", "piv_vectors", "particles_cost", "MEMORY_FRACTION",
           "MAX_ITERATIONS", "MAX_PLANES"]

log = logging.getLogger(__name__)

#: Most iterations a reconstruction takes (MART / SMART converge in 5-50; far more is a typo).
MAX_ITERATIONS = 10_000

#: Most planes a focal stack has: a light field resolves depth in tens to a few thousand
#: planes (the benchmarks use up to 1000); far more is a typo (1e7 planes of even an 8 x 8
#: light field are 2.4 GiB and most of an hour of work).
MAX_PLANES = 100_000

#: Share of the available memory a single array set may take before it is refused.
MEMORY_FRACTION = 0.8

# Throughputs (orders of magnitude, 2-core development machine, compiled kernels). The MART
# and PIV figures were measured on `make demo` at commit 5ea634e (bench/bench_demo.py): MART
# 614 M voxel-camera updates (2 frames x 12.8 M voxels x 4 cameras x (5 + 1) sweeps, weights
# built once) in 18.1 s; PIV 3.2e10 correlation voxels (x 3, see piv_cost) in 9.9 s.
#: MART / SMART: voxel-camera updates per second per iteration.
MART_VOXEL_CAMERA_PER_S = 3.5e7
#: Refocusing: light-field samples (s, t, u, v) gathered per second per plane.
REFOCUS_SAMPLES_PER_S = 2e8
#: Refocusing: the fixed cost of a plane (its geometry and interpolation tables), measured
#: 0.2-0.7 ms a plane on 8 x 8 px light fields (2 cores), where it is all of the time.
REFOCUS_SECONDS_PER_PLANE = 2e-4
#: 3D PIV: correlation-window voxels (FFT of (2w)^3 per vector) per second.
PIV_VOXELS_PER_S = 2.5e9
#: Seeding and advection: particles per second.
PARTICLES_PER_S = 5e6
# DRT-MART (mitpiv.reconstruct.plenoptic.drt_weights / drt_mart), measured on the lfpiv-vs-tomo
# replication's light-field grids (docs/replications/lfpiv-vs-tomo, commit 806ae28): weight
# entries = pixels x rays per pixel x slabs along the optical axis x 0.91-1.05 over its seven
# grids (67-182 slabs, PMR 7 / 14 / 28); the replica's 3.97e8 entries built in 59 s, 400
# iterations at 1.3e8 updates/s over the 47 % of the entries left once dark and edge voxels
# are dropped, and ~14 GB resident at the peak (~35 bytes per entry).
#: DRT weight entries per pixel, ray and slab.
DRT_ENTRIES_PER_PIXEL_RAY_SLAB = 1.0
#: Bytes per weight entry at the peak: the measured ~35 (the matrix, its dark rows and its
#: live columns held at once while DRT-MART starts; the keys and values of every chunk and
#: their concatenation while the weights are built take 24 of them).
DRT_BYTES_PER_ENTRY = 35.0
#: Weight entries built per second.
DRT_ENTRIES_PER_S = 6.7e6
#: MART updates (weight entries) per second per iteration, and the share of the entries left.
DRT_UPDATES_PER_S = 1.3e8
DRT_ACTIVE_FRACTION = 0.5


@dataclass(frozen=True)
class Cost:
    """An estimate: ``memory_bytes`` the run must hold at once (a lower bound), ``seconds``
    (order of magnitude), ``disk_bytes`` written, and what it counts (``items``, e.g.
    "12.8 M voxels")."""

    memory_bytes: float
    seconds: float
    items: str
    disk_bytes: float = 0.0

    def __str__(self) -> str:
        disk = f", {human_bytes(self.disk_bytes)} on disk" if self.disk_bytes else ""
        return f"{self.items}: about {human_bytes(self.memory_bytes)} of memory{disk}, ~{human_seconds(self.seconds)}"


def human_bytes(n: float) -> str:
    n = float(n)
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if abs(n) < 1024 or unit == "PiB":
            return f"{n:.3g} {unit}"
        n /= 1024
    return f"{n:.3g} PiB"  # pragma: no cover


def human_seconds(s: float) -> str:
    s = float(s)
    if s < 60:
        return f"{s:.2g} s"
    if s < 3600:
        return f"{s / 60:.2g} min"
    if s < 86400 * 2:
        return f"{s / 3600:.2g} h"
    return f"{s / 86400:.3g} days"


def available_memory_bytes() -> int:
    """Memory available to a new allocation now [bytes] (psutil, /proc/meminfo or sysconf)."""
    try:
        import psutil

        return int(psutil.virtual_memory().available)
    except ImportError:
        pass
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE"))
    except (ValueError, OSError, AttributeError):  # pragma: no cover - no way to tell: do not refuse
        return 2**62


def check_memory(cost: Cost, *, what: str, fix: str, available: int | None = None, quiet: bool = False) -> Cost:
    """Raise :class:`ConfigError` when ``cost.memory_bytes`` exceeds ``MEMORY_FRACTION`` of
    the available memory, naming ``what`` (the knob and its value) and ``fix``; otherwise
    log the estimate (info; a warning above an hour; debug only with ``quiet``, for checks
    that run again later, such as validating an experiment) and return ``cost``."""
    avail = available_memory_bytes() if available is None else int(available)
    if not math.isfinite(cost.memory_bytes) or cost.memory_bytes > MEMORY_FRACTION * avail:
        raise ConfigError(f"{what}: {cost.items} need at least {human_bytes(cost.memory_bytes)} of memory, more than "
                          f"{MEMORY_FRACTION:.0%} of the {human_bytes(avail)} available on this machine "
                          f"({human_bytes(MEMORY_FRACTION * avail)}); {fix}.")
    if quiet:
        log.debug("estimate for %s: %s", what, cost)
        return cost
    log.info("estimate for %s: %s", what, cost)
    if cost.seconds > 3600:
        log.warning("%s will take long: %s (Ctrl-C stops it; finished stages are kept)", what, cost)
    return cost


def check_disk(cost: Cost, folder, *, what: str, fix: str) -> Cost:
    """Raise :class:`ConfigError` when ``cost.disk_bytes`` exceed the free space of ``folder``."""
    folder = Path(folder)
    while not folder.exists() and folder != folder.parent:
        folder = folder.parent
    free = shutil.disk_usage(folder).free
    if not math.isfinite(cost.disk_bytes) or cost.disk_bytes > free:
        raise ConfigError(f"{what}: {cost.items} need {human_bytes(cost.disk_bytes)} on disk, more than the "
                          f"{human_bytes(free)} free in {str(folder)!r}; {fix}.")
    return cost


def _count(n: float) -> str:
    n = float(n)
    for div, unit in ((1e12, "T"), (1e9, "G"), (1e6, "M"), (1e3, "k")):
        if n >= div:
            return f"{n / div:.3g} {unit}"
    return f"{n:.0f}"


def reconstruction_cost(n_voxels: float, *, n_images: int = 1, iterations: int = 1, method: str = "mart") -> Cost:
    """A volume reconstruction: the float32 volume, its float64 working copy and the
    candidate mask (13 bytes per voxel, held at once: the lower bound); time from the
    voxel-camera updates of ``iterations`` MART sweeps (one sweep for MLOS / SAPIV)."""
    n_voxels = float(n_voxels)
    sweeps = max(int(iterations), 1) if method in ("mart", "smart", "drt-mart") else 1
    return Cost(memory_bytes=13.0 * n_voxels, seconds=n_voxels * max(n_images, 1) * (sweeps + 1) / MART_VOXEL_CAMERA_PER_S,
                items=f"{_count(n_voxels)} voxels x {n_images} image(s) x {sweeps} iteration(s)")


def drt_mart_cost(pixels: float, rays_per_pixel: int, slabs: int, *, iterations: int, n_voxels: float,
                  n_images: int = 1, entries_per_pixel_ray_slab: float = DRT_ENTRIES_PER_PIXEL_RAY_SLAB) -> Cost:
    """DRT-MART of a plenoptic image: its sparse weights (:data:`DRT_BYTES_PER_ENTRY` per
    entry while they are built; pixels x rays per pixel x slabs of the grid along the optical
    axis x ``entries_per_pixel_ray_slab`` entries, which
    :func:`mitpiv.reconstruct.plenoptic.drt_cost` measures on a sample of the pixels) and the
    voxel arrays (13 bytes a voxel), time from building the weights and sweeping the live
    entries ``iterations`` times, for each of ``n_images`` images."""
    entries = float(pixels) * int(rays_per_pixel) * int(slabs) * float(entries_per_pixel_ray_slab)
    per_image = entries / DRT_ENTRIES_PER_S + max(int(iterations), 1) * DRT_ACTIVE_FRACTION * entries / DRT_UPDATES_PER_S
    return Cost(memory_bytes=DRT_BYTES_PER_ENTRY * entries + 13.0 * float(n_voxels),
                seconds=per_image * max(int(n_images), 1),
                items=f"{_count(entries)} weight entries ({_count(pixels)} px x {int(rays_per_pixel)} rays x "
                      f"{int(slabs)} slabs) x {max(int(iterations), 1)} iteration(s)")


def focal_stack_cost(n_planes: float, plane_shape, *, n_samples_per_plane: float | None = None,
                     streamed: bool = True) -> Cost:
    """A focal stack: streamed to disk (float32 planes on disk; in memory a block of 16
    planes, one plane's weights and the plane depths), or with ``streamed=False`` held in
    memory whole; time from the light-field samples gathered per plane and a fixed cost per
    plane."""
    px = float(math.prod(plane_shape))
    n_planes = float(n_planes)
    samples = n_samples_per_plane if n_samples_per_plane is not None else px
    stack = 4.0 * px * n_planes
    work = 16.0 * px + 4.0 * px * min(n_planes, 16.0) + 16.0 * n_planes  # + depths and alphas (float64)
    return Cost(memory_bytes=work + (0.0 if streamed else stack),
                seconds=n_planes * (samples / REFOCUS_SAMPLES_PER_S + REFOCUS_SECONDS_PER_PLANE),
                items=f"{_count(n_planes)} plane(s) of {_count(px)} px", disk_bytes=stack if streamed else 0.0)


def piv_vectors(grid_shape, window, overlap: float) -> int:
    """Vectors of one PIV pass on a (n_z, n_y, n_x) grid: windows of ``window`` voxels (one
    size, or (w_x, w_y, w_z)) stepped by ``window * (1 - overlap)`` along each axis."""
    w_zyx = _window_zyx(window)
    return int(math.prod(max(0, (int(n) - w) // max(1, int(round(w * (1.0 - overlap)))) + 1)
                         for n, w in zip(grid_shape, w_zyx, strict=True)))


def _window_zyx(window) -> tuple[int, int, int]:
    """A PIV window (one size or (w_x, w_y, w_z)) as (w_z, w_y, w_x)."""
    import numpy as np

    if np.ndim(window) == 0:
        return (int(window),) * 3
    w = tuple(int(v) for v in np.ravel(window))
    if len(w) != 3:
        raise ConfigError(f"PIV window {window!r} must be one size or three (w_x, w_y, w_z).")
    return w[::-1]


def piv_cost(grid_shape, windows, overlap: float) -> Cost:
    """Multi-pass 3D PIV: the vector fields of the last pass (positions, velocities,
    flags: 80 bytes a vector) and one correlation of twice the window per axis (complex, 16
    bytes a voxel) per vector of the largest batch; time from the correlation voxels of every
    pass. Windows: one size, or (w_x, w_y, w_z), per pass."""
    ws = [_window_zyx(w)[::-1] for w in windows]  # (w_x, w_y, w_z)
    n = [piv_vectors(grid_shape, w, overlap) for w in ws]
    corr = [math.prod(2 * v for v in w) for w in ws]
    vox = sum(k * c for k, c in zip(n, corr, strict=True))
    return Cost(memory_bytes=80.0 * max(n) + 16.0 * max(corr), seconds=vox * 3 / PIV_VOXELS_PER_S,
                items=f"{_count(max(n))} vectors per pass x {len(ws)} pass(es)")


def particles_cost(count: float, *, frames: int = 2) -> Cost:
    """Seeding, advection and the PLY files of ``count`` particles: float64 positions of
    every frame, the diameters and one float32 PLY record (56 bytes) each."""
    count = float(count)
    return Cost(memory_bytes=count * (24.0 * frames + 8.0 + 56.0), seconds=count * frames / PARTICLES_PER_S,
                items=f"{_count(count)} particles", disk_bytes=56.0 * count * frames)
