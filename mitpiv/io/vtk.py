"""ParaView / VTK files: volumes as image data (``.vti``), vector fields on a lattice as
structured grids (``.vts``), particles as point clouds (``.vtu`` vertices), tracks as
polylines (``.vtu``), lines and polygons (``.vtu``: a rig's wireframes) and a collection (``.pvd``) that groups them by time; all VTK XML,
binary (raw appended), written atomically.

The writer is pyevtk (a kept library; nothing here formats VTK by hand): this module only
lays the arrays out as VTK expects (x fastest: a ``(n_z, n_y, n_x)`` volume is passed as
its ``(n_x, n_y, n_z)`` transpose, which is already Fortran-ordered), turns booleans into
``uint8`` (VTK XML has no boolean type), builds polyline connectivity with NumPy and
renames pyevtk's output into place. Coordinates are world millimetres. No field data: pyevtk
places it inside the ``Piece`` element, where VTK's readers (and ParaView) do not look;
times go into the ``.pvd`` collection instead.

Array conventions (every writer): a scalar is an array with the grid's (or the point
set's) shape, a vector adds a last axis of 3 (x, y, z components) and is written as a
3-component VTK array, so ParaView offers it to Glyph and Stream Tracer directly.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError
from mitpiv.io.atomic import atomic_path

__all__ = ["write_image_data", "write_structured_grid", "write_points", "write_tracks", "write_cells",
           "write_collection", "VTK_SUFFIXES"]

log = logging.getLogger(__name__)

#: The file suffix of each writer's output.
VTK_SUFFIXES = {"image": ".vti", "structured": ".vts", "points": ".vtu", "tracks": ".vtu", "cells": ".vtu",
                "collection": ".pvd"}

_DTYPES = {np.dtype(t) for t in ("int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64",
                                 "float32", "float64")}


def _check_path(path, suffix: str, owner: str) -> Path:
    path = Path(path)
    if path.suffix.lower() != suffix:
        raise ConfigError(f"{owner}: the file name must end in {suffix!r} (VTK XML), got {str(path)!r}.")
    return path


def _as_vtk_array(a, name: str, owner: str) -> np.ndarray:
    a = np.asarray(a)
    if a.dtype == bool:
        return a.astype(np.uint8)
    if a.dtype not in _DTYPES:
        try:
            return a.astype(np.float64)
        except (TypeError, ValueError):
            raise ConfigError(f"{owner}: array {name!r} has dtype {a.dtype}; give numbers or booleans.") from None
    return a


def _layout(arrays: Mapping | None, shape: tuple, owner: str, *, to_vtk) -> dict:
    """pyevtk's data dict: scalars as one array, vectors as a tuple of three, each passed
    through ``to_vtk`` (the reordering of the grid into VTK's x-fastest layout)."""
    out = {}
    for name, value in (arrays or {}).items():
        a = _as_vtk_array(value, name, owner)
        if a.shape == shape:
            out[name] = np.ascontiguousarray(to_vtk(a)) if a.ndim == 1 else to_vtk(a)
        elif a.shape == (*shape, 3):
            out[name] = tuple(np.ascontiguousarray(to_vtk(a[..., c])) if a.ndim == 2 else
                              np.asfortranarray(to_vtk(a[..., c])) for c in range(3))
        else:
            raise ConfigError(f"{owner}: array {name!r} has shape {a.shape}; it must be {shape} (a scalar) or "
                              f"{(*shape, 3)} (a vector x, y, z).")
    return out


def _write(path: Path, suffix: str, fn) -> Path:
    """Run the pyevtk writer ``fn(stem)`` (it appends ``suffix``) on a temporary name beside
    ``path``, then rename it into place."""
    with atomic_path(path, suffix=suffix) as tmp:
        fn(str(tmp)[: -len(suffix)])
    return path


def _zyx_to_vtk(a):
    """(n_z, n_y, n_x) -> the (n_x, n_y, n_z) Fortran-ordered view pyevtk writes x-fastest."""
    return np.asfortranarray(np.transpose(a, (2, 1, 0)))


def write_image_data(path, grid, arrays: Mapping[str, np.ndarray]) -> Path:
    """Write volumes on a :class:`~mitpiv.grid.VoxelGrid` as VTK image data (``.vti``).

    Parameters
    ----------
    path : str or Path
        Target file, ``.vti``.
    grid : VoxelGrid
        The voxel grid; the values are point data at the voxel centres (the image's origin
        is the centre of voxel (0, 0, 0), its spacing the voxel size) [mm].
    arrays : mapping of name -> (n_z, n_y, n_x) or (n_z, n_y, n_x, 3) array
        Scalars (e.g. ``{"reconstructed": vol, "true": truth}``) or vectors.

    Returns
    -------
    Path
        ``path``.
    """
    path = _check_path(path, ".vti", "write_image_data")
    if not arrays:
        raise ConfigError("write_image_data: give at least one array (name -> (n_z, n_y, n_x) volume).")
    from pyevtk.hl import imageToVTK

    data = _layout(arrays, tuple(grid.shape), "write_image_data", to_vtk=_zyx_to_vtk)
    origin = tuple(float(o + 0.5 * d) for o, d in zip(grid.origin_mm, grid.voxel_mm, strict=True))
    return _write(path, ".vti", lambda stem: imageToVTK(stem, origin=origin, spacing=tuple(grid.voxel_mm),
                                                        pointData=data))


def write_structured_grid(path, x_mm, y_mm, z_mm, arrays: Mapping[str, np.ndarray]) -> Path:
    """Write point data on a lattice (e.g. a PIV vector field) as a VTK structured grid (``.vts``).

    Parameters
    ----------
    path : str or Path
        Target file, ``.vts``.
    x_mm, y_mm, z_mm : (n_x,), (n_y,), (n_z,) array
        The lattice's coordinates along each axis [mm] (the interrogation-window centres).
    arrays : mapping of name -> (n_z, n_y, n_x) or (n_z, n_y, n_x, 3) array
        Scalars or vectors at the lattice points (booleans are written as uint8 0 / 1).

    Returns
    -------
    Path
        ``path``.
    """
    path = _check_path(path, ".vts", "write_structured_grid")
    from pyevtk.hl import gridToVTK

    x, y, z = (np.asarray(a, dtype=np.float64).ravel() for a in (x_mm, y_mm, z_mm))
    shape = (z.size, y.size, x.size)
    if min(shape) < 1:
        raise ConfigError(f"write_structured_grid: empty lattice {shape} (n_z, n_y, n_x).")
    zz, yy, xx = np.meshgrid(z, y, x, indexing="ij")
    data = _layout(arrays, shape, "write_structured_grid", to_vtk=_zyx_to_vtk)
    return _write(path, ".vts", lambda stem: gridToVTK(stem, _zyx_to_vtk(xx), _zyx_to_vtk(yy), _zyx_to_vtk(zz),
                                                       pointData=data or None))


def _positions(p, owner: str, name: str = "positions_mm") -> np.ndarray:
    a = np.asarray(p, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ConfigError(f"{owner}: {name!r} must be an (N, 3) array of x, y, z [mm], got shape {a.shape}.")
    return a


def write_points(path, positions_mm, arrays: Mapping[str, np.ndarray] | None = None) -> Path:
    """Write particles as a VTK point cloud (unstructured grid of vertices, ``.vtu``).

    Parameters
    ----------
    path : str or Path
        Target file, ``.vtu``.
    positions_mm : (N, 3) array
        Particle positions x, y, z [mm].
    arrays : mapping of name -> (N,) or (N, 3) array, optional
        Per-particle values (e.g. ``match`` as a boolean, ``error_mm`` as a vector).

    Returns
    -------
    Path
        ``path``.
    """
    path = _check_path(path, ".vtu", "write_points")
    from pyevtk.hl import pointsToVTK

    p = _positions(positions_mm, "write_points")
    data = _layout(arrays, (p.shape[0],), "write_points", to_vtk=lambda a: a)
    cols = tuple(np.ascontiguousarray(p[:, c]) for c in range(3))
    return _write(path, ".vtu", lambda stem: pointsToVTK(stem, *cols, data=data or None))


def write_tracks(path, positions_mm, track_id, arrays: Mapping[str, np.ndarray] | None = None, *,
                 track_arrays: Mapping[str, np.ndarray] | None = None) -> Path:
    """Write particle tracks as VTK polylines (``.vtu``), one polyline per track.

    Parameters
    ----------
    path : str or Path
        Target file, ``.vtu``.
    positions_mm : (N, 3) array
        Every track point x, y, z [mm], in time order within each track.
    track_id : (N,) int array
        The track of each point. Points are grouped by track (a stable sort, so each
        track keeps its points' order); tracks are written in ascending id.
    arrays : mapping of name -> (N,) or (N, 3) array, optional
        Per-point values (e.g. ``time_s``, ``velocity_mm_s``).
    track_arrays : mapping of name -> (T,) or (T, 3) array, optional
        Per-track values for the T distinct ids in ascending order (e.g. ``correct``).

    Returns
    -------
    Path
        ``path``. The file also holds the point array ``track_id`` and the cell array
        ``track_id``.
    """
    path = _check_path(path, ".vtu", "write_tracks")
    from pyevtk.hl import unstructuredGridToVTK
    from pyevtk.vtk import VtkPolyLine

    p = _positions(positions_mm, "write_tracks")
    tid = np.asarray(track_id).ravel()
    if tid.shape[0] != p.shape[0] or not np.issubdtype(tid.dtype, np.integer):
        raise ConfigError(f"write_tracks: 'track_id' must be {p.shape[0]} integers (one per point), got "
                          f"{tid.shape[0]} of dtype {tid.dtype}.")
    order = np.argsort(tid, kind="stable")
    p, tid = p[order], tid[order]
    ids, counts = np.unique(tid, return_counts=True)
    pts = {"track_id": tid.astype(np.int64),
           **{k: _as_vtk_array(v, k, "write_tracks")[order] for k, v in (arrays or {}).items()}}
    point_data = _layout(pts, (p.shape[0],), "write_tracks", to_vtk=lambda a: a)
    cell_data = _layout({"track_id": ids.astype(np.int64), **(track_arrays or {})}, (ids.size,), "write_tracks",
                        to_vtk=lambda a: a)
    connectivity = np.arange(p.shape[0], dtype=np.int32)
    offsets = np.cumsum(counts).astype(np.int32)
    types = np.full(ids.size, VtkPolyLine.tid, dtype=np.uint8)
    cols = tuple(np.ascontiguousarray(p[:, c]) for c in range(3))
    return _write(path, ".vtu", lambda stem: unstructuredGridToVTK(
        stem, *cols, connectivity=connectivity, offsets=offsets, cell_types=types, cellData=cell_data,
        pointData=point_data))


def write_cells(path, points_mm, cells: Sequence[Sequence[int]], arrays: Mapping[str, np.ndarray] | None = None
                ) -> Path:
    """Write line and polygon geometry (wireframes, outlines, faces) as a VTK unstructured
    grid (``.vtu``): a cell of two point indices is a line, of more a polygon.

    Parameters
    ----------
    path : str or Path
        Target file, ``.vtu``.
    points_mm : (N, 3) array
        Vertices x, y, z [mm].
    cells : sequence of sequences of int
        Each cell's vertex indices (2: a line; 3 or more: a polygon, in order round it).
    arrays : mapping of name -> (C,) or (C, 3) array, optional
        Per-cell values (e.g. an integer ``part`` to colour by).

    Returns
    -------
    Path
        ``path``.
    """
    path = _check_path(path, ".vtu", "write_cells")
    from pyevtk.hl import unstructuredGridToVTK
    from pyevtk.vtk import VtkLine, VtkPolygon

    p = _positions(points_mm, "write_cells", "points_mm")
    cells = [np.asarray(c, dtype=np.int64).ravel() for c in cells]
    bad = [k for k, c in enumerate(cells) if c.size < 2 or c.min() < 0 or c.max() >= p.shape[0]]
    if bad:
        raise ConfigError(f"write_cells: cell {bad[0]} ({cells[bad[0]].tolist()}) must hold 2 or more indices of the "
                          f"{p.shape[0]} points.")
    cell_data = _layout(arrays, (len(cells),), "write_cells", to_vtk=lambda a: a)
    connectivity = np.concatenate(cells).astype(np.int32) if cells else np.zeros(0, np.int32)
    offsets = np.cumsum([c.size for c in cells]).astype(np.int32)
    types = np.array([VtkLine.tid if c.size == 2 else VtkPolygon.tid for c in cells], dtype=np.uint8)
    cols = tuple(np.ascontiguousarray(p[:, c]) for c in range(3))
    return _write(path, ".vtu", lambda stem: unstructuredGridToVTK(
        stem, *cols, connectivity=connectivity, offsets=offsets, cell_types=types, cellData=cell_data or None))


def write_collection(path, entries: Sequence[tuple]) -> Path:
    """Write a ParaView collection (``.pvd``) that opens several VTK files as one time series.

    Parameters
    ----------
    path : str or Path
        Target file, ``.pvd``.
    entries : sequence of (file, time_s), (file, time_s, part) or (file, time_s, part, name)
        Each dataset, its time [s], its part number (datasets of one part form one
        series in ParaView; default 0) and the part's name (the block name ParaView shows). A relative file is taken relative to the
        collection's folder; the collection stores every file relative to its folder.

    Returns
    -------
    Path
        ``path``.
    """
    path = _check_path(path, ".pvd", "write_collection")
    if not entries:
        raise ConfigError("write_collection: give at least one (file, time_s[, part]) entry.")
    from pyevtk.vtk import VtkGroup

    rows = []
    for e in entries:
        f, t, part, name = (*e, 0, "", "")[:4] if len(e) == 2 else (*e, "")[:4]
        full = Path(f) if Path(f).is_absolute() else path.parent / f
        if not full.is_file():  # what ParaView would not find (e.g. a path relative to the working folder)
            raise ConfigError(
                f"write_collection: entry {str(f)!r} is not a file: a relative entry is taken relative to the "
                f"collection's folder {str(path.parent)!r} (where ParaView looks), i.e. {str(full)!r}. Write the "
                f"file first and give its path relative to that folder (e.g. {Path(f).name!r}) or an absolute path.")
        rows.append((full, t, part, name))

    def write(stem):
        g = VtkGroup(stem)  # stores each file relative to the folder of stem, which is path's folder
        for full, t, part, name in rows:
            g.addFile(filepath=str(full), sim_time=float(t), part=int(part), name=str(name))
        g.save()

    return _write(path, ".pvd", write)
