"""Time-resolved Lagrangian particle tracking experiments (``kind = "tracking"``): a seeded
flow advected over N frames, every frame rendered by the scene's cameras, the particle
image model (OTF) calibrated from the images, Shake-The-Box over the sequence and the
tracks scored with the LPT Challenge's metrics.

Experiment file (paths relative to it; ``mitpiv schema --kind tracking`` lists every key)::

    kind = "tracking"
    name = "tracking-lpt"
    seed = 0
    [scene]        xml = "scene.xml"; params = { width = 320, height = 200 }
    [seeding]      box_min_mm, box_max_mm, one of count | concentration_per_mm3 | ppp,
                   diameter_um, reseed = "inflow" | "uniform", ...
    [flow]         kind = "uniform" | "solid_body" | ... | "channel" (mitpiv.physics.flows), dt_s
    [sequence]     frames (N), substeps (RK4 steps per frame)
    [render]       spp, sensors, workers (frames in parallel), chunk_frames
    [sensor]       the camera sensor (mitpiv.imaging.SensorModel: peak_photons, shot_noise,
                   read_noise_e, bit_depth, ...); optional, none: the tracker sees the radiance
    [calibration]  model = "true" | "pinhole" (a fit to a noisy virtual target), noise_px
    [otf]          source = "images" | "truth", subvolumes, window_px, frames
    [tracking]     bounds_mm, tolerance_px, search_px, ... (mitpiv.tracking.stb.stb)
    [evaluate]     radius_px, bin_mm
    [output]       vtk = true: ParaView files of the tracks in RUN/vtk
    [compare]      openlpt = true, tomo = true, tomo_*: other methods on the same images (opt-in,
                   mitpiv.studies.kinds.tracking.compare)

Stages: ``field`` (seeding and advection, :func:`mitpiv.physics.sequence.advect_sequence`;
one PLY per frame and the truth in the one truth format, with identities, velocities and
accelerations), ``render`` (EXR per camera and frame through
:func:`mitpiv.render.render.render_scene`, the renderer of the tomo kind; chunks of frames in
this process or, with ``[render] workers > 1``, on a local Dask cluster of processes, as
``mitpiv sweep`` runs its points), ``sensor`` (with a ``[sensor]`` table: counts per camera
and frame, :func:`mitpiv.studies.shared.sensor_stage`; the otf and track stages and the
``[compare]`` methods read them less the black level,
:func:`~mitpiv.studies.kinds.tracking.scoring.tracked_images`), ``calibrate`` (the cameras: the rendered images' own
models, or pinhole fits to a virtual calibration target, :func:`mitpiv.reconstruct.calibration.calibrate`),
``otf`` (:func:`mitpiv.tracking.otf.calibrate_otf` from particles triangulated in the
images), ``track`` (:func:`mitpiv.tracking.stb.stb`; a sequence shorter than four frames is
reconstructed frame by frame with IPR and has no velocities), ``evaluate``
(:func:`mitpiv.tracking.metrics.track_metrics` and :func:`~mitpiv.tracking.metrics.bin_tracks`),
``report`` (:func:`mitpiv.studies.report.tracking_report`) and ``vtk`` (with
``[output] vtk = true``, :func:`mitpiv.studies.export.export_tracking_vtk`). With
``[compare]``, ``openlpt`` and ``tomo`` run between evaluate and report
(:mod:`mitpiv.studies.kinds.tracking.compare`: OpenLPT's STB and MART + 3-D PIV on the same
frames and cameras, scored by :func:`~mitpiv.studies.kinds.tracking.scoring.score_tracks`
and :func:`~mitpiv.studies.kinds.tracking.scoring.binned_error`).

The kind is a package: this module (schema, stages, summary), :mod:`.scoring` (the run's
cameras and tracks, the truth as tracks, the scoring every method of a run shares) and
:mod:`.compare` (the ``[compare]`` stages).

The calibration runs after the rendering (the scene's cameras do not depend on it), so a
changed calibration setting does not render again.
"""

from __future__ import annotations

import math
import os
import shutil
from functools import cache
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, model_validator

from mitpiv.errors import CalibrationError, ConfigError
from mitpiv.studies.kinds.tracking.compare import CompareTable
from mitpiv.studies.kinds.tracking.compare import stages as compare_stages
from mitpiv.studies.kinds.tracking.compare import summary as compare_summary
from mitpiv.studies.kinds.tracking.scoring import load_cameras, score_tracks, tracked_images, write_tracks_npz
from mitpiv.studies.schema import Table, Vec3
from mitpiv.studies.shared import (
    RENDER_PACKAGES,
    Kind,
    SceneTable,
    Stage,
    StageContext,
    bounds_of,
    check_coverage,
    check_scene_sensors,
    check_sheet_focus,
    count_for_density,
    flow_union,
    frame_images,
    null_metrics,
    read_tracks,
    resolve_scene_xml,
    resolve_table_file,
    run_truth,
    scene_files,
    sensor_stage,
    sensor_table,
)

PosFloat = Annotated[float, Field(gt=0)]
PosInt = Annotated[int, Field(ge=1)]
Bounds = tuple[float, float, float, float, float, float]

#: Frames STB needs to start tracks; a shorter sequence is reconstructed frame by frame.
STB_MIN_FRAMES = 4
#: Most frames of one experiment (a bound on the truth arrays and the rendering).
MAX_FRAMES = 2000
#: Most frames the OTF calibration pools when the first [otf] frames hold too few isolated particles.
OTF_MAX_FRAMES = 32


# ------------------------------------------------------------------------------- schema
class SeedingTable(Table):
    """Particles seeded uniformly in a box and kept there at a constant count."""

    box_min_mm: Vec3 = Field(..., description="lower corner of the seeding box [mm]; particles leaving it are dropped")
    box_max_mm: Vec3 = Field(..., description="upper corner of the seeding box [mm]")
    count: Annotated[int, Field(ge=0)] | None = Field(None, description="number of particles")
    concentration_per_mm3: PosFloat | None = Field(None, description="particles per mm^3")
    ppp: PosFloat | None = Field(None, description="particles per pixel of the density sensor")
    density_sensor: str | None = Field(None, description="sensor id for ppp (default: the first rendered sensor)")
    diameter_um: PosFloat = Field(1.0, description="particle diameter (median of a log-normal) [um]")
    distribution: Literal["monodisperse", "lognormal"] = Field("monodisperse", description="diameter distribution")
    geometric_std: Annotated[float, Field(gt=1)] = Field(1.5, description="geometric standard deviation (lognormal)")
    proxy_radius_mm: PosFloat = Field(0.01, description="radius of the particles' proxy spheres in the scene [mm]")
    reseed: Literal["inflow", "uniform"] = Field(
        "inflow", description="where particles replacing those that left appear: at the inflow (points that crossed "
        "the box boundary during the frame) or anywhere in the box")

    @model_validator(mode="after")
    def _one_density(self):
        given = [k for k in ("count", "concentration_per_mm3", "ppp") if getattr(self, k) is not None]
        if len(given) != 1:
            raise ValueError(f"give exactly one of count, concentration_per_mm3 or ppp; got {given or 'none'}")
        if any(hi <= lo for lo, hi in zip(self.box_min_mm, self.box_max_mm, strict=True)):
            raise ValueError(f"box_max_mm {list(self.box_max_mm)} must exceed box_min_mm {list(self.box_min_mm)} "
                             "on every axis")
        return self


def _flow_union():
    return flow_union("TrackingFlow", "time between consecutive frames [s]")


class SequenceTable(Table):
    """The time-resolved sequence."""

    frames: Annotated[int, Field(ge=1, le=MAX_FRAMES)] = Field(
        ..., description=f"number of frames N (STB needs >= {STB_MIN_FRAMES}; fewer: IPR per frame, no velocities)")
    substeps: Annotated[int, Field(ge=1, le=1000)] = Field(8, description="RK4 steps per frame")


class RenderTable(Table):
    """Rendering (mitpiv.render.render.render_scene, as the tomo kind renders)."""

    spp: PosInt | None = Field(None, description="samples per pixel / particle tracer passes (default the scene's)")
    sensors: Annotated[list[str], Field(min_length=2)] | None = Field(
        None, description="ids of the scene's sensors to render (default all; tracking needs >= 2)")
    workers: Annotated[int, Field(ge=1, le=512)] = Field(
        1, description="1: render in this process; more: a local Dask cluster of this many processes, one chunk "
                       "of frames per task")
    chunk_frames: Annotated[int, Field(ge=1, le=MAX_FRAMES)] = Field(
        8, description="frames per rendering task (the scenes of a chunk are loaded together)")


class CalibrationTable(Table):
    """The cameras the tracker uses."""

    model: Literal["true", "pinhole"] = Field(
        "true", description="'true': the rendered images' camera models; 'pinhole': a pinhole fit (no distortion) to "
        "a virtual target of points in the seeding box, their images perturbed by noise_px")
    noise_px: Annotated[float, Field(ge=0)] = Field(
        0.0, description="pinhole: standard deviation of the target points' image positions [px]")
    points: Annotated[int, Field(ge=3, le=20)] = Field(
        6, description="pinhole: target points per axis of the seeding box (points^3 in all)")


class OtfTable(Table):
    """Calibration of the particle image model (mitpiv.tracking.otf.calibrate_otf)."""

    source: Literal["images", "truth", "file"] = Field(
        "images", description="3D positions of the fitted particles: triangulated in the images (as in an experiment) "
        "or the true ones; or 'file': the OTF of another run ([otf] file), e.g. a sparser recording of the same optics")
    file: str | None = Field(None, description="source = 'file': an otf.json written by the otf stage of another run "
                                               "(RUN/otf/otf.json), relative to the experiment's folder")
    file_sha256: str | None = Field(None, description="set by mitpiv: the file's content hash (a changed file reruns "
                                                      "the stage)")
    subvolumes: tuple[PosInt, PosInt, PosInt] = Field((1, 1, 1), description="sub-volumes (n_x, n_y, n_z)")
    window_px: Annotated[int, Field(ge=1, le=10)] = Field(2, description="half width of the fitted window [px]")
    frames: Annotated[int, Field(ge=1, le=MAX_FRAMES)] = Field(
        8, description="frames whose isolated particles are pooled in the fit (at most the sequence's); dense images "
        "hold few isolated particle images per frame")
    tolerance_px: PosFloat = Field(0.5, description="triangulation tolerance of the fitted particles [px]")
    isolation_px: PosFloat | None = Field(
        None, description="fit only particles with no other particle or image peak closer than this [px] (default "
        "2 window_px + 2)")
    refine: Annotated[int, Field(ge=0, le=5)] = Field(
        0, description="passes re-fitting the OTF on augmented residual images of the particles IPR reconstructs "
        "with it (frame 0; mitpiv.tracking.refine_otf)")

    @model_validator(mode="after")
    def _file(self):
        if (self.source == "file") != (self.file is not None):
            raise ValueError(f"give [otf] file together with source = 'file' (got source = {self.source!r}, file = "
                             f"{self.file!r})")
        return self


class TrackingTable(Table):
    """Shake-The-Box (mitpiv.tracking.stb.stb) and its IPR."""

    bounds_mm: Bounds | None = Field(
        None, description="measurement box [xmin, xmax, ymin, ymax, zmin, zmax] [mm] (default the seeding box)")
    tolerance_px: PosFloat = Field(1.0, description="triangulation tolerance of IPR [px]")
    search_px: PosFloat = Field(10.0, description="search radius from frame 0 to 1 around the velocity guess [px]")
    predict_px: PosFloat = Field(1.5, description="search radius around extrapolated positions (initialisation) [px]")
    max_shake_px: PosFloat = Field(1.0, description="a shaken particle farther than this from its prediction ends "
                                                    "its track [px]")
    velocity_guess_mm_s: Vec3 | None = Field(None, description="velocity guess of the initial linking [mm/s]")
    shake_iterations: Annotated[int, Field(ge=1, le=50)] = Field(4, description="shaking per frame")
    min_intensity: Annotated[float, Field(gt=0, lt=1)] = Field(0.1, description="particles below this fraction of "
                                                                                "the median intensity are dropped")
    outer_loops: Annotated[int, Field(ge=1, le=20)] = Field(4, description="IPR loops with all cameras")
    reduced_loops: Annotated[int, Field(ge=0, le=5)] = Field(1, description="IPR loops with one camera left out")
    regularise_window: Annotated[int, Field(ge=0, le=50)] = Field(
        3, description="half window of the track regularisation [frames] (0: none, then no velocities)")
    # the dense-sequence rules of mitpiv.tracking.stb.stb (issue 51, docs/guide.md "Dense sequences")
    predict_points: Annotated[int, Field(ge=4, le=50)] = Field(
        8, description="a track predicts from up to this many of its last positions (a line through 4-5, a "
                       "parabola through 6 or more; 4: the parabola through the last 4)")
    back_shake: bool = Field(True, description="start tracks also from pairs of untracked particles of the last "
                                               "two frames, extended two frames back by shaking")
    capped_residual: bool = Field(True, description="the residual IPR searches subtracts each tracked particle at "
                                                    "most at its track's median intensity of its last 6 frames")
    camera_gain: bool = Field(True, description="every shake uses the per-camera gain IPR measures on frame 0")
    track_gain: bool = Field(True, description="with camera_gain: the gain measured again on every frame from the "
                                               "tracks at least 6 frames old")
    link_from_tracks: bool = Field(True, description="new chains start from the nearest tracks' median velocity")
    frame_threshold: bool = Field(True, description="the residual's IPR detects against the frame's own threshold")
    joint_check: bool = Field(False, description="test tracks after the joint shake with the residual's particles")
    track_support: Annotated[float, Field(ge=0, lt=1)] = Field(
        0.0, description="with joint_check: end tracks whose particle some camera supports below this fraction "
                         "(0: off)")

    @model_validator(mode="after")
    def _bounds(self):
        b = self.bounds_mm
        if b is not None and not (b[0] < b[1] and b[2] < b[3] and b[4] < b[5]):
            raise ValueError(f"bounds_mm {list(b)} must be [xmin, xmax, ymin, ymax, zmin, zmax] with min < max")
        return self


class EvaluateTable(Table):
    """Scoring against the truth (mitpiv.tracking.metrics)."""

    radius_px: PosFloat = Field(1.0, description="match radius [px, object-space equivalent at the box centre]")
    bin_mm: PosFloat | tuple[PosFloat, PosFloat, PosFloat] | None = Field(
        None, description="Eulerian bin size [mm] (default: the measurement box in 4 x 4 x 4 bins)")


class OutputTable(Table):
    """Extra files a run writes beside its report."""

    vtk: bool = Field(False, description="ParaView / VTK files of the tracks and true trajectories in RUN/vtk")


class _Experiment(Table):
    """Checks across tables."""

    @model_validator(mode="after")
    def _sizes(self):
        from mitpiv import costs

        c, n = self.compare, self.sequence.frames
        if c.tomo and n < 2:
            raise ValueError(f"[compare] tomo = true correlates frame pairs: it needs [sequence] frames >= 2, got {n}")
        if c.tomo and c.tomo_pairs is not None and c.tomo_pairs > n - 1:
            raise ValueError(f"[compare] tomo_pairs = {c.tomo_pairs} exceeds the {n - 1} frame pair(s) of [sequence] "
                             f"frames = {n}; give at most {n - 1} or leave it out (all pairs)")

        if self.seeding.count is not None:
            n = self.seeding.count * self.sequence.frames  # particle samples; truth: 3 arrays of 3 float64
            costs.check_memory(costs.Cost(memory_bytes=2 * 9 * 8 * n, seconds=0.0, items=f"{n} particle samples"),
                               what=f"[seeding] count = {self.seeding.count} over [sequence] frames = "
                               f"{self.sequence.frames}", fix="seed fewer particles or render fewer frames", quiet=True)
        return self


@cache
def schema():
    """The tracking experiment model."""
    from pydantic import create_model

    fields = {
        "kind": (Literal["tracking"], Field("tracking", description="experiment kind")),
        "name": (Annotated[str, Field(min_length=1)], Field(..., description="experiment name (default: the file "
                                                                             "name)")),
        "seed": (Annotated[int, Field(ge=0, lt=2**63)], Field(0, description="experiment seed")),
        "scene": (SceneTable, Field(..., description="the scene")),
        "seeding": (SeedingTable, Field(..., description="particle seeding")),
        "flow": (_flow_union(), Field(..., description="the flow (kind and its parameters) and dt_s")),
        "sequence": (SequenceTable, Field(..., description="the time-resolved sequence")),
        "render": (RenderTable, Field(default_factory=RenderTable, description="rendering")),
        "sensor": (sensor_table() | None, Field(None, description="sensor model: photon and read noise, gain, bit "
                                                                  "depth (optional; none: the rendered radiance)")),
        "calibration": (CalibrationTable, Field(default_factory=CalibrationTable, description="camera calibration")),
        "otf": (OtfTable, Field(default_factory=OtfTable, description="particle image model calibration")),
        "tracking": (TrackingTable, Field(default_factory=TrackingTable, description="Shake-The-Box")),
        "evaluate": (EvaluateTable, Field(default_factory=EvaluateTable, description="scoring")),
        "output": (OutputTable, Field(default_factory=OutputTable, description="extra output files")),
        "compare": (CompareTable, Field(default_factory=CompareTable, description="other methods on the same images "
                                                                               "(opt-in)")),
    }
    return create_model("TrackingExperiment", __base__=_Experiment,
                        __doc__="A time-resolved particle tracking experiment: seeded flow over N frames, rendered, "
                                "tracked by Shake-The-Box and scored.", **fields)


def prepare(raw: dict, base_dir: Path) -> dict:
    """Resolve the scene XML and an [otf] file against the experiment's folder (before
    validation); the OTF file's content hash joins the otf table."""
    return resolve_table_file(resolve_scene_xml(raw, base_dir), "otf", base_dir,
                              hint="; give the otf.json of another run's otf stage (RUN/otf/otf.json)")


# ------------------------------------------------------------------------------- helpers
def _count(cfg) -> int:
    s = cfg.seeding
    if s.count is not None:
        return int(s.count)
    if s.concentration_per_mm3 is not None:
        return int(round(s.concentration_per_mm3 * np.prod(np.subtract(s.box_max_mm, s.box_min_mm))))
    return count_for_density(cfg)


def load_otf(run: Path):
    from mitpiv.io import read_json
    from mitpiv.tracking import OTF

    return OTF.from_dict(read_json(run / "otf" / "otf.json"))


# ------------------------------------------------------------------------------- stages
def stage_field(ctx: StageContext) -> dict:
    from mitpiv.io import write_particles_ply, write_truth
    from mitpiv.physics.flows import flow_from_dict
    from mitpiv.physics.sequence import advect_sequence
    from mitpiv.streams import generator

    cfg, out = ctx.cfg, ctx.out
    s = cfg.seeding
    f = cfg.flow.model_dump()
    dt = float(f.pop("dt_s"))
    flow = flow_from_dict(f)
    seq = advect_sequence(flow, box_min_mm=s.box_min_mm, box_max_mm=s.box_max_mm, n_frames=cfg.sequence.frames,
                          dt_s=dt, count=_count(cfg), diameter_um=s.diameter_um, distribution=s.distribution,
                          geometric_std=s.geometric_std, substeps=cfg.sequence.substeps, reseed=s.reseed,
                          seed=generator(cfg.seed, "tracking-field"), progress=ctx.progress)
    for k in range(cfg.sequence.frames):
        p, d, _ = seq.frame(k)
        write_particles_ply(out / f"particles_{k}.ply", p, d, proxy_radius_mm=s.proxy_radius_mm)
    write_truth(out / "truth.npz", positions_mm=seq.positions_mm, times_s=seq.times_s, diameters_um=seq.diameters_um,
                velocities_mm_s=seq.velocities_mm_s, accelerations_mm_s2=seq.accelerations_mm_s2, ids=seq.ids,
                flow=flow.to_dict(), extra={"seed": cfg.seed, "box_min_mm": list(s.box_min_mm),
                                            "box_max_mm": list(s.box_max_mm), "reseed": s.reseed})
    present = seq.present
    return {"n_particles": int(present[0].sum()), "n_identities": int(seq.ids.size), "frames": cfg.sequence.frames,
            "entered": int(seq.ids.size - present[0].sum())}


def render_chunk(xml: str, frames: list[int], params: dict, spp, seed: int, sensors, out_dir: str,
                 search_dirs=(), source_file=None) -> list[str]:
    """Render one chunk of frames (a module-level function: it runs in Dask workers too)."""
    from mitpiv.render.render import render_scene

    files = render_scene(xml, out_dir=out_dir, frames=frames, params=params, spp=spp, seed=seed, sensors=sensors,
                         search_dirs=search_dirs, source_file=source_file)
    (Path(out_dir) / "render.json").unlink(missing_ok=True)  # one index per chunk: the stage writes its own
    return [f.name for f in files]


def stage_render(ctx: StageContext) -> dict:
    from mitpiv.io import write_json
    from mitpiv.progress import bar

    cfg = ctx.cfg
    n = cfg.sequence.frames
    # the scene reads particles_$frame.ply beside itself: the stage keeps its own copy of the
    # XML and links the particle files beside it while it renders (as the tomo kind does)
    xml = ctx.out / "scene.xml"
    shutil.copy(cfg.scene.xml, xml)
    links = []
    r = cfg.render
    chunks = [list(range(i, min(i + r.chunk_frames, n))) for i in range(0, n, r.chunk_frames)]
    # the files the XML names (a calibration) are found beside the original
    args = (str(xml), dict(cfg.scene.params), r.spp, cfg.seed, r.sensors, str(ctx.out), [str(Path(cfg.scene.xml).parent)],
            str(cfg.scene.xml))
    names: list[str] = []
    try:
        for k in range(n):
            src, dst = ctx.input("field", f"particles_{k}.ply"), ctx.out / f"particles_{k}.ply"
            try:
                os.link(src, dst)
            except OSError:  # a file system without hard links
                shutil.copy(src, dst)
            links.append(dst)
        with bar(len(chunks), desc="render frames", progress=ctx.progress, unit="chunk") as b:
            if r.workers > 1 and len(chunks) > 1:
                from dask.distributed import Client, LocalCluster, as_completed

                with LocalCluster(n_workers=r.workers, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, Client(cluster) as client:
                    futs = [client.submit(render_chunk, args[0], c, *args[1:], pure=False, retries=1) for c in chunks]
                    for fut in as_completed(futs):
                        names += fut.result()
                        b.update()
            else:
                for c in chunks:
                    names += render_chunk(args[0], c, *args[1:])
                    b.update()
    finally:
        for f in links:
            f.unlink(missing_ok=True)
    names = sorted(names)
    write_json(ctx.out / "render.json", {"scene": str(xml), "frames": list(range(n)), "files": names})
    return {"images": len(names), "chunks": len(chunks), "workers": r.workers}


def stage_sensor(ctx: StageContext) -> dict:
    return sensor_stage(ctx, range(ctx.cfg.sequence.frames))


def stage_calibrate(ctx: StageContext) -> dict:
    from mitpiv.io import camera_from_metadata
    from mitpiv.reconstruct.calibration import calibrate
    from mitpiv.streams import generator

    cfg = ctx.cfg
    c = cfg.calibration
    _, metas = frame_images(ctx.run_dir, 0)
    ids = [m.get("sensor_id") for m in metas]
    true = [camera_from_metadata(m) for m in metas]
    if len(true) < 2:
        raise ConfigError(f"experiment: tracking needs at least 2 cameras; the render stage made images of {ids}.")
    if c.model == "true":
        return _write_cameras(ctx.out, true, true, ids, [None] * len(true))
    lo, hi = np.asarray(cfg.seeding.box_min_mm, float), np.asarray(cfg.seeding.box_max_mm, float)
    axes = [np.linspace(lo[i], hi[i], c.points) for i in range(3)]
    world = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    fitted, reports = [], []
    for cam, sid in zip(true, ids, strict=True):
        vis = cam.visible(world)
        uv = cam.project(world[vis])
        uv = uv + generator(cfg.seed, "calibration-noise", sid).normal(0.0, c.noise_px, uv.shape)
        try:
            mapping = calibrate(uv, world[vis], model="pinhole", resolution=cam.resolution, distortion="none",
                                pixel_pitch_um=cam.pixel_pitch_um, max_rms_px=max(0.5, 5 * c.noise_px))
        except CalibrationError as e:
            raise CalibrationError(
                f"experiment: [calibration] model = 'pinhole': camera {sid!r} ({int(vis.sum())} target points, "
                f"noise_px = {c.noise_px}): {e} Use model = 'true', a smaller noise_px or more target points "
                f"([calibration] points).") from None
        fitted.append(mapping.camera)
        reports.append(mapping.fit_report)
    return _write_cameras(ctx.out, fitted, true, ids, reports)


def _write_cameras(out: Path, cams, true, ids, reports) -> dict:
    from mitpiv.io import write_json

    write_json(out / "cameras.json", {"ids": ids, "cameras": [c.to_dict() for c in cams],
                                      "true": [c.to_dict() for c in true], "fit": reports})
    err = [None if r is None else r.get("rms_px") for r in reports]
    return {"cameras": ids, "fit_rms_px": err}


def stage_otf(ctx: StageContext) -> dict:
    from mitpiv.io import write_json
    from mitpiv.tracking import calibrate_otf_frames, detect_peaks, ipr, refine_otf, triangulate

    cfg = ctx.cfg
    o = cfg.otf
    cams = load_cameras(ctx.run_dir)
    lo, hi = bounds_of(cfg)
    if o.source == "file":
        from mitpiv.io import read_json
        from mitpiv.tracking import OTF

        try:
            otf = OTF.from_dict(read_json(o.file))
        except (KeyError, TypeError, ValueError) as e:
            raise ConfigError(f"experiment: [otf] file = {o.file!r} is not an otf.json of the otf stage ({e}).") from None
        if otf.n_cameras != len(cams):
            raise ConfigError(f"experiment: [otf] file = {o.file!r} holds {otf.n_cameras} cameras, the experiment "
                              f"{len(cams)}; give the OTF of a run with the same cameras.")
        write_json(ctx.out / "otf.json", otf.to_dict())
        return {"sigma_max_px": otf.sigma_max_px(), "peak": [float(np.median(otf.peak[k])) for k in range(len(cams))],
                "source": "file", "file": o.file}
    truth = run_truth(ctx.run_dir, "field") if o.source == "truth" else None
    imgs_all, pts_all = [], []

    def load(n):  # the first n frames' images and fitted positions
        for f in range(len(imgs_all), n):
            imgs = tracked_images(cfg, ctx.run_dir, f)
            if o.source == "truth":
                p = truth["positions_mm"][f]
                p = p[np.all(np.isfinite(p), axis=1)]
            else:
                peaks = [detect_peaks(i)[0] for i in imgs]
                p, _, _ = triangulate(peaks, cams, tolerance_px=o.tolerance_px, lower_mm=lo, upper_mm=hi)
            imgs_all.append(imgs)
            pts_all.append(p)
        return imgs_all[:n], pts_all[:n]

    # one fit over the frames: the isolated particles of every frame are pooled. Dense images
    # hold few isolated particle images: without a given isolation_px, more frames (up to
    # OTF_MAX_FRAMES), then the closest isolation that keeps the neighbours out of the fitted
    # window (2 window_px + 1: a neighbour's image centre at least 3 px beyond the window)
    n_all = min(cfg.sequence.frames, max(o.frames, OTF_MAX_FRAMES))
    tries = [(min(o.frames, cfg.sequence.frames), o.isolation_px)]
    if o.isolation_px is None:
        tries += [(n_all, None), (n_all, 2.0 * o.window_px + 1)]
    for k, (n, iso) in enumerate(tries):
        try:
            imgs, pts = load(n)
            otf = calibrate_otf_frames(imgs, cams, pts, lower_mm=lo, upper_mm=hi, subvolumes=o.subvolumes,
                                       window_px=o.window_px, isolation_px=iso)
            used = (n, 2.0 * o.window_px + 2 if iso is None else float(iso))
            break
        except CalibrationError as e:
            if k == len(tries) - 1:
                raise CalibrationError(
                    f"experiment: [otf] the images are too dense to calibrate the particle image model from isolated "
                    f"particles ({e}). Calibrate it from a sparser recording of the same optics and give its "
                    f"OTF ([otf] source = \"file\", file = \"RUN/otf/otf.json\"), or [otf] source = \"truth\" "
                    f"(a diagnostic: true positions).") from None
    sigmas = [otf.sigma_max_px()]
    for _ in range(o.refine):
        r = ipr(imgs_all[0], cams, otf, lower_mm=lo, upper_mm=hi, tolerance_px=cfg.tracking.tolerance_px,
                min_intensity=cfg.tracking.min_intensity)
        otf = refine_otf(imgs_all[0], cams, otf, r.positions_mm, r.intensities, window_px=o.window_px)
        sigmas.append(otf.sigma_max_px())
    write_json(ctx.out / "otf.json", otf.to_dict())
    return {"sigma_max_px": otf.sigma_max_px(), "peak": [float(np.median(otf.peak[k])) for k in range(otf.n_cameras)],
            "fitted_from": int(sum(p.shape[0] for p in pts_all[:used[0]])), "frames": used[0],
            "isolation_px": used[1], "source": o.source,
            "sigma_max_px_per_pass": sigmas}


def track_images(sequence, cameras, otf, *, dt_s: float, lower_mm, upper_mm, tracking,
                 calibration_error_px: float | None = None, progress=None):
    """Track a sequence (list of frames, each a list of per-camera images) with the
    settings of a [tracking] table: STB for 4 frames or more; fewer, IPR per frame (every
    particle a track of one frame, no velocities). ``calibration_error_px``: the
    calibration's reprojection error, when known; IPR refuses a triangulation tolerance that
    does not exceed it. Returns :class:`~mitpiv.tracking.stb.Tracks`."""
    from mitpiv.tracking import Tracks, ipr, stb

    t = tracking
    opts = {"tolerance_px": t.tolerance_px, "outer_loops": t.outer_loops, "reduced_loops": t.reduced_loops}
    if calibration_error_px is not None:
        opts["calibration_error_px"] = float(calibration_error_px)
    if len(sequence) >= STB_MIN_FRAMES:
        return stb(sequence, cameras, otf, dt_s=dt_s, lower_mm=lower_mm, upper_mm=upper_mm, search_px=t.search_px,
                   predict_px=t.predict_px, max_shake_px=t.max_shake_px, velocity_guess=t.velocity_guess_mm_s,
                   shake_iterations=t.shake_iterations, min_intensity=t.min_intensity, ipr_options=opts,
                   regularise_window=t.regularise_window, predict_points=t.predict_points, back_shake=t.back_shake,
                   capped_residual=t.capped_residual, camera_gain=t.camera_gain, track_gain=t.track_gain,
                   link_from_tracks=t.link_from_tracks, frame_threshold=t.frame_threshold,
                   joint_check=t.joint_check, track_support=t.track_support, progress=progress)
    res = [ipr(imgs, cameras, otf, lower_mm=lower_mm, upper_mm=upper_mm, min_intensity=t.min_intensity, **opts)
           for imgs in sequence]
    n = sum(len(r) for r in res)
    pos = np.full((n, len(sequence), 3), np.nan)
    inten = np.full((n, len(sequence)), np.nan)
    start = 0
    for f, r in enumerate(res):
        pos[start:start + len(r), f] = r.positions_mm
        inten[start:start + len(r), f] = r.intensities
        start += len(r)
    return Tracks(pos, inten, float(dt_s), history=[{"frame": f, "particles": len(r)} for f, r in enumerate(res)])


def check_track_coverage(cfg, cameras: dict) -> None:
    """The track stage's scene check: the measurement box (``[tracking] bounds_mm`` or the
    seeding box) in every camera's view (:func:`~mitpiv.studies.shared.check_coverage`)."""
    lo, hi = bounds_of(cfg)
    what = "[tracking] bounds_mm" if cfg.tracking.bounds_mm is not None else "[seeding] box_min_mm..box_max_mm"
    check_coverage(cameras, lo, hi, what=f"experiment {cfg.name!r}: {what}",
                   fix="give a box within the cameras' common view (or aim the cameras at it)")


def check_sheet_in_focus(cfg, rig) -> None:
    """The render stage's rig check: the laser sheet's mid-plane within the measurement box
    inside the depth of field of each camera that has a focus
    (:func:`~mitpiv.studies.shared.check_sheet_focus`: a warning, never a refusal)."""
    lo, hi = bounds_of(cfg)
    what = "[tracking] bounds_mm" if cfg.tracking.bounds_mm is not None else "[seeding] box_min_mm..box_max_mm"
    check_sheet_focus(rig, lo, hi, what=f"experiment {cfg.name!r}: {what}")


def stage_track(ctx: StageContext) -> dict:
    cfg = ctx.cfg
    cams = load_cameras(ctx.run_dir)
    otf = load_otf(ctx.run_dir)
    lo, hi = bounds_of(cfg)
    ids = (ctx.results.get("calibrate") or {}).get("cameras") or [f"camera{i}" for i in range(len(cams))]
    check_track_coverage(cfg, dict(zip(ids, cams, strict=True)))  # what --check did, with the calibrated cameras
    seq = [tracked_images(cfg, ctx.run_dir, f) for f in range(cfg.sequence.frames)]
    fit = [e for e in (ctx.results.get("calibrate") or {}).get("fit_rms_px") or [] if e is not None]
    tr = track_images(seq, cams, otf, dt_s=cfg.flow.dt_s, lower_mm=lo, upper_mm=hi, tracking=cfg.tracking,
                      calibration_error_px=max(fit) if fit else None, progress=ctx.progress)
    write_tracks_npz(ctx.out / "tracks.npz", tr)
    lengths = tr.lengths
    return {"n_tracks": tr.n_tracks, "mean_track_length": float(lengths.mean()) if lengths.size else 0.0,
            "method": "stb" if cfg.sequence.frames >= STB_MIN_FRAMES else "ipr",
            "history": tr.history}


def stage_evaluate(ctx: StageContext) -> dict:
    from mitpiv.io import write_npz

    cfg = ctx.cfg
    tracks = read_tracks(ctx.run_dir / "track" / "tracks.npz")
    sc = score_tracks(cfg, ctx.run_dir, tracks)
    m, per_frame, hist, vel_err, binned = (sc[k] for k in ("metrics", "per_frame", "length_histogram",
                                                            "velocity_error_mm_s", "binned"))
    write_npz(ctx.out / "errors.npz", {"velocity_error_mm_s": vel_err, "length_histogram": np.asarray(hist),
                                       "yield_per_frame": np.array([p["yield"] for p in per_frame], float),
                                       "ghost_per_frame": np.array([p["ghost_fraction"] for p in per_frame], float),
                                       **binned}, owner="tracking")
    short = cfg.sequence.frames < STB_MIN_FRAMES or cfg.tracking.regularise_window == 0
    why = (f"a sequence of {cfg.sequence.frames} frame(s) is reconstructed frame by frame (STB needs "
           f"{STB_MIN_FRAMES}): particles have no velocity" if cfg.sequence.frames < STB_MIN_FRAMES else
           "[tracking] regularise_window = 0: the tracks carry no velocities")
    reasons = {"velocity": why, "acceleration": why, "binned": why} if short else {}
    reasons.update({"position_error": "no reconstructed particle matched a true one",
                    "yield": "no true particle in the measurement box",
                    "ghost_fraction": "no particle was reconstructed",
                    "correct_track": "no track sample inside the measurement box",
                    "velocity_error_rel": "the true velocities are all zero: a relative error is undefined",
                    "acceleration_error_rel": "the true accelerations are all zero (e.g. a uniform flow): a relative "
                                              "error is undefined",
                    "": "not computable"})
    for k in ("velocity_error_mm_s", "velocity_error_rel", "acceleration_error_mm_s2", "acceleration_error_rel",
              "binned_mean_error_mm_s", "binned_error_rel"):
        if m.get(k) is None:
            m[k] = float("nan")  # no value: None in the result, with its reason
    out = null_metrics(m, reasons, where="tracking evaluate")
    out["length_histogram"] = hist
    out["per_frame"] = [{k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in p.items()}
                        for p in per_frame]
    return out


def stage_report(ctx: StageContext) -> dict:
    from mitpiv.studies import report

    return report.write(report.tracking_report(ctx.cfg, ctx.run_dir, ctx.results, ctx.timings), ctx.out)


def stage_vtk(ctx: StageContext) -> dict:
    from mitpiv.studies.export import export_tracking_vtk

    return {"files": [f.name for f in export_tracking_vtk(ctx.run_dir, ctx.out, progress=ctx.progress)]}


def stages(cfg) -> list[Stage]:
    dens = cfg.seeding.ppp is not None
    out = [Stage("field", ("seed", "seeding", "flow", "sequence") + (("scene", "render") if dens else ()), stage_field,
                 files=scene_files if dens else None, packages=RENDER_PACKAGES if dens else ()),
           Stage("render", ("scene", "render"), stage_render, files=scene_files, packages=RENDER_PACKAGES,
                 check=check_scene_sensors, rig_check=check_sheet_in_focus),
           *([Stage("sensor", ("sensor",), stage_sensor)] if cfg.sensor is not None else []),
           Stage("calibrate", ("calibration",), stage_calibrate),
           Stage("otf", ("otf", "tracking"), stage_otf),
           Stage("track", ("tracking", "flow"), stage_track, scene_check=check_track_coverage),
           Stage("evaluate", ("evaluate",), stage_evaluate),
           *compare_stages(cfg),
           Stage("report", (), stage_report)]
    if cfg.output.vtk:
        out.append(Stage("vtk", ("output",), stage_vtk))
    return out


# ------------------------------------------------------------------------------- summary
METRIC_KEYS = ("yield", "ghost_fraction", "position_error_px", "position_error_mm", "velocity_error_mm_s",
               "velocity_error_rel", "acceleration_error_mm_s2", "acceleration_error_rel", "correct_track_fraction",
               "mean_track_length", "n_tracks", "ppp", "binned_mean_error_mm_s", "binned_error_rel", "binned_coverage",
               "calibration_error_px")


def summary(cfg, results: dict) -> dict:
    """metrics.json of a tracking run: the evaluate stage's metrics, the particle count and
    the tracking method."""
    ev = results.get("evaluate") or {}
    out = {"name": cfg.name, "seed": cfg.seed, "kind": "tracking", "evaluate": ev,
           "n_particles": (results.get("field") or {}).get("n_particles"), "frames": cfg.sequence.frames,
           "method": (results.get("track") or {}).get("method")}
    compare = compare_summary(results)
    if compare:
        out["compare"] = compare
    return out


def row(metrics: dict) -> dict:
    """The sweep-table columns: the LPT Challenge metrics (yield, ghost_fraction,
    position_error_px, ...), ppp, n_particles, frames, and with ``[compare]`` the other
    methods' scalar results as ``openlpt.<key>`` and ``tomo.<key>``."""
    ev = metrics.get("evaluate") or {}
    out = {k: ev.get(k) for k in METRIC_KEYS}
    out.update({"n_particles": metrics.get("n_particles"), "frames": metrics.get("frames"),
                "method": metrics.get("method")})
    for name, res in (metrics.get("compare") or {}).items():  # opt-in methods: "openlpt.yield", "tomo.wall_s", ...
        out.update({f"{name}.{k}": v for k, v in res.items() if isinstance(v, int | float | str | bool) or v is None})
    return out


def _pct(x):
    return "n/a" if x is None else f"{100 * x:.1f} %"


def _num(x, spec):
    return "n/a" if x is None else format(x, spec)


def headline(m: dict) -> str:
    ev = m.get("evaluate") or {}
    n = m.get("frames")
    text = (f"{m['name']}: {n} frame{'' if n == 1 else 's'}, ppp {_num(ev.get('ppp'), '.4f')}, yield {_pct(ev.get('yield'))}, "
            f"ghosts {_pct(ev.get('ghost_fraction'))}, position error {_num(ev.get('position_error_px'), '.3f')} px, "
            f"velocity error {_pct(ev.get('velocity_error_rel'))}")
    why = ev.get("null_reasons") or {}
    if why:
        text += f" (no value: {next(iter(why.values()))})"
    return text


KIND = Kind(name="tracking", build_schema=schema, stages=stages, summary=summary, row=row, prepare=prepare,
            headline=headline, describe="time-resolved sequence, Shake-The-Box tracking and LPT Challenge metrics",
            columns=(*METRIC_KEYS, "n_particles", "frames", "method", "openlpt.*", "tomo.*"))
