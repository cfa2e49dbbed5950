"""Keep freed memory in the process for reuse (glibc's allocator), so that large temporary
arrays do not page-fault afresh each time.

glibc serves every allocation above 32 MB by ``mmap`` and gives it back on ``free``; the next
array of that size touches new pages, and each 4 kB page is a fault. On the 2-core VM the
benchmarks run on, first-touch memory costs 2.1 s per GB (100 MB in 0.21 s, against 0.003 s
to rewrite it; no transparent huge pages), and the pipeline's stages allocate and free
arrays of 50-500 MB all the time (FFT batches, weight assembly, rankings). With mmap turned
off and the heap's trim threshold raised, freed blocks stay in the heap and the next array
reuses their pages: ``make demo`` 48.7 s -> 41.0 s (PIV 16.2 -> 10.9 s), peak RSS 3.34 ->
3.56 GB (the same run back to back).

The cost is that freed memory is not returned to the system until the process ends: fine
for a run, a sweep worker or a benchmark, not wanted inside a user's long-lived process, so
only the runner (every ``mitpiv run`` and sweep point) and each replication point call
:func:`retain_freed_memory`; library functions do not. A no-op (returns False) where the C
library is not glibc.

Written by hand: two ``mallopt`` calls through ctypes; no kept library wraps them.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools

M_TRIM_THRESHOLD = -1
M_MMAP_MAX = -4
#: heap space above this much free at the top is given back (the largest int mallopt takes)
TRIM_THRESHOLD = 2**31 - 1


@functools.lru_cache(maxsize=1)
def retain_freed_memory() -> bool:
    """Turn off glibc's mmap for large blocks and keep up to 2 GB of freed heap top: True
    when set (once per process), False where it cannot be (no glibc ``mallopt``)."""
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c"))
    except (OSError, TypeError):
        return False
    if not (hasattr(libc, "mallopt") and hasattr(libc, "gnu_get_libc_version")):
        return False  # glibc only: other C libraries' mallopt options differ
    mallopt = libc.mallopt
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    mallopt.restype = ctypes.c_int
    return bool(mallopt(M_MMAP_MAX, 0)) and bool(mallopt(M_TRIM_THRESHOLD, TRIM_THRESHOLD))
