"""Decoded light fields on disk: ``.npz`` with the sub-aperture images and the decode
geometry, the camera optics and the decode info as JSON (atomic writes).

Entries: ``data`` (n_v, n_u, n_t, n_s) float32, ``s_px`` (n_s,), ``t_px`` (n_t,),
``du_px`` (n_u,), ``view_weights`` (n_v, n_u), ``valid`` (n_t, n_s) bool, ``optics``
(JSON: ``PlenopticCamera.to_dict()`` or null), ``info`` (JSON). Stored uncompressed: the
float data hardly compresses and light fields are large.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING

from mitpiv.io.arrays import json_entry, read_npz, write_npz
from mitpiv.io.records import to_jsonable

if TYPE_CHECKING:
    from mitpiv.lightfield.decode import LightField

__all__ = ["write_lightfield", "read_lightfield"]

_ARRAYS = ("data", "s_px", "t_px", "du_px", "view_weights", "valid")


def write_lightfield(path, lf: LightField) -> Path:
    """Write the light field ``lf`` to ``path`` (``.npz``, atomic) with its optics and decode info.

    Raises :class:`~mitpiv.errors.ConfigError` for another suffix (nothing is written).
    """
    optics = None if lf.optics is None else lf.optics.to_dict()
    return write_npz(path, {**{k: getattr(lf, k) for k in _ARRAYS}, "optics": json.dumps(to_jsonable(optics)),
                            "info": json.dumps(to_jsonable(lf.info))}, compressed=False, owner="write_lightfield")


def read_lightfield(path) -> dict:
    """Read a light field written by :func:`write_lightfield` (or ``LightField.save``) as
    the record ``LightField(**record)`` takes (``LightField.load(path)`` does that): the
    arrays, ``optics`` (a PlenopticCamera or None) and ``info``.

    Raises :class:`~mitpiv.errors.FileFormatError` naming the file when it is missing or
    not a mitpiv light field.
    """
    from mitpiv.errors import FileFormatError
    from mitpiv.physics.plenoptic import PlenopticCamera

    z = read_npz(path, what="mitpiv light field", required=(*_ARRAYS, "optics", "info"))
    optics = json_entry(z, "optics", path)
    try:
        cam = None if optics is None else PlenopticCamera.from_dict(optics)
    except (KeyError, TypeError, ValueError) as e:
        raise FileFormatError(f"{str(path)!r}: the light field's optics are not a plenoptic camera ({e}).") from None
    return {**{k: z[k] for k in _ARRAYS}, "optics": cam, "info": json_entry(z, "info", path)}
