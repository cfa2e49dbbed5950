"""Other methods on a tracking experiment's images (issue 27, item 7): OpenLPT's
Shake-The-Box and mitpiv's tomographic PIV, scored against the same truth as mitpiv's STB.
The ``[compare]`` table and stages of the tracking kind (:mod:`mitpiv.studies.kinds.tracking`),
scored by :mod:`mitpiv.studies.kinds.tracking.scoring` as the kind's evaluate stage scores.

Opt-in: an experiment without a ``[compare]`` table (or with ``openlpt = false``,
``tomo = false``, the defaults) has no extra stage and costs nothing. With it::

    [compare]
    openlpt = true         # OpenLPT STB (PyPI openlpt) on the rendered frames
    tomo = true            # MART / SMART volumes of the frames + multi-pass 3-D PIV
    tomo_method = "mart"   # or "smart"; tomo_voxel_mm, tomo_iterations, tomo_windows, ...

Stages (after ``evaluate``, before ``report``; each reuses the render and calibrate stages'
outputs, so a changed ``[compare]`` setting reruns only these and the report):

``openlpt``
    the frames and the calibrated cameras (``calibrate/cameras.json``, the cameras mitpiv's
    STB uses) exported by :func:`mitpiv.io.openlpt.export_openlpt` (distorted cameras with
    ``undistort=True``, the work-around of openlpt 2.2.4's stereo matching), OpenLPT run by
    :func:`mitpiv.tracking.peers.run_openlpt`, its long tracks regularised by mitpiv's
    regularisation and scored by :func:`mitpiv.studies.kinds.tracking.scoring.score_tracks`
    (the evaluate stage's scoring). OpenLPT's settings follow the experiment (below) unless
    ``openlpt_settings`` overrides them. A failure of OpenLPT (not installed, its exit status,
    a time-out, no tracks) does not fail the run: the stage records ``status = "failed"``
    and ``error``, the exact reason, and null metrics.
``tomo``
    every frame of ``tomo_pairs + 1`` consecutive frames reconstructed by MART / SMART
    (:func:`mitpiv.reconstruct.tomo.reconstruct_volume`, the calibrated cameras, one weight
    cache) on a voxel grid over the measurement box, consecutive volumes correlated by
    :func:`mitpiv.analysis.piv3d` (velocities [mm/s] at the window centres), the valid
    vectors of all pairs averaged per bin of the evaluate stage's Eulerian grid and compared
    with the true trajectories over the same frames binned on it
    (:func:`~mitpiv.studies.kinds.tracking.scoring.binned_error`; with all pairs, the same binned
    truth as the tracks').
    Yield, ghost fraction and particle position error do not apply to tomographic PIV (it
    measures window-averaged displacements of voxel intensity, not particles): they are
    null with that reason.

Every stage records its own wall time (``wall_s``: OpenLPT's run without the export;
reconstruction plus correlation for tomo, after a warm-up that compiles its Numba kernels,
``warm_up_s``); the runner records the stage's total too
(``seconds.openlpt``, ``seconds.tomo`` in a sweep row).

OpenLPT settings derived from the experiment (``openlpt_settings`` overrides any of
:class:`mitpiv.io.openlpt.OpenLPTSettings`' fields), each from OpenLPT's own documentation or
source (openlpt 2.2.4; its sources github.com/JHU-NI-LAB/OpenLPT_GUI 2.1.8, the sample
``test/inputs/test_STB``, the GUI's ``gui/docs/settings.html`` and
``gui/views/tracking_settings_view.py``). The derivation is shared with ``mitpiv export
--openlpt`` (:mod:`mitpiv.studies.peer_settings`, which reads the quantities from the run
folder and says where each came from); this stage gives it the measurement box, the
calibrated cameras and the ``[tracking]`` settings below:

* voxel: one pixel in object space at the box centre (``mm_per_px``), as OpenLPT's sample
  (0.04 mm voxels at 0.041 mm/px) and its GUI default (view volume / 1000).
* particle radius (the "Tracer Radius" the GUI docs call, with the intensity threshold, the
  setting the user must tune to the experiment): :func:`particle_radius_px`, the half width
  at half maximum of the particle image of the experiment's OTF calibration (the ``otf``
  stage, the calibration mitpiv's STB uses) rounded up to a half pixel, and at least 1.5 px,
  the smallest radius whose subtraction window is centred on the particle. OpenLPT uses the
  radius three ways (src/srcSTB/Shake.cpp, OTF.cpp): the residual image subtracts each
  particle over a window ``round(2 r)`` px wide, shaking compares model and image in that
  window, and its own OTF (the particle image model it shakes with) is fitted in windows of
  radius ``r`` around every detected peak of the first five frames. With the sample's 2 px
  the OTF fit takes in the neighbours' images as the density grows: OpenLPT reports
  ``b = 0.50, 0.41, 0.30`` (``I = a exp(-b x^2 - c y^2)``, a particle image of sigma 1.0,
  1.1, 1.3 px) at 0.01, 0.02, 0.05 ppp on the same optics (0.64, 0.55, 0.43 with 1.5 px),
  and the shaking model is as much too wide. On the study's points 1.5 px instead of 2 px
  raised the yield from 0.93 / 0.68 / 0.10 to 0.95 / 0.80 / 0.21 at 0.01 / 0.02 / 0.05 ppp
  and lowered the ghost fraction (0.009 / 0.061 / 0.44 to 0.006 / 0.038 / 0.31). 1 px (a
  2 x 2 px window) went further at 0.02 and 0.05 ppp (0.89, 0.35) but tripled the ghosts at
  0.01 ppp (0.032). These runs used mitpiv's OTF calibration before it pooled frames and
  checked isolation against every image peak, when its half width also widened with the
  density (0.82, 0.91, 1.39 px at 0.01, 0.02, 0.05 ppp); it now stays near 0.8-0.9 px (the
  radius is 1.5 px at every density of the study).
* initial-phase search radius: the displacement per frame of ``[tracking]
  velocity_guess_mm_s`` (0 without one: the comparison gives OpenLPT what mitpiv's STB gets,
  where the export derives the motion from the run's flow) plus ``[tracking] search_px``. OpenLPT links the initial frames to the
  nearest object within this radius of the position its predictive field predicts
  (``STB::buildTrackFromPredField``), so ``search_px`` alone would do with a good field; on the
  study's images it made no difference (``search_px`` = 4 voxels against 8.5: yield 0.110
  against 0.100 at 0.05 ppp with a 2 px radius, 0.942 against 0.946 at 0.01 ppp with 1.5 px),
  and the wider radius stays safe where the field is poor.
* predictive field: OpenLPT's sample grid (51 points per axis); its search radius 1.5 times
  the initial search radius (``PFParam``'s note: "make sure displacement < 0.5 * r"; the
  displacement histogram spans +-2 r).
* IPR: OpenLPT's sample loop counts (2 full-camera loops, 2 per reduced camera set; 4 full
  loops changed nothing at 0.05 ppp: the tolerance grows by 1.5 per loop); the 2-D tolerance
  ``[tracking] tolerance_px`` (plus 3 times the calibrate stage's largest fit RMS with
  ``[calibration] model = "pinhole"``), the 3-D one half of it (1 voxel, the sample's, found 34 %
  instead of 33 % of frame 0's particles at 0.05 ppp, with more ghosts: 43 % against 39 %).
* ghost threshold ``[tracking] min_intensity`` (0.1, the sample's; the GUI's 0.01 changed
  nothing): both drop a candidate whose intensity score is below that fraction of the mean
  (``Shake::runShake``).
* neighbour spacing: the mean spacing of the particles at frame 0 (its definition in the
  config, "Avg Interparticle spacing (vox) to identify neighbour tracks").
* 2-D finder threshold 30 counts and shake width 0.25 voxel: the sample's (its particle
  images peak at 125 counts; the export's peak near 100-120, OpenLPT's OTF ``a``).

What these do not change (the limits of openlpt 2.2.4 on dense images, observed on the study's
0.05 ppp point): its residual image is ``min`` over particles of ``image - projection``
(``Shake::calResidueImage``), not the image minus the sum of all projections, so overlapping
images are never both removed; its IPR of one frame finds a third to a half of the particles
(frame 0: 33 % found and 39 % of its candidates more than 1 px from any particle with the 2 px
radius, whatever the tolerances, loop counts, ghost threshold or shake width; 45 % and 33 %
with 1.5 px; the particle images overlap: ``N_s`` = ppp x pi x (2 sigma)^2 = 0.3 at sigma
0.7 px); and a long track ends when its last point lies more
than ``MAX_ERR_LINEARFIT = 0.05`` world units (mm here, 0.79 px at 0.063 mm/px; 1.2 px in its
sample) from a line through its last four points, a constant of its source.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, model_validator

from mitpiv.errors import ConfigError
from mitpiv.studies import peer_settings as _peers
from mitpiv.studies.kinds.tracking.scoring import (
    binned_error,
    eulerian_grid,
    load_cameras,
    score_tracks,
    tracked_images,
    truth_tracks,
    write_tracks_npz,
)
from mitpiv.studies.schema import Table
from mitpiv.studies.shared import Stage, StageContext, bounds_of, null_metrics

PosFloat = Annotated[float, Field(gt=0)]
Window = Annotated[int, Field(ge=4)] | tuple[Annotated[int, Field(ge=4)], Annotated[int, Field(ge=4)],
                                             Annotated[int, Field(ge=4)]]

#: The methods of the comparison, as named in ``results.json``.
METHODS = ("mitpiv-stb", "openlpt-stb", "mitpiv-tomo")

#: Why tomographic PIV has no yield, ghost fraction or particle position error.
TOMO_NOT_APPLICABLE = ("tomographic PIV measures window-averaged displacements of the reconstructed voxel "
                       "intensity on a grid, not individual particles: yield, ghost fraction and particle "
                       "position error do not apply (its velocity error is on the binned grid)")


class CompareTable(Table):
    """Other methods on the same images (opt-in; mitpiv.studies.kinds.tracking.compare)."""

    openlpt: bool = Field(False, description="run OpenLPT's STB (PyPI openlpt) on the exported frames and score it")
    openlpt_timeout_s: PosFloat = Field(3600.0, description="OpenLPT: time limit of its run [s]")
    openlpt_threads: Annotated[int, Field(ge=0, le=512)] = Field(1, description="OpenLPT: threads (0: all cores)")
    openlpt_settings: dict[str, float | int | list[int]] = Field(
        default_factory=dict, description="OpenLPT: overrides of mitpiv.io.openlpt.OpenLPTSettings' fields (e.g. "
                                          "finder_threshold = 20); the others follow the experiment")
    tomo: bool = Field(False, description="tomographic PIV: MART / SMART volumes + multi-pass 3-D correlation")
    tomo_method: Literal["mart", "smart"] = Field("mart", description="tomo: reconstruction method")
    tomo_voxel_mm: PosFloat | None = Field(None, description="tomo: voxel [mm] (default: one pixel in object space at "
                                                              "the box centre)")
    tomo_iterations: Annotated[int, Field(ge=1, le=50)] = Field(5, description="tomo: MART / SMART iterations")
    tomo_windows: Annotated[list[Window], Field(min_length=1)] = Field(
        [32, 24, 16], description="tomo: window edge per PIV pass [voxels]")
    tomo_overlap: Annotated[float, Field(ge=0, lt=1)] = Field(0.75, description="tomo: window overlap fraction")
    tomo_pairs: Annotated[int, Field(ge=1)] | None = Field(
        None, description="tomo: consecutive frame pairs correlated, from frame 0 (default all: frames - 1)")

    @model_validator(mode="after")
    def _settings(self):
        from dataclasses import fields

        from mitpiv.io.openlpt import OpenLPTSettings

        names = {f.name for f in fields(OpenLPTSettings)}
        bad = sorted(set(self.openlpt_settings) - names)
        if bad:
            raise ValueError(f"openlpt_settings: unknown key(s) {bad}; OpenLPTSettings' fields are {sorted(names)}")
        return self


def _scale(cfg, run: Path) -> float:
    """mm per pixel at the measurement box's centre (the true cameras)."""
    from mitpiv.io import camera_from_metadata, read_json
    from mitpiv.tracking import mm_per_px

    true = [camera_from_metadata(c) for c in read_json(run / "calibrate" / "cameras.json")["true"]]
    lo, hi = bounds_of(cfg)
    return float(mm_per_px(true, 0.5 * (lo + hi)))


#: The smallest OpenLPT particle radius [px] whose subtraction window (``round(2 r)`` px) is
#: centred on the particle: 3 x 3 px (:data:`mitpiv.studies.peer_settings.MIN_PARTICLE_RADIUS_PX`).
MIN_PARTICLE_RADIUS_PX = _peers.MIN_PARTICLE_RADIUS_PX


def particle_radius_px(run: Path, *, default: float = 2.0) -> float:
    """OpenLPT's particle radius [px] for a run: the half width at half maximum of the widest
    particle image of the experiment's OTF calibration (``otf/otf.json``; along the weaker
    principal axis of ``exp(-(a du^2 + 2 b du dv + c dv^2) / 2)``: ``sqrt(2 ln 2 / l_min)``,
    ``l_min`` the smaller eigenvalue of ``[[a, b], [b, c]]``, the largest over cameras and
    sub-volumes), rounded up to a half pixel, and at least 1.5 px: OpenLPT's subtraction window
    is ``round(2 r)`` px wide (``Shake::calROIBound``), so 1.5 px is the smallest window centred
    on the particle (3 x 3 px, the core its peak finder and 3-point Gaussian fit use; 1 px
    gives 2 x 2). ``default`` (OpenLPT's sample, 2 px) when the run has no OTF calibration.
    See the module notes for why the radius matters to OpenLPT."""
    from mitpiv.io import read_json

    f = run / "otf" / "otf.json"
    if not f.is_file():
        return default
    return _peers.radius_from_hwhm(_peers.otf_hwhm_px(read_json(f)), default=default)


def openlpt_settings(cfg, run: Path):
    """The :class:`~mitpiv.io.openlpt.OpenLPTSettings` and voxel [mm] for a run (module
    notes): the shared derivation of :mod:`mitpiv.studies.peer_settings` (the one
    ``mitpiv export --openlpt`` uses) on the measurement box and the calibrated cameras, with
    the experiment's ``[tracking]`` velocity guess for the motion per frame (0 without one, as
    mitpiv's STB gets it), and ``[compare] openlpt_settings`` over it."""
    t = cfg.tracking
    lo, hi = bounds_of(cfg)
    from dataclasses import replace

    q = replace(_peers.run_quantities(run, lower_mm=lo, upper_mm=hi, calibrated=True), tolerance_px=t.tolerance_px,
                search_px=t.search_px, ghost_threshold=t.min_intensity)
    # the experiment's guess, as mitpiv's STB gets it (0 without one): OpenLPT is not told the truth's motion
    motion = 0.0 if t.velocity_guess_mm_s is None else float(np.linalg.norm(t.velocity_guess_mm_s)) * cfg.flow.dt_s
    over = {k: (tuple(v) if isinstance(v, list) else v) for k, v in cfg.compare.openlpt_settings.items()}
    return _peers.openlpt_settings_from(q, motion_mm=motion, particle_radius_px=particle_radius_px(run), **over), \
        q.voxel_mm


def _null_result(reason: str, *, status: str, extra: dict | None = None) -> dict:
    keys = ("yield", "ghost_fraction", "position_error_px", "position_error_mm", "velocity_error_rel",
            "binned_mean_error_mm_s", "binned_error_rel", "wall_s")
    return {"status": status, "error": reason, **{k: None for k in keys}, **(extra or {}),
            "null_reasons": {k: reason for k in keys}}


def stage_openlpt(ctx: StageContext) -> dict:
    from mitpiv.errors import MitpivError
    from mitpiv.io import write_npz
    from mitpiv.io.openlpt import export_openlpt
    from mitpiv.studies.shared import frame_files, source_of
    from mitpiv.tracking.peers import run_openlpt

    cfg, run, c = ctx.cfg, ctx.run_dir, ctx.cfg.compare
    cams = load_cameras(run)
    lo, hi = bounds_of(cfg)
    settings, vox = openlpt_settings(cfg, run)
    folder = ctx.out / "export"
    distorted = any(not cam.distortion.is_zero for cam in cams)
    info = {"export_s": None, "voxel_mm": vox, "undistorted": distorted}
    try:  # the export (a camera OpenLPT cannot represent) or the peer's run may fail
        t0 = time.perf_counter()
        if cfg.sensor is not None and cfg.sensor.black_level:  # the counts less the black level, as STB reads them
            per_frame = [tracked_images(cfg, run, f) for f in range(cfg.sequence.frames)]
        else:  # the files of the stage this experiment reads (not a folder a former setting left)
            per_frame = [frame_files(run, f, source_of(cfg)) for f in range(cfg.sequence.frames)]
        frames = [[fr[k] for fr in per_frame] for k in range(len(cams))]
        export_openlpt(folder, frames, cams, lower_mm=lo, upper_mm=hi,
                       frame_rate_hz=1.0 / cfg.flow.dt_s, voxel_mm=vox, settings=settings, threads=c.openlpt_threads,
                       undistort=distorted, progress=ctx.progress)
        info["export_s"] = time.perf_counter() - t0
        tracks, wall = run_openlpt(folder, timeout_s=c.openlpt_timeout_s)
    except MitpivError as e:  # the peer's failure is a result: the row says why
        import warnings

        from mitpiv.errors import MitpivWarning

        reason = f"OpenLPT could not run on this experiment's frames: {type(e).__name__}: {e}"
        warnings.warn(reason, MitpivWarning, stacklevel=2)
        return _null_result(reason, status="failed", extra=info)
    write_tracks_npz(ctx.out / "tracks.npz", tracks)
    sc = score_tracks(cfg, run, tracks)
    write_npz(ctx.out / "errors.npz", {"velocity_error_mm_s": sc["velocity_error_mm_s"], **sc["binned"]},
              owner="tracking")
    m = {**sc["metrics"], "status": "ok", "error": "", "wall_s": wall, **info}
    for k in ("velocity_error_rel", "binned_mean_error_mm_s", "binned_error_rel"):
        m.setdefault(k, float("nan"))
    return null_metrics(m, {"position_error": "OpenLPT found no particle that matches a true one",
                            "yield": "no true particle in the measurement box",
                            "ghost_fraction": "OpenLPT returned no track sample in the measurement box",
                            "": "not computable from OpenLPT's tracks"}, where="openlpt compare")


def tomo_grid(cfg, run: Path):
    """The voxel grid of the tomographic reconstruction: the measurement box, voxels of
    ``[compare] tomo_voxel_mm`` (default one pixel at the box centre)."""
    from mitpiv.grid import VoxelGrid

    lo, hi = bounds_of(cfg)
    vox = cfg.compare.tomo_voxel_mm or _scale(cfg, run)
    return VoxelGrid.from_bounds(tuple(lo), tuple(hi), vox)


def bin_vectors(points_mm, velocities_mm_s, grid) -> dict:
    """Mean velocity per voxel of ``grid`` of vectors at ``points_mm`` ((N, 3) [mm], (N, 3)
    [mm/s]; rows with a NaN left out): ``count`` (n_z, n_y, n_x) and ``mean_mm_s``
    (n_z, n_y, n_x, 3), NaN where empty (as :func:`mitpiv.tracking.metrics.bin_tracks`)."""
    from mitpiv.tracking.metrics import bin_velocities

    b = bin_velocities(points_mm, velocities_mm_s, grid)
    return {"count": b["count"], "mean_mm_s": b["mean_mm_s"]}


def _warm_up(images, maps, grid, method) -> None:
    """Compile the Numba kernels of MART / SMART and of the 3-D correlation on a 16^3-voxel
    grid at the box centre before the clock starts: a Dask worker's first call pays the
    compilation (about 20 s on 2 cores), which is not the method's cost."""
    from mitpiv import analysis
    from mitpiv.grid import VoxelGrid
    from mitpiv.reconstruct.tomo import reconstruct_volume

    vox = np.asarray(grid.voxel_mm, float)
    centre = np.asarray(grid.origin_mm, float) + 0.5 * vox * np.asarray(grid.shape[::-1])
    small = VoxelGrid.from_bounds(tuple(centre - 8 * vox), tuple(centre + 8 * vox), tuple(vox))
    reconstruct_volume(images, maps, small, method, iterations=1)
    rng = np.random.default_rng(0)
    a = rng.random(small.shape).astype(np.float32)
    analysis.piv3d(a, np.roll(a, 1, axis=2), small, windows=[8, 8], overlap=0.5)


def stage_tomo(ctx: StageContext) -> dict:
    from mitpiv import analysis, costs
    from mitpiv.io import write_npz
    from mitpiv.reconstruct.mapping import PinholeMapping
    from mitpiv.reconstruct.tomo import WeightCache, reconstruct_volume
    from mitpiv.tracking import Tracks, bin_tracks

    cfg, run, c = ctx.cfg, ctx.run_dir, ctx.cfg.compare
    n = cfg.sequence.frames
    if n < 2:
        raise ConfigError(f"experiment: [compare] tomo = true needs at least 2 frames (a pair to correlate); "
                          f"[sequence] frames = {n}. Render more frames or set tomo = false.")
    pairs = n - 1 if c.tomo_pairs is None else c.tomo_pairs
    if pairs > n - 1:
        raise ConfigError(f"experiment: [compare] tomo_pairs = {pairs} exceeds the {n - 1} pair(s) of [sequence] "
                          f"frames = {n}; give at most {n - 1} or leave it out (all pairs).")
    grid = tomo_grid(cfg, run)
    maps = [PinholeMapping(cam) for cam in load_cameras(run)]
    costs.check_memory(costs.reconstruction_cost(grid.n_voxels, n_images=len(maps), iterations=c.tomo_iterations,
                                                 method=c.tomo_method),
                       what=f"[compare] tomo on {grid.shape[2]}x{grid.shape[1]}x{grid.shape[0]} voxels",
                       fix="set [compare] tomo_voxel_mm larger or [tracking] bounds_mm smaller")
    costs.check_memory(costs.piv_cost(grid.shape, c.tomo_windows, c.tomo_overlap),
                       what=f"[compare] tomo_windows = {list(c.tomo_windows)}, tomo_overlap = {c.tomo_overlap}",
                       fix="use a smaller overlap or larger windows")
    tw = time.perf_counter()
    def volume_images(f):  # MART takes no negative pixel: counts less the black level clipped at 0
        return [np.maximum(i, 0.0) for i in tracked_images(cfg, run, f)]

    _warm_up(volume_images(0), maps, grid, c.tomo_method)
    warm_s = time.perf_counter() - tw
    t0 = time.perf_counter()
    cache = WeightCache()
    recon_s = piv_s = 0.0
    pts, vels, valid, residual = [], [], [], []
    prev = None
    for f in range(pairs + 1):
        ta = time.perf_counter()
        vol, inf = reconstruct_volume(volume_images(f), maps, grid, c.tomo_method,
                                      iterations=c.tomo_iterations, progress=ctx.progress, cache=cache)
        recon_s += time.perf_counter() - ta
        if inf.get("residuals"):
            residual.append(float(np.ravel(inf["residuals"])[-1]))
        if prev is not None:
            tb = time.perf_counter()
            fld = analysis.piv3d(prev, vol, grid, windows=c.tomo_windows, overlap=c.tomo_overlap, dt_s=cfg.flow.dt_s,
                                 progress=ctx.progress)
            piv_s += time.perf_counter() - tb
            v = np.stack([fld.u, fld.v, fld.w], axis=-1).reshape(-1, 3)
            ok = (fld.valid & ~(fld.outlier & ~fld.replaced)).reshape(-1)
            v[~ok] = np.nan
            pts.append(fld.points_mm().reshape(-1, 3))
            vels.append(v)
            valid.append(float(ok.mean()))
        prev = vol
    wall = time.perf_counter() - t0
    egrid = eulerian_grid(cfg)
    found = bin_vectors(np.concatenate(pts), np.concatenate(vels), egrid)
    tt = truth_tracks(run)  # the truth over the frames the pairs span
    k = pairs + 1
    ref = bin_tracks(Tracks(tt.positions_mm[:, :k], tt.intensities[:, :k], tt.dt_s, tt.velocities_mm_s[:, :k]), egrid)
    m = {"status": "ok", "error": "", **binned_error(found["mean_mm_s"], found["count"], ref["mean_mm_s"],
                                                       ref["count"]),
         "yield": None, "ghost_fraction": None, "position_error_px": None, "position_error_mm": None,
         "wall_s": wall, "reconstruction_s": recon_s, "piv_s": piv_s, "warm_up_s": warm_s, "pairs": pairs,
         "voxels": list(grid.shape[::-1]), "voxel_mm": list(map(float, grid.voxel_mm)),
         "method": c.tomo_method, "valid_fraction": float(np.mean(valid)),
         "mart_residual": float(np.mean(residual)) if residual else None}
    m["velocity_error_rel"] = m["binned_error_rel"]
    write_npz(ctx.out / "binned.npz", {"bin_count": found["count"], "bin_mean_mm_s": found["mean_mm_s"],
                                       "bin_true_mean_mm_s": ref["mean_mm_s"],
                                       "bin_origin_mm": np.asarray(egrid.origin_mm, float),
                                       "bin_voxel_mm": np.asarray(egrid.voxel_mm, float)}, owner="tracking")
    out = null_metrics(m, {"binned": "no PIV vector fell in a bin that the true trajectories fill",
                           "velocity_error_rel": "no PIV vector fell in a bin that the true trajectories fill",
                           "": "not computable"}, where="tomo compare")
    # by definition, not a missing value: no warning
    na = {k: TOMO_NOT_APPLICABLE for k in ("yield", "ghost_fraction", "position_error_px", "position_error_mm")}
    out["null_reasons"] = {**na, **out.get("null_reasons", {})}
    return out


def stages(cfg) -> list[Stage]:
    """The opt-in comparison stages of a tracking experiment (none without ``[compare]``)."""
    c = cfg.compare
    out = []
    # the peer last: a stage's key holds every earlier stage's output, so new OpenLPT
    # settings (or version) rerun OpenLPT alone, not the tomographic comparison
    if c.tomo:
        out.append(Stage("tomo", ("compare",), stage_tomo))
    if c.openlpt:
        out.append(Stage("openlpt", ("compare",), stage_openlpt, packages=("openlpt",)))
    return out


def summary(results: dict) -> dict:
    """The comparison's part of a tracking run's metrics.json: per method its result."""
    return {k: results[k] for k in ("openlpt", "tomo") if results.get(k) is not None}


__all__ = ["CompareTable", "METHODS", "TOMO_NOT_APPLICABLE", "openlpt_settings", "particle_radius_px", "tomo_grid", "bin_vectors",
           "stage_openlpt", "stage_tomo", "stages", "summary"]
