"""Sensor model: each noise stage's mean and variance against theory, exact clipping and
quantisation, seeding; integer image files; FFT convolution.

Statistical tolerances: 5 standard errors of the sample mean / sample variance over
~2.6e5 pixels (the variance's standard error from the fourth central moment), so a
correct implementation fails with probability < 1e-6 per check.
"""

import json

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.imaging import SensorModel, apply_sensor, apply_sensor_set, convolve_psf, sensor_mean_variance
from mitpiv.io.counts import read_counts, write_counts

SHAPE = (512, 512)
NPIX = SHAPE[0] * SHAPE[1]
# Statistical tolerance (module docstring): standard errors allowed for a sample mean, a sample
# variance, a ratio of means or a Pearson r of independent fields; 5 sigma of a normal statistic
# is a two-sided p of 5.7e-7 per check. Exact scalings (rel 1e-12 .. 1e-15) stay inline.
N_SIGMA = 5


def _check(x, mean, var, mu4):
    x = np.asarray(x, dtype=float).ravel()
    assert abs(x.mean() - mean) < N_SIGMA * np.sqrt(var / x.size), (x.mean(), mean)
    se_var = np.sqrt((mu4 - var**2) / x.size)
    assert abs(x.var(ddof=1) - var) < N_SIGMA * se_var, (x.var(ddof=1), var)


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


# ------------------------------------------------------------------ scene-wide exposure
def _particle_image(rng, shape=SHAPE, n=400):
    """A sparse image of Gaussian spots of random brightness (a rendered particle image)."""
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]]
    img = np.zeros(shape)
    for y, x, a in zip(rng.uniform(0, shape[0], n), rng.uniform(0, shape[1], n), rng.uniform(0.2, 1.0, n), strict=True):
        m = (np.abs(yy - y) < 5) & (np.abs(xx - x) < 5)
        img[m] += a * np.exp(-((yy[m] - y) ** 2 + (xx[m] - x) ** 2) / (2 * 1.2**2))
    return img


def test_peak_photons_is_one_exposure_for_the_whole_set():
    # A forward-scatter camera renders 3x the radiance of a back-scatter one.
    base = _particle_image(np.random.default_rng(20))
    fwd, back = 3.0 * base, base
    res = apply_sensor_set({("fwd", 0): fwd, ("back", 0): back}, peak_photons=1000.0, seed=4)
    exposure = 1000.0 / fwd.max()  # the set's brightest pixel becomes 1000 photons
    assert res.scene_peak == fwd.max() and res.exposure == pytest.approx(exposure, rel=1e-15)
    np.testing.assert_allclose(res.counts[("fwd", 0)], fwd * exposure, rtol=1e-12)
    np.testing.assert_allclose(res.counts[("back", 0)], back * exposure, rtol=1e-12)
    assert res.counts[("back", 0)].max() == pytest.approx(1000.0 / 3)  # not rescaled to its own peak
    # With Poisson shot noise and 12-bit rounding (Poisson counts are integers: rounding
    # adds nothing) each image's mean count is exposure * mean(radiance) within 5 standard
    # errors, sqrt(sum(lambda)) / N; so the means keep the 3:1 ratio.
    res = apply_sensor_set({("fwd", 0): fwd, ("back", 0): back}, peak_photons=1000.0, shot_noise=True,
                           bit_depth=12, seed=4)
    means = {}
    for key, img in (("fwd", fwd), ("back", back)):
        lam = img * exposure
        c = res.counts[(key, 0)].astype(float)
        assert abs(c.mean() - lam.mean()) < N_SIGMA * np.sqrt(lam.sum()) / lam.size
        means[key] = c.mean()
    se_ratio = 3 * np.sqrt(1 / (fwd * exposure).sum() + 1 / (back * exposure).sum())  # relative errors in quadrature
    assert means["fwd"] / means["back"] == pytest.approx(3.0, abs=N_SIGMA * se_ratio)


def test_gaussian_noise_percent_has_one_sigma_for_the_whole_set():
    base = _particle_image(np.random.default_rng(21))
    fwd, back = 3.0 * base, base
    res = apply_sensor_set({("fwd", 0): fwd, ("back", 0): back}, gaussian_noise_percent=5.0, seed=8)
    sigma = 0.05 * fwd.max()  # 5 % of the set's noise-free peak count (values are photons)
    assert res.noise_peak_counts == pytest.approx(fwd.max()) and res.exposure == 1.0
    for key, img in (("fwd", fwd), ("back", back)):
        _check(res.counts[(key, 0)] - img, 0.0, sigma**2, 3 * sigma**4)
    # the means keep 3:1 (noise of sigma over N pixels: 5 standard errors of the ratio)
    m_f, m_b = res.counts[("fwd", 0)].mean(), res.counts[("back", 0)].mean()
    assert m_f / m_b == pytest.approx(3.0, abs=N_SIGMA * sigma / np.sqrt(NPIX) * np.hypot(1 / m_b, 3 / m_b))


def test_apply_sensor_on_one_image_of_a_set():
    img = _particle_image(np.random.default_rng(22), shape=(64, 64), n=30)
    # one image is the whole set: its own maximum is the peak
    np.testing.assert_allclose(apply_sensor(img, peak_photons=100.0).max(), 100.0)
    # the set's peak given explicitly
    np.testing.assert_allclose(apply_sensor(img, peak_photons=100.0, scene_peak=3 * img.max()).max(), 100.0 / 3)
    with pytest.raises(ConfigError, match="scene_peak"):
        apply_sensor(img, peak_photons=100.0, scene_peak=0.5 * img.max())
    # exposure is physical: no dependence on the peak at all
    np.testing.assert_allclose(apply_sensor(img, exposure=7.0, scene_peak=10 * img.max()), 7.0 * img)


def _noise_fields(res, images):
    return {k: res.counts[k] - images[k] for k in images}


def test_each_camera_and_frame_has_its_own_noise_stream():
    img = np.full((256, 256), 50.0)
    images = {("cam0", 0): img, ("cam1", 0): img, ("cam0", 1): img}
    m = SensorModel(gaussian_noise_percent=10.0)
    res = apply_sensor_set(images, m, seed=123)
    n = _noise_fields(res, images)
    # Independent fields: the sample Pearson r of N pairs has standard deviation 1/sqrt(N);
    # |r| < 5/sqrt(N) fails by chance with probability 6e-7. A shared stream gives r = 1.
    bound = N_SIGMA / np.sqrt(img.size)
    for a, b in ((("cam0", 0), ("cam1", 0)), (("cam0", 0), ("cam0", 1)), (("cam1", 0), ("cam0", 1))):
        r = np.corrcoef(n[a].ravel(), n[b].ravel())[0, 1]
        assert abs(r) < bound, (a, b, r)
    assert len(set(res.seeds.values())) == 3
    # a rerun is bit-identical; the derived seed reproduces one image on its own
    again = apply_sensor_set(images, m, seed=123)
    assert all(np.array_equal(res.counts[k], again.counts[k]) for k in images) and again.seeds == res.seeds
    for k in images:
        assert np.array_equal(apply_sensor(img, m, seed=res.seeds[k], scene_peak=res.scene_peak), res.counts[k])
    # another experiment seed gives other noise
    assert not np.array_equal(apply_sensor_set(images, m, seed=124).counts[("cam0", 0)], res.counts[("cam0", 0)])


def test_a_subset_of_cameras_keeps_each_cameras_stream():
    rng = np.random.default_rng(30)
    images = {(f"cam{i}", f): rng.random((32, 40)) * 100 for i in range(3) for f in (0, 1)}
    m = SensorModel(exposure=2.0, shot_noise=True, read_noise_e=2.0, bit_depth=12)
    full = apply_sensor_set(images, m, seed=9)
    sub = apply_sensor_set({k: v for k, v in images.items() if k[0] == "cam1"}, m, seed=9)
    assert all(np.array_equal(sub.counts[k], full.counts[k]) for k in sub.counts)


def test_sensor_set_metadata_and_bad_input():
    img = np.ones((8, 8))
    res = apply_sensor_set({("camA", 2): img}, SensorModel(peak_photons=10.0, gaussian_noise_percent=1.0), seed=5)
    meta = res.metadata(("camA", 2))
    assert meta["exposure_used_photons_per_unit"] == 10.0 and meta["scene_peak"] == 1.0
    assert meta["noise_peak_counts"] == 10.0 and meta["experiment_seed"] == 5
    assert meta["sensor_seed"] == res.seeds[("camA", 2)] and meta["peak_photons"] == 10.0 and meta["exposure"] is None
    assert meta["stream"] == {"purpose": "sensor", "camera": "camA", "frame": 2}
    json.dumps(meta)  # JSON-ready
    for bad, match in (({}, "non-empty mapping"), ([img], "mapping"), ({("camA",): img}, "camera_id"),
                       ({(0, 0): img}, "camera_id"), ({("camA", -1): img}, "camera_id"),
                       ({("camA", 0): -img}, "finite and >= 0")):
        with pytest.raises(ConfigError, match=match):
            apply_sensor_set(bad, seed=0)
    for seed in (-1, 1.5, 2**63, None):
        with pytest.raises(ConfigError, match="seed"):
            apply_sensor_set({("camA", 0): img}, seed=seed)
    for seed in (-1, 2.0, 2**64):
        with pytest.raises(ConfigError, match="seed"):
            apply_sensor(img, seed=seed)


def test_gaussian_point_table_and_point_images():
    """A point centred on a pixel peaks at ``peak * factor``; its neighbour holds the Gaussian
    integrated over the next pixel (written afresh with erf), up to the window renormalisation."""
    from math import erf, sqrt

    from mitpiv.imaging import PointPSFTable, point_images
    from mitpiv.physics.camera import PinholeCamera

    sigma = 0.6
    table = PointPSFTable.gaussian(sigma)
    assert table.window == 2 * 2 + 1 and table.oversample == 9

    def pixel(a, b):  # 1D Gaussian integrated over [a, b] [px]
        return 0.5 * (erf(b / (sqrt(2) * sigma)) - erf(a / (sqrt(2) * sigma)))

    cam = PinholeCamera((32, 32), 50.0, 10.0, position_mm=(0.0, 0.0, -500.0))
    o, d = cam.pixel_to_ray(np.array([16.5, 16.5]))
    p = (o + d * (500.0 / d[2]))[None, :]
    img, dim = point_images([cam, cam], p, table, peak=200.0, factors=[1.0, 0.25])
    assert img.dtype == np.float64 and img.max() == pytest.approx(200.0, rel=1e-9)
    assert dim.max() == pytest.approx(50.0, rel=1e-9)
    j, i = np.unravel_index(int(img.argmax()), img.shape)
    assert (j, i) == (16, 16)
    assert img[j, i + 1] / img[j, i] == pytest.approx(pixel(0.5, 1.5) / pixel(-0.5, 0.5), rel=1e-9)
    assert point_images([cam], p, table, peak=200.0)[0] == pytest.approx(img)
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ConfigError, match="sigma_px"):
            PointPSFTable.gaussian(bad)
    with pytest.raises(ConfigError, match="oversample"):
        PointPSFTable.gaussian(1.0, oversample=0)


# ------------------------------------------------------------------ decimated PSF convolution
class TestDecimatedConvolve:
    """``decimated_convolve`` (what ``RenderPSF.apply`` uses) against the full-resolution path it
    replaces, ``convolve_psf(fine, k) / s^2`` at the pixel centres ``[s//2::s, s//2::s]``.

    Tolerance 1e-12 of the reference's peak: both sides are float64 sums of the same products,
    the FFT ones with round-off of about 1e-16 times log2 of the transform size (~1e-15 here);
    an index error moves whole kernel samples and shows as O(1) of the peak."""

    TOL = 1e-12
    COARSE = (40, 50)  # (H, W); non-square, so a swapped axis shows

    @staticmethod
    def _fine(s, rng, n=60, coarse=COARSE):
        """Bilinear splats of random brightness (a tent-filtered particle render), with particles
        on the four corners and edges, a few negative pixels (a Catmull-Rom film's lobes)."""
        shape = (coarse[0] * s, coarse[1] * s)
        f = np.zeros(shape)
        ys = np.concatenate([rng.uniform(0, shape[0] - 1, n), [0.0, 0.0, shape[0] - 1.0, shape[0] - 1.0, 0.3, shape[0] - 1.3]])
        xs = np.concatenate([rng.uniform(0, shape[1] - 1, n), [0.0, shape[1] - 1.0, 0.0, shape[1] - 1.0, shape[1] / 2, 0.6]])
        iy = np.minimum(ys.astype(int), shape[0] - 2)
        ix = np.minimum(xs.astype(int), shape[1] - 2)
        fy, fx = ys - iy, xs - ix
        a = rng.uniform(0.2, 1.0, ys.size)
        for dy, wy in ((0, 1 - fy), (1, fy)):
            for dx, wx in ((0, 1 - fx), (1, fx)):
                np.add.at(f, (iy + dy, ix + dx), a * wy * wx)
        f[rng.integers(0, shape[0], 5), rng.integers(0, shape[1], 5)] -= 0.05
        return f

    @staticmethod
    def _reference(fine, k, s):
        return convolve_psf(fine, k)[s // 2::s, s // 2::s] / (s * s)

    def _check(self, fine, k, s):
        from mitpiv.imaging import decimated_convolve

        ref = self._reference(fine, k, s)
        peak = ref.max()
        outs = {m: decimated_convolve(fine, k, s, method=m) / (s * s) for m in ("auto", "direct", "fft")}
        for m, out in outs.items():
            assert out.shape == ref.shape and out.min() >= 0.0
            assert np.abs(out - ref).max() <= self.TOL * peak, (m, np.abs(out - ref).max() / peak)
        assert np.abs(outs["direct"] - outs["fft"]).max() <= self.TOL * peak
        return ref

    @pytest.mark.parametrize("s", [1, 3, 5, 7])
    def test_small_psf_kernel(self, s):
        from mitpiv.imaging import RenderPSF

        k = RenderPSF(mode="fft", f_number=2.8, pixel_pitch_um=10.0, magnification=0.2, energy_tolerance=0.005,
                      oversample=s).fft_kernel
        ref = self._check(self._fine(s, np.random.default_rng(s)), k, s)
        assert ref[0, 0] > 0.0 and ref[-1, -1] > 0.0  # the corner particles were kept

    @pytest.mark.parametrize("s", [1, 3, 5, 7])
    def test_large_aberrated_kernel_wider_than_the_image(self, s):
        from mitpiv.imaging import RenderPSF

        k = RenderPSF(mode="fft", f_number=22.0, pixel_pitch_um=10.0, magnification=1.0, zernike_coefficients=((11, 0.1),),
                      energy_tolerance=0.005, oversample=s).fft_kernel
        fine = self._fine(s, np.random.default_rng(10 + s))
        assert k.shape[0] > fine.shape[0] and k.shape[1] > fine.shape[1]
        self._check(fine, k, s)

    @pytest.mark.parametrize("s", [1, 3, 5, 7])
    def test_random_kernel_wider_than_the_image_in_one_axis(self, s):
        rng = np.random.default_rng(20 + s)
        fine = self._fine(s, rng)
        k = rng.uniform(0.0, 1.0, (2 * (fine.shape[0] // 3) + 1, 2 * fine.shape[1] + 5 + 2 * s))
        assert k.shape[0] < fine.shape[0] and k.shape[1] > fine.shape[1]
        self._check(fine, k, s)
        self._check(fine.T.copy(), k.T.copy(), s)  # wider in the other axis

    def test_auto_takes_the_direct_kernel_for_sparse_images_and_the_fft_for_dense(self, monkeypatch):
        import mitpiv.imaging as im

        calls = []
        real = im._decimate_kernels()
        monkeypatch.setattr(im, "_decimate_kernels", lambda: {**real, "direct": lambda *a: (calls.append(1), real["direct"](*a))})
        fine = self._fine(5, np.random.default_rng(0))
        small = im.RenderPSF(mode="fft", f_number=2.8, pixel_pitch_um=10.0, magnification=0.2, energy_tolerance=0.005).fft_kernel
        im.decimated_convolve(fine, small, 5)
        assert calls == [1]
        im.decimated_convolve(fine + 0.01, small, 5)  # dense: every fine pixel is non-zero
        assert calls == [1]

    def test_render_psf_apply(self):
        from mitpiv.imaging import RenderPSF

        psf = RenderPSF(mode="fft", f_number=8.0, pixel_pitch_um=10.0, magnification=0.5, oversample=5)
        fine = self._fine(5, np.random.default_rng(3))
        ref = self._reference(fine, psf.fft_kernel, 5)
        np.testing.assert_allclose(psf.apply(fine), ref, rtol=0, atol=self.TOL * ref.max())
        with pytest.raises(ConfigError, match="5 times"):
            psf.apply(fine[:-1])

    def test_bad_input(self):
        from mitpiv.imaging import decimated_convolve

        img = np.zeros((15, 15))
        with pytest.raises(ConfigError, match="odd"):
            decimated_convolve(img, np.ones((4, 3)), 3)
        with pytest.raises(ConfigError, match="multiple"):
            decimated_convolve(img, np.ones((3, 3)), 4)
        with pytest.raises(ConfigError, match="step"):
            decimated_convolve(img, np.ones((3, 3)), 0)
        with pytest.raises(ConfigError, match="method"):
            decimated_convolve(img, np.ones((3, 3)), 3, method="fast")
        with pytest.raises(ConfigError, match="2D"):
            decimated_convolve(img[0], np.ones((3, 3)), 3)
