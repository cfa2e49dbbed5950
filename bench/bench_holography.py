"""Holography benchmark and the plenoptic vs digital in-line holography study.

1. Time per reconstructed plane against the image size: mitpiv's focal stack (spectrum
   once, one single-precision inverse FFT per plane) against a plain NumPy implementation
   (forward FFT, transfer function and inverse FFT per plane, double precision), same run,
   same hologram, with the largest difference between the two amplitudes.
2. A 1000-plane stack of a 2048x2048 hologram reduced on the fly to the minimum-intensity
   map (nothing stored), against the plain NumPy per-plane time measured on 10 planes.
3. The study pair on identical particle fields and the same sensor (5.5 um pixels): a
   drop impact (droplets 0.05-0.5 mm, 1200 px, 6.6 mm) and 2 mm pellets (2400 px,
   13.2 mm), each imaged by the backlit plenoptic camera (55 um lenslets, |M| = 1 and 0.25)
   and by DIH (collimated 532 nm beam): lateral resolution, detected fraction, size error,
   depth uncertainty in diameters, compute time. Table on stdout; plots in
   out/bench/plenoptic_vs_dih.png.

``python bench/bench_holography.py`` (about 8 minutes on 2 cores); ``--quick`` skips the
1000-plane stack and halves the study sizes.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mitpiv import holography as ho  # noqa: E402
from mitpiv.analysis.backlit import evaluate_detections, hybrid_detect  # noqa: E402

OUT = ROOT / "out" / "bench"
WL_NM = 532.0


def numpy_plane(img, z, pixel_um):
    """Plain NumPy: FFT, transfer function and inverse FFT for every plane (complex128)."""
    H = ho.transfer_function(img.shape, pixel_um * 1e-3, -z, WL_NM * 1e-6)
    return np.abs(np.fft.ifft2(np.fft.fft2(img) * H))


def plane_timing():
    print("time per reconstructed plane (amplitude), 5.5 um pixels, z = 20 mm")
    print(f"{'size':>10s} {'mitpiv [ms]':>12s} {'NumPy [ms]':>11s} {'ratio':>6s} {'max |diff|':>11s}")
    rows = []
    for n in (256, 512, 1024, 2048):
        rng = np.random.default_rng(0)
        pos = np.column_stack([rng.uniform(-0.4, 0.4, (20, 2)) * n * 5.5e-3, -rng.uniform(15, 25, 20)])
        h = ho.record(pos, 0.08, sensor_z_mm=0.0, pixel_um=5.5, resolution=(n, n), oversample=1, guard_mm=0.5)
        z = np.linspace(18.0, 22.0, 10)
        t0 = time.perf_counter()
        ours = ho.focal_stack(h, z)
        t_ours = (time.perf_counter() - t0) / z.size
        t0 = time.perf_counter()
        ref = np.stack([numpy_plane(h.image / h.background, zk, 5.5) for zk in z])
        t_np = (time.perf_counter() - t0) / z.size
        diff = float(np.abs(ours - ref).max())
        rows.append((n, t_ours, t_np))
        print(f"{n:>5d}x{n:<4d} {1e3 * t_ours:12.1f} {1e3 * t_np:11.1f} {t_np / t_ours:6.1f} {diff:11.2e}", flush=True)
    return rows


def big_stack(t_np_2048):
    n = 2048
    rng = np.random.default_rng(1)
    pos = np.column_stack([rng.uniform(-5.0, 5.0, (200, 2)), -rng.uniform(20, 60, 200)])
    t0 = time.perf_counter()
    h = ho.record(pos, rng.uniform(0.05, 0.3, 200), sensor_z_mm=0.0, pixel_um=5.5, resolution=(n, n), oversample=1,
                  guard_mm=1.0, plane_tolerance_mm=0.05)
    t_rec = time.perf_counter() - t0
    z = np.linspace(15.0, 65.0, 1000)
    t0 = time.perf_counter()
    mn = np.full((n, n), np.inf, np.float32)
    for k, plane in ho.iter_planes(h, z):
        np.minimum(mn, np.abs(plane), out=mn)
        if (k + 1) % 100 == 0:
            print(f"  1000-plane stack: {k + 1} planes, {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    t_stack = time.perf_counter() - t0
    print(f"\n2048x2048 hologram of 200 particles recorded in {t_rec:.1f} s ({h.info['planes']} planes); "
          f"1000-plane stack reduced to its minimum map in {t_stack:.0f} s ({1e3 * t_stack / 1000:.0f} ms/plane); "
          f"plain NumPy at {1e3 * t_np_2048:.0f} ms/plane would take {t_np_2048 * 1000:.0f} s "
          f"({t_np_2048 * 1000 / t_stack:.1f}x)")


def plenoptic_detect(sensor, pos, d, z, spp=16):
    import mitsuba as mi

    from mitpiv.calibrate import calibrate_dewarp
    from mitpiv.lightfield import decode, focal_stack
    from mitpiv.lightfield.refocus import stack_pixels
    from mitpiv.render.backlit import render_backlit

    cam = mi.load_dict({"type": "scene", "sensor": sensor}).sensors()[0].camera
    dewarp, _ = calibrate_dewarp(sensor, np.linspace(z[0], z[-1], 5) * 0.8, spp=spp)
    t0 = time.perf_counter()
    raw = render_backlit(sensor, pos, d, spp=spp)
    white = render_backlit(sensor, np.zeros((0, 3)), [], spp=spp)
    t_render = time.perf_counter() - t0
    t0 = time.perf_counter()
    lf = decode(raw, optics=cam, white=white)
    st = focal_stack(lf, z)
    bg = focal_stack(decode(white, optics=cam, white=white), z)
    det = hybrid_detect(st, z, background=bg, dewarp=dewarp, pixel_to_stack=lambda u, v: stack_pixels(lf, u, v))
    return det, t_render, time.perf_counter() - t0, cam.lateral_resolution_mm(), (raw, st, bg)


def dih_detect(pos, d, res, z_rec, distance_mm):
    t0 = time.perf_counter()
    h = ho.record(pos - [0.0, 0.0, distance_mm], d, sensor_z_mm=0.0, pixel_um=5.5, resolution=(res, res), oversample=1,
                  plane_tolerance_mm=0.005)
    t_rec = time.perf_counter() - t0
    t0 = time.perf_counter()
    det = ho.detect(h, z_rec)
    det.positions_mm = det.positions_mm + [0.0, 0.0, distance_mm]
    return det, t_rec, time.perf_counter() - t0, h


def study(quick):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import mitsuba as mi

    from mitpiv.physics.droplets import drop_impact_field, pellet_field
    from mitpiv.render.variant import ensure_variant

    ensure_variant()  # the sensor dicts below build Mitsuba transforms

    def sensor(res, focus):
        return {"type": "plenoptic", "pixel_pitch_um": 5.5, "focal_length_mm": 50.0, "f_number": 2.8,
                "focus_distance_mm": focus, "mla_pitch_um": 55.0,
                "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, focus], target=[0, 0, 0], up=[0, 1, 0]),
                "film": {"type": "hdrfilm", "width": res, "height": res, "pixel_format": "luminance",
                         "rfilter": {"type": "box"}}}

    s = 0.5 if quick else 1.0
    drops = drop_impact_field(int(150 * s), crown_radius_mm=1.3 * s, crown_height_mm=2.0 * s, seed=7)
    pellets = pellet_field(int(8 * s) or 4, diameter_mm=2.0, box_mm=((-5 * s, 5 * s), (-5 * s, 5 * s), (-4, 4)),
                           view_axis=(0, 0, 1), seed=3)
    cases = [
        ("drop impact", drops["positions_mm"] - [0.0, 1.2 * s, 0.0], drops["diameters_mm"], int(1200 * s), 100.0,
         np.linspace(-3.0, 3.0, 121), 20.0),
        ("2 mm pellets", pellets["positions_mm"], pellets["diameters_mm"], int(2400 * s), 250.0,
         np.linspace(-6.0, 6.0, 61), 60.0),
    ]
    print(f"\n{'field':14s} {'modality':10s} {'pixel [um]':>10s} {'found':>6s} {'detected':>9s} {'size bias':>10s} "
          f"{'size RMS':>9s} {'depth RMS [d]':>14s} {'median |dz| [d]':>16s} {'time [s]':>9s}")
    results = []
    for name, pos, d, res, focus, z_plen, dist in cases:
        half = res * 5.5e-3 / 2
        mag = 50.0 / (focus - 50.0)
        inside_plen = np.all(np.abs(pos[:, :2]) < half / mag - d[:, None] / 2, axis=1)
        inside_dih = np.all(np.abs(pos[:, :2]) < half - d[:, None] / 2, axis=1)
        pdet, t_r, t_d, lat, _ = plenoptic_detect(sensor(res, focus), pos, d, z_plen)
        ev_p = evaluate_detections(pdet, pos[inside_plen], d[inside_plen], axis=(0, 0, -1))
        z_rec = dist - z_plen[::-1]  # distances from the DIH sensor, particles at world z shifted by -dist
        ddet, t_rec, t_dd, _ = dih_detect(pos, d, res, np.sort(z_rec), dist)
        ev_d = evaluate_detections(ddet, pos[inside_dih], d[inside_dih], axis=(0, 0, 1))
        for mod, ev, lat_um, t in (("plenoptic", ev_p, 1e3 * lat, t_r + t_d), ("DIH", ev_d, 5.5, t_rec + t_dd)):
            print(f"{name:14s} {mod:10s} {lat_um:10.1f} {ev['n_found']:6d} {100 * ev['detected_fraction']:8.0f}% "
                  f"{1e3 * ev['size_bias_mm']:+8.0f}um {1e3 * ev['size_rms_mm']:7.0f}um {ev['depth_rms_diameters']:14.2f} "
                  f"{ev['depth_median_abs_diameters']:16.2f} {t:9.1f}", flush=True)
            results.append((name, mod, ev, d[inside_plen] if mod == "plenoptic" else d[inside_dih]))
    fig, axs = plt.subplots(2, 2, figsize=(12, 8))
    for row, name in enumerate(("drop impact", "2 mm pellets")):
        for name_, mod, ev, dtrue in results:
            if name_ != name:
                continue
            col = "C0" if mod == "plenoptic" else "C3"
            found_d = dtrue[ev["pairs"][:, 1]] + ev["size_error_mm"]
            bins = np.linspace(0, 0.55, 23) if row == 0 else np.linspace(1.5, 2.5, 21)
            if mod == "plenoptic":
                axs[row, 0].hist(dtrue, bins=bins, histtype="step", color="k", label="truth in the plenoptic field")
            axs[row, 0].hist(found_d, bins=bins, histtype="step", color=col, label=f"{mod} ({ev['n_matched']} matched)")
            axs[row, 1].scatter(dtrue[ev["pairs"][:, 1]], ev["depth_error_diameters"], s=10, color=col, label=mod)
        axs[row, 0].set_xlabel("diameter [mm]")
        axs[row, 0].set_title(f"{name}: size histogram")
        axs[row, 0].legend(fontsize=8)
        axs[row, 1].axhline(0, color="k", lw=0.5)
        axs[row, 1].set_xlabel("true diameter [mm]")
        axs[row, 1].set_ylabel("depth error [diameters]")
        axs[row, 1].set_title(f"{name}: depth error")
        axs[row, 1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(OUT / "plenoptic_vs_dih.png", dpi=90)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true")
    args = ap.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    rows = plane_timing()
    if not args.quick:
        big_stack(rows[-1][2])
    study(args.quick)
    print(f"\nplot: {OUT / 'plenoptic_vs_dih.png'}")


if __name__ == "__main__":
    main()
