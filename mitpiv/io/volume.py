"""Reconstructed volumes on disk: ``.npz`` with the (n_z, n_y, n_x) array and JSON metadata
(the voxel grid, the method, ...), written atomically."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.io.atomic import atomic_path


def write_volume(path, volume, meta: dict) -> Path:
    """Write ``volume`` and ``meta`` (must hold ``grid``, a VoxelGrid dict) to ``path`` (.npz)."""
    path = Path(path)
    if path.suffix != ".npz":
        raise ConfigError(f"write_volume: file name must end in .npz, got {str(path)!r}.")
    if "grid" not in meta:
        raise ConfigError("write_volume: meta must hold the voxel grid ('grid': VoxelGrid.to_dict()).")
    with atomic_path(path, suffix=".npz") as tmp:
        with open(tmp, "wb") as fh:
            np.savez_compressed(fh, volume=np.asarray(volume), meta=json.dumps(meta))
    return path


def read_volume(path):
    """(volume, VoxelGrid, meta) from a file written by :func:`write_volume`."""
    from mitpiv.grid import VoxelGrid

    path = Path(path)
    if not path.is_file():
        raise FileFormatError(f"volume file {str(path)!r} does not exist.")
    try:
        with np.load(path) as z:
            vol = z["volume"]
            meta = json.loads(str(z["meta"]))
        grid = VoxelGrid.from_dict(meta["grid"])
    except (KeyError, ValueError, OSError) as e:
        raise FileFormatError(f"{str(path)!r} is not a volume written by 'mitpiv reconstruct' ({e}).") from None
    return grid.check_volume(vol, str(path)), grid, meta
