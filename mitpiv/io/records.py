"""Run records and small text files: JSON (``experiment.json``, ``stage.json``,
``metrics.json``, ``timings.json``) and markdown, written atomically.

JSON is written as the standard library writes it, with NumPy scalars and arrays, tuples
and paths made JSON-safe first (:func:`to_jsonable`). Non-finite floats are written as
``NaN`` / ``Infinity`` (Python's JSON dialect, which :func:`read_json` reads back): a
metric that could not be computed stays NaN rather than becoming a string.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path, PurePath

import numpy as np

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.io.atomic import atomic_path

__all__ = ["to_jsonable", "json_default", "write_json", "read_json", "write_text", "file_sha256"]


def to_jsonable(obj):
    """A copy of ``obj`` that :func:`json.dumps` accepts.

    Dicts (keys made ``str`` where they are NumPy scalars or paths), lists and tuples
    (-> lists) are converted recursively; NumPy arrays become nested lists, NumPy scalars
    Python numbers, paths strings. Anything else is returned unchanged (``json`` then
    decides, or the ``default`` hook of :func:`write_json`).
    """
    if isinstance(obj, dict):
        return {_key(k): to_jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [to_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return to_jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, PurePath):
        return str(obj)
    return obj


def _key(k):
    if isinstance(k, np.generic):
        k = k.item()
    return str(k) if isinstance(k, PurePath) else k


def json_default(o):
    """``default=`` hook for :func:`json.dumps`: NumPy arrays/scalars and paths, else TypeError."""
    if isinstance(o, (np.ndarray, np.generic, PurePath)):
        return to_jsonable(o)
    raise TypeError(f"value of type {type(o).__name__} is not JSON-serialisable")


def write_json(path, obj, *, indent: int | None = 2, sort_keys: bool = False, default=None) -> Path:
    """Write ``obj`` as JSON to ``path`` (atomic: a temporary file renamed over ``path``).

    Parameters
    ----------
    path : str or Path
        Target file (its folder is created).
    obj : JSON-like
        Dicts, lists, numbers, strings, None, NumPy arrays and scalars, tuples, paths.
    indent, sort_keys
        As for :func:`json.dumps`.
    default : callable, optional
        Hook for other objects (e.g. ``str``), as for :func:`json.dumps`; without it such an
        object raises :class:`ConfigError` and nothing is written.

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    try:
        with atomic_path(path, suffix=".json") as tmp:
            with open(tmp, "w", encoding="utf-8") as fh:
                json.dump(to_jsonable(obj), fh, indent=indent, sort_keys=sort_keys, default=default)
                fh.write("\n")
    except (TypeError, ValueError) as e:  # json stops midway; atomic_path has removed the partial file
        raise ConfigError(f"write_json: the record for {str(path)!r} cannot be written as JSON: {e}. Give "
                          f"numbers, strings, lists and dicts (or default=str).") from None
    return path


def read_json(path):
    """Read a JSON file. Raises :class:`FileFormatError` naming the file when it is missing
    or not JSON."""
    path = Path(path)
    if not path.is_file():
        raise FileFormatError(f"read_json: {str(path)!r} does not exist.")
    try:
        return json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise FileFormatError(f"read_json: {str(path)!r} is not a JSON file ({e}).") from None


def write_text(path, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically (reports, markdown, CSV made elsewhere)."""
    path = Path(path)
    with atomic_path(path) as tmp:
        with open(tmp, "w", encoding="utf-8") as fh:
            fh.write(text)
    return path


def file_sha256(path) -> str:
    """The hex SHA-256 of a file's content, read in a stream (constant memory): the
    checksums of stage outputs and the content keys of input files."""
    with open(path, "rb") as fh:
        return hashlib.file_digest(fh, "sha256").hexdigest()
