"""Deprecated home of :class:`~mitpiv.grid.VoxelGrid`; it lives in :mod:`mitpiv.grid` (imported by
reconstruction, analysis and io alike). This re-export keeps ``mitpiv.reconstruct.grid.VoxelGrid``
working."""

from mitpiv.grid import VoxelGrid

__all__ = ["VoxelGrid"]
