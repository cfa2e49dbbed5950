"""Float32 EXR images with mitpiv metadata (JSON in the header attribute ``mitpiv``).

A single-channel image is stored as channel ``Y``; an (H, W, C) image as ``R, G, B[, A]``
for C = 3/4 or ``C0..Cn`` otherwise. Writes are atomic: a temporary file in the same
folder is renamed over the target once complete.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.io.atomic import atomic_path
from mitpiv.io.records import json_default

__all__ = ["write_exr", "read_exr", "read_exr_metadata", "METADATA_KEY"]

METADATA_KEY = "mitpiv"


def write_exr(path, image, metadata: dict | None = None) -> Path:
    """Write ``image`` (H, W) or (H, W, C) as float32 EXR with ``metadata`` as JSON.

    Raises :class:`ConfigError` for a non-finite or badly shaped image, or metadata that
    cannot be written as JSON; nothing is written then.
    """
    import OpenEXR

    path = Path(path)
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim not in (2, 3) or img.shape[0] == 0 or img.shape[1] == 0:
        raise ConfigError(f"write_exr: image must have shape (H, W) or (H, W, C), got {img.shape}.")
    img = np.ascontiguousarray(img, dtype=np.float32)
    if not np.all(np.isfinite(img)):
        raise ConfigError(
            f"write_exr: image for {str(path)!r} has {np.count_nonzero(~np.isfinite(img))} "
            f"non-finite pixel(s); refusing to write it."
        )
    try:
        meta_json = json.dumps(metadata or {}, default=json_default, sort_keys=True)
    except (TypeError, ValueError) as e:
        raise ConfigError(f"write_exr: metadata cannot be stored as JSON: {e}.") from None
    if img.ndim == 2:
        channels = {"Y": img}
    elif img.shape[2] == 3:
        channels = {"RGB": img}
    elif img.shape[2] == 4:
        channels = {"RGBA": img}
    else:
        channels = {f"C{i}": np.ascontiguousarray(img[:, :, i]) for i in range(img.shape[2])}
    header = {
        "compression": OpenEXR.ZIP_COMPRESSION,
        "type": OpenEXR.scanlineimage,
        METADATA_KEY: meta_json,
    }
    with atomic_path(path, suffix=".exr", size_bytes=img.nbytes + len(meta_json)) as tmp:
        with OpenEXR.File(header, channels) as f:
            f.write(str(tmp))
    return path


def _check_exr(path: Path, owner: str) -> None:
    if path.is_dir():
        raise FileFormatError(f"{owner}: {str(path)!r} is a folder, not an EXR file; give one of its .exr files, e.g. "
                              f"{str(path / 'cam0_frame000.exr')!r}.")
    if not path.is_file():
        raise FileFormatError(f"{owner}: {str(path)!r} does not exist.")
    with open(path, "rb") as fh:
        head = fh.read(4)
    if head != b"\x76\x2f\x31\x01":  # the OpenEXR magic number 20000630
        what = "the file is empty, not a readable EXR file" if not head else \
            f"it is not a readable EXR file (it starts with {head!r})"
        raise FileFormatError(f"{owner}: {str(path)!r}: {what}; expected a float32 OpenEXR image (.exr).")


def _metadata(meta, path: Path, owner: str) -> dict:
    if meta is None:
        return {}
    if isinstance(meta, bytes):
        meta = meta.decode()
    try:
        return json.loads(meta)
    except json.JSONDecodeError as e:
        raise FileFormatError(f"{owner}: metadata in {str(path)!r} is not valid JSON ({e}).") from None


def read_exr_metadata(path) -> dict:
    """The mitpiv metadata of an EXR file, from its header alone (no pixels read): the
    dict :func:`read_exr` returns beside the image ({} for files of other software)."""
    import OpenEXR

    path = Path(path)
    _check_exr(path, "read_exr_metadata")
    try:
        with OpenEXR.File(str(path), header_only=True) as f:
            meta = f.header().get(METADATA_KEY)
    except Exception as e:  # OpenEXR raises plain exceptions for corrupt files
        raise FileFormatError(f"read_exr_metadata: {str(path)!r} is not a readable EXR file ({e}).") from None
    return _metadata(meta, path, "read_exr_metadata")


def read_exr(path) -> tuple[np.ndarray, dict]:
    """Read an EXR file: (image float32 (H, W) or (H, W, C), metadata dict).

    Files without mitpiv metadata (e.g. from other software) return an empty dict.
    """
    import OpenEXR

    path = Path(path)
    _check_exr(path, "read_exr")
    try:
        with OpenEXR.File(str(path)) as f:
            meta = f.header().get(METADATA_KEY)
            channels = {k: np.array(v.pixels, dtype=np.float32) for k, v in f.channels().items()}
    except Exception as e:  # OpenEXR raises plain exceptions for corrupt files
        raise FileFormatError(f"read_exr: {str(path)!r} is not a readable EXR file ({e}).") from None
    if "Y" in channels and len(channels) == 1:
        img = channels["Y"]
    elif len(channels) == 1:
        img = next(iter(channels.values()))
    else:
        keys = sorted(channels, key=lambda k: (len(k), k))
        img = np.stack([channels[k] if channels[k].ndim == 2 else channels[k][..., 0] for k in keys], axis=-1)
    return img, _metadata(meta, path, "read_exr")
