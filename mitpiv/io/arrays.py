"""Named NumPy arrays in ``.npz`` files, written atomically and read with errors that name
the file: the container of the light-field, vector-field, truth, volume and backlit formats,
and of a study's own arrays (match pairs, tracks)."""

from __future__ import annotations

import json
import math
import zipfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.io.atomic import atomic_path

__all__ = ["write_npz", "read_npz", "stack_output", "MAX_IN_MEMORY_BYTES"]

#: Largest stack kept in memory [bytes]; larger ones must stream to a file.
MAX_IN_MEMORY_BYTES = 2 * 1024**3


def write_npz(path, arrays: dict, *, compressed: bool = True, owner: str = "write_npz") -> Path:
    """Write named arrays to ``path`` (``.npz``, atomic).

    Parameters
    ----------
    path : str or Path
        Target file; must end in ``.npz``.
    arrays : dict of str -> array_like or str
        The entries. ``None`` values are left out (optional entries); a ``str`` is stored
        as a 0-d string array (JSON metadata). Object arrays are refused (they would need
        pickle to read back).
    compressed : bool
        ``np.savez_compressed`` (default) or ``np.savez`` (large float data where the
        compression costs more time than it saves).
    owner : str
        The public function named in error messages.
    """
    path = Path(path)
    if path.suffix != ".npz":
        raise ConfigError(f"{owner}: the file name must end in .npz, got {str(path)!r}.")
    entries = {}
    for key, value in arrays.items():
        if value is None:
            continue
        a = np.asarray(value)
        if a.dtype == object:
            raise ConfigError(f"{owner}: entry {key!r} for {str(path)!r} is not a numeric or string array "
                              f"(dtype object); give a NumPy array or a JSON string.")
        entries[key] = a
    with atomic_path(path, suffix=".npz", size_bytes=sum(a.nbytes for a in entries.values())) as tmp:
        with open(tmp, "wb") as fh:
            _savez(fh, entries, compressed)
    return path


#: The zip time stamp of every entry: fixed, so that equal arrays give byte-identical files.
_ZIP_DATE = (1980, 1, 1, 0, 0, 0)


def _savez(fh, entries: dict, compressed: bool) -> None:
    """``np.savez`` / ``np.savez_compressed`` (the same ``.npy`` entries, the same zip
    layout that ``np.load`` reads), but with a fixed time stamp per entry instead of the
    current time, so that a file's checksum depends on its content only (a run's stage
    outputs are compared and keyed by checksum). Hand-written because NumPy's writer has no
    time-stamp option; ``np.lib.format.write_array`` still writes each array."""
    comp = zipfile.ZIP_DEFLATED if compressed else zipfile.ZIP_STORED
    with zipfile.ZipFile(fh, mode="w", compression=comp, allowZip64=True) as zf:
        for key, a in entries.items():
            info = zipfile.ZipInfo(f"{key}.npy", date_time=_ZIP_DATE)
            info.compress_type = comp
            info.external_attr = 0o600 << 16
            with zf.open(info, "w", force_zip64=True) as fid:
                np.lib.format.write_array(fid, np.asanyarray(a), allow_pickle=False)


def read_npz(path, *, what: str = "array file", required=()) -> dict:
    """All arrays of an ``.npz`` file, as a dict (loaded into memory).

    Raises :class:`FileFormatError` naming the file when it does not exist, is not an
    ``.npz`` archive readable without pickle, or lacks one of the ``required`` entries.
    ``what`` names the format in the message (e.g. ``"mitpiv light field"``).
    """
    path = Path(path)
    if not path.is_file():
        raise FileFormatError(f"{what} file {str(path)!r} does not exist.")
    expected = f"expected a {what} (.npz: a zip archive of named NumPy arrays, as mitpiv writes it)"
    with open(path, "rb") as fh:
        head = fh.read(6)
    if not head:
        raise FileFormatError(f"{str(path)!r}: the file is empty; {expected}.")
    if head.startswith(b"\x93NUMPY"):
        raise FileFormatError(f"{str(path)!r}: it holds a single array (.npy), not named arrays; {expected}.")
    if not head.startswith(b"PK"):
        raise FileFormatError(f"{str(path)!r}: it is not a zip archive (it starts with {head!r}); {expected}.")
    try:
        with np.load(path, allow_pickle=False) as z:
            out = {k: z[k] for k in z.files}
    except ValueError as e:
        if "pickle" in str(e):
            raise FileFormatError(f"{str(path)!r}: an entry holds pickled Python objects, which mitpiv never reads "
                                  f"(unsafe); {expected}.") from None
        raise FileFormatError(f"{str(path)!r}: {e}; {expected}.") from None
    except (OSError, EOFError, zipfile.BadZipFile) as e:
        raise FileFormatError(f"{str(path)!r}: the archive is truncated or corrupt ({e}); {expected}.") from None
    missing = [k for k in required if k not in out]
    if missing:
        raise FileFormatError(f"{str(path)!r}: it lacks the entries {missing} (it holds {sorted(out)}); expected a "
                              f"{what} file with {list(required)}.")
    return out


def json_entry(arrays: dict, key: str, path, *, default=None):
    """Parse the JSON string entry ``key`` of :func:`read_npz`'s result (``default`` when absent)."""
    if key not in arrays:
        return default
    try:
        return json.loads(str(arrays[key]))
    except json.JSONDecodeError as e:
        raise FileFormatError(f"{str(path)!r}: entry {key!r} is not valid JSON ({e}).") from None


@contextmanager
def stack_output(shape, out=None, what: str = "stack"):
    """Yield the float32 array of ``shape`` that a stack (focal stack, refocused volume) is
    written into: in memory, or with ``out`` a memory map of a temporary ``.npy`` beside
    ``out`` that replaces it only once complete (a failed run leaves nothing). ``what``
    names the caller in errors. In-memory results above 2 GiB are refused: stream them."""
    if out is None:
        nbytes = 4 * math.prod(shape)
        if nbytes > MAX_IN_MEMORY_BYTES:
            raise ConfigError(f"{what}: the result needs {nbytes / 1024**3:.1f} GiB; give out='result.npy' to stream it to disk.")
        yield np.empty(shape, np.float32)
        return
    path = Path(out)
    if path.suffix != ".npy":
        raise ConfigError(f"{what}: 'out' must be a .npy file, got {str(path)!r}.")
    with atomic_path(path, suffix=".npy", size_bytes=4 * math.prod(shape)) as tmp:
        arr = np.lib.format.open_memmap(tmp, mode="w+", dtype=np.float32, shape=shape)
        try:
            yield arr
            arr.flush()
        finally:
            del arr
