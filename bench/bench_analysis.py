"""Particles and 3D PIV benchmark: what accuracy costs in time.

1. Multi-pass 3D PIV on a 256x256x128-voxel pair (Lamb-Oseen vortex, up to ~3 voxels of
   displacement, 0.02 particles per voxel): time and RMS velocity error (against the
   window-averaged analytic flow) for window size, passes, deformation/interpolation and
   overlap; OpenPIV's single-pass 3D correlation on the same volumes in the same run, time
   per vector as the ratio.
2. Particle detection time and error against the volume size and localisation method.
3. Backlit plenoptic tracking on a drop-impact realisation (reduced size): detected
   fraction, depth uncertainty in diameters against the theoretical depth resolution,
   size histogram against the truth (out/bench/backlit_drop_impact.png).

Writes tables to stdout and out/bench/piv_accuracy_time.png. ``python bench/bench_analysis.py``
(about 6 minutes on 2 cores); ``--quick`` runs a 128x128x64 PIV pair.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mitpiv import analysis as an  # noqa: E402
from mitpiv.physics.advection import advect  # noqa: E402
from mitpiv.physics.flows import LambOseen  # noqa: E402
from mitpiv.reconstruct import VoxelGrid  # noqa: E402

OUT = ROOT / "out" / "bench"
VOX = 0.05


def volumes(shape, ppv=0.02, seed=0):
    grid = VoxelGrid((0.0, 0.0, 0.0), (VOX,) * 3, shape)
    lo, hi = np.asarray(grid.origin_mm), np.asarray(grid.upper_mm)
    rng = np.random.default_rng(seed)
    n = int(ppv * np.prod(shape))
    p = rng.uniform(lo - 0.3, hi + 0.3, (n, 3))
    c = 0.5 * (lo + hi)
    flow = LambOseen(circulation_mm2_s=6.0 * (hi[0] - lo[0]), core_radius_mm=0.3 * (hi[0] - lo[0]),
                     center=(c[0], c[1], 0.0), axis=(0, 0, 1))
    dt = 0.04
    q = advect(p, flow, dt_s=dt)
    return grid, an.truth_volume(p, grid, sigma_voxels=1.0), an.truth_volume(q, grid, sigma_voxels=1.0), flow, dt, p


def piv_table(grid, a, b, flow, dt):
    cases = [
        ("1 pass 32, shift", dict(windows=32, deform=False)),
        ("2 passes 64-32, shift", dict(windows=(64, 32), deform=False)),
        ("3 passes 64-48-32, shift", dict(windows=(64, 48, 32), deform=False)),
        ("3 passes 64-48-32, deform linear", dict(windows=(64, 48, 32), interpolation="linear")),
        ("3 passes 64-48-32, deform cubic (default)", dict(windows=(64, 48, 32))),
        ("3 passes 64-48-32, cubic, predictor unfiltered", dict(windows=(64, 48, 32), smooth=None)),
        ("4 passes 64-48-32-32, deform cubic", dict(windows=(64, 48, 32, 32))),
        ("3 passes 64-32-24, deform cubic", dict(windows=(64, 32, 24))),
        ("3 passes 64-48-32, cubic, 50 % overlap", dict(windows=(64, 48, 32), overlap=0.5)),
    ]
    rows = []
    print(f"\n3D PIV, {grid.shape[2]}x{grid.shape[1]}x{grid.shape[0]} voxels, 75 % overlap unless noted")
    print("RMS error [voxels] against the window-averaged flow, and (centre) against its value at the window centre")
    print(f"{'setting':44s} {'vectors':>8s} {'time [s]':>9s} {'us/vector':>10s} {'RMS err':>8s} {'(centre)':>9s} {'outliers':>9s}")
    for name, kw in cases:
        kw = {"overlap": 0.75, **kw}
        t0 = time.perf_counter()
        f = an.piv3d(a, b, grid, dt_s=dt, **kw)
        el = time.perf_counter() - t0
        rms = float(np.sqrt(np.sum(np.square(an.velocity_error(f, flow)["rms_vox"]))))
        rms_c = float(np.sqrt(np.sum(np.square(an.velocity_error(f, flow, samples=1)["rms_vox"]))))
        rows.append((name, f.n_vectors, el, rms, f.outlier_ratio))
        print(f"{name:44s} {f.n_vectors:8d} {el:9.1f} {1e6 * el / f.n_vectors:10.0f} {rms:8.4f} {rms_c:9.4f} "
              f"{100 * f.outlier_ratio:8.2f}%", flush=True)
    return rows


def openpiv_row(grid, a, b, flow, dt, window=32, overlap=24):
    from openpiv.pyprocess3D import extended_search_area_piv3D

    t0 = time.perf_counter()
    comps = extended_search_area_piv3D(a.astype(np.float64), b.astype(np.float64), window_size=(window,) * 3,
                                       overlap=(overlap,) * 3, search_area_size=(window,) * 3)
    el = time.perf_counter() - t0
    # OpenPIV's components: array axes (z, y, x) come back permuted and signed (see REFERENCE.md);
    # x displacement = comps[2], y = -comps[0], z = comps[1] on this layout (checked in tests)
    d = np.stack([comps[2], -comps[0], comps[1]], axis=-1)
    f = an.piv3d(a, b, grid, windows=window, overlap=overlap / window, deform=False, validate=False)
    if d.shape[:3] != f.shape:
        return el, int(d[..., 0].size), float("nan")
    g = f.with_displacement_vox(d)
    g.dt_s = None
    e = an.velocity_error(g, flow, dt_s=dt)
    return el, int(d[..., 0].size), float(np.sqrt(np.sum(np.square(e["rms_vox"]))))


def detection_table():
    print("\nparticle detection (blobs sigma 1 voxel, 0.002 particles per voxel)")
    print(f"{'volume':>14s} {'method':>9s} {'time [s]':>9s} {'found':>7s} {'detected':>9s} {'median err [vox]':>17s}")
    rows = []
    for shape in ((64, 128, 128), (128, 256, 256), (128, 512, 512)):
        grid = VoxelGrid((0.0, 0.0, 0.0), (VOX,) * 3, shape)
        rng = np.random.default_rng(2)
        p = rng.uniform(grid.origin_mm, grid.upper_mm, (int(0.002 * np.prod(shape)), 3))
        vol = an.truth_volume(p, grid, sigma_voxels=1.0)
        for method in ("gauss3", "centroid", "lsq"):
            t0 = time.perf_counter()
            found = an.find_particles(vol, grid, method=method)
            el = time.perf_counter() - t0
            r = an.match(found, p, grid=grid)
            med = float(np.median(np.linalg.norm(r.errors_mm, axis=1)) / VOX)
            rows.append((shape, method, el))
            print(f"{'x'.join(map(str, shape[::-1])):>14s} {method:>9s} {el:9.2f} {len(found):7d} {100 * r.detection_rate:8.1f}% "
                  f"{med:17.4f}", flush=True)
    return rows


def backlit_study():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import mitsuba as mi

    from mitpiv.analysis.backlit import evaluate_detections, hybrid_detect
    from mitpiv.calibrate import calibrate_dewarp
    from mitpiv.lightfield import decode, focal_stack
    from mitpiv.lightfield.refocus import stack_pixels
    from mitpiv.physics.droplets import drop_impact_field
    from mitpiv.render.backlit import render_backlit

    res = 1200
    s = {"type": "plenoptic", "pixel_pitch_um": 5.5, "focal_length_mm": 50.0, "f_number": 2.8, "focus_distance_mm": 100.0,
         "mla_pitch_um": 55.0, "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 100], target=[0, 0, 0], up=[0, 1, 0]),
         "film": {"type": "hdrfilm", "width": res, "height": res, "pixel_format": "luminance", "rfilter": {"type": "box"}}}
    t0 = time.perf_counter()
    dewarp, _ = calibrate_dewarp(s, [-2.0, -1.0, 0.0, 1.0, 2.0], spp=16)
    t_cal = time.perf_counter() - t0
    fld = drop_impact_field(150, crown_radius_mm=1.3, crown_height_mm=2.0, seed=7)
    p, d = fld["positions_mm"] - [0.0, 1.2, 0.0], fld["diameters_mm"]
    t0 = time.perf_counter()
    raw = render_backlit(s, p, d, spp=16)
    white = render_backlit(s, np.zeros((0, 3)), [], spp=16)
    t_render = time.perf_counter() - t0
    cam = mi.load_dict({"type": "scene", "sensor": s}).sensors()[0].camera
    t0 = time.perf_counter()
    lf = decode(raw, optics=cam, white=white)
    z = np.linspace(-3.0, 3.0, 121)
    st = focal_stack(lf, z)
    bg = focal_stack(decode(white, optics=cam, white=white), z)
    det = hybrid_detect(st, z, background=bg, dewarp=dewarp, pixel_to_stack=lambda u, v: stack_pixels(lf, u, v))
    t_det = time.perf_counter() - t0
    fov = res * 5.5e-3 / cam.magnification / 2
    inside = np.all(np.abs(p[:, :2]) < fov - d[:, None] / 2, axis=1)
    ev = evaluate_detections(det, p[inside], d[inside], axis=(0, 0, -1))
    dm = d[inside][ev["pairs"][:, 1]]
    print(f"\nbacklit plenoptic, drop impact ({inside.sum()} droplets 0.05-0.5 mm in a {2 * fov:.1f} mm field, "
          f"{1e3 * cam.lateral_resolution_mm():.0f} um per refocused pixel)")
    print(f"  dewarp fit {t_cal:.1f} s (rms {1e3 * dewarp.rms_mm:.2f} um), render {t_render:.1f} s, decode+stack+detect "
          f"{t_det:.1f} s ({z.size} planes)")
    print(f"  found {ev['n_found']}, matched {ev['n_matched']} ({100 * ev['detected_fraction']:.0f} %), depth RMS "
          f"{ev['depth_rms_diameters']:.2f} diameters (median |error| {ev['depth_median_abs_diameters']:.2f}), theoretical depth resolution {cam.depth_resolution():.3f} mm "
          f"= {cam.depth_resolution() / np.median(dm):.2f} median matched diameters")
    print(f"  size bias {1e3 * ev['size_bias_mm']:+.1f} um, RMS {1e3 * ev['size_rms_mm']:.1f} um")
    for lo, hi in ((0.05, 0.1), (0.1, 0.2), (0.2, 0.5)):
        sel = (d[inside] >= lo) & (d[inside] < hi)
        got = np.isin(np.nonzero(sel)[0], ev["pairs"][:, 1]).sum()
        print(f"  diameters {lo:.2f}-{hi:.2f} mm: {got}/{sel.sum()} detected")
    fig, ax = plt.subplots(1, 3, figsize=(15, 4.5))
    ax[0].imshow(np.where(bg > 0, st / np.where(bg > 0, bg, 1), 1).min(axis=0), cmap="gray", vmin=0, vmax=1)
    ax[0].plot(*det.uv_px.T, "r+", ms=6)
    ax[0].set_title("minimum-intensity map, detections (+)")
    bins = np.linspace(0, 0.55, 23)
    ax[1].hist(d[inside], bins=bins, histtype="step", color="k", label="truth (in field)")
    ax[1].hist(det.diameters_mm, bins=bins, histtype="step", color="r", label="measured")
    ax[1].set_xlabel("diameter [mm]")
    ax[1].legend()
    ax[1].set_title("size histogram")
    ax[2].scatter(dm, ev["depth_error_diameters"], s=12)
    ax[2].axhline(0, color="k", lw=0.5)
    ax[2].set_xlabel("true diameter [mm]")
    ax[2].set_ylabel("depth error [diameters]")
    ax[2].set_title(f"depth RMS {ev['depth_rms_diameters']:.2f} d; resolution {cam.depth_resolution():.2f} mm")
    fig.tight_layout()
    fig.savefig(OUT / "backlit_drop_impact.png", dpi=90)
    plt.close(fig)


def main():
    from mitpiv.render.variant import ensure_variant

    ensure_variant()  # Mitsuba objects below (importing mitpiv selects no variant)
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="128x128x64 PIV pair")
    args = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    shape = (64, 128, 128) if args.quick else (128, 256, 256)
    t0 = time.perf_counter()
    grid, a, b, flow, dt, _ = volumes(shape)
    print(f"volumes {time.perf_counter() - t0:.1f} s; max displacement "
          f"{np.abs(an.velocity_error(an.piv3d(a, a, grid, windows=64, overlap=0.0, dt_s=dt), flow)['reference']).max() * dt / VOX:.2f} voxels")
    rows = piv_table(grid, a, b, flow, dt)
    el, n, rms = openpiv_row(grid, a, b, flow, dt)
    ours = next(r for r in rows if r[0] == "1 pass 32, shift")
    print(f"{'OpenPIV 3D, 1 pass 32, 75 % overlap':44s} {n:8d} {el:9.1f} {1e6 * el / n:10.0f} {rms:8.4f}")
    print(f"time per vector, OpenPIV / ours (same single-pass setting): {(el / n) / (ours[2] / ours[1]):.1f}x; "
          f"RMS error OpenPIV / ours default: {rms / next(r[3] for r in rows if 'default' in r[0]):.1f}x")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 5))
    for name, _, el_, rms_, _ in rows:
        ax.loglog(el_, rms_, "o")
        ax.annotate(name, (el_, rms_), fontsize=7, xytext=(4, 2), textcoords="offset points")
    ax.loglog(el, rms, "s", color="k")
    ax.annotate("OpenPIV 3D (1 pass 32)", (el, rms), fontsize=7, xytext=(4, 2), textcoords="offset points")
    ax.set_xlabel("wall time [s] (2 cores)")
    ax.set_ylabel("RMS velocity error [voxels]")
    ax.set_title(f"3D PIV accuracy vs time, {shape[2]}x{shape[1]}x{shape[0]} voxels")
    fig.tight_layout()
    fig.savefig(OUT / "piv_accuracy_time.png", dpi=110)
    plt.close(fig)
    detection_table()
    backlit_study()
    print(f"\nplots: {OUT / 'piv_accuracy_time.png'}, {OUT / 'backlit_drop_impact.png'}")


if __name__ == "__main__":
    main()
