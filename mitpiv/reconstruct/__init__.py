"""Reconstruction inputs: camera mappings and their calibration (NumPy/OpenCV, no renderer).

``calibrate`` fits a mapping to marker correspondences; mappings have ``project()`` and
``jacobian()``; ``mapping_from_metadata`` gives the true model of a rendered image.
"""

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
