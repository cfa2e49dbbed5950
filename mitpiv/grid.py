"""The voxel grid every reconstruction and every volume analysis is computed on: world
millimetres, axis-aligned, anisotropic voxel sizes allowed.

A low-level module (it imports only :mod:`mitpiv.errors`): :mod:`mitpiv.reconstruct`,
:mod:`mitpiv.analysis` and :mod:`mitpiv.io` import it without importing one another.
``mitpiv.reconstruct.VoxelGrid`` and ``mitpiv.reconstruct.grid.VoxelGrid`` re-export it.

Layout: a volume is a ``(n_z, n_y, n_x)`` array; voxel ``(k, j, i)`` is the cell
``origin + [i, i+1) dx`` x ``[j, j+1) dy`` x ``[k, k+1) dz`` and its centre is at
``origin + (i + 0.5, j + 0.5, k + 0.5) * voxel_mm``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mitpiv.errors import ConfigError

__all__ = ["VoxelGrid"]


def _triple(name: str, value, *, positive: bool) -> tuple[float, float, float]:
    try:
        v = np.broadcast_to(np.asarray(value, dtype=float), (3,))
    except (TypeError, ValueError):
        raise ConfigError(f"VoxelGrid: '{name}' must be three numbers (x, y, z) [mm], got {value!r}.") from None
    if not np.all(np.isfinite(v)) or (positive and np.any(v <= 0)):
        what = "finite and > 0" if positive else "finite"
        raise ConfigError(f"VoxelGrid: '{name}' must be {what} [mm], got {value!r}.")
    return tuple(float(x) for x in v)


@dataclass(frozen=True)
class VoxelGrid:
    """Axis-aligned voxel grid in world millimetres.

    Parameters
    ----------
    origin_mm : (3,) float
        Lower corner (x, y, z) of voxel (0, 0, 0) [mm].
    voxel_mm : (3,) float or float
        Voxel size (dx, dy, dz) [mm]; anisotropic sizes are allowed.
    shape : (n_z, n_y, n_x) int
        Array shape of a volume on this grid.
    """

    origin_mm: tuple
    voxel_mm: tuple
    shape: tuple

    def __post_init__(self) -> None:
        object.__setattr__(self, "origin_mm", _triple("origin_mm", self.origin_mm, positive=False))
        object.__setattr__(self, "voxel_mm", _triple("voxel_mm", self.voxel_mm, positive=True))
        try:
            shp = tuple(int(n) for n in self.shape)
        except (TypeError, ValueError):
            shp = ()
        if len(shp) != 3 or min(shp) < 1 or shp != tuple(self.shape):
            raise ConfigError(f"VoxelGrid: 'shape' must be three positive integers (n_z, n_y, n_x), got {self.shape!r}.")
        if math.prod(shp) > 2**31 - 1:
            raise ConfigError(f"VoxelGrid: {math.prod(shp)} voxels exceed 2^31 - 1; use larger voxels or split the volume.")
        object.__setattr__(self, "shape", shp)

    @classmethod
    def from_bounds(cls, lower_mm, upper_mm, voxel_mm) -> VoxelGrid:
        """Grid covering the box ``[lower, upper]`` with voxels of ``voxel_mm``.

        When the box is not a whole number of voxels the voxel count is rounded up and the
        grid is centred on the box.
        """
        lo = np.asarray(_triple("lower_mm", lower_mm, positive=False))
        hi = np.asarray(_triple("upper_mm", upper_mm, positive=False))
        d = np.asarray(_triple("voxel_mm", voxel_mm, positive=True))
        if np.any(hi <= lo):
            raise ConfigError(f"VoxelGrid.from_bounds: 'upper_mm' {hi.tolist()} must exceed 'lower_mm' {lo.tolist()} on every axis.")
        ext = hi - lo
        n = np.maximum(np.ceil(ext / d - 1e-9), 1).astype(int)
        origin = 0.5 * (lo + hi) - 0.5 * n * d
        return cls(tuple(origin), tuple(d), (int(n[2]), int(n[1]), int(n[0])))

    @classmethod
    def for_camera(cls, lower_mm, upper_mm, *, pixel_size_mm: float, ratio=(1.0, 1.0, 1.0)) -> VoxelGrid:
        """Grid whose voxels are ``ratio`` times a camera pixel's object-space size.

        ``pixel_size_mm`` is the pixel pitch divided by the magnification (e.g.
        ``pixel_pitch_um * 1e-3 / camera.magnification``); ``ratio`` is the pixel:voxel
        ratio per axis (x, y, z), such as ``(2, 2, 10)`` for light-field reconstructions.
        """
        r = np.asarray(_triple("ratio", ratio, positive=True))
        if not (np.isfinite(pixel_size_mm) and pixel_size_mm > 0):
            raise ConfigError(f"VoxelGrid.for_camera: 'pixel_size_mm' must be > 0, got {pixel_size_mm!r}.")
        return cls.from_bounds(lower_mm, upper_mm, r * pixel_size_mm)

    # ------------------------------------------------------------------ geometry
    @property
    def n_voxels(self) -> int:
        return math.prod(self.shape)

    @property
    def upper_mm(self) -> tuple:
        nz, ny, nx = self.shape
        return tuple(o + n * d for o, n, d in zip(self.origin_mm, (nx, ny, nz), self.voxel_mm, strict=True))

    @property
    def centre_mm(self) -> np.ndarray:
        return 0.5 * (np.asarray(self.origin_mm) + np.asarray(self.upper_mm))

    @property
    def x_mm(self) -> np.ndarray:
        """Voxel-centre x coordinates (n_x,) [mm]."""
        return self.origin_mm[0] + (np.arange(self.shape[2]) + 0.5) * self.voxel_mm[0]

    @property
    def y_mm(self) -> np.ndarray:
        return self.origin_mm[1] + (np.arange(self.shape[1]) + 0.5) * self.voxel_mm[1]

    @property
    def z_mm(self) -> np.ndarray:
        return self.origin_mm[2] + (np.arange(self.shape[0]) + 0.5) * self.voxel_mm[2]

    def plane_points(self, k: int) -> np.ndarray:
        """Voxel centres of plane ``k``, shape (n_y, n_x, 3) [mm]."""
        yy, xx = np.meshgrid(self.y_mm, self.x_mm, indexing="ij")
        return np.stack([xx, yy, np.full_like(xx, self.z_mm[k])], axis=-1)

    def centres(self, flat_index) -> np.ndarray:
        """Voxel centres (..., 3) [mm] of flat (C-order) voxel indices."""
        k, j, i = np.unravel_index(np.asarray(flat_index), self.shape)
        return np.stack([self.x_mm[i], self.y_mm[j], self.z_mm[k]], axis=-1)

    def to_voxel(self, p_world) -> np.ndarray:
        """World points (..., 3) [mm] -> continuous voxel coordinates (..., 3) in (i, j, k) order
        (voxel centres at integers)."""
        p = np.asarray(p_world, dtype=float)
        return (p - np.asarray(self.origin_mm)) / np.asarray(self.voxel_mm) - 0.5

    def check_volume(self, volume, name: str = "volume") -> np.ndarray:
        v = np.asarray(volume)
        if v.shape != self.shape:
            raise ConfigError(f"'{name}' has shape {v.shape}; the grid needs {self.shape} (n_z, n_y, n_x).")
        return v

    def to_dict(self) -> dict:
        return {"origin_mm": list(self.origin_mm), "voxel_mm": list(self.voxel_mm), "shape": list(self.shape),
                "layout": "volume[k, j, i]: z_k, y_j, x_i; centres origin + (index + 0.5) * voxel"}

    @classmethod
    def from_dict(cls, d: dict) -> VoxelGrid:
        return cls(tuple(d["origin_mm"]), tuple(d["voxel_mm"]), tuple(d["shape"]))
