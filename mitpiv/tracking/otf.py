"""Particle image model for Lagrangian particle tracking: the optical transfer function
(OTF) of Schanz et al. (2013) and a vectorised projector of 3D particles into images.

Model
-----
The image of a particle of intensity ``E`` at world position ``X`` in camera ``c`` is an
elliptical Gaussian centred on the particle's projection ``(u0, v0) = project_c(X)``::

    I(u, v) = E * peak_c(X) * exp(-(a du^2 + 2 b du dv + c dv^2) / 2),   du = u - u0, dv = v - v0

sampled at pixel centres (pixel ``(i, j)`` has its centre at ``(i + 0.5, j + 0.5)``, the
camera contract's convention). ``(a, b, c)`` [1/px^2] is the inverse covariance of the
blob and ``peak`` its peak value per unit particle intensity. Schanz et al. write the same
ellipse with two widths and an angle; the inverse-covariance form is used here because it
interpolates linearly between sub-volumes (an angle does not). Every parameter is given on a
regular grid of sub-volume centres over a box and interpolated trilinearly (clamped at the
box), one grid per camera.

Calibration (:func:`calibrate_otf`) fits the parameters to the images of particles whose
3D positions are known (triangulated or true): each isolated particle image is fitted by a
weighted linear least-squares fit of ``log I`` to a quadratic in ``(u, v)`` (exact for a
Gaussian, batched over particles), and each sub-volume takes the median of the particles
inside it.

Hand-written: the projector is a compiled scatter of small Gaussian stamps
(``splat`` in :mod:`mitpiv.tracking._kernels`; :func:`stamps` gives the same stamps as
NumPy arrays) (no kept library renders elliptical Gaussians at arbitrary sub-pixel
positions with per-particle shapes); the calibration fit is a batched 6x6 solve.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mitpiv.errors import CalibrationError, ConfigError, check_positive

__all__ = ["OTF", "calibrate_otf", "calibrate_otf_frames", "refine_otf", "project_particles", "add_particles", "stamps"]


def _box(lower_mm, upper_mm, what):
    lo = np.asarray(lower_mm, dtype=np.float64).reshape(-1)
    hi = np.asarray(upper_mm, dtype=np.float64).reshape(-1)
    if lo.shape != (3,) or hi.shape != (3,) or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
        raise ConfigError(f"{what}: 'lower_mm' and 'upper_mm' must be finite (x, y, z) triples [mm], got {lower_mm!r}, {upper_mm!r}.")
    if np.any(hi <= lo):
        raise ConfigError(f"{what}: 'upper_mm' {hi.tolist()} must exceed 'lower_mm' {lo.tolist()} on every axis.")
    return lo, hi


def _subvolumes(subvolumes, what):
    try:
        n = tuple(int(v) for v in np.broadcast_to(np.asarray(subvolumes), (3,)))
    except (TypeError, ValueError):
        n = ()
    if len(n) != 3 or min(n) < 1:
        raise ConfigError(f"{what}: 'subvolumes' must be three positive integers (n_x, n_y, n_z), got {subvolumes!r}.")
    return n


@dataclass
class OTF:
    """Elliptical Gaussian particle image model per camera and sub-volume.

    Attributes
    ----------
    lower_mm, upper_mm : (3,) arrays
        Box [mm] the sub-volume grid covers; sub-volume ``(ix, iy, iz)`` is the
        ``(ix, iy, iz)``-th cell of an ``n_x x n_y x n_z`` split of the box.
    a, b, c : (n_cameras, n_x, n_y, n_z) arrays
        Inverse covariance ``[[a, b], [b, c]]`` of the particle image [1/px^2].
    peak : (n_cameras, n_x, n_y, n_z) array
        Peak image value per unit particle intensity.
    """

    lower_mm: np.ndarray
    upper_mm: np.ndarray
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    peak: np.ndarray

    def __post_init__(self) -> None:
        self.lower_mm, self.upper_mm = _box(self.lower_mm, self.upper_mm, "OTF")
        arrs = [np.array(getattr(self, k), dtype=np.float64) for k in ("a", "b", "c", "peak")]
        shape = arrs[0].shape
        if len(shape) != 4 or any(x.shape != shape for x in arrs):
            raise ConfigError(f"OTF: 'a', 'b', 'c' and 'peak' must share one shape (n_cameras, n_x, n_y, n_z), got {[x.shape for x in arrs]}.")
        a, b, c, peak = arrs
        if not all(np.all(np.isfinite(x)) for x in arrs):
            raise ConfigError("OTF: parameters hold NaN or infinite values.")
        if np.any(a <= 0) or np.any(c <= 0) or np.any(a * c - b * b <= 0):
            raise ConfigError("OTF: the inverse covariance [[a, b], [b, c]] must be positive definite in every sub-volume.")
        if np.any(peak <= 0):
            raise ConfigError("OTF: 'peak' must be > 0 in every sub-volume.")
        self.a, self.b, self.c, self.peak = a, b, c, peak

    @classmethod
    def uniform(cls, n_cameras: int, *, sigma_px=1.0, peak: float = 1.0, lower_mm=(-1, -1, -1), upper_mm=(1, 1, 1),
                subvolumes=(1, 1, 1), angle_deg: float = 0.0) -> OTF:
        """The same Gaussian everywhere: ``sigma_px`` a width or (major, minor) widths [px]
        along axes turned ``angle_deg`` from the image u axis; ``peak`` per unit intensity."""
        if isinstance(n_cameras, bool) or int(n_cameras) != n_cameras or n_cameras < 1:
            raise ConfigError(f"OTF.uniform: 'n_cameras' must be a positive integer, got {n_cameras!r}.")
        s = np.broadcast_to(np.asarray(sigma_px, dtype=np.float64), (2,))
        s1 = check_positive("sigma_px", s[0], owner="OTF.uniform", unit="px")
        s2 = check_positive("sigma_px", s[1], owner="OTF.uniform", unit="px")
        t = np.radians(angle_deg)
        rot = np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
        inv = rot @ np.diag([1 / s1**2, 1 / s2**2]) @ rot.T
        n = (int(n_cameras),) + _subvolumes(subvolumes, "OTF.uniform")
        peak = check_positive("peak", peak, owner="OTF.uniform")
        return cls(lower_mm, upper_mm, np.full(n, inv[0, 0]), np.full(n, inv[0, 1]), np.full(n, inv[1, 1]), np.full(n, peak))

    @property
    def n_cameras(self) -> int:
        return int(self.a.shape[0])

    def sigma_max_px(self) -> float:
        """Largest standard deviation of any particle image [px] (the major axis)."""
        det = self.a * self.c - self.b**2
        # covariance = [[c, -b], [-b, a]] / det; its largest eigenvalue
        tr, dt = (self.a + self.c) / det, 1.0 / det
        lam = 0.5 * (tr + np.sqrt(np.maximum(tr * tr - 4 * dt, 0.0)))
        return float(np.sqrt(lam.max()))

    def radius_px(self, *, n_sigma: float = 3.0) -> int:
        """Half width of the stamp [px] that holds the particle image to ``n_sigma``."""
        return max(1, int(np.ceil(n_sigma * self.sigma_max_px())))

    def params(self, camera: int, p_mm) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(a, b, c, peak)`` at world points ``p_mm`` (N, 3) for camera index ``camera``:
        trilinear interpolation between sub-volume centres, clamped at the box."""
        p = np.asarray(p_mm, dtype=np.float64).reshape(-1, 3)
        stack = np.stack([self.a[camera], self.b[camera], self.c[camera], self.peak[camera]], axis=-1)
        if stack.shape[:3] == (1, 1, 1):
            return tuple(np.full(p.shape[0], v) for v in stack[0, 0, 0])
        n = np.asarray(stack.shape[:3])
        t = (p - self.lower_mm) / (self.upper_mm - self.lower_mm) * n - 0.5
        t = np.nan_to_num(np.clip(t, 0.0, n - 1.0))
        i0 = np.minimum(np.floor(t).astype(np.int64), n - 1)
        f = t - i0
        i1 = np.minimum(i0 + 1, n - 1)
        flat = stack.reshape(-1, 4)
        v = np.zeros((p.shape[0], 4))
        for corner in range(8):
            bits = [(corner >> ax) & 1 for ax in range(3)]
            idx = [np.where(bits[ax], i1[:, ax], i0[:, ax]) for ax in range(3)]
            wgt = np.prod([f[:, ax] if bits[ax] else 1 - f[:, ax] for ax in range(3)], axis=0)
            v += wgt[:, None] * flat[np.ravel_multi_index(idx, tuple(n))]
        return tuple(v.T.copy())

    def to_dict(self) -> dict:
        return {"model": "elliptical_gaussian_otf", "lower_mm": self.lower_mm.tolist(), "upper_mm": self.upper_mm.tolist(),
                "a_per_px2": self.a.tolist(), "b_per_px2": self.b.tolist(), "c_per_px2": self.c.tolist(),
                "peak": self.peak.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> OTF:
        return cls(d["lower_mm"], d["upper_mm"], d["a_per_px2"], d["b_per_px2"], d["c_per_px2"], d["peak"])


def stamps(uv_px, a, b, c, amplitude, radius: int):
    """Gaussian stamps around sub-pixel centres: pixel indices and values.

    Parameters
    ----------
    uv_px : (N, 2) centres [px]; a, b, c, amplitude : (N,) shape and peak value.
    radius : half width of the (2r+1)^2 stamp [px].

    Returns
    -------
    cols, rows : (N, S, S) int64 pixel indices (S = 2 radius + 1), around ``floor(uv)``.
    values : (N, S, S) float64 stamp values at the pixel centres.
    """
    uv = np.asarray(uv_px, dtype=np.float64).reshape(-1, 2)
    o = np.arange(-radius, radius + 1)
    i0 = np.floor(uv[:, 0]).astype(np.int64)
    j0 = np.floor(uv[:, 1]).astype(np.int64)
    cols = i0[:, None, None] + o[None, None, :]
    rows = j0[:, None, None] + o[None, :, None]
    du = cols + 0.5 - uv[:, 0, None, None]
    dv = rows + 0.5 - uv[:, 1, None, None]
    q = a[:, None, None] * du * du + 2 * b[:, None, None] * du * dv + c[:, None, None] * dv * dv
    return np.broadcast_to(cols, q.shape), np.broadcast_to(rows, q.shape), amplitude[:, None, None] * np.exp(-0.5 * q)


def project_particles(positions_mm, intensities, cameras, otf: OTF, *, chunk: int = 50_000) -> list[np.ndarray]:
    """Render particles into one image per camera with the OTF.

    Parameters
    ----------
    positions_mm : (N, 3) world positions [mm].
    intensities : (N,) or scalar particle intensities (multiplying the OTF's peak).
    cameras : sequence of cameras (the camera contract: ``project``, ``visible``, ``resolution``).
    otf : :class:`OTF` with one grid per camera.
    chunk : particles per batch (bounds memory).

    Returns
    -------
    list of (H, W) float64 images, one per camera.
    """
    p = np.asarray(positions_mm, dtype=np.float64).reshape(-1, 3)
    e = np.broadcast_to(np.asarray(intensities, dtype=np.float64), (p.shape[0],))
    if len(cameras) != otf.n_cameras:
        raise ConfigError(f"project_particles: {len(cameras)} cameras but the OTF has {otf.n_cameras}; calibrate one per camera.")
    from mitpiv.tracking._kernels import kernels

    r = otf.radius_px()
    splat = kernels()["splat"]
    images = []
    for k, cam in enumerate(cameras):
        w, h = cam.resolution
        img = np.zeros((h, w))
        for s in range(0, p.shape[0], chunk):
            ps, es = p[s:s + chunk], e[s:s + chunk]
            front = cam.in_front(ps)
            ps, es = ps[front], es[front]
            uv = cam.project(ps)
            near = np.all(np.isfinite(uv), axis=1) & (uv[:, 0] > -r) & (uv[:, 0] < w + r) & (uv[:, 1] > -r) & (uv[:, 1] < h + r)
            a, b, c, pk = otf.params(k, ps[near])
            splat(img, np.ascontiguousarray(uv[near]), a, b, c, np.ascontiguousarray(pk * es[near]), int(r))
        images.append(img)
    return images


def add_particles(images, positions_mm, intensities, cameras, otf: OTF) -> None:
    """Add the images of particles to ``images`` in place (negative intensities subtract):
    the sparse counterpart of :func:`project_particles` for a few particles."""
    from mitpiv.tracking._kernels import kernels

    p = np.asarray(positions_mm, dtype=np.float64).reshape(-1, 3)
    e = np.broadcast_to(np.asarray(intensities, dtype=np.float64), (p.shape[0],))
    r = otf.radius_px()
    for k, cam in enumerate(cameras):
        img = images[k]
        h, w = img.shape
        front = cam.in_front(p)
        uv = cam.project(p[front])
        a, b, c, pk = otf.params(k, p[front])
        kernels()["splat"](img, np.ascontiguousarray(uv, dtype=np.float64), a, b, c,
                           np.ascontiguousarray(pk * e[front]), int(r))


def _fit_blobs(image, uv, h, own=None):
    """Weighted log-quadratic fit of (2h+1)^2 windows around ``uv`` (N, 2): returns
    a, b, c [1/px^2], centre (N, 2) [px], peak (N,) and a validity mask. ``own``: optional
    ``(a, b, c, amplitude)`` (N,) of a model image centred on ``uv`` added to each window
    (a particle's own image put back into a residual image)."""
    hgt, wid = image.shape
    o = np.arange(-h, h + 1)
    i0 = np.round(uv[:, 0] - 0.5).astype(np.int64)
    j0 = np.round(uv[:, 1] - 0.5).astype(np.int64)
    cols = np.clip(i0[:, None, None] + o[None, None, :], 0, wid - 1)
    rows = np.clip(j0[:, None, None] + o[None, :, None], 0, hgt - 1)
    win = image[rows, cols]
    if own is not None:
        oa, ob, oc, amp = (np.asarray(x, dtype=np.float64)[:, None, None] for x in own)
        du = i0[:, None, None] + o[None, None, :] + 0.5 - uv[:, 0, None, None]
        dv = j0[:, None, None] + o[None, :, None] + 0.5 - uv[:, 1, None, None]
        win = win + amp * np.exp(-0.5 * (oa * du * du + 2 * ob * du * dv + oc * dv * dv))
    win = win.reshape(uv.shape[0], o.size * o.size)
    x = np.broadcast_to(o[None, None, :], (1, o.size, o.size)).reshape(-1).astype(np.float64)
    y = np.broadcast_to(o[None, :, None], (1, o.size, o.size)).reshape(-1).astype(np.float64)
    mx = win.max(axis=1, keepdims=True)
    use = win > 0.05 * mx
    wgt = np.where(use, win, 0.0) ** 2
    logv = np.log(np.where(use, win, 1.0))
    basis = np.stack([np.ones_like(x), x, y, x * x, x * y, y * y], axis=1)  # (P, 6)
    ata = np.einsum("np,pi,pj->nij", wgt, basis, basis)
    atb = np.einsum("np,pi,np->ni", wgt, basis, logv)
    ok = use.sum(axis=1) >= 6
    ata[~ok] = np.eye(6)
    coef = np.linalg.solve(ata + 1e-12 * np.eye(6), atb[..., None])[..., 0]
    a, b, c = -2 * coef[:, 3], -coef[:, 4], -2 * coef[:, 5]
    det = a * c - b * b
    ok &= (a > 0) & (c > 0) & (det > 0)
    det = np.where(ok, det, 1.0)
    # gradient zero: [[a, b], [b, c]] d = (c1, c2)
    du = (c * coef[:, 1] - b * coef[:, 2]) / det
    dv = (a * coef[:, 2] - b * coef[:, 1]) / det
    ok &= (np.abs(du) < 1.0) & (np.abs(dv) < 1.0)
    logpk = coef[:, 0] + 0.5 * (coef[:, 1] * du + coef[:, 2] * dv)
    centre = np.stack([i0 + 0.5 + du, j0 + 0.5 + dv], axis=1)
    return a, b, c, centre, np.exp(np.clip(logpk, -700, 700)), ok


def calibrate_otf(images, cameras, positions_mm, *, lower_mm, upper_mm, subvolumes=(1, 1, 1), intensities=None,
                  window_px: int = 2, isolation_px: float | None = None, min_particles: int = 5) -> OTF:
    """Fit the OTF (Schanz et al. 2013) to images of particles of known 3D position.

    Parameters
    ----------
    images : sequence of (H, W) images, one per camera (background subtracted).
    cameras : sequence of cameras (the camera contract).
    positions_mm : (N, 3) positions [mm] of particles in the images (triangulated or true).
    lower_mm, upper_mm : (3,) box [mm] split into ``subvolumes`` = (n_x, n_y, n_z) cells.
    intensities : (N,) particle intensities, or None for 1 (then ``peak`` is the particles'
        median peak image value).
    window_px : half width of the fitted window [px]; 2 (5 x 5) suits sigma ~ 0.6 - 1.5 px.
    isolation_px : only particles with no other projection and no other image peak
        (:func:`~mitpiv.tracking.ipr.detect_peaks`) closer than this [px] are fitted (the
        peaks stand for the particles the positions miss, e.g. those a dense image did not
        triangulate); default ``2 window_px + 2``.
    min_particles : fewest fitted particles a camera needs (else :class:`CalibrationError`).

    Returns
    -------
    OTF; a sub-volume with no fitted particle takes the camera's median over all particles.
    See :func:`calibrate_otf_frames` to pool the particles of several frames (dense images,
    where few particle images stand alone in one frame).
    """
    return calibrate_otf_frames([images], cameras, [positions_mm], lower_mm=lower_mm, upper_mm=upper_mm,
                                subvolumes=subvolumes, intensities=None if intensities is None else [intensities],
                                window_px=window_px, isolation_px=isolation_px, min_particles=min_particles)


def calibrate_otf_frames(frames, cameras, positions_mm, *, lower_mm, upper_mm, subvolumes=(1, 1, 1),
                         intensities=None, window_px: int = 2, isolation_px: float | None = None,
                         min_particles: int = 5) -> OTF:
    """:func:`calibrate_otf` over several frames: the isolated particles of every frame are
    fitted and pooled before the per-sub-volume medians (the particle image model does not
    change between frames). ``frames``: a sequence of frames, each a sequence of per-camera
    images; ``positions_mm``: one (N_f, 3) array per frame; ``intensities``: None or one
    (N_f,) array per frame. Other parameters as :func:`calibrate_otf`."""
    from scipy.spatial import cKDTree

    from mitpiv.tracking.ipr import detect_peaks  # ipr imports this module

    lo, hi = _box(lower_mm, upper_mm, "calibrate_otf")
    n = _subvolumes(subvolumes, "calibrate_otf")
    if len(frames) == 0 or len(positions_mm) != len(frames):
        raise ConfigError(f"calibrate_otf: {len(frames)} frame(s) and {len(positions_mm)} position array(s); give one "
                          f"position array per frame (at least one frame).")
    if intensities is not None and len(intensities) != len(frames):
        raise ConfigError(f"calibrate_otf: {len(intensities)} intensity array(s) for {len(frames)} frame(s).")
    for images in frames:
        if len(images) != len(cameras):
            raise ConfigError(f"calibrate_otf: {len(images)} images for {len(cameras)} cameras; give one image per camera.")
    h = int(window_px)
    if h < 1:
        raise ConfigError(f"calibrate_otf: 'window_px' must be an integer >= 1, got {window_px!r}.")
    iso = 2 * h + 2 if isolation_px is None else check_positive("isolation_px", isolation_px, owner="calibrate_otf", unit="px")
    shape = (len(cameras),) + n
    out = {k: np.zeros(shape) for k in ("a", "b", "c", "peak")}
    for k, cam in enumerate(cameras):
        fits = []
        for f, images in enumerate(frames):
            img = np.asarray(images[k], dtype=np.float64)
            p = np.asarray(positions_mm[f], dtype=np.float64).reshape(-1, 3)
            e = np.ones(p.shape[0]) if intensities is None else np.broadcast_to(
                np.asarray(intensities[f], float), (p.shape[0],))
            vis = cam.visible(p)
            uv = cam.project(p[vis])
            pv, ev = p[vis], e[vis]
            if uv.shape[0] > 1:
                d, _ = cKDTree(uv).query(uv, k=2)
                keep = d[:, 1] > iso
            else:
                keep = np.ones(uv.shape[0], bool)
            # particles the positions do not hold (not triangulated) are peaks in the image:
            # a fitted particle has no peak but its own within the isolation distance
            peaks, _ = detect_peaks(img)
            if peaks.shape[0] and uv.shape[0]:
                keep &= np.asarray(cKDTree(peaks).query_ball_point(uv, iso, return_length=True)) <= 1
            w, hh = cam.resolution
            keep &= (uv[:, 0] > h + 1) & (uv[:, 0] < w - h - 1) & (uv[:, 1] > h + 1) & (uv[:, 1] < hh - h - 1)
            a, b, c, _, pk, ok = _fit_blobs(img, uv[keep], h)
            pk = pk / ev[keep]
            ok &= np.isfinite(pk) & (pk > 0)
            fits.append((pv[keep][ok], a[ok], b[ok], c[ok], pk[ok]))
        pp, a, b, c, pk = (np.concatenate(x) for x in zip(*fits, strict=True))
        if pp.shape[0] < min_particles:
            raise CalibrationError(
                f"calibrate_otf: camera {k} has {pp.shape[0]} isolated, fittable particle images in {len(frames)} "
                f"frame(s), fewer than min_particles={min_particles}. Give more frames (or sparser particles), or "
                f"lower 'isolation_px'.")
        _cell_medians(out, k, pp, (a, b, c, pk), n, lo, hi)
    return OTF(lo, hi, out["a"], out["b"], out["c"], out["peak"])


def _cell_medians(out, k, pp, fits, n, lo, hi):
    """Per sub-volume medians of the fitted (a, b, c, peak) of camera k into ``out``; a cell
    with no particle takes the camera's median over all."""
    cell = np.clip(((pp - lo) / (hi - lo) * np.asarray(n)).astype(np.int64), 0, np.asarray(n) - 1)
    flat = np.ravel_multi_index(cell.T, n)
    for key, vals in zip(("a", "b", "c", "peak"), fits, strict=True):
        med = np.full(int(np.prod(n)), np.median(vals))
        # per-cell median: sort by (cell, value) and take the middle element of each run
        order = np.lexsort((vals, flat))
        fs, vs = flat[order], vals[order]
        starts = np.flatnonzero(np.r_[True, fs[1:] != fs[:-1]])
        counts = np.diff(np.r_[starts, fs.size])
        lo_i, hi_i = starts + (counts - 1) // 2, starts + counts // 2
        med[fs[starts]] = 0.5 * (vs[lo_i] + vs[hi_i])
        out[key][k] = med.reshape(n)


def refine_otf(images, cameras, otf: OTF, positions_mm, intensities, *, subvolumes=None, window_px: int = 2,
               isolation_px: float = 2.0, min_particles: int = 5, camera_gain=None) -> OTF:
    """Re-fit the OTF on augmented residual images (Schanz et al. 2013): each particle's
    window is the image minus the model images of all particles plus its own, so its
    neighbours' light no longer widens the fit, as it does in a dense image where few
    particle images stand alone.

    Parameters
    ----------
    images : per-camera (H, W) images; cameras : the cameras.
    otf : the current OTF (its model images are subtracted; its box and, by default, its
        sub-volumes are kept).
    positions_mm : (N, 3) reconstructed particles (e.g. :func:`~mitpiv.tracking.ipr.ipr`'s).
    intensities : (N,) their intensities.
    subvolumes : (n_x, n_y, n_z) of the new OTF (default: the current one's).
    window_px : half width of the fitted window [px].
    isolation_px : particles with another particle's projection closer than this [px] are
        not fitted (their images merge).
    min_particles : fewest fitted particles a camera needs (else :class:`CalibrationError`).
    camera_gain : (n_cameras,) factors on each camera's model images, as the tracker measured
        them against ``otf`` (:func:`~mitpiv.tracking.stb.stb`'s last ``history`` entry with a
        ``camera_gain``; default 1). Without them a camera whose particles are brighter than the OTF says keeps
        part of every neighbour in the residual, and its fit widens. The new OTF's peak takes
        the gain in.

    Returns
    -------
    OTF.
    """
    from scipy.spatial import cKDTree

    p = np.asarray(positions_mm, dtype=np.float64).reshape(-1, 3)
    e = np.broadcast_to(np.asarray(intensities, dtype=np.float64), (p.shape[0],))
    if len(images) != len(cameras) or len(cameras) != otf.n_cameras:
        raise ConfigError(f"refine_otf: {len(images)} images, {len(cameras)} cameras and an OTF of {otf.n_cameras}; "
                          f"give one image per camera.")
    h = int(window_px)
    if h < 1:
        raise ConfigError(f"refine_otf: 'window_px' must be an integer >= 1, got {window_px!r}.")
    iso = check_positive("isolation_px", isolation_px, owner="refine_otf", unit="px")
    n = otf.a.shape[1:] if subvolumes is None else _subvolumes(subvolumes, "refine_otf")
    if camera_gain is None:
        gain = np.ones(len(cameras))
    else:
        gain = np.asarray(camera_gain, dtype=np.float64).ravel()
        if gain.shape != (len(cameras),) or not np.all(np.isfinite(gain)) or np.any(gain <= 0):
            raise ConfigError(f"refine_otf: 'camera_gain' must hold one positive factor per camera ({len(cameras)}), "
                              f"got {camera_gain!r}.")
    lo, hi = otf.lower_mm, otf.upper_mm
    shape = (len(cameras),) + tuple(n)
    out = {k: np.zeros(shape) for k in ("a", "b", "c", "peak")}
    residuals = project_particles(p, e, cameras, otf)
    for k, (img, cam) in enumerate(zip(images, cameras, strict=True)):
        res = np.asarray(img, dtype=np.float64) - gain[k] * residuals[k]
        vis = cam.visible(p) & (e > 0)
        uv = cam.project(p[vis])
        pv, ev = p[vis], e[vis]
        keep = np.ones(uv.shape[0], bool)
        if uv.shape[0] > 1:
            d, _ = cKDTree(uv).query(uv, k=2)
            keep = d[:, 1] > iso
        w, hh = cam.resolution
        keep &= (uv[:, 0] > h + 1) & (uv[:, 0] < w - h - 1) & (uv[:, 1] > h + 1) & (uv[:, 1] < hh - h - 1)
        oa, ob, oc, opk = otf.params(k, pv[keep])
        a, b, c, _, pk, ok = _fit_blobs(res, uv[keep], h, own=(oa, ob, oc, gain[k] * opk * ev[keep]))
        pk = pk / ev[keep]
        ok &= np.isfinite(pk) & (pk > 0)
        if ok.sum() < min_particles:
            raise CalibrationError(
                f"refine_otf: camera {k} has {int(ok.sum())} fittable particle images, fewer than "
                f"min_particles={min_particles}. Give more particles, or lower 'isolation_px'.")
        _cell_medians(out, k, pv[keep][ok], (a[ok], b[ok], c[ok], pk[ok]), n, lo, hi)
    return OTF(lo, hi, out["a"], out["b"], out["c"], out["peak"])
