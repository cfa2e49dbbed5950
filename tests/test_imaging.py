"""Sensor model: each noise stage's mean and variance against theory, exact clipping and
quantisation, seeding; integer image files; FFT convolution.

Statistical tolerances: 5 standard errors of the sample mean / sample variance over
~2.6e5 pixels (the variance's standard error from the fourth central moment), so a
correct implementation fails with probability < 1e-6 per check.
"""

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.imaging import SensorModel, apply_sensor, convolve_psf, sensor_mean_variance
from mitpiv.io.counts import read_counts, write_counts

SHAPE = (512, 512)
NPIX = SHAPE[0] * SHAPE[1]


def _check(x, mean, var, mu4):
    x = np.asarray(x, dtype=float).ravel()
    assert abs(x.mean() - mean) < 5 * np.sqrt(var / x.size), (x.mean(), mean)
    se_var = np.sqrt((mu4 - var**2) / x.size)
    assert abs(x.var(ddof=1) - var) < 5 * se_var, (x.var(ddof=1), var)


def _poisson_mu4(lam):
    return lam * (1 + 3 * lam)


def test_shot_noise_and_quantum_efficiency_are_poisson():
    img = np.full(SHAPE, 2.0)
    out = apply_sensor(img, exposure=40.0, shot_noise=True, seed=1)  # 80 photons
    _check(out, 80.0, 80.0, _poisson_mu4(80.0))
    out = apply_sensor(img, exposure=40.0, quantum_efficiency=0.6, shot_noise=True, seed=2)
    _check(out, 48.0, 48.0, _poisson_mu4(48.0))
    # Without shot noise the chain is deterministic and linear.
    np.testing.assert_allclose(apply_sensor(img, exposure=40.0, quantum_efficiency=0.6), 48.0)


def test_dark_current_read_noise_and_gain():
    img = np.zeros(SHAPE)
    out = apply_sensor(img, dark_current_e_per_s=50.0, exposure_time_s=0.2, seed=3)  # 10 e-
    _check(out, 10.0, 10.0, _poisson_mu4(10.0))
    out = apply_sensor(img, read_noise_e=3.0, black_level=100.0, seed=4)
    _check(out, 100.0, 9.0, 3 * 81.0)
    # Gain divides the electrons: variance / g^2.
    out = apply_sensor(np.full(SHAPE, 100.0), shot_noise=True, exposure=1.0, gain_e_per_count=2.0, seed=5)
    _check(out * 2.0, 100.0, 100.0, _poisson_mu4(100.0))


def test_whole_chain_matches_the_photon_transfer_relation():
    m = SensorModel(exposure=300.0, quantum_efficiency=0.7, shot_noise=True, dark_current_e_per_s=20.0,
                    exposure_time_s=0.5, read_noise_e=5.0, gain_e_per_count=0.5, black_level=10.0)
    out = apply_sensor(np.full(SHAPE, 1.0), m, seed=6)
    mean, var = sensor_mean_variance(300.0, m)
    assert mean == pytest.approx(0.7 * 300 / 0.5 + 10 / 0.5 + 10)
    assert var == pytest.approx((210 + 10 + 25) / 0.25)
    # Poisson + Gaussian: mu4 = 3 var^2 + the Poisson excess kurtosis part (small); bound it.
    _check(out, mean, var, 3 * var**2 + (220.0 / 0.25**2))


def test_gaussian_percent_noise():
    img = np.zeros(SHAPE)
    img[10, 10] = 200.0  # the peak particle intensity
    out = apply_sensor(img, gaussian_noise_percent=5.0, seed=7)
    bg = np.delete(out.ravel(), 10 * SHAPE[1] + 10)
    _check(bg, 0.0, 100.0, 3 * 100.0**2)  # sigma = 5 % of 200 = 10
    out = apply_sensor(img, gaussian_noise_percent=5.0, peak=1000.0, seed=7)
    _check(np.delete(out.ravel(), 10 * SHAPE[1] + 10), 0.0, 2500.0, 3 * 2500.0**2)


def test_full_well_clipping_and_quantisation_are_exact():
    img = np.array([[0.0, 0.4, 0.5, 0.6, 1.49, 254.4, 254.6, 300.0, 5000.0]])
    out = apply_sensor(img, bit_depth=8)
    assert out.dtype == np.uint8
    assert out.tolist() == [[0, 0, 0, 1, 1, 254, 255, 255, 255]]  # round half to even, clip at 255
    out = apply_sensor(img, full_well_e=1000.0, bit_depth=12)
    assert out.dtype == np.uint16 and out.tolist() == [[0, 0, 0, 1, 1, 254, 255, 300, 1000]]
    out = apply_sensor(img, bit_depth=10)
    assert out.max() == 1023
    out = apply_sensor(img * 100, bit_depth=16, gain_e_per_count=2.0)
    assert out[0, -1] == 65535 and out[0, 7] == 15000
    # peak_photons scales the brightest pixel.
    np.testing.assert_allclose(apply_sensor(img, peak_photons=100.0)[0, -1], 100.0)


def test_seeded_and_vectorised():
    img = np.random.default_rng(0).random((64, 80)) * 50
    m = SensorModel(exposure=10.0, shot_noise=True, read_noise_e=2.0, bit_depth=12)
    a = apply_sensor(img, m, seed=11)
    b = apply_sensor(img, m, seed=11)
    c = apply_sensor(img, m, seed=12)
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    assert a.shape == img.shape


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"bit_depth": 7}, "bit_depth"),
        ({"quantum_efficiency": 1.5}, "quantum_efficiency"),
        ({"gain_e_per_count": 0.0}, "gain_e_per_count"),
        ({"read_noise_e": -1.0}, "read_noise_e"),
        ({"shot_noise": True}, "exposure"),
        ({"exposure": 1.0, "peak_photons": 10.0}, "not both"),
        ({"full_well_e": float("inf")}, "full_well_e"),
    ],
)
def test_bad_sensor_parameters(kwargs, match):
    with pytest.raises(ConfigError, match=match):
        apply_sensor(np.ones((4, 4)), **kwargs)


def test_bad_images():
    with pytest.raises(ConfigError, match="finite"):
        apply_sensor(np.array([[1.0, np.nan]]))
    with pytest.raises(ConfigError, match="2D"):
        apply_sensor(np.ones(5))


@pytest.mark.parametrize("suffix", [".exr", ".png", ".tif"])
@pytest.mark.parametrize("bits", [8, 16])
def test_counts_files_round_trip(tmp_path, suffix, bits):
    rng = np.random.default_rng(3)
    arr = rng.integers(0, 2**bits, size=(37, 53)).astype(np.uint8 if bits == 8 else np.uint16)
    p = write_counts(tmp_path / f"img{suffix}", arr, {"bit_depth": bits})
    back, meta = read_counts(p)
    assert np.array_equal(back.astype(np.int64), arr.astype(np.int64))
    if suffix == ".exr":
        assert meta == {"bit_depth": bits}


def test_counts_bad_input_writes_nothing(tmp_path):
    with pytest.raises(ConfigError, match="uint8 or uint16"):
        write_counts(tmp_path / "a.png", np.ones((4, 4)))
    with pytest.raises(ConfigError, match="must end in"):
        write_counts(tmp_path / "a.jpg", np.ones((4, 4), np.uint8))
    assert list(tmp_path.iterdir()) == []


def test_fft_convolution_conserves_energy_and_centres():
    img = np.zeros((64, 64))
    img[20, 30] = 1.0
    k = np.zeros((5, 5))
    k[2, 2], k[2, 3], k[1, 2] = 0.5, 0.3, 0.2
    out = convolve_psf(img, k)
    assert out.sum() == pytest.approx(1.0)
    assert out[20, 30] == pytest.approx(0.5) and out[20, 31] == pytest.approx(0.3) and out[19, 30] == pytest.approx(0.2)
    with pytest.raises(ConfigError, match="odd"):
        convolve_psf(img, np.ones((4, 4)))
