"""Backlit plenoptic droplet tracking as an experiment (``kind = "backlit"``): the same run
folders, atomic stages, resume, metrics and sweeps as particle-image experiments, for
opaque droplets or pellets in front of a diffuse backlight seen by one plenoptic camera.

Experiment file::

    name = "backlit_droplets"
    kind = "backlit"
    seed = 0
    [camera]        plenoptic sensor on the +z axis looking at the origin: resolution [px],
                    pixel_pitch_um, focal_length_mm, f_number, focus_distance_mm,
                    mla_pitch_um, mla_focal_length_um, mla_layout, distance_mm (default:
                    the focus distance)
    [field]         kind = "drop_impact" (secondary droplets of a drop impact, the impact
                    axis +y) | "pellets"; the keyword arguments of
                    mitpiv.physics.droplets.drop_impact_field / pellet_field; dt_s (the
                    time between the frames; droplets fly ballistically)
    [render]        spp, backlight_mm, backlight_size_mm
    [calibration]   depths_mm (dot-card depths from the focal plane), spp, degree_xy, degree_z
    [detection]     z_range_mm = [near, far] (focal-stack depths, + farther), planes,
                    threshold, min_area_px, split_touching, min_separation_px
    [tracking]      radius_mm (two-frame matching radius), predictor_mm_s (expected
                    velocity, optional)

Stages: ``field`` (truth positions, diameters, velocities), ``calibrate`` (dot card at each
depth -> polynomial dewarp), ``render`` (raw images of both frames and the empty backlight),
``detect`` (decode, focal stack, hybrid detection with the dewarp), ``evaluate`` (detection,
depth, lateral and size errors per frame; two-frame tracking against the true velocities),
``report``. Metrics: ``evaluate.frame0/1`` (detected_fraction, depth_rms_diameters, ...)
and ``piv`` (velocity RMS [mm/s], correct-track fraction, outlier ratio).
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError

STAGES = ("field", "calibrate", "render", "detect", "evaluate", "report")
_TABLES = {"camera", "field", "render", "calibration", "detection", "tracking"}
_TOP = {"name", "seed", "kind"} | _TABLES
_CAMERA_KEYS = {"resolution", "pixel_pitch_um", "focal_length_mm", "f_number", "focus_distance_mm", "mla_pitch_um",
                "mla_focal_length_um", "mla_layout", "distance_mm"}
_FIELDS = {"drop_impact", "pellets"}


def check_backlit(cfg: dict, name: str) -> dict:
    """Check a backlit experiment dict (loaded by :func:`mitpiv.studies.load_experiment`)."""
    unknown = set(cfg) - _TOP
    if unknown:
        raise ConfigError(f"experiment {name}: unknown key(s) {sorted(unknown)} for kind = \"backlit\"; expected "
                          f"{sorted(_TOP)}.")
    for t in _TABLES:
        cfg.setdefault(t, {})
        if not isinstance(cfg[t], dict):
            raise ConfigError(f"experiment {name}: [{t}] must be a table, got {cfg[t]!r}.")
    bad = set(cfg["camera"]) - _CAMERA_KEYS
    if bad:
        raise ConfigError(f"experiment {name}: [camera] unknown key(s) {sorted(bad)}; expected {sorted(_CAMERA_KEYS)}.")
    for k in ("resolution", "pixel_pitch_um", "focal_length_mm", "f_number", "focus_distance_mm", "mla_pitch_um"):
        if k not in cfg["camera"]:
            raise ConfigError(f"experiment {name}: [camera] needs {k}.")
    res = cfg["camera"]["resolution"]
    if isinstance(res, bool) or not isinstance(res, int) or res < 16:
        raise ConfigError(f"experiment {name}: [camera] resolution must be an integer >= 16 [px], got {res!r}.")
    f = cfg["field"]
    if f.get("kind") not in _FIELDS:
        raise ConfigError(f"experiment {name}: [field] kind must be one of {sorted(_FIELDS)}, got {f.get('kind')!r}.")
    if not isinstance(f.get("dt_s"), int | float) or not f["dt_s"] > 0:
        raise ConfigError(f"experiment {name}: [field] needs dt_s > 0 (the time between the frames), got "
                          f"{f.get('dt_s')!r}.")
    zr = cfg["detection"].get("z_range_mm", [-2.5, 2.5])
    if not (isinstance(zr, list) and len(zr) == 2 and all(isinstance(v, int | float) for v in zr) and zr[0] < zr[1]):
        raise ConfigError(f"experiment {name}: [detection] z_range_mm must be [near, far] with near < far, got {zr!r}.")
    planes = cfg["detection"].get("planes", 101)
    if isinstance(planes, bool) or not isinstance(planes, int) or planes < 3:
        raise ConfigError(f"experiment {name}: [detection] planes must be an integer >= 3, got {planes!r}.")
    depths = cfg["calibration"].get("depths_mm", [-1.5, -0.75, 0.0, 0.75, 1.5])
    if not (isinstance(depths, list) and len(depths) >= 3):
        raise ConfigError(f"experiment {name}: [calibration] depths_mm needs >= 3 card depths, got {depths!r}.")
    return cfg


def backlit_sensor(camera: dict) -> dict:
    """The plenoptic sensor dict of a [camera] table: on the +z axis, looking at the origin."""
    import mitsuba as mi

    c = dict(camera)
    res = int(c.pop("resolution"))
    dist = float(c.pop("distance_mm", c["focus_distance_mm"]))
    return {"type": "plenoptic", **{k: (v if isinstance(v, str) else float(v)) for k, v in c.items()},
            "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, dist], target=[0, 0, 0], up=[0, 1, 0]),
            "film": {"type": "hdrfilm", "width": res, "height": res, "pixel_format": "luminance",
                     "rfilter": {"type": "box"}}}


def _camera(sensor: dict):
    import mitsuba as mi

    try:
        return mi.load_dict({"type": "scene", "sensor": sensor}).sensors()[0].camera
    except ConfigError:
        raise
    except Exception as e:  # the plugin's own message names the parameter
        raise ConfigError(f"experiment: [camera] is not a valid plenoptic camera: {e}") from None


def _stage_field(cfg, out: Path):
    from mitpiv.physics.droplets import drop_impact_field, pellet_field

    f = dict(cfg["field"])
    kind, dt = f.pop("kind"), float(f.pop("dt_s"))
    fn = drop_impact_field if kind == "drop_impact" else pellet_field
    try:
        field = fn(seed=cfg["seed"], **f)
    except TypeError as e:
        raise ConfigError(f"experiment: [field] for kind = {kind!r}: {e}.") from None
    p0, d, v = field["positions_mm"], field["diameters_mm"], field["velocities_mm_s"]
    np.savez(out / "truth.npz", positions_mm=np.stack([p0, p0 + v * dt]), diameters_mm=d, velocities_mm_s=v,
             times_s=np.array([0.0, dt]))
    return {"n_particles": int(len(d))}


def _stage_calibrate(cfg, out: Path):
    from mitpiv.render.backlit import calibrate_dewarp

    c = cfg["calibration"]
    sensor = backlit_sensor(cfg["camera"])
    _camera(sensor)
    dewarp, obs = calibrate_dewarp(sensor, c.get("depths_mm", [-1.5, -0.75, 0.0, 0.75, 1.5]), spp=int(c.get("spp", 16)),
                                   degree_xy=int(c.get("degree_xy", 3)), degree_z=int(c.get("degree_z", 2)),
                                   progress=True)
    np.savez(out / "dewarp.npz", coef=dewarp.coef, degree_xy=dewarp.degree_xy, degree_z=dewarp.degree_z,
             centre=dewarp.centre, scale=dewarp.scale, rms_mm=dewarp.rms_mm, uvz=obs["uvz"], xyz=obs["xyz"])
    return {"dewarp_rms_mm": float(dewarp.rms_mm), "markers": int(len(obs["xyz"]))}


def _load_dewarp(path):
    from mitpiv.analysis.backlit import Dewarp

    z = np.load(path)
    return Dewarp(z["coef"], int(z["degree_xy"]), int(z["degree_z"]), z["centre"], z["scale"], float(z["rms_mm"]))


def _stage_render(cfg, run: Path, out: Path):
    from mitpiv.io import write_exr
    from mitpiv.render.backlit import render_backlit

    r = cfg["render"]
    kw = {k: float(r[k]) for k in ("backlight_mm", "backlight_size_mm") if k in r}
    spp = int(r.get("spp", 16))
    sensor = backlit_sensor(cfg["camera"])
    truth = np.load(run / "field" / "truth.npz")
    meta = {"camera": cfg["camera"], "spp": spp, **kw}
    white = render_backlit(sensor, np.zeros((0, 3)), [], spp=spp, seed=cfg["seed"], **kw)
    write_exr(out / "white.exr", white, {**meta, "frame": "white"})
    for k in (0, 1):
        raw = render_backlit(sensor, truth["positions_mm"][k], truth["diameters_mm"], spp=spp, seed=cfg["seed"] + 1 + k,
                             **kw)
        write_exr(out / f"raw_frame{k:03d}.exr", raw, {**meta, "frame": k})
    return {"images": ["white.exr", "raw_frame000.exr", "raw_frame001.exr"]}


def _stage_detect(cfg, run: Path, out: Path):
    from mitpiv.analysis.backlit import hybrid_detect
    from mitpiv.io import read_exr
    from mitpiv.lightfield import decode, focal_stack
    from mitpiv.render.backlit import stack_pixels

    d = cfg["detection"]
    cam = _camera(backlit_sensor(cfg["camera"]))
    dewarp = _load_dewarp(run / "calibrate" / "dewarp.npz")
    z = np.linspace(*d.get("z_range_mm", [-2.5, 2.5]), int(d.get("planes", 101)))
    white = read_exr(run / "render" / "white.exr")[0]
    bg = focal_stack(decode(white, optics=cam, white=white), z)
    kw = {k: d[k] for k in ("threshold", "min_area_px", "split_touching", "min_separation_px") if k in d}
    result = {}
    for k in (0, 1):
        lf = decode(read_exr(run / "render" / f"raw_frame{k:03d}.exr")[0], optics=cam, white=white)
        stack = focal_stack(lf, z)
        det = hybrid_detect(stack, z, background=bg, dewarp=dewarp, pixel_to_stack=functools.partial(stack_pixels, lf),
                            **kw)
        np.savez(out / f"detections_{k}.npz", uv_px=det.uv_px, z_stack_mm=det.z_stack_mm, area_px=det.area_px,
                 diameter_px=det.diameter_px, aspect=det.aspect, darkness=det.darkness,
                 positions_mm=det.positions_mm, diameters_mm=det.diameters_mm,
                 min_map=(stack / np.maximum(bg, 1e-12)).min(axis=0).astype(np.float32))
        result[f"frame{k}"] = {"n_found": len(det)}
    return result


def _load_detections(path):
    from mitpiv.analysis.backlit import BacklitDetections

    z = np.load(path)
    det = BacklitDetections(z["uv_px"], z["z_stack_mm"], z["area_px"], z["diameter_px"], z["aspect"], z["darkness"])
    det.positions_mm, det.diameters_mm = z["positions_mm"], z["diameters_mm"]
    return det


def _stage_evaluate(cfg, run: Path, out: Path):
    from mitpiv.analysis.backlit import evaluate_detections, match_frames

    truth = np.load(run / "field" / "truth.npz")
    d_true, v_true = truth["diameters_mm"], truth["velocities_mm_s"]
    view = (0.0, 0.0, -1.0)  # the camera looks along -z
    dets, result, to_truth = [], {}, []
    for k in (0, 1):
        det = _load_detections(run / "detect" / f"detections_{k}.npz")
        ev = evaluate_detections(det, truth["positions_mm"][k], d_true, axis=view)
        pairs = ev.pop("pairs")
        np.savez(out / f"errors_{k}.npz", pairs=pairs, depth_error_diameters=ev.pop("depth_error_diameters"),
                 size_error_mm=ev.pop("size_error_mm"))
        m = np.full(len(det), -1)
        m[pairs[:, 0]] = pairs[:, 1]
        dets.append(det)
        to_truth.append(m)
        result[f"frame{k}"] = ev
    t = cfg["tracking"]
    dt = float(truth["times_s"][1])
    radius = float(t.get("radius_mm", 4.0 * float(np.median(d_true))))
    pred = np.asarray(t["predictor_mm_s"], dtype=float) * dt if "predictor_mm_s" in t else None
    tr = match_frames(dets[0], dets[1], dt_s=dt, radius_mm=radius, predictor_mm=pred)
    ia, ib = to_truth[0][tr["pairs"][:, 0]], to_truth[1][tr["pairs"][:, 1]]
    correct = (ia >= 0) & (ia == ib)
    err = tr["velocity_mm_s"][correct] - v_true[ia[correct]]
    n_pairs = int(tr["pairs"].shape[0])
    nan = float("nan")
    result["tracking"] = {
        "rms": np.sqrt(np.mean(err**2, axis=0)).tolist() if err.size else [nan] * 3,
        "bias": err.mean(axis=0).tolist() if err.size else [nan] * 3,
        "rms_magnitude": float(np.sqrt(np.mean(np.sum(err**2, axis=1)))) if err.size else nan,
        "n": n_pairs, "n_correct": int(correct.sum()), "tracked_fraction": float(correct.sum()) / len(d_true),
        "outlier_ratio": float(1.0 - correct.sum() / n_pairs) if n_pairs else nan, "radius_mm": radius,
        "units": "mm/s"}
    np.savez(out / "tracks.npz", pairs=tr["pairs"], correct=correct, velocity_mm_s=tr["velocity_mm_s"],
             truth_index=ia)
    return result


def _stage_report(cfg, run: Path, out: Path, metrics: dict, timings: dict):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mitpiv.io import read_exr

    truth = np.load(run / "field" / "truth.npz")
    raw = read_exr(run / "render" / "raw_frame000.exr")[0]
    det = np.load(run / "detect" / "detections_0.npz")
    fig, ax = plt.subplots(1, 2, figsize=(11, 5))
    ax[0].imshow(raw, cmap="gray")
    ax[0].set_title("raw plenoptic image, frame 0")
    ax[1].imshow(det["min_map"], cmap="gray", vmin=0, vmax=1.2)
    ax[1].plot(det["uv_px"][:, 0], det["uv_px"][:, 1], "r+", ms=8, label="detections")
    ax[1].set_title("minimum transmittance over the focal stack")
    ax[1].legend(loc="upper right")
    fig.tight_layout()
    fig.savefig(out / "images.png", dpi=90)
    plt.close(fig)
    e = np.load(run / "evaluate" / "errors_0.npz")
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    ax[0].hist(e["depth_error_diameters"], bins=30)
    ax[0].set_xlabel("depth error [droplet diameters]")
    ax[0].set_ylabel("droplets")
    dt_ = truth["diameters_mm"][e["pairs"][:, 1]]
    ax[1].plot(dt_, dt_ + e["size_error_mm"], "o", ms=4)
    lim = [0, float(truth["diameters_mm"].max()) * 1.1]
    ax[1].plot(lim, lim, "k--", lw=1)
    ax[1].set_xlabel("true diameter [mm]")
    ax[1].set_ylabel("measured diameter [mm]")
    fig.tight_layout()
    fig.savefig(out / "errors.png", dpi=90)
    plt.close(fig)
    ev = metrics["evaluate"]
    lines = [f"# {cfg['name']}: backlit plenoptic droplet tracking", "",
             f"{metrics['field']['n_particles']} droplets ({cfg['field']['kind']}), dewarp residual "
             f"{metrics['calibrate']['dewarp_rms_mm'] * 1e3:.1f} um over {metrics['calibrate']['markers']} dots.", "",
             "| frame | found | detected | lateral RMS [d] | depth RMS [d] | size bias [mm] | size RMS [mm] |",
             "|---|---|---|---|---|---|---|"]
    for k in (0, 1):
        f = ev[f"frame{k}"]
        lines.append(f"| {k} | {f['n_found']} | {f['detected_fraction']:.2f} | {f['lateral_rms_diameters']:.3f} | "
                     f"{f['depth_rms_diameters']:.3f} | {f['size_bias_mm']:.4f} | {f['size_rms_mm']:.4f} |")
    t = ev["tracking"]
    lines += ["", f"Tracking: {t['n']} pairs, {t['n_correct']} correct ({t['tracked_fraction']:.2f} of the droplets, "
              f"outlier ratio {t['outlier_ratio']:.2f}); velocity RMS x, y, z = "
              f"{', '.join(f'{v:.1f}' for v in t['rms'])} mm/s.", "",
              "| stage | seconds |", "|---|---|", *[f"| {k} | {v:.1f} |" for k, v in timings.items()], "",
              "![images](images.png)", "", "![errors](errors.png)", ""]
    (out / "report.md").write_text("\n".join(lines))
    return {"report": "report.md"}


def run_backlit_config(cfg: dict, out_dir) -> dict:
    """Run a checked backlit experiment into ``out_dir`` (stages resume; see the module notes)."""
    from mitpiv.studies.experiment import run_stages, write_run_results

    run = Path(out_dir)
    parts = {"field": ("seed", "field"), "calibrate": ("camera", "calibration"), "render": ("camera", "render"),
             "detect": ("detection",), "evaluate": ("tracking",), "report": ()}
    stages = {"field": lambda tmp: _stage_field(cfg, tmp), "calibrate": lambda tmp: _stage_calibrate(cfg, tmp),
              "render": lambda tmp: _stage_render(cfg, run, tmp), "detect": lambda tmp: _stage_detect(cfg, run, tmp),
              "evaluate": lambda tmp: _stage_evaluate(cfg, run, tmp)}

    def call(st, tmp, metrics, timings):
        return stages[st](tmp) if st in stages else _stage_report(cfg, run, tmp, metrics, timings)

    metrics, timings = run_stages(cfg, run, parts, call)
    ev = metrics["evaluate"]
    out = {"name": cfg["name"], "seed": cfg["seed"], "kind": "backlit",
           "evaluate": {"frame0": ev["frame0"], "frame1": ev["frame1"]}, "piv": ev["tracking"],
           "n_particles": metrics["field"]["n_particles"], "dewarp_rms_mm": metrics["calibrate"]["dewarp_rms_mm"]}
    write_run_results(run, out, timings)
    return out
