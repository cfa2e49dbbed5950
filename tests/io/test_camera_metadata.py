"""camera_from_metadata: one reader for every camera, from the metadata of real renders.

A tiny scene per camera is rendered, written to EXR with the camera entry render_scene
writes (``sensor_model``), read back, and the camera rebuilt. It must project exactly like
the plugin's own camera model, and the rendered particles must sit where it projects them:
the pinhole image's centroid within the box-filtered pixel (a 0.17 px proxy, so at most
half a pixel plus the proxy from the projection); the plenoptic camera's particles, one in
focus and one 6 mm behind the focal plane, both on the chief ray of a lenslet centre,
centred on that lenslet's image (the aperture image of a lenslet and the blur disk over
a symmetric patch of lenslets are symmetric about it)."""

import json

import numpy as np
import pytest

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.io import camera_from_metadata, read_exr, write_exr
from mitpiv.physics.camera import Camera, PinholeCamera
from mitpiv.physics.plenoptic import PlenopticCamera

PINHOLE_CENTROID_TOL_PX = 0.5 + 0.1  # box filter: the pixel centre of the pixel hit, + proxy
# The plenoptic centroid: Monte Carlo (1e5 rays over a ~5 px radius aperture image: 0.02 px)
# plus the binning of the aperture image into pixels (< 0.1 px for a disk ~10 px wide)
PLENOPTIC_CENTROID_TOL_PX = 0.1
MITSUBA_POSE_TOL_PX = 1e-3  # the render's true pose is float32 in Mitsuba, the nominal one float64


def _centroid(img, centre, half):
    h, w = img.shape
    yy, xx = np.mgrid[0:h, 0:w] + 0.5
    m = (np.abs(xx - centre[0]) <= half) & (np.abs(yy - centre[1]) <= half)
    s = img[m].sum()
    assert s > 0
    return np.array([(img * xx)[m].sum() / s, (img * yy)[m].sum() / s])


def _through_exr(tmp_path, img, sensor):
    from mitpiv.render.render import sensor_model

    path = write_exr(tmp_path / "img.exr", img.astype(np.float32), {"camera": sensor_model(sensor), "frame": 0})
    return read_exr(path)


def test_pinhole_from_rendered_metadata(tmp_path):
    from mitpiv.physics.camera import look_at_rotation
    from mitpiv.physics.distortion import Distortion
    from tests.render.helpers import render, scene

    # 12 mm lens, 10 um pixels at 500 mm: a 20 x 17 mm field; k1 = -150 bends its corners by ~1.2 px
    pos = np.array([0.0, 0.0, 500.0])
    cam0 = PinholeCamera((48, 40), 12.0, 10.0, rotation=look_at_rotation(pos, [0, 0, 0], up=[0, 1, 0]),
                         position_mm=pos, distortion=Distortion(k1=-150.0))
    pts = np.array([[-8.0, -6.5, 0.5], [-3.1, 4.2, -0.8], [0.3, 0.2, 0.0], [4.4, -2.9, 0.9], [7.6, 6.1, -0.4]])
    sc = scene(tmp_path, pts, cam=cam0, sensor_props={"k1": -150.0})
    sensor = sc.sensors()[0]
    img = render(sc)
    back, meta = _through_exr(tmp_path, img, sensor)
    cam = camera_from_metadata(meta)
    assert isinstance(cam, PinholeCamera) and isinstance(cam, Camera)
    assert camera_from_metadata(meta["camera"]).to_dict() == cam.to_dict()  # the entry itself works too
    grid = np.random.default_rng(5).uniform(-4, 4, (200, 3))
    np.testing.assert_allclose(cam.project(grid), sensor.camera.project(grid), rtol=0, atol=1e-9)
    np.testing.assert_array_equal(cam.visible(grid), sensor.camera.visible(grid))
    uv = cam.project(pts)
    assert np.all(cam.visible(pts))
    for p_uv in uv:
        np.testing.assert_allclose(_centroid(back, p_uv, 2.5), p_uv, atol=PINHOLE_CENTROID_TOL_PX)
    # the true pose of the render (float32 in Mitsuba) and the nominal one agree to 1e-3 px;
    # the distortion was read back (it moves the corner particles by pixels)
    np.testing.assert_allclose(uv, cam0.project(pts), atol=MITSUBA_POSE_TOL_PX)
    assert cam.distortion.k1 == -150.0
    assert np.abs(uv - PinholeCamera((48, 40), 12.0, 10.0, rotation=cam.rotation, position_mm=cam.position_mm)
                  .project(pts)).max() > 2 * PINHOLE_CENTROID_TOL_PX


def test_plenoptic_from_rendered_metadata(tmp_path):
    import mitsuba as mi

    from tests.lightfield.helpers import particle_scene, render, sensor

    nominal = mi.load_dict(sensor(200)).camera
    si, so = nominal.image_distance_mm, nominal.focus_distance_mm
    centres = nominal.lenslet_centres_mm()  # (ny, nx, 2) on the MLA, sensor frame
    picks = [(10, 7), (9, 13)]  # (row, col): 6 lenslets apart
    pts_local = []
    for (r, c), dz in zip(picks, (0.0, 6.0), strict=True):
        depth = so + dz  # on the chief ray of the lenslet centre: X_mla = -s_i (x, y) / z
        pts_local.append([*(-centres[r, c] * depth / si), depth])
    m = nominal.to_world_mitsuba
    pts = np.asarray(pts_local) @ m[:3, :3].T + m[:3, 3]
    sc = particle_scene(tmp_path, pts, {"type": "particle_tracer", "rays_per_particle": 100_000})
    sens = sc.sensors()[0]
    img = render(sc)
    back, meta = _through_exr(tmp_path, img, sens)
    cam = camera_from_metadata(meta)
    assert isinstance(cam, PlenopticCamera) and isinstance(cam, Camera)
    grid = np.random.default_rng(6).uniform(-4, 4, (200, 3))
    np.testing.assert_allclose(cam.project(grid), sens.camera.project(grid), rtol=0, atol=1e-9)
    np.testing.assert_allclose(cam.image_centres_px(), sens.camera.image_centres_px(), rtol=0, atol=1e-9)
    uv = cam.project(pts)
    expect = cam.image_centres_px()[[r for r, _ in picks], [c for _, c in picks]]
    np.testing.assert_allclose(uv, expect, atol=MITSUBA_POSE_TOL_PX)
    for p_uv, half in zip(uv, (8.0, 25.0), strict=True):  # in focus: one aperture image; defocused: a patch
        np.testing.assert_allclose(_centroid(back, p_uv, half), p_uv, atol=PLENOPTIC_CENTROID_TOL_PX)


def _pinhole_dict():
    return PinholeCamera((16, 12), 20.0, 10.0).to_dict()


def test_accepted_forms():
    d = _pinhole_dict()  # a camera's to_dict (a "model", no "type")
    for meta in (d, {"camera": d}, {"camera": {**d, "type": "distorted_pinhole"}}, json.loads(json.dumps({"camera": d}))):
        assert camera_from_metadata(meta).project([[0.0, 0.0, 100.0]]).tolist() == [[8.0, 6.0]]


def test_unusable_metadata_is_a_file_format_error():
    with pytest.raises(FileFormatError, match="no 'camera' entry"):
        camera_from_metadata({"frame": 0, "seed": 1})
    with pytest.raises(FileFormatError, match="'perspective'"):
        camera_from_metadata({"camera": {"type": "perspective", "resolution": [8, 8]}})
    with pytest.raises(FileFormatError, match="not a camera description"):
        camera_from_metadata({"camera": [1, 2]})
    d = _pinhole_dict()
    del d["R"]
    with pytest.raises(FileFormatError, match="'R'"):
        camera_from_metadata({"camera": d})
    with pytest.raises(FileFormatError, match="mla_pitch_um"):
        camera_from_metadata({"camera": {"type": "plenoptic", "resolution": [8, 8], "pixel_pitch_um": 5.5,
                                         "focal_length_mm": 50.0, "focus_distance_mm": 250.0}})
    with pytest.raises(ConfigError, match="metadata dict"):
        camera_from_metadata("cam0_frame000.exr")
    bad = {**_pinhole_dict(), "focal_length_mm": -1.0}  # stored but invalid values: the model says why
    with pytest.raises(ConfigError, match="focal_length_mm"):
        camera_from_metadata(bad)
