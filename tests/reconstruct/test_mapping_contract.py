"""Reconstruction mappings on the camera contract: a PinholeMapping is its camera (no second
copy of the projection or its Jacobian), the fitted Soloff polynomial offers the same
methods (visible = on the sensor when it knows its resolution), mappings round-trip
through to_dict/from_dict, mapping_from_metadata reads cameras through
io.camera_from_metadata, and VoxelGrid keeps its old import paths."""

import json

import numpy as np
import pytest

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.physics.camera import Camera, PinholeCamera, place_camera
from mitpiv.physics.distortion import Distortion
from mitpiv.physics.plenoptic import PlenopticCamera
from mitpiv.reconstruct import CameraMapping, PinholeMapping, PolynomialMapping, mapping_from_metadata

RES = (128, 96)
ROT, POS = place_camera(azimuth_deg=25, elevation_deg=40, distance_mm=400)
CAM = PinholeCamera(RES, 50.0, 10.0, rotation=ROT, position_mm=POS, distortion=Distortion(k1=-3.0, p1=1e-3))
PTS = np.random.default_rng(0).uniform([-20, -20, -20], [20, 20, 20], (2000, 3))
# A Soloff polynomial fitted to the distorted camera over a 16 x 12 x 8 mm volume: its RMS
# reprojection error (the polynomial's model error for k1 = -3).
SOLOFF_FIT_RMS_TOL_PX = 0.05


def test_pinhole_mapping_is_its_camera():
    m = PinholeMapping(CAM)
    assert isinstance(m, Camera)
    np.testing.assert_array_equal(m.project(PTS), CAM.project(PTS))
    np.testing.assert_array_equal(m.jacobian(PTS), CAM.jacobian(PTS))
    np.testing.assert_array_equal(m.visible(PTS), CAM.visible(PTS))
    np.testing.assert_array_equal(m.in_front(PTS), CAM.in_front(PTS))
    vis = m.visible(PTS)
    assert 0.02 < vis.mean() < 0.9  # a partial view: in front, some off the sensor
    behind = 2 * POS - PTS  # mirrored through the pinhole: the same pixels, never visible
    np.testing.assert_allclose(m.project(behind), m.project(PTS), atol=1e-9)
    assert not m.visible(behind).any() and not m.in_front(behind).any()
    with pytest.raises(ConfigError, match="PinholeCamera"):
        PinholeMapping(PlenopticCamera(resolution=(64, 64), pixel_pitch_um=5.5, focal_length_mm=50.0, f_number=2.8,
                                       focus_distance_mm=250.0, mla_pitch_um=55.0))


def test_polynomial_mapping_contract():
    """A Soloff fit to the camera over a volume: the same methods; visible = on the sensor
    (it cannot know where its camera is: in_front is all True)."""
    vol = np.random.default_rng(1).uniform([-8, -6, -4], [8, 6, 4], (3000, 3))
    poly = PolynomialMapping.fit(CAM.project(vol), vol, resolution=RES)
    assert isinstance(poly, Camera)
    assert poly.rms_error(CAM.project(vol), vol) < SOLOFF_FIT_RMS_TOL_PX
    uv = poly.project(PTS)
    on = (uv[:, 0] >= 0) & (uv[:, 0] < RES[0]) & (uv[:, 1] >= 0) & (uv[:, 1] < RES[1])
    np.testing.assert_array_equal(poly.visible(PTS), on)
    assert poly.in_front(PTS).all() and 0 < on.mean() < 1
    bare = PolynomialMapping(poly.coefficients, poly.centre_mm, poly.scale_mm)  # no resolution: nothing to test
    assert bare.visible(PTS).all()


def test_mappings_round_trip_through_json():
    vol = np.random.default_rng(2).uniform([-8, -6, -4], [8, 6, 4], (500, 3))
    for m in (PinholeMapping(CAM), PolynomialMapping.fit(CAM.project(vol), vol, resolution=RES)):
        back = CameraMapping.from_dict(json.loads(json.dumps(m.to_dict())))
        assert type(back) is type(m) and back.resolution == m.resolution
        # the same numbers in the same memory layout (BLAS's kernel, and so its summation order,
        # depends on the layout and the CPU): exact equality then holds on any x86-64 CPU
        for name in ("coefficients",):
            if hasattr(m, name):
                assert getattr(m, name).flags["C_CONTIGUOUS"] and getattr(back, name).flags["C_CONTIGUOUS"]
        np.testing.assert_array_equal(back.project(vol), m.project(vol))
        np.testing.assert_array_equal(back.jacobian(vol), m.jacobian(vol))
        assert type(m).from_dict(m.to_dict()).to_dict() == m.to_dict()
    with pytest.raises(ConfigError, match="type"):
        CameraMapping.from_dict({"type": "tsai"})


def test_mapping_from_metadata_goes_through_camera_from_metadata():
    from mitpiv.io import camera_from_metadata

    meta = {"camera": {"type": "distorted_pinhole", **CAM.to_dict()}}
    m = mapping_from_metadata(meta)
    np.testing.assert_array_equal(m.project(PTS), camera_from_metadata(meta).project(PTS))
    np.testing.assert_array_equal(mapping_from_metadata(CAM.to_dict()).project(PTS), CAM.project(PTS))
    with pytest.raises(FileFormatError, match="no 'camera' entry"):
        mapping_from_metadata({"frame": 0})
    with pytest.raises(FileFormatError, match="'perspective'"):
        mapping_from_metadata({"camera": {"type": "perspective"}})
    plen = PlenopticCamera(resolution=(64, 64), pixel_pitch_um=5.5, focal_length_mm=50.0, f_number=2.8,
                           focus_distance_mm=250.0, mla_pitch_um=55.0)
    for d in ({"camera": {"type": "plenoptic", **plen.to_dict()}}, {"camera": plen.to_dict()}):
        with pytest.raises(ConfigError, match="no pinhole camera model"):
            mapping_from_metadata(d)


def test_voxel_grid_old_import_paths():
    import mitpiv.grid
    import mitpiv.reconstruct
    import mitpiv.reconstruct.grid

    assert mitpiv.reconstruct.VoxelGrid is mitpiv.reconstruct.grid.VoxelGrid is mitpiv.grid.VoxelGrid
    g = mitpiv.grid.VoxelGrid.from_bounds((0, 0, 0), (1, 2, 3), 0.5)
    assert g.shape == (6, 4, 2) and mitpiv.reconstruct.VoxelGrid.from_dict(g.to_dict()) == g
