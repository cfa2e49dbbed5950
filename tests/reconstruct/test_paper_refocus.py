"""Fahringer & Thurow's plenoptic refocusing by their definitions, each against its equation
written afresh in float64: additive (eq. 13), multiplicative with white-image weights (eq. 14)
and the multi-camera combination (eq. 15)."""

import numpy as np
import pytest
from scipy.interpolate import RegularGridInterpolator

from mitpiv.errors import ConfigError
from mitpiv.grid import VoxelGrid
from mitpiv.lightfield import decode
from mitpiv.physics.plenoptic import PRESETS, PlenopticCamera
from mitpiv.reconstruct import fuse, paper_refocus, paper_view_weights

# float32 light-field storage and kernels against float64 here: relative 1e-5 (a product of
# ~80 powers in log space, float32 eps 6e-8 per term, exponentiated).
REL_TOL = 1e-5


def _camera():
    return PlenopticCamera(**{**PRESETS["multiplenoptic_paper"], "resolution": (160, 160), "mla_count": (16, 16)})


def _light_field(seed=0):
    cam = _camera()
    rng = np.random.default_rng(seed)
    raw = rng.uniform(0.2, 1.0, (160, 160)).astype(np.float32)  # strictly positive: every view sees light
    lf = decode(raw, optics=cam)
    return cam, lf


def _grid():
    # voxels whose rays stay inside the decoded lenslet grid (+-0.091 mm on the array: +-0.27 mm
    # at S_o = 40 mm, less the views' parallax)
    return VoxelGrid(origin_mm=(-0.1, -0.1, 39.0), voxel_mm=(0.05, 0.05, 0.5), shape=(5, 4, 4))


def eq14_afresh(lf, cam, grid, w, gamma_l, *, multiplicative=True):
    """Eqs. 13 / 14 written from the paper: s' = u + d_M ((u - x)/z - u/f_M), L sampled bilinearly."""
    d_m, f_m = cam.image_distance_mm, cam.focal_length_mm
    a = lf.aperture_mm  # main-lens coordinate of each angular sample (u and v alike)
    z, y, x = np.meshgrid(grid.z_mm, grid.y_mm, grid.x_mm, indexing="ij")  # lens at the origin, looking along +z
    out = np.zeros(x.shape) if not multiplicative else np.ones(x.shape)
    for iv, v in enumerate(a):
        for iu, u in enumerate(a):
            s1 = u + d_m * ((u - x) / z - u / f_m)
            t1 = v + d_m * ((v - y) / z - v / f_m)
            f = RegularGridInterpolator((lf.t_mm, lf.s_mm), lf.data[iv, iu].astype(np.float64), method="linear")
            val = f(np.stack([t1.ravel(), s1.ravel()], -1)).reshape(x.shape)
            if multiplicative:
                out *= val ** w[iv, iu]
            else:
                out += val
    return out**gamma_l if multiplicative else out


def test_eq14_multiplicative_against_the_equation():
    cam, lf = _light_field()
    grid = _grid()
    w = np.random.default_rng(1).uniform(0.0, 1.0, lf.data.shape[:2])
    gamma_l = 0.01  # the paper's typical value: 1 / (pixels under a lenslet)
    ours = paper_refocus(lf, grid, equation=14, weights=w, gamma_l=gamma_l)
    ref = eq14_afresh(lf, cam, grid, w, gamma_l)
    np.testing.assert_allclose(ours, ref, rtol=REL_TOL)
    # the default gamma_L = 1 / sum w: the weighted geometric mean (histogram of the views)
    np.testing.assert_allclose(paper_refocus(lf, grid, equation=14, weights=w),
                               eq14_afresh(lf, cam, grid, w, 1.0 / w.sum()), rtol=REL_TOL)
    # a floor raises dark samples: with every sample above it, nothing changes
    np.testing.assert_allclose(paper_refocus(lf, grid, equation=14, weights=w, gamma_l=gamma_l, floor=0.1), ref,
                               rtol=REL_TOL)


def test_eq13_additive_against_the_equation():
    cam, lf = _light_field(3)
    grid = _grid()
    ours = paper_refocus(lf, grid, equation=13)
    ref = eq14_afresh(lf, cam, grid, None, None, multiplicative=False)
    np.testing.assert_allclose(ours, ref, rtol=REL_TOL)


def test_view_weights_from_a_white_image():
    """w(u, v) = sum_st L_white(u, v, s, t), scaled to [0, 1]: 1 at the centre views, 0 outside
    the lenslet image of the aperture."""
    cam = _camera()
    white = np.zeros((160, 160), np.float32)
    cen = cam.image_centres_px().reshape(-1, 2)
    uu, vv = np.meshgrid(np.arange(160) + 0.5, np.arange(160) + 0.5)
    r_img_px = cam.aperture_radius_mm * cam.gap_mm / cam.image_distance_mm / (cam.pixel_pitch_um * 1e-3)
    for c in cen:  # each lenslet images the aperture disk
        white[np.hypot(uu - c[0], vv - c[1]) < r_img_px] = 1.0
    lf = decode(white, optics=cam, interpolation="nearest")
    w = paper_view_weights(lf)
    ref = lf.data.astype(np.float64)[:, :, lf.valid].sum(axis=2)
    np.testing.assert_allclose(w, ref / ref.max(), rtol=1e-12)
    assert w.max() == 1.0 and w.min() == 0.0
    du = lf.du_px
    inside = np.hypot(du[None, :], du[:, None]) < r_img_px - 0.5
    assert np.all(w[inside] == 1.0) and np.all(w[np.hypot(du[None, :], du[:, None]) > r_img_px + 0.75] == 0.0)
    with pytest.raises(ConfigError, match="dark"):
        paper_view_weights(decode(np.zeros((160, 160), np.float32), optics=cam))


def test_eq15_multi_camera_combination():
    rng = np.random.default_rng(4)
    vols = [rng.uniform(0.1, 2.0, (3, 4, 5)) for _ in range(3)]
    ref = (vols[0] * vols[1] * vols[2]) ** (1.0 / 3.0)  # eq. 15 with gamma_M = 1 / M
    np.testing.assert_allclose(fuse(vols, normalise="none"), ref, rtol=1e-6)
    np.testing.assert_allclose(fuse(vols, normalise="none", gamma_m=0.5), (vols[0] * vols[1] * vols[2]) ** 0.5, rtol=1e-6)
    with pytest.raises(ConfigError, match="gamma_m"):
        fuse(vols, gamma_m=0.0)
    with pytest.raises(ConfigError, match="equation"):
        paper_refocus(_light_field()[1], _grid(), equation=12)


def test_gamma_exponent_matches_the_sub_aperture_histogram():
    """The paper's rule for gamma_L: a volume whose intensities, raised to e0 = 3, are exactly
    the central views' samples gives back e0 (the Wasserstein distance is 0 there; the bounded
    search finds it to its 1e-4 tolerance in log e, 1e-3 relative allowed); the same volume
    raised to 0.5 asks for 6; the rim views (weight below half the largest) are left out of the
    reference, and bad inputs are refused."""
    from mitpiv.reconstruct import paper_gamma_exponent

    _, lf = _light_field(seed=3)
    w = np.ones(lf.data.shape[:2])
    w[0, :] = 0.1  # a vignetted rim row of views, brighter than the rest: must not enter the reference
    lf.data[0] *= 5.0
    ref = lf.data[w >= 0.5][:, lf.valid].astype(np.float64).ravel()
    vol = (ref / ref.max()) ** (1.0 / 3.0)
    assert paper_gamma_exponent(vol, lf, weights=w) == pytest.approx(3.0, rel=1e-3)
    assert paper_gamma_exponent(vol**0.5, lf, weights=w) == pytest.approx(6.0, rel=1e-3)
    assert paper_gamma_exponent(vol * 7.0, lf, weights=w) == pytest.approx(3.0, rel=1e-3)  # scale-free
    # dark samples (0) and uncovered voxels (0): eq. 14's floor raises the samples to it (0.3
    # here, inside the light field's 0.2-1 range); the zero voxels are left out; the rule then
    # recovers e0 whatever their share (with the zeros counted on one side only it read 4.7-14)
    dark = lf.data.copy()
    dark[:, :, ::3, :] = 0.0
    lf.data[:] = dark
    ref = np.maximum(lf.data[w >= 0.5][:, lf.valid].astype(np.float64).ravel(), 0.3)
    vol = np.concatenate([(ref / ref.max()) ** (1.0 / 3.0), np.zeros(ref.size // 2)])
    assert paper_gamma_exponent(vol, lf, weights=w, floor=0.3) == pytest.approx(3.0, rel=1e-3)
    assert abs(paper_gamma_exponent(vol, lf, weights=w, floor=0.0) / 3.0 - 1.0) > 0.05  # the floor matters
    with pytest.raises(ConfigError, match="weights"):
        paper_gamma_exponent(vol, lf, weights=np.ones((2, 2)))
    with pytest.raises(ConfigError, match="no positive voxel"):
        paper_gamma_exponent(np.zeros(10), lf, weights=w)


def test_cubic_decoding_never_gives_negative_light():
    """The paper samples the sensor by cubic interpolation; a cubic spline through a sparse
    particle image undershoots below zero beside each bright pixel (checked here on the same
    image), and decode clips those samples to 0: light is not negative, and eq. 13's sums and
    eq. 15's products need non-negative volumes."""
    from scipy import ndimage

    cam = _camera()
    raw = np.zeros((160, 160), np.float32)
    rng = np.random.default_rng(2)
    raw[rng.integers(0, 160, 60), rng.integers(0, 160, 60)] = 1000.0  # isolated bright pixels
    yy, xx = np.mgrid[0:160:0.37, 0:160:0.37]
    spline = ndimage.map_coordinates(raw, [yy.ravel(), xx.ravel()], order=3, mode="constant", prefilter=True)
    assert spline.min() < -10.0  # the undershoot exists
    lf = decode(raw, optics=cam, interpolation="cubic")
    assert lf.data.min() >= 0.0 and lf.data.max() > 100.0
