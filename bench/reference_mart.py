"""Frozen copy of mitpiv's MART/SMART code path as of commit bec7139 (before issue 26), kept
as the baseline the benchmark prints beside today's ``mitpiv.reconstruct.mart`` in the same
run: plane-by-plane NumPy MLOS pass, NumPy camera projections and Jacobians, CSR weights
built per frame, the image residual after every iteration. Numerically the same method;
only the speed differs. Not part of the library (bench-only)."""

import logging
import math
import time

import numpy as np

from mitpiv.errors import ConfigError
from mitpiv.grid import VoxelGrid
from mitpiv.progress import Progress, track
from mitpiv.reconstruct._kernels import CIRCLE, GAUSSIAN, kernels
from mitpiv.reconstruct.tomo import (
    INTERPOLATIONS,
    _check_choice,
    _check_coverage,
    _check_images,
    _check_weight_options,
    _combine,
    _footprints,
    _inside,
    _plane_projections,
    _sampler,
    _warn_dark,
    check_iterations,
    preprocess_images,
    smart_sweep,
)

log = logging.getLogger(__name__)


class _CameraWeights:
    """CSR weights of one camera over the active voxels."""

    def __init__(self, indptr, indices, data, width, span, wsum):
        self.indptr, self.indices, self.data = indptr, indices, data
        self.width, self.span, self.wsum = width, span, wsum

    @property
    def nbytes(self) -> int:
        return self.indptr.nbytes + self.indices.nbytes + self.data.nbytes



def _build_weights(uv, fp, model, shape_hw):
    """CSR (pixel rows) of one camera, assembled in parallel over image rows."""
    k = kernels()
    h, w = shape_hw
    u, v = (np.ascontiguousarray(uv[:, i], dtype=np.float64) for i in (0, 1))
    rad = np.ascontiguousarray(fp[0], dtype=np.float64)
    pars = tuple(np.ascontiguousarray(a, dtype=np.float64) for a in fp[1:])
    # voxels bucketed by the image row of their projected centre (clamped onto the image)
    crow = np.clip(np.floor(v), 0, h - 1).astype(np.int64)
    order = np.argsort(crow, kind="stable")
    bucket = np.zeros(h + 1, np.int64)
    np.cumsum(np.bincount(crow, minlength=h), out=bucket[1:])
    reach = int(np.ceil(rad.max())) + 1 if len(rad) else 0
    span = int((np.floor(v + rad) - np.floor(v - rad)).max()) + 1 if len(rad) else 1
    counts = np.zeros(h * w + 1, np.int64)
    args = (u, v, rad, *pars, CIRCLE if model == "circle" else GAUSSIAN, h, w, order, bucket, reach)
    k["row_pass"](*args, counts, counts, np.zeros(0, np.int32), np.zeros(0, np.float32), False)
    indptr = np.cumsum(counts)
    indices = np.empty(indptr[-1], np.int32)
    data = np.empty(indptr[-1], np.float32)
    k["row_pass"](*args, counts, indptr[:-1].copy(), indices, data, True)
    wsum = np.bincount(indices, weights=data, minlength=len(u))
    return _CameraWeights(indptr, indices, data, w, max(span, 1), wsum)


def _candidates(imgs, maps, grid, interpolation, prune, progress, what):
    """Flat indices of voxels worth reconstructing, their MLOS values and projections."""
    samplers = [_sampler(im, interpolation) for im in imgs]
    idx, init, uvs = [], [], [[] for _ in maps]
    plane = np.arange(grid.shape[1] * grid.shape[2])
    t0 = time.perf_counter()
    for k in track(range(grid.shape[0]), desc=f"{what}: MLOS planes", progress=progress, unit="plane"):
        uv = _plane_projections(maps, grid, k)
        inside = np.stack([_inside(p, im) for p, im in zip(uv, imgs, strict=True)])
        val = _combine([f(p) for f, p in zip(samplers, uv, strict=True)], inside, "multiplicative", 1.0 / len(imgs))
        keep = (val > 0) if prune else inside.all(axis=0)
        idx.append(plane[keep] + k * len(plane))
        init.append(val[keep])
        for c, p in enumerate(uv):
            uvs[c].append(p[keep].astype(np.float32))  # float32: 1e-4 px at 1000 px
    log.debug("%s: MLOS pass over %d planes in %.1f s", what, grid.shape[0], time.perf_counter() - t0)
    return np.concatenate(idx), np.concatenate(init), [np.concatenate(u) for u in uvs]


def mart_reference(images, mappings, grid: VoxelGrid, *, iterations: int = 5, mu: float = 1.0, smart: bool = False,
         init="mlos", weights: str = "circle", psf_sigma_px: float = 0.5, interpolation: str = "linear",
         prune: bool = True, preprocess: float | None = None, chunk: int = 1_000_000, progress: Progress = None,
         return_info: bool = False):
    """MART or SMART reconstruction on sparse voxel-pixel weights.

    MART (``smart=False``; Elsinga et al. 2006): for every pixel ``i`` of every camera in
    turn, ``E_j <- E_j (I_i / sum_j w_ij E_j)^(mu w_ij)``. SMART (Atkinson & Soria 2009):
    all pixels of all cameras at once, ``E_j <- E_j prod_i (I_i / sum_k w_ik E_k)^(mu w_ij /
    sum_i w_ij)``, evaluated in log space.

    Voxels: with ``prune`` (default) only those whose MLOS value is positive are
    reconstructed, and among them those that give weight to a zero pixel in any camera
    are zero from the start (the first MART update would zero them); without ``prune``,
    every voxel that all cameras see. Voxels outside that set are zero in the result.

    Parameters
    ----------
    images, mappings, grid
        As for :func:`mlos`.
    iterations : int >= 0
        Sweeps over all cameras.
    mu : float in (0, 2)
        Relaxation.
    smart : bool
        Simultaneous MART.
    init : "mlos" | "uniform" | array (n_z, n_y, n_x)
        Start: the MLOS volume (geometric mean of the images), 1 everywhere, or a volume.
    weights : "circle" | "gaussian"
        Voxel-pixel weight model (see the module notes); ``psf_sigma_px`` widens the
        Gaussian one.
    interpolation : "linear" | "cubic"
        Image interpolation of the MLOS pass.
    prune : bool
        MLOS and zero-pixel pruning.
    preprocess : float or None
        When given, the images are first thresholded by :func:`preprocess_images` with this
        ``k``.
    chunk : int
        Voxels per batch when computing weight footprints (bounds temporary memory).
    progress : None, bool or callable
        One step per MLOS plane (desc ``"mart: MLOS planes"``), then one per iteration
        (``"mart: iterations"``); see :mod:`mitpiv.progress`.
    return_info : bool
        Also return a dict: active voxels, weight entries and bytes, the image residual
        ``||I - W E|| / ||I||`` after each iteration, timings.

    Returns
    -------
    (n_z, n_y, n_x) float32 volume, or ``(volume, info)``
    """
    what = "smart" if smart else "mart"
    imgs, maps = _check_images(images, mappings, grid, what)
    check_iterations(what, iterations, mu)
    _check_choice(what, "interpolation", interpolation, INTERPOLATIONS)
    psf = _check_weight_options(what, weights, psf_sigma_px)
    if isinstance(init, str):
        _check_choice(what, "init", init, ("mlos", "uniform"))
    else:
        init_vol = grid.check_volume(init, "init").astype(np.float64)
        if not np.all(np.isfinite(init_vol)) or np.any(init_vol < 0):
            raise ConfigError(f"{what}: 'init' must be finite and >= 0.")
    if preprocess is not None:
        imgs = preprocess_images(imgs, k=preprocess)
    _check_coverage(maps, imgs, grid, what)
    _warn_dark(imgs, what)
    t0 = time.perf_counter()
    idx, e_mlos, uvs = _candidates(imgs, maps, grid, interpolation, prune, progress, what)
    k = kernels()
    model = weights
    mcode = CIRCLE if model == "circle" else GAUSSIAN

    def footprints(c, sel):
        """Footprints of camera c for the voxels idx[sel], in chunks (float32 storage)."""
        ids = idx[sel]
        out = [np.empty(len(ids), np.float32) for _ in range(5)]
        for s in range(0, len(ids), chunk):
            part = _footprints(maps[c], grid.centres(ids[s : s + chunk]), grid, model, psf)
            for o, p in zip(out, part, strict=True):
                o[s : s + chunk] = p
        return out

    # Zero-pixel pruning, camera by camera and chunk by chunk (footprints are not kept)
    alive = np.ones(len(idx), np.bool_)
    if prune:
        for c in range(len(maps)):
            if not np.any(imgs[c] <= 0):
                continue
            for s in range(0, len(idx), chunk):
                sl = slice(s, s + chunk)
                fp = _footprints(maps[c], grid.centres(idx[sl]), grid, model, psf)
                a = alive[sl].copy()
                k["survives"](uvs[c][sl, 0].copy(), uvs[c][sl, 1].copy(), *fp, mcode, imgs[c], a)
                alive[sl] = a
    idx = idx[alive]
    if isinstance(init, str):
        vol = e_mlos[alive].astype(np.float64) if init == "mlos" else np.ones(len(idx))
    else:
        vol = init_vol.ravel()[idx].copy()
    del e_mlos
    cams = []
    for c in range(len(maps)):
        uvs[c] = uvs[c][alive]
        cams.append(_build_weights(uvs[c], footprints(c, slice(None)), model, imgs[c].shape))
        uvs[c] = None
    t_setup = time.perf_counter() - t0
    flat = [np.ascontiguousarray(im.ravel()) for im in imgs]
    norm = math.sqrt(sum(float(f @ f) for f in flat)) or 1.0
    wsum = sum(cw.wsum for cw in cams)
    residuals, t1 = [], time.perf_counter()
    proj = [np.empty(f.size) for f in flat]
    lr = [np.empty(f.size) for f in flat] if smart else []
    for it in track(range(iterations), desc=f"{what}: iterations", progress=progress):
        if smart:
            smart_sweep(cams, flat, vol, wsum, float(mu), proj, lr)
            if return_info:
                residuals.append(_residual(cams, flat, proj, vol, k) / norm)
        else:
            for cw, f in zip(cams, flat, strict=True):
                k["mart_camera"](cw.indptr, cw.indices, cw.data, f, cw.width, cw.span, vol, float(mu))
            if return_info:
                residuals.append(_residual(cams, flat, proj, vol, k) / norm)
        log.debug("%s: iteration %d/%d, %.1f s", what, it + 1, iterations, time.perf_counter() - t1)
    log.info("%s: %d active voxels of %d candidates, setup %.1f s, %d iterations %.1f s", what, len(idx), len(alive),
             t_setup, iterations, time.perf_counter() - t1)
    out = np.zeros(grid.n_voxels, np.float32)
    out[idx] = vol
    out = out.reshape(grid.shape)
    if not return_info:
        return out
    info = {"active_voxels": int(len(idx)), "candidate_voxels": int(len(alive)), "weight_entries": int(sum(len(c.data) for c in cams)),
            "weight_bytes": int(sum(c.nbytes for c in cams)), "residuals": residuals, "setup_s": t_setup,
            "iterate_s": time.perf_counter() - t1, "row_span": [c.span for c in cams]}
    return out, info


def _residual(cams, flat, proj, vol, k) -> float:
    r = 0.0
    for cw, f, p in zip(cams, flat, proj, strict=True):
        k["project"](cw.indptr, cw.indices, cw.data, vol, p)
        r += float(np.sum((f - p) ** 2))
    return math.sqrt(r)


TOMO_METHODS = ("mlos", "mart", "smart", "sapiv")
