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

import logging
import math
import time

import numpy as np

from mitpiv._numba import numba
from mitpiv.errors import ConfigError
from mitpiv.io.arrays import stack_output
from mitpiv.lightfield.decode import LightField
from mitpiv.lightfield.geometry import alpha_from_z, z_from_alpha
from mitpiv.progress import Progress, bar, track

__all__ = ["refocus", "focal_stack", "refocus_volume", "grid_steps", "METHODS"]

log = logging.getLogger(__name__)

METHODS = ("additive", "multiplicative")
_EPS = 1e-6  # grid units: samples this close outside the border count as on it


_KERNELS = {}


def _kernels():
    if _KERNELS:
        return _KERNELS
    # helpers called by other kernels: module globals, not closure cells (see mitpiv._numba)
    global on_grid, cell, nodes, bilinear, accumulate, result
    nb = numba()

    @nb.njit(inline="always", cache=True)
    def on_grid(x, n):
        """x snapped onto [0, n-1] when it is within rounding of the border; NaN outside."""
        if -_EPS < x < 0.0 or n - 1 < x < n - 1 + _EPS:
            x = min(max(x, 0.0), n - 1.0)
        return x if 0.0 <= x <= n - 1 else math.nan

    @nb.njit(inline="always", cache=True)
    def cell(x, n):
        """Lower node, fraction and upper node of the linear interpolation at x."""
        x0 = min(int(math.floor(x)), n - 2) if n > 1 else 0
        return x0, x - x0, min(x0 + 1, n - 1)

    @nb.njit(inline="always", cache=True)
    def nodes(x, n, nearest):
        """:func:`cell` of the sample at x on a grid of n nodes (rounded to the nearest node
        when ``nearest``); lower node -1 when it falls outside the grid."""
        x = on_grid(x, n)
        if math.isnan(x):
            return -1, 0.0, -1
        if nearest:
            x = math.floor(x + 0.5)
        return cell(x, n)

    @nb.njit(inline="always", cache=True)
    def bilinear(img, y0, fy, y1, x0, fx, x1):
        return (1.0 - fy) * ((1.0 - fx) * img[y0, x0] + fx * img[y0, x1]) + fy * ((1.0 - fx) * img[y1, x0] + fx * img[y1, x1])

    @nb.njit(inline="always", cache=True)
    def accumulate(acc, wacc, dark, wt, val, mult):
        """A view's sample ``val`` of weight ``wt`` added to an output point's sums: the value
        (additive) or its log (multiplicative, where a dark sample darkens the point)."""
        if not mult:
            acc += wt * val
        elif val > 0.0:
            acc += wt * math.log(val)
        else:
            dark = True
        return acc, wacc + wt, dark

    @nb.njit(inline="always", cache=True)
    def result(acc, wacc, dark, wmin, mult):
        if wacc <= 0.0 or wacc < wmin or (mult and dark):
            return 0.0
        return math.exp(acc / wacc) if mult else acc / wacc

    @nb.njit(parallel=True, fastmath=False, cache=True)
    def plane(views, w, base_s, base_t, sh_u, sh_v, mult, nearest, wmin, out):
        nv, nu, nt, ns = views.shape
        for ti in nb.prange(base_t.shape[0]):
            m = base_s.shape[0]
            acc = np.zeros(m)
            wacc = np.zeros(m)
            dark = np.zeros(m, np.bool_)
            for iv in range(nv):
                y0, fy, y1 = nodes(base_t[ti] + sh_v[iv], nt, nearest)
                if y0 < 0:
                    continue
                for iu in range(nu):
                    wt = w[iv, iu]
                    if wt <= 0.0:
                        continue
                    img = views[iv, iu]
                    for si in range(m):
                        x0, fx, x1 = nodes(base_s[si] + sh_u[iu], ns, nearest)
                        if x0 < 0:
                            continue
                        val = bilinear(img, y0, fy, y1, x0, fx, x1)
                        acc[si], wacc[si], dark[si] = accumulate(acc[si], wacc[si], dark[si], wt, val, mult)
            for si in range(m):
                out[ti, si] = result(acc[si], wacc[si], dark[si], wmin, mult)

    @nb.njit(parallel=True, fastmath=False, cache=True)
    def points(views, w, bs, bt, gs, gt, au, av, mult, wmin, out):
        """Per output point (flattened): position (bs, bt) + (gs au[iu], gt av[iv]) in grid units."""
        nv, nu, nt, ns = views.shape
        for k in nb.prange(bs.shape[0]):
            acc = 0.0
            wacc = 0.0
            dark = False
            for iv in range(nv):
                y = on_grid(bt[k] + gt[k] * av[iv], nt)
                if math.isnan(y):
                    continue
                y0, fy, y1 = cell(y, nt)
                for iu in range(nu):
                    wt = w[iv, iu]
                    if wt <= 0.0:
                        continue
                    x = on_grid(bs[k] + gs[k] * au[iu], ns)
                    if math.isnan(x):
                        continue
                    x0, fx, x1 = cell(x, ns)
                    val = bilinear(views[iv, iu], y0, fy, y1, x0, fx, x1)
                    acc, wacc, dark = accumulate(acc, wacc, dark, wt, val, mult)
            out[k] = result(acc, wacc, dark, wmin, mult)

    @nb.njit(cache=True)
    def axis_table(base, shifts, n, nearest, lo, frac, hi):
        """Interpolation table of one axis for a set of planes: for plane p, view a and
        output index i, the lower node, fraction and upper node of the sample at
        ``base[i] + shifts[p, a]`` (lo = -1 where it falls outside), exactly as
        :func:`plane` computes them per sample."""
        for p in range(shifts.shape[0]):
            for a in range(shifts.shape[1]):
                for i in range(base.shape[0]):
                    x0, fx, x1 = nodes(base[i] + shifts[p, a], n, nearest)
                    lo[p, a, i] = x0
                    if x0 < 0:
                        continue
                    frac[p, a, i] = fx
                    hi[p, a, i] = x1

    @nb.njit(parallel=True, fastmath=False, cache=True)
    def planes(views, w, ty0, tfy, ty1, tx0, tfx, tx1, mult, wmin, out):
        """Several planes of :func:`plane` at once, parallel over (plane, output row), from
        the precomputed per-plane interpolation tables of :func:`axis_table` (same
        arithmetic per sample, so the same result)."""
        nv, nu, nt, ns = views.shape
        npl = out.shape[0]
        for pt in nb.prange(npl * nt):
            p = pt // nt
            ti = pt - p * nt
            acc = np.zeros(ns)
            wacc = np.zeros(ns)
            dark = np.zeros(ns, np.bool_)
            for iv in range(nv):
                y0 = ty0[p, iv, ti]
                if y0 < 0:
                    continue
                fy = tfy[p, iv, ti]
                y1 = ty1[p, iv, ti]
                for iu in range(nu):
                    wt = w[iv, iu]
                    if wt <= 0.0:
                        continue
                    r0 = views[iv, iu, y0]
                    r1 = views[iv, iu, y1]
                    x0s = tx0[p, iu]
                    fxs = tfx[p, iu]
                    x1s = tx1[p, iu]
                    for si in range(ns):
                        x0 = x0s[si]
                        if x0 < 0:
                            continue
                        fx = fxs[si]
                        x1 = x1s[si]
                        val = (1.0 - fy) * ((1.0 - fx) * r0[x0] + fx * r0[x1]) + fy * ((1.0 - fx) * r1[x0] + fx * r1[x1])
                        acc[si], wacc[si], dark[si] = accumulate(acc[si], wacc[si], dark[si], wt, val, mult)
            for si in range(ns):
                out[p, ti, si] = result(acc[si], wacc[si], dark[si], wmin, mult)

    _KERNELS.update(plane=plane, points=points, axis_table=axis_table, planes=planes)
    return _KERNELS


def _check_stack_size(what: str, n_planes: int, plane_shape, n_views: int, out, *, cap: bool) -> None:
    """Refuse a stack before anything is allocated or written: more than
    :data:`~mitpiv.costs.MAX_PLANES` planes (``cap``), more memory than is available (in
    memory) or more disk than is free beside ``out`` (streamed); the estimate is logged
    (debug: the CLI logs its own)."""
    from pathlib import Path

    from mitpiv import costs

    px = math.prod(plane_shape)
    cost = costs.focal_stack_cost(n_planes, plane_shape, n_samples_per_plane=float(px * n_views),
                                  streamed=out is not None)
    if cap and n_planes > costs.MAX_PLANES:
        raise ConfigError(f"{what}: z_mm has {costs._count(n_planes)} planes, more than the {costs.MAX_PLANES} a focal "
                          f"stack may have ({cost}); a light field resolves depth in tens to a few thousand planes: "
                          f"give fewer planes.")
    label = f"{what}: z_mm of {costs._count(n_planes)} planes"
    if out is None:
        costs.check_memory(cost, what=label, fix="give fewer planes, or give out='stack.npy' to stream it to disk",
                           quiet=True)
    else:
        costs.check_memory(cost, what=label, fix="give fewer planes", quiet=True)
        costs.check_disk(cost, Path(out).parent, what=label, fix="give fewer planes, or write 'out' to a larger disk")


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


def grid_steps(lf: LightField) -> tuple[float, float]:
    """Spacing ``(ds, dt)`` [sensor px] of a light field's spatial grid along s and t (1 where
    an axis has one sample): refocused-image index ``(i, j)`` sits at sensor pixel
    ``(lf.s_px[0] + i ds, lf.t_px[0] + j dt)``."""
    ds = lf.s_px[1] - lf.s_px[0] if len(lf.s_px) > 1 else 1.0
    dt = lf.t_px[1] - lf.t_px[0] if len(lf.t_px) > 1 else 1.0
    return ds, dt


_grid_steps = grid_steps  # deprecated private name


def _plane_geometry(lf: LightField, alpha: float, magnification: str, z_mm: float | None):
    """Grid-unit positions (base_s, base_t) and per-view shifts (sh_u, sh_v) of one plane."""
    if not (np.isfinite(alpha) and alpha > 0):
        raise ConfigError(f"refocus: 'alpha' must be finite and > 0, got {alpha!r}.")
    ds, dt = grid_steps(lf)
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
                progress: Progress = None) -> np.ndarray:
    """Refocused images at depths ``z_mm`` from the focal plane (positive = farther).

    Parameters
    ----------
    lf : LightField
        Must carry its optics (alpha from z by the thin-lens equation).
    z_mm : sequence of float
    out : path, optional
        Stream the planes into this ``.npy`` file (memory-mapped; the stack never has to
        fit in memory) and return the memory map. Stacks over 2 GiB require it.
    progress : None, bool or callable
        One step per plane (desc ``"focal stack: planes"``); see :mod:`mitpiv.progress`.

    Returns
    -------
    (n_z, n_t, n_s) float32 array (or a memory map of ``out``)
    """
    _check_method(method)
    o = lf._need_optics("focal_stack")
    z = np.atleast_1d(np.asarray(z_mm, dtype=np.float64))
    if z.ndim != 1 or len(z) == 0:
        raise ConfigError(f"focal_stack: 'z_mm' must be a non-empty 1D sequence, got shape {z.shape}.")
    _check_stack_size("focal_stack", len(z), (len(lf.t_px), len(lf.s_px)), lf.data.shape[0] * lf.data.shape[1], out,
                      cap=True)
    alphas = alpha_from_z(z, focal_length_mm=o.focal_length_mm, magnification=o.magnification)
    w = _weights(lf, weights)
    shape = (len(z), len(lf.t_px), len(lf.s_px))
    k = _kernels()
    nearest = interpolation == "nearest"
    wmin = _wmin(w, min_view_fraction)
    nv, nu, nt, ns = lf.data.shape
    t0 = time.perf_counter()
    with stack_output(shape, out, "focal_stack") as stack, \
            bar(len(z), desc="focal stack: planes", progress=progress, unit="plane") as pbar:
        # planes in blocks: the geometry and the interpolation tables of a block are
        # computed once, then one compiled call fills the block in parallel over
        # (plane, row)
        block = max(1, min(len(z), 16))
        for b0 in range(0, len(z), block):
            geo = [_plane_geometry(lf, float(ak), magnification, float(zk))
                   for zk, ak in zip(z[b0:b0 + block], alphas[b0:b0 + block], strict=True)]
            npl = len(geo)
            tabs = []
            for ax, n_out, n_grid, shifts in ((0, nt, nt, [g[3] for g in geo]), (1, ns, ns, [g[2] for g in geo])):
                lo = np.empty((npl, len(shifts[0]), n_out), np.int64)
                fr = np.zeros((npl, len(shifts[0]), n_out))
                hi = np.zeros((npl, len(shifts[0]), n_out), np.int64)
                for p, g in enumerate(geo):  # the base positions can differ per plane (constant magnification)
                    k["axis_table"](np.ascontiguousarray(g[1 - ax]), np.ascontiguousarray(shifts[p])[None], n_grid,
                                    nearest, lo[p:p + 1], fr[p:p + 1], hi[p:p + 1])
                tabs.append((lo, fr, hi))
            res = stack[b0:b0 + npl] if out is None else np.empty((npl, nt, ns), np.float32)
            k["planes"](lf.data, w, *tabs[0], *tabs[1], method == "multiplicative", wmin, res)
            if out is not None:
                stack[b0:b0 + npl] = res
            pbar.update(npl)
        el = time.perf_counter() - t0
        log.debug("focal stack: %d planes in %.1f s, %.1f ms/plane", len(z), el, el / len(z) * 1e3)
        result = stack if out is None else None
    return result if out is None else np.load(out, mmap_mode="r")


def refocus_volume(lf: LightField, x_mm, y_mm, z_mm, *, method: str = "additive", weights=None,
                   min_view_fraction: float = 0.5, out=None, progress: Progress = None) -> np.ndarray:
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
    # a voxel grid's planes are not capped by MAX_PLANES: its memory (or disk) bounds it
    _check_stack_size("refocus_volume", len(zs), (len(ys), len(xs)), lf.data.shape[0] * lf.data.shape[1], out,
                      cap=False)
    w = _weights(lf, weights)
    shape = (len(zs), len(ys), len(xs))
    ds, dt = grid_steps(lf)
    pp = o.pixel_pitch_um * 1e-3
    si, f = o.image_distance_mm, o.focal_length_mm
    a = lf.aperture_mm
    cx, cy = o.resolution[0] / 2.0, o.resolution[1] / 2.0
    sc = o.image_scale / pp  # MLA-plane mm -> lattice-image px
    kern = _kernels()["points"]
    yy, xx = np.meshgrid(ys, xs, indexing="ij")
    with stack_output(shape, out, "refocus_volume") as stack:
        for k, zw in enumerate(track(zs, desc="refocus_volume: planes", progress=progress, unit="plane")):
            loc = o.world_to_local(np.stack([xx, yy, np.full_like(xx, zw)], axis=-1).reshape(-1, 3))
            if np.any(loc[:, 2] <= f):
                raise ConfigError(f"refocus_volume: voxels at z = {zw} mm lie within the focal length of the main lens "
                                  f"(or behind the camera); move the grid in front of the camera.")
            gamma = 1.0 - si * (loc[:, 2] - f) / (f * loc[:, 2])  # 1 - s_i / s_i'
            bs = (-loc[:, 0] * si / loc[:, 2] * sc + cx - lf.s_px[0]) / ds  # chief ray on the MLA, grid units
            bt = (-loc[:, 1] * si / loc[:, 2] * sc + cy - lf.t_px[0]) / dt
            res = np.empty(len(bs), np.float32)
            kern(lf.data, w, bs, bt, gamma * sc / ds, gamma * sc / dt, a, a, method == "multiplicative",
                 _wmin(w, min_view_fraction), res)
            stack[k] = res.reshape(len(ys), len(xs))
        result = stack if out is None else None
    return result if out is None else np.load(out, mmap_mode="r")


def stack_depth(camera, points_world) -> np.ndarray:
    """Depth from the focal plane (+ farther, the focal-stack convention) of world points."""
    return camera.world_to_local(points_world)[..., 2] - camera.focus_distance_mm


def stack_pixels(lf, u_index, v_index):
    """Refocused-image indices (column, row; pixel centres at integers) -> sensor pixels of
    the lenslet lattice, the coordinates a :class:`Dewarp` is fitted in."""
    ds, dt = grid_steps(lf)
    return lf.s_px[0] + np.asarray(u_index) * ds, lf.t_px[0] + np.asarray(v_index) * dt
