"""The tracks of a tracking run and their scores, for the kind's evaluate stage
(:mod:`mitpiv.studies.kinds.tracking`) and its ``[compare]`` stages
(:mod:`mitpiv.studies.kinds.tracking.compare`) alike: the cameras the tracker uses
(:func:`load_cameras`), the images they read (:func:`tracked_images`), the tracks file (:func:`write_tracks_npz`), the true trajectories as
tracks (:func:`truth_tracks`), the LPT Challenge's scoring (:func:`score_tracks`) and the
Eulerian binning every method's velocities are compared on (:func:`eulerian_grid`,
:func:`binned_error`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mitpiv.studies.shared import bounds_of, frame_images, run_truth, source_of

__all__ = ["load_cameras", "tracked_images", "write_tracks_npz", "truth_tracks", "eulerian_grid", "binned_error", "score_tracks"]


def load_cameras(run: Path) -> list:
    """The cameras the tracker uses (the calibrate stage's ``cameras.json``)."""
    from mitpiv.io import camera_from_metadata, read_json

    return [camera_from_metadata(c) for c in read_json(run / "calibrate" / "cameras.json")["cameras"]]


def tracked_images(cfg, run: Path, frame: int) -> list[np.ndarray]:
    """The images of one frame that the trackers read: the ``sensor`` stage's counts less the
    black level when the experiment has a ``[sensor]`` table (a camera's background
    subtraction; a dark-current offset stays in), else the rendered radiance. Read or shot
    noise leaves negative pixels; MART's callers clip them at 0."""
    imgs, _ = frame_images(run, frame, source_of(cfg))
    if cfg.sensor is not None and cfg.sensor.black_level:
        imgs = [i - float(cfg.sensor.black_level) for i in imgs]
    return imgs


def write_tracks_npz(path, tracks) -> Path:
    from mitpiv.io import write_npz

    return write_npz(path, {"positions_mm": tracks.positions_mm, "intensities": tracks.intensities,
                            "dt_s": np.float64(tracks.dt_s), "velocities_mm_s": tracks.velocities_mm_s,
                            "accelerations_mm_s2": tracks.accelerations_mm_s2,
                            "raw_positions_mm": tracks.raw_positions_mm}, owner="tracking")


def _calibration_error_px(cams, true, lo, hi) -> float:
    """Largest reprojection difference [px] between fitted and true cameras over the box corners and centre."""
    pts = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])]
                   + [0.5 * (lo + hi)])
    return float(max(np.max(np.linalg.norm(c.project(pts) - t.project(pts), axis=1)) for c, t in
                     zip(cams, true, strict=True)))


def _grid(cfg, lo, hi):
    from mitpiv.grid import VoxelGrid

    b = cfg.evaluate.bin_mm
    vox = tuple((hi - lo) / 4) if b is None else (b if isinstance(b, tuple) else (b,) * 3)
    return VoxelGrid.from_bounds(tuple(lo), tuple(hi), vox)


def truth_tracks(run: Path):
    """The true trajectories of a run as :class:`~mitpiv.tracking.stb.Tracks` (particles,
    frames, 3), with the true velocities and accelerations."""
    from mitpiv.tracking import Tracks

    truth = run_truth(run, "field")
    pos = np.transpose(truth["positions_mm"], (1, 0, 2))
    vel, acc = truth["velocities_mm_s"], truth["accelerations_mm_s2"]
    vel = None if vel is None or vel.ndim != 3 else np.transpose(vel, (1, 0, 2))
    acc = None if acc is None else np.transpose(acc, (1, 0, 2))
    dt = np.diff(np.asarray(truth["times_s"], float))
    return Tracks(pos, np.ones(pos.shape[:2]), float(dt[0]) if dt.size else 1.0, vel, acc)


def eulerian_grid(cfg):
    """The Eulerian grid every method's velocities are binned on ([evaluate] bin_mm over the
    measurement box)."""
    lo, hi = bounds_of(cfg)
    return _grid(cfg, lo, hi)


def binned_error(found_mean, found_count, ref_mean, ref_count) -> dict:
    """Velocity error on an Eulerian grid: ``binned_mean_error_mm_s`` (RMS over the bins
    that both fill of the difference of the mean velocities [mm/s]), ``binned_error_rel``
    (divided by the RMS of the true bin means there) and ``binned_coverage`` (filled true bins
    that the method fills too); NaN where no bin is shared."""
    both = (np.asarray(found_count) > 0) & (np.asarray(ref_count) > 0)
    d = np.asarray(found_mean)[both] - np.asarray(ref_mean)[both]
    err = float(np.sqrt(np.mean(np.sum(d**2, axis=1)))) if d.size else float("nan")
    ref = float(np.sqrt(np.mean(np.sum(np.asarray(ref_mean)[both] ** 2, axis=1)))) if d.size else 0.0
    return {"binned_mean_error_mm_s": err, "binned_error_rel": err / ref if ref > 0 else float("nan"),
            "binned_coverage": float(both.sum() / max(int((np.asarray(ref_count) > 0).sum()), 1))}


def score_tracks(cfg, run: Path, tracks) -> dict:
    """Score tracks of a run's sequence against its truth (the evaluate stage's scoring, for
    mitpiv's tracks and a peer's alike).

    Returns
    -------
    dict: ``metrics`` (:func:`~mitpiv.tracking.metrics.track_metrics` without ``per_frame``
    and ``length_histogram``, plus ppp, the match radius, track counts, the calibration error
    and, when the tracks carry velocities, the binned errors of :func:`binned_error`),
    ``per_frame``, ``length_histogram``, ``velocity_error_mm_s`` ((tracks, frames), NaN where
    unmatched) and ``binned`` (the bin arrays for ``errors.npz``; empty without velocities).
    """
    from mitpiv.io import camera_from_metadata, read_json
    from mitpiv.tracking import bin_tracks, mm_per_px, track_metrics

    cams = load_cameras(run)
    true_cams = [camera_from_metadata(c) for c in read_json(run / "calibrate" / "cameras.json")["true"]]
    truth = run_truth(run, "field")
    ref_tracks = truth_tracks(run)
    lo, hi = bounds_of(cfg)
    scale = mm_per_px(true_cams, 0.5 * (lo + hi))
    radius = cfg.evaluate.radius_px * scale
    pos, vel, acc = ref_tracks.positions_mm, ref_tracks.velocities_mm_s, ref_tracks.accelerations_mm_s2
    m = track_metrics(tracks, pos, radius_mm=radius, truth_velocities_mm_s=vel, truth_accelerations_mm_s2=acc,
                      cameras=true_cams, lower_mm=lo, upper_mm=hi)
    per_frame = m.pop("per_frame")
    hist = m.pop("length_histogram")
    # the image density: particles in the box seen by the first camera, per pixel
    w, h = true_cams[0].resolution
    p0 = truth["positions_mm"][0]
    p0 = p0[np.all(np.isfinite(p0), axis=1)]
    m["ppp"] = float(true_cams[0].visible(p0).sum() / (w * h))
    m["match_radius_mm"] = radius
    m["mm_per_px"] = scale
    m["n_tracks"] = tracks.n_tracks
    lengths = tracks.lengths
    m["mean_track_length"] = float(lengths.mean()) if lengths.size else float("nan")
    m["calibration_error_px"] = _calibration_error_px(cams, true_cams, lo, hi)
    # per-sample errors for the report and the VTK export
    vel_err = np.full(tracks.positions_mm.shape[:2], np.nan)
    if tracks.velocities_mm_s is not None and vel is not None:
        from mitpiv.analysis.particles import assign

        for f in range(tracks.n_frames):
            q, ids = tracks.frame(f)
            t = pos[:, f]
            ok_t = np.flatnonzero(np.all(np.isfinite(t), axis=1))
            pr = assign(q, t[ok_t], radius)
            vel_err[ids[pr[:, 0]], f] = np.linalg.norm(tracks.velocities_mm_s[ids[pr[:, 0]], f]
                                                       - vel[ok_t[pr[:, 1]], f], axis=1)
    # Eulerian binning of the tracks and of the truth on the same grid
    binned = {}
    if tracks.velocities_mm_s is not None and vel is not None:
        grid = _grid(cfg, lo, hi)
        found = bin_tracks(tracks, grid)
        ref = bin_tracks(ref_tracks, grid)
        m.update(binned_error(found["mean_mm_s"], found["count"], ref["mean_mm_s"], ref["count"]))
        binned = {"bin_count": found["count"], "bin_mean_mm_s": found["mean_mm_s"], "bin_std_mm_s": found["std_mm_s"],
                  "bin_true_mean_mm_s": ref["mean_mm_s"], "bin_origin_mm": np.asarray(grid.origin_mm, float),
                  "bin_voxel_mm": np.asarray(grid.voxel_mm, float)}
    return {"metrics": m, "per_frame": per_frame, "length_histogram": hist, "velocity_error_mm_s": vel_err,
            "binned": binned}
