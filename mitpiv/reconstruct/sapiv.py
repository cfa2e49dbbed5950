"""Synthetic-aperture refocusing as in the SAPIV aberration study (Kubaczyk, MIT S.M.
thesis, sections 2.2.2, 2.3.3 and 3.3; after Belden et al. 2010).

* Each camera's image is realigned to the reference view plane by plane. With a pinhole
  calibration (no distortion terms) the map from a depth plane ``z = z_k`` to camera ``c``'s
  pixels is the homography (eq. 2.2)::

      [b u, b v, b]^T = H_ck [x, y, 1]^T,   H_ck = [P_c[:, 0], P_c[:, 1], z_k P_c[:, 2] + P_c[:, 3]]

  (``P_c = K_c R_c [I | -C_c]`` the calibrated projection matrix), exact for a pinhole; the
  refocused plane is sampled on the reference view's grid of the plane (the world ``x, y``
  grid of voxels of the study, whose pixels are 0.05 mm: 10 um / 0.2). A calibration that
  models distortion is not a homography: ``warp="mapping"`` projects the plane's points
  through the full calibrated mapping instead (what a user does after a Brown fit).
* Additive refocusing (eq. 2.3): ``I_Rk = 1/N sum_i I_Ski`` over the ``N`` cameras that see
  the point.
* Thresholding (section 3.3): a normal distribution is fitted to the *noise part* of each
  refocused plane's intensity histogram and only values above ``mu + k sigma`` (k = 3) are
  kept. The fit (:func:`noise_normal_fit`) is hand-written (no library fits a normal to the
  left part of a skewed histogram): a weighted least-squares parabola through the log of
  the histogram counts (a normal density is a parabola in log space; Caruana's estimator,
  weights = counts^2), refitted on the bins up to ``mu + 2 sigma`` of the previous fit until
  it settles, so the long tail of in-focus particles does not widen it.
"""

from __future__ import annotations

import logging

import numpy as np
from scipy import ndimage

from mitpiv.errors import ConfigError
from mitpiv.progress import Progress, track
from mitpiv.reconstruct.mapping import CameraMapping, PinholeMapping

__all__ = ["plane_homography", "noise_normal_fit", "refocus_planes", "RefocusResult", "WARPS"]

log = logging.getLogger(__name__)

WARPS = ("homography", "mapping")


def plane_homography(mapping: CameraMapping, z_mm: float) -> np.ndarray:
    """3x3 homography from world ``(x, y)`` on the plane ``z = z_mm`` to the pixels of a
    distortion-free pinhole ``mapping`` (exact: the columns 1, 2 and ``z P3 + P4`` of its
    projection matrix ``P = K R [I | -C]``), normalised to ``H[2, 2] = 1``.

    The pixel convention is mitpiv's (pixel ``i`` spans ``[i, i + 1)``), the camera's own.
    """
    if not isinstance(mapping, PinholeMapping) or not mapping.camera.distortion.is_zero:
        raise ConfigError("plane_homography: the mapping must be a distortion-free PinholeMapping (a homography "
                          "cannot represent distortion); use refocus_planes(warp='mapping') for other mappings.")
    cam = mapping.camera
    p = cam.K @ np.hstack([cam.rotation, (-cam.rotation @ cam.position_mm)[:, None]])
    h = np.column_stack([p[:, 0], p[:, 1], float(z_mm) * p[:, 2] + p[:, 3]])
    return h / h[2, 2]


def noise_normal_fit(values, *, bins: int = 256, iterations: int = 20) -> tuple[float, float]:
    """Mean and standard deviation of a normal distribution fitted to the noise part of
    the histogram of ``values`` (the low-intensity peak, not the tail of in-focus light).

    A parabola ``ln n(x) = a + b x + c x^2`` is fitted by weighted least squares (weights
    ``n^2``) to the histogram bins from the lowest value up to ``mu + 2 sigma`` of the
    previous fit (start: the whole range up to the 99th percentile), giving ``sigma^2 =
    -1 / (2 c)`` and ``mu = b sigma^2``; repeated until the window stops changing. When the
    noise peak spans fewer than three occupied bins (a nearly empty plane), the plain
    mean and standard deviation of the values up to the 99th percentile are returned.

    Returns
    -------
    (mu, sigma) in the units of ``values``.
    """
    v = np.asarray(values, dtype=np.float64).ravel()
    if v.size == 0 or not np.all(np.isfinite(v)):
        raise ConfigError("noise_normal_fit: 'values' must be a non-empty finite array.")
    lo, hi = float(v.min()), float(np.percentile(v, 99.0))
    core = v[v <= hi]
    mu, sd = float(core.mean()), float(core.std())
    if hi <= lo or sd == 0.0:
        return mu, sd
    counts, edges = np.histogram(v, bins=bins, range=(lo, hi))
    x = 0.5 * (edges[:-1] + edges[1:])
    cut = hi
    for _ in range(iterations):
        sel = (x <= cut) & (counts > 0)
        if sel.sum() < 3:
            break
        w = counts[sel].astype(float)
        a = np.column_stack([np.ones(sel.sum()), x[sel], x[sel] ** 2]) * w[:, None]
        coef, *_ = np.linalg.lstsq(a, np.log(w) * w, rcond=None)
        if not coef[2] < 0:
            break
        var = -1.0 / (2.0 * coef[2])
        mu_new, sd_new = float(coef[1] * var), float(np.sqrt(var))
        new_cut = mu_new + 2.0 * sd_new
        mu, sd = mu_new, sd_new
        if abs(new_cut - cut) <= 0.5 * (x[1] - x[0]):
            break
        cut = max(new_cut, x[np.argmax(counts)] + 2 * (x[1] - x[0]))
    return mu, sd


class RefocusResult:
    """Refocused planes and their histogram statistics.

    Attributes
    ----------
    planes : (n_z, n_points) float32, thresholded (or raw with ``threshold_k=None``).
    mu, sigma : (n_z,) normal fit of each raw plane's noise histogram.
    peak : (n_z,) maximum of each raw plane.
    mean, std : (n_z,) plain mean and standard deviation of each raw plane (the normal fit
        of the whole histogram, signal tail included).
    """

    def __init__(self, planes, mu, sigma, peak, mean=None, std=None):
        self.planes, self.mu, self.sigma, self.peak, self.mean, self.std = planes, mu, sigma, peak, mean, std


def refocus_planes(images, mappings, xy_mm, z_mm, *, warp: str = "homography", threshold_k: float | None = 3.0,
                   progress: Progress = None) -> RefocusResult:
    """Additive synthetic-aperture refocusing on the planes ``z_mm`` at the points ``xy_mm``.

    Parameters
    ----------
    images : sequence of (H, W) arrays, one per camera.
    mappings : sequence of CameraMapping (the calibration), one per image.
    xy_mm : (n, 2) world x, y of the reference-view grid points [mm] (any set of points,
        e.g. the union of several patches).
    z_mm : (n_z,) depths of the refocused planes [mm].
    warp : "homography" (eq. 2.2, needs distortion-free pinhole mappings) or "mapping"
        (the full calibrated mapping, for calibrations that model distortion).
    threshold_k : k of the ``mu + k sigma`` threshold (3 in the study); None keeps raw planes.

    Returns
    -------
    RefocusResult
    """
    if warp not in WARPS:
        raise ConfigError(f"refocus_planes: 'warp' must be one of {WARPS}, got {warp!r}.")
    imgs = [np.asarray(im, dtype=np.float32) for im in images]
    if len(imgs) != len(mappings) or not imgs:
        raise ConfigError(f"refocus_planes: {len(imgs)} images for {len(mappings)} mappings; give one mapping per image.")
    xy = np.asarray(xy_mm, dtype=np.float64).reshape(-1, 2)
    z = np.atleast_1d(np.asarray(z_mm, dtype=np.float64))
    if threshold_k is not None and not (np.isfinite(threshold_k) and threshold_k >= 0):
        raise ConfigError(f"refocus_planes: 'threshold_k' must be >= 0 or None, got {threshold_k!r}.")
    n = len(xy)
    planes = np.empty((len(z), n), np.float32)
    mu = np.empty(len(z))
    sigma = np.empty(len(z))
    peak = np.empty(len(z))
    mean = np.empty(len(z))
    std = np.empty(len(z))
    if warp == "homography":  # one fused compiled pass per plane (mitpiv.reconstruct._kernels)
        from mitpiv.reconstruct._kernels import kernels

        fused = kernels()["refocus_homography"]
        flat = np.concatenate([im.ravel() for im in imgs])
        offs = np.cumsum([0] + [im.size for im in imgs[:-1]]).astype(np.int64)
        hs = np.array([im.shape[0] for im in imgs], np.int64)
        ws = np.array([im.shape[1] for im in imgs], np.int64)
        xs, ys = np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1])
        raw = np.empty(n)
    for k in track(range(len(z)), desc="refocus: planes", progress=progress, unit="plane"):
        if warp == "homography":
            hom = np.stack([plane_homography(m, z[k]) for m in mappings]).astype(np.float64)
            fused(flat, offs, hs, ws, hom, xs, ys, raw)
        else:
            acc = np.zeros(n)
            cnt = np.zeros(n)
            pts = np.column_stack([xy, np.full(n, z[k])])
            for im, m in zip(imgs, mappings, strict=True):
                uv = m.project(pts)
                h, w = im.shape
                inside = (uv[:, 0] >= 0) & (uv[:, 0] <= w) & (uv[:, 1] >= 0) & (uv[:, 1] <= h)
                acc += ndimage.map_coordinates(im, [uv[:, 1] - 0.5, uv[:, 0] - 0.5], order=1, mode="constant",
                                               cval=0.0)
                cnt += inside
            raw = np.where(cnt > 0, acc / np.maximum(cnt, 1), 0.0)
        mu[k], sigma[k] = noise_normal_fit(raw)
        peak[k] = raw.max()
        mean[k], std[k] = raw.mean(), raw.std()
        planes[k] = raw if threshold_k is None else np.where(raw > mu[k] + threshold_k * sigma[k], raw, 0.0)
    return RefocusResult(planes, mu, sigma, peak, mean, std)
