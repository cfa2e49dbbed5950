"""mitpiv._alloc.retain_freed_memory: after it, a freed 400 MB (381 MiB) array stays in the
process and the next array reuses its pages (no page faults), where by default glibc gives
it back at once and the next array faults its pages in again (at least 191 faults: one per
2 MiB huge page where the kernel gives them, else one per 4 kB page). Each case runs in a
fresh interpreter (the setting is process-wide).

A busy or NUMA machine also faults on pages a process already holds (the kernel's NUMA
balancing unmaps them now and then to see who uses them: 565 such faults were counted on a
loaded 2-core Xeon). So the second array's faults are compared with a control measured in the
same process: rewriting another 400 MB array that stays resident throughout. Reuse means no
more faults than the control; giving the block back means 191 or more beyond it."""

import subprocess
import sys

import pytest

SCRIPT = r"""
import resource, sys
import numpy as np
from mitpiv._alloc import retain_freed_memory
ok = retain_freed_memory() if sys.argv[1] == "on" else None
def rss_mb():
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * resource.getpagesize() / 2**20
control = np.ones(100_000_000, np.float32)  # resident throughout: the machine's own faults
base = rss_mb()
a = np.ones(100_000_000, np.float32)  # 400 MB, touched
held = rss_mb()
del a
after_free = rss_mb()
faults0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
b = np.ones(100_000_000, np.float32)
faults = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults0
faults0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
control[:] = 2.0  # the same amount of writing to pages the process holds
machine = resource.getrusage(resource.RUSAGE_SELF).ru_minflt - faults0
print(ok, held - base, after_free - base, faults - machine)
"""


def _run(mode):
    out = subprocess.run([sys.executable, "-c", SCRIPT, mode], capture_output=True, text=True, check=True)
    ok, held, after, faults = out.stdout.split()
    return ok, float(held), float(after), int(faults)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's allocator: Linux only")
def test_freed_memory_is_kept_and_reused():
    ok, held, after, faults = _run("on")
    assert ok == "True" and held > 375
    assert after > 375, "the freed array was given back to the system"
    assert faults < 20, f"the second array page-faulted {faults} times more than resident memory did"
    ok, held, after, faults = _run("off")
    assert ok == "None" and held > 375
    assert after < 20, "glibc's default gives a freed 381 MiB block back (mmap)"
    assert faults >= 191
