"""Backlit droplet tracking data on disk: the dewarp polynomial with its calibration
observations, and the particles detected in a focal stack (``.npz``, atomic writes).

The entries are those the backlit experiment has always written, so run folders made
before these functions existed still read.

``dewarp.npz``: ``coef`` (n_terms, 3), ``degree_xy``, ``degree_z`` (ints), ``centre`` (3,),
``scale`` (3,) (the normalisation of (u, v, z_stack)), ``rms_mm`` (fit residual [mm]) and,
when given, the calibration observations ``uvz`` (M, 3) (stack pixels u, v [px] and
stack depth [mm]) and ``xyz`` (M, 3) (world [mm]).

``detections_k.npz``: per particle ``uv_px`` (N, 2), ``z_stack_mm``, ``area_px``,
``diameter_px``, ``aspect``, ``darkness`` (N,); ``positions_mm`` (N, 3) and
``diameters_mm`` (N,) when a dewarp gave world values; optionally ``min_map`` (H, W), the
minimum transmittance over the focal stack (for figures).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.io.arrays import read_npz, write_npz

if TYPE_CHECKING:  # io imports no analysis module at run time: readers return records
    from mitpiv.analysis.backlit import BacklitDetections, Dewarp

__all__ = ["write_dewarp", "read_dewarp", "write_detections", "read_detections"]

_DEWARP = ("coef", "degree_xy", "degree_z", "centre", "scale", "rms_mm")
_PER_PARTICLE = ("uv_px", "z_stack_mm", "area_px", "diameter_px", "aspect", "darkness")


def _n_terms(degree_xy: int, degree_z: int) -> int:
    """Monomials u^a v^b z^c with a + b <= degree_xy, c <= degree_z (as in analysis.backlit)."""
    return (degree_z + 1) * (degree_xy + 1) * (degree_xy + 2) // 2


def _observations(uvz, xyz, path):
    if (uvz is None) != (xyz is None):
        raise ConfigError(f"write_dewarp: give both uvz and xyz (the calibration observations) or neither, for "
                          f"{str(path)!r}.")
    if uvz is None:
        return None, None
    uvz, xyz = (np.asarray(a, dtype=np.float64) for a in (uvz, xyz))
    if uvz.ndim != 2 or uvz.shape[1] != 3 or uvz.shape != xyz.shape:
        raise ConfigError(f"write_dewarp: uvz and xyz must both have shape (M, 3), got {uvz.shape} and {xyz.shape}.")
    return uvz, xyz


def write_dewarp(path, dewarp: Dewarp, *, uvz=None, xyz=None) -> Path:
    """Write a :class:`~mitpiv.analysis.backlit.Dewarp` to ``path`` (``.npz``, atomic).

    Parameters
    ----------
    path : str or Path
        Target ``.npz`` file.
    dewarp : Dewarp
        The fitted polynomial.
    uvz, xyz : (M, 3) arrays, optional
        The calibration observations it was fitted to: (u [px], v [px], z_stack [mm]) and
        world (x, y, z) [mm]. Both or neither.
    """
    uvz, xyz = _observations(uvz, xyz, path)
    coef = np.asarray(dewarp.coef, dtype=np.float64)
    n = _n_terms(int(dewarp.degree_xy), int(dewarp.degree_z))
    if coef.shape != (n, 3):
        raise ConfigError(f"write_dewarp: coef has shape {coef.shape}, but degree_xy={dewarp.degree_xy}, "
                          f"degree_z={dewarp.degree_z} need ({n}, 3).")
    return write_npz(path, {"coef": coef, "degree_xy": int(dewarp.degree_xy), "degree_z": int(dewarp.degree_z),
                            "centre": np.asarray(dewarp.centre, dtype=np.float64),
                            "scale": np.asarray(dewarp.scale, dtype=np.float64), "rms_mm": float(dewarp.rms_mm),
                            "uvz": uvz, "xyz": xyz}, owner="write_dewarp")


def read_dewarp(path) -> dict:
    """Read a dewarp written by :func:`write_dewarp` (or a backlit run's ``dewarp.npz``) as a
    record: the :class:`~mitpiv.analysis.backlit.Dewarp` fields (``Dewarp.load(path)`` builds
    one) and the calibration observations ``uvz``, ``xyz`` ((M, 3), or None when the file
    has none).

    Raises :class:`FileFormatError` naming the file when it is missing or not a dewarp.
    """
    z = read_npz(path, what="backlit dewarp", required=_DEWARP)
    dxy, dz = int(z["degree_xy"]), int(z["degree_z"])
    n = _n_terms(dxy, dz)
    if z["coef"].shape != (n, 3) or z["centre"].shape != (3,) or z["scale"].shape != (3,):
        raise FileFormatError(f"backlit dewarp {str(path)!r}: coef {z['coef'].shape}, centre {z['centre'].shape}, "
                              f"scale {z['scale'].shape} do not fit degree_xy={dxy}, degree_z={dz} (({n}, 3), (3,), "
                              f"(3,) expected).")
    return {"coef": z["coef"], "degree_xy": dxy, "degree_z": dz, "centre": z["centre"], "scale": z["scale"],
            "rms_mm": float(z["rms_mm"]), "uvz": z.get("uvz"), "xyz": z.get("xyz")}


def write_detections(path, detections: BacklitDetections, *, min_map=None) -> Path:
    """Write :class:`~mitpiv.analysis.backlit.BacklitDetections` to ``path`` (``.npz``, atomic).

    Parameters
    ----------
    path : str or Path
        Target ``.npz`` file.
    detections : BacklitDetections
        The particles of one frame; ``positions_mm`` / ``diameters_mm`` are stored when set.
    min_map : (H, W) array, optional
        Minimum transmittance over the focal stack, stored as float32 (for figures).
    """
    det = detections
    n = len(det)
    arrays = {k: np.asarray(getattr(det, k)) for k in _PER_PARTICLE}
    arrays["positions_mm"] = None if det.positions_mm is None else np.asarray(det.positions_mm)
    arrays["diameters_mm"] = None if det.diameters_mm is None else np.asarray(det.diameters_mm)
    bad = {k: a.shape for k, a in arrays.items() if a is not None and (a.ndim == 0 or a.shape[0] != n)}
    if bad:
        raise ConfigError(f"write_detections: {n} detections but entries with other lengths: {bad}.")
    if min_map is not None:
        min_map = np.asarray(min_map, dtype=np.float32)
        if min_map.ndim != 2:
            raise ConfigError(f"write_detections: min_map must be an (H, W) image, got shape {min_map.shape}.")
    return write_npz(path, {**arrays, "min_map": min_map}, owner="write_detections")


def read_detections(path) -> dict:
    """Read detections written by :func:`write_detections` (or a backlit run's
    ``detections_k.npz``) as a record: the
    :class:`~mitpiv.analysis.backlit.BacklitDetections` fields (``BacklitDetections.load(path)``
    builds one) and ``min_map`` ((H, W) float32, or None when the file has none).

    Raises :class:`FileFormatError` naming the file when it is missing or not detections.
    """
    z = read_npz(path, what="backlit detections", required=_PER_PARTICLE)
    n = z["uv_px"].shape[0] if z["uv_px"].ndim == 2 else -1
    bad = {k: z[k].shape for k in (*_PER_PARTICLE, "positions_mm", "diameters_mm")
           if k in z and (z[k].ndim == 0 or z[k].shape[0] != n)}
    if n < 0 or z["uv_px"].shape[1] != 2 or bad:
        raise FileFormatError(f"backlit detections {str(path)!r}: the entries do not describe N particles (uv_px "
                              f"{z['uv_px'].shape}, mismatched: {bad}).")
    return {**{k: z[k] for k in _PER_PARTICLE}, "positions_mm": z.get("positions_mm"),
            "diameters_mm": z.get("diameters_mm"), "min_map": z.get("min_map")}
