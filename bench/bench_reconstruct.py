"""Reconstruction benchmark: time and quality Q of every method against its accuracy knobs
(iterations, interpolation order, weight model, voxel size, ray bundle size), the Numba
SMART iteration against a SciPy-sparse baseline in the same run, DRT-MART voxel updates per
second, and the 480x320x130-voxel, 4-camera, 40-iteration (S)MART case (time, peak memory).

Images: Gaussian particle images (sigma 0.6 px, pixel-integrated) projected through the
true camera mappings (the reconstruction cost does not depend on how they were made);
the plenoptic rows render with the ``plenoptic`` sensor. Writes a table to stdout and
out/bench/reconstruct_accuracy_time.png.

``python bench/bench_reconstruct.py`` (a few minutes); ``--big`` adds the 480x320x130
case (about 10 minutes on 2 cores).
"""

import argparse
import math
import resource
import sys
import time
from pathlib import Path

import numpy as np
from scipy.special import erf

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mitpiv import analysis as an  # noqa: E402
from mitpiv import reconstruct as rc  # noqa: E402
from mitpiv.physics.camera import PinholeCamera, scatter_arrangement  # noqa: E402
from mitpiv.reconstruct.tomo import _build_weights, _footprints, smart_sweep  # noqa: E402

OUT = ROOT / "out" / "bench"


def blob_images(cams, pts, sigma=0.6):
    """Pixel-integrated Gaussian particle images through each camera's mapping."""
    imgs = []
    off = np.arange(-3, 4)
    for c in cams:
        w, h = c.resolution
        uv = c.project(pts)
        cu = np.floor(uv[:, :1]).astype(int) + off
        cv = np.floor(uv[:, 1:]).astype(int) + off

        def wts(x, ci):
            lo = (ci - x[:, None]) / (math.sqrt(2) * sigma)
            return 0.5 * (erf(lo + 1 / (math.sqrt(2) * sigma)) - erf(lo))

        val = wts(uv[:, 1], cv)[:, :, None] * wts(uv[:, 0], cu)[:, None, :]
        ok = (cu[:, None, :] >= 0) & (cu[:, None, :] < w) & (cv[:, :, None] >= 0) & (cv[:, :, None] < h)
        flat = cv[:, :, None] * w + cu[:, None, :]
        imgs.append(np.bincount(flat[ok], val[ok], minlength=w * h).reshape(h, w))
    return imgs


def setup(res, half, ppp, seed=0, dist=500.0):
    arr = scatter_arrangement("symmetric", n=4, azimuth_deg=25, elevation_deg=55, distance_mm=dist)
    cams = [PinholeCamera(res, 85.0, 10.0, rotation=a["rotation"], position_mm=a["position_mm"]) for a in arr]
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-np.asarray(half), np.asarray(half), (int(ppp * res[0] * res[1]), 3))
    return cams, pts, blob_images(cams, pts)


def timed(f, *a, **k):
    t = time.perf_counter()
    r = f(*a, **k)
    return r, time.perf_counter() - t


def row(name, setting, sec, q, extra=""):
    print(f"| {name:22s} | {setting:26s} | {sec:8.2f} | {q:6.3f} | {extra}")
    return (name, setting, sec, q)


def tomo_rows(ppp):
    half = (5.0, 5.0, 1.5)
    cams, pts, imgs = setup((256, 256), half, ppp)
    grid = rc.VoxelGrid.from_bounds(-np.asarray(half), half, 0.05)
    truth = an.truth_volume(pts, grid)
    rc.mart(imgs, cams, grid, iterations=1)  # compile the kernels outside the timings
    rows = []
    print(f"\n### 4 cameras, 256x256 px, {ppp} ppp, grid {grid.shape[2]}x{grid.shape[1]}x{grid.shape[0]}\n")
    print("| method                 | setting                    | time [s] | Q      |")
    print("|---|---|---|---|")
    for interp in ("linear", "cubic"):
        v, s = timed(rc.mlos, imgs, cams, grid, interpolation=interp)
        rows.append(row("MLOS", interp, s, an.quality_q(v, truth)))
    for smart in (False, True):
        for it in (1, 2, 5, 10, 20):
            (v, info), s = timed(rc.mart, imgs, cams, grid, iterations=it, smart=smart, return_info=True)
            rows.append(row("SMART" if smart else "MART", f"{it} iterations", s, an.quality_q(v, truth),
                            f"setup {info['setup_s']:.2f} s"))
    for model in ("circle", "gaussian"):
        v, s = timed(rc.mart, imgs, cams, grid, iterations=5, weights=model)
        rows.append(row("MART 5 it", f"weights {model}", s, an.quality_q(v, truth)))
    v, s = timed(rc.mart, imgs, cams, grid, iterations=5, init="uniform")
    rows.append(row("MART 5 it", "uniform start (no MLOS)", s, an.quality_q(v, truth)))
    for vox in (0.1, 0.075, 0.05, 0.035):
        g = rc.VoxelGrid.from_bounds(-np.asarray(half), half, vox)
        v, s = timed(rc.mart, imgs, cams, g, iterations=5)
        rows.append(row("MART 5 it", f"voxel {vox} mm ({0.049 / vox:.2f} px)", s, an.quality_q(v, an.truth_volume(pts, g))))
    for m in ("additive", "multiplicative"):
        v, s = timed(rc.sapiv_refocus, imgs, cams, grid, method=m)
        rows.append(row("SAPIV", m, s, an.quality_q(v, truth)))
    return rows, (cams, imgs, grid)


def scipy_baseline(cams, imgs, grid, iterations=5):
    """SMART iteration with scipy.sparse (W @ e, W.T @ log ratio) on the same matrices vs ours."""
    from scipy.sparse import csr_matrix

    ids = np.arange(grid.n_voxels)
    pts = grid.centres(ids)
    mats = []
    for c, im in zip(cams, imgs, strict=True):
        cw = _build_weights(c.project(pts), _footprints(rc.PinholeMapping(c), pts, grid, "circle", 0.5), "circle", im.shape)
        mats.append((cw, csr_matrix((cw.data, cw.indices, cw.indptr), shape=(im.size, len(ids)))))
    flat = [im.ravel() for im in imgs]
    wsum = sum(cw.wsum for cw, _ in mats)
    e1, e2 = np.ones(len(ids)), np.ones(len(ids))
    t = time.perf_counter()
    for _ in range(iterations):
        acc = np.zeros(len(ids))
        for (_, a), f in zip(mats, flat, strict=True):
            p = a @ e1
            with np.errstate(divide="ignore", invalid="ignore"):
                lr = np.where(p > 0, np.log(np.where(f > 0, f, 0) / np.where(p > 0, p, 1)), 0.0)
            acc += a.T @ lr
        with np.errstate(invalid="ignore"):
            e1 = np.where(wsum > 0, e1 * np.exp(np.where(np.isfinite(acc), acc, -np.inf) / np.where(wsum > 0, wsum, 1)), e1)
    t_scipy = time.perf_counter() - t
    t = time.perf_counter()
    work = ([np.empty(f.size) for f in flat], [np.empty(f.size) for f in flat])
    for _ in range(iterations):
        smart_sweep([cw for cw, _ in mats], flat, e2, wsum, 1.0, *work)
    t_ours = time.perf_counter() - t
    diff = float(np.max(np.abs(e1 - e2)) / np.max(e2))
    nnz = sum(len(cw.data) for cw, _ in mats)
    print(f"\nSMART iteration, {nnz / 1e6:.1f} M weights, no pruning: scipy.sparse {t_scipy / iterations:.3f} s, "
          f"Numba {t_ours / iterations:.3f} s -> {t_scipy / t_ours:.1f}x (max rel. difference {diff:.1e})")


def drt_rows():
    import mitsuba as mi

    from mitpiv.lightfield import decode
    from tests.lightfield.helpers import particle_scene, render

    tmp = OUT / "drt_tmp"
    tmp.mkdir(parents=True, exist_ok=True)
    pts = np.random.default_rng(1).uniform([-1.5, -1.5, -3], [1.5, 1.5, 3], (15, 3))
    to_world = mi.ScalarTransform4f().look_at(origin=[0, 0, 250], target=[0, 0, 0], up=[0, 1, 0])
    sc = particle_scene(tmp, pts, {"type": "particle_tracer", "rays_per_particle": 20000}, res=240, to_world=to_world)
    raw = render(sc)
    cam = sc.sensors()[0].camera
    lf = decode(raw, optics=cam)
    rows = []
    print("\n### Plenoptic, 240x240 raw px (PMR 10), 15 particles\n")
    print("| method                 | setting                    | time [s] | Q*     |")
    print("|---|---|---|---|")
    for ratio in ((2, 2, 10), (4, 4, 20)):
        g = rc.VoxelGrid.for_camera((-2, -2, -3.5), (2, 2, 3.5), pixel_size_mm=0.022, ratio=ratio)
        truth = an.truth_volume(pts, g)
        for m in ("additive", "multiplicative"):
            v, s = timed(rc.plenoptic_volume, lf, g, method=m)
            rows.append(row(f"refocus {ratio}", m, s, an.quality_q_zero_mean(v, truth)))
        for rays in (4, 16, 64):
            w, s_w = timed(rc.drt_weights, cam, g, rays_per_pixel=rays)
            (v, info), s = timed(rc.drt_mart, raw, cam, g, iterations=5, matrix=w, return_info=True)
            rows.append(row(f"DRT-MART 5 it {ratio}", f"{rays} rays/px", s_w + s, an.quality_q_zero_mean(v, truth),
                            f"weights {s_w:.1f} s, {w.nnz / 1e6:.1f} M entries ({info['weight_bytes'] / 2**20:.0f} MiB), "
                            f"{info['voxel_updates_per_s'] / 1e6:.1f} M voxel updates/s on {info['active_voxels']} voxels"))
    return rows


def big_case():
    """480 x 320 x 130 voxels, 4 cameras, 40 iterations (Atkinson & Soria's size)."""
    vox = 0.1
    half = (24.0, 16.0, 6.5)
    res = (640, 480)
    cams, pts, imgs = setup(res, half, 0.05, dist=1000.0)
    grid = rc.VoxelGrid.from_bounds(-np.asarray(half), half, vox)
    print(f"\n### Large case: grid {grid.shape[2]}x{grid.shape[1]}x{grid.shape[0]} = {grid.n_voxels / 1e6:.1f} M voxels, "
          f"4 cameras {res[0]}x{res[1]}, {len(pts)} particles (0.05 ppp), 40 iterations\n")
    truth = an.truth_volume(pts, grid)
    for smart in (True, False):
        (v, info), s = timed(rc.mart, imgs, cams, grid, iterations=40, smart=smart, return_info=True, progress=True)
        rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
        print(f"{'SMART' if smart else 'MART'}: {s:.0f} s (setup {info['setup_s']:.0f} s, iterations {info['iterate_s']:.0f} s), "
              f"Q = {an.quality_q(v, truth):.3f}, active voxels {info['active_voxels'] / 1e6:.1f} M, weights "
              f"{info['weight_bytes'] / 2**30:.2f} GiB, peak RSS so far {rss:.2f} GiB", flush=True)


def plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8, 5))
    series = {}
    for name, setting, sec, q in rows:
        key = name if not name.startswith("MART 5") else f"MART 5 it ({setting.split()[0]})"
        series.setdefault(key, []).append((sec, q, setting))
    colours = plt.get_cmap("tab20").colors  # more series than the default cycle's 10 colours
    for i, (key, pts) in enumerate(series.items()):
        pts.sort()
        ax.plot([p[0] for p in pts], [p[1] for p in pts], "os^"[i % 3] + "-", color=colours[(2 * i) % 20 + (i >= 10)],
                label=key)
    ax.set_xscale("log")
    ax.set_xlabel("time [s] (2 cores)")
    ax.set_ylabel("Q (tomographic) / Q* (plenoptic)")
    ax.set_title("Reconstruction: accuracy vs time (tomo: 4 cameras, 0.02 ppp; plenoptic: pixel:voxel ratio)")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    print(f"\nplot: {path}")


def main(argv=None):
    from mitpiv.render.variant import ensure_variant

    ensure_variant()  # Mitsuba objects below (importing mitpiv selects no variant)
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--big", action="store_true", help="also the 480x320x130, 4-camera, 40-iteration case")
    a = ap.parse_args(argv)
    rows, (cams, imgs, grid) = tomo_rows(0.02)
    rows2, _ = tomo_rows(0.05)
    scipy_baseline(cams, imgs, grid)
    drt = drt_rows()
    plot(rows + drt, OUT / "reconstruct_accuracy_time.png")
    if a.big:
        big_case()


if __name__ == "__main__":
    main()
