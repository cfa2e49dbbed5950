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
stores :meth:`PinholeCamera.to_dict`, and :meth:`PinholeCamera.from_dict` restores it
(:func:`mitpiv.io.camera_from_metadata` builds any camera from an image's metadata).

The camera contract
-------------------
:class:`Camera` writes down the one interface every camera model offers (the pinhole
here, distorted or not, thin lens or not, and :class:`~mitpiv.physics.plenoptic.PlenopticCamera`):
``project``, ``in_front``, ``visible``, ``jacobian``, ``resolution``, ``to_dict`` /
``from_dict``. The reconstruction mappings, the seeding-density targets
(:func:`mitpiv.physics.seeding.count_for_density`) and :func:`mitpiv.io.camera_from_metadata`
are written against it, not against one camera class.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol, runtime_checkable

import numpy as np

from mitpiv.errors import ConfigError, check_positive
from mitpiv.physics.distortion import Distortion, check_distortion, distort, distort_jacobian, fold_radius, undistort

__all__ = [
    "Camera",
    "CV_TO_MITSUBA",
    "on_sensor",
    "box_coverage",
    "box_corners",
    "PinholeCamera",
    "look_at_rotation",
    "place_camera",
    "ring_arrangement",
    "planar_array",
    "scatter_arrangement",
    "scheimpflug",
    "COC_PX",
    "thin_lens_depth_of_field",
    "focal_depth",
    "defocus_ratio",
    "sensor_corner_rays",
    "camera_to_world",
]

#: OpenCV camera frame -> Mitsuba camera frame (x and y flip): a Mitsuba camera-to-world
#: rotation is ``R.T @ CV_TO_MITSUBA`` for the world-to-camera (OpenCV) rotation ``R``.
CV_TO_MITSUBA = np.diag([-1.0, -1.0, 1.0])
CV_TO_MITSUBA.flags.writeable = False
_CV_TO_MI = CV_TO_MITSUBA  # deprecated private name


@runtime_checkable
class Camera(Protocol):
    """The camera contract: what every camera model offers (pinhole, distorted, thin lens,
    plenoptic). Structural: a class satisfies it by having these members, no inheritance.

    Pixel coordinates ``(u, v)`` are continuous: pixel ``(i, j)`` spans ``[i, i+1) x [j, j+1)``
    (centre at ``i + 0.5``), ``u`` along image columns, ``v`` along rows; the sensor is
    ``[0, W) x [0, H)``.

    Attributes
    ----------
    resolution : (int, int)
        Sensor width and height ``(W, H)`` [px].

    Methods
    -------
    project(p_world_mm) -> (..., 2)
        Pixel coordinates of world points (..., 3) [mm]: the image of the point's chief
        ray (for a thin lens the centre of its blur spot; for a plenoptic camera the chief
        ray through the main-lens centre onto the microlens plane, scaled to the sensor).
        Defined (finite) for points in front of the camera; points behind it may project
        anywhere (mirrored), so combine with ``in_front`` or use ``visible``.
    in_front(p_world_mm) -> (...) bool
        The point lies in front of the camera's projection centre (depth > 0).
    visible(p_world_mm) -> (...) bool
        ``in_front`` and ``project`` lands on the sensor ``[0, W) x [0, H)``.
    jacobian(p_world_mm) -> (..., 2, 3)
        ``d(u, v) / d(x, y, z)`` [px/mm] of ``project``.
    to_dict() -> dict, from_dict(d) -> Camera
        JSON-ready description (units in the key names, ``"model"`` naming the model) and
        its exact inverse: ``from_dict(c.to_dict())`` projects like ``c``.
    """

    resolution: tuple[int, int]

    def project(self, p_world_mm) -> np.ndarray: ...

    def in_front(self, p_world_mm) -> np.ndarray: ...

    def visible(self, p_world_mm) -> np.ndarray: ...

    def jacobian(self, p_world_mm) -> np.ndarray: ...

    def to_dict(self) -> dict: ...

    @classmethod
    def from_dict(cls, d: dict) -> Camera: ...


def on_sensor(uv_px, resolution) -> np.ndarray:
    """Whether pixel coordinates (..., 2) lie on a sensor of ``resolution = (W, H)``:
    ``0 <= u < W`` and ``0 <= v < H`` (NaN is off the sensor)."""
    uv = np.asarray(uv_px, dtype=float)
    w, h = resolution
    return (uv[..., 0] >= 0) & (uv[..., 0] < w) & (uv[..., 1] >= 0) & (uv[..., 1] < h)


#: Cells per axis of :func:`box_coverage` (16 x 16 x 16 = 4096 cell centres).
COVERAGE_SAMPLES = 16


def box_coverage(cameras, box_min_mm, box_max_mm, *, samples: int = COVERAGE_SAMPLES) -> dict:
    """How much of an axis-aligned box each camera sees, and how much every camera sees.

    The box is cut into ``samples`` cells per axis; a cell counts for a camera where
    ``camera.visible`` holds at its centre (in front of it, projected onto its sensor), so
    the fractions are volume fractions to about one layer of cells. Where every camera sees
    a part but no centre is seen by all (a box much larger than the views), the common
    fraction is sampled again, on as many cells, inside the box that the parts can share.
    The eight corners are projected too, for the message of a box that a camera cuts.
    Deterministic: the same box and cameras give the same numbers.

    Parameters
    ----------
    cameras : mapping of name to Camera
        Any cameras of the camera contract (:class:`Camera`).
    box_min_mm, box_max_mm : (3,) float
        Opposite corners of the box [mm, world].
    samples : int
        Cells per axis (>= 1).

    Returns
    -------
    dict
        ``"cameras"``: ``{name: {"fraction": seen volume fraction, "corners_px": (8, 2)
        pixel positions of the corners (NaN behind the camera), "corners_visible": (8,)
        bool}}``; ``"common"``: the volume fraction every camera sees; ``"common_box_mm"``:
        ``(lower, upper)`` of the cells every camera sees (their extent, None where there
        is none), a box to shrink to; ``"corners_mm"``: (8, 3).
    """
    lo = np.asarray(box_min_mm, dtype=float)
    hi = np.asarray(box_max_mm, dtype=float)
    if lo.shape != (3,) or hi.shape != (3,) or not np.all(np.isfinite(lo) & np.isfinite(hi)) or np.any(hi < lo):
        raise ConfigError(f"box_coverage: box_min_mm {lo.tolist()} and box_max_mm {hi.tolist()} must be 3 finite "
                          f"values each with box_max_mm >= box_min_mm [mm].")
    if isinstance(samples, bool) or int(samples) != samples or samples < 1:
        raise ConfigError(f"box_coverage: 'samples' must be a positive integer, got {samples!r}.")
    if not cameras:
        raise ConfigError("box_coverage: no cameras given.")
    n = int(samples)
    corners = box_corners(lo, hi)
    pts, cell = _cell_centres(lo, hi, n)
    seen = {name: np.asarray(cam.visible(pts), bool) for name, cam in cameras.items()}
    seen_all = np.logical_and.reduce(list(seen.values()))
    common, box = float(seen_all.mean()), _extent(pts[seen_all], cell)
    if not seen_all.any() and all(v.any() for v in seen.values()):
        # every camera sees a part, no cell centre is seen by all: the parts may overlap
        # between the centres (a box much larger than the views); sample again where they can
        lo2 = np.max([pts[v].min(axis=0) - cell for v in seen.values()], axis=0).clip(lo, hi)
        hi2 = np.min([pts[v].max(axis=0) + cell for v in seen.values()], axis=0).clip(lo, hi)
        if np.all(hi2 > lo2):
            pts2, cell2 = _cell_centres(lo2, hi2, n)
            all2 = np.logical_and.reduce([np.asarray(cam.visible(pts2), bool) for cam in cameras.values()])
            common = float(all2.mean() * np.prod(hi2 - lo2) / np.prod(np.where(hi > lo, hi - lo, 1.0)))
            box = _extent(pts2[all2], cell2)
    per = {}
    for name, cam in cameras.items():
        with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
            uv = np.asarray(cam.project(corners), float)
            front = np.asarray(cam.in_front(corners), bool)
        per[name] = {"fraction": float(seen[name].mean()), "corners_px": np.where(front[:, None], uv, np.nan),
                     "corners_visible": np.asarray(cam.visible(corners), bool)}
    return {"cameras": per, "common": common, "corners_mm": corners, "common_box_mm": box}


def box_corners(box_min_mm, box_max_mm) -> np.ndarray:
    """The 8 corners (8, 3) of an axis-aligned box, corner ``k`` taking axis ``i``'s upper
    value where bit ``i`` of ``k`` is set (the order of :func:`box_coverage`'s corners)."""
    lo, hi = np.asarray(box_min_mm, dtype=float), np.asarray(box_max_mm, dtype=float)
    return np.array([[(lo, hi)[(k >> i) & 1][i] for i in range(3)] for k in range(8)])


def _cell_centres(lo, hi, n: int):
    cell = (hi - lo) / n
    axes = [lo[i] + (np.arange(n) + 0.5) * cell[i] for i in range(3)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3), cell


def _extent(points, cell):
    return (points.min(axis=0) - cell / 2, points.max(axis=0) + cell / 2) if len(points) else None


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
        if len(self.principal_point_px) != 2 or not all(math.isfinite(v) for v in self.principal_point_px):
            raise ConfigError(f"camera: 'principal_point_px' must be two finite pixel coordinates (cx, cy), got "
                              f"{self.principal_point_px!r}; leave it out for the sensor centre ({w / 2}, {h / 2}).")
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
            if self.focus_distance_mm <= self.focal_length_mm:
                raise ConfigError(
                    f"camera: 'focus_distance_mm' = {self.focus_distance_mm:g} mm is not beyond the focal length "
                    f"({self.focal_length_mm:g} mm): a thin lens forms a real image only of objects farther than f "
                    f"(1/s + 1/s' = 1/f), so this camera would render black. Focus farther than the focal length "
                    f"(e.g. the distance to the volume).")
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

    def project(self, p_world_mm) -> np.ndarray:
        """Project world points [mm], shape (..., 3), to pixel coordinates (..., 2).

        For a thin-lens camera this is the image of the chief ray (the centre of the
        defocus blur). A point behind the pinhole projects mirrored (see :meth:`visible`).
        """
        pc = self.world_to_camera(p_world_mm)
        with np.errstate(divide="ignore", invalid="ignore"):
            x = pc[..., 0] / pc[..., 2]
            y = pc[..., 1] / pc[..., 2]
        xd, yd = distort(x, y, self.distortion)
        cx, cy = self.principal_point_px
        f = self.focal_px
        return np.stack([f * xd + cx, f * yd + cy], axis=-1)

    def in_front(self, p_world_mm) -> np.ndarray:
        """Points (..., 3) [mm] in front of the pinhole (camera-frame z > 0), shape (...)."""
        return self.world_to_camera(p_world_mm)[..., 2] > 0

    @property
    def fold_radius(self) -> float:
        """Undistorted normalised radius beyond which the distortion folds back
        (:func:`mitpiv.physics.distortion.fold_radius`; ``inf`` without a fold)."""
        return fold_radius(self.distortion)

    def visible(self, p_world_mm) -> np.ndarray:
        """Points (..., 3) [mm] in front of the pinhole whose projection lands on the sensor
        ``[0, W) x [0, H)``, shape (...). (A point behind the pinhole projects mirrored,
        possibly onto the sensor: reconstructions must leave it out.) With a distortion
        that folds back (strong barrel), a point beyond the fold radius is not visible
        although :meth:`project` may land on the sensor: no pixel's ray reaches it, and the
        renderer's particle tracing leaves it out too."""
        with np.errstate(invalid="ignore", over="ignore"):
            vis = self.in_front(p_world_mm) & on_sensor(self.project(p_world_mm), self.resolution)
            r_fold = self.fold_radius
            if np.isfinite(r_fold):
                pc = self.world_to_camera(p_world_mm)
                vis &= pc[..., 0] ** 2 + pc[..., 1] ** 2 < (r_fold * pc[..., 2]) ** 2
            return vis

    def jacobian(self, p_world_mm) -> np.ndarray:
        """``d(u, v)/d(x, y, z)`` of :meth:`project`, shape (..., 2, 3) [px/mm] (analytic:
        pinhole division, Brown-Conrady Jacobian, rotation)."""
        pc = self.world_to_camera(p_world_mm)
        z = pc[..., 2]
        x, y = pc[..., 0] / z, pc[..., 1] / z
        _, _, a, b, c, e = distort_jacobian(x, y, self.distortion)
        # d(x, y)/d(p_camera)
        dn = np.zeros(pc.shape[:-1] + (2, 3))
        dn[..., 0, 0] = 1 / z
        dn[..., 0, 2] = -x / z
        dn[..., 1, 1] = 1 / z
        dn[..., 1, 2] = -y / z
        dd = np.stack([np.stack([a, b], -1), np.stack([c, e], -1)], -2) * self.focal_px
        return dd @ dn @ self.rotation

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
        m[:3, :3] = self.rotation.T @ CV_TO_MITSUBA
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
        rotation = (r_cw_mi @ CV_TO_MITSUBA).T
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


# ---------------------------------------------------------------------- arrangements
def _entry(rotation, position, target, e1, extra=None) -> dict:
    d = position - target
    cos_scatter = float((d / np.linalg.norm(d)) @ e1)  # laser direction vs direction towards the camera
    out = {"rotation": rotation, "position_mm": position,
           "scattering_angle_deg": float(np.degrees(np.arccos(np.clip(cos_scatter, -1, 1))))}
    out.update(extra or {})
    return out


def ring_arrangement(
    n: int,
    *,
    distance_mm: float,
    elevation_deg: float,
    azimuth_start_deg: float = 0.0,
    azimuth_span_deg: float = 360.0,
    target_mm=(0.0, 0.0, 0.0),
    laser_direction=(1.0, 0.0, 0.0),
    sheet_normal=(0.0, 0.0, 1.0),
) -> list[dict]:
    """``n`` cameras on a cone (fixed elevation) around the target, evenly spread in azimuth.

    A full ring (span 360) spaces them ``360 / n`` apart; a partial span places the first
    and last camera at its ends. Angles in the laser-sheet frame of :func:`place_camera`.
    Each entry: ``rotation``, ``position_mm``, ``azimuth_deg``, ``elevation_deg``,
    ``scattering_angle_deg``.
    """
    if isinstance(n, bool) or int(n) != n or n < 1:
        raise ConfigError(f"ring_arrangement: 'n' must be a positive integer, got {n!r}.")
    n = int(n)
    if azimuth_span_deg >= 360.0:
        az = azimuth_start_deg + 360.0 * np.arange(n) / n
    else:
        az = azimuth_start_deg + (np.linspace(0.0, azimuth_span_deg, n) if n > 1 else np.zeros(1))
    return _scatter_list(az, np.full(n, float(elevation_deg)), distance_mm, target_mm, laser_direction, sheet_normal)


def _scatter_list(az, el, distance_mm, target_mm, laser_direction, sheet_normal) -> list[dict]:
    e1 = np.asarray(laser_direction, dtype=float)
    e1 = e1 / np.linalg.norm(e1)
    out = []
    for a, e in zip(az, el, strict=True):
        rot, pos = place_camera(target_mm=target_mm, azimuth_deg=float(a), elevation_deg=float(e),
                                distance_mm=distance_mm, laser_direction=laser_direction, sheet_normal=sheet_normal)
        out.append(_entry(rot, pos, np.asarray(target_mm, float), e1, {"azimuth_deg": float(a), "elevation_deg": float(e)}))
    return out


def scatter_arrangement(
    kind: str,
    *,
    n: int = 4,
    azimuth_deg: float = 25.0,
    elevation_deg: float = 35.0,
    distance_mm: float,
    target_mm=(0.0, 0.0, 0.0),
    laser_direction=(1.0, 0.0, 0.0),
    sheet_normal=(0.0, 0.0, 1.0),
) -> list[dict]:
    """Tomographic arrangements relative to the laser direction (n = 2 or 4 cameras).

    - ``"forward"``: cameras at azimuth +-``azimuth_deg`` (and elevation +-``elevation_deg``
      for 4), all seeing forward scatter (scattering angle acos(cos el cos az) < 90 deg).
    - ``"backward"``: the same about azimuth 180 (backward scatter).
    - ``"symmetric"``: mirror pairs about the plane normal to the laser: azimuths
      ``a`` and ``180 - a`` (and their negatives for 4) at elevation ``elevation_deg``,
      half in forward and half in backward scatter (the pyramid of scenes/tomo4).
    """
    if n not in (2, 4):
        raise ConfigError(f"scatter_arrangement: 'n' must be 2 or 4, got {n!r}.")
    a, e = float(azimuth_deg), float(elevation_deg)
    if kind == "forward":
        az, el = ([a, -a], [e, e]) if n == 2 else ([a, -a, a, -a], [e, e, -e, -e])
    elif kind == "backward":
        az, el = ([180 - a, 180 + a], [e, e]) if n == 2 else ([180 - a, 180 + a, 180 - a, 180 + a], [e, e, -e, -e])
    elif kind == "symmetric":
        az, el = ([a, 180 - a], [e, e]) if n == 2 else ([a, -a, 180 - a, -(180 - a)], [e, e, e, e])
    else:
        raise ConfigError(f"scatter_arrangement: 'kind' must be 'forward', 'backward' or 'symmetric', got {kind!r}.")
    return _scatter_list(np.array(az), np.array(el), distance_mm, target_mm, laser_direction, sheet_normal)


def planar_array(
    rows: int,
    cols: int,
    *,
    spacing_mm: float,
    distance_mm: float,
    target_mm=(0.0, 0.0, 0.0),
    view_direction=(0.0, 0.0, -1.0),
    up=(0.0, 1.0, 0.0),
    laser_direction=(1.0, 0.0, 0.0),
) -> list[dict]:
    """A rows x cols camera array on a plane ``distance_mm`` from the target, all aimed at it.

    The array plane is normal to ``view_direction`` (the direction the centre camera looks
    along); cameras sit on a grid of pitch ``spacing_mm`` centred on the axis through the
    target (e.g. the 5 x 5, 153 mm synthetic-aperture array). Row 0 is the top (along ``up``).
    """
    for name, v in (("rows", rows), ("cols", cols)):
        if isinstance(v, bool) or int(v) != v or v < 1:
            raise ConfigError(f"planar_array: '{name}' must be a positive integer, got {v!r}.")
    spacing_mm = check_positive("spacing_mm", spacing_mm, owner="planar_array", unit="mm")
    distance_mm = check_positive("distance_mm", distance_mm, owner="planar_array", unit="mm")
    vd = np.asarray(view_direction, dtype=float)
    vd = vd / np.linalg.norm(vd)
    upv = np.asarray(up, dtype=float)
    right = np.cross(vd, upv)
    if np.linalg.norm(right) < 1e-9:
        raise ConfigError("planar_array: 'up' must not be parallel to 'view_direction'.")
    right /= np.linalg.norm(right)
    upv = np.cross(right, vd)
    target = np.asarray(target_mm, dtype=float)
    centre = target - distance_mm * vd
    e1 = np.asarray(laser_direction, dtype=float)
    e1 = e1 / np.linalg.norm(e1)
    out = []
    for i in range(int(rows)):
        for j in range(int(cols)):
            pos = centre + ((j - (cols - 1) / 2) * right + ((rows - 1) / 2 - i) * upv) * spacing_mm
            out.append(_entry(look_at_rotation(pos, target, up=upv), pos, target, e1, {"row": i, "col": j}))
    return out


def scheimpflug(rotation, position_mm, *, focal_length_mm: float, plane_point_mm, plane_normal) -> dict:
    """Scheimpflug focusing of a thin-lens camera on a plane (e.g. the laser-sheet mid-plane).

    The camera keeps its pose; the plane of focus becomes the given plane. Returns
    ``focus_distance_mm`` (where the optical axis meets the plane), ``focus_plane_normal``
    (for the ``distorted_pinhole`` property of that name), the object-plane tilt ``alpha``
    (between the plane and the lens plane), the axial magnification ``M = f / (s - f)`` and
    the sensor tilt a real camera needs, ``beta = atan(M tan(alpha))`` [deg].
    """
    f = check_positive("focal_length_mm", focal_length_mm, owner="scheimpflug", unit="mm")
    r = np.asarray(rotation, dtype=float)
    pos = np.asarray(position_mm, dtype=float)
    n = np.asarray(plane_normal, dtype=float)
    n = n / np.linalg.norm(n)
    axis = r[2]  # optical axis (OpenCV z) in world
    den = float(axis @ n)
    if abs(den) < 1e-6:
        raise ConfigError("scheimpflug: the optical axis is parallel to the plane; it never meets it.")
    s = float((np.asarray(plane_point_mm, dtype=float) - pos) @ n) / den
    if s <= f:
        raise ConfigError(f"scheimpflug: the plane meets the optical axis {s:.4g} mm from the lens, inside the focal length {f} mm.")
    alpha = float(np.degrees(np.arccos(min(1.0, abs(den)))))
    m = f / (s - f)
    beta = float(np.degrees(np.arctan(m * np.tan(np.radians(alpha)))))
    return {"focus_distance_mm": s, "focus_plane_normal": n.tolist(), "object_tilt_deg": alpha,
            "magnification": m, "sensor_tilt_deg": beta}


# ---------------------------------------------------------------------- depth of field
#: Circle of confusion of the focus checks: a point is in focus while its defocus blur spot
#: stays within one pixel (one lenslet for a plenoptic camera).
COC_PX = 1.0


def thin_lens_depth_of_field(*, focal_length_mm: float, f_number: float, focus_distance_mm: float,
                             blur_mm: float) -> tuple[float, float]:
    """(near, far) distances [mm, along the optical axis from the lens] between which a point's
    defocus blur spot on the sensor of a thin-lens ``distorted_pinhole`` stays within ``blur_mm``.

    The renderer's thin lens (as Mitsuba's ``thinlens``) has its image plane at the focal
    length ``f``: a point at depth ``z`` seen through the aperture point ``a`` lands
    ``a (1/s - 1/z)`` (normalised coordinates) from its chief ray's image, ``s`` the focus
    distance, so the blur spot's diameter on the sensor is ``c(z) = f D |1/z - 1/s|`` with the
    aperture ``D = f / N``. ``c(z) <= c`` is ``|1/z - 1/s| <= N c / f^2``; with the hyperfocal
    distance ``H = f^2 / (N c)``::

        near = s H / (H + s),    far = s H / (H - s)   (infinite for s >= H)

    (A physical thin lens with its sensor at the image distance ``s_i = f s / (s - f)`` blurs
    ``s_i / f = 1 + M`` times more; the renderer's model is the one its images follow.)

    Parameters
    ----------
    focal_length_mm, f_number, focus_distance_mm : float
        ``f`` [mm], ``N``, ``s`` [mm].
    blur_mm : float
        Largest blur spot diameter ``c`` on the sensor [mm] (e.g. one pixel pitch).

    Returns
    -------
    (float, float)
        ``near``, ``far`` [mm]; ``far`` is ``inf`` at or beyond the hyperfocal distance.
    """
    f = check_positive("focal_length_mm", focal_length_mm, owner="thin_lens_depth_of_field", unit="mm")
    n = check_positive("f_number", f_number, owner="thin_lens_depth_of_field")
    s = check_positive("focus_distance_mm", focus_distance_mm, owner="thin_lens_depth_of_field", unit="mm")
    c = check_positive("blur_mm", blur_mm, owner="thin_lens_depth_of_field", unit="mm")
    h = f * f / (n * c)
    return s * h / (h + s), (s * h / (h - s) if s < h else math.inf)


def camera_to_world(camera) -> np.ndarray:
    """A camera's 4x4 camera-to-world matrix in Mitsuba's convention (x left, y up, z along the
    optical axis), of a :class:`PinholeCamera` or a plenoptic camera alike."""
    m = camera.to_world_mitsuba
    return np.asarray(m() if callable(m) else m, dtype=float)


def focal_depth(camera, *, coc: float = COC_PX) -> dict | None:
    """Where a camera images sharply: its focus distance ``s`` [mm], the tolerance ``kappa``
    [1/mm] on inverse depth (a point at depth ``z`` along the axis is in focus while
    ``|1/z - 1/s| <= kappa``) and the (near, far) limits on the axis ``1 / (1/s +- kappa)``.

    * thin-lens :class:`PinholeCamera` (an ``f_number``): ``kappa = N c / f^2`` with ``c``
      ``coc`` pixels (:func:`thin_lens_depth_of_field`);
    * :class:`~mitpiv.physics.plenoptic.PlenopticCamera`: the range it refocuses over, where a
      perspective view (one angular sample of the aperture, ``D / n_u``) blurs a point by at
      most ``coc`` lenslets on the MLA (Deem et al. 2016;
      :meth:`~mitpiv.physics.plenoptic.PlenopticCamera.depth_of_field` ``"perspective"``):
      ``kappa = coc p n_u / (D s_i)``;
    * an ideal pinhole: None (infinitely deep; its PSF, if any, is the same at every depth).
    """
    if hasattr(camera, "angular_samples"):  # plenoptic
        s, nu = float(camera.focus_distance_mm), max(float(camera.angular_samples), 1.0)
        kappa = coc * camera.mla_pitch_um * 1e-3 * nu / (camera.aperture_diameter_mm * camera.image_distance_mm)
        what = (f"plenoptic refocusing range (f/{camera.f_number:.3g}, a perspective view blurs by at most "
                f"{coc:g} lenslet)")
    elif getattr(camera, "f_number", None) is not None and getattr(camera, "focus_distance_mm", None) is not None:
        s = float(camera.focus_distance_mm)
        kappa = camera.f_number * coc * camera.pixel_pitch_um * 1e-3 / camera.focal_length_mm ** 2
        what = f"depth of field (thin lens f/{camera.f_number:.3g}, blur of at most {coc:g} px)"
    else:
        return None
    far = 1.0 / (1.0 / s - kappa) if kappa < 1.0 / s else math.inf
    return {"focus_distance_mm": s, "kappa_per_mm": kappa, "near_mm": 1.0 / (1.0 / s + kappa), "far_mm": far,
            "what": what}


def defocus_ratio(camera, p_world_mm, *, focus_plane_normal=None, coc: float = COC_PX) -> np.ndarray:
    """A point's defocus blur in units of the allowed blur (:func:`focal_depth`): ``<= 1`` in
    focus; for a thin lens with ``coc = 1`` it is the blur spot's diameter in pixels.

    ``|1/z - 1/z_f| / kappa`` with ``z`` the point's depth along the optical axis and ``z_f``
    the depth at which its chief ray meets the plane of focus: ``s`` or, for a plane of focus
    tilted to ``focus_plane_normal`` (camera-local Mitsuba frame, as the ``distorted_pinhole``
    records it; Scheimpflug), ``n_z s / (n_x x/z + n_y y/z + n_z)`` (first order in the
    aperture for the tilted plane). Zeros for a camera without a focus (a pinhole); ``inf``
    behind the camera.

    Parameters
    ----------
    camera : Camera
    p_world_mm : (..., 3) float
    focus_plane_normal : (3,) float, optional
    coc : float
        Allowed blur [px; lenslets for a plenoptic camera].

    Returns
    -------
    ndarray (...)
    """
    p = np.asarray(p_world_mm, dtype=float)
    fd = focal_depth(camera, coc=coc)
    if fd is None:
        return np.zeros(p.shape[:-1])
    m = camera_to_world(camera)
    q = (p - m[:3, 3]) @ m[:3, :3]  # camera-local Mitsuba frame (x left, y up, z forward)
    z = q[..., 2]
    s = fd["focus_distance_mm"]
    with np.errstate(divide="ignore", invalid="ignore"):
        if focus_plane_normal is None:
            zf = np.full_like(z, s)
        else:
            nx, ny, nz = (float(v) for v in focus_plane_normal)
            zf = nz * s / (nx * q[..., 0] / z + ny * q[..., 1] / z + nz)
        r = np.abs(1.0 / z - 1.0 / zf) / fd["kappa_per_mm"]
    return np.where(z > 0, r, np.inf)


def sensor_corner_rays(camera) -> tuple[np.ndarray, np.ndarray]:
    """The chief rays through the sensor's four corners ``(0, 0), (W, 0), (W, H), (0, H)``
    (``pixel_to_ray``): origin (3,) and unit directions (4, 3) in world [mm]."""
    w, h = camera.resolution
    return camera.pixel_to_ray(np.array([[0.0, 0.0], [w, 0.0], [w, h], [0.0, h]]))
