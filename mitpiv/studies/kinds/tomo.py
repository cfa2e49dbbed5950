"""Particle-image experiments (``kind = "tomo"``, the default; ``"particles"`` is its old
name): seeded particles advected by a flow, rendered by the scene's cameras (pinhole,
distorted, thin-lens or plenoptic), an optional sensor model, a volume reconstruction, the
particles found in it, 3D PIV, and every result scored against the truth.

Experiment file (paths relative to it; ``mitpiv schema`` lists every key with its unit,
default and range)::

    name = "tomo4-small"
    seed = 0
    [scene]            xml = "scene.xml"; params = { resolution = 256 }
    [seeding]          box_min_mm, box_max_mm, one of count | concentration_per_mm3 | ppp |
                       particles_per_microlens (ppp and particles_per_microlens may go
                       together: the density sensor's kind picks), diameter_um, ...
    [flow]             kind = "vortex_ring", ... (mitpiv.physics.flows), dt_s
    [render]           spp, sensors
    [sensor]           the sensor model (mitpiv.imaging.SensorModel); optional
    [reconstruction]   method, bounds_mm, voxel_mm, iterations, ...
    [piv]              windows, overlap, deform, interpolation, ...
    [particles]        method, threshold_rel, threshold_of, radius_voxels
    [report]           slice_axis, slice_mm: the plane of flow_slice.png
    [output]           vtk = true: ParaView files in RUN/vtk (mitpiv.studies.export)

Stages: ``particles`` (seeding, advection, PLY files, truth), ``render`` (EXR per camera
and frame), ``sensor`` (counts; only with a [sensor] table), ``reconstruct`` (volume per
frame), ``evaluate`` (particles and quality per frame), ``piv`` (vector field and its error
against the flow), ``report`` (report.md and figures, :mod:`mitpiv.studies.report`), ``vtk``
(only with ``[output] vtk = true``: :func:`mitpiv.studies.export.export_vtk`).
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

from mitpiv.costs import MAX_ITERATIONS
from mitpiv.errors import ConfigError
from mitpiv.studies.schema import Table, Vec3
from mitpiv.studies.shared import (
    RENDER_PACKAGES,
    Kind,
    SceneTable,
    Stage,
    StageContext,
    check_coverage,
    check_scene_sensors,
    check_sheet_focus,
    count_for_density,
    flatten,
    flow_union,
    fmt_metric,
    grid_of,
    images,
    null_metrics,
    resolve_scene_xml,
    resolve_table_file,
    scene_files,
    sensor_stage,
    sensor_table,
    source_of,
    volume,
)

FRAMES = (0, 1)
STAGES = ("particles", "render", "sensor", "reconstruct", "evaluate", "piv", "report", "vtk")

PosFloat = Annotated[float, Field(gt=0)]


# ------------------------------------------------------------------------------- schema
class SeedingTable(Table):
    """Particles seeded uniformly in a box (mitpiv.physics.seeding.seed_box), or the user's
    own particle list (``file``)."""

    box_min_mm: Vec3 | None = Field(None, description="lower corner of the seeding box [mm] (required unless file)")
    box_max_mm: Vec3 | None = Field(None, description="upper corner of the seeding box [mm] (required unless file)")
    file: str | None = Field(None, description="the user's particle list instead of random seeding: CSV with x_mm, "
                                               "y_mm, z_mm[, diameter_um] (mitpiv.io.read_particles_csv), relative "
                                               "to the experiment file")
    file_sha256: str | None = Field(None, description="set by mitpiv: the file's content hash (a changed file "
                                                      "reruns the particles stage)")
    count: Annotated[int, Field(ge=0)] | None = Field(None, description="number of particles")
    concentration_per_mm3: PosFloat | None = Field(None, description="particles per mm^3")
    ppp: PosFloat | None = Field(None, description="particles per pixel of the density sensor")
    particles_per_microlens: PosFloat | None = Field(
        None, description="particles per microlens of a plenoptic density sensor")
    density_sensor: str | None = Field(
        None, description="sensor id for ppp / particles_per_microlens (default: the first rendered sensor)")
    diameter_um: PosFloat = Field(1.0, description="particle diameter (median of a log-normal) [um]")
    distribution: Literal["monodisperse", "lognormal"] = Field("monodisperse", description="diameter distribution")
    geometric_std: Annotated[float, Field(gt=1)] = Field(1.5, description="geometric standard deviation (lognormal)")
    min_separation_mm: PosFloat | None = Field(None, description="minimum distance between particle centres [mm]")
    proxy_radius_mm: PosFloat = Field(0.02, description="radius of the particles' proxy spheres in the scene [mm]")

    @model_validator(mode="after")
    def _one_density(self):
        given = [k for k in ("count", "concentration_per_mm3") if getattr(self, k) is not None]
        dens = [k for k in ("ppp", "particles_per_microlens") if getattr(self, k) is not None]
        if self.file is not None:
            if given or dens:
                raise ValueError(f"file gives the particles; remove {given + dens}")
            from mitpiv.io import read_particles_csv

            if len(read_particles_csv(self.file, diameter_um=self.diameter_um)["positions_mm"]) == 0:
                raise ValueError(f"file = {Path(self.file).name!r} holds no particles (a header without rows): "
                                 "nothing to render; add rows x_mm, y_mm, z_mm or seed a box (count = N)")
            return self
        if self.count == 0:
            raise ValueError("count = 0 seeds no particles: nothing to render (the renderer cannot load an empty "
                             "particle set); give count >= 1")
        if self.box_min_mm is None or self.box_max_mm is None:
            raise ValueError("box_min_mm and box_max_mm are required (or file = a particle list)")
        if len(given) + (1 if dens else 0) != 1:
            raise ValueError("give exactly one of count, concentration_per_mm3, ppp or particles_per_microlens "
                             "(ppp and particles_per_microlens may go together: the density sensor's kind picks); "
                             f"got {given + dens or 'none'}")
        if any(hi <= lo for lo, hi in zip(self.box_min_mm, self.box_max_mm, strict=True)):
            raise ValueError(f"box_max_mm {list(self.box_max_mm)} must exceed box_min_mm {list(self.box_min_mm)} "
                             "on every axis")
        half = 0.5 * min(hi - lo for lo, hi in zip(self.box_min_mm, self.box_max_mm, strict=True))
        if self.proxy_radius_mm >= half:
            raise ValueError(f"proxy_radius_mm = {self.proxy_radius_mm} mm is not smaller than half the seeding box "
                             f"({half:g} mm): every particle's proxy sphere would fill the volume. Choose it below the "
                             f"pixel footprint in object space (e.g. 0.01-0.05 mm)")
        if self.count is not None:
            from mitpiv import costs

            costs.check_memory(costs.particles_cost(self.count), what=f"count = {self.count}",
                               fix="seed fewer particles (count, concentration_per_mm3 or ppp)", quiet=True)
        return self


def _flow_union():
    return flow_union()


class RenderTable(Table):
    """Rendering settings."""

    spp: Annotated[int, Field(ge=1)] | None = Field(
        None, description="samples per pixel (camera tracing) or passes (particle tracer); default the scene's")
    sensors: Annotated[list[str], Field(min_length=1)] | None = Field(
        None, description="ids of the scene's sensors to render (default all)")


class ReconstructionTable(Table):
    """Volume reconstruction (mitpiv.reconstruct.images.reconstruct_images)."""

    method: Literal["mlos", "mart", "smart", "sapiv", "plenoptic", "drt-mart"] = Field(
        "mart", description="reconstruction method")
    bounds_mm: tuple[float, float, float, float, float, float] = Field(
        ..., description="volume [xmin, xmax, ymin, ymax, zmin, zmax] [mm]")
    voxel_mm: PosFloat | tuple[PosFloat, PosFloat, PosFloat] = Field(
        ..., description="voxel size [mm]: one (cubic) or [dx, dy, dz]")
    iterations: Annotated[int, Field(ge=1, le=MAX_ITERATIONS)] = Field(
        5, description="MART / SMART / DRT-MART iterations")
    mu: Annotated[float, Field(gt=0, lt=2)] = Field(1.0, description="MART relaxation")
    weights: Literal["circle", "gaussian"] = Field("circle", description="MART pixel-voxel weights")
    interpolation: Literal["linear", "cubic"] = Field("linear", description="image interpolation")
    preprocess: float | None = Field(None, description="histogram threshold: background + K sigma")
    smooth_px: Annotated[float, Field(ge=0, le=10)] = Field(
        0.0, description="MART / SMART: Gaussian image smoothing [px] before the threshold; use ~0.7 for noisy "
                         "8-bit images, whose clipped zero pixels otherwise zero the particles' voxels (0: off)")
    floor_rel: Annotated[float, Field(ge=0, lt=1)] = Field(
        0.0, description="MART / SMART: pixels below this fraction of each image's maximum set to 0 (the camera's "
                         "dynamic range; lets MLOS prune voxels when particle-image tails never reach 0; 0: off)")
    combine: Literal["additive", "multiplicative"] = Field("multiplicative", description="sapiv / plenoptic combination")
    threshold_k: float | None = Field(3.0, description="sapiv: keep mean + k sigma per plane (none: no threshold)")
    fuse_normalise: Literal["histogram", "max", "none"] = Field(
        "histogram", description="plenoptic: normalisation before fusing cameras")
    rays_per_pixel: Annotated[int, Field(ge=1)] = Field(16, description="drt-mart ray bundle per pixel")
    min_coverage: Annotated[float, Field(gt=0, lt=1)] | None = Field(
        None, description="drt-mart: drop the voxels at the edge of the field whose ray cones the sensor catches less "
                          "than this share of (0.75: those it sees half of; none: keep all)")
    camera_model: Literal["true", "undistorted"] = Field(
        "true", description="'undistorted': the cameras' lens distortion left uncorrected")

    @model_validator(mode="after")
    def _bounds(self):
        b = self.bounds_mm
        if not (b[0] < b[1] and b[2] < b[3] and b[4] < b[5]):
            raise ValueError(f"bounds_mm {list(b)} must be [xmin, xmax, ymin, ymax, zmin, zmax] with min < max")
        from mitpiv import costs

        vox = self.voxel_mm if isinstance(self.voxel_mm, tuple) else (self.voxel_mm,) * 3
        n = math.prod((b[2 * i + 1] - b[2 * i]) / vox[i] for i in range(3))
        costs.check_memory(costs.reconstruction_cost(n, iterations=self.iterations, method=self.method),
                           what=f"voxel_mm = {self.voxel_mm} on bounds_mm = {list(b)}",
                           fix="use larger voxels or smaller bounds", quiet=True)
        return self


Window = Annotated[int, Field(ge=4)] | tuple[Annotated[int, Field(ge=4)], Annotated[int, Field(ge=4)],
                                             Annotated[int, Field(ge=4)]]


class PivTable(Table):
    """Multi-pass 3D PIV (mitpiv.analysis.piv3d)."""

    windows: Annotated[list[Window], Field(min_length=1)] = Field(
        [64, 48, 32], description="window edge per pass [voxels]: N or [wx, wy, wz]")
    overlap: Annotated[float, Field(ge=0, lt=1)] = Field(0.75, description="window overlap fraction")
    deform: bool = Field(True, description="window deformation (else integer window shifting)")
    interpolation: Literal["linear", "cubic"] = Field("cubic", description="deformation resampling")
    normalised: bool = Field(False, description="normalised cross-correlation")
    correlation: Literal["fft", "ncc"] = Field(
        "fft", description="fft: circular correlation of equal windows; ncc: Lewis normalised coefficient in a "
        "search region grown by half a window (first pass) or a quarter (later passes)")
    threshold: PosFloat = Field(2.0, description="universal outlier detection threshold")
    replace: Literal["median", "interpolation", "none"] = Field("median", description="outlier replacement")


class ParticlesTable(Table):
    """Particles found in the reconstructed volume and matched to the truth."""

    method: Literal["gauss3", "centroid", "lsq"] = Field("gauss3", description="sub-voxel localisation")
    threshold_rel: Annotated[float, Field(gt=0, lt=1)] = Field(
        0.1, description="local maxima above this fraction of the reference that threshold_of names are particles")
    threshold_of: Literal["robust", "max"] = Field(
        "robust", description="the reference of threshold_rel: 'robust' = the 99.99th percentile of the heights of the "
                              "volume's local maxima, at least the 50th brightest (two frames of equal quality detect "
                              "alike; needs more than ~50 particles), 'max' = the single brightest voxel (the rule "
                              "before this key: one bright voxel moves a frame's threshold)")
    radius_voxels: PosFloat = Field(2.0, description="matching search radius [voxels]")


class ReportTable(Table):
    """The run's report (mitpiv.studies.report.tomo_report)."""

    slice_axis: Literal["auto", "x", "y", "z"] = Field(
        "auto", description="normal of the plane flow_slice.png shows: x, y or z, or 'auto' = of the three mid-planes "
                            "(through the middle of the PIV field) the one with the most in-plane motion of the true "
                            "window-averaged flow: the largest mean vorticity normal to it (in-plane rotation), for a "
                            "flow without vorticity the largest mean in-plane speed")
    slice_mm: float | None = Field(
        None, description="position of that plane along slice_axis [mm], within [reconstruction] bounds_mm (the PIV "
                          "plane nearest it is drawn; default: the middle of the PIV field); needs slice_axis x, y or z")

    @model_validator(mode="after")
    def _position_needs_axis(self):
        if self.slice_mm is not None and self.slice_axis == "auto":
            raise ValueError(f"slice_mm = {self.slice_mm:g} with slice_axis = 'auto': 'auto' picks one of the three "
                             "mid-planes itself; give slice_axis = 'x', 'y' or 'z' with slice_mm, or drop slice_mm")
        return self


class _Experiment(Table):
    """Checks across tables: the cost of the PIV on the reconstruction grid."""

    @model_validator(mode="after")
    def _piv_cost(self):
        from mitpiv import costs

        shape = grid_of(self).shape
        costs.check_memory(costs.piv_cost(shape, self.piv.windows, self.piv.overlap),
                           what=f"[piv] windows = {list(self.piv.windows)}, overlap = {self.piv.overlap} on a "
                                f"{shape[2]}x{shape[1]}x{shape[0]} grid",
                           fix="use a smaller overlap or larger windows", quiet=True)
        return self

    @model_validator(mode="after")
    def _report_slice(self):
        r, b = self.report, self.reconstruction.bounds_mm
        if r.slice_mm is not None:
            a = "xyz".index(r.slice_axis)
            lo, hi = b[2 * a], b[2 * a + 1]
            if not lo <= r.slice_mm <= hi:
                raise ValueError(f"[report] slice_mm = {r.slice_mm:g} mm lies outside the reconstructed volume along "
                                 f"{r.slice_axis} ({lo:g} .. {hi:g} mm, [reconstruction] bounds_mm); give a position "
                                 f"within it")
        return self


def check_volume_coverage(cfg, cameras: dict) -> None:
    """The reconstruction stage's scene check: the ``[reconstruction] bounds_mm`` box in
    every camera's view (:func:`~mitpiv.studies.shared.check_coverage`: refused where no
    point of it is seen by every camera, a warning where a camera sees under 90 % of it)."""
    b = cfg.reconstruction.bounds_mm
    check_coverage(cameras, (b[0], b[2], b[4]), (b[1], b[3], b[5]),
                   what=f"experiment {cfg.name!r}: [reconstruction] bounds_mm",
                   fix="give bounds_mm within the cameras' common view (or aim the cameras at the volume)")


def check_sheet_in_focus(cfg, rig) -> None:
    """The render stage's rig check: the laser sheet's mid-plane within ``[reconstruction]
    bounds_mm`` inside the depth of field of each camera that has a focus
    (:func:`~mitpiv.studies.shared.check_sheet_focus`: a warning, never a refusal)."""
    b = cfg.reconstruction.bounds_mm
    check_sheet_focus(rig, (b[0], b[2], b[4]), (b[1], b[3], b[5]),
                      what=f"experiment {cfg.name!r}: [reconstruction] bounds_mm")


def check_piv_windows(cfg) -> None:
    """The PIV stage's check (run before a run that reaches it starts): every window fits
    the reconstruction grid (``piv3d`` refuses a larger one, after the render and the
    reconstruction)."""
    nz, ny, nx = grid_of(cfg).shape
    for w in cfg.piv.windows:
        wx, wy, wz = w if isinstance(w, tuple) else (w, w, w)
        if wx > nx or wy > ny or wz > nz:
            raise ConfigError(f"experiment {cfg.name!r}: [piv] windows: {wx}x{wy}x{wz} voxels (x, y, z) do not fit the "
                              f"reconstruction grid of {nx}x{ny}x{nz} voxels ([reconstruction] bounds_mm / voxel_mm); "
                              f"give windows no larger than the volume, or larger bounds / smaller voxels (or stop "
                              f"the run before the PIV).")


class OutputTable(Table):
    """Extra files a run writes beside its report."""

    vtk: bool = Field(False, description="ParaView / VTK files of volumes, PIV field, particles and tracks in "
                                         "RUN/vtk (mitpiv.studies.export)")


@cache
def schema():
    """The tomo experiment model (built once: the flow and sensor tables come from the physics)."""
    from pydantic import create_model

    fields = {
        "kind": (Literal["tomo"], Field("tomo", description="experiment kind")),
        "name": (Annotated[str, Field(min_length=1)], Field(..., description="experiment name (default: the file "
                                                                             "name)")),
        "seed": (Annotated[int, Field(ge=0, lt=2**63)], Field(0, description="experiment seed (every random stream "
                                                                              "derives from it)")),
        "scene": (SceneTable, Field(..., description="the scene")),
        "seeding": (SeedingTable, Field(..., description="particle seeding")),
        "flow": (_flow_union(), Field(..., description="the flow (kind and its parameters) and dt_s")),
        "render": (RenderTable, Field(default_factory=RenderTable, description="rendering")),
        "sensor": (sensor_table() | None, Field(None, description="sensor model (optional)")),
        "reconstruction": (ReconstructionTable, Field(..., description="volume reconstruction")),
        "piv": (PivTable, Field(default_factory=PivTable, description="3D PIV")),
        "particles": (ParticlesTable, Field(default_factory=ParticlesTable, description="particle evaluation")),
        "report": (ReportTable, Field(default_factory=ReportTable, description="the run's report (figures)")),
        "output": (OutputTable, Field(default_factory=OutputTable, description="extra output files")),
    }
    model = create_model("TomoExperiment", __base__=_Experiment,
                         __doc__="A particle-image experiment: seeding, flow, render, reconstruction, "
                                 "particles, 3D PIV.", **fields)
    return model


def prepare(raw: dict, base_dir: Path) -> dict:
    """Resolve the scene XML and a particle list against the experiment's folder (before
    validation); the particle list's content hash joins the seeding table."""
    raw = resolve_table_file(resolve_scene_xml(raw, base_dir), "seeding", base_dir)
    if raw.get("kind") == "particles":
        raw = {**raw, "kind": "tomo"}
    return raw


# ------------------------------------------------------------------------------- stages
def _seeding_kwargs(s) -> dict:
    kw = s.model_dump(exclude={"box_min_mm", "box_max_mm", "proxy_radius_mm", "density_sensor", "ppp",
                               "particles_per_microlens", "file", "file_sha256"}, exclude_none=True)
    return kw


def stage_particles(ctx: StageContext) -> dict:
    from mitpiv.io import write_particles_ply, write_truth
    from mitpiv.physics.advection import advect
    from mitpiv.physics.flows import flow_from_dict
    from mitpiv.physics.seeding import seed_box

    cfg, out = ctx.cfg, ctx.out
    s = cfg.seeding
    if s.file is not None:  # the user's particle list
        from mitpiv.io import read_particles_csv

        user = read_particles_csv(s.file, diameter_um=s.diameter_um)
        p0, diam = user["positions_mm"], user["diameters_um"]
    else:
        kw = _seeding_kwargs(s)
        if s.ppp is not None or s.particles_per_microlens is not None:
            kw["count"] = count_for_density(cfg)
        particles = seed_box(s.box_min_mm, s.box_max_mm, seed=cfg.seed, **kw)
        p0, diam = particles.positions_mm, particles.diameters_um
    f = cfg.flow.model_dump()
    dt = float(f.pop("dt_s"))
    flow = flow_from_dict(f)
    p1 = advect(p0, flow, dt_s=dt, t0_s=0.0, substeps=8)
    for k, p in enumerate((p0, p1)):
        write_particles_ply(out / f"particles_{k}.ply", p, diam, proxy_radius_mm=s.proxy_radius_mm)
    write_truth(out / "truth.npz", positions_mm=[p0, p1], times_s=[0.0, dt], diameters_um=diam, flow=flow.to_dict(),
                extra={"seed": cfg.seed})
    return {"n_particles": len(p0)}


def _uses_density(cfg) -> bool:
    return cfg.seeding.ppp is not None or cfg.seeding.particles_per_microlens is not None


def stage_render(ctx: StageContext) -> dict:
    from mitpiv.render.render import render_scene

    cfg = ctx.cfg
    # the scene reads particles_$frame.ply beside itself: the stage keeps its own copy of the
    # XML (the scene it rendered) and links the particle files beside it while it renders
    xml = ctx.out / "scene.xml"
    shutil.copy(cfg.scene.xml, xml)
    links = []
    try:
        for k in FRAMES:
            src, dst = ctx.input("particles", f"particles_{k}.ply"), ctx.out / f"particles_{k}.ply"
            try:
                os.link(src, dst)
            except OSError:  # a file system without hard links
                shutil.copy(src, dst)
            links.append(dst)
        files = render_scene(xml, out_dir=ctx.out, frames=FRAMES, params=cfg.scene.params, spp=cfg.render.spp,
                             seed=cfg.seed, progress=ctx.progress, sensors=cfg.render.sensors,
                             search_dirs=[Path(cfg.scene.xml).parent], source_file=cfg.scene.xml)
    finally:
        for f in links:
            f.unlink(missing_ok=True)
    from mitpiv.io import read_exr_metadata

    first = [f for f in files if Path(f).stem.endswith(f"_frame{FRAMES[0]:03d}")]
    return {"images": [f.name for f in files], "cameras": camera_budget([read_exr_metadata(f) for f in first])}


def camera_budget(metas: list[dict]) -> dict:
    """The cameras of one frame's images (their EXR metadata): how many, their types, and the
    pixels they record together (the budget LTPR compares: for one plenoptic camera against
    N_c tomographic ones, ``LTPR = pixels_LF / pixels_tomo``, Shi et al.'s
    ``(p_x p_y)_LF / (p_x p_y N_c)_Tomo``, :func:`mitpiv.physics.plenoptic.ltpr`)."""
    cams = [m.get("camera") or {} for m in metas]
    res = [c.get("resolution") for c in cams]
    if any(r is None or len(r) != 2 for r in res):
        return {"n": len(cams), "types": sorted({str(c.get("type")) for c in cams}), "pixels": None}
    return {"n": len(cams), "types": sorted({str(c.get("type")) for c in cams}),
            "pixels": int(sum(int(r[0]) * int(r[1]) for r in res))}


def stage_sensor(ctx: StageContext) -> dict:
    return sensor_stage(ctx, FRAMES)


def _undistorted(meta: dict) -> dict:
    """The metadata of a pinhole camera with its lens distortion set to zero."""
    cam = dict(meta.get("camera") or {})
    if isinstance(cam.get("distortion"), dict):
        cam["distortion"] = {k: (0.0 if isinstance(v, int | float) else v) for k, v in cam["distortion"].items()}
    return {**meta, "camera": cam}


def stage_reconstruct(ctx: StageContext) -> dict:
    from mitpiv import costs
    from mitpiv.io import camera_from_metadata, read_exr_metadata, write_volume
    from mitpiv.reconstruct.images import reconstruct_images, reconstruction_cost_of
    from mitpiv.reconstruct.tomo import WeightCache

    cfg = ctx.cfg
    r = cfg.reconstruction
    grid = grid_of(cfg)
    first = sorted((ctx.run_dir / source_of(cfg)).glob("*_frame000.exr"))
    metas0 = [read_exr_metadata(f) for f in first]
    cost = reconstruction_cost_of(metas0, grid, r.method, iterations=r.iterations,
                                  rays_per_pixel=r.rays_per_pixel)
    fix = "use larger voxels or smaller bounds" + (
        ", fewer rays_per_pixel or a smaller light-field sensor (a crop)" if r.method == "drt-mart" else "")
    costs.check_memory(cost, what=f"[reconstruction] {r.method} on {grid.shape[2]}x{grid.shape[1]}x{grid.shape[0]} "
                       "voxels, per frame", fix=fix)
    # the volume in the cameras' view, from the rendered cameras (what --check did from the scene)
    check_volume_coverage(cfg, {f.stem.rsplit("_frame", 1)[0]: camera_from_metadata(m)
                                for f, m in zip(first, metas0, strict=True)})
    info = {}
    cache = WeightCache()  # the cameras do not move between frames: weights built once
    for frame in FRAMES:
        imgs, metas, _ = images(ctx.run_dir, frame, source_of(cfg))
        if r.camera_model == "undistorted":
            metas = [_undistorted(m) for m in metas]
        vol, inf = reconstruct_images(imgs, metas, grid, r.method, iterations=r.iterations, mu=r.mu,
                                      weights=r.weights, interpolation=r.interpolation, preprocess=r.preprocess,
                                      smooth_px=r.smooth_px, floor_rel=r.floor_rel,
                                      combine=r.combine, threshold_k=r.threshold_k,
                                      fuse_normalise=r.fuse_normalise, rays_per_pixel=r.rays_per_pixel,
                                      min_coverage=r.min_coverage, progress=ctx.progress, cache=cache)
        if inf:
            info[f"frame{frame}"] = {k: v for k, v in inf.items() if isinstance(v, int | float | str)}
        write_volume(ctx.out / f"volume_{frame}.npz", vol, {"method": r.method, "grid": grid.to_dict()})
    return info


def stage_evaluate(ctx: StageContext) -> dict:
    from mitpiv import analysis
    from mitpiv.analysis.summary import VOLUME_QUALITY_KEYS
    from mitpiv.io import read_truth

    cfg = ctx.cfg
    p = cfg.particles
    grid = grid_of(cfg)
    truth = read_truth(ctx.input("particles", "truth.npz"))
    metrics = {}
    for frame in FRAMES:
        vol = volume(ctx.run_dir, frame)
        m, res = analysis.evaluate_volume(
            vol, grid, truth["positions_mm"][frame], method=p.method,
            threshold_rel=p.threshold_rel, radius_voxels=p.radius_voxels, threshold_of=p.threshold_of)
        reasons = {"particles": f"no reconstructed particle of frame {frame} matched a true one"}
        if not np.any(np.asarray(vol) > 0):
            # an empty volume correlates with nothing: its Q would read 0, not a measurement
            why = (f"the reconstructed volume of frame {frame} is empty (no voxel > 0): the images carry no "
                   f"particle inside the reconstruction bounds (check the sensor exposure, the cameras' view "
                   f"and [reconstruction] bounds_mm)")
            m.update({k: None for k in VOLUME_QUALITY_KEYS})
            reasons = {**{k: why for k in VOLUME_QUALITY_KEYS}, "particles": why}
        metrics[f"frame{frame}"] = null_metrics(m, reasons, where=f"evaluate frame {frame}")
        res.save(ctx.out / f"matches_{frame}.npz")
    return metrics


def stage_piv(ctx: StageContext) -> dict:
    from mitpiv import analysis
    from mitpiv.io import read_truth
    from mitpiv.io.vectors import write_velocity_error
    from mitpiv.physics.flows import flow_from_dict

    cfg = ctx.cfg
    grid = grid_of(cfg)
    truth = read_truth(ctx.input("particles", "truth.npz"))
    dt = float(truth["times_s"][1] - truth["times_s"][0])
    pv = cfg.piv
    from mitpiv import costs

    costs.check_memory(costs.piv_cost(grid.shape, pv.windows, pv.overlap),
                       what=f"[piv] windows = {list(pv.windows)}, overlap = {pv.overlap}",
                       fix="use a smaller overlap or larger windows")
    field = analysis.piv3d(volume(ctx.run_dir, 0), volume(ctx.run_dir, 1), grid, windows=pv.windows,
                           overlap=pv.overlap, deform=pv.deform, interpolation=pv.interpolation,
                           normalised=pv.normalised, correlation=pv.correlation, threshold=pv.threshold,
                           replace=None if pv.replace == "none" else pv.replace, dt_s=dt, progress=ctx.progress)
    res = analysis.velocity_error(field, flow_from_dict(truth["flow"]))
    metrics = null_metrics(analysis.velocity_error_summary(res), {
        "": f"{res.get('n', 0)} valid PIV vector(s): the volumes hold no correlation peak to measure (see the "
            f"evaluate stage's Q and the images)"}, where="piv")
    field.info["velocity_error"] = metrics
    field.save(ctx.out / "field.npz")
    write_velocity_error(ctx.out / "velocity_error.npz", res)
    return metrics


def stage_report(ctx: StageContext) -> dict:
    from mitpiv.studies import report

    return report.write(report.tomo_report(ctx.cfg, ctx.run_dir, ctx.results, ctx.timings), ctx.out)


def stage_vtk(ctx: StageContext) -> dict:
    from mitpiv.studies.export import export_vtk

    return {"files": [f.name for f in export_vtk(ctx.run_dir, ctx.out, progress=ctx.progress)]}


def stages(cfg) -> list[Stage]:
    # the particles stage reads the scene (with Mitsuba) only to turn a density into a count
    dens = _uses_density(cfg)
    out = [Stage("particles", ("seed", "seeding", "flow") + (("scene",) if dens else ()), stage_particles,
                 files=scene_files if dens else None, packages=RENDER_PACKAGES if dens else ()),
           Stage("render", ("scene", "render"), stage_render, files=scene_files, packages=RENDER_PACKAGES,
                 check=check_scene_sensors, rig_check=check_sheet_in_focus)]
    if cfg.sensor is not None:
        out.append(Stage("sensor", ("sensor",), stage_sensor))
    out += [Stage("reconstruct", ("reconstruction",), stage_reconstruct, scene_check=check_volume_coverage),
            Stage("evaluate", ("particles",), stage_evaluate),
            Stage("piv", ("piv",), stage_piv, check=check_piv_windows),
            Stage("report", ("report",), stage_report)]
    if cfg.output.vtk:
        out.append(Stage("vtk", ("output",), stage_vtk))
    return out


def summary(cfg, results: dict) -> dict:
    """metrics.json of a tomo run: Q, particles per frame (``evaluate``), PIV errors (``piv``)."""
    return {"name": cfg.name, "seed": cfg.seed, "kind": "tomo", "evaluate": results.get("evaluate"),
            "piv": results.get("piv"), "n_particles": (results.get("particles") or {}).get("n_particles"),
            "cameras": (results.get("render") or {}).get("cameras")}


def row(metrics: dict) -> dict:
    """The sweep-table columns of a tomo run: frame0.*, frame1.*, piv.*, n_particles, and
    the camera budget (cameras.n, cameras.type, cameras.pixels) from which a sweep computes
    LTPR (:func:`mitpiv.studies.sweep.add_ltpr`)."""
    ev = metrics.get("evaluate") or {}
    out = {}
    flatten("", {"frame0": ev.get("frame0"), "frame1": ev.get("frame1"), "piv": metrics.get("piv"),
                 "n_particles": metrics.get("n_particles")}, out)
    cams = metrics.get("cameras") or {}
    out.update({"cameras.n": cams.get("n"), "cameras.type": "+".join(cams.get("types") or []) or None,
                "cameras.pixels": cams.get("pixels")})
    return out


def headline(m: dict) -> str:
    ev = (m.get("evaluate") or {}).get("frame0", {})
    pv = m.get("piv") or {}
    rate = (ev.get("particles") or {}).get("detection_rate")
    text = (f"{m['name']}: Q {fmt_metric(ev.get('Q'), '.3f')}, particles detected "
            f"{fmt_metric(None if rate is None else 100 * rate, '.1f')} %, PIV RMS error "
            f"{', '.join(fmt_metric(x, '.4f') for x in pv.get('rms_vox') or [])} voxels")
    why = {**(ev.get("null_reasons") or {}), **(pv.get("null_reasons") or {})}
    if why:
        text += f" (no value: {next(iter(why.values()))})"
    return text


KIND = Kind(name="tomo", build_schema=schema, stages=stages, summary=summary, row=row, aliases=("particles",),
            prepare=prepare, headline=headline, describe="particle images, reconstruction, particles and 3D PIV",
            columns=("frame0.*", "frame1.*", "piv.*", "n_particles", "cameras.n", "cameras.type", "cameras.pixels"))
