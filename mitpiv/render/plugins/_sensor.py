"""What mitpiv's Python sensors share: the film checks and a ``mi.Sensor`` base with the
methods of a sensor that neither emits nor is sampled by position (importance only through
``sample_direction``). Built for the active variant; :func:`register_all` reloads this
module before the sensor plugins when the variant changes."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi

from mitpiv.errors import ConfigError


def film_resolution(sensor, owner: str) -> tuple[int, int]:
    """(width, height) of the sensor's film; crop windows are rejected."""
    film = sensor.film()
    w, h = (int(v) for v in film.size())
    if tuple(film.crop_size()) != (w, h):
        raise ConfigError(f"{owner}: film crop windows are not supported; remove crop_*.")
    return w, h


_VARIANT = mi.variant()


class MitpivSensor(mi.Sensor):
    """Base of mitpiv's sensors, positioned at ``self._pos``."""

    def sample_ray_differential(self, time, sample1, sample2, sample3, active=True):
        ray, weight = self.sample_ray(time, sample1, sample2, sample3, active)
        return mi.RayDifferential3f(ray), weight

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
