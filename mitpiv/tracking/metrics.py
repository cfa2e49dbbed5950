"""Metrics of particle tracking in the spirit of the first LPT Challenge (Leclaire,
Sciacchitano, Schroeder et al.): yield, ghosts, position, velocity and acceleration
errors, track lengths and correct tracks, and binning of tracks onto an Eulerian grid.

Definitions (stated here because the Challenge's exact match radius is a parameter)
-----------------------------------------------------------------------------------
- Matching: per frame, reconstructed particles are paired one-to-one with true particles
  within ``radius_mm`` by a minimum-total-distance assignment
  (:func:`mitpiv.analysis.particles.assign`). Only true particles inside the box
  ``[lower_mm, upper_mm]`` (when given) count, and only reconstructed particles inside it.
- ``yield``: matched / true particles. ``missed_fraction`` = 1 - yield.
- ``ghost_fraction``: unmatched reconstructed / reconstructed particles.
- ``position_error_mm``: mean Euclidean distance of matched pairs; ``position_error_px``:
  the same distance projected, averaged over the cameras (``|P_c(found) - P_c(true)|``).
- ``velocity_error``: mean ``|v - v_true|`` of matched track samples [mm/s], and divided by
  the RMS true speed (``velocity_error_rel``); the same for acceleration.
- A track is ``correct`` when all its samples (inside the box) match one and the same
  true particle.

All routines are vectorised (NumPy, SciPy sparse matching); frames are a short loop.
"""

from __future__ import annotations

import numpy as np

from mitpiv.analysis.particles import assign
from mitpiv.errors import ConfigError, check_positive
from mitpiv.grid import VoxelGrid

__all__ = ["particle_metrics", "track_metrics", "bin_tracks", "bin_velocities", "track_length_histogram"]


def _points(a, name, what):
    x = np.asarray(a, dtype=np.float64)
    if x.ndim != 2 or x.shape[1] != 3:
        raise ConfigError(f"{what}: '{name}' must be an (N, 3) array of positions [mm], got shape {x.shape}.")
    return x


def _inside(p, lower_mm, upper_mm):
    if lower_mm is None or upper_mm is None:
        return np.all(np.isfinite(p), axis=1)
    lo, hi = np.asarray(lower_mm, float), np.asarray(upper_mm, float)
    return np.all(np.isfinite(p), axis=1) & np.all((p >= lo) & (p <= hi), axis=1)


def particle_metrics(found_mm, truth_mm, *, radius_mm: float, cameras=None, lower_mm=None, upper_mm=None) -> dict:
    """Yield, ghost fraction and position errors of one frame's particles.

    Parameters
    ----------
    found_mm : (N, 3) reconstructed positions [mm]; truth_mm : (M, 3) true positions [mm]
        (NaN rows are absent particles).
    radius_mm : match radius [mm].
    cameras : optional cameras for the error in pixels.
    lower_mm, upper_mm : optional box; true and found particles outside it are not counted.

    Returns
    -------
    dict with ``n_true``, ``n_found``, ``n_matched``, ``yield``, ``missed_fraction``,
    ``ghost_fraction``, ``position_error_mm`` (mean), ``position_rms_mm`` (per axis),
    ``position_error_px`` (when cameras are given) and ``pairs`` ((K, 2) indices into
    found and truth).
    """
    f = _points(found_mm, "found_mm", "particle_metrics")
    t = _points(truth_mm, "truth_mm", "particle_metrics")
    r = check_positive("radius_mm", radius_mm, owner="particle_metrics", unit="mm")
    fidx = np.flatnonzero(_inside(f, lower_mm, upper_mm))
    tidx = np.flatnonzero(_inside(t, lower_mm, upper_mm))
    pairs = assign(f[fidx], t[tidx], r)
    pairs[:, 0] = fidx[pairs[:, 0]]
    pairs[:, 1] = tidx[pairs[:, 1]]
    nt, nf, nm = int(tidx.size), int(fidx.size), int(pairs.shape[0])
    err = f[pairs[:, 0]] - t[pairs[:, 1]]
    out = {"n_true": nt, "n_found": nf, "n_matched": nm,
           "yield": nm / nt if nt else float("nan"),
           "missed_fraction": 1.0 - nm / nt if nt else float("nan"),
           "ghost_fraction": (nf - nm) / nf if nf else float("nan"),
           "position_error_mm": float(np.linalg.norm(err, axis=1).mean()) if nm else float("nan"),
           "position_rms_mm": np.sqrt(np.mean(err**2, axis=0)).tolist() if nm else [float("nan")] * 3,
           "pairs": pairs}
    if cameras is not None:
        if nm:
            d = [np.linalg.norm(c.project(f[pairs[:, 0]]) - c.project(t[pairs[:, 1]]), axis=1) for c in cameras]
            out["position_error_px"] = float(np.mean(d))
        else:
            out["position_error_px"] = float("nan")
    return out


def track_length_histogram(lengths) -> np.ndarray:
    """Number of tracks of each length: ``h[n]`` tracks have ``n`` frames."""
    n = np.asarray(lengths, dtype=np.int64)
    return np.bincount(n) if n.size else np.zeros(1, np.int64)


def track_metrics(tracks, truth_positions_mm, *, radius_mm: float, truth_velocities_mm_s=None,
                  truth_accelerations_mm_s2=None, cameras=None, lower_mm=None, upper_mm=None, frames=None) -> dict:
    """Score tracks against true trajectories.

    Parameters
    ----------
    tracks : :class:`~mitpiv.tracking.stb.Tracks` (regularised for velocity and
        acceleration errors).
    truth_positions_mm : (n_particles, n_frames, 3) true positions, NaN where absent.
    radius_mm : match radius [mm].
    truth_velocities_mm_s, truth_accelerations_mm_s2 : same shape, optional.
    cameras, lower_mm, upper_mm : as in :func:`particle_metrics`.
    frames : frame indices to score (default all).

    Returns
    -------
    dict: summed over frames ``n_true``, ``n_found``, ``n_matched``, ``yield``,
    ``ghost_fraction``; mean ``position_error_mm`` (and ``_px``); ``velocity_error_mm_s``,
    ``velocity_error_rel``, ``acceleration_error_mm_s2``, ``acceleration_error_rel`` (when
    the truth is given and the tracks carry them); ``correct_track_fraction``;
    ``length_histogram`` (list) and ``per_frame`` (list of dicts of the frame's counts).
    """
    truth = np.asarray(truth_positions_mm, dtype=np.float64)
    if truth.ndim != 3 or truth.shape[2] != 3 or truth.shape[1] != tracks.n_frames:
        raise ConfigError(f"track_metrics: 'truth_positions_mm' must be (n_particles, {tracks.n_frames}, 3), "
                          f"got {truth.shape}.")
    frames = range(tracks.n_frames) if frames is None else [int(f) for f in frames]
    tot = {"n_true": 0, "n_found": 0, "n_matched": 0}
    e_pos, e_px, e_v, e_a, v_true, a_true = [], [], [], [], [], []
    owner = np.full(tracks.positions_mm.shape[:2], -1, np.int64)  # true particle matched per sample
    scored_sample = np.zeros(tracks.positions_mm.shape[:2], bool)  # present and inside the box
    per_frame = []
    for f in frames:
        q, ids = tracks.frame(f)
        m = particle_metrics(q, truth[:, f], radius_mm=radius_mm, cameras=cameras, lower_mm=lower_mm, upper_mm=upper_mm)
        for k in tot:
            tot[k] += m[k]
        per_frame.append({k: m[k] for k in ("n_true", "n_found", "n_matched", "yield", "ghost_fraction")})
        pr = m["pairs"]
        owner[ids[pr[:, 0]], f] = pr[:, 1]
        scored_sample[ids, f] = _inside(q, lower_mm, upper_mm)
        e_pos.append(np.linalg.norm(q[pr[:, 0]] - truth[pr[:, 1], f], axis=1))
        if cameras is not None and pr.shape[0]:
            e_px.append(np.mean([np.linalg.norm(c.project(q[pr[:, 0]]) - c.project(truth[pr[:, 1], f]), axis=1)
                                 for c in cameras], axis=0))
        for est, ref, err_l, ref_l in ((tracks.velocities_mm_s, truth_velocities_mm_s, e_v, v_true),
                                       (tracks.accelerations_mm_s2, truth_accelerations_mm_s2, e_a, a_true)):
            if est is not None and ref is not None:
                ref = np.asarray(ref, dtype=np.float64)
                d = np.linalg.norm(est[ids[pr[:, 0]], f] - ref[pr[:, 1], f], axis=1)
                ok = np.isfinite(d)
                err_l.append(d[ok])
                ref_l.append(np.linalg.norm(ref[pr[:, 1], f], axis=1)[ok])
    out = dict(tot)
    out["yield"] = tot["n_matched"] / tot["n_true"] if tot["n_true"] else float("nan")
    out["ghost_fraction"] = (tot["n_found"] - tot["n_matched"]) / tot["n_found"] if tot["n_found"] else float("nan")
    ep = np.concatenate(e_pos) if e_pos else np.zeros(0)
    out["position_error_mm"] = float(ep.mean()) if ep.size else float("nan")
    if cameras is not None:
        epx = np.concatenate(e_px) if e_px else np.zeros(0)
        out["position_error_px"] = float(epx.mean()) if epx.size else float("nan")
    for name, err_l, ref_l, unit in (("velocity", e_v, v_true, "mm_s"), ("acceleration", e_a, a_true, "mm_s2")):
        if err_l:
            e, r = np.concatenate(err_l), np.concatenate(ref_l)
            out[f"{name}_error_{unit}"] = float(e.mean()) if e.size else float("nan")
            rms = np.sqrt(np.mean(r**2)) if r.size else 0.0
            out[f"{name}_error_rel"] = float(e.mean() / rms) if e.size and rms > 0 else float("nan")
    # correct tracks: every scored sample matched, all to the same true particle
    present = scored_sample[:, list(frames)]
    own = owner[:, list(frames)]
    scored = present.any(axis=1)
    first = np.where(present, own, np.iinfo(np.int64).max).min(axis=1)
    same = np.all(~present | (own == first[:, None]), axis=1) & np.all(~present | (own >= 0), axis=1)
    out["correct_track_fraction"] = float((same & scored).sum() / scored.sum()) if scored.any() else float("nan")
    out["length_histogram"] = track_length_histogram(tracks.lengths).tolist()
    out["per_frame"] = per_frame
    return out


def bin_tracks(tracks, grid: VoxelGrid) -> dict:
    """Eulerian statistics of track velocities on a voxel grid (for comparison with
    tomographic PIV): every regularised sample falls in the voxel holding its position.

    Returns
    -------
    dict with ``count`` (n_z, n_y, n_x), ``mean_mm_s`` and ``std_mm_s`` (n_z, n_y, n_x, 3)
    (NaN where a bin has no sample; the standard deviation, the fluctuating velocity, is
    the population value, NaN with fewer than 2 samples).
    """
    if tracks.velocities_mm_s is None:
        raise ConfigError("bin_tracks: the tracks carry no velocities; regularise them first "
                          "(mitpiv.tracking.stb.regularise).")
    return bin_velocities(tracks.positions_mm, tracks.velocities_mm_s, grid)


def bin_velocities(points_mm, velocities_mm_s, grid: VoxelGrid) -> dict:
    """Velocities at points binned onto the voxels of ``grid`` (the Eulerian statistics of
    :func:`bin_tracks`, also used for PIV vectors): ``points_mm`` and ``velocities_mm_s``
    (..., 3) [mm], [mm/s]; rows with a NaN and points outside the grid are left out.
    Returns ``count`` (n_z, n_y, n_x), ``mean_mm_s`` and ``std_mm_s`` (n_z, n_y, n_x, 3), NaN
    where a bin has no sample (std: fewer than 2; the population value)."""
    p = np.asarray(points_mm, dtype=float).reshape(-1, 3)
    v = np.asarray(velocities_mm_s, dtype=float).reshape(-1, 3)
    ok = np.all(np.isfinite(p), axis=1) & np.all(np.isfinite(v), axis=1)
    p, v = p[ok], v[ok]
    nz, ny, nx = grid.shape
    ijk = np.floor((p - np.asarray(grid.origin_mm)) / np.asarray(grid.voxel_mm)).astype(np.int64)
    inside = np.all((ijk >= 0) & (ijk < np.array([nx, ny, nz])), axis=1)
    ijk, v = ijk[inside], v[inside]
    flat = (ijk[:, 2] * ny + ijk[:, 1]) * nx + ijk[:, 0]
    n = grid.n_voxels
    count = np.bincount(flat, minlength=n).astype(np.float64)
    s1 = np.stack([np.bincount(flat, weights=v[:, c], minlength=n) for c in range(3)], axis=1)
    s2 = np.stack([np.bincount(flat, weights=v[:, c] ** 2, minlength=n) for c in range(3)], axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = s1 / count[:, None]
        var = np.maximum(s2 / count[:, None] - mean**2, 0.0)
    mean[count == 0] = np.nan
    std = np.sqrt(var)
    std[count < 2] = np.nan
    shp = (nz, ny, nx)
    return {"count": count.reshape(shp).astype(np.int64), "mean_mm_s": mean.reshape(shp + (3,)),
            "std_mm_s": std.reshape(shp + (3,))}
