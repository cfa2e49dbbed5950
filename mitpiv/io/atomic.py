"""Atomic file writing: write to a hidden temporary file in the same folder, flush it to
disk (``fsync``), rename it over the target, and flush the folder, so that a crash leaves
either the old file or the new one, never a torn one.

Also: the free-disk-space check before large writes (:func:`check_free_space`), the
clean-up of temporary files that an interrupted run left behind (:func:`clean_temps`), and
the folder flush used when a whole stage folder is renamed into place (:func:`fsync_dir`).

Folder locks (:func:`folder_lock`): one process at a time writes a run or sweep folder; the
lock is an OS file lock (``flock`` through the kept library filelock) on ``.mitpiv.lock``,
released by the OS when the holder dies, so a killed run never leaves a stale lock; who
holds it (PID, host, start time, command) is in ``.mitpiv.lock.owner``.

Temporary names carry mitpiv's tag, so that they are recognisable as ours beyond doubt: a
file ``x.npz`` is written as ``.x.npz.mitpiv-tmp-<8 random>.npz`` (the random part from
:func:`tempfile.mkstemp`); a runner's stage folder ``s`` is filled as
``.s.mitpiv-tmp-<token>`` (and an old one moved aside as ``.s.mitpiv-old-<token>``), where
``<token>`` is the lock identity of the run that made it (12 hex digits, a fresh random one
each time a folder's lock is taken, recorded in the owner record; :func:`temp_dir`).
:func:`clean_temps` removes exactly these: files of the file shape, folders of the folder
shape. Everything else is left alone: every other hidden name (a user's
``.config.settings.json``, ``.notes.old_2024.txt``, ``.cache.old/`` ..., and the untagged
names of earlier mitpiv versions, ``.s.tmp``, ``.x.npz.tmp-<random>.npz``), a link, a file
of the folder shape or a folder of the file shape, and the current holder's own folders.
"""

from __future__ import annotations

import datetime
import json
import logging
import os
import re
import secrets
import shutil
import socket
import sys
import tempfile
import threading
from contextlib import contextmanager
from pathlib import Path

from mitpiv.errors import DiskSpaceError, FolderLockedError

__all__ = ["atomic_path", "fsync_dir", "check_free_space", "clean_temps", "folder_lock", "lock_holder", "temp_dir",
           "TMP_MARK", "LOCK_NAME", "DiskSpaceError", "FolderLockedError"]

log = logging.getLogger(__name__)

#: Part of every temporary file name (``.<name>.mitpiv-tmp-<random><suffix>``).
TMP_MARK = ".mitpiv-tmp-"

#: The lock file of a locked folder, and the record of who holds it.
LOCK_NAME = ".mitpiv.lock"
_OWNER_NAME = ".mitpiv.lock.owner"

#: Free space kept in reserve beyond a write's estimate [bytes].
RESERVE_BYTES = 64 * 2**20

# temporary files of atomic_path: the tag, mkstemp's 8 random characters, one suffix
_TMP_FILE = re.compile(r"^\..+\.mitpiv-tmp-[a-z0-9_]{8}(\.[A-Za-z0-9_-]{1,16})?$")
# a runner's stage folders being filled (-tmp-) or moved aside (-old-), with the lock token
_TMP_DIR = re.compile(r"^\..+\.mitpiv-(tmp|old)-(?P<token>[0-9a-f]{12})$")


def fsync_dir(path) -> None:
    """Flush a folder's entries (a rename inside it) to disk; a no-op where the platform
    cannot open folders (Windows)."""
    try:
        fd = os.open(str(path), os.O_RDONLY)
    except OSError:  # pragma: no cover - Windows
        return
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover - file systems without folder fsync
        pass
    finally:
        os.close(fd)


def check_free_space(folder, size_bytes: float, *, what: str = "the output") -> None:
    """Raise :class:`DiskSpaceError` when ``folder``'s file system has less than
    ``size_bytes`` (an estimate of what is about to be written) plus a 64 MiB reserve free.

    folder : an existing folder (or a path below one: the nearest existing parent is used).
    size_bytes : the estimate [bytes].
    """
    p = Path(folder)
    while not p.exists() and p != p.parent:
        p = p.parent
    free = shutil.disk_usage(p).free
    need = float(size_bytes) + RESERVE_BYTES
    if free < need:
        raise DiskSpaceError(
            f"not enough free disk space for {what} in {str(folder)!r}: it needs about {_size(size_bytes)} "
            f"(+ {_size(RESERVE_BYTES)} reserve), {_size(free)} is free. Free some space, write to another "
            f"folder (--out), or make the output smaller (resolution, voxel size, frames).")


def _size(n: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if abs(n) < 1024 or unit == "TiB":
            return f"{n:.1f} {unit}" if unit != "B" else f"{int(n)} B"
        n /= 1024
    return f"{n} B"  # pragma: no cover


@contextmanager
def atomic_path(path, suffix: str | None = None, *, size_bytes: float | None = None):
    """Yield a temporary path beside ``path``; on success flush it to disk and rename it
    over ``path`` (then flush the folder).

    On an exception (or a ``KeyboardInterrupt`` / ``SystemExit``) the temporary file is
    removed and ``path`` is untouched. A ``path`` that is an existing folder (or lies in a
    file) is a :class:`~mitpiv.errors.ConfigError`. The file gets the permissions of a
    plainly created one (0666 less the umask), not mkstemp's 0600.

    size_bytes : an estimate of the file's size [bytes]; when given, the free disk space is
        checked first (:func:`check_free_space`) and nothing is written if it is short.
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
    if size_bytes is not None:
        check_free_space(path.parent, size_bytes, what=f"{path.name!r}")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}{TMP_MARK}", suffix=suffix or path.suffix or ".tmp",
                               dir=path.parent)
    os.close(fd)
    try:
        yield Path(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        _fsync_file(tmp)
        os.replace(tmp, path)
        fsync_dir(path.parent)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise


def _fsync_file(path) -> None:
    fd = os.open(str(path), os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def clean_temps(folder, *, recursive: bool = False, token: str | None = None) -> list[Path]:
    """Remove the temporary files and stage folders that an interrupted mitpiv write or run
    left in ``folder`` (only names of mitpiv's own shapes, see the module notes: a user's
    hidden files are never touched); returns what was removed.

    Call it only while no other process writes there (the runner holds the run folder's
    lock). recursive : also look in every sub-folder (not inside removed ones); off by
    default, so that a run folder given as a large existing folder is not walked whole.
    token : the lock token of the current holder (what :func:`folder_lock` yields): its own
        temporary folders are kept.
    """
    folder = Path(folder)
    removed: list[Path] = []
    if not folder.is_dir():
        return removed
    for root, dirs, files in os.walk(folder):
        r = Path(root)
        for d in list(dirs):
            m = _TMP_DIR.match(d)
            if m and m["token"] != token and not (r / d).is_symlink():
                shutil.rmtree(r / d, ignore_errors=True)
                removed.append(r / d)
                dirs.remove(d)
        for f in files:
            if _TMP_FILE.match(f) and not (r / f).is_symlink():
                try:
                    (r / f).unlink()
                    removed.append(r / f)
                except FileNotFoundError:
                    pass
        if not recursive:
            break
    if removed:
        log.info("removed %d temporary file(s) of an interrupted run in %s", len(removed), folder)
    return removed


# (folder, thread) -> [nesting depth, lock token]: a run inside a sweep point or run_config
# around run_stages takes the lock it already holds again without blocking itself
_HELD: dict[tuple[str, int], list] = {}


def temp_dir(folder, name: str, kind: str = "tmp") -> Path:
    """The temporary folder ``.<name>.mitpiv-<kind>-<token>`` in ``folder``, whose lock this
    thread must hold (``token``: the lock's, see :func:`folder_lock`): where a stage folder
    ``name`` is filled (kind ``"tmp"``) or an old one is moved aside (``"old"``). It is
    named for this holder alone, so it is never a user's, and :func:`clean_temps` of a later
    run removes it if this one dies."""
    folder = Path(folder)
    held = _HELD.get((str(folder.resolve()), threading.get_ident()))
    if held is None or kind not in ("tmp", "old"):
        raise ValueError(f"temp_dir({str(folder)!r}, {name!r}, {kind!r}): call it inside folder_lock of that "
                         "folder, with kind 'tmp' or 'old'.")
    return folder / f".{name}.mitpiv-{kind}-{held[1]}"


def lock_holder(folder) -> str:
    """Who holds ``folder``'s lock, in words (from its owner record)."""
    try:
        o = json.loads((Path(folder) / _OWNER_NAME).read_text())
        cmd = " ".join(o.get("command") or [])
        return (f"PID {o['pid']} on host {o['host']} since {o['started']}" + (f" ({cmd})" if cmd else ""))
    except (OSError, ValueError, KeyError, TypeError):
        return "another process (it is starting, or its owner record is unreadable)"


@contextmanager
def folder_lock(folder, *, what: str = "run folder"):
    """Hold the exclusive lock of ``folder`` (created if missing) for the ``with`` block;
    yields the lock token (12 random hex digits, new each time the lock is taken, the same
    for nested calls; in the owner record) that names this holder's temporary folders
    (:func:`temp_dir`).

    Raises :class:`FolderLockedError` at once (no waiting) when another process, or another
    thread of this one, holds it: the message names the holder's PID, host, start time and
    command. The same thread may take a lock it holds again (nested calls).
    """
    from filelock import FileLock, Timeout

    folder = Path(folder)
    for p in (folder, *folder.parents):
        if p.is_dir():
            break
        if p.exists():
            from mitpiv.errors import ConfigError

            raise ConfigError(f"{what} {str(folder)!r}: {str(p)!r} is a file, not a folder; give another "
                              f"folder, or move that file away.")
    folder.mkdir(parents=True, exist_ok=True)
    key = (str(folder.resolve()), threading.get_ident())
    if key in _HELD:
        _HELD[key][0] += 1
        try:
            yield _HELD[key][1]
        finally:
            _HELD[key][0] -= 1
        return
    lock = FileLock(str(folder / LOCK_NAME), timeout=0)
    try:
        lock.acquire(timeout=0)
    except Timeout:
        raise FolderLockedError(
            f"{what} {str(folder)!r} is locked by {lock_holder(folder)}: another mitpiv process is writing "
            f"there. Wait for it to finish (or stop it), or give another output folder.") from None
    try:
        token = secrets.token_hex(6)
        owner = {"pid": os.getpid(), "host": socket.gethostname(), "token": token,
                 "started": datetime.datetime.now(datetime.UTC).strftime("%Y-%m-%d %H:%M:%S UTC"),
                 "command": [Path(sys.argv[0]).name] + sys.argv[1:] if sys.argv and sys.argv[0] else []}
        with atomic_path(folder / _OWNER_NAME, suffix=".json") as tmp:
            tmp.write_text(json.dumps(owner))
        _HELD[key] = [1, token]
        yield token
    finally:
        _HELD.pop(key, None)
        try:
            (folder / _OWNER_NAME).unlink()
        except OSError:
            pass
        lock.release()
