"""Frozen copy of mitpiv.analysis.piv3d.normalised_cross_correlation as of commit 0ac2986
(before the compiled local energies): float64 FFTs of every stack and the local energies
of the search regions from summed-volume tables (np.cumsum, three float64 copies per
region). The baseline bench/bench_speed.py prints beside today's NCC in the same run.
Bench-only."""

import math

import numpy as np


def _box_sums(x, w_zyx):
    c = np.pad(np.cumsum(np.cumsum(np.cumsum(x, axis=1, dtype=np.float64), axis=2), axis=3),
               ((0, 0), (1, 0), (1, 0), (1, 0)))
    wz, wy, wx = w_zyx
    return (c[:, wz:, wy:, wx:] - c[:, :-wz, wy:, wx:] - c[:, wz:, :-wy, wx:] - c[:, wz:, wy:, :-wx]
            + c[:, :-wz, :-wy, wx:] + c[:, :-wz, wy:, :-wx] + c[:, wz:, :-wy, :-wx] - c[:, :-wz, :-wy, :-wx])


def normalised_cross_correlation(template, search):
    from scipy import fft

    t = np.asarray(template, dtype=np.float64)
    f = np.asarray(search, dtype=np.float64)
    w = t.shape[1:]
    tp = t - t.mean(axis=(1, 2, 3), keepdims=True)
    et = np.sum(tp * tp, axis=(1, 2, 3))
    big = f.shape[1:]
    ft = fft.rfftn(tp, s=big, axes=(1, 2, 3), workers=-1)
    ff = fft.rfftn(f, axes=(1, 2, 3), workers=-1)
    num = fft.irfftn(np.conj(ft) * ff, s=big, axes=(1, 2, 3), workers=-1)
    nz, ny, nx = (b - a + 1 for a, b in zip(w, big, strict=True))
    num = num[:, :nz, :ny, :nx]
    s1 = _box_sums(f, w)
    s2 = _box_sums(f * f, w)
    ef = np.maximum(s2 - s1 * s1 / math.prod(w), 0.0)
    den = np.sqrt(ef * et[:, None, None, None])
    scale = np.max(den) if den.size else 0.0
    ok = den > 1e-12 * max(scale, 1e-300)
    return np.where(ok, num / np.where(ok, den, 1.0), 0.0)
