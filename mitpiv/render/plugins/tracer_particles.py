"""``tracer_particles``: light scattered by tracer particles, attached to an ``ellipsoidsmesh`` shape.

.. list-table::
   :header-rows: 1

   * - Parameter
     - Type
     - Unit
     - Default
     - Meaning
   * - sheet
     - reference
     - --
     - none
     - The ``laser_sheet`` emitter that lights the particles (``<ref name="sheet" id="..."/>``).
   * - irradiance
     - float
     - W/mm^2
     - 1.0
     - Uniform irradiance when no ``sheet`` is given (incident along ``laser_direction``).
   * - laser_direction
     - vector
     - --
     - (1, 0, 0)
     - Propagation direction when no ``sheet`` is given.
   * - scattering_efficiency
     - float
     - --
     - 2.0
     - Q_sca: C_sca = Q_sca pi d^2 / 4 (2 is the large-particle limit).
   * - diameter_um
     - float
     - um
     - 1.0
     - Diameter used when the shape has no per-particle ``diameter`` attribute.
   * - (nested phase)
     - phase
     - --
     - isotropic
     - Angular distribution of the scattered light (any Mitsuba phase function).

Each particle radiates the intensity ``I(w) = E_sheet(c) C_sca phase(theta)`` [W/sr], with
``c`` its centre, ``theta`` the angle between the laser direction and ``w``. The proxy
shell of radius ``R`` (the ellipsoid's scale times its extent; a convex polyhedron, by
default Mitsuba's 20-face icosahedron) carries the radiance ``L = I / A(w)``, with
``A(w) = R^2 sum_f |n_f . w| a_f / 2`` its exact projected area seen from ``w``, so that the
power a camera receives, and hence the image, does not depend on ``R`` or on the shell. Per-particle centres, proxy radii and diameters are read from the shape
(attributes ``center``, ``scale``, ``extent``, ``diameter``).

The shape's BSDF must be black (reflectance 0), otherwise the laser light would be counted
twice; :func:`mitpiv.render.scene.load_scene` checks this. For direct illumination of other
surfaces by particles, ``sample_direction`` returns a zero-pdf sample: that light is then
estimated by BSDF sampling alone, which stays unbiased (and is negligible in PIV scenes).

.. code-block:: xml

    <shape type="ellipsoidsmesh">
        <string name="filename" value="particles_$frame.ply"/>
        <float name="extent" value="1"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf>
        <emitter type="tracer_particles">
            <ref name="sheet" id="laser"/>
            <phase type="isotropic"/>
        </emitter>
    </shape>
"""

from __future__ import annotations

import math

import drjit as dr
import mitsuba as mi
import numpy as np

from mitpiv.errors import ConfigError, check_positive
from mitpiv.render.plugins._props import PropertyReader

_VARIANT = mi.variant()


class TracerParticles(mi.Emitter):
    """Tracer-particle emitter; see the module docstring for parameters."""

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        rd = PropertyReader(props, "tracer_particles")
        self.sheet = None
        self.phase = None
        for name in props.keys():
            obj = props.get(name)
            if isinstance(obj, mi.PhaseFunction):
                if self.phase is not None:
                    raise ConfigError("tracer_particles: give at most one nested phase function.")
                self.phase = obj
            elif name == "sheet":
                if not hasattr(obj, "irradiance") or not hasattr(obj, "laser_direction"):
                    raise ConfigError(
                        f"tracer_particles: 'sheet' must reference a laser_sheet emitter, got {type(obj).__name__}."
                    )
                self.sheet = obj
        self.uniform_irradiance = rd.float("irradiance", None)
        direction = rd.vector("laser_direction", None)
        if self.sheet is not None and (self.uniform_irradiance is not None or direction is not None):
            raise ConfigError("tracer_particles: 'irradiance'/'laser_direction' are for scenes without a 'sheet'; give one or the other.")
        if self.sheet is None:
            self.uniform_irradiance = check_positive(
                "irradiance", 1.0 if self.uniform_irradiance is None else self.uniform_irradiance,
                owner="tracer_particles", unit="W/mm^2")
            d = np.asarray(direction or (1.0, 0.0, 0.0), float)
            if np.linalg.norm(d) == 0:
                raise ConfigError("tracer_particles: 'laser_direction' must be non-zero.")
            self._direction = d / np.linalg.norm(d)
        self.q_sca = check_positive("scattering_efficiency", rd.float("scattering_efficiency", 2.0), owner="tracer_particles")
        self.default_diameter_um = check_positive("diameter_um", rd.float("diameter_um", 1.0), owner="tracer_particles", unit="um")
        rd.finish()
        if self.phase is None:
            self.phase = mi.load_dict({"type": "isotropic"})
        self.m_flags = mi.EmitterFlags.Surface

    # ------------------------------------------------------------------ physics
    def laser_direction(self):
        if self.sheet is not None:
            return self.sheet.laser_direction()
        return mi.ScalarVector3f(*self._direction.tolist())

    def irradiance_at(self, p):
        if self.sheet is not None:
            return self.sheet.irradiance(p)
        return mi.Float(self.uniform_irradiance)

    def intensity(self, center, diameter_um, w_out, wavelengths, active=True):
        """Radiant intensity [W/sr] of particles at ``center`` toward unit directions ``w_out``."""
        e = self.irradiance_at(center)
        c_sca = self.q_sca * (math.pi / 4.0) * dr.square(diameter_um * 1e-3)  # mm^2
        mei = dr.zeros(mi.MediumInteraction3f)
        mei.p = center
        mei.wi = -mi.Vector3f(self.laser_direction())
        mei.sh_frame = mi.Frame3f(mei.wi)
        mei.wavelengths = wavelengths
        ctx = mi.PhaseFunctionContext(None)
        phase_val, _ = self.phase.eval_pdf(ctx, mei, w_out, active)
        return e * c_sca * phase_val[0]

    def bind_shape(self, shape) -> None:
        """Attach the particle shape (Mitsuba does not expose a mesh emitter's shape to Python).

        :func:`mitpiv.render.scene.load_scene` calls this for every particle shape.
        """
        if shape.class_name() != "EllipsoidsMesh":
            raise ConfigError(
                f"tracer_particles must be nested in an 'ellipsoidsmesh' shape, got "
                f"{shape.class_name()!r}. (Mitsuba's analytic 'ellipsoids' loses float32 "
                f"precision for proxies much smaller than one scene unit: its ray-plane step "
                f"divides by |d| instead of |d|^2 in scaled space.)"
            )
        self._shape = shape
        self._has_diameter = "diameter" in mi.traverse(shape).keys()  # per-particle PLY column
        self._shell_cache = None
        self._shell()  # computed now: it reads arrays, which must not happen while tracing

    def get_particle_shape(self):
        shape = getattr(self, "_shape", None)
        if shape is None:
            raise ConfigError(
                "tracer_particles: its shape is not bound; load scenes with "
                "mitpiv.render.scene.load_scene (or call bind_particle_shapes(scene))."
            )
        return shape

    def particle_arrays(self):
        """(centres (N, 3) float32 world mm, proxy radii [mm], diameters [um]) as Dr.Jit arrays."""
        shape = self.get_particle_shape()
        params = mi.traverse(shape)
        data = params["data"]
        n = dr.width(data) // 10
        idx = dr.arange(mi.UInt32, n) * 10
        center = mi.Point3f(dr.gather(mi.Float, data, idx), dr.gather(mi.Float, data, idx + 1), dr.gather(mi.Float, data, idx + 2))
        radius = dr.gather(mi.Float, data, idx + 3) * params["extent"]
        if self._has_diameter:
            diameter = mi.Float(params["diameter"])
        else:
            diameter = dr.full(mi.Float, self.default_diameter_um, n)
        return center, radius, diameter

    # ------------------------------------------------------------------ Emitter interface
    def _shell(self):
        """Unit shell template of the particle mesh: face normals (F, 3) and areas / R^2 (F,)."""
        if getattr(self, "_shell_cache", None) is None:
            shape = self.get_particle_shape()
            center, radius, _ = self.particle_arrays()
            n = dr.width(radius)
            if n == 0:
                self._shell_cache = ([], [], 0.0)
                return self._shell_cache
            faces = np.array(shape.faces_buffer()).reshape(-1, 3)
            per = faces.shape[0] // max(n, 1)
            verts = np.array(shape.vertex_positions_buffer(), dtype=np.float64).reshape(-1, 3)
            c0 = np.array([center.x[0], center.y[0], center.z[0]], dtype=np.float64)
            v = (verts - c0) / float(radius[0])
            f = faces[:per]
            cr = np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
            area = 0.5 * np.linalg.norm(cr, axis=1)
            normal = cr / (2.0 * area[:, None])
            # The shell is centrally symmetric: keep one face of each opposite pair.
            keep, used = [], np.zeros(per, bool)
            for i in range(per):  # template faces only (tens), not particles
                if used[i]:
                    continue
                j = np.argmin(np.linalg.norm(normal + normal[i], axis=1))
                symmetric = np.allclose(normal[j], -normal[i], atol=1e-5) and np.isclose(area[j], area[i], rtol=1e-5)
                used[i] = True
                if symmetric and j != i:
                    used[j] = True
                    keep.append((normal[i], area[i]))  # counts twice: 1/2 |n.w| (a_i + a_j) = |n.w| a_i
                else:
                    keep.append((normal[i], 0.5 * area[i]))
            self._shell_cache = ([k[0].tolist() for k in keep], [float(k[1]) for k in keep], float(area.sum()))
        return self._shell_cache

    def projected_area_unit(self, w):
        """Projected area of the unit proxy shell seen from direction ``w`` (exact, convex shell)."""
        normals, weights, _ = self._shell()
        acc = mi.Float(0.0)
        for nrm, wt in zip(normals, weights, strict=True):
            acc += wt * dr.abs(w.x * nrm[0] + w.y * nrm[1] + w.z * nrm[2])
        return acc

    def eval(self, si, active=True):
        shape = self.get_particle_shape()
        active = mi.Bool(active) & (mi.Frame3f.cos_theta(si.wi) > 0)
        c = shape.eval_attribute_3("center", si, active)
        center = mi.Point3f(c[0], c[1], c[2])
        radius = shape.eval_attribute_3("scale", si, active)[0] * shape.eval_attribute_1("extent", si, active)
        if self._has_diameter:
            diameter = shape.eval_attribute_1("diameter", si, active)
        else:
            diameter = mi.Float(self.default_diameter_um)
        w_out = si.to_world(si.wi)
        intensity = self.intensity(center, diameter, w_out, si.wavelengths, active)
        radiance = intensity / (dr.square(radius) * self.projected_area_unit(w_out))
        return dr.select(active, mi.Spectrum(radiance), mi.Spectrum(0.0))

    def sample_direction(self, it, sample, active=True):
        ds = dr.zeros(mi.DirectionSample3f)
        return ds, mi.Spectrum(0.0)

    def pdf_direction(self, it, ds, active=True):
        return mi.Float(0.0)

    def eval_direction(self, it, ds, active=True):
        return mi.Spectrum(0.0)

    def sample_ray(self, time, sample1, sample2, sample3, active=True):
        raise ConfigError(
            "tracer_particles: Mitsuba's light tracer ('ptracer') is not supported; use "
            "mitpiv's 'particle_tracer' integrator for light tracing from particles."
        )

    def sample_position(self, time, sample, active=True):
        return dr.zeros(mi.PositionSample3f), mi.Float(0.0)

    def pdf_position(self, ps, active=True):
        return mi.Float(0.0)

    def sample_wavelengths(self, si, sample, active=True):
        return dr.zeros(mi.Color0f), mi.Spectrum(1.0)

    def bbox(self):
        shape = getattr(self, "_shape", None)
        return shape.bbox() if shape is not None else mi.ScalarBoundingBox3f()

    def to_string(self):
        return f"TracerParticles[q_sca={self.q_sca}, phase={self.phase}, sheet={self.sheet is not None}]"

    def describe(self) -> dict:
        return {
            "type": "tracer_particles",
            "scattering_efficiency": self.q_sca,
            "phase": self.phase.class_name() if hasattr(self.phase, "class_name") else str(self.phase),
            "sheet": None if self.sheet is None else self.sheet.describe(),
            "uniform_irradiance_w_mm2": self.uniform_irradiance if self.sheet is None else None,
            "radiance_normalisation": "L = I / A_proj(w), exact projected area of the proxy shell",
        }


mi.register_emitter("tracer_particles", lambda props: TracerParticles(props))
