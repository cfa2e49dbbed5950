"""Iterative particle reconstruction (IPR, Wieneke 2013): 2D peaks, triangulation across
cameras, shaking against the residual images with the OTF, ghost removal, outer loops
with reduced camera sets.

Steps
-----
1. :func:`detect_peaks`: local maxima (3 x 3) above a threshold, sub-pixel position by a
   3-point Gaussian fit per axis (:func:`mitpiv.analysis.particles.gauss3_offset`).
2. :func:`triangulate`: for each peak of the first camera of a set, its line of sight
   (``pixel_to_ray``) is clipped to the measurement box and sampled in 3D; the samples
   project onto the epipolar curve in the second camera, and peaks there within
   ``tolerance_px`` (plus half a sample step) pair up. Each pair gives a 3D candidate,
   which is projected into the other cameras to collect their peaks within the tolerance
   (every combination is kept); the final position minimises the reprojection error by
   Gauss-Newton on ``project`` / ``jacobian`` and candidates whose largest reprojection
   error exceeds ``tolerance_px`` are dropped. Distortion is handled through the camera's
   own ``project``; only the first guess uses the rays.
3. :func:`shake`: each particle's position and intensity are moved to reduce the squared
   difference between its augmented residual (``I - the images of all other particles``)
   and its own image, summed over its stamp in every camera. Wieneke shakes each
   coordinate by ``-s, 0, +s`` and fits a parabola; here one damped Gauss-Newton step per
   iteration does the same job with the analytic derivatives of the OTF and of the
   camera (``jacobian``), each coordinate step limited to the shake amplitude ``s``
   (ten times fewer image evaluations, the same minimum). The particles are shaken one
   after another (a compiled Gauss-Seidel pass, :mod:`mitpiv.tracking._kernels`) with the
   residual updated after each, so overlapping particles share their light.
4. :func:`ipr`: outer loops of detection on the residual images, triangulation (all
   cameras first, then every set with one camera left out), shaking and removal of weak
   particles (intensity below ``min_intensity`` times the median) and duplicates. A
   candidate from a reduced set must be hidden in the left-out camera (its raw image is
   above the threshold there) or fall off that camera's sensor; else it is a ghost.
5. Ghost screens after each loop's shake (issue 51; Wieneke 2013, Jahn et al. 2021):
   *image support*: in every camera that sees it, a particle's own intensity must be
   supported by its augmented residual (the least-squares intensity of residual plus its
   own image on its 3 x 3 core, relative to the camera's median), else its light there
   belongs to other particles and it is a ghost; *weak particles*: below
   ``weak_intensity`` times the mean intensity of the particles established by earlier
   loops, when some camera also supports them below ``weak_support`` (a dim true particle,
   a small one of a polydisperse seeding, owns its light in every view); *camera gain*:
   the OTF's peak per camera is rescaled by the median support, so that a camera brighter
   or dimmer than the OTF says (Mie scattering differs per view; a Gaussian fitted to a
   diffraction-limited image misjudges its peak) leaves no part of every particle in its
   residual. The detection threshold takes its noise from the
   darkest quarter of the pixels (:func:`auto_threshold` ``noise="background"``): in a
   dense image the spread of all pixels is particle light. All-camera loops continue past
   ``outer_loops`` (to ``max_outer_loops``) while a loop still triangulates new candidates
   (more than ``converged`` times the particle count): each particle found frees the light
   of its neighbours, and dense frames need 10-20 loops. The literature's tight
   triangulation tolerance first (``tolerance_start``) and one candidate per 2D peak
   (``unique_peaks``) are offered but off: on rendered LPT images they lowered the yield
   (a particle placed alone takes the light of its unresolved neighbours, which then never
   show as peaks), see docs/guide.md.

Memory and time are linear in the particle count: KD-trees and sparse neighbour lists
(SciPy) do the searches, chunks of particles bound the stamp arrays, and the shake costs
one pass over each particle's windows per iteration. Hand-written because
no kept Python library offers IPR; the projector is :mod:`mitpiv.tracking.otf`.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from itertools import combinations

import numpy as np

from mitpiv.analysis.particles import gauss3_offset
from mitpiv.errors import ConfigError, check_positive
from mitpiv.progress import bar
from mitpiv.tracking.otf import OTF, project_particles

__all__ = ["IPRResult", "detect_peaks", "triangulate", "shake", "ipr", "auto_threshold", "mm_per_px"]

log = logging.getLogger(__name__)


# ---------------------------------------------------------------------- checks
def _check_images(images, cameras, what):
    if len(images) != len(cameras) or len(cameras) < 2:
        raise ConfigError(f"{what}: need one image per camera and at least 2 cameras, got {len(images)} images "
                          f"for {len(cameras)} cameras.")
    out = []
    for k, (img, cam) in enumerate(zip(images, cameras, strict=True)):
        a = np.asarray(img, dtype=np.float64)
        w, h = cam.resolution
        if a.shape != (h, w):
            raise ConfigError(f"{what}: image {k} has shape {a.shape}, camera {k} expects (H, W) = {(h, w)}.")
        if not np.all(np.isfinite(a)):
            raise ConfigError(f"{what}: image {k} holds NaN or infinite pixels; clean it (np.nan_to_num) first.")
        out.append(a)
    return out


def _check_rays(cameras, what):
    for k, cam in enumerate(cameras):
        if not hasattr(cam, "pixel_to_ray"):
            raise ConfigError(f"{what}: camera {k} ({type(cam).__name__}) has no back-projection 'pixel_to_ray'; "
                              f"triangulation works with pinhole cameras (mitpiv.physics.camera.PinholeCamera) for now.")


def mm_per_px(cameras, point_mm) -> float:
    """Mean object-space size of a pixel [mm/px] at ``point_mm`` over the cameras (from
    the camera Jacobians: the inverse of the RMS singular value)."""
    p = np.asarray(point_mm, dtype=np.float64).reshape(1, 3)
    s = [np.linalg.svd(cam.jacobian(p)[0], compute_uv=False) for cam in cameras]
    return float(1.0 / np.sqrt(np.mean(np.square(s))))


# ---------------------------------------------------------------------- peaks
def auto_threshold(image, *, noise: str = "all") -> float:
    """A detection threshold for ``image``: the larger of 5 robust noise standard
    deviations above the median and 5 % of the 99.9th percentile (the particle peaks).

    ``noise``: ``"all"``, the median and the median absolute deviation of all pixels;
    ``"background"``, the lower of that level and the one from the darkest quarter of the
    pixels taken as Gaussian noise (standard deviation ``(q25 - q5) / 0.97``, median
    ``q25 + 0.674`` of it): in a dense image the particles' own light fills the median and
    the spread of all pixels (at 0.1 particles per pixel, 5 deviations above the median
    reach most of a particle's peak); in a residual image the darkest pixels are misfit."""
    a = np.asarray(image, dtype=np.float64)
    if noise not in ("all", "background"):
        raise ConfigError(f"auto_threshold: 'noise' must be 'all' or 'background', got {noise!r}.")
    med = np.median(a)
    level = med + 5 * 1.4826 * np.median(np.abs(a - med))
    if noise == "background":
        q5, q25 = np.percentile(a, [5, 25])
        sigma = (q25 - q5) / 0.97
        # the lower of the two: a residual image (particles subtracted) has its darkest
        # pixels in the model's misfit, not in noise, and there all pixels tell better
        level = min(level, q25 + 0.674 * sigma + 5 * sigma)
    hi = np.percentile(a, 99.9)
    return float(max(level, 0.05 * hi, np.finfo(float).tiny))


def detect_peaks(image, *, threshold: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Local maxima (3 x 3 neighbourhood) above ``threshold`` with sub-pixel positions.

    Returns
    -------
    uv_px : (M, 2) peak positions [px] (pixel centres at ``i + 0.5``); offsets by a
        3-point Gaussian fit along each axis (0 at the image border).
    values : (M,) pixel values at the maxima.
    """
    from scipy.ndimage import maximum_filter

    a = np.asarray(image, dtype=np.float64)
    thr = auto_threshold(a) if threshold is None else float(threshold)
    if not np.isfinite(thr):
        raise ConfigError(f"detect_peaks: 'threshold' must be finite, got {threshold!r}.")
    mx = maximum_filter(a, size=3, mode="constant", cval=-np.inf)
    rows, cols = np.nonzero((a >= mx) & (a > thr))
    h, w = a.shape
    pad = np.pad(a, 1, mode="constant", constant_values=0.0)
    c = a[rows, cols]
    du = gauss3_offset(pad[rows + 1, cols], c, pad[rows + 1, cols + 2])
    dv = gauss3_offset(pad[rows, cols + 1], c, pad[rows + 2, cols + 1])
    du = np.where((cols == 0) | (cols == w - 1), 0.0, du)
    dv = np.where((rows == 0) | (rows == h - 1), 0.0, dv)
    return np.stack([cols + 0.5 + du, rows + 0.5 + dv], axis=1), c


# ---------------------------------------------------------------------- triangulation
def _clip_rays(o, d, lo, hi):
    """Ray parameters (t0, t1) where rays o + t d cross the box (slab method); NaN if not."""
    with np.errstate(divide="ignore", invalid="ignore"):
        inv = 1.0 / d
        ta = (lo - o) * inv
        tb = (hi - o) * inv
    tmin = np.nanmax(np.minimum(ta, tb), axis=-1)
    tmax = np.nanmin(np.maximum(ta, tb), axis=-1)
    tmin = np.maximum(tmin, 0.0)
    bad = ~(tmax > tmin)
    return np.where(bad, np.nan, tmin), np.where(bad, np.nan, tmax)


def _ls_rays(origins, dirs, mask):
    """Least-squares intersection of rays: origins (K, C, 3), dirs (K, C, 3), mask (K, C)."""
    m = mask[..., None, None].astype(np.float64)
    proj = np.eye(3) - dirs[..., :, None] * dirs[..., None, :]
    a = (m * proj).sum(axis=1)
    b = (m * proj @ origins[..., None]).sum(axis=1)[..., 0]
    a = a + 1e-12 * np.eye(3)
    return np.linalg.solve(a, b[..., None])[..., 0]


def _refine(points, cams_uv, mask, cameras, iterations=3):
    """Gauss-Newton on the reprojection error; returns points and the per-camera errors [px]."""
    x = points.copy()
    for _ in range(iterations):
        jtj = np.zeros((x.shape[0], 3, 3)) + 1e-12 * np.eye(3)
        jtr = np.zeros((x.shape[0], 3))
        for k, cam in enumerate(cameras):
            mk = mask[:, k]
            if not mk.any():
                continue
            r = cams_uv[mk, k] - cam.project(x[mk])
            jac = cam.jacobian(x[mk])
            jtj[mk] += np.einsum("nij,nik->njk", jac, jac)
            jtr[mk] += np.einsum("nij,ni->nj", jac, r)
        x = x + np.linalg.solve(jtj, jtr[..., None])[..., 0]
    err = np.full(mask.shape, np.nan)
    for k, cam in enumerate(cameras):
        mk = mask[:, k]
        if mk.any():
            err[mk, k] = np.linalg.norm(cams_uv[mk, k] - cam.project(x[mk]), axis=1)
    return x, err


def triangulate(peaks, cameras, *, tolerance_px: float, lower_mm, upper_mm, use=None,
                max_candidates: int = 5_000_000) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """3D candidates from 2D peaks by epipolar search across cameras.

    Parameters
    ----------
    peaks : sequence of (M_c, 2) peak positions [px], one per camera.
    cameras : sequence of cameras with ``project``, ``jacobian`` and ``pixel_to_ray``.
    tolerance_px : allowed triangulation (reprojection) error [px].
    lower_mm, upper_mm : measurement box [mm]; candidates outside are dropped.
    use : indices of the cameras to combine (at least 2); default all.
    max_candidates : bound on intermediate candidate pairs (a :class:`ConfigError` beyond).

    Returns
    -------
    positions_mm : (K, 3); peak_index : (K, n_cameras) index of the peak used in each
    camera (-1 where a camera is not used); error_px : (K,) largest reprojection error.
    """
    from scipy.spatial import cKDTree

    tol = check_positive("tolerance_px", tolerance_px, owner="triangulate", unit="px")
    lo = np.asarray(lower_mm, dtype=np.float64)
    hi = np.asarray(upper_mm, dtype=np.float64)
    n_cam = len(cameras)
    use = list(range(n_cam)) if use is None else [int(u) for u in use]
    if len(use) < 2 or len(set(use)) != len(use) or min(use) < 0 or max(use) >= n_cam:
        raise ConfigError(f"triangulate: 'use' must name at least 2 distinct cameras among 0..{n_cam - 1}, got {use!r}.")
    _check_rays([cameras[k] for k in use], "triangulate")
    pk = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in peaks]
    empty = (np.zeros((0, 3)), np.zeros((0, n_cam), np.int64), np.zeros(0))
    if any(pk[k].shape[0] == 0 for k in use):
        return empty
    c0, c1 = use[0], use[1]
    # line of sight of each peak of c0, clipped to the box and sampled in 3D
    o0, d0 = cameras[c0].pixel_to_ray(pk[c0])
    o0 = np.broadcast_to(o0, d0.shape)
    t0, t1 = _clip_rays(o0, d0, lo, hi)
    ok = np.isfinite(t0)
    idx0 = np.flatnonzero(ok)
    if idx0.size == 0:
        return empty
    a = o0[ok] + t0[ok, None] * d0[ok]
    b = o0[ok] + t1[ok, None] * d0[ok]
    ua, ub = cameras[c1].project(a), cameras[c1].project(b)
    length = np.linalg.norm(ub - ua, axis=1)
    step = tol
    ns = np.maximum(2, np.ceil(np.nan_to_num(length, nan=0.0) / step).astype(np.int64) + 1)
    if ns.sum() > max_candidates:
        raise ConfigError(f"triangulate: {int(ns.sum())} epipolar samples exceed max_candidates={max_candidates}; "
                          f"reduce the box or the peak count, or raise 'max_candidates'.")
    ray = np.repeat(np.arange(idx0.size), ns)
    first = np.repeat(np.cumsum(ns) - ns, ns)
    frac = (np.arange(ns.sum()) - first) / (ns[ray] - 1)
    pts = a[ray] + frac[:, None] * (b[ray] - a[ray])
    uv = cameras[c1].project(pts)
    okp = np.all(np.isfinite(uv), axis=1) & cameras[c1].in_front(pts)
    tree1 = cKDTree(pk[c1])
    sm = cKDTree(uv[okp]).sparse_distance_matrix(tree1, np.hypot(tol, step), output_type="coo_matrix")
    pair_ray = ray[okp][sm.row]
    key = np.unique(pair_ray.astype(np.int64) * pk[c1].shape[0] + sm.col)
    i0 = idx0[key // pk[c1].shape[0]]
    i1 = key % pk[c1].shape[0]
    if i0.size > max_candidates:
        raise ConfigError(f"triangulate: {i0.size} candidate pairs exceed max_candidates={max_candidates}; "
                          f"lower 'tolerance_px' or the particle density.")
    ids = np.full((i0.size, n_cam), -1, np.int64)
    ids[:, c0], ids[:, c1] = i0, i1
    rays_o = np.zeros((i0.size, n_cam, 3))
    rays_d = np.zeros((i0.size, n_cam, 3))

    def set_rays(rows, k):
        o, d = cameras[k].pixel_to_ray(pk[k][ids[rows, k]])
        rays_o[rows, k], rays_d[rows, k] = o, d

    set_rays(np.arange(i0.size), c0)
    set_rays(np.arange(i0.size), c1)
    x = _ls_rays(rays_o, rays_d, ids >= 0)
    for k in use[2:]:
        if ids.shape[0] == 0:
            return empty
        front = cameras[k].in_front(x)
        uvk = cameras[k].project(x)
        good = front & np.all(np.isfinite(uvk), axis=1)
        rows_g = np.flatnonzero(good)
        smk = cKDTree(uvk[good]).sparse_distance_matrix(cKDTree(pk[k]), tol * 1.5, output_type="coo_matrix")
        rows = rows_g[smk.row]
        if rows.size > max_candidates:
            raise ConfigError(f"triangulate: {rows.size} candidates exceed max_candidates={max_candidates}; "
                              f"lower 'tolerance_px' or the particle density.")
        ids = ids[rows]
        ids[:, k] = smk.col
        rays_o, rays_d = rays_o[rows], rays_d[rows]
        set_rays(np.arange(ids.shape[0]), k)
        x = _ls_rays(rays_o, rays_d, ids >= 0)
    if ids.shape[0] == 0:
        return empty
    mask = ids >= 0
    cams_uv = np.zeros((ids.shape[0], n_cam, 2))
    for k in use:
        cams_uv[:, k] = pk[k][ids[:, k]]
    x, err = _refine(x, cams_uv, mask, cameras)
    emax = np.nanmax(err, axis=1)
    keep = (emax <= tol) & np.all((x >= lo) & (x <= hi), axis=1)
    return x[keep], ids[keep], emax[keep]


# ---------------------------------------------------------------------- shaking
def _pass_inputs(cameras, otf, p):
    """Per-camera projections, Jacobians, visibility and OTF parameters of particles p,
    stacked (K, N, ...) for the compiled shake pass."""
    n = p.shape[0]
    k_n = len(cameras)
    uv = np.zeros((k_n, n, 2))
    jac = np.zeros((k_n, n, 2, 3))
    vis = np.zeros((k_n, n), bool)
    prm = np.zeros((4, k_n, n))
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        for k, cam in enumerate(cameras):
            u = cam.project(p)
            j = cam.jacobian(p)
            ok = cam.in_front(p) & np.all(np.isfinite(u), axis=1) & np.all(np.isfinite(j), axis=(1, 2))
            uv[k] = np.where(ok[:, None], u, 0.0)
            jac[k] = np.where(ok[:, None, None], j, 0.0)
            vis[k] = ok
            prm[:, k] = otf.params(k, p)
    return uv, jac, vis, prm


def shake(images, cameras, otf: OTF, positions_mm, intensities, *, step_mm: float, iterations: int = 6,
          fixed_intensity: bool = False) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Shake particles against the residual images (see the module notes).

    Each iteration visits the particles one after another in a random order (Wieneke's
    sequential shake, compiled: :mod:`mitpiv.tracking._kernels`): a particle takes one
    damped Gauss-Newton step of its position (and intensity) against its augmented
    residual, and the residual images are updated before the next particle, so two
    overlapping particles share their light.

    Parameters
    ----------
    images : per-camera (H, W) images; cameras : the cameras; otf : the particle image model.
    positions_mm : (N, 3) start positions [mm]; intensities : (N,) start intensities.
    step_mm : first shake amplitude (largest step per coordinate) [mm]; it shrinks by 0.6
        per iteration (floor 5 %).
    iterations : shake iterations.
    fixed_intensity : keep the intensities (only move).

    Returns
    -------
    positions_mm (N, 3), intensities (N,) (>= 0), residual images (list of (H, W)).
    """
    from mitpiv.tracking._kernels import kernels

    imgs = [np.asarray(i, dtype=np.float64) for i in images]
    p = np.array(positions_mm, dtype=np.float64).reshape(-1, 3)
    e = np.array(np.broadcast_to(np.asarray(intensities, dtype=np.float64), (p.shape[0],)))
    s0 = check_positive("step_mm", step_mm, owner="shake", unit="mm")
    r = otf.radius_px()
    if p.shape[0] and int(iterations) > 0:
        wh = np.array([[i.shape[1], i.shape[0]] for i in imgs], dtype=np.int64)
        res = np.zeros((len(imgs), int(wh[:, 1].max()), int(wh[:, 0].max())))
        for k, (img, pr) in enumerate(zip(imgs, project_particles(p, e, cameras, otf), strict=True)):
            res[k, :img.shape[0], :img.shape[1]] = img - pr
        shake_pass = kernels()["shake_pass"]
        for it in range(int(iterations)):
            s = s0 * max(0.6**it, 0.05)
            uv, jac, vis, (a, b, c, pk) = _pass_inputs(cameras, otf, p)
            order = np.random.default_rng(it).permutation(p.shape[0])
            shake_pass(res, wh, uv, jac, vis, a, b, c, pk, p, e, order, float(s), int(r), bool(fixed_intensity))
    res = [img - pr for img, pr in zip(imgs, project_particles(p, e, cameras, otf), strict=True)]
    return p, e, res


# ---------------------------------------------------------------------- IPR
@dataclass
class IPRResult:
    """Particles reconstructed by :func:`ipr`.

    positions_mm : (N, 3); intensities : (N,); residuals : per-camera residual images;
    history : per outer loop, a dict (cameras used, peaks, candidates, particles kept,
    the camera gains so far); camera_gain : (n_cameras,) the factors IPR applied to the
    OTF's peak per camera (``ipr(camera_gain=True)``; ones when off).
    """

    positions_mm: np.ndarray
    intensities: np.ndarray
    residuals: list = field(repr=False)
    history: list = field(default_factory=list)
    camera_gain: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.positions_mm.shape[0])


def _prune(p, e, lo, hi, min_intensity, dup_mm):
    """Drop weak particles, particles outside the box, and the dimmer of close pairs."""
    from scipy.spatial import cKDTree

    if p.shape[0] == 0:
        return p, e
    ref = np.median(e[e > 0]) if np.any(e > 0) else 0.0
    keep = (e > min_intensity * ref) & np.all((p >= lo) & (p <= hi), axis=1) & np.all(np.isfinite(p), axis=1)
    p, e = p[keep], e[keep]
    if p.shape[0] > 1:
        pairs = cKDTree(p).query_pairs(dup_mm, output_type="ndarray")
        if pairs.size:
            drop = np.where(e[pairs[:, 0]] >= e[pairs[:, 1]], pairs[:, 1], pairs[:, 0])
            keep = np.ones(p.shape[0], bool)
            keep[drop] = False
            p, e = p[keep], e[keep]
    return p, e


def _unique_peaks(ids, err, use):
    """Candidates that claim each 2D peak at most once: greedy by triangulation error
    (the best-matching candidate of a peak takes it; a candidate is kept when it is the
    best remaining one for every peak it uses). Vectorised rounds of that rule reach the
    sequential greedy result. Returns a boolean mask over the candidates."""
    n = ids.shape[0]
    keep = np.zeros(n, bool)
    if n == 0:
        return keep
    rank = np.empty(n, np.int64)
    rank[np.argsort(err, kind="stable")] = np.arange(n)
    active = np.ones(n, bool)
    big = np.iinfo(np.int64).max
    for _ in range(64):
        if not active.any():
            break
        win = active.copy()
        for k in use:
            best = np.full(int(ids[:, k].max()) + 1, big)
            np.minimum.at(best, ids[active, k], rank[active])
            win &= best[ids[:, k]] == rank
        keep |= win
        taken = [np.zeros(int(ids[:, k].max()) + 1, bool) for k in use]
        for t, k in zip(taken, use, strict=True):
            t[ids[win, k]] = True
        lost = np.zeros(n, bool)
        for t, k in zip(taken, use, strict=True):
            lost |= t[ids[:, k]]
        active &= ~lost
    return keep


def _support(res, cameras, otf, p, e, *, radius: int = 1):
    """Per camera, the image's support of each particle: the intensity that camera alone
    gives it (least squares of the augmented residual, the residual plus the particle's
    own image, on the particle's (2 radius + 1)^2 core) over its intensity. (K, N), NaN
    where the particle is off the camera's sensor or has no intensity."""
    from mitpiv.tracking.otf import stamps

    out = np.full((len(cameras), p.shape[0]), np.nan)
    if p.shape[0] == 0:
        return out
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        for k, cam in enumerate(cameras):
            on = np.flatnonzero(cam.visible(p) & (e > 0))
            if on.size == 0:
                continue
            a, b, c, pk = otf.params(k, p[on])
            cols, rows, g = stamps(cam.project(p[on]), a, b, c, pk, radius)
            h, w = res[k].shape
            inside = (cols >= 0) & (cols < w) & (rows >= 0) & (rows < h)
            r = np.where(inside, res[k][np.clip(rows, 0, h - 1), np.clip(cols, 0, w - 1)], 0.0)
            g = np.where(inside, g, 0.0)
            gg = (g * g).sum(axis=(1, 2))
            ok = gg > 0
            out[k, on[ok]] = 1.0 + (r * g).sum(axis=(1, 2))[ok] / (e[on[ok]] * gg[ok])
    return out


def _camera_gain(res, cameras, otf, p, e):
    """Per camera, the median support (:func:`_support`) of the particles, normalised to a
    geometric mean of 1 (cameras with no estimate: 1)."""
    s = _support(res, cameras, otf, p, e)
    g = np.ones(len(cameras))
    for k in range(len(cameras)):
        v = s[k][np.isfinite(s[k])]
        if v.size >= 10 and np.median(v) > 0:
            g[k] = np.median(v)
    g = np.clip(g, 0.25, 4.0)
    return g / np.exp(np.mean(np.log(g)))


def _screen(res, cameras, otf, p, e, *, support, weak_intensity, established, weak_support=np.inf):
    """Ghost screens of one loop (module notes): particles whose image is unsupported in
    some camera (support below ``support``) and particles weaker than ``weak_intensity``
    times the mean intensity of the established ones (those kept by earlier loops; all
    particles in the first loop) whose support in some camera is below ``weak_support``
    (a dim true particle owns its light in every view). Returns a mask."""
    keep = np.ones(p.shape[0], bool)
    if p.shape[0] == 0:
        return keep
    if support or (weak_intensity and np.isfinite(weak_support)):
        s = _support(res, cameras, otf, p, e)
        # relative to the camera's typical support: the OTF's peak per camera is fitted on a
        # wider window than the core and the particle images are not exact Gaussians
        ref = np.ones((s.shape[0], 1))
        for k in range(s.shape[0]):  # cameras: the median of those that see some particle
            v = s[k][np.isfinite(s[k])]
            if v.size and np.median(v) > 0:
                ref[k] = np.median(v)
        smin = np.nanmin(np.where(np.isfinite(s), s / ref, np.inf), axis=0)
    else:
        smin = np.full(p.shape[0], -np.inf)
    if support:
        keep &= ~(smin < support)
    if weak_intensity:
        ref_set = established if established.any() else np.ones_like(keep)
        ref = np.mean(e[ref_set & keep]) if np.any(ref_set & keep) else np.mean(e[ref_set])
        keep &= (e >= weak_intensity * ref) | ~(smin < weak_support)
    return keep


def ipr(images, cameras, otf: OTF, *, lower_mm, upper_mm, threshold=None, tolerance_px: float = 1.0,
        outer_loops: int = 4, reduced_loops: int = 1, shake_iterations: int = 3, shake_step_px: float = 0.5,
        final_iterations: int = 8, min_intensity: float = 0.1, duplicate_px: float = 1.0, initial=None,
        reduced_tolerance: float = 0.5, calibration_error_px: float | None = None, tolerance_start: float = 1.0,
        unique_peaks: bool = False, weak_intensity: float = 0.25, support: float = 0.5, camera_gain: bool = True,
        final_screen: bool = True, max_outer_loops: int = 16, converged: float = 0.02, weak_support: float = 0.8,
        progress=None) -> IPRResult:
    """Iterative particle reconstruction of one frame (Wieneke 2013).

    Parameters
    ----------
    images : per-camera (H, W) images (background subtracted), one per camera.
    cameras : cameras (the camera contract plus ``pixel_to_ray``), at least 2.
    otf : particle image model (:func:`~mitpiv.tracking.otf.calibrate_otf`).
    lower_mm, upper_mm : measurement box [mm].
    threshold : peak detection threshold (one value or one per camera); default
        :func:`auto_threshold` of each input image with the background's noise
        (``noise="background"``), kept for every loop.
    tolerance_px : allowed triangulation error [px]; must exceed the calibration's
        reprojection error.
    outer_loops : loops with all cameras; reduced_loops : further loops with every set of
        one camera fewer (for particles hidden in one view; 0 to skip; needs >= 3 cameras).
    shake_iterations, shake_step_px : shaking per loop and its first amplitude [px].
    final_iterations : a last shake of every particle from a fifth of the amplitude (lets
        overlapping particles settle).
    min_intensity : particles below this fraction of the median intensity are removed.
    duplicate_px : particles closer than this [px, object-space equivalent] merge.
    initial : optional ``(positions_mm, intensities)`` to start from (STB's predictions).
    reduced_tolerance : the reduced sets triangulate with this fraction of ``tolerance_px``
        (a set with one camera fewer admits many more ghosts: their number grows with the
        tolerance cubed for four cameras, squared for three).
    calibration_error_px : the calibration's reprojection error [px], when known; it must
        be below ``tolerance_px`` (else :class:`ConfigError`).
    tolerance_start : the first all-camera loop triangulates within this fraction of
        ``tolerance_px``; the tolerance grows linearly to ``tolerance_px`` by the last
        all-camera loop (the best-matching candidates first: ghosts rarely match tightly,
        and each true particle found first takes its light out of the residual). 1: every
        loop at ``tolerance_px``.
    unique_peaks : each 2D peak goes to at most one candidate per loop, the one with the
        smallest triangulation error (a peak left over is found again in the residual of the
        next loop when two particles share it).
    weak_intensity : after each loop's shake, particles below this fraction of the mean
        intensity of the established particles (kept by earlier loops) are removed when their
        support (see ``support``) in some camera is below ``weak_support`` (a dim true particle
        owns its light in every view; ``inf``: every weak particle) (0: off;
        ``min_intensity`` against the median still applies).
    support : after each loop's shake, a particle is removed when some camera that sees it
        supports less than this fraction of its intensity: the least-squares intensity of
        its augmented residual (residual plus its own image) on its 3 x 3 core in that
        camera, over its intensity (a ghost's light in some view belongs to other
        particles). 0: off.
    camera_gain : after each loop, rescale the OTF's peak per camera by the median
        least-squares intensity of the particles' cores in that camera over their intensity
        (geometric mean 1: the intensity scale is kept): the relative brightness of the
        cameras (Mie scattering and polarisation differ per view; a Gaussian fitted to a
        non-Gaussian particle image misjudges its peak) would otherwise leave a part of every
        particle in the residual of some cameras, where it makes peaks and ghosts.
    final_screen : apply the ``support`` and ``weak_intensity`` screens once more after
        the final shake.
    max_outer_loops, converged : after the ``outer_loops`` all-camera loops, more follow
        (up to ``max_outer_loops`` in all) while the last one triangulated more than
        ``converged`` times the particle count in new candidates: dense images need 10-20
        loops (each particle found frees the light of its neighbours), sparse ones stop at
        ``outer_loops``. ``max_outer_loops <= outer_loops``: exactly ``outer_loops``.
    progress : see :mod:`mitpiv.progress`.

    Raises
    ------
    ConfigError
        When the calibration error reaches the tolerance, or when the first loop finds at
        least 20 peaks in every camera but fewer than 5 % of them triangulate within the
        tolerance (the cameras' calibration does not fit the images).

    A camera that shows no peak at all in the frame (a dropped image) is left out.
    """
    imgs = _check_images(images, cameras, "ipr")
    if otf.n_cameras != len(cameras):
        raise ConfigError(f"ipr: the OTF has {otf.n_cameras} cameras, got {len(cameras)}; calibrate one per camera.")
    lo = np.asarray(lower_mm, dtype=np.float64)
    hi = np.asarray(upper_mm, dtype=np.float64)
    if lo.shape != (3,) or hi.shape != (3,) or np.any(hi <= lo):
        raise ConfigError(f"ipr: 'upper_mm' {upper_mm!r} must exceed 'lower_mm' {lower_mm!r} on every axis.")
    for name, v in (("outer_loops", outer_loops), ("reduced_loops", reduced_loops), ("shake_iterations", shake_iterations),
                    ("final_iterations", final_iterations)):
        if isinstance(v, bool) or int(v) != v or v < 0:
            raise ConfigError(f"ipr: '{name}' must be a non-negative integer, got {v!r}.")
    tol = check_positive("tolerance_px", tolerance_px, owner="ipr", unit="px")
    if calibration_error_px is not None and not float(calibration_error_px) < tol:
        raise ConfigError(f"ipr: the calibration's reprojection error {calibration_error_px!r} px reaches the triangulation "
                          f"tolerance tolerance_px={tol} px; true particles would not triangulate. Recalibrate "
                          f"(volume self-calibration) or raise 'tolerance_px' above the calibration error.")
    reduced_tol = tol * check_positive("reduced_tolerance", reduced_tolerance, owner="ipr")
    thr = threshold if threshold is not None else [auto_threshold(i, noise="background") for i in imgs]
    thr = list(np.broadcast_to(np.asarray(thr, dtype=np.float64), (len(imgs),)))
    scale = mm_per_px(cameras, 0.5 * (lo + hi))
    step_mm = check_positive("shake_step_px", shake_step_px, owner="ipr", unit="px") * scale
    dup_mm = check_positive("duplicate_px", duplicate_px, owner="ipr", unit="px") * scale
    n = len(cameras)
    blank = [k for k in range(n) if detect_peaks(imgs[k], threshold=thr[k])[0].shape[0] == 0]
    if blank and initial is None:
        # a camera that sees no particle in this frame carries no information: leave it out
        live = [k for k in range(n) if k not in blank]
        log.debug("ipr: cameras %s show no peak above the threshold; reconstructing with %s", blank, live)
        if len(live) < 2:
            return IPRResult(np.zeros((0, 3)), np.zeros(0), [i.copy() for i in imgs],
                             [{"cameras": live, "peaks": [0] * n, "candidates": 0, "particles": 0}])
        sub = OTF(otf.lower_mm, otf.upper_mm, otf.a[live], otf.b[live], otf.c[live], otf.peak[live])
        r = ipr([imgs[k] for k in live], [cameras[k] for k in live], sub, lower_mm=lo, upper_mm=hi,
                threshold=[thr[k] for k in live], tolerance_px=tol, outer_loops=outer_loops, reduced_loops=reduced_loops,
                shake_iterations=shake_iterations, shake_step_px=shake_step_px, final_iterations=final_iterations,
                min_intensity=min_intensity, duplicate_px=duplicate_px, reduced_tolerance=reduced_tolerance,
                tolerance_start=tolerance_start, unique_peaks=unique_peaks, weak_intensity=weak_intensity,
                support=support, camera_gain=camera_gain, final_screen=final_screen, max_outer_loops=max_outer_loops,
                converged=converged, weak_support=weak_support, progress=progress)
        res = [imgs[k].copy() for k in range(n)]
        for j, k in enumerate(live):
            res[k] = r.residuals[j]
        g = np.ones(n)
        g[live] = r.camera_gain
        return IPRResult(r.positions_mm, r.intensities, res, [dict(h, cameras=[live[c] for c in h["cameras"]]) for h in r.history],
                         g)
    if initial is not None:
        p = np.asarray(initial[0], dtype=np.float64).reshape(-1, 3)
        e = np.array(np.broadcast_to(np.asarray(initial[1], dtype=np.float64), (p.shape[0],)))
    else:
        p, e = np.zeros((0, 3)), np.zeros(0)
    res = [i - pr for i, pr in zip(imgs, project_particles(p, e, cameras, otf), strict=True)] if p.size else [i.copy() for i in imgs]
    sets = [list(range(n))] * int(outer_loops)
    f0 = check_positive("tolerance_start", tolerance_start, owner="ipr")
    if f0 > 1:
        raise ConfigError(f"ipr: 'tolerance_start' is a fraction of tolerance_px in (0, 1], got {tolerance_start!r}.")
    tols = list(tol * np.linspace(f0, 1.0, int(outer_loops))) if int(outer_loops) > 1 else [tol] * int(outer_loops)
    for name, v in (("weak_intensity", weak_intensity), ("support", support)):
        if not (np.isfinite(v) and 0 <= v < 1):
            raise ConfigError(f"ipr: '{name}' must be a fraction in [0, 1), got {v!r}.")
    if n >= 3:
        subsets = [list(s) for s in combinations(range(n), n - 1)]
        sets += [s for _ in range(int(reduced_loops)) for s in subsets]
    history = []
    otf_in = otf
    gain = np.ones(n)
    n_all = int(outer_loops)
    if isinstance(max_outer_loops, bool) or int(max_outer_loops) != max_outer_loops or max_outer_loops < 0:
        raise ConfigError(f"ipr: 'max_outer_loops' must be a non-negative integer, got {max_outer_loops!r}.")
    if not (np.isfinite(converged) and converged >= 0):
        raise ConfigError(f"ipr: 'converged' must be a fraction >= 0, got {converged!r}.")
    with bar(len(sets), desc="IPR", progress=progress) as pb:
        for loop, use in enumerate(sets):
            peaks = [detect_peaks(r, threshold=t) for r, t in zip(res, thr, strict=True)]
            x, ids, err = triangulate([q[0] for q in peaks], cameras, lower_mm=lo, upper_mm=hi, use=use,
                                      tolerance_px=(tols[loop] if loop < len(tols) else tol) if len(use) == n
                                      else reduced_tol)
            if unique_peaks and x.shape[0]:
                u = _unique_peaks(ids, err, use)
                x, ids = x[u], ids[u]
            if x.shape[0] and len(use) < n:
                # a particle missed by one camera must be hidden there (behind another
                # particle's light in the raw image) or off its sensor: else it is a ghost
                ok = np.ones(x.shape[0], bool)
                for k in set(range(n)) - set(use):
                    uv = cameras[k].project(x)
                    on = cameras[k].visible(x)
                    hk, wk = imgs[k].shape
                    col = np.clip(np.nan_to_num(uv[:, 0]).astype(np.int64), 0, wk - 1)
                    row = np.clip(np.nan_to_num(uv[:, 1]).astype(np.int64), 0, hk - 1)
                    ok &= ~on | (imgs[k][row, col] > thr[k])
                x, ids = x[ok], ids[ok]
            n_cand = int(x.shape[0])
            n_min = min(q[0].shape[0] for q in peaks)
            if not history and p.shape[0] == 0 and initial is None and n_min >= 20 and n_cand < 0.05 * n_min:
                raise ConfigError(
                    f"ipr: {[int(q[0].shape[0]) for q in peaks]} peaks in the cameras but only {n_cand} triangulate "
                    f"within tolerance_px={tol} px: the calibration does not fit the images (reprojection error above "
                    f"the tolerance?). Check the cameras, recalibrate, or raise 'tolerance_px'.")
            n_old = p.shape[0]
            pk_otf = np.array([np.median(otf.peak[k]) for k in range(n)])
            if x.shape[0]:
                vals = np.stack([peaks[k][1][ids[:, k]] / pk_otf[k] for k in use], axis=1)
                e_new = vals.mean(axis=1)
                p = np.concatenate([p, x])
                e = np.concatenate([e, e_new])
            if p.shape[0]:
                p, e, res = shake(imgs, cameras, otf, p, e, step_mm=step_mm, iterations=shake_iterations)
                old = np.arange(p.shape[0]) < n_old
                keep = _screen(res, cameras, otf, p, e, support=support, weak_intensity=weak_intensity,
                               established=old, weak_support=weak_support)
                p, e = _prune(p[keep], e[keep], lo, hi, min_intensity, dup_mm)
                if camera_gain and p.shape[0] >= 20:
                    res = [i - pr for i, pr in zip(imgs, project_particles(p, e, cameras, otf), strict=True)]
                    gain = gain * _camera_gain(res, cameras, otf, p, e)
                    otf = OTF(otf_in.lower_mm, otf_in.upper_mm, otf_in.a, otf_in.b, otf_in.c,
                              otf_in.peak * gain[:, None, None, None])
                res = [i - pr for i, pr in zip(imgs, project_particles(p, e, cameras, otf), strict=True)]
            history.append({"cameras": use, "peaks": [int(q[0].shape[0]) for q in peaks], "candidates": n_cand,
                            "particles": int(p.shape[0]), "camera_gain": gain.tolist()})
            log.debug("IPR loop cameras %s: %s peaks, %d candidates, %d particles", use,
                      history[-1]["peaks"], n_cand, p.shape[0])
            if (len(use) == n and loop == n_all - 1 and n_all < max_outer_loops
                    and n_cand > converged * max(p.shape[0], 1)):
                # not converged: one more all-camera loop before the reduced sets (the list
                # iterator reads the inserted set next)
                sets.insert(loop + 1, list(range(n)))
                n_all += 1
            pb.update()
    if p.shape[0] and final_iterations:
        p, e, res = shake(imgs, cameras, otf, p, e, step_mm=0.2 * step_mm, iterations=final_iterations)
        keep = _screen(res, cameras, otf, p, e, support=support if final_screen else 0.0,
                       weak_intensity=weak_intensity if final_screen else 0.0, established=np.ones(p.shape[0], bool),
                       weak_support=weak_support)
        p, e = _prune(p[keep], e[keep], lo, hi, min_intensity, dup_mm)
        res = [i - pr for i, pr in zip(imgs, project_particles(p, e, cameras, otf), strict=True)]
    return IPRResult(p, e, res, history, gain)
