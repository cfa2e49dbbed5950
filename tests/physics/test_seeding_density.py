"""Seeding densities for any camera of the contract: visible_fraction and count_for_density
against the implementations they replace (copied here as float64 references: the
experiment runner's chief-ray/pinhole visible fraction and its per-pixel / per-microlens
count, and seeding.count_for_ppp), and against analytic cases: a box wholly in view
(fraction 1) and a thin slab cut in half by the edge of the field (0.5 within binomial
standard errors)."""

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.physics.camera import PinholeCamera, look_at_rotation
from mitpiv.physics.plenoptic import PlenopticCamera
from mitpiv.physics.seeding import count_for_density, count_for_ppp, seed_box, visible_fraction

SAMPLES = 200_000
N_SIGMA = 4.0  # binomial standard errors allowed for a Monte Carlo fraction


def _pose(pos, target=(0.0, 0.0, 0.0)):
    rot = look_at_rotation(pos, target, up=[0, 1, 0])
    m = np.eye(4)
    m[:3, :3] = rot.T @ np.diag([-1.0, -1.0, 1.0])
    m[:3, 3] = pos
    return rot, np.asarray(pos, float), m


def pinhole(pos=(0.0, 0.0, 500.0)):
    rot, p, _ = _pose(pos)
    return PinholeCamera((128, 96), 50.0, 10.0, rotation=rot, position_mm=p)


def plenoptic(pos=(0.0, 0.0, 250.0), layout="rect"):
    _, _, m = _pose(pos)
    return PlenopticCamera(resolution=(220, 200), pixel_pitch_um=5.5, focal_length_mm=50.0, f_number=2.8,
                           focus_distance_mm=250.0, mla_pitch_um=55.0, mla_layout=layout, to_world_mitsuba=m)


# ---------------------------------------------------------------- the replaced implementations
def old_visible_fraction(cam, box_min, box_max, *, samples=SAMPLES, seed=0):
    """mitpiv/studies/experiment.py visible_fraction before the camera contract (float64)."""
    lo, hi = np.asarray(box_min, float), np.asarray(box_max, float)
    pts = np.random.default_rng(seed).uniform(lo, hi, size=(samples, 3))
    if isinstance(cam, PlenopticCamera):
        loc = cam.world_to_local(pts)
        front = loc[:, 2] > 0
        z = np.where(front, loc[:, 2], 1.0)
        uv = cam.sensor_mm_to_px(-cam.image_distance_mm * cam.image_scale * loc[:, :2] / z[:, None])
    else:
        front = cam.world_to_camera(pts)[:, 2] > 0
        uv = cam.project(pts)
    w, h = cam.resolution
    inside = front & (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
    return float(inside.mean())


def old_count_for_density(cam, box_min, box_max, *, ppp, ppm, seed):
    """The runner's _count_for_density after the sensor lookup (both given: the kind picks)."""
    plen = isinstance(cam, PlenopticCamera)
    if ppp is not None and ppm is not None:
        ppp, ppm = (None, ppm) if plen else (ppp, None)
    frac = old_visible_fraction(cam, box_min, box_max, seed=seed)
    w, h = cam.resolution
    if ppp is not None:
        return int(round(ppp * w * h / frac))
    return int(round(ppm * int(np.prod(cam.mla_count)) / frac))


CAMERAS = {"pinhole": pinhole, "pinhole_oblique": lambda: pinhole((300.0, 120.0, 380.0)),
           "plenoptic": plenoptic, "plenoptic_hex_oblique": lambda: plenoptic((90.0, -40.0, 230.0), "hex")}
BOX = ((-8.0, -6.0, -3.0), (8.0, 6.0, 3.0))  # partly outside every camera's view


@pytest.mark.parametrize("name", sorted(CAMERAS))
def test_agrees_with_the_old_implementations(name):
    cam = CAMERAS[name]()
    frac = visible_fraction(cam, *BOX, seed=7)
    ref = old_visible_fraction(cam, *BOX, seed=7)
    assert 0.02 < ref < 0.98  # a partial view: the comparison means something
    assert frac == pytest.approx(ref, abs=1.0 / SAMPLES)  # the same draws: at most an edge point apart
    for ppp, ppm in ((0.05, None), (None, 0.3), (0.05, 0.3)):
        if ppm is not None and ppp is None and not isinstance(cam, PlenopticCamera):
            continue
        new = count_for_density(cam, *BOX, ppp=ppp, particles_per_microlens=ppm, seed=7)
        old = old_count_for_density(cam, *BOX, ppp=ppp, ppm=ppm, seed=7)
        assert abs(new - old) <= 1 + 1e-5 * old


def test_count_for_ppp_and_seed_box_unchanged():
    """count_for_ppp (kept for scripts) and seed_box(ppp=...) draw exactly as before."""
    cam = pinhole()

    def old_count_for_ppp(ppp, camera, box_min, box_max, seed):
        lo, hi = np.asarray(box_min, float), np.asarray(box_max, float)
        rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
        pts = rng.uniform(lo, hi, size=(SAMPLES, 3))
        uv = camera.project(pts)
        w, h = camera.resolution
        z = camera.world_to_camera(pts)[:, 2]
        inside = (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
        return int(round(ppp * w * h / inside.mean()))

    assert count_for_ppp(0.05, cam, *BOX, seed=3) == old_count_for_ppp(0.05, cam, *BOX, 3)
    rng = np.random.default_rng(11)
    n = old_count_for_ppp(0.05, cam, *BOX, rng)
    expected = rng.uniform(*BOX, size=(n, 3))  # seed_box draws the positions after the count
    got = seed_box(*BOX, ppp=0.05, camera=cam, seed=11)
    np.testing.assert_array_equal(got.positions_mm, expected)


def _half_width_mm(cam, distance_mm):
    """Half-width of the field along image u at a distance along the axis, written afresh:
    pinhole W/2 / f_px; plenoptic the chief ray to the sensor at s_i + g behind the lens."""
    w = cam.resolution[0]
    if isinstance(cam, PlenopticCamera):
        f, so = cam.focal_length_mm, cam.focus_distance_mm
        si = f * so / (so - f)
        return 0.5 * w * cam.pixel_pitch_um * 1e-3 / (si + cam.mla_gap_um * 1e-3) * distance_mm
    return 0.5 * w / (cam.focal_length_mm / (cam.pixel_pitch_um * 1e-3)) * distance_mm


@pytest.mark.parametrize("kind", ["pinhole", "plenoptic"])
def test_analytic_fractions(kind):
    """Both cameras sit on +z looking at the origin with image u along world x (either
    sign: the field is symmetric about the axis)."""
    cam = CAMERAS[kind]()
    dist = 500.0 if kind == "pinhole" else 250.0
    xh = _half_width_mm(cam, dist)
    inside = ((-0.5 * xh, -0.3 * xh, -2.0), (0.5 * xh, 0.3 * xh, 2.0))
    assert visible_fraction(cam, *inside, seed=1) == 1.0
    # a slab 1 um thick at the origin plane, x from the axis to twice the edge: half in view
    slab = ((0.0, -0.3 * xh, -5e-4), (2.0 * xh, 0.3 * xh, 5e-4))
    frac = visible_fraction(cam, *slab, seed=2)
    sigma = np.sqrt(0.25 / SAMPLES)
    assert frac == pytest.approx(0.5, abs=N_SIGMA * sigma + 1e-5)  # + the field's 1e-6 taper over the slab
    # a slab 20 % in view: 0.2; and one wholly out: the count is refused
    slab = ((0.8 * xh, -0.3 * xh, -5e-4), (1.8 * xh, 0.3 * xh, 5e-4))
    assert visible_fraction(cam, *slab, seed=3) == pytest.approx(0.2, abs=N_SIGMA * np.sqrt(0.16 / SAMPLES))
    out = ((1.1 * xh, -1.0, -1.0), (2.0 * xh, 1.0, 1.0))
    assert visible_fraction(cam, *out, seed=4) == 0.0
    with pytest.raises(ConfigError, match="sees no part"):
        count_for_density(cam, *out, ppp=0.01)
    # count: density x (pixels or lenslets) / fraction
    w, h = cam.resolution
    assert count_for_density(cam, *inside, ppp=0.02) == round(0.02 * w * h)
    if kind == "plenoptic":
        assert count_for_density(cam, *inside, particles_per_microlens=0.5) == round(0.5 * cam.n_lenslets)
        # both given: a plenoptic camera counts per microlens
        assert count_for_density(cam, *inside, ppp=0.02, particles_per_microlens=0.5) == round(0.5 * cam.n_lenslets)
    else:
        assert count_for_density(cam, *inside, ppp=0.02, particles_per_microlens=0.5) == round(0.02 * w * h)


def test_bad_input():
    cam = pinhole()
    with pytest.raises(ConfigError, match="plenoptic"):
        count_for_density(cam, *BOX, particles_per_microlens=0.1)
    with pytest.raises(ConfigError, match="give 'ppp'"):
        count_for_density(cam, *BOX)
    for bad in (0.0, -1.0, np.nan, True, "0.1"):
        with pytest.raises(ConfigError, match="ppp"):
            count_for_density(cam, *BOX, ppp=bad)
    with pytest.raises(ConfigError, match="box_max_mm"):
        visible_fraction(cam, BOX[1], BOX[0])
    with pytest.raises(ConfigError, match="three numbers"):
        visible_fraction(cam, (0, 0), (1, 1))
    with pytest.raises(ConfigError, match="samples"):
        visible_fraction(cam, *BOX, samples=0)
    with pytest.raises(ConfigError, match="ppp"):
        count_for_ppp(-0.1, cam, *BOX)
