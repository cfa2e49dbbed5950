"""Cameras from linear and polynomial calibrations, and back.

- :func:`dlt_matrix`: the normalised direct linear transform (Hartley & Zisserman, alg. 7.1),
  a 3x4 projection matrix from point correspondences (NumPy's SVD).
- :func:`decompose_projection`: ``P = K [R | t]`` by SciPy's RQ decomposition.
- :func:`dlt_from_projection` / :func:`projection_from_dlt`: the 11 DLT parameters
  L1..L11 of Abdel-Aziz & Karara (1971), ``u = (L1 X + L2 Y + L3 Z + L4) / (L9 X + L10 Y +
  L11 Z + 1)``, ``v = (L5 X + L6 Y + L7 Z + L8) / (L9 X + L10 Y + L11 Z + 1)``: the 3x4
  matrix with ``P[2, 3] = 1``.
- :func:`camera_from_projection`: a :class:`~mitpiv.physics.camera.PinholeCamera` (square
  pixels, no skew) from a 3x4 matrix, with the residual of that approximation over the
  image; :func:`projection_from_camera` the exact inverse for an undistorted camera.
- :func:`fit_pinhole_camera`: pinhole + Brown-Conrady fitted to correspondences by OpenCV's
  ``calibrateCamera`` from a DLT start (the core of :func:`mitpiv.reconstruct.calibrate`).
- :func:`monomials`, :func:`camera_from_polynomial`, :func:`polynomial_from_camera`: the
  Soloff et al. (1997) third-order polynomial (cubic in X, Y, quadratic in Z: 19 terms, or
  the full cubic with Z^3: 20 terms) evaluated, turned into a renderable camera by a fit to
  points sampled through it over a stated volume (refused above a residual tolerance),
  and fitted to a camera by least squares.

Hand-written here: only the bookkeeping around the libraries (normalisation, sign and
pixel conventions, residual checks). Pixels in the mitpiv convention (pixel ``(i, j)``
spans ``[i, i+1)``); world coordinates in mm.
"""

from __future__ import annotations

import numpy as np

from mitpiv.errors import CalibrationError, ConfigError
from mitpiv.physics.camera import PinholeCamera
from mitpiv.physics.distortion import Distortion

__all__ = [
    "dlt_matrix",
    "decompose_projection",
    "dlt_from_projection",
    "projection_from_dlt",
    "camera_from_projection",
    "projection_from_camera",
    "fit_pinhole_camera",
    "SOLOFF_TERMS",
    "CUBIC_TERMS",
    "monomials",
    "camera_from_polynomial",
    "polynomial_from_camera",
    "DEFAULT_MAX_RESIDUAL_PX",
]

#: Exponents (i, j, k) of X^i Y^j Z^k in Soloff's polynomial (i + j <= 3, k <= 2,
#: i + j + k <= 3): 19 terms, ordered by the power of Z, then the total degree in X and Y,
#: then falling powers of X: 1, x, y, x2, xy, y2, x3, x2y, xy2, y3, z, xz, yz, x2z, xyz, y2z,
#: z2, xz2, yz2.
SOLOFF_TERMS = tuple((i, j, k) for k in range(3) for n in range(4 - k) for i in range(n, -1, -1) for j in [n - i])
#: The full cubic in X, Y, Z (20 terms): Soloff's 19 and Z^3 last.
CUBIC_TERMS = SOLOFF_TERMS + ((0, 0, 3),)

#: Default largest reprojection error [px] accepted when a calibration is approximated by a
#: renderable camera (square pixels, no skew; or a pinhole + Brown-Conrady fit to a
#: polynomial): a tenth of a pixel, below the 0.1-0.2 px calibration residuals tomographic
#: PIV works with (Wieneke 2008) so the approximation does not dominate them.
DEFAULT_MAX_RESIDUAL_PX = 0.1


# ---------------------------------------------------------------------- DLT
def dlt_matrix(pixels_px, world_mm) -> np.ndarray:
    """Normalised DLT: the 3x4 projection matrix ``P`` with ``x ~ P X`` (least squares in
    the algebraic error after Hartley normalisation), from (n, 2) pixels and (n, 3) points,
    n >= 6 not coplanar."""
    px = np.asarray(pixels_px, dtype=np.float64).reshape(-1, 2)
    w = np.asarray(world_mm, dtype=np.float64).reshape(-1, 3)

    def norm(a):
        c = a.mean(axis=0)
        s = np.sqrt(a.shape[1]) / np.mean(np.linalg.norm(a - c, axis=1))
        t = np.eye(a.shape[1] + 1)
        t[:-1, :-1] *= s
        t[:-1, -1] = -s * c
        return t

    tx, tw = norm(px), norm(w)
    xh = (np.column_stack([px, np.ones(len(px))])) @ tx.T
    wh = (np.column_stack([w, np.ones(len(w))])) @ tw.T
    z = np.zeros((len(wh), 4))
    rows = np.concatenate([np.hstack([z, -wh, xh[:, 1:2] * wh]), np.hstack([wh, z, -xh[:, 0:1] * wh])])
    # thin SVD: the full one builds a (2n x 2n) U, minutes for a few thousand markers
    _, _, vt = np.linalg.svd(rows, full_matrices=False)
    p = vt[-1].reshape(3, 4)
    return np.linalg.inv(tx) @ p @ tw


def decompose_projection(p) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``P ~ K [R | t]`` (SciPy's RQ): K upper triangular with a positive diagonal and
    ``K[2, 2] = 1``, R a proper rotation, t (3,). The overall sign of ``P`` is chosen so
    that ``det(P[:, :3]) > 0`` (a projective matrix is defined up to scale and sign)."""
    from scipy.linalg import rq

    p = np.asarray(p, dtype=np.float64).reshape(3, 4)
    m = p[:, :3]
    if np.linalg.det(m) < 0:
        p = -p
        m = -m
    k, r = rq(m)
    d = np.diag(np.sign(np.diag(k)))
    k, r = k @ d, d @ r
    t = np.linalg.solve(k, p[:, 3])
    return k / k[2, 2], r, t


def projection_from_dlt(coefficients) -> np.ndarray:
    """The 3x4 matrix of the 11 DLT parameters L1..L11 (``P[2, 3] = 1``)."""
    c = np.asarray(coefficients, dtype=np.float64).ravel()
    if c.size != 11:
        raise ConfigError(f"projection_from_dlt: the DLT has 11 parameters L1..L11, got {c.size}.")
    return np.append(c, 1.0).reshape(3, 4)


def dlt_from_projection(p) -> np.ndarray:
    """The 11 DLT parameters L1..L11 of a 3x4 matrix (scaled to ``P[2, 3] = 1``; refused
    when ``P[2, 3]`` is 0: the world origin lies in the camera's principal plane)."""
    p = np.asarray(p, dtype=np.float64).reshape(3, 4)
    if not np.abs(p[2, 3]) > 1e-12 * np.abs(p[2]).max():
        raise ConfigError("dlt_from_projection: P[2, 3] is 0 (the world origin lies in the camera's principal "
                          "plane), so the 11-parameter DLT (L12 = 1) cannot represent this camera; move the world "
                          "origin into the measurement volume.")
    return (p / p[2, 3]).ravel()[:11]


def _approximation_residual(k, resolution):
    """(K', max, rms) of the square-pixel, zero-skew K' closest to K: the same rays map to
    ``K' K^-1 x``, an affine map of the pixel, so the largest error over the image is at a
    corner; the RMS over a 21 x 21 grid of the image."""
    w, h = resolution
    f = 0.5 * (k[0, 0] + k[1, 1])
    k2 = np.array([[f, 0.0, k[0, 2]], [0.0, f, k[1, 2]], [0.0, 0.0, 1.0]])
    a = k2 @ np.linalg.inv(k)
    gu, gv = np.meshgrid(np.linspace(0, w, 21), np.linspace(0, h, 21))
    x = np.stack([gu.ravel(), gv.ravel(), np.ones(gu.size)], axis=-1)
    d = np.linalg.norm(x @ a.T - x, axis=-1)
    return k2, float(d.max()), float(np.sqrt(np.mean(d**2)))


def camera_from_projection(p, *, resolution, pixel_pitch_um: float, name: str = "camera",
                           max_residual_px: float = DEFAULT_MAX_RESIDUAL_PX, volume_mm=None,
                           f_number: float | None = None, focus_distance_mm: float | None = None):
    """A :class:`PinholeCamera` from a 3x4 projection matrix (mitpiv pixels, world mm).

    Our cameras have square pixels and no skew. ``P = K [R | t]`` is decomposed; K is
    replaced by the closest ``[[f, 0, cx], [0, f, cy], [0, 0, 1]]`` with ``f = (fx + fy) /
    2`` (the pose kept), and the reprojection error this causes is measured over the image
    (exact: the error is an affine function of the pixel, largest at a corner).

    Parameters
    ----------
    p : (3, 4) array
        Projection matrix, ``(u w, v w, w) = P (X, Y, Z, 1)``.
    resolution : (int, int)
        Image (width, height) [px].
    pixel_pitch_um : float
        Pixel pitch [um] (the focal length in mm is ``f * pitch``).
    name : str
        The camera's name in error messages.
    max_residual_px : float
        Largest accepted error of the square-pixel approximation [px].
    volume_mm : (6,) array, optional
        ``(x_min, x_max, y_min, y_max, z_min, z_max)``: checked to lie in front of the camera.
    f_number, focus_distance_mm : float, optional
        A thin-lens aperture for the render.

    Returns
    -------
    camera : PinholeCamera
    info : dict
        ``fx_px``, ``fy_px``, ``skew_px``, ``max_residual_px``, ``rms_residual_px`` (of the
        approximation over the image).

    Raises
    ------
    ConfigError
        Non-finite or singular matrix, a residual above ``max_residual_px``, a volume behind
        the camera.
    """
    p = np.asarray(p, dtype=np.float64)
    if p.shape != (3, 4) or not np.all(np.isfinite(p)):
        raise ConfigError(f"camera {name!r}: the projection matrix must be 3x4 and finite, got {p.tolist()}.")
    m = p[:, :3]
    sv = np.linalg.svd(m, compute_uv=False)
    if not sv[-1] > 1e-12 * sv[0]:
        raise ConfigError(f"camera {name!r}: the DLT / projection matrix is singular (its left 3x3 block has "
                          f"singular values {sv.tolist()}): it maps the world to a line or a point, no camera. Check "
                          f"the coefficient order (L1..L11 row by row) and the file's camera.")
    k, r, t = decompose_projection(p)
    k2, dmax, drms = _approximation_residual(k, resolution)
    info = {"fx_px": float(k[0, 0]), "fy_px": float(k[1, 1]), "skew_px": float(k[0, 1]),
            "max_residual_px": dmax, "rms_residual_px": drms}
    if not dmax <= max_residual_px:
        raise ConfigError(
            f"camera {name!r}: fx = {k[0, 0]:.6g} px, fy = {k[1, 1]:.6g} px, skew = {k[0, 1]:.3g} px; mitpiv cameras "
            f"have square pixels and no skew, and the closest such camera (f = {k2[0, 0]:.6g} px) reprojects up to "
            f"{dmax:.3g} px off (RMS {drms:.3g} px) over the {resolution[0]} x {resolution[1]} image, above "
            f"max_residual_px = {max_residual_px:g}. Calibrate with a fixed aspect ratio and zero skew, or raise "
            f"max_residual_px to accept the approximation.")
    pos = -r.T @ t
    cam = PinholeCamera(tuple(int(v) for v in resolution), float(k2[0, 0]) * pixel_pitch_um * 1e-3, pixel_pitch_um,
                        rotation=r, position_mm=pos, principal_point_px=(float(k2[0, 2]), float(k2[1, 2])),
                        f_number=f_number, focus_distance_mm=focus_distance_mm)
    if volume_mm is not None:
        corners = _box_corners(volume_mm, name)
        if not np.all(cam.in_front(corners)):
            raise ConfigError(f"camera {name!r}: part of the volume {list(map(float, volume_mm))} mm lies behind the "
                              f"camera at {np.round(pos, 3).tolist()} mm; check the world frame (a mirrored axis?) and "
                              f"the file's length unit.")
    return cam, info


def projection_from_camera(camera: PinholeCamera) -> np.ndarray:
    """The 3x4 projection matrix ``K [R | -R c]`` of an undistorted pinhole camera (mitpiv
    pixels, world mm; a thin lens projects its chief ray through the same matrix)."""
    d = camera.distortion
    if any(v != 0 for v in (d.k1, d.k2, d.k3, d.p1, d.p2)):
        raise ConfigError(
            f"projection_from_camera: the camera has Brown-Conrady distortion {d.to_dict()}, which a DLT / 3x4 matrix "
            f"cannot hold; export a polynomial table (write_polynomial_table) or an OpenCV file instead.")
    r = camera.rotation
    return camera.K @ np.hstack([r, (-r @ camera.position_mm).reshape(3, 1)])


# ---------------------------------------------------------------------- pinhole fit
def fit_pinhole_camera(pixels_px, world_mm, *, resolution, distortion: str = "brown",
                       pixel_pitch_um: float = 10.0) -> tuple[PinholeCamera, dict]:
    """Pinhole + Brown-Conrady camera fitted to correspondences: a normalised-DLT start
    refined by OpenCV's ``calibrateCamera`` (square pixels: ``CALIB_FIX_ASPECT_RATIO``).

    Parameters
    ----------
    pixels_px : (n, 2) pixel positions (mitpiv convention).
    world_mm : (n, 3) world points [mm], not coplanar.
    resolution : (width, height) [px].
    distortion : "none", "radial" (k1, k2) or "brown" (k1, k2, k3, p1, p2).
    pixel_pitch_um : expresses the focal length in mm.

    Returns
    -------
    (PinholeCamera, info) with ``info = {"model", "distortion", "dlt_focal_px"}``.
    """
    import cv2

    px = np.asarray(pixels_px, dtype=np.float64).reshape(-1, 2)
    w = np.asarray(world_mm, dtype=np.float64).reshape(-1, 3)
    if distortion not in ("none", "radial", "brown"):
        raise ConfigError(f"calibrate: parameter 'distortion' must be one of ('none', 'radial', 'brown'), got "
                          f"{distortion!r}.")
    n_par = 10 + {"none": 0, "radial": 2, "brown": 5}[distortion]
    if len(px) < max(2 * n_par, 12):
        raise CalibrationError(
            f"calibrate: a pinhole fit with distortion '{distortion}' ({n_par} parameters) needs at least "
            f"{max(2 * n_par, 12)} markers, got {len(px)}."
        )
    s = np.linalg.svd(w - w.mean(axis=0), compute_uv=False)  # spread of the markers per principal axis
    s0 = float(s[0])
    if s0 == 0 or s[1] < 1e-6 * s0:
        raise CalibrationError("calibrate: the markers are collinear (or coincide); a camera cannot be fitted.")
    if s[2] < 1e-3 * s0:
        raise CalibrationError(
            "calibrate: all markers lie in one plane; a pinhole fit from one view needs the target at "
            ">= 2 depths or tilts (non-coplanar markers)."
        )
    k, r, t = decompose_projection(dlt_matrix(px, w))
    # decompose_projection fixes det(M) > 0; markers still behind the camera mean wrong labels.
    if np.mean((w @ r.T + t)[:, 2]) < 0:
        raise CalibrationError("calibrate: the linear start puts the markers behind the camera; check the labels.")
    f0 = 0.5 * (k[0, 0] + k[1, 1])
    k0 = np.array([[f0, 0, k[0, 2] - 0.5], [0, f0, k[1, 2] - 0.5], [0, 0, 1.0]])
    wd, ht = (float(v) for v in resolution)
    start = "dlt"
    if not (0.0 <= k0[0, 2] < wd and 0.0 <= k0[1, 2] < ht):
        # A narrow field of view (a long lens, a small crop) is nearly affine: with noisy
        # points the DLT's principal point is poorly determined and can leave the image,
        # which OpenCV refuses as a start. Start instead from the image centre, the DLT's
        # focal length and the pose that solvePnP fits with these intrinsics fixed.
        k0 = np.array([[f0, 0, 0.5 * wd - 0.5], [0, f0, 0.5 * ht - 0.5], [0, 0, 1.0]])
        ok, rv, tv = cv2.solvePnP(w, (px - 0.5).reshape(-1, 1, 2), k0, np.zeros(5), flags=cv2.SOLVEPNP_ITERATIVE)
        if not ok:
            raise CalibrationError("calibrate: the linear start's principal point lies outside the image and "
                                   "OpenCV's solvePnP found no pose from the image centre; check the markers.")
        r, _ = cv2.Rodrigues(rv)
        t = np.asarray(tv, float).ravel()
        start = "image centre + solvePnP (the DLT principal point left the image)"
    flags = cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_ASPECT_RATIO
    if distortion == "none":
        flags |= cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST
    elif distortion == "radial":
        flags |= cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST
    rvec0, _ = cv2.Rodrigues(r)
    obj = [w.astype(np.float32)]
    img = [(px - 0.5).astype(np.float32).reshape(-1, 1, 2)]
    flags |= getattr(cv2, "CALIB_USE_EXTRINSIC_GUESS", 0)  # start from the DLT pose where OpenCV allows it
    crit = (cv2.TERM_CRITERIA_COUNT + cv2.TERM_CRITERIA_EPS, 500, 1e-15)
    try:
        _, kk, dist, rvecs, tvecs = cv2.calibrateCamera(
            obj, img, tuple(int(v) for v in resolution), k0, np.zeros(5), [rvec0], [t.reshape(3, 1)],
            flags=flags, criteria=crit)
    except cv2.error as e:
        raise CalibrationError(f"calibrate: OpenCV's calibrateCamera failed: {str(e).strip().splitlines()[-1]}") from None
    rot, _ = cv2.Rodrigues(rvecs[0])
    d = np.asarray(dist, dtype=float).ravel()
    d = np.concatenate([d, np.zeros(max(0, 5 - d.size))])
    cam = PinholeCamera(
        tuple(int(v) for v in resolution), float(kk[0, 0]) * pixel_pitch_um * 1e-3, pixel_pitch_um, rotation=rot,
        position_mm=-rot.T @ np.asarray(tvecs[0], float).ravel(),
        principal_point_px=(float(kk[0, 2]) + 0.5, float(kk[1, 2]) + 0.5),
        distortion=Distortion(k1=d[0], k2=d[1], p1=d[2], p2=d[3], k3=d[4]),
    )
    return cam, {"model": "pinhole", "distortion": distortion, "dlt_focal_px": float(f0), "start": start}


# ---------------------------------------------------------------------- polynomial
def monomials(q, terms=SOLOFF_TERMS) -> np.ndarray:
    """The monomials ``x^i y^j z^k`` of points q (..., 3) for ``terms`` [(i, j, k), ...],
    shape (..., len(terms))."""
    q = np.asarray(q, dtype=np.float64)
    return np.stack([q[..., 0] ** i * q[..., 1] ** j * q[..., 2] ** k for i, j, k in terms], axis=-1)


def _box_corners(volume_mm, name):
    v = np.asarray(volume_mm, dtype=np.float64).ravel()
    if v.size != 6 or not np.all(np.isfinite(v)) or not np.all(v[1::2] > v[0::2]):
        raise ConfigError(f"camera {name!r}: volume_mm must be (x_min, x_max, y_min, y_max, z_min, z_max) [mm] with "
                          f"each max > min, got {v.tolist()}.")
    g = np.stack(np.meshgrid(v[0:2], v[2:4], v[4:6], indexing="ij"), axis=-1).reshape(-1, 3)
    return g


def _volume_grid(volume_mm, n_xy: int, n_z: int, name: str):
    v = np.asarray(volume_mm, dtype=np.float64).ravel()
    _box_corners(v, name)
    g = np.meshgrid(np.linspace(v[0], v[1], n_xy), np.linspace(v[2], v[3], n_xy), np.linspace(v[4], v[5], n_z),
                    indexing="ij")
    return np.stack(g, axis=-1).reshape(-1, 3)


def _check_terms(terms, name):
    terms = tuple(tuple(int(e) for e in t) for t in terms)
    if terms not in (SOLOFF_TERMS, CUBIC_TERMS):
        raise ConfigError(f"camera {name!r}: the polynomial terms must be Soloff's 19 {list(SOLOFF_TERMS)} or the "
                          f"20 of the full cubic (the 19 and z^3), in that order; got {list(terms)}.")
    return terms


def camera_from_polynomial(coefficients, *, terms=SOLOFF_TERMS, centre_mm=(0.0, 0.0, 0.0),
                           scale_mm=(1.0, 1.0, 1.0), volume_mm, resolution, pixel_pitch_um: float,
                           name: str = "camera", distortion: str = "brown",
                           max_residual_px: float = DEFAULT_MAX_RESIDUAL_PX, samples_xy: int = 13,
                           samples_z: int = 7, f_number: float | None = None,
                           focus_distance_mm: float | None = None) -> tuple[PinholeCamera, dict]:
    """A renderable pinhole + Brown-Conrady camera fitted to a polynomial calibration.

    The polynomial ``(u, v) = C m(q)``, ``q = (X - centre) / scale``, ``m`` the monomials of
    ``terms`` is sampled on a ``samples_xy^2 x samples_z`` grid over ``volume_mm``; the
    points that land on the image are fitted by :func:`fit_pinhole_camera`, and the fitted
    camera is checked against the polynomial on a second grid offset by half a cell
    (points between the fitted ones).

    Parameters
    ----------
    coefficients : (2, n_terms) array
        Rows for u and v [px] (mitpiv pixel convention).
    terms : sequence of (i, j, k)
        :data:`SOLOFF_TERMS` or :data:`CUBIC_TERMS`.
    centre_mm, scale_mm : (3,) arrays
        Normalisation of the world coordinates [mm].
    volume_mm : (6,) array
        ``(x_min, x_max, y_min, y_max, z_min, z_max)`` [mm]: where the polynomial is valid.
    resolution : (int, int)
        Image (width, height) [px].
    pixel_pitch_um : float
        Pixel pitch [um].
    distortion : "none", "radial" or "brown"
        The distortion terms fitted.
    max_residual_px : float
        Largest accepted reprojection error of the fitted camera against the polynomial [px].

    Returns
    -------
    camera : PinholeCamera
    info : dict
        ``rms_px``, ``max_px`` (on the check grid), ``fit_rms_px`` (on the fitted points),
        ``points`` (fitted), ``distortion``.

    Raises
    ------
    ConfigError
        No volume, a degenerate volume, too few points on the image, a residual above
        ``max_residual_px``.
    """
    if volume_mm is None:
        raise ConfigError(f"camera {name!r}: a polynomial calibration is valid only inside the volume it was made "
                          f"in; give volume_mm = (x_min, x_max, y_min, y_max, z_min, z_max) [mm] (the calibration "
                          f"volume: a '# volume_mm = ...' line in the table, the sensor property "
                          f"'calibration_volume_mm' or the volume_mm argument) to fit a renderable camera to it.")
    terms = _check_terms(terms, name)
    c = np.asarray(coefficients, dtype=np.float64)
    if c.shape != (2, len(terms)) or not np.all(np.isfinite(c)):
        raise ConfigError(f"camera {name!r}: the polynomial needs 2 x {len(terms)} finite coefficients, got shape "
                          f"{c.shape}.")
    centre = np.asarray(centre_mm, dtype=np.float64).reshape(3)
    scale = np.asarray(scale_mm, dtype=np.float64).reshape(3)
    if not (np.all(np.isfinite(centre)) and np.all(np.isfinite(scale)) and np.all(scale != 0)):
        raise ConfigError(f"camera {name!r}: the normalisation needs finite centre_mm and non-zero scale_mm, got "
                          f"{centre.tolist()} and {scale.tolist()}.")
    w, h = (int(v) for v in resolution)

    def project(p):
        return monomials((p - centre) / scale, terms) @ c.T

    def on_image(uv):
        return (uv[:, 0] >= 0) & (uv[:, 0] <= w) & (uv[:, 1] >= 0) & (uv[:, 1] <= h)

    pts = _volume_grid(volume_mm, samples_xy, samples_z, name)
    uv = project(pts)
    keep = on_image(uv)
    if keep.sum() < 40:
        raise ConfigError(f"camera {name!r}: only {int(keep.sum())} of {len(pts)} points of the volume "
                          f"{np.asarray(volume_mm, float).tolist()} mm project onto the {w} x {h} image through the "
                          f"polynomial; check the volume, the length unit and the image size.")
    try:
        cam, info = fit_pinhole_camera(uv[keep], pts[keep], resolution=(w, h), distortion=distortion,
                                       pixel_pitch_um=pixel_pitch_um)
    except CalibrationError as e:
        raise ConfigError(f"camera {name!r}: no pinhole camera fits the polynomial ({e}).") from None
    fit_err = np.linalg.norm(cam.project(pts[keep]) - uv[keep], axis=1)
    v = np.asarray(volume_mm, dtype=np.float64).ravel()
    half = np.array([(v[1] - v[0]) / (samples_xy - 1), (v[3] - v[2]) / (samples_xy - 1),
                     (v[5] - v[4]) / max(samples_z - 1, 1)]) / 2
    inner = v.copy()
    inner[0::2] += half
    inner[1::2] -= half
    chk = _volume_grid(inner, samples_xy - 1, max(samples_z - 1, 2), name)
    uvc = project(chk)
    kc = on_image(uvc) & cam.visible(chk)
    err = np.linalg.norm(cam.project(chk[kc]) - uvc[kc], axis=1)
    err = np.concatenate([err, fit_err])
    rms, mx = float(np.sqrt(np.mean(err**2))), float(err.max())
    info = {**info, "rms_px": rms, "max_px": mx, "fit_rms_px": float(np.sqrt(np.mean(fit_err**2))),
            "points": int(keep.sum()), "check_points": int(kc.sum())}
    if not mx <= max_residual_px:
        raise ConfigError(
            f"camera {name!r}: the pinhole + Brown-Conrady ({distortion}) camera closest to the polynomial reprojects "
            f"up to {mx:.3g} px off (RMS {rms:.3g} px) over the volume {v.tolist()} mm, above max_residual_px = "
            f"{max_residual_px:g}; the renderer cannot reproduce this calibration. Check the volume (the polynomial "
            f"extrapolates badly outside its calibration volume), or raise max_residual_px to accept the "
            f"approximation.")
    cam.f_number = f_number
    cam.focus_distance_mm = focus_distance_mm
    cam.__post_init__()
    return cam, info


def polynomial_from_camera(camera, *, volume_mm, terms=SOLOFF_TERMS, samples_xy: int = 13, samples_z: int = 7,
                           normalise: bool = True) -> dict:
    """A Soloff polynomial fitted by least squares to a camera over a volume.

    Returns ``{"terms", "coefficients" (2, n_terms) [px], "centre_mm", "scale_mm",
    "rms_px", "max_px"}``: with ``normalise`` the centre and half-size of the volume (the
    usual normalisation, well conditioned), else 0 and 1 (coefficients in raw mm)."""
    terms = _check_terms(terms, "camera")
    pts = _volume_grid(volume_mm, samples_xy, samples_z, "camera")
    pts = pts[camera.visible(pts)]
    v = np.asarray(volume_mm, dtype=np.float64).ravel()
    if normalise:
        centre, scale = 0.5 * (v[0::2] + v[1::2]), 0.5 * (v[1::2] - v[0::2])
    else:
        centre, scale = np.zeros(3), np.ones(3)
    a = monomials((pts - centre) / scale, terms)
    uv = camera.project(pts)
    coef, *_ = np.linalg.lstsq(a, uv, rcond=None)
    err = np.linalg.norm(a @ coef - uv, axis=1)
    return {"terms": terms, "coefficients": coef.T, "centre_mm": centre, "scale_mm": scale,
            "rms_px": float(np.sqrt(np.mean(err**2))), "max_px": float(err.max())}
