"""What the near-field jet's synthetic turbulence costs (mitpiv.physics.jet.NearFieldJet,
the lfpiv-vs-tomo replication's flow: advection and the window-averaged truth call it for
every particle and every quadrature node).

The sum over its 400 random Fourier modes, ``psi = sum b_n sin(theta_n)`` and
``curl psi = sum amp_n cos(theta_n)``, as the earlier code computed it (NumPy: the
``(N, 400)`` phase array, ``cos`` and ``sin`` of it, two matrix products, in chunks of 20000
points) beside the Numba kernel that replaced it (one pass over the modes per point, points
in parallel), in the same run: median of 3 after a warm-up, the ratio, and the largest
relative difference of the two results. Then ``velocity`` (mean flow + turbulence) per
point.

``.venv/bin/python bench/bench_jet.py`` (about a minute on 2 cores).
"""

from __future__ import annotations

import os
import platform
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
from mitpiv.physics.jet import NearFieldJet  # noqa: E402


def numpy_sums(jet, p, chunk: int = 20000):
    """The earlier NumPy evaluation of the mode sums (the baseline)."""
    le = jet.length_scale_mm
    kv = jet._khat * (jet._kmag_le / le)[:, None]
    b = np.cross(jet._amp, kv) / np.sum(kv * kv, axis=1)[:, None]
    psi, curl = np.empty_like(p), np.empty_like(p)
    for s in range(0, len(p), chunk):
        th = (p[s : s + chunk] - jet.nozzle_mm) @ kv.T + jet._phase
        curl[s : s + chunk] = np.cos(th) @ jet._amp
        psi[s : s + chunk] = np.sin(th) @ b
    return psi, curl


def timed(fn, repeat: int = 3) -> tuple[float, object]:
    fn()  # warm-up (the kernel's compilation or its cache load)
    walls, out = [], None
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        walls.append(time.perf_counter() - t)
    return statistics.median(walls), out


def main() -> None:
    print(f"Machine: {platform.node()} ({platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}), {time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")
    jet = NearFieldJet()
    print("| points | NumPy (earlier) | Numba kernel | ratio | max relative difference |")
    print("|---|---|---|---|---|")
    for n in (20_000, 100_000, 400_000):
        p = np.random.default_rng(0).uniform([1.0, -30.0, -30.0], [40.0, 30.0, 30.0], (n, 3))
        t0, (psi0, curl0) = timed(lambda p=p: numpy_sums(jet, p))
        t1, (psi1, curl1) = timed(lambda p=p: jet._psi_and_curl(p, jet.length_scale_mm))
        diff = max(np.abs(psi1 - psi0).max() / np.abs(psi0).max(), np.abs(curl1 - curl0).max() / np.abs(curl0).max())
        print(f"| {n} | {t0:.3f} s | {t1:.3f} s | {t0 / t1:.1f}x | {diff:.1e} |")
    p = np.random.default_rng(1).uniform([1.0, -30.0, -30.0], [40.0, 30.0, 30.0], (100_000, 3))
    t, _ = timed(lambda: jet.velocity(p))
    print(f"velocity (mean + turbulence): {1e6 * t / len(p):.1f} us per point (100000 points)")


if __name__ == "__main__":
    main()
