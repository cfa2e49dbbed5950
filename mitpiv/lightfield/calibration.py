"""Microlens-array calibration from a white (uniformly lit) raw image.

Lenslet-image centres are found to sub-pixel accuracy, then a lattice (rect or hex:
origin, pitch, rotation; a similarity, as a rigid MLA on a square-pixel sensor is) is fitted
to them by least squares with outlier rejection, and every lenslet image inside the sensor
is predicted from the fit. Spot centres come from the centroid of the spot above half its
own peak, which the cos^4 shading across a spot biases far less than an intensity centroid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree

from mitpiv.errors import CalibrationError, ConfigError

__all__ = ["MLACalibration", "calibrate_mla", "calibration_from_camera", "calibration_error"]


def _shape_matrix(layout: str) -> np.ndarray:
    """``b2 = Q b1`` for the layout (rect: +90 deg, hex: +60 deg)."""
    ang = math.pi / 2 if layout == "rect" else math.pi / 3
    return np.array([[math.cos(ang), -math.sin(ang)], [math.sin(ang), math.cos(ang)]])


@dataclass
class MLACalibration:
    """Lenslet-image lattice in raw-pixel coordinates ``(u, v)`` (pixel (i, j) spans [i, i+1)).

    Attributes
    ----------
    layout : "rect" | "hex"
    basis_px : (2, 2) rows ``b1`` (along a lenslet row) and ``b2`` (next row)
    origin_px : (2,) centre of the lenslet image with axial index (0, 0)
    axial : (N, 2) int axial indices ``(i, j)`` of the lenslet images used
    centres_px : (N, 2) their centres ``origin + i b1 + j b2``
    rms_residual_px : RMS distance of the detected spot centres from the fitted lattice
    n_detected : spots detected and used in the fit
    """

    layout: str
    basis_px: np.ndarray
    origin_px: np.ndarray
    axial: np.ndarray
    centres_px: np.ndarray
    rms_residual_px: float = 0.0
    n_detected: int = 0

    @property
    def pitch_px(self) -> float:
        return float(np.linalg.norm(self.basis_px[0]))

    @property
    def rotation_deg(self) -> float:
        return float(np.degrees(np.arctan2(self.basis_px[0, 1], self.basis_px[0, 0])))

    def to_dict(self) -> dict:
        return {"layout": self.layout, "basis_px": np.asarray(self.basis_px).tolist(),
                "origin_px": np.asarray(self.origin_px).tolist(), "pitch_px": self.pitch_px,
                "rotation_deg": self.rotation_deg, "lenslets": int(len(self.axial)),
                "rms_residual_px": self.rms_residual_px, "n_detected": self.n_detected}


def calibration_from_camera(camera, *, margin_px: float | None = None) -> MLACalibration:
    """The exact lenslet-image lattice of a :class:`~mitpiv.physics.plenoptic.PlenopticCamera`
    (lenslet images whose centre lies at least ``margin_px`` inside the sensor; default
    half a pitch)."""
    nx, ny = camera.mla_count
    row, col = np.mgrid[0:ny, 0:nx]
    i, j = camera.storage_to_axial(col, row)
    centres = camera.image_centres_px().reshape(-1, 2)
    scale = camera.image_scale / (camera.pixel_pitch_um * 1e-3)
    basis = camera.basis_mm * scale
    origin = camera.sensor_mm_to_px(camera.origin_mm * camera.image_scale)
    axial = np.column_stack([i.ravel(), j.ravel()])
    keep = _inside(centres, camera.resolution, 0.5 * np.linalg.norm(basis[0]) if margin_px is None else margin_px)
    return MLACalibration(camera.mla_layout, basis, origin, axial[keep], centres[keep])


def _inside(c, resolution, margin):
    w, h = resolution
    return (c[:, 0] >= margin) & (c[:, 0] <= w - margin) & (c[:, 1] >= margin) & (c[:, 1] <= h - margin)


def _estimate_pitch(img: np.ndarray, layout: str) -> float:
    """Lenslet pitch [px]: radius of the first ring of the image's autocorrelation peaks
    (the nearest lattice vectors; their length is the pitch for both layouts)."""
    h, w = img.shape
    f = np.fft.rfft2(img - img.mean())
    ac = np.fft.fftshift(np.fft.irfft2(np.abs(f) ** 2, s=img.shape))
    yy, xx = np.indices(ac.shape)
    r = np.hypot(xx - w // 2, yy - h // 2)
    rb = np.rint(r).astype(int)
    nmax = min(h, w) // 3
    prof = np.bincount(rb.ravel(), ac.ravel())[:nmax] / np.maximum(np.bincount(rb.ravel())[:nmax], 1)
    # The first shell of lattice vectors: the first local maximum of the radial profile
    # after its first local minimum (the edge of the central peak).
    k = 1
    while k < nmax - 1 and not (prof[k] <= prof[k - 1] and prof[k] <= prof[k + 1]):
        k += 1
    j = k + 1
    floor = prof[k] + 0.5 * (prof[k:].max() - prof[k])  # ignore ripples of the central peak's flank
    while j < nmax - 1 and not (prof[j] >= prof[j - 1] and prof[j] >= prof[j + 1] and prof[j] >= floor):
        j += 1
    if j >= nmax - 1:
        return float("nan")
    # Refine on the highest 2D peak within that shell.
    masked = np.where(np.abs(r - j) <= max(0.25 * j, 1.0), ac, -np.inf)
    iy, ix = np.unravel_index(np.argmax(masked), ac.shape)
    if not (0 < iy < h - 1 and 0 < ix < w - 1):
        return float("nan")

    def vertex(a, b, c):
        den = a - 2 * b + c
        return 0.5 * (a - c) / den if den < 0 else 0.0

    dx = ix + vertex(ac[iy, ix - 1], ac[iy, ix], ac[iy, ix + 1]) - w // 2
    dy = iy + vertex(ac[iy - 1, ix], ac[iy, ix], ac[iy + 1, ix]) - h // 2
    return float(np.hypot(dx, dy))


def _spot_centroids(img, est, pitch, iterations=4):
    """Centroid of each spot above half its local peak, within a soft-edged disk window
    (radius ~0.5 pitch) centred on the current estimate, iterated: the window is symmetric
    about the estimate, so the sub-pixel phase of the lattice does not bias the result."""
    h, w = img.shape
    half = int(math.ceil(0.6 * pitch)) + 1
    off = np.arange(-half, half + 1)
    r_in, r_out = 0.4 * pitch, 0.55 * pitch
    c = np.asarray(est, dtype=float)
    ok = np.ones(len(c), bool)
    for _ in range(iterations):
        ix = np.floor(c[:, 0]).astype(int)
        iy = np.floor(c[:, 1]).astype(int)
        ys = np.clip(iy[:, None, None] + off[None, :, None], 0, h - 1)
        xs = np.clip(ix[:, None, None] + off[None, None, :], 0, w - 1)
        patch = img[ys, xs]
        d = np.hypot(xs + 0.5 - c[:, 0, None, None], ys + 0.5 - c[:, 1, None, None])
        win = np.clip((r_out - d) / (r_out - r_in), 0.0, 1.0)
        top = (patch * (d <= r_in)).max(axis=(1, 2), keepdims=True)
        wgt = np.clip(patch - 0.5 * top, 0.0, None) * win
        tot = wgt.sum(axis=(1, 2))
        ok = tot > 0
        c = np.where(ok[:, None], np.column_stack([(wgt * (xs + 0.5)).sum(axis=(1, 2)), (wgt * (ys + 0.5)).sum(axis=(1, 2))])
                     / np.maximum(tot, 1e-300)[:, None], c)
    return c, ok


def _detect(img, p, min_relative_intensity):
    """Spot centres for an assumed pitch, or None if they do not form a lattice of that pitch."""
    smooth = ndimage.gaussian_filter(img, 0.2 * p)
    size = max(int(round(0.7 * p)), 3)
    level = np.percentile(smooth, 99.0)
    if level <= 0 or np.ptp(smooth) <= 1e-6 * level:
        raise CalibrationError("calibrate_mla: the white image has no spot structure (saturated or uniform).")
    peaks_mask = (smooth == ndimage.maximum_filter(smooth, size=size)) & (smooth > min_relative_intensity * level)
    yy, xx = np.nonzero(peaks_mask)
    half = max(int(math.ceil(0.45 * p)), 1)
    keep = (xx >= half) & (xx < img.shape[1] - half) & (yy >= half) & (yy < img.shape[0] - half)
    peaks = np.column_stack([xx[keep], yy[keep]]).astype(float)
    if len(peaks) < 6:
        return None
    c, ok = _spot_centroids(img, peaks + 0.5, p)
    c = c[ok]
    tree = cKDTree(c)
    _, idx = tree.query(c, k=min(7, len(c)))
    vec = c[idx[:, 1:]] - c[:, None, :]
    ln = np.linalg.norm(vec, axis=2)
    good = (ln > 0.8 * p) & (ln < 1.2 * p)
    if good.sum() < max(4, 0.5 * len(c)):
        return None
    return p, smooth, level, c, good, ln, vec


def calibrate_mla(white_image, *, layout: str, pitch_px: float | None = None, min_relative_intensity: float = 0.3,
                  max_rms_px: float = 0.5) -> MLACalibration:
    """Fit the lenslet-image lattice of a white raw image.

    Parameters
    ----------
    white_image : (H, W) array
        Raw image of a uniformly lit scene through the plenoptic camera.
    layout : "rect" | "hex"
    pitch_px : float, optional
        Approximate lenslet-image pitch [px]; default: from the power spectrum.
    min_relative_intensity : float
        Spots dimmer than this fraction of the 99th-percentile brightness are ignored
        (vignetted edges, gaps outside the array).
    max_rms_px : float
        Raise :class:`CalibrationError` when the detected centres scatter more than this
        about the fitted lattice.

    Returns
    -------
    MLACalibration
    """
    if layout not in ("rect", "hex"):
        raise ConfigError(f"calibrate_mla: 'layout' must be 'rect' or 'hex', got {layout!r}.")
    img = np.asarray(white_image, dtype=np.float64)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[..., 0]
    if img.ndim != 2 or min(img.shape) < 8:
        raise ConfigError(f"calibrate_mla: 'white_image' must be a 2D image of at least 8x8 pixels, got shape {img.shape}.")
    if not np.all(np.isfinite(img)):
        raise ConfigError("calibrate_mla: 'white_image' contains NaN or infinite values.")
    if img.max() <= 0:
        raise CalibrationError("calibrate_mla: the white image is all dark; render or record it with light.")
    if not 0 < min_relative_intensity < 1:
        raise ConfigError(f"calibrate_mla: 'min_relative_intensity' must lie in (0, 1), got {min_relative_intensity}.")
    if pitch_px is None:
        p0 = _estimate_pitch(img, layout)
        # The autocorrelation can lock onto a sub-harmonic; try the neighbouring shells too.
        candidates = [p0, 2.0 * p0, math.sqrt(3.0) * p0, math.sqrt(2.0) * p0, 0.5 * p0]
    else:
        candidates = [float(pitch_px)]
    found = None
    for p in candidates:
        if not 2.0 <= p <= min(img.shape) / 2:  # (also catches NaN)
            continue
        found = _detect(img, p, min_relative_intensity)
        if found is not None:
            break
    if found is None:
        raise CalibrationError(
            f"calibrate_mla: no {layout} lenslet lattice found (pitch estimate {candidates[0]:.4g} px); check "
            f"'layout', give 'pitch_px', or check that the image is a white image."
        )
    p, smooth, level, c, good, ln, vec = found
    period = math.pi / 2 if layout == "rect" else math.pi / 3
    ang = np.arctan2(vec[..., 1], vec[..., 0])[good] * (2 * math.pi / period)
    theta = math.atan2(np.sin(ang).mean(), np.cos(ang).mean()) * period / (2 * math.pi)
    pitch = float(np.median(ln[good]))
    q = _shape_matrix(layout)
    b1 = pitch * np.array([math.cos(theta), math.sin(theta)])
    centre = np.array(img.shape[::-1]) / 2.0
    origin = c[np.argmin(np.linalg.norm(c - centre, axis=1))]
    # Spots at the edge of the array have no neighbour on one side, which biases their
    # window centroids outwards; fit the lattice to spots with a full ring of neighbours.
    full = 4 if layout == "rect" else 6
    use = (good.sum(axis=1) >= full) if len(c) > 4 * full else np.ones(len(c), bool)
    if use.sum() < 6:
        use = np.ones(len(c), bool)
    for _ in range(4):
        basis = np.stack([b1, q @ b1])
        ij = np.rint(np.linalg.solve(basis.T, (c - origin).T).T).astype(int)
        # Least squares in (origin, b1): c = origin + (i I + j Q) b1.
        n = int(use.sum())
        a = np.zeros((2 * n, 4))
        a[0::2, 0] = 1.0
        a[1::2, 1] = 1.0
        m = ij[use, 0, None, None] * np.eye(2) + ij[use, 1, None, None] * q
        a[:, 2:] = m.reshape(2 * n, 2)
        sol, *_ = np.linalg.lstsq(a, c[use].reshape(-1), rcond=None)
        origin, b1 = sol[:2], sol[2:]
        basis = np.stack([b1, q @ b1])
        res = np.linalg.norm(c - origin - ij @ basis, axis=1)
        mad = np.median(res[use]) * 1.4826
        new = res < max(0.3, 4.0 * mad)
        if np.array_equal(new, use):
            break
        use = new
    rms = float(np.sqrt(np.mean(res[use] ** 2)))
    if rms > max_rms_px:
        raise CalibrationError(
            f"calibrate_mla: detected lenslet centres scatter {rms:.3f} px RMS about the fitted {layout} lattice "
            f"(limit max_rms_px={max_rms_px}); check 'layout' and 'pitch_px'."
        )
    # Predict every lattice position inside the sensor with a lit spot.
    h, w = img.shape
    corners = np.array([[0, 0], [w, 0], [0, h], [w, h]], float)
    cij = np.linalg.solve(basis.T, (corners - origin).T).T
    lo, hi = np.floor(cij.min(0)).astype(int) - 1, np.ceil(cij.max(0)).astype(int) + 1
    gi, gj = np.mgrid[lo[0]:hi[0] + 1, lo[1]:hi[1] + 1]
    allij = np.column_stack([gi.ravel(), gj.ravel()])
    cent = origin + allij @ basis
    inside = _inside(cent, (w, h), 0.5 * np.linalg.norm(b1))
    allij, cent = allij[inside], cent[inside]
    lit = ndimage.map_coordinates(smooth, [cent[:, 1] - 0.5, cent[:, 0] - 0.5], order=1) > min_relative_intensity * level
    return MLACalibration(layout, basis, origin, allij[lit], cent[lit], rms, int(use.sum()))


def calibration_error(calibration: MLACalibration, camera) -> dict:
    """Compare a calibration with the true geometry of a
    :class:`~mitpiv.physics.plenoptic.PlenopticCamera`: distances of the calibrated
    centres to the nearest true lenslet-image centres [px], pitch and rotation errors."""
    truth = calibration_from_camera(camera, margin_px=0.0)
    d, _ = cKDTree(truth.centres_px).query(calibration.centres_px)
    return {
        "lenslets": int(len(d)),
        "rms_px": float(np.sqrt(np.mean(d**2))),
        "max_px": float(d.max()),
        "pitch_error_px": calibration.pitch_px - truth.pitch_px,
        "rotation_error_deg": calibration.rotation_deg - truth.rotation_deg,
        "fit_rms_residual_px": calibration.rms_residual_px,
    }
