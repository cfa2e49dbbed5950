"""Settings of other particle trackers (OpenLPT, OpenPTV) derived from a finished run, so
that a peer tool starts from what a user of that experiment would know (issue 52, item 4):
the particle image size, the motion per frame, the calibration error and the seeding
density. :func:`run_quantities` reads them from a run folder of any kind, each with its
source; :func:`openlpt_settings_for_run` and :func:`openptv_settings_for_run` map them to the
tools' settings. :func:`mitpiv.studies.export.export_tracker_inputs` uses them by default
and writes the record into ``mitpiv_export.json`` (``derived_settings``); the tracking
kind's OpenLPT comparison (:func:`mitpiv.studies.kinds.tracking.compare.openlpt_settings`)
uses the same derivation, with the experiment's own ``[tracking]`` velocity guess.

The quantities (:class:`RunQuantities`)
---------------------------------------
``voxel_mm``
    one pixel in object space at the measurement box's centre (``mm_per_px`` of the
    rendered cameras: the inverse RMS singular value of their Jacobians). OpenLPT's voxel,
    as its sample (0.04 mm voxels at 0.041 mm/px).
``particle_hwhm_px`` / ``particle_radius_px``
    the half width at half maximum of the particle image: from the run's OTF calibration
    (``otf/otf.json`` of a tracking run: the widest image over cameras and sub-volumes,
    along its weaker principal axis), else measured on the first frame's images (the median
    over the isolated peaks of every camera of the larger of the two 3-point Gaussian widths,
    ``sigma^2 = 1 / (2 ln I0 - ln I- - ln I+)``, along rows and columns). OpenLPT's particle
    radius is that half width rounded up to a half pixel and at least
    :data:`MIN_PARTICLE_RADIUS_PX` (the module notes of
    :mod:`mitpiv.studies.kinds.tracking.compare` say why); :data:`DEFAULT_PARTICLE_RADIUS_PX`
    (OpenLPT's sample) when neither source has a particle.
``motion_mm``, ``motion_axis_mm``, ``acceleration_mm``
    the :data:`MOTION_PERCENTILE` th percentile over the true particles (the run's truth:
    ``particles/truth.npz`` of a tomo run, ``field/truth.npz`` of a tracking run) of the
    displacement between consecutive frames (magnitude, and per axis of the absolute
    component), and of the second difference ``|x(t+1) - 2 x(t) + x(t-1)|``: a design
    property of the experiment's flow and frame rate (the velocity and its range a user
    sets the frame rate for), not something measured from the images.
``calibration_error_px``
    the reprojection error of the cameras given to the tool: 0 for the rendered cameras
    that :func:`~mitpiv.studies.export.export_tracker_inputs` writes (exact); for a tracking
    run's calibrated cameras (``calibrated=True``, the cameras of its OpenLPT comparison)
    the largest fit RMS of the calibrate stage (``calibrate/cameras.json`` ``fit``; 0 when
    the experiment uses the true cameras, ``[calibration] model = "true"``).
``spacing_mm``
    the mean interparticle spacing ``(V / N)^(1/3)`` of the ``N`` true particles inside the
    measurement box (volume ``V``) at frame 0: the seeding density.
``tolerance_px``, ``search_px``, ``ghost_threshold``
    the run's own ``[tracking]`` triangulation tolerance, search radius and ghost threshold
    (``min_intensity``) when it has that table (a tracking run), else the tracking kind's
    defaults (:data:`DEFAULT_TOLERANCE_PX`, :data:`DEFAULT_SEARCH_PX`,
    :data:`DEFAULT_GHOST_THRESHOLD`).

OpenLPT (:func:`openlpt_settings_from`; every length in voxels of ``voxel_mm``)
-------------------------------------------------------------------------------
* initial-phase search radius: ``motion_mm / voxel_mm + search_px`` (the displacement per
  frame plus the deviation from it the experiment allows); the tracking kind's comparison
  uses its ``[tracking] velocity_guess_mm_s`` times the frame interval for the motion.
* predictive-field search radius: 1.5 times that (OpenLPT's ``PFParam``: "make sure
  displacement < 0.5 * r").
* 2-D tolerance: ``tolerance_px + 3 calibration_error_px``; 3-D tolerance half of it
  (a voxel is a pixel at the box centre).
* particle radius: ``particle_radius_px``; neighbour spacing ``spacing_mm / voxel_mm``;
  ghost threshold ``ghost_threshold``; the others OpenLPT's sample's
  (:class:`~mitpiv.io.openlpt.OpenLPTSettings`).

OpenPTV (:func:`openptv_settings_from`)
---------------------------------------
* ``eps0_mm`` (criteria.par, the epipolar band's half width on the sensor): the 2-D
  tolerance above times the pixel pitch.
* ``track.par`` ``dvxmin..dvzmax``: ``-/+ (motion_axis_mm + search_px voxel_mm)`` per axis
  (liboptv's ``searchquader`` searches that box around the predicted position, which is the
  current one for a particle without a history, and ``pos3d_in_bounds`` bounds each link's
  displacement by it).
* ``dacc`` (the largest distance of a candidate from the predicted position [mm],
  ``angle_acc``): ``acceleration_mm + sqrt(6) tolerance_3d`` (the prediction ``2 x1 - x0``
  and the candidate each carry a position error up to the 3-D tolerance,
  ``tolerance_2d_px voxel_mm / 2``; ``sqrt(4 + 1 + 1)``); ``dangle`` stays 100 gon.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from mitpiv.errors import FileFormatError
from mitpiv.studies.shared import read_run_record, truth_file

__all__ = ["RunQuantities", "run_quantities", "otf_hwhm_px", "image_hwhm_px", "radius_from_hwhm",
           "openlpt_settings_from", "openlpt_settings_for_run", "openptv_settings_from", "openptv_settings_for_run",
           "MOTION_PERCENTILE", "MIN_PARTICLE_RADIUS_PX", "DEFAULT_PARTICLE_RADIUS_PX", "DEFAULT_TOLERANCE_PX",
           "DEFAULT_SEARCH_PX", "DEFAULT_GHOST_THRESHOLD", "CALIBRATION_FACTOR", "PREDICT_FACTOR"]

#: Percentile over the true particles of the displacement per frame (and its axis components
#: and second difference) taken as "the motion per frame".
MOTION_PERCENTILE = 99.0
#: The smallest OpenLPT particle radius [px] whose subtraction window (``round(2 r)`` px) is
#: centred on the particle: 3 x 3 px.
MIN_PARTICLE_RADIUS_PX = 1.5
#: OpenLPT's sample radius [px], used when the run has no particle image to measure.
DEFAULT_PARTICLE_RADIUS_PX = 2.0
#: The tracking kind's default ``[tracking] tolerance_px`` (for runs without that table).
DEFAULT_TOLERANCE_PX = 1.0
#: Search margin [px] around the motion per frame for runs without a ``[tracking]`` table
#: (``scenes/tracking_lpt/experiment.toml``'s ``search_px``).
DEFAULT_SEARCH_PX = 4.0
#: The tracking kind's default ``[tracking] min_intensity`` (OpenLPT's sample ghost threshold).
DEFAULT_GHOST_THRESHOLD = 0.1
#: Calibration RMS errors [px] added to the 2-D tolerance (a radial error of 3 RMS holds
#: 99 % of Gaussian reprojection errors).
CALIBRATION_FACTOR = 3.0
#: OpenLPT's predictive-field search radius over the initial-phase one.
PREDICT_FACTOR = 1.5


@dataclass(frozen=True)
class RunQuantities:
    """What a peer tracker's settings are derived from (module notes); lengths in mm or px
    as named, ``sources`` says where each came from."""

    voxel_mm: float
    particle_hwhm_px: float | None
    particle_radius_px: float
    motion_mm: float
    motion_axis_mm: tuple[float, float, float]
    acceleration_mm: float | None
    calibration_error_px: float
    spacing_mm: float
    n_particles: int
    frame_interval_s: float | None
    pixel_pitch_mm: float | None
    tolerance_px: float
    search_px: float
    ghost_threshold: float
    lower_mm: tuple[float, float, float]
    upper_mm: tuple[float, float, float]
    sources: dict = field(default_factory=dict)

    @property
    def motion_vox(self) -> float:
        return self.motion_mm / self.voxel_mm

    def to_dict(self) -> dict:
        d = asdict(self)
        d["motion_vox"] = self.motion_vox
        d["motion_percentile"] = MOTION_PERCENTILE
        return d


# ------------------------------------------------------------------------------ particle image
def otf_hwhm_px(otf: dict) -> float | None:
    """The half width at half maximum [px] of the widest particle image of an OTF
    calibration (``otf.json``: ``exp(-(a du^2 + 2 b du dv + c dv^2) / 2)`` per camera and
    sub-volume; along the weaker principal axis, ``sqrt(2 ln 2 / l_min)`` with ``l_min`` the
    smaller eigenvalue of ``[[a, b], [b, c]]``); None without a valid entry."""
    a, b, c = (np.asarray(otf[k], dtype=np.float64) for k in ("a_per_px2", "b_per_px2", "c_per_px2"))
    lam = 0.5 * (a + c) - np.sqrt((0.5 * (a - c)) ** 2 + b**2)
    lam = lam[np.isfinite(lam) & (lam > 0)]
    if lam.size == 0:
        return None
    return float(np.sqrt(2.0 * np.log(2.0) / lam.min()))


def image_hwhm_px(images, *, rel_threshold: float = 0.2, isolation_px: int = 4) -> tuple[float | None, int]:
    """The particle image's half width at half maximum [px] measured on images: every local
    maximum above ``rel_threshold`` of its image's brightest pixel (after subtracting the
    median background), at least 2 px from the border and with no other local maximum above
    a twentieth of that brightest pixel within ``isolation_px``, gives the 3-point Gaussian
    widths along rows and columns (``sigma^2 = 1 / (2 ln I0 - ln I- - ln I+)``); the result
    is ``sqrt(2 ln 2)`` times the median over the peaks of the larger of the two.

    Returns (hwhm or None when no isolated peak was found, the number of peaks used).
    """
    from scipy.ndimage import maximum_filter

    widths = []
    for img in images:
        a = np.asarray(img, dtype=np.float64)
        a = a - np.median(a)
        top = float(a.max()) if a.size else 0.0
        if not top > 0:
            continue
        local = (a == maximum_filter(a, size=3)) & (a > 0.05 * top)
        ys, xs = np.nonzero(local)
        if ys.size == 0:
            continue
        h, w = a.shape
        pts = np.stack([ys, xs], axis=1)
        for y, x in pts:
            if a[y, x] < rel_threshold * top or not (2 <= y < h - 2 and 2 <= x < w - 2):
                continue
            d = np.max(np.abs(pts - (y, x)), axis=1)
            if np.count_nonzero(d <= isolation_px) > 1:
                continue
            i0, s = a[y, x], []
            for lo, hi in ((a[y, x - 1], a[y, x + 1]), (a[y - 1, x], a[y + 1, x])):
                if lo <= 0 or hi <= 0:
                    break
                den = 2.0 * np.log(i0) - np.log(lo) - np.log(hi)
                if not den > 0:
                    break
                s.append(1.0 / np.sqrt(den))
            if len(s) == 2:
                widths.append(max(s))
    if not widths:
        return None, 0
    return float(np.sqrt(2.0 * np.log(2.0)) * np.median(widths)), len(widths)


def radius_from_hwhm(hwhm_px: float | None, *, default: float = DEFAULT_PARTICLE_RADIUS_PX) -> float:
    """OpenLPT's particle radius [px] for a particle image half width: rounded up to a half
    pixel, at least :data:`MIN_PARTICLE_RADIUS_PX`; ``default`` when ``hwhm_px`` is None."""
    if hwhm_px is None or not np.isfinite(hwhm_px):
        return default
    return max(MIN_PARTICLE_RADIUS_PX, float(np.ceil(2.0 * hwhm_px - 1e-9)) / 2.0)


# ------------------------------------------------------------------------------ the run's record
def _read(run: Path) -> dict:
    return read_run_record(run, owner="peer settings")


def _box(exp: dict, run: Path):
    b = (exp.get("tracking") or {}).get("bounds_mm")
    if b is not None:
        return np.array([b[0], b[2], b[4]], float), np.array([b[1], b[3], b[5]], float), "[tracking] bounds_mm"
    s = exp.get("seeding") or {}
    if "box_min_mm" not in s or "box_max_mm" not in s:
        raise FileFormatError(f"peer settings: {str(run / 'experiment.json')!r} has no [seeding] box_min_mm / "
                              "box_max_mm (the measurement box).")
    return np.asarray(s["box_min_mm"], float), np.asarray(s["box_max_mm"], float), "[seeding] box"


def _truth(run: Path):
    from mitpiv.io import read_truth

    f = truth_file(run)
    if f is not None:
        return read_truth(f), f"{f.parent.name}/truth.npz"
    raise FileFormatError(f"peer settings: the run {str(run)!r} has no truth (particles/truth.npz or "
                          "field/truth.npz): the motion per frame and the seeding density come from it; finish the "
                          "run first.")


def _motion(pos: np.ndarray) -> tuple[float, np.ndarray, float | None]:
    """Percentiles of the displacement per frame (magnitude, |axis components|) and of the
    second difference over consecutive frames of the particles present in them."""
    if pos.shape[0] < 2:
        return 0.0, np.zeros(3), None
    d = np.diff(pos, axis=0).reshape(-1, 3)
    d = d[np.all(np.isfinite(d), axis=1)]
    if d.size == 0:
        return 0.0, np.zeros(3), None
    mag = float(np.percentile(np.linalg.norm(d, axis=1), MOTION_PERCENTILE))
    axis = np.percentile(np.abs(d), MOTION_PERCENTILE, axis=0)
    acc = None
    if pos.shape[0] >= 3:
        a = (pos[2:] - 2.0 * pos[1:-1] + pos[:-2]).reshape(-1, 3)
        a = a[np.all(np.isfinite(a), axis=1)]
        if a.size:
            acc = float(np.percentile(np.linalg.norm(a, axis=1), MOTION_PERCENTILE))
    return mag, axis, acc


def run_quantities(run_dir, *, lower_mm=None, upper_mm=None, calibrated: bool = False,
                   cameras=None) -> RunQuantities:
    """The quantities a peer tracker's settings are derived from, read from a finished run
    folder of any kind (module notes).

    Parameters
    ----------
    run_dir : str or Path
        The run folder (``experiment.json``, a truth file, rendered images or an OTF
        calibration).
    lower_mm, upper_mm : (3,) float, optional
        The measurement box [mm]; default ``[tracking] bounds_mm`` or the seeding box.
    calibrated : bool
        The tool gets the run's calibrated cameras (``calibrate/cameras.json``), not the
        rendered ones: their fit error is the calibration error.
    cameras : sequence, optional
        The rendered cameras (default: ``calibrate/cameras.json``'s ``true`` cameras, else
        the first frame's image metadata).

    Raises
    ------
    FileFormatError
        Not a run folder, or one without a truth file or measurement box.
    """
    from mitpiv.io import camera_from_metadata, read_exr, read_json
    from mitpiv.tracking import mm_per_px

    run = Path(run_dir)
    exp = _read(run)
    src: dict[str, str] = {}
    lo, hi, src["box"] = _box(exp, run)
    if lower_mm is not None and upper_mm is not None:
        lo, hi, src["box"] = np.asarray(lower_mm, float), np.asarray(upper_mm, float), "given"
    cam_file = run / "calibrate" / "cameras.json"
    cal = read_json(cam_file) if cam_file.is_file() else None
    first_images = None
    if cameras is None:
        if cal is not None and cal.get("true"):
            cameras = [camera_from_metadata(c) for c in cal["true"]]
            src["cameras"] = "calibrate/cameras.json (the rendered cameras)"
        else:
            from mitpiv.studies.shared import run_images

            imgs = run_images(run)
            cameras = imgs["cameras"]
            first_images = [read_exr(f[0])[0] for f in imgs["files"]]
            src["cameras"] = f"the {imgs['source']} stage's image metadata"
    else:
        src["cameras"] = "given"
    cameras = list(cameras)
    centre = 0.5 * (lo + hi)
    vox = float(mm_per_px(cameras, centre))
    src["voxel_mm"] = "one pixel in object space at the box centre (mm_per_px of the rendered cameras)"
    pitch = getattr(cameras[0], "pixel_pitch_um", None)
    pitch_mm = None if pitch is None else float(pitch) * 1e-3

    # the particle image
    hwhm = None
    otf_file = run / "otf" / "otf.json"
    if otf_file.is_file():
        hwhm = otf_hwhm_px(read_json(otf_file))
        src["particle_hwhm_px"] = "otf/otf.json (the run's OTF calibration: widest image, weaker axis)"
    if hwhm is None:
        if first_images is None:
            from mitpiv.studies.shared import run_images

            imgs = run_images(run)
            first_images = [read_exr(f[0])[0] for f in imgs["files"]]
        hwhm, n_peaks = image_hwhm_px(first_images)
        src["particle_hwhm_px"] = (f"measured on frame 0's images ({n_peaks} isolated peaks, median 3-point "
                                   "Gaussian width)" if hwhm is not None else
                                   f"no isolated particle image in frame 0: OpenLPT's sample radius "
                                   f"{DEFAULT_PARTICLE_RADIUS_PX:g} px")
    radius = radius_from_hwhm(hwhm)
    src["particle_radius_px"] = (f"the half width at half maximum rounded up to a half pixel, at least "
                                 f"{MIN_PARTICLE_RADIUS_PX:g} px")

    # the flow: motion per frame and seeding density from the truth
    truth, tname = _truth(run)
    pos = np.asarray(truth["positions_mm"], dtype=np.float64)
    motion, axis, acc = _motion(pos)
    src["motion_mm"] = (f"{MOTION_PERCENTILE:g}th percentile of the true particles' displacement between "
                        f"consecutive frames ({tname}: the experiment's flow and frame interval)")
    src["acceleration_mm"] = (f"{MOTION_PERCENTILE:g}th percentile of |x(t+1) - 2 x(t) + x(t-1)| of the true "
                              f"particles ({tname})" if acc is not None else
                              "none: fewer than 3 frames (taken as 0 where a setting needs it)")
    times = np.asarray(truth["times_s"], dtype=np.float64)
    dt = float(times[1] - times[0]) if times.size > 1 and times[1] > times[0] else None
    p0 = pos[0]
    inside = np.all(np.isfinite(p0), axis=1) & np.all((p0 >= lo) & (p0 <= hi), axis=1)
    n = int(inside.sum())
    spacing = float(np.prod(hi - lo) / max(n, 1)) ** (1.0 / 3.0)
    src["spacing_mm"] = f"(box volume / {n} true particles in it at frame 0)^(1/3) ({tname})"

    # the cameras' calibration error
    if calibrated:
        fits = [f.get("rms_px") for f in (cal or {}).get("fit") or [] if isinstance(f, dict)]
        fits = [float(e) for e in fits if e is not None]
        err = max(fits) if fits else 0.0
        src["calibration_error_px"] = ("the calibrate stage's largest fit RMS (calibrate/cameras.json)" if fits else
                                       "0: the calibrated cameras are the rendered ones ([calibration] model = "
                                       "'true')")
    else:
        err = 0.0
        src["calibration_error_px"] = "0: the rendered cameras (image metadata), exact"
        fits = [f.get("rms_px") for f in (cal or {}).get("fit") or [] if isinstance(f, dict)]
        if any(e is not None for e in fits):
            src["calibration_error_px"] += (f"; the run's calibrate stage fitted cameras with RMS up to "
                                            f"{max(e for e in fits if e is not None):.3g} px, not the exported ones")

    t = exp.get("tracking") or {}
    tol = float(t.get("tolerance_px", DEFAULT_TOLERANCE_PX))
    search = float(t.get("search_px", DEFAULT_SEARCH_PX))
    ghost = float(t.get("min_intensity", DEFAULT_GHOST_THRESHOLD))
    which = "the run's [tracking] table" if t else "the tracking kind's defaults (the run has no [tracking] table)"
    for k in ("tolerance_px", "search_px", "ghost_threshold"):
        src[k] = which
    return RunQuantities(voxel_mm=vox, particle_hwhm_px=hwhm, particle_radius_px=radius, motion_mm=motion,
                         motion_axis_mm=tuple(float(v) for v in axis), acceleration_mm=acc,
                         calibration_error_px=float(err), spacing_mm=spacing, n_particles=n, frame_interval_s=dt,
                         pixel_pitch_mm=pitch_mm, tolerance_px=tol, search_px=search, ghost_threshold=ghost,
                         lower_mm=tuple(map(float, lo)), upper_mm=tuple(map(float, hi)), sources=src)


# ------------------------------------------------------------------------------ the tools' settings
def _tolerance_2d_px(q: RunQuantities) -> float:
    return q.tolerance_px + CALIBRATION_FACTOR * q.calibration_error_px


def openlpt_settings_from(q: RunQuantities, *, motion_mm: float | None = None, particle_radius_px: float | None = None,
                          **overrides):
    """The :class:`~mitpiv.io.openlpt.OpenLPTSettings` for the quantities ``q`` (module
    notes); ``motion_mm`` replaces ``q.motion_mm`` (the tracking kind's velocity guess),
    ``particle_radius_px`` ``q.particle_radius_px``, and ``overrides`` set any field."""
    from mitpiv.io.openlpt import OpenLPTSettings

    vox = q.voxel_mm
    cover = (q.motion_mm if motion_mm is None else float(motion_mm)) / vox + q.search_px
    tol = _tolerance_2d_px(q)
    s = OpenLPTSettings(search_radius_vox=round(cover, 3), pred_search_vox=round(PREDICT_FACTOR * cover, 3),
                        tolerance_2d_px=tol, tolerance_3d_vox=0.5 * tol,
                        neighbour_spacing_vox=round(q.spacing_mm / vox, 3), ghost_threshold=q.ghost_threshold,
                        particle_radius_px=q.particle_radius_px if particle_radius_px is None else particle_radius_px)
    return replace(s, **overrides) if overrides else s


def openlpt_settings_for_run(run_dir, *, voxel_mm: float | None = None, **kw):
    """(:class:`~mitpiv.io.openlpt.OpenLPTSettings`, voxel [mm], record) for a run: the
    settings of :func:`openlpt_settings_from` and the record of :func:`run_quantities`
    (``kw``: its options) with the rules that made them. ``voxel_mm``: a voxel chosen by
    the caller (the lengths in voxels follow it) instead of one pixel at the box centre."""
    q = run_quantities(run_dir, **kw)
    if voxel_mm is not None:
        from mitpiv.errors import check_positive

        q = replace(q, voxel_mm=check_positive("voxel_mm", voxel_mm, owner="openlpt_settings_for_run", unit="mm"),
                    sources={**q.sources, "voxel_mm": "given"})
    s = openlpt_settings_from(q)
    rec = {**q.to_dict(), "rules": {
        "voxel_mm": "voxel_mm",
        "search_radius_vox": "motion_mm / voxel_mm + search_px",
        "pred_search_vox": f"{PREDICT_FACTOR:g} x search_radius_vox",
        "tolerance_2d_px": f"tolerance_px + {CALIBRATION_FACTOR:g} x calibration_error_px",
        "tolerance_3d_vox": "tolerance_2d_px / 2",
        "particle_radius_px": "particle_radius_px",
        "neighbour_spacing_vox": "spacing_mm / voxel_mm",
        "ghost_threshold": "ghost_threshold"}}
    return s, q.voxel_mm, rec


def openptv_settings_from(q: RunQuantities, **overrides):
    """The :class:`~mitpiv.io.openptv.OpenPTVSettings` for the quantities ``q`` (module
    notes); ``overrides`` set any field."""
    from mitpiv.io.openptv import OpenPTVSettings

    tol = _tolerance_2d_px(q)
    margin = q.search_px * q.voxel_mm
    dv = tuple(round(float(a) + margin, 6) for a in q.motion_axis_mm)
    pos_err = 0.5 * tol * q.voxel_mm
    acc = (q.acceleration_mm or 0.0) + np.sqrt(6.0) * pos_err
    kw = {"max_displacement_mm": dv, "acceleration": round(float(acc), 6)}
    if q.pixel_pitch_mm is not None:
        kw["eps0_mm"] = round(tol * q.pixel_pitch_mm, 6)
    s = OpenPTVSettings(**kw)
    return replace(s, **overrides) if overrides else s


def openptv_settings_for_run(run_dir, **kw):
    """(:class:`~mitpiv.io.openptv.OpenPTVSettings`, record) for a run (module notes;
    ``kw``: :func:`run_quantities`' options)."""
    q = run_quantities(run_dir, **kw)
    s = openptv_settings_from(q)
    rec = {**q.to_dict(), "rules": {
        "eps0_mm": f"(tolerance_px + {CALIBRATION_FACTOR:g} x calibration_error_px) x pixel_pitch_mm",
        "max_displacement_mm": "per axis: motion_axis_mm + search_px x voxel_mm (track.par: -dv..+dv)",
        "acceleration": "acceleration_mm + sqrt(6) x tolerance_2d_px x voxel_mm / 2"}}
    return s, rec
