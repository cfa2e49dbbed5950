"""Backlit scenes: opaque spheres (droplets, pellets) in front of a diffuse backlight, rendered
by camera tracing through Mitsuba's ``direct`` integrator (any sensor: plenoptic, pinhole).

The dot-card dewarp calibration moved to :func:`mitpiv.calibrate.calibrate_dewarp`;
``stack_depth`` and ``stack_pixels`` to :mod:`mitpiv.lightfield.refocus` (still importable
from here).
"""

from __future__ import annotations

import logging

import mitsuba as mi
import numpy as np

from mitpiv.errors import ConfigError, check_positive
from mitpiv.render.render import render_sensor
from mitpiv.render.variant import ensure_variant

__all__ = ["backlit_scene", "render_backlit"]


def __getattr__(name):
    if name in ("stack_depth", "stack_pixels"):  # deprecated here: they belong to the light field
        from mitpiv.lightfield import refocus

        return getattr(refocus, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")

log = logging.getLogger(__name__)


def backlit_scene(sensor, positions_mm, diameters_mm, *, backlight_mm: float = 30.0, backlight_size_mm: float = 100.0,
                  radiance: float = 1.0):
    """Scene: ``sensor`` (dict or object), one black opaque sphere per particle, and a
    Lambertian backlight square of side ``backlight_size_mm`` a distance ``backlight_mm``
    behind the origin, facing the camera along the camera's optical axis."""
    ensure_variant()
    p = np.asarray(positions_mm, dtype=np.float64).reshape(-1, 3)
    d = np.broadcast_to(np.asarray(diameters_mm, dtype=np.float64), (p.shape[0],))
    if p.shape[0] and (not np.all(np.isfinite(p)) or not np.all(d > 0)):
        raise ConfigError("backlit_scene: positions must be finite and diameters_mm > 0.")
    check_positive("backlight_mm", backlight_mm, owner="backlit_scene", unit="mm")
    check_positive("backlight_size_mm", backlight_size_mm, owner="backlit_scene", unit="mm")
    m = sensor["to_world"].matrix if isinstance(sensor, dict) else sensor.world_transform().matrix
    fwd = np.array([float(m[i][2]) for i in range(3)])
    up = np.array([float(m[i][1]) for i in range(3)])
    centre = backlight_mm * fwd  # behind the origin as seen from the camera
    light = mi.ScalarTransform4f().look_at(origin=mi.ScalarPoint3f(*centre.tolist()),
                                           target=mi.ScalarPoint3f(*(centre - fwd).tolist()), up=mi.ScalarVector3f(*up.tolist()))
    black = {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}}
    scene = {"type": "scene", "integrator": {"type": "direct"}, "sensor": sensor,
             "light": {"type": "rectangle", "to_world": light @ mi.ScalarTransform4f().scale([backlight_size_mm / 2] * 2 + [1]),
                       "bsdf": black, "emitter": {"type": "area", "radiance": {"type": "rgb", "value": float(radiance)}}}}
    for i, (c, di) in enumerate(zip(p, d, strict=True)):
        scene[f"particle{i}"] = {"type": "sphere", "center": mi.ScalarPoint3f(*map(float, c)), "radius": float(di) / 2,
                                 "bsdf": black}
    return mi.load_dict(scene)


def render_backlit(sensor, positions_mm, diameters_mm, *, spp: int = 16, seed: int = 0, **kwargs) -> np.ndarray:
    """Render a backlit scene (see :func:`backlit_scene`); returns (H, W) float32 radiance."""
    sc = backlit_scene(sensor, positions_mm, diameters_mm, **kwargs)
    return render_sensor(sc, sc.sensors()[0], spp=int(spp), seed=seed)
