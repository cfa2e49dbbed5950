"""Accuracy versus time: every accuracy knob of the pipeline, its wall time and its error
against a converged reference on the same scene (``mitpiv bench accuracy-time``).

One scene per size preset: log-normal 1 um DEHS droplets (Mie phase, n = 1.45) in a
Gaussian laser sheet, seeded at 0.05 particles per pixel, advected by a vortex ring, seen
by four ``distorted_pinhole`` cameras in the tomo4 pyramid (55 deg elevation, azimuth
+-25 and 180 +-25 deg, 85 mm lens, 10 um pixels, 1 m away) with the f/16 diffraction PSF.
A plenoptic camera (5.5 um pixels, 55 um lenslets, 50 mm f/2.8 at 250 mm) images a sparse
field for the light-field stage. Each stage's knobs are varied one at a time, the other
knobs at their reference values, and each stage is measured alone:

* ``render`` (camera 0, frame 0; error = relative L1 image error against particle tracing
  with a phase table at tolerance 1e-5 and the FFT PSF at 15 samples per pixel):
  camera tracing (``direct``, FFT PSF at the default 5 samples per pixel: camera tracing
  renders the oversampled film, so its cost grows with the square of the oversampling)
  against samples per pixel; particle tracing with the
  in-sensor PSF jitter against rays per particle; particle tracing with the FFT PSF
  against ``psf_oversample`` (PSF and pupil sampling); the Mie phase table's
  ``tolerance`` (its nodes chosen for that relative accuracy at every angle; the default
  1e-3) and, for comparison, fixed ``angles`` grids. Time: scene load (phase tables, PSF)
  plus render.
* ``lightfield`` (error = RMS depth error [mm] of the particles, each the brightest voxel
  of its column in the multiplicative volumetric refocus with a 3-point sub-plane fit,
  against their true depth): decoder interpolation; focal-plane count. Time: decode plus
  refocus.
* ``reconstruct`` (the four reference images of frame 0; error = 1 - Q against the true
  particle volume): MLOS, MART and SMART against iterations.
* ``piv`` (the true particle volumes of both frames, so that the error is the
  correlation's own; error = RMS velocity error [voxels] against the window-averaged
  flow): final window size and number of passes.
* ``end_to_end``: whole pipelines (render both frames, reconstruct both, correlate) from
  cheap to accurate settings; total time against the final velocity RMS error.

Writes ``accuracy_time.csv`` (one row per measurement), ``accuracy_time.md`` (a table per
stage and the end-to-end table) and ``pareto_<stage>.png`` (error against time, log-log,
one line per knob, the Pareto front marked) into the output folder.
"""

from __future__ import annotations

import csv
import logging
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError

STAGES = ("render", "lightfield", "reconstruct", "piv", "end_to_end")

# Size presets. "quick" keeps every stage to seconds (tests, a first look); "full" is what
# the README figures come from (about 15 minutes on 2 cores).
SIZES = {
    "quick": dict(res=96, box=(7.0, 7.0, 3.2), voxel=0.11, spp=(1, 4, 16), rays=(4, 16, 64), psf_os=(1, 3),
                  mie_tol=(1e-1, 1e-2, 1e-3), angles=(128, 1024), mart=(1, 3), smart=(2, 6), lf_res=160, lf_particles=6, lf_rays=20000,
                  lf_planes=(9, 17, 33), lf_ref_planes=65, piv=((16,), (12,), (24, 16)), piv_final=(16, 12),
                  e2e=("fast", "default")),
    "full": dict(res=256, box=(20.0, 20.0, 6.0), voxel=0.11, spp=(1, 4, 16, 64, 256), rays=(4, 16, 64, 256, 1024),
                 psf_os=(1, 3, 5, 9), mie_tol=(1e-1, 1e-2, 1e-3, 1e-4), angles=(128, 1024, 4096), mart=(1, 2, 5, 10), smart=(2, 5, 10, 20),
                 lf_res=300, lf_particles=16, lf_rays=100000, lf_planes=(11, 21, 41, 81, 161), lf_ref_planes=321,
                 piv=((32,), (24,), (16,), (32, 24), (48, 32, 24), (48, 32, 24, 16)), piv_final=(24, 16),
                 e2e=("fast", "camera", "default", "accurate")),
}
REF = {"tolerance": 1e-5, "psf_oversample": 15}
DEFAULT = {"spp": 16, "rays_per_particle": 16, "psf_oversample": 5, "tolerance": 1e-3}  # the plugins' defaults
PPP = 0.05
_CAMS = ((25.0, 55.0), (-25.0, 55.0), (155.0, 55.0), (-155.0, 55.0))
_PSF = {"psf_f_number": 16.0, "psf_magnification": 0.093, "psf_energy_tolerance": 0.005}


log = logging.getLogger(__name__)


def _log(msg):
    log.info("accuracy-time: %s", msg)


@dataclass
class Row:
    stage: str
    knob: str
    value: str
    seconds: float
    error: float
    metric: str
    note: str = ""


def _timed(fn, *a, **kw):
    t0 = time.perf_counter()
    out = fn(*a, **kw)
    return out, time.perf_counter() - t0


# ------------------------------------------------------------------------- the scene
class _Scene:
    """The particles, the flow, the cameras and the voxel grid of one size preset."""

    def __init__(self, size: str, tmp: Path, seed: int = 0):
        from mitpiv.grid import VoxelGrid
        from mitpiv.io import write_particles_ply
        from mitpiv.physics.advection import advect
        from mitpiv.physics.camera import PinholeCamera, place_camera
        from mitpiv.physics.flows import flow_from_dict
        from mitpiv.physics.seeding import seed_box

        self.p = SIZES[size]
        self.tmp = tmp
        res = self.p["res"]
        bx, by, bz = self.p["box"]
        self.lo, self.hi = np.array([-bx / 2, -by / 2, -bz / 2]), np.array([bx / 2, by / 2, bz / 2])
        rot, pos = place_camera(azimuth_deg=_CAMS[0][0], elevation_deg=_CAMS[0][1], distance_mm=1000.0)
        cam0 = PinholeCamera((res, res), 85.0, 10.0, rotation=rot, position_mm=pos)
        parts = seed_box(self.lo, self.hi, ppp=PPP, camera=cam0, diameter_um=1.0, distribution="lognormal",
                         geometric_std=1.3, min_separation_mm=0.03, seed=seed)
        self.grid = VoxelGrid.from_bounds(self.lo, self.hi, self.p["voxel"])
        # vortex ring across the slab (axis +y), scaled to the box; dt gives 3 voxels at most
        self.flow = flow_from_dict({"kind": "vortex_ring", "ring_radius_mm": 0.3 * bx, "core_radius_mm": 0.15 * bx,
                                    "circulation_mm2_s": 100.0 * bx ** 2, "center": [0.0, -0.2 * by, 0.0],
                                    "axis": [0.0, 1.0, 0.0]})
        g = np.stack(np.meshgrid(self.grid.x_mm, self.grid.y_mm, self.grid.z_mm[len(self.grid.z_mm) // 2], indexing="ij"),
                     -1).reshape(-1, 3)
        vmax = float(np.linalg.norm(self.flow(g), axis=1).max())
        self.dt = 3.0 * self.p["voxel"] / vmax
        p1 = advect(parts.positions_mm, self.flow, dt_s=self.dt, substeps=8)
        self.positions = [parts.positions_mm, p1]
        self.diameters = parts.diameters_um
        self.ply = [write_particles_ply(tmp / f"p{k}.ply", p, parts.diameters_um, proxy_radius_mm=0.02)
                    for k, p in enumerate(self.positions)]

    def scene(self, frame=0, *, integrator="particle_tracer", rays=None, psf="fft", psf_oversample=None,
              tolerance=None, angles=None, cameras=(0, 1, 2, 3)):
        import mitsuba as mi  # noqa: F401  (variant set by accuracy_time: ensure_variant)

        from mitpiv.render.scene import load_dict

        res = self.p["res"]
        integ = {"type": integrator}
        if rays is not None:
            integ["rays_per_particle"] = int(rays)
        d = {"type": "scene", "integrator": integ,
             "laser": {"type": "laser_sheet", "id": "laser", "thickness": float(self.hi[2] - self.lo[2]),
                       "profile": "gaussian", "wavelength_nm": 532.0},
             "particles": {"type": "ellipsoidsmesh", "filename": str(self.ply[frame]), "extent": 1.0,
                           "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}},
                           "emitter": {"type": "tracer_particles", "sheet": {"type": "ref", "id": "laser"},
                                       "phase": {"type": "mie", "index": 1.45, **(
                                           {"angles": int(angles)} if angles is not None else
                                           {"tolerance": float(tolerance or DEFAULT["tolerance"])})}}}}
        for k in cameras:
            az, el = _CAMS[k]
            s = {"type": "distorted_pinhole", "id": f"cam{k}", "azimuth_deg": az, "elevation_deg": el,
                 "distance_mm": 1000.0, "focal_length_mm": 85.0, "pixel_pitch_um": 10.0, "psf": psf, **_PSF,
                 "film": {"type": "hdrfilm", "width": res, "height": res, "pixel_format": "luminance",
                          "rfilter": {"type": "catmullrom" if psf == "fft" else "box"}}}
            if psf == "fft":
                s["psf_oversample"] = int(psf_oversample or DEFAULT["psf_oversample"])
            d[f"cam{k}"] = s
        return load_dict(d)

    def render(self, sc, *, spp=0, seed=0):
        """Images of every sensor of ``sc`` and their mappings."""
        from mitpiv.reconstruct import mapping_from_metadata
        from mitpiv.render.render import render_sensor, sensor_model

        imgs, maps = [], []
        for s in sc.sensors():
            imgs.append(render_sensor(sc, s, spp=spp, seed=seed).astype(np.float64))
            maps.append(mapping_from_metadata({"camera": sensor_model(s)}))
        return imgs, maps


def _l1(img, ref):
    return float(np.abs(img - ref).sum() / ref.sum())


# ------------------------------------------------------------------------- stages
def _stage_render(S: _Scene) -> list[Row]:
    p = S.p

    def one(**kw):
        spp = kw.pop("spp", 0)
        sc, t_load = _timed(S.scene, cameras=(0,), **kw)
        (imgs, _), t = _timed(S.render, sc, spp=spp, seed=1)
        return imgs[0], t_load + t

    ref, t_ref = one(psf_oversample=REF["psf_oversample"], tolerance=REF["tolerance"])
    rows = [Row("render", "reference: particle tracing, FFT PSF",
                f"os {REF['psf_oversample']}, Mie tolerance {REF['tolerance']:g}", t_ref, 0.0, "L1 image error")]
    # camera tracing samples the PSF's oversampled film (psf_oversample^2 film pixels per
    # pixel, each with spp samples): it runs at the default oversampling
    series = [("camera tracing (spp, psf_oversample 5)", "spp", p["spp"],
               lambda v: one(integrator="direct", spp=v, tolerance=REF["tolerance"])),
              ("particle tracing, PSF jitter (rays per particle)", "rays", p["rays"],
               lambda v: one(psf="jitter", rays=v, tolerance=REF["tolerance"])),
              ("particle tracing, FFT PSF (psf_oversample)", "os", p["psf_os"],
               lambda v: one(psf_oversample=v, tolerance=REF["tolerance"])),
              ("Mie phase table (tolerance, default 1e-3)", "tol", p["mie_tol"],
               lambda v: one(psf_oversample=REF["psf_oversample"], tolerance=v)),
              ("Mie phase table (fixed angles)", "angles", p["angles"],
               lambda v: one(psf_oversample=REF["psf_oversample"], angles=v))]
    for knob, _, values, fn in series:
        fn(values[0])  # warm-up: kernel compilation of this configuration
        for v in values:
            img, t = fn(v)
            rows.append(Row("render", knob, str(v), t, _l1(img, ref), "L1 image error"))
            _log(f"render {knob} = {v}: {t:.2f} s, L1 {rows[-1].error:.3g}")
    return rows


def _lf_scene(S: _Scene, tmp: Path):
    """Sparse particles for the plenoptic camera (its own small field, 250 mm away)."""
    import mitsuba as mi

    from mitpiv.io import write_particles_ply
    from mitpiv.render.scene import load_dict

    res, n = S.p["lf_res"], S.p["lf_particles"]
    half = 0.35 * res * 5.5e-3 / 0.25  # 70 % of the object field
    rng = np.random.default_rng(7)
    # depths over +-10 mm, three times the camera's depth resolution (3.4 mm) each way
    pts = np.column_stack([rng.uniform(-half, half, (n, 2)), rng.uniform(-10.0, 10.0, n)])
    write_particles_ply(tmp / "lf.ply", pts, 2.0, proxy_radius_mm=0.01)
    sensor = {"type": "plenoptic", "pixel_pitch_um": 5.5, "focal_length_mm": 50.0, "f_number": 2.8,
              "focus_distance_mm": 250.0, "mla_pitch_um": 55.0,
              "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 250.0], target=[0, 0, 0], up=[0, 1, 0]),
              "film": {"type": "hdrfilm", "width": res, "height": res, "pixel_format": "luminance",
                       "rfilter": {"type": "box"}}}
    sc = load_dict({"type": "scene", "integrator": {"type": "particle_tracer", "rays_per_particle": S.p["lf_rays"]},
                    "sensor": sensor, "laser": {"type": "laser_sheet", "id": "laser", "thickness": 400.0},
                    "particles": {"type": "ellipsoidsmesh", "filename": str(tmp / "lf.ply"), "extent": 1.0,
                                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}},
                                  "emitter": {"type": "tracer_particles", "sheet": {"type": "ref", "id": "laser"}}}})
    white = load_dict({"type": "scene", "integrator": {"type": "direct"}, "sensor": sensor, "env": {"type": "constant"}})
    raw = np.array(mi.render(sc, spp=0, seed=0), dtype=np.float32)[..., 0]
    wimg = np.array(mi.render(white, spp=64, seed=0), dtype=np.float32)[..., 0]
    return pts, raw, wimg, sc.sensors()[0].camera


def _depths(vol, grid, pts) -> np.ndarray:
    """Depth [mm] of each particle: the brightest voxel of a +-2 voxel column about its true
    lateral position, refined by a 3-point parabola along z."""
    zs = []
    for i, j, _ in np.rint(grid.to_voxel(pts)).astype(int):
        col = vol[:, max(j - 2, 0):j + 3, max(i - 2, 0):i + 3].reshape(vol.shape[0], -1).max(axis=1)
        k = int(np.argmax(col))
        dk = 0.0
        if 0 < k < len(col) - 1:
            a, b, c = col[k - 1], col[k], col[k + 1]
            den = a - 2 * b + c
            dk = 0.5 * (a - c) / den if den < 0 else 0.0
        zs.append(grid.z_mm[0] + (k + dk) * grid.voxel_mm[2])
    return np.array(zs)


def _rms(a) -> float:
    return float(np.sqrt(np.mean(np.square(a))))


def _stage_lightfield(S: _Scene) -> list[Row]:
    from mitpiv.lightfield import decode
    from mitpiv.reconstruct import VoxelGrid, plenoptic_volume

    pts, raw, white, cam = _lf_scene(S, S.tmp)
    half = float(np.abs(pts[:, :2]).max()) + 0.3

    def one(interp, nz):
        g = VoxelGrid.from_bounds((-half, -half, -12.0), (half, half, 12.0), (0.044, 0.044, 24.0 / (nz - 1)))
        lf, t1 = _timed(decode, raw, optics=cam, white=white, interpolation=interp)
        vol, t2 = _timed(plenoptic_volume, lf, g, method="multiplicative")
        return _depths(vol, g, pts), t1 + t2

    one("linear", 9)  # warm-up: refocus kernels
    z_ref, t_ref = one("cubic", S.p["lf_ref_planes"])
    metric = "RMS depth difference from the reference [mm]"
    rows = [Row("lightfield", "reference: cubic decode", f"{S.p['lf_ref_planes']} planes", t_ref, 0.0, metric,
                f"RMS depth error against the truth {_rms(z_ref - pts[:, 2]):.2f} mm; depth resolution "
                f"{cam.depth_resolution():.2f} mm")]
    nz = S.p["lf_planes"][-1]
    for knob, interp, n in ([(f"decoder interpolation ({nz} planes)", i, nz) for i in ("nearest", "linear", "cubic")]
                            + [("focal planes (linear decode)", "linear", n) for n in S.p["lf_planes"]]):
        z, t = one(interp, n)
        e = _rms(z - z_ref)
        rows.append(Row("lightfield", knob, interp if knob.startswith("decoder") else str(n), t, e, metric,
                        f"against the truth {_rms(z - pts[:, 2]):.2f} mm"))
        _log(f"lightfield {interp} {n} planes: {t:.2f} s, depth RMS {e:.3f} mm from the reference")
    return rows


def _reference_images(S: _Scene, frame: int):
    return S.render(S.scene(frame), seed=1)


def _stage_reconstruct(S: _Scene, imgs, maps) -> list[Row]:
    from mitpiv.analysis import quality_q, truth_volume
    from mitpiv.reconstruct import reconstruct_volume

    truth = truth_volume(S.positions[0], S.grid)
    rows = []
    runs = [("MLOS", "mlos", [1])] + [(m.upper() + " (iterations)", m, list(S.p[m])) for m in ("mart", "smart")]
    reconstruct_volume(imgs, maps, S.grid, "smart", iterations=1)  # warm-up: Numba kernels
    for knob, method, its in runs:
        for it in its:
            (vol, _), t = _timed(reconstruct_volume, imgs, maps, S.grid, method, iterations=it)
            q = quality_q(vol, truth)
            rows.append(Row("reconstruct", knob, "-" if method == "mlos" else str(it), t, 1.0 - q, "1 - Q",
                            f"Q = {q:.3f}"))
            _log(f"reconstruct {method} {it}: {t:.2f} s, Q {q:.3f}")
    return rows


def _velocity_rms(field, S) -> float:
    from mitpiv.analysis import velocity_error

    r = velocity_error(field, S.flow)
    return float(np.sqrt(np.sum(np.square(r["rms_vox"]))))


def _stage_piv(S: _Scene) -> list[Row]:
    from mitpiv.analysis import piv3d, truth_volume

    va, vb = (truth_volume(p, S.grid) for p in S.positions)
    rows = []
    piv3d(va, vb, S.grid, windows=S.p["piv"][0], overlap=0.5)  # warm-up
    for w in S.p["piv"]:
        knob = "passes, windows" if len(w) > 1 else "single pass, window"
        field, t = _timed(piv3d, va, vb, S.grid, windows=w, overlap=0.75, dt_s=S.dt)
        e = _velocity_rms(field, S)
        rows.append(Row("piv", knob, "-".join(map(str, w)), t, e, "RMS velocity error [voxels]"))
        _log(f"piv {w}: {t:.2f} s, RMS {e:.4f} voxels")
    return rows


def _e2e_configs(S: _Scene) -> dict:
    f = S.p["piv_final"]
    return {
        "fast": dict(integrator="particle_tracer", psf_oversample=1, tolerance=1e-1, method="mlos", iterations=1,
                     windows=(f[0],)),
        "camera": dict(integrator="direct", spp=16, psf_oversample=5, tolerance=1e-3, method="mart", iterations=5,
                       windows=(3 * f[0] // 2, f[0])),
        "default": dict(integrator="particle_tracer", psf_oversample=5, tolerance=1e-3, method="mart", iterations=5,
                        windows=(3 * f[0] // 2, f[0])),
        "accurate": dict(integrator="particle_tracer", psf_oversample=9, tolerance=1e-4, method="smart", iterations=20,
                         windows=(3 * f[0] // 2, f[0], f[1])),
    }


def _stage_end_to_end(S: _Scene) -> list[Row]:
    from mitpiv.analysis import piv3d
    from mitpiv.reconstruct import reconstruct_volume

    rows = []
    configs = _e2e_configs(S)
    for name in S.p["e2e"]:
        c = configs[name]
        times = {"render": 0.0, "reconstruct": 0.0}
        vols = []
        for frame in (0, 1):
            sc, t0 = _timed(S.scene, frame, integrator=c["integrator"], psf_oversample=c["psf_oversample"],
                            tolerance=c["tolerance"])
            (imgs, maps), t1 = _timed(S.render, sc, spp=c.get("spp", 0), seed=frame + 1)
            (vol, _), t2 = _timed(reconstruct_volume, imgs, maps, S.grid, c["method"], iterations=c["iterations"])
            times["render"] += t0 + t1
            times["reconstruct"] += t2
            vols.append(vol)
        field, times["piv"] = _timed(piv3d, vols[0], vols[1], S.grid, windows=c["windows"], overlap=0.75, dt_s=S.dt)
        e = _velocity_rms(field, S)
        total = sum(times.values())
        desc = (f"{'camera tracing ' + str(c['spp']) + ' spp' if c['integrator'] == 'direct' else 'particle tracing'}, "
                f"psf_oversample {c['psf_oversample']}, Mie tolerance {c['tolerance']:g}, {c['method'].upper()}"
                f"{'' if c['method'] == 'mlos' else ' ' + str(c['iterations'])}, windows "
                f"{'-'.join(map(str, c['windows']))}")
        note = ", ".join(f"{k} {v:.1f} s" for k, v in times.items())
        rows.append(Row("end_to_end", name, desc, total, e, "RMS velocity error [voxels]", note))
        _log(f"end to end {name}: {total:.1f} s ({note}), velocity RMS {e:.4f} voxels")
    return rows


# ------------------------------------------------------------------------- output
def _intro(size: str, S: _Scene, seconds: float) -> tuple[str, str]:
    return (f"Accuracy versus time ({size})",
            f"{S.p['res']}x{S.p['res']} px cameras, {len(S.positions[0])} particles ({PPP} ppp), grid "
            f"{'x'.join(map(str, S.grid.shape[::-1]))} voxels of {S.p['voxel']} mm, dt {1e3 * S.dt:.2f} ms "
            f"(3 voxels at most). Total {seconds:.0f} s.")


def accuracy_time(out_dir, *, size: str = "full", stages=None, seed: int = 0) -> list[Row]:
    """Measure every knob of ``stages`` (default all of :data:`STAGES`) on the ``size``
    preset ("quick" or "full"); writes the CSV, the Markdown tables and the Pareto plots
    into ``out_dir`` and returns the rows."""
    if size not in SIZES:
        raise ConfigError(f"accuracy-time: size={size!r} is not one of {sorted(SIZES)}.")
    stages = list(STAGES if stages is None else stages)
    bad = [s for s in stages if s not in STAGES]
    if bad or not stages:
        raise ConfigError(f"accuracy-time: stages {bad or stages!r} not known; choose from {list(STAGES)}.")
    from mitpiv.render.variant import ensure_variant

    ensure_variant()  # importing mitpiv selects no variant; the stages build Mitsuba values directly

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    t_all = time.perf_counter()
    rows: list[Row] = []
    with tempfile.TemporaryDirectory() as td:
        S = _Scene(size, Path(td), seed)
        _log(f"{size}: {len(S.positions[0])} particles, grid {S.grid.shape[::-1]}, stages {stages}")
        for st in stages:
            _log(f"stage {st} ...")
            if st == "render":
                rows += _stage_render(S)
            elif st == "lightfield":
                rows += _stage_lightfield(S)
            elif st == "reconstruct":
                imgs, maps = _reference_images(S, 0)
                rows += _stage_reconstruct(S, imgs, maps)
            elif st == "piv":
                rows += _stage_piv(S)
            else:
                rows += _stage_end_to_end(S)
            seconds = time.perf_counter() - t_all
            _write(out, rows, [s for s in stages if any(r.stage == s for r in rows)], size, S, seconds)
    _log(f"done in {seconds:.0f} s: {out / 'accuracy_time.md'}")
    return rows


def _write(out: Path, rows: list[Row], stages, size, S, seconds):
    """(Re)write the CSV, the plots and the tables of the stages measured so far."""
    from mitpiv.io.atomic import atomic_path

    with atomic_path(out / "accuracy_time.csv", suffix=".csv") as tmp:
        with open(tmp, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["stage", "knob", "value", "seconds", "error", "metric", "note"])
            for r in rows:
                w.writerow([r.stage, r.knob, r.value, f"{r.seconds:.4f}", f"{r.error:.6g}", r.metric, r.note])
    from mitpiv.studies.report import accuracy_report, write

    title, intro = _intro(size, S, seconds)
    write(accuracy_report(rows, title=title, intro=intro, stages=[st for st in STAGES if st in stages]), out,
          name="accuracy_time.md")
