"""``laser_sheet``: a collimated laser light sheet (delta-direction emitter masked in space).

Parameters
----------
origin : point [mm]; default (0, 0, 0)
    A point on the sheet's mid-plane (the centre of the measurement region).
direction : vector; default (1, 0, 0)
    Propagation direction of the laser light.
normal : vector; default (0, 0, 1)
    Sheet normal (thickness direction); made orthogonal to ``direction``.
thickness : float [mm], default 1.0, range > 0
    Sheet thickness: FWHM of the profile across the sheet.
profile : string, default ``gaussian``, one of ``gaussian``, ``tophat``, ``supergaussian``
    ``gaussian`` | ``tophat`` | ``supergaussian``.
order : float, default 2.0, range > 0
    Super-Gaussian order: E = E0 2^(-(2|s|/t)^order).
irradiance : float [W/mm^2], default 1.0, range > 0
    Peak irradiance on the mid-plane.
wavelength_nm : float [nm], default 532, range > 0
    Vacuum wavelength (used by wavelength-dependent scattering such as Mie).
width : float [mm], default unbounded, range > 0
    Optional full width of the sheet in the plane (top-hat edges, centred on
    ``origin``, measured along ``normal x direction``).
polarization : vector, default unpolarised
    Optional direction of the electric field of a linearly polarised laser; must be
    perpendicular to ``direction`` (usually in the sheet plane, ``normal x direction``).
    Only the ``mie`` phase function of ``tracer_particles`` uses it.

Notes
-----
Ordinary surfaces are lit through Mitsuba's ``direct`` / ``path`` integrators:
``sample_direction`` returns the delta direction ``-direction`` weighted by the local
irradiance ``E(p)``. Particles query :meth:`LaserSheet.irradiance` directly. The sheet
extends without attenuation along its propagation direction. Light tracing from the sheet
(``sample_ray``, used by Mitsuba's ``ptracer``) is not supported: mitpiv's
``particle_tracer`` starts at the particles instead.

.. code-block:: xml

    <emitter type="laser_sheet" id="laser">
        <point name="origin" value="0, 0, 0"/>
        <vector name="direction" value="1, 0, 0"/>
        <vector name="normal" value="0, 0, 1"/>
        <float name="thickness" value="2"/>
        <string name="profile" value="gaussian"/>
        <float name="irradiance" value="1"/>
    </emitter>
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from mitpiv.errors import ConfigError, check_positive
from mitpiv.physics.sheet import check_profile, drjit_ops, sheet_profile
from mitpiv.render.plugins._endpoint import MitpivEmitter
from mitpiv.render.plugins._props import PropertyReader

_VARIANT = mi.variant()


class LaserSheet(MitpivEmitter):
    """Laser light sheet; see the module docstring for parameters."""

    NO_LIGHT_TRACING = ("laser_sheet: light tracing from the sheet (Mitsuba's 'ptracer') is not supported; "
                        "use mitpiv's 'particle_tracer' or a camera-tracing integrator ('direct', 'path').")

    def __init__(self, props: mi.Properties):
        super().__init__(props)
        rd = PropertyReader(props, "laser_sheet")
        self.origin = np.asarray(rd.vector("origin", (0.0, 0.0, 0.0)), float)
        direction = np.asarray(rd.vector("direction", (1.0, 0.0, 0.0)), float)
        normal = np.asarray(rd.vector("normal", (0.0, 0.0, 1.0)), float)
        self.thickness_mm = check_positive("thickness", rd.float("thickness", 1.0), owner="laser_sheet", unit="mm")
        self.profile = rd.string("profile", "gaussian")
        self.order = rd.float("order", 2.0)
        check_profile(self.profile, self.order)
        self.irradiance_peak = check_positive("irradiance", rd.float("irradiance", 1.0), owner="laser_sheet", unit="W/mm^2")
        self.wavelength_nm = check_positive("wavelength_nm", rd.float("wavelength_nm", 532.0), owner="laser_sheet", unit="nm")
        width = rd.float("width", None)
        self.width_mm = None if width is None else check_positive("width", width, owner="laser_sheet", unit="mm")
        pol = rd.vector("polarization", None)
        rd.finish()
        if np.linalg.norm(direction) == 0:
            raise ConfigError("laser_sheet: parameter 'direction' must be a non-zero vector.")
        self.direction = direction / np.linalg.norm(direction)
        normal = normal - self.direction * (normal @ self.direction)
        if np.linalg.norm(normal) < 1e-9:
            raise ConfigError("laser_sheet: parameter 'normal' must not be parallel to 'direction'.")
        self.normal = normal / np.linalg.norm(normal)
        self.width_axis = np.cross(self.normal, self.direction)
        self.polarization = None
        if pol is not None:
            pol = np.asarray(pol, float)
            if not np.linalg.norm(pol) > 0:
                raise ConfigError("laser_sheet: parameter 'polarization' must be a non-zero vector (or left out: unpolarised).")
            pol = pol / np.linalg.norm(pol)
            if abs(pol @ self.direction) > 1e-6:
                raise ConfigError(
                    f"laser_sheet: 'polarization' {pol.tolist()} is not perpendicular to 'direction' "
                    f"{self.direction.tolist()} (light is transverse); e.g. use {self.width_axis.round(12).tolist()} "
                    f"(in the sheet plane) or {self.normal.round(12).tolist()} (across it)."
                )
            self.polarization = pol
        self.m_flags = mi.EmitterFlags.DeltaDirection

    # ------------------------------------------------------------------ physics
    def irradiance(self, p):
        """Irradiance [W/mm^2] at points ``p`` (mi.Point3f), normal to the propagation."""
        rel = p - mi.ScalarPoint3f(*self.origin.tolist())
        s = dr.dot(rel, mi.ScalarVector3f(*self.normal.tolist()))
        e = self.irradiance_peak * sheet_profile(s, self.thickness_mm, self.profile, self.order, xp=drjit_ops())
        if self.width_mm is not None:
            w = dr.dot(rel, mi.ScalarVector3f(*self.width_axis.tolist()))
            e = dr.select(dr.abs(w) <= 0.5 * self.width_mm, e, 0.0)
        return e

    def irradiance_numpy(self, p_world_mm) -> np.ndarray:
        """Float64 NumPy twin of :meth:`irradiance` for points of shape (N, 3)."""
        rel = np.asarray(p_world_mm, float) - self.origin
        e = self.irradiance_peak * sheet_profile(rel @ self.normal, self.thickness_mm, self.profile, self.order)
        if self.width_mm is not None:
            e = np.where(np.abs(rel @ self.width_axis) <= 0.5 * self.width_mm, e, 0.0)
        return e

    def laser_direction(self):
        return mi.ScalarVector3f(*self.direction.tolist())

    # ------------------------------------------------------------------ Emitter interface
    def sample_direction(self, it, sample, active=True):
        e = self.irradiance(it.p)
        ds = dr.zeros(mi.DirectionSample3f)
        ds.d = mi.Vector3f(*(-self.direction).tolist())
        # A distance beyond the scene; the light is collimated so it only sets the shadow ray.
        ds.dist = mi.Float(1e7)
        ds.p = it.p + ds.d * ds.dist
        ds.n = mi.Vector3f(*self.direction.tolist())
        ds.pdf = mi.Float(1.0)
        ds.delta = mi.Bool(True)
        ds.time = it.time
        active = mi.Bool(active) & (e > 0)
        return ds, dr.select(active, mi.Spectrum(e), mi.Spectrum(0.0))

    def to_string(self):
        return (
            f"LaserSheet[origin={self.origin.tolist()}, direction={self.direction.tolist()}, "
            f"normal={self.normal.tolist()}, thickness={self.thickness_mm} mm, "
            f"profile={self.profile}, irradiance={self.irradiance_peak} W/mm^2, "
            f"wavelength={self.wavelength_nm} nm, width={self.width_mm}, "
            f"polarization={None if self.polarization is None else self.polarization.tolist()}]"
        )

    def describe(self) -> dict:
        """JSON-ready description for image metadata."""
        return {
            "type": "laser_sheet",
            "origin_mm": self.origin.tolist(),
            "direction": self.direction.tolist(),
            "normal": self.normal.tolist(),
            "thickness_mm": self.thickness_mm,
            "profile": self.profile,
            "order": self.order,
            "irradiance_w_mm2": self.irradiance_peak,
            "wavelength_nm": self.wavelength_nm,
            "width_mm": self.width_mm,
            "polarization": None if self.polarization is None else self.polarization.tolist(),
        }


mi.register_emitter("laser_sheet", lambda props: LaserSheet(props))
