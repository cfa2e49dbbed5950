"""A user's DLT or third-order polynomial camera calibration (one table for all cameras),
read and written; the cameras a render can use built from them.

Both formats hold one entry per camera, in CSV (the standard library's :mod:`csv`) or JSON
(:mod:`json`). Settings that apply to every camera are ``# key = value`` comment lines
before the CSV header, or top-level keys in JSON:

``first_pixel_centre_px``
    Coordinate of the first pixel's centre in the file's pixel convention: 0 (OpenCV,
    0-based tools; the default), 0.5 (mitpiv: pixel ``i`` spans ``[i, i+1)``) or 1
    (MATLAB, 1-based). ``u`` runs along image columns (right), ``v`` along rows (down).
``length_unit_mm``
    Millimetres per unit of the file's world coordinates (1 for mm, 1000 for m).
``pixel_pitch_um``, ``image_width``, ``image_height``
    Optional: the sensor's pixel pitch [um] and the image size [px] (also per camera: CSV
    columns / JSON keys of those names; function arguments override them).
``volume_mm``
    Polynomial only, optional: ``x_min x_max y_min y_max z_min z_max`` [mm], the volume the
    polynomial was calibrated in (where a renderable camera is fitted to it).

DLT (``format = dlt``)
    The 11-parameter direct linear transform of Abdel-Aziz & Karara (1971)::

        u = (L1 X + L2 Y + L3 Z + L4) / (L9 X + L10 Y + L11 Z + 1)
        v = (L5 X + L6 Y + L7 Z + L8) / (L9 X + L10 Y + L11 Z + 1)

    CSV header ``camera, L1, ..., L11`` or, for a 3x4 projection matrix (any scale),
    ``camera, P11, P12, P13, P14, P21, ..., P34`` (row by row); JSON
    ``{"format": "dlt", "cameras": [{"name": "cam0", "L": [11 numbers]} or {"name":
    "cam0", "P": [[4], [4], [4]]}, ...]}``.

Polynomial (``format = polynomial``)
    Soloff et al. (1997): ``u = sum_t a_t q^t``, ``v = sum_t b_t q^t`` over the monomials
    ``q^t = qx^i qy^j qz^k`` of the normalised world point ``q = (X - centre) / scale``
    (centre 0 and scale 1 unless given; in the file's length unit). Accepted term sets:
    Soloff's 19 (cubic in X and Y, quadratic in Z, total degree <= 3; LaVision DaVis'
    "3rd order XY, 2nd order Z") or the full cubic's 20 (those and ``z^3``). The header
    names the terms in the file's own order, each a product of ``x``, ``y``, ``z`` with
    optional powers: ``1``, ``x``, ``x^2``, ``x2y``, ``x*y*z``, ``z^3`` (case and ``*``
    / ``^`` do not matter); every term of the set must appear once. The canonical order
    (:data:`~mitpiv.physics.camera_fit.SOLOFF_TERMS`, written by the writer) is ``1, x, y,
    x2, xy, y2, x3, x2y, xy2, y3, z, xz, yz, x2z, xyz, y2z, z2, xz2, yz2[, z3]``. CSV:
    header ``camera, coordinate, <terms>[, centre_x, centre_y, centre_z, scale_x, scale_y,
    scale_z]``, two rows per camera (``coordinate`` = ``u`` and ``v``); JSON ``{"format":
    "polynomial", "terms": [names], "cameras": [{"name", "u": [...], "v": [...],
    "centre": [3], "scale": [3]}, ...]}``.

Readers (:func:`read_dlt_table`, :func:`read_polynomial_table`) return plain records in
mitpiv's conventions (pixels with centres at ``i + 0.5``, world mm); the cameras come from
:func:`read_dlt_cameras` (a 3x4 decomposition; refused beyond ``max_residual_px`` when skew
or non-square pixels cannot be represented) and :func:`read_polynomial_cameras` (a pinhole
+ Brown-Conrady camera fitted to the polynomial over the volume, its residual reported and
refused beyond ``max_residual_px``); both in :mod:`mitpiv.physics.camera_fit`. Writers
(:func:`write_dlt_table`, :func:`write_polynomial_table`) are atomic. Hand-written here:
only the table layout, the parsing of term names and the convention changes.
"""

from __future__ import annotations

import csv
import io as _io
import json
import math
import re
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.io.atomic import atomic_path
from mitpiv.physics.camera_fit import (
    CUBIC_TERMS,
    DEFAULT_MAX_RESIDUAL_PX,
    SOLOFF_TERMS,
    camera_from_polynomial,
    camera_from_projection,
    dlt_from_projection,
    polynomial_from_camera,
    projection_from_camera,
    projection_from_dlt,
)

__all__ = ["read_dlt_table", "write_dlt_table", "read_dlt_cameras", "read_polynomial_table",
           "write_polynomial_table", "read_polynomial_cameras", "calibration_table_format", "select_camera",
           "term_name", "parse_term"]

_SETTINGS = ("first_pixel_centre_px", "length_unit_mm", "pixel_pitch_um", "image_width", "image_height", "volume_mm",
             "format")
_DLT_L = tuple(f"l{i}" for i in range(1, 12))
_DLT_P = tuple(f"p{r}{c}" for r in range(1, 4) for c in range(1, 5))
_NORM = ("centre_x", "centre_y", "centre_z", "scale_x", "scale_y", "scale_z")
_PER_CAMERA = ("image_width", "image_height", "pixel_pitch_um")


# ---------------------------------------------------------------------- terms
def term_name(term) -> str:
    """The canonical name of a monomial (i, j, k): ``1``, ``x``, ``x2y``, ``xyz``, ``z3``."""
    s = "".join(f"{a}{'' if e == 1 else e}" for a, e in zip("xyz", term, strict=True) if e)
    return s or "1"


def parse_term(name: str) -> tuple[int, int, int]:
    """(i, j, k) of a monomial name (``1``, ``x^2*y``, ``X2Y``, ``x*x*y``, ``z3``); raises
    :class:`ValueError` for anything else."""
    s = str(name).strip().lower().replace("*", "").replace("^", "").replace(" ", "")
    if s in ("1", "c", "const"):
        return (0, 0, 0)
    if not re.fullmatch(r"([xyz]\d*)+", s):
        raise ValueError(name)
    e = [0, 0, 0]
    for a, p in re.findall(r"([xyz])(\d*)", s):
        e["xyz".index(a)] += int(p) if p else 1
    return tuple(e)


# ---------------------------------------------------------------------- parsing
def _settings_value(key, text, src):
    try:
        if key == "format":
            return text.strip().lower()
        if key == "volume_mm":
            v = [float(x) for x in re.split(r"[,\s]+", text.strip().strip("[]()")) if x]
            return v
        if key in ("image_width", "image_height"):
            return int(text)
        return float(text)
    except ValueError:
        raise FileFormatError(f"{src}: setting {key} = {text!r} is not a number.") from None


def _read_csv(path: Path, src: str):
    """(settings, header (lower case), rows) of a CSV table with ``# key = value`` settings."""
    settings, lines = {}, []
    for ln in path.read_text().splitlines():
        s = ln.strip()
        if not s:
            continue
        if s.startswith("#"):
            m = re.match(r"#\s*([A-Za-z_]+)\s*[=:]\s*(.+)$", s)
            if m and m.group(1).lower() in _SETTINGS:  # a value may end in its own "# comment"
                settings[m.group(1).lower()] = _settings_value(m.group(1).lower(), m.group(2).split("#")[0], src)
            continue
        lines.append(ln)
    rows = list(csv.reader(lines, skipinitialspace=True))
    if len(rows) < 2:
        raise FileFormatError(f"{src} holds no table (a header line and one row per camera).")
    header = [h.strip().lower() for h in rows[0]]
    body = []
    for n, r in enumerate(rows[1:], start=2):
        if len(r) != len(header):
            raise FileFormatError(f"{src}: row {n} has {len(r)} fields, the header {len(header)}.")
        body.append(dict(zip(header, (v.strip() for v in r), strict=True)))
    return settings, header, body


def _read_json(path: Path, src: str) -> dict:
    try:
        d = json.loads(path.read_text())
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise FileFormatError(f"{src} is not a JSON file ({e}).") from None
    if not isinstance(d, dict) or not isinstance(d.get("cameras"), list) or not d["cameras"]:
        raise FileFormatError(f"{src} must hold a JSON object with a non-empty list 'cameras'.")
    return d


def _read_table(path, owner: str):
    """(src, format, settings, data) of a calibration table: ``"csv"`` with data (header,
    rows) or ``"json"`` with the file's object; ``src`` names ``owner`` and the file in messages."""
    path = Path(path)
    src = f"{owner}: {str(path)!r}"
    if not path.is_file():
        raise FileFormatError(f"{src} does not exist.")
    suf = path.suffix.lower()
    if suf == ".csv":
        settings, header, body = _read_csv(path, src)
        return src, "csv", settings, (header, body)
    if suf == ".json":
        d = _read_json(path, src)
        return src, "json", {k: d[k] for k in _SETTINGS if k in d}, d
    raise ConfigError(f"{src} must end in .csv or .json.")


def _number(v, what, src):
    try:
        x = float(v)
    except (TypeError, ValueError):
        raise FileFormatError(f"{src}: {what} = {v!r} is not a number.") from None
    if not math.isfinite(x):
        raise FileFormatError(f"{src}: {what} = {v!r} is not finite; every coefficient must be a finite number.")
    return x


def _numbers(values, what, src, n=None):
    vals = np.asarray(values, dtype=object).ravel() if not isinstance(values, str) else [values]
    if n is not None and len(vals) != n:
        raise FileFormatError(f"{src}: {what} has {len(vals)} numbers, expected {n}.")
    return np.array([_number(v, f"{what}[{i}]", src) for i, v in enumerate(vals)], dtype=np.float64)


def _common(settings, src):
    c0 = float(settings.get("first_pixel_centre_px", 0.0))
    if c0 not in (0.0, 0.5, 1.0):
        raise ConfigError(f"{src}: first_pixel_centre_px = {c0:g}; give 0 (OpenCV, 0-based), 0.5 (mitpiv) or 1 "
                          f"(MATLAB, 1-based).")
    unit = float(settings.get("length_unit_mm", 1.0))
    if not (math.isfinite(unit) and unit > 0):
        raise ConfigError(f"{src}: length_unit_mm = {unit:g} must be > 0 (1 for mm, 1000 for m).")
    return c0, unit


def _per_camera(rec, entry, settings):
    for k in _PER_CAMERA:
        v = entry.get(k, settings.get(k))
        if v not in (None, ""):
            rec[k] = int(float(v)) if k != "pixel_pitch_um" else float(v)
    return rec


def _names(records, src):
    names = [r["name"] for r in records]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise FileFormatError(f"{src}: camera name(s) {dup} appear more than once; name each camera once.")


def calibration_table_format(path) -> str | None:
    """``"dlt"``, ``"polynomial"`` or ``"opencv"`` for a calibration file (by its content),
    None when it is none of them."""
    path = Path(path)
    suf = path.suffix.lower()
    if suf in (".yml", ".yaml", ".xml"):
        return "opencv"
    if not path.is_file():
        return None
    if suf == ".json":
        try:
            d = json.loads(path.read_text())
        except (UnicodeDecodeError, json.JSONDecodeError):
            return None
        if isinstance(d, dict) and str(d.get("format", "")).lower() in ("dlt", "polynomial"):
            return str(d["format"]).lower()
        if isinstance(d, dict) and isinstance(d.get("cameras"), list):
            c = d["cameras"][0] if d["cameras"] else {}
            return "dlt" if isinstance(c, dict) and ("L" in c or "P" in c) else "polynomial"
        return "opencv"
    if suf == ".csv":
        try:
            settings, header, _ = _read_csv(path, str(path))
        except FileFormatError:
            return None
        if settings.get("format") in ("dlt", "polynomial"):
            return settings["format"]
        if "coordinate" in header:
            return "polynomial"
        if "l1" in header or "p11" in header:
            return "dlt"
    return None


def select_camera(records, camera, *, path="") -> dict:
    """The record of one camera: ``camera`` a name, an index (int or digits), or None (the
    only camera of a one-camera file)."""
    names = [r["name"] for r in records]
    src = f"calibration {str(path)!r}"
    if camera is None:
        if len(records) == 1:
            return records[0]
        raise ConfigError(f"{src} holds {len(records)} cameras ({', '.join(names)}); name the one to use "
                          f"(calibration_camera).")
    if camera in names:
        return records[names.index(camera)]
    if isinstance(camera, int) or (isinstance(camera, str) and camera.isdigit()):
        i = int(camera)
        if 0 <= i < len(records):
            return records[i]
    raise ConfigError(f"{src} holds {len(records)} camera(s) ({', '.join(names)}), none named {camera!r}; give one "
                      f"calibration per sensor (set calibration_camera to a name or index in the file).")


def _check_count(records, expected, src):
    if expected is not None and len(records) != int(expected):
        raise ConfigError(f"{src} holds {len(records)} camera(s) ({', '.join(r['name'] for r in records)}) but the "
                          f"scene has {expected}; give one calibration per camera.")


# ---------------------------------------------------------------------- DLT
def read_dlt_table(path) -> tuple[list[dict], dict]:
    """Read a DLT table (CSV or JSON; layout in the module notes).

    Returns
    -------
    cameras : list of dict
        Per camera: ``name``, ``P`` (3, 4) projection matrix in mitpiv's conventions (pixel
        centres at ``i + 0.5``, world mm), ``L`` (11,) the file's own parameters (or those
        of its matrix), and ``image_width`` / ``image_height`` / ``pixel_pitch_um`` when given.
    settings : dict
        The file's settings.

    Raises
    ------
    FileFormatError
        Missing file, wrong columns, a wrong number of coefficients, non-finite values.
    ConfigError
        Unknown pixel convention or length unit.
    """
    src, fmt, settings, data = _read_table(path, "read_dlt_table")
    entries = []
    if fmt == "csv":
        header, body = data
        if all(k in header for k in _DLT_L):
            keys, kind = _DLT_L, "L"
        elif all(k in header for k in _DLT_P):
            keys, kind = _DLT_P, "P"
        else:
            have = [h for h in header if re.fullmatch(r"l\d+|p\d+", h)]
            raise FileFormatError(f"{src}: the header must name the 11 DLT parameters L1..L11 (or the 12 entries "
                                  f"P11..P34 of a 3x4 matrix), found {len(have)}: {have}. The DLT has exactly 11 "
                                  f"parameters (L12 = 1).")
        extra = [h for h in header if re.fullmatch(r"l\d+", h) and h not in _DLT_L]
        if extra:
            raise FileFormatError(f"{src}: columns {extra} are not DLT parameters; the 11-parameter DLT has L1..L11 "
                                  f"(extended DLTs with lens terms are not supported: drop them or fit a polynomial).")
        for n, row in enumerate(body):
            name = row.get("camera") or row.get("name") or f"cam{n}"
            vals = _numbers([row[k] for k in keys], f"camera {name!r} {kind}", src)
            entries.append((name, kind, vals, row))
    else:
        for n, c in enumerate(data["cameras"]):
            if not isinstance(c, dict):
                raise FileFormatError(f"{src}: cameras[{n}] must be an object with 'L' (11 numbers) or 'P' (3x4).")
            name = str(c.get("name", f"cam{n}"))
            if "L" in c:
                entries.append((name, "L", _numbers(c["L"], f"camera {name!r} L", src), c))
            elif "P" in c:
                entries.append((name, "P", _numbers(c["P"], f"camera {name!r} P", src), c))
            else:
                raise FileFormatError(f"{src}: camera {name!r} has neither 'L' (the 11 DLT parameters) nor 'P' (3x4).")
    c0, unit = _common(settings, src)
    records = []
    for name, kind, vals, entry in entries:
        if kind == "L" and vals.size != 11:
            raise FileFormatError(f"{src}: camera {name!r} has {vals.size} DLT parameters; the DLT has exactly 11 "
                                  f"(L1..L11, L12 = 1). Give a 3x4 matrix as 'P' instead.")
        if kind == "P" and vals.size != 12:
            raise FileFormatError(f"{src}: camera {name!r} has a projection matrix of {vals.size} numbers, not 3x4.")
        p_file = projection_from_dlt(vals) if kind == "L" else vals.reshape(3, 4)
        # file pixels -> mitpiv pixels (+ 0.5 - c0), file units -> mm
        shift = np.array([[1.0, 0.0, 0.5 - c0], [0.0, 1.0, 0.5 - c0], [0.0, 0.0, 1.0]])
        p = shift @ p_file @ np.diag([1 / unit, 1 / unit, 1 / unit, 1.0])
        rec = {"name": name, "P": p, "L": vals if kind == "L" else None}
        records.append(_per_camera(rec, entry, settings))
    _names(records, src)
    return records, settings


def _resolution_pitch(rec, resolution, pixel_pitch_um, src):
    name = rec["name"]
    if resolution is not None:
        res = tuple(int(v) for v in resolution)
        have = (rec.get("image_width"), rec.get("image_height"))
        if None not in have and tuple(have) != res:
            raise ConfigError(f"{src}: camera {name!r} is calibrated for {have[0]} x {have[1]} px images, not "
                              f"{res[0]} x {res[1]}; render at the calibrated size.")
    elif rec.get("image_width") and rec.get("image_height"):
        res = (rec["image_width"], rec["image_height"])
    else:
        raise ConfigError(f"{src}: camera {name!r}: give resolution=(width, height) [px]; the file holds no image size "
                          f"(image_width, image_height).")
    pitch = pixel_pitch_um if pixel_pitch_um is not None else rec.get("pixel_pitch_um")
    if pitch is None:
        raise ConfigError(f"{src}: camera {name!r}: give pixel_pitch_um (the sensor's pixel pitch [um]); the file has "
                          f"none and the focal length in mm needs it.")
    return res, float(pitch)


def _table_cameras(src, path, records, build, *, camera, expected_cameras, resolution, pixel_pitch_um):
    """``(camera, info)`` of each record of a table, or of the one named ``camera``:
    ``build(record, resolution, pixel_pitch_um)`` gives the camera and its info."""
    _check_count(records, expected_cameras, src)
    chosen = records if camera is None else [select_camera(records, camera, path=path)]
    out = []
    for rec in chosen:
        res, pitch = _resolution_pitch(rec, resolution, pixel_pitch_um, src)
        cam, info = build(rec, res, pitch)
        out.append((cam, {"name": rec["name"], **info}))
    return out[0] if camera is not None else out


def read_dlt_cameras(path, *, camera=None, pixel_pitch_um: float | None = None, resolution=None,
                     max_residual_px: float = DEFAULT_MAX_RESIDUAL_PX, volume_mm=None,
                     expected_cameras: int | None = None, f_number: float | None = None,
                     focus_distance_mm: float | None = None):
    """The :class:`~mitpiv.physics.camera.PinholeCamera` of each camera of a DLT table.

    Parameters
    ----------
    path : str or Path
        DLT table (module notes).
    camera : str or int, optional
        Only this camera (name or index): returns one ``(camera, info)``.
    pixel_pitch_um : float, optional
        Pixel pitch [um]; required unless the file holds it.
    resolution : (int, int), optional
        Image (width, height) [px]; required unless the file holds it.
    max_residual_px : float
        Largest error [px] accepted for representing skew / non-square pixels by square
        pixels (:func:`~mitpiv.physics.camera_fit.camera_from_projection`).
    volume_mm : (6,) array, optional
        Checked to lie in front of every camera.
    expected_cameras : int, optional
        The number of cameras the file must hold (the scene's).

    Returns
    -------
    list of (PinholeCamera, dict)
        Each camera and ``info`` (``name``, fx, fy, skew, the approximation's residual).
    """
    def build(rec, res, pitch):
        return camera_from_projection(rec["P"], resolution=res, pixel_pitch_um=pitch, name=rec["name"],
                                      max_residual_px=max_residual_px, volume_mm=volume_mm, f_number=f_number,
                                      focus_distance_mm=focus_distance_mm)

    return _table_cameras(f"read_dlt_cameras: {str(path)!r}", path, read_dlt_table(path)[0], build, camera=camera,
                          expected_cameras=expected_cameras, resolution=resolution, pixel_pitch_um=pixel_pitch_um)


def _write_table(path, settings: dict, header, rows) -> Path:
    buf = _io.StringIO()
    for k, v in settings.items():
        if v is not None:
            buf.write(f"# {k} = {' '.join(repr(float(x)) for x in v) if isinstance(v, list | tuple) else v}\n")
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(header)
    w.writerows(rows)
    with atomic_path(path) as tmp:
        Path(tmp).write_text(buf.getvalue())
    return Path(path)


def _json_table(path, obj) -> Path:
    with atomic_path(path) as tmp:
        Path(tmp).write_text(json.dumps(obj, indent=1))
    return Path(path)


def _cam_names(cameras, names):
    names = [f"cam{i}" for i in range(len(cameras))] if names is None else [str(n) for n in names]
    if len(names) != len(cameras):
        raise ConfigError(f"write: {len(names)} names for {len(cameras)} cameras.")
    return names


def write_dlt_table(path, cameras, *, names=None, first_pixel_centre_px: float = 0.0,
                    length_unit_mm: float = 1.0) -> Path:
    """Write undistorted :class:`~mitpiv.physics.camera.PinholeCamera` s (or 3x4 matrices in
    mitpiv's conventions) as a DLT table (``.csv`` or ``.json``; atomic) that
    :func:`read_dlt_table` reads: L1..L11 per camera in the given pixel convention and
    length unit, with the image size and pixel pitch of each camera."""
    path = Path(path)
    suf = path.suffix.lower()
    if suf not in (".csv", ".json"):
        raise ConfigError(f"write_dlt_table: {str(path)!r} must end in .csv or .json.")
    _common({"first_pixel_centre_px": first_pixel_centre_px, "length_unit_mm": length_unit_mm}, "write_dlt_table")
    names = _cam_names(cameras, names)
    shift = np.array([[1.0, 0.0, first_pixel_centre_px - 0.5], [0.0, 1.0, first_pixel_centre_px - 0.5],
                      [0.0, 0.0, 1.0]])
    rows = []
    for name, cam in zip(names, cameras, strict=True):
        p = np.asarray(cam, dtype=np.float64) if isinstance(cam, np.ndarray) else projection_from_camera(cam)
        p_file = shift @ p @ np.diag([length_unit_mm] * 3 + [1.0])
        extra = {} if isinstance(cam, np.ndarray) else {"image_width": int(cam.resolution[0]),
                                                        "image_height": int(cam.resolution[1]),
                                                        "pixel_pitch_um": float(cam.pixel_pitch_um)}
        rows.append((name, dlt_from_projection(p_file), extra))
    settings = {"format": "dlt", "first_pixel_centre_px": first_pixel_centre_px, "length_unit_mm": length_unit_mm}
    if suf == ".json":
        return _json_table(path, {**settings, "cameras": [{"name": n, "L": L.tolist(), **e} for n, L, e in rows]})
    extra_keys = [k for k in _PER_CAMERA if all(k in e for _, _, e in rows)]
    return _write_table(path, settings, ["camera", *[f"L{i}" for i in range(1, 12)], *extra_keys],
                        [[n, *map(repr, L.tolist()), *(e[k] for k in extra_keys)] for n, L, e in rows])


# ---------------------------------------------------------------------- polynomial
def _term_order(names, src):
    try:
        terms = [parse_term(t) for t in names]
    except ValueError as e:
        raise FileFormatError(f"{src}: {str(e)!r} is not a monomial name (1, x, y, z, x2, xy, x^2*y, z3, ...).") from None
    dup = sorted({term_name(t) for t in terms if terms.count(t) > 1})
    if dup:
        raise FileFormatError(f"{src}: term(s) {dup} appear more than once in the header.")
    want = CUBIC_TERMS if (0, 0, 3) in terms else SOLOFF_TERMS
    missing = [term_name(t) for t in want if t not in terms]
    extra = [term_name(t) for t in terms if t not in want]
    if missing or extra:
        raise FileFormatError(
            f"{src}: the polynomial has {len(terms)} terms; mitpiv reads Soloff's 19 (cubic in x and y, quadratic in "
            f"z: {', '.join(map(term_name, SOLOFF_TERMS))}) or those and z3 (20). Missing: {missing or 'none'}; not "
            f"accepted: {extra or 'none'}.")
    return want, [terms.index(t) for t in want]


def read_polynomial_table(path) -> tuple[list[dict], dict]:
    """Read a third-order polynomial calibration table (CSV or JSON; module notes).

    Returns
    -------
    cameras : list of dict
        Per camera: ``name``, ``terms`` (canonical order), ``coefficients`` (2, n_terms) [px,
        mitpiv pixel convention], ``centre_mm``, ``scale_mm`` (3,), and ``volume_mm``,
        ``image_width`` / ``image_height`` / ``pixel_pitch_um`` when given.
    settings : dict
        The file's settings.

    Raises
    ------
    FileFormatError
        Missing file, unknown or missing terms, a u or v row missing, non-finite values.
    ConfigError
        Unknown pixel convention or length unit.
    """
    src, fmt, settings, data = _read_table(path, "read_polynomial_table")
    cams = []  # (name, u, v, centre, scale, entry)
    if fmt == "csv":
        header, body = data
        if "coordinate" not in header:
            raise FileFormatError(f"{src}: the header needs a 'coordinate' column (u or v) and one column per term.")
        skip = {"camera", "name", "coordinate", *_NORM, *_PER_CAMERA}
        tcols = [h for h in header if h not in skip]
        terms, order = _term_order(tcols, src)
        by_cam: dict[str, dict] = {}
        for n, row in enumerate(body):
            name = row.get("camera") or row.get("name") or "cam0"
            coord = row["coordinate"].lower()
            if coord not in ("u", "v"):
                raise FileFormatError(f"{src}: row {n + 2}: coordinate {row['coordinate']!r} must be u or v.")
            c = by_cam.setdefault(name, {"entry": row})
            if coord in c:
                raise FileFormatError(f"{src}: camera {name!r} has two {coord} rows.")
            c[coord] = _numbers([row[t] for t in tcols], f"camera {name!r} {coord}", src)[order]
            for k in _NORM:
                if row.get(k) not in (None, ""):
                    c.setdefault("norm", {})[k] = _number(row[k], f"camera {name!r} {k}", src)
        for name, c in by_cam.items():
            miss = [k for k in ("u", "v") if k not in c]
            if miss:
                raise FileFormatError(f"{src}: camera {name!r} has no {miss[0]} row; give a u and a v row per camera.")
            nm = c.get("norm", {})
            centre = [nm.get(k, 0.0) for k in _NORM[:3]]
            scale = [nm.get(k, 1.0) for k in _NORM[3:]]
            cams.append((name, c["u"], c["v"], np.array(centre), np.array(scale), c["entry"]))
    else:
        names = data.get("terms", [term_name(t) for t in SOLOFF_TERMS])
        terms, order = _term_order(names, src)
        for n, c in enumerate(data["cameras"]):
            name = str(c.get("name", f"cam{n}")) if isinstance(c, dict) else f"cam{n}"
            if not isinstance(c, dict) or "u" not in c or "v" not in c:
                raise FileFormatError(f"{src}: camera {name!r} needs 'u' and 'v' coefficient lists.")
            u = _numbers(c["u"], f"camera {name!r} u", src, len(names))[order]
            v = _numbers(c["v"], f"camera {name!r} v", src, len(names))[order]
            centre = _numbers(c.get("centre", [0, 0, 0]), f"camera {name!r} centre", src, 3)
            scale = _numbers(c.get("scale", [1, 1, 1]), f"camera {name!r} scale", src, 3)
            cams.append((name, u, v, centre, scale, c))
    c0, unit = _common(settings, src)
    vol = settings.get("volume_mm")
    if vol is not None:
        vol = np.asarray(vol, dtype=np.float64).ravel()
        if vol.size != 6 or not np.all(np.isfinite(vol)) or not np.all(vol[1::2] > vol[0::2]):
            raise FileFormatError(f"{src}: volume_mm = {vol.tolist()} must be x_min x_max y_min y_max z_min z_max "
                                  f"[mm] with each max > min.")
    records = []
    for name, u, v, centre, scale, entry in cams:
        if np.any(scale == 0):
            raise FileFormatError(f"{src}: camera {name!r} has a zero scale {scale.tolist()}.")
        coef = np.stack([u, v])
        coef[:, terms.index((0, 0, 0))] += 0.5 - c0  # file pixels -> mitpiv pixels
        rec = {"name": name, "terms": terms, "coefficients": coef, "centre_mm": centre * unit,
               "scale_mm": scale * unit, "volume_mm": vol}
        records.append(_per_camera(rec, entry, settings))
    _names(records, src)
    return records, settings


def read_polynomial_cameras(path, *, camera=None, volume_mm=None, pixel_pitch_um: float | None = None,
                            resolution=None, max_residual_px: float = DEFAULT_MAX_RESIDUAL_PX,
                            distortion: str = "brown", expected_cameras: int | None = None,
                            f_number: float | None = None, focus_distance_mm: float | None = None):
    """Renderable cameras fitted to each camera of a polynomial table.

    A polynomial is not a pinhole: a pinhole + Brown-Conrady camera is fitted to points
    sampled through it over ``volume_mm`` (:func:`~mitpiv.physics.camera_fit.camera_from_polynomial`);
    the fit's RMS and largest residual [px] are returned and a fit worse than
    ``max_residual_px`` is refused.

    Parameters
    ----------
    path : str or Path
        Polynomial table (module notes).
    camera : str or int, optional
        Only this camera (name or index): returns one ``(camera, info)``.
    volume_mm : (6,) array, optional
        The calibration volume ``(x_min, x_max, y_min, y_max, z_min, z_max)`` [mm];
        required unless the file holds ``volume_mm``.
    pixel_pitch_um, resolution : optional
        As :func:`read_dlt_cameras`.
    max_residual_px : float
        Largest accepted reprojection error of the fitted camera against the polynomial [px].
    distortion : "none", "radial" or "brown"
        Distortion terms of the fitted camera.
    expected_cameras : int, optional
        The number of cameras the file must hold (the scene's).

    Returns
    -------
    list of (PinholeCamera, dict)
        Each camera and ``info`` (``name``, ``rms_px``, ``max_px``, points used).
    """
    def build(rec, res, pitch):
        vol = volume_mm if volume_mm is not None else rec["volume_mm"]
        return camera_from_polynomial(rec["coefficients"], terms=rec["terms"], centre_mm=rec["centre_mm"],
                                      scale_mm=rec["scale_mm"], volume_mm=vol, resolution=res, pixel_pitch_um=pitch,
                                      name=rec["name"], distortion=distortion, max_residual_px=max_residual_px,
                                      f_number=f_number, focus_distance_mm=focus_distance_mm)

    return _table_cameras(f"read_polynomial_cameras: {str(path)!r}", path, read_polynomial_table(path)[0], build,
                          camera=camera, expected_cameras=expected_cameras, resolution=resolution,
                          pixel_pitch_um=pixel_pitch_um)


def write_polynomial_table(path, cameras, *, volume_mm=None, names=None, terms=SOLOFF_TERMS,
                           first_pixel_centre_px: float = 0.0, length_unit_mm: float = 1.0) -> Path:
    """Write polynomial calibrations as a table (``.csv`` or ``.json``; atomic) that
    :func:`read_polynomial_table` reads.

    ``cameras``: :class:`~mitpiv.physics.camera.PinholeCamera` s (a polynomial of ``terms``
    is fitted to each over ``volume_mm`` by
    :func:`~mitpiv.physics.camera_fit.polynomial_from_camera`) or records with ``terms``,
    ``coefficients`` (2, n) in mitpiv pixels, ``centre_mm``, ``scale_mm`` (as returned by
    that function or :func:`read_polynomial_table`)."""
    path = Path(path)
    suf = path.suffix.lower()
    if suf not in (".csv", ".json"):
        raise ConfigError(f"write_polynomial_table: {str(path)!r} must end in .csv or .json.")
    _common({"first_pixel_centre_px": first_pixel_centre_px, "length_unit_mm": length_unit_mm},
            "write_polynomial_table")
    names = _cam_names(cameras, names)
    recs = []
    for cam in cameras:
        if isinstance(cam, dict):
            rec = cam
        else:
            if volume_mm is None:
                raise ConfigError("write_polynomial_table: give volume_mm (x_min, x_max, y_min, y_max, z_min, z_max) "
                                  "[mm], the volume to fit each camera's polynomial over.")
            rec = {**polynomial_from_camera(cam, volume_mm=volume_mm, terms=terms), "image_width": cam.resolution[0],
                   "image_height": cam.resolution[1], "pixel_pitch_um": cam.pixel_pitch_um}
        recs.append(rec)
    tset = {tuple(map(tuple, r["terms"])) for r in recs}
    if len(tset) != 1:
        raise ConfigError("write_polynomial_table: every camera must use the same terms.")
    tt = tset.pop()
    i0 = tt.index((0, 0, 0))
    vol = volume_mm if volume_mm is not None else recs[0].get("volume_mm")
    settings = {"format": "polynomial", "first_pixel_centre_px": first_pixel_centre_px,
                "length_unit_mm": length_unit_mm,
                "volume_mm": None if vol is None else [float(x) for x in np.asarray(vol).ravel()]}
    rows = []
    for name, r in zip(names, recs, strict=True):
        coef = np.array(r["coefficients"], dtype=np.float64)
        coef[:, i0] -= 0.5 - first_pixel_centre_px
        extra = {k: r[k] for k in _PER_CAMERA if r.get(k) is not None}
        rows.append((name, coef, np.asarray(r["centre_mm"], float) / length_unit_mm,
                     np.asarray(r["scale_mm"], float) / length_unit_mm, extra))
    tnames = [term_name(t) for t in tt]
    if suf == ".json":
        obj = {**{k: v for k, v in settings.items() if v is not None}, "terms": tnames,
               "cameras": [{"name": n, "u": c[0].tolist(), "v": c[1].tolist(), "centre": ce.tolist(),
                            "scale": sc.tolist(), **e} for n, c, ce, sc, e in rows]}
        return _json_table(path, obj)
    extra_keys = [k for k in _PER_CAMERA if all(k in e for *_, e in rows)]
    out = []
    for n, c, ce, sc, e in rows:
        for k, coord in enumerate("uv"):
            out.append([n, coord, *map(repr, c[k].tolist()), *map(repr, ce.tolist()), *map(repr, sc.tolist()),
                        *(e[x] for x in extra_keys)])
    return _write_table(path, settings, ["camera", "coordinate", *tnames, *_NORM, *extra_keys], out)
