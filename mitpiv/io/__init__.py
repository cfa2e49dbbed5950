"""File formats: EXR images with JSON metadata, particle PLY files, truth files, volumes."""

from mitpiv.io.camera import camera_from_metadata
from mitpiv.io.exr import read_exr, write_exr
from mitpiv.io.particles import read_particles_ply, read_truth, write_particles_ply, write_truth
from mitpiv.io.volume import read_volume, write_volume

__all__ = ["read_exr", "write_exr", "write_particles_ply", "read_particles_ply", "write_truth", "read_truth",
           "read_volume", "write_volume"]
__all__ += ["camera_from_metadata"]
