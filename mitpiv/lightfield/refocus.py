"""Refocusing a light field: additive (shift-and-add) and multiplicative, focal stacks,
and direct refocusing onto a world voxel grid.

For a view through aperture point ``a`` and an output point whose chief ray meets the MLA
plane at ``X`` (pinhole projection through the lens centre), the ray from ``a`` through
the point's image meets the MLA at ``X + (1 - 1/alpha) a`` (Ng 2005, exact for the thin
lens). ``alpha = s_i'/s_i`` of the refocus plane; a world point at local ``(x, y, z)`` has
``X = -(x, y) s_i / z`` and ``alpha = s_i' / s_i`` of its own image distance.

* additive: ``E = sum_w w L_a(.) / sum_w w`` over the views with weight ``w > 0``;
* multiplicative (multi-plenoptic PIV): ``E = (prod_a L_a(.)^w_a)^(1 / sum w)``, weights
  ``w`` from the white image, so a point is bright only where every view sees light.

Samples falling outside the light field are left out of both (the weight sum counts only
the views that land inside); an output point that fewer than ``min_view_fraction`` of the
total view weight reaches (the borders of a refocused plane) is set to zero rather than
estimated from a few views. The kernels run in parallel over output rows (Numba).
"""

from __future__ import annotations

import math
import os
import sys
import time
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError
from mitpiv.lightfield.decode import LightField
from mitpiv.lightfield.geometry import alpha_from_z, z_from_alpha

__all__ = ["refocus", "focal_stack", "refocus_volume", "METHODS"]

METHODS = ("additive", "multiplicative")
_MAX_IN_MEMORY = 2 * 1024**3  # bytes: larger stacks must stream to a file
_EPS = 1e-6  # grid units: samples this close outside the border count as on it


def _numba():
    os.environ.setdefault("NUMBA_CACHE_DIR", str(Path.home() / ".cache" / "mitpiv" / "numba"))
    import numba

    return numba


_KERNELS = {}


def _kernels():
    if _KERNELS:
        return _KERNELS
    nb = _numba()

    @nb.njit(parallel=True, fastmath=False, cache=True)
    def plane(views, w, base_s, base_t, sh_u, sh_v, mult, nearest, wmin, out):
        nv, nu, nt, ns = views.shape
        for ti in nb.prange(base_t.shape[0]):
            m = base_s.shape[0]
            acc = np.zeros(m)
            wacc = np.zeros(m)
            dark = np.zeros(m, np.bool_)
            for iv in range(nv):
                y = base_t[ti] + sh_v[iv]
                if -_EPS < y < 0.0 or nt - 1 < y < nt - 1 + _EPS:  # rounding at the border
                    y = min(max(y, 0.0), nt - 1.0)
                if y < 0.0 or y > nt - 1:
                    continue
                if nearest:
                    y = math.floor(y + 0.5)
                y0 = min(int(math.floor(y)), nt - 2) if nt > 1 else 0
                fy = y - y0
                for iu in range(nu):
                    wt = w[iv, iu]
                    if wt <= 0.0:
                        continue
                    for si in range(m):
                        x = base_s[si] + sh_u[iu]
                        if -_EPS < x < 0.0 or ns - 1 < x < ns - 1 + _EPS:
                            x = min(max(x, 0.0), ns - 1.0)
                        if x < 0.0 or x > ns - 1:
                            continue
                        if nearest:
                            x = math.floor(x + 0.5)
                        x0 = min(int(math.floor(x)), ns - 2) if ns > 1 else 0
                        fx = x - x0
                        val = (1.0 - fy) * ((1.0 - fx) * views[iv, iu, y0, x0] + fx * views[iv, iu, y0, min(x0 + 1, ns - 1)]) \
                            + fy * ((1.0 - fx) * views[iv, iu, min(y0 + 1, nt - 1), x0]
                                    + fx * views[iv, iu, min(y0 + 1, nt - 1), min(x0 + 1, ns - 1)])
                        if mult:
                            if val > 0.0:
                                acc[si] += wt * math.log(val)
                            else:
                                dark[si] = True
                        else:
                            acc[si] += wt * val
                        wacc[si] += wt
            for si in range(m):
                if wacc[si] <= 0.0 or wacc[si] < wmin or (mult and dark[si]):
                    out[ti, si] = 0.0
                elif mult:
                    out[ti, si] = math.exp(acc[si] / wacc[si])
                else:
                    out[ti, si] = acc[si] / wacc[si]

    @nb.njit(parallel=True, fastmath=False, cache=True)
    def points(views, w, bs, bt, gs, gt, au, av, mult, wmin, out):
        """Per output point (flattened): position (bs, bt) + (gs au[iu], gt av[iv]) in grid units."""
        nv, nu, nt, ns = views.shape
        for k in nb.prange(bs.shape[0]):
            acc = 0.0
            wacc = 0.0
            dark = False
            for iv in range(nv):
                y = bt[k] + gt[k] * av[iv]
                if -_EPS < y < 0.0 or nt - 1 < y < nt - 1 + _EPS:
                    y = min(max(y, 0.0), nt - 1.0)
                if y < 0.0 or y > nt - 1:
                    continue
                y0 = min(int(math.floor(y)), nt - 2) if nt > 1 else 0
                fy = y - y0
                y1 = min(y0 + 1, nt - 1)
                for iu in range(nu):
                    wt = w[iv, iu]
                    if wt <= 0.0:
                        continue
                    x = bs[k] + gs[k] * au[iu]
                    if -_EPS < x < 0.0 or ns - 1 < x < ns - 1 + _EPS:
                        x = min(max(x, 0.0), ns - 1.0)
                    if x < 0.0 or x > ns - 1:
                        continue
                    x0 = min(int(math.floor(x)), ns - 2) if ns > 1 else 0
                    fx = x - x0
                    x1 = min(x0 + 1, ns - 1)
                    val = (1.0 - fy) * ((1.0 - fx) * views[iv, iu, y0, x0] + fx * views[iv, iu, y0, x1]) \
                        + fy * ((1.0 - fx) * views[iv, iu, y1, x0] + fx * views[iv, iu, y1, x1])
                    if mult:
                        if val > 0.0:
                            acc += wt * math.log(val)
                        else:
                            dark = True
                    else:
                        acc += wt * val
                    wacc += wt
            if wacc <= 0.0 or wacc < wmin or (mult and dark):
                out[k] = 0.0
            elif mult:
                out[k] = math.exp(acc / wacc)
            else:
                out[k] = acc / wacc

    _KERNELS.update(plane=plane, points=points)
    return _KERNELS


def _check_method(method):
    if method not in METHODS:
        raise ConfigError(f"refocus: 'method' must be one of {METHODS}, got {method!r}.")


def _weights(lf: LightField, weights):
    w = lf.view_weights if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != lf.data.shape[:2]:
        raise ConfigError(f"refocus: 'weights' must have shape {lf.data.shape[:2]} (n_v, n_u), got {w.shape}.")
    if not np.all(np.isfinite(w)) or np.any(w < 0) or not np.any(w > 0):
        raise ConfigError("refocus: 'weights' must be finite, >= 0 and not all zero.")
    return np.ascontiguousarray(w)


def _wmin(w, fraction) -> float:
    if not 0.0 <= fraction <= 1.0:
        raise ConfigError(f"refocus: 'min_view_fraction' must lie in [0, 1], got {fraction!r}.")
    return float(fraction * w.sum() * (1 - 1e-9))


def _plane_geometry(lf: LightField, alpha: float, magnification: str, z_mm: float | None):
    """Grid-unit positions (base_s, base_t) and per-view shifts (sh_u, sh_v) of one plane."""
    if not (np.isfinite(alpha) and alpha > 0):
        raise ConfigError(f"refocus: 'alpha' must be finite and > 0, got {alpha!r}.")
    ds = lf.s_px[1] - lf.s_px[0] if len(lf.s_px) > 1 else 1.0
    dt = lf.t_px[1] - lf.t_px[0] if len(lf.t_px) > 1 else 1.0
    gamma = 1.0 - 1.0 / alpha
    kappa = 1.0
    if magnification == "constant":
        o = lf._need_optics("constant-magnification refocusing")
        if z_mm is None:
            z_mm = z_from_alpha(alpha, focal_length_mm=o.focal_length_mm, magnification=o.magnification)
        kappa = o.focus_distance_mm / (o.focus_distance_mm + z_mm)
    elif magnification != "natural":
        raise ConfigError(f"refocus: 'magnification' must be 'natural' or 'constant', got {magnification!r}.")
    # Shift of view a on the MLA plane: gamma a (mm) = gamma * (-du p s_i / g) = gamma * du * (-s_i/g) px
    # of the sensor, i.e. gamma * du * (-s_i/g) / (1 + g/s_i)-scaled lattice units (px of the grid).
    o = lf._need_optics("refocus")  # s_i / g converts pixel offsets to aperture points
    k = -o.image_distance_mm / o.gap_mm * o.image_scale  # aperture offset in lattice-image pixels per du
    cx, cy = o.resolution[0] / 2.0, o.resolution[1] / 2.0  # constant magnification scales about the axis
    base_s = ((cx + kappa * (lf.s_px - cx)) - lf.s_px[0]) / ds
    base_t = ((cy + kappa * (lf.t_px - cy)) - lf.t_px[0]) / dt
    sh_u = gamma * k * lf.du_px / ds
    sh_v = gamma * k * lf.du_px / dt
    return base_s, base_t, sh_u, sh_v


def refocus(lf: LightField, alpha: float, *, method: str = "additive", magnification: str = "natural",
            weights=None, interpolation: str = "linear", min_view_fraction: float = 0.5) -> np.ndarray:
    """Refocus onto the plane ``alpha = s_i'/s_i`` (1: the MLA plane / focal plane).

    Parameters
    ----------
    lf : LightField
    alpha : float
    method : "additive" | "multiplicative"
    magnification : "natural" | "constant"
        natural: Ng's refocusing, output samples on the chief rays of the lenslet grid
        (object-space sampling grows with distance, as in a photograph); constant: every
        plane sampled on the object-space grid of the focal plane (needs the optics).
    weights : (n_v, n_u), optional
        View weights (default ``lf.view_weights``).
    interpolation : "linear" | "nearest"
        Resampling of the sub-aperture images.
    min_view_fraction : float
        Output points reached by less than this fraction of the view weight are zero.

    Returns
    -------
    (n_t, n_s) float32 image
    """
    _check_method(method)
    if interpolation not in ("linear", "nearest"):
        raise ConfigError(f"refocus: 'interpolation' must be 'linear' or 'nearest', got {interpolation!r}.")
    w = _weights(lf, weights)
    out = np.empty((len(lf.t_px), len(lf.s_px)), np.float32)
    base_s, base_t, sh_u, sh_v = _plane_geometry(lf, float(alpha), magnification, None)
    _kernels()["plane"](lf.data, w, base_s, base_t, sh_u, sh_v, method == "multiplicative", interpolation == "nearest",
                        _wmin(w, min_view_fraction), out)
    return out


def focal_stack(lf: LightField, z_mm, *, method: str = "additive", magnification: str = "natural", weights=None,
                interpolation: str = "linear", min_view_fraction: float = 0.5, out=None,
                progress: bool = False) -> np.ndarray:
    """Refocused images at depths ``z_mm`` from the focal plane (positive = farther).

    Parameters
    ----------
    lf : LightField
        Must carry its optics (alpha from z by the thin-lens equation).
    z_mm : sequence of float
    out : path, optional
        Stream the planes into this ``.npy`` file (memory-mapped; the stack never has to
        fit in memory) and return the memory map. Stacks over 2 GiB require it.
    progress : bool
        Print a progress line per 5 % of the planes to stderr.

    Returns
    -------
    (n_z, n_t, n_s) float32 array (or a memory map of ``out``)
    """
    _check_method(method)
    o = lf._need_optics("focal_stack")
    z = np.atleast_1d(np.asarray(z_mm, dtype=np.float64))
    if z.ndim != 1 or len(z) == 0:
        raise ConfigError(f"focal_stack: 'z_mm' must be a non-empty 1D sequence, got shape {z.shape}.")
    alphas = alpha_from_z(z, focal_length_mm=o.focal_length_mm, magnification=o.magnification)
    w = _weights(lf, weights)
    shape = (len(z), len(lf.t_px), len(lf.s_px))
    nbytes = 4 * math.prod(shape)
    if out is None and nbytes > _MAX_IN_MEMORY:
        raise ConfigError(f"focal_stack: the stack needs {nbytes / 1024**3:.1f} GiB; give out='stack.npy' to stream it to disk.")
    if out is not None:
        from mitpiv.io.atomic import atomic_path

        path = Path(out)
        if path.suffix != ".npy":
            raise ConfigError(f"focal_stack: 'out' must be a .npy file, got {str(path)!r}.")
        ctx = atomic_path(path, suffix=".npy")
        tmp = ctx.__enter__()
        stack = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.float32, shape=shape)
    else:
        stack = np.empty(shape, np.float32)
    kern = _kernels()["plane"]
    t0 = time.perf_counter()
    step = max(len(z) // 20, 1)
    try:
        for k, (zk, ak) in enumerate(zip(z, alphas, strict=True)):
            base_s, base_t, sh_u, sh_v = _plane_geometry(lf, float(ak), magnification, float(zk))
            kern(lf.data, w, base_s, base_t, sh_u, sh_v, method == "multiplicative", interpolation == "nearest",
                 _wmin(w, min_view_fraction), stack[k])
            if progress and ((k + 1) % step == 0 or k + 1 == len(z)):
                el = time.perf_counter() - t0
                print(f"focal stack: {k + 1}/{len(z)} planes, {el:.1f} s, {el / (k + 1) * 1e3:.1f} ms/plane", file=sys.stderr, flush=True)
    except BaseException:
        if out is not None:
            del stack
            ctx.__exit__(*sys.exc_info())
        raise
    if out is not None:
        stack.flush()
        del stack
        ctx.__exit__(None, None, None)
        return np.load(out, mmap_mode="r")
    return stack


def refocus_volume(lf: LightField, x_mm, y_mm, z_mm, *, method: str = "additive", weights=None,
                   min_view_fraction: float = 0.5, out=None, progress: bool = False) -> np.ndarray:
    """Refocus directly onto a world voxel grid (any camera pose).

    For each voxel centre ``(x, y, z)`` (world mm) and each view, the ray from the view's
    aperture point through the voxel's thin-lens image is followed to the MLA plane and
    the sub-aperture image sampled there.

    Returns
    -------
    (n_z, n_y, n_x) float32 volume (or a memory map of ``out``, a ``.npy`` path)
    """
    _check_method(method)
    o = lf._need_optics("refocus_volume")
    xs, ys, zs = (np.atleast_1d(np.asarray(a, dtype=np.float64)) for a in (x_mm, y_mm, z_mm))
    w = _weights(lf, weights)
    shape = (len(zs), len(ys), len(xs))
    if out is not None:
        stack = np.lib.format.open_memmap(Path(out), mode="w+", dtype=np.float32, shape=shape)
    else:
        if 4 * math.prod(shape) > _MAX_IN_MEMORY:
            raise ConfigError("refocus_volume: the volume exceeds 2 GiB; give out='volume.npy'.")
        stack = np.empty(shape, np.float32)
    ds = lf.s_px[1] - lf.s_px[0] if len(lf.s_px) > 1 else 1.0
    dt = lf.t_px[1] - lf.t_px[0] if len(lf.t_px) > 1 else 1.0
    pp = o.pixel_pitch_um * 1e-3
    si, f = o.image_distance_mm, o.focal_length_mm
    a = lf.aperture_mm
    cx, cy = o.resolution[0] / 2.0, o.resolution[1] / 2.0
    kern = _kernels()["points"]
    yy, xx = np.meshgrid(ys, xs, indexing="ij")
    for k, zw in enumerate(zs):
        loc = o.world_to_local(np.stack([xx, yy, np.full_like(xx, zw)], axis=-1).reshape(-1, 3))
        if np.any(loc[:, 2] <= f):
            raise ConfigError(f"refocus_volume: voxels at z = {zw} mm lie within the focal length of the main lens "
                              f"(or behind the camera); move the grid in front of the camera.")
        sip = f * loc[:, 2] / (loc[:, 2] - f)
        gamma = 1.0 - si / sip
        bx = -loc[:, 0] * si / loc[:, 2]  # MLA-plane point of the chief ray (sensor frame mm)
        by = -loc[:, 1] * si / loc[:, 2]
        # MLA mm -> lattice-image px: * image_scale / pp + centre
        sc = o.image_scale / pp
        bs = (bx * sc + cx - lf.s_px[0]) / ds
        bt = (by * sc + cy - lf.t_px[0]) / dt
        res = np.empty(len(bs), np.float32)
        kern(lf.data, w, bs, bt, gamma * sc / ds, gamma * sc / dt, a, a, method == "multiplicative",
             _wmin(w, min_view_fraction), res)
        stack[k] = res.reshape(len(ys), len(xs))
        if progress:
            print(f"refocus_volume: plane {k + 1}/{len(zs)}", file=sys.stderr, flush=True)
    if out is not None:
        stack.flush()
    return stack
