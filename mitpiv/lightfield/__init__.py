"""Light-field decoding and refocusing for plenoptic 1.0 cameras (NumPy / Numba).

Pipeline: :func:`calibrate_mla` (white image -> lenslet lattice) -> :func:`decode` (raw ->
:class:`LightField` ``L[s, t, u, v]``) -> :func:`refocus` / :func:`focal_stack` /
:func:`refocus_volume`. Geometry: :func:`alpha_from_z`, :func:`depth_resolution`,
:func:`depth_of_field`; camera model and design calculators in
:mod:`mitpiv.physics.plenoptic`.
"""

from mitpiv.lightfield.calibration import MLACalibration, calibrate_mla, calibration_error, calibration_from_camera
from mitpiv.lightfield.decode import LightField, decode
from mitpiv.lightfield.geometry import (
    alpha_from_z,
    depth_of_field,
    depth_resolution,
    focal_plane_distance,
    z_from_alpha,
)
from mitpiv.lightfield.refocus import focal_stack, refocus, refocus_volume

__all__ = [
    "MLACalibration", "calibrate_mla", "calibration_error", "calibration_from_camera",
    "LightField", "decode", "refocus", "focal_stack", "refocus_volume",
    "alpha_from_z", "z_from_alpha", "depth_resolution", "depth_of_field", "focal_plane_distance",
]
