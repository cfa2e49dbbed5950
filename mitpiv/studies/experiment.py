"""Experiment runner: one TOML file takes a PIV experiment from particles to an evaluated
reconstruction and vector field, in a run folder of stages that are written atomically
and resumed when rerun.

Experiment file (paths relative to it; every table but ``scene`` optional)::

    name = "tomo4-small"
    seed = 0
    kind = "particles"  # the default; "backlit": plenoptic droplet tracking (mitpiv.studies.backlit)
    [scene]            xml = "scene.xml"; params = { resolution = 256 }
    [seeding]          box_min_mm, box_max_mm, one of count | concentration_per_mm3 | ppp
                       (particles per pixel of ``density_sensor``, default the first
                       rendered sensor) | particles_per_microlens (of a plenoptic
                       ``density_sensor``; give both and the sensor's kind picks),
                       diameter_um, distribution, geometric_std,
                       min_separation_mm, proxy_radius_mm
    [flow]             kind = "vortex_ring", ... (mitpiv.physics.flows), dt_s
    [render]           spp, sensors (ids of the scene's sensors to render; default all)
    [sensor]           SensorModel fields (bit_depth, peak_photons, shot_noise, ...)
    [reconstruction]   method (mlos | mart | smart | sapiv | plenoptic | drt-mart),
                       bounds_mm (6), voxel_mm, iterations, mu, weights, interpolation,
                       combine, fuse_normalise, rays_per_pixel, camera_model ("true" |
                       "undistorted": the cameras' lens distortion left uncorrected)
    [piv]              windows, overlap, deform, interpolation
    [particles]        method, threshold_rel, radius_voxels

Stages, each a sub-folder of the run folder completed by renaming a temporary folder
(a killed run leaves no half-written stage; a rerun skips the stages whose inputs did
not change): ``particles`` (seeding, advection, PLY files, truth), ``render`` (EXR per
camera and frame), ``sensor`` (counts, only with a [sensor] table), ``reconstruct``
(volume per frame), ``evaluate`` (particles and quality per frame), ``piv`` (vector field
and its error against the flow), ``report`` (report.md and PNG plots). ``metrics.json``
and ``timings.json`` (wall time per stage) are written at the end.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import sys
import time
import tomllib
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError

STAGES = ("particles", "render", "sensor", "reconstruct", "evaluate", "piv", "report")
_TABLES = {"scene", "seeding", "flow", "render", "sensor", "reconstruction", "piv", "particles"}
_TOP = {"name", "seed"} | _TABLES


def read_toml(path, what: str = "experiment") -> dict:
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"{what} file {str(path)!r} does not exist.")
    try:
        return tomllib.loads(path.read_text())
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{what} file {str(path)!r} is not valid TOML: {e}.") from None


def load_experiment(path, overrides: dict | None = None) -> dict:
    """Read and check an experiment TOML file; returns the config with absolute paths.
    ``overrides`` maps dotted keys ("scene.params.resolution") to values set before the checks."""
    path = Path(path)
    cfg = read_toml(path)
    for key, value in (overrides or {}).items():
        set_dotted(cfg, key, value)
    cfg.setdefault("name", path.stem)
    cfg.setdefault("seed", 0)
    if not isinstance(cfg["seed"], int) or cfg["seed"] < 0:
        raise ConfigError(f"experiment {path.name}: seed must be an integer >= 0, got {cfg['seed']!r}.")
    kind = cfg.get("kind", "particles")
    if kind == "backlit":
        from mitpiv.studies.backlit import check_backlit

        return check_backlit(cfg, path.name)
    if kind != "particles":
        raise ConfigError(f"experiment {path.name}: kind must be \"particles\" (the default: particle images, "
                          f"reconstruction, PIV) or \"backlit\" (backlit plenoptic droplet tracking), got {kind!r}.")
    cfg.pop("kind", None)
    unknown = set(cfg) - _TOP
    if unknown:
        raise ConfigError(f"experiment {path.name}: unknown key(s) {sorted(unknown)}; expected {sorted(_TOP)}.")
    if "scene" not in cfg or "xml" not in cfg["scene"]:
        raise ConfigError(f"experiment {path.name}: [scene] needs xml = \"path/to/scene.xml\".")
    xml = (path.parent / cfg["scene"]["xml"]).resolve()
    if not xml.is_file():
        raise ConfigError(f"experiment {path.name}: [scene] xml = {cfg['scene']['xml']!r} does not exist "
                          f"(resolved to {xml}).")
    cfg["scene"]["xml"] = str(xml)
    for t in _TABLES - {"sensor"}:
        cfg.setdefault(t, {})
    if "dt_s" not in cfg["flow"]:
        raise ConfigError(f"experiment {path.name}: [flow] needs dt_s (the time between the two frames).")
    if "bounds_mm" not in cfg["reconstruction"] or len(cfg["reconstruction"]["bounds_mm"]) != 6:
        raise ConfigError(f"experiment {path.name}: [reconstruction] needs bounds_mm = [xmin, xmax, ymin, ymax, zmin, zmax].")
    if "voxel_mm" not in cfg["reconstruction"]:
        raise ConfigError(f"experiment {path.name}: [reconstruction] needs voxel_mm (one size or [dx, dy, dz]).")
    return cfg


def set_dotted(cfg: dict, key: str, value) -> None:
    """Set ``cfg["a"]["b"]["c"] = value`` for key "a.b.c", creating tables on the way."""
    parts = str(key).split(".")
    if not all(parts):
        raise ConfigError(f"parameter name {key!r} is not a dotted key like 'reconstruction.iterations'.")
    node = cfg
    for p in parts[:-1]:
        nxt = node.setdefault(p, {})
        if not isinstance(nxt, dict):
            raise ConfigError(f"parameter {key!r}: {p!r} is a value, not a table.")
        node = nxt
    node[parts[-1]] = value


def _hash(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, default=str).encode()).hexdigest()[:16]


class _Stage:
    """A stage folder completed atomically: work in ``<name>.tmp``, then rename."""

    def __init__(self, run_dir: Path, name: str, key: str):
        self.final = run_dir / name
        self.tmp = run_dir / f".{name}.tmp"
        self.key = key

    def done(self) -> bool:
        m = self.final / "stage.json"
        return m.is_file() and json.loads(m.read_text()).get("key") == self.key

    def __enter__(self) -> Path:
        shutil.rmtree(self.tmp, ignore_errors=True)
        self.tmp.mkdir(parents=True)
        return self.tmp

    def __exit__(self, exc_type, exc, tb):
        if exc_type is not None:
            shutil.rmtree(self.tmp, ignore_errors=True)
            return False
        (self.tmp / "stage.json").write_text(json.dumps({"key": self.key}))
        old = self.final.with_name(f".{self.final.name}.old")
        shutil.rmtree(old, ignore_errors=True)
        if self.final.exists():
            os.replace(self.final, old)
        os.replace(self.tmp, self.final)
        shutil.rmtree(old, ignore_errors=True)
        return False


def _log(msg):
    print(msg, file=sys.stderr, flush=True)


def _stage_particles(cfg, out: Path):
    from mitpiv.io import write_particles_ply, write_truth
    from mitpiv.physics.advection import advect
    from mitpiv.physics.flows import flow_from_dict
    from mitpiv.physics.seeding import seed_box

    s = dict(cfg["seeding"])
    box_min = s.pop("box_min_mm", None)
    box_max = s.pop("box_max_mm", None)
    if box_min is None or box_max is None:
        raise ConfigError("experiment: [seeding] needs box_min_mm and box_max_mm.")
    proxy = float(s.pop("proxy_radius_mm", 0.02))
    density_sensor = s.pop("density_sensor", None)
    ppp, ppm = s.pop("ppp", None), s.pop("particles_per_microlens", None)
    if ppp is not None or ppm is not None:
        if "count" in s or "concentration_per_mm3" in s:
            raise ConfigError("experiment: [seeding] give one of count, concentration_per_mm3, ppp or "
                              "particles_per_microlens (ppp and particles_per_microlens may go together: the "
                              "density_sensor's type picks one).")
        s["count"] = _count_for_density(cfg, out, box_min, box_max, ppp=ppp, ppm=ppm, sensor_id=density_sensor)
    particles = seed_box(box_min, box_max, seed=cfg["seed"], **s)
    f = dict(cfg["flow"])
    dt = float(f.pop("dt_s"))
    flow = flow_from_dict(f)
    p1 = advect(particles.positions_mm, flow, dt_s=dt, t0_s=0.0, substeps=8)
    for k, p in enumerate((particles.positions_mm, p1)):
        write_particles_ply(out / f"particles_{k}.ply", p, particles.diameters_um, proxy_radius_mm=proxy)
    write_truth(out / "truth.npz", positions_mm=[particles.positions_mm, p1], times_s=[0.0, dt],
                diameters_um=particles.diameters_um, flow=flow.to_dict(), extra={"seed": cfg["seed"]})
    # the scene reads particles_$frame.ply beside itself: the run gets its own copy of the XML
    shutil.copy(cfg["scene"]["xml"], out / "scene.xml")
    return {"n_particles": len(particles)}


def visible_fraction(camera_meta: dict, box_min, box_max, *, samples: int = 200_000, seed: int = 0) -> float:
    """Fraction of a uniformly seeded box that images onto the sensor of a rendered camera
    (its EXR metadata ``camera``): pinhole projection, or for a plenoptic camera the chief
    ray through the main-lens centre onto the microlens plane, scaled to the sensor."""
    lo, hi = np.asarray(box_min, float), np.asarray(box_max, float)
    pts = np.random.default_rng(seed).uniform(lo, hi, size=(samples, 3))
    if camera_meta.get("type") == "plenoptic":
        from mitpiv.physics.plenoptic import PlenopticCamera

        cam = PlenopticCamera.from_dict(camera_meta)
        loc = cam.world_to_local(pts)
        front = loc[:, 2] > 0
        z = np.where(front, loc[:, 2], 1.0)
        uv = cam.sensor_mm_to_px(-cam.image_distance_mm * cam.image_scale * loc[:, :2] / z[:, None])
        w, h = cam.resolution
    else:
        from mitpiv.reconstruct.mapping import mapping_from_metadata

        m = mapping_from_metadata({"camera": camera_meta})
        front = m.visible(pts)
        uv = m.project(pts)
        w, h = m.resolution
    inside = front & (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
    return float(inside.mean())


def _count_for_density(cfg, out: Path, box_min, box_max, *, ppp, ppm, sensor_id):
    """Particle count for a target per-pixel (or per-microlens) density in one sensor."""
    from mitpiv.io import write_particles_ply
    from mitpiv.render.render import sensor_model
    from mitpiv.render.scene import load_scene

    for v, name in ((ppp, "ppp"), (ppm, "particles_per_microlens")):
        if v is not None and (isinstance(v, bool) or not isinstance(v, int | float) or not v > 0):
            raise ConfigError(f"experiment: [seeding] {name} must be a number > 0, got {v!r}.")
    # the scene reads particles_$frame.ply beside itself: a one-particle placeholder to load it
    xml = out / "scene.xml"
    shutil.copy(cfg["scene"]["xml"], xml)
    centre = 0.5 * (np.asarray(box_min, float) + np.asarray(box_max, float))
    for k in (0, 1):
        write_particles_ply(out / f"particles_{k}.ply", centre[None], 1.0, proxy_radius_mm=0.01)
    sc = load_scene(xml, frame=0, params=cfg["scene"].get("params"))
    sensors = {(s.id() or f"sensor{i}"): s for i, s in enumerate(sc.sensors())}
    wanted = sensor_id or (cfg["render"].get("sensors") or [next(iter(sensors))])[0]
    if wanted not in sensors:
        raise ConfigError(f"experiment: [seeding] density_sensor = {wanted!r} is not in the scene; its sensors are "
                          f"{sorted(sensors)}.")
    meta = sensor_model(sensors[wanted])
    if ppp is not None and ppm is not None:  # both: the density sensor's kind picks
        ppp, ppm = (None, ppm) if meta.get("type") == "plenoptic" else (ppp, None)
    what = "ppp" if ppp is not None else "particles_per_microlens"
    if ppm is not None and meta.get("type") != "plenoptic":
        raise ConfigError(f"experiment: [seeding] particles_per_microlens needs a plenoptic density_sensor; "
                          f"{wanted!r} is a {meta.get('type')!r}. Use ppp for pinhole cameras.")
    frac = visible_fraction(meta, box_min, box_max, seed=cfg["seed"])
    if frac == 0:
        raise ConfigError(f"experiment: sensor {wanted!r} sees no part of the seeding box; cannot target a {what}.")
    w, h = meta["resolution"]
    if ppp is not None:
        return int(round(ppp * w * h / frac))
    from mitpiv.physics.plenoptic import PlenopticCamera

    lenslets = int(np.prod(PlenopticCamera.from_dict(meta).mla_count))
    return int(round(ppm * lenslets / frac))


def _stage_render(cfg, run: Path, out: Path):
    from mitpiv.render.render import render_scene

    files = render_scene(run / "particles" / "scene.xml", out_dir=out, frames=(0, 1),
                         params=cfg["scene"].get("params"), spp=cfg["render"].get("spp"), seed=cfg["seed"],
                         progress=True, sensors=cfg["render"].get("sensors"))
    return {"images": [f.name for f in files]}


def _images(run: Path, frame: int, source: str):
    from mitpiv.io import read_exr

    files = sorted((run / source).glob(f"*_frame{frame:03d}.exr"))
    if not files:
        raise ConfigError(f"experiment: no images of frame {frame} in {run / source}.")
    data = [read_exr(f) for f in files]
    return [np.asarray(img if img.ndim == 2 else img[..., 0], dtype=np.float64) for img, _ in data], \
        [m for _, m in data], files


def _stage_sensor(cfg, run: Path, out: Path):
    from mitpiv.imaging import SensorModel, apply_sensor
    from mitpiv.io import write_exr

    model = SensorModel(**cfg["sensor"])
    for frame in (0, 1):
        imgs, metas, files = _images(run, frame, "render")
        for img, meta, f in zip(imgs, metas, files, strict=True):
            counts = apply_sensor(img, model, seed=cfg["seed"] * 1000 + frame)
            write_exr(out / f.name, np.asarray(counts, dtype=np.float32), {**meta, "sensor": model.to_dict()})
    return {}


def _grid(cfg):
    from mitpiv.reconstruct import VoxelGrid

    b = cfg["reconstruction"]["bounds_mm"]
    return VoxelGrid.from_bounds((b[0], b[2], b[4]), (b[1], b[3], b[5]), cfg["reconstruction"]["voxel_mm"])


def _stage_reconstruct(cfg, run: Path, out: Path, source: str):
    from mitpiv.io import write_volume
    from mitpiv.reconstruct.images import reconstruct_images

    r = dict(cfg["reconstruction"])
    method = r.get("method", "mart")
    model = r.get("camera_model", "true")
    if model not in ("true", "undistorted"):
        raise ConfigError(f"experiment: [reconstruction] camera_model = {model!r}; use \"true\" (the rendered "
                          f"cameras) or \"undistorted\" (their lens distortion ignored, as when it is not calibrated).")
    grid = _grid(cfg)
    info = {}
    for frame in (0, 1):
        imgs, metas, _ = _images(run, frame, source)
        if model == "undistorted":
            metas = [_undistorted(m) for m in metas]
        vol, inf = reconstruct_images(imgs, metas, grid, method, iterations=int(r.get("iterations", 5)),
                                      mu=float(r.get("mu", 1.0)), weights=r.get("weights", "circle"),
                                      interpolation=r.get("interpolation", "linear"),
                                      combine=r.get("combine", "multiplicative"),
                                      fuse_normalise=r.get("fuse_normalise", "histogram"),
                                      rays_per_pixel=int(r.get("rays_per_pixel", 16)), progress=True)
        if inf:
            info[f"frame{frame}"] = {k: v for k, v in inf.items() if isinstance(v, int | float | str)}
        write_volume(out / f"volume_{frame}.npz", vol, {"method": method, "grid": grid.to_dict()})
    return info


def _undistorted(meta: dict) -> dict:
    """The metadata of a pinhole camera with its lens distortion set to zero."""
    cam = dict(meta.get("camera") or {})
    if isinstance(cam.get("distortion"), dict):
        cam["distortion"] = {k: (0.0 if isinstance(v, int | float) else v) for k, v in cam["distortion"].items()}
    return {**meta, "camera": cam}


def _volume(run: Path, frame: int):
    from mitpiv.io import read_volume

    return read_volume(run / "reconstruct" / f"volume_{frame}.npz")[0]


def _stage_evaluate(cfg, run: Path, out: Path):
    from mitpiv import analysis
    from mitpiv.io import read_truth

    p = cfg["particles"]
    grid = _grid(cfg)
    truth = read_truth(run / "particles" / "truth.npz")
    metrics = {}
    for frame in (0, 1):
        metrics[f"frame{frame}"], res = analysis.evaluate_volume(
            _volume(run, frame), grid, truth["positions_mm"][frame], method=p.get("method", "gauss3"),
            threshold_rel=float(p.get("threshold_rel", 0.1)), radius_voxels=float(p.get("radius_voxels", 2.0)))
        res.plot(out / f"particle_errors_{frame}.png", title=f"frame {frame} particle position error")
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2))
    return metrics


def _stage_piv(cfg, run: Path, out: Path):
    from mitpiv import analysis
    from mitpiv.io import read_truth
    from mitpiv.physics.flows import flow_from_dict

    grid = _grid(cfg)
    truth = read_truth(run / "particles" / "truth.npz")
    dt = float(truth["times_s"][1] - truth["times_s"][0])
    pv = dict(cfg["piv"])
    field = analysis.piv3d(_volume(run, 0), _volume(run, 1), grid, windows=pv.get("windows", (64, 48, 32)),
                           overlap=pv.get("overlap", 0.75), deform=bool(pv.get("deform", True)),
                           interpolation=pv.get("interpolation", "cubic"), dt_s=dt, progress=True)
    res = analysis.velocity_error(field, flow_from_dict(truth["flow"]))
    metrics = analysis.velocity_error_summary(res)
    field.info["velocity_error"] = metrics
    field.save(out / "field.npz")
    analysis.plot_velocity_error(field, res, out / "velocity_error.png")
    (out / "metrics.json").write_text(json.dumps(metrics, indent=2))
    return metrics


def _stage_report(cfg, run: Path, out: Path, metrics: dict, timings: dict, source: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    imgs, _, files = _images(run, 0, source)
    fig, axs = plt.subplots(1, len(imgs), figsize=(3.2 * len(imgs), 3.2), squeeze=False)
    for ax, img, f in zip(axs[0], imgs, files, strict=True):
        ax.imshow(img, cmap="gray", vmax=np.percentile(img, 99.9) or None)
        ax.set_title(f.stem, fontsize=8)
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(out / "sensor_images.png", dpi=90)
    plt.close(fig)
    vol = _volume(run, 0)
    fig, axs = plt.subplots(1, 2, figsize=(9, 4))
    for ax, proj, title, aspect in ((axs[0], vol.max(axis=0), "frame 0 volume, max along z", "equal"),
                                    (axs[1], vol.max(axis=1), "max along y", "auto")):
        # a few bright voxels would hide the rest: the colour scale ends at the 99.5th percentile
        ax.imshow(proj, cmap="magma", origin="lower", aspect=aspect, vmax=float(np.percentile(proj, 99.5)) or None)
        ax.set_title(title)
    fig.tight_layout()
    fig.savefig(out / "volume_projections.png", dpi=90)
    plt.close(fig)
    # focal-stack slices: the frame-0 volume at five depths through the measurement volume
    grid = _grid(cfg)
    ks = np.linspace(0, vol.shape[0] - 1, 5).round().astype(int)
    fig, axs = plt.subplots(1, len(ks), figsize=(3.0 * len(ks), 3.2))
    top = float(np.percentile(vol, 99.9)) or None
    for ax, k in zip(axs, ks, strict=True):
        ax.imshow(vol[k], cmap="magma", origin="lower", vmax=top)
        ax.set_title(f"z = {grid.z_mm[k]:+.2f} mm", fontsize=9)
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(out / "volume_slices.png", dpi=90)
    plt.close(fig)
    figures = ["sensor_images.png", "volume_projections.png", "volume_slices.png"]
    _, metas, files = _images(run, 0, source)
    plen = [(f, m) for f, m in zip(files, metas, strict=True) if (m.get("camera") or {}).get("type") == "plenoptic"]
    if plen:
        from mitpiv.lightfield import decode

        lf = decode(plen[0][0])
        nv, nu, nt, ns = lf.data.shape
        mosaic = lf.mosaic()
        fig, ax = plt.subplots(figsize=(7, 7 * nv * nt / max(nu * ns, 1)))
        ax.imshow(mosaic, cmap="gray", vmax=float(np.percentile(mosaic, 99.9)) or None)
        ax.set_title(f"{plen[0][0].stem}: sub-aperture images ({nu} x {nv} views)", fontsize=9)
        ax.axis("off")
        fig.tight_layout()
        fig.savefig(out / "subaperture_mosaic.png", dpi=90)
        plt.close(fig)
        figures.append("subaperture_mosaic.png")
    for name in ("particle_errors_0.png", "particle_errors_1.png"):
        shutil.copy(run / "evaluate" / name, out / name)
    shutil.copy(run / "piv" / "velocity_error.png", out / "velocity_error.png")
    ev, pv = metrics["evaluate"], metrics["piv"]
    lines = [f"# {cfg['name']}", "", f"Scene `{Path(cfg['scene']['xml']).name}`, seed {cfg['seed']}, "
             f"method {cfg['reconstruction'].get('method', 'mart')}.", "", "## Reconstruction and particles", "",
             "| frame | Q | Q* | Q' | SNR | detected | ghosts | u95 x / y / z [voxels] |", "|---|---|---|---|---|---|---|---|"]
    for frame in (0, 1):
        m = ev[f"frame{frame}"]
        pr = m["particles"]
        u = pr.get("u95_vox", [float("nan")] * 3)
        q_rank = m["Q'"]
        lines.append(f"| {frame} | {m['Q']:.3f} | {m['Q*']:.3f} | {q_rank:.3f} | {m['SNR']:.1f} | "
                     f"{100 * pr['detection_rate']:.1f} % | {100 * pr['ghost_fraction']:.1f} % | "
                     f"{u[0]:.3f} / {u[1]:.3f} / {u[2]:.3f} |")
    r, b = pv["rms_vox"], pv["bias_vox"]
    lines += ["", "## 3D PIV", "", f"{pv['n']} vectors, outlier ratio {100 * pv['outlier_ratio']:.2f} %.", "",
              "| | u | v | w |", "|---|---|---|---|",
              f"| RMS error [voxels] | {r[0]:.4f} | {r[1]:.4f} | {r[2]:.4f} |",
              f"| bias [voxels] | {b[0]:+.4f} | {b[1]:+.4f} | {b[2]:+.4f} |", "", "## Wall time per stage", "",
              "| stage | seconds |", "|---|---|"]
    lines += [f"| {k} | {v:.1f} |" for k, v in timings.items()]
    lines += [""] + [f"![{f[:-4].replace('_', ' ')}]({f})\n" for f in figures]
    lines += ["![particle errors](particle_errors_0.png)", "", "![velocity error](velocity_error.png)", ""]
    (out / "report.md").write_text("\n".join(lines))
    return {}


def run_experiment(path, out_dir) -> dict:
    """Run (or resume) the experiment in ``path`` into ``out_dir``; returns the metrics.

    Each stage is skipped when its folder holds a completion record with the same inputs
    (the experiment's settings that reach it); a changed setting reruns that stage and
    the ones after it. The same seed gives the same metrics.
    """
    return run_config(load_experiment(path), out_dir)


def run_stages(cfg: dict, run: Path, parts: dict, call) -> tuple[dict, dict]:
    """Run the stages of ``parts`` (stage name -> the config tables it reads, in order) into
    the run folder ``run``. A stage's key hashes its tables and the previous stage's key, so
    a changed setting reruns that stage and the ones after it; a stage whose folder records
    the same key is skipped (its saved result and time are read back). Otherwise
    ``call(stage, tmp_dir, metrics, timings)`` fills a temporary folder, which is renamed
    into place with the result (``stage_result.json``) and wall time (``seconds.txt``).
    Returns (metrics, timings) per stage."""
    run.mkdir(parents=True, exist_ok=True)
    (run / "experiment.json").write_text(json.dumps(cfg, indent=2, default=str))
    name, keys, prev = cfg["name"], {}, ""
    for st, tables in parts.items():
        prev = _hash([prev] + [cfg.get(t) for t in tables])
        keys[st] = prev
    timings, metrics = {}, {}
    for st in keys:
        stage = _Stage(run, st, keys[st])
        if stage.done():
            _log(f"[{name}] {st}: done earlier, skipped")
            saved = stage.final / "stage_result.json"
            if saved.is_file():
                metrics[st] = json.loads(saved.read_text())
            t_file = stage.final / "seconds.txt"
            timings[st] = float(t_file.read_text()) if t_file.is_file() else 0.0
            continue
        _log(f"[{name}] {st} ...")
        t0 = time.perf_counter()
        with stage as tmp:
            result = call(st, tmp, metrics, timings)
            el = time.perf_counter() - t0
            (tmp / "stage_result.json").write_text(json.dumps(result, indent=2, default=float))
            (tmp / "seconds.txt").write_text(f"{el:.3f}")
        timings[st] = el
        metrics[st] = json.loads((run / st / "stage_result.json").read_text())
        _log(f"[{name}] {st}: {el:.1f} s")
    return metrics, timings


def run_config(cfg: dict, out_dir) -> dict:
    """:func:`run_experiment` on an already loaded (and checked) experiment dict."""
    if cfg.get("kind") == "backlit":
        from mitpiv.studies.backlit import run_backlit_config

        return run_backlit_config(cfg, out_dir)
    run = Path(out_dir)
    source = "sensor" if "sensor" in cfg else "render"
    parts = {"particles": ("seed", "seeding", "flow", "scene"), "render": ("scene", "render"), "sensor": ("sensor",),
             "reconstruct": ("reconstruction",), "evaluate": ("particles",), "piv": ("piv",), "report": ()}
    if source != "sensor":
        del parts["sensor"]

    def call(st, tmp, metrics, timings):
        if st == "particles":
            return _stage_particles(cfg, tmp)
        if st == "render":
            return _stage_render(cfg, run, tmp)
        if st == "sensor":
            return _stage_sensor(cfg, run, tmp)
        if st == "reconstruct":
            return _stage_reconstruct(cfg, run, tmp, source)
        if st == "evaluate":
            return _stage_evaluate(cfg, run, tmp)
        if st == "piv":
            return _stage_piv(cfg, run, tmp)
        return _stage_report(cfg, run, tmp, metrics, timings, source)

    metrics, timings = run_stages(cfg, run, parts, call)
    out = {"name": cfg["name"], "seed": cfg["seed"], "evaluate": metrics.get("evaluate"), "piv": metrics.get("piv"),
           "n_particles": metrics.get("particles", {}).get("n_particles")}
    write_run_results(run, out, timings)
    return out


def write_run_results(run: Path, metrics: dict, timings: dict) -> None:
    """``metrics.json`` and ``timings.json`` of a finished run, each written atomically."""
    from mitpiv.io.atomic import atomic_path

    for name, obj in (("metrics.json", metrics), ("timings.json", timings)):
        with atomic_path(run / name) as tmp:
            tmp.write_text(json.dumps(obj, indent=2, default=float))
