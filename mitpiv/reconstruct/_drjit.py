"""The MLOS pass of the pinhole fast path written in Dr.Jit (LLVM backend, float64).

The performance issue's experiment: a gather over voxels written once in Dr.Jit, kept where
it wins on the CPU. It does here: Dr.Jit traces the whole pass (the pinhole projection with
Brown-Conrady distortion, four bilinear gathers per camera, the log-space product, the
exponential) into one SIMD kernel over all voxels of a block of planes, where the Numba
kernel (``_kernels.mlos_pinhole``, kept as the fallback) runs scalar code per voxel:
480x320x130 voxels, 4 cameras of 640x480 px, 2 cores: 0.15 s against 0.95 s, equal to
2.6e-16 relative (``bench/bench_speed.py --sections drjit``). The float32 variant is faster
still (0.12 s) but differs by 2e-3 of the peak and flips 2e-6 of the candidates, so the
library computes in float64.

Only the LLVM (CPU) backend is used: the same code would run on ``drjit.cuda``, but no GPU
was available to check it. When Dr.Jit's LLVM backend is missing (LLVM < 16 on the
machine) the Numba kernel runs instead; :func:`available` says which.

Written by hand: the arithmetic mirrors ``_kernels.pinhole`` and ``_kernels.sample_linear``
line for line (the tests compare the two kernels on distorted cameras, voxels outside the
views and zero pixels).
"""

from __future__ import annotations

import functools
import math

import numpy as np

#: voxels per kernel launch: the float64 output and the mask of one block stay < 150 MB
BLOCK_VOXELS = 1 << 24


@functools.lru_cache(maxsize=1)
def available() -> bool:
    """True when Dr.Jit's LLVM backend is initialised (LLVM >= 16 found)."""
    try:
        import drjit as dr

        return bool(dr.has_backend(dr.JitBackend.LLVM))
    except Exception:  # noqa: BLE001 - any import or initialisation failure means "use Numba"
        return False


def mlos_block(flat, shapes, rows, xs, ys, zs, exponent, *, dtype=np.float64):
    """MLOS of every voxel of the planes ``zs`` (flat z, y, x order): ``(val, seen)``,
    ``val = exp(exponent sum_c log I_c(P_c(x)))`` (0 when a camera does not see the voxel
    or samples 0) as ``dtype`` and ``seen`` (every camera sees the voxel's projected centre
    within its image, ``0 <= u <= w``, ``0 <= v <= h``) as bool, as ``_kernels.mlos_pinhole``.

    ``flat``: the images raveled one after another; ``shapes``: their (h, w);
    ``rows``: the packed cameras (``_kernels.camera_row``). ``dtype`` float32 runs the same
    kernel in single precision (the variant measured and not kept, see the module notes;
    ``bench/bench_speed.py --sections drjit``)."""
    import drjit as dr
    from drjit.llvm import Bool, Float, Float64, UInt32

    F = {np.dtype(np.float64): Float64, np.dtype(np.float32): Float}[np.dtype(dtype)]

    nz, ny, nx = len(zs), len(ys), len(xs)
    n = nz * ny * nx
    img = F(np.ascontiguousarray(flat, dtype))
    gx, gy, gz = (F(np.ascontiguousarray(a, dtype)) for a in (xs, ys, zs))
    i = dr.arange(UInt32, n)
    x = dr.gather(F, gx, i % nx)
    y = dr.gather(F, gy, (i // nx) % ny)
    z = dr.gather(F, gz, i // (nx * ny))
    lg = dr.zeros(F, n)
    seen = dr.full(Bool, True, n)
    off = 0
    for (h, w), cam in zip(shapes, rows, strict=True):
        # opaque parameters: one compiled kernel serves every camera set of the same count
        c = [dr.opaque(F, float(v)) for v in cam]
        hf, wf = dr.opaque(F, float(h)), dr.opaque(F, float(w))
        hu, wu, base = dr.opaque(UInt32, int(h)), dr.opaque(UInt32, int(w)), dr.opaque(UInt32, int(off))
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
        front = zc > 0.0
        seen &= front & (u >= 0.0) & (u <= wf) & (v >= 0.0) & (v <= hf)
        rr, cc = v - 0.5, u - 0.5
        ok = front & (rr >= 0.0) & (rr <= hf - 1.0) & (cc >= 0.0) & (cc <= wf - 1.0)
        r0 = dr.minimum(UInt32(dr.floor(dr.select(ok, rr, 0.0))), dr.maximum(hu, 2) - 2)
        c0 = dr.minimum(UInt32(dr.floor(dr.select(ok, cc, 0.0))), dr.maximum(wu, 2) - 2)
        fr, fc = rr - F(r0), cc - F(c0)
        r1, c1 = dr.minimum(r0 + 1, hu - 1), dr.minimum(c0 + 1, wu - 1)
        g00 = dr.gather(F, img, base + r0 * wu + c0, ok)
        g01 = dr.gather(F, img, base + r0 * wu + c1, ok)
        g10 = dr.gather(F, img, base + r1 * wu + c0, ok)
        g11 = dr.gather(F, img, base + r1 * wu + c1, ok)
        s = (1.0 - fr) * ((1.0 - fc) * g00 + fc * g01) + fr * ((1.0 - fc) * g10 + fc * g11)
        pos = ok & (s > 0.0)
        lg += dr.select(pos, dr.log(dr.select(pos, s, 1.0)), -math.inf)
        off += h * w
    val = dr.exp(lg * dr.opaque(F, float(exponent)))
    dr.eval(val, seen)
    return val.numpy(), seen.numpy()


def mlos_blocks(imgs, rows, grid, exponent, *, progress=None, desc="mlos: planes"):
    """Yield ``(first plane, val, seen)`` for the blocks of planes of ``grid`` (at most
    :data:`BLOCK_VOXELS` voxels each; :func:`mlos_block` on each), the progress counted in
    planes. ``imgs``: the (h, w) images; ``rows``: their packed cameras."""
    from mitpiv.progress import bar

    flat = np.concatenate([np.asarray(im, np.float64).ravel() for im in imgs])
    shapes = [im.shape for im in imgs]
    step = max(1, BLOCK_VOXELS // (grid.shape[1] * grid.shape[2]))
    with bar(grid.shape[0], desc=desc, progress=progress, unit="plane") as b:
        for k0 in range(0, grid.shape[0], step):
            zs = grid.z_mm[k0:k0 + step]
            val, seen = mlos_block(flat, shapes, rows, grid.x_mm, grid.y_mm, zs, exponent)
            yield k0, val, seen
            b.update(len(zs))
