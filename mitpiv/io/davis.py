"""DaVis (LaVision) files through LaVision's own Python package ``lvpyio`` (checked against
1.5.0): multi-camera image sets out and back (:func:`write_davis_images`,
:func:`read_davis_images`), vector fields in (:func:`read_davis_vectors`: 2D-2C, 2D-3C and
3D-3C volumes) and out (:func:`write_davis_vectors`), particle fields / tracks out and back
(:func:`write_davis_particles`, :func:`read_davis_particles`), and the description of a
calibration plate for DaVis's calibration wizard (:func:`write_plate_description`).

``lvpyio`` is LaVision's reader and writer of DaVis ``.set`` image / vector sets and particle
fields, ``.im7`` / ``.imx`` images and ``.vc7`` / ``.vec`` vector fields (PyPI ``lvpyio``,
"Free To Use But Restricted" licence; its readers and writers are compiled from DaVis's own
I/O library). Every byte of a DaVis file here is written and read by it; mitpiv writes by
hand only the mapping between its arrays and lvpyio's objects (``Buffer`` / ``Frame`` /
``Component`` / ``Scales`` / ``Grid`` / ``Track``), stated below, because lvpyio leaves that
mapping (coordinates of a vector, sign of v, time attributes) to the caller.

Image sets
----------
One DaVis *buffer* per time step (``B00001.im7``, ...), holding one *frame* per camera, in the
order of ``sensors`` (how DaVis stores a multi-camera recording: a buffer is one acquisition,
its frames the cameras). Pixels are kept as they are given: ``uint16`` when every value is an
integer in [0, 65535] (sensor counts), else ``float32`` (radiance). Scales: x and y
``1 pixel`` per pixel, intensity ``counts``: the images are uncalibrated, as a camera records
them (DaVis's calibration then sets the world scales). Time: each frame and buffer carries the
attribute ``AcqTimeSeries`` = ``"<t> µs"`` (t = time of the step in microseconds, 3 decimals),
the attribute DaVis writes for a recording's acquisition time and that its readers parse
(``"73401 µs"``); lvpyio 1.5.0 reads it back as written and fills it with ``"no acquisition
time series value"`` where it is absent. Each frame also carries ``CameraName`` (the sensor
id). DaVis 10's newer per-frame ``Acq.Time`` array is not written (lvpyio fills it with 0 on
reading): its unit is not documented by lvpyio.

Vector fields (DaVis's conventions, as lvpyio applies them)
-----------------------------------------------------------
A vector frame holds ``U0``, ``V0`` (and ``W0`` for 3C) float32 planes of shape (ny, nx), one
plane per z level (a volume: nz planes), with a ``Grid`` (vector spacing in pixels / voxels),
``Scales`` x, y, z (world per pixel: ``slope``, ``offset``, ``unit``) and ``i`` (velocity per
stored unit), an ``ENABLED`` and a ``MASK`` plane (1 = valid) and an ``ACTIVE_CHOICE`` plane.

* Coordinates: vector ``k`` along an axis lies at ``(k + 0.5) * grid * slope + offset``: the
  centre of its grid cell, DaVis's own rule (lvpyio's ``plot_utils.scaled_coordinate``: "we
  want 0 to be top left edge, not center of top left pixel/vector"); for z the same rule with
  ``grid.z`` (lvpyio plots x and y only: the z rule is the same convention by analogy, not
  checked against a volume written by DaVis; a planar field, one plane, has
  ``z = [z offset]``).
* y: DaVis's rows run from the top of the image down, and its world y usually points up (a
  negative y slope). :func:`read_davis_vectors` returns every axis in ascending order, so the
  rows of such a file come out reversed; ``v`` is the world y component, as lvpyio's
  ``as_masked_array`` gives it: ``raw * i.slope + i.offset`` times the sign of the y slope
  (likewise u with x and w with z).
* Valid vectors: ``ENABLED & MASK`` (lvpyio's mask), choice by ``ACTIVE_CHOICE`` (lvpyio).
  Disabled vectors read as NaN.
* ``dt_s``: the attribute ``FrameDt`` (``"<value> <unit>"``, unit s / ms / µs / us / ns) of
  the buffer or frame, when present (DaVis's time between the two frames of a PIV pair).

:func:`write_davis_vectors` writes the same conventions: grid 1, x slope = the x spacing, y
slope = minus the y spacing (rows top-down, y up, as DaVis writes), z slope = the z spacing,
velocity scale 1 in ``velocity_unit``.

Particle fields
---------------
``lvpyio.write_particles`` / ``read_particles``: a time-resolved field of tracks, each a
``Track(start, particles)`` with ``particle_t`` (x, y, z, intensity float32) rows, the world
scales ``mm``, ``times`` in seconds as given (lvpyio's ``times()`` returns them unchanged;
lvpyio's API states no time unit, seconds are taken). Velocities go as track scalars ``Vx``,
``Vy``, ``Vz`` in m/s (scalar scales with that unit); the reader also takes ``U`` / ``V`` /
``W`` and converts m/s, mm/s and µm/s. A track is contiguous
(lvpyio: at least 2 time steps, no gaps), so positions with a gap inside a track are refused.

Calibration (what DaVis can and cannot import)
----------------------------------------------
lvpyio writes images, vector fields and particle fields only: its API is ``write_buffer`` /
``write_set`` / ``append_to_set`` (whose set type, ``guess_output_set_type``, is image or
vector, nothing else) and ``write_particles``. No DaVis calibration can be written through it
(``SET_TYPE_ID_CALIBRATION`` and ``PerspectiveCalibrationSet`` appear only inside its compiled
library), and DaVis keeps a calibration in its own project files, an undocumented format that
lvpyio neither reads nor writes and that mitpiv does not write by hand. DaVis builds a
calibration in its calibration wizard from images of a plate. The route taken is therefore
the one a DaVis user takes with real cameras: images of a dot plate at several z positions
through the run's own cameras (rendered by Mitsuba: the physically based choice, the same
sensors, distortion and PSF as the particle images;
:func:`mitpiv.studies.export_davis.export_davis`), written as a DaVis image set, with the
plate's description (:func:`write_plate_description`) and a README of the wizard's steps.
The plate is mitpiv's symmetric dot grid (:class:`mitpiv.physics.targets.CalibrationTarget`)
without a reference mark: the user picks the origin dot in the wizard. Not verified in DaVis
itself (no DaVis licence here): the sets are checked by reading them back with lvpyio.

Writes are atomic: a folder is filled under a temporary name beside it and renamed into place
(:func:`replace_dir`); a ``.vc7`` through :func:`mitpiv.io.atomic.atomic_path`.
"""

from __future__ import annotations

import logging
import os
import re
import secrets
import shutil
from collections.abc import Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.io.atomic import TMP_MARK, atomic_path, fsync_dir

__all__ = ["DavisVectors", "write_davis_images", "read_davis_images", "read_davis_vectors", "write_davis_vectors",
           "read_davis_particles", "write_davis_particles", "write_plate_description", "replace_dir", "write_image_set",
           "IMAGE_SET", "PARTICLE_SET", "LENGTH_MM", "VELOCITY_MM_S"]

log = logging.getLogger(__name__)

#: Name of the image set an export writes (``Images.set`` and ``Images/``).
IMAGE_SET = "Images"
#: Name of the particle field :func:`write_davis_particles` writes.
PARTICLE_SET = "Particles"
#: Length units read and their size in mm.
LENGTH_MM = {"mm": 1.0, "m": 1000.0, "cm": 10.0, "µm": 1e-3, "um": 1e-3}
#: Velocity units read and their size in mm/s.
VELOCITY_MM_S = {"m/s": 1000.0, "mm/s": 1.0, "µm/s": 1e-3, "um/s": 1e-3}
_TIME_S = {"s": 1.0, "ms": 1e-3, "µs": 1e-6, "us": 1e-6, "ns": 1e-9}
_FIX_READ = ("give a DaVis .im7 / .vc7 / .vec file, a .set file, the set's folder, or a folder holding one "
             "<name>.set beside its <name>/ folder")


def _lv():
    import lvpyio

    return lvpyio


# ----------------------------------------------------------------------------------------- files
@contextmanager
def replace_dir(out_dir):
    """Yield a temporary folder beside ``out_dir``; on success it replaces ``out_dir`` (an
    existing one is moved aside, then removed), so that a failure leaves ``out_dir`` as it
    was. The temporary name carries mitpiv's tag (:mod:`mitpiv.io.atomic`).

    Only a new folder, an empty one or an earlier DaVis output (a folder holding a ``.set``
    file) is replaced: any other folder is refused (:class:`ConfigError`), so that a mistyped
    path (a run folder, a home folder) is never removed."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ConfigError(f"'out_dir' {str(out)!r} is a file, not a folder; give a folder (it is created).")
    if out.is_dir() and any(out.iterdir()) and not any(out.glob("*.set")):
        raise ConfigError(f"'out_dir' {str(out)!r} is a folder that holds other files (no DaVis .set in it); it would "
                          "be replaced whole. Give a new or empty folder, or an earlier DaVis export to overwrite.")
    out.parent.mkdir(parents=True, exist_ok=True)
    token = secrets.token_hex(6)
    tmp = out.parent / f".{out.name}{TMP_MARK}{token}"
    old = out.parent / f".{out.name}.mitpiv-old-{token}"
    tmp.mkdir()
    try:
        yield tmp
        if out.exists():
            os.replace(out, old)
        os.replace(tmp, out)
        fsync_dir(out.parent)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    shutil.rmtree(old, ignore_errors=True)


def _set_path(path, owner: str) -> Path:
    """The ``.set`` file a DaVis path names: the file itself, the folder beside one, or a
    folder holding exactly one ``<name>.set`` with its ``<name>/`` folder."""
    p = Path(path)
    if p.suffix.lower() == ".set" and p.is_file():
        return p
    if p.is_dir():
        beside = p.with_name(p.name + ".set")
        if beside.is_file():
            return beside
        inside = [s for s in sorted(p.glob("*.set")) if s.with_suffix("").is_dir()]
        if len(inside) == 1:
            return inside[0]
        raise FileFormatError(f"{owner}: 'path' {str(p)!r} is a folder but not a DaVis set "
                              f"({'several sets in it: ' + str([s.name for s in inside]) if inside else 'no <name>.set beside or inside it'}); "
                              f"{_FIX_READ}.")
    raise FileFormatError(f"{owner}: 'path' {str(p)!r} is not a DaVis set; {_FIX_READ}.")


def _check_exists(path, owner: str) -> Path:
    p = Path(path)
    if not p.exists():
        raise FileFormatError(f"{owner}: 'path' {str(p)!r} does not exist; {_FIX_READ}.")
    return p


def _read_set(path, owner: str):
    """lvpyio's set at ``path`` (a multi-set is refused)."""
    lv = _lv()
    s = _set_path(path, owner)
    try:
        out = lv.read_set(str(s))
    except RuntimeError as e:
        if "particle field" in str(e):
            raise FileFormatError(f"{owner}: {str(s)!r} is a DaVis particle field, not an image or vector set; read "
                                  "it with read_davis_particles.") from None
        raise FileFormatError(f"{owner}: lvpyio cannot read {str(s)!r} as a DaVis set ({e}); {_FIX_READ}.") from None
    if isinstance(out, list):
        raise FileFormatError(f"{owner}: {str(s)!r} is a DaVis multi-set ({len(out)} sets); give one of its sets.")
    return out


def _read_buffer(path, owner: str):
    """One buffer: a single file (.im7 / .vc7 / ...), read by lvpyio."""
    try:
        return _lv().read_buffer(str(path))
    except RuntimeError as e:
        raise FileFormatError(f"{owner}: {str(path)!r} is not a DaVis file lvpyio can read ({e}); {_FIX_READ}.") from None


def _parse_time(value) -> float | None:
    """``"<number> <unit>"`` (s, ms, µs, us, ns) in seconds, or None."""
    if not isinstance(value, str):
        return None
    m = re.fullmatch(r"\s*([-+0-9.eE]+)\s*(s|ms|µs|us|ns)\s*", value)
    if not m:
        return None
    try:
        return float(m[1]) * _TIME_S[m[2]]
    except ValueError:
        return None


def _us(t_s: float) -> str:
    return f"{t_s * 1e6:.3f} µs"


# ---------------------------------------------------------------------------------------- images
def _image_stack(images, n_cam: int, owner: str) -> np.ndarray:
    from mitpiv.io.tiff import frame_stack, load_frame

    stack = frame_stack(images, n_cam, owner=owner)
    frames = [[np.asarray(f) if not isinstance(f, str | Path) else load_frame(f) for f in cam] for cam in stack]
    shapes = {f.shape for cam in frames for f in cam}
    if len(shapes) != 1:
        raise ConfigError(f"{owner}: the cameras' frames have the shapes {sorted(shapes)}; a DaVis buffer holds "
                          "frames of one size. Give cameras of one resolution (or crop the images to one size).")
    return np.stack([np.stack(cam) for cam in frames])  # (n_cam, n_frames, H, W)


def _pixel_dtype(a: np.ndarray) -> np.dtype:
    if not np.all(np.isfinite(a)):
        raise ConfigError("write_davis_images: 'images' holds NaN or infinite values; re-render or re-quantise them.")
    if np.issubdtype(a.dtype, np.integer) or np.all(a == np.rint(a)):
        if a.min(initial=0) >= 0 and a.max(initial=0) <= 65535:
            return np.dtype(np.uint16)
    return np.dtype(np.float32)


def _image_buffers(stack: np.ndarray, sensors, times_s, attributes: dict | None):
    lv = _lv()
    dtype = _pixel_dtype(stack)
    buffers = []
    for f in range(stack.shape[1]):
        b = lv.arrays_to_buffer([np.ascontiguousarray(stack[c, f], dtype=dtype) for c in range(stack.shape[0])])
        t = _us(times_s[f])
        b.attributes.update({"AcqTimeSeries": t, **(attributes or {})})
        for c, fr in enumerate(b.frames):
            fr.attributes.update({"AcqTimeSeries": t, "CameraName": str(sensors[c])})
            fr.scales.x.description, fr.scales.y.description, fr.scales.i.description = "x", "y", "intensity"
        buffers.append(b)
    return buffers, dtype


def _check_times(times_s, n: int, owner: str) -> np.ndarray:
    t = np.asarray(times_s, dtype=np.float64).reshape(-1) if times_s is not None else None
    if t is None or t.size != n or not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0):
        raise ConfigError(f"{owner}: 'times_s' must hold {n} finite, non-decreasing frame times [s] (one per time "
                          f"step), got {times_s!r}.")
    return t


def _check_sensors(sensors, n_cam: int, owner: str) -> list[str]:
    if isinstance(sensors, str) or not isinstance(sensors, Sequence) or len(sensors) != n_cam:
        raise ConfigError(f"{owner}: 'sensors' must name the {n_cam} cameras of 'images' in order (e.g. "
                          f"['cam0', 'cam1']), got {sensors!r}.")
    names = [str(s) for s in sensors]
    for s in names:
        try:
            s.encode("latin-1")
        except UnicodeEncodeError:
            raise ConfigError(f"{owner}: sensor name {s!r} is not latin-1 (DaVis attributes are); rename it.") from None
    return names


def write_davis_images(out_dir, images, *, sensors, times_s, name: str = IMAGE_SET,
                       attributes: dict | None = None) -> dict:
    """Write a run's multi-camera frames as a DaVis image set ``out_dir/<name>.set`` +
    ``out_dir/<name>/B<nnnnn>.im7`` (module notes: one buffer per time step, one frame per
    camera, ``AcqTimeSeries`` times, pixel scales). ``out_dir`` is replaced atomically.

    Parameters
    ----------
    out_dir : str or Path
        The folder to write (created; a new or empty folder, or an earlier DaVis output,
        which is replaced whole: :func:`replace_dir`).
    images : sequence or array
        One sequence of frames per camera, each an (H, W) array (counts or radiance) or an
        EXR path; or an array (n_cameras, n_frames, H, W). Every frame the same size.
    sensors : sequence of str
        The cameras' names (``CameraName``), in the order of ``images``.
    times_s : (n_frames,) float
        The time of each step [s] (finite, non-decreasing).
    name : str
        The set's name.
    attributes : dict, optional
        More buffer attributes (str -> str), e.g. the source run.

    Returns
    -------
    dict
        ``set`` (the .set path), ``n_cameras``, ``n_frames``, ``shape`` (H, W), ``dtype``,
        ``times_s``, ``sensors``.
    """
    out = Path(out_dir)
    with replace_dir(out) as tmp:
        m = write_image_set(tmp, images, sensors=sensors, times_s=times_s, name=name, attributes=attributes)
    m["set"] = str(out / f"{name}.set")
    return m


def write_image_set(folder, images, *, sensors, times_s, name: str = IMAGE_SET,
                    attributes: dict | None = None) -> dict:
    """:func:`write_davis_images` into an existing ``folder`` (not atomic by itself: for a
    writer that fills a temporary folder of its own, as the run export does); everything is
    checked before lvpyio writes."""
    owner = "write_davis_images"
    n_cam = len(images) if not isinstance(images, np.ndarray) else images.shape[0]
    names = _check_sensors(sensors, n_cam, owner)
    stack = _image_stack(images, n_cam, owner)
    t = _check_times(times_s, stack.shape[1], owner)
    buffers, dtype = _image_buffers(stack, names, t, attributes)
    _lv().write_set(buffers, str(Path(folder) / name))
    log.debug("DaVis image set: %d cameras x %d frames -> %s", n_cam, stack.shape[1], folder)
    return {"set": str(Path(folder) / f"{name}.set"), "n_cameras": n_cam, "n_frames": int(stack.shape[1]),
            "shape": list(stack.shape[2:]), "dtype": dtype.name, "times_s": t.tolist(), "sensors": names}


def read_davis_images(path) -> dict:
    """Read a DaVis image set (or one ``.im7`` / ``.imx`` buffer) into arrays.

    Returns
    -------
    dict
        ``images`` (n_cameras, n_frames, H, W) in the file's dtype (the raw pixels; the
        intensity scale is in ``intensity_scale``), ``times_s`` (n_frames,) from
        ``AcqTimeSeries`` (NaN where a buffer has none), ``sensors`` (``CameraName`` of each
        frame of the first buffer, ``frame<k>`` without one), ``pixel_unit``,
        ``intensity_scale`` (slope, offset, unit), ``source``.

    Raises
    ------
    FileFormatError
        A missing path, not a DaVis file, a vector set or particle field, or buffers whose
        frames differ in number or size.
    """
    owner = "read_davis_images"
    p = _check_exists(path, owner)
    if p.is_file() and p.suffix.lower() != ".set":
        buffers = [_read_buffer(p, owner)]
    else:
        s = _read_set(p, owner)
        if s.type_id not in ("SET_TYPE_ID_IMAGE", "SET_TYPE_ID_RECORDING"):
            raise FileFormatError(f"{owner}: {str(p)!r} is a DaVis {s.type_id} set, not an image set; read vector "
                                  "sets with read_davis_vectors.")
        buffers = [s[i] for i in range(len(s))]
    frames, times, shape0 = [], [], None
    for k, b in enumerate(buffers):
        if b[0].type_id != "ImageFrame":
            raise FileFormatError(f"{owner}: {str(p)!r} holds vector fields, not images; read it with "
                                  "read_davis_vectors.")
        imgs = [fr.images[0] for fr in b.frames]
        shape = (len(imgs), imgs[0].shape)
        if shape0 is None:
            shape0 = shape
        elif shape != shape0:
            raise FileFormatError(f"{owner}: buffer {k} of {str(p)!r} has {shape[0]} frames of {shape[1]}, buffer 0 "
                                  f"{shape0[0]} of {shape0[1]}; give a set of one camera layout.")
        frames.append(imgs)
        t = _parse_time(b[0].attributes.get("AcqTimeSeries"))
        if t is None:
            t = _parse_time(b.attributes.get("AcqTimeSeries"))
        times.append(np.nan if t is None else t)
    first = buffers[0][0]
    images = np.stack([np.stack(f) for f in frames], axis=1)
    sensors = [str(fr.attributes.get("CameraName") or f"frame{c}") for c, fr in enumerate(buffers[0].frames)]
    sc = first.scales
    return {"images": images, "times_s": np.asarray(times, dtype=np.float64), "sensors": sensors,
            "pixel_unit": sc.x.unit, "intensity_scale": (sc.i.slope, sc.i.offset, sc.i.unit), "source": str(p)}


# --------------------------------------------------------------------------------------- vectors
@dataclass
class DavisVectors:
    """A DaVis vector field in world coordinates (module notes for the conventions).

    Attributes
    ----------
    x, y, z : 1-D float64 arrays
        Coordinates of the vectors, ascending, in ``length_unit`` (``z`` has length 1 for
        a planar field).
    u, v, w : float64 (nz, ny, nx) arrays
        Components in ``velocity_unit``; NaN where a vector is not enabled (``w`` of a 2C
        field: zeros everywhere).
    enabled : bool (nz, ny, nx) array
        DaVis's ENABLED and MASK (and the active choice's data).
    length_unit, velocity_unit : str
        The scales' unit strings (e.g. ``"mm"``, ``"m/s"``; ``"pixel"`` for an
        uncalibrated field).
    dt_s : float or None
        The frame separation [s] (``FrameDt``), None when the file does not record it.
    n_components : int
        2 or 3.
    source : str
        The path read.
    """

    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    u: np.ndarray
    v: np.ndarray
    w: np.ndarray
    enabled: np.ndarray
    length_unit: str
    velocity_unit: str
    dt_s: float | None
    n_components: int
    source: str


def _axis(n: int, grid: int, scale, planar: bool = False) -> np.ndarray:
    if planar:
        return np.array([float(scale.offset)])
    return (np.arange(n) + 0.5) * float(grid) * float(scale.slope) + float(scale.offset)


def read_davis_vectors(path, *, frame: int = 0) -> DavisVectors:
    """Read a DaVis vector field (2D-2C, 2D-3C, or a 3D-3C volume) into world coordinates.

    Parameters
    ----------
    path : str or Path
        A ``.vc7`` / ``.vec`` file, or a vector set (``.set`` file or its folder).
    frame : int
        The buffer (time step) of a set; 0 for a single file.

    Returns
    -------
    DavisVectors

    Raises
    ------
    FileFormatError
        A missing path, not a DaVis file, an image set or particle field, a field without
        vectors.
    ConfigError
        ``frame`` out of range.
    """
    owner = "read_davis_vectors"
    p = _check_exists(path, owner)
    if isinstance(frame, bool) or not isinstance(frame, int | np.integer) or frame < 0:
        raise ConfigError(f"{owner}: 'frame' must be an integer >= 0 (the buffer of a set), got {frame!r}.")
    if p.is_file() and p.suffix.lower() != ".set":
        if frame != 0:
            raise ConfigError(f"{owner}: {str(p)!r} is one buffer; 'frame' must be 0, got {frame}.")
        b = _read_buffer(p, owner)
    else:
        s = _read_set(p, owner)
        if s.type_id != "SET_TYPE_ID_VECTOR":
            raise FileFormatError(f"{owner}: {str(p)!r} is a DaVis {s.type_id} set, not a vector set; read image sets "
                                  "with read_davis_images.")
        if frame >= len(s):
            raise ConfigError(f"{owner}: 'frame' {frame} is out of range: the set {str(p)!r} has {len(s)} buffers "
                              f"(0..{len(s) - 1}).")
        b = s[frame]
    fr = b[0]
    if fr.type_id != "VectorFrame":
        raise FileFormatError(f"{owner}: {str(p)!r} holds images, not vectors; read it with read_davis_images.")
    nz = len(fr)
    ny, nx = fr.shape
    is3c = bool(fr.is_3c)
    u, v, w = (np.zeros((nz, ny, nx)) for _ in range(3))
    enabled = np.zeros((nz, ny, nx), dtype=bool)
    for k in range(nz):  # one masked structured array per plane (lvpyio's choice and scale handling)
        m = fr.as_masked_array(k)
        enabled[k] = ~np.broadcast_to(np.ma.getmaskarray(m)["u"], (ny, nx))
        u[k], v[k] = np.asarray(m["u"].data, float), np.asarray(m["v"].data, float)
        if is3c:
            w[k] = np.asarray(m["w"].data, float)
    sc, g = fr.scales, fr.grid
    x = _axis(nx, g.x, sc.x)
    y = _axis(ny, g.y, sc.y)
    z = _axis(nz, g.z, sc.z, planar=nz == 1)
    # every axis ascending (DaVis rows run top-down; its y usually points up)
    for ax, c in ((2, x), (1, y), (0, z)):
        if c.size > 1 and c[1] < c[0]:
            u, v, w, enabled = (np.flip(a, axis=ax) for a in (u, v, w, enabled))
    x, y, z = (np.sort(c) for c in (x, y, z))
    for a in (u, v, w) if is3c else (u, v):  # a 2C field's w stays zero (not a measured component)
        a[~enabled] = np.nan
    dt = _parse_time(b.attributes.get("FrameDt"))
    if dt is None:
        dt = _parse_time(fr.attributes.get("FrameDt"))
    return DavisVectors(x=x, y=y, z=z, u=np.ascontiguousarray(u), v=np.ascontiguousarray(v),
                        w=np.ascontiguousarray(w), enabled=np.ascontiguousarray(enabled), length_unit=str(sc.x.unit),
                        velocity_unit=str(sc.i.unit), dt_s=dt, n_components=3 if is3c else 2, source=str(p))


def _uniform(c, name: str, n: int, owner: str) -> tuple[float, float]:
    """(first, spacing) of a uniform ascending axis of length n (spacing 1 when n == 1)."""
    a = np.asarray(c, dtype=np.float64).reshape(-1)
    if a.size != n or not np.all(np.isfinite(a)):
        raise ConfigError(f"{owner}: '{name}' must hold {n} finite coordinates (the components' shape "
                          f"(nz, ny, nx) sets it), got {a.size}.")
    if n == 1:
        return float(a[0]), 1.0
    d = np.diff(a)
    step = float(np.mean(d))
    if not step > 0 or np.max(np.abs(d - step)) > 1e-6 * abs(step):
        raise ConfigError(f"{owner}: '{name}' must be ascending with a uniform spacing (a DaVis grid), got spacings "
                          f"{d.min():g}..{d.max():g}; resample the field onto a uniform grid first.")
    return float(a[0]), step


def write_davis_vectors(path, x, y, z, u, v, w=None, *, enabled=None, length_unit: str = "mm",
                        velocity_unit: str = "m/s", dt_s: float | None = None,
                        attributes: dict | None = None) -> Path:
    """Write a vector field as a DaVis ``.vc7`` buffer (conventions in the module notes).

    Parameters
    ----------
    path : str or Path
        The ``.vc7`` file (written atomically).
    x, y, z : 1-D arrays
        Ascending, uniformly spaced coordinates [``length_unit``]; ``z`` of length 1 (or
        None, z = 0) for a planar field.
    u, v, w : (nz, ny, nx) or (ny, nx) arrays
        Components [``velocity_unit``]; ``w`` None for a 2C field. NaN marks a vector as
        not enabled.
    enabled : bool array, optional
        Valid vectors (default: where every component is finite).
    length_unit, velocity_unit : str
        The units written into the scales.
    dt_s : float, optional
        The frame separation [s], written as ``FrameDt``.
    attributes : dict, optional
        More buffer attributes (str -> str).

    Returns
    -------
    Path
    """
    owner = "write_davis_vectors"
    lv = _lv()
    path = Path(path)
    if path.suffix.lower() != ".vc7":
        raise ConfigError(f"{owner}: 'path' must end in .vc7 (a DaVis vector buffer), got {str(path)!r}.")
    comps = []
    for name, c in (("u", u), ("v", v), ("w", w)):
        if c is None:
            comps.append(None)
            continue
        a = np.asarray(c, dtype=np.float64)
        if a.ndim == 2:
            a = a[None]
        if a.ndim != 3 or 0 in a.shape:
            raise ConfigError(f"{owner}: '{name}' must be an (nz, ny, nx) or (ny, nx) array, got shape {np.shape(c)}.")
        comps.append(a)
    shape = comps[0].shape
    for name, a in zip("vw", comps[1:], strict=True):
        if a is not None and a.shape != shape:
            raise ConfigError(f"{owner}: '{name}' has shape {a.shape}, 'u' has {shape}; give components of one shape.")
    nz, ny, nx = shape
    x0, dx = _uniform(x, "x", nx, owner)
    y0, dy = _uniform(y, "y", ny, owner)
    z0, dz = _uniform([0.0] if z is None else z, "z", nz, owner)
    finite = np.all([np.isfinite(a) for a in comps if a is not None], axis=0)
    ok = finite if enabled is None else np.asarray(enabled, dtype=bool).reshape(shape) & finite
    if dt_s is not None and not (np.isfinite(dt_s) and dt_s > 0):
        raise ConfigError(f"{owner}: 'dt_s' must be a positive time [s] or None, got {dt_s!r}.")
    # rows top-down with y up: row r at y[ny - 1 - r]; the stored V is minus the world v
    dtype = lv.vec3c if comps[2] is not None else lv.vec2c
    planes = np.zeros(shape, dtype=dtype)
    planes["u"] = np.where(ok, comps[0], 0.0)
    planes["v"] = -np.where(ok, comps[1], 0.0)
    if comps[2] is not None:
        planes["w"] = np.where(ok, comps[2], 0.0)
    planes = np.ascontiguousarray(planes[:, ::-1, :])
    b = lv.arrays_to_buffer(planes)
    fr = b[0]
    en = np.ascontiguousarray(ok[:, ::-1, :]).astype(np.uint8)
    for k in range(nz):
        fr.components["ENABLED"].planes[k][...] = en[k]
    fr.grid.x = fr.grid.y = fr.grid.z = 1
    sx, sy, sz, si = fr.scales.x, fr.scales.y, fr.scales.z, fr.scales.i
    sx.slope, sx.offset, sx.unit, sx.description = dx, x0 - 0.5 * dx, length_unit, "x"
    sy.slope, sy.offset, sy.unit, sy.description = -dy, y0 + (ny - 0.5) * dy, length_unit, "y"
    if nz == 1:
        sz.slope, sz.offset = 1.0, z0
    else:
        sz.slope, sz.offset = dz, z0 - 0.5 * dz
    sz.unit, sz.description = length_unit, "z"
    si.slope, si.offset, si.unit, si.description = 1.0, 0.0, velocity_unit, "velocity"
    for key, comp in fr.components.items():
        if key[0] in "UVW" and key[1:].isdigit():
            comp.scale.slope, comp.scale.offset, comp.scale.unit = 1.0, 0.0, velocity_unit
    b.attributes.update(attributes or {})
    if dt_s is not None:
        b.attributes["FrameDt"] = f"{dt_s * 1e6:.9g} µs"
    with atomic_path(path, suffix=".vc7") as tmp:
        lv.write_buffer(b, str(tmp))
    return path


# ------------------------------------------------------------------------------------- particles
def _particle_field(path, owner: str):
    lv = _lv()
    p = _check_exists(path, owner)
    s = _set_path(p, owner)
    try:
        return lv.read_particles(str(s)), s
    except (RuntimeError, ValueError, TypeError) as e:
        raise FileFormatError(f"{owner}: {str(s)!r} is not a DaVis particle field lvpyio can read ({e}); give a "
                              "particle field (.set) of DaVis's STB / IPR, or one of write_davis_particles. Image "
                              "and vector sets read with read_davis_images / read_davis_vectors.") from None


def read_davis_particles(path) -> dict:
    """Read a DaVis particle field's tracks (lvpyio ``read_particles``) into dense arrays.

    Returns
    -------
    dict
        ``positions_mm`` (n_tracks, n_frames, 3) float64, NaN where a track is absent;
        ``times_s`` (n_frames,); ``intensity`` (n_tracks, n_frames); ``velocities_mm_s``
        (n_tracks, n_frames, 3) or None (track scalars Vx / Vy / Vz or U / V / W);
        ``track_start`` (n_tracks,) the first frame of each track; ``length_unit`` (the file's),
        ``source``. Multi-pulse fields (2 or 4 pulses per step) have ``n_frames`` = steps x
        pulses, in time order.

    Raises
    ------
    FileFormatError
        A missing path, not a particle field, a field without tracks (IPR), or positions in
        a unit that is not a length (``pixel``).
    """
    owner = "read_davis_particles"
    pf, s = _particle_field(path, owner)
    times = np.asarray(pf.times(), dtype=np.float64)
    pulses = 1 if times.ndim == 1 else times.shape[1]
    times = times.reshape(-1)
    if pf.track_count == 0:
        raise FileFormatError(f"{owner}: {str(s)!r} holds particles without tracks (an IPR field); read its time "
                              "steps with lvpyio.read_particles(path)[i].particles.")
    unit = str(pf.scales.x.unit)
    if unit not in LENGTH_MM:
        raise FileFormatError(f"{owner}: the particle positions of {str(s)!r} are in {unit!r}, not a length "
                              f"({sorted(LENGTH_MM)}); calibrate the field in DaVis first.")
    to_mm = LENGTH_MM[unit]
    tracks = pf.tracks()
    n = len(times)
    pos = np.full((len(tracks), n, 3), np.nan)
    inten = np.full((len(tracks), n), np.nan)
    names = {k.lower(): k for k in pf.scalar_scales}
    vkeys = next(([names[a], names[b], names[c]] for a, b, c in (("vx", "vy", "vz"), ("u", "v", "w"))
                  if a in names and b in names and c in names), None)
    vel = np.full((len(tracks), n, 3), np.nan) if vkeys else None
    v_mm = 1.0
    if vkeys:
        vu = str(pf.scalar_scales[vkeys[0]].unit)
        if vu not in VELOCITY_MM_S:
            raise FileFormatError(f"{owner}: the track velocities of {str(s)!r} are in {vu!r}, not one of "
                                  f"{sorted(VELOCITY_MM_S)}.")
        v_mm = VELOCITY_MM_S[vu]
    starts = np.zeros(len(tracks), dtype=np.int64)
    for i, tr in enumerate(tracks):
        st = tr.start if pulses == 1 else (tr.start * pulses if isinstance(tr.start, int)
                                           else tr.start[0] * pulses + tr.start[1])
        starts[i] = st
        m = len(tr.particles)
        pa = tr.particles
        pos[i, st:st + m] = np.column_stack([pa["x"], pa["y"], pa["z"]]).astype(np.float64) * to_mm
        inten[i, st:st + m] = pa["intensity"]
        if vkeys:
            vel[i, st:st + m] = np.column_stack([np.asarray(tr.scalars[k], float) for k in vkeys]) * v_mm
    return {"positions_mm": pos, "times_s": times, "intensity": inten, "velocities_mm_s": vel,
            "track_start": starts, "length_unit": unit, "source": str(s)}


def write_davis_particles(out_dir, positions_mm, times_s, *, velocities_mm_s=None, intensity=None,
                          name: str = PARTICLE_SET, attributes: dict | None = None) -> Path:
    """Write tracks as a DaVis time-resolved particle field (lvpyio ``write_particles``):
    ``out_dir/<name>.set`` and ``out_dir/<name>/``, ``out_dir`` replaced atomically.

    Parameters
    ----------
    positions_mm : (n_tracks, n_frames, 3) float
        Positions [mm], NaN where a track is absent; each track one contiguous run of at
        least 2 frames (lvpyio's tracks have no gaps).
    times_s : (n_frames,) float
        Frame times [s], increasing.
    velocities_mm_s : (n_tracks, n_frames, 3), optional
        Written as the track scalars Vx, Vy, Vz [m/s].
    intensity : (n_tracks, n_frames), optional
        Particle intensities (default 1).

    Returns
    -------
    Path
        The ``.set`` file.
    """
    owner = "write_davis_particles"
    lv = _lv()
    pos = np.asarray(positions_mm, dtype=np.float64)
    if pos.ndim != 3 or pos.shape[2] != 3 or 0 in pos.shape[:2]:
        raise ConfigError(f"{owner}: 'positions_mm' must be an (n_tracks, n_frames, 3) array, got shape "
                          f"{np.shape(positions_mm)}.")
    nt, nf = pos.shape[:2]
    t = np.asarray(times_s, dtype=np.float64).reshape(-1)
    if t.size != nf or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise ConfigError(f"{owner}: 'times_s' must hold {nf} increasing finite times [s] (one per frame of "
                          f"'positions_mm'), got {times_s!r}.")
    vel = None if velocities_mm_s is None else np.asarray(velocities_mm_s, dtype=np.float64)
    if vel is not None and vel.shape != pos.shape:
        raise ConfigError(f"{owner}: 'velocities_mm_s' has shape {vel.shape}, 'positions_mm' {pos.shape}; give one "
                          "velocity per position.")
    inten = np.ones((nt, nf)) if intensity is None else np.asarray(intensity, dtype=np.float64)
    if inten.shape != (nt, nf):
        raise ConfigError(f"{owner}: 'intensity' must have shape {(nt, nf)}, got {inten.shape}.")
    present = np.all(np.isfinite(pos), axis=2)
    tracks = []
    for i in range(nt):
        idx = np.flatnonzero(present[i])
        if idx.size < 2 or idx[-1] - idx[0] + 1 != idx.size:
            raise ConfigError(f"{owner}: track {i} is present in frames {idx.tolist()}; a DaVis track is one "
                              "contiguous run of at least 2 frames. Split it into tracks without gaps, or drop it.")
        a, e = int(idx[0]), int(idx[-1]) + 1
        p = np.zeros(e - a, dtype=lv.particle_t)
        p["x"], p["y"], p["z"] = pos[i, a:e, 0], pos[i, a:e, 1], pos[i, a:e, 2]
        p["intensity"] = inten[i, a:e]
        sc = {} if vel is None else {k: (vel[i, a:e, j] / 1000.0).astype(np.float32)
                                     for j, k in enumerate(("Vx", "Vy", "Vz"))}
        tracks.append(lv.Track(a, p, sc))
    mm = [lv.Scale(1.0, 0.0, "mm", d) for d in ("X", "Y", "Z")]
    field = {"times": t, "tracks": tracks, "scales": lv.Scales(*mm, lv.Scale(1.0, 0.0, "counts", "intensity"))}
    if vel is not None:
        field["scalar_scales"] = {k: lv.Scale(1.0, 0.0, "m/s", k) for k in ("Vx", "Vy", "Vz")}
    if attributes:
        field["attributes"] = {str(k): str(v) for k, v in attributes.items()}
    out = Path(out_dir)
    with replace_dir(out) as tmp:
        lv.write_particles(field, str(tmp / name))
    return out / f"{name}.set"


# ----------------------------------------------------------------------------------- calibration
def write_plate_description(path, target, z_positions_mm, *, origin_mm=(0.0, 0.0), plate_normal: str = "+z") -> dict:
    """Write the description of a dot calibration plate as DaVis's calibration wizard asks
    for it (a JSON file; the same fields in words go into the export's README).

    Parameters
    ----------
    path : str or Path
        The JSON file (written atomically).
    target : CalibrationTarget
        A ``"dots"`` target (:class:`mitpiv.physics.targets.CalibrationTarget`).
    z_positions_mm : sequence of float
        The plate's z positions (world mm), one per calibration view.
    origin_mm : (2,) float
        World (x, y) of the plate's centre dot (the origin mark to pick in the wizard).
    plate_normal : str
        The side the plate faces (the cameras' side).

    Returns
    -------
    dict
        What was written.
    """
    from mitpiv.io.records import write_json

    if getattr(target, "kind", None) != "dots":
        raise ConfigError(f"write_plate_description: 'target' must be a dot plate (CalibrationTarget kind 'dots'), "
                          f"got {getattr(target, 'kind', type(target).__name__)!r}; DaVis's wizard calibrates on "
                          "dot (or cross) plates.")
    z = [float(v) for v in np.asarray(z_positions_mm, dtype=float).reshape(-1)]
    if not z:
        raise ConfigError("write_plate_description: 'z_positions_mm' is empty; give the plate's z positions.")
    desc = {
        "plate_type": "custom, single-level (one plane of dots), moved along z (traverse)",
        "mark_type": "circular dots, white on black",
        "dot_spacing_mm": float(target.spacing_mm),
        "dot_diameter_mm": float(target.dot_diameter),
        "dots_x": int(target.cols), "dots_y": int(target.rows),
        "plate_size_mm": [float(v) for v in target.size_mm],
        "reference_mark": "none: pick the centre dot as origin, and its neighbours in +x (right) and +y (up)",
        "origin_dot_world_mm": [float(origin_mm[0]), float(origin_mm[1])],
        "number_of_levels": 1, "level_separation_mm": 0.0, "plate_thickness_mm": 0.0,
        "z_positions_mm": z, "plate_faces": plate_normal,
        "axes": "world x right, y up, z towards the cameras (right-handed); mitpiv's world frame",
    }
    write_json(path, desc)
    return desc
