"""Tomographic and synthetic-aperture reconstruction from pinhole-camera images.

Every method is driven by camera mappings (``project``/``jacobian``: the true model from
EXR metadata or a fitted calibration, distortion included) and computes on a
:class:`VoxelGrid`. Voxel centres are projected into every image (voxel-driven, so no
camera has to look along a grid axis).

* :func:`mlos`: multiplicative line of sight, the product of the images interpolated at
  each voxel's projection (Atkinson & Soria 2009).
* :func:`mart`: MART (Elsinga et al. 2006; Herman & Lent 1976), or SMART (Atkinson &
  Soria 2009) with ``smart=True``, on sparse voxel-pixel weights, MLOS-initialised by
  default, with zero-pixel pruning.
* :func:`sapiv_refocus`: synthetic-aperture refocusing of a camera array (Belden et al.
  2010): every image reprojected onto each depth plane, combined additively or
  multiplicatively, thresholded at ``mean + k sigma`` of a normal fit per plane.

Weight models (``weights=``): ``"circle"``, the equal-area circle overlap of the TomoPIV
toolbox generalised to any voxel footprint (the voxel's projected area, from the mapping's
Jacobian, as a circle; the pixel as a circle of radius 0.564 px; weight = overlap area /
pixel area), and ``"gaussian"``, the voxel's projected box covariance ``J diag(d^2/12)
J^T`` widened by an isotropic PSF of ``psf_sigma_px`` (weight = projected area x Gaussian
density at the pixel centre, truncated at 3 sigma). Weights are never stored as a dense
matrix: they are computed once per camera for the voxels that survive pruning and kept
as a CSR matrix (pixels x active voxels, float32); a :class:`WeightCache` keeps them for the
next frame of the same cameras and grid (the experiment runner shares one across frames).

Speed (issue 26): for pinhole mappings the MLOS pass, the projections and the weight
footprints run in compiled kernels (``_kernels.py``; hand-written because they fuse the
camera model with the sampling and no library offers that), the CSR assembly reads
footprints computed in image-row order (a compiled counting sort), and the MART sweep
keeps the active voxels in float32 (the output's precision; 20 % faster than float64 on the
demo, max difference 1.5e-7 of the maximum) and evaluates its factor in single precision,
by a Taylor polynomial for the rows near convergence (issue 50: 1.3x at the published size,
the sweep being bound by the gathers of voxel values and the ``exp``, not by bandwidth).
The pre-issue code path is kept as the benchmark baseline in bench/reference_mart.py.
"""

from __future__ import annotations

import logging
import math
import time
import warnings

import numpy as np
from scipy import ndimage

from mitpiv.errors import ConfigError, MitpivWarning
from mitpiv.grid import VoxelGrid
from mitpiv.physics.camera import PinholeCamera
from mitpiv.progress import Progress, track
from mitpiv.reconstruct._kernels import CIRCLE, GAUSSIAN, PIXEL_RADIUS, camera_row, kernels
from mitpiv.reconstruct.mapping import CameraMapping, PinholeMapping, mapping_from_metadata

__all__ = ["mlos", "mart", "WeightCache", "sapiv_refocus", "preprocess_images", "voxel_weights", "INTERPOLATIONS", "WEIGHT_MODELS"]

log = logging.getLogger(__name__)

INTERPOLATIONS = ("linear", "cubic")
WEIGHT_MODELS = ("circle", "gaussian")


# ---------------------------------------------------------------------- inputs
def _as_mapping(m, index: int) -> CameraMapping:
    if isinstance(m, CameraMapping):
        return m
    if isinstance(m, PinholeCamera):
        return PinholeMapping(m)
    if isinstance(m, dict):
        return mapping_from_metadata(m)
    raise ConfigError(
        f"mappings[{index}] is a {type(m).__name__}; give a CameraMapping (e.g. from "
        f"mitpiv.reconstruct.calibrate), a PinholeCamera or an image's metadata dict."
    )


def _check_images(images, mappings, grid, what):
    if not isinstance(grid, VoxelGrid):
        raise ConfigError(f"{what}: 'grid' must be a VoxelGrid, got {type(grid).__name__}.")
    if isinstance(images, np.ndarray) and images.ndim == 2:
        images = [images]
    imgs = [np.asarray(im, dtype=np.float64) for im in images]
    maps = [_as_mapping(m, i) for i, m in enumerate(mappings if isinstance(mappings, list | tuple) else [mappings])]
    if len(imgs) == 0:
        raise ConfigError(f"{what}: no images given.")
    if len(imgs) != len(maps):
        raise ConfigError(f"{what}: {len(imgs)} images but {len(maps)} mappings; give one mapping per camera image.")
    for i, (im, m) in enumerate(zip(imgs, maps, strict=True)):
        if im.ndim != 2:
            raise ConfigError(f"{what}: images[{i}] must be a 2D (height, width) image, got shape {im.shape}.")
        if not np.all(np.isfinite(im)):
            raise ConfigError(f"{what}: images[{i}] contains {int(np.sum(~np.isfinite(im)))} NaN or infinite pixels.")
        if m.resolution is not None and tuple(m.resolution) != (im.shape[1], im.shape[0]):
            raise ConfigError(
                f"{what}: images[{i}] is {im.shape[1]}x{im.shape[0]} px but mappings[{i}] is for "
                f"{m.resolution[0]}x{m.resolution[1]} px; pair each image with its own camera."
            )
    # Negative pixels (noise after background subtraction) carry no light: clip them.
    return [np.maximum(im, 0.0) for im in imgs], maps


def check_iterations(what, iterations, mu) -> None:
    """ConfigError unless ``iterations`` is an integer >= 0 and the relaxation ``mu`` is in (0, 2)."""
    if isinstance(iterations, bool) or not isinstance(iterations, int | np.integer) or iterations < 0:
        raise ConfigError(f"{what}: 'iterations' must be an integer >= 0, got {iterations!r}.")
    if not (np.isfinite(mu) and 0 < mu < 2):
        raise ConfigError(f"{what}: relaxation 'mu' must lie in (0, 2), got {mu!r}.")


def _check_choice(what, name, value, choices):
    if value not in choices:
        raise ConfigError(f"{what}: '{name}' must be one of {choices}, got {value!r}.")


def preprocess_images(images, *, k: float | None = 2.0, smooth_px: float = 0.0,
                      floor_rel: float = 0.0) -> list[np.ndarray]:
    """Optional Gaussian smoothing, then histogram-based thresholding: subtract each image's
    background + ``k`` noise sigmas.

    ``smooth_px`` > 0 first convolves each image with a Gaussian of that sigma [px]
    (scipy.ndimage.gaussian_filter, reflecting edges), as tomographic PIV practice does before
    MART (e.g. a 3 x 3 Gaussian). It matters for noisy images clipped at 0 by the ADC: MART's
    multiplicative update zeroes every voxel that sees a zero pixel, so noise that clips a
    particle image's wings to 0 strips the particle to its brightest voxel (the channel-tomo
    replication: 8-bit images, noise 10 % of the peak, particle images 2 px across, 1,483
    active voxels for 3,974 particles and Q 0.32; smoothed with sigma 0.7 px: 118,649 active
    voxels, Q 0.44, and the PIV error falls from 0.9-1.3 to 0.07-0.12 voxel).

    The background level is the mode of the image histogram (mean of the fullest of 1024
    bins up to the 99.5th percentile), the noise sigma the root-mean-square deviation below the mode (the lower
    half of the background peak, free of particle light). Pixels at or below ``mode + k
    sigma`` become exactly zero, which is what lets MART prune the volume; the rest keep
    their excess over that level. A noise-free image (mode ~0, sigma ~0) keeps its light.

    When at least :data:`CLIPPED_FLOOR_SHARE` of the pixels sit at the image minimum (zero-mean
    noise clipped at 0 by an 8-bit ADC: the histogram's mode is the floor), the background is
    taken as a normal distribution clipped there and its mean and sigma come from the floor
    share and a quantile above it (:func:`_clipped_background`); the threshold is then
    ``mean + k sigma`` of that normal (``2 sigma`` for zero-mean noise at k = 2).

    Before MART keep ``k`` small: a threshold also cuts the wings of particle images, and
    MART's zero-pixel rule then removes voxels that hold particles (with 5 % background
    and 1 % noise, k = 0 keeps Q within 0.03 of the unprocessed images and prunes 97 % of
    the voxels; k = 2 loses 0.3 in Q).

    ``floor_rel`` > 0 finally sets every pixel below ``floor_rel`` times the image's largest
    value to exactly zero: the dynamic range of a camera (a 12-bit sensor records nothing below
    about 2.4e-4 of full scale). Noise-free rendered or analytic particle images have tails that
    never reach zero, so without a floor MLOS and the zero-pixel rule prune almost nothing (83 %
    of the voxels active at 0.05 ppp in the speed bench); a floor of 1e-3 keeps 28 % active, Q
    0.7912 against 0.7908, 2.0x faster in the same run (bench/bench_speed.py).

    Parameters
    ----------
    images : sequence of (H, W) arrays
    k : float >= 0, or None (smoothing only, no threshold)
    smooth_px : float >= 0
        Gaussian sigma [px] of the smoothing before the threshold (0: none).
    floor_rel : float in [0, 1)
        Pixels below this fraction of the image's maximum become zero (0: none).

    Returns
    -------
    list of float64 images
    """
    if k is not None and not (np.isfinite(k) and k >= 0):
        raise ConfigError(f"preprocess_images: 'k' must be finite and >= 0 (or None for no threshold), got {k!r}.")
    if not (np.isfinite(smooth_px) and 0 <= smooth_px <= 10):
        raise ConfigError(f"preprocess_images: 'smooth_px' must be a Gaussian sigma in [0, 10] px, got {smooth_px!r}; "
                          f"0 turns the smoothing off.")
    if not (np.isfinite(floor_rel) and 0 <= floor_rel < 1):
        raise ConfigError(f"preprocess_images: 'floor_rel' must be a fraction of the image maximum in [0, 1), got "
                          f"{floor_rel!r}; 0 turns the floor off (1e-3 is about a 10-bit camera's range).")
    out = []
    for i, im in enumerate([images] if isinstance(images, np.ndarray) and images.ndim == 2 else images):
        a = np.asarray(im, dtype=np.float64)
        if a.ndim != 2 or not np.all(np.isfinite(a)):
            raise ConfigError(f"preprocess_images: images[{i}] must be a finite 2D image, got shape {a.shape}.")
        if smooth_px > 0:
            from scipy import ndimage

            a = ndimage.gaussian_filter(a, float(smooth_px), mode="reflect")
        if k is None:
            out.append(a)
            continue
        lo, hi = float(a.min()), float(np.percentile(a, 99.5))
        if hi <= lo:
            out.append(np.maximum(a - lo, 0.0) if lo > 0 else a.copy())
            continue
        p0 = float(np.mean(a <= lo))  # share of pixels at the floor (clipped negative noise)
        clipped = _clipped_background(a, lo, p0) if p0 >= CLIPPED_FLOOR_SHARE else None
        if clipped is not None:
            mode, sigma = clipped
        else:
            counts, edges = np.histogram(a, bins=1024, range=(lo, hi))
            peak = counts.argmax()
            in_peak = a[(a >= edges[peak]) & (a <= edges[peak + 1])]
            mode = float(in_peak.mean())  # the background level: mean of the histogram's peak bin
            below = a[a <= mode]
            sigma = float(np.sqrt(np.mean((below - mode) ** 2))) if below.size else 0.0
        out.append(np.maximum(a - (mode + k * sigma), 0.0))
    if floor_rel > 0:
        out = [np.where(a >= floor_rel * a.max(), a, 0.0) for a in out]
    return out


#: Share of pixels at the image minimum above which :func:`preprocess_images` treats the
#: background as a normal distribution clipped at the floor (an ADC clips negative noise at 0).
CLIPPED_FLOOR_SHARE = 0.05
#: Largest misfit [sigma] of the clipped normal at a second quantile before the image is
#: treated as not clipped noise (a noise-free particle image).
CLIPPED_NORMAL_TOL = 0.5


def _clipped_background(a, floor, p0):
    """(mean, sigma) of a normal background clipped at ``floor`` (None when the pixels above
    the floor do not follow one), from the share ``p0`` of
    pixels at the floor and the quantile ``q1 = p0 + (1 - p0) / 4`` above it:
    ``floor = mu + sigma z(p0)`` and ``v(q1) = mu + sigma z(q1)`` (z the standard normal
    quantile). The histogram mode of such an image is the floor itself and nothing lies
    below it, so the mode / lower-half estimate finds no noise there. Particle light only
    enters above ``q1`` unless particles cover more than a quarter of the pixels above the floor."""
    from scipy.special import ndtri

    if np.all(a == np.round(a)):  # integer counts: the floor holds everything below floor + 0.5
        floor = floor + 0.5
    q1 = p0 + 0.25 * (1.0 - p0)
    v1 = float(np.quantile(a, q1))
    dz = float(ndtri(q1) - ndtri(min(p0, 1.0 - 1e-12)))
    if v1 <= floor or dz <= 0:
        return None
    sigma = (v1 - floor) / dz
    mu = floor - sigma * float(ndtri(min(p0, 1.0 - 1e-12)))
    # a clipped normal also predicts the quantile three quarters up; particle light alone (a
    # noise-free image: most pixels exactly 0, long-tailed wings) does not follow it
    q2 = p0 + 0.75 * (1.0 - p0)
    if abs(float(np.quantile(a, q2)) - (mu + sigma * float(ndtri(q2)))) > CLIPPED_NORMAL_TOL * sigma:
        return None
    return mu, float(sigma)


# ---------------------------------------------------------------------- sampling
def _sampler(image, interpolation):
    """Function uv (n, 2) -> interpolated values (0 outside the image, clipped >= 0)."""
    if interpolation == "cubic":
        coef = ndimage.spline_filter(image, order=3, mode="constant")

        def sample(uv):
            v = ndimage.map_coordinates(coef, [uv[:, 1] - 0.5, uv[:, 0] - 0.5], order=3, mode="constant",
                                        cval=0.0, prefilter=False)
            return np.maximum(v, 0.0)
    else:
        def sample(uv):
            return ndimage.map_coordinates(image, [uv[:, 1] - 0.5, uv[:, 0] - 0.5], order=1, mode="constant", cval=0.0)
    return sample


def _inside(uv, image):
    h, w = image.shape
    return (uv[:, 0] >= 0) & (uv[:, 0] <= w) & (uv[:, 1] >= 0) & (uv[:, 1] <= h)


def _project(m, pts):
    """Pixels of world points; points behind the camera go far outside the image."""
    uv = m.project(pts)
    uv[~m.in_front(pts)] = -1e9
    return uv


def _plane_projections(maps, grid, k):
    pts = grid.plane_points(k).reshape(-1, 3)
    return [_project(m, pts) for m in maps]


def _check_coverage(maps, imgs, grid, what):
    """ConfigError for a camera whose image no voxel projects into."""
    corners = np.array([[x, y, z] for x in (grid.x_mm[0], grid.x_mm[-1]) for y in (grid.y_mm[0], grid.y_mm[-1])
                        for z in (grid.z_mm[0], grid.z_mm[-1])])
    ks = sorted({0, grid.shape[0] // 2, grid.shape[0] - 1})
    for c, (m, im) in enumerate(zip(maps, imgs, strict=True)):
        seen = any(np.any(_inside(_plane_projections([m], grid, k)[0], im)) for k in ks)
        uv = _project(m, corners)
        if not seen and not np.any(_inside(uv, im)):
            front = m.in_front(corners)
            where = ("the grid lies behind it" if not np.any(front) else
                     f"its corners project to u in [{uv[front, 0].min():.0f}, {uv[front, 0].max():.0f}], v in "
                     f"[{uv[front, 1].min():.0f}, {uv[front, 1].max():.0f}] px")
            raise ConfigError(
                f"{what}: camera {c} sees none of the voxel grid ({where} "
                f"on a {im.shape[1]}x{im.shape[0]} image). Check the camera's mapping or the grid bounds."
            )


def _combine(samples, inside, method, exponent):
    """Per-voxel combination of the cameras' interpolated intensities."""
    s = np.stack(samples)
    if method == "additive":
        n = inside.sum(axis=0)
        return np.where(n > 0, s.sum(axis=0) / np.maximum(n, 1), 0.0)
    # multiplicative, in log space: exp(n sum log I); a zero (or unseen) sample gives 0
    with np.errstate(divide="ignore"):
        lg = np.log(np.where(inside, s, 0.0))
    return np.exp(exponent * lg.sum(axis=0))


def _volume_by_planes(imgs, maps, grid, interpolation, method, exponent, per_plane=None, progress=None, what=""):
    samplers = [_sampler(im, interpolation) for im in imgs]
    out = np.empty(grid.shape, np.float32)
    t0 = time.perf_counter()
    for k in track(range(grid.shape[0]), desc=f"{what}: planes", progress=progress, unit="plane"):
        uvs = _plane_projections(maps, grid, k)
        inside = np.stack([_inside(uv, im) for uv, im in zip(uvs, imgs, strict=True)])
        val = _combine([f(uv) for f, uv in zip(samplers, uvs, strict=True)], inside, method, exponent)
        plane = val.reshape(grid.shape[1:])
        out[k] = per_plane(plane) if per_plane else plane
    log.debug("%s: %d planes in %.1f s", what, grid.shape[0], time.perf_counter() - t0)
    return out


def _exponent(exponent, n, what):
    e = 1.0 / n if exponent is None else exponent
    if not (np.isfinite(e) and 0 < e <= 1):
        raise ConfigError(f"{what}: 'exponent' must lie in (0, 1] (default 1/N for N cameras), got {exponent!r}.")
    return float(e)


def _warn_dark(imgs, what):
    for c, im in enumerate(imgs):
        if not np.any(im > 0):
            warnings.warn(f"{what}: image {c} is entirely dark; a multiplicative reconstruction is zero everywhere.",
                          MitpivWarning, stacklevel=3)


def mlos(images, mappings, grid: VoxelGrid, *, interpolation: str = "linear", exponent: float | None = None,
         progress: Progress = None) -> np.ndarray:
    """Multiplicative line-of-sight (MLOS) volume.

    ``E(x) = (prod_c I_c(P_c(x)))^exponent`` with ``I_c`` interpolated at the projection
    ``P_c(x)`` of the voxel centre; zero where any camera sees no light or does not see the
    voxel. Computed in log space per plane (no underflow for many cameras or tiny values).
    Pinhole cameras with bilinear interpolation take one Dr.Jit kernel per block of planes
    (:mod:`mitpiv.reconstruct._drjit`; 288x192x130 voxels, 4 cameras: 0.09 s against 1.2 s
    for the per-plane NumPy path, values equal to float32 rounding).

    Parameters
    ----------
    images : sequence of (H, W) arrays
    mappings : sequence of CameraMapping / PinholeCamera / metadata dicts, one per image
    grid : VoxelGrid
    interpolation : "linear" | "cubic"
        Bilinear, or cubic B-spline (negative overshoots clipped to 0).
    exponent : float in (0, 1], optional
        Default ``1/N`` (the geometric mean, which keeps image intensity units); 1 gives
        Atkinson & Soria's plain product.
    progress : None, bool or callable
        One step per depth plane; see :mod:`mitpiv.progress`.

    Returns
    -------
    (n_z, n_y, n_x) float32 volume
    """
    imgs, maps = _check_images(images, mappings, grid, "mlos")
    _check_choice("mlos", "interpolation", interpolation, INTERPOLATIONS)
    e = _exponent(exponent, len(imgs), "mlos")
    _check_coverage(maps, imgs, grid, "mlos")
    _warn_dark(imgs, "mlos")
    from mitpiv.reconstruct import _drjit

    rows = _pinhole_rows(maps) if interpolation == "linear" else None
    if rows is not None and _drjit.available():
        out = np.empty(grid.shape, np.float32)
        for k0, val, _ in _drjit.mlos_blocks(imgs, rows, grid, e, progress=progress, desc="mlos: planes"):
            block = val.reshape(-1, *grid.shape[1:])
            out[k0:k0 + len(block)] = block
        return out
    return _volume_by_planes(imgs, maps, grid, interpolation, "multiplicative", e, progress=progress, what="mlos")


def sapiv_refocus(images, mappings, grid: VoxelGrid, *, method: str = "additive", exponent: float | None = None,
                  threshold_k: float | None = 3.0, interpolation: str = "linear", progress: Progress = None) -> np.ndarray:
    """Synthetic-aperture refocusing of a camera array onto the grid's depth planes.

    Every image is reprojected onto each plane through its mapping (distortion included
    when the mapping has it), then combined:

    * ``additive``: the mean over the cameras that see the point;
    * ``multiplicative``: ``prod_c I_c^n`` with ``n = exponent`` (default ``1/N``).

    Then each refocused plane is thresholded (Belden et al. 2010): a normal distribution
    is fitted to its histogram (maximum likelihood: mean ``mu`` and std ``sigma``) and only
    values above ``mu + threshold_k sigma`` are kept (others zero).

    Parameters
    ----------
    threshold_k : float or None
        ``k`` of the threshold (3 by default); None keeps the raw refocused planes.

    Returns
    -------
    (n_z, n_y, n_x) float32 volume (the stack of refocused planes)
    """
    imgs, maps = _check_images(images, mappings, grid, "sapiv_refocus")
    _check_choice("sapiv_refocus", "method", method, ("additive", "multiplicative"))
    _check_choice("sapiv_refocus", "interpolation", interpolation, INTERPOLATIONS)
    e = _exponent(exponent, len(imgs), "sapiv_refocus")
    if threshold_k is not None and not (np.isfinite(threshold_k) and threshold_k >= 0):
        raise ConfigError(f"sapiv_refocus: 'threshold_k' must be >= 0 or None, got {threshold_k!r}.")
    _check_coverage(maps, imgs, grid, "sapiv_refocus")

    def threshold(plane):
        if threshold_k is None:
            return plane
        mu, sigma = plane.mean(), plane.std()
        return np.where(plane > mu + threshold_k * sigma, plane, 0.0)

    return _volume_by_planes(imgs, maps, grid, interpolation, method, e, per_plane=threshold, progress=progress,
                             what="sapiv_refocus")


# ---------------------------------------------------------------------- weights
def _footprints(mapping, pts, grid, model, psf_sigma_px):
    """Per voxel: support radius [px] and the weight model's four parameters."""
    jac = mapping.jacobian(pts)  # (n, 2, 3) px/mm
    d = np.asarray(grid.voxel_mm)
    a = jac * d  # columns: the voxel's edge vectors in the image
    area = (np.abs(a[:, 0, 0] * a[:, 1, 1] - a[:, 0, 1] * a[:, 1, 0]) + np.abs(a[:, 0, 1] * a[:, 1, 2] - a[:, 0, 2] * a[:, 1, 1])
            + np.abs(a[:, 0, 0] * a[:, 1, 2] - a[:, 0, 2] * a[:, 1, 0]))  # projected box (zonotope) area [px^2]
    n = len(pts)
    if model == "circle":
        rv = np.sqrt(area / math.pi)
        z = np.zeros(n)
        return rv + PIXEL_RADIUS, rv, z, z, z
    cov = np.einsum("nik,njk->nij", a, a) / 12.0 + psf_sigma_px**2 * np.eye(2)
    det = cov[:, 0, 0] * cov[:, 1, 1] - cov[:, 0, 1] ** 2
    lam = 0.5 * (cov[:, 0, 0] + cov[:, 1, 1]) + np.sqrt(0.25 * (cov[:, 0, 0] - cov[:, 1, 1]) ** 2 + cov[:, 0, 1] ** 2)
    return (3.0 * np.sqrt(lam) + 0.75, cov[:, 1, 1] / det, -cov[:, 0, 1] / det, cov[:, 0, 0] / det,
            area / (2 * math.pi * np.sqrt(det)))


class _CameraWeights:
    """CSR weights of one camera over the active voxels."""

    def __init__(self, indptr, indices, data, width, span, n_voxels):
        self.indptr, self.indices, self.data = indptr, indices, data
        self.width, self.span, self.n_voxels = width, span, int(n_voxels)
        self._wsum = None
        self._wmax = None

    @property
    def wsum(self) -> np.ndarray:
        """Per-voxel sum of this camera's weights (float64), computed on first use: only SMART
        needs it (a scatter over every weight entry, 1.6 s per camera on the demo)."""
        if self._wsum is None:
            self._wsum = np.bincount(self.indices, weights=self.data, minlength=self.n_voxels)
        return self._wsum

    @property
    def wmax(self) -> float:
        """Largest weight (computed on first use): bounds ``|lr w|`` for the MART sweep's
        Taylor factor (``_kernels.mart_row_f32``)."""
        if self._wmax is None:
            self._wmax = float(self.data.max()) if len(self.data) else 0.0
        return self._wmax

    @property
    def nbytes(self) -> int:
        return self.indptr.nbytes + self.indices.nbytes + self.data.nbytes


def _build_weights(uv, fp, model, shape_hw):
    """CSR (pixel rows) of one camera, assembled in parallel over image rows."""
    h, w = shape_hw
    v_all = np.asarray(uv[:, 1], dtype=np.float64)
    # voxels bucketed by the image row of their projected centre (clamped onto the image);
    # the footprints are sorted by bucket so the row kernel reads them sequentially
    # (a stable sort of 16-bit keys is NumPy's radix sort: 3x the int64 merge sort)
    crow = np.clip(np.floor(v_all), 0, h - 1).astype(np.int16 if h <= np.iinfo(np.int16).max else np.int64)
    order = np.argsort(crow, kind="stable")
    bucket = np.zeros(h + 1, np.int64)
    np.cumsum(np.bincount(crow, minlength=h), out=bucket[1:])
    del crow
    u, v = (np.ascontiguousarray(uv[order, i], dtype=np.float64) for i in (0, 1))
    rad = np.ascontiguousarray(fp[0][order], dtype=np.float64)
    pars = tuple(np.ascontiguousarray(a[order], dtype=np.float64) for a in fp[1:])
    return _assemble(u, v, rad, pars, order, bucket, model, shape_hw)


def _build_weights_pinhole(row, ids, grid, model, psf, shape_hw):
    """:func:`_build_weights` for a packed pinhole camera (the same matrix): the image rows
    of the voxels first, a compiled counting sort, then the footprints computed directly in
    bucket order (no argsort, no gather of seven footprint arrays: 1.3 s less per camera of
    the demo's 12.8 M voxels)."""
    k = kernels()
    h = shape_hw[0]
    crow = np.empty(len(ids), np.int32)
    k["pinhole_image_rows"](ids, grid.x_mm, grid.y_mm, grid.z_mm, row, h, crow)
    order = np.empty(len(ids), np.int64)
    bucket = np.empty(h + 1, np.int64)
    k["counting_order"](crow, h, order, bucket)
    del crow
    u, v, fp = _footprints_pinhole(row, ids[order], grid, model, psf, dtype=np.float64)  # float32-rounded values
    return _assemble(u, v, fp[0], fp[1:], order, bucket, model, shape_hw)


def _assemble(u, v, rad, pars, order, bucket, model, shape_hw):
    """Count, then fill, the CSR entries from footprints sorted by image-row bucket."""
    k = kernels()
    h, w = shape_hw
    rmax, span = k["support_extent"](v, rad) if len(rad) else (0.0, 1)
    reach = int(math.ceil(rmax)) + 1 if len(rad) else 0
    counts = np.zeros(h * w + 1, np.int64)
    args = (u, v, rad, *pars, CIRCLE if model == "circle" else GAUSSIAN, h, w, order, bucket, reach)
    k["row_pass_sorted"](*args, counts, counts, np.zeros(0, np.int32), np.zeros(0, np.float32), False)
    indptr = np.cumsum(counts)
    indices = np.empty(indptr[-1], np.int32)
    data = np.empty(indptr[-1], np.float32)
    k["row_pass_sorted"](*args, counts, indptr[:-1].copy(), indices, data, True)
    return _CameraWeights(indptr, indices, data, w, max(span, 1), len(u))


def _check_weight_options(what, weights, psf_sigma_px):
    _check_choice(what, "weights", weights, WEIGHT_MODELS)
    if not (np.isfinite(psf_sigma_px) and psf_sigma_px >= 0):
        raise ConfigError(f"{what}: 'psf_sigma_px' must be >= 0, got {psf_sigma_px!r}.")
    if weights == "gaussian" and psf_sigma_px == 0:
        psf_sigma_px = 1e-3
    return psf_sigma_px


def voxel_weights(mapping, grid: VoxelGrid, voxels, *, weights: str = "circle", psf_sigma_px: float = 0.5,
                  resolution=None):
    """Sparse voxel-pixel weights of one camera as a ``scipy.sparse.csr_matrix``.

    Parameters
    ----------
    mapping : CameraMapping or PinholeCamera
    grid : VoxelGrid
    voxels : (n,) int
        Flat voxel indices (the matrix columns, in this order).
    weights : "circle" | "gaussian"
    psf_sigma_px : float
        PSF standard deviation of the Gaussian model [px].
    resolution : (W, H), optional
        Image size (default the mapping's).

    Returns
    -------
    csr_matrix of shape (H * W, n): row ``v * W + u`` is pixel ``(u, v)``.
    """
    from scipy.sparse import csr_matrix

    m = _as_mapping(mapping, 0)
    psf = _check_weight_options("voxel_weights", weights, psf_sigma_px)
    res = resolution or m.resolution
    if res is None:
        raise ConfigError("voxel_weights: the mapping has no resolution; give resolution=(W, H).")
    idx = np.asarray(voxels, dtype=np.int64).ravel()
    pts = grid.centres(idx)
    cw = _build_weights(m.project(pts), _footprints(m, pts, grid, weights, psf), weights, (res[1], res[0]))
    return csr_matrix((cw.data, cw.indices, cw.indptr), shape=(res[0] * res[1], len(idx)))


# ---------------------------------------------------------------------- MART / SMART
def _pinhole_rows(maps):
    """(n_cameras, 20) packed cameras when every mapping is a PinholeMapping (the compiled
    fast path), else None (the generic NumPy path)."""
    if all(type(m) is PinholeMapping for m in maps):
        return np.stack([camera_row(m.camera) for m in maps])
    return None


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


def _candidates_pinhole(imgs, rows, grid, prune, progress, what, engine=None):
    """:func:`_candidates` (linear interpolation) in compiled passes: flat indices and MLOS
    values of the candidate voxels (their projections are recomputed with the footprints,
    cheaper than storing them). ``engine``: "drjit" (one Dr.Jit kernel per block of planes,
    :mod:`mitpiv.reconstruct._drjit`; the default when Dr.Jit's LLVM backend is there) or
    "numba" (one compiled call per plane); both give the same values."""
    from mitpiv.reconstruct import _drjit

    engine = engine or ("drjit" if _drjit.available() else "numba")
    nyx = grid.shape[1] * grid.shape[2]
    idx, init = [], []
    if engine == "drjit":
        for k0, val, seen in _drjit.mlos_blocks(imgs, rows, grid, 1.0 / len(imgs), progress=progress,
                                                desc=f"{what}: MLOS planes"):
            sel = np.flatnonzero(val > 0 if prune else seen)
            # no copies where none are needed: fresh 100 MB arrays cost ~0.4 s of page faults here
            init.append(val if len(sel) == len(val) else val[sel])
            sel += k0 * nyx
            idx.append(sel)
        return (idx[0], init[0]) if len(idx) == 1 else (np.concatenate(idx), np.concatenate(init))
    k = kernels()
    flat = np.concatenate([np.asarray(im, np.float64).ravel() for im in imgs])
    xs, ys, zs = grid.x_mm, grid.y_mm, grid.z_mm
    offs = np.concatenate([[0], np.cumsum([im.size for im in imgs])[:-1]]).astype(np.int64)
    hs = np.array([im.shape[0] for im in imgs], np.int64)
    ws = np.array([im.shape[1] for im in imgs], np.int64)
    val = np.empty(nyx)
    keep = np.empty(nyx, np.bool_)
    for kz in track(range(grid.shape[0]), desc=f"{what}: MLOS planes", progress=progress, unit="plane"):
        k["mlos_pinhole"](xs, ys, float(zs[kz]), rows, flat, offs, hs, ws, 1.0 / len(imgs), bool(prune), val, keep)
        sel = np.flatnonzero(keep)
        idx.append(sel + kz * nyx)
        init.append(val[sel])
    return np.concatenate(idx), np.concatenate(init)


def _footprints_pinhole(row, ids, grid, model, psf, dtype=np.float32):
    """Projections (float32, as the generic path stores them) and footprints (float32) of
    voxels ``ids`` for one packed camera: (u, v, [radius, p0, p1, p2, p3]); ``dtype``
    float64 holds the same float32-rounded values in float64 arrays."""
    out = [np.empty(len(ids), dtype) for _ in range(7)]
    kernels()["footprints_pinhole"](np.ascontiguousarray(ids, np.int64), grid.x_mm, grid.y_mm, grid.z_mm, row,
                                    *(float(d) for d in grid.voxel_mm), CIRCLE if model == "circle" else GAUSSIAN,
                                    float(psf) ** 2, *out)
    return out[0], out[1], out[2:]


class WeightCache:
    """Voxel-pixel weights kept between :func:`mart` calls on the same cameras and grid.

    The geometry does not change between the frames of an experiment: when a frame's
    active voxels (those surviving MLOS and zero-pixel pruning) are the same as the
    previous frame's, its weights are reused instead of rebuilt. Holds one set of weights
    (:attr:`nbytes`); drop the object (or :meth:`clear`) to free it.
    """

    def __init__(self):
        self.clear()

    def clear(self) -> None:
        self._key, self._idx, self._cams = None, None, None
        self.hits = 0

    @property
    def nbytes(self) -> int:
        if self._cams is None:
            return 0
        size = sum(c.nbytes if hasattr(c, "nbytes") else c.data.nbytes + c.indices.nbytes + c.indptr.nbytes
                   for c in self._cams)  # arrays, or a sparse matrix (DRT-MART)
        return int(size + self._idx.nbytes)

    def get(self, key, idx):
        if self._cams is not None and key == self._key and np.array_equal(idx, self._idx):
            self.hits += 1
            return self._cams
        return None

    def put(self, key, idx, cams) -> None:
        self._key, self._idx, self._cams = key, idx, cams


def _cache_key(maps, imgs, grid, model, psf):
    import json

    return (tuple(json.dumps(m.to_dict(), sort_keys=True, default=str) for m in maps),
            tuple(im.shape for im in imgs), json.dumps(grid.to_dict(), sort_keys=True), model, float(psf))


RESIDUALS = ("each", "final")


def mart(images, mappings, grid: VoxelGrid, *, iterations: int = 5, mu: float = 1.0, smart: bool = False,
         init="mlos", weights: str = "circle", psf_sigma_px: float = 0.5, interpolation: str = "linear",
         prune: bool = True, preprocess: float | None = None, smooth_px: float = 0.0, floor_rel: float = 0.0,
         chunk: int = 1_000_000,
         progress: Progress = None, return_info: bool = False, cache: WeightCache | None = None,
         residuals: str = "each"):
    """MART or SMART reconstruction on sparse voxel-pixel weights.

    MART (``smart=False``; Elsinga et al. 2006): for every pixel ``i`` of every camera in
    turn, ``E_j <- E_j (I_i / sum_j w_ij E_j)^(mu w_ij)``. SMART (Atkinson & Soria 2009):
    all pixels of all cameras at once, ``E_j <- E_j prod_i (I_i / sum_k w_ik E_k)^(mu w_ij /
    sum_i w_ij)``, evaluated in log space.

    Voxels: with ``prune`` (default) only those whose MLOS value is positive are
    reconstructed, and among them those that give weight to a zero pixel in any camera
    are zero from the start (the first MART update would zero them); without ``prune``,
    every voxel that all cameras see. Voxels outside that set are zero in the result.

    Pinhole mappings (:class:`PinholeMapping`, the true or a fitted pinhole + Brown-Conrady
    model) with linear interpolation take a compiled path for the MLOS pass and the weight
    footprints; other mappings the generic NumPy one (same result).

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
    smooth_px : float >= 0
        Gaussian smoothing of the images [px] before the threshold (:func:`preprocess_images`);
        0 (default) leaves them as they are. Use it for noisy images clipped at 0, whose zero
        pixels inside particle images would otherwise zero the particles' voxels.
    floor_rel : float in [0, 1)
        Pixels below this fraction of each image's maximum are set to zero first
        (:func:`preprocess_images`): the camera's dynamic range, which lets MLOS prune the
        volume when the images' particle tails never reach zero (0, the default: no floor).
    chunk : int
        Voxels per batch when computing weight footprints on the generic path (bounds
        temporary memory).
    progress : None, bool or callable
        One step per MLOS plane (desc ``"mart: MLOS planes"``), then one per iteration
        (``"mart: iterations"``); see :mod:`mitpiv.progress`.
    return_info : bool
        Also return a dict: active voxels, weight entries and bytes, the image residual
        ``||I - W E|| / ||I||`` (see ``residuals``), timings, whether the weights came from
        ``cache``.
    cache : WeightCache, optional
        Reuse the weights of the previous call when cameras, grid, weight model and active
        voxels are the same (the frames of one experiment), and keep this call's.
    residuals : "each" | "final"
        With ``return_info``: the residual after every iteration, or only after the last
        (each costs about a quarter of a MART sweep).

    Returns
    -------
    (n_z, n_y, n_x) float32 volume, or ``(volume, info)``
    """
    what = "smart" if smart else "mart"
    for i, im in enumerate([images] if isinstance(images, np.ndarray) and images.ndim == 2 else images):
        if np.any(np.asarray(im) < 0):
            a = np.asarray(im)
            raise ConfigError(f"{what}: images[{i}] has {int(np.sum(a < 0))} negative pixel(s) (min {a.min():.4g}); "
                              f"MART multiplies each voxel by measured / projected intensity, which a negative "
                              f"intensity makes meaningless. Clip the image at 0 (np.maximum(image, 0)) or subtract "
                              f"less background first.")
    imgs, maps = _check_images(images, mappings, grid, what)
    if len(imgs) == 1:
        warnings.warn(f"{what}: one camera: MART with one view cannot resolve depth (every voxel on a pixel's line of "
                      f"sight gets the same update, so particles smear along the viewing direction); use two or more "
                      f"cameras, or method 'drt-mart' / 'plenoptic' for a light-field camera.", MitpivWarning,
                      stacklevel=2)
    check_iterations(what, iterations, mu)
    _check_choice(what, "interpolation", interpolation, INTERPOLATIONS)
    _check_choice(what, "residuals", residuals, RESIDUALS)
    psf = _check_weight_options(what, weights, psf_sigma_px)
    if cache is not None and not isinstance(cache, WeightCache):
        raise ConfigError(f"{what}: 'cache' must be a WeightCache or None, got {type(cache).__name__}.")
    if isinstance(init, str):
        _check_choice(what, "init", init, ("mlos", "uniform"))
    else:
        init_vol = grid.check_volume(init, "init").astype(np.float64)
        if not np.all(np.isfinite(init_vol)) or np.any(init_vol < 0):
            raise ConfigError(f"{what}: 'init' must be finite and >= 0.")
    if preprocess is not None or smooth_px or floor_rel:
        imgs = preprocess_images(imgs, k=preprocess, smooth_px=smooth_px, floor_rel=floor_rel)
    _check_coverage(maps, imgs, grid, what)
    _warn_dark(imgs, what)
    t0 = time.perf_counter()
    rows = _pinhole_rows(maps) if interpolation == "linear" else None
    if rows is not None:
        idx, e_mlos = _candidates_pinhole(imgs, rows, grid, prune, progress, what)
        uvs = None
    else:
        idx, e_mlos, uvs = _candidates(imgs, maps, grid, interpolation, prune, progress, what)
    t_mlos = time.perf_counter() - t0
    k = kernels()
    model = weights
    mcode = CIRCLE if model == "circle" else GAUSSIAN

    def footprints(c, sel, dtype=np.float32):
        """(u, v, footprints) of camera c for the voxels idx[sel]."""
        ids = idx[sel]
        if rows is not None:
            return _footprints_pinhole(rows[c], ids, grid, model, psf)
        out = [np.empty(len(ids), dtype) for _ in range(5)]
        for s in range(0, len(ids), chunk):
            part = _footprints(maps[c], grid.centres(ids[s : s + chunk]), grid, model, psf)
            for o, p in zip(out, part, strict=True):
                o[s : s + chunk] = p
        return uvs[c][sel, 0], uvs[c][sel, 1], out

    # Zero-pixel pruning, camera by camera
    alive = np.ones(len(idx), np.bool_)
    if prune:
        for c in range(len(maps)):
            if not np.any(imgs[c] <= 0):
                continue
            if rows is not None:  # footprints computed inside the check
                zero_dist = ndimage.distance_transform_cdt(imgs[c] > 0, metric="chessboard").astype(np.int32)
                k["survives_pinhole"](idx, grid.x_mm, grid.y_mm, grid.z_mm, rows[c], *(float(d) for d in grid.voxel_mm),
                                      mcode, float(psf) ** 2, imgs[c], zero_dist, alive)
                continue
            for s in range(0, len(idx), chunk):
                sl = slice(s, s + chunk)
                u, v, fp = footprints(c, sl, np.float64)
                a = alive[sl].copy()
                k["survives"](np.ascontiguousarray(u), np.ascontiguousarray(v), *fp, mcode, imgs[c], a)
                alive[sl] = a
    n_candidates = len(idx)
    if not alive.all():
        idx = idx[alive]
        if uvs is not None:
            uvs = [u[alive] for u in uvs]
    if isinstance(init, str):
        vol = e_mlos[alive].astype(np.float32) if init == "mlos" else np.ones(len(idx), np.float32)
    else:
        vol = init_vol.ravel()[idx].astype(np.float32)
    del e_mlos
    key = _cache_key(maps, imgs, grid, model, psf) if cache is not None else None
    cams = cache.get(key, idx) if cache is not None else None
    from_cache = cams is not None
    if cams is None:
        cams = []
        for c in range(len(maps)):
            if rows is not None:
                cams.append(_build_weights_pinhole(rows[c], idx, grid, model, psf, imgs[c].shape))
                continue
            u, v, fp = footprints(c, slice(None))
            uvs[c] = None
            cams.append(_build_weights(np.column_stack([u, v]), fp, model, imgs[c].shape))
            del u, v, fp
        if cache is not None:
            cache.put(key, idx, cams)
    t_setup = time.perf_counter() - t0
    flat = [np.ascontiguousarray(im.ravel()) for im in imgs]
    norm = math.sqrt(sum(float(f @ f) for f in flat)) or 1.0
    wsum = sum(cw.wsum for cw in cams) if smart else None
    res, t1 = [], time.perf_counter()
    proj = [np.empty(f.size) for f in flat]
    lr = [np.empty(f.size) for f in flat] if smart else []
    for it in track(range(iterations), desc=f"{what}: iterations", progress=progress):
        if smart:
            smart_sweep(cams, flat, vol, wsum, float(mu), proj, lr)
        else:
            for cw, f in zip(cams, flat, strict=True):
                k["mart_camera_f32"](cw.indptr, cw.indices, cw.data, f, cw.width, cw.span, vol, float(mu), cw.wmax)
        if return_info and (residuals == "each" or it == iterations - 1):
            res.append(_residual(cams, flat, proj, vol, k) / norm)
        log.debug("%s: iteration %d/%d, %.1f s", what, it + 1, iterations, time.perf_counter() - t1)
    t_iter = time.perf_counter() - t1
    log.info("%s: %d active voxels of %d candidates, setup %.1f s (MLOS %.1f s, weights %s), %d iterations %.1f s",
             what, len(idx), n_candidates, t_setup, t_mlos, "cached" if from_cache else "built", iterations, t_iter)
    out = np.zeros(grid.n_voxels, np.float32)
    out[idx] = vol
    out = out.reshape(grid.shape)
    if not return_info:
        return out
    wbytes = int(sum(c.nbytes for c in cams))
    info = {"active_voxels": int(len(idx)), "candidate_voxels": int(n_candidates),
            "weight_entries": int(sum(len(c.data) for c in cams)), "weight_bytes": wbytes,
            "memory_bytes": int(wbytes + (8 * len(vol) * len(cams) if smart else 0) + vol.nbytes + idx.nbytes
                                + sum(p.nbytes for p in proj) + sum(p.nbytes for p in lr)),
            "residuals": res, "setup_s": t_setup, "mlos_s": t_mlos, "iterate_s": t_iter,
            "row_span": [c.span for c in cams], "weights_cached": bool(from_cache),
            "fast_path": rows is not None}
    return out, info


def smart_sweep(cams, flat, vol, wsum, mu, proj, lr) -> None:
    """One SMART iteration in place on ``vol`` (active voxels): project, log ratios, back
    projection, update. ``proj``/``lr``: per-camera work arrays of the image size."""
    k = kernels()
    acc = np.zeros(len(vol))
    for cw, f, p, r in zip(cams, flat, proj, lr, strict=True):
        k["project"](cw.indptr, cw.indices, cw.data, vol, p)
        k["log_ratio"](f, p, r)
        k["back_project"](cw.indptr, cw.indices, cw.data, cw.width, cw.span, r, acc)
    k["smart_update"](vol, acc, wsum, mu)


def _residual(cams, flat, proj, vol, k) -> float:
    r = 0.0
    for cw, f, p in zip(cams, flat, proj, strict=True):
        k["project"](cw.indptr, cw.indices, cw.data, vol, p)
        r += float(np.sum((f - p) ** 2))
    return math.sqrt(r)


TOMO_METHODS = ("mlos", "mart", "smart", "sapiv")


def reconstruct_volume(images, mappings, grid: VoxelGrid, method: str = "mart", *, iterations: int = 5, mu: float = 1.0,
                       weights: str = "circle", interpolation: str = "linear", preprocess: float | None = None,
                       smooth_px: float = 0.0, combine: str = "multiplicative", threshold_k: float | None = 3.0,
                       progress: Progress = None, cache: WeightCache | None = None,
                       floor_rel: float = 0.0) -> tuple[np.ndarray, dict]:
    """One entry point for the camera-image methods (``mlos``, ``mart``, ``smart``,
    ``sapiv``, the latter combining by ``combine`` with per-plane ``threshold_k``); returns
    (volume, info), info from :func:`mart` (the final residual only) or empty. ``cache``: a
    :class:`WeightCache` shared by the frames of one experiment (MART/SMART)."""
    if method == "mlos":
        return mlos(images, mappings, grid, interpolation=interpolation, progress=progress), {}
    if method == "sapiv":
        return sapiv_refocus(images, mappings, grid, method=combine, interpolation=interpolation,
                             threshold_k=threshold_k, progress=progress), {}
    if method in ("mart", "smart"):
        return mart(images, mappings, grid, iterations=iterations, mu=mu, smart=method == "smart", weights=weights,
                    interpolation=interpolation, preprocess=preprocess, smooth_px=smooth_px, floor_rel=floor_rel,
                    progress=progress, return_info=True, cache=cache, residuals="final")
    raise ConfigError(f"reconstruct: method={method!r} is not one of {TOMO_METHODS}.")
