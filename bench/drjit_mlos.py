"""The MLOS pass in float32 Dr.Jit: the variant of ``mitpiv.reconstruct._drjit.mlos_block``
(float64, what the library runs) that was measured and not kept. Faster (0.12 s against
0.15 s for 480x320x130 voxels and 4 cameras on 2 cores), but 2e-3 of the peak away from the
float64 values, and 2e-6 of the voxels change candidate status. The same single-kernel
structure, with literal (not opaque) camera constants: a new camera set compiles a new
kernel. Bench-only (``bench/bench_speed.py --sections drjit``), ``backend_name="cuda"``
untried (no GPU).
"""

from __future__ import annotations

import math

import numpy as np


def backend(name="llvm"):
    import drjit as dr

    mod = {"llvm": "drjit.llvm", "cuda": "drjit.cuda"}[name]
    if name == "llvm" and not dr.has_backend(dr.JitBackend.LLVM):
        raise RuntimeError("Dr.Jit's LLVM backend is not available (LLVM >= 16 needed: scripts/setup.sh)")
    if name == "cuda" and not dr.has_backend(dr.JitBackend.CUDA):
        raise RuntimeError("Dr.Jit's CUDA backend is not available (no GPU)")
    import importlib

    return importlib.import_module(mod)


def mlos_drjit(imgs, rows, grid, *, backend_name="llvm"):
    """MLOS values of every voxel of ``grid`` (flat z, y, x order), float32 NumPy array.
    ``rows``: the packed pinhole cameras (``_kernels.camera_row``), one per image."""
    import drjit as dr

    m = backend(backend_name)
    Float, UInt32 = m.Float, m.UInt32
    npf = np.float32
    nz, ny, nx = grid.shape
    flat = Float(np.concatenate([np.asarray(im, npf).ravel() for im in imgs]))
    xs, ys, zs = (Float(np.asarray(a, npf)) for a in (grid.x_mm, grid.y_mm, grid.z_mm))
    i = dr.arange(UInt32, nz * ny * nx)
    x = dr.gather(Float, xs, i % nx)
    y = dr.gather(Float, ys, (i // nx) % ny)
    z = dr.gather(Float, zs, i // (nx * ny))
    lg = dr.zeros(Float, nz * ny * nx)
    off = 0
    for im, cam in zip(imgs, rows, strict=True):
        h, w = im.shape
        c = [float(v) for v in cam]
        px, py, pz = x - c[9], y - c[10], z - c[11]
        xc = c[0] * px + c[1] * py + c[2] * pz
        yc = c[3] * px + c[4] * py + c[5] * pz
        zc = c[6] * px + c[7] * py + c[8] * pz
        xn, yn = xc / zc, yc / zc
        r2 = xn * xn + yn * yn
        radial = 1.0 + r2 * (c[15] + r2 * (c[16] + r2 * c[17]))
        xy2 = 2.0 * xn * yn
        u = c[12] * (xn * radial + c[18] * xy2 + c[19] * (r2 + 2.0 * xn * xn)) + c[13]
        v = c[12] * (yn * radial + c[18] * (r2 + 2.0 * yn * yn) + c[19] * xy2) + c[14]
        rr, cc = v - 0.5, u - 0.5
        ok = (zc > 0) & (rr >= 0) & (rr <= h - 1) & (cc >= 0) & (cc <= w - 1)
        r0 = dr.minimum(UInt32(dr.floor(dr.select(ok, rr, 0))), max(h - 2, 0))
        c0 = dr.minimum(UInt32(dr.floor(dr.select(ok, cc, 0))), max(w - 2, 0))
        fr, fc = rr - Float(r0), cc - Float(c0)
        r1, c1 = dr.minimum(r0 + 1, h - 1), dr.minimum(c0 + 1, w - 1)
        g = [dr.gather(Float, flat, off + a * w + b, ok) for a, b in ((r0, c0), (r0, c1), (r1, c0), (r1, c1))]
        s = (1.0 - fr) * ((1.0 - fc) * g[0] + fc * g[1]) + fr * ((1.0 - fc) * g[2] + fc * g[3])
        lg += dr.select(ok & (s > 0), dr.log(dr.select(ok & (s > 0), s, 1.0)), -math.inf)
        off += h * w
    val = dr.exp(lg * (1.0 / len(imgs)))
    dr.eval(val)
    return val.numpy()
