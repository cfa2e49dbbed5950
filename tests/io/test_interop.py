"""A user's own data in: an OpenCV calibration (YAML / XML written by OpenCV's FileStorage,
plain JSON) becomes a mitpiv camera that projects as OpenCV's ``projectPoints`` does, and
drives a render (the ``distorted_pinhole`` ``calibration`` property); a particle list in
CSV drives a render (and an experiment: tests/studies/test_outputs.py)."""

import cv2
import numpy as np
import pytest

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.io import read_opencv_camera, read_particles_csv, write_opencv_camera

#: float64 projection of the same model by two implementations (mitpiv's distortion and
#: OpenCV's): agreement to rounding.
PROJECTION_ATOL_PX = 1e-6
#: With a box film filter a particle's whole image lands in one pixel: its centroid is that
#: pixel's centre, to float32 accumulation (as tests/render/test_plugins.py).
BOX_CENTROID_ATOL_PX = 1e-6

K = np.array([[8500.0, 0.0, 95.3], [0.0, 8500.0, 81.7], [0.0, 0.0, 1.0]])  # 85 mm on 10 um pixels
DIST = np.array([[-0.3, 0.8, 1e-3, -2e-3, 0.0]])  # k1, k2, p1, p2, k3
RVEC = np.array([[0.15], [-0.25], [0.05]])
TVEC = np.array([[3.0], [-2.0], [500.0]])  # mm: the target 500 mm in front of the camera
SIZE = (192, 160)


def write_fs(path, **entries):
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for k, v in entries.items():
        fs.write(k, v)
    fs.release()
    return path


def opencv_pixels(points):
    """OpenCV's own projection, moved to mitpiv's pixel convention (centres at i + 0.5)."""
    uv, _ = cv2.projectPoints(np.asarray(points, float).reshape(-1, 1, 3), RVEC, TVEC, K, DIST)
    return uv.reshape(-1, 2) + 0.5


@pytest.mark.parametrize("suffix", [".yml", ".xml", ".json"])
def test_opencv_calibration_projects_like_opencv(tmp_path, suffix):
    f = write_fs(tmp_path / f"cam{suffix}", image_width=SIZE[0], image_height=SIZE[1], camera_matrix=K,
                 distortion_coefficients=DIST, rvec=RVEC, tvec=TVEC)
    cam = read_opencv_camera(f, pixel_pitch_um=10.0)
    assert cam.resolution == SIZE and cam.focal_length_mm == pytest.approx(85.0)
    pts = np.random.default_rng(0).uniform([-6, -5, -3], [6, 5, 3], (200, 3))
    np.testing.assert_allclose(cam.project(pts), opencv_pixels(pts), atol=PROJECTION_ATOL_PX)
    # written back by mitpiv, read by OpenCV and by mitpiv: the same camera
    g = write_opencv_camera(tmp_path / f"back{suffix}", cam)
    fs = cv2.FileStorage(str(g), cv2.FILE_STORAGE_READ)
    np.testing.assert_allclose(fs.getNode("camera_matrix").mat(), K, rtol=1e-12)
    fs.release()
    again = read_opencv_camera(g)  # the pitch travels in the file
    np.testing.assert_allclose(again.project(pts), cam.project(pts), atol=PROJECTION_ATOL_PX)


def test_plain_json_and_size_option(tmp_path):
    import json

    f = tmp_path / "cam.json"
    f.write_text(json.dumps({"K": K.tolist(), "dist_coeffs": DIST.ravel()[:4].tolist()}))
    cam = read_opencv_camera(f, pixel_pitch_um=10.0, resolution=SIZE)
    assert cam.distortion.k3 == 0 and cam.principal_point_px == (95.8, 82.2)
    assert np.allclose(cam.position_mm, 0) and np.allclose(cam.rotation, np.eye(3))  # no pose in the file


def test_bad_calibrations(tmp_path):
    def fs(name, **kw):
        base = {"image_width": SIZE[0], "image_height": SIZE[1], "camera_matrix": K, "distortion_coefficients": DIST}
        return write_fs(tmp_path / name, **{**base, **kw})

    with pytest.raises(ConfigError, match="square pixels"):
        read_opencv_camera(fs("a.yml", camera_matrix=np.diag([8500.0, 8600.0, 1.0])), pixel_pitch_um=10)
    with pytest.raises(ConfigError, match="skew"):
        read_opencv_camera(fs("b.yml", camera_matrix=K + np.array([[0, 3.0, 0], [0, 0, 0], [0, 0, 0]])),
                           pixel_pitch_um=10)
    with pytest.raises(ConfigError, match="k4"):
        read_opencv_camera(fs("c.yml", distortion_coefficients=np.array([[0.1, 0, 0, 0, 0, 0.2, 0, 0]])),
                           pixel_pitch_um=10)
    with pytest.raises(ConfigError, match="pixel_pitch_um"):
        read_opencv_camera(fs("d.yml"))
    with pytest.raises(ConfigError, match="192 x 160"):
        read_opencv_camera(fs("e.yml"), pixel_pitch_um=10, resolution=(100, 100))
    with pytest.raises(ConfigError, match="pose"):
        read_opencv_camera(fs("f.yml", rvec=RVEC, tvec=TVEC), pixel_pitch_um=10, pose="forbid")
    with pytest.raises(FileFormatError, match="camera matrix"):
        read_opencv_camera(write_fs(tmp_path / "g.yml", foo=np.eye(2)), pixel_pitch_um=10)
    with pytest.raises(FileFormatError, match="does not exist"):
        read_opencv_camera(tmp_path / "none.yml", pixel_pitch_um=10)


def test_particle_csv(tmp_path):
    f = tmp_path / "p.csv"
    f.write_text("# my particles\nid,Z_mm,x_mm,y_mm,diameter_um\n0,0.5,1.0,2.0,1.5\n1,-0.5,-1.0,0.25,2.0\n")
    p = read_particles_csv(f)
    np.testing.assert_array_equal(p["positions_mm"], [[1.0, 2.0, 0.5], [-1.0, 0.25, -0.5]])
    np.testing.assert_array_equal(p["diameters_um"], [1.5, 2.0])
    g = tmp_path / "q.csv"
    g.write_text("x,y,z\n0.001,0.002,0.0\n")
    assert read_particles_csv(g, diameter_um=1.0, length_unit_mm=1000.0)["positions_mm"].tolist() == [[1.0, 2.0, 0.0]]
    with pytest.raises(ConfigError, match="diameter"):
        read_particles_csv(g)
    h = tmp_path / "r.csv"
    h.write_text("x_mm,y_mm\n1,2\n")
    with pytest.raises(FileFormatError, match="z_mm"):
        read_particles_csv(h, diameter_um=1.0)
    h.write_text("x_mm,y_mm,z_mm\n1,2,abc\n")
    with pytest.raises(FileFormatError, match="non-numeric"):
        read_particles_csv(h, diameter_um=1.0)


def test_calibration_file_and_particle_csv_drive_a_render(tmp_path):
    """Particles from a CSV rendered through a sensor built from an OpenCV calibration
    (pose included): each particle's image lands in the pixel OpenCV projects it to."""
    import mitsuba as mi

    from mitpiv.io import write_particles_ply
    from mitpiv.render.scene import load_dict

    rng = np.random.default_rng(1)
    pts = rng.uniform([-4, -3, -1], [4, 3, 1], (60, 3))
    uv = opencv_pixels(pts)
    frac = uv - np.floor(uv)
    inside = np.all((uv > 1) & (uv < np.array(SIZE) - 1), axis=1)
    pts = pts[np.all((frac > 0.05) & (frac < 0.95), axis=1) & inside][:12]  # clear of pixel edges (float32 rays)
    uv = opencv_pixels(pts)
    np.savetxt(tmp_path / "particles.csv", pts, delimiter=",", header="x_mm,y_mm,z_mm", comments="")
    user = read_particles_csv(tmp_path / "particles.csv", diameter_um=2.0)
    write_particles_ply(tmp_path / "p.ply", user["positions_mm"], user["diameters_um"], proxy_radius_mm=0.01)
    write_fs(tmp_path / "cam0.yml", image_width=SIZE[0], image_height=SIZE[1], camera_matrix=K,
             distortion_coefficients=DIST, rvec=RVEC, tvec=TVEC)
    sc = load_dict({
        "type": "scene", "integrator": {"type": "particle_tracer"},
        "sensor": {"type": "distorted_pinhole", "calibration": str(tmp_path / "cam0.yml"), "pixel_pitch_um": 10.0,
                   "film": {"type": "hdrfilm", "width": SIZE[0], "height": SIZE[1], "pixel_format": "luminance",
                            "rfilter": {"type": "box"}}},
        "laser": {"type": "laser_sheet", "id": "laser", "thickness": 40.0},
        "particles": {"type": "ellipsoidsmesh", "filename": str(tmp_path / "p.ply"), "extent": 1.0,
                      "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}},
                      "emitter": {"type": "tracer_particles", "sheet": {"type": "ref", "id": "laser"}}}})
    img = np.array(mi.render(sc, spp=1, seed=0), dtype=np.float64)[..., 0]
    lit = np.argwhere(img > 0)  # (row, column)
    assert len(lit) == len(pts)
    got = lit[:, ::-1] + 0.5  # (u, v) pixel centres
    want = np.floor(uv) + 0.5
    order = lambda a: a[np.lexsort((a[:, 1], a[:, 0]))]  # noqa: E731 - compare as sets of pixels
    np.testing.assert_allclose(order(got), order(want), atol=BOX_CENTROID_ATOL_PX)
    # the pose given twice (file and to_world) is refused
    with pytest.raises(Exception, match="pose"):
        load_dict({"type": "distorted_pinhole", "calibration": str(tmp_path / "cam0.yml"), "pixel_pitch_um": 10.0,
                   "to_world": mi.ScalarTransform4f(), "film": {"type": "hdrfilm", "width": SIZE[0],
                                                                "height": SIZE[1]}})

