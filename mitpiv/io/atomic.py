"""Atomic file writing: write to a temporary file in the same folder, then rename."""

from __future__ import annotations

import os
import tempfile
from contextlib import contextmanager
from pathlib import Path


@contextmanager
def atomic_path(path, suffix: str | None = None):
    """Yield a temporary path beside ``path``; on success rename it over ``path``.

    On an exception the temporary file is removed and ``path`` is untouched. A ``path``
    that is an existing folder (or lies in a file) is a :class:`~mitpiv.errors.ConfigError`. The file gets
    the permissions of a plainly created one (0666 less the umask), not mkstemp's 0600.
    """
    path = Path(path)
    if path.is_dir():
        from mitpiv.errors import ConfigError

        raise ConfigError(f"{str(path)!r} is a folder, not a file name; give the file to write, e.g. "
                          f"{str(path / ('result' + (suffix or path.suffix or '')))!r}.")
    if path.parent.exists() and not path.parent.is_dir():
        from mitpiv.errors import ConfigError

        raise ConfigError(f"{str(path.parent)!r} is a file, not a folder; {path.name!r} cannot be written in it.")
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix or path.suffix or ".tmp", dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
