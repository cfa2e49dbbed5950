"""``plenoptic``: plenoptic 1.0 camera (thin main lens + microlens array + sensor).

Geometry and frames: :mod:`mitpiv.physics.plenoptic`. The film's width/height give the
sensor resolution; use a ``box`` reconstruction filter (a pixel integrates its own area).

Parameters
----------
preset : string, default none
    A reference camera of :data:`mitpiv.physics.plenoptic.PRESETS` (``lytro_like``,
    ``lfpiv_hex_{800,1600}_pmr{7,14,28}``); the other parameters override it. The film
    size must equal the preset's resolution.
to_world : transform [mm], default identity
    Pose of the main lens (Mitsuba convention: looks along +z, x left, y up), as for
    ``distorted_pinhole``. Not with a placement.
target : point [mm], default (0, 0, 0)
    Placement (instead of ``to_world``, as for ``distorted_pinhole``): the point the main
    lens looks at.
azimuth_deg, elevation_deg : float [deg], required for a placement
    Placement angles in the laser-sheet frame, as for ``distorted_pinhole``: azimuth in
    the sheet plane from ``laser_direction``, elevation out of it towards ``sheet_normal``.
distance_mm : float [mm], required for a placement, range > 0
    Placement: distance from ``target`` to the main lens' centre, along the optical axis.
laser_direction, sheet_normal : vector; default (1, 0, 0), (0, 0, 1)
    Placement only: the laser-sheet frame of the angles.
focal_length_mm : float [mm], required without a preset
    Main-lens focal length.
f_number : float, required without a preset (or ``aperture_diameter_mm``)
    Main-lens aperture as an f-number. Not with ``aperture_diameter_mm``.
aperture_diameter_mm : float [mm], required without a preset (or ``f_number``)
    Main-lens aperture diameter, instead of ``f_number``.
focus_distance_mm : float [mm], required without a preset
    Object distance in focus on the MLA.
pixel_pitch_um : float [um], required without a preset
    Sensor pixel pitch.
mla_pitch_um : float [um], required without a preset
    Lenslet pitch.
mla_focal_length_um : float [um], default f-number matched
    Lenslet focal length (default ``p s_i / D``).
mla_layout : string, default ``rect``, one of ``rect``, ``hex``
    ``rect`` or ``hex``.
mla_count_x, mla_count_y : integer, default fill the sensor
    Lenslets per row and rows.
mla_rotation_deg, mla_offset_x_um, mla_offset_y_um, mla_gap_um : float [deg, um]; default 0, 0, 0, lenslet focal length
    Misalignment of the array and its distance to the sensor.
k1, k2, k3 : float, default 0
    Radial distortion of the main lens (Brown-Conrady on the object-side ray tangent;
    :class:`mitpiv.physics.plenoptic.PlenopticCamera`, ``distortion``). The pixel weights
    stay those of the undistorted lens (the distortion moves light; the irradiance change,
    ``O(k1 r^2)``, is not modelled).
crosstalk_sample_fraction : float, default 0.8, range (0, 1)
    Camera tracing only, when neighbouring lenslets can light a pixel: the share of
    samples sent through the pixel's own lenslet (importance sampling; unbiased for any
    value in (0, 1)).
far_clip : float [mm], default 1e7, range > 0
    Ray length.

Notes
-----
Camera tracing (``sample_ray``): pixel point -> a lenslet (its own, or with f-number
mismatch a neighbour that can reach it) -> a uniform point on that lenslet's cell ->
thin-lens refraction at the lenslet -> main-lens plane (rays outside the aperture are
vignetted: weight zero, counted in :meth:`Plenoptic.ray_stats`) -> refraction -> scene.
Particle tracing (``sample_direction``): scene point -> uniform main-lens aperture point ->
refraction -> MLA plane (the lenslet whose cell it hits) -> refraction -> sensor pixel,
with the importance weight ``W = pi R_ap^2 cos(theta_a) / (|p - a|^2 p_pix^2 N_pixels)``
[sr mm^-2]: ``|p - a|`` [mm] the distance from the point to the aperture point ``a``,
``theta_a`` its angle to the optical axis, ``R_ap`` the aperture radius and ``p_pix`` the
pixel pitch [mm]; averaged over ``a`` it is the aperture's solid angle seen from the point
divided by the pixel area (and ``N_pixels``, which the particle tracer multiplies back).
Refraction is the ideal thin lens, exact in ray tangents. Pixel values are sensor
irradiance [W/mm^2] averaged over the pixel, with the power entering the aperture from
the scene conserved: a point source of intensity I on the axis at distance z puts
``I 2 pi (1 - z / sqrt(z^2 + D^2/4))`` watts on the sensor; both strategies estimate the
same image.

.. code-block:: xml

    <sensor type="plenoptic">
        <string name="preset" value="lfpiv_hex_800_pmr14"/>
        <transform name="to_world"><lookat origin="0, 0, 250" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="800"/><integer name="height" value="800"/>
            <string name="pixel_format" value="luminance"/><rfilter type="box"/></film>
    </sensor>
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from mitpiv.errors import ConfigError, check_positive
from mitpiv.physics.camera import CV_TO_MITSUBA as _CV_TO_MI
from mitpiv.physics.camera import PinholeCamera
from mitpiv.physics.distortion import Distortion, distort, undistort
from mitpiv.physics.plenoptic import PRESETS, PlenopticCamera
from mitpiv.render.plugins._endpoint import MitpivSensor

_VARIANT = mi.variant()


class Plenoptic(MitpivSensor):
    """Plenoptic 1.0 sensor; see the module docstring for parameters."""

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        rd, film, (w, h) = self._open(props, "plenoptic")
        if film.rfilter().class_name() != "BoxFilter":
            raise ConfigError(
                f"plenoptic: the film's reconstruction filter must be <rfilter type=\"box\"/> (a pixel integrates "
                f"its own area), got {film.rfilter().class_name()}."
            )
        name = rd.string("preset", None)
        base = {}
        if name is not None:
            if name not in PRESETS:
                raise ConfigError(f"plenoptic: unknown preset {name!r}; choose one of {sorted(PRESETS)}.")
            base = dict(PRESETS[name])
            if tuple(base["resolution"]) != (w, h):
                raise ConfigError(
                    f"plenoptic: preset {name!r} has a {base['resolution'][0]}x{base['resolution'][1]} sensor but the "
                    f"film is {w}x{h}; set the film's width/height to match."
                )
        base["resolution"] = (w, h)
        self._place(rd, props)
        to_world = self._to_world()
        rotation, _ = PinholeCamera.rotation_from_mitsuba(to_world)  # rigid check; float32 snapped to a rotation
        to_world[:3, :3] = rotation.T @ _CV_TO_MI

        kw = dict(base)
        for key in ("pixel_pitch_um", "focal_length_mm", "focus_distance_mm", "mla_pitch_um", "mla_focal_length_um",
                    "mla_rotation_deg", "mla_gap_um"):
            if rd.has(key):
                kw[key] = rd.float(key)
        if rd.has("f_number") or rd.has("aperture_diameter_mm"):
            kw.pop("f_number", None)
            kw.pop("aperture_diameter_mm", None)
            kw["f_number"] = rd.float("f_number", None)
            kw["aperture_diameter_mm"] = rd.float("aperture_diameter_mm", None)
            if kw["f_number"] is not None and kw["aperture_diameter_mm"] is not None:
                raise ConfigError("plenoptic: give 'f_number' or 'aperture_diameter_mm', not both.")
        if rd.has("mla_layout"):
            kw["mla_layout"] = rd.string("mla_layout")
        if rd.has("mla_count_x") or rd.has("mla_count_y"):
            if not (rd.has("mla_count_x") and rd.has("mla_count_y")):
                raise ConfigError("plenoptic: give both 'mla_count_x' and 'mla_count_y' (or neither, to fill the sensor).")
            kw["mla_count"] = (rd.int("mla_count_x"), rd.int("mla_count_y"))
        if rd.has("mla_offset_x_um") or rd.has("mla_offset_y_um"):
            kw["mla_offset_um"] = (rd.float("mla_offset_x_um", 0.0), rd.float("mla_offset_y_um", 0.0))
        missing = [k for k in ("pixel_pitch_um", "focal_length_mm", "focus_distance_mm", "mla_pitch_um") if k not in kw]
        if kw.get("f_number") is None and kw.get("aperture_diameter_mm") is None:
            missing.append("f_number (or aperture_diameter_mm)")
        if missing:
            raise ConfigError(f"plenoptic: missing parameter(s) {missing}; give them or a 'preset'.")
        if any(rd.has(k) for k in ("k1", "k2", "k3")):
            kw["distortion"] = Distortion(k1=rd.float("k1", 0.0), k2=rd.float("k2", 0.0), k3=rd.float("k3", 0.0))
        q_home = rd.float("crosstalk_sample_fraction", 0.8)
        if not 0.0 < q_home < 1.0:
            raise ConfigError(f"plenoptic: 'crosstalk_sample_fraction' must lie in (0, 1), got {q_home}.")
        self.far_clip = check_positive("far_clip", rd.float("far_clip", 1e7), owner="plenoptic", unit="mm")
        rd.finish()
        self.preset = name
        cam = PlenopticCamera(to_world_mitsuba=to_world, **kw)
        self.camera = cam
        self.m_needs_sample_3 = True

        # Constants baked into the traced kernels (Python floats).
        self._w, self._h = w, h
        self._pp = cam.pixel_pitch_um * 1e-3
        self._si = cam.image_distance_mm
        self._g = cam.gap_mm
        self._fm = cam.mla_focal_length_um * 1e-3
        self._f = cam.focal_length_mm
        self._ra = cam.aperture_radius_mm
        self._scale = cam.image_scale
        b = cam.basis_mm
        self._b = [[float(v) for v in row] for row in b]
        binv = np.linalg.inv(b.T)
        self._binv = [[float(v) for v in row] for row in binv]
        self._o = [float(v) for v in cam.origin_mm]
        self._hex = cam.mla_layout == "hex"
        self._dist = cam.distortion
        self._nx, self._ny = cam.mla_count
        self._area = cam.cell_area_mm2
        offs = cam.crosstalk_offsets()
        self._n_cand = len(offs)
        self._q_home = 1.0 if self._n_cand == 1 else q_home
        self._offsets = offs
        self._rho2 = cam.image_region_radius_mm ** 2
        self._set_pose(to_world)
        self.reset_ray_stats()

    # ------------------------------------------------------------------ lattice helpers
    def _centre(self, i, j):
        fi, fj = mi.Float(i), mi.Float(j)
        b = self._b
        return self._o[0] + fi * b[0][0] + fj * b[1][0], self._o[1] + fi * b[0][1] + fj * b[1][1]

    def _centre64(self, i, j):
        """Lenslet centre in float64."""
        fi, fj = mi.Float64(i), mi.Float64(j)
        b = self._b
        return self._o[0] + fi * b[0][0] + fj * b[1][0], self._o[1] + fi * b[0][1] + fj * b[1][1]

    def _nearest(self, x, y):
        """Axial lattice indices (i, j) of the lenslet whose cell contains (x, y) [mm]."""
        dx, dy = x - self._o[0], y - self._o[1]
        bi = self._binv
        fi = bi[0][0] * dx + bi[0][1] * dy
        fj = bi[1][0] * dx + bi[1][1] * dy
        if not self._hex:
            return mi.Int32(dr.floor(fi + 0.5)), mi.Int32(dr.floor(fj + 0.5))
        i0, j0 = mi.Int32(dr.floor(fi)), mi.Int32(dr.floor(fj))
        best_i, best_j, best_d = i0, j0, mi.Float(math.inf)
        for di, dj in ((0, 0), (1, 0), (0, 1), (1, 1)):
            ci, cj = self._centre(i0 + di, j0 + dj)
            d = (x - ci) ** 2 + (y - cj) ** 2
            better = d < best_d
            best_i = dr.select(better, i0 + di, best_i)
            best_j = dr.select(better, j0 + dj, best_j)
            best_d = dr.select(better, d, best_d)
        return best_i, best_j

    def _exists(self, i, j):
        col = i + (j >> 1) if self._hex else i
        return (col >= 0) & (col < self._nx) & (j >= 0) & (j < self._ny)

    # ------------------------------------------------------------------ camera tracing
    def _camera_path(self, u, v, s_sel, s_m):
        """Pixel (u, v) -> sensor point, lenslet, MLA point, lens point, object-side tangent, weight."""
        px = (u - 0.5 * self._w) * self._pp
        py = (v - 0.5 * self._h) * self._pp
        hi, hj = self._nearest(px * (1.0 / self._scale), py * (1.0 / self._scale))
        li, lj, q = hi, hj, mi.Float(1.0)
        if self._n_cand > 1:
            # Neighbours whose lenslet image can reach this pixel (disk of radius rho around
            # their image centre); the pixel's own lenslet gets the share q_home of samples.
            reach = []
            n_other = mi.UInt32(0)
            for di, dj in self._offsets[1:]:
                cx, cy = self._centre(hi + di, hj + dj)
                r = ((px - cx * self._scale) ** 2 + (py - cy * self._scale) ** 2) < self._rho2
                reach.append(r)
                n_other += dr.select(r, 1, 0)
            qh = self._q_home
            other = (s_sel >= qh) & (n_other > 0)
            pick = mi.UInt32(dr.floor((s_sel - qh) / (1.0 - qh) * mi.Float(n_other)))
            count = mi.UInt32(0)
            for (di, dj), r in zip(self._offsets[1:], reach, strict=True):
                chosen = other & r & (count == pick)
                li = dr.select(chosen, hi + di, li)
                lj = dr.select(chosen, hj + dj, lj)
                count += dr.select(r, 1, 0)
            q = dr.select(n_other > 0, dr.select(other, (1.0 - qh) / mi.Float(dr.maximum(n_other, 1)), qh), 1.0)
        valid = self._exists(li, lj)
        cx, cy = self._centre(li, lj)
        b = self._b
        a, c = s_m.x - 0.5, s_m.y - 0.5
        dx = a * b[0][0] + c * b[1][0]  # m - c: a point of the lenslet's cell
        dy = a * b[0][1] + c * b[1][1]
        if self._hex:  # fold the parallelogram onto the hexagonal cell (a fundamental domain)
            ni, nj = self._nearest(cx + dx, cy + dy)
            di, dj = mi.Float(ni - li), mi.Float(nj - lj)
            dx, dy = dx - di * b[0][0] - dj * b[1][0], dy - di * b[0][1] - dj * b[1][1]
        # c - P in float64: both are millimetres apart by a few micrometres, and the lens
        # plane magnifies their difference by s_i / g.
        c64x, c64y = self._centre64(li, lj)
        ex = mi.Float(c64x - (mi.Float64(u) - 0.5 * self._w) * self._pp)
        ey = mi.Float(c64y - (mi.Float64(v) - 0.5 * self._h) * self._pp)
        mx, my = cx + dx, cy + dy
        # t1 = (m - P)/g = (d + e)/g; t2 = t1 - d/f_m; lens point m + s_i t2, with the
        # coefficients combined in float64 (fewest float32 roundings where s_i/g magnifies)
        k2 = 1.0 / self._g - 1.0 / self._fm
        t2x, t2y = ex * (1.0 / self._g) + dx * k2, ey * (1.0 / self._g) + dy * k2
        a1, a2 = self._si / self._g, 1.0 + self._si * k2
        lx, ly = cx + (a1 * ex + a2 * dx), cy + (a1 * ey + a2 * dy)
        inside = (lx * lx + ly * ly) <= self._ra * self._ra
        t3x, t3y = t2x - lx * (1.0 / self._f), t2y - ly * (1.0 / self._f)
        cos2 = dr.rcp(1.0 + t3x * t3x + t3y * t3y)
        weight = dr.select(valid & inside, (self._area / (self._g * self._g)) * cos2 * cos2 / q, 0.0)
        if not self._dist.is_zero:  # the object-side tangent the distorting lens maps onto t3
            t3x, t3y = undistort(t3x, t3y, self._dist, iterations=12)
        return dict(px=px, py=py, i=li, j=lj, valid=valid, inside=inside, mx=mx, my=my, lx=lx, ly=ly,
                    t3x=t3x, t3y=t3y, weight=weight)

    def sample_ray(self, time, sample1, sample2, sample3, active=True):
        wavelengths, wav_weight = self.sample_wavelengths(dr.zeros(mi.SurfaceInteraction3f), sample1, active)
        u, v = sample2.x * self._w, sample2.y * self._h
        s_sel = self._hash(sample2, sample3)
        r = self._camera_path(u, v, s_sel, sample3)
        active = mi.Bool(active) & (u >= 0.0)  # full width
        dr.scatter_reduce(dr.ReduceOp.Add, self._stats, mi.UInt32(1), mi.UInt32(0), active)
        dr.scatter_reduce(dr.ReduceOp.Add, self._stats, mi.UInt32(1), mi.UInt32(1), active & r["valid"] & ~r["inside"])
        dr.scatter_reduce(dr.ReduceOp.Add, self._stats, mi.UInt32(1), mi.UInt32(2), active & ~r["valid"])
        d_local = dr.normalize(mi.Vector3f(r["t3x"], r["t3y"], 1.0))
        ray = mi.Ray3f()
        ray.time = time
        ray.wavelengths = wavelengths
        ray.o = self._pos + self._rot_to_world @ mi.Vector3f(r["lx"], r["ly"], 0.0)
        ray.d = self._rot_to_world @ d_local
        ray.maxt = self.far_clip
        return ray, wav_weight * r["weight"]

    @staticmethod
    def _hash(a, b):
        """A uniform decorrelated from the 2D samples a, b (TEA hash of their bits)."""
        ax = dr.reinterpret_array(mi.UInt32, a.x)
        by = dr.reinterpret_array(mi.UInt32, b.y)
        bx = dr.reinterpret_array(mi.UInt32, b.x)
        return mi.sample_tea_float32(ax ^ by, bx ^ dr.reinterpret_array(mi.UInt32, a.y))

    def reset_ray_stats(self) -> None:
        self._stats = dr.zeros(mi.UInt32, 3)

    def ray_stats(self) -> dict:
        """Camera rays traced since the last reset: total, vignetted by the main-lens aperture,
        and those through no lenslet (outside the array)."""
        s = np.array(self._stats, dtype=np.int64)
        return {"rays": int(s[0]), "vignetted": int(s[1]), "outside_mla": int(s[2]),
                "vignetted_fraction": float(s[1] / s[0]) if s[0] else 0.0}

    # ------------------------------------------------------------------ particle tracing
    def _particle_path(self, p, sample):
        """Local point p (z > 0) and an aperture sample -> lens point, MLA point, lenslet, sensor point."""
        a = mi.warp.square_to_uniform_disk_concentric(sample) * self._ra
        inv_z = dr.rcp(p.z)
        t3x, t3y = (p.x - a.x) * inv_z, (p.y - a.y) * inv_z
        if not self._dist.is_zero:  # the lens refracts the distorted object-side tangent
            t3x, t3y = distort(t3x, t3y, self._dist)
        t2x, t2y = t3x + a.x * (1.0 / self._f), t3y + a.y * (1.0 / self._f)
        mx, my = a.x - self._si * t2x, a.y - self._si * t2y
        li, lj = self._nearest(mx, my)
        valid = self._exists(li, lj) & (p.z > 0)
        cx, cy = self._centre(li, lj)
        t1x, t1y = t2x + (mx - cx) * (1.0 / self._fm), t2y + (my - cy) * (1.0 / self._fm)
        px, py = mx - self._g * t1x, my - self._g * t1y
        u = px * (1.0 / self._pp) + 0.5 * self._w
        v = py * (1.0 / self._pp) + 0.5 * self._h
        valid &= (u >= 0) & (u <= self._w) & (v >= 0) & (v <= self._h)
        return dict(ax=a.x, ay=a.y, mx=mx, my=my, i=li, j=lj, px=px, py=py, u=u, v=v, valid=valid)

    def sample_direction(self, it, sample, active=True):
        p = self._rot_to_local @ mi.Vector3f(it.p - self._pos)
        r = self._particle_path(p, sample)
        active = mi.Bool(active) & r["valid"]
        dvec = p - mi.Vector3f(r["ax"], r["ay"], 0.0)
        dist = dr.norm(dvec)
        cos_o = dvec.z / dist
        ds = dr.zeros(mi.DirectionSample3f)
        ds.uv = mi.Point2f(r["u"], r["v"])
        ds.p = self._pos + self._rot_to_world @ mi.Vector3f(r["ax"], r["ay"], 0.0)
        ds.d = (ds.p - it.p) / dist
        ds.dist = dist
        ds.n = self._rot_to_world @ mi.Vector3f(0.0, 0.0, 1.0)
        ds.time = it.time
        area = math.pi * self._ra * self._ra
        ds.pdf = dr.select(active, dist * dist / (cos_o * area), 0.0)
        n_pix = float(self._w * self._h)
        weight = area * cos_o / (dist * dist * self._pp * self._pp * n_pix)
        return ds, mi.Spectrum(dr.select(active, weight, 0.0))

    # ------------------------------------------------------------------ inspection (tests, tools)
    def trace_camera(self, uv_px, s_m, s_sel=None) -> dict:
        """Run the camera-tracing path for pixel positions (N, 2) and cell samples (N, 2);
        returns NumPy arrays (sensor, MLA and lens points [mm, sensor frame], lenslet axial
        indices, object-side tangents, weights, flags)."""
        uv = np.asarray(uv_px, dtype=np.float32)
        sm = np.asarray(s_m, dtype=np.float32)
        sel = np.zeros(len(uv), np.float32) if s_sel is None else np.asarray(s_sel, np.float32)
        r = self._camera_path(mi.Float(uv[:, 0]), mi.Float(uv[:, 1]), mi.Float(sel), mi.Point2f(sm[:, 0], sm[:, 1]))
        return {k: np.array(v) for k, v in r.items()}

    def trace_particles(self, points_world, s_ap) -> dict:
        """Run the particle-tracing path for world points (N, 3) and aperture samples (N, 2)."""
        pw = np.asarray(points_world, dtype=np.float64)
        loc = self.camera.world_to_local(pw).astype(np.float32)
        s = np.asarray(s_ap, dtype=np.float32)
        r = self._particle_path(mi.Vector3f(loc[:, 0], loc[:, 1], loc[:, 2]), mi.Point2f(s[:, 0], s[:, 1]))
        return {k: np.array(v) for k, v in r.items()}

    # ------------------------------------------------------------------ boilerplate
    def to_string(self):
        c = self.camera
        return (f"Plenoptic[resolution={c.resolution}, main lens {c.focal_length_mm} mm f/{c.f_number:.3g} focused at "
                f"{c.focus_distance_mm} mm, MLA {c.mla_layout} {c.mla_count[0]}x{c.mla_count[1]} pitch "
                f"{c.mla_pitch_um} um f/{c.mla_f_number:.3g}, PMR {c.pmr:.3g}]")

    def describe(self) -> dict:
        """JSON-ready camera model for image metadata (everything a decoder needs)."""
        return {"type": "plenoptic", "preset": self.preset, **self.camera.to_dict(),
                "pixel_value": "sensor irradiance [W/mm^2] averaged over the pixel",
                "crosstalk_sample_fraction": self._q_home}


mi.register_sensor("plenoptic", lambda props: Plenoptic(props))
