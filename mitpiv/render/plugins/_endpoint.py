"""What mitpiv's Python sensors and emitters share.

- the methods of an endpoint that is not sampled by position and has no directional density
  of its own (importance and emission only through the plugin's own ``sample_direction`` /
  ``eval``);
- :class:`MitpivSensor`: the base of the sensors, which reads the film (crop windows
  rejected) and the pose (``to_world`` or a placement around a target) and holds the pose's
  kernel constants;
- :class:`MitpivEmitter`: the base of the emitters, which Mitsuba's light tracer
  (``ptracer``) cannot start rays from.

Built for the active variant; :func:`register_all` reloads this module before the plugins
when the variant changes."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from mitpiv.errors import ConfigError
from mitpiv.render.plugins._props import PropertyReader, read_placement


def film_resolution(sensor, owner: str) -> tuple[int, int]:
    """(width, height) of the sensor's film; crop windows are rejected."""
    film = sensor.film()
    w, h = (int(v) for v in film.size())
    if tuple(film.crop_size()) != (w, h):
        raise ConfigError(f"{owner}: film crop windows are not supported; remove crop_*.")
    return w, h


_VARIANT = mi.variant()


def _unsampled(base):
    """``base`` (``mi.Sensor`` or ``mi.Emitter``) as an endpoint with no position sampling and
    no directional density of its own: zero pdfs, zero emitted radiance, unit-weight
    wavelengths. (A class factory: Mitsuba's classes take no second base, so no mixin.)"""

    class Unsampled(base):
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

    Unsampled.__name__ = Unsampled.__qualname__ = f"Unsampled{base.__name__}"
    return Unsampled


class MitpivSensor(_unsampled(mi.Sensor)):
    """Base of mitpiv's sensors, positioned at ``self._pos``."""

    # ------------------------------------------------------------------ construction
    def _open(self, props: mi.Properties, owner: str):
        """(reader of the plugin ``owner``'s properties, the film, its (width, height))."""
        return PropertyReader(props, owner), self.film(), film_resolution(self, owner)

    def _place(self, rd: PropertyReader, props: mi.Properties) -> bool:
        """Apply a placement around a target (:func:`~mitpiv.render.plugins._props.read_placement`)
        to ``to_world``; True when the properties give one. :attr:`placement_distance_mm` is
        then the placement's ``distance_mm`` (the camera looks at the target, so it is the
        target's distance along the optical axis), else None (a bare ``to_world`` states none)."""
        placed = read_placement(rd, props)
        self.placement_distance_mm = None
        if placed is not None:
            self.m_to_world = mi.Transform4f(placed)
            self.placement_distance_mm = rd.float("distance_mm")
        return placed is not None

    def _to_world(self) -> np.ndarray:
        """The sensor's camera-to-world matrix (Mitsuba convention), 4x4 float64."""
        return np.array(self.world_transform().matrix, dtype=np.float64).reshape(4, 4)

    def _set_pose(self, to_world: np.ndarray) -> None:
        """Kernel constants of the pose ``to_world`` (4x4, rigid): the position ``_pos`` and the
        rotations ``_rot_to_world`` (local -> world) and ``_rot_to_local`` (its inverse)."""
        self._pos = mi.ScalarPoint3f(*to_world[:3, 3].tolist())
        lin = np.eye(4)
        lin[:3, :3] = to_world[:3, :3]
        self._rot_to_world = mi.Transform4f(lin)
        lin_inv = np.eye(4)
        lin_inv[:3, :3] = to_world[:3, :3].T
        self._rot_to_local = mi.Transform4f(lin_inv)

    # ------------------------------------------------------------------ Sensor interface
    def sample_ray_differential(self, time, sample1, sample2, sample3, active=True):
        ray, weight = self.sample_ray(time, sample1, sample2, sample3, active)
        return mi.RayDifferential3f(ray), weight

    def bbox(self):
        p = self._pos
        return mi.ScalarBoundingBox3f(p, p)


class MitpivEmitter(_unsampled(mi.Emitter)):
    """Base of mitpiv's emitters; light tracing from them is refused with :attr:`NO_LIGHT_TRACING`."""

    #: The error of :meth:`sample_ray` (Mitsuba's ``ptracer``): what to use instead.
    NO_LIGHT_TRACING = "mitpiv's emitters do not support Mitsuba's light tracer ('ptracer'); use 'particle_tracer'."

    def sample_ray(self, time, sample1, sample2, sample3, active=True):
        raise ConfigError(self.NO_LIGHT_TRACING)

    def bbox(self):
        return mi.ScalarBoundingBox3f()
