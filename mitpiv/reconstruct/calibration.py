"""Calibration: marker detection, labelling, mapping fits and plane homographies.

Pixel convention: mitpiv's (pixel ``(i, j)`` spans ``[i, i+1)``, centre ``i + 0.5``);
OpenCV puts pixel centres on integers, so coordinates are shifted by 0.5 at its boundary.

Every fit checks its input (enough markers, not degenerate, inside the image) and its
result (the RMS reprojection error against ``max_rms_px``) and raises
:class:`CalibrationError` instead of returning a bad fit.
"""

from __future__ import annotations

import numpy as np

from mitpiv.errors import CalibrationError, ConfigError
from mitpiv.physics.camera_fit import decompose_projection, dlt_matrix, fit_pinhole_camera
from mitpiv.reconstruct.mapping import SOLOFF_TERMS, CameraMapping, PinholeMapping, PolynomialMapping

__all__ = [
    "detect_dots",
    "detect_checkerboard",
    "label_markers",
    "calibrate",
    "calibrate_views",
    "plane_homographies",
    "apply_homography",
]

_DISTORTION_MODELS = ("none", "radial", "brown")


# ---------------------------------------------------------------------- detection
def _noise_sigma(img: np.ndarray) -> float:
    med = np.median(img)
    return 1.4826 * float(np.median(np.abs(img - med)))


def detect_dots(image, *, threshold: float | None = None, min_area_px: int = 3, max_area_px: int | None = None,
                grow_px: int = 2) -> np.ndarray:
    """Sub-pixel centres of bright dots: (n, 2) pixel coordinates (x = column, y = row).

    Background = the image median; threshold default: Otsu's on the background-subtracted
    image (at least 5 noise sigmas). Each connected blob above it is grown by ``grow_px``
    pixels and gives the centroid of the background-subtracted intensity over that region:
    using whole pixels rather than the part above the threshold avoids pixel locking
    (measured on rendered 4-6 px dots: 0.12 / 0.07 px RMS error with the thresholded
    centroid). Blobs touching the image border or outside the area limits are dropped.
    """
    from scipy import ndimage

    img = np.asarray(image, dtype=np.float64)
    if img.ndim != 2 or img.size == 0 or not np.all(np.isfinite(img)):
        raise ConfigError(f"detect_dots: image must be a finite 2D array, got shape {img.shape}.")
    sig = img - np.median(img)
    top = np.percentile(sig, 99.9)
    noise = _noise_sigma(img)
    if top <= 0 or top < 8 * noise:
        raise CalibrationError(
            f"detect_dots: no markers: the brightest pixels ({top:.3g} above the median) do not stand "
            f"out of the noise (sigma {noise:.3g}). Check the exposure, the target pose and the camera."
        )
    if threshold is None:
        hist, edges = np.histogram(sig, bins=256, range=(sig.min(), sig.max()))
        p = hist / hist.sum()
        w0 = np.cumsum(p)
        mu = np.cumsum(p * 0.5 * (edges[:-1] + edges[1:]))
        between = (mu[-1] * w0 - mu) ** 2 / np.maximum(w0 * (1 - w0), 1e-300)
        threshold = float(edges[np.argmax(between) + 1])
        threshold = max(threshold, 5 * noise)
    mask = sig > threshold
    labels, n = ndimage.label(mask)
    if n == 0:
        raise CalibrationError(f"detect_dots: no pixel exceeds the threshold {threshold:.3g}.")
    idx = np.arange(1, n + 1)
    area = ndimage.sum_labels(np.ones_like(sig), labels, idx)
    grown = labels
    if grow_px > 0:
        grown = ndimage.grey_dilation(labels, size=(2 * grow_px + 1, 2 * grow_px + 1))
        grown = np.where(labels > 0, labels, grown)
    cy, cx = np.array(ndimage.center_of_mass(sig, grown, idx)).T
    border = np.zeros(n + 1, bool)
    edge = np.concatenate([grown[0], grown[-1], grown[:, 0], grown[:, -1]])
    border[np.unique(edge)] = True
    keep = (area >= min_area_px) & ~border[1:]
    if max_area_px is not None:
        keep &= area <= max_area_px
    return np.column_stack([cx[keep] + 0.5, cy[keep] + 0.5])


def detect_checkerboard(image, rows: int, cols: int) -> np.ndarray:
    """Inner corners of a checkerboard (rows x cols), (rows * cols, 2) pixels, OpenCV's order.

    OpenCV's ``findChessboardCornersSB`` finds the board; ``cornerSubPix`` on the float
    image refines the corners (measured on a rendered 20-degree tilted board: SB alone is
    biased by 0.2 px, refined 0.003 px mean and 0.08 px RMS).
    """
    import cv2

    img = np.asarray(image, dtype=np.float64)
    if img.ndim != 2 or not np.all(np.isfinite(img)):
        raise ConfigError(f"detect_checkerboard: image must be a finite 2D array, got shape {img.shape}.")
    lo, hi = np.percentile(img, [0.5, 99.5])
    if hi <= lo:
        raise CalibrationError("detect_checkerboard: the image is flat (no pattern).")
    img8 = np.clip((img - lo) / (hi - lo) * 255, 0, 255).astype(np.uint8)
    found, corners = cv2.findChessboardCornersSB(img8, (cols, rows), flags=cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY)
    if not found:
        raise CalibrationError(
            f"detect_checkerboard: no {rows}x{cols} inner-corner checkerboard found; check rows/cols "
            f"(inner corners, not squares) and that the whole board is in the image."
        )
    c = corners.reshape(-1, 2).astype(np.float32)
    spacing = float(np.median(np.linalg.norm(np.diff(c.reshape(rows, cols, 2), axis=1), axis=-1)))
    win = int(np.clip(spacing / 3, 2, 10))
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 100, 1e-6)
    c = cv2.cornerSubPix(img.astype(np.float32), c.reshape(-1, 1, 2), (win, win), (-1, -1), crit)
    return c.reshape(-1, 2).astype(np.float64) + 0.5


def label_markers(detected_px, predicted_px, *, max_distance_px: float | None = None):
    """One-to-one labels of detections by a nominal projection of the markers.

    Each predicted marker takes its nearest detection within ``max_distance_px`` (default
    0.4 x the smallest predicted spacing), if that detection's nearest prediction is this
    marker too. Returns (marker indices, detection indices). Real set-ups label with a
    reference mark; the nominal projection (design camera poses) plays that role here.
    """
    from scipy.spatial import cKDTree

    det = np.asarray(detected_px, dtype=float).reshape(-1, 2)
    pred = np.asarray(predicted_px, dtype=float).reshape(-1, 2)
    if len(det) == 0 or len(pred) == 0:
        return np.zeros(0, int), np.zeros(0, int)
    if max_distance_px is None:
        dmin, _ = cKDTree(pred).query(pred, k=2)
        max_distance_px = 0.4 * float(np.min(dmin[:, 1])) if len(pred) > 1 else 5.0
    d1, j = cKDTree(det).query(pred)
    _, back = cKDTree(pred).query(det)
    i = np.arange(len(pred))
    ok = (d1 <= max_distance_px) & (back[np.minimum(j, len(det) - 1)] == i)
    return i[ok], j[ok]


# ---------------------------------------------------------------------- fits
def _check_points(pixels, world, resolution):
    px = np.asarray(pixels, dtype=float)
    w = np.asarray(world, dtype=float)
    if px.ndim != 2 or px.shape[1] != 2 or w.ndim != 2 or w.shape[1] != 3 or len(px) != len(w):
        raise CalibrationError(
            f"calibrate: pixels must be (n, 2) and world (n, 3) with the same n; got {px.shape} and {w.shape}."
        )
    if not (np.all(np.isfinite(px)) and np.all(np.isfinite(w))):
        raise CalibrationError("calibrate: marker coordinates must be finite.")
    if resolution is not None:
        wd, ht = resolution
        out = (px[:, 0] < 0) | (px[:, 0] > wd) | (px[:, 1] < 0) | (px[:, 1] > ht)
        if np.any(out):
            raise CalibrationError(
                f"calibrate: {int(out.sum())} marker(s) lie outside the {wd}x{ht} image (e.g. "
                f"{px[out][0].round(2).tolist()} px); drop markers that are not in the image."
            )
    return px, w


# the fits live in mitpiv.physics.camera_fit (the renderer turns user calibrations into cameras
# with them too); the private names stay for scripts that used them
_dlt = dlt_matrix
_decompose = decompose_projection


def calibrate(
    pixels,
    world_mm,
    *,
    model: str = "pinhole",
    resolution: tuple[int, int] | None = None,
    distortion: str = "brown",
    pixel_pitch_um: float = 10.0,
    max_rms_px: float = 0.5,
) -> CameraMapping:
    """Fit a camera mapping to marker correspondences.

    Parameters
    ----------
    pixels : (n, 2) detected marker positions [px].
    world_mm : (n, 3) marker world coordinates [mm] (several depths or tilts).
    model : "pinhole" (pinhole + Brown-Conrady by OpenCV's ``calibrateCamera`` from a
        normalised-DLT start) or "polynomial" (Soloff, 19 terms per coordinate).
    resolution : (width, height); required for "pinhole".
    distortion : "none", "radial" (k1, k2) or "brown" (k1, k2, k3, p1, p2); pinhole only.
    pixel_pitch_um : used to express the fitted focal length in mm.
    max_rms_px : largest acceptable RMS reprojection error; a worse fit raises.

    Returns
    -------
    CameraMapping with ``fit_report`` = {"rms_px", "max_px", "markers", "model", ...}.
    """
    px, w = _check_points(pixels, world_mm, resolution)
    if model == "polynomial":
        need = 2 * len(SOLOFF_TERMS)
        if len(px) < need:
            raise CalibrationError(f"calibrate: the polynomial mapping needs at least {need} markers, got {len(px)}.")
        depths = np.unique(np.round(w[:, 2], 6))
        centre, scale = PolynomialMapping.normalisation(w)
        sv = np.linalg.svd(PolynomialMapping.design((w - centre) / scale), compute_uv=False)
        if len(depths) < 3 or sv[-1] < 1e-8 * sv[0]:
            raise CalibrationError(
                f"calibrate: the markers do not determine the polynomial mapping (quadratic in z needs "
                f"markers at >= 3 depths spread in x and y; got {len(depths)} depth(s), design condition "
                f"{sv[0] / max(sv[-1], 1e-300):.3g}). Add target positions."
            )
        mapping = PolynomialMapping.fit(px, w, resolution=resolution)
        info = {"model": "polynomial", "terms": len(SOLOFF_TERMS), "depths": len(depths)}
    elif model == "pinhole":
        mapping, info = _fit_pinhole(px, w, resolution, distortion, pixel_pitch_um)
    else:
        raise ConfigError(f"calibrate: parameter 'model' must be 'pinhole' or 'polynomial', got {model!r}.")
    r = mapping.residuals(px, w)
    err = np.linalg.norm(r, axis=1)
    rms = float(np.sqrt(np.mean(err**2)))
    mapping.fit_report = {**info, "rms_px": rms, "max_px": float(err.max()), "markers": len(px)}
    if not np.isfinite(rms) or rms > max_rms_px:
        raise CalibrationError(
            f"calibrate: the {model} fit leaves an RMS reprojection error of {rms:.3g} px (max "
            f"{err.max():.3g} px) over {len(px)} markers, above max_rms_px={max_rms_px}. Check the marker "
            f"labels, add distortion terms or use the polynomial model, or raise max_rms_px knowingly."
        )
    return mapping


def _fit_pinhole(px, w, resolution, distortion, pitch):
    if resolution is None:
        raise ConfigError("calibrate: the pinhole model needs 'resolution' (width, height).")
    if distortion not in _DISTORTION_MODELS:
        raise ConfigError(f"calibrate: parameter 'distortion' must be one of {_DISTORTION_MODELS}, got {distortion!r}.")
    cam, info = fit_pinhole_camera(px, w, resolution=resolution, distortion=distortion, pixel_pitch_um=pitch)
    return PinholeMapping(cam), info


def _dlt_start(px, w):
    k, r, t = _decompose(_dlt(px, w))
    # _decompose fixes det(M) > 0; markers still behind the camera mean wrong labels.
    if np.mean((w @ r.T + t)[:, 2]) < 0:
        raise CalibrationError("calibrate: the linear start puts the markers behind the camera; check the labels.")
    return k, r, t


def calibrate_views(views, sensor_index: int, nominal: CameraMapping, target, *, model: str = "pinhole",
                    resolution=None, **kwargs) -> CameraMapping:
    """Detect, label and fit from :func:`mitpiv.render.targets.render_target_views` output.

    ``nominal`` (e.g. the design camera) only labels the detections; the fit uses the
    detected positions and the exact marker coordinates.
    """
    pix, wld = [], []
    for v in views:
        img = v["images"][sensor_index]
        if target.kind == "dots":
            det = detect_dots(img)
        else:
            det = detect_checkerboard(img, target.rows, target.cols)
        i, j = label_markers(det, nominal.project(v["markers_world"]))
        pix.append(det[j])
        wld.append(v["markers_world"][i])
    if resolution is None:
        resolution = nominal.resolution
    return calibrate(np.concatenate(pix), np.concatenate(wld), model=model, resolution=resolution, **kwargs)


# ---------------------------------------------------------------------- homographies
def plane_homographies(mappings, reference: CameraMapping, z_mm, *, extent_mm, samples: int = 21):
    """Homographies from each camera's pixels to the reference view's pixels on planes z = const.

    Points on a ``samples x samples`` grid over ``extent_mm`` = (x_min, x_max, y_min, y_max)
    at each depth are projected by both mappings; a normalised DLT fits H (3x3, H[2,2] = 1).
    Returns ``(H (n_cameras, n_z, 3, 3), max_residual_px (n_cameras, n_z))``; the residual is
    what a homography cannot represent (distortion, or a non-pinhole mapping).
    """
    z = np.atleast_1d(np.asarray(z_mm, dtype=float))
    x0, x1, y0, y1 = (float(v) for v in extent_mm)
    if not (x1 > x0 and y1 > y0):
        raise ConfigError(f"plane_homographies: extent_mm must be (x_min, x_max, y_min, y_max) with max > min, got {extent_mm!r}.")
    gx, gy = np.meshgrid(np.linspace(x0, x1, samples), np.linspace(y0, y1, samples))
    hs = np.zeros((len(mappings), len(z), 3, 3))
    res = np.zeros((len(mappings), len(z)))
    for k, zk in enumerate(z):
        pts = np.column_stack([gx.ravel(), gy.ravel(), np.full(gx.size, zk)])
        dst = reference.project(pts)
        for c, m in enumerate(mappings):
            src = m.project(pts)
            h = _homography_dlt(src, dst)
            if h is None:
                raise CalibrationError(f"plane_homographies: no homography for camera {c} at z = {zk} mm (degenerate view).")
            hs[c, k] = h
            res[c, k] = float(np.max(np.linalg.norm(apply_homography(hs[c, k], src) - dst, axis=1)))
    return hs, res


def _homography_dlt(src, dst):
    """Normalised DLT homography src -> dst in float64 (None if degenerate)."""
    def norm(a):
        c = a.mean(axis=0)
        sc = np.sqrt(2) / np.mean(np.linalg.norm(a - c, axis=1))
        return np.array([[sc, 0, -sc * c[0]], [0, sc, -sc * c[1]], [0, 0, 1.0]])

    ts, td = norm(src), norm(dst)
    a = np.column_stack([src, np.ones(len(src))]) @ ts.T
    b = np.column_stack([dst, np.ones(len(dst))]) @ td.T
    z = np.zeros((len(a), 3))
    rows = np.concatenate([np.hstack([z, -a, b[:, 1:2] * a]), np.hstack([a, z, -b[:, 0:1] * a])])
    _, sv, vt = np.linalg.svd(rows)
    if sv[-2] < 1e-12 * sv[0]:
        return None
    h = np.linalg.inv(td) @ vt[-1].reshape(3, 3) @ ts
    return h / h[2, 2]


def apply_homography(h, pixels) -> np.ndarray:
    """Map (..., 2) pixel positions by a 3x3 homography."""
    p = np.asarray(pixels, dtype=float)
    q = p @ np.asarray(h)[:2, :2].T + np.asarray(h)[:2, 2]
    wgt = p @ np.asarray(h)[2, :2] + h[2, 2]
    return q / wgt[..., None]
