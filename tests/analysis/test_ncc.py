"""Normalised cross-correlation (Lewis 1995; channel-tomo paper eq. 3) against the formula
evaluated by hand, shift by shift, in float64, and as a selectable correlation of piv3d."""

import numpy as np
import pytest

from mitpiv.analysis import truth_volume
from mitpiv.analysis.piv3d import normalised_cross_correlation, piv3d
from mitpiv.errors import ConfigError
from mitpiv.reconstruct import VoxelGrid

NCC_ATOL = 1e-12  # float64 FFT and running box sums against direct sums: rounding only
# float32 inputs take single-precision FFTs: rounding of ~eps32 (6e-8) times log2 of the
# transform size relative to the energies, on a coefficient in [-1, 1]
NCC_F32_ATOL = 1e-5
# Mean displacement of interior windows, a uniform sub-voxel shift, cubic deformation:
# the FFT correlation holds 0.03 voxel (tests/analysis/test_piv3d.py); the NCC likewise.
SHIFT_BIAS_TOL_VOX = 0.03


def _ncc_by_hand(t, f):
    """gamma(u) = sum (F - Fbar_u)(T - Tbar) / sqrt(sum (F - Fbar_u)^2 sum (T - Tbar)^2) at every shift."""
    wz, wy, wx = t.shape
    mz, my, mx = ((b - a) // 2 for a, b in zip(t.shape, f.shape, strict=True))
    out = np.zeros((2 * mz + 1, 2 * my + 1, 2 * mx + 1))
    tc = t - t.mean()
    for k in range(2 * mz + 1):
        for j in range(2 * my + 1):
            for i in range(2 * mx + 1):
                sub = f[k:k + wz, j:j + wy, i:i + wx]
                fc = sub - sub.mean()
                out[k, j, i] = (fc * tc).sum() / np.sqrt((fc * fc).sum() * (tc * tc).sum())
    return out


def test_ncc_matches_the_formula_by_hand():
    rng = np.random.default_rng(4)
    t = rng.random((2, 4, 5, 3))
    f = rng.random((2, 8, 7, 9))
    got = normalised_cross_correlation(t, f)
    assert got.shape == (2, 5, 3, 7)
    for n in range(2):
        assert np.abs(got[n] - _ncc_by_hand(t[n], f[n])).max() < NCC_ATOL
    # the template embedded in the search region (scaled and offset) correlates to 1 there
    f2 = rng.random((1, 8, 9, 7))
    f2[0, 3:7, 1:6, 2:5] = 3.0 * t[0] + 5.0
    g = normalised_cross_correlation(t[:1], f2)
    assert g[0, 3, 1, 2] == pytest.approx(1.0, abs=1e-12) and np.argmax(g[0]) == np.ravel_multi_index((3, 1, 2),
                                                                                                       g[0].shape)
    # a flat template has no coefficient: 0, not NaN
    assert np.all(normalised_cross_correlation(np.ones((1, 4, 5, 3)), f[:1]) == 0)
    with pytest.raises(ConfigError, match="grown by an even"):
        normalised_cross_correlation(t, f[:, :7])


def test_ncc_single_precision_path_matches_the_formula_on_a_bright_background():
    """piv3d's float32 volumes take the single-precision FFT path; a background 1000 times the
    fluctuations (a reconstruction's haze) must not cost accuracy: F's mean is removed first."""
    rng = np.random.default_rng(5)
    t = (rng.random((3, 6, 5, 7)) + 1000.0).astype(np.float32)
    f = (rng.random((3, 12, 9, 11)) + 1000.0).astype(np.float32)
    got = normalised_cross_correlation(t, f)
    for n in range(3):
        ref = _ncc_by_hand(t[n].astype(np.float64), f[n].astype(np.float64))
        assert np.abs(got[n] - ref).max() < NCC_F32_ATOL
        assert np.argmax(got[n]) == np.argmax(ref)


def test_piv3d_with_ncc_recovers_a_shift():
    vox = 0.05
    grid = VoxelGrid((0.0, 0.0, 0.0), (vox, vox, vox), (40, 40, 40))
    rng = np.random.default_rng(1)
    p = rng.uniform(-0.3, 2.3, (1500, 3))
    a = truth_volume(p, grid, sigma_voxels=1.0)
    shift = np.array([1.6, -0.7, 0.4])
    b = truth_volume(p + shift * vox, grid, sigma_voxels=1.0)
    f = piv3d(a, b, grid, windows=(24, 16), overlap=0.5, correlation="ncc")
    d = f.displacement_vox()[1:-1, 1:-1, 1:-1].reshape(-1, 3)
    assert np.allclose(d.mean(axis=0), shift, atol=SHIFT_BIAS_TOL_VOX)
    assert f.info["correlation"] == "ncc" and np.all(f.peak[1:-1, 1:-1, 1:-1] <= 1 + 1e-9)
    assert np.median(f.peak[1:-1, 1:-1, 1:-1]) > 0.9
    with pytest.raises(ConfigError, match="correlation"):
        piv3d(a, b, grid, windows=16, correlation="xcorr")
