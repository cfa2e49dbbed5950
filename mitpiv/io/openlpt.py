"""Export to OpenLPT (Tan, Salibindla, Masuk & Ni 2020; PyPI ``openlpt``, C++ core
``pyopenlpt`` with a Shake-The-Box tracker run from a config file), and read its tracks.

Checked against ``openlpt`` 2.2.4 (the cp311 manylinux wheel) and the format of its sources
(github.com/JHU-NI-LAB/OpenLPT_GUI: ``src/srcMath/Camera.cpp``, the sample
``test/inputs/test_STB``, and the config writer of the GUI, ``gui/views/tracking_settings_view.py``).

Folder written by :func:`export_openlpt`
----------------------------------------
``config.txt``
    the main config: frame range, frame rate, threads, camera files with their maximum
    intensity, image lists, view volume, voxel size, output folder, object type
    (``Tracer``) and the STB config file; paths relative to the folder. OpenLPT reads it
    with ``openlpt config.txt`` or ``pyopenlpt.run("config.txt")``; run it from the
    folder (:func:`mitpiv.tracking.peers.run_openlpt` does).
``tracerConfig.txt``
    the STB settings (:class:`OpenLPTSettings`).
``camFile/cam<k>.txt``
    one PINHOLE camera file per camera (below).
``imgFile/cam<k>/img<nnnnn>.tif`` and ``imgFile/cam<k>ImageNames.txt``
    the frames as uncompressed 8-bit (or 16-bit) grey TIFFs, scaled as in
    :mod:`mitpiv.io.tiff`, and the list of them, one path per frame.
``mitpiv_export.json``
    what was written: cameras, frames, the intensity gain, the settings.

Camera file (PINHOLE)
---------------------
OpenLPT's pinhole model is OpenCV's: ``p_cam = R p_world + T`` (OpenCV frame, x right,
y down, z forward), normalised ``x = X/Z``, ``y = Y/Z``, OpenCV's Brown-Conrady distortion
``(k1, k2, p1, p2, k3)`` (optionally the rational ``k4..k6``), then ``u = fx x_d + cx``,
``v = fy y_d + cy`` with ``u`` along columns; the image size line is ``n_row,n_col``. The file
stores ``K``, the distortion, the Rodrigues vector, ``R``, ``R^-1``, ``T`` and ``-R^-1 T``
(the camera centre), comma-separated. mitpiv's camera is the same model with pixel centres at
``i + 0.5`` where OpenLPT's (like OpenCV's, and its 2-D peak finder) are at ``i``: the
principal point loses 0.5 px on each axis, so ``u_openlpt = u_mitpiv - 0.5`` exactly.

Distortion and a bug of openlpt 2.2.4: the loader switches distortion on only when some
coefficient is *positive* (``dist_coeff > SMALLNUMBER``), so a purely barrel lens
(``k1 < 0``, the other terms zero or negative) would be projected without distortion. The
exporter writes such a lens in OpenLPT's 8-coefficient rational form, which is the same
model: ``(1 + k1 r2 + k2 r4) = (1 + (k1+a) r2 + (k2+a k1) r4 + a k2 r6) / (1 + a r2)`` with
``a = 1`` (positive, so the loader sees distortion). When ``k3 != 0`` and no term is positive
no exact form exists, and the export is refused (:class:`~mitpiv.errors.ConfigError`).

Known limit of openlpt 2.2.4 with distorted cameras (observed, not fixed here): on the
exported files its projection and line of sight agree with mitpiv (1e-6 px; a point lies
1e-9 mm from the line of sight of its own projection), yet its stereo matching pairs almost
no particles once a camera file carries distortion: on bench/bench_peers.py's sequence (4
cameras, 200 particles, 6 frames) ``Matched 0 objects`` for ``k1 = +-3.8`` (a 2 % shift at the
corner, 5-coefficient and rational forms alike) and a yield of 0.04 for ``k1 = 0.05`` (0.09 px
at the corner), against 0.99 for ``k1 = 1e-6`` and without distortion. The cause, measured
through its Python API (``StereoMatch.makeLine2DFromLOS3D``): the 2-D epipolar line it draws
in a second camera is anchored at a point of the line of sight that projects far outside the
sensor (pixel (27518, -2005) on a 512 px sensor here), where the lens polynomial is evaluated
at a normalised radius of about 5 and means nothing: with ``k1 = 0.05`` the line misses the
true image by 6.5 px (8e-11 px without distortion), and matching from the exact 2-D positions
finds 2 of 200 particles (200 of 200 without distortion). The exporter writes such cameras
faithfully and logs a warning; ``undistort=True`` resamples the frames onto the undistorted
pinhole image (:func:`undistort_image`) and writes the cameras without distortion instead.

Hand-written: the file text (OpenLPT ships no writer usable without its GUI) and the track
reader (the CSV layout of its output, checked on its output files).
"""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError, FileFormatError, check_positive
from mitpiv.io.atomic import atomic_path
from mitpiv.io.tiff import BITS, frame_stack, intensity_gain, load_frame, quantise, write_tiff

__all__ = ["OpenLPTSettings", "openlpt_camera_text", "write_openlpt_camera", "openlpt_distortion",
           "export_openlpt", "read_openlpt_tracks", "undistort_image", "RATIONAL_A"]

log = logging.getLogger(__name__)

#: The denominator coefficient ``a`` of the rational rewriting of a barrel lens (see the
#: module notes); any positive value gives the same model, 1 keeps the numbers O(k).
RATIONAL_A = 1.0

#: openlpt's threshold above which a coefficient switches distortion on (SMALLNUMBER).
_SMALL = 1e-8


@dataclass(frozen=True)
class OpenLPTSettings:
    """The STB settings written to ``tracerConfig.txt`` (OpenLPT's names and units; voxels
    are ``voxel_mm`` of the main config). Defaults: OpenLPT's sample ``test_STB`` except
    where noted.

    search_radius_vox : search radius linking tracks to particles in the initial phase [voxel].
    initial_frames : frames of the initial phase (4, as in Schanz et al. 2016).
    neighbour_spacing_vox : mean interparticle spacing identifying neighbour tracks [voxel].
    shake_width_vox : shake width [voxel].
    pred_grid : (x, y, z) points of the predictive-field grid.
    pred_search_vox : predictive-field search radius [voxel].
    ipr_loops, shake_loops : IPR loops and shake loops per IPR loop.
    ghost_threshold : relative intensity below which a candidate is a ghost.
    tolerance_2d_px : 2-D matching tolerance [px]; tolerance_3d_vox : 3-D tolerance [voxel].
    reduced_cameras, reduced_loops : cameras left out in reduced loops, and loops per set.
    finder_threshold : 2-D peak threshold in image counts (of ``2**bits - 1``).
    particle_radius_px : particle image radius for residual images and shaking [px].

    OpenLPT also fits its OTF in windows of ``particle_radius_px``, and subtracts and shakes
    in windows ``round(2 r)`` px wide. The sample's 2 px suits its particle images (sigma
    0.88 px) at 0.01 ppp; for denser images the window takes in the neighbours (see
    :func:`mitpiv.studies.kinds.tracking.compare.particle_radius_px`).
    """

    search_radius_vox: float = 10.0
    initial_frames: int = 4
    neighbour_spacing_vox: float = 30.0
    shake_width_vox: float = 0.25
    pred_grid: tuple[int, int, int] = (51, 51, 51)
    pred_search_vox: float = 25.0
    ipr_loops: int = 2
    shake_loops: int = 4
    ghost_threshold: float = 0.1
    tolerance_2d_px: float = 0.8
    tolerance_3d_vox: float = 1.0
    reduced_cameras: int = 1
    reduced_loops: int = 2
    finder_threshold: float = 30.0
    particle_radius_px: float = 2.0

    def text(self) -> str:
        g = self.pred_grid
        return (
            "############################\n######### Tracking #########\n############################\n"
            "######### Initial Phase ##############\n"
            f"{self.search_radius_vox:g} # Search radius for connecting tracks to objects\n"
            f"{int(self.initial_frames)} # Number of frames for initial phase\n"
            "######### Convergence Phase #############\n"
            f"{self.neighbour_spacing_vox:g} # Avg Interparticle spacing. (vox) to identify neighbour tracks\n\n"
            "#########################\n######### Shake #########\n#########################\n"
            f"{self.shake_width_vox:g} # shake width\n\n"
            "#################################\n######### Predict Field #########\n"
            "#################################\n"
            f"{int(g[0])} # xgrid\n{int(g[1])} # ygrid\n{int(g[2])} # zgrid\n"
            f"{self.pred_search_vox:g} # searchRadius [voxel]\n\n"
            "#######################\n######### IPR #########\n#######################\n"
            f"{int(self.ipr_loops)} # No. of IPR loop\n{int(self.shake_loops)} # No. of Shake loop\n"
            f"{self.ghost_threshold:g} # ghost threshold\n{self.tolerance_2d_px:g} # 2D tolerance [px]\n"
            f"{self.tolerance_3d_vox:g} # 3D tolerance [voxel]\n\n"
            f"{int(self.reduced_cameras)} # number of reduced camera\n"
            f"{int(self.reduced_loops)} # no. of ipr loops for each reduced camera combination\n\n"
            "###############################\n######### Object Info #########\n"
            "###############################\n"
            f"{self.finder_threshold:g} # 2D particle finder threshold\n"
            f"{self.particle_radius_px:g} # Particle radius [px], for calculating residue image and shaking\n")


def _num(x) -> str:
    return repr(float(x))


def _row(v) -> str:
    return ",".join(_num(x) for x in np.ravel(v))


def _check_camera(camera, owner: str):
    for attr in ("K", "rotation", "position_mm", "distortion", "resolution"):
        if not hasattr(camera, attr):
            raise ConfigError(f"{owner}: OpenLPT's PINHOLE model holds a pinhole camera with Brown-Conrady "
                              f"distortion; a {type(camera).__name__} (no {attr!r}) cannot be written. Export the "
                              "experiment's pinhole cameras (a plenoptic camera has no OpenLPT model).")
    return camera


def openlpt_distortion(distortion) -> list[float]:
    """OpenLPT's distortion coefficients for a mitpiv :class:`~mitpiv.physics.distortion.Distortion`:
    OpenCV's ``(k1, k2, p1, p2, k3)``, or the exact 8-coefficient rational form
    ``(k1+a, k2+a k1, p1, p2, a k2, a, 0, 0)`` when no coefficient is positive (so that
    openlpt 2.2.4 switches distortion on; see the module notes).

    Raises
    ------
    ConfigError
        A lens with ``k3 != 0`` and no positive coefficient: OpenLPT would ignore it.
    """
    d = distortion
    five = [float(d.k1), float(d.k2), float(d.p1), float(d.p2), float(d.k3)]
    if all(c == 0.0 for c in five) or any(c > _SMALL for c in five):
        return five
    if d.k3 != 0.0:
        raise ConfigError(f"export_openlpt: the lens distortion ({d}) has k3 != 0 and no positive coefficient; "
                          "openlpt 2.2.4 switches distortion on only when a coefficient is positive, and this "
                          "lens has no exact rational rewriting. Use a lens with k3 = 0 (or any positive term), "
                          "or an undistorted camera.")
    a = RATIONAL_A
    return [d.k1 + a, d.k2 + a * d.k1, d.p1, d.p2, a * d.k2, a, 0.0, 0.0]


def openlpt_camera_text(camera) -> str:
    """The text of OpenLPT's PINHOLE camera file for a mitpiv pinhole camera (see the
    module notes for the conventions)."""
    import cv2

    cam = _check_camera(camera, "openlpt_camera_text")
    K = np.array(cam.K, dtype=np.float64)
    K[0, 2] -= 0.5  # mitpiv pixel centres at i + 0.5, OpenLPT's at i
    K[1, 2] -= 0.5
    R = np.asarray(cam.rotation, dtype=np.float64)
    T = -R @ np.asarray(cam.position_mm, dtype=np.float64)
    rvec = cv2.Rodrigues(R)[0].ravel()
    w, h = cam.resolution
    lines = ["# Camera Model: (PINHOLE/POLYNOMIAL)", "PINHOLE", "# Camera Calibration Error: ", "None",
             "# Pose Calibration Error: ", "None", "# Image Size: (n_row,n_col)", f"{int(h)},{int(w)}",
             "# Camera Matrix: ", *(_row(r) for r in K), "# Distortion Coefficients: ",
             _row(openlpt_distortion(cam.distortion)), "# Rotation Vector: ", _row(rvec), "# Rotation Matrix: ",
             *(_row(r) for r in R), "# Inverse of Rotation Matrix: ", *(_row(r) for r in R.T),
             "# Translation Vector: ", _row(T), "# Inverse of Translation Vector: ", _row(-R.T @ T)]
    return "\n".join(lines) + "\n"


def write_openlpt_camera(path, camera) -> Path:
    """Write OpenLPT's PINHOLE camera file for ``camera`` (atomic)."""
    text = openlpt_camera_text(camera)
    path = Path(path)
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return path


def undistort_image(image, camera) -> np.ndarray:
    """Resample an image of a distorted pinhole camera onto the image the same camera
    without distortion would take (same ``K``, R, position): the output pixel centred at
    ``(u, v)`` takes the input at ``K distort(K^-1 (u, v))``, by OpenCV's bicubic ``remap``
    (zero outside the input). Returns float64 (H, W).

    Bicubic interpolation keeps a particle image's centroid within a few hundredths of a
    pixel and its peak within a few per cent for images of 2 px or more across; it can ring
    slightly negative next to steep peaks (the export clips at 0).
    """
    import cv2

    from mitpiv.physics.distortion import distort

    img = np.asarray(image, dtype=np.float64)
    w, h = camera.resolution
    cx, cy = camera.principal_point_px
    f = camera.focal_px
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    xd, yd = distort((u - cx) / f, (v - cy) / f, camera.distortion)
    map_x = (f * xd + cx - 0.5).astype(np.float32)  # array index of the source (centres at i + 0.5)
    map_y = (f * yd + cy - 0.5).astype(np.float32)
    return cv2.remap(img, map_x, map_y, interpolation=cv2.INTER_CUBIC, borderMode=cv2.BORDER_CONSTANT, borderValue=0)


def _box(lower_mm, upper_mm, owner):
    lo, hi = np.asarray(lower_mm, dtype=np.float64).ravel(), np.asarray(upper_mm, dtype=np.float64).ravel()
    if lo.shape != (3,) or hi.shape != (3,) or not np.all(np.isfinite(lo)) or not np.all(np.isfinite(hi)) \
            or not np.all(hi > lo):
        raise ConfigError(f"{owner}: the view volume needs finite 'lower_mm' < 'upper_mm' (3 values each) [mm], "
                          f"got {lower_mm!r} and {upper_mm!r}.")
    return lo, hi


def export_openlpt(out_dir, images, cameras, *, lower_mm, upper_mm, frame_rate_hz: float = 1.0,
                   voxel_mm: float | None = None, bits: int = 8, gain: float | None = None,
                   settings: OpenLPTSettings | None = None, threads: int = 1, undistort: bool = False,
                   progress=None) -> dict:
    """Write a folder OpenLPT's STB runs on: config, STB settings, camera files, TIFF frames.

    Parameters
    ----------
    out_dir : str or Path
        The folder (created; files in it are replaced).
    images : sequence
        One sequence of frames per camera, each frame an (H, W) image (radiance or counts)
        or the path of an EXR file; every camera the same number of frames.
    cameras : sequence of PinholeCamera
        The cameras, in the order of ``images`` (resolution (W, H) matching the frames).
    lower_mm, upper_mm : (3,) float
        The view volume [mm] (OpenLPT's ``xmin,xmax,ymin,ymax,zmin,zmax``).
    frame_rate_hz : float
        Frames per second (OpenLPT's velocities are per frame times this rate).
    voxel_mm : float, optional
        OpenLPT's voxel [mm] (its 3-D tolerances and radii are in voxels); default the
        largest side of the volume / 1000, as OpenLPT's sample.
    bits : 8 or 16
        TIFF bit depth; OpenLPT's maximum intensity is ``2**bits - 1``.
    gain : float, optional
        Counts per image unit; default ``(2**bits - 1) / max`` over all frames and cameras.
    settings : OpenLPTSettings, optional
        STB settings (default :class:`OpenLPTSettings`).
    threads : int
        OpenLPT's thread count (0: all cores).
    undistort : bool
        Resample each frame of a distorted camera onto its undistorted pinhole image (same
        ``K``; :func:`undistort_image`) and write the camera without distortion: the
        work-around for openlpt 2.2.4's stereo matching on distorted cameras (module notes).
    progress : optional
        Progress bar control (:mod:`mitpiv.progress`).

    Returns
    -------
    dict
        The manifest written to ``mitpiv_export.json`` (``config`` the main config's path).

    Raises
    ------
    ConfigError
        No frames, frames and cameras that disagree, a camera OpenLPT cannot represent, a bad
        volume or option. Everything is checked before the first file is written.
    """
    from mitpiv.io.records import write_json, write_text
    from mitpiv.progress import bar

    owner = "export_openlpt"
    cameras = list(cameras)
    if not cameras:
        raise ConfigError(f"{owner}: 'cameras' is empty; give the experiment's cameras.")
    for c in cameras:
        _check_camera(c, owner)
    distorted = [not c.distortion.is_zero for c in cameras]
    if undistort:
        from dataclasses import replace

        from mitpiv.physics.distortion import Distortion

        written = [replace(c, distortion=Distortion()) if d else c for c, d in zip(cameras, distorted, strict=True)]
    else:
        written = cameras
    cam_texts = [openlpt_camera_text(c) for c in written]
    stack = frame_stack(images, len(cameras), owner=owner)
    lo, hi = _box(lower_mm, upper_mm, owner)
    frame_rate_hz = check_positive("frame_rate_hz", frame_rate_hz, owner=owner, unit="Hz")
    voxel_mm = float(np.max(hi - lo) / 1000.0) if voxel_mm is None else \
        check_positive("voxel_mm", voxel_mm, owner=owner, unit="mm")
    if bits not in BITS:
        raise ConfigError(f"{owner}: 'bits' must be 8 or 16, got {bits!r}.")
    if isinstance(threads, bool) or int(threads) != threads or threads < 0:
        raise ConfigError(f"{owner}: 'threads' must be an integer >= 0 (0: all cores), got {threads!r}.")
    settings = settings or OpenLPTSettings()
    if not isinstance(settings, OpenLPTSettings):
        raise ConfigError(f"{owner}: 'settings' must be an OpenLPTSettings, got {type(settings).__name__}.")
    for k, (cam, frames) in enumerate(zip(cameras, stack, strict=True)):
        shape = load_frame(frames[0]).shape
        if shape != (cam.resolution[1], cam.resolution[0]):
            raise ConfigError(f"{owner}: camera {k + 1}'s frames are {shape[1]} x {shape[0]} px, its resolution "
                              f"is {cam.resolution[0]} x {cam.resolution[1]}; give each camera its own images.")
    gain = intensity_gain(stack, bits=bits, owner=owner) if gain is None else \
        check_positive("gain", gain, owner=owner, unit="counts per image unit")
    if any(distorted) and not undistort:
        log.warning("export_openlpt: the cameras carry lens distortion; openlpt 2.2.4's stereo matching pairs "
                    "almost no particles on distorted camera files (see mitpiv.io.openlpt's notes), although "
                    "the files project exactly.")

    out = Path(out_dir)
    n_cam, n_frames = len(cameras), len(stack[0])
    top = 2**bits - 1
    with bar(n_cam * n_frames, desc="openlpt export", progress=progress, unit="image") as b:
        for k in range(n_cam):
            names = []
            for f, frame in enumerate(stack[k]):
                rel = f"imgFile/cam{k + 1}/img{f:05d}.tif"
                img = load_frame(frame)
                if undistort and distorted[k]:
                    img = undistort_image(img, cameras[k])
                write_tiff(out / rel, quantise(img, gain, bits))
                names.append(rel)
                b.update()
            write_text(out / f"imgFile/cam{k + 1}ImageNames.txt", "\n".join(names) + "\n")
            write_text(out / f"camFile/cam{k + 1}.txt", cam_texts[k])
    vol = ",".join(_num(v) for v in np.ravel(np.stack([lo, hi], axis=1)))
    config = "\n".join([
        "# Frame Range: [startID,endID]", f"0,{n_frames - 1}", "# Frame Rate: [Hz]", _num(frame_rate_hz),
        "# Number of Threads: (0: use as many as possible)", f"{int(threads)}", "# Number of Cameras: ", f"{n_cam}",
        "# Camera File Path, Max Intensity", *(f"camFile/cam{k + 1}.txt,{top}" for k in range(n_cam)),
        "# Image File Path", *(f"imgFile/cam{k + 1}ImageNames.txt" for k in range(n_cam)),
        "# View Volume: (xmin,xmax,ymin,ymax,zmin,zmax)", vol,
        "# Voxel to MM: e.g. use 1000^3 voxel, (xmax-xmin)/1000", _num(voxel_mm),
        "# Output Folder Path: ", "results/", "# Object Types: ", "Tracer", "# STB Config Files:",
        "tracerConfig.txt", "# Flag to load previous track files, previous frameID", "0,-1",
        "# Path to active long track files", "results/ConvergeTrack/", "# Path to active short track files",
        "results/ConvergeTrack/"]) + "\n"
    write_text(out / "tracerConfig.txt", settings.text())
    write_text(out / "config.txt", config)
    manifest = {
        "tool": "openlpt", "checked_version": "2.2.4", "config": str(out / "config.txt"),
        "n_cameras": n_cam, "n_frames": n_frames, "frame_rate_hz": frame_rate_hz, "voxel_mm": voxel_mm,
        "lower_mm": lo.tolist(), "upper_mm": hi.tolist(), "bits": bits, "gain": gain,
        "scaling": f"value = round(clip(image * gain, 0, {top})), one gain for all cameras and frames",
        "pixel_convention": "OpenLPT pixel centres at integers: u_openlpt = u_mitpiv - 0.5",
        "cameras": [c.to_dict() for c in written] if all(hasattr(c, "to_dict") for c in written) else None,
        "settings": asdict(settings), "undistorted_images": bool(undistort and any(distorted)),
    }
    write_json(out / "mitpiv_export.json", manifest)
    return manifest


def read_openlpt_tracks(path, *, n_frames: int | None = None) -> dict:
    """Read OpenLPT's track CSV files (``LongTrack*.csv`` / ``ShortTrack*.csv`` / ``ExitTrack*``
    as its STB writes them: a header line, then one row per track point ``TrackID, FrameID,
    WorldX, WorldY, WorldZ, ...``) into dense arrays.

    Parameters
    ----------
    path : str or Path or list
        A CSV file, a folder (every ``*.csv`` in it), or a list of files.
    n_frames : int, optional
        Frames of the sequence (default: the largest frame id + 1).

    Returns
    -------
    dict with ``positions_mm`` (n_tracks, n_frames, 3) (NaN where a track is absent),
    ``track_ids`` (n_tracks,) (OpenLPT's ids, made unique per file) and ``files``.
    """
    import pandas as pd

    p = Path(path) if not isinstance(path, list | tuple) else None
    files = sorted(p.glob("*.csv")) if p is not None and p.is_dir() else ([p] if p is not None else
                                                                          [Path(f) for f in path])
    rows = []
    for i, f in enumerate(files):
        if not f.is_file():
            raise FileFormatError(f"read_openlpt_tracks: {str(f)!r} does not exist.")
        try:
            df = pd.read_csv(f, skipinitialspace=True)
        except pd.errors.EmptyDataError:
            continue
        cols = {c.strip().lower(): c for c in df.columns}
        need = ("trackid", "frameid", "worldx", "worldy", "worldz")
        if not all(n in cols for n in need):
            raise FileFormatError(f"read_openlpt_tracks: {str(f)!r} lacks the columns {list(need)} (has "
                                  f"{list(df.columns)[:8]}); is it an OpenLPT track file?")
        a = df[[cols[n] for n in need]].to_numpy(dtype=np.float64)
        rows.append(np.column_stack([np.full(len(a), i, np.float64), a]))
    data = np.concatenate(rows) if rows else np.zeros((0, 6))
    key = data[:, 0].astype(np.int64) * (1 << 32) + data[:, 1].astype(np.int64)
    uniq, inverse = np.unique(key, return_inverse=True)
    frames = data[:, 2].astype(np.int64)
    nf = int(frames.max() + 1 if frames.size else 0) if n_frames is None else int(n_frames)
    if frames.size and (frames.min() < 0 or frames.max() >= nf):
        raise FileFormatError(f"read_openlpt_tracks: frame ids {frames.min()}..{frames.max()} lie outside the "
                              f"{nf} frames of the sequence.")
    pos = np.full((len(uniq), nf, 3), np.nan)
    pos[inverse, frames] = data[:, 3:6]
    return {"positions_mm": pos, "track_ids": uniq, "files": [str(f) for f in files]}
