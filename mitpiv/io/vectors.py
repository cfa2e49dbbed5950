"""3D vector fields on disk: ``.npz`` with the window-centre axes, the components and the
per-vector flags, and JSON ``meta`` (voxel size, window, dt, info); atomic writes.

Entries: ``x_mm`` (n_x,), ``y_mm`` (n_y,), ``z_mm`` (n_z,); ``u, v, w, snr, peak`` and the
bool ``valid, outlier, replaced``, each (n_z, n_y, n_x); ``meta`` = JSON ``{"voxel_mm":
[3], "window_vox": [3], "dt_s": float or null, "info": {...}}``. Components are in mm
(``dt_s`` null: displacements) or mm/s.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

from mitpiv.io.arrays import json_entry, read_npz, write_npz
from mitpiv.io.records import to_jsonable

if TYPE_CHECKING:  # io imports no analysis module at run time: readers return records
    from mitpiv.analysis.piv3d import VectorField

__all__ = ["write_vector_field", "read_vector_field", "write_velocity_error", "read_velocity_error"]

_ARRAYS = ("x_mm", "y_mm", "z_mm", "u", "v", "w", "snr", "peak", "valid", "outlier", "replaced")


def write_vector_field(path, field: VectorField) -> Path:
    """Write ``field`` to ``path`` (``.npz``, compressed, atomic).

    Raises :class:`~mitpiv.errors.ConfigError` for another suffix (nothing is written).
    """
    meta = {"voxel_mm": list(field.voxel_mm), "window_vox": list(field.window_vox), "dt_s": field.dt_s,
            "info": field.info}
    return write_npz(path, {**{k: getattr(field, k) for k in _ARRAYS}, "meta": json.dumps(to_jsonable(meta))},
                     owner="write_vector_field")


def read_vector_field(path) -> dict:
    """Read a vector field written by :func:`write_vector_field` (or ``VectorField.save``) as
    the record ``VectorField(**record)`` takes (``VectorField.load(path)`` does that).

    Raises :class:`~mitpiv.errors.FileFormatError` naming the file when it is missing or
    not a mitpiv vector field.
    """
    from mitpiv.errors import FileFormatError

    z = read_npz(path, what="mitpiv vector field", required=(*_ARRAYS, "meta"))
    meta = json_entry(z, "meta", path)
    try:
        return {**{k: z[k] for k in _ARRAYS}, "voxel_mm": tuple(meta["voxel_mm"]),
                "window_vox": tuple(meta["window_vox"]), "dt_s": meta["dt_s"], "info": meta.get("info", {})}
    except (KeyError, TypeError) as e:
        raise FileFormatError(f"{str(path)!r}: the vector field's meta lacks {e}.") from None


def write_velocity_error(path, result: dict) -> Path:
    """Write the result of :func:`mitpiv.analysis.velocity_error` (its scalars as JSON, its
    ``reference`` and ``error`` arrays) to ``path`` (``.npz``, atomic)."""
    import numpy as np

    arrays = {k: np.asarray(result[k]) for k in ("reference", "error") if result.get(k) is not None}
    scalars = {k: v for k, v in result.items() if k not in arrays}
    return write_npz(path, {**arrays, "summary": json.dumps(to_jsonable(scalars))}, owner="write_velocity_error")


def read_velocity_error(path) -> dict:
    """Read a velocity-error result written by :func:`write_velocity_error`."""
    z = read_npz(path, what="mitpiv velocity error", required=("summary",))
    return {**json_entry(z, "summary", path), **{k: z[k] for k in ("reference", "error") if k in z}}
