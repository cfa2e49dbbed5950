"""Integer sensor images: EXR with a UINT channel (and mitpiv metadata), 8/16-bit PNG and TIFF.

PNG and TIFF are what other PIV software reads; the EXR keeps the metadata beside the
counts. Writes are atomic (a temporary file renamed over the target).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.io.atomic import atomic_path
from mitpiv.io.exr import METADATA_KEY
from mitpiv.io.records import json_default

__all__ = ["write_counts", "read_counts"]

_SUFFIXES = (".exr", ".png", ".tif", ".tiff")


def write_counts(path, counts, metadata: dict | None = None) -> Path:
    """Write an integer image (uint8 or uint16, shape (H, W)) by file suffix.

    ``.exr``: one ``Y`` channel of type UINT (32-bit) with ``metadata`` as JSON;
    ``.png`` / ``.tif`` / ``.tiff``: 8- or 16-bit greyscale (metadata not stored).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in _SUFFIXES:
        raise ConfigError(f"write_counts: file {str(path)!r} must end in one of {_SUFFIXES}.")
    arr = np.asarray(counts)
    if arr.ndim != 2 or arr.size == 0:
        raise ConfigError(f"write_counts: counts must be a non-empty 2D array, got shape {arr.shape}.")
    if arr.dtype not in (np.uint8, np.uint16):
        raise ConfigError(
            f"write_counts: counts must be uint8 or uint16 (apply_sensor with a bit_depth), got {arr.dtype}."
        )
    if suffix == ".exr":
        import OpenEXR

        try:
            meta_json = json.dumps(metadata or {}, default=json_default, sort_keys=True)
        except (TypeError, ValueError) as e:
            raise ConfigError(f"write_counts: metadata cannot be stored as JSON: {e}.") from None
        header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage, METADATA_KEY: meta_json}
        with atomic_path(path, suffix=".exr") as tmp:
            with OpenEXR.File(header, {"Y": np.ascontiguousarray(arr, dtype=np.uint32)}) as f:
                f.write(str(tmp))
        return path
    import cv2

    with atomic_path(path, suffix=suffix) as tmp:
        if not cv2.imwrite(str(tmp), np.ascontiguousarray(arr)):
            raise FileFormatError(f"write_counts: OpenCV could not write {str(path)!r}.")
    return path


def read_counts(path) -> tuple[np.ndarray, dict]:
    """Read an integer image written by :func:`write_counts`: (array, metadata)."""
    path = Path(path)
    if not path.is_file():
        raise FileFormatError(f"read_counts: {str(path)!r} does not exist.")
    if path.suffix.lower() == ".exr":
        import OpenEXR

        try:
            with OpenEXR.File(str(path)) as f:
                meta = f.header().get(METADATA_KEY)
                ch = f.channels()
                arr = np.array(ch["Y"].pixels)
        except Exception as e:
            raise FileFormatError(f"read_counts: {str(path)!r} is not a readable counts EXR ({e}).") from None
        if isinstance(meta, bytes):
            meta = meta.decode()
        return arr, (json.loads(meta) if meta else {})
    import cv2

    arr = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if arr is None:
        raise FileFormatError(f"read_counts: {str(path)!r} is not a readable image.")
    return arr, {}
