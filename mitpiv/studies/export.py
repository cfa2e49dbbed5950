"""Export a finished run folder to files other tools open: ParaView / VTK
(:func:`export_vtk`, the writers of :mod:`mitpiv.io.vtk`), and the inputs of other particle
trackers on the run's own images (:func:`export_tracker_inputs`: OpenLPT,
:mod:`mitpiv.io.openlpt`; OpenPTV, :mod:`mitpiv.io.openptv`), with the tool's settings
derived from the run (:mod:`mitpiv.studies.peer_settings`: particle image size, motion per
frame, calibration error, seeding density; recorded as ``derived_settings`` in
``mitpiv_export.json``).

A tomo run (:mod:`mitpiv.studies.kinds.tomo`) becomes, in ``out_dir`` (default
``RUN/vtk``):

``volume_<frame>.vti``
    image data on the reconstruction's voxel grid (point data at voxel centres): arrays
    ``reconstructed`` and ``true`` (the true intensity volume of the frame's particles,
    :func:`mitpiv.analysis.truth_volume`).
``piv.vts``
    structured grid on the interrogation-window centres: ``velocity_measured``,
    ``velocity_true`` (the flow averaged over each window, the reference of the run's
    velocity error), ``velocity_error`` (measured - true; NaN where a vector was not
    valid), ``velocity_error_magnitude``, ``outlier``, ``replaced``, ``valid`` (0 / 1),
    ``snr``, ``peak``, ``vorticity`` and ``vorticity_true`` (curl of the measured and true
    fields, :func:`mitpiv.analysis.curl`). Velocities in mm/s, vorticity in 1/s.
``particles_true_<frame>.vtu``, ``particles_found_<frame>.vtu``
    point clouds: ``diameter_um`` (true), ``peak`` (found), ``match`` (1 where the
    particle has a partner), ``error_mm`` (found - true, NaN without a partner) and
    ``error_magnitude_mm``; ``truth_index`` (found; -1 for ghosts).
``tracks_true.vtu``
    the true path of every particle from frame 0 to frame 1 as a polyline
    (:func:`~mitpiv.io.vtk.write_tracks`; RK4 in the run's flow), with ``time_s`` and
    ``velocity_mm_s`` per point.
``run.pvd``
    a ParaView collection of all of them at the frame times (open this one).

A tracking run (:mod:`mitpiv.studies.kinds.tracking`) becomes ``tracks.vtu``,
``tracks_true.vtu`` and ``run.pvd`` (:func:`export_tracking_vtk`). The export reads a run's
records (its ``experiment.json`` and the files its stages wrote, through
:mod:`mitpiv.studies.shared`); it imports no experiment kind.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.progress import Progress, bar
from mitpiv.studies.shared import read_run_record, run_images, truth_file

__all__ = ["export_vtk", "export_tracking_vtk", "export_tracker_inputs", "export_images", "run_images", "found_positions",
           "particle_errors", "TRACK_SAMPLES", "TRACKERS"]

log = logging.getLogger(__name__)

#: Points per true track between frame 0 and frame 1 (RK4 positions at equal times).
TRACK_SAMPLES = 9


def _experiment(run: Path) -> dict:
    return read_run_record(run, owner="export")


def _need(run: Path, *names: str) -> None:
    missing = [n for n in names if not (run / n / "stage.json").is_file()]
    if missing:
        raise FileFormatError(f"export: the run {str(run)!r} has not finished the stage(s) {missing}; run "
                              f"'mitpiv run EXPERIMENT --out {run}' to complete it.")


def found_positions(run: Path, exp: dict, frame: int, matches) -> np.ndarray:
    """The positions of the particles found in frame ``frame`` (ghosts included): kept with
    the matches, or for runs whose matches predate that, found again in the saved volume
    with the run's own settings (the same deterministic detection)."""
    if matches.found_mm is not None:
        return np.asarray(matches.found_mm, dtype=np.float64)
    from mitpiv.analysis import find_particles
    from mitpiv.io import read_volume

    vol, grid, _ = read_volume(run / "reconstruct" / f"volume_{frame}.npz")
    p = exp.get("particles") or {}
    # a run's experiment.json names its threshold_of ("robust" by default); one without the
    # key predates it and detected with the volume maximum
    found = find_particles(vol, grid, method=p.get("method", "gauss3"), threshold_rel=p.get("threshold_rel", 0.1),
                           threshold_of=p.get("threshold_of", "max"))
    if len(found) != matches.n_found:
        raise FileFormatError(f"export: {len(found)} particles found again in frame {frame}, the run found "
                              f"{matches.n_found}; rerun the evaluate stage.")
    return found.positions_mm


def particle_errors(found_mm, truth_mm, matches) -> dict:
    """Per-particle match flags and errors for the found and the true particles.

    Returns a dict with ``found_match`` (n_found,) bool, ``found_error_mm`` (n_found, 3),
    ``found_truth_index`` (n_found,) int (-1: ghost), ``true_match`` (n_truth_all,) bool and
    ``true_error_mm`` (n_truth_all, 3); errors are found - true [mm], NaN without a partner.
    """
    nf, nt = len(found_mm), len(truth_mm)
    fi, ti = matches.pairs[:, 0], matches.pairs[:, 1]
    out = {"found_match": np.zeros(nf, bool), "found_error_mm": np.full((nf, 3), np.nan),
           "found_truth_index": np.full(nf, -1, np.int64), "true_match": np.zeros(nt, bool),
           "true_error_mm": np.full((nt, 3), np.nan)}
    out["found_match"][fi] = True
    out["true_match"][ti] = True
    out["found_error_mm"][fi] = matches.errors_mm
    out["true_error_mm"][ti] = matches.errors_mm
    out["found_truth_index"][fi] = ti
    return out


def _magnitude(e):
    return np.sqrt(np.sum(np.asarray(e) ** 2, axis=-1))


def export_vtk(run_dir, out_dir=None, *, progress: Progress = None) -> list[Path]:
    """Write a finished tomo run's volumes, PIV field, particles and true tracks as VTK files
    for ParaView (see the module notes for the files and their arrays).

    Parameters
    ----------
    run_dir : str or Path
        The run folder of ``mitpiv run`` / :func:`~mitpiv.studies.run_experiment` (its
        particles, reconstruct, evaluate and piv stages finished).
    out_dir : str or Path, optional
        Where the files go (default ``run_dir / "vtk"``).
    progress : optional
        Progress bar control (:mod:`mitpiv.progress`).

    Returns
    -------
    list of Path
        The files written, ``run.pvd`` last.

    Raises
    ------
    FileFormatError
        ``run_dir`` is not a run folder or a stage it needs has not finished.
    ConfigError
        The run is not a tomo run (backlit runs have no volumes or vector field).
    """
    from mitpiv.analysis import MatchResult, VectorField, curl, truth_volume
    from mitpiv.io import read_truth, read_volume
    from mitpiv.io import vtk as vt
    from mitpiv.io.vectors import read_velocity_error
    from mitpiv.physics.advection import advect
    from mitpiv.physics.flows import flow_from_dict

    run = Path(run_dir)
    exp = _experiment(run)
    if exp.get("kind") == "tracking":  # its own files: tracks and true trajectories
        return export_tracking_vtk(run, out_dir, progress=progress)
    if exp.get("kind", "tomo") != "tomo":
        raise ConfigError(f"export: --vtk exports tomo and tracking runs; {str(run)!r} is a {exp.get('kind')!r} run.")
    _need(run, "particles", "reconstruct", "evaluate", "piv")
    out = Path(out_dir) if out_dir is not None else run / "vtk"
    truth = read_truth(run / "particles" / "truth.npz")
    times = [float(t) for t in truth["times_s"]]
    # pvd: the collection's entries by file name, relative to run.pvd's folder (``out``, where every file
    # lies): what ParaView resolves, wherever the folder is (the vtk stage's temporary folder is renamed)
    files, pvd = [], []
    with bar(8, desc="vtk export", progress=progress, unit="file") as b:
        for frame in (0, 1):
            vol, grid, _ = read_volume(run / "reconstruct" / f"volume_{frame}.npz")
            p_true = truth["positions_mm"][frame]
            f = vt.write_image_data(out / f"volume_{frame}.vti", grid,
                                    {"reconstructed": vol.astype(np.float32),
                                     "true": truth_volume(p_true, grid).astype(np.float32)})
            files.append(f)
            pvd.append((f.name, times[frame], 0, "volume"))
            b.update()
            m = MatchResult.load(run / "evaluate" / f"matches_{frame}.npz")
            found = found_positions(run, exp, frame, m)
            pe = particle_errors(found, p_true, m)
            f_true = vt.write_points(out / f"particles_true_{frame}.vtu", p_true, {
                "diameter_um": truth["diameters_um"], "match": pe["true_match"], "error_mm": pe["true_error_mm"],
                "error_magnitude_mm": _magnitude(pe["true_error_mm"])})
            f_found = vt.write_points(out / f"particles_found_{frame}.vtu", found, {
                "match": pe["found_match"], "error_mm": pe["found_error_mm"],
                "error_magnitude_mm": _magnitude(pe["found_error_mm"]), "truth_index": pe["found_truth_index"]})
            files += [f_true, f_found]
            pvd += [(f_true.name, times[frame], 1, "particles_true"), (f_found.name, times[frame], 2, "particles_found")]
            b.update(2)
        field = VectorField.load(run / "piv" / "field.npz")
        err = read_velocity_error(run / "piv" / "velocity_error.npz")
        meas = np.stack([field.u, field.v, field.w], axis=-1)
        ref = np.asarray(err["reference"], dtype=np.float64)
        e = np.asarray(err["error"], dtype=np.float64)
        f = vt.write_structured_grid(out / "piv.vts", field.x_mm, field.y_mm, field.z_mm, {
            "velocity_measured": meas, "velocity_true": ref, "velocity_error": e,
            "velocity_error_magnitude": _magnitude(e), "outlier": field.outlier, "replaced": field.replaced,
            "valid": field.valid, "snr": field.snr, "peak": field.peak,
            "vorticity": curl(meas, field.x_mm, field.y_mm, field.z_mm),
            "vorticity_true": curl(ref, field.x_mm, field.y_mm, field.z_mm)})
        files.append(f)
        b.update()
        flow = flow_from_dict(dict(truth["flow"]))
        dt = times[1] - times[0]
        n = truth["positions_mm"].shape[1]
        steps = [truth["positions_mm"][0]]
        ts = times[0] + dt * np.arange(TRACK_SAMPLES) / (TRACK_SAMPLES - 1)
        for k in range(1, TRACK_SAMPLES):  # a loop over time steps; each step is vectorised over particles
            steps.append(advect(steps[-1], flow, dt_s=ts[k] - ts[k - 1], t0_s=ts[k - 1], substeps=2))
        pts = np.stack(steps, axis=1).reshape(-1, 3)  # particle-major: each track's points in time order
        t_pt = np.tile(ts, n)
        f_tr = vt.write_tracks(out / "tracks_true.vtu", pts, np.repeat(np.arange(n), TRACK_SAMPLES),
                               {"time_s": t_pt, "velocity_mm_s": _flow_at(flow, pts, t_pt)},
                               track_arrays={"diameter_um": truth["diameters_um"]})
        files.append(f_tr)
        b.update()
        for t in times:
            pvd += [(f.name, t, 3, "piv"), (f_tr.name, t, 4, "tracks_true")]
        files.append(vt.write_collection(out / "run.pvd", sorted(pvd, key=lambda x: (x[1], x[2]))))
        b.update()
    log.debug("vtk export: %d files in %s", len(files), out)  # the CLI prints the result line
    return files


def export_tracking_vtk(run_dir, out_dir=None, *, progress: Progress = None) -> list[Path]:
    """ParaView files of a finished tracking run (:mod:`mitpiv.studies.kinds.tracking`; its
    field, track and evaluate stages finished): ``tracks.vtu`` (the tracks as polylines:
    ``time_s``, ``velocity_mm_s``, ``velocity_error_mm_s``), ``tracks_true.vtu`` (the true
    trajectories: ``time_s``, ``velocity_mm_s``) and ``run.pvd``. :func:`export_vtk` calls it
    for a tracking run."""
    from mitpiv.io import read_npz
    from mitpiv.io.vtk import write_collection, write_tracks
    from mitpiv.studies.shared import read_tracks, run_truth

    run = Path(run_dir)
    out = Path(out_dir) if out_dir is not None else run / "vtk"
    out.mkdir(parents=True, exist_ok=True)
    for st in ("field", "track", "evaluate"):
        if not (run / st / "stage.json").is_file():
            raise FileFormatError(f"export: the {st} stage of {str(run)!r} has not finished; run the experiment first.")
    tr = read_tracks(run / "track" / "tracks.npz")
    err = read_npz(run / "evaluate" / "errors.npz", what="errors")["velocity_error_mm_s"]
    truth = run_truth(run, "field")
    times = np.asarray(truth["times_s"], float)
    files = []
    with bar(2, desc="vtk", progress=progress, unit="file") as b:
        present = tr.present
        tid, fr = np.nonzero(present)
        arrays = {"time_s": times[fr]}
        if tr.velocities_mm_s is not None:
            arrays["velocity_mm_s"] = np.nan_to_num(tr.velocities_mm_s[tid, fr])
        arrays["velocity_error_mm_s"] = err[tid, fr]
        files.append(write_tracks(out / "tracks.vtu", tr.positions_mm[tid, fr], tid.astype(np.int64), arrays))
        b.update()
        tp = truth["positions_mm"]
        ok = np.all(np.isfinite(tp), axis=2)
        fr2, pid = np.nonzero(ok)
        order = np.lexsort((fr2, pid))
        fr2, pid = fr2[order], pid[order]
        arr2 = {"time_s": times[fr2]}
        if truth["velocities_mm_s"] is not None and truth["velocities_mm_s"].ndim == 3:
            arr2["velocity_mm_s"] = truth["velocities_mm_s"][fr2, pid]
        files.append(write_tracks(out / "tracks_true.vtu", tp[fr2, pid], pid.astype(np.int64), arr2))
        b.update()
    files.append(write_collection(out / "run.pvd", [(f.name, 0.0) for f in files]))
    return files


def _flow_at(flow, pts, t_s) -> np.ndarray:
    """The flow's velocity at points with their own times (grouped by distinct time)."""
    v = np.empty_like(pts)
    for t in np.unique(t_s):  # a handful of sample times, each vectorised over points
        sel = t_s == t
        v[sel] = flow(pts[sel], float(t))
    return v



#: The trackers :func:`export_tracker_inputs` writes for.
TRACKERS = ("openlpt", "openptv")


def _derive_settings(run: Path, tool: str, box: dict, options: dict) -> tuple[dict | None, str]:
    """Fill ``options`` with the settings (and OpenLPT's voxel) derived from the run
    (:mod:`mitpiv.studies.peer_settings`) where the caller gave none; returns (the record
    of the derivation or None, what the settings came from)."""
    import warnings

    from mitpiv.errors import MitpivWarning
    from mitpiv.studies import peer_settings as ps

    need = ("settings", "voxel_mm") if tool == "openlpt" else ("settings",)
    if all(k in options for k in need):
        return None, "given"
    applied = {k: "given" if k in options else "derived" for k in need}
    try:
        if tool == "openlpt":
            settings, vox, rec = ps.openlpt_settings_for_run(run, voxel_mm=options.get("voxel_mm"), **box)
            options.setdefault("voxel_mm", vox)
        else:
            settings, rec = ps.openptv_settings_for_run(run, **box)
    except FileFormatError as e:  # images without a truth: the tool's own defaults, said so
        warnings.warn(f"export: {tool} settings are the tool's defaults, nothing to derive them from: {e}",
                      MitpivWarning, stacklevel=3)
        return {"error": str(e)}, "defaults"
    options.setdefault("settings", settings)
    rec["applied"] = applied
    given = [k for k, v in applied.items() if v == "given"]
    return rec, "derived" + (f" ({', '.join(given)} given)" if given else "")


def export_tracker_inputs(run_dir, out_dir, *, tool: str, progress: Progress = None, **options) -> dict:
    """Write the inputs of another tracker for a run's images and cameras.

    Parameters
    ----------
    run_dir : str or Path
        A run folder whose render stage finished (its sensor stage's counts are used when
        it has one).
    out_dir : str or Path
        The folder to write.
    tool : ``"openlpt"`` or ``"openptv"``
        :func:`mitpiv.io.openlpt.export_openlpt` or :func:`mitpiv.io.openptv.export_openptv`.
    progress : optional
        Progress bar control (:mod:`mitpiv.progress`).
    **options
        Passed to the exporter (``bits``, ``gain``, ``settings``, ``voxel_mm``, ...). The
        volume is the experiment's seeding box; OpenLPT's frame rate is 1 / the truth's frame
        interval. Without ``settings`` (and, for OpenLPT, ``voxel_mm``) the tool's settings
        are derived from the run (:mod:`mitpiv.studies.peer_settings`: particle image size,
        motion per frame, calibration error, seeding density); an explicit one wins.

    Returns
    -------
    dict
        The exporter's manifest, with ``run``, ``source``, ``sensors``, ``settings_from``
        (``"derived"``, ``"derived (voxel_mm given)"``, ``"given"``, or ``"defaults"``: the
        exporter's defaults when the run has nothing to derive them from, a warning says why)
        and ``derived_settings`` (the derived quantities, their sources and the rules mapping
        them to the settings; ``{"error": reason}`` with the defaults; absent when everything
        was given) added.

    Raises
    ------
    ConfigError
        An unknown tool, or cameras / options the tool cannot take (nothing is written).
    FileFormatError
        Not a run folder, or one without rendered images.
    """
    if tool not in TRACKERS:
        raise ConfigError(f"export: 'tool' must be one of {TRACKERS}, got {tool!r}.")
    run = Path(run_dir)
    exp = _experiment(run)
    imgs = run_images(run)
    seeding = exp.get("seeding") or {}
    if "box_min_mm" not in seeding or "box_max_mm" not in seeding:
        raise FileFormatError(f"export: {str(run / 'experiment.json')!r} has no [seeding] box_min_mm / box_max_mm "
                              "(the volume the tracker observes).")
    box = {"lower_mm": seeding["box_min_mm"], "upper_mm": seeding["box_max_mm"]}
    derived, settings_from = _derive_settings(run, tool, box, options)
    if tool == "openlpt":
        from mitpiv.io.openlpt import export_openlpt

        # the truth: a tomo run's particles stage, a tracking run's field stage
        truth = truth_file(run)
        if "frame_rate_hz" not in options and truth is not None:
            from mitpiv.io import read_truth

            t = np.asarray(read_truth(truth)["times_s"], dtype=np.float64)
            if t.size > 1 and t[1] > t[0]:
                options["frame_rate_hz"] = 1.0 / float(t[1] - t[0])
        manifest = export_openlpt(out_dir, imgs["files"], imgs["cameras"], **box, progress=progress, **options)
    else:
        from mitpiv.io.openptv import export_openptv

        manifest = export_openptv(out_dir, imgs["files"], imgs["cameras"], **box, progress=progress, **options)
    manifest.update(run=str(run), source=imgs["source"], sensors=imgs["sensors"], settings_from=settings_from)
    if derived is not None:
        manifest["derived_settings"] = derived
    from mitpiv.io import write_json

    write_json(Path(out_dir) / "mitpiv_export.json", manifest)
    return manifest


def export_images(run_dir, out_dir, *, bits: int = 16, progress: Progress = None) -> dict:
    """Write a run's camera images as integer TIFF frames for any 2-D PIV code (OpenPIV,
    PIVlab, ...): ``<sensor>_<frame:04d>.tif`` in ``out_dir`` and ``mitpiv_export.json`` (the
    frames, their times, each camera's pixel pitch and the scaling).

    The sensor stage's counts are written as they are (gain 1) when they are whole numbers
    that fit in ``bits``; radiance (a run without a sensor stage), or counts that do not fit,
    are scaled by one gain for the sequence (:func:`mitpiv.io.tiff.intensity_gain`). The
    pixel ``(row, column)`` of a TIFF is the image pixel mitpiv's cameras project to: x along
    columns, y down the rows (the origin at the top-left corner), as PIV codes read images.

    Returns the manifest (``files`` per sensor, ``gain``, ``bits``, ``times_s``).
    """
    from mitpiv.io import read_truth, write_json
    from mitpiv.io.tiff import BITS, intensity_gain, load_frame, quantise, write_tiff

    if bits not in BITS:
        raise ConfigError(f"export: 'bits' must be one of {BITS}, got {bits!r}.")
    run = Path(run_dir)
    imgs = run_images(run)
    top = 2**bits - 1
    stack = imgs["files"]
    gain = 1.0
    if imgs["source"] == "sensor":
        def fits(a):  # whole counts within the bit depth: written as they are
            return bool(np.all(a == np.rint(a)) and a.min() >= 0 and a.max() <= top)

        if not all(fits(load_frame(f)) for cam in stack for f in cam):  # one frame in memory at a time
            gain = intensity_gain(stack, bits=bits, owner="export")
    else:
        gain = intensity_gain(stack, bits=bits, owner="export")
    truth = truth_file(run)
    times = read_truth(truth)["times_s"] if truth is not None else None
    out = Path(out_dir)
    files = {}
    with bar(len(stack) * len(imgs["frames"]), desc="tiff export", progress=progress, unit="image") as b:
        for sid, cam in zip(imgs["sensors"], stack, strict=True):
            files[sid] = []
            for k, f in zip(imgs["frames"], cam, strict=True):
                name = f"{sid}_{k:04d}.tif"
                write_tiff(out / name, quantise(load_frame(f), gain, bits))
                files[sid].append(name)
                b.update()
    manifest = {"run": str(run), "source": imgs["source"], "sensors": imgs["sensors"], "frames": imgs["frames"],
                "times_s": None if times is None else [float(times[k]) for k in imgs["frames"]],
                "files": files, "bits": bits, "gain": gain,
                "scaling": f"value = round(clip(image * gain, 0, {top}))" + (" (the camera's counts as they are)"
                                                                             if gain == 1.0 else ""),
                "pixel_pitch_um": {s: float(c.pixel_pitch_um) for s, c in zip(imgs["sensors"], imgs["cameras"],
                                                                               strict=True)
                                   if hasattr(c, "pixel_pitch_um")},
                "pixel_convention": "x along columns, y down the rows; pixel i spans [i, i + 1)"}
    write_json(out / "mitpiv_export.json", manifest)
    return manifest
