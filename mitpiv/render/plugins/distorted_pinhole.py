"""``distorted_pinhole``: pinhole camera with Brown-Conrady distortion and an optional thin lens.

Parameters
----------
to_world : transform [mm], default identity
    Camera pose (Mitsuba convention: looks along +z, x left, y up; with
    ``<lookat origin="..." target="..." up="..."/>`` the image's up is ``up`` projected on
    the image plane). Rigid only. Not with a placement.
target : point [mm], default (0, 0, 0)
    Placement (instead of ``to_world``, by :func:`mitpiv.physics.camera.place_camera`):
    the point the camera looks at.
azimuth_deg : float [deg], required for a placement
    Placement: angle in the sheet plane from ``laser_direction`` (e1) towards
    ``sheet_normal x laser_direction`` (e2); 0 is downstream (forward scatter), 180
    upstream (backward scatter).
elevation_deg : float [deg], required for a placement
    Placement: angle out of the sheet plane towards ``sheet_normal`` (e3). The camera
    sits at ``target + distance_mm (cos(el) cos(az) e1 + cos(el) sin(az) e2 + sin(el) e3)``
    and looks at ``target``; the image's up is e3 projected on the image plane, or e2 when
    the camera looks within 8.1 deg of e3 (``|sin(el)| >= 0.99``).
distance_mm : float [mm], required for a placement, range > 0
    Placement: distance from ``target`` to the camera's pinhole (lens centre), which is
    the target's distance along the optical axis.
laser_direction, sheet_normal : vector; default (1, 0, 0), (0, 0, 1)
    Placement only: the laser-sheet frame of the angles, e1 and e3 (``sheet_normal`` is
    made orthogonal to ``laser_direction``; they must not be parallel).
calibration : string, default none
    A user's OpenCV calibration (``.yml``/``.yaml``/``.xml``/``.json``: camera matrix,
    distortion, optionally rvec/tvec in mm; :func:`mitpiv.io.read_opencv_camera`)
    instead of ``focal_length_mm``/``fov``, the principal point and ``k1``..``p2``; its
    pose is used unless ``to_world`` or a placement is given (then the file must hold
    none). Or a DLT or third-order polynomial table (``.csv``/``.json``, several
    cameras; :mod:`mitpiv.io.calibration_tables`): the pose always comes from the table.
    Relative paths resolve against the scene's folder. The film must have the
    calibrated size; ``pixel_pitch_um`` comes from the file or the property.
calibration_camera : string, default the sensor's id
    DLT / polynomial table only: the camera's name (or index) in the table (default: the
    only camera, else the one named as the sensor's ``id``).
calibration_volume_mm : string [mm], default the table's
    Polynomial table only: ``"x_min x_max y_min y_max z_min z_max"``, the calibration
    volume over which a pinhole + Brown-Conrady camera is fitted to the polynomial.
calibration_max_residual_px : float [px], default 0.1, range > 0
    Largest reprojection error accepted for the renderable approximation of a DLT (skew,
    non-square pixels) or a polynomial (the fitted camera); beyond it loading fails.
focal_length_mm : float [mm], default 50, range > 0
    Focal length (pinhole to image plane).
pixel_pitch_um : float [um], default 10, range > 0
    Pixel pitch. The film's width/height give the resolution.
fov : float [deg], range (0, 180)
    Alternative to ``focal_length_mm``: horizontal field of view.
principal_point_x_px, principal_point_y_px : float [px], default image centre
    Principal point (pixel (i, j) spans [i, i+1)).
k1, k2, k3, p1, p2 : float, default 0
    Brown-Conrady distortion, OpenCV convention (undistorted -> distorted).
distortion_percent : float [%]
    Alternative to ``k1``: radial shift at the image corner (positive = barrel).
f_number : float, default none
    Thin-lens aperture (f / diameter); absent = ideal pinhole.
photometric_f_number : float, default ``psf_f_number``, range > 0
    Pinhole only: the f-number whose aperture the camera collects light through, for the
    sensor model's aperture photometry (:mod:`mitpiv.photometry`), keeping the pinhole's
    infinite depth of field. A thin lens collects through its ``f_number``.
focus_distance_mm : float [mm]
    In-focus distance along the optical axis (required with ``f_number``).
focus_plane_normal : vector, default optical axis
    Thin lens only: normal (world) of a tilted plane of focus through the axis point at
    ``focus_distance_mm`` (Scheimpflug; see :func:`mitpiv.physics.camera.scheimpflug`).
    The pixel mapping stays that of the untilted sensor; the importance carries the
    Jacobian of the tilted-plane mapping, so both transport strategies agree.
near_clip, far_clip : float [mm]; default 0.01, 1e7; range > 0
    Clip distances along the optical axis (``far_clip`` > ``near_clip``).
psf : string, default none, one of ``none``, ``fft``, ``jitter``
    Diffraction/aberration PSF: ``none``, ``fft`` (space invariant: oversampled render,
    FFT convolution by :func:`mitpiv.render.render.render_sensor`; film filter
    ``catmullrom`` (best), ``lanczos`` or ``tent``) or
    ``jitter`` (ray offsets drawn from the PSF, may vary over the field; film filter
    ``box``). See :class:`mitpiv.imaging.RenderPSF`. ``fft`` happens after rendering:
    ``mi.render`` alone returns the image without it; use ``render_sensor`` or
    ``mitpiv.render_scene``.
psf_f_number : float, default ``f_number``
    Diffraction f-number (default: the thin lens'; a pinhole must give it).
psf_wavelength_nm : float [nm], default 532
    Wavelength of the diffraction PSF.
psf_magnification : float, default from the focus or the placement
    Magnification M of the working f-number ``N (1 + |M|)``. Not given: a thin lens'
    ``f / (focus_distance_mm - f)``; a pinhole placed around a target, ``f / (d - f)``
    with ``f`` the ``focal_length_mm`` and ``d > f`` the placement's ``distance_mm`` (the
    target's distance along the optical axis; logged); a pinhole posed by ``to_world``
    alone states no distance and gets none (the plain f-number ``N``, as M = 0). The
    camera's ``describe()`` records it (``psf``) and where it came from
    (``psf_magnification_from``).
psf_zernike, psf_defocus_waves, psf_spherical_waves : string, float [waves RMS]; default none
    Wavefront: ``"noll:waves, ..."`` (e.g. ``"11:0.05, 8:0.02"``), plus shorthands for
    Noll 4 and 11.
psf_defocus_corner_waves : float [waves RMS], default 0
    ``jitter`` only: field curvature, defocus growing as ``(h / h_corner)^2``.
psf_energy_tolerance, psf_oversample, psf_table_oversample, psf_field_levels : float, int; default 1e-3, 5, 8, 16
    Accuracy knobs: PSF window truncation; FFT render oversampling (odd); jitter table
    cells per pixel; field heights tabulated.

Notes
-----
Camera tracing (``sample_ray``) maps a film sample to pixel coordinates, inverts the
distortion (Newton's method, iteration count fixed at construction by a float64 check over
the image) and shoots the chief ray, or, with an aperture, a ray from a uniform aperture
point through the chief ray's point on the focus plane. Particle tracing
(``sample_direction``) runs the forward model: point -> (aperture point ->) focus plane ->
normalised coordinates -> distortion -> pixel, with the importance weight
``W = f_px^2 |det J_distortion| / (N_pixels cos^3(theta) |p - a|^2)`` [mm^-2], where
``p - a`` runs from the aperture point ``a`` (the pinhole itself without a lens) to the
point, ``|p - a|`` is its length [mm] and ``theta`` its angle to the optical axis (a tilted
plane of focus multiplies ``W`` by that mapping's Jacobian too). That is
``W = 1 / (N_pixels Omega_pix |p - a|^2)`` with ``Omega_pix = cos^3(theta) / (f_px^2
|det J_distortion|)`` the solid angle [sr] of the pixel the point lands on; the particle
tracer multiplies it by the particle's intensity [W/sr] and by ``N_pixels``, so a particle
adds ``I / (|p - a|^2 Omega_pix)`` [W mm^-2 sr^-1] to the image (averaged over the aperture
points): radiance averaged over the pixel footprint, the quantity camera tracing estimates
(the absolute formula: ``docs/radiometry.md``). A distortion that folds over inside
the image is rejected at construction. A strong barrel distortion that folds back *outside*
the image (beyond the undistorted radius :func:`~mitpiv.physics.distortion.fold_radius`)
would map points far outside the field of view onto the image: particle tracing leaves
points beyond the fold radius out, as camera tracing (which never reaches them) and the
reconstruction mapping (:meth:`~mitpiv.physics.camera.PinholeCamera.visible`) do. Distortion, aperture and PSF code is only traced when
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

import logging
import math

import drjit as dr
import mitsuba as mi
import numpy as np

from mitpiv.errors import ConfigError, check_positive
from mitpiv.imaging import RenderPSF
from mitpiv.physics.camera import PinholeCamera
from mitpiv.physics.distortion import Distortion, distort_jacobian, percent_to_k1, undistort
from mitpiv.render.plugins._endpoint import MitpivSensor

_VARIANT = mi.variant()


class DistortedPinhole(MitpivSensor):
    """Distorted pinhole / thin-lens sensor; see the module docstring for parameters."""

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        rd, film, (w, h) = self._open(props, "distorted_pinhole")
        self.resolution = (w, h)

        calibration = rd.string("calibration", None)
        if calibration is not None:
            return self._init_calibrated(props, rd, calibration, (w, h))
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
        self._place(rd, props)
        to_world = self._to_world()
        rotation, position = PinholeCamera.rotation_from_mitsuba(to_world)

        k1 = rd.float("k1", None)
        pct = rd.float("distortion_percent", None)
        if k1 is not None and pct is not None:
            raise ConfigError("distorted_pinhole: give 'k1' or 'distortion_percent', not both.")
        dist = Distortion(k1=0.0 if k1 is None else k1, k2=rd.float("k2", 0.0), k3=rd.float("k3", 0.0),
                          p1=rd.float("p1", 0.0), p2=rd.float("p2", 0.0))
        f_number = rd.float("f_number", None)
        focus = rd.float("focus_distance_mm", None)
        self.photometric_f_number = _photometric_f_number(rd, f_number)
        focus_normal = rd.vector("focus_plane_normal", None)
        self.near_clip = check_positive("near_clip", rd.float("near_clip", 0.01), owner="distorted_pinhole", unit="mm")
        self.far_clip = check_positive("far_clip", rd.float("far_clip", 1e7), owner="distorted_pinhole", unit="mm")
        if self.far_clip <= self.near_clip:
            raise ConfigError(f"distorted_pinhole: far_clip ({self.far_clip}) must exceed near_clip ({self.near_clip}).")
        psf_props = _read_psf_props(rd, f_number, focus, focal, pitch, distance_mm=self.placement_distance_mm)
        rd.finish()

        cam = PinholeCamera((w, h), focal, pitch, rotation=rotation, position_mm=position,
                            principal_point_px=(cx, cy), distortion=dist, f_number=f_number,
                            focus_distance_mm=focus)
        if pct is not None:
            cam.distortion = Distortion(k1=percent_to_k1(pct, r_max=cam.corner_radius), k2=dist.k2, k3=dist.k3, p1=dist.p1, p2=dist.p2)
        self.distortion_percent = pct
        self._finish_init(cam, to_world, focus_normal, psf_props, film)

    def _init_calibrated(self, props, rd, calibration: str, size) -> None:
        """The camera of a user's calibration file (the ``calibration`` property): OpenCV, or a
        DLT / polynomial table (:mod:`mitpiv.io.calibration_tables`)."""
        from mitpiv.io.calibration_tables import (
            calibration_table_format,
            read_dlt_cameras,
            read_dlt_table,
            read_polynomial_cameras,
            read_polynomial_table,
            select_camera,
        )
        from mitpiv.io.opencv import read_opencv_camera

        clash = [k for k in ("focal_length_mm", "fov", "principal_point_x_px", "principal_point_y_px", "k1", "k2", "k3",
                             "p1", "p2", "distortion_percent") if rd.has(k)]
        if clash:
            raise ConfigError(f"distorted_pinhole: 'calibration' gives the intrinsics and distortion; remove {clash}.")
        pitch = rd.float("pixel_pitch_um", None)
        xml_pose = self._place(rd, props) or "to_world" in props
        f_number = rd.float("f_number", None)
        focus = rd.float("focus_distance_mm", None)
        self.photometric_f_number = _photometric_f_number(rd, f_number)
        focus_normal = rd.vector("focus_plane_normal", None)
        self.near_clip = check_positive("near_clip", rd.float("near_clip", 0.01), owner="distorted_pinhole", unit="mm")
        self.far_clip = check_positive("far_clip", rd.float("far_clip", 1e7), owner="distorted_pinhole", unit="mm")
        path = str(mi.file_resolver().resolve(calibration))
        which = rd.string("calibration_camera", None)
        vol = rd.string("calibration_volume_mm", None)
        max_res = rd.float("calibration_max_residual_px", None)
        fmt = calibration_table_format(path)
        self.calibration_info = None
        if fmt in ("dlt", "polynomial"):
            if xml_pose:
                raise ConfigError(f"distorted_pinhole: the {fmt} table {calibration!r} holds the camera's pose; remove "
                                  f"to_world / the placement (target, azimuth_deg, ...).")
            volume = None
            if vol is not None:
                try:
                    volume = [float(v) for v in vol.replace(",", " ").split()]
                except ValueError:
                    volume = []
                if len(volume) != 6:
                    raise ConfigError(f"distorted_pinhole: 'calibration_volume_mm' must be six numbers 'x_min x_max "
                                      f"y_min y_max z_min z_max' [mm], got {vol!r}.")
            records = (read_dlt_table if fmt == "dlt" else read_polynomial_table)(path)[0]
            if which is None and len(records) > 1:
                which = props.id() or None  # the sensor's id names its camera in the table
            rec = select_camera(records, which, path=calibration)
            kw = {"camera": rec["name"], "pixel_pitch_um": pitch, "resolution": size, "f_number": f_number,
                  "focus_distance_mm": focus}
            if max_res is not None:
                kw["max_residual_px"] = check_positive("calibration_max_residual_px", max_res,
                                                       owner="distorted_pinhole", unit="px")
            if fmt == "dlt":
                cam, self.calibration_info = read_dlt_cameras(path, volume_mm=volume, **kw)
            else:
                cam, self.calibration_info = read_polynomial_cameras(path, volume_mm=volume, **kw)
            res = self.calibration_info.get("max_px", self.calibration_info.get("max_residual_px"))
            logging.getLogger(__name__).info("distorted_pinhole: camera %r of the %s table %s, renderable within %.3g px",
                                             rec["name"], fmt, calibration, res)
        else:
            extra = [k for k, v in (("calibration_camera", which), ("calibration_volume_mm", vol),
                                    ("calibration_max_residual_px", max_res)) if v is not None]
            if extra:
                raise ConfigError(f"distorted_pinhole: {extra} apply to DLT and polynomial tables only; "
                                  f"{calibration!r} is an OpenCV calibration (one camera, no volume).")
            cam = read_opencv_camera(path, pixel_pitch_um=pitch, resolution=size, f_number=f_number,
                                     focus_distance_mm=focus, pose="forbid" if xml_pose else "optional")
        if not xml_pose:
            self.m_to_world = mi.Transform4f(cam.to_world_mitsuba())
        to_world = self._to_world()
        cam.rotation, cam.position_mm = PinholeCamera.rotation_from_mitsuba(to_world)
        psf_props = _read_psf_props(rd, f_number, focus, cam.focal_length_mm, cam.pixel_pitch_um,
                                    distance_mm=self.placement_distance_mm)
        rd.finish()
        self.distortion_percent = None
        self.calibration_file = path
        self._finish_init(cam, to_world, focus_normal, psf_props, self.film())

    def _finish_init(self, cam, to_world, focus_normal, psf_props, film) -> None:
        w, h = cam.resolution
        # Folding check and Newton iteration count (float64, over the whole image).
        self.newton_iterations = cam.validate_distortion()
        self.camera = cam
        self._focus_n = None
        if focus_normal is not None:
            if cam.f_number is None:
                raise ConfigError("distorted_pinhole: 'focus_plane_normal' needs a thin lens ('f_number', 'focus_distance_mm').")
            self._focus_n = _focus_plane_local(focus_normal, to_world, cam)
        psf_props = None if psf_props is None else dict(psf_props)
        #: where the PSF's magnification came from (describe()): "given", "thin lens
        #: focus_distance_mm", "placement distance_mm", or None (none: the plain f-number)
        self.psf_magnification_from = None if psf_props is None else psf_props.pop("magnification_from")
        self.psf = None if psf_props is None else _make_psf(psf_props, film)
        self.m_needs_sample_3 = cam.f_number is not None or self.psf_mode == "jitter"
        if self.psf_mode == "jitter":
            self._build_psf_sampler(cam)

        # Constants for the kernels (Python floats: baked into the traced code).
        self._fx = cam.focal_px
        self._cx, self._cy = cam.principal_point_px
        self._n_pix = float(w * h)
        self._r_ap = cam.aperture_radius_mm
        self._r_fold = cam.fold_radius  # normalised; inf without a fold
        self._set_pose(to_world)

    # ------------------------------------------------------------------ helpers
    def _pixel_to_local_dir(self, u, v):
        """Pixel coordinates -> (x, y) of the chief ray in Mitsuba local coordinates (z = 1)."""
        xd = (u - self._cx) * (1.0 / self._fx)
        yd = (v - self._cy) * (1.0 / self._fx)
        d = self.camera.distortion
        if not d.is_zero:
            xd, yd = undistort(xd, yd, d, iterations=self.newton_iterations)
        return -xd, -yd  # OpenCV (x right, y down) -> Mitsuba (x left, y up)

    @property
    def psf_mode(self) -> str:
        return "none" if self.psf is None else self.psf.mode

    def _build_psf_sampler(self, cam):
        tables, size, levels = self.psf.jitter_tables
        cdf = np.cumsum(tables.reshape(levels, -1), axis=1)
        cdf /= cdf[:, -1:]
        cdf += np.arange(levels)[:, None]
        self._psf_cdf = mi.Float(cdf.ravel().astype(np.float32))
        self._psf_size = size
        self._psf_levels = levels
        self._psf_cell_px = 1.0 / self.psf.table_oversample
        w, h = self.resolution
        cx, cy = cam.principal_point_px
        self._psf_inv_h2 = 1.0 / max((u - cx) ** 2 + (v - cy) ** 2 for u in (0, w) for v in (0, h))

    def _psf_offset(self, u, v, s):
        """Offset (dx, dy) [px] drawn from the PSF at film position (u, v), from uniforms s."""
        sx, sy = s.x, s.y
        if self._psf_levels > 1:
            t = dr.clip(((u - self._cx) ** 2 + (v - self._cy) ** 2) * self._psf_inv_h2, 0.0, 1.0) * (self._psf_levels - 1)
            k0 = dr.minimum(mi.UInt32(dr.floor(t)), self._psf_levels - 2)
            frac = t - mi.Float(k0)
            up = sy < frac
            sy = dr.select(up, sy / dr.maximum(frac, 1e-12), (sy - frac) / dr.maximum(1.0 - frac, 1e-12))
            level = mi.Float(k0 + dr.select(up, 1, 0))
        else:
            level = mi.Float(0.0)
        target = level + dr.minimum(sx, 0.999999)
        cdf = self._psf_cdf
        n = dr.width(cdf)
        idx = dr.binary_search(0, n - 1, lambda i: dr.gather(mi.Float, cdf, i) <= target)
        prev = dr.select(idx > 0, dr.gather(mi.Float, cdf, dr.maximum(idx, 1) - 1), 0.0)
        cell = dr.maximum(dr.gather(mi.Float, cdf, idx) - prev, 1e-30)
        ux = dr.clip((target - prev) / cell, 0.0, 1.0)
        ss = self._psf_size * self._psf_size
        j = idx % ss
        row = mi.Float(j // self._psf_size)
        col = mi.Float(j % self._psf_size)
        half = self._psf_size // 2
        return (col - half + ux - 0.5) * self._psf_cell_px, (row - half + sy - 0.5) * self._psf_cell_px

    def _tilted_focus(self, a, d):
        """Image (x, y) (OpenCV normalised) of the ray a + t d via the tilted focus plane, and
        |d(x, y)/d(xi, eta)| with (xi, eta) = (d.x, d.y) / d.z (the importance Jacobian)."""
        nx, ny, nz = self._focus_n
        xi, eta = d.x / d.z, d.y / d.z
        c = nz * self.camera.focus_distance_mm - nx * a.x - ny * a.y
        den = nx * xi + ny * eta + nz
        t = c / den
        t_xi, t_eta = -c * nx / (den * den), -c * ny / (den * den)
        px, py, pz = a.x + t * xi, a.y + t * eta, t
        inv = 1.0 / pz
        x, y = px * inv, py * inv
        # d(px, py, pz)/d(xi) = (t + xi t_xi, eta t_xi, t_xi); /d(eta) = (xi t_eta, t + eta t_eta, t_eta)
        x_xi = (t + xi * t_xi - x * t_xi) * inv
        y_xi = (eta * t_xi - y * t_xi) * inv
        x_eta = (xi * t_eta - x * t_eta) * inv
        y_eta = (t + eta * t_eta - y * t_eta) * inv
        return -x, -y, dr.abs(x_xi * y_eta - x_eta * y_xi)

    @staticmethod
    def _hash2(a, b):
        """Two uniforms decorrelated from the 2D samples a, b (TEA hash of their bits)."""
        ax = dr.reinterpret_array(mi.UInt32, a.x)
        ay = dr.reinterpret_array(mi.UInt32, a.y)
        bx = dr.reinterpret_array(mi.UInt32, b.x)
        by = dr.reinterpret_array(mi.UInt32, b.y)
        return mi.Point2f(mi.sample_tea_float32(ax ^ by, ay), mi.sample_tea_float32(ay ^ bx, ax ^ 0x9E3779B9))

    # ------------------------------------------------------------------ camera tracing
    def sample_ray(self, time, sample1, sample2, sample3, active=True):
        wavelengths, wav_weight = self.sample_wavelengths(dr.zeros(mi.SurfaceInteraction3f), sample1, active)
        w, h = self.resolution
        u, v = sample2.x * w, sample2.y * h
        if self.psf_mode == "jitter":
            s = sample3 if self.camera.f_number is None else self._hash2(sample2, sample3)
            dx, dy = self._psf_offset(u, v, s)
            u, v = u - dx, v - dy  # I(x) = E[I0(x - delta)], delta ~ PSF
        lx, ly = self._pixel_to_local_dir(u, v)
        if self.camera.f_number is None:
            d_local = dr.normalize(mi.Vector3f(lx, ly, 1.0))
            o_local = mi.Point3f(0.0)
        else:
            f = self.camera.focus_distance_mm
            a = mi.warp.square_to_uniform_disk_concentric(sample3) * self._r_ap
            o_local = mi.Point3f(a.x, a.y, 0.0)
            if self._focus_n is not None:  # chief ray meets the tilted plane of focus at s (lx, ly, 1)
                nx, ny, nz = self._focus_n
                f = (nz * self.camera.focus_distance_mm) / (nx * lx + ny * ly + nz)
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
            if self._focus_n is None:
                t = f * dr.rcp(d.z)
                xn, yn = -(a.x + d.x * t) / f, -(a.y + d.y * t) / f
            else:
                xn, yn, tilt_jac = self._tilted_focus(a, d)
        dvec = p - a
        dist = dr.norm(dvec)
        cos_t = dvec.z / dist
        dd = self.camera.distortion
        if math.isfinite(self._r_fold):
            # beyond the fold the distortion maps back onto the image, where no pixel's ray
            # (camera tracing: the inverse, on the principal branch) reaches: not seen
            active &= xn * xn + yn * yn < self._r_fold * self._r_fold
        if dd.is_zero:
            xd, yd, jac = xn, yn, 1.0
        else:
            xd, yd, ja, jb, jc, je = distort_jacobian(xn, yn, dd)
            jac = dr.abs(ja * je - jb * jc)
        u = self._fx * xd + self._cx
        v = self._fx * yd + self._cy
        w, h = self.resolution
        if self.psf_mode == "jitter":
            s = sample if self.camera.f_number is None else self._hash2(sample, mi.Point2f(xd, yd))
            dx, dy = self._psf_offset(u, v, s)
            u, v = u + dx, v + dy
        active &= (u >= 0) & (u <= w) & (v >= 0) & (v <= h)
        if self._focus_n is not None:
            jac = jac * tilt_jac
        importance = (self._fx * self._fx / self._n_pix) * jac / (cos_t * cos_t * cos_t)
        ds = dr.zeros(mi.DirectionSample3f)
        # An oversampled film (PSF 'fft' mode, set by render_sensor) gets scaled positions.
        scale = self.film().size()[0] / w
        ds.uv = mi.Point2f(u, v) if scale == 1 else mi.Point2f(u * scale, v * scale)
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

    def to_string(self):
        c = self.camera
        return (
            f"DistortedPinhole[resolution={c.resolution}, focal_length={c.focal_length_mm} mm, "
            f"pixel_pitch={c.pixel_pitch_um} um, distortion=({c.distortion}), "
            f"f_number={c.f_number}, focus_distance={c.focus_distance_mm} mm, psf={self.psf_mode}]"
        )

    def describe(self) -> dict:
        """JSON-ready camera model for image metadata."""
        d = {"type": "distorted_pinhole", **self.camera.to_dict()}
        d["distortion_percent"] = self.distortion_percent
        d["near_clip_mm"], d["far_clip_mm"] = self.near_clip, self.far_clip
        d["newton_iterations"] = self.newton_iterations
        d["focus_plane_normal_camera_mitsuba"] = None if self._focus_n is None else list(self._focus_n)
        d["psf"] = None if self.psf is None else self.psf.to_dict()
        d["psf_magnification_from"] = self.psf_magnification_from
        d["photometric_f_number"] = self.photometric_f_number
        return d


def _focus_plane_local(normal_world, to_world, cam) -> tuple[float, float, float]:
    """Unit normal of the plane of focus in Mitsuba's camera frame, oriented towards the camera,
    after checking that the plane lies in front of the camera over the whole image."""
    n = np.asarray(normal_world, dtype=float)
    if not np.all(np.isfinite(n)) or np.linalg.norm(n) == 0:
        raise ConfigError(f"distorted_pinhole: 'focus_plane_normal' must be a non-zero vector, got {normal_world!r}.")
    n_loc = to_world[:3, :3].T @ (n / np.linalg.norm(n))
    if n_loc[2] < 0:
        n_loc = -n_loc
    if n_loc[2] < 0.05:
        raise ConfigError(
            f"distorted_pinhole: the plane of focus (normal {np.round(n, 4).tolist()}) is within 3 degrees of "
            f"containing the optical axis; it cannot be the plane of focus."
        )
    w, h = cam.resolution
    cx, cy = cam.principal_point_px
    for u in (0, w):
        for v in (0, h):
            lx, ly = -(u - cx) / cam.focal_px, -(v - cy) / cam.focal_px
            den = n_loc[0] * lx + n_loc[1] * ly + n_loc[2]
            if den <= 0:
                raise ConfigError(
                    f"distorted_pinhole: the tilted plane of focus passes behind the camera at image corner "
                    f"({u}, {v}); reduce its tilt (focus_plane_normal {np.round(n, 4).tolist()})."
                )
    return tuple(float(x) for x in n_loc)


def _photometric_f_number(rd, f_number):
    """The pinhole's stated photometric f-number (None: not stated, or a thin lens)."""
    n = rd.float("photometric_f_number", None)
    if n is None:
        return None
    if f_number is not None:
        raise ConfigError(f"distorted_pinhole: 'photometric_f_number' ({n}) is for a pinhole; this camera is a thin lens "
                          f"and collects light through its 'f_number' ({f_number}). Remove 'photometric_f_number'.")
    return check_positive("photometric_f_number", n, owner="distorted_pinhole")


def _read_psf_props(rd, f_number, focus, focal, pitch, *, distance_mm=None):
    """Read the psf_* properties (None when the scene asks for no PSF). Without
    ``psf_magnification`` the magnification is a thin lens' ``f / (focus - f)``, or a
    pinhole's ``f / (d - f)`` with ``d = distance_mm`` the placement's distance to its target
    (the camera looks at it: the distance along the optical axis), logged; a pinhole posed
    by ``to_world`` alone has none. ``magnification_from`` says which."""
    mode = rd.string("psf", "none")
    names = ("psf_f_number", "psf_wavelength_nm", "psf_magnification", "psf_zernike", "psf_defocus_waves",
             "psf_spherical_waves", "psf_defocus_corner_waves", "psf_energy_tolerance", "psf_oversample",
             "psf_table_oversample", "psf_field_levels")
    if mode == "none":
        given = [k for k in names if rd.has(k)]
        if given:
            raise ConfigError(f"distorted_pinhole: {given} given but psf is 'none'; add <string name=\"psf\" value=\"fft\"/> or \"jitter\".")
        return None
    n = rd.float("psf_f_number", f_number)
    if n is None:
        raise ConfigError("distorted_pinhole: psf needs 'psf_f_number' (the camera is a pinhole, without 'f_number').")
    mag = rd.float("psf_magnification", None)
    source = None if mag is None else "given"
    if mag is None and f_number is not None and focus is not None and focal is not None and focus > focal:
        mag, source = focal / (focus - focal), "thin lens focus_distance_mm"
    elif mag is None and f_number is None and distance_mm is not None and focal is not None and distance_mm > focal:
        mag, source = focal / (distance_mm - focal), "placement distance_mm"
        logging.getLogger(__name__).info(
            "distorted_pinhole: psf_magnification %.6g = f / (d - f) = %g / %g (focal_length_mm %g, the placement's "
            "distance_mm %g; give 'psf_magnification' to override)", mag, focal, distance_mm - focal, focal, distance_mm)
    coefs = {}
    text = rd.string("psf_zernike", "")
    for item in filter(None, (t.strip() for t in text.split(","))):
        try:
            j, c = item.split(":")
            coefs[int(j)] = coefs.get(int(j), 0.0) + float(c)
        except ValueError:
            raise ConfigError(
                f"distorted_pinhole: parameter 'psf_zernike' must read 'noll:waves, ...' (e.g. '11:0.05, 8:0.02'), "
                f"got {text!r}."
            ) from None
    for j, key in ((4, "psf_defocus_waves"), (11, "psf_spherical_waves")):
        c = rd.float(key, 0.0)
        if c:
            coefs[j] = coefs.get(j, 0.0) + c
    return dict(mode=mode, f_number=n, pixel_pitch_um=pitch, wavelength_nm=rd.float("psf_wavelength_nm", 532.0),
                magnification=mag, magnification_from=source, zernike_coefficients=tuple(sorted(coefs.items())),
                defocus_corner_waves=rd.float("psf_defocus_corner_waves", 0.0),
                energy_tolerance=rd.float("psf_energy_tolerance", 1e-3), oversample=rd.int("psf_oversample", 5),
                table_oversample=rd.int("psf_table_oversample", 8), field_levels=rd.int("psf_field_levels", 16))


_PSF_FILTERS = {"fft": ("TentFilter", "CatmullRomFilter", "LanczosSincFilter"), "jitter": ("BoxFilter",)}


def _make_psf(props: dict, film) -> RenderPSF:
    psf = RenderPSF(**props)
    # FFT: an interpolating splat keeps the sub-pixel position of a particle on the fine
    # film; jitter: the PSF is sampled already, the box filter integrates over the pixel.
    have = film.rfilter().class_name()
    if have not in _PSF_FILTERS[psf.mode]:
        names = {"TentFilter": "tent", "CatmullRomFilter": "catmullrom", "LanczosSincFilter": "lanczos", "BoxFilter": "box"}
        ok = " or ".join(f'<rfilter type="{names[k]}"/>' for k in _PSF_FILTERS[psf.mode])
        raise ConfigError(
            f"distorted_pinhole: psf '{psf.mode}' needs the film's reconstruction filter to be {ok} "
            f"(got {have}); set it in the film."
        )
    return psf


mi.register_sensor("distorted_pinhole", lambda props: DistortedPinhole(props))
