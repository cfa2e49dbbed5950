"""Compiled PIV kernels of issue 26 against the SciPy/NumPy code they replace: cubic
B-spline window deformation against scipy.ndimage.map_coordinates, mean-subtracted window
stacks and the peak search against the NumPy formulation."""

import importlib

import numpy as np
from scipy import ndimage

P = importlib.import_module("mitpiv.analysis.piv3d")

# map_coordinates gets float32 sample coordinates (~1e-6 voxel rounding at 40 voxels) and
# returns float32; measured difference 2.6e-6 on values ~1.
DEFORM_ATOL = 1e-5


def test_cubic_deformation_matches_scipy_map_coordinates():
    rng = np.random.default_rng(0)
    shape = (12, 18, 24)
    a, b = (rng.random(shape).astype(np.float32) for _ in range(2))
    d = rng.normal(0.0, 3.0, shape + (3,)).astype(np.float32)  # (x, y, z), some samples leave the volume
    base = np.stack(np.meshgrid(*(np.arange(n, dtype=np.float64) for n in shape), indexing="ij"))
    half = 0.5 * np.moveaxis(d[..., ::-1].astype(np.float64), -1, 0)
    ref = [ndimage.map_coordinates(v.astype(np.float64), base + s * half, order=3, mode="grid-constant", cval=0.0)
           for v, s in ((a, -1), (b, 1))]
    got = P._deform_pair(a, b, d, "cubic")
    for g, r in zip(got, ref, strict=True):
        np.testing.assert_allclose(g, r, atol=DEFORM_ATOL)


def test_centred_windows_and_peaks_equal_the_numpy_formulation():
    rng = np.random.default_rng(1)
    vol = rng.random((30, 34, 38)).astype(np.float32)
    volb = np.roll(vol, (1, -2, 3), axis=(0, 1, 2)) + 0.2 * rng.random(vol.shape).astype(np.float32)
    pad = 2
    pa, pb = np.pad(vol, pad), np.pad(volb, pad)
    starts = rng.integers(0, 14, (50, 3))
    w = (12, 16, 10)
    for normalised in (False, True):
        ref = P._correlate(P._gather(pa, pad, starts, w), P._gather(pb, pad, starts, w), normalised, 2)
        wa, ea = P._centred_windows(pa, pad, starts, w)
        wb, eb = P._centred_windows(pb, pad, starts, w)
        got = P._correlate(wa, wb, normalised, 2, ea, eb)
        for g, r in zip(got, ref, strict=True):
            np.testing.assert_array_equal(g, r)
        assert np.all(np.abs(got[0][:, 0] - 3) < 0.5)  # x shift +3 found
