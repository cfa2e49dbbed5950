"""Export to OpenPTV (liboptv and its Python bindings, PyPI ``optv``; the pyptv GUI): the
camera orientation files (``.ori`` + ``.addpar``), the parameter folder and the image
sequence of a rendered experiment.

Checked against ``optv`` 0.3.2 (the cp311 manylinux wheel: its ``Calibration.from_file``,
``image_coordinates``, ``convert_arr_metric_to_pixel`` and parameter readers) and the
sources of liboptv (github.com/OpenPTV/openptv: ``liboptv/src/calibration.c``,
``imgcoord.c``, ``trafo.c``, ``multimed.c``, ``parameters.c``, the ``test_cavity`` case).

OpenPTV's camera model, and mitpiv's in it
------------------------------------------
- Exterior (``.ori`` line 1-2): the projection centre ``x0, y0, z0`` [mm] and the angles
  ``omega, phi, kappa`` [rad]; liboptv rebuilds the rotation ``dm`` from the angles
  (``rotation_matrix``; the 3 x 3 matrix in the file is ignored on reading) and maps a point
  to its camera frame by ``dm^T (p - x0)``. That frame has x right, y *up*, z *backward*
  (points in front have negative z): ``dm = R^T diag(1, -1, -1)`` for mitpiv's OpenCV rotation
  ``R``, and the angles follow from ``dm`` (``phi = atan2(dm02, hypot(dm00, dm01))``,
  ``omega = atan2(-dm12, dm22)``, ``kappa = atan2(-dm01, dm00)``).
- Interior (``.ori``): ``xh, yh`` [mm] the principal point's offset from the sensor centre
  (y up) and ``cc`` the principal distance [mm]: ``cc = focal_length_mm``,
  ``xh = (cx - W/2) pitch``, ``yh = (H/2 - cy) pitch`` (``cx, cy`` mitpiv's principal
  point [px]).
- Glass vector (``.ori``, last line): the multimedia interface; the export is in air (all
  refractive indices 1 in ``ptv.par``), where liboptv's refraction step is the identity and
  the vector only has to be non-zero: half the way from the world origin to the camera.
- Pixels (``ptv.par``: one image size and pixel pitch for all cameras): ``x_pix = x/pitch +
  W/2``, ``y_pix = H/2 - y/pitch``. OpenPTV's pixel coordinates are mitpiv's: its target
  recognition (``targ_rec`` and ``peak_fit`` in ``segmentation.c``) adds 0.5 to the
  grey-weighted pixel index, so pixel ``i`` spans ``[i, i + 1)`` as in mitpiv, and
  ``(x_pix, y_pix) = (u, v)`` (checked with optv 0.3.2 on exported images: its targets'
  mean offset from mitpiv's projections is below 0.03 px, where a half-pixel convention
  error would show as 0.5 px).
- Distortion (``.addpar``: ``k1 k2 k3 p1 p2 scx she``) acts on metric coordinates measured
  from the *sensor centre* (after adding ``xh, yh``), with y up and OpenPTV's tangential terms
  (``x += p1 (r2 + 2 x^2) + 2 p2 x y``). For a principal point on OpenPTV's sensor centre
  (``xh = yh = 0``) mitpiv's Brown-Conrady lens converts exactly: ``k1/cc^2, k2/cc^4,
  k3/cc^6``, ``p1_ptv = p2/cc``, ``p2_ptv = -p1/cc``; mitpiv's default principal point (the
  sensor centre) is this case. Otherwise the two distortion centres differ and no exact
  conversion exists: the exporter fits the five coefficients by linear
  least squares to mitpiv's projection on a 41 x 41 grid over the sensor and records the
  largest remaining difference (``distortion_fit_px``) in the manifest; a fit worse than
  :data:`MAX_FIT_PX` is refused.

Folder written by :func:`export_openptv` (pyptv's layout, as in liboptv's ``test_cavity``)
------------------------------------------------------------------------------------------
``parameters/`` ``ptv.par`` (cameras, image size, pitch, media), ``sequence.par`` (image
base names, first and last frame), ``criteria.par`` (observed volume, correspondence
tolerances), ``track.par`` (velocity bounds per frame, angle and acceleration limits),
``targ_rec.par`` and ``detect_plate.par`` (target recognition), ``cal_ori.par`` (target
file and orientation names), and neutral ``man_ori.par``, ``orient.par``, ``examine.par``,
``shaking.par``, ``sortgrid.par``, ``dumbbell.par``, ``multi_planes.par``,
``unsharp_mask.par``, ``pft_version.par`` that pyptv opens; ``cal/cam<k>.tif.ori`` and
``.addpar``; ``cal/target.txt`` (the volume's corners as points ``id x y z``);
``img/cam<k>.<n>`` the frames as uncompressed TIFFs (8 or 16 bit, :mod:`mitpiv.io.tiff`)
numbered from ``first_frame`` (OpenPTV's ``base_name + number``, no extension); and
``mitpiv_export.json``.

Hand-written: the file texts and the convention conversion above (liboptv's writer
rounds ``xh, yh, cc`` to 1e-4 mm; these files carry full double precision, which its
``fscanf("%lf")`` reads).
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError, check_positive
from mitpiv.io.atomic import atomic_path
from mitpiv.io.tiff import BITS, frame_stack, intensity_gain, load_frame, quantise, write_tiff

__all__ = ["OpenPTVSettings", "openptv_calibration", "write_openptv_calibration", "export_openptv", "MAX_FIT_PX",
           "FIT_GRID"]

log = logging.getLogger(__name__)

#: Largest difference [px] between mitpiv's distorted projection and OpenPTV's fitted
#: distortion on the sensor that the export accepts (a tenth of a typical 2-D
#: correspondence tolerance; see the module notes).
MAX_FIT_PX = 0.01

#: Points per side of the sensor grid on which a distortion is fitted.
FIT_GRID = 41


@dataclass(frozen=True)
class OpenPTVSettings:
    """The processing settings written to the parameter folder (OpenPTV's names and units).

    Attributes
    ----------
    gray_threshold : float
        Target recognition threshold per camera, in counts of an 8-bit image (scaled for
        16 bits; liboptv reads four values).
    min_pixels, max_pixels : int
        Pixels per target (total).
    min_sum_gray : int
        Least grey-value sum of a target.
    discontinuity : int
        Largest grey-value step inside a target.
    cross_size : int
        Marker size [px].
    eps0_mm : float
        Epipolar band half-width on the sensor [mm].
    corrmin : float
        Least correspondence quality.
    cn, cnx, cny, csumg : float
        Relative tolerances of target size and brightness.
    max_displacement_mm : float, (3,) float or None
        Tracking bounds ``dv*min / dv*max`` [mm per frame]: ``-dv..+dv`` on every axis, or
        per axis (x, y, z) (None: a tenth of the volume's smallest side; the run exports
        derive it from the flow, :mod:`mitpiv.studies.peer_settings`).
    angle_deg, acceleration : float
        Tracking limits (OpenPTV's ``dangle`` [deg] and ``dacc`` [mm]).
    add_particles : bool
        OpenPTV's ``add`` flag (search for unused targets while tracking).
    """

    gray_threshold: float = 30.0
    min_pixels: int = 2
    max_pixels: int = 100
    min_sum_gray: int = 20
    discontinuity: int = 100
    cross_size: int = 2
    eps0_mm: float = 0.02
    corrmin: float = 33.0
    cn: float = 0.02
    cnx: float = 0.02
    cny: float = 0.02
    csumg: float = 0.02
    max_displacement_mm: float | tuple[float, float, float] | None = None
    angle_deg: float = 100.0
    acceleration: float = 0.4
    add_particles: bool = True


def _check_camera(camera, owner: str):
    for attr in ("K", "rotation", "position_mm", "distortion", "resolution", "focal_length_mm", "pixel_pitch_um"):
        if not hasattr(camera, attr):
            raise ConfigError(f"{owner}: OpenPTV's model holds a pinhole camera with Brown distortion; a "
                              f"{type(camera).__name__} (no {attr!r}) cannot be written. Export the experiment's "
                              "pinhole cameras (a plenoptic camera has no OpenPTV model).")
    return camera


def _angles(dm: np.ndarray) -> tuple[float, float, float]:
    """(omega, phi, kappa) of liboptv's ``rotation_matrix`` for the matrix ``dm``."""
    phi = float(np.arctan2(dm[0, 2], np.hypot(dm[0, 0], dm[0, 1])))
    if np.hypot(dm[0, 0], dm[0, 1]) > 1e-12:
        omega = float(np.arctan2(-dm[1, 2], dm[2, 2]))
        kappa = float(np.arctan2(-dm[0, 1], dm[0, 0]))
    else:  # phi = +-90 deg: only omega +- kappa is defined; take kappa = 0
        kappa = 0.0
        omega = float(np.arctan2(dm[1, 0], dm[1, 1])) if dm[0, 2] > 0 else float(-np.arctan2(dm[1, 0], dm[1, 1]))
    return omega, phi, kappa


def _dm(omega: float, phi: float, kappa: float) -> np.ndarray:
    """liboptv's rotation_matrix(omega, phi, kappa)."""
    co, so, cp, sp, ck, sk = np.cos(omega), np.sin(omega), np.cos(phi), np.sin(phi), np.cos(kappa), np.sin(kappa)
    return np.array([[cp * ck, -cp * sk, sp],
                     [co * sk + so * sp * ck, co * ck - so * sp * sk, -so * cp],
                     [so * sk - co * sp * ck, so * ck + co * sp * sk, co * cp]])


def _ptv_distort(x, y, ap):
    """liboptv's distort_brown_affin with scx = 1, she = 0 (metric, from the sensor centre)."""
    k1, k2, k3, p1, p2 = ap
    r2 = x * x + y * y
    rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    return x * rad + p1 * (r2 + 2 * x * x) + 2 * p2 * x * y, y * rad + p2 * (r2 + 2 * y * y) + 2 * p1 * x * y


def _fit_distortion(camera, xh: float, yh: float, cc: float, pitch_mm: float):
    """Least-squares OpenPTV distortion (k1, k2, k3, p1, p2) reproducing mitpiv's projection
    on a grid over the sensor; returns (coefficients, largest difference [px])."""
    from mitpiv.physics.distortion import distort, undistort

    w, h = camera.resolution
    cx, cy = camera.principal_point_px
    f = camera.focal_px
    uu, vv = np.meshgrid(np.linspace(0, w, FIT_GRID), np.linspace(0, h, FIT_GRID))
    # undistorted normalised points near the sensor grid; their exact images by mitpiv's model
    xn, yn = undistort((uu.ravel() - cx) / f, (vv.ravel() - cy) / f, camera.distortion, iterations=50)
    xd, yd = distort(xn, yn, camera.distortion)
    u, v = f * xd + cx, f * yd + cy
    tx, ty = (u - w / 2) * pitch_mm, (h / 2 - v) * pitch_mm  # targets: OpenPTV metric, distorted
    sx, sy = cc * xn + xh, -cc * yn + yh  # flat, from the sensor centre
    r2 = sx * sx + sy * sy
    ax = np.stack([sx * r2, sx * r2**2, sx * r2**3, r2 + 2 * sx * sx, 2 * sx * sy], axis=1)
    ay = np.stack([sy * r2, sy * r2**2, sy * r2**3, 2 * sx * sy, r2 + 2 * sy * sy], axis=1)
    a = np.concatenate([ax, ay])
    b = np.concatenate([tx - sx, ty - sy])
    scale = np.linalg.norm(a, axis=0)
    scale[scale == 0] = 1.0
    coef = np.linalg.lstsq(a / scale, b, rcond=None)[0] / scale
    px, py = _ptv_distort(sx, sy, coef)
    worst = float(np.max(np.hypot(px - tx, py - ty)) / pitch_mm)
    return [float(c) for c in coef], worst


def openptv_calibration(camera, *, max_fit_px: float = MAX_FIT_PX) -> dict:
    """OpenPTV's orientation of a mitpiv pinhole camera (see the module notes).

    Returns
    -------
    dict: ``position_mm`` (x0, y0, z0), ``angles_rad`` (omega, phi, kappa), ``dm`` (3, 3),
    ``xh_mm``, ``yh_mm``, ``cc_mm``, ``glass_mm`` (3,), ``addpar`` (k1, k2, k3, p1, p2, scx,
    she), ``image_size`` (W, H), ``pixel_mm``, ``distortion`` (``"none"``, ``"exact"`` or
    ``"fitted"``) and ``distortion_fit_px`` (largest difference on the sensor [px]).

    Raises
    ------
    ConfigError
        A camera OpenPTV cannot represent (not a pinhole; a distortion whose fit is worse than
        ``max_fit_px``).
    """
    cam = _check_camera(camera, "openptv_calibration")
    R = np.asarray(cam.rotation, dtype=np.float64)
    pos = np.asarray(cam.position_mm, dtype=np.float64)
    dm = R.T @ np.diag([1.0, -1.0, -1.0])
    omega, phi, kappa = _angles(dm)
    dm_back = _dm(omega, phi, kappa)
    if not np.allclose(dm_back, dm, atol=1e-12, rtol=0):  # pragma: no cover - the angles always rebuild dm
        raise ConfigError("openptv_calibration: the rotation has no omega/phi/kappa form (internal error).")
    w, h = cam.resolution
    pitch = cam.pixel_pitch_um * 1e-3
    cx, cy = cam.principal_point_px
    cc = float(cam.focal_length_mm)
    xh, yh = (cx - w / 2) * pitch, (h / 2 - cy) * pitch
    d = cam.distortion
    if d.is_zero:
        ap, kind, fit = [0.0] * 5, "none", 0.0
    elif xh == 0.0 and yh == 0.0:
        ap, kind, fit = [d.k1 / cc**2, d.k2 / cc**4, d.k3 / cc**6, d.p2 / cc, -d.p1 / cc], "exact", 0.0
    else:
        ap, fit = _fit_distortion(cam, xh, yh, cc, pitch)
        kind = "fitted"
        if not fit <= max_fit_px:
            raise ConfigError(f"openptv_calibration: OpenPTV centres lens distortion on the sensor centre, this "
                              f"camera's principal point is ({cx:g}, {cy:g}) px, {np.hypot(xh, yh) / pitch:.3g} px "
                              f"off it; the best OpenPTV distortion differs from the lens ({d}) by up to {fit:.3g} "
                              f"px on the sensor (limit max_fit_px = {max_fit_px:g}). Use a principal point at "
                              f"({w / 2:g}, {h / 2:g}) px (the sensor centre), a weaker distortion, or a larger max_fit_px.")
    glass = 0.5 * pos if np.linalg.norm(pos) > 0 else -R[2]  # any non-zero vector in air
    return {"position_mm": pos.tolist(), "angles_rad": [omega, phi, kappa], "dm": dm_back.tolist(),
            "xh_mm": xh, "yh_mm": yh, "cc_mm": cc, "glass_mm": glass.tolist(),
            "addpar": [*ap, 1.0, 0.0], "image_size": [int(w), int(h)], "pixel_mm": pitch,
            "distortion": kind, "distortion_fit_px": fit}


def _n(x) -> str:
    return repr(float(x))


def _ori_text(cal: dict) -> str:
    p, a = cal["position_mm"], cal["angles_rad"]
    rows = "\n".join("    " + " ".join(_n(v) for v in r) for r in cal["dm"])
    return (f"{_n(p[0])} {_n(p[1])} {_n(p[2])}\n    {_n(a[0])} {_n(a[1])} {_n(a[2])}\n\n{rows}\n\n"
            f"    {_n(cal['xh_mm'])} {_n(cal['yh_mm'])}\n    {_n(cal['cc_mm'])}\n\n"
            f"    {' '.join(_n(v) for v in cal['glass_mm'])}\n")


def _addpar_text(cal: dict) -> str:
    return " ".join(_n(v) for v in cal["addpar"]) + "\n"


def write_openptv_calibration(ori_path, camera, *, addpar_path=None, max_fit_px: float = MAX_FIT_PX) -> dict:
    """Write OpenPTV's ``.ori`` and ``.addpar`` files of ``camera`` (atomic; ``addpar_path``
    defaults to the ``.ori`` path with ``.addpar``). Returns :func:`openptv_calibration`'s dict."""
    cal = openptv_calibration(camera, max_fit_px=max_fit_px)
    ori = Path(ori_path)
    add = Path(addpar_path) if addpar_path is not None else ori.with_suffix(".addpar")
    for path, text in ((ori, _ori_text(cal)), (add, _addpar_text(cal))):
        with atomic_path(path) as tmp:
            tmp.write_text(text)
    return cal


def _lines(*values) -> str:
    return "\n".join(str(v) for v in values) + "\n"


def export_openptv(out_dir, images, cameras, *, lower_mm, upper_mm, first_frame: int = 10001, bits: int = 8,
                   gain: float | None = None, settings: OpenPTVSettings | None = None,
                   max_fit_px: float = MAX_FIT_PX, progress=None) -> dict:
    """Write an OpenPTV / pyptv experiment folder: parameters, orientations, image sequence.

    Parameters
    ----------
    out_dir : str or Path
        The folder (created; files in it are replaced).
    images : sequence
        One sequence of frames per camera, each an (H, W) image or an EXR path.
    cameras : sequence of PinholeCamera
        The cameras (OpenPTV: one image size and pixel pitch for all).
    lower_mm, upper_mm : (3,) float
        The observed volume [mm] (``criteria.par``: x range, z range at both x ends).
    first_frame : int
        Number of the first frame's files (``img/cam1.10001``, ...).
    bits : 8 or 16; gain : optional
        TIFF depth and scaling (:mod:`mitpiv.io.tiff`).
    settings : OpenPTVSettings, optional
    max_fit_px : float
        Largest accepted distortion-fit difference [px] (:func:`openptv_calibration`).
    progress : optional
        Progress bar control (:mod:`mitpiv.progress`).

    Returns
    -------
    dict
        The manifest written to ``mitpiv_export.json``.

    Raises
    ------
    ConfigError
        No frames, cameras OpenPTV cannot hold (not pinhole; differing image sizes or pixel
        pitches; a distortion it cannot reproduce), bad volume or options. Checked before
        anything is written.
    """
    from mitpiv.io.records import write_json, write_text
    from mitpiv.progress import bar

    owner = "export_openptv"
    cameras = list(cameras)
    if not cameras:
        raise ConfigError(f"{owner}: 'cameras' is empty; give the experiment's cameras.")
    cams = [_check_camera(c, owner) for c in cameras]
    sizes = {(tuple(c.resolution), float(c.pixel_pitch_um)) for c in cams}
    if len(sizes) != 1:
        raise ConfigError(f"{owner}: OpenPTV's ptv.par holds one image size and pixel pitch for all cameras; "
                          f"these cameras have {sorted(sizes)} ((W, H), pitch um). Export cameras of one sensor.")
    cals = [openptv_calibration(c, max_fit_px=max_fit_px) for c in cams]
    stack = frame_stack(images, len(cams), owner=owner)
    lo = np.asarray(lower_mm, dtype=np.float64).ravel()
    hi = np.asarray(upper_mm, dtype=np.float64).ravel()
    if lo.shape != (3,) or hi.shape != (3,) or not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))) \
            or not np.all(hi > lo):
        raise ConfigError(f"{owner}: the volume needs finite 'lower_mm' < 'upper_mm' (3 values each) [mm], got "
                          f"{lower_mm!r} and {upper_mm!r}.")
    if bits not in BITS:
        raise ConfigError(f"{owner}: 'bits' must be 8 or 16, got {bits!r}.")
    if isinstance(first_frame, bool) or int(first_frame) != first_frame or first_frame < 0:
        raise ConfigError(f"{owner}: 'first_frame' must be an integer >= 0, got {first_frame!r}.")
    first_frame = int(first_frame)
    settings = settings or OpenPTVSettings()
    if not isinstance(settings, OpenPTVSettings):
        raise ConfigError(f"{owner}: 'settings' must be an OpenPTVSettings, got {type(settings).__name__}.")
    w, h = cams[0].resolution
    for k, frames in enumerate(stack):
        shape = load_frame(frames[0]).shape
        if shape != (h, w):
            raise ConfigError(f"{owner}: camera {k + 1}'s frames are {shape[1]} x {shape[0]} px, the cameras' "
                              f"resolution is {w} x {h}; give each camera its own images.")
    if settings.max_displacement_mm is None:
        dv = [float(np.min(hi - lo) / 10.0)] * 3
    else:
        md = np.ravel(np.asarray(settings.max_displacement_mm, dtype=object))
        if md.size not in (1, 3):
            raise ConfigError(f"{owner}: 'max_displacement_mm' must be one value or three (x, y, z) [mm per frame], "
                              f"got {settings.max_displacement_mm!r}.")
        dv = [check_positive("max_displacement_mm", v, owner=owner, unit="mm") for v in md]
        dv = dv * 3 if len(dv) == 1 else dv
    gain = intensity_gain(stack, bits=bits, owner=owner) if gain is None else \
        check_positive("gain", gain, owner=owner, unit="counts per image unit")

    out = Path(out_dir)
    n_cam, n_frames = len(cams), len(stack[0])
    last = first_frame + n_frames - 1
    with bar(n_cam * n_frames, desc="openptv export", progress=progress, unit="image") as b:
        for k in range(n_cam):
            for f, frame in enumerate(stack[k]):
                write_tiff(out / f"img/cam{k + 1}.{first_frame + f}", quantise(load_frame(frame), gain, bits))
                b.update()
    for k, cal in enumerate(cals):
        write_text(out / f"cal/cam{k + 1}.tif.ori", _ori_text(cal))
        write_text(out / f"cal/cam{k + 1}.tif.addpar", _addpar_text(cal))
    corners = np.stack(np.meshgrid(*zip(lo, hi, strict=True), indexing="ij"), axis=-1).reshape(-1, 3)
    write_text(out / "cal/target.txt", "".join(f"{i + 1} {_n(p[0])} {_n(p[1])} {_n(p[2])}\n"
                                                for i, p in enumerate(corners)))
    s = settings
    scale = (2**bits - 1) / 255.0  # thresholds are given for 8 bits
    thr = [int(round(s.gray_threshold * scale))] * max(4, n_cam)
    par = out / "parameters"
    img_cal = [x for k in range(n_cam) for x in (f"img/cam{k + 1}.{first_frame}", f"cal/cam{k + 1}.tif")]
    pitch = cals[0]["pixel_mm"]
    files = {
        # n_img, (image, calibration image) per camera, hp_flag, allCam_flag, tiff_flag, imx, imy,
        # pix_x, pix_y, chfield, n1 (air), n2 (glass: air), n3 (water: air), d (glass thickness)
        "ptv.par": _lines(n_cam, *img_cal, 0, 0, 1, w, h, _n(pitch), _n(pitch), 0, 1.0, 1.0, 1.0, 1.0),
        "sequence.par": _lines(*(f"img/cam{k + 1}." for k in range(n_cam)), first_frame, last),
        "criteria.par": _lines(_n(lo[0]), _n(lo[2]), _n(hi[2]), _n(hi[0]), _n(lo[2]), _n(hi[2]), s.cnx, s.cny, s.cn,
                               s.csumg, s.corrmin, s.eps0_mm),
        "track.par": _lines(-dv[0], dv[0], -dv[1], dv[1], -dv[2], dv[2], s.angle_deg, s.acceleration,
                            int(bool(s.add_particles))),
        "targ_rec.par": _lines(*thr[:4], s.discontinuity, f"{s.min_pixels}  {s.max_pixels}",
                               f"{1}  {s.max_pixels}", f"{1}  {s.max_pixels}", s.min_sum_gray, s.cross_size),
        "detect_plate.par": _lines(*thr[:4], s.discontinuity, s.min_pixels, s.max_pixels, 1, s.max_pixels, 1,
                                   s.max_pixels, s.min_sum_gray, s.cross_size),
        "cal_ori.par": _lines("cal/target.txt", *[x for k in range(n_cam) for x in
                                                  (f"cal/cam{k + 1}.tif", f"cal/cam{k + 1}.tif.ori")], 1, 0, 0),
        "man_ori.par": _lines(*([1, 2, 3, 4] * n_cam)),
        "orient.par": _lines(*([0] * 12)),
        "examine.par": _lines(0, 0),
        "shaking.par": _lines(first_frame, last, 10, 5),
        "sortgrid.par": _lines(20),
        "dumbbell.par": _lines(3.0, 25.0, 0.05, 1.0, 1, 500),
        "multi_planes.par": _lines(0),
        "unsharp_mask.par": _lines(12),
        "pft_version.par": _lines(0),
    }
    for name, text in files.items():
        write_text(par / name, text)
    manifest = {
        "tool": "openptv", "checked_version": "optv 0.3.2", "n_cameras": n_cam, "n_frames": n_frames,
        "first_frame": first_frame, "last_frame": last, "lower_mm": lo.tolist(), "upper_mm": hi.tolist(),
        "bits": bits, "gain": gain,
        "scaling": f"value = round(clip(image * gain, 0, {2**bits - 1})), one gain for all cameras and frames",
        "pixel_convention": "OpenPTV pixel i spans [i, i + 1) as in mitpiv: x_pix = u_mitpiv",
        "calibrations": cals, "cameras": [c.to_dict() for c in cams] if all(hasattr(c, "to_dict") for c in cams)
        else None, "settings": asdict(settings),
    }
    write_json(out / "mitpiv_export.json", manifest)
    return manifest
