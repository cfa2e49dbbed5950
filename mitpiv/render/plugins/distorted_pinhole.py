"""``distorted_pinhole``: pinhole camera with Brown-Conrady distortion and an optional thin lens.

.. list-table::
   :header-rows: 1

   * - Parameter
     - Type
     - Unit
     - Default
     - Meaning
   * - to_world
     - transform
     - mm
     - identity
     - Camera pose (Mitsuba convention: looks along +z, x left, y up). Rigid only.
   * - target, azimuth_deg, elevation_deg, distance_mm
     - point, float
     - mm, deg
     - --
     - Alternative to ``to_world``: place the camera around ``target`` with
       :func:`mitpiv.physics.camera.place_camera` (angles in the laser-sheet frame given
       by ``laser_direction`` (1,0,0) and ``sheet_normal`` (0,0,1)).
   * - focal_length_mm
     - float
     - mm
     - 50
     - Focal length (pinhole to image plane).
   * - pixel_pitch_um
     - float
     - um
     - 10
     - Pixel pitch. The film's width/height give the resolution.
   * - fov
     - float
     - deg
     - --
     - Alternative to ``focal_length_mm``: horizontal field of view.
   * - principal_point_x_px, principal_point_y_px
     - float
     - px
     - image centre
     - Principal point (pixel (i, j) spans [i, i+1)).
   * - k1, k2, k3, p1, p2
     - float
     - --
     - 0
     - Brown-Conrady distortion, OpenCV convention (undistorted -> distorted).
   * - distortion_percent
     - float
     - %
     - --
     - Alternative to ``k1``: radial shift at the image corner (positive = barrel).
   * - f_number
     - float
     - --
     - none
     - Thin-lens aperture (f / diameter); absent = ideal pinhole.
   * - focus_distance_mm
     - float
     - mm
     - --
     - In-focus distance along the optical axis (required with ``f_number``).
   * - near_clip, far_clip
     - float
     - mm
     - 0.01, 1e7
     - Clip distances along the optical axis.

Camera tracing (``sample_ray``) maps a film sample to pixel coordinates, inverts the
distortion (Newton's method, iteration count fixed at construction by a float64 check over
the image) and shoots the chief ray, or, with an aperture, a ray from a uniform aperture
point through the chief ray's point on the focus plane. Particle tracing
(``sample_direction``) runs the forward model: point -> (aperture point ->) focus plane ->
normalised coordinates -> distortion -> pixel, with the importance
``f_px^2 |det J_distortion| / (N_pixels cos^3 theta)``. A distortion that folds over inside
the image is rejected at construction. Distortion and aperture code is only traced when
the scene asks for it.

.. code-block:: xml

    <sensor type="distorted_pinhole" id="cam0">
        <transform name="to_world"><lookat origin="0, -400, 300" target="0, 0, 0" up="0, 0, 1"/></transform>
        <float name="focal_length_mm" value="85"/>
        <float name="pixel_pitch_um" value="10"/>
        <float name="distortion_percent" value="0.5"/>
        <film type="hdrfilm"><integer name="width" value="1024"/><integer name="height" value="1024"/>
            <string name="pixel_format" value="luminance"/></film>
    </sensor>
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from mitpiv.errors import ConfigError, check_positive
from mitpiv.physics.camera import PinholeCamera, place_camera
from mitpiv.physics.distortion import Distortion, distort_jacobian, percent_to_k1, undistort
from mitpiv.render.plugins._props import PropertyReader

_VARIANT = mi.variant()


class DistortedPinhole(mi.Sensor):
    """Distorted pinhole / thin-lens sensor; see the module docstring for parameters."""

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        rd = PropertyReader(props, "distorted_pinhole")
        film = self.film()
        w, h = (int(v) for v in film.size())
        if tuple(film.crop_size()) != (w, h):
            raise ConfigError("distorted_pinhole: film crop windows are not supported; remove crop_*.")
        self.resolution = (w, h)

        pitch = check_positive("pixel_pitch_um", rd.float("pixel_pitch_um", 10.0), owner="distorted_pinhole", unit="um")
        fov = rd.float("fov", None)
        focal = rd.float("focal_length_mm", None)
        if fov is not None and focal is not None:
            raise ConfigError("distorted_pinhole: give 'focal_length_mm' or 'fov', not both.")
        if fov is not None:
            if not 0 < fov < 180:
                raise ConfigError(f"distorted_pinhole: parameter 'fov' must be in (0, 180) deg, got {fov}.")
            focal = (w / 2.0) / math.tan(math.radians(fov) / 2.0) * pitch * 1e-3
        focal = check_positive("focal_length_mm", 50.0 if focal is None else focal, owner="distorted_pinhole", unit="mm")
        cx = rd.float("principal_point_x_px", w / 2.0)
        cy = rd.float("principal_point_y_px", h / 2.0)

        # Pose: to_world (read by the Mitsuba base class) or placement around a target.
        placement = [rd.has(k) for k in ("azimuth_deg", "elevation_deg", "distance_mm")]
        if any(placement):
            if not all(placement):
                raise ConfigError("distorted_pinhole: placement needs all of 'azimuth_deg', 'elevation_deg', 'distance_mm'.")
            if "to_world" in props:
                raise ConfigError("distorted_pinhole: give 'to_world' or azimuth/elevation placement, not both.")
            rot, pos = place_camera(
                target_mm=rd.vector("target", (0.0, 0.0, 0.0)),
                azimuth_deg=rd.float("azimuth_deg"),
                elevation_deg=rd.float("elevation_deg"),
                distance_mm=rd.float("distance_mm"),
                laser_direction=rd.vector("laser_direction", (1.0, 0.0, 0.0)),
                sheet_normal=rd.vector("sheet_normal", (0.0, 0.0, 1.0)),
            )
            tmp = PinholeCamera((w, h), focal, pitch, rotation=rot, position_mm=pos)
            self.m_to_world = mi.Transform4f(tmp.to_world_mitsuba())
        to_world = np.array(self.world_transform().matrix, dtype=np.float64).reshape(4, 4)
        rotation, position = PinholeCamera.rotation_from_mitsuba(to_world)

        k1 = rd.float("k1", None)
        pct = rd.float("distortion_percent", None)
        if k1 is not None and pct is not None:
            raise ConfigError("distorted_pinhole: give 'k1' or 'distortion_percent', not both.")
        dist = Distortion(k1=0.0 if k1 is None else k1, k2=rd.float("k2", 0.0), k3=rd.float("k3", 0.0),
                          p1=rd.float("p1", 0.0), p2=rd.float("p2", 0.0))
        f_number = rd.float("f_number", None)
        focus = rd.float("focus_distance_mm", None)
        self.near_clip = check_positive("near_clip", rd.float("near_clip", 0.01), owner="distorted_pinhole", unit="mm")
        self.far_clip = check_positive("far_clip", rd.float("far_clip", 1e7), owner="distorted_pinhole", unit="mm")
        if self.far_clip <= self.near_clip:
            raise ConfigError(f"distorted_pinhole: far_clip ({self.far_clip}) must exceed near_clip ({self.near_clip}).")
        rd.finish()

        cam = PinholeCamera((w, h), focal, pitch, rotation=rotation, position_mm=position,
                            principal_point_px=(cx, cy), distortion=dist, f_number=f_number,
                            focus_distance_mm=focus)
        if pct is not None:
            cam.distortion = Distortion(k1=percent_to_k1(pct, r_max=cam.corner_radius), k2=dist.k2, k3=dist.k3, p1=dist.p1, p2=dist.p2)
        self.distortion_percent = pct
        # Folding check and Newton iteration count (float64, over the whole image).
        self.newton_iterations = cam.validate_distortion()
        self.camera = cam
        self.m_needs_sample_3 = cam.f_number is not None

        # Constants for the kernels (Python floats: baked into the traced code).
        self._fx = cam.focal_px
        self._cx, self._cy = cam.principal_point_px
        self._n_pix = float(w * h)
        self._r_ap = cam.aperture_radius_mm
        self._pos = mi.ScalarPoint3f(*position.tolist())
        lin = np.eye(4)
        lin[:3, :3] = to_world[:3, :3]
        self._rot_to_world = mi.Transform4f(lin)
        lin_inv = np.eye(4)
        lin_inv[:3, :3] = to_world[:3, :3].T
        self._rot_to_local = mi.Transform4f(lin_inv)

    # ------------------------------------------------------------------ helpers
    def _pixel_to_local_dir(self, u, v):
        """Pixel coordinates -> (x, y) of the chief ray in Mitsuba local coordinates (z = 1)."""
        xd = (u - self._cx) * (1.0 / self._fx)
        yd = (v - self._cy) * (1.0 / self._fx)
        d = self.camera.distortion
        if not d.is_zero:
            xd, yd = undistort(xd, yd, d, iterations=self.newton_iterations)
        return -xd, -yd  # OpenCV (x right, y down) -> Mitsuba (x left, y up)

    # ------------------------------------------------------------------ camera tracing
    def sample_ray(self, time, sample1, sample2, sample3, active=True):
        wavelengths, wav_weight = self.sample_wavelengths(dr.zeros(mi.SurfaceInteraction3f), sample1, active)
        w, h = self.resolution
        lx, ly = self._pixel_to_local_dir(sample2.x * w, sample2.y * h)
        if self.camera.f_number is None:
            d_local = dr.normalize(mi.Vector3f(lx, ly, 1.0))
            o_local = mi.Point3f(0.0)
        else:
            f = self.camera.focus_distance_mm
            a = mi.warp.square_to_uniform_disk_concentric(sample3) * self._r_ap
            o_local = mi.Point3f(a.x, a.y, 0.0)
            d_local = dr.normalize(mi.Vector3f(lx * f - a.x, ly * f - a.y, f))
        inv_z = dr.rcp(d_local.z)
        o_local = o_local + d_local * (self.near_clip * inv_z)
        ray = mi.Ray3f()
        ray.time = time
        ray.wavelengths = wavelengths
        ray.o = self._pos + self._rot_to_world @ mi.Vector3f(o_local)
        ray.d = self._rot_to_world @ d_local
        ray.maxt = (self.far_clip - self.near_clip) * inv_z
        return ray, wav_weight

    def sample_ray_differential(self, time, sample1, sample2, sample3, active=True):
        ray, weight = self.sample_ray(time, sample1, sample2, sample3, active)
        return mi.RayDifferential3f(ray), weight

    # ------------------------------------------------------------------ particle tracing
    def sample_direction(self, it, sample, active=True):
        # Relative to the camera first (precision at large world offsets), then rotate.
        p = self._rot_to_local @ mi.Vector3f(it.p - self._pos)
        active = mi.Bool(active) & (p.z >= self.near_clip) & (p.z <= self.far_clip)
        if self.camera.f_number is None:
            a = mi.Point3f(0.0)
            inv_z = dr.rcp(p.z)
            xn, yn = -p.x * inv_z, -p.y * inv_z
        else:
            f = self.camera.focus_distance_mm
            s = mi.warp.square_to_uniform_disk_concentric(sample) * self._r_ap
            a = mi.Point3f(s.x, s.y, 0.0)
            d = p - a
            t = f * dr.rcp(d.z)
            xn, yn = -(a.x + d.x * t) / f, -(a.y + d.y * t) / f
        dvec = p - a
        dist = dr.norm(dvec)
        cos_t = dvec.z / dist
        dd = self.camera.distortion
        if dd.is_zero:
            xd, yd, jac = xn, yn, 1.0
        else:
            xd, yd, ja, jb, jc, je = distort_jacobian(xn, yn, dd)
            jac = dr.abs(ja * je - jb * jc)
        u = self._fx * xd + self._cx
        v = self._fx * yd + self._cy
        w, h = self.resolution
        active &= (u >= 0) & (u <= w) & (v >= 0) & (v <= h)
        importance = (self._fx * self._fx / self._n_pix) * jac / (cos_t * cos_t * cos_t)
        ds = dr.zeros(mi.DirectionSample3f)
        ds.uv = mi.Point2f(u, v)
        ds.p = self._pos + self._rot_to_world @ mi.Vector3f(a)
        ds.d = (ds.p - it.p) / dist
        ds.dist = dist
        ds.n = self._rot_to_world @ mi.Vector3f(0.0, 0.0, 1.0)
        ds.time = it.time
        if self.camera.f_number is None:
            ds.pdf = dr.select(active, 1.0, 0.0)
        else:
            ds.pdf = dr.select(active, dist * dist / (cos_t * math.pi * self._r_ap**2), 0.0)
        weight = dr.select(active, importance / (dist * dist), 0.0)
        return ds, mi.Spectrum(weight)

    def pdf_direction(self, it, ds, active=True):
        return mi.Float(0.0)

    def eval_direction(self, it, ds, active=True):
        return mi.Spectrum(0.0)

    def sample_position(self, time, sample, active=True):
        return dr.zeros(mi.PositionSample3f), mi.Float(0.0)

    def pdf_position(self, ps, active=True):
        return mi.Float(0.0)

    def eval(self, si, active=True):
        return mi.Spectrum(0.0)

    def sample_wavelengths(self, si, sample, active=True):
        return dr.zeros(mi.Color0f), mi.Spectrum(1.0)

    def bbox(self):
        p = self._pos
        return mi.ScalarBoundingBox3f(p, p)

    def to_string(self):
        c = self.camera
        return (
            f"DistortedPinhole[resolution={c.resolution}, focal_length={c.focal_length_mm} mm, "
            f"pixel_pitch={c.pixel_pitch_um} um, distortion=({c.distortion}), "
            f"f_number={c.f_number}, focus_distance={c.focus_distance_mm} mm]"
        )

    def describe(self) -> dict:
        """JSON-ready camera model for image metadata."""
        d = {"type": "distorted_pinhole", **self.camera.to_dict()}
        d["distortion_percent"] = self.distortion_percent
        d["near_clip_mm"], d["far_clip_mm"] = self.near_clip, self.far_clip
        d["newton_iterations"] = self.newton_iterations
        return d


mi.register_sensor("distorted_pinhole", lambda props: DistortedPinhole(props))
