"""Score another tool's result against a run's truth with mitpiv's own metrics
(``mitpiv score RUN RESULT``): the loop a user runs with their own processing — render a
case, process its images in DaVis, OpenPIV, PIVlab, OpenLPT, OpenPTV or an in-house code,
and get that result scored the way mitpiv scores its own.

What is scored (:func:`score`; the readers are :mod:`mitpiv.io.external`):

**A 2-D vector field** (planar PIV on one camera's images, ``--camera``; default the run's
only or first camera). The field's positions and displacements are in that camera's pixels
(``--length-unit px``; OpenPIV's default) or in world units on a plane ``z = const``
(``--plane-z-mm``, default the laser sheet's mid-plane; a calibrated planar field: DaVis in mm
and m/s), which are projected through the run's exact camera into pixels. Each vector's
reference is a *window-averaged truth* between the two frames (``--frames A B``, default
0 1) over its interrogation window (a square of ``--window`` in the field's length unit),
one of two (``--reference``):

* ``flow`` (the default when the run records an analytic flow): ``4 x 4`` points spread over
  the window traced back through the camera onto the sheet's mid-plane, advected by the flow
  and projected again (:func:`flow_image_reference`): the averaging
  :func:`mitpiv.analysis.velocity_error` does in 3-D, on the plane the camera images.
* ``particles``: the image displacement of the true particles whose frame-A image lies inside
  the window, each weighted by ``I_A I_B``, the product of its image intensities in the two
  frames (a correlation peak is the sum of such products): ``I = d^2 x`` the laser sheet's
  relative irradiance at the particle (the scene's sheet profile; ``d`` the diameter);
  :func:`image_plane_truth`. What the correlation could see, out-of-plane motion and the
  sheet profile included, but a sample of the few particles of a small window: where the
  displacement varies across a window it scatters by about ``dU / sqrt(12 N)``. Windows
  without a true particle have no reference and are left out (counted).

Both are computed; ``reference_spread_px``, the RMS difference between them, is the floor
the particle sample puts under any comparison. Errors in pixels: RMS per component, bias, RMS
magnitude, the fraction with ``|error| > 1 px`` (:data:`ERROR_OUTLIER`) and the universal
outlier detection's ratio (:func:`mitpiv.analysis.uod`, threshold 2, epsilon 0.1 px, as
mitpiv validates its own).

**A 3-D vector field** (tomographic PIV): positions in mm (or m), velocities in mm/s or m/s,
or displacements (mm, m or the run's voxels) between the frames. Scored by
:func:`mitpiv.analysis.velocity_error` exactly as a mitpiv run scores its own field: the
reference is the flow advected from ``4^3`` points spread over each window (``--window`` in
mm), over the frames' interval. The field must lie on a rectilinear lattice (missing nodes
are invalid vectors).

**Particles or tracks** (LPT, PTV, STB): positions in mm matched per frame to the true
particles within ``--radius-mm`` (default: the run's own match radius) inside the run's
measurement box: yield, ghost fraction, position error (mm and px) per the LPT Challenge
(:func:`mitpiv.tracking.particle_metrics`); tracks (rows linked over at least 3 frames)
are regularised as mitpiv's own (:func:`mitpiv.tracking.stb.regularise`, a local quadratic
over 7 frames) and scored by :func:`mitpiv.tracking.track_metrics` (velocity and
acceleration errors, correct tracks). ``--first-frame`` is the run frame of the result's
first frame (OpenLPT and OpenPTV number their own frames from their first image).

**Refused, not silently scored** (:class:`ResultMismatch`, exit status 2; ``--force`` scores
anyway and records the flags): a field whose positions mostly lie outside the camera's image
or the run's volume, whose RMS displacement differs from the truth's by more than a factor
:data:`MISMATCH_FACTOR` (2; the message names the likely cause: m against mm, a velocity read
as a displacement), or one of whose components is anti-correlated with the truth (a y axis
pointing up: OpenPIV's ``transform_coordinates``; ``--flip-y`` undoes it); particles whose
median distance to the nearest true particle exceeds 3 match radii.

Writes, in ``out_dir``: ``score.json`` (every number, the settings used and the flags),
``score.md`` (the table a mitpiv run's report shows) and a figure (``velocity_error.png``:
the error map and its distribution; ``particles.png``: yield and ghosts per frame and the
position-error histogram).

Hand-written here: the window-averaged image-plane references (the flow traced onto the
sheet; an integral image of the particles' weighted displacements: no PIV package scores
against a rendered run's truth) and the checks; the
metrics are mitpiv's own (:mod:`mitpiv.analysis`, :mod:`mitpiv.tracking.metrics`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError, FileFormatError, MitpivError
from mitpiv.studies.shared import read_run_record, truth_file

__all__ = ["score", "ResultMismatch", "MISMATCH_FACTOR", "ERROR_OUTLIER", "LENGTH_UNITS", "VELOCITY_UNITS",
           "image_plane_truth", "flow_image_reference"]

log = logging.getLogger(__name__)

#: A field whose RMS displacement differs from the truth's by more than this factor is refused.
MISMATCH_FACTOR = 2.0
#: An error larger than this (px of a 2-D field, voxels of a 3-D one) counts as an outlier.
ERROR_OUTLIER = 1.0

#: Length units [mm per unit] (``px`` and ``vox``: the camera's pixels, the run's voxels).
LENGTH_UNITS = {"mm": 1.0, "m": 1e3, "cm": 10.0, "um": 1e-3, "px": None, "pixel": None, "vox": None}
#: Vector units: displacements between the frames (a length unit) or velocities (``.../s``).
VELOCITY_UNITS = ("px", "px/s", "vox", "mm", "m", "mm/s", "m/s", "cm/s", "um/s")


class ResultMismatch(MitpivError, ValueError):
    """The result does not describe the run's truth in the units and frame assumed: a wrong
    unit, coordinate system or frame pair (the message names the likely fix)."""


def _unit(u, what: str, allowed) -> str | None:
    if u is None:
        return None
    s = str(u).strip().lower().replace("µ", "u").replace(" ", "")
    s = {"pixel": "px", "pixels": "px", "voxel": "vox", "voxels": "vox", "pixel/s": "px/s"}.get(s, s)
    if s not in allowed:
        raise ConfigError(f"score: {what} {u!r} is not one of {sorted(set(allowed))}.")
    return s


@dataclass
class _Run:
    path: Path
    exp: dict
    truth: dict
    times: np.ndarray
    cameras: dict
    sheets: dict
    lower: np.ndarray
    upper: np.ndarray
    voxel_mm: float | None


def _load_run(run_dir) -> _Run:
    from mitpiv.io import camera_from_metadata, read_json, read_truth

    run = Path(run_dir)
    exp = read_run_record(run, owner="score")
    tf = truth_file(run)
    if tf is None:
        raise FileFormatError(f"score: the run {str(run)!r} has no truth yet (particles/ or field/ truth.npz); run "
                              f"'mitpiv run EXPERIMENT --out {run}' first.")
    truth = read_truth(tf)
    cameras = {}
    if (run / "calibrate" / "cameras.json").is_file():  # a tracking run: the true cameras
        d = read_json(run / "calibrate" / "cameras.json")
        ids = d.get("ids") or [f"cam{i}" for i in range(len(d["true"]))]
        cameras = {i: camera_from_metadata(c) for i, c in zip(ids, d["true"], strict=False)}
    if not cameras:
        try:
            from mitpiv.studies.shared import run_images

            im = run_images(run)
            cameras = dict(zip(im["sensors"], im["cameras"], strict=True))
        except FileFormatError:
            cameras = {}
    sheets = {}
    sc = exp.get("scene") or {}
    if sc.get("xml"):
        try:
            from mitpiv.studies.shared import load_scene_rig

            rig = load_scene_rig(sc["xml"], params=sc.get("params"))
            sheets = rig.sheets
            if not cameras:
                cameras = rig.cameras
        except (MitpivError, OSError, RuntimeError) as e:  # the scene moved: no sheet weighting
            log.warning("score: the scene %s could not be loaded (%s); particles are weighted by d^2 alone",
                        sc["xml"], e)
    seed = exp.get("seeding") or {}
    lo = np.asarray(seed.get("box_min_mm", np.nanmin(truth["positions_mm"], axis=(0, 1))), float)
    hi = np.asarray(seed.get("box_max_mm", np.nanmax(truth["positions_mm"], axis=(0, 1))), float)
    b = (exp.get("tracking") or {}).get("bounds_mm") or (exp.get("reconstruction") or {}).get("bounds_mm")
    if b:
        lo, hi = np.array(b[0::2], float), np.array(b[1::2], float)
    vox = (exp.get("reconstruction") or {}).get("voxel_mm")
    vox = float(vox[0] if isinstance(vox, list | tuple) else vox) if vox else None
    return _Run(run, exp, truth, np.asarray(truth["times_s"], float), cameras, sheets, lo, hi, vox)


def _frames(run: _Run, frames) -> tuple[int, int]:
    a, b = (int(f) for f in frames)
    n = len(run.times)
    if not (0 <= a < n and 0 <= b < n and a != b):
        raise ConfigError(f"score: --frames {a} {b} must be two different frames of the run's {n} (0..{n - 1}).")
    return a, b


def _camera(run: _Run, camera: str | None):
    if not run.cameras:
        raise FileFormatError(f"score: the run {str(run.path)!r} has no camera records (no rendered images); a 2-D "
                              "field is scored in a camera's image.")
    if camera is None:
        camera = next(iter(run.cameras))
    if camera not in run.cameras:
        raise ConfigError(f"score: --camera {camera!r} is not a camera of the run; its cameras: {list(run.cameras)}.")
    return camera, run.cameras[camera]


def _intensity(run: _Run, p_mm: np.ndarray) -> np.ndarray:
    """Relative image intensity of particles at ``p_mm``: d^2 x the sheets' summed irradiance."""
    from mitpiv.physics.sheet import sheet_profile

    d2 = np.asarray(run.truth["diameters_um"], float) ** 2
    if not run.sheets:
        return d2 * np.all(np.isfinite(p_mm), axis=1)
    irr = np.zeros(len(p_mm))
    for s in run.sheets.values():
        n = np.asarray(s["normal"], float)
        n = n / np.linalg.norm(n)
        dist = (p_mm - np.asarray(s["origin_mm"], float)) @ n
        irr += np.nan_to_num(sheet_profile(dist, float(s["thickness_mm"]), s.get("profile", "gaussian"),
                                           float(s.get("order") or 2.0)))
    return d2 * irr


def image_plane_truth(centres_px, window_px, pa_px, pb_px, weights, resolution) -> tuple[np.ndarray, np.ndarray]:
    """Window-averaged image displacement at window centres.

    Parameters
    ----------
    centres_px : (M, 2) window centres (x, y) [px], pixel ``i`` spanning ``[i, i + 1)``.
    window_px : the square window's side [px]; its edges are rounded to whole pixels.
    pa_px, pb_px : (N, 2) particle images in the two frames [px] (NaN: not imaged).
    weights : (N,) weight of each particle (0 leaves it out).
    resolution : (W, H) of the image.

    Returns
    -------
    (M, 2) weighted mean displacement ``pb - pa`` of the particles whose frame-A image lies
    in each window (NaN where none does) and (M,) the number of such particles.
    """
    W, H = (int(r) for r in resolution)
    pa, pb = np.asarray(pa_px, float), np.asarray(pb_px, float)
    w = np.asarray(weights, float)
    ok = np.all(np.isfinite(pa), axis=1) & np.all(np.isfinite(pb), axis=1) & (w > 0)
    ix = np.floor(pa[:, 0]).astype(np.int64, copy=False) if len(pa) else np.zeros(0, np.int64)
    iy = np.floor(pa[:, 1]).astype(np.int64, copy=False) if len(pa) else np.zeros(0, np.int64)
    ok &= (ix >= 0) & (ix < W) & (iy >= 0) & (iy < H)
    flat = iy[ok] * W + ix[ok]
    d = pb[ok] - pa[ok]
    sums = [np.bincount(flat, weights=x, minlength=W * H).reshape(H, W)
            for x in (w[ok], w[ok] * d[:, 0], w[ok] * d[:, 1], np.ones(ok.sum()))]
    integ = [np.pad(np.cumsum(np.cumsum(s, axis=0), axis=1), ((1, 0), (1, 0))) for s in sums]
    c = np.asarray(centres_px, float)
    half = 0.5 * float(window_px)
    x0 = np.clip(np.rint(c[:, 0] - half), 0, W).astype(np.int64)
    x1 = np.clip(np.rint(c[:, 0] + half), 0, W).astype(np.int64)
    y0 = np.clip(np.rint(c[:, 1] - half), 0, H).astype(np.int64)
    y1 = np.clip(np.rint(c[:, 1] + half), 0, H).astype(np.int64)
    box = [s[y1, x1] - s[y0, x1] - s[y1, x0] + s[y0, x0] for s in integ]
    with np.errstate(invalid="ignore", divide="ignore"):
        ref = np.stack([box[1] / box[0], box[2] / box[0]], axis=1)
    ref[~(box[0] > 0)] = np.nan
    return ref, np.rint(box[3]).astype(np.int64)


def flow_image_reference(cam, flow, centres_px, window_px, *, plane_point_mm, plane_normal, t0_s: float, dt_s: float,
                         samples: int = 4, substeps: int = 10) -> np.ndarray:
    """Window-averaged image displacement of an analytic flow on a plane (a 2-D field's flow
    reference).

    ``samples`` x ``samples`` points spread uniformly over each square window (side
    ``window_px``, centres ``centres_px`` (M, 2), pixel ``i`` spanning ``[i, i + 1)``) are
    traced back through the camera (``pixel_to_ray``) onto the plane through
    ``plane_point_mm`` with normal ``plane_normal`` (the laser sheet's mid-plane), advected by
    ``flow`` from ``t0_s`` over ``dt_s`` (RK4, ``substeps``) and projected again; the mean
    image displacement per window, (M, 2) [px], is returned (NaN where a ray misses the
    plane). The same averaging as :func:`mitpiv.analysis.velocity_error` in 3-D, on the plane
    the camera images.
    """
    from mitpiv.physics.advection import advect

    c = np.asarray(centres_px, float)
    q = ((np.arange(samples) + 0.5) / samples - 0.5) * float(window_px)
    ox, oy = np.meshgrid(q, q)
    uv = c[:, None, :] + np.stack([ox.ravel(), oy.ravel()], axis=-1)[None]  # (M, S, 2)
    o, d = cam.pixel_to_ray(uv)
    n = np.asarray(plane_normal, float)
    n = n / np.linalg.norm(n)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = ((np.asarray(plane_point_mm, float) - o) @ n) / (d @ n)
    world = o + d * np.where(t > 0, t, np.nan)[..., None]
    flat = world.reshape(-1, 3)
    ok = np.all(np.isfinite(flat), axis=1)
    disp = np.full((len(flat), 2), np.nan)
    if ok.any():
        moved = advect(flat[ok], flow, dt_s=dt_s, t0_s=t0_s, substeps=substeps)
        disp[ok] = cam.project(moved) - cam.project(flat[ok])
    return disp.reshape(uv.shape).mean(axis=1)


def _lattice(points: np.ndarray, rel_tol: float = 1e-4):
    """The rectilinear lattice of ``points`` (N, D): (axes, index (N, D)) or None."""
    axes, index = [], []
    for k in range(points.shape[1]):
        x = points[:, k]
        span = float(np.ptp(x)) if x.size else 0.0
        tol = rel_tol * (span if span > 0 else 1.0)
        key = np.rint(x / tol).astype(np.int64)
        _, inv = np.unique(key, return_inverse=True)
        vals = np.bincount(inv, weights=x) / np.bincount(inv)  # each lattice coordinate: its points' mean
        axes.append(vals)
        index.append(inv)
    idx = np.stack(index, axis=1)
    shape = tuple(len(a) for a in axes)
    if np.prod(shape) > 8 * len(points) + 64:
        return None  # scattered: most nodes of the product would be empty
    flat = np.ravel_multi_index(idx.T, shape)
    if np.unique(flat).size != len(points):
        return None  # two vectors on one node
    return axes, idx


def _uod_ratio(points, disp, valid, step_units) -> tuple[float, np.ndarray]:
    """mitpiv's universal outlier detection on a gridded field (2-D or 3-D): (ratio, outlier mask)."""
    from mitpiv.analysis import VectorField, uod

    lat = _lattice(points)
    if lat is None:
        return float("nan"), np.zeros(len(points), bool)
    axes, idx = lat
    while len(axes) < 3:
        axes.append(np.zeros(1))
        idx = np.column_stack([idx, np.zeros(len(idx), np.int64)])
    shape = (len(axes[2]), len(axes[1]), len(axes[0]))
    comp = np.zeros(shape + (3,))
    ok = np.zeros(shape, bool)
    comp[idx[:, 2], idx[:, 1], idx[:, 0], :disp.shape[1]] = disp / step_units
    ok[idx[:, 2], idx[:, 1], idx[:, 0]] = valid
    z = np.zeros(shape)
    f = VectorField(axes[0], axes[1], axes[2], comp[..., 0], comp[..., 1], comp[..., 2], z, z, ok,
                    np.zeros(shape, bool), np.zeros(shape, bool), (1.0, 1.0, 1.0), (1, 1, 1))
    out = uod(f)
    return out.outlier_ratio, out.outlier[idx[:, 2], idx[:, 1], idx[:, 0]]


def _ratio_hint(r: float, vu: str) -> str:
    hints = []
    for factor, why in ((1e3, "a length in m read as mm (or mm/s as m/s): give --length-unit / --velocity-unit"),
                        (1e-3, "a length in mm read as m (or m/s as mm/s): give --length-unit / --velocity-unit")):
        if abs(np.log(r / factor)) < np.log(MISMATCH_FACTOR):
            hints.append(why)
    if vu.endswith("/s") and r < 1.0 / MISMATCH_FACTOR:
        hints.append("a displacement read as a velocity: give --velocity-unit px, vox or mm")
    if not vu.endswith("/s") and r > MISMATCH_FACTOR:
        hints.append("a velocity read as a displacement: give --velocity-unit px/s, mm/s or m/s")
    return "; likely " + " or ".join(hints) if hints else "; check the frame pair (--frames) and the units"


def _check_agreement(meas, ref, *, noise: float, unit: str, vu: str, names="xyz") -> list[str]:
    """The flags of a field against its reference (module notes)."""
    ok = np.all(np.isfinite(meas), axis=1) & np.all(np.isfinite(ref), axis=1)
    m, r = meas[ok], ref[ok]
    flags = []
    if not len(m):
        return ["no vector of the result has a true reference (positions outside the run's image / volume)"]
    rms_m = float(np.sqrt(np.mean(np.sum(m * m, axis=1))))
    rms_r = float(np.sqrt(np.mean(np.sum(r * r, axis=1))))
    if rms_r > noise:
        q = rms_m / rms_r
        if not (1.0 / MISMATCH_FACTOR <= q <= MISMATCH_FACTOR):
            flags.append(f"the RMS displacement is {q:.3g} x the truth's ({rms_m:.4g} against {rms_r:.4g} {unit})"
                         + _ratio_hint(q, vu))
    for k in range(m.shape[1]):
        rr = float(np.sum(r[:, k] ** 2))
        if rr / len(r) > noise**2:
            s = float(np.sum(m[:, k] * r[:, k])) / rr
            if s < -0.25:  # clearly anti-correlated, not a near-zero fit
                flip = " (a y axis pointing up, as OpenPIV's transform_coordinates makes it: give --flip-y)" \
                    if names[k] == "y" else ""
                flags.append(f"the {names[k]} component runs against the truth's (fitted slope {s:.3g}){flip}")
    return flags


def _stats(e: np.ndarray, unit: str) -> dict:
    if not len(e):
        nan = [float("nan")] * e.shape[1]
        return {"rms": nan, "bias": nan, "rms_magnitude": float("nan"), "mean_abs_magnitude": float("nan"),
                "units": unit}
    return {"rms": np.sqrt(np.mean(e * e, axis=0)).tolist(), "bias": e.mean(axis=0).tolist(),
            "rms_magnitude": float(np.sqrt(np.mean(np.sum(e * e, axis=1)))),
            "mean_abs_magnitude": float(np.mean(np.linalg.norm(e, axis=1))), "units": unit}


def _to_px(run: _Run, cam, ev, lu: str, vu: str, dt: float, plane_z: float):
    """A 2-D field's positions and displacements in the camera's pixels."""
    P, V = ev.points[:, :2], ev.vectors[:, :2]
    if lu == "px":
        if vu not in ("px", "px/s"):
            raise ConfigError(f"score: positions in px with vectors in {vu!r}: a 2-D field in a camera's pixels has "
                              "displacements in px (or px/s); give --velocity-unit px or --length-unit mm.")
        return P.copy(), V * (dt if vu == "px/s" else 1.0)
    if lu == "vox" or vu in ("px", "px/s", "vox"):
        raise ConfigError(f"score: a 2-D field with positions in {lu!r} needs world vectors (mm, m, mm/s, m/s), "
                          f"got {vu!r}; or give both in px.")
    s = LENGTH_UNITS[lu]
    world = np.column_stack([P * s, np.full(len(P), plane_z)])
    vmm = V * LENGTH_UNITS[vu.split("/")[0]] * (dt if vu.endswith("/s") else 1.0)
    d_world = np.column_stack([vmm, np.zeros(len(P))])
    a = cam.project(world)
    return a, cam.project(world + d_world) - a


def _sheet_plane(run: _Run, plane_z_mm):
    """The plane a 2-D field lies on: z = ``plane_z_mm`` when given, else the run's one laser
    sheet's mid-plane, else z = the volume's middle. Returns (point, normal, what)."""
    if plane_z_mm is not None:
        return np.array([0.0, 0.0, float(plane_z_mm)]), np.array([0.0, 0.0, 1.0]), f"z = {float(plane_z_mm):g} mm"
    if len(run.sheets) == 1:
        s = next(iter(run.sheets.values()))
        return np.asarray(s["origin_mm"], float), np.asarray(s["normal"], float), "the laser sheet's mid-plane"
    z = float(0.5 * (run.lower[2] + run.upper[2]))
    return np.array([0.0, 0.0, z]), np.array([0.0, 0.0, 1.0]), f"z = {z:g} mm (the volume's middle)"


def _score_2d(run: _Run, ev, *, camera, frames, window, lu, vu, plane_z_mm, reference, force) -> tuple[dict, dict]:
    cam_id, cam = _camera(run, camera)
    a, b = _frames(run, frames)
    dt = float(run.times[b] - run.times[a])
    lu = lu or "px"
    vu = vu or ("px" if lu == "px" else None)
    if vu is None:
        raise ConfigError(f"score: {ev.source!r} does not state its vector unit; give --velocity-unit (mm/s, m/s, mm, "
                          "m, px).")
    plane_pt, plane_n, plane_what = _sheet_plane(run, plane_z_mm)
    plane_z = float(plane_pt[2])
    if lu != "px" and abs(abs(plane_n[2]) - 1.0) > 1e-9:
        raise ConfigError(f"score: a 2-D field in {lu!r} is read on a plane z = const; the run's sheet is tilted "
                          f"(normal {plane_n.tolist()}): give --plane-z-mm, or the field in px.")
    pts, disp = _to_px(run, cam, ev, lu, vu, dt, plane_z)
    Wd, Ht = cam.resolution
    if window is None:
        raise ConfigError("score: give --window, the interrogation window's side in the field's length unit (e.g. "
                          "--window 32 for 32 x 32 px windows): the truth is averaged over it.")
    win = float(window)
    if not win > 0:
        raise ConfigError(f"score: --window must be > 0, got {window!r}.")
    if lu != "px":  # the window in pixels at the plane's centre
        c = np.array([[*(0.5 * (run.lower[:2] + run.upper[:2])), plane_z]])
        s = LENGTH_UNITS[lu] * win
        win_px = float(np.mean([np.linalg.norm(cam.project(c + d) - cam.project(c)) for d in
                                (np.array([[s, 0, 0]]), np.array([[0, s, 0]]))]))
    else:
        win_px = win
    pos = run.truth["positions_mm"]
    pa_w, pb_w = pos[a], pos[b]
    pa, pb = cam.project(pa_w), cam.project(pb_w)
    vis = cam.visible(pa_w) & cam.visible(pb_w)
    w = _intensity(run, pa_w) * _intensity(run, pb_w) * vis
    ref_p, n_in = image_plane_truth(pts, win_px, pa, pb, w, cam.resolution)
    has_flow = bool(run.truth.get("flow"))
    if reference is None:
        reference = "flow" if has_flow else "particles"
    if reference not in ("flow", "particles"):
        raise ConfigError(f"score: --reference {reference!r} is not 'flow' or 'particles'.")
    ref_f = None
    if has_flow:
        from mitpiv.physics.flows import flow_from_dict

        ref_f = flow_image_reference(cam, flow_from_dict(dict(run.truth["flow"])), pts, win_px, plane_point_mm=plane_pt,
                                     plane_normal=plane_n, t0_s=float(run.times[a]), dt_s=dt)
    elif reference == "flow":
        raise FileFormatError(f"score: the run {str(run.path)!r} records no analytic flow; use --reference particles.")
    ref = ref_f if reference == "flow" else ref_p
    inside = (pts[:, 0] >= 0) & (pts[:, 0] <= Wd) & (pts[:, 1] >= 0) & (pts[:, 1] <= Ht)
    flags = []
    if inside.mean() < 0.5:
        flags.append(f"{100 * (1 - inside.mean()):.0f} % of the vectors lie outside camera {cam_id!r}'s {Wd} x {Ht} px "
                     f"image (positions span x {np.nanmin(pts[:, 0]):.4g}..{np.nanmax(pts[:, 0]):.4g}, y "
                     f"{np.nanmin(pts[:, 1]):.4g}..{np.nanmax(pts[:, 1]):.4g} px): a different length unit, origin "
                     "or camera (--length-unit, --camera)")
    use = ev.valid & np.all(np.isfinite(ref), axis=1) & inside
    span = float(max(np.ptp(pts[:, 0]), np.ptp(pts[:, 1]))) if len(pts) > 1 else 0.0
    if len(pts) > 1 and span < win_px:
        flags.append(f"the {len(pts)} vectors span {span:.3g} px, less than one {win_px:.3g} px window: a length "
                     "unit too large (m read as mm?), give --length-unit")
    flags += _check_agreement(np.where(use[:, None], disp, np.nan), ref, noise=0.1, unit="px", vu=vu, names="xy")
    err = np.where(use[:, None], disp - ref, np.nan)
    e = err[use]
    uod_ratio, uod_out = _uod_ratio(pts, disp, ev.valid, 1.0)
    both = use & np.all(np.isfinite(ref_p), axis=1) & (np.all(np.isfinite(ref_f), axis=1) if ref_f is not None
                                                         else False)
    spread = float(np.sqrt(np.mean(np.sum((ref_p[both] - ref_f[both]) ** 2, axis=1)))) if np.any(both) else \
        float("nan")
    m = {"kind": "vectors-2d", "camera": cam_id, "frames": [a, b], "dt_s": dt, "window_px": win_px,
         "reference": reference, "plane": plane_what, "reference_spread_px": spread,
         "n_vectors": int(len(pts)), "n_valid": int(ev.valid.sum()), "n_scored": int(use.sum()),
         "n_without_truth": int((ev.valid & inside & ~np.all(np.isfinite(ref), axis=1)).sum()),
         "particles_per_window": float(np.mean(n_in[use])) if use.any() else float("nan"),
         **{f"{k}_px" if k != "units" else k: v for k, v in _stats(e, "px").items()},
         "error_outlier_fraction": float(np.mean(np.linalg.norm(e, axis=1) > ERROR_OUTLIER)) if len(e) else
         float("nan"), "error_outlier_px": ERROR_OUTLIER, "uod_outlier_ratio": uod_ratio,
         "length_unit": lu, "velocity_unit": vu, "plane_z_mm": plane_z if lu != "px" else None}
    arrays = {"points_px": pts, "measured_px": disp, "reference_px": ref, "error_px": err, "scored": use,
              "uod_outlier": uod_out, "resolution": np.asarray(cam.resolution)}
    return _flagged(m, flags, force), arrays


def _score_3d(run: _Run, ev, *, frames, window, lu, vu, force) -> tuple[dict, dict]:
    from mitpiv.analysis import VectorField, uod, velocity_error
    from mitpiv.analysis.summary import velocity_error_summary
    from mitpiv.physics.flows import flow_from_dict

    a, b = _frames(run, frames)
    dt = float(run.times[b] - run.times[a])
    if not run.truth.get("flow"):
        raise FileFormatError(f"score: the run {str(run.path)!r} records no analytic flow; a 3-D field is scored "
                              "against the flow averaged over its windows.")
    flow = flow_from_dict(dict(run.truth["flow"]))
    if lu is None or lu in ("px", "vox"):
        raise ConfigError(f"score: a 3-D field's positions must be in mm, m, cm or um (--length-unit), got {lu!r}.")
    if vu is None:
        raise ConfigError(f"score: {ev.source!r} does not state its vector unit; give --velocity-unit (mm/s, m/s, mm, "
                          "m, vox).")
    if vu in ("px", "px/s"):
        raise ConfigError("score: a 3-D field's vectors cannot be in px; give --velocity-unit mm/s, m/s, mm, m or vox.")
    P = ev.points * LENGTH_UNITS[lu]
    if vu == "vox":
        if run.voxel_mm is None:
            raise ConfigError("score: --velocity-unit vox needs the run's voxel ([reconstruction] voxel_mm); this run "
                              "has none. Give mm or mm/s.")
        vel = ev.vectors * run.voxel_mm / dt
    elif vu.endswith("/s"):
        vel = ev.vectors * LENGTH_UNITS[vu[:-2]]
    else:
        vel = ev.vectors * LENGTH_UNITS[vu] / dt
    if window is None:
        raise ConfigError("score: give --window, the interrogation window's side in the field's length unit (e.g. "
                          "--window 1.6 for 1.6 mm windows): the truth is averaged over it.")
    win_mm = float(window) * LENGTH_UNITS[lu]
    if not win_mm > 0:
        raise ConfigError(f"score: --window must be > 0, got {window!r}.")
    lat = _lattice(P)
    if lat is None:
        raise FileFormatError(f"score: the {len(P)} vectors of {ev.source!r} do not lie on a rectilinear lattice; "
                              "mitpiv scores gridded PIV fields (score scattered points as particles).")
    axes, idx = lat
    steps = [float(np.median(np.diff(x))) if len(x) > 1 else win_mm for x in axes]
    vox = run.voxel_mm or float(min(steps))
    shape = (len(axes[2]), len(axes[1]), len(axes[0]))
    comp = np.zeros(shape + (3,))
    ok = np.zeros(shape, bool)
    comp[idx[:, 2], idx[:, 1], idx[:, 0]] = vel
    ok[idx[:, 2], idx[:, 1], idx[:, 0]] = ev.valid
    z = np.full(shape, np.nan)
    f = VectorField(axes[0], axes[1], axes[2], comp[..., 0], comp[..., 1], comp[..., 2], z, z, ok,
                    np.zeros(shape, bool), np.zeros(shape, bool), (vox,) * 3, (win_mm / vox,) * 3, dt_s=dt)
    f = uod(f)
    inside = np.all((P >= run.lower - win_mm) & (P <= run.upper + win_mm), axis=1)
    flags = []
    if inside.mean() < 0.5:
        flags.append(f"{100 * (1 - inside.mean()):.0f} % of the vectors lie outside the run's volume "
                     f"{run.lower.tolist()}..{run.upper.tolist()} mm: a different length unit or origin "
                     "(--length-unit)")
    res = velocity_error(f, flow, dt_s=dt, t0_s=float(run.times[a]))
    ref = res["reference"][idx[:, 2], idx[:, 1], idx[:, 0]]
    use = ev.valid & inside
    flags += _check_agreement(np.where(use[:, None], vel, np.nan), ref, noise=0.1 * vox / dt, unit="mm/s", vu=vu)
    e_vox = (res["error"][ok] * dt / vox)
    e_vox = e_vox[np.all(np.isfinite(e_vox), axis=1)]
    m = {"kind": "vectors-3d", "frames": [a, b], "dt_s": dt, "window_mm": win_mm, "voxel_mm": vox,
         "n_vectors": int(len(P)), "n_valid": int(ev.valid.sum()), **velocity_error_summary(res),
         "error_outlier_fraction": float(np.mean(np.linalg.norm(e_vox, axis=1) > ERROR_OUTLIER)) if len(e_vox) else
         float("nan"), "error_outlier_vox": ERROR_OUTLIER, "uod_outlier_ratio": f.outlier_ratio,
         "length_unit": lu, "velocity_unit": vu}
    m.pop("outlier_ratio", None)
    return _flagged(m, flags, force), {"field": f, "result": res}


def _flagged(m: dict, flags: list[str], force: bool) -> dict:
    m["flags"] = flags
    if flags and not force:
        raise ResultMismatch("score: the result does not describe the run's truth as read: " + "; ".join(flags)
                             + ". Fix the units or axes, or give --force to score it anyway (the flags are recorded).")
    return m


def _radius(run: _Run, radius_mm) -> float:
    from mitpiv.errors import check_positive

    if radius_mm is not None:
        return check_positive("--radius-mm", radius_mm, owner="score", unit="mm")
    ev = run.exp.get("evaluate") or {}
    if "radius_px" in ev and run.cameras:
        from mitpiv.tracking import mm_per_px

        return float(ev["radius_px"]) * mm_per_px(list(run.cameras.values()), 0.5 * (run.lower + run.upper))
    p = run.exp.get("particles") or {}
    if run.voxel_mm is not None:
        return float(p.get("radius_voxels", 2.0)) * run.voxel_mm
    raise ConfigError("score: the run has no match radius of its own; give --radius-mm.")


def _score_tracks(run: _Run, et, *, lu, first_frame, radius_mm, force) -> tuple[dict, dict]:
    from mitpiv.tracking import Tracks, particle_metrics, track_metrics
    from mitpiv.tracking.stb import regularise

    lu = lu or et.length_unit
    if lu is None:
        raise ConfigError(f"score: {et.source!r} does not state its length unit; give --length-unit (mm, m).")
    if lu in ("px", "vox"):
        raise ConfigError(f"score: particle positions must be in a world unit (mm, m), got {lu!r}.")
    pos_ext = et.positions * LENGTH_UNITS[lu]
    nrun = len(run.times)
    run_frames = np.asarray(et.frames, np.int64) + int(first_frame)
    if run_frames.min() < 0 or run_frames.max() >= nrun:
        raise ConfigError(f"score: the result's frames map to run frames {int(run_frames.min())}.."
                          f"{int(run_frames.max())}, the run has {nrun} (0..{nrun - 1}); give --first-frame.")
    r = _radius(run, radius_mm)
    cams = list(run.cameras.values()) or None
    truth = run.truth["positions_mm"][run_frames]  # (F, N, 3)
    found = pos_ext.reshape(-1, 3)
    found = found[np.all(np.isfinite(found), axis=1)]
    flags = []
    inside = np.all((found >= run.lower - 0.1 * (run.upper - run.lower))
                    & (found <= run.upper + 0.1 * (run.upper - run.lower)), axis=1)
    if inside.mean() < 0.5:
        flags.append(f"{100 * (1 - inside.mean()):.0f} % of the particles lie outside the run's volume "
                     f"{run.lower.tolist()}..{run.upper.tolist()} mm: a different length unit or origin (--length-unit)")
    else:  # found about as many particles as there are, and almost none matches: another frame or origin
        t0 = truth[0][np.all(np.isfinite(truth[0]), axis=1)]
        f0 = pos_ext[:, 0][np.all(np.isfinite(pos_ext[:, 0]), axis=1)]
        if len(t0) and len(f0) >= 0.3 * len(t0):
            pm = particle_metrics(f0, t0, radius_mm=r, lower_mm=run.lower, upper_mm=run.upper)
            if pm["n_found"] and pm["n_matched"] < 0.1 * min(pm["n_found"], pm["n_true"]):
                flags.append(f"only {pm['n_matched']} of the {pm['n_found']} particles of the result's first frame lie "
                             f"within {r:.4g} mm of a true one: another frame (--first-frame), origin or a match "
                             "radius too small (--radius-mm)")
    linked = et.linked and pos_ext.shape[1] >= 3
    dt = float(np.median(np.diff(run.times[run_frames]))) if len(run_frames) > 1 else 1.0
    if linked:
        tr = Tracks(pos_ext, np.where(np.isfinite(pos_ext[..., 0]), 1.0, np.nan), dt)
        tr = regularise(tr)
        vel = run.truth["velocities_mm_s"]
        acc = run.truth["accelerations_mm_s2"]
        tv = np.transpose(vel[run_frames], (1, 0, 2)) if vel is not None and vel.ndim == 3 else None
        ta = np.transpose(acc[run_frames], (1, 0, 2)) if acc is not None else None
        res = track_metrics(tr, np.transpose(truth, (1, 0, 2)), radius_mm=r, truth_velocities_mm_s=tv,
                            truth_accelerations_mm_s2=ta, cameras=cams, lower_mm=run.lower, upper_mm=run.upper)
        per_frame = res.pop("per_frame")
        res.pop("length_histogram")
        res["n_tracks"] = int(tr.n_tracks)
        res["mean_track_length"] = float(tr.lengths.mean()) if tr.n_tracks else float("nan")
        m = {"kind": "tracks", **res}
        errs = []
        for k in range(pos_ext.shape[1]):
            q = tr.positions_mm[:, k]
            q = q[np.all(np.isfinite(q), axis=1)]
            pm = particle_metrics(q, truth[k], radius_mm=r, lower_mm=run.lower, upper_mm=run.upper)
            errs.append(np.linalg.norm(q[pm["pairs"][:, 0]] - truth[k][pm["pairs"][:, 1]], axis=1))
    else:
        per_frame, errs = [], []
        tot = {"n_true": 0, "n_found": 0, "n_matched": 0}
        px = []
        for k in range(pos_ext.shape[1]):
            q = pos_ext[:, k]
            q = q[np.all(np.isfinite(q), axis=1)]
            pm = particle_metrics(q, truth[k], radius_mm=r, cameras=cams, lower_mm=run.lower, upper_mm=run.upper)
            for key in tot:
                tot[key] += pm[key]
            per_frame.append({key: pm[key] for key in ("n_true", "n_found", "n_matched", "yield", "ghost_fraction")})
            errs.append(np.linalg.norm(q[pm["pairs"][:, 0]] - truth[k][pm["pairs"][:, 1]], axis=1))
            if cams is not None and pm["n_matched"]:
                px.append(pm["position_error_px"] * pm["n_matched"])
        e = np.concatenate(errs) if errs else np.zeros(0)
        m = {"kind": "particles", **tot,
             "yield": tot["n_matched"] / tot["n_true"] if tot["n_true"] else float("nan"),
             "ghost_fraction": (tot["n_found"] - tot["n_matched"]) / tot["n_found"] if tot["n_found"] else float("nan"),
             "position_error_mm": float(e.mean()) if e.size else float("nan")}
        if cams is not None:
            m["position_error_px"] = float(sum(px) / tot["n_matched"]) if tot["n_matched"] else float("nan")
    m.update(match_radius_mm=r, frames=run_frames.tolist(), length_unit=lu, linked=bool(linked))
    return _flagged(m, flags, force), {"per_frame": per_frame, "errors_mm": errs}


# ------------------------------------------------------------------------------------ outputs


def _fmt(x, spec=".4g") -> str:
    if x is None or (isinstance(x, float) and not np.isfinite(x)):
        return "n/a"
    if isinstance(x, list | tuple):
        return ", ".join(_fmt(v, spec) for v in x)
    return format(x, spec) if isinstance(x, float) else str(x)


def _markdown(m: dict, source: str, run: Path) -> str:
    lines = [f"# Score of `{source}` against the truth of `{run}`", "",
             f"Scored by `mitpiv score` ({m['kind']}); every number is in score.json.", ""]
    if m.get("flags"):
        lines += ["**Flagged** (scored with --force):", ""] + [f"- {f}" for f in m["flags"]] + [""]
    lines += ["| quantity | value |", "|---|---|"]
    order = {"vectors-2d": [("vectors scored / valid / all", lambda: f"{m['n_scored']} / {m['n_valid']} / "
                                                                       f"{m['n_vectors']}"),
                            ("reference", lambda: f"{m['reference']} (window-averaged; on {m['plane']})"),
                            ("true particles per window (mean)", lambda: _fmt(m["particles_per_window"], ".3g")),
                            ("RMS particles - flow reference [px]", lambda: _fmt(m["reference_spread_px"])),
                            ("RMS error x, y [px]", lambda: _fmt(m["rms_px"])),
                            ("bias x, y [px]", lambda: _fmt(m["bias_px"])),
                            ("RMS error magnitude [px]", lambda: _fmt(m["rms_magnitude_px"])),
                            (f"errors > {ERROR_OUTLIER:g} px", lambda: _fmt(m["error_outlier_fraction"], ".2%")),
                            ("UOD outlier ratio", lambda: _fmt(m["uod_outlier_ratio"], ".2%"))],
             "vectors-3d": [("vectors scored / all", lambda: f"{m['n']} / {m['n_vectors']}"),
                            ("RMS error x, y, z [mm/s]", lambda: _fmt(m["rms"])),
                            ("RMS error x, y, z [voxel]", lambda: _fmt(m["rms_vox"])),
                            ("bias x, y, z [voxel]", lambda: _fmt(m["bias_vox"])),
                            ("RMS error magnitude [mm/s]", lambda: _fmt(m["rms_magnitude"])),
                            (f"errors > {ERROR_OUTLIER:g} voxel", lambda: _fmt(m["error_outlier_fraction"], ".2%")),
                            ("UOD outlier ratio", lambda: _fmt(m["uod_outlier_ratio"], ".2%"))]}
    pt = [("true / found / matched", lambda: f"{m['n_true']} / {m['n_found']} / {m['n_matched']}"),
          ("yield", lambda: _fmt(m["yield"], ".2%")), ("ghost fraction", lambda: _fmt(m["ghost_fraction"], ".2%")),
          ("position error [mm]", lambda: _fmt(m["position_error_mm"])),
          ("position error [px]", lambda: _fmt(m.get("position_error_px"))),
          ("match radius [mm]", lambda: _fmt(m["match_radius_mm"]))]
    if m["kind"] == "tracks":
        pt += [("tracks / mean length [frames]", lambda: f"{m['n_tracks']} / {_fmt(m['mean_track_length'], '.3g')}"),
               ("velocity error [mm/s] / relative", lambda: f"{_fmt(m.get('velocity_error_mm_s'))} / "
                                                           f"{_fmt(m.get('velocity_error_rel'), '.2%')}"),
               ("correct tracks", lambda: _fmt(m.get("correct_track_fraction"), ".2%"))]
    for name, val in order.get(m["kind"], pt):
        lines.append(f"| {name} | {val()} |")
    return "\n".join(lines) + "\n"


def _plot_2d(arr: dict, m: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mitpiv.io.figures import save_figure

    p, e, use = arr["points_px"], arr["error_px"], arr["scored"]
    mag = np.linalg.norm(e, axis=1)
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.5))
    W, H = arr["resolution"]
    sc = ax[0].scatter(p[use, 0], p[use, 1], c=mag[use], s=12, cmap="viridis", marker="s")
    q = np.flatnonzero(use)[:: max(1, int(np.sqrt(use.sum() / 150)))]  # about 150 arrows
    ax[0].quiver(p[q, 0], p[q, 1], arr["measured_px"][q, 0], arr["measured_px"][q, 1], color="k",
                 angles="xy", scale_units="xy", scale=0.25, width=0.003)
    ax[0].set(xlim=(0, W), ylim=(H, 0), xlabel="x [px]", ylabel="y [px]", aspect="equal",
              title=f"|error| on {m['camera']}; arrows: measured x4")
    fig.colorbar(sc, ax=ax[0], label=f"|measured - window-averaged {m['reference']} truth| [px]")
    for k, name in enumerate("xy"):
        ax[1].hist(e[use, k], bins=60, histtype="step", label=f"{name}: RMS {_fmt(m['rms_px'][k], '.3g')} px")
    ax[1].set(xlabel="error [px]", ylabel="vectors", title="error distribution")
    ax[1].legend()
    save_figure(fig, path)
    plt.close(fig)


def _plot_particles(aux: dict, m: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mitpiv.io.figures import save_figure

    pf = aux["per_frame"]
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    fr = m["frames"]
    ax[0].plot(fr, [f["yield"] for f in pf], "o-", label="yield")
    ax[0].plot(fr, [f["ghost_fraction"] for f in pf], "s-", label="ghost fraction")
    ax[0].set(xlabel="run frame", ylabel="fraction", ylim=(0, 1.05), title="per frame")
    ax[0].legend()
    e = np.concatenate(aux["errors_mm"]) if aux["errors_mm"] else np.zeros(0)
    ax[1].hist(e * 1e3, bins=50, histtype="step")
    ax[1].set(xlabel="position error of matched particles [um]", ylabel="particles",
              title=f"mean {_fmt(e.mean() * 1e3 if e.size else None, '.3g')} um (match radius "
                    f"{m['match_radius_mm'] * 1e3:.3g} um)")
    save_figure(fig, path)
    plt.close(fig)


def _what(path: Path, fmt: str | None) -> str:
    from mitpiv.io.external import TRACK_FORMATS, VECTOR_FORMATS, track_format, vector_format

    if fmt in ("openpiv", "npz", "hdf5") or (fmt is None and path.suffix.lower() in (".txt", ".vec", ".npz", ".h5",
                                                                                      ".hdf5", ".vc7")):
        return "vectors"
    if fmt in ("openlpt", "openptv"):
        return "tracks"
    if path.suffix.lower() == ".csv" and path.is_file():
        import pandas as pd

        cols = {str(c).strip().lower() for c in pd.read_csv(path, nrows=0, comment="#").columns}
        if {"u", "v"} <= cols:
            return "vectors"
        return "tracks"
    if fmt is None:
        try:
            fmt = track_format(path)
        except ConfigError:
            vector_format(path)
            return "vectors"
        if fmt != "davis":
            return "tracks"
    if fmt == "davis":  # a .set or set folder: lvpyio says whether it is a particle field
        from mitpiv.io.davis import _read_set

        try:
            _read_set(path, "score")
        except FileFormatError as e:
            if "particle field" in str(e):
                return "tracks"
            raise
        return "vectors"
    if fmt not in VECTOR_FORMATS + TRACK_FORMATS:
        raise ConfigError(f"score: --format {fmt!r} is not one of {sorted(set(VECTOR_FORMATS + TRACK_FORMATS))}.")
    raise ConfigError(f"score: cannot tell whether {str(path)!r} holds vectors or particles; give --what vectors or "
                      "--what particles.")


def score(run_dir, result, *, out_dir=None, what: str | None = None, fmt: str | None = None,
          camera: str | None = None, frames=(0, 1), window: float | None = None, length_unit: str | None = None,
          velocity_unit: str | None = None, flip_y: bool = False, plane_z_mm: float | None = None,
          radius_mm: float | None = None, first_frame: int = 0, group: str | None = None, davis_frame: int = 0,
          reference: str | None = None, force: bool = False) -> dict:
    """Score another tool's result against a run's truth (see the module notes).

    Parameters
    ----------
    run_dir : a run folder of ``mitpiv run`` (its truth; the images' cameras).
    result : the tool's result file or folder (:mod:`mitpiv.io.external`).
    out_dir : where ``score.json``, ``score.md`` and the figure go (default
        ``<result>_score`` beside the result).
    what : ``"vectors"`` or ``"particles"`` (default: from the format).
    fmt : the result's format (default: from its name).
    camera : the camera a 2-D field was measured on (default the run's first).
    frames : the run frames the field's two images are (default 0 1).
    window : the interrogation window's side, in the field's length unit (vector fields).
    length_unit, velocity_unit : the field's units where the file does not state them
        (:data:`LENGTH_UNITS`, :data:`VELOCITY_UNITS`); given, they override the file's.
    flip_y : the field's y axis points up (OpenPIV's ``transform_coordinates``): mirror y about
        the field's middle row and negate v.
    plane_z_mm : the world plane z a 2-D field lies on (default the run's laser sheet's
        mid-plane, else the volume's middle).
    radius_mm : the particle match radius (default the run's own).
    first_frame : the run frame of the result's first frame (particles and tracks).
    group : the HDF5 group of the datasets; davis_frame : the frame of a DaVis vector set.
    reference : a 2-D field's reference, ``"flow"`` (default when the run records an analytic
        flow) or ``"particles"`` (module notes).
    force : score a result that is flagged as not describing the truth (the flags are kept).

    Returns
    -------
    dict: the metrics (``kind``, the errors, ``flags``), as written to ``score.json``, with
    ``files`` (the files written).

    Raises
    ------
    ResultMismatch
        The result is flagged (units, axes, frames) and ``force`` is False; nothing is written.
    ConfigError, FileFormatError
        A setting or file that cannot be scored (the message names it and the fix).
    """
    from mitpiv.io import write_json, write_text
    from mitpiv.io.external import read_tracks, read_vectors

    res_path = Path(result)
    if not res_path.exists():
        raise FileFormatError(f"score: {str(res_path)!r} does not exist; give the result file of your tool.")
    run = _load_run(run_dir)
    what = what or _what(res_path, fmt)
    if what not in ("vectors", "particles", "tracks"):
        raise ConfigError(f"score: --what {what!r} is not 'vectors' or 'particles'.")
    lu = _unit(length_unit, "--length-unit", LENGTH_UNITS)
    vu = _unit(velocity_unit, "--velocity-unit", VELOCITY_UNITS)
    if what == "vectors":
        ev = read_vectors(res_path, fmt=fmt, group=group, frame=davis_frame)
        if flip_y:
            ev.points[:, 1] = np.nanmin(ev.points[:, 1]) + np.nanmax(ev.points[:, 1]) - ev.points[:, 1]
            ev.vectors[:, 1] *= -1.0
        flu = _unit(ev.length_unit, f"the length unit of {str(res_path)!r}", LENGTH_UNITS) if lu is None else lu
        fvu = _unit(ev.velocity_unit, f"the vector unit of {str(res_path)!r}", VELOCITY_UNITS) if vu is None else vu
        if ev.fmt == "openpiv":
            flu, fvu = flu or "px", fvu or ("px" if (flu or "px") == "px" else None)
        if ev.dims == 2 and ev.components == 2:
            m, arr = _score_2d(run, ev, camera=camera, frames=frames, window=window, lu=flu, vu=fvu,
                               plane_z_mm=plane_z_mm, reference=reference, force=force)
        elif ev.dims == 3 and ev.components == 3:
            m, arr = _score_3d(run, ev, frames=frames, window=window, lu=flu, vu=fvu, force=force)
        else:
            raise FileFormatError(f"score: {str(res_path)!r} holds {ev.components} components at {ev.dims}-D "
                                  "positions; mitpiv scores 2-D 2-C (planar) and 3-D 3-C (volumetric) fields.")
    else:
        et = read_tracks(res_path, fmt=fmt)
        m, arr = _score_tracks(run, et, lu=lu, first_frame=first_frame, radius_mm=radius_mm, force=force)
    m.update(source=str(res_path), format=fmt or (ev.fmt if what == "vectors" else et.fmt), run=str(run.path),
             flip_y=bool(flip_y))
    from mitpiv.studies.shared import null_metrics

    m = null_metrics(m, {"uod_outlier_ratio": "the vectors are not on a lattice (no neighbours to test)",
                         "": "nothing to compute it from (no vector or particle scored, or no truth for it)"},
                     where="score")
    out = Path(out_dir) if out_dir is not None else res_path.parent / f"{res_path.stem}_score"
    files = [write_json(out / "score.json", m, default=float), write_text(out / "score.md", _markdown(m, str(res_path),
                                                                                                      run.path))]
    if m["kind"] == "vectors-2d":
        _plot_2d(arr, m, out / "velocity_error.png")
        files.append(out / "velocity_error.png")
    elif m["kind"] == "vectors-3d":
        from mitpiv.analysis import plot_velocity_error

        plot_velocity_error(arr["field"], arr["result"], out / "velocity_error.png")
        files.append(out / "velocity_error.png")
    else:
        _plot_particles(arr, m, out / "particles.png")
        files.append(out / "particles.png")
    m["files"] = [str(f) for f in files]
    return m
