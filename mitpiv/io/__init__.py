"""File formats: EXR images with JSON metadata, particle PLY files, the truth format, volumes,
light fields, vector fields, particle matches, backlit dewarps and detections, run records
(JSON), figures, ParaView / VTK files (:mod:`mitpiv.io.vtk`), and a user's own data in:
OpenCV camera calibrations (:mod:`mitpiv.io.opencv`), DLT and third-order polynomial
calibration tables (:mod:`mitpiv.io.calibration_tables`) and particle lists (CSV); every writer is atomic (a temporary file in the same folder renamed over
the target). Cameras are rebuilt from image metadata by :func:`camera_from_metadata`.

io sits below the packages whose objects it stores: its readers return plain records
(dicts of arrays and metadata) that the classes build themselves from (``LightField.load``,
``VectorField.load``, ...), so io imports no lightfield or analysis module."""

from mitpiv.io.arrays import read_npz, write_npz
from mitpiv.io.backlit import read_detections, read_dewarp, write_detections, write_dewarp
from mitpiv.io.calibration_tables import (
    read_dlt_cameras,
    read_dlt_table,
    read_polynomial_cameras,
    read_polynomial_table,
    write_dlt_table,
    write_polynomial_table,
)
from mitpiv.io.camera import camera_from_metadata
from mitpiv.io.exr import read_exr, read_exr_metadata, write_exr
from mitpiv.io.figures import save_figure
from mitpiv.io.lightfield import read_lightfield, write_lightfield
from mitpiv.io.opencv import read_opencv_camera, write_opencv_camera
from mitpiv.io.particles import read_particles_csv, read_particles_ply, read_truth, write_particles_ply, write_truth
from mitpiv.io.records import read_json, to_jsonable, write_json, write_text
from mitpiv.io.vectors import read_vector_field, write_vector_field
from mitpiv.io.volume import read_volume, write_volume

__all__ = ["read_exr", "read_exr_metadata", "write_exr", "write_particles_ply", "read_particles_ply", "write_truth", "read_truth",
           "read_volume", "write_volume", "camera_from_metadata", "write_npz", "read_npz", "write_dewarp",
           "read_dewarp", "write_detections", "read_detections", "write_lightfield", "read_lightfield", "write_json",
           "read_json", "write_text", "to_jsonable", "write_vector_field", "read_vector_field", "save_figure",
           "read_particles_csv", "read_opencv_camera", "write_opencv_camera", "read_dlt_table", "write_dlt_table",
           "read_dlt_cameras", "read_polynomial_table", "write_polynomial_table", "read_polynomial_cameras"]
