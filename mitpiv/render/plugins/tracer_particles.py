"""``tracer_particles``: light scattered by tracer particles, attached to an ``ellipsoidsmesh`` shape.

Parameters
----------
sheet : reference, default none
    The ``laser_sheet`` emitter that lights the particles (``<ref name="sheet" id="..."/>``).
irradiance : float [W/mm^2], default 1.0, range > 0
    Uniform irradiance when no ``sheet`` is given (incident along ``laser_direction``).
laser_direction : vector; default (1, 0, 0)
    Propagation direction when no ``sheet`` is given.
scattering_efficiency : float, default 2.0, range > 0
    Q_sca: C_sca = Q_sca pi d^2 / 4 (2 is the large-particle limit). Not with the
    ``mie`` phase, which computes C_sca.
diameter_um : float [um], default 1.0, range > 0
    Diameter used when the shape has no per-particle ``diameter`` attribute.
(nested phase) : phase, default isotropic
    Angular distribution of the scattered light (any Mitsuba phase function).
    With ``mie`` the particle radiates ``I = E dC/dOmega(d, theta)`` from Mie theory
    (per-particle diameters interpolated in a table, see ``mie``'s ``size_step``), and
    a polarised laser sheet gives ``E [dC_par cos^2(phi) + dC_per sin^2(phi)]``, phi
    the angle between the polarisation and the scattering plane.

Notes
-----
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
from mitpiv.render.plugins._endpoint import MitpivEmitter
from mitpiv.render.plugins._props import PropertyReader

_VARIANT = mi.variant()


class TracerParticles(MitpivEmitter):
    """Tracer-particle emitter; see the module docstring for parameters."""

    NO_LIGHT_TRACING = ("tracer_particles: Mitsuba's light tracer ('ptracer') is not supported; use "
                        "mitpiv's 'particle_tracer' integrator for light tracing from particles.")

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
        q_sca = rd.float("scattering_efficiency", None)
        self.q_sca = check_positive("scattering_efficiency", 2.0 if q_sca is None else q_sca, owner="tracer_particles")
        self.default_diameter_um = check_positive("diameter_um", rd.float("diameter_um", 1.0), owner="tracer_particles", unit="um")
        rd.finish()
        if self.phase is None:
            self.phase = mi.load_dict({"type": "isotropic"})
        self.is_mie = bool(getattr(self.phase, "is_mie", False))
        if self.is_mie:
            self.phase.nested_in_tracer = True
        if self.is_mie and q_sca is not None:
            raise ConfigError("tracer_particles: 'scattering_efficiency' cannot be combined with the mie phase, "
                              "which computes the scattering cross-section; remove it.")
        self.polarization = None if self.sheet is None else self.sheet.polarization
        if self.polarization is not None and not self.is_mie:
            raise ConfigError(
                "tracer_particles: the laser sheet is polarised ('polarization'), but only the mie phase "
                "function has a polarised form; nest <phase type=\"mie\"> or remove the sheet's 'polarization'."
            )
        self._xs = None
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

    def wavelength_nm(self):
        return self.sheet.wavelength_nm if self.sheet is not None else None

    def _bind_mie(self, diameters_um) -> None:
        """Upload the Mie differential cross-section table (rows: diameters, columns: angles)."""
        from mitpiv.render.plugins.mie_phase import AngleNodes

        t = self.phase.cross_section_table(diameters_um, wavelength_nm=self.wavelength_nm())
        rows, cols = t["par"].shape
        nodes = AngleNodes(t["theta"])  # float32 angles with the grid of the interval lookup
        self._xs = {
            "theta": nodes.nodes, "nodes": nodes, "n": cols, "rows": rows,
            "d0": t["d0_um"], "inv_dd": 0.0 if rows == 1 else 1.0 / t["dd_um"],
            "par": mi.Float(t["par"].astype(np.float32).ravel()), "per": mi.Float(t["per"].astype(np.float32).ravel()),
        }

    def _mie_intensity(self, e, diameter_um, w_out):
        from mitpiv.render.plugins.mie_phase import interval, scattering_angle

        xs = self._xs
        k = mi.Vector3f(self.laser_direction())
        i, t, _ = interval(xs["nodes"], scattering_angle(w_out, k))
        if xs["rows"] == 1:
            rows = [(mi.UInt32(0), mi.Float(1.0))]
        else:
            u = dr.clip((diameter_um - xs["d0"]) * xs["inv_dd"], 0.0, xs["rows"] - 1.0)
            j = mi.UInt32(dr.minimum(dr.floor(u), xs["rows"] - 2.0))  # rows j, j+1 stay in the table
            f = u - mi.Float(j)
            rows = [(j, 1.0 - f), (j + 1, f)]
        par, per = mi.Float(0.0), mi.Float(0.0)
        for j, wj in rows:  # bilinear: two rows x two angles
            base = j * xs["n"] + i
            par += wj * dr.lerp(dr.gather(mi.Float, xs["par"], base), dr.gather(mi.Float, xs["par"], base + 1), t)
            per += wj * dr.lerp(dr.gather(mi.Float, xs["per"], base), dr.gather(mi.Float, xs["per"], base + 1), t)
        if self.polarization is None:
            return e * 0.5 * (par + per)
        # phi: angle between the polarisation and the scattering plane (k, w_out)
        pol = mi.Vector3f(*self.polarization.tolist())
        wk = dr.dot(w_out, k)
        s2 = dr.maximum(1.0 - wk * wk, 0.0)
        cos2 = dr.select(s2 > 1e-12, dr.square(dr.dot(w_out, pol)) / dr.maximum(s2, 1e-30), 0.5)
        return e * (par * cos2 + per * (1.0 - cos2))

    def intensity(self, center, diameter_um, w_out, wavelengths, active=True):
        """Radiant intensity [W/sr] of particles at ``center`` toward unit directions ``w_out``."""
        e = self.irradiance_at(center)
        if self.is_mie:
            return self._mie_intensity(e, diameter_um, w_out)
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
        if self.is_mie:
            self._bind_mie(np.array(mi.traverse(shape)["diameter"], dtype=np.float64) if self._has_diameter else None)

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

    def ready(self) -> bool:
        """Bound to its shape (and, with the mie phase, its cross-section table uploaded)."""
        return getattr(self, "_shape", None) is not None and (not self.is_mie or self._xs is not None)

    def eval(self, si, active=True):
        if not self.ready():
            # Dr.Jit traces a virtual call for every live emitter instance, including one left
            # over from a scene whose loading failed: such an instance must trace, and radiates
            # nothing. Scenes loaded through load_scene / load_dict are always bound.
            return mi.Spectrum(0.0)
        shape = self._shape
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

    def bbox(self):
        shape = getattr(self, "_shape", None)
        return shape.bbox() if shape is not None else mi.ScalarBoundingBox3f()

    def to_string(self):
        return f"TracerParticles[q_sca={self.q_sca}, phase={self.phase}, sheet={self.sheet is not None}]"

    def describe(self) -> dict:
        return {
            "type": "tracer_particles",
            "scattering_efficiency": "mie" if self.is_mie else self.q_sca,
            "phase": self.phase.describe() if hasattr(self.phase, "describe") else self.phase.class_name(),
            "mie_table_rows": None if self._xs is None else self._xs["rows"],
            "sheet": None if self.sheet is None else self.sheet.describe(),
            "uniform_irradiance_w_mm2": self.uniform_irradiance if self.sheet is None else None,
            "radiance_normalisation": "L = I / A_proj(w), exact projected area of the proxy shell",
        }


mi.register_emitter("tracer_particles", lambda props: TracerParticles(props))
