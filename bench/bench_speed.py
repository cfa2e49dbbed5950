"""Issue 26 benchmark: ours beside a baseline, in the same run, for every row of the
performance table, and writes docs/benchmarks.md (machine, commit, load average).

Rows (each: our time, the baseline's, the ratio, the accuracy difference):

* MART, 4 cameras, 0.05 ppp, 40 iterations, on a 480x320x130-voxel grid scaled by
  ``--scale`` per lateral axis (1 = the published size): ours vs the frozen pre-issue code
  path (bench/reference_mart.py) vs a plain scipy.sparse MART on the same weights (matrix
  built once; row-action updates in blocks of pixels that share no voxel, which is exact).
  Also MART's iterations against the machine's streaming bandwidth measured in the same
  run (a compiled parallel triad and ``np.copyto`` of 1 GiB, best of 3): the bytes an
  iteration must move, its bytes per second and their ratio to the triad's.
* The MLOS pass of MART's pinhole fast path: the Dr.Jit kernel (LLVM backend, float64,
  what the library runs) vs the Numba kernel per plane (its fallback), and the same kernel
  in float32, measured and not kept.
* 3D multi-pass PIV (64-48-32, 75 % overlap, Lamb-Oseen vortex) on a volume of
  ``--piv-shape`` voxels: ours vs the frozen pre-issue piv3d (bench/reference_piv3d.py);
  OpenPIV's 3D single pass at 32^3 windows beside them (time and RMS error).
* Normalised cross-correlation (the channel-tomo paper's eq. 3) of window stacks in search
  regions, the first pass (36^3 windows, 18-voxel margin) and a later one (24^3, 6): ours
  (float32 FFTs of the fluctuations, compiled running box sums) vs the frozen float64 /
  summed-volume-table code (bench/reference_ncc.py); largest coefficient difference.
* The tracker's shake (IPR and STB) at 0.05 ppp, 4 cameras: ours (compiled sequential
  Gauss-Seidel pass) vs the frozen coloured-group NumPy shake (bench/reference_shake.py);
  RMS projected error against the truth of both.
* Focal stack of a plenoptic raw image (additive): ours vs shift-and-add over the
  sub-aperture views with scipy.ndimage.shift (bilinear).
* 1000-plane focal stack of a 6600x4400 raw image: ours and the pre-issue plane kernel on
  a crop, planes timed on a subset, extrapolated.
* Scaling: MART (10 iterations) and PIV time at four sizes, fitted exponent; MART memory
  per voxel.

The machine is shared: absolute times are noisy; the ratios are taken in the same run.
``python bench/bench_speed.py [--quick | --scale S] [--sections ...]``: a run of every section
rewrites its block of docs/benchmarks.md (``speed-quick``, ``speed-full`` at scale 1) and
the README's performance table; a run of some sections only prints.
"""

import argparse
import datetime
import math
import os
import platform
import re
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import docblocks  # noqa: E402
from bench_mart_bandwidth import stream_bandwidth  # noqa: E402
from bench_reconstruct import setup  # noqa: E402
from reference_mart import mart_reference  # noqa: E402

from mitpiv import analysis as an  # noqa: E402
from mitpiv import reconstruct as rc  # noqa: E402

ROWS = []
SCALING = []
SECTIONS = "mart,drjit,piv,ncc,shake,focal,big,scaling"


def timed(f, *a, **k):
    t = time.perf_counter()
    c = time.process_time()
    r = f(*a, **k)
    return r, time.perf_counter() - t, time.process_time() - c


def seconds(t):
    return f"{t:.2f} s" if t >= 0.1 else f"{t * 1e3:.2f} ms"


def emit(stage, ours, base_name, base, accuracy, note=""):
    ratio = base / ours if ours > 0 else float("nan")
    shown = f"{ratio:.1f}x" if not ratio < 0.1 else f"{ratio:.2g}x"  # e.g. MART against the bandwidth floor
    line = f"| {stage} | {seconds(ours)} | {base_name} | {seconds(base)} | {shown} | {accuracy} | {note} |"
    print(line, flush=True)
    ROWS.append(line)


# ------------------------------------------------------------------------------ MART
def mart_case(scale, ppp=0.05, seed=0):
    half = (24.0 * scale, 16.0 * scale, 6.5)
    res = (max(32, int(640 * scale)), max(32, int(480 * scale)))
    cams, pts, imgs = setup(res, half, ppp, seed=seed, dist=1000.0)
    grid = rc.VoxelGrid.from_bounds(-np.asarray(half), half, 0.1)
    return cams, pts, imgs, grid


def scipy_mart(cams, imgs, grid, iterations, mu=1.0):
    """Plain scipy.sparse MART on the same weights and voxels as ours: pixels of one image
    column in image rows ``span`` apart share no voxel, so each such block is one exact
    simultaneous row-action update: p = A v (scipy.sparse), v_j *= (I_i / p_i)^(mu w_ij)
    for the one row i of the block that sees voxel j (zero pixels zero their voxels)."""
    from scipy.sparse import csr_matrix

    cache = rc.WeightCache()
    v0, info = rc.mart(imgs, cams, grid, iterations=0, cache=cache, return_info=True)
    idx, cws = cache._idx, cache._cams
    vol = v0.ravel()[idx].astype(np.float64)
    t = time.perf_counter()
    blocks = []
    for cw, im in zip(cws, imgs, strict=True):
        h, w = im.shape
        a = csr_matrix((cw.data, cw.indices, cw.indptr), shape=(h * w, len(idx)))
        f = im.ravel()
        for colour in range(cw.span):
            for col in range(w):
                rows = np.arange(colour, h, cw.span) * w + col
                sub = a[rows]
                if sub.nnz:
                    rep = np.repeat(np.arange(len(rows)), np.diff(sub.indptr))
                    blocks.append((sub, rep, f[rows]))
    t_build = time.perf_counter() - t
    t = time.perf_counter()
    for _ in range(iterations):
        for sub, rep, f in blocks:
            p = sub @ vol
            ok = (p > 0) & (f > 0)
            lr = np.zeros(len(f))
            lr[ok] = mu * np.log(f[ok] / p[ok])
            fac = np.exp(lr[rep] * sub.data)
            fac[(f <= 0)[rep]] = 0.0
            vol[sub.indices] *= fac
    t_iter = time.perf_counter() - t
    out = np.zeros(grid.n_voxels, np.float32)
    out[idx] = vol
    return out.reshape(grid.shape), info["setup_s"] + t_build, t_iter


def iteration_bytes(info, imgs):
    """Bytes one MART iteration must move at least (:func:`bench_mart_bandwidth.mart_bytes`
    from ``mart``'s info): the weights, voxel indices and row pointers of every camera read
    once, the active voxels' float32 values read and written once per camera, the float64
    images read once."""
    return info["weight_bytes"] + 2 * 4 * info["active_voxels"] * len(imgs) + sum(8 * np.asarray(im).size for im in imgs)


def mart_rows(scale, iterations):
    cams, pts, imgs, grid = mart_case(scale)
    truth = an.truth_volume(pts, grid)
    triad_gbs, copy_gbs = stream_bandwidth()  # the machine's streaming bandwidth, same run
    small = mart_case(0.1)
    rc.mart(small[2], small[0], small[3], iterations=1)  # compile outside the timings
    mart_reference(small[2], small[0], small[3], iterations=1)
    label = f"MART {grid.shape[2]}x{grid.shape[1]}x{grid.shape[0]}, 4 cameras, {iterations} it"
    (v1, info), t1, c1 = timed(rc.mart, imgs, cams, grid, iterations=iterations, return_info=True, residuals="final")
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
    (v0, info0), t0, c0 = timed(mart_reference, imgs, cams, grid, iterations=iterations, return_info=True)
    q1, q0 = an.quality_q(v1, truth), an.quality_q(v0, truth)
    diff = float(np.max(np.abs(v1.astype(np.float64) - v0)) / max(float(v0.max()), 1e-30))
    emit(label, t1, "pre-issue code path", t0, f"Q {q1:.4f} vs {q0:.4f}; max abs diff {diff:.1e} of max",
         f"CPU {c1:.0f} s vs {c0:.0f} s; setup {info['setup_s']:.1f} s vs {info0['setup_s']:.1f} s; "
         f"{info['active_voxels'] / 1e6:.2f} M active voxels, weights {info['weight_bytes'] / 2**20:.0f} MiB, "
         f"MART memory {info['memory_bytes'] / 2**20:.0f} MiB = {info['memory_bytes'] / grid.n_voxels:.1f} B per grid "
         f"voxel ({info['memory_bytes'] / max(info['active_voxels'], 1):.0f} B per active voxel); peak RSS {rss:.2f} GiB")
    # MART's iterations against the streaming bandwidth: the bytes they must move at least
    moved = iteration_bytes(info, imgs)
    floor_s = iterations * moved / (triad_gbs * 1e9)
    emit(label + ", iterations vs bandwidth", info["iterate_s"], "bandwidth floor (bytes moved / triad)", floor_s,
         f"{iterations * moved / info['iterate_s'] / 1e9:.2f} GB/s = {iterations * moved / info['iterate_s'] / 1e9 / triad_gbs:.3f} "
         f"of the triad's {triad_gbs:.1f} GB/s",
         f"{moved / 1e9:.2f} GB per iteration (weights, voxel indices and row pointers read once, voxel values read and "
         f"written once per camera, images read once); {info['iterate_s'] / iterations / info['weight_entries'] * 1e9:.2f} "
         f"ns per weight-entry update; np.copyto of 1 GiB {copy_gbs:.1f} GB/s; best of 3, "
         f"bench/bench_mart_bandwidth.py splits the time")
    # the image floor (floor_rel): the camera's dynamic range lets MLOS prune the analytic tails
    for floor in (1e-4, 1e-3):
        (vf, inf_f), tf, cf = timed(rc.mart, imgs, cams, grid, iterations=iterations, floor_rel=floor,
                                    return_info=True, residuals="final")
        emit(label + f", floor_rel {floor:g}", tf, "ours without a floor", t1,
             f"Q {an.quality_q(vf, truth):.4f} vs {q1:.4f}",
             f"{inf_f['active_voxels'] / 1e6:.2f} M active voxels vs {info['active_voxels'] / 1e6:.2f} M; setup "
             f"{inf_f['setup_s']:.1f} s, iterations {inf_f['iterate_s']:.1f} s")
    (v2, setup_s, iter_s), t2, c2 = timed(scipy_mart, cams, imgs, grid, iterations)
    diff2 = float(np.max(np.abs(v1.astype(np.float64) - v2)) / max(float(v2.max()), 1e-30))
    emit(label, t1, "scipy.sparse MART, same weights", t2, f"Q {q1:.4f} vs {an.quality_q(v2, truth):.4f}; "
         f"max abs diff {diff2:.1e} of max", f"its iterations {iter_s:.1f} s vs ours {info['iterate_s']:.1f} s")


# ------------------------------------------------------------------------------ Dr.Jit
def drjit_rows(scale):
    """The MLOS pass of the pinhole fast path: the Dr.Jit kernel (LLVM backend, float64,
    what the library runs) against the Numba kernel per plane (the fallback) on the MART
    case's images and grid, and the float32 Dr.Jit variant that was not kept."""
    import drjit as dr

    from mitpiv.reconstruct import _drjit, tomo

    def mlos32(imgs, rows, grid):
        flat = np.concatenate([np.asarray(im, np.float32).ravel() for im in imgs])
        return _drjit.mlos_block(flat, [im.shape for im in imgs], rows, grid.x_mm, grid.y_mm, grid.z_mm,
                                 1.0 / len(imgs), dtype=np.float32)[0]

    if not _drjit.available():
        print("drjit: Dr.Jit's LLVM backend is not available; rows skipped")
        return
    cams, pts, imgs, grid = mart_case(scale)
    imgs, maps = tomo._check_images(imgs, cams, grid, "mlos")
    rows = tomo._pinhole_rows(maps)
    small = mart_case(0.1)
    si, sm = tomo._check_images(small[2], small[0], small[3], "mlos")
    for eng in ("drjit", "numba"):  # compile / load both kernels outside the timings
        tomo._candidates_pinhole(si, tomo._pinhole_rows(sm), small[3], True, False, "b", engine=eng)
    mlos32(si, tomo._pinhole_rows(sm), small[3])

    def best(f):
        ts = []
        for _ in range(3):
            r, t, _ = timed(f)
            ts.append(t)
        return r, min(ts)

    (i1, v1), t1 = best(lambda: tomo._candidates_pinhole(imgs, rows, grid, True, False, "b", engine="drjit"))
    (i0, v0), t0 = best(lambda: tomo._candidates_pinhole(imgs, rows, grid, True, False, "b", engine="numba"))
    same = np.array_equal(i1, i0)
    d = float(np.max(np.abs(v1 - v0)) / v0.max()) if same else float("nan")
    label = f"MLOS pass {grid.shape[2]}x{grid.shape[1]}x{grid.shape[0]}, 4 cameras"
    backend = f"Dr.Jit {dr.__version__} LLVM backend (CPU, {dr.thread_count()} threads), float64"
    emit(label, t1, "Numba kernel per plane (float64)", t0,
         f"same {len(i1)} candidates: {same}; max abs diff {d:.1e} of max", f"ours: {backend}; best of 3")
    full = np.zeros(grid.n_voxels)
    full[i1] = v1
    v32, t32 = best(lambda: mlos32(imgs, rows, grid))
    flips = int(np.count_nonzero((v32 > 0) != (full > 0)))
    emit(label + ", Dr.Jit float32 (not kept)", t32, "ours (Dr.Jit float64)", t1,
         f"max abs diff {float(np.max(np.abs(v32 - full)) / full.max()):.1e} of max; {flips} voxels change candidate status",
         "best of 3")


# ------------------------------------------------------------------------------ PIV
def piv_rows(shape):
    from bench_analysis import openpiv_row, volumes
    from reference_piv3d import piv3d as piv3d_reference

    grid, a, b, flow, dt, _ = volumes(shape)
    kw = dict(windows=(64, 48, 32), overlap=0.75, dt_s=dt)
    an.piv3d(a[:40, :80, :80], b[:40, :80, :80], rc.VoxelGrid((0, 0, 0), (0.05,) * 3, (40, 80, 80)),
             windows=(32, 24, 16), overlap=0.5, dt_s=dt)  # compile
    f1, t1, c1 = timed(an.piv3d, a, b, grid, **kw)
    f0, t0, c0 = timed(piv3d_reference, a, b, grid, **kw)
    e1 = an.velocity_error(f1, flow)["rms_vox"]
    e0 = an.velocity_error(f0, flow)["rms_vox"]
    d = float(np.max(np.abs(f1.displacement_vox() - f0.displacement_vox())))
    label = f"3D PIV 64-48-32, {shape[2]}x{shape[1]}x{shape[0]} voxels, {f1.n_vectors} vectors"
    emit(label, t1, "pre-issue piv3d", t0, f"RMS {', '.join(f'{x:.4f}' for x in e1)} vs "
         f"{', '.join(f'{x:.4f}' for x in e0)} vox; max abs diff {d:.1e} vox", f"CPU {c1:.0f} s vs {c0:.0f} s")
    try:
        t_op, n_op, rms_op = openpiv_row(grid, a, b, flow, dt, window=32, overlap=24)
        emit(label, t1, f"OpenPIV 3D single pass 32^3 ({n_op} vectors)", t_op,
             f"RMS error magnitude ours {math.sqrt(sum(x * x for x in e1)):.4f} vs OpenPIV {rms_op:.4f} vox",
             f"per vector: ours {1e6 * t1 / f1.n_vectors:.0f} us, OpenPIV {1e6 * t_op / max(n_op, 1):.0f} us")
    except ImportError as exc:
        print(f"OpenPIV not available: {exc}")


def ncc_rows(quick):
    from reference_ncc import normalised_cross_correlation as ncc_reference

    from mitpiv.analysis.piv3d import normalised_cross_correlation as ncc

    rng = np.random.default_rng(0)
    ncc(*(rng.random((1, 4, 4, 4 + k), dtype=np.float32) for k in (0, 4)))  # compile
    for w, m, n in ((36, 18, 20 if quick else 60), (24, 6, 100 if quick else 300)):
        # particle-like stacks on a background: sparse bright voxels plus a haze
        a = (rng.random((n, w, w, w), dtype=np.float32) ** 40 + 0.1).astype(np.float32)
        b = (rng.random((n, w + 2 * m, w + 2 * m, w + 2 * m), dtype=np.float32) ** 40 + 0.1).astype(np.float32)
        g1, t1, c1 = timed(ncc, a, b)
        g0, t0, c0 = timed(ncc_reference, a, b)
        emit(f"NCC {n} windows {w}^3, margin {m}", t1, "float64 FFT + summed-volume tables", t0,
             f"max gamma diff {float(np.max(np.abs(g1 - g0))):.1e}",
             f"per vector {1e3 * t1 / n:.1f} ms vs {1e3 * t0 / n:.1f} ms")


# ------------------------------------------------------------------------------ tracking
def _tracking_rig(res):
    from mitpiv.physics.camera import PinholeCamera, place_camera

    cams = []
    for az, el in [(20, 25), (-20, 25), (20, -25), (-20, -25)]:
        rot, pos = place_camera(azimuth_deg=az + 90, elevation_deg=el, distance_mm=400.0)
        cams.append(PinholeCamera(resolution=res, focal_length_mm=50.0, pixel_pitch_um=10.0, rotation=rot,
                                  position_mm=pos))
    return cams


def shake_rows(quick):
    """The shake of IPR / STB (issue 27's tracker) at 0.05 ppp: ours (compiled sequential
    pass) vs the frozen coloured-group shake (bench/reference_shake.py), both from the same
    start about 0.2 px (RMS, projected) off the truth; accuracy: RMS projected distance to the truth after."""
    from reference_shake import shake as shake_reference

    from mitpiv.tracking import OTF, project_particles, shake

    res = (256, 256) if quick else (512, 512)
    lo, hi = np.array([-7.0, -7.0, -3.5]), np.array([7.0, 7.0, 3.5])
    if not quick:
        lo, hi = 2 * lo, 2 * hi
    cams = _tracking_rig(res)
    otf = OTF.uniform(4, sigma_px=1.0, lower_mm=lo, upper_mm=hi)
    rng = np.random.default_rng(0)
    n = int(0.05 * res[0] * res[1])
    true = rng.uniform(lo, hi, (n, 3))
    imgs = project_particles(true, 1.0, cams, otf)
    scale = 0.07  # mm per px at the box centre of this rig
    start = true + rng.normal(0.0, 0.3 * scale / math.sqrt(3), (n, 3))
    shake(imgs, cams, otf, start[:10], 1.0, step_mm=0.2 * scale, iterations=1)  # compile

    def err(p):
        return float(np.sqrt(np.mean([np.sum((c.project(p) - c.project(true)) ** 2, axis=1) for c in cams])))

    (p1, _, _), t1, _ = timed(shake, imgs, cams, otf, start, 1.0, step_mm=0.5 * scale, iterations=6)
    (p0, _, _), t0, _ = timed(shake_reference, imgs, cams, otf, start, 1.0, step_mm=0.5 * scale, iterations=6)
    emit(f"shake {n} particles (0.05 ppp), 4 cameras {res[0]}x{res[1]}, 6 iterations", t1,
         "coloured groups, vectorised NumPy (pre-issue)", t0,
         f"RMS error {err(p1):.4f} px vs {err(p0):.4f} px (start {err(start):.3f} px)")


# ------------------------------------------------------------------------------ focal stacks
def focal_rows(n_px, planes):
    from bench_lightfield import baseline_plane, synthetic_lf
    from reference_refocus import focal_stack as focal_stack_reference

    from mitpiv import lightfield as lfm
    from mitpiv.physics.plenoptic import PlenopticCamera

    cam = PlenopticCamera(resolution=(n_px, n_px), pixel_pitch_um=5.5, focal_length_mm=50, f_number=2.8,
                          focus_distance_mm=250, mla_pitch_um=5.5 * 14, mla_layout="hex")
    lf = synthetic_lf(cam)
    z = np.linspace(-20, 20, planes)
    lfm.focal_stack(lf, z[:2])
    focal_stack_reference(lf, z[:2])
    st, t1, _ = timed(lfm.focal_stack, lf, z)
    st0, t0, _ = timed(focal_stack_reference, lf, z)
    alphas = lfm.alpha_from_z(z[:3], focal_length_mm=50, magnification=cam.magnification)
    base, tb, _ = timed(lambda: [baseline_plane(lf, a) for a in alphas])
    o = lf.optics
    shift = np.abs(1 - 1 / alphas).max() * o.image_distance_mm / o.gap_mm * o.image_scale * np.abs(lf.du_px).max()
    mg = int(np.ceil(shift / (lf.t_px[1] - lf.t_px[0]))) + 2
    inner = (slice(mg, -mg), slice(mg, -mg))
    err = max(np.abs(st[k][inner] - base[k][inner]).max() / np.abs(base[k][inner]).max() for k in range(3))
    per, per0, perb = t1 / planes, t0 / planes, tb / 3
    label = f"focal stack {n_px}x{n_px} raw px (PMR 14 hex, {lf.shape}), per plane"
    emit(label, per, "shift-and-add, scipy.ndimage.shift per view", perb, f"max abs diff {err:.1e} relative (inner)",
         f"pre-issue kernel {per0 * 1e3:.1f} ms/plane ({per0 / per:.1f}x ours)")
    d0 = float(np.max(np.abs(st - st0)) / np.abs(st0).max())
    return per, per0, d0


def big_stack_row(crop_px, planes_timed):
    """1000 planes of a 6600x4400 raw image, from a crop: time per plane per raw pixel."""
    from bench_lightfield import synthetic_lf
    from reference_refocus import focal_stack as focal_stack_reference

    from mitpiv import lightfield as lfm
    from mitpiv.physics.plenoptic import PlenopticCamera

    cam = PlenopticCamera(resolution=(crop_px, crop_px), pixel_pitch_um=5.5, focal_length_mm=50, f_number=2.8,
                          focus_distance_mm=250, mla_pitch_um=77.0, mla_layout="hex")
    lf = synthetic_lf(cam)
    z = np.linspace(-30, 30, 1000)[:: max(1, 1000 // planes_timed)][:planes_timed]
    lfm.focal_stack(lf, z[:1])
    focal_stack_reference(lf, z[:1])
    _, t1, _ = timed(lfm.focal_stack, lf, z)
    _, t0, _ = timed(focal_stack_reference, lf, z)
    k = 1000 / len(z) * (6600 * 4400) / crop_px**2
    emit(f"1000-plane focal stack 6600x4400 (from a {crop_px}^2 crop, {len(z)} planes)", t1 * k,
         "pre-issue plane kernel, same extrapolation", t0 * k, "same kernel output (see focal-stack row)",
         f"extrapolated x{k:.0f}; paper: about 10 h per image per core")


# ------------------------------------------------------------------------------ scaling
def scaling(quick):
    print("\n### Scaling\n")
    small = mart_case(0.1)
    rc.mart(small[2], small[0], small[3], iterations=1)  # compile / load the kernels outside the timings
    sizes, times = [], []
    for s in ((0.15, 0.2, 0.3, 0.4) if quick else (0.25, 0.35, 0.5, 0.7)):
        cams, pts, imgs, grid = mart_case(s)
        (v, info), t, _ = timed(rc.mart, imgs, cams, grid, iterations=10, return_info=True, residuals="final")
        sizes.append(grid.n_voxels)
        times.append(t)
        line = (f"MART 10 it: {grid.n_voxels / 1e6:.2f} M voxels, {info['active_voxels'] / 1e6:.2f} M active: {t:.1f} s, "
                f"memory {info['memory_bytes'] / grid.n_voxels:.1f} B/voxel")
        print(line, flush=True)
        SCALING.append(line)
    p = np.polyfit(np.log(sizes), np.log(times), 1)[0]
    SCALING.append(f"MART time ~ voxels^{p:.2f}")
    print(f"MART time ~ voxels^{p:.2f}")
    from bench_analysis import volumes

    grid, a, b, _, dt, _ = volumes((40, 80, 80))
    an.piv3d(a, b, grid, windows=(32, 24, 16), overlap=0.5, dt_s=dt)  # compile / load the kernels outside the timings
    sizes, times = [], []
    for shape in (((48, 96, 96), (48, 128, 128), (64, 160, 160), (64, 192, 192)) if quick else
                  ((64, 128, 128), (64, 192, 192), (80, 256, 256), (80, 320, 320))):
        grid, a, b, flow, dt, _ = volumes(shape)
        f, t, _ = timed(an.piv3d, a, b, grid, windows=(32, 24, 16) if quick else (64, 48, 32), overlap=0.75, dt_s=dt)
        sizes.append(f.n_vectors)
        times.append(t)
        line = f"PIV: {f.n_vectors} vectors ({'x'.join(map(str, shape[::-1]))}): {t:.1f} s"
        print(line, flush=True)
        SCALING.append(line)
    p = np.polyfit(np.log(sizes), np.log(times), 1)[0]
    SCALING.append(f"PIV time ~ vectors^{p:.2f}")
    print(f"PIV time ~ vectors^{p:.2f}")


def head_commit():
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                              text=True).stdout.strip() or "unknown"
    except OSError:
        return "unknown"


def machine(commit=None):
    """The machine, the commit (give the one read when the run started: a commit made during
    a long run must not relabel it), the time and the load average, as one line."""
    commit = commit or head_commit()
    cpu = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return (f"{platform.node()} ({cpu}, {os.cpu_count()} cores, Python {platform.python_version()}), commit {commit}, "
            f"{datetime.datetime.now(datetime.UTC):%Y-%m-%d %H:%M} UTC, load average at the end "
            f"{', '.join(f'{x:.1f}' for x in os.getloadavg())}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--quick", action="store_true", help="smaller cases (a few minutes)")
    ap.add_argument("--scale", type=float, default=None, help="MART lateral scale (1 = 480x320x130)")
    ap.add_argument("--out", default=str(ROOT / "docs" / "benchmarks.md"))
    ap.add_argument("--sections", default=SECTIONS, help="comma-separated subset to run")
    a = ap.parse_args(argv)
    commit = head_commit()
    scale = a.scale or (0.3 if a.quick else 0.5)
    print("| stage | ours | baseline | baseline time | ratio | accuracy | notes |")
    print("|---|---|---|---|---|---|---|")
    sections = set(a.sections.split(","))
    unknown = sections - set(SECTIONS.split(","))
    if unknown:
        ap.error(f"--sections {a.sections}: unknown {', '.join(sorted(unknown))}; choose from {SECTIONS}")
    if "mart" in sections:
        mart_rows(scale, 10 if a.quick else 40)
    if "drjit" in sections:
        drjit_rows(scale)
    if "piv" in sections:
        piv_rows((64, 160, 160) if a.quick else (80, 256, 256))
    if "ncc" in sections:
        ncc_rows(a.quick)
    if "shake" in sections:
        shake_rows(a.quick)
    if "focal" in sections:
        focal_rows(800 if a.quick else 1600, 11 if a.quick else 21)
    if "big" in sections:
        big_stack_row(1600 if a.quick else 3300, 16 if a.quick else 32)
    if "scaling" in sections:
        scaling(a.quick)
    if sections != set(SECTIONS.split(",")):
        print(f"\nnot written: --sections {a.sections} is a subset; a run of every section regenerates {a.out}")
        return
    name = "speed-quick" if a.quick else ("speed-full" if scale == 1 else f"speed-scale-{scale:g}")
    cmd = ("python bench/bench_speed.py" + (" --quick" if a.quick else "") + (f" --scale {a.scale:g}" if a.scale else ""))
    body = (f"`{cmd}`" + (" (`make bench`)" if a.quick else "") + f". Machine: {machine(commit)}.\n\n"
            "| stage | ours | baseline | baseline time | ratio | accuracy | notes |\n|---|---|---|---|---|---|---|\n"
            + "\n".join(ROWS) + "\n\nScaling (MART 10 iterations; PIV " + ("32-24-16" if a.quick else "64-48-32")
            + ", 75 % overlap):\n\n" + "\n".join(f"- {x}" for x in SCALING) + "\n")
    docblocks.update_file(a.out, name, body, heading=f"bench_speed.py{' --quick' if a.quick else ''}"
                          + (f" --scale {a.scale:g}" if a.scale else ""))
    print(f"\nwritten: block {name} of {a.out}")
    write_readme_table(Path(a.out))


def readme_rows(doc_text):
    """The README's performance table, regenerated from docs/benchmarks.md: the rows of the
    published-size run (block speed-full) where there is one, else of the quick run, and the
    demo's end-to-end row (block demo)."""
    name = "speed-full" if docblocks.read_block(doc_text, "speed-full") else "speed-quick"
    block = docblocks.read_block(doc_text, name)
    if block is None:
        raise ValueError("docs/benchmarks.md has no speed-full or speed-quick block: run bench/bench_speed.py first")
    prov = re.search(r"commit (\w+), (\d{4}-\d\d-\d\d)", block)
    out = ["| stage | ours | baseline | ratio | accuracy |", "|---|---|---|---|---|"]
    demo = docblocks.read_block(doc_text, "demo")
    for cells in docblocks.table_rows(demo):
        if cells[0].startswith("**end to end"):
            stage, base, ours, ratio, acc = cells[:5]
            out.append(f"| {stage.strip('*')} | {ours} | code of {base} | {ratio} | {acc} |")
    for cells in docblocks.table_rows(block):
        stage, ours, base, base_t, ratio, acc = cells[:6]
        out.append(f"| {stage} | {ours} | {base} {base_t} | {ratio} | {acc} |")
    src = f"block `{name}`" + (f", commit {prov.group(1)}, {prov.group(2)}" if prov else "")
    return "\n".join(out) + f"\n\nRegenerated from [docs/benchmarks.md](docs/benchmarks.md) ({src}).\n"


def write_readme_table(doc_path, readme=ROOT / "README.md"):
    try:
        body = readme_rows(Path(doc_path).read_text())
    except ValueError as e:
        print(f"README table not regenerated: {e}")
        return
    docblocks.update_file(readme, "speed-table", body)
    print(f"written: block speed-table of {readme}")


if __name__ == "__main__":
    main()
