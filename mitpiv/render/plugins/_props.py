"""Typed, validated reading of Mitsuba plugin properties; unknown names are rejected."""

from __future__ import annotations

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
