"""Exceptions raised by mitpiv.

Every error derives from :class:`MitpivError` and from the builtin exception that fits,
so ``except ValueError`` keeps working for callers that do not know mitpiv.
A message names the parameter, the value it got, the valid range and what to do.
"""

from __future__ import annotations


class MitpivError(Exception):
    """Base class of all mitpiv errors."""


class ConfigError(MitpivError, ValueError):
    """A parameter, plugin property or scene file is invalid."""


class BackendError(MitpivError, RuntimeError):
    """The rendering backend (Dr.Jit / Mitsuba variant) cannot be used."""


class FileFormatError(MitpivError, ValueError):
    """A file exists but does not have the expected content."""


class FolderLockedError(MitpivError, RuntimeError):
    """A run or sweep folder is being written by another process (its lock is held)."""


class DiskSpaceError(MitpivError, OSError):
    """Not enough free disk space for a write."""


class MitpivWarning(UserWarning):
    """Warning category for mitpiv."""


def check_positive(name: str, value, *, owner: str = "", unit: str = "") -> float:
    """Return ``float(value)`` or raise :class:`ConfigError` unless it is finite and > 0."""
    where = f"{owner}: " if owner else ""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ConfigError(
            f"{where}parameter '{name}' must be a positive number{_u(unit)}, got {value!r}."
        ) from None
    if not (v > 0.0) or v == float("inf"):
        raise ConfigError(
            f"{where}parameter '{name}' must be finite and > 0{_u(unit)}, got {value!r}. "
            f"Give a positive value."
        )
    return v


def _u(unit: str) -> str:
    return f" [{unit}]" if unit else ""


class CalibrationError(MitpivError, ValueError):
    """A calibration cannot be fitted reliably (too few or degenerate markers, bad residual)."""
