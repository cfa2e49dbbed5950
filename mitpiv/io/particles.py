"""Particle files: PLY for Mitsuba's ``ellipsoids`` shape, NPZ/CSV ground truth.

PLY layout (binary little-endian, one ``vertex`` per particle, all float32), as Mitsuba's
``ellipsoids`` shape expects: ``x y z nx ny nz diameter scale_0 scale_1 scale_2 rot_0 rot_1
rot_2 rot_3``. ``x y z`` is the centre [mm]; ``diameter`` the physical diameter [um]
(exposed by the shape as the attribute ``diameter``); ``scale_i = ln(proxy radius [mm])``
(Mitsuba applies an exponential); the quaternion is the identity. The proxy sphere only
makes particles visible to camera rays: the ``tracer_particles`` emitter normalises its
radiance by the proxy's projected area, so images do not depend on the proxy radius.
Scenes must set ``<float name="extent" value="1"/>`` on the shape so that the proxy radius
is the stored one (any extent works physically; 1 keeps it as written).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError, FileFormatError, check_positive
from mitpiv.io.arrays import json_entry, read_npz, write_npz
from mitpiv.io.atomic import atomic_path
from mitpiv.io.records import to_jsonable

__all__ = ["write_particles_ply", "read_particles_ply", "write_truth", "read_truth", "read_particles_csv", "PLY_FIELDS"]

PLY_FIELDS = ("x", "y", "z", "nx", "ny", "nz", "diameter", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3")


def write_particles_ply(path, positions_mm, diameters_um, *, proxy_radius_mm: float) -> Path:
    """Write particles as a PLY file that Mitsuba's ``ellipsoids`` shape reads (atomic).

    Parameters
    ----------
    positions_mm : (N, 3) array
        Particle centres [mm].
    diameters_um : (N,) array or float
        Physical diameters [um].
    proxy_radius_mm : float
        Radius of the proxy sphere [mm] used for camera-ray intersection. Choose it
        well below the pixel footprint (e.g. 0.1-0.3 of it).
    """
    pos = np.asarray(positions_mm, dtype=np.float64)
    if pos.ndim != 2 or pos.shape[1] != 3:
        raise ConfigError(f"write_particles_ply: positions_mm must have shape (N, 3), got {pos.shape}.")
    n = pos.shape[0]
    diam = np.broadcast_to(np.asarray(diameters_um, dtype=np.float64), (n,))
    if not np.all(np.isfinite(pos)):
        raise ConfigError("write_particles_ply: positions_mm contain non-finite values.")
    if n and not np.all(diam > 0):
        raise ConfigError("write_particles_ply: diameters_um must all be > 0.")
    r = check_positive("proxy_radius_mm", proxy_radius_mm, owner="write_particles_ply", unit="mm")
    data = np.zeros((n, len(PLY_FIELDS)), dtype="<f4")
    data[:, 0:3] = pos
    data[:, 6] = diam
    data[:, 7:10] = np.log(r)
    data[:, 10] = 1.0  # quaternion (w, x, y, z) = identity: rot_0 is the real part
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        "comment mitpiv tracer particles: x y z [mm], diameter [um], scale = ln(proxy radius [mm])\n"
        f"element vertex {n}\n" + "".join(f"property float {f}\n" for f in PLY_FIELDS) + "end_header\n"
    )
    path = Path(path)
    with atomic_path(path, suffix=".ply") as tmp:
        with open(tmp, "wb") as f:
            f.write(header.encode("ascii"))
            f.write(data.tobytes())
    return path


def read_particles_ply(path) -> dict:
    """Read a particle PLY written by :func:`write_particles_ply`.

    Returns a dict with ``positions_mm`` (N, 3), ``diameters_um`` (N,) and
    ``proxy_radius_mm`` (N,). Raises :class:`FileFormatError` for a missing or malformed file.
    """
    path = Path(path)
    if not path.is_file():
        raise FileFormatError(f"particle file {str(path)!r} does not exist.")
    raw = path.read_bytes()
    end = raw.find(b"end_header\n")
    if not raw.startswith(b"ply\n") or end < 0:
        raise FileFormatError(f"particle file {str(path)!r} is not a PLY file (no 'ply' / 'end_header').")
    lines = raw[:end].decode("ascii", "replace").splitlines()
    if "format binary_little_endian 1.0" not in lines:
        raise FileFormatError(f"particle file {str(path)!r} must be binary little-endian PLY.")
    count = None
    props = []
    for ln in lines:
        parts = ln.split()
        if parts[:2] == ["element", "vertex"]:
            count = int(parts[2])
        elif parts[:1] == ["property"]:
            if parts[1] != "float":
                raise FileFormatError(f"particle file {str(path)!r}: property {parts[-1]} must be float.")
            props.append(parts[-1])
    if count is None or tuple(props) != PLY_FIELDS:
        raise FileFormatError(
            f"particle file {str(path)!r} has properties {props}; expected {list(PLY_FIELDS)}."
        )
    body = raw[end + len(b"end_header\n") :]
    need = count * len(PLY_FIELDS) * 4
    if len(body) != need:
        raise FileFormatError(
            f"particle file {str(path)!r} is truncated or padded: {len(body)} data bytes for "
            f"{count} particles ({need} expected)."
        )
    data = np.frombuffer(body, dtype="<f4").reshape(count, len(PLY_FIELDS)).astype(np.float64)
    bad = ~np.isfinite(data[:, [0, 1, 2, 6, 7]]).all(axis=1)
    if bad.any():
        raise FileFormatError(f"particle file {str(path)!r}: {int(bad.sum())} of {count} particles have a non-finite "
                              f"position, diameter or proxy radius (the first: particle {int(np.argmax(bad))}); expected "
                              f"finite float32 values as write_particles_ply writes them.")
    if count and not (data[:, 6] > 0).all():
        raise FileFormatError(f"particle file {str(path)!r}: {int((data[:, 6] <= 0).sum())} particles have a diameter "
                              f"<= 0; expected positive diameters [um].")
    return {
        "positions_mm": data[:, 0:3].copy(),
        "diameters_um": data[:, 6].copy(),
        "proxy_radius_mm": np.exp(data[:, 7]),
    }


def write_truth(path, *, positions_mm, times_s, diameters_um, velocities_mm_s=None, flow: dict | None = None,
                extra: dict | None = None, accelerations_mm_s2=None, ids=None) -> Path:
    """Write ground truth for F frames of N particles (atomic): the one truth format of
    every experiment kind (particle images and backlit droplets).

    Parameters
    ----------
    path : str or Path
        ``.npz`` (the format :func:`read_truth` reads) or ``.csv`` (for other software).
    positions_mm : (F, N, 3) array
        Particle centres in every frame [mm]; NaN where particle ``n`` is absent from frame
        ``f`` (time-resolved sequences: particles leave and enter the volume, each column
        one identity throughout).
    times_s : (F,) array
        Frame times [s].
    diameters_um : (N,) array or float
        Physical diameters [um] (micrometres also for millimetre droplets: convert once
        at the boundary, ``diameters_mm * 1e3``).
    velocities_mm_s : (N, 3) or (F, N, 3) array, optional
        Per-particle velocity [mm/s] (e.g. ballistic droplets), or per frame and particle
        (time-resolved sequences); stored when given.
    accelerations_mm_s2 : (F, N, 3) array, optional
        Per frame and particle material acceleration [mm/s^2]; stored when given.
    ids : (N,) integer array, optional
        Particle identities (default: the column index); stored when given.
    flow, extra : dict, optional
        JSON metadata (the flow model, the seeding, ...).

    ``.npz`` entries: ``positions_mm`` (F, N, 3), ``times_s`` (F,), ``diameters_um`` (N,),
    ``displacements_mm`` (F-1, N, 3) between consecutive frames, ``velocities_mm_s``
    (N, 3) when given, and JSON ``flow``/``extra``. ``.csv``: one row per particle with
    the diameter, the positions of every frame, the velocity (when given) and the
    displacement from the first to the last frame (the last three columns).
    """
    pos = np.asarray(positions_mm, dtype=np.float64)
    if pos.ndim != 3 or pos.shape[2] != 3:
        raise ConfigError(f"write_truth: positions_mm must have shape (F, N, 3), got {pos.shape}.")
    times = np.asarray(times_s, dtype=np.float64).reshape(-1)
    if times.shape[0] != pos.shape[0]:
        raise ConfigError(f"write_truth: {pos.shape[0]} frames but {times.shape[0]} times.")
    try:
        diam = np.broadcast_to(np.asarray(diameters_um, dtype=np.float64), (pos.shape[1],))
    except ValueError:
        raise ConfigError(f"write_truth: diameters_um must be one value or one per particle ({pos.shape[1]}), got "
                          f"shape {np.shape(diameters_um)}.") from None
    vel = None
    if velocities_mm_s is not None:
        vel = np.asarray(velocities_mm_s, dtype=np.float64)
        if vel.shape not in ((pos.shape[1], 3), pos.shape):
            raise ConfigError(f"write_truth: velocities_mm_s must have shape (N, 3) = ({pos.shape[1]}, 3) or (F, N, 3) = "
                              f"{pos.shape} [mm/s], got {vel.shape}.")
    acc = None
    if accelerations_mm_s2 is not None:
        acc = np.asarray(accelerations_mm_s2, dtype=np.float64)
        if acc.shape != pos.shape:
            raise ConfigError(f"write_truth: accelerations_mm_s2 must have shape (F, N, 3) = {pos.shape} [mm/s^2], got "
                              f"{acc.shape}.")
    pid = None
    if ids is not None:
        pid = np.asarray(ids)
        if pid.shape != (pos.shape[1],) or not np.issubdtype(pid.dtype, np.integer):
            raise ConfigError(f"write_truth: ids must be ({pos.shape[1]},) integers, got {pid.dtype} {pid.shape}.")
        pid = pid.astype(np.int64)
    path = Path(path)
    if path.suffix == ".npz":
        write_npz(path, {"positions_mm": pos, "times_s": times, "diameters_um": diam,
                         "displacements_mm": np.diff(pos, axis=0), "velocities_mm_s": vel,
                         "accelerations_mm_s2": acc, "ids": pid,
                         "flow": json.dumps(to_jsonable(flow or {})), "extra": json.dumps(to_jsonable(extra or {}))},
                  owner="write_truth")
    elif path.suffix == ".csv":
        with atomic_path(path, suffix=".csv") as tmp:
            with open(tmp, "w", newline="") as f:
                w = csv.writer(f)
                cols = ["id", "diameter_um"]
                for k in range(pos.shape[0]):
                    cols += [f"x{k}_mm", f"y{k}_mm", f"z{k}_mm"]
                if vel is not None and vel.ndim == 3:  # per frame: the first frame's
                    vel = vel[0]
                if vel is not None:
                    cols += ["vx_mm_s", "vy_mm_s", "vz_mm_s"]
                cols += ["dx_mm", "dy_mm", "dz_mm"]
                w.writerow(cols)
                disp = pos[-1] - pos[0]
                parts = [np.arange(pos.shape[1]), diam, *[pos[k] for k in range(pos.shape[0])]]
                rows = np.column_stack([*parts, *([] if vel is None else [vel]), disp])
                for row in rows:
                    w.writerow([int(row[0])] + [repr(float(v)) for v in row[1:]])
    else:
        raise ConfigError(f"write_truth: file name must end in .npz or .csv, got {str(path)!r}.")
    return path


def read_truth(path) -> dict:
    """Read an NPZ truth file written by :func:`write_truth`.

    Returns a dict with ``positions_mm`` (F, N, 3), ``times_s`` (F,), ``diameters_um``
    (N,), ``displacements_mm`` (F-1, N, 3), ``velocities_mm_s`` ((N, 3), (F, N, 3) or
    None when not stored), ``accelerations_mm_s2`` ((F, N, 3) or None), ``ids`` ((N,) or
    None), ``flow`` and ``extra`` (dicts).

    Truth files of earlier backlit runs (``diameters_mm``, ``velocities_mm_s``, no
    displacements or metadata) read too: their diameters are converted to micrometres.
    Raises :class:`FileFormatError` naming the file when it is missing or not a truth file.
    """
    z = read_npz(path, what="truth", required=("positions_mm", "times_s"))
    if "diameters_um" in z:
        diam_um = z["diameters_um"]
    elif "diameters_mm" in z:  # backlit runs before the one truth format
        diam_um = np.asarray(z["diameters_mm"], dtype=np.float64) * 1e3
    else:
        raise FileFormatError(f"{str(path)!r} is not a truth file: it has neither 'diameters_um' nor 'diameters_mm' "
                              f"(it holds {sorted(z)}).")
    pos = z["positions_mm"]
    if pos.ndim != 3 or pos.shape[2] != 3 or diam_um.shape != (pos.shape[1],):
        raise FileFormatError(f"truth file {str(path)!r}: positions_mm {pos.shape} and diameters {diam_um.shape} do "
                              f"not describe F frames of N particles ((F, N, 3) and (N,)).")
    return {"positions_mm": pos, "times_s": z["times_s"], "diameters_um": diam_um,
            "displacements_mm": z["displacements_mm"] if "displacements_mm" in z else np.diff(pos, axis=0),
            "velocities_mm_s": z.get("velocities_mm_s"), "accelerations_mm_s2": z.get("accelerations_mm_s2"),
            "ids": z.get("ids"),
            "flow": json_entry(z, "flow", path, default={}), "extra": json_entry(z, "extra", path, default={})}


#: Column names :func:`read_particles_csv` accepts (first found, case-insensitive).
CSV_COLUMNS = {"x": ("x_mm", "x", "x0_mm"), "y": ("y_mm", "y", "y0_mm"), "z": ("z_mm", "z", "z0_mm"),
               "d": ("diameter_um", "d_um", "diameter", "dp_um")}


def read_particles_csv(path, *, diameter_um: float | None = None, length_unit_mm: float = 1.0) -> dict:
    """Read a user's particle list from CSV: one particle per row, a header naming the columns.

    Parameters
    ----------
    path : str or Path
        CSV file (comma-separated, ``#`` comments allowed). Columns (case-insensitive, any
        order, others ignored): ``x_mm, y_mm, z_mm`` (or ``x, y, z``; also the frame-0
        columns ``x0_mm, ...`` of :func:`write_truth`'s CSV) and optionally
        ``diameter_um`` (or ``d_um``, ``diameter``) [um].
    diameter_um : float, optional
        Diameter of every particle when the file has no diameter column [um].
    length_unit_mm : float
        Millimetres per unit of the position columns (1000 for positions in metres).

    Returns
    -------
    dict
        ``positions_mm`` (N, 3) and ``diameters_um`` (N,), float64.

    Raises
    ------
    FileFormatError
        Missing file, no position columns, non-numeric or non-finite values.
    ConfigError
        No diameter column and no ``diameter_um``, or diameters <= 0.
    """
    path = Path(path)
    if not path.is_file():
        raise FileFormatError(f"read_particles_csv: {str(path)!r} does not exist.")
    lines = [ln for ln in path.read_text().splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    if not lines:
        raise FileFormatError(f"read_particles_csv: {str(path)!r} is empty.")
    header = [h.strip().lower() for h in next(csv.reader([lines[0]]))]
    cols = {}
    for key, names in CSV_COLUMNS.items():
        cols[key] = next((header.index(n) for n in names if n in header), None)
    if any(cols[k] is None for k in "xyz"):
        raise FileFormatError(f"read_particles_csv: {str(path)!r} needs position columns x_mm, y_mm, z_mm (or x, y, "
                              f"z); its header is {header}.")
    try:
        data = np.loadtxt(lines[1:], delimiter=",", ndmin=2, dtype=np.float64,
                          usecols=[cols[k] for k in "xyzd" if cols[k] is not None]) if lines[1:] else np.zeros((0, 0))
    except ValueError as e:
        raise FileFormatError(f"read_particles_csv: {str(path)!r} has a non-numeric value ({e}).") from None
    if data.size == 0:
        data = np.zeros((0, 3 + (cols["d"] is not None)))
    if not np.all(np.isfinite(data)):
        raise FileFormatError(f"read_particles_csv: {str(path)!r} holds NaN or infinite values.")
    pos = data[:, :3] * float(length_unit_mm)
    if cols["d"] is not None:
        diam = data[:, 3]
    elif diameter_um is not None:
        diam = np.full(pos.shape[0], float(diameter_um))
    else:
        raise ConfigError(f"read_particles_csv: {str(path)!r} has no diameter column (diameter_um); give "
                          "diameter_um=... for all particles.")
    if pos.shape[0] and not np.all(diam > 0):
        raise ConfigError(f"read_particles_csv: {str(path)!r}: diameters must be > 0 um, got min {diam.min():g}.")
    return {"positions_mm": pos, "diameters_um": diam}
