"""What Mie scattering costs: table build time, render time, and image error per table knob.

1. Table build time (phase_table, 1024 angles) for x = 10, 100, 1000, 10000 (numba warm).
2. Render time of a 20k-particle field (log-normal 1 um DEHS droplets in air, 512x512,
   one camera at 55 deg elevation, 25 deg azimuth) with the `isotropic` phase, `mie`, and
   `mie` with a polarised sheet, for particle tracing and camera tracing (16 spp), in the
   same run; median of 5 after a warm-up, ratio to isotropic.
3. Image error against table resolution (`angles`) and the per-particle diameter spacing
   (`size_step`), against a converged table (16384 angles, size_step 0.001); particle
   tracing is deterministic, so the error is the table's alone. Writes
   out/bench/mie_accuracy.png.
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
from mitpiv.physics import mie  # noqa: E402
from mitpiv.physics.camera import PinholeCamera, place_camera  # noqa: E402
from mitpiv.physics.seeding import seed_box  # noqa: E402
from mitpiv.render.scene import load_dict  # noqa: E402


def build_scene(ply, cam, integrator, phase, polarization=None):
    laser = {"type": "laser_sheet", "id": "laser", "thickness": 6.0}
    if polarization is not None:
        laser["polarization"] = mi.ScalarVector3f(*polarization)
    return load_dict({
        "type": "scene", "integrator": {"type": integrator}, "laser": laser,
        "sensor": {"type": "distorted_pinhole", "to_world": mi.ScalarTransform4f(cam.to_world_mitsuba()),
                   "focal_length_mm": 85.0, "pixel_pitch_um": 10.0,
                   "film": {"type": "hdrfilm", "width": 512, "height": 512, "pixel_format": "luminance",
                            "rfilter": {"type": "gaussian", "stddev": 0.7}}},
        "particles": {"type": "ellipsoidsmesh", "filename": str(ply), "extent": 1.0,
                      "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}},
                      "emitter": {"type": "tracer_particles", "sheet": {"type": "ref", "id": "laser"}, "phase": phase}},
    })


def timed(sc, spp, repeats=5):
    mi.render(sc, spp=spp)  # warm-up: kernel compilation
    t = []
    for k in range(repeats):
        t0 = time.perf_counter()
        np.array(mi.render(sc, spp=spp, seed=k + 1))
        t.append(time.perf_counter() - t0)
    return float(np.median(t))


def table_times():
    print("1. Mie table build (1024 angles, one diameter, m = 1.45, numba warm)")
    mie.phase_table(1.0, 1.45)  # warm-up: numba compilation / cache load
    print(f"{'x':>8s} {'time [ms]':>10s}")
    for x in (10, 100, 1000, 10000):
        d = x * 532e-3 / np.pi
        mie._table_cached.cache_clear()
        t0 = time.perf_counter()
        mie.phase_table(d, 1.45)
        print(f"{x:8d} {1e3 * (time.perf_counter() - t0):10.1f}", flush=True)


def render_times(ply, cam):
    print("\n2. Render time, 20k particles, 512x512 (ratio to isotropic, same run)")
    oil = {"type": "mie", "index": 1.45}
    configs = [("isotropic", {"type": "isotropic"}, None), ("mie", oil, None), ("mie + polarised sheet", oil, (0, 1, 0))]
    for integrator, spp in (("particle_tracer", 1), ("direct", 16)):
        base = None
        print(f"{integrator} ({spp} spp)" if integrator == "direct" else integrator)
        for name, phase, pol in configs:
            t_load = time.perf_counter()
            sc = build_scene(ply, cam, integrator, dict(phase), pol)
            t_load = time.perf_counter() - t_load
            t = timed(sc, spp)
            base = base or t
            print(f"  {name:28s} render {t:7.3f} s  ratio {t / base:5.2f}   (scene load incl. table {t_load:5.2f} s)", flush=True)


def accuracy(ply, cam):
    print("\n3. Image error against table resolution (particle tracing, relative L1 over the image)")
    def img(**kw):
        sc = build_scene(ply, cam, "particle_tracer", {"type": "mie", "index": 1.45, **kw})
        return np.array(mi.render(sc), dtype=np.float64)[..., 0]

    ref = img(angles=16384, size_step=0.001)
    rows = {"angles": [], "size_step": []}
    for n in (32, 64, 128, 256, 512, 1024, 4096):
        t0 = time.perf_counter()
        e = np.abs(img(angles=n, size_step=0.001) - ref).sum() / ref.sum()
        rows["angles"].append((n, e, time.perf_counter() - t0))
    for s in (0.5, 0.2, 0.05, 0.02, 0.005):
        t0 = time.perf_counter()
        e = np.abs(img(angles=16384, size_step=s) - ref).sum() / ref.sum()
        rows["size_step"].append((s, e, time.perf_counter() - t0))
    for knob, vals in rows.items():
        print(f"{knob:>10s} {'L1 error':>10s} {'load+render [s]':>16s}")
        for v, e, t in vals:
            print(f"{v:10g} {e:10.2e} {t:16.2f}")
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 2, figsize=(9, 3.6))
    for a, (knob, vals) in zip(ax, rows.items(), strict=True):
        v, e, _ = np.array(vals).T
        a.loglog(v, e, "o-")
        a.set_xlabel(knob + (" (table nodes)" if knob == "angles" else " (spacing in x)"))
        a.set_ylabel("relative L1 image error")
        a.grid(True, which="both", alpha=0.3)
        a.axvline(1024 if knob == "angles" else 0.02, color="k", ls=":", label="default")
        a.legend()
    fig.suptitle("mie phase: image error vs table resolution (20k log-normal DEHS particles)")
    fig.tight_layout()
    out = ROOT / "out" / "bench" / "mie_accuracy.png"
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


def main():
    from mitpiv.render.variant import ensure_variant

    ensure_variant()  # Mitsuba objects below (importing mitpiv selects no variant)
    tmp = Path(tempfile.mkdtemp())
    p = seed_box((-14, -14, -3), (14, 14, 3), count=20000, diameter_um=1.0, distribution="lognormal", geometric_std=1.3, seed=0)
    ply = write_particles_ply(tmp / "p.ply", p.positions_mm, p.diameters_um, proxy_radius_mm=0.01)
    rot, pos = place_camera(azimuth_deg=25.0, elevation_deg=55.0, distance_mm=500.0)
    cam = PinholeCamera((512, 512), 85.0, 10.0, rotation=rot, position_mm=pos)
    table_times()
    render_times(ply, cam)
    accuracy(ply, cam)


if __name__ == "__main__":
    main()
