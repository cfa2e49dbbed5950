"""Calibration: marker detection on rendered targets, mapping fits, homographies, bad input.

Truth: the exact marker world coordinates of the rendered target and the camera model the
renderer used (its describe()). Rendered images carry no noise unless added; the residual
left by detection on 4-6 px dots was measured at 0.01-0.03 px RMS (64 spp), so fits are
held to a few hundredths of a pixel.
"""

import mitsuba as mi
import numpy as np
import pytest

from mitpiv.errors import CalibrationError, ConfigError
from mitpiv.imaging import apply_sensor, convolve_psf
from mitpiv.io import read_exr
from mitpiv.physics.camera import PinholeCamera, place_camera
from mitpiv.physics.distortion import Distortion
from mitpiv.physics.psf import psf
from mitpiv.physics.targets import CalibrationTarget, markers_world, target_pose
from mitpiv.reconstruct import (
    PinholeMapping,
    apply_homography,
    calibrate,
    calibrate_views,
    detect_dots,
    label_markers,
    mapping_from_metadata,
    plane_homographies,
)
from mitpiv.render.scene import load_dict
from mitpiv.render.targets import render_target_views, save_target_views

RES = (256, 256)
ROT, POS = place_camera(azimuth_deg=25, elevation_deg=45, distance_mm=400)
NOMINAL = PinholeMapping(PinholeCamera(RES, 50.0, 10.0, rotation=ROT, position_mm=POS))
DOTS = CalibrationTarget("dots", 15, 19, 1.2)
POSES = [target_pose(z, tilt_x_deg=tx, tilt_y_deg=ty) for z in (-6, 0, 6) for tx, ty in ((0, 0), (20, 0), (0, -20))]
VOLUME = np.random.default_rng(0).uniform([-8, -6, -5], [8, 6, 5], (3000, 3))  # inside the calibrated region

# Tolerances and their provenance (module docstring: detection on rendered 4-6 px dots leaves
# 0.01-0.03 px RMS, measured at 64 spp; fits are held to a few hundredths of a pixel).
DETECTION_BIAS_TOL_PX = 0.01
FIT_RMS_TOL_PX = 0.05  # detection residual and fit RMS; also the fitted mapping's worst projection error
# The pinhole fit of one fixed camera against the renderer's camera: a 12 mm deep target
# trades the principal point with the pose (measured 1.7 px off at 64 spp).
FOCAL_RTOL = 2e-3
PRINCIPAL_POINT_TOL_PX = 4.0
POSITION_TOL_MM = 0.4  # 0.1 % of the 400 mm distance
ROTATION_ATOL = 2e-3
# Exact correspondences: OpenCV takes float32 points (~1e-5 relative).
EXACT_RMS_TOL_PX = 1e-4
EXACT_FOCAL_RTOL = 1e-5
EXACT_POSE_ATOL = 0.01  # principal point [px] and position [mm]
EXACT_DISTORTION_RTOL, EXACT_DISTORTION_ATOL = 1e-3, 1e-7
# 1 % barrel distortion: a polynomial and a Brown pinhole absorb it; a plain pinhole leaves > 0.2 px.
POLYNOMIAL_TOL_PX = 0.1
BROWN_TOL_PX = 0.05
UNMODELLED_MIN_PX = 0.2
CHECKERBOARD_RMS_TOL_PX = 0.15  # corner detection on a rendered board
CHECKERBOARD_TOL_PX = 0.1
NOISY_DETECTION_RMS_TOL_PX = 0.15  # diffraction blur, 8-bit, shot noise and 3 % Gaussian noise
JACOBIAN_FD_RTOL, JACOBIAN_FD_ATOL = 1e-6, 1e-6  # central differences, h = 1e-4 mm
MITSUBA_POSE_TOL_PX = 1e-3  # the render's pose is float32 in Mitsuba
HOMOGRAPHY_TOL_PX = 1e-6  # a plane maps to a plane exactly; fit residual at rounding


def sensor(**extra):
    return load_dict({
        "type": "distorted_pinhole", "to_world": mi.ScalarTransform4f(NOMINAL.camera.to_world_mitsuba()),
        "focal_length_mm": 50.0, "pixel_pitch_um": 10.0,
        "film": {"type": "hdrfilm", "width": RES[0], "height": RES[1], "pixel_format": "luminance",
                 "rfilter": {"type": "box"}}, **extra})


@pytest.fixture(scope="module")
def plain():
    s = sensor()
    return s, render_target_views([s], DOTS, POSES, spp=64)


@pytest.fixture(scope="module")
def distorted():
    s = sensor(distortion_percent=1.0)
    return s, render_target_views([s], DOTS, POSES, spp=64)


def truth_of(s):
    return PinholeMapping(PinholeCamera.from_dict(s.describe()))


def visible(px, margin=5.0):
    """Markers whose image lies at least `margin` px inside the image (whole dots)."""
    return (px[:, 0] > margin) & (px[:, 0] < RES[0] - margin) & (px[:, 1] > margin) & (px[:, 1] < RES[1] - margin)


def test_detected_dots_match_the_true_projection(plain):
    s, views = plain
    v = views[4]
    det = detect_dots(v["images"][0])
    i, j = label_markers(det, truth_of(s).project(v["markers_world"]))
    assert len(i) >= np.count_nonzero(visible(truth_of(s).project(v["markers_world"]))) > 200
    r = det[j] - truth_of(s).project(v["markers_world"][i])
    assert np.all(np.abs(r.mean(axis=0)) < DETECTION_BIAS_TOL_PX) and np.sqrt(np.mean(np.sum(r * r, 1))) < FIT_RMS_TOL_PX


def test_pinhole_fit_recovers_the_true_camera(plain):
    s, views = plain
    m = calibrate_views(views, 0, NOMINAL, DOTS, model="pinhole", distortion="none")
    c, t = m.camera, truth_of(s).camera
    assert m.fit_report["rms_px"] < FIT_RMS_TOL_PX and m.fit_report["markers"] > 2000
    assert c.focal_length_mm == pytest.approx(50.0, rel=FOCAL_RTOL)
    # the principal point is the least determined parameter (PRINCIPAL_POINT_TOL_PX)
    np.testing.assert_allclose(c.principal_point_px, t.principal_point_px, atol=PRINCIPAL_POINT_TOL_PX)
    np.testing.assert_allclose(c.position_mm, t.position_mm, atol=POSITION_TOL_MM)
    np.testing.assert_allclose(c.rotation, t.rotation, atol=ROTATION_ATOL)
    assert np.max(np.abs(m.project(VOLUME) - truth_of(s).project(VOLUME))) < FIT_RMS_TOL_PX


def test_exact_correspondences_recover_intrinsics_and_extrinsics_exactly():
    cam = PinholeCamera(RES, 50.0, 10.0, rotation=ROT, position_mm=POS, principal_point_px=(131.3, 122.8),
                        distortion=Distortion(k1=-0.8, k2=3.0, p1=1e-3, p2=-5e-4))
    w = np.concatenate([markers_world(DOTS, p) for p in POSES])
    w = w[visible(cam.project(w))]
    m = calibrate(cam.project(w), w, resolution=RES, distortion="brown")
    c = m.camera
    assert m.fit_report["rms_px"] < EXACT_RMS_TOL_PX
    assert c.focal_length_mm == pytest.approx(50.0, rel=EXACT_FOCAL_RTOL)
    np.testing.assert_allclose(c.principal_point_px, cam.principal_point_px, atol=EXACT_POSE_ATOL)
    np.testing.assert_allclose(c.position_mm, POS, atol=EXACT_POSE_ATOL)
    np.testing.assert_allclose([c.distortion.k1, c.distortion.p1, c.distortion.p2], [-0.8, 1e-3, -5e-4],
                               rtol=EXACT_DISTORTION_RTOL, atol=EXACT_DISTORTION_ATOL)


def test_polynomial_absorbs_distortion_and_a_plain_pinhole_does_not(distorted):
    s, views = distorted
    truth = truth_of(s)
    err = {}
    for model, dist in (("polynomial", "none"), ("pinhole", "none"), ("pinhole", "brown")):
        m = calibrate_views(views, 0, NOMINAL, DOTS, model=model, distortion=dist, max_rms_px=1.0)
        err[model, dist] = np.max(np.abs(m.project(VOLUME) - truth.project(VOLUME)))
    assert err["polynomial", "none"] < POLYNOMIAL_TOL_PX
    assert err["pinhole", "brown"] < BROWN_TOL_PX
    assert err["pinhole", "none"] > UNMODELLED_MIN_PX  # 1 % barrel distortion left unmodelled


def test_checkerboard_views():
    s = sensor()
    board = CalibrationTarget("checkerboard", 7, 9, 1.4)
    views = render_target_views([s], board, POSES, spp=64)
    m = calibrate_views(views, 0, NOMINAL, board, model="polynomial")
    assert m.fit_report["markers"] == 63 * len(POSES) and m.fit_report["rms_px"] < CHECKERBOARD_RMS_TOL_PX
    inside = VOLUME[(np.abs(VOLUME[:, 0]) < 5.6) & (np.abs(VOLUME[:, 1]) < 4.2)]  # the board's corners span
    assert np.max(np.abs(m.project(inside) - truth_of(s).project(inside))) < CHECKERBOARD_TOL_PX


def test_detection_is_robust_to_noise_and_blur(plain):
    s, views = plain
    v = views[0]
    # Diffraction blur (working f/22: Airy diameter 2.9 px, half the dot), then an 8-bit
    # camera with shot noise and 3 % Gaussian noise of the peak.
    blurred = convolve_psf(v["images"][0], psf(f_number=11.0, magnification=1.0, pixel_pitch_um=10.0))
    noisy = apply_sensor(blurred, peak_photons=200.0, shot_noise=True, gaussian_noise_percent=3.0, bit_depth=8, seed=1)
    det = detect_dots(noisy.astype(float))
    i, j = label_markers(det, truth_of(s).project(v["markers_world"]))
    assert len(i) >= np.count_nonzero(visible(truth_of(s).project(v["markers_world"])))
    r = det[j] - truth_of(s).project(v["markers_world"][i])
    assert np.sqrt(np.mean(np.sum(r * r, 1))) < NOISY_DETECTION_RMS_TOL_PX


def test_jacobians_match_finite_differences():
    cam = PinholeCamera(RES, 50.0, 10.0, rotation=ROT, position_mm=POS, distortion=Distortion(k1=-0.5, p1=1e-3))
    w = np.concatenate([markers_world(DOTS, p) for p in POSES])
    maps = [PinholeMapping(cam), calibrate(cam.project(w), w, model="polynomial")]
    p = VOLUME[:50]
    h = 1e-4
    for m in maps:
        fd = np.stack([(m.project(p + h * e) - m.project(p - h * e)) / (2 * h) for e in np.eye(3)], axis=-1)
        np.testing.assert_allclose(m.jacobian(p), fd, rtol=JACOBIAN_FD_RTOL, atol=JACOBIAN_FD_ATOL)


def test_mapping_from_metadata_is_the_render_camera(plain):
    s, _ = plain
    m = mapping_from_metadata({"camera": s.describe()})
    np.testing.assert_allclose(m.project(VOLUME), NOMINAL.project(VOLUME), atol=MITSUBA_POSE_TOL_PX)
    with pytest.raises(ConfigError, match="pinhole camera model"):
        mapping_from_metadata({"camera": {"type": "plenoptic"}})


def test_homographies_to_a_reference_view():
    cams = [PinholeMapping(PinholeCamera(RES, 50.0, 10.0, *place_camera(azimuth_deg=a, elevation_deg=45, distance_mm=400)))
            for a in (-20, 0, 20)]
    z = [-2.0, 0.0, 2.0]
    hs, res = plane_homographies(cams, cams[1], z, extent_mm=(-8, 8, -6, 6))
    assert hs.shape == (3, 3, 3, 3) and np.all(res < HOMOGRAPHY_TOL_PX)
    pts = np.column_stack([np.random.default_rng(1).uniform(-8, 8, 20), np.random.default_rng(2).uniform(-6, 6, 20), np.full(20, 2.0)])
    np.testing.assert_allclose(apply_homography(hs[0, 2], cams[0].project(pts)), cams[1].project(pts),
                               atol=HOMOGRAPHY_TOL_PX)
    # Distortion cannot be a homography: the residual says so.
    bent = PinholeMapping(PinholeCamera(RES, 50.0, 10.0, *place_camera(azimuth_deg=-20, elevation_deg=45, distance_mm=400),
                                        distortion=Distortion(k1=-2.0)))
    _, res = plane_homographies([bent], cams[1], z, extent_mm=(-8, 8, -6, 6))
    assert np.all(res > 0.05)


def test_bad_calibration_input():
    w = np.concatenate([markers_world(DOTS, p) for p in POSES])
    w = w[visible(NOMINAL.project(w))]
    px = NOMINAL.project(w)
    with pytest.raises(CalibrationError, match="at least"):
        calibrate(px[:10], w[:10], resolution=RES)
    line = np.column_stack([np.linspace(-5, 5, 50), np.zeros(50), np.zeros(50)])
    with pytest.raises(CalibrationError, match="collinear"):
        calibrate(NOMINAL.project(line), line, resolution=RES)
    flat = markers_world(DOTS, target_pose(0.0))
    flat = flat[visible(NOMINAL.project(flat))]
    with pytest.raises(CalibrationError, match="one plane"):
        calibrate(NOMINAL.project(flat), flat, resolution=RES)
    with pytest.raises(CalibrationError, match=">= 3 depths"):
        two = np.concatenate([markers_world(DOTS, target_pose(z)) for z in (0, 2)])
        two = two[visible(NOMINAL.project(two))]
        calibrate(NOMINAL.project(two), two, model="polynomial")
    shifted = px + [200.0, 0.0]
    with pytest.raises(CalibrationError, match="outside"):
        calibrate(shifted, w, resolution=RES)
    shuffled = px[np.random.default_rng(0).permutation(len(px))]
    with pytest.raises(CalibrationError, match="RMS reprojection error"):
        calibrate(shuffled, w, model="polynomial")
    with pytest.raises(ConfigError, match="model"):
        calibrate(px, w, model="tsai", resolution=RES)
    with pytest.raises(CalibrationError, match="no markers"):
        detect_dots(np.random.default_rng(0).normal(10.0, 1.0, RES))
    with pytest.raises(ConfigError, match="dot_diameter_mm"):
        CalibrationTarget("dots", 5, 5, 1.0, dot_diameter_mm=1.5)


def test_saved_views_carry_truth_and_camera(plain, tmp_path):
    s, views = plain
    paths = save_target_views(views[:2], tmp_path, sensors=[s], target=DOTS)
    assert [p.name for p in paths] == ["target_pose00_sensor0.exr", "target_pose01_sensor0.exr", "target_truth.npz"]
    img, meta = read_exr(paths[1])
    np.testing.assert_array_equal(img, views[1]["images"][0])
    assert meta["target"]["rows"] == 15 and np.allclose(meta["pose"], views[1]["pose"])
    np.testing.assert_allclose(mapping_from_metadata(meta).project(VOLUME), truth_of(s).project(VOLUME), atol=1e-9)
    with np.load(paths[2]) as z:
        np.testing.assert_array_equal(z["markers_world"][1], views[1]["markers_world"])
    bad = [{**views[0], "images": [np.full((4, 4), np.nan)]}]
    with pytest.raises(ConfigError, match="non-finite"):
        save_target_views(bad, tmp_path / "bad", sensors=[s], target=DOTS)
    assert not (tmp_path / "bad").exists()


# A narrow field of view (f = 100 mm, 600 mm away, a 160 x 100 px crop: the tracking_lpt
# tiny cameras) is nearly affine: with 0.1 px of noise on the target points the linear
# start's principal point leaves the image (OpenCV refused it as a start before the
# image-centre + solvePnP start). The principal point is then undetermined, but the mapping
# over the calibrated volume is what matters: measured 0.05 px from the true projection at
# 0.1 px noise on 216 points (about noise * sqrt(10 parameters / 216 points) * 2.5).
NARROW_NOISE_PX = 0.1
NARROW_PROJECTION_TOL_PX = 0.15


def test_a_narrow_field_pinhole_fit_with_noisy_points_succeeds():
    from mitpiv.physics.camera import look_at_rotation

    centre = np.array([0.0, 0.0, 15.0])
    pos = centre + 600.0 * np.array([np.sin(np.radians(30)), 0.0, np.cos(np.radians(30))])
    cam = PinholeCamera((160, 100), 100.0, 10.0, rotation=look_at_rotation(pos, centre, up=(0.0, 1.0, 0.0)),
                        position_mm=pos)
    axes = [np.linspace(c - h, c + h, 6) for c, h in zip(centre, (3.0, 2.0, 2.0), strict=True)]
    w = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    w = w[cam.visible(w)]
    uv = cam.project(w) + np.random.default_rng(3).normal(0.0, NARROW_NOISE_PX, (len(w), 2))
    m = calibrate(uv, w, resolution=cam.resolution, distortion="none", max_rms_px=0.5)
    assert "solvePnP" in m.fit_report["start"]
    assert m.fit_report["rms_px"] < 2 * NARROW_NOISE_PX
    inside = np.random.default_rng(4).uniform(centre - (3, 2, 2), centre + (3, 2, 2), (2000, 3))
    assert np.max(np.linalg.norm(m.project(inside) - cam.project(inside), axis=1)) < NARROW_PROJECTION_TOL_PX
