"""Backlit plenoptic droplet tracking (``kind = "backlit"``): opaque droplets or pellets in
front of a diffuse backlight seen by one plenoptic camera, with the same run folders,
atomic stages, resume, metrics and sweeps as particle-image experiments.

Experiment file (``mitpiv schema --kind backlit`` lists every key)::

    name = "backlit_droplets"
    kind = "backlit"
    seed = 0
    [camera]        plenoptic sensor on the +z axis looking at the origin: resolution [px],
                    pixel_pitch_um, focal_length_mm, f_number, focus_distance_mm,
                    mla_pitch_um, mla_focal_length_um, mla_layout, distance_mm (default:
                    the focus distance)
    [field]         kind = "drop_impact" | "pellets" with the keyword arguments of
                    mitpiv.physics.droplets.drop_impact_field / pellet_field; dt_s
    [render]        spp, backlight_mm, backlight_size_mm
    [calibration]   depths_mm (dot-card depths from the focal plane), spp, degree_xy, degree_z
    [detection]     z_range_mm = [near, far], planes, threshold, min_area_px,
                    split_touching, min_separation_px
    [tracking]      radius_mm (two-frame matching radius), predictor_mm_s (expected velocity)

Stages: ``field`` (truth positions, diameters, velocities), ``calibrate`` (dot card at each
depth -> polynomial dewarp, :func:`mitpiv.calibrate.calibrate_dewarp`), ``render`` (raw
images of both frames and the empty backlight), ``detect`` (decode, focal stack, hybrid
detection with the dewarp), ``evaluate`` (detection, depth, lateral and size errors per
frame; two-frame tracking against the true velocities), ``report``.
"""

from __future__ import annotations

import functools
from functools import cache
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, model_validator

from mitpiv.calibrate import calibrate_dewarp
from mitpiv.errors import ConfigError
from mitpiv.studies.schema import Table, Vec3, discriminated, model_from_signature
from mitpiv.studies.shared import RENDER_PACKAGES, Kind, Stage, StageContext, flatten

STAGES = ("field", "calibrate", "render", "detect", "evaluate", "report")
PosFloat = Annotated[float, Field(gt=0)]


class CameraTable(Table):
    """The plenoptic camera, on the +z axis looking at the origin."""

    resolution: Annotated[int, Field(ge=16)] = Field(..., description="sensor side [px] (square)")
    pixel_pitch_um: PosFloat = Field(..., description="pixel pitch [um]")
    focal_length_mm: PosFloat = Field(..., description="main-lens focal length [mm]")
    f_number: PosFloat = Field(..., description="main-lens f-number")
    focus_distance_mm: PosFloat = Field(..., description="object distance in focus [mm]")
    mla_pitch_um: PosFloat = Field(..., description="lenslet pitch [um]")
    mla_focal_length_um: PosFloat | None = Field(None, description="lenslet focal length [um] (default: f-matched)")
    mla_layout: Literal["rect", "hex"] | None = Field(None, description="lenslet layout (default the plugin's)")
    distance_mm: PosFloat | None = Field(None, description="camera distance from the origin [mm] (default: focus)")


@cache
def _field_union():
    from mitpiv.physics.droplets import drop_impact_field, pellet_field

    dt = (PosFloat, Field(..., description="time between the frames [s]; droplets fly ballistically"))
    return discriminated({
        "drop_impact": model_from_signature("Field_drop_impact", drop_impact_field, skip=("seed",),
                                            extra_fields={"dt_s": dt}),
        "pellets": model_from_signature("Field_pellets", pellet_field, skip=("seed",), extra_fields={"dt_s": dt}),
    })


class RenderTable(Table):
    """Rendering of the backlit scene."""

    spp: Annotated[int, Field(ge=1)] = Field(16, description="samples per pixel")
    backlight_mm: PosFloat = Field(30.0, description="backlight distance behind the origin [mm]")
    backlight_size_mm: PosFloat = Field(100.0, description="backlight square side [mm]")


class CalibrationTable(Table):
    """Dot-card calibration of the dewarp polynomial."""

    depths_mm: Annotated[list[float], Field(min_length=3)] = Field(
        [-1.5, -0.75, 0.0, 0.75, 1.5], description="card depths from the focal plane [mm]")
    spp: Annotated[int, Field(ge=1)] = Field(16, description="samples per pixel of the card renders")
    degree_xy: Annotated[int, Field(ge=1, le=5)] = Field(3, description="polynomial degree in (u, v)")
    degree_z: Annotated[int, Field(ge=0, le=4)] = Field(2, description="polynomial degree in depth")


class DetectionTable(Table):
    """Focal stack and hybrid detection (mitpiv.analysis.backlit.hybrid_detect)."""

    z_range_mm: tuple[float, float] = Field((-2.5, 2.5), description="focal-stack depths [near, far] [mm] (+ farther)")
    planes: Annotated[int, Field(ge=3)] = Field(101, description="focal-stack planes")
    threshold: Annotated[float, Field(gt=0, lt=1)] = Field(0.5, description="darkness threshold")
    min_area_px: Annotated[int, Field(ge=1)] = Field(2, description="smallest silhouette [px]")
    split_touching: bool = Field(True, description="split touching silhouettes (watershed)")
    min_separation_px: Annotated[int, Field(ge=1)] = Field(2, description="peak separation for splitting [px]")

    @model_validator(mode="after")
    def _range(self):
        if not self.z_range_mm[0] < self.z_range_mm[1]:
            raise ValueError(f"z_range_mm must be [near, far] with near < far, got {list(self.z_range_mm)}")
        return self


class TrackingTable(Table):
    """Two-frame tracking."""

    radius_mm: PosFloat | None = Field(None, description="matching radius [mm] (default 4 median diameters)")
    predictor_mm_s: Vec3 | None = Field(None, description="expected velocity [mm/s]")


@cache
def schema():
    from pydantic import create_model

    fields = {
        "kind": (Literal["backlit"], Field(..., description="experiment kind")),
        "name": (Annotated[str, Field(min_length=1)], Field(..., description="experiment name (default: the file "
                                                                             "name)")),
        "seed": (Annotated[int, Field(ge=0, lt=2**63)], Field(0, description="experiment seed")),
        "camera": (CameraTable, Field(..., description="the plenoptic camera")),
        "field": (_field_union(), Field(..., description="the droplet field (kind and parameters) and dt_s")),
        "render": (RenderTable, Field(default_factory=RenderTable, description="rendering")),
        "calibration": (CalibrationTable, Field(default_factory=CalibrationTable, description="dewarp calibration")),
        "detection": (DetectionTable, Field(default_factory=DetectionTable, description="detection")),
        "tracking": (TrackingTable, Field(default_factory=TrackingTable, description="tracking")),
    }
    return create_model("BacklitExperiment", __base__=Table,
                        __doc__="Backlit plenoptic droplet tracking: field, calibration, render, detection, "
                                "evaluation and two-frame tracking.", **fields)


def backlit_sensor(camera) -> dict:
    """The plenoptic sensor dict of a [camera] table: on the +z axis, looking at the origin."""
    import mitsuba as mi

    from mitpiv.render.variant import ensure_variant

    ensure_variant()
    c = camera.model_dump(exclude_none=True) if hasattr(camera, "model_dump") else dict(camera)
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
    except Exception as e:  # noqa: BLE001 - the plugin's own message names the parameter
        raise ConfigError(f"experiment: [camera] is not a valid plenoptic camera: {e}") from None


# ------------------------------------------------------------------------------- stages
def stage_field(ctx: StageContext) -> dict:
    from mitpiv.io import write_truth
    from mitpiv.physics.droplets import drop_impact_field, pellet_field

    cfg = ctx.cfg
    f = cfg.field.model_dump()
    kind, dt = f.pop("kind"), float(f.pop("dt_s"))
    fn = drop_impact_field if kind == "drop_impact" else pellet_field
    field = fn(seed=cfg.seed, **f)
    p0, d, v = field["positions_mm"], field["diameters_mm"], field["velocities_mm_s"]
    write_truth(ctx.out / "truth.npz", positions_mm=np.stack([p0, p0 + v * dt]), times_s=[0.0, dt],
                diameters_um=np.asarray(d) * 1e3, velocities_mm_s=v, extra={"seed": cfg.seed, "field": kind})
    return {"n_particles": int(len(d))}


def _truth(ctx):
    from mitpiv.io import read_truth

    return read_truth(ctx.input("field", "truth.npz"))


def stage_calibrate(ctx: StageContext) -> dict:
    c = ctx.cfg.calibration
    sensor = backlit_sensor(ctx.cfg.camera)
    _camera(sensor)
    dewarp, obs = calibrate_dewarp(sensor, c.depths_mm, spp=c.spp, degree_xy=c.degree_xy, degree_z=c.degree_z,
                                   seed=ctx.cfg.seed, progress=ctx.progress)
    dewarp.save(ctx.out / "dewarp.npz", uvz=obs["uvz"], xyz=obs["xyz"])
    return {"dewarp_rms_mm": float(dewarp.rms_mm), "markers": int(len(obs["xyz"]))}


def stage_render(ctx: StageContext) -> dict:
    from mitpiv.io import write_exr
    from mitpiv.render.backlit import render_backlit
    from mitpiv.streams import render_seed

    cfg = ctx.cfg
    r = cfg.render
    kw = {"backlight_mm": r.backlight_mm, "backlight_size_mm": r.backlight_size_mm}
    sensor = backlit_sensor(cfg.camera)
    truth = _truth(ctx)
    d_mm = truth["diameters_um"] / 1e3
    meta = {"camera": cfg.camera.model_dump(), "spp": r.spp, "seed": cfg.seed, **kw}
    seed = render_seed(cfg.seed, camera="backlit_white", frame=0)
    white = render_backlit(sensor, np.zeros((0, 3)), [], spp=r.spp, seed=seed, **kw)
    write_exr(ctx.out / "white.exr", white, {**meta, "frame": "white", "render_seed": seed})
    for k in (0, 1):
        seed = render_seed(cfg.seed, camera="backlit", frame=k)
        raw = render_backlit(sensor, truth["positions_mm"][k], d_mm, spp=r.spp, seed=seed, **kw)
        write_exr(ctx.out / f"raw_frame{k:03d}.exr", raw, {**meta, "frame": k, "render_seed": seed})
    return {"images": ["white.exr", "raw_frame000.exr", "raw_frame001.exr"]}


def stage_detect(ctx: StageContext) -> dict:
    from mitpiv.analysis.backlit import Dewarp, hybrid_detect
    from mitpiv.io import read_exr
    from mitpiv.lightfield import decode, focal_stack
    from mitpiv.lightfield.refocus import stack_pixels

    d = ctx.cfg.detection
    cam = _camera(backlit_sensor(ctx.cfg.camera))
    dewarp = Dewarp.load(ctx.input("calibrate", "dewarp.npz"))
    z = np.linspace(*d.z_range_mm, d.planes)
    white = read_exr(ctx.input("render", "white.exr"))[0]
    bg = focal_stack(decode(white, optics=cam, white=white), z)
    result = {}
    for k in (0, 1):
        lf = decode(read_exr(ctx.input("render", f"raw_frame{k:03d}.exr"))[0], optics=cam, white=white)
        stack = focal_stack(lf, z, progress=ctx.progress)
        det = hybrid_detect(stack, z, background=bg, dewarp=dewarp, threshold=d.threshold, min_area_px=d.min_area_px,
                            split_touching=d.split_touching, min_separation_px=d.min_separation_px,
                            pixel_to_stack=functools.partial(stack_pixels, lf))
        det.save(ctx.out / f"detections_{k}.npz", min_map=(stack / np.maximum(bg, 1e-12)).min(axis=0))
        result[f"frame{k}"] = {"n_found": len(det)}
    return result


def stage_evaluate(ctx: StageContext) -> dict:
    from mitpiv.analysis.backlit import BacklitDetections, evaluate_detections, match_frames
    from mitpiv.io import write_npz

    truth = _truth(ctx)
    d_true, v_true = truth["diameters_um"] / 1e3, truth["velocities_mm_s"]
    view = (0.0, 0.0, -1.0)  # the camera looks along -z
    dets, result, to_truth = [], {}, []
    for k in (0, 1):
        det = BacklitDetections.load(ctx.input("detect", f"detections_{k}.npz"))
        ev = evaluate_detections(det, truth["positions_mm"][k], d_true, axis=view)
        pairs = ev.pop("pairs")
        write_npz(ctx.out / f"errors_{k}.npz", {"pairs": pairs, "depth_error_diameters": ev.pop("depth_error_diameters"),
                                                "size_error_mm": ev.pop("size_error_mm")})
        m = np.full(len(det), -1)
        m[pairs[:, 0]] = pairs[:, 1]
        dets.append(det)
        to_truth.append(m)
        result[f"frame{k}"] = ev
    t = ctx.cfg.tracking
    dt = float(truth["times_s"][1])
    radius = t.radius_mm if t.radius_mm is not None else 4.0 * float(np.median(d_true))
    pred = np.asarray(t.predictor_mm_s, dtype=float) * dt if t.predictor_mm_s is not None else None
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
    write_npz(ctx.out / "tracks.npz", {"pairs": tr["pairs"], "correct": correct, "velocity_mm_s": tr["velocity_mm_s"],
                                       "truth_index": ia})
    return result


def stage_report(ctx: StageContext) -> dict:
    from mitpiv.studies import report

    return report.write(report.backlit_report(ctx.cfg, ctx.run_dir, ctx.results, ctx.timings), ctx.out)


def stages(cfg) -> list[Stage]:
    return [Stage("field", ("seed", "field"), stage_field),
            Stage("calibrate", ("camera", "calibration"), stage_calibrate, packages=RENDER_PACKAGES),
            Stage("render", ("camera", "render"), stage_render, packages=RENDER_PACKAGES),
            Stage("detect", ("detection",), stage_detect),
            Stage("evaluate", ("tracking",), stage_evaluate),
            Stage("report", (), stage_report)]


def summary(cfg, results: dict) -> dict:
    ev = results["evaluate"]
    return {"name": cfg.name, "seed": cfg.seed, "kind": "backlit",
            "evaluate": {"frame0": ev["frame0"], "frame1": ev["frame1"]}, "piv": ev["tracking"],
            "n_particles": results["field"]["n_particles"], "dewarp_rms_mm": results["calibrate"]["dewarp_rms_mm"]}


def row(metrics: dict) -> dict:
    out = {}
    flatten("", {"frame0": metrics["evaluate"]["frame0"], "frame1": metrics["evaluate"]["frame1"],
                 "piv": metrics["piv"], "n_particles": metrics["n_particles"],
                 "dewarp_rms_mm": metrics["dewarp_rms_mm"]}, out)
    return out


def headline(m: dict) -> str:
    ev, pv = m["evaluate"]["frame0"], m["piv"]
    return (f"{m['name']}: {ev['n_matched']}/{ev['n_truth']} droplets detected, depth RMS "
            f"{ev['depth_rms_diameters']:.2f} diameters, size RMS {ev['size_rms_mm'] * 1e3:.1f} um; "
            f"{pv['n_correct']} correct tracks, velocity RMS {pv['rms_magnitude']:.1f} mm/s")


KIND = Kind(name="backlit", build_schema=schema, stages=stages, summary=summary, row=row, headline=headline,
            describe="backlit plenoptic droplet tracking",
            columns=("frame0.*", "frame1.*", "piv.*", "n_particles", "dewarp_rms_mm"))
