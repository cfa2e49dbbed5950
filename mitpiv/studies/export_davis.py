"""Export a finished run folder to LaVision DaVis (:func:`export_davis`, ``mitpiv export RUN
--davis DIR``), through LaVision's ``lvpyio`` (:mod:`mitpiv.io.davis`).

Folder written (``out_dir``, replaced as a whole and atomically: filled under a temporary name
beside it, then renamed; only a new or empty folder or an earlier DaVis export is replaced,
never the run folder or a folder holding it):

``Images.set``, ``Images/B<nnnnn>.im7``
    the run's camera images as a DaVis image set: one buffer per time step, one frame per
    camera (``CameraName``), ``AcqTimeSeries`` the frame time of the run's truth. The sensor
    stage's counts when the run has one (kept as ``uint16`` counts), else the render stage's
    radiance quantised to 16 bits with one gain for every camera and frame
    (:mod:`mitpiv.io.tiff`'s rule, as the OpenLPT / OpenPTV exports).
``Calibration.set``, ``Calibration/B<nnnnn>.im7`` (``calibration=True``)
    a dot calibration plate imaged through the run's own cameras at ``n_planes`` z positions
    spanning the seeding box, one buffer per position. The plate is rendered by Mitsuba
    through the scene's sensors (the render stage's ``scene.xml`` with the run's parameters:
    the same distortion, PSF and resolution as the particle images; :mod:`mitpiv.render.targets`),
    without the sensor stage's noise, quantised to 16 bits. Cost: one Mitsuba render per
    camera and plane (``spp`` samples per pixel), which dominates the export. Measured on a
    2-core CPU (LLVM variant), a 512 x 512 px camera of ``scenes/tomo4`` with its FFT PSF:
    12 s per view at 4 spp (the default), 39 s at 16 spp, so ``make demo``'s run (4 cameras x
    5 planes) takes about 4 min; the test suite's 80 px cameras about 1 s per view at 16 spp.
    ``n_planes`` and ``spp`` trade that time for views and antialiasing (the plate texture is
    itself antialiased); ``calibration=False`` skips it. ``spp`` counts samples per pixel of
    the film Mitsuba renders, which for an FFT-PSF camera is ``oversample`` times finer
    (5 x 5 for the planar and tomo4 cameras). Measured on ``scenes/planar``'s 512 px camera
    (2026-11-28, the machine shared with another job), against spp 16 (50.6 s a view): spp 1
    9.0 s, RMS difference 0.06 % of the peak, largest 16 % (a dot edge pixel); spp 4 17.5 s,
    0.007 % and 0.2 %. (``mitpiv export --davis DIR --plate-planes N --plate-spp N``.)
``calibration_plate.json`` and ``README.txt``
    the plate as DaVis's calibration wizard asks for it (custom single-level dot plate,
    dot spacing and diameter, z positions, origin dot) and the steps to calibrate in DaVis.
``Truth.set``, ``Truth/`` (``truth=True``)
    the true particle tracks as a DaVis particle field (:func:`~mitpiv.io.davis.write_davis_particles`).
``piv_measured.vc7`` (a tomo run whose PIV stage finished)
    the run's 3D PIV field as a DaVis 3D-3C vector volume (mm, m/s).
``mitpiv_export.json``
    what was written, units and times.

Why plate images and not camera files: lvpyio writes image / vector / particle data only, and
DaVis builds its calibrations from plate images in its wizard (no import of a camera model
from a file mitpiv could write); see :mod:`mitpiv.io.davis`.
"""

from __future__ import annotations

import logging
import math
import time
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.progress import Progress
from mitpiv.studies.shared import truth_file

__all__ = ["export_davis", "plate_for_box", "DEFAULT_PLANES", "DEFAULT_SPP"]

log = logging.getLogger(__name__)

#: Plate positions written by default (evenly across the seeding box's depth, ends included).
DEFAULT_PLANES = 5
#: Samples per pixel of the plate renders.
DEFAULT_SPP = 4


def plate_for_box(lower_mm, upper_mm):
    """A dot plate covering the box's x-y extent: about 9 dots across its larger side, an odd
    number of dots on each axis (so a dot sits at the centre, the origin to pick in DaVis),
    dots 0.4 of the spacing wide."""
    from mitpiv.physics.targets import CalibrationTarget

    lo, hi = np.asarray(lower_mm, float), np.asarray(upper_mm, float)
    w, h = hi[:2] - lo[:2]
    spacing = float(max(w, h)) / 8.0
    cols = 2 * int(math.floor(w / 2 / spacing)) + 1
    rows = 2 * int(math.floor(h / 2 / spacing)) + 1
    return CalibrationTarget("dots", max(rows, 3), max(cols, 3), spacing)


def _times(run: Path, frames: list[int]) -> np.ndarray:
    from mitpiv.io import read_truth

    truth = truth_file(run)
    if truth is None:
        raise FileFormatError(f"export: the run {str(run)!r} has no truth file (particles/truth.npz or "
                              "field/truth.npz) with its frame times; re-run its first stage.")
    t = np.asarray(read_truth(truth)["times_s"], dtype=np.float64)
    if max(frames) >= t.size:
        raise FileFormatError(f"export: the images have frames {frames}, the truth {str(truth)!r} {t.size} times; "
                              "re-run the experiment.")
    return t[frames]


def _run_stack(imgs: dict, bits: int, gain):
    """(n_cam, n_frames, H, W) uint16 images and how they were scaled."""
    from mitpiv.io.tiff import intensity_gain, load_frame, quantise

    stack = np.stack([np.stack([load_frame(f) for f in cam]) for cam in imgs["files"]])
    if imgs["source"] == "sensor" and gain is None:
        if np.all(stack == np.rint(stack)) and stack.min() >= 0 and stack.max() <= 65535:
            return stack.astype(np.uint16), {"gain": 1.0, "scaling": "the sensor stage's counts, unchanged"}
        log.warning("export_davis: the sensor images are not integer counts in 0..65535; quantising them")
    g = intensity_gain(list(stack), bits=bits, owner="export_davis") if gain is None else float(gain)
    top = 2**bits - 1
    q = np.stack([np.stack([quantise(f, g, bits) for f in cam]) for cam in stack]).astype(np.uint16)
    return q, {"gain": g, "scaling": f"value = round(clip(image * gain, 0, {top})), one gain for all cameras "
                                     "and frames"}


def _scene_sensors(run: Path, exp: dict, ids: list[str]):
    from mitpiv.render.scene import load_sensors

    scene = exp.get("scene") or {}
    # the render stage's copy (what it rendered); the experiment's own file when the copy's
    # relative references (a calibration file beside the scene) do not resolve from the run
    candidates = [x for x in (run / "render" / "scene.xml", Path(scene.get("xml", ""))) if x.is_file()]
    if not candidates:
        raise FileFormatError(f"export: no scene file for the calibration plate ({str(run / 'render' / 'scene.xml')!r} "
                              "is missing); re-run the render stage, or call export_davis(..., calibration=False).")
    for k, xml in enumerate(candidates):
        try:
            sensors = load_sensors(xml, params=scene.get("params") or {})
            break
        except Exception:
            if k == len(candidates) - 1:
                raise
    missing = [i for i in ids if i not in sensors]
    if missing:
        raise FileFormatError(f"export: the scene {str(xml)!r} has no sensor(s) {missing} of the run's images.")
    return [sensors[i] for i in ids]


def _calibration(run: Path, exp: dict, imgs: dict, box, *, n_planes: int, spp: int, target, seed: int, progress):
    """Render the plate through the run's sensors; returns (stack uint16, target, z, info)."""
    from mitpiv.io.tiff import intensity_gain, quantise
    from mitpiv.physics.targets import target_pose
    from mitpiv.render.targets import render_target_views

    lo, hi = box
    target = target or plate_for_box(lo, hi)
    if target.kind != "dots":
        raise ConfigError(f"export_davis: 'target' must be a dot plate (kind 'dots'), got {target.kind!r}.")
    z = np.linspace(lo[2], hi[2], n_planes) if n_planes > 1 else np.array([(lo[2] + hi[2]) / 2])
    centre = (hi[:2] + lo[:2]) / 2
    # the plate emits on its +z face: turn it round (about y) when the cameras look from -z
    cam_z = np.array([float(np.asarray(c.position_mm)[2]) for c in imgs["cameras"]]) if all(
        hasattr(c, "position_mm") for c in imgs["cameras"]) else np.array([1.0])
    below = bool(np.all(cam_z < lo[2]))
    if not (below or np.all(cam_z > hi[2])):
        log.warning("export_davis: the cameras look at the box from both sides of z; the one-sided plate faces +z")
    tilt = 180.0 if below else 0.0
    poses = [target_pose(float(zk), centre_xy_mm=centre, tilt_y_deg=tilt) for zk in z]
    sensors = _scene_sensors(run, exp, imgs["sensors"])
    t0 = time.perf_counter()
    views = render_target_views(sensors, target, poses, spp=spp, seed=seed, progress=progress)
    seconds = time.perf_counter() - t0
    stack = np.stack([np.stack([v["images"][c] for v in views]) for c in range(len(sensors))]).astype(np.float64)
    gain = intensity_gain(list(stack), bits=16, owner="export_davis calibration")
    q = np.stack([np.stack([quantise(f, gain, 16) for f in cam]) for cam in stack])
    info = {"render_seconds": round(seconds, 3), "spp": int(spp), "gain": gain, "plate_faces": "-z" if below else "+z"}
    return q, target, z, centre, info


def _write_truth(tmp: Path, run: Path) -> dict | None:
    from mitpiv.io import read_truth
    from mitpiv.io.davis import write_davis_particles

    f = truth_file(run)
    if f is None:
        return None
    tr = read_truth(f)
    pos = np.transpose(np.asarray(tr["positions_mm"], float), (1, 0, 2))  # (N, F, 3)
    t = np.asarray(tr["times_s"], float)
    if pos.shape[1] < 2:
        return None
    ok = np.all(np.isfinite(pos), axis=2)
    # tracks of at least 2 frames without a gap: first to last present frame all present
    n = ok.sum(axis=1)
    first = np.argmax(ok, axis=1)
    last = ok.shape[1] - 1 - np.argmax(ok[:, ::-1], axis=1)
    keep = (n >= 2) & (last - first + 1 == n)
    vel = tr["velocities_mm_s"]
    vel = np.transpose(np.asarray(vel, float), (1, 0, 2))[keep] if vel is not None and np.ndim(vel) == 3 else None
    lv_dir = tmp / ".truth"
    write_davis_particles(lv_dir, pos[keep], t, velocities_mm_s=vel, name="Truth",
                          attributes={"Source": "mitpiv truth"})
    for p in lv_dir.iterdir():  # Truth.set and Truth/ into the export folder
        p.rename(tmp / p.name)
    lv_dir.rmdir()
    return {"set": "Truth.set", "n_tracks": int(keep.sum()), "dropped_tracks_with_gaps": int((~keep).sum()),
            "velocities": vel is not None, "units": {"position": "mm", "velocity": "m/s (track scalars Vx, Vy, Vz)",
                                                     "time": "s"}}


def _write_piv(tmp: Path, run: Path) -> dict | None:
    from mitpiv.analysis import VectorField
    from mitpiv.io.davis import write_davis_vectors

    f = run / "piv" / "field.npz"
    if not (run / "piv" / "stage.json").is_file() or not f.is_file():
        return None
    fld = VectorField.load(f)
    per_s = fld.dt_s is not None
    scale = 1e-3 if per_s else 1.0  # mm/s -> m/s; a displacement stays in mm
    try:
        write_davis_vectors(tmp / "piv_measured.vc7", fld.x_mm, fld.y_mm, fld.z_mm, fld.u * scale, fld.v * scale,
                            fld.w * scale, enabled=np.asarray(fld.valid, bool), length_unit="mm",
                            velocity_unit="m/s" if per_s else "mm", dt_s=fld.dt_s,
                            attributes={"Source": "mitpiv piv"})
    except ConfigError as e:  # e.g. window centres off a uniform grid: the images are still exported
        log.warning("export_davis: the PIV field is not written: %s", e)
        return None
    return {"file": "piv_measured.vc7", "shape": list(fld.u.shape), "velocity_unit": "m/s" if per_s else "mm"}


README = """DaVis export of the mitpiv run {run}
====================================================================

Written by mitpiv {version} through LaVision's lvpyio {lvpyio} (mitpiv.studies.export_davis).

Images.set / Images/       the particle images: {n_cam} cameras x {n_frames} time steps,
                           one DaVis buffer per time step, one frame per camera
                           (cameras in order: {sensors}), {dtype} {source}.
                           Frame times (attribute AcqTimeSeries): {times}
{calib}{truth}{piv}mitpiv_export.json         what was written, units and times.

What DaVis can take from mitpiv, and what not
---------------------------------------------
- Images with their frame times: yes (this image set; Project > Import > set, or copy the set
  into a project folder).
- Camera calibration: not as a file. lvpyio writes no DaVis calibration and DaVis imports no
  camera model mitpiv could write; calibrate in DaVis from the plate images below, as with
  real cameras. The exact mitpiv cameras are in mitpiv_export.json ("cameras") for comparison.
{calib_steps}"""

CALIB_STEPS = """
Calibrating in DaVis from Calibration.set
-----------------------------------------
1. Import Calibration.set into the project; start the calibration wizard
   (Calibration > Define new: 3D / volume calibration, {n_cam} cameras).
2. Plate: custom single-level plate (one plane of dots), moved along z by a traverse:
   dot spacing {spacing:g} mm, dot diameter {diameter:g} mm, {cols} x {rows} dots,
   white dots on a black background, no reference mark, plate thickness 0.
3. Views: one buffer per z position, z = {z} mm (buffer 1 first); the plate faces {faces}.
4. Marks: pick the centre dot as the origin, world (x, y) = ({ox:g}, {oy:g}) mm, and its
   neighbours in +x (right) and +y (up). DaVis's world frame is then mitpiv's (x right, y up,
   z towards the cameras; mm).
5. Fit a pinhole (or 3rd-order polynomial) model; then volume self-calibration on the
   particle images if wanted. The plate images carry no sensor noise.
"""


def export_davis(run_dir, out_dir, *, progress: Progress = None, calibration: bool = True, truth: bool = True,
                 bits: int = 16, gain: float | None = None, n_planes: int = DEFAULT_PLANES, spp: int = DEFAULT_SPP,
                 target=None) -> dict:
    """Write a finished run's images (and a calibration plate set, the truth, the PIV field)
    for LaVision DaVis; see the module notes for the folder.

    Parameters
    ----------
    run_dir : str or Path
        A run folder whose render stage finished.
    out_dir : str or Path
        The export folder (replaced as a whole, atomically).
    progress : optional
        Progress bar control (:mod:`mitpiv.progress`): the plate renders.
    calibration : bool
        Render and write the calibration plate set (Mitsuba; the costly part).
    truth : bool
        Write the true tracks as a DaVis particle field.
    bits : 8 or 16
        Depth of render-stage radiance quantised for DaVis (sensor counts are kept).
    gain : float, optional
        Counts per image unit (default: the brightest pixel of the run maps to ``2**bits - 1``).
    n_planes : int
        Plate positions (>= 1), evenly from the seeding box's lower to upper z.
    spp : int
        Samples per pixel of the plate renders.
    target : CalibrationTarget, optional
        The dot plate (default :func:`plate_for_box` of the seeding box).

    Returns
    -------
    dict
        The manifest written to ``mitpiv_export.json``.

    Raises
    ------
    FileFormatError
        Not a run folder, no rendered images, no truth (frame times), no scene for the plate.
    ConfigError
        Bad options, or cameras of differing resolution (a DaVis buffer holds one size).
    """
    import lvpyio

    from mitpiv.io.davis import IMAGE_SET, replace_dir, write_image_set, write_plate_description
    from mitpiv.io.records import write_json, write_text
    from mitpiv.studies.export import _experiment, run_images
    from mitpiv.version import __version__

    if bits not in (8, 16):
        raise ConfigError(f"export_davis: 'bits' must be 8 or 16, got {bits!r}.")
    if isinstance(n_planes, bool) or not isinstance(n_planes, int) or n_planes < 1:
        raise ConfigError(f"export_davis: 'n_planes' must be an integer >= 1 (plate positions), got {n_planes!r}.")
    if isinstance(spp, bool) or not isinstance(spp, int) or spp < 1:
        raise ConfigError(f"export_davis: 'spp' must be an integer >= 1, got {spp!r}.")
    run = Path(run_dir)
    exp = _experiment(run)
    out = Path(out_dir)
    if out.resolve() == run.resolve() or out.resolve() in run.resolve().parents:
        raise ConfigError(f"export_davis: 'out_dir' {str(out)!r} is the run folder or holds it, and the export replaces "
                          f"its folder whole; give a folder of its own, e.g. {str(run / 'davis')!r}.")
    imgs = run_images(run)
    times = _times(run, imgs["frames"])
    stack, scaling = _run_stack(imgs, bits, gain)
    shapes = {tuple(c.resolution) for c in imgs["cameras"] if hasattr(c, "resolution")}
    if len(shapes) > 1:
        raise ConfigError(f"export_davis: the cameras have resolutions {sorted(shapes)}; a DaVis buffer holds frames "
                          "of one size. Export cameras of one resolution ([render] sensors).")
    seeding = exp.get("seeding") or {}
    box = None
    if "box_min_mm" in seeding and "box_max_mm" in seeding:
        box = (np.asarray(seeding["box_min_mm"], float), np.asarray(seeding["box_max_mm"], float))
    elif calibration:
        raise FileFormatError(f"export: {str(run / 'experiment.json')!r} has no [seeding] box_min_mm / box_max_mm "
                              "(where the calibration plate goes); export with calibration=False.")
    cal = None
    if calibration:  # rendered before anything is written: a failure leaves no folder
        cal = _calibration(run, exp, imgs, box, n_planes=n_planes, spp=spp, target=target,
                           seed=int(exp.get("seed", 0) or 0), progress=progress)
    cams = [c.to_dict() if hasattr(c, "to_dict") else None for c in imgs["cameras"]]
    manifest = {"tool": "davis", "lvpyio_version": lvpyio.__version__, "run": str(run), "source": imgs["source"],
                "sensors": imgs["sensors"], "frames": imgs["frames"], "times_s": times.tolist(), "bits": bits,
                **scaling, "units": {"time": "s", "length": "mm", "image_scales": "pixel (uncalibrated)",
                                     "intensity": "counts"},
                "cameras": cams}
    with replace_dir(out) as tmp:
        m = write_image_set(tmp, stack, sensors=imgs["sensors"], times_s=times, name=IMAGE_SET,
                            attributes={"Source": f"mitpiv run {run.name}"})
        manifest["images"] = {k: m[k] for k in ("n_cameras", "n_frames", "shape", "dtype")} | {"set": "Images.set"}
        calib_txt = calib_steps = ""
        if cal is not None:
            q, tgt, z, centre, info = cal
            write_image_set(tmp, q, sensors=imgs["sensors"], times_s=np.zeros(len(z)), name="Calibration",
                            attributes={"Source": "mitpiv calibration plate"})
            plate = write_plate_description(tmp / "calibration_plate.json", tgt, z, origin_mm=centre,
                                            plate_normal=info["plate_faces"])
            manifest["calibration"] = {"set": "Calibration.set", "plate": "calibration_plate.json",
                                       "route": "plate images rendered by Mitsuba through the run's sensors",
                                       "z_positions_mm": z.tolist(), **info,
                                       "target": tgt.to_dict()}
            calib_txt = (f"Calibration.set / ...     a dot plate at {len(z)} z positions through the same cameras "
                         f"(Mitsuba, {spp} spp, {info['render_seconds']:.1f} s)\n"
                         "calibration_plate.json     the plate, as DaVis's calibration wizard asks for it\n")
            calib_steps = CALIB_STEPS.format(n_cam=len(imgs["sensors"]), spacing=plate["dot_spacing_mm"],
                                             diameter=plate["dot_diameter_mm"], cols=plate["dots_x"],
                                             rows=plate["dots_y"], z=", ".join(f"{v:g}" for v in z),
                                             faces=plate["plate_faces"], ox=centre[0], oy=centre[1])
        tr = _write_truth(tmp, run) if truth else None
        if tr is not None:
            manifest["truth"] = tr
        pv = _write_piv(tmp, run)
        if pv is not None:
            manifest["piv"] = pv
        readme = README.format(
            run=run, version=__version__, lvpyio=lvpyio.__version__, n_cam=m["n_cameras"], n_frames=m["n_frames"],
            sensors=", ".join(imgs["sensors"]), dtype=m["dtype"],
            source="sensor counts" if scaling["gain"] == 1.0 and imgs["source"] == "sensor" else
            f"render radiance x gain {scaling['gain']:.6g}", times=", ".join(f"{t:.9g} s" for t in times),
            calib=calib_txt,
            truth=("Truth.set / Truth/         the true particle tracks (DaVis particle field, mm, m/s)\n"
                   if tr else ""),
            piv="piv_measured.vc7           the run's 3D PIV field (DaVis 3D-3C vector volume)\n" if pv else "",
            calib_steps=calib_steps or "\n(No calibration set: exported with calibration=False.)\n")
        write_text(tmp / "README.txt", readme)
        write_json(tmp / "mitpiv_export.json", manifest)
    manifest["out"] = str(out)
    return manifest
