"""MART iterations against the machine's memory bandwidth (issue 50, item 2).

Measures, in one run: the streaming bandwidth (a compiled parallel triad ``a = b + s c`` over
arrays much larger than the caches, and ``np.copyto`` of a 1 GiB array; best of 3), the bytes
one MART iteration must move (weights, voxel indices, row pointers, voxel values, image
values), MART's bytes per second and its ratio to the bandwidth; then splits an iteration's
time (projection only; update without the power; the library's sweep) and times candidate
kernels with their accuracy (max abs difference of the volume after ``--iterations`` against
the library's sweep, and Q against the truth).

``python bench/bench_mart_bandwidth.py [--scale 0.3] [--iterations 10] [--repeat 3]``
(scale 0.3: 144x96x130 voxels, seconds; 1: 480x320x130, the published size, minutes).
The machine may be shared: compare the ratios taken in the same run.
"""

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from mitpiv import analysis as an  # noqa: E402
from mitpiv import reconstruct as rc  # noqa: E402
from mitpiv._numba import numba  # noqa: E402
from mitpiv.reconstruct._kernels import kernels  # noqa: E402

_T = {}


def _triad_kernel():
    if not _T:
        nb = numba()

        @nb.njit(parallel=True, fastmath=True)
        def triad(a, b, c, s):
            for i in nb.prange(a.shape[0]):
                a[i] = b[i] + s * c[i]

        _T["triad"] = triad
    return _T["triad"]


def best(f, repeat=3):
    ts = []
    for _ in range(repeat):
        t = time.perf_counter()
        f()
        ts.append(time.perf_counter() - t)
    return min(ts)


def stream_bandwidth(n_bytes=2**30, repeat=3):
    """(triad GB/s, copy GB/s), best of ``repeat``: the triad reads b, c and writes a (3 x 8 B
    per element counted; write-allocate traffic not counted, as STREAM does); the copy
    ``np.copyto`` of ``n_bytes`` counts read + write."""
    n = n_bytes // 8 // 2  # three float64 arrays of 0.5 GiB each
    a, b, c = np.empty(n), np.full(n, 1.0), np.full(n, 2.0)
    a[:] = 0.0
    triad = _triad_kernel()
    triad(a, b, c, 3.0)  # compile, touch
    t_triad = best(lambda arrs=(a, b, c): triad(*arrs, 3.0), repeat)
    del a, b, c
    src = np.ones(n_bytes // 8)
    dst = np.zeros_like(src)
    t_copy = best(lambda: np.copyto(dst, src), repeat)
    return 3 * 8 * n / t_triad / 1e9, 2 * src.nbytes / t_copy / 1e9


def mart_bytes(cams, flat, n_active):
    """Bytes one MART iteration must move at least: every camera's weights (float32), voxel
    indices (int32) and row pointers (int64) read once, every voxel value (float32) read and
    written once per camera, every image value (float64) read once."""
    b = 0
    for cw, f in zip(cams, flat, strict=True):
        b += cw.data.nbytes + cw.indices.nbytes + cw.indptr.nbytes + 2 * 4 * n_active + f.nbytes
    return b


def _variants():
    """Experimental sweeps: the same colouring and row order as ``mart_sweep``."""
    nb = numba()
    kernels()
    from mitpiv.reconstruct import _kernels

    mart_log_ratio = _kernels.mart_log_ratio
    mart_row_f32 = _kernels.mart_row_f32

    @nb.njit(parallel=True)
    def project_only(indptr, indices, data, img, w, span, vol, out):
        h = img.shape[0] // w
        for colour in range(span):
            n = (h - colour + span - 1) // span
            for rr in nb.prange(n):
                row = colour + rr * span
                for col in range(w):
                    p = row * w + col
                    acc = 0.0
                    for q in range(indptr[p], indptr[p + 1]):
                        acc += data[q] * vol[indices[q]]
                    out[p] = acc

    @nb.njit(parallel=True)
    def project_cached(indptr, indices, data, img, w, span, vol, out):
        """Timing only: :func:`project_only` with every voxel index masked to the first 4096
        voxels (16 KiB, cache-resident): the projection without the cost of its gathers."""
        h = img.shape[0] // w
        for colour in range(span):
            n = (h - colour + span - 1) // span
            for rr in nb.prange(n):
                row = colour + rr * span
                for col in range(w):
                    p = row * w + col
                    acc = 0.0
                    for q in range(indptr[p], indptr[p + 1]):
                        acc += data[q] * vol[indices[q] & 4095]
                    out[p] = acc

    @nb.njit(parallel=True)
    def linear_update(indptr, indices, data, img, w, span, vol, mu):
        """Timing only: the factor 1 + lr w instead of exp(lr w) (not MART)."""
        h = img.shape[0] // w
        for colour in range(span):
            n = (h - colour + span - 1) // span
            for rr in nb.prange(n):
                row = colour + rr * span
                for col in range(w):
                    p = row * w + col
                    update, r = mart_log_ratio(p, indptr, indices, data, img, vol)
                    if not update:
                        continue
                    lr = np.float32(mu * r)
                    for q in range(indptr[p], indptr[p + 1]):
                        vol[indices[q]] *= np.float32(1.0) + lr * data[q]

    @nb.njit(parallel=True)
    def poly_small(indptr, indices, data, img, w, span, vol, mu, xmax):
        """exp(lr w) by its degree-5 Taylor polynomial in float32 when |lr| <= xmax (then
        |lr w| <= xmax: truncation error xmax^6/720), else by exp."""
        h = img.shape[0] // w
        for colour in range(span):
            n = (h - colour + span - 1) // span
            for rr in nb.prange(n):
                row = colour + rr * span
                for col in range(w):
                    p = row * w + col
                    update, r = mart_log_ratio(p, indptr, indices, data, img, vol)
                    if not update:
                        continue
                    lr = np.float32(mu * r)
                    if lr == 0.0:
                        continue
                    if abs(lr) <= xmax:
                        c1 = np.float32(1.0)
                        c2 = np.float32(0.5)
                        c3 = np.float32(1.0 / 6.0)
                        c4 = np.float32(1.0 / 24.0)
                        c5 = np.float32(1.0 / 120.0)
                        for q in range(indptr[p], indptr[p + 1]):
                            x = lr * data[q]
                            vol[indices[q]] *= c1 + x * (c1 + x * (c2 + x * (c3 + x * (c4 + x * c5))))
                    else:
                        for q in range(indptr[p], indptr[p + 1]):
                            vol[indices[q]] *= math.exp(lr * data[q])

    @nb.njit(parallel=True)
    def poly_buffered(indptr, indices, data, img, w, span, vol, mu, xmax, maxrow):
        """Fused: the projection keeps the gathered voxel values in a row buffer; for
        |lr| <= xmax the factors exp(lr w) come from a degree-7 Taylor polynomial in a
        separate (vectorisable) loop, else from exp; then one scatter vol = buf * factor."""
        h = img.shape[0] // w
        c2 = np.float32(0.5)
        c3 = np.float32(1.0 / 6.0)
        c4 = np.float32(1.0 / 24.0)
        c5 = np.float32(1.0 / 120.0)
        c6 = np.float32(1.0 / 720.0)
        c7 = np.float32(1.0 / 5040.0)
        one = np.float32(1.0)
        for colour in range(span):
            n = (h - colour + span - 1) // span
            for rr in nb.prange(n):
                buf = np.empty(maxrow, np.float32)
                fac = np.empty(maxrow, np.float32)
                row = colour + rr * span
                for col in range(w):
                    p = row * w + col
                    s, e = indptr[p], indptr[p + 1]
                    if s == e:
                        continue
                    if img[p] <= 0.0:
                        for q in range(s, e):
                            vol[indices[q]] = 0.0
                        continue
                    proj = 0.0
                    for q in range(s, e):
                        b = vol[indices[q]]
                        buf[q - s] = b
                        proj += data[q] * b
                    if proj <= 0.0:
                        continue
                    lr = np.float32(mu * math.log(img[p] / proj))
                    if lr == 0.0:
                        continue
                    m = e - s
                    if abs(lr) <= xmax:
                        for q in range(m):
                            x = lr * data[s + q]
                            fac[q] = one + x * (one + x * (c2 + x * (c3 + x * (c4 + x * (c5 + x * (c6 + x * c7))))))
                    else:
                        for q in range(m):
                            fac[q] = math.exp(lr * data[s + q])
                    for q in range(m):
                        vol[indices[s + q]] = buf[q] * fac[q]

    @nb.njit(parallel=True)
    def mart_wave(indptr, indices, data, img, w, span, vol, mu, block, lrmax):
        """Not kept (slower, measured): the library's sweep in a wavefront order that gives the same result bit for bit and
        keeps the voxels in cache. Row ``colour + j span`` (group ``g = j // block``) runs at
        step ``2 colour - g``, the steps in increasing order, a step's rows in parallel. Two
        rows share voxels only when fewer than ``span`` rows apart (same or adjacent ``j``,
        different colours); such pairs keep mart_sweep's order (the lower colour first) and
        never share a step, so every voxel sees the same updates in the same order. A step's
        rows lie in a window of about ``2 span^2 block`` image rows moving down the image, so
        each voxel is fetched from memory about once per camera rather than once per colour
        (mart_sweep's colour passes each run over the whole image)."""
        h = img.shape[0] // w
        groups = ((h + span - 1) // span + block - 1) // block
        for t in range(-(groups - 1), 2 * (span - 1) + 1):
            for q in nb.prange(span * block):
                colour = q // block
                g = 2 * colour - t
                if g < 0:
                    continue
                row = colour + (g * block + q % block) * span
                if row >= h:
                    continue
                for col in range(w):
                    mart_row_f32(row * w + col, indptr, indices, data, img, vol, mu, lrmax)

    @nb.njit
    def lr_histogram(indptr, indices, data, img, w, span, vol, mu, edges, counts):
        """Counts of |mu log ratio| per row (weight entries) below each edge; no update."""
        h = img.shape[0] // w
        for p in range(h * w):
            update, r = mart_log_ratio(p, indptr, indices, data, img, vol)
            if not update:
                continue
            x = abs(mu * r)
            for e in range(edges.shape[0]):
                if x <= edges[e]:
                    counts[e] += indptr[p + 1] - indptr[p]
                    break

    return project_only, project_cached, linear_update, poly_small, poly_buffered, mart_wave, lr_histogram


def voxel_orders(idx, grid, brick):
    """Permutations of the active voxels (flat (z, y, x) grid indices ``idx``): the grid's
    (z, y, x) order, (y, z, x), and bricks of ``brick``^3 voxels (bricks and voxels inside
    them in (z, y, x) order)."""
    nz, ny, nx = grid.shape
    z, rest = np.divmod(idx, ny * nx)
    y, x = np.divmod(rest, nx)
    nbz, nby, nbx = (-(-n // brick) for n in (nz, ny, nx))
    bkey = ((z // brick) * nby + y // brick) * nbx + x // brick
    ikey = ((z % brick) * brick + y % brick) * brick + x % brick
    return {"(z, y, x) (library)": np.arange(len(idx)),
            "(y, z, x)": np.lexsort((x, z, y)),
            f"bricks {brick}^3": np.lexsort((ikey, bkey))}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--scale", type=float, default=0.3)
    ap.add_argument("--iterations", type=int, default=10)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--xmax", type=float, default=0.1)
    ap.add_argument("--orders", action="store_true", help="also time the sweep with the voxels reordered")
    ap.add_argument("--brick", type=int, default=8)
    ap.add_argument("--few", action="store_true", help="only the sweeps before and now, and the time split")
    a = ap.parse_args(argv)
    from bench_speed import mart_case

    triad_gbs, copy_gbs = stream_bandwidth(repeat=a.repeat)
    print(f"streaming bandwidth (best of {a.repeat}): triad {triad_gbs:.1f} GB/s, np.copyto 1 GiB {copy_gbs:.1f} GB/s",
          flush=True)
    cams, pts, imgs, grid = mart_case(a.scale)
    truth = an.truth_volume(pts, grid)
    small = mart_case(0.1)
    rc.mart(small[2], small[0], small[3], iterations=1)
    cache = rc.WeightCache()
    v0, info = rc.mart(imgs, cams, grid, iterations=0, cache=cache, return_info=True)
    idx, cws = cache._idx, cache._cams
    vol0 = v0.ravel()[idx].astype(np.float32)
    flat = [np.ascontiguousarray(np.asarray(im, np.float64).ravel()) for im in imgs]
    nnz = sum(len(c.data) for c in cws)
    nbytes = mart_bytes(cws, flat, len(idx))
    print(f"grid {grid.shape[2]}x{grid.shape[1]}x{grid.shape[0]}, {len(idx) / 1e6:.2f} M active voxels, "
          f"{nnz / 1e6:.1f} M weight entries, {nbytes / 1e9:.2f} GB per iteration", flush=True)
    k = kernels()
    project_only, project_cached, linear_update, poly_small, poly_buffered, mart_wave, lr_hist = _variants()
    maxrow = int(max(np.diff(c.indptr).max() for c in cws))
    mu = 1.0

    def sweep(fn, *extra):
        def run(vol):
            for cw, f in zip(cws, flat, strict=True):
                fn(cw.indptr, cw.indices, cw.data, f, cw.width, cw.span, vol, *extra)
        return run

    outs = [np.empty(f.size) for f in flat]

    def proj_run(vol):
        for cw, f, o in zip(cws, flat, outs, strict=True):
            project_only(cw.indptr, cw.indices, cw.data, f, cw.width, cw.span, vol, o)

    def library(vol):
        for cw, f in zip(cws, flat, strict=True):
            k["mart_camera_f32"](cw.indptr, cw.indices, cw.data, f, cw.width, cw.span, vol, mu, cw.wmax)

    def wave(vol):  # the library sweep's rows (its Taylor bound per camera) in wavefront order
        for cw, f in zip(cws, flat, strict=True):
            mart_wave(cw.indptr, cw.indices, cw.data, f, cw.width, cw.span, vol, mu, 4,
                      np.float32(0.4 / cw.wmax if cw.wmax > 0 else 0.0))

    def cached_run(vol):
        for cw, f, o in zip(cws, flat, outs, strict=True):
            project_cached(cw.indptr, cw.indices, cw.data, f, cw.width, cw.span, vol, o)

    # the library's float32 sweep: wmax inf keeps exp for every entry (the sweep before issue 50),
    # wmax 1 takes the Taylor-7 factor for |lr| <= 0.4
    cases = {"exp factor (the sweep before issue 50)": sweep(k["mart_camera_f32"], mu, math.inf),
             "library sweep (mart_camera_f32, Taylor factor)": library,
             "float64 factor (mart_camera)": sweep(k["mart_camera"], mu),
             "projection only": proj_run,
             "projection, gathers from 16 KiB (timing only)": cached_run,
             "update 1 + lr w (timing only)": sweep(linear_update, mu),
             f"Taylor-5 factor for |lr| <= {a.xmax:g}": sweep(poly_small, mu, np.float32(a.xmax)),
             "Taylor-7 factor for |lr| <= 0.4": sweep(k["mart_camera_f32"], mu, 1.0),
             "fused buffer, Taylor-7 pass for |lr| <= 0.4": sweep(poly_buffered, mu, np.float32(0.4), maxrow),
             "wavefront order (mart_wave, block 4)": wave}
    if a.few:
        keep = ("exp factor", "library", "projection", "update 1")
        cases = {n: f for n, f in cases.items() if n.startswith(keep)}
    # one iteration's time: best of `repeat` after `iterations` (converged rows, as late sweeps)
    ref = vol0.copy()
    for _ in range(a.iterations):
        cases["exp factor (the sweep before issue 50)"](ref)
    edges = np.array([1e-3, 1e-2, 0.1, 1.0, np.inf])
    for label, state in (("start", vol0), (f"after {a.iterations} it", ref)):
        counts = np.zeros(len(edges), np.int64)
        for cw, f in zip(cws, flat, strict=True):
            lr_hist(cw.indptr, cw.indices, cw.data, f, cw.width, cw.span, state.copy(), mu, edges, counts)
        print(f"|mu log ratio| of the entries' rows ({label}): " + ", ".join(
            f"<= {e:g}: {c / max(counts.sum(), 1):.1%}" for e, c in zip(edges, counts, strict=True)), flush=True)
    t_first, t_late = {n: math.inf for n in cases}, {n: math.inf for n in cases}
    cpu_late = {n: math.inf for n in cases}
    for _ in range(a.repeat):  # rounds over all sweeps: load changes hit every sweep alike
        for name, fn in cases.items():
            for tab, state in ((t_first, vol0), (t_late, ref)):
                v = state.copy()
                t, c = time.perf_counter(), time.process_time()
                fn(v)
                tab[name] = min(tab[name], time.perf_counter() - t)
                if tab is t_late:
                    cpu_late[name] = min(cpu_late[name], time.process_time() - c)
    base_t = None
    print(f"\n| sweep | s per iteration (at it 1 / after {a.iterations}) | CPU s (after) | speed-up | ns per entry | GB/s | of triad | "
          f"max abs diff after {a.iterations} it (of max) | Q |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, fn in cases.items():
        if base_t is None:
            base_t = t_late[name]
        vol = vol0.copy()
        for _ in range(a.iterations):
            fn(vol)
        if name.startswith("projection") or "timing only" in name:
            acc = "-"
        else:
            out = np.zeros(grid.n_voxels, np.float32)
            out[idx] = vol
            diff = float(np.max(np.abs(vol.astype(np.float64) - ref)) / max(float(ref.max()), 1e-30))
            acc = f"{diff:.1e} | {an.quality_q(out.reshape(grid.shape), truth):.4f}"
        tl = t_late[name]
        print(f"| {name} | {t_first[name]:.3f} / {tl:.3f} | {cpu_late[name]:.3f} | {base_t / tl:.2f}x | {tl / nnz * 1e9:.2f} | {nbytes / tl / 1e9:.2f} | "
              f"{nbytes / tl / 1e9 / triad_gbs:.2f} | {acc} |", flush=True)
    print(f"\nratio to the sweep before issue 50: time / {base_t:.3f} s; bandwidth floor {nbytes / triad_gbs / 1e9:.3f} s "
          f"per iteration ({base_t / (nbytes / triad_gbs / 1e9):.1f}x of it)")
    if a.orders:
        from mitpiv.reconstruct.tomo import _build_weights_pinhole, _pinhole_rows

        rows = _pinhole_rows([rc.PinholeMapping(c) for c in cams])
        print("\n| voxel order | s per iteration (late) | projection only | ratio to (z, y, x) | max abs diff "
              f"after {a.iterations} it (of max) |")
        print("|---|---|---|---|---|")
        t_ref = None
        for name, perm in voxel_orders(idx, grid, a.brick).items():
            pcw = [_build_weights_pinhole(rows[c], idx[perm], grid, "circle", 0.5, imgs[c].shape) for c in range(len(cams))]
            pv0 = vol0[perm].copy()
            def run(vol, pcw=pcw):
                for cw, f in zip(pcw, flat, strict=True):
                    k["mart_camera_f32"](cw.indptr, cw.indices, cw.data, f, cw.width, cw.span, vol, mu)

            late = pv0.copy()
            for _ in range(a.iterations):
                run(late)
            t = best(lambda late=late, run=run: run(late.copy()), a.repeat)
            tp = best(lambda late=late, pcw=pcw: [project_only(cw.indptr, cw.indices, cw.data, f, cw.width, cw.span, late, o)
                                                    for cw, f, o in zip(pcw, flat, outs, strict=True)], a.repeat)
            t_ref = t_ref or t
            back = np.empty_like(late)
            back[perm] = late
            diff = float(np.max(np.abs(back.astype(np.float64) - ref)) / max(float(ref.max()), 1e-30))
            print(f"| {name} | {t:.3f} | {tp:.3f} | {t_ref / t:.2f}x | {diff:.1e} |", flush=True)
            del pcw


if __name__ == "__main__":
    main()
