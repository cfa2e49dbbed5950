"""Typed, validated reading of Mitsuba plugin properties; unknown names are rejected."""

from __future__ import annotations

import math

import mitsuba as mi

from mitpiv.errors import ConfigError


class PropertyReader:
    """Read properties of plugin ``owner``; :meth:`finish` rejects any property not read."""

    def __init__(self, props: mi.Properties, owner: str):
        self.props = props
        self.owner = owner

    def has(self, name: str) -> bool:
        return name in self.props

    def _get(self, name, default, kinds, what):
        if name not in self.props:
            return default
        value = self.props.get(name)
        if not isinstance(value, kinds) or isinstance(value, bool) and bool not in kinds:
            raise ConfigError(f"{self.owner}: parameter '{name}' must be {what}, got {value!r}.")
        return value

    def float(self, name: str, default=None):
        v = self._get(name, default, (int, float), "a number")
        if v is not None and not math.isfinite(v):
            raise ConfigError(f"{self.owner}: parameter '{name}' must be a finite number, got {v!r}. Give a real value "
                              f"(or leave the parameter out for its default).")
        return None if v is None else float(v)

    def int(self, name: str, default=None):
        v = self._get(name, default, (int, float), "an integer")
        if v is None:
            return None
        if float(v) != int(v):
            raise ConfigError(f"{self.owner}: parameter '{name}' must be an integer, got {v!r}.")
        return int(v)

    def bool(self, name: str, default=None):
        return self._get(name, default, (bool,), "a boolean")

    def string(self, name: str, default=None):
        return self._get(name, default, (str,), "a string")

    def vector(self, name: str, default=None):
        if name not in self.props:
            return default
        v = self.props.get(name)
        try:
            out = [float(v[i]) for i in range(3)]
        except Exception:
            raise ConfigError(f"{self.owner}: parameter '{name}' must be a 3-vector, got {v!r}.") from None
        if not all(math.isfinite(x) for x in out):
            raise ConfigError(f"{self.owner}: parameter '{name}' must be three finite numbers, got {out}.")
        return out

    def object(self, name: str, default=None):
        return self.props.get(name) if name in self.props else default

    def finish(self) -> None:
        """Raise :class:`ConfigError` for properties nobody read (typos, unsupported names)."""
        left = [k for k in self.props.unqueried() if not k.startswith("_")]
        if left:
            raise ConfigError(
                f"{self.owner}: unknown parameter(s) {', '.join(repr(k) for k in sorted(left))}. "
                f"See the plugin's parameter table (help(mitpiv.render.plugins.{self.owner}))."
            )


def read_placement(rd: PropertyReader, props: mi.Properties):
    """Camera pose from ``target``/``azimuth_deg``/``elevation_deg``/``distance_mm`` (see
    :func:`mitpiv.physics.camera.place_camera`) as a 4x4 Mitsuba to_world matrix, or None
    when the placement properties are absent (the sensor uses ``to_world``)."""
    import numpy as np

    from mitpiv.physics.camera import CV_TO_MITSUBA as _CV_TO_MI
    from mitpiv.physics.camera import place_camera

    placement = [rd.has(k) for k in ("azimuth_deg", "elevation_deg", "distance_mm")]
    if not any(placement):
        return None
    if not all(placement):
        raise ConfigError(f"{rd.owner}: placement needs all of 'azimuth_deg', 'elevation_deg', 'distance_mm'.")
    if "to_world" in props:
        raise ConfigError(f"{rd.owner}: give 'to_world' or azimuth/elevation placement, not both.")
    rot, pos = place_camera(
        target_mm=rd.vector("target", (0.0, 0.0, 0.0)),
        azimuth_deg=rd.float("azimuth_deg"),
        elevation_deg=rd.float("elevation_deg"),
        distance_mm=rd.float("distance_mm"),
        laser_direction=rd.vector("laser_direction", (1.0, 0.0, 0.0)),
        sheet_normal=rd.vector("sheet_normal", (0.0, 0.0, 1.0)),
    )
    m = np.eye(4)
    m[:3, :3] = rot.T @ _CV_TO_MI
    m[:3, 3] = pos
    return m
