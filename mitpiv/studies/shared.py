"""What the experiment engine's modules share, so that no kind imports another kind and the
runner, the report and the export read a run without importing a kind:

* the kind protocol: :class:`Stage`, :class:`StageContext`, :class:`Kind` and
  :data:`RENDER_PACKAGES` (the runner runs any kind that declares them);
* tables several kinds declare: :class:`SceneTable`, the ``[flow]`` table
  (:func:`flow_union`);
* the experiment's files: :func:`resolve_scene_xml`, :func:`resolve_table_file` (before
  validation), :func:`scene_files` (the files reading a scene touches: part of stage keys),
  :func:`count_for_density` (a particle count for a target image density in a scene's sensor);
* a run folder's records, as the stages wrote them: :func:`frame_files`, :func:`images`,
  :func:`frame_images`, :func:`volume`, :func:`read_tracks`, :func:`run_truth`, and the
  settings that locate them (:func:`grid_of`, :func:`source_of`, :func:`bounds_of`);
* results: :func:`null_metrics` (no NaN in a result: ``None`` and the reason),
  :func:`flatten` (nested metrics as table columns), :func:`fmt_metric`, :func:`pareto_front`.

It imports nothing of :mod:`mitpiv.studies` but the schema helpers.
"""

from __future__ import annotations

import difflib
import functools
import re
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Annotated

import numpy as np
from pydantic import BaseModel, Field, model_validator

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.progress import Progress
from mitpiv.studies.schema import Table, discriminated, model_from_signature

__all__ = ["RENDER_PACKAGES", "Stage", "StageContext", "Kind", "SceneTable", "flow_union", "resolve_scene_xml", "check_scene_sensors",
           "scene_cameras", "check_coverage", "SceneRig", "scene_rig", "load_scene_rig", "sheet_region", "sheet_focus",
           "check_sheet_focus",
           "resolve_table_file", "scene_files", "truth_file", "TRUTH_STAGES", "read_run_record", "count_for_density", "frame_files", "images", "frame_images",
           "volume", "read_tracks", "run_truth", "grid_of", "source_of", "sensor_table", "sensor_stage", "bounds_of", "null_metrics", "flatten",
           "fmt_metric", "pareto_front"]

# ------------------------------------------------------------------------------- the kind protocol
#: Packages whose version is part of the key of a stage that renders.
RENDER_PACKAGES = ("mitsuba", "drjit")


@dataclass(frozen=True)
class Stage:
    """One stage of an experiment kind.

    Attributes
    ----------
    name : str
        The stage folder's name.
    reads : tuple of str
        The experiment's top-level keys (tables) whose values reach this stage.
    run : callable
        ``run(ctx) -> dict``: fills ``ctx.out`` and returns a JSON-ready result.
    files : callable or None
        ``files(cfg) -> list of paths``: the files outside the run folder that the stage
        reads (their content is part of its key); None: none.
    packages : tuple of str
        Installed packages whose version shapes the stage's output (part of its key), e.g.
        :data:`RENDER_PACKAGES` for a stage that renders.
    check : callable or None
        ``check(cfg)``: refuses (ConfigError) an experiment this stage cannot run, before
        any stage of a run that includes it starts (and at ``mitpiv run --check``); for
        checks that hold only when the stage runs (a PIV window against the grid of a run
        stopped after the reconstruction is no error).
    scene_check : callable or None
        ``scene_check(cfg, cameras)``: a check that needs the scene's cameras (``{sensor id:
        camera model}``, :func:`scene_cameras`), run by ``mitpiv run --check``, which loads
        the scene's sensors once for all stages (a run checks again from the rendered
        images' metadata, in the stage itself).
    rig_check : callable or None
        ``rig_check(cfg, rig)``: as ``scene_check``, for a check that needs more of the scene
        than the camera models (:class:`SceneRig`: a thin lens' tilted plane of focus, the
        laser sheets), run by ``mitpiv run --check`` and ``mitpiv preview`` from the same
        loading of the scene.
    """

    name: str
    reads: tuple[str, ...]
    run: Callable[[StageContext], dict | None]
    files: Callable[[BaseModel], list] | None = None
    packages: tuple[str, ...] = ()
    check: Callable[[BaseModel], None] | None = None
    scene_check: Callable[[BaseModel, dict], None] | None = None
    rig_check: Callable[[BaseModel, SceneRig], None] | None = None


@dataclass
class StageContext:
    """What a stage sees: the experiment, where earlier stages wrote, where it writes."""

    cfg: BaseModel
    run_dir: Path
    out: Path
    results: dict[str, dict]
    timings: dict[str, float]
    progress: Progress = None

    def input(self, stage: str, name: str) -> Path:
        """The file ``name`` that the earlier stage ``stage`` wrote."""
        return self.run_dir / stage / name


@dataclass(frozen=True)
class Kind:
    """An experiment kind: its schema, stages, summary (metrics.json) and sweep-table row."""

    name: str
    build_schema: Callable[[], type[BaseModel]]
    stages: Callable[[BaseModel], list[Stage]]
    summary: Callable[[BaseModel, dict], dict]
    row: Callable[[dict], dict]
    describe: str = ""
    headline: Callable[[dict], str] | None = None
    aliases: tuple[str, ...] = ()
    prepare: Callable[[dict, Path], dict] | None = None
    #: The sweep-table columns ``row`` makes, as shell patterns (``"piv.*"``); a sweep checks
    #: its ``[plot]`` names against them before any point runs. Empty: not declared (unchecked).
    columns: tuple[str, ...] = ()

    @property
    def schema(self) -> type[BaseModel]:
        """The kind's experiment model (one frozen pydantic model, a field per TOML table)."""
        return self.build_schema()


# ------------------------------------------------------------------------------- tables
PosFloat = Annotated[float, Field(gt=0)]


class SceneTable(Table):
    """The scene: a Mitsuba scene XML with mitpiv's plugins and its $parameters."""

    xml: str = Field(..., description="scene XML file (relative to the experiment file)")
    params: dict[str, str | int | float | bool] = Field(
        default_factory=dict, description="$name substitutions of the scene XML")

    @model_validator(mode="after")
    def _known_params(self):
        """Every param must be a $name of the scene XML (a typo would otherwise change nothing)."""
        try:
            text = Path(self.xml).read_text(encoding="utf-8", errors="replace")
        except OSError:
            return self  # a missing file is reported where it is resolved (prepare)
        names = set(re.findall(r"\$(\w+)", text)) | set(re.findall(r"<default\s+name=\"(\w+)\"", text)) | {"truth"}
        unknown = sorted(set(self.params) - names)
        if unknown:
            hints = [f"{k!r}" + (f" (did you mean {close[0]!r}?)" if (close := difflib.get_close_matches(
                k, sorted(names), n=1, cutoff=0.6)) else "") for k in unknown]
            raise ValueError(f"params {', '.join(hints)} not used by {Path(self.xml).name}, whose $parameters are "
                             f"{sorted(names - {'truth'})}; a parameter the scene does not use changes nothing")
        return self


@cache
def flow_union(prefix: str = "Flow", dt_description: str = "time between the two frames [s]"):
    """The ``[flow]`` table: one model per flow kind (generated from the flow classes'
    signatures) plus ``dt_s``, discriminated by ``kind``; shared by the experiment kinds."""
    from mitpiv.physics.flows import FLOW_KINDS

    dt = (PosFloat, Field(..., description=dt_description))
    models = {kind: model_from_signature(f"{prefix}_{kind}", cls, extra_fields={"dt_s": dt}, base=_flow_base(cls))
              for kind, cls in FLOW_KINDS.items()}
    return discriminated(models)


def _flow_base(cls) -> type[Table]:
    """The base of a ``[flow]`` table: validating it builds the flow once, so that the flow's
    own checks (a zero core radius or axis, too few modes or segments, a missing grid file)
    refuse the experiment at ``--check`` rather than in the particles stage."""

    class FlowTable(Table):
        @model_validator(mode="after")
        def _flow_checks(self):
            import json

            kw = {k: v for k, v in self.model_dump().items() if k not in ("kind", "dt_s")}
            _build_flow(cls, json.dumps(kw, sort_keys=True))  # ConfigError: a ValueError
            return self

    return FlowTable


@functools.lru_cache(maxsize=32)
def _build_flow(cls, kwargs_json: str) -> None:
    """Build a flow once per parameter set (a channel flow takes ~0.5 s; a sweep validates
    every point, and a run validates again when it starts); errors are not cached."""
    import json

    cls(**json.loads(kwargs_json))


# ------------------------------------------------------------------------------- the experiment's files
def resolve_scene_xml(raw: dict, base_dir: Path) -> dict:
    """``[scene] xml`` resolved against the experiment's folder (before validation); a
    missing file is a ConfigError naming the key and the resolved path."""
    scene = raw.get("scene")
    if isinstance(scene, dict) and isinstance(scene.get("xml"), str):
        xml = (base_dir / scene["xml"]).resolve()
        if not xml.is_file():
            raise ConfigError(f"experiment: [scene] xml = {scene['xml']!r} does not exist (resolved to {xml}).")
        raw = {**raw, "scene": {**scene, "xml": str(xml)}}
    return raw


def resolve_table_file(raw: dict, table: str, base_dir: Path, *, hint: str = "") -> dict:
    """``[table] file`` resolved against the experiment's folder (before validation), with its
    content hash as ``file_sha256`` (part of the stage keys: a changed file reruns); a missing
    file is a ConfigError naming the key, the resolved path and ``hint``."""
    t = raw.get(table)
    if isinstance(t, dict) and isinstance(t.get("file"), str):
        import hashlib

        f = (base_dir / t["file"]).resolve()
        if not f.is_file():
            raise ConfigError(f"experiment: [{table}] file = {t['file']!r} does not exist (resolved to {f}){hint}.")
        raw = {**raw, table: {**t, "file": str(f), "file_sha256": hashlib.sha256(f.read_bytes()).hexdigest()}}
    return raw


def scene_files(cfg, *, frames: tuple[int, ...] = (0, 1)) -> list[Path]:
    """The files outside the run folder that reading the scene touches: the scene XML and
    every file it names (``filename`` attributes, ``<string name="filename">`` and a
    sensor's ``<string name="calibration">`` values,
    ``$name`` substituted from its defaults and ``[scene] params``, ``$frame`` with each of
    ``frames``, relative names resolved against its folder), except the particle files,
    which the run makes. Their content is part of the render stage's key. Parsed with the
    standard library (no Mitsuba import)."""
    import xml.etree.ElementTree as ET

    xml = Path(cfg.scene.xml)
    out = [xml]
    try:
        root = ET.parse(xml).getroot()
    except (ET.ParseError, OSError):
        return out  # the render stage reports the broken file
    values = {d.get("name"): d.get("value") for d in root.iter("default")}
    values.update({k: str(v) for k, v in cfg.scene.params.items()})
    made = {id(s) for shape in root.iter("shape") if shape.get("type") in ("ellipsoidsmesh", "ellipsoids")
            for s in shape.findall("string")}
    names = []
    for el in root.iter():
        if el.get("filename"):
            names.append(el.get("filename"))
        elif el.tag == "string" and el.get("name") in ("filename", "calibration") and id(el) not in made \
                and el.get("value"):
            names.append(el.get("value"))
    for n in names:
        for frame in frames:
            v = {**values, "frame": str(frame)}
            text = n
            for k in sorted(v, key=len, reverse=True):  # as Mitsuba substitutes: each $name, longest first
                text = text.replace(f"${k}", str(v[k]))
            p = Path(text)
            p = p if p.is_absolute() else xml.parent / p
            if p not in out:
                out.append(p)
    return out


def check_scene_sensors(cfg) -> None:
    """The render stage's check: every id in ``[render] sensors`` names a sensor of the scene
    XML (read with the standard library; a scene that includes other files is left to the
    render, which checks again)."""
    import xml.etree.ElementTree as ET

    wanted = getattr(cfg.render, "sensors", None)
    if not wanted:
        return
    try:
        root = ET.parse(Path(cfg.scene.xml)).getroot()
    except (ET.ParseError, OSError):
        return  # the render stage reports the broken file
    if any(True for _ in root.iter("include")):
        return
    ids = [s.get("id") for s in root.iter("sensor")]
    missing = [s for s in wanted if s not in ids]
    if missing:
        raise ConfigError(f"experiment {cfg.name!r}: [render] sensors: {missing} not in the scene {str(cfg.scene.xml)!r}; "
                          f"its sensors are {[i for i in ids if i]}. Name sensors of the scene (or leave "
                          f"[render] sensors out for all of them).")


@dataclass(frozen=True)
class SceneRig:
    """A scene's geometry without its particles, what the checks that need the cameras or the
    laser sheet (``Stage.scene_check``, ``Stage.rig_check``) and ``mitpiv preview`` read
    (:func:`scene_rig`, :func:`load_scene_rig`).

    Attributes
    ----------
    cameras : dict
        ``{sensor id: camera model}`` of the sensors mitpiv models, in the scene's order.
    focus_normals : dict
        ``{sensor id: normal of a tilted plane of focus (camera-local Mitsuba frame) or None}``:
        a thin lens' Scheimpflug plane, which the camera model does not carry.
    sheets : dict
        ``{emitter id: the laser_sheet's describe() dict}`` (origin_mm, normal, direction,
        thickness_mm, width_mm, ...).
    """

    cameras: dict
    focus_normals: dict
    sheets: dict


def load_scene_rig(xml, *, params: dict | None = None, sensors=None, where: str | None = None) -> SceneRig:
    """The :class:`SceneRig` of a scene XML (its ``sensors``, default all), from its sensors
    and laser sheets alone (:func:`mitpiv.render.scene.load_rig`: no particle file, no Mie
    table). A sensor mitpiv does not model (Mitsuba's own ``perspective``) is left out."""
    from mitpiv.io import camera_from_metadata
    from mitpiv.render.render import sensor_model
    from mitpiv.render.scene import load_rig

    loaded = load_rig(xml, params=params)
    found = loaded["sensors"]
    wanted = list(sensors or found)
    missing = [name for name in wanted if name not in found]
    if missing:
        raise ConfigError(f"{where or 'sensors'}: {missing} not in the scene {str(xml)!r}; its sensors are "
                          f"{list(found)}.")
    cameras, normals = {}, {}
    for name in wanted:
        d = sensor_model(found[name])
        try:
            cameras[name] = camera_from_metadata({"camera": d})
        except FileFormatError:
            continue
        normals[name] = d.get("focus_plane_normal_camera_mitsuba")
    return SceneRig(cameras, normals, {k: e.describe() for k, e in loaded["sheets"].items()})


def scene_rig(cfg) -> SceneRig:
    """The :class:`SceneRig` of the sensors a run renders (``[render] sensors``, default all)."""
    return load_scene_rig(cfg.scene.xml, params=cfg.scene.params, sensors=getattr(cfg.render, "sensors", None),
                          where=f"experiment {cfg.name!r}: [render] sensors")


def scene_cameras(cfg) -> dict:
    """The camera models of the sensors a run renders (``[render] sensors``, default all),
    ``{sensor id: camera}`` in the scene's order, from the scene's sensors alone
    (:func:`scene_rig`: no particle file, no Mie table). A sensor mitpiv does not model
    (Mitsuba's own ``perspective``) is left out."""
    return scene_rig(cfg).cameras


#: A camera that sees less than this fraction of a measurement volume is warned about.
COVERAGE_WARN = 0.9


def check_coverage(cameras: dict, lower_mm, upper_mm, *, what: str, fix: str) -> dict:
    """Refuse a measurement volume that no point of is seen by every camera; warn
    (:class:`~mitpiv.errors.MitpivWarning`) when a camera sees less than
    :data:`COVERAGE_WARN` of it. The numbers come from
    :func:`mitpiv.physics.camera.box_coverage` (16 x 16 x 16 cells and the corners);
    the message names each short camera's fraction, its corners off the sensor (pixel
    positions) and the box every camera sees. Returns the coverage (None without a
    modelled camera)."""
    import warnings

    from mitpiv.errors import MitpivWarning
    from mitpiv.physics.camera import box_coverage

    if not cameras:
        return None
    cov = box_coverage(cameras, lower_mm, upper_mm)
    short = {k: c for k, c in cov["cameras"].items() if c["fraction"] < COVERAGE_WARN}
    if not short:
        return cov

    def corner(k, c):
        uv = c["corners_px"][k]
        at = "behind the camera" if not np.all(np.isfinite(uv)) else f"at pixel ({uv[0]:.0f}, {uv[1]:.0f})"
        return f"({', '.join(f'{v:g}' for v in cov['corners_mm'][k])}) {at}"

    lines = []
    for name, c in short.items():
        off = [corner(k, c) for k in range(8) if not c["corners_visible"][k]]
        w, h = cameras[name].resolution
        lines.append(f"camera {name!r} sees {100 * c['fraction']:.0f} % of it ({len(off)} of its 8 corners off its "
                     f"{w}x{h} sensor, e.g. {'; '.join(off[:2])})" if off else
                     f"camera {name!r} sees {100 * c['fraction']:.0f} % of it")
    box = cov["common_box_mm"]
    lo, hi = np.asarray(lower_mm, float), np.asarray(upper_mm, float)
    where = "no point of it is seen by every camera" if box is None else \
        f"{100 * cov['common']:.0f} % of it is seen by every camera"
    if box is not None and np.any(box[1] - box[0] < 0.95 * (hi - lo)):  # a smaller box holds the common view
        where += ", within about " + ", ".join(f"{a} {lo_:.3g}..{hi_:.3g}" for a, lo_, hi_ in
                                               zip("xyz", box[0], box[1], strict=True)) + " mm"
    msg = f"{what} = {[float(v) for v in lower_mm]}..{[float(v) for v in upper_mm]} mm: {'; '.join(lines)}; {where}."
    if cov["common"] == 0.0:
        raise ConfigError(f"{msg} Nothing in it can be measured: {fix}.")
    warnings.warn(f"{msg} The rest holds no measurement; {fix} if that is not intended.", MitpivWarning, stacklevel=2)
    return cov


#: A camera that has less than this fraction of the sheet's mid-plane in focus is warned about.
FOCUS_WARN = 0.9


def sheet_region(rig: SceneRig, sheet: dict, lower_mm=None, upper_mm=None) -> np.ndarray:
    """The part of a laser sheet's mid-plane that matters, a convex polygon (K, 3) [mm]: its
    section with the box ``lower_mm..upper_mm`` (a measurement volume) or, without a box, with
    the view every camera shares (the intersection of their fields of view on the plane; their
    joint extent where they share none); cut to the sheet's ``width_mm`` where it has one.
    (0, 3) where the plane misses the box."""
    from mitpiv.physics.camera import sensor_corner_rays
    from mitpiv.physics.sheet import clip_polygon, plane_basis, plane_box_section

    o, n = np.asarray(sheet["origin_mm"], float), np.asarray(sheet["normal"], float)
    if lower_mm is not None:
        poly = plane_box_section(o, n, lower_mm, upper_mm)
    else:
        prints = []
        for cam in rig.cameras.values():
            pos, d = sensor_corner_rays(cam)
            den = d @ n
            with np.errstate(divide="ignore", invalid="ignore"):
                t = ((o - pos) @ n) / den
            if np.all(np.isfinite(t) & (t > 0)):
                prints.append(pos + t[:, None] * d)
        if not prints:
            return np.zeros((0, 3))
        poly = prints[0]
        for fp in prints[1:]:  # the common view: cut by each footprint's edges
            c = fp.mean(axis=0)
            for k in range(len(fp)):
                a, b = fp[k], fp[(k + 1) % len(fp)]
                out = np.cross(b - a, n)
                out = out if (c - a) @ out < 0 else -out
                poly = clip_polygon(poly, a, out)
        if len(poly) < 3:  # no shared view: the joint extent (convex hull in the plane)
            from scipy.spatial import ConvexHull

            pts = np.concatenate(prints)
            u, v = plane_basis(n)
            poly = pts[ConvexHull(np.stack([pts @ u, pts @ v], axis=-1)).vertices]
    if sheet.get("width_mm") and len(poly):
        w = np.cross(n, np.asarray(sheet["direction"], float))
        w /= np.linalg.norm(w)
        half = 0.5 * float(sheet["width_mm"])
        poly = clip_polygon(clip_polygon(poly, o + half * w, w), o - half * w, -w)
    return poly


def sheet_focus(rig: SceneRig, lower_mm=None, upper_mm=None) -> dict:
    """How much of each laser sheet's mid-plane each camera with a focus images sharply.

    The mid-plane within the box (or the cameras' common view, :func:`sheet_region`) is
    sampled on a 32 x 32 grid; for each camera the points it sees (``visible``) count as in
    focus where their defocus blur is within one pixel (a plenoptic camera: within its
    refocusing range), :func:`mitpiv.physics.camera.defocus_ratio` with the camera's tilted
    plane of focus where it has one. An ideal pinhole is infinitely deep and left out.

    Returns
    -------
    dict
        ``{sheet id: {"region_mm": (K, 3), "cameras": {sensor id: {"in_focus": fraction,
        "depth_mm": (min, max) depth of the seen points along the axis, "axis_meets_sheet_mm":
        distance at which the optical axis meets the mid-plane (None: parallel or behind),
        "focus": focal_depth(), "tilted": bool}}}}``.
    """
    from mitpiv.physics.camera import camera_to_world, defocus_ratio, focal_depth
    from mitpiv.physics.sheet import polygon_points

    out = {}
    for sid, sheet in rig.sheets.items():
        region = sheet_region(rig, sheet, lower_mm, upper_mm)
        pts = polygon_points(region, 32)
        res = {}
        o, n = np.asarray(sheet["origin_mm"], float), np.asarray(sheet["normal"], float)
        for name, cam in rig.cameras.items():
            fd = focal_depth(cam)
            if fd is None or not len(pts):
                continue
            seen = np.asarray(cam.visible(pts), bool)
            if not seen.any():
                continue
            tilt = rig.focus_normals.get(name)
            r = defocus_ratio(cam, pts[seen], focus_plane_normal=tilt)
            m = camera_to_world(cam)
            z = (pts[seen] - m[:3, 3]) @ m[:3, 2]
            den = float(m[:3, 2] @ n)
            t = float((o - m[:3, 3]) @ n) / den if abs(den) > 1e-9 else None
            res[name] = {"in_focus": float(np.mean(r <= 1.0)), "depth_mm": (float(z.min()), float(z.max())),
                         "axis_meets_sheet_mm": t if t is not None and t > 0 else None, "focus": fd,
                         "tilted": tilt is not None}
        out[sid] = {"region_mm": region, "cameras": res}
    return out


def check_sheet_focus(rig: SceneRig, lower_mm=None, upper_mm=None, *, what: str) -> dict:
    """Warn (:class:`~mitpiv.errors.MitpivWarning`) when a camera has less than
    :data:`FOCUS_WARN` of a laser sheet's mid-plane within the volume in focus
    (:func:`sheet_focus`), or when the mid-plane misses the volume; the message names each
    camera's in-focus share, the depths of the mid-plane along its axis, its depth of field
    and the focus distance that would put the sheet in focus. Returns :func:`sheet_focus`."""
    import warnings

    from mitpiv.errors import MitpivWarning

    res = sheet_focus(rig, lower_mm, upper_mm)
    box = "" if lower_mm is None else \
        f" within {[float(v) for v in lower_mm]}..{[float(v) for v in upper_mm]} mm"
    for sid, r in res.items():
        sheet = rig.sheets[sid]
        plane = (f"laser sheet {sid!r} (mid-plane through {[round(float(v), 4) for v in sheet['origin_mm']]} mm, "
                 f"normal {[round(float(v), 4) for v in sheet['normal']]})")
        if not len(r["region_mm"]):  # the mid-plane misses the volume: does the slab miss it too?
            if lower_mm is not None:
                from mitpiv.physics.camera import box_corners

                d = (box_corners(lower_mm, upper_mm) - np.asarray(sheet["origin_mm"], float)) @ \
                    np.asarray(sheet["normal"], float)
                half = 0.5 * float(sheet["thickness_mm"])
                if d.min() > half or d.max() < -half:
                    warnings.warn(f"{what}: the {plane} does not reach the volume{box}: its {2 * half:g} mm thick "
                                  f"slab spans {-half:g}..{half:g} mm about the mid-plane along its normal, the volume "
                                  f"{d.min():.4g}..{d.max():.4g} mm; no particle in it is lit. Move the sheet's "
                                  f"origin into the volume.", MitpivWarning, stacklevel=2)
            continue
        lines = []
        for name, c in r["cameras"].items():
            if c["in_focus"] >= FOCUS_WARN:
                continue
            fd = c["focus"]
            far = "infinity" if not np.isfinite(fd["far_mm"]) else f"{fd['far_mm']:.4g}"
            tilt = ", about its tilted plane of focus" if c["tilted"] else ""
            hint = "" if c["axis_meets_sheet_mm"] is None else \
                f" (its axis meets the mid-plane {c['axis_meets_sheet_mm']:.4g} mm away)"
            lines.append(f"camera {name!r} has {100 * c['in_focus']:.0f} % of it in focus: the mid-plane lies "
                         f"{c['depth_mm'][0]:.4g}..{c['depth_mm'][1]:.4g} mm from it along its axis{hint}, its "
                         f"{fd['what']} {fd['near_mm']:.4g}..{far} mm (focus_distance_mm "
                         f"{fd['focus_distance_mm']:.4g}{tilt})")
        if lines:
            warnings.warn(f"{what}: the {plane}{box}: {'; '.join(lines)}. Particles there image as blurred spots; "
                          f"focus each camera on the sheet (focus_distance_mm where its axis meets the mid-plane), "
                          f"tilt its plane of focus onto the sheet (focus_plane_normal = the sheet normal: "
                          f"Scheimpflug) or stop it down (a larger f_number), if that is not intended.",
                          MitpivWarning, stacklevel=2)
    return res


def count_for_density(cfg) -> int:
    """Particle count for the target per-pixel (or per-microlens) density of ``[seeding]``
    (``ppp``, and ``particles_per_microlens`` where the kind has it) in one sensor of the
    scene (``[seeding] density_sensor``, default the first rendered one), from the scene's
    sensors alone (:func:`mitpiv.render.scene.load_sensors`: no particle file is needed)."""
    from mitpiv.io import camera_from_metadata
    from mitpiv.physics.seeding import count_for_density as count
    from mitpiv.render.render import sensor_model
    from mitpiv.render.scene import load_sensors
    from mitpiv.streams import derived_seed

    s = cfg.seeding
    sensors = load_sensors(cfg.scene.xml, params=cfg.scene.params)
    wanted = s.density_sensor or (cfg.render.sensors or [next(iter(sensors))])[0]
    if wanted not in sensors:
        raise ConfigError(f"experiment: [seeding] density_sensor = {wanted!r} is not in the scene; its sensors are "
                          f"{sorted(sensors)}.")
    camera = camera_from_metadata({"camera": sensor_model(sensors[wanted])})
    try:
        # both densities given: the camera's kind picks (per microlens for a plenoptic one);
        # the visible fraction's Monte Carlo points take a stream of their own, not the seeding's
        return count(camera, s.box_min_mm, s.box_max_mm, ppp=s.ppp,
                     particles_per_microlens=getattr(s, "particles_per_microlens", None),
                     seed=derived_seed(cfg.seed, "density", wanted))
    except ConfigError as e:
        raise ConfigError(f"experiment: [seeding] density sensor {wanted!r}: {e}") from None


# ------------------------------------------------------------------------------- a run's records
def frame_files(run: Path, frame: int, source: str = "render") -> list[Path]:
    """The EXR files of one frame from the ``render`` or ``sensor`` stage, one per camera
    (sorted by sensor id)."""
    files = sorted((run / source).glob(f"*_frame{frame:03d}.exr"))
    if not files:
        raise ConfigError(f"experiment: no images of frame {frame} in {run / source}.")
    return files


def images(run: Path, frame: int, source: str = "render"):
    """The images of one frame from the ``render`` or ``sensor`` stage: (arrays (float64
    (H, W)), metadata, files), one per camera (sorted by sensor id)."""
    from mitpiv.io import read_exr

    files = frame_files(run, frame, source)
    data = [read_exr(f) for f in files]
    return [np.asarray(img if img.ndim == 2 else img[..., 0], dtype=np.float64) for img, _ in data], \
        [m for _, m in data], files


def frame_images(run: Path, frame: int, source: str = "render") -> tuple[list[np.ndarray], list[dict]]:
    """The images (float64 (H, W)) and metadata of one frame, one per camera (sorted by id)."""
    imgs, metas, _ = images(run, frame, source)
    return imgs, metas


def volume(run: Path, frame: int):
    """The reconstructed volume of one frame (the ``reconstruct`` stage's ``volume_<frame>.npz``)."""
    from mitpiv.io import read_volume

    return read_volume(run / "reconstruct" / f"volume_{frame}.npz")[0]


def read_tracks(path):
    """A :class:`~mitpiv.tracking.stb.Tracks` from the track stage's ``tracks.npz``."""
    from mitpiv.io import read_npz
    from mitpiv.tracking import Tracks

    z = read_npz(path, what="tracks", required=("positions_mm", "intensities", "dt_s"))
    return Tracks(z["positions_mm"], z["intensities"], float(z["dt_s"]), z.get("velocities_mm_s"),
                  z.get("accelerations_mm_s2"), z.get("raw_positions_mm"))


def run_images(run_dir) -> dict:
    """The images of a run for export: the sensor stage's counts when the run has one, else
    the render stage's radiance.

    Returns
    -------
    dict: ``source`` (``"sensor"`` / ``"render"``), ``sensors`` (ids, sorted), ``frames``
    (frame numbers, sorted), ``files`` (per sensor, the EXR paths of its frames), ``cameras``
    (per sensor, the camera from the first frame's metadata).

    Raises
    ------
    FileFormatError
        No rendered images (the render stage has not finished), sensors with differing
        frames, or images without a camera in their metadata.
    """
    from mitpiv.io import camera_from_metadata, read_exr

    run = Path(run_dir)
    read_run_record(run, owner="export")
    source = next((s for s in ("sensor", "render") if (run / s / "stage.json").is_file()), None)
    files = sorted((run / source).glob("*_frame*.exr")) if source else []
    if not files:
        raise FileFormatError(f"export: the run {str(run)!r} has no rendered images (no finished render stage); "
                              f"run 'mitpiv run EXPERIMENT --out {run}' first.")
    by_sensor: dict[str, dict[int, Path]] = {}
    for f in files:
        sid, _, num = f.stem.rpartition("_frame")
        if not num.isdigit():
            continue
        by_sensor.setdefault(sid, {})[int(num)] = f
    sensors = sorted(by_sensor)
    frames = sorted(by_sensor[sensors[0]])
    for s in sensors:
        if sorted(by_sensor[s]) != frames:
            raise FileFormatError(f"export: sensor {s!r} of {str(run / source)!r} has frames {sorted(by_sensor[s])}, "
                                  f"sensor {sensors[0]!r} has {frames}; re-run the render stage.")
    cameras = [camera_from_metadata(read_exr(by_sensor[s][frames[0]])[1]) for s in sensors]
    return {"source": source, "sensors": sensors, "frames": frames,
            "files": [[by_sensor[s][k] for k in frames] for s in sensors], "cameras": cameras}


def read_run_record(run, *, owner: str) -> dict:
    """A finished run folder's ``experiment.json``; a :class:`FileFormatError` naming ``owner``
    when ``run`` is not a run folder."""
    from mitpiv.io.records import read_json

    f = Path(run) / "experiment.json"
    if not f.is_file():
        raise FileFormatError(f"{owner}: {str(run)!r} is not a run folder (no experiment.json); give the --out "
                              "folder of 'mitpiv run'.")
    return read_json(f)


#: The stages that write a run's truth: ``particles`` (a tomo run), ``field`` (a tracking or
#: backlit run).
TRUTH_STAGES = ("particles", "field")


def truth_file(run) -> Path | None:
    """The truth file of a finished run of any kind (the first of :data:`TRUTH_STAGES` that
    wrote one), or None."""
    return next((Path(run) / s / "truth.npz" for s in TRUTH_STAGES if (Path(run) / s / "truth.npz").is_file()), None)


def run_truth(run: Path, stage: str) -> dict:
    """The truth file a run's ``stage`` wrote (``particles`` of a tomo run, ``field`` of a
    tracking or backlit run), :func:`mitpiv.io.read_truth`."""
    from mitpiv.io import read_truth

    return read_truth(run / stage / "truth.npz")


def grid_of(cfg):
    """The voxel grid of a tomo experiment's ``[reconstruction]`` (bounds_mm, voxel_mm)."""
    from mitpiv.grid import VoxelGrid

    b = cfg.reconstruction.bounds_mm
    return VoxelGrid.from_bounds((b[0], b[2], b[4]), (b[1], b[3], b[5]), cfg.reconstruction.voxel_mm)


def source_of(cfg) -> str:
    """The stage whose images a tomo run reconstructs: ``sensor`` with a [sensor] table, else ``render``."""
    return "sensor" if cfg.sensor is not None else "render"


@cache
def sensor_table():
    """The ``[sensor]`` table of the kinds that render (the tomo and tracking kinds): the
    camera sensor model :class:`mitpiv.imaging.SensorModel`, built from its signature."""
    from mitpiv.imaging import SensorModel

    base = model_from_signature("SensorTable", SensorModel, doc="The camera sensor model (mitpiv.imaging.SensorModel).")

    class SensorTable(base):
        @model_validator(mode="after")
        def _physics(self):
            SensorModel(**self.model_dump())  # its own range checks (ConfigError -> ValueError)
            noise = [k for k in ("gaussian_noise_percent", "read_noise_e") if getattr(self, k)] + (
                ["dark_current_e_per_s"] if self.dark_current_e_per_s * self.exposure_time_s else [])
            exposed = not (self.exposure is None and self.peak_photons is None and self.illumination_time_s is None)
            electrons = [k for k in noise if k != "gaussian_noise_percent"]
            if electrons and not exposed and self.bit_depth is None:
                raise ValueError(
                    f"{', '.join(electrons)} in electrons but no 'exposure', 'peak_photons' or 'illumination_time_s': "
                    f"the rendered radiance (~1e-5) would be taken as photons, far below the noise; give "
                    f"peak_photons (e.g. 2000), exposure or illumination_time_s")
            if self.bit_depth is not None and noise and not exposed:
                raise ValueError(
                    f"bit_depth = {self.bit_depth} with noise ({', '.join(noise)}) but no 'exposure', 'peak_photons' or "
                    f"'illumination_time_s': the rendered radiance (~1e-5) would be taken as photons and round to 0 "
                    f"counts, leaving images of pure noise; give peak_photons (e.g. 2000), exposure or "
                    f"illumination_time_s")
            return self

    SensorTable.__doc__ = base.__doc__
    return SensorTable


def sensor_stage(ctx: StageContext, frames) -> dict:
    """The ``sensor`` stage: the rendered images of ``frames`` turned into counts by the
    experiment's ``[sensor]`` model (:func:`mitpiv.imaging.apply_sensor_set`, one exposure for
    the whole set), one EXR per camera and frame with the sensor's metadata."""
    from mitpiv.imaging import SensorModel, apply_sensor_set
    from mitpiv.io import write_exr
    from mitpiv.photometry import cameras_from_metadata, wavelength_from_metadata

    cfg = ctx.cfg
    model = SensorModel(**cfg.sensor.model_dump())
    rendered, metas, names = {}, {}, {}
    for frame in frames:
        imgs, ms, files = images(ctx.run_dir, frame, "render")
        for img, meta, f in zip(imgs, ms, files, strict=True):
            key = (meta.get("sensor_id") or f.stem.rsplit("_frame", 1)[0], frame)
            rendered[key], metas[key], names[key] = img, meta, f.name
    # each camera's counts follow its aperture (photometry "auto": when every camera states one)
    by_cam = {k[0]: metas[k] for k in metas}
    cameras = None if model.photometry == "image" else cameras_from_metadata(by_cam)
    # every image without particle signal (no exposure: radiance rounds to 0 counts) is refused
    res = apply_sensor_set(rendered, model, seed=cfg.seed, progress=ctx.progress, on_degenerate="raise",
                           cameras=cameras, wavelength_nm=wavelength_from_metadata(list(metas.values())))
    for key, c in res.counts.items():
        write_exr(ctx.out / names[key], np.asarray(c, dtype=np.float32),
                  {**metas[key], "sensor": res.metadata(key)})
    return {"exposure": res.exposure, "exposure_units": res.exposure_units, "photometry": res.photometry,
            "etendue_axis": res.etendue_axis, "scene_peak": res.scene_peak, "noise_peak_counts": res.noise_peak_counts}


def bounds_of(cfg) -> tuple[np.ndarray, np.ndarray]:
    """The measurement box (lower, upper) [mm]: [tracking] bounds_mm or the seeding box."""
    b = cfg.tracking.bounds_mm
    if b is None:
        return np.asarray(cfg.seeding.box_min_mm, float), np.asarray(cfg.seeding.box_max_mm, float)
    return np.array([b[0], b[2], b[4]], float), np.array([b[1], b[3], b[5]], float)


# ------------------------------------------------------------------------------- results
def null_metrics(metrics: dict, reasons: dict, *, where: str) -> dict:
    """Metrics with no value as ``None`` plus the reason: never NaN in a result.

    Every non-finite float (NaN, inf; in lists too) becomes ``None``; the dotted path of
    each (a list counts once) goes into ``metrics["null_reasons"]`` with the first reason of
    ``reasons`` (``{path prefix: reason}``, ``""`` matching all) whose prefix it starts
    with. Keys already ``None`` that ``reasons`` names exactly are listed too. A
    :class:`~mitpiv.errors.MitpivWarning` names them.
    """
    import math
    import warnings

    from mitpiv.errors import MitpivWarning

    nulls = {}

    def reason(path):
        return next((r for k, r in reasons.items() if path.startswith(k)), "not computable")

    def walk(x, path):
        if isinstance(x, dict):
            return {k: walk(v, f"{path}.{k}" if path else str(k)) for k, v in x.items()}
        if isinstance(x, list | tuple):
            out = [walk(v, None) for v in x]
            if any(v is None for v in out) and path is not None:
                nulls[path] = reason(path)
            return out
        if x is None and path in reasons:
            nulls[path] = reasons[path]
        if isinstance(x, float) and not math.isfinite(x):
            if path is not None:
                nulls[path] = reason(path)
            return None
        return x

    out = walk(metrics, "")
    if nulls:
        out["null_reasons"] = {**out.get("null_reasons", {}), **nulls}
        first = next(iter(nulls))
        warnings.warn(f"{where}: {len(nulls)} metric(s) have no value, e.g. {first!r}: {nulls[first]}.",
                      MitpivWarning, stacklevel=2)
    return out


def flatten(prefix, obj, out):
    """Flatten nested metrics into table columns: ``a.b``; a 3-vector ``v`` gives ``v_x, v_y, v_z``."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            flatten(f"{prefix}.{k}" if prefix else str(k), v, out)
    elif isinstance(obj, list) and all(isinstance(x, int | float) for x in obj) and len(obj) == 3:
        for axis, v in zip("xyz", obj, strict=True):
            out[f"{prefix}_{axis}"] = v
    elif isinstance(obj, int | float | str | bool) or obj is None:
        out[prefix] = obj


def fmt_metric(x, spec: str) -> str:
    """A metric for the headline and report tables: 'n/a' where it has no value."""
    return "n/a" if x is None else format(x, spec)


def pareto_front(seconds, errors) -> np.ndarray:
    """Mask of the points no other point beats in both time and error."""
    t, e = np.asarray(seconds, float), np.asarray(errors, float)
    keep = np.ones(len(t), bool)
    for i in range(len(t)):
        keep[i] = not np.any((t <= t[i]) & (e <= e[i]) & ((t < t[i]) | (e < e[i])))
    return keep
