"""Particles found in a volume and matched to the truth, on disk (``.npz``, atomic): the
record of a :class:`~mitpiv.analysis.particles.MatchResult`.

Entries: ``pairs`` (K, 2) int (found, truth) indices, ``errors_mm`` (K, 3) found - truth,
``truth_index`` (optional), ``found_mm`` (optional, (n_found, 3): every found position,
ghosts included) and JSON ``meta`` = ``{"n_found", "n_truth", "radius_mm",
"voxel_mm"}``.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from mitpiv.errors import FileFormatError
from mitpiv.io.arrays import json_entry, read_npz, write_npz
from mitpiv.io.records import to_jsonable

__all__ = ["write_matches", "read_matches"]


def write_matches(path, result) -> Path:
    """Write a :class:`~mitpiv.analysis.particles.MatchResult` to ``path`` (``.npz``, atomic)."""
    meta = {"n_found": int(result.n_found), "n_truth": int(result.n_truth), "radius_mm": float(result.radius_mm),
            "voxel_mm": None if result.voxel_mm is None else list(result.voxel_mm)}
    return write_npz(path, {"pairs": np.asarray(result.pairs), "errors_mm": np.asarray(result.errors_mm),
                            "truth_index": result.truth_index, "found_mm": getattr(result, "found_mm", None),
                            "meta": json.dumps(to_jsonable(meta))},
                     owner="write_matches")


def read_matches(path) -> dict:
    """Read the record that ``MatchResult(**record)`` takes (``MatchResult.load(path)`` does that)."""
    z = read_npz(path, what="mitpiv particle matches", required=("pairs", "errors_mm", "meta"))
    meta = json_entry(z, "meta", path)
    try:
        return {"pairs": z["pairs"], "errors_mm": z["errors_mm"], "n_found": int(meta["n_found"]),
                "n_truth": int(meta["n_truth"]), "radius_mm": float(meta["radius_mm"]),
                "voxel_mm": None if meta["voxel_mm"] is None else tuple(meta["voxel_mm"]),
                "truth_index": z.get("truth_index"), "found_mm": z.get("found_mm")}
    except (KeyError, TypeError) as e:
        raise FileFormatError(f"{str(path)!r}: the matches' meta lacks {e}.") from None
