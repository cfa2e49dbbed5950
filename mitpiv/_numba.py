"""Lazy Numba import with a writable on-disk kernel cache (shared by every Numba user)."""

from __future__ import annotations

import os
from pathlib import Path

CACHE_DIR = str(Path.home() / ".cache" / "mitpiv" / "numba")


def set_cache_dir() -> None:
    """Point Numba's cache at mitpiv's folder unless the user chose one."""
    os.environ.setdefault("NUMBA_CACHE_DIR", CACHE_DIR)


def numba():
    """Import numba (after :func:`set_cache_dir`); imported only when a kernel is needed."""
    set_cache_dir()
    import numba as nb

    return nb
