"""Other tools' results, read for scoring (:mod:`mitpiv.studies.score`): vector fields and
particles or tracks in the formats PIV and PTV users have.

Vector fields (:func:`read_vectors`, an :class:`ExternalVectors`):

``davis``
    a DaVis vector buffer or set (``.vc7``, ``.set``, a set folder), through LaVision's
    ``lvpyio`` (:func:`mitpiv.io.davis.read_davis_vectors`); units from the file's scales.
``openpiv``
    the text file of ``openpiv.tools.save``: a ``# x y u v flags mask`` header, then one
    row per vector (``flags`` 0 valid, 1 invalid, 2 interpolated; ``mask`` 1 masked). Its
    coordinates are pixels with the origin at the image's top-left corner, the edges of
    pixel ``i`` at ``i`` and ``i + 1`` (OpenPIV's first window of ``W`` pixels is centred at
    ``W / 2``): mitpiv's own pixel convention. Units: ``px`` and ``px`` per frame pair unless
    given (OpenPIV divides by its ``dt``; with the default ``dt = 1`` that is pixels).
``csv``
    a header row naming the columns ``x, y[, z], u, v[, w][, valid]`` (any order, more
    columns ignored; ``valid`` 0 / 1), one row per vector.
``npz``
    arrays ``x, y[, z], u, v[, w][, valid]`` of one shape (scattered rows or a grid), and
    optionally the strings ``length_unit`` / ``velocity_unit`` and the number ``dt_s``.
``hdf5``
    datasets ``x, y[, z], u, v[, w][, valid]`` in the root or the group ``group``; the
    group's attributes ``length_unit``, ``velocity_unit`` and ``dt_s`` when present.

Particles and tracks (:func:`read_tracks`, an :class:`ExternalTracks`):

``davis``
    a DaVis particle field or track set (``lvpyio.read_particles``,
    :func:`mitpiv.io.davis.read_davis_particles`).
``openlpt``
    OpenLPT's track CSV files (a ``results/ConvergeTrack`` folder, an export folder, or
    files; :func:`mitpiv.io.openlpt.read_openlpt_tracks`), in mm.
``openptv``
    OpenPTV's ``ptv_is.<frame>`` files (tracks: a count line, then ``prev next x y z`` per
    particle, ``prev`` / ``next`` the row in the previous / next frame's file, negative for
    none; liboptv's ``write_path_frame``) or ``rt_is.<frame>`` files (particles: a count line,
    then ``id x y z`` and the pixel ids per camera), in the folder (``res``) given. Frame
    ``k`` of the run is the file with the ``k``-th smallest number.
``csv``
    columns ``frame, x, y, z`` (mm unless ``--length-unit`` says otherwise) and optionally
    ``track`` (or ``track_id``): rows with a track
    id are linked into tracks, rows without one are particles of their frame.

Units: every reader returns what the file holds and its unit where the file states it
(``length_unit`` / ``velocity_unit``, None where it does not); the scoring converts, and
refuses a field whose unit it does not know (:func:`mitpiv.studies.score.score`).

Hand-written here: the OpenPIV text, CSV, NPZ and OpenPTV ``ptv_is`` / ``rt_is`` readers (a
few lines each over NumPy / pandas / h5py; no kept library reads these as arrays). DaVis files
go through ``lvpyio`` and HDF5 through ``h5py``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError, FileFormatError

__all__ = ["ExternalVectors", "ExternalTracks", "read_vectors", "read_tracks", "VECTOR_FORMATS", "TRACK_FORMATS",
           "vector_format", "track_format"]

#: Vector-field formats :func:`read_vectors` reads.
VECTOR_FORMATS = ("davis", "openpiv", "csv", "npz", "hdf5")
#: Particle / track formats :func:`read_tracks` reads.
TRACK_FORMATS = ("davis", "openlpt", "openptv", "csv")


@dataclass
class ExternalVectors:
    """A vector field from another tool, as its file holds it.

    Attributes
    ----------
    points : (N, 2) or (N, 3) array
        Vector positions (x, y[, z]) in ``length_unit``.
    vectors : (N, 2) or (N, 3) array
        Components (u, v[, w]) in ``velocity_unit``.
    valid : (N,) bool array
        False where the tool marked a vector invalid or masked.
    length_unit, velocity_unit : str or None
        The units the file states (None where it does not).
    dt_s : float or None
        The time between the frames the file states (None where it does not).
    fmt, source : str
        The format and the file.
    info : dict
        Anything else the reader found (OpenPIV: the number of interpolated vectors).
    """

    points: np.ndarray
    vectors: np.ndarray
    valid: np.ndarray
    length_unit: str | None = None
    velocity_unit: str | None = None
    dt_s: float | None = None
    fmt: str = ""
    source: str = ""
    info: dict = field(default_factory=dict)

    @property
    def dims(self) -> int:
        return int(self.points.shape[1])

    @property
    def components(self) -> int:
        return int(self.vectors.shape[1])


@dataclass
class ExternalTracks:
    """Particles or tracks from another tool.

    Attributes
    ----------
    positions : (n_tracks, n_frames, 3) array
        Positions (NaN where a track is absent; for unlinked particles each row is one
        particle in one frame).
    frames : (n_frames,) array
        The frame of each column, counted from the result's first frame.
    linked : bool
        True when rows are tracks (a particle's identity kept across frames).
    length_unit : str or None
        The unit the file states (None where it does not).
    fmt, source : str
        The format and the file or folder read.
    """

    positions: np.ndarray
    frames: np.ndarray
    linked: bool
    length_unit: str | None = None
    fmt: str = ""
    source: str = ""


def _suffix(p: Path) -> str:
    return p.suffix.lower()


def vector_format(path) -> str:
    """The vector-field format of ``path`` from its name (``.vc7`` / ``.set`` / a folder with a
    ``.set`` beside it: davis; ``.txt`` / ``.vec``: openpiv; ``.csv``, ``.npz``, ``.h5`` /
    ``.hdf5``)."""
    p = Path(path)
    s = _suffix(p)
    if s in (".vc7", ".set", ".im7") or (p.is_dir() and (p.with_suffix(".set").is_file() or any(p.glob("*.vc7")))):
        return "davis"
    table = {".txt": "openpiv", ".vec": "openpiv", ".csv": "csv", ".npz": "npz", ".h5": "hdf5", ".hdf5": "hdf5"}
    if s in table:
        return table[s]
    raise ConfigError(f"score: cannot tell the format of {str(path)!r} from its name; give --format, one of "
                      f"{VECTOR_FORMATS}.")


def track_format(path) -> str:
    """The particle / track format of ``path`` from its name and contents."""
    p = Path(path)
    if p.is_dir():
        if (p / "results" / "ConvergeTrack").is_dir() or any(p.glob("LongTrack*.csv")) or \
                (p / "ConvergeTrack").is_dir():
            return "openlpt"
        if any(p.glob("ptv_is.*")) or any(p.glob("rt_is.*")) or any(p.glob("res/ptv_is.*")):
            return "openptv"
        if p.with_suffix(".set").is_file() or any(p.glob("*.set")):
            return "davis"
    s = _suffix(p)
    if s == ".set":
        return "davis"
    if s == ".csv":
        head = p.read_text(errors="replace").splitlines()[:1] if p.is_file() else [""]
        return "openlpt" if head and "worldx" in head[0].lower().replace(" ", "") else "csv"
    if re.match(r"^(ptv_is|rt_is)\.\d+$", p.name):
        return "openptv"
    raise ConfigError(f"score: cannot tell the particle / track format of {str(path)!r}; give --format, one of "
                      f"{TRACK_FORMATS}.")


def _exists(path) -> Path:
    p = Path(path)
    if not p.exists():
        raise FileFormatError(f"score: {str(p)!r} does not exist; give the result file of your tool.")
    return p


def _columns(cols: dict, src: str, fmt: str) -> tuple[list[str], list[str]]:
    pos = [k for k in ("x", "y", "z") if k in cols]
    vec = [k for k in ("u", "v", "w") if k in cols]
    if pos[:2] != ["x", "y"] or vec[:2] != ["u", "v"]:
        raise FileFormatError(f"score: {src!r} ({fmt}) needs the columns x, y[, z] and u, v[, w]; it has "
                              f"{sorted(cols)[:12]}.")
    if len(pos) != len(vec):
        raise FileFormatError(f"score: {src!r} ({fmt}) has positions {pos} but components {vec}; a 2-D field has "
                              "x, y, u, v and a 3-D one x, y, z, u, v, w.")
    return pos, vec


def _assemble(cols: dict, src: str, fmt: str, **kw) -> ExternalVectors:
    pos, vec = _columns(cols, src, fmt)
    shape = np.shape(cols["x"])
    for k in pos + vec:
        if np.shape(cols[k]) != shape:
            raise FileFormatError(f"score: {src!r}: the arrays {pos + vec} must have one shape; {k!r} is "
                                  f"{np.shape(cols[k])}, x is {shape}.")
    P = np.stack([np.asarray(cols[k], dtype=np.float64).ravel() for k in pos], axis=1)
    V = np.stack([np.asarray(cols[k], dtype=np.float64).ravel() for k in vec], axis=1)
    valid = np.ones(len(P), bool)
    if "valid" in cols:
        valid &= np.asarray(cols["valid"]).ravel().astype(bool)
    valid &= np.all(np.isfinite(P), axis=1) & np.all(np.isfinite(V), axis=1)
    return ExternalVectors(P, V, valid, fmt=fmt, source=src, **kw)


def _read_openpiv(p: Path) -> ExternalVectors:
    try:
        a = np.loadtxt(p, comments="#", ndmin=2)
    except ValueError as e:
        raise FileFormatError(f"score: {str(p)!r} is not an OpenPIV text field (numbers in columns x y u v "
                              f"[flags mask]): {e}") from None
    if a.shape[1] < 4:
        raise FileFormatError(f"score: {str(p)!r} has {a.shape[1]} columns; an OpenPIV field has x y u v "
                              "[flags mask].")
    cols = {"x": a[:, 0], "y": a[:, 1], "u": a[:, 2], "v": a[:, 3]}
    valid = np.ones(len(a), bool)
    if a.shape[1] >= 5:
        valid &= a[:, 4] != 1  # 1: invalid; 2: interpolated (a value, kept)
    if a.shape[1] >= 6:
        valid &= a[:, 5] == 0
    cols["valid"] = valid
    out = _assemble(cols, str(p), "openpiv")
    out.info["interpolated"] = int(np.sum(a[:, 4] == 2)) if a.shape[1] >= 5 else 0
    return out


def _read_csv(p: Path) -> dict:
    import pandas as pd

    try:
        df = pd.read_csv(p, skipinitialspace=True, comment="#")
    except (pd.errors.EmptyDataError, pd.errors.ParserError, UnicodeDecodeError) as e:
        raise FileFormatError(f"score: {str(p)!r} is not a CSV table with a header row: {e}") from None
    return {str(c).strip().lower(): df[c].to_numpy() for c in df.columns}


def _text(v) -> str | None:
    if v is None:
        return None
    if isinstance(v, bytes):
        return v.decode()
    a = np.asarray(v)
    return str(a.item() if a.ndim == 0 else a)


def _read_npz(p: Path) -> ExternalVectors:
    from mitpiv.io import read_npz

    z = read_npz(p, what="vector field")
    cols = {k.lower(): v for k, v in z.items()}
    dt = cols.pop("dt_s", None)
    return _assemble(cols, str(p), "npz", length_unit=_text(cols.pop("length_unit", None)),
                     velocity_unit=_text(cols.pop("velocity_unit", None)),
                     dt_s=None if dt is None else float(np.asarray(dt)))


def _read_hdf5(p: Path, group: str | None) -> ExternalVectors:
    import h5py

    try:
        fh = h5py.File(p, "r")
    except OSError as e:
        raise FileFormatError(f"score: {str(p)!r} is not an HDF5 file: {e}") from None
    with fh:
        g = fh if not group else fh.get(group)
        if g is None or not isinstance(g, h5py.Group):
            raise FileFormatError(f"score: {str(p)!r} has no group {group!r}; its groups: "
                                  f"{[k for k in fh if isinstance(fh[k], h5py.Group)]}.")
        cols = {k.lower(): g[k][()] for k in g if isinstance(g[k], h5py.Dataset)}
        at = {k.lower(): g.attrs[k] for k in g.attrs}
    dt = at.get("dt_s")
    return _assemble(cols, str(p), "hdf5", length_unit=_text(at.get("length_unit")),
                     velocity_unit=_text(at.get("velocity_unit")), dt_s=None if dt is None else float(dt))


def _read_davis_vectors(p: Path, frame: int) -> ExternalVectors:
    from mitpiv.io.davis import read_davis_vectors

    d = read_davis_vectors(p, frame=frame)
    planar = len(d.z) == 1 and not np.any(np.asarray(d.w))
    zz, yy, xx = np.meshgrid(d.z, d.y, d.x, indexing="ij")
    cols = {"x": xx, "y": yy, "u": np.asarray(d.u), "v": np.asarray(d.v), "valid": np.asarray(d.enabled, bool)}
    if not planar:
        cols.update(z=zz, w=np.asarray(d.w))
    return _assemble(cols, str(p), "davis", length_unit=d.length_unit, velocity_unit=d.velocity_unit, dt_s=d.dt_s)


def read_vectors(path, *, fmt: str | None = None, group: str | None = None, frame: int = 0) -> ExternalVectors:
    """Read another tool's vector field (see the module notes for the formats).

    Parameters
    ----------
    path : the file (or a DaVis set folder).
    fmt : one of :data:`VECTOR_FORMATS` (default: from the name, :func:`vector_format`).
    group : the HDF5 group holding the datasets (default the root).
    frame : the frame of a DaVis vector set.

    Raises
    ------
    FileFormatError
        A missing file, or one that does not hold a field in that format (the message names
        the columns it lacks).
    ConfigError
        An unknown format.
    """
    p = _exists(path)
    fmt = fmt or vector_format(p)
    if fmt not in VECTOR_FORMATS:
        raise ConfigError(f"score: --format {fmt!r} is not a vector-field format; use one of {VECTOR_FORMATS}.")
    if fmt == "openpiv":
        out = _read_openpiv(p)
    elif fmt == "csv":
        out = _assemble(_read_csv(p), str(p), "csv")
    elif fmt == "npz":
        out = _read_npz(p)
    elif fmt == "hdf5":
        out = _read_hdf5(p, group)
    else:
        out = _read_davis_vectors(p, frame)
    if out.points.shape[0] == 0:
        raise FileFormatError(f"score: {str(p)!r} holds no vectors.")
    return out


# ------------------------------------------------------------------------------ particles / tracks


def _dense(track_ids, frame_ids, xyz) -> tuple[np.ndarray, np.ndarray]:
    """Rows (track id, frame, x, y, z) as (n_tracks, n_frames, 3), NaN-padded, and the frames."""
    frames, fcol = np.unique(frame_ids, return_inverse=True)
    tids, trow = np.unique(track_ids, return_inverse=True)
    pos = np.full((len(tids), len(frames), 3), np.nan)
    pos[trow, fcol] = xyz
    return pos, frames.astype(np.int64)


def _read_tracks_csv(p: Path) -> ExternalTracks:
    cols = _read_csv(p)
    need = ("frame", "x", "y", "z")
    if not all(k in cols for k in need):
        raise FileFormatError(f"score: {str(p)!r} needs the columns frame, x, y, z [, track]; it has "
                              f"{sorted(cols)[:12]}.")
    fr = np.asarray(cols["frame"], dtype=np.float64)
    if np.any(fr != np.round(fr)) or np.any(fr < 0):
        raise FileFormatError(f"score: {str(p)!r}: the column frame must hold run frame numbers (integers >= 0).")
    xyz = np.stack([np.asarray(cols[k], dtype=np.float64) for k in "xyz"], axis=1)
    tcol = next((k for k in ("track", "track_id", "trackid") if k in cols), None)
    if tcol is None:
        tid = np.arange(len(fr))
        linked = False
    else:
        t = np.asarray(cols[tcol], dtype=np.float64)
        # rows without a track id are particles of their own
        tid = np.where(np.isfinite(t), t, -1.0 - np.arange(len(t)))
        linked = bool(np.isfinite(t).any())
    pos, frames = _dense(tid, fr.astype(np.int64), xyz)
    return ExternalTracks(pos, frames, linked, length_unit="mm", fmt="csv", source=str(p))


def _numbered(folder: Path, stem: str) -> list[tuple[int, Path]]:
    out = []
    for f in folder.glob(f"{stem}.*"):
        num = f.name.split(".", 1)[1]
        if num.isdigit():
            out.append((int(num), f))
    return sorted(out)


def _rows(f: Path, ncol: int) -> np.ndarray:
    lines = f.read_text(errors="replace").split("\n")
    try:
        n = int(lines[0].split()[0])
        a = np.loadtxt(lines[1:1 + n], ndmin=2) if n else np.zeros((0, ncol))
    except (ValueError, IndexError) as e:
        raise FileFormatError(f"score: {str(f)!r} is not an OpenPTV result file (a count line, then one row per "
                              f"particle): {e}") from None
    if a.shape[0] != n or (n and a.shape[1] < ncol):
        raise FileFormatError(f"score: {str(f)!r} announces {n} particles and holds {a.shape[0]} rows of "
                              f"{a.shape[1] if a.ndim == 2 else 0} columns (expected >= {ncol}).")
    return a


def _read_openptv(p: Path) -> ExternalTracks:
    folder = p if p.is_dir() else p.parent
    if p.is_dir() and (p / "res").is_dir() and not (_numbered(p, "ptv_is") or _numbered(p, "rt_is")):
        folder = p / "res"
    files = _numbered(folder, "ptv_is")
    linked = bool(files)
    if not files:
        files = _numbered(folder, "rt_is")
    if not files:
        raise FileFormatError(f"score: {str(folder)!r} holds no OpenPTV ptv_is.* or rt_is.* files; give the "
                              "folder OpenPTV wrote its results to (res).")
    data = [_rows(f, 5 if linked else 4) for _, f in files]
    nf = len(files)
    if not linked:
        rows = [(np.full(len(a), k), a[:, 1:4]) for k, a in enumerate(data)]
        fr = np.concatenate([r[0] for r in rows]).astype(np.int64)
        xyz = np.concatenate([r[1] for r in rows]) if rows else np.zeros((0, 3))
        pos = np.full((len(fr), nf, 3), np.nan)
        pos[np.arange(len(fr)), fr] = xyz
        return ExternalTracks(pos, np.arange(nf), False, length_unit="mm", fmt="openptv", source=str(folder))
    # link: a particle's track is its predecessor's; the frames' rows are numbered globally and the
    # track id of each row found by following prev pointers frame by frame (a loop over frames,
    # vectorised over particles)
    tid_prev = None
    tids, frs, xyzs = [], [], []
    next_id = 0
    for k, a in enumerate(data):
        prev = a[:, 0].astype(np.int64) if len(a) else np.zeros(0, np.int64)
        t = np.empty(len(a), np.int64)
        has = (prev >= 0) & (tid_prev is not None)
        if tid_prev is not None:
            has &= prev < len(tid_prev)
            t[has] = tid_prev[prev[has]]
        new = ~has
        t[new] = next_id + np.arange(new.sum())
        next_id += int(new.sum())
        tids.append(t)
        frs.append(np.full(len(a), k))
        xyzs.append(a[:, 2:5])
        tid_prev = t
    pos, _ = _dense(np.concatenate(tids), np.concatenate(frs), np.concatenate(xyzs))
    if pos.shape[1] != nf:  # frames without a particle
        full = np.full((pos.shape[0], nf, 3), np.nan)
        used = np.unique(np.concatenate(frs))
        full[:, used] = pos
        pos = full
    return ExternalTracks(pos, np.arange(nf), True, length_unit="mm", fmt="openptv", source=str(folder))


def _read_openlpt(p: Path) -> ExternalTracks:
    from mitpiv.io.openlpt import read_openlpt_tracks

    if p.is_dir():
        for sub in (p / "results" / "ConvergeTrack", p / "ConvergeTrack"):
            if sub.is_dir():
                p = sub
                break
        files = sorted(f for f in p.glob("*.csv") if not f.name.startswith("ShortTrack"))
        if not files:
            raise FileFormatError(f"score: {str(p)!r} holds no OpenLPT track files (LongTrack*.csv, "
                                  "ExitTrack*.csv); did OpenLPT run?")
        d = read_openlpt_tracks(files)
    else:
        d = read_openlpt_tracks(p)
    pos = d["positions_mm"]
    return ExternalTracks(pos, np.arange(pos.shape[1]), True, length_unit="mm", fmt="openlpt", source=str(p))


def _read_davis_tracks(p: Path) -> ExternalTracks:
    from mitpiv.io.davis import read_davis_particles

    d = read_davis_particles(p)
    pos = np.asarray(d["positions_mm"], dtype=np.float64)
    return ExternalTracks(pos, np.arange(pos.shape[1]), bool(d.get("linked", True)), length_unit="mm",
                          fmt="davis", source=str(p))


def read_tracks(path, *, fmt: str | None = None) -> ExternalTracks:
    """Read another tool's particles or tracks (see the module notes for the formats).

    Raises
    ------
    FileFormatError
        A missing file or folder, or one that holds no particles in that format.
    ConfigError
        An unknown format.
    """
    p = _exists(path)
    fmt = fmt or track_format(p)
    if fmt not in TRACK_FORMATS:
        raise ConfigError(f"score: --format {fmt!r} is not a particle / track format; use one of {TRACK_FORMATS}.")
    reader = {"csv": _read_tracks_csv, "openptv": _read_openptv, "openlpt": _read_openlpt,
              "davis": _read_davis_tracks}[fmt]
    out = reader(p)
    if not np.isfinite(out.positions).any():
        raise FileFormatError(f"score: {str(p)!r} ({fmt}) holds no particle.")
    return out
