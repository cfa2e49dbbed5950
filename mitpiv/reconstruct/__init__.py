"""Volumetric reconstruction (NumPy/SciPy/Numba, no renderer) and its inputs.

Camera mappings and calibration: ``calibrate`` fits a mapping to marker correspondences;
mappings have ``project()`` and ``jacobian()``; ``mapping_from_metadata`` gives the true
model of a rendered image. Reconstructions on a :class:`VoxelGrid`: ``mlos``, ``mart``
(MART / SMART), ``sapiv_refocus`` (camera arrays), ``plenoptic_volume``, ``fuse``
(multi-plenoptic) and ``drt_mart`` (dense-ray-tracing MART of a raw light-field image).
"""

from mitpiv.grid import VoxelGrid
from mitpiv.reconstruct.calibration import (
    apply_homography,
    calibrate,
    calibrate_views,
    detect_checkerboard,
    detect_dots,
    label_markers,
    plane_homographies,
)
from mitpiv.reconstruct.mapping import CameraMapping, PinholeMapping, PolynomialMapping, mapping_from_metadata

__all__ = [
    "calibrate",
    "calibrate_views",
    "detect_dots",
    "detect_checkerboard",
    "label_markers",
    "plane_homographies",
    "apply_homography",
    "CameraMapping",
    "PinholeMapping",
    "PolynomialMapping",
    "mapping_from_metadata",
]
from mitpiv.reconstruct.plenoptic import (  # noqa: E402
    drt_mart,
    drt_weights,
    fuse,
    paper_gamma_exponent,
    paper_refocus,
    paper_view_weights,
    plenoptic_volume,
)
from mitpiv.reconstruct.tomo import (  # noqa: E402
    WeightCache,
    mart,
    mlos,
    preprocess_images,
    reconstruct_volume,
    sapiv_refocus,
    voxel_weights,
)

__all__ += ["VoxelGrid", "mlos", "mart", "WeightCache", "reconstruct_volume", "sapiv_refocus", "preprocess_images", "voxel_weights", "plenoptic_volume",
            "fuse", "paper_gamma_exponent", "paper_refocus", "paper_view_weights", "drt_weights", "drt_mart"]
