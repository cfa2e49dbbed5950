"""Lazy Numba import with a writable on-disk kernel cache (shared by every Numba user).

Kernel factories (``kernels()`` functions that define ``@njit(cache=True)`` kernels on first
use) declare the helpers that other kernels call as module globals (``global name``), not as
closure cells: Numba's cache key hashes a kernel's closure cells, and a pickled dispatcher
differs in every process, so a kernel calling a closure helper was compiled afresh in every
process (10 s of the demo's MART set-up) and added one cache entry each time
(tests/test_numba_cache.py)."""

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
