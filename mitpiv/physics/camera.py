"""Pinhole / thin-lens camera model in float64 NumPy, and camera placement helpers.

Frames
------
``p_world``: scene millimetres. ``p_camera``: OpenCV camera frame (x right, y down,
z forward along the optical axis), origin at the pinhole (entrance pupil centre).
Pixel coordinates ``(u, v)`` are continuous: pixel ``(i, j)`` covers
``[i, i+1) x [j, j+1)``, so its centre is at ``(i + 0.5, j + 0.5)``; ``u`` runs along
image columns (to the right), ``v`` along rows (down).

Mitsuba's camera frame has x left, y up, z forward; :meth:`PinholeCamera.to_world_mitsuba`
returns the matrix a Mitsuba sensor needs.

This model is the contract between rendering and reconstruction: the EXR metadata
stores :meth:`PinholeCamera.to_dict`, and :meth:`PinholeCamera.from_dict` restores it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mitpiv.errors import ConfigError, check_positive
from mitpiv.physics.distortion import Distortion, check_distortion, distort, undistort

__all__ = ["PinholeCamera", "look_at_rotation", "place_camera"]

# OpenCV camera frame -> Mitsuba camera frame (x and y flip).
_CV_TO_MI = np.diag([-1.0, -1.0, 1.0])


@dataclass
class PinholeCamera:
    """A pinhole camera with optional Brown-Conrady distortion and thin-lens aperture.

    Parameters
    ----------
    resolution : (int, int)
        Image width and height [px].
    focal_length_mm : float
        Focal length (pinhole to image-plane distance) [mm].
    pixel_pitch_um : float
        Pixel pitch [um].
    rotation : (3, 3) array
        World-to-camera rotation R (OpenCV frame): ``p_camera = R (p_world - position)``.
    position_mm : (3,) array
        Pinhole position in world millimetres.
    principal_point_px : (float, float), optional
        Principal point [px]; default the image centre.
    distortion : Distortion
        Brown-Conrady coefficients (OpenCV convention: undistorted -> distorted).
    f_number : float or None
        Thin-lens f-number; None for an ideal pinhole (infinite depth of field).
    focus_distance_mm : float or None
        Distance of the plane in focus along the optical axis [mm] (thin lens only).
    """

    resolution: tuple[int, int]
    focal_length_mm: float
    pixel_pitch_um: float
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    position_mm: np.ndarray = field(default_factory=lambda: np.zeros(3))
    principal_point_px: tuple[float, float] | None = None
    distortion: Distortion = field(default_factory=Distortion)
    f_number: float | None = None
    focus_distance_mm: float | None = None

    def __post_init__(self) -> None:
        w, h = (int(v) for v in self.resolution)
        if w <= 0 or h <= 0:
            raise ConfigError(f"camera: resolution must be positive, got {self.resolution!r}.")
        self.resolution = (w, h)
        self.focal_length_mm = check_positive("focal_length_mm", self.focal_length_mm, owner="camera", unit="mm")
        self.pixel_pitch_um = check_positive("pixel_pitch_um", self.pixel_pitch_um, owner="camera", unit="um")
        if self.principal_point_px is None:
            self.principal_point_px = (w / 2.0, h / 2.0)
        self.principal_point_px = tuple(float(v) for v in self.principal_point_px)
        self.rotation = np.asarray(self.rotation, dtype=float).reshape(3, 3)
        if not np.allclose(self.rotation @ self.rotation.T, np.eye(3), atol=1e-9) or np.linalg.det(self.rotation) < 0:
            raise ConfigError("camera: rotation must be a proper rotation matrix (orthonormal, det +1).")
        self.position_mm = np.asarray(self.position_mm, dtype=float).reshape(3)
        if isinstance(self.distortion, dict):
            self.distortion = Distortion(**self.distortion)
        if self.f_number is not None:
            self.f_number = check_positive("f_number", self.f_number, owner="camera")
            if self.focus_distance_mm is None:
                raise ConfigError("camera: 'focus_distance_mm' is required with 'f_number'.")
            self.focus_distance_mm = check_positive("focus_distance_mm", self.focus_distance_mm, owner="camera", unit="mm")
        elif self.focus_distance_mm is not None:
            raise ConfigError("camera: 'focus_distance_mm' needs 'f_number' (a thin-lens aperture).")

    # ------------------------------------------------------------------ intrinsics
    @property
    def focal_px(self) -> float:
        """Focal length in pixels."""
        return self.focal_length_mm / (self.pixel_pitch_um * 1e-3)

    @property
    def K(self) -> np.ndarray:
        """3x3 intrinsic matrix (OpenCV)."""
        f = self.focal_px
        cx, cy = self.principal_point_px
        return np.array([[f, 0, cx], [0, f, cy], [0, 0, 1.0]])

    @property
    def aperture_radius_mm(self) -> float:
        return 0.0 if self.f_number is None else self.focal_length_mm / (2.0 * self.f_number)

    @property
    def corner_radius(self) -> float:
        """Largest principal-point-to-corner distance in normalised coordinates."""
        w, h = self.resolution
        cx, cy = self.principal_point_px
        return max(np.hypot(u - cx, v - cy) for u in (0, w) for v in (0, h)) / self.focal_px

    def validate_distortion(self) -> int:
        """Raise :class:`ConfigError` if the distortion folds over; return Newton iterations."""
        return check_distortion(
            self.distortion,
            resolution=self.resolution,
            focal_px=self.focal_px,
            principal_point_px=self.principal_point_px,
        )

    # ------------------------------------------------------------------ mapping
    def world_to_camera(self, p_world) -> np.ndarray:
        p = np.asarray(p_world, dtype=float)
        return (p - self.position_mm) @ self.rotation.T

    def project(self, p_world) -> np.ndarray:
        """Project world points [mm], shape (..., 3), to pixel coordinates (..., 2).

        For a thin-lens camera this is the image of the chief ray (the centre of the
        defocus blur).
        """
        pc = self.world_to_camera(p_world)
        x = pc[..., 0] / pc[..., 2]
        y = pc[..., 1] / pc[..., 2]
        xd, yd = distort(x, y, self.distortion)
        cx, cy = self.principal_point_px
        f = self.focal_px
        return np.stack([f * xd + cx, f * yd + cy], axis=-1)

    def pixel_to_ray(self, uv_px, *, iterations: int = 20):
        """Chief rays through pixel positions: (origin (3,), directions (..., 3)) in world."""
        uv = np.asarray(uv_px, dtype=float)
        cx, cy = self.principal_point_px
        f = self.focal_px
        x, y = undistort((uv[..., 0] - cx) / f, (uv[..., 1] - cy) / f, self.distortion, iterations=iterations)
        d_cam = np.stack([x, y, np.ones_like(x)], axis=-1)
        d_cam /= np.linalg.norm(d_cam, axis=-1, keepdims=True)
        return self.position_mm.copy(), d_cam @ self.rotation

    # ------------------------------------------------------------------ Mitsuba
    def to_world_mitsuba(self) -> np.ndarray:
        """4x4 camera-to-world matrix in Mitsuba's camera convention (x left, y up)."""
        m = np.eye(4)
        m[:3, :3] = self.rotation.T @ _CV_TO_MI
        m[:3, 3] = self.position_mm
        return m

    @classmethod
    def rotation_from_mitsuba(cls, to_world: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(R world->camera OpenCV, position) from a Mitsuba camera-to-world matrix."""
        m = np.asarray(to_world, dtype=float)
        lin = m[:3, :3]
        scale = np.linalg.norm(lin, axis=0)
        if not np.allclose(scale, 1.0, atol=1e-5):
            raise ConfigError(
                f"camera: to_world must be a rigid transform (rotation + translation); its "
                f"columns have lengths {np.round(scale, 6).tolist()}. Remove scaling."
            )
        # Mitsuba stores float32: snap to the nearest rotation (polar decomposition).
        u, _, vt = np.linalg.svd(lin)
        r_cw_mi = u @ vt
        if np.linalg.det(r_cw_mi) < 0:
            raise ConfigError("camera: to_world must not mirror the scene (negative determinant).")
        rotation = (r_cw_mi @ _CV_TO_MI).T
        return rotation, m[:3, 3].copy()

    # ------------------------------------------------------------------ metadata
    def to_dict(self) -> dict:
        """JSON-ready description (units in the key names)."""
        return {
            "model": "pinhole_brown_conrady",
            "convention": "OpenCV camera frame (x right, y down, z forward); "
            "p_camera = R (p_world - position_mm); pixel (i, j) spans [i, i+1)",
            "resolution": list(self.resolution),
            "focal_length_mm": self.focal_length_mm,
            "pixel_pitch_um": self.pixel_pitch_um,
            "focal_px": self.focal_px,
            "principal_point_px": list(self.principal_point_px),
            "K": self.K.tolist(),
            "R": self.rotation.tolist(),
            "position_mm": self.position_mm.tolist(),
            "t_mm": (-self.rotation @ self.position_mm).tolist(),
            "distortion": self.distortion.to_dict(),
            "f_number": self.f_number,
            "focus_distance_mm": self.focus_distance_mm,
            "aperture_radius_mm": self.aperture_radius_mm,
            "to_world_mitsuba": self.to_world_mitsuba().tolist(),
        }

    @classmethod
    def from_dict(cls, d: dict) -> PinholeCamera:
        return cls(
            resolution=tuple(d["resolution"]),
            focal_length_mm=d["focal_length_mm"],
            pixel_pitch_um=d["pixel_pitch_um"],
            rotation=np.asarray(d["R"]),
            position_mm=np.asarray(d["position_mm"]),
            principal_point_px=tuple(d["principal_point_px"]),
            distortion=Distortion(**d["distortion"]),
            f_number=d.get("f_number"),
            focus_distance_mm=d.get("focus_distance_mm"),
        )


def look_at_rotation(position_mm, target_mm, up=(0.0, 0.0, 1.0)) -> np.ndarray:
    """World-to-camera rotation (OpenCV frame) of a camera at ``position`` aimed at ``target``.

    The image's "up" (-y in OpenCV) is the projection of ``up`` on the image plane.
    """
    p = np.asarray(position_mm, dtype=float)
    t = np.asarray(target_mm, dtype=float)
    z = t - p
    n = np.linalg.norm(z)
    if n == 0:
        raise ConfigError("look_at_rotation: position and target coincide.")
    z /= n
    up = np.asarray(up, dtype=float)
    x = np.cross(z, up)  # right = forward x up  (y down)
    if np.linalg.norm(x) < 1e-9:
        raise ConfigError(
            f"look_at_rotation: 'up' {up.tolist()} is parallel to the viewing direction; "
            f"choose another up vector."
        )
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z])


def place_camera(
    *,
    target_mm=(0.0, 0.0, 0.0),
    azimuth_deg: float,
    elevation_deg: float,
    distance_mm: float,
    laser_direction=(1.0, 0.0, 0.0),
    sheet_normal=(0.0, 0.0, 1.0),
    up=None,
) -> tuple[np.ndarray, np.ndarray]:
    """Place a camera on a sphere around ``target`` as in tomographic PIV set-ups.

    Angles are measured in the frame of the laser sheet: ``e1`` the laser propagation
    direction, ``e3`` the sheet normal, ``e2 = e3 x e1`` (in the sheet plane). The
    camera sits at ``target + distance (cos(el) cos(az) e1 + cos(el) sin(az) e2 +
    sin(el) e3)`` and looks at the target, so azimuth 0 / elevation 0 is a camera on the
    laser axis downstream (forward scatter, scattering angle 0) and azimuth 180 a
    backward-scatter camera. The scattering angle is ``acos(cos(el) cos(az))``.

    Returns
    -------
    rotation : (3, 3) world-to-camera rotation (OpenCV frame)
    position_mm : (3,) camera position
    """
    distance_mm = check_positive("distance_mm", distance_mm, owner="place_camera", unit="mm")
    e1 = np.asarray(laser_direction, dtype=float)
    e1 /= np.linalg.norm(e1)
    e3 = np.asarray(sheet_normal, dtype=float)
    e3 = e3 - e1 * (e3 @ e1)
    if np.linalg.norm(e3) < 1e-9:
        raise ConfigError("place_camera: sheet_normal must not be parallel to laser_direction.")
    e3 /= np.linalg.norm(e3)
    e2 = np.cross(e3, e1)
    az, el = np.radians(azimuth_deg), np.radians(elevation_deg)
    direction = np.cos(el) * np.cos(az) * e1 + np.cos(el) * np.sin(az) * e2 + np.sin(el) * e3
    target = np.asarray(target_mm, dtype=float)
    position = target + distance_mm * direction
    if up is None:
        # Image "up" along the sheet normal unless the camera looks along it.
        up = e3 if abs(direction @ e3) < 0.99 else e2
    return look_at_rotation(position, target, up=up), position
