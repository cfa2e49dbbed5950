"""The camera contract (mitpiv.physics.camera.Camera) for every camera model: the pinhole
(ideal, and distorted with a thin-lens aperture) and the plenoptic 1.0 camera (rect and
hex lattices). Each is checked against geometry written afresh here in float64: the
optical axis at the focus distance images at the sensor centre; ``visible`` is "in front
(depth along the optical axis > 0) and on the sensor [0, W) x [0, H)"; the Jacobian
matches central differences within a bound derived below; ``to_dict``/``from_dict``
survive JSON and project identically. The plenoptic chief-ray projection is also checked
against the pinhole formula of the equivalent camera (focal length ``s_i + g``)."""

import json

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.physics.camera import CV_TO_MITSUBA, Camera, PinholeCamera, look_at_rotation, on_sensor, place_camera
from mitpiv.physics.distortion import Distortion
from mitpiv.physics.plenoptic import PlenopticCamera

EPS = np.finfo(np.float64).eps
H_FD_MM = 1e-3  # central-difference step [mm]
# Tolerances and their provenance (the references are the float64 geometry written here).
# Closed-form projections (optical axis to the sensor centre, chief ray = pinhole of focal
# length s_i + g, lenslet chief rays to their image centres): float64 rounding on pixel
# coordinates of a few hundred px, far below this.
CLOSED_FORM_ATOL_PX = 1e-9
# The Jacobian against central differences: the derived truncation + rounding bound
# (test_jacobian_matches_central_differences) times this safety factor.
FD_BOUND_SAFETY = 10


def _mitsuba_pose(rotation, position):
    m = np.eye(4)
    m[:3, :3] = np.asarray(rotation).T @ np.diag([-1.0, -1.0, 1.0])
    m[:3, 3] = position
    return m


def _pinhole_case(distorted: bool):
    rot, pos = place_camera(azimuth_deg=30.0, elevation_deg=25.0, distance_mm=450.0, target_mm=(2.0, -1.0, 0.5))
    # a wide field (f = 600 px, half-diagonal 0.1 in x/z) so that the distortion moves the
    # image by pixels: 5 % barrel at the edge of the test cloud
    dist = Distortion(k1=-5.0, k2=30.0, p1=2e-3, p2=-1e-3)
    kw = dict(distortion=dist, f_number=4.0, focus_distance_mm=450.0) if distorted else {}
    cam = PinholeCamera((96, 64), 12.0, 20.0, rotation=rot, position_mm=pos, **kw)
    # optical axis (OpenCV z) in world, projection centre, scale k [px] of x/z
    return dict(camera=cam, axis=rot[2], centre=pos, focus_mm=450.0, k_px=cam.focal_px,
                distortion_sum=5.0 + 30.0 + 2e-3 + 1e-3 if distorted else 0.0)


def _plenoptic_case(layout: str):
    rot = look_at_rotation([40.0, -30.0, 240.0], [0.0, 0.0, 0.0], up=[0, 1, 0])
    pos = np.array([40.0, -30.0, 240.0])
    extra = {"mla_rotation_deg": 2.0, "mla_offset_um": (7.0, -4.0)} if layout == "hex" else {}
    cam = PlenopticCamera(resolution=(240, 200), pixel_pitch_um=5.5, focal_length_mm=50.0, f_number=2.8,
                          focus_distance_mm=250.0, mla_pitch_um=55.0, mla_layout=layout,
                          to_world_mitsuba=_mitsuba_pose(rot, pos), **extra)
    # thin-lens equation afresh: s_i = f s_o / (s_o - f); gap g = the f-number-matched lenslet focal length
    si = 50.0 * 250.0 / (250.0 - 50.0)
    g = 0.055 * si / (50.0 / 2.8)
    return dict(camera=cam, axis=rot[2], centre=pos, focus_mm=250.0, k_px=(si + g) / 5.5e-3, distortion_sum=0.0)


CASES = {"pinhole": lambda: _pinhole_case(False), "pinhole_distorted_thinlens": lambda: _pinhole_case(True),
         "plenoptic_rect": lambda: _plenoptic_case("rect"), "plenoptic_hex": lambda: _plenoptic_case("hex")}


@pytest.fixture(params=sorted(CASES))
def case(request):
    return CASES[request.param]()


def _depth(case, p):
    return (np.asarray(p) - case["centre"]) @ case["axis"]


def _cloud(case, n=4000, seed=0):
    """Points round the view: most in front (some off the sensor), some behind the camera."""
    rng = np.random.default_rng(seed)
    cam = case["camera"]
    w, h = cam.resolution
    half = 0.75 * max(w, h) / case["k_px"] * case["focus_mm"]  # past the field's half-width at the focus
    target = case["centre"] + case["focus_mm"] * case["axis"]
    p = target + rng.uniform(-half, half, (n, 3))
    behind = rng.random(n) < 0.15
    p[behind] = 2 * case["centre"] - p[behind]  # point reflection through the projection centre
    return p


def test_satisfies_the_protocol(case):
    assert isinstance(case["camera"], Camera)
    assert tuple(case["camera"].resolution) == case["camera"].resolution


def test_the_distorted_case_is_distorted():
    bent, ideal = _pinhole_case(True), _pinhole_case(False)
    p = _cloud(ideal)
    p = p[ideal["camera"].visible(p)]
    shift = np.linalg.norm(bent["camera"].project(p) - ideal["camera"].project(p), axis=1)
    assert shift.max() > 1.0  # px: the Jacobian test below exercises the distortion terms


def test_axis_point_at_focus_images_at_the_sensor_centre(case):
    cam = case["camera"]
    w, h = cam.resolution
    for dist in (case["focus_mm"], 0.5 * case["focus_mm"], 3.0 * case["focus_mm"]):
        uv = cam.project((case["centre"] + dist * case["axis"])[None])
        np.testing.assert_allclose(uv[0], [w / 2, h / 2], atol=CLOSED_FORM_ATOL_PX)
        assert cam.visible((case["centre"] + dist * case["axis"])[None])[0]
        assert not cam.visible((case["centre"] - dist * case["axis"])[None])[0]  # behind


def test_visible_is_in_front_and_on_the_sensor(case):
    cam = case["camera"]
    p = _cloud(case)
    w, h = cam.resolution
    uv = cam.project(p)
    front = _depth(case, p) > 0
    on = (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
    vis = cam.visible(p)
    np.testing.assert_array_equal(vis, front & on)
    np.testing.assert_array_equal(cam.in_front(p), front)
    # the sample exercises every branch: visible, in front but off the sensor, and behind the
    # camera yet projected onto the sensor (mirrored), which must not count
    assert vis.sum() > 200 and (front & ~on).sum() > 200 and (~front & on).sum() > 20
    # shapes: (..., 3) -> (...), (..., 2)
    assert cam.visible(p.reshape(40, 100, 3)).shape == (40, 100) and cam.project(p.reshape(40, 100, 3)).shape == (40, 100, 2)


def test_jacobian_matches_central_differences(case):
    cam = case["camera"]
    p = _cloud(case, 500, seed=1)
    p = p[cam.visible(p)]
    h = H_FD_MM
    fd = np.stack([(cam.project(p + h * e) - cam.project(p - h * e)) / (2 * h) for e in np.eye(3)], axis=-1)
    jac = cam.jacobian(p)
    assert jac.shape == (len(p), 2, 3)
    # Error bound of the central difference: truncation h^2/6 |d^3 uv/ds^3| plus rounding.
    # Along a unit direction (a, c) in the camera frame, d^3/ds^3 (x + a s)/(z + c s) =
    # -6 c^2 (a z - c x) / z^4, so |d^3 uv| <= k 6 sqrt(2) |p_cam| / z^4 (times 1 + 10 sum|k_i|
    # for the mild distortion here); rounding: eps (|p| |J| + |uv|) / h per evaluation.
    depth = _depth(case, p)
    rng_cam = np.linalg.norm(p - case["centre"], axis=1)
    trunc = h**2 / 6 * case["k_px"] * 6 * np.sqrt(2) * np.max(rng_cam / depth**4) * (1 + 10 * case["distortion_sum"])
    rounding = 4 * EPS * (np.abs(p).max() * np.abs(jac).max() + np.abs(cam.project(p)).max()) / h
    tol = FD_BOUND_SAFETY * (trunc + rounding)
    assert tol < 1e-6 * np.abs(jac).max()  # the bound is tight enough to mean something
    np.testing.assert_allclose(jac, fd, rtol=0, atol=tol)


def test_to_dict_from_dict_round_trip(case):
    cam = case["camera"]
    d = json.loads(json.dumps(cam.to_dict()))  # as stored in EXR metadata
    back = type(cam).from_dict(d)
    assert isinstance(back, Camera) and back.resolution == cam.resolution
    p = _cloud(case, 300, seed=2)
    np.testing.assert_array_equal(back.project(p), cam.project(p))
    np.testing.assert_array_equal(back.visible(p), cam.visible(p))
    np.testing.assert_array_equal(back.jacobian(p), cam.jacobian(p))


@pytest.mark.parametrize("layout", ["rect", "hex"])
def test_plenoptic_projection_is_the_chief_ray_pinhole_of_focal_length_si_plus_g(layout):
    """Chief ray through the main-lens centre onto the MLA (X = -s_i (x, y)/z, Mitsuba local
    frame), scaled to the sensor by 1 + g/s_i: a pinhole of focal length s_i + g. Written
    afresh in float64, and the same as an OpenCV PinholeCamera at the lens."""
    case = _plenoptic_case(layout)
    cam = case["camera"]
    p = _cloud(case, 500, seed=3)
    p = p[_depth(case, p) > 0]
    m = cam.to_world_mitsuba
    q = (p - m[:3, 3]) @ m[:3, :3]
    si = 50.0 * 250.0 / 200.0
    g = cam.mla_gap_um * 1e-3
    x_mla = -si * q[:, :2] / q[:, 2:3]
    uv = x_mla * (1 + g / si) / 5.5e-3 + np.array(cam.resolution) / 2.0
    np.testing.assert_allclose(cam.project(p), uv, rtol=0, atol=CLOSED_FORM_ATOL_PX)
    rotation = (m[:3, :3] @ CV_TO_MITSUBA).T
    pin = PinholeCamera(cam.resolution, si + g, 5.5, rotation=rotation, position_mm=m[:3, 3])
    np.testing.assert_allclose(cam.project(p), pin.project(p), rtol=0, atol=CLOSED_FORM_ATOL_PX)
    np.testing.assert_allclose(cam.jacobian(p), pin.jacobian(p), rtol=1e-12, atol=1e-12)
    # the image point of a lenslet's chief ray is its lenslet-image centre, at any depth
    centres = cam.image_centres_px().reshape(-1, 2)[[0, 7, -1]]
    c_mla = cam.lenslet_centres_mm().reshape(-1, 2)[[0, 7, -1]]
    for depth in (200.0, 250.0, 330.0):
        local = np.column_stack([-c_mla * depth / si, np.full(3, depth)])
        world = local @ m[:3, :3].T + m[:3, 3]
        np.testing.assert_allclose(cam.project(world), centres, atol=CLOSED_FORM_ATOL_PX)


def test_on_sensor_is_half_open():
    uv = np.array([[0.0, 0.0], [9.999, 4.999], [10.0, 1.0], [1.0, 5.0], [-1e-12, 1.0], [np.nan, 1.0]])
    np.testing.assert_array_equal(on_sensor(uv, (10, 5)), [True, True, False, False, False, False])


def test_cv_to_mitsuba_is_read_only():
    with pytest.raises(ValueError):
        CV_TO_MITSUBA[0, 0] = 1.0
    assert PinholeCamera((8, 8), 10.0, 5.0).to_world_mitsuba()[:3, :3].tolist() == CV_TO_MITSUBA.tolist()


def test_plenoptic_lenslet_count():
    cam = _plenoptic_case("rect")["camera"]
    assert cam.n_lenslets == cam.mla_count[0] * cam.mla_count[1] == cam.pixel_budget()["lenslets"]
    with pytest.raises(ConfigError):
        PlenopticCamera(resolution=(64, 64), pixel_pitch_um=5.5, focal_length_mm=50.0, f_number=2.8,
                        focus_distance_mm=30.0, mla_pitch_um=55.0)
