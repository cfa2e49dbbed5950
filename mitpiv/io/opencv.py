"""A user's own camera calibration from OpenCV (camera matrix, distortion coefficients,
optionally the pose) as a mitpiv :class:`~mitpiv.physics.camera.PinholeCamera`, and back.

Formats: OpenCV ``FileStorage`` YAML / XML (``.yml``, ``.yaml``, ``.xml``: what
``cv::FileStorage`` and OpenCV's calibration samples write, ``!!opencv-matrix`` nodes or plain
sequences), read by OpenCV itself; JSON (``.json``), read by the standard library, with each
matrix either OpenCV's ``{"type_id": "opencv-matrix", "rows", "cols", "data"}`` or a nested
list. Hand-written here is only the choice of keys and the conversion of conventions:

- keys (first found): camera matrix ``camera_matrix`` / ``cameraMatrix`` / ``K`` / ``mtx``;
  distortion ``distortion_coefficients`` / ``dist_coeffs`` / ``distCoeffs`` / ``dist`` / ``D``;
  image size ``image_width`` + ``image_height`` or ``image_size`` / ``imageSize`` ([w, h]);
  pose (optional) ``rvec`` (Rodrigues) or ``R`` / ``rotation``, with ``tvec`` / ``T`` /
  ``translation`` (world -> camera, ``x_cam = R x_world + t``); optional ``pixel_pitch_um``.
- OpenCV puts pixel centres on integers, mitpiv at ``i + 0.5``: the principal point gains
  0.5 px on each axis.
- distortion ``(k1, k2, p1, p2[, k3])`` maps to mitpiv's Brown-Conrady (the same model);
  the rational (k4-k6), thin-prism and tilt terms are refused unless zero.
- mitpiv cameras have square pixels and no skew: ``fx`` and ``fy`` must agree to
  :data:`SQUARE_PIXEL_RTOL`, and the skew must be zero. The focal length in mm needs the
  pixel pitch (from the file or the ``pixel_pitch_um`` argument): ``f_mm = fx * pitch``.
- lengths in the pose are taken as mm times ``length_unit_mm``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.io.atomic import atomic_path

__all__ = ["read_opencv_camera", "write_opencv_camera", "SQUARE_PIXEL_RTOL"]

#: Largest relative difference of fx and fy accepted as square pixels (a calibration's
#: fx / fy scatter is typically 1e-4 .. 1e-3 for square-pixel sensors).
SQUARE_PIXEL_RTOL = 2e-3

_KEYS = {
    "K": ("camera_matrix", "cameraMatrix", "K", "mtx", "intrinsic_matrix"),
    "dist": ("distortion_coefficients", "dist_coeffs", "distCoeffs", "dist", "D", "distortion"),
    "rvec": ("rvec", "rotation_vector"),
    "R": ("R", "rotation", "rotation_matrix"),
    "t": ("tvec", "T", "t", "translation"),
    "size": ("image_size", "imageSize"),
}
_DIST_NAMES = ("k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6", "s1", "s2", "s3", "s4", "tau_x", "tau_y")


def _json_value(v):
    if isinstance(v, dict) and "data" in v:
        a = np.asarray(v["data"], dtype=np.float64)
        return a.reshape(int(v.get("rows", a.size)), int(v.get("cols", 1)))
    return np.asarray(v, dtype=np.float64)


def _read_json(path: Path) -> dict:
    try:
        raw = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise FileFormatError(f"read_opencv_camera: {str(path)!r} is not a JSON file ({e}).") from None
    if not isinstance(raw, dict):
        raise FileFormatError(f"read_opencv_camera: {str(path)!r} must hold a JSON object of named matrices.")
    out = {}
    for k, v in raw.items():
        try:
            out[k] = _json_value(v)
        except (TypeError, ValueError):
            continue  # names, dates and other text are not matrices
    return out


def _read_filestorage(path: Path) -> dict:
    import cv2

    try:
        fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    except cv2.error as e:
        raise FileFormatError(f"read_opencv_camera: OpenCV cannot read {str(path)!r} "
                              f"({str(e).strip().splitlines()[-1]}).") from None
    if not fs.isOpened():
        raise FileFormatError(f"read_opencv_camera: OpenCV cannot open {str(path)!r} as FileStorage YAML / XML.")
    out = {}
    try:
        root = fs.root()
        for k in root.keys():
            n = fs.getNode(k)
            if n.isSeq():
                vals = [n.at(i) for i in range(n.size())]
                if all(v.isReal() or v.isInt() for v in vals):
                    out[k] = np.array([v.real() for v in vals], dtype=np.float64)
                elif all(v.isSeq() for v in vals):  # a nested list: rows
                    out[k] = np.array([[v.at(j).real() for j in range(v.size())] for v in vals], dtype=np.float64)
            elif n.isReal() or n.isInt():
                out[k] = np.array(n.real())
            elif n.isMap():
                m = n.mat()
                if m is not None:
                    out[k] = np.asarray(m, dtype=np.float64)
    finally:
        fs.release()
    return out


def _first(d: dict, what: str):
    for k in _KEYS[what]:
        if k in d:
            return k, d[k]
    return None, None


def read_opencv_camera(path, *, pixel_pitch_um: float | None = None, resolution=None, length_unit_mm: float = 1.0,
                       f_number: float | None = None, focus_distance_mm: float | None = None,
                       pose: str = "optional"):
    """Read an OpenCV camera calibration as a :class:`~mitpiv.physics.camera.PinholeCamera`.

    Parameters
    ----------
    path : str or Path
        ``.yml`` / ``.yaml`` / ``.xml`` (OpenCV FileStorage) or ``.json``; keys in the module notes.
    pixel_pitch_um : float, optional
        Pixel pitch [um]; required unless the file holds ``pixel_pitch_um``.
    resolution : (int, int), optional
        Image (width, height) [px]; required unless the file holds the image size.
    length_unit_mm : float
        Millimetres per unit of the file's translation (1 for a calibration in mm, 1000 in m).
    f_number, focus_distance_mm : float, optional
        A thin-lens aperture for the render (a calibration does not hold one).
    pose : {"optional", "require", "forbid"}
        Whether the file must (``"require"``) or must not (``"forbid"``: the pose comes
        from elsewhere, e.g. a scene's ``to_world``) hold the camera's pose.

    Returns
    -------
    PinholeCamera
        Intrinsics and distortion from the file; the pose from ``rvec``/``R`` and ``tvec``
        when present, else the camera at the world origin looking along +z (OpenCV frame).

    Raises
    ------
    FileFormatError
        Missing or unreadable file, no camera matrix, malformed matrices.
    ConfigError
        Non-square pixels, skew, distortion terms mitpiv does not model, missing pitch or
        image size, or a resolution that disagrees with the file's.
    """
    from mitpiv.physics.camera import PinholeCamera
    from mitpiv.physics.distortion import Distortion

    path = Path(path)
    if not path.is_file():
        raise FileFormatError(f"read_opencv_camera: {str(path)!r} does not exist.")
    suffix = path.suffix.lower()
    if suffix == ".json":
        d = _read_json(path)
    elif suffix in (".yml", ".yaml", ".xml"):
        d = _read_filestorage(path)
    else:
        raise ConfigError(f"read_opencv_camera: {str(path)!r} must end in .yml, .yaml, .xml or .json.")
    src = f"read_opencv_camera: {str(path)!r}"
    kname, K = _first(d, "K")
    if K is None or K.size != 9:
        raise FileFormatError(f"{src} holds no 3x3 camera matrix (looked for {', '.join(_KEYS['K'])}; found "
                              f"{sorted(d)}).")
    K = K.reshape(3, 3)
    fx, fy, skew, cx, cy = K[0, 0], K[1, 1], K[0, 1], K[0, 2], K[1, 2]
    if not (fx > 0 and fy > 0) or not np.allclose(K[2], [0, 0, 1]) or abs(K[1, 0]) > 0:
        raise FileFormatError(f"{src}: {kname} = {K.tolist()} is not a camera matrix [[fx, s, cx], [0, fy, cy], "
                              "[0, 0, 1]] with fx, fy > 0.")
    if abs(fx - fy) > SQUARE_PIXEL_RTOL * fx:
        raise ConfigError(f"{src}: fx = {fx:g} and fy = {fy:g} px differ by {abs(fx - fy) / fx:.2%}; mitpiv cameras "
                          f"have square pixels (|fx - fy| <= {SQUARE_PIXEL_RTOL:.1%} of fx). Calibrate with "
                          "CALIB_FIX_ASPECT_RATIO.")
    if abs(skew) > 1e-9 * fx:
        raise ConfigError(f"{src}: skew {skew:g} px; mitpiv cameras have none (calibrate with zero skew).")
    _, dist = _first(d, "dist")
    dist = np.zeros(5) if dist is None else np.asarray(dist, dtype=np.float64).ravel()
    if dist.size not in (4, 5, 8, 12, 14):
        raise FileFormatError(f"{src}: {dist.size} distortion coefficients; OpenCV writes 4, 5, 8, 12 or 14.")
    extra = {n: float(v) for n, v in zip(_DIST_NAMES[5:], dist[5:], strict=False) if v != 0}
    if extra:
        raise ConfigError(f"{src}: distortion terms {extra} are not modelled by mitpiv (Brown-Conrady k1, k2, k3, p1, "
                          "p2); calibrate without CALIB_RATIONAL_MODEL / THIN_PRISM / TILTED_MODEL.")
    k1, k2, p1, p2 = dist[:4]
    k3 = dist[4] if dist.size > 4 else 0.0
    pitch = pixel_pitch_um if pixel_pitch_um is not None else (float(d["pixel_pitch_um"]) if "pixel_pitch_um" in d
                                                               else None)
    if pitch is None:
        raise ConfigError(f"{src}: give pixel_pitch_um (the sensor's pixel pitch [um]); the file has none and the "
                          "focal length in mm needs it.")
    if "image_width" in d and "image_height" in d:
        size = (int(d["image_width"]), int(d["image_height"]))
    else:
        _, s = _first(d, "size")
        size = None if s is None else tuple(int(v) for v in np.asarray(s).ravel()[:2])
    if resolution is not None:
        resolution = tuple(int(v) for v in resolution)
        if size is not None and size != resolution:
            raise ConfigError(f"{src}: the calibration is for {size[0]} x {size[1]} px images, not {resolution[0]} x "
                              f"{resolution[1]}; render at the calibrated size.")
        size = resolution
    if size is None:
        raise ConfigError(f"{src}: give resolution=(width, height) [px]; the file holds no image size.")
    rot, pos = np.eye(3), np.zeros(3)
    _, rvec = _first(d, "rvec")
    _, R = _first(d, "R")
    _, t = _first(d, "t")
    if (rvec is not None or R is not None) != (t is not None):
        raise FileFormatError(f"{src}: a pose needs both a rotation (rvec or R) and a translation (tvec or T).")
    if pose not in ("optional", "require", "forbid"):
        raise ConfigError(f"read_opencv_camera: pose={pose!r}; choose 'optional', 'require' or 'forbid'.")
    if pose == "require" and t is None:
        raise FileFormatError(f"{src} holds no camera pose (rvec or R, and tvec); add it or place the camera otherwise.")
    if pose == "forbid" and t is not None:
        raise ConfigError(f"{src} holds a camera pose (rvec / tvec) and the camera is placed elsewhere too; give the "
                          "pose once (drop to_world / azimuth placement to use the calibration's).")
    if t is not None:
        import cv2

        rot = cv2.Rodrigues(np.asarray(rvec, dtype=np.float64).reshape(3, 1))[0] if rvec is not None \
            else np.asarray(R, dtype=np.float64).reshape(3, 3)
        pos = -rot.T @ (np.asarray(t, dtype=np.float64).reshape(3) * float(length_unit_mm))
    return PinholeCamera(size, float(fx) * pitch * 1e-3, pitch, rotation=rot, position_mm=pos,
                         principal_point_px=(float(cx) + 0.5, float(cy) + 0.5),
                         distortion=Distortion(k1=float(k1), k2=float(k2), k3=float(k3), p1=float(p1), p2=float(p2)),
                         f_number=f_number, focus_distance_mm=focus_distance_mm)


def write_opencv_camera(path, camera) -> Path:
    """Write a :class:`~mitpiv.physics.camera.PinholeCamera` as an OpenCV FileStorage file
    (``.yml`` / ``.yaml`` / ``.xml`` / ``.json``, by OpenCV; atomic) that OpenCV and
    :func:`read_opencv_camera` read: ``camera_matrix``, ``distortion_coefficients`` (k1, k2,
    p1, p2, k3), ``image_width``, ``image_height``, ``rvec``, ``tvec`` [mm] and ``pixel_pitch_um``."""
    import cv2

    path = Path(path)
    if path.suffix.lower() not in (".yml", ".yaml", ".xml", ".json"):
        raise ConfigError(f"write_opencv_camera: {str(path)!r} must end in .yml, .yaml, .xml or .json.")
    K = camera.K.copy()
    K[0, 2] -= 0.5  # mitpiv pixel centres at i + 0.5, OpenCV's at i
    K[1, 2] -= 0.5
    dd = camera.distortion
    with atomic_path(path, suffix=path.suffix) as tmp:
        fs = cv2.FileStorage(str(tmp), cv2.FILE_STORAGE_WRITE)
        fs.write("image_width", int(camera.resolution[0]))
        fs.write("image_height", int(camera.resolution[1]))
        fs.write("camera_matrix", K)
        fs.write("distortion_coefficients", np.array([[dd.k1, dd.k2, dd.p1, dd.p2, dd.k3]]))
        fs.write("rvec", cv2.Rodrigues(camera.rotation)[0])
        fs.write("tvec", (-camera.rotation @ camera.position_mm).reshape(3, 1))
        fs.write("pixel_pitch_um", float(camera.pixel_pitch_um))
        fs.release()
    return path
