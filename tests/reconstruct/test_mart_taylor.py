"""The MART sweep's Taylor factor (issue 50): rows with |mu log ratio| <= 0.4 / max(w) take
exp(lr w) from a degree-7 polynomial in float32; against the same sweep with exp for every
entry, and the polynomial against exp written afresh in float64."""

import math

import numpy as np

from mitpiv.reconstruct import WeightCache, mart
from mitpiv.reconstruct._kernels import kernels

from .test_fast_paths import GRID, _cameras, _images

# float32 volume after several sweeps; truncation 1.6e-8 relative per factor, float32 Horner
# rounding of a few ulp: measured 2e-7 to 4e-7 of the maximum at the bench sizes.
TAYLOR_ATOL_OF_MAX = 2e-6


def _poly7(x):
    return sum(x**n / math.factorial(n) for n in range(8))


def test_taylor_polynomial_bound():
    """|exp(x) - p7(x)| / exp(x) <= 0.4^8 / 8! (times e^0.4 for the remainder) on |x| <= 0.4."""
    x = np.linspace(-0.4, 0.4, 20001)
    rel = np.abs(np.exp(x) - _poly7(x)) / np.exp(x)
    assert rel.max() <= 0.4**8 / math.factorial(8) * math.exp(0.4)
    assert rel.max() < 2.0**-24  # below float32's half ulp at 1


def test_taylor_sweep_matches_exp_sweep():
    cams = _cameras()
    imgs = [im + 1e-3 for im in _images(cams)]  # no zero pixel: every voxel stays active
    cache = WeightCache()
    v0, info = mart(imgs, cams, GRID, iterations=0, cache=cache, return_info=True)
    idx, cws = cache._idx, cache._cams
    flat = [np.ascontiguousarray(im.ravel()) for im in imgs]
    k = kernels()
    taylor = v0.ravel()[idx].astype(np.float32)
    plain = taylor.copy()
    for _ in range(8):
        for cw, f in zip(cws, flat, strict=True):
            k["mart_camera_f32"](cw.indptr, cw.indices, cw.data, f, cw.width, cw.span, taylor, 1.0, cw.wmax)
            k["mart_camera_f32"](cw.indptr, cw.indices, cw.data, f, cw.width, cw.span, plain, 1.0)
    assert all(0 < cw.wmax == float(cw.data.max()) for cw in cws)
    assert len(idx) > 1000 and not np.array_equal(taylor, plain)  # the polynomial path ran
    np.testing.assert_allclose(taylor, plain, rtol=0, atol=TAYLOR_ATOL_OF_MAX * float(plain.max()))
    # the library's mart() runs the Taylor sweep
    out = mart(imgs, cams, GRID, iterations=8)
    ref = np.zeros(GRID.n_voxels, np.float32)
    ref[idx] = taylor
    np.testing.assert_array_equal(out.ravel(), ref)
