"""preprocess_images on 8-bit images whose zero-mean noise the ADC clipped at 0 (the
channel-tomo paper's camera noise): the histogram mode is the floor itself, and before the
fix nothing was removed."""

import numpy as np
import pytest
from scipy.stats import norm

from mitpiv.reconstruct.tomo import preprocess_images

SIGMA = 20.0  # noise sigma [counts], 10 % of a 200-count particle peak
PEAK = 200.0


def _image(seed=0, particles=600, size=300):
    rng = np.random.default_rng(seed)
    clean = np.zeros((size, size))
    iy, ix = rng.integers(3, size - 3, (2, particles))
    yy, xx = np.mgrid[-2:3, -2:3]
    for dy, dx in zip(yy.ravel(), xx.ravel(), strict=True):
        np.add.at(clean, (iy + dy, ix + dx), PEAK * np.exp(-(dx * dx + dy * dy) / (2 * 0.75**2)))
    noisy = np.clip(np.rint(clean + rng.normal(0.0, SIGMA, clean.shape)), 0, 255)
    return clean, noisy


def test_clipped_noise_background_is_removed():
    clean, noisy = _image()
    out = preprocess_images([noisy], k=2.0)[0]
    background = clean < 1e-3 * PEAK  # pixels that hold noise only
    # a normal clipped at 0: 1 - Phi(2) = 2.3 % of noise pixels stay above mean + 2 sigma; the
    # sigma estimate (+-13 %: rounding, and particle light on 16 % of the pixels here) moves that
    # within 0.5-4.5 % (z = 2 -+ 0.26)
    kept = np.mean(out[background] > 0)
    assert 0.005 < kept < 0.045, kept
    assert np.mean(noisy[background] > 0) > 0.45  # the input: about half of the noise is > 0
    # particle centres (200 counts) survive, lowered by the threshold ~2 sigma = 40 counts
    centres = clean > 0.9 * PEAK
    assert np.median(out[centres]) == pytest.approx(np.median(noisy[centres]) - 2 * SIGMA, abs=0.25 * 2 * SIGMA)


def test_clipped_noise_threshold_follows_k():
    _, noisy = _image(seed=1, particles=200)
    lost = [np.mean(preprocess_images([noisy], k=k)[0] == 0) for k in (0.0, 1.0, 2.0)]
    # noise-only share below mean + k sigma: Phi(k) (0.50, 0.84, 0.98), less the particle pixels
    for k, share in zip((0.0, 1.0, 2.0), lost, strict=True):
        assert share == pytest.approx(norm.cdf(k), abs=0.04), (k, lost)


def test_noise_free_sparse_image_keeps_its_light():
    clean, _ = _image(seed=2)
    out = preprocess_images([clean], k=2.0)[0]
    assert out.sum() > 0.98 * clean.sum()
