"""What Mie scattering costs: table build time, render time, and image error per table knob.

1. Table build time (phase_table) for x = 10, 100, 1000, 10000 (numba warm): the former
   default (1024 fixed angles) and the default (nodes chosen for the relative tolerance
   1e-3), or the up-front refusal with its estimate.
2. Render time of a 20k-particle field (log-normal 1 um DEHS droplets in air, 512x512,
   one camera at 55 deg elevation, 25 deg azimuth) with the `isotropic` phase, `mie`, and
   `mie` with a polarised sheet, for particle tracing and camera tracing (16 spp), in the
   same run; median of 5 after a warm-up, ratio to isotropic.
3. Image error against table resolution (`angles`, and the default chosen for the
   tolerance) and the per-particle diameter spacing (`size_step`), each against a converged
   table with the other knob held (65536 angles; size_step 0.001); particle tracing is
   deterministic, so the error is the table's alone. Writes
   out/bench/mie_accuracy.png.
4. The default table per particle size (1, 5, 20 um DEHS droplets, one diameter): nodes,
   table build time, render time (particle tracing of 200k particles, camera tracing of
   20k particles at 16 spp, 512x512) and the largest
   relative error of p_par / p_per against Mie theory evaluated directly (300,000 angles and
   the deep minima), for the former default (1024 angles), 8192 angles and tolerances 1e-2,
   1e-3 (the default), 1e-4; ratios against the former default, measured in the same run.
5. Interpolants (the design's alternatives): the largest relative error of uniform grids
   interpolated linearly, linearly in log p, by PCHIP and by a cubic spline, against the
   default's adaptive grid with linear interpolation (5 and 20 um).
6. The table's interval lookup per ray: 50M uniform random angles in [0, 3.1] through
   ``mi.math.find_interval`` over all nodes (the former lookup) and through the uniform
   grid with its fixed-step binary search (``interval``), on the default 1, 5 and 20 um
   tables; ns per lookup net of generating the angles (best of 3 after a compiling call),
   ratio in the same run.
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
from mitpiv.errors import ConfigError  # noqa: E402
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


def build_time(d, repeats=3, **kw):
    """Median build time [s] of a phase table (cache cleared before each build) and the table."""
    t = []
    for _ in range(repeats):
        mie._table_cached.cache_clear()
        t0 = time.perf_counter()
        tab = mie.phase_table(d, 1.45, **kw)
        t.append(time.perf_counter() - t0)
    return float(np.median(t)), tab


def table_times():
    print("1. Mie table build (one diameter, m = 1.45, numba warm)")
    mie.phase_table(1.0, 1.45)  # warm-up: numba compilation / cache load
    print(f"{'x':>8s} {'1024 angles [ms]':>17s} {'default [ms]':>13s} {'nodes':>9s} {'ratio':>7s}")
    for x in (10, 100, 1000, 10000):
        d = x * 532e-3 / np.pi
        t_old, _ = build_time(d, repeats=1, angles=1024)
        try:
            t_new, tab = build_time(d, repeats=1)
            new = f"{1e3 * t_new:13.1f} {tab.angles:9d} {t_new / t_old:7.1f}"
        except ConfigError as e:
            new = f"  refused up front: {str(e).split(': ', 1)[1][:110]}..."
        print(f"{x:8d} {1e3 * t_old:17.1f} {new}", flush=True)


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

    # Each knob against its own converged reference with the other knob held: the angles at the
    # default size_step (0.02), the size_step at 2048 fixed angles (a table of 16384 angles x
    # 14,700 diameters at size_step 0.001 would need ~12 GB).
    rows = {"angles": [], "size_step": []}
    ref = img(angles=65536)
    for n in (32, 64, 128, 256, 512, 1024, 4096):
        t0 = time.perf_counter()
        e = np.abs(img(angles=n) - ref).sum() / ref.sum()
        rows["angles"].append((n, e, time.perf_counter() - t0))
    t0 = time.perf_counter()
    default = img()
    e = np.abs(default - ref).sum() / ref.sum()
    print(f"default table (tolerance {mie.TABLE_TOLERANCE:g}, grid of the largest diameter): L1 error {e:.2e}, "
          f"load+render {time.perf_counter() - t0:.2f} s")
    ref = img(angles=2048, size_step=0.001)
    for s in (0.5, 0.2, 0.05, 0.02, 0.005):
        t0 = time.perf_counter()
        e = np.abs(img(angles=2048, size_step=s) - ref).sum() / ref.sum()
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
        a.axvline(1024 if knob == "angles" else 0.02, color="k", ls=":", label="1024: former default" if knob == "angles" else "default")
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
    sections = set(sys.argv[1:]) or {"1", "2", "3", "4", "5", "6"}  # e.g. `python bench/bench_mie.py 4 5`
    if "1" in sections:
        table_times()
    if "2" in sections:
        render_times(ply, cam)
    if "3" in sections:
        accuracy(ply, cam)
    if "4" in sections:
        per_size(tmp, cam)
    if "5" in sections:
        interpolants()
    if "6" in sections:
        lookup_times()


SETTINGS = [("1024 angles (former default)", {"angles": 1024}), ("8192 angles", {"angles": 8192}),
            ("tolerance 1e-2", {"tolerance": 1e-2}), ("tolerance 1e-3 (default)", {}),
            ("tolerance 1e-4", {"tolerance": 1e-4})]


def reference(d):
    """Mie theory evaluated directly (float64): 300,000 angles and the deep minima of p_par
    and p_per (each refined on the dense scan by a bounded scalar minimisation)."""
    from scipy.optimize import minimize_scalar

    th = np.linspace(0.0, np.pi, 300001)
    par, per = mie.polarized_intensities(d, 1.45, np.degrees(th))
    extra = []
    for f in (par, per):
        for i in np.flatnonzero((f[1:-1] < f[:-2]) & (f[1:-1] < f[2:])) + 1:
            k = 0 if f is par else 1
            r = minimize_scalar(lambda t, k=k: mie.polarized_intensities(d, 1.45, [np.degrees(t)])[k][0],
                                bounds=(th[i - 1], th[i + 1]), method="bounded", options={"xatol": 1e-10})
            extra.append(r.x)
    th = np.sort(np.concatenate([th, extra]))
    return (th, *mie.polarized_intensities(d, 1.45, np.degrees(th)))


def max_error(tab, ref):
    th, par, per = ref
    floor = mie.TABLE_FLOOR * max(par.max(), per.max())
    asc = tab.theta[::-1]
    return max(float(np.max(np.abs(np.interp(th, asc, t[0][::-1]) - r) / (r + floor)))
               for t, r in ((tab.p_par, par), (tab.p_per, per)))


def per_size(tmp, cam):
    print("\n4. The table per particle size (DEHS in air, 532 nm, one diameter): nodes, build time, render time "
          "(particle tracing of 200k particles; camera tracing of 20k particles at 16 spp; 512x512, median of 5), "
          "largest relative error of p_par/p_per against Mie theory; ratios to the former default, same run")
    many = seed_box((-14, -14, -3), (14, 14, 3), count=200000, diameter_um=1.0, seed=0)
    few = seed_box((-14, -14, -3), (14, 14, 3), count=20000, diameter_um=1.0, seed=1)
    print(f"{'size':>6s} {'setting':30s} {'nodes':>7s} {'build [ms]':>11s} {'ratio':>6s} {'particle tr. [s]':>17s} "
          f"{'ratio':>6s} {'camera tr. [s]':>15s} {'ratio':>6s} {'max rel. error':>15s}")
    for d in (1.0, 5.0, 20.0):
        plys = [write_particles_ply(tmp / f"p{d:g}_{k}.ply", p.positions_mm, np.full(len(p.positions_mm), d),
                                    proxy_radius_mm=0.01) for k, p in enumerate((many, few))]
        ref = reference(d)
        base = None
        for name, kw in SETTINGS:
            t_build, tab = build_time(d, **kw)
            phase = {"type": "mie", "index": 1.45, **kw}
            t_pt = timed(build_scene(plys[0], cam, "particle_tracer", dict(phase)), 1)
            t_ct = timed(build_scene(plys[1], cam, "direct", dict(phase)), 16)
            base = base or (t_build, t_pt, t_ct)
            print(f"{d:4g}um {name:30s} {tab.angles:7d} {1e3 * t_build:11.1f} {t_build / base[0]:6.2f} {t_pt:17.3f} "
                  f"{t_pt / base[1]:6.2f} {t_ct:15.3f} {t_ct / base[2]:6.2f} {max_error(tab, ref):15.2e}", flush=True)


def interpolants():
    from scipy.interpolate import CubicSpline, PchipInterpolator

    print("\n5. Interpolants: largest relative error of p_par/p_per on uniform grids vs the default's adaptive grid")
    kinds = {"linear": lambda g, v, t: np.interp(t, g, v), "linear in log p": lambda g, v, t: np.exp(np.interp(t, g, np.log(v))),
             "PCHIP": lambda g, v, t: PchipInterpolator(g, v)(t), "cubic spline": lambda g, v, t: CubicSpline(g, v)(t)}
    for d in (5.0, 20.0):
        th, par, per = reference(d)
        floor = mie.TABLE_FLOOR * max(par.max(), per.max())
        for n in (1024, 4096, 16384):
            g = np.linspace(0.0, np.pi, n)
            gp, gq = mie.polarized_intensities(d, 1.45, np.degrees(g))
            errs = [max(float(np.max(np.abs(f(g, v, th) - r) / (r + floor))) for v, r in ((gp, par), (gq, per)))
                    for f in kinds.values()]
            print(f"{d:4g}um uniform {n:6d}: " + "  ".join(f"{k} {e:.1e}" for k, e in zip(kinds, errs, strict=True)))
        tab = mie.phase_table(d, 1.45)
        print(f"{d:4g}um adaptive {tab.angles:5d}: linear {max_error(tab, (th, par, per)):.1e} (the default)")


def lookup_times(count=50_000_000):
    import drjit as dr

    from mitpiv.render.plugins.mie_phase import AngleNodes, interval

    print(f"\n6. Interval lookup, {count // 1_000_000}M uniform random angles in [0, 3.1] (ns per lookup, net of "
          f"generating the angles; the three kernels timed in turn, best of 5 after a compiling call)")

    def angles():
        return 3.1 * mi.sample_tea_float32(dr.arange(mi.UInt32, count), mi.UInt32(7))

    def find_interval(nodes, n, theta):  # the former lookup: a binary search over all nodes
        i = mi.math.find_interval(n, lambda k: dr.gather(mi.Float, nodes, k) <= theta)
        t0 = dr.gather(mi.Float, nodes, i)
        width = dr.gather(mi.Float, nodes, i + 1) - t0
        return i, dr.clip((theta - t0) / width, 0.0, 1.0), width

    def seconds(f):
        t0 = time.perf_counter()
        dr.eval(f())
        dr.sync_thread()
        return time.perf_counter() - t0

    print(f"{'size':>6s} {'nodes':>7s} {'cells':>8s} {'span':>5s} {'steps':>6s} {'find_interval':>14s} {'grid':>6s} {'ratio':>6s}")
    for d in (1.0, 5.0, 20.0):
        table = AngleNodes(mie.phase_table(d, 1.45).theta[::-1])
        kernels = (angles, lambda tb=table: find_interval(tb.nodes, tb.n, angles()), lambda tb=table: interval(tb, angles()))
        ts = [[seconds(f) for f in kernels] for _ in range(6)][1:]  # interleaved: the same load on each
        base, t_old, t_new = (min(t[k] for t in ts) for k in range(3))
        t_old, t_new = ((t - base) / count * 1e9 for t in (t_old, t_new))
        print(f"{d:4g}um {table.n:7d} {table.cells:8d} {table.max_span:5d} {table.steps:6d} {t_old:14.1f} {t_new:6.1f} "
              f"{t_old / t_new:6.2f}", flush=True)

if __name__ == "__main__":
    main()
