"""What imaging optics cost: PSF tables, PSF accuracy knobs, PSF in rendering, calibration.

1. Centre-pixel and first/second pixel-ring energies vs RMS spherical aberration
   (0, 0.02, 0.05, 0.10 waves) at f/2.8 and f/8 (working f/16 at |M| = 1), 10 um pixels,
   532 nm, particle centred on a pixel, and the Strehl ratio.
2. PSF error vs pupil samples (against 2048) and its time.
3. PSF in rendering: 2000 particles, 256x256 camera, f/11 working f/12 with 0.05 waves of
   spherical aberration. Reference: FFT mode at oversample 15. FFT mode at oversample
   1..9 and in-sensor jitter at 16..4096 rays per particle: time (median of 3 after a
   warm-up) as a ratio to rendering without PSF, and error (relative L1, max / peak).
   A field-dependent PSF (1 wave RMS defocus at the corner): jitter against jitter at
   65536 rays, and what the space-invariant FFT mode misses. Writes out/bench/psf_modes.png.
4. Calibration from rendered dot targets (9 poses, 1 % barrel distortion, 256x256):
   reprojection RMS of each model and its error against the true mapping over the volume.
5. The FFT-mode PSF at the pixel centres (``RenderPSF.apply``): a 1000x1000 camera at
   oversample 5 (a 5000x5000 fine image of 100,000 bilinear particle splats), the sapiv
   kernel (f/2.8, M = 0.2) and the channel kernel (f/16, M = 0.525), 10 um pixels, 532 nm,
   energy tolerance 0.005. Old: full-resolution ``convolve_psf`` then keep every 5th
   sample; new: ``decimated_convolve`` (auto, and each strategy forced). Minimum of 3 runs,
   old / new ratios from the same run, max difference / peak.
   ``python bench/bench_optics.py decimate`` runs this section alone.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import mitsuba as mi
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
import mitpiv  # noqa: E402,F401
from mitpiv.io import write_particles_ply  # noqa: E402
from mitpiv.physics import psf as P  # noqa: E402
from mitpiv.physics.camera import PinholeCamera, place_camera  # noqa: E402
from mitpiv.physics.targets import CalibrationTarget, target_pose  # noqa: E402
from mitpiv.reconstruct import PinholeMapping, calibrate_views  # noqa: E402
from mitpiv.render.render import render_sensor  # noqa: E402
from mitpiv.render.scene import load_dict  # noqa: E402
from mitpiv.render.targets import render_target_views  # noqa: E402

OUT = ROOT / "out" / "bench"


def ring_table():
    print("1. Pixel energies vs RMS spherical aberration (10 um pixels, 532 nm, centred particle)")
    print(f"   {'f-number':>12} {'SA [waves]':>10} {'centre':>8} {'ring 1':>8} {'ring 2':>8} {'Strehl':>7} {'ms':>6}")
    for n, m in ((2.8, None), (8.0, 1.0)):
        for sa in (0.0, 0.02, 0.05, 0.10):
            t0 = time.perf_counter()
            img = P.psf(f_number=n, pixel_pitch_um=10.0, magnification=m, spherical_waves=sa)
            dt = (time.perf_counter() - t0) * 1e3
            c, r1, r2 = P.ring_energies(img)
            label = f"f/{n:g}" + ("" if m is None else f" (M={m:g})")
            print(f"   {label:>12} {sa:>10.2f} {c:>8.4f} {r1:>8.4f} {r2:>8.4f} {P.strehl_ratio(spherical_waves=sa):>7.4f} {dt:>6.1f}")


def pupil_sampling():
    print("\n2. PSF error vs pupil samples (f/2.8, 0.1 waves SA, pixels lambda N / 2, 41x41), against 2048")
    kw = dict(f_number=2.8, pixel_pitch_um=0.532 * 2.8 / 2, spherical_waves=0.1, size_px=41)
    ref = P.psf(**kw, pupil_samples=2048)
    for n in (64, 128, 256, 512, 1024):
        t0 = time.perf_counter()
        img = P.psf(**kw, pupil_samples=n)
        dt = (time.perf_counter() - t0) * 1e3
        print(f"   n = {n:5d}: max error {np.max(np.abs(img - ref)) / ref.max():.2e} of the peak, {dt:7.1f} ms")


def particle_scene(ply, cam, *, sensor_props, rfilter, integrator):
    return load_dict({
        "type": "scene", "integrator": integrator,
        "laser": {"type": "laser_sheet", "id": "laser", "thickness": 6.0},
        "sensor": {"type": "distorted_pinhole", "to_world": mi.ScalarTransform4f(cam.to_world_mitsuba()),
                   "focal_length_mm": 50.0, "pixel_pitch_um": 10.0, **sensor_props,
                   "film": {"type": "hdrfilm", "width": 256, "height": 256, "pixel_format": "luminance",
                            "rfilter": {"type": rfilter}}},
        "particles": {"type": "ellipsoidsmesh", "filename": str(ply), "extent": 1.0,
                      "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}},
                      "emitter": {"type": "tracer_particles", "sheet": {"type": "ref", "id": "laser"}}},
    })


def timed(sc, repeats=3):
    render_sensor(sc, sc.sensors()[0])
    ts, img = [], None
    for k in range(repeats):
        t0 = time.perf_counter()
        img = render_sensor(sc, sc.sensors()[0], seed=k + 1)
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts)), img.astype(np.float64)


def psf_modes(tmp):
    print("\n3. PSF in rendering (2000 particles, 256x256, working f/12, 0.05 waves SA)")
    rng = np.random.default_rng(1)
    pts = np.column_stack([rng.uniform(-9, 9, (2000, 2)), rng.uniform(-3, 3, 2000)])
    ply = tmp / "p.ply"
    write_particles_ply(ply, pts, 1.0, proxy_radius_mm=0.01)
    rot, pos = place_camera(azimuth_deg=0.0, elevation_deg=90.0, distance_mm=500.0, up=(0.0, 1.0, 0.0))
    cam = PinholeCamera((256, 256), 50.0, 10.0, rotation=rot, position_mm=pos)
    optics = {"psf_f_number": 11.0, "psf_magnification": 0.11, "psf_spherical_waves": 0.05, "psf_energy_tolerance": 5e-3}
    pt = {"type": "particle_tracer"}
    t_none, _ = timed(particle_scene(ply, cam, sensor_props={}, rfilter="box", integrator=pt))
    _, ref = timed(particle_scene(ply, cam, sensor_props={"psf": "fft", "psf_oversample": 15, **optics},
                                  rfilter="catmullrom", integrator=pt), repeats=1)

    def err(img):
        return np.abs(img - ref).sum() / ref.sum(), np.abs(img - ref).max() / ref.max()

    rows = []
    print(f"   no PSF: {t_none * 1e3:.1f} ms (the baseline)")
    for s in (1, 3, 5, 9):
        t, img = timed(particle_scene(ply, cam, sensor_props={"psf": "fft", "psf_oversample": s, **optics},
                                      rfilter="catmullrom", integrator=pt))
        e1, em = err(img)
        rows.append(("fft", s, t, e1, em))
        print(f"   fft    oversample {s:5d}: {t * 1e3:8.1f} ms ({t / t_none:6.1f}x), L1 {e1:.2e}, max {em:.2e} of peak")
    for r in (16, 64, 256, 1024, 4096):
        t, img = timed(particle_scene(ply, cam, sensor_props={"psf": "jitter", **optics}, rfilter="box",
                                      integrator={**pt, "rays_per_particle": r}))
        e1, em = err(img)
        rows.append(("jitter", r, t, e1, em))
        print(f"   jitter rays/part. {r:5d}: {t * 1e3:8.1f} ms ({t / t_none:6.1f}x), L1 {e1:.2e}, max {em:.2e} of peak")

    print("   field-dependent PSF (+1 wave RMS defocus at the corner), reference: jitter at 65536 rays")
    field = {"psf": "jitter", "psf_defocus_corner_waves": 1.0, **optics}
    _, fref = timed(particle_scene(ply, cam, sensor_props=field, rfilter="box", integrator={**pt, "rays_per_particle": 65536}), repeats=1)
    frows = []
    for r in (64, 1024, 4096):
        t, img = timed(particle_scene(ply, cam, sensor_props=field, rfilter="box", integrator={**pt, "rays_per_particle": r}))
        e1 = np.abs(img - fref).sum() / fref.sum()
        frows.append((r, t, e1))
        print(f"   jitter rays/part. {r:5d}: {t * 1e3:8.1f} ms, L1 {e1:.2e}")
    t, img = timed(particle_scene(ply, cam, sensor_props={"psf": "fft", "psf_oversample": 5, **optics},
                                  rfilter="catmullrom", integrator=pt))
    e_fft = np.abs(img - fref).sum() / fref.sum()
    print(f"   fft (centre PSF, oversample 5): {t * 1e3:8.1f} ms, L1 {e_fft:.2e}  <- the field dependence it cannot show")
    plot(rows, frows, e_fft, t_none)


def plot(rows, frows, e_fft, t_none):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    for mode, marker in (("fft", "o-"), ("jitter", "s-")):
        sel = [r for r in rows if r[0] == mode]
        ax[0].loglog([r[2] for r in sel], [r[3] for r in sel], marker, label=f"{mode}")
        for r in sel:
            ax[0].annotate(str(r[1]), (r[2], r[3]), fontsize=7, textcoords="offset points", xytext=(3, 3))
    ax[0].axvline(t_none, color="grey", ls=":", label="no PSF")
    ax[0].set_xlabel("render time [s]")
    ax[0].set_ylabel("relative L1 error vs FFT at oversample 15")
    ax[0].set_title("space-invariant PSF (labels: oversample / rays)")
    ax[0].legend()
    ax[1].loglog([r[0] for r in frows], [r[2] for r in frows], "s-", label="jitter")
    ax[1].axhline(e_fft, color="C0", ls="--", label="fft with the centre PSF")
    ax[1].set_xlabel("rays per particle")
    ax[1].set_ylabel("relative L1 error vs jitter at 65536 rays")
    ax[1].set_title("field-dependent PSF (1 wave defocus at corner)")
    ax[1].legend()
    fig.tight_layout()
    OUT.mkdir(parents=True, exist_ok=True)
    fig.savefig(OUT / "psf_modes.png", dpi=110)
    print(f"   plot: {OUT / 'psf_modes.png'}")


def calibration():
    print("\n4. Calibration from rendered dot targets (15x19 dots, 9 poses, 64 spp, 1 % barrel distortion)")
    rot, pos = place_camera(azimuth_deg=25, elevation_deg=45, distance_mm=400)
    nominal = PinholeMapping(PinholeCamera((256, 256), 50.0, 10.0, rotation=rot, position_mm=pos))
    sensor = load_dict({"type": "distorted_pinhole", "to_world": mi.ScalarTransform4f(nominal.camera.to_world_mitsuba()),
                        "focal_length_mm": 50.0, "pixel_pitch_um": 10.0, "distortion_percent": 1.0,
                        "film": {"type": "hdrfilm", "width": 256, "height": 256, "pixel_format": "luminance",
                                 "rfilter": {"type": "box"}}})
    truth = PinholeMapping(PinholeCamera.from_dict(sensor.describe()))
    target = CalibrationTarget("dots", 15, 19, 1.2)
    poses = [target_pose(z, tilt_x_deg=tx, tilt_y_deg=ty) for z in (-6, 0, 6) for tx, ty in ((0, 0), (20, 0), (0, -20))]
    t0 = time.perf_counter()
    views = render_target_views([sensor], target, poses, spp=64)
    print(f"   rendering 9 views: {time.perf_counter() - t0:.2f} s")
    vol = np.random.default_rng(0).uniform([-8, -6, -5], [8, 6, 5], (5000, 3))
    for model, dist in (("pinhole", "none"), ("pinhole", "radial"), ("pinhole", "brown"), ("polynomial", "none")):
        t0 = time.perf_counter()
        m = calibrate_views(views, 0, nominal, target, model=model, distortion=dist, max_rms_px=2.0)
        dt = time.perf_counter() - t0
        e = np.linalg.norm(m.project(vol) - truth.project(vol), axis=1)
        name = model + ("" if model == "polynomial" else f" ({dist})")
        print(f"   {name:>18}: reprojection RMS {m.fit_report['rms_px']:.4f} px over {m.fit_report['markers']} markers; "
              f"vs true mapping RMS {np.sqrt(np.mean(e**2)):.4f} / max {e.max():.4f} px; detect+fit {dt:.2f} s")


def _splats(n, shape, rng):
    """Bilinear splats of n particles of random brightness (a tent-filtered particle render)."""
    f = np.zeros(shape)
    y, x = rng.uniform(0, shape[0] - 1, n), rng.uniform(0, shape[1] - 1, n)
    iy, ix = np.minimum(y.astype(int), shape[0] - 2), np.minimum(x.astype(int), shape[1] - 2)
    fy, fx, a = y - iy, x - ix, rng.uniform(0.2, 1.0, n)
    for dy, wy in ((0, 1 - fy), (1, fy)):
        for dx, wx in ((0, 1 - fx), (1, fx)):
            np.add.at(f, (iy + dy, ix + dx), a * wy * wx)
    return f


def decimated_psf(repeats=3):
    from mitpiv.imaging import RenderPSF, convolve_psf, decimated_convolve

    s, n = 5, 1000
    fine = _splats(100_000, (n * s, n * s), np.random.default_rng(0))
    print(f"\n5. FFT-mode PSF at the pixel centres: {n}x{n} camera, oversample {s}, 100,000 particles "
          f"({np.count_nonzero(fine):,} non-zero fine pixels)")

    def best(fn):
        fn()
        ts = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            r = fn()
            ts.append(time.perf_counter() - t0)
        return min(ts), r

    for name, kw in (("sapiv f/2.8 M=0.2", dict(f_number=2.8, magnification=0.2)),
                     ("channel f/16 M=0.525", dict(f_number=16.0, magnification=0.525253))):
        psf = RenderPSF(mode="fft", pixel_pitch_um=10.0, wavelength_nm=532.0, energy_tolerance=0.005, oversample=s, **kw)
        k = psf.fft_kernel
        t_old, ref = best(lambda k=k: convolve_psf(fine, k)[s // 2::s, s // 2::s] / (s * s))
        t_new, out = best(lambda psf=psf: psf.apply(fine))
        row = [f"   {name:>20} ({k.shape[0]}^2 fine px): old {t_old:6.3f} s, apply {t_new:6.3f} s ({t_old / t_new:4.1f}x)"]
        for m in ("direct", "fft"):
            t, o = best(lambda k=k, m=m: decimated_convolve(fine, k, s, method=m) / (s * s))
            row.append(f"{m} {t:6.3f} s ({t_old / t:4.1f}x, diff {np.abs(o - ref).max() / ref.max():.0e})")
        print(", ".join(row) + f"; apply diff {np.abs(out - ref).max() / ref.max():.0e} of peak")


def main():
    from mitpiv.render.variant import set_variant

    if sys.argv[1:] == ["decimate"]:
        decimated_psf()
        return
    set_variant()
    ring_table()
    pupil_sampling()
    with tempfile.TemporaryDirectory() as d:
        psf_modes(Path(d))
    calibration()
    decimated_psf()


if __name__ == "__main__":
    main()
