"""The PSF in rendering: FFT mode and in-sensor jitter against a NumPy reference built from
the float64 camera model, the closed-form particle intensities and mitpiv.physics.psf at
each particle's exact sub-pixel position (with the same window).

Tolerances: FFT mode at oversample 9 (catmullrom splat) leaves 9e-4 of the peak, measured;
jitter with 65536 rays per particle leaves Monte Carlo noise of ~1 % of the peak per pixel.
"""

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.physics import psf as P
from mitpiv.render.render import render_sensor

from .helpers import camera, scene, window_stats
from .test_plugins import PTS, analytic_totals

OPTICS = {"psf_f_number": 8.0, "psf_magnification": 0.2, "psf_spherical_waves": 0.1, "psf_energy_tolerance": 5e-3}
KW = {"f_number": 8.0, "pixel_pitch_um": 10.0, "magnification": 0.2, "spherical_waves": 0.1}

# Tolerances and their provenance (module docstring: the reference is the float64 camera
# model, the closed-form intensities and mitpiv.physics.psf at each exact sub-pixel position).
FFT_TOL_OF_PEAK = 2e-3  # FFT mode at oversample 9 (catmullrom splat): measured 9e-4 of the peak
FFT_COARSE_TOL_OF_PEAK = 0.05  # oversample 3: larger error, but bounded
FFT_TOTAL_REL_TOL = 5e-4  # image totals: the fine and coarse PSF windows truncate different tails (1e-4)
# Jitter, 65536 rays per particle: Monte Carlo noise of ~1 % of the peak per pixel, so 3 % on
# the worst pixel; window sums (+-5 px) lose only what crosses the window's edge.
JITTER_TOL_OF_PEAK = 0.03
JITTER_WINDOW_SUM_RTOL = 5e-3
N_SIGMA = 5  # centroids: standard errors sqrt(second moment per axis / rays)
# Camera tracing, four seeds pooled: the spread of the per-seed mean was 0.2 % (measured), so
# 1 % is 5 of those spreads.
CAMERA_TRACING_ABS_TOL = 0.01
SECOND_MOMENT_RTOL = 0.05  # field-dependent PSF: second moments of 65536-ray particle images


def reference(cam, pts, defocus_corner=0.0):
    """Sum over particles of E_i * PSF(pixel-integrated, at the particle's sub-pixel offset)."""
    w, h = cam.resolution
    energy = analytic_totals(cam, pts)
    uv = cam.project(pts)
    cx, cy = cam.principal_point_px
    hc2 = max((u - cx) ** 2 + (v - cy) ** 2 for u in (0, w) for v in (0, h))
    img = np.zeros((h, w))
    for e, (u, v) in zip(energy, uv, strict=True):
        i, j = int(np.floor(v)), int(np.floor(u))
        h2 = ((u - cx) ** 2 + (v - cy) ** 2) / hc2
        k = P.psf(**KW, offset_px=(u - j - 0.5, v - i - 0.5), energy_tolerance=5e-3, normalize="window",
                  defocus_waves=defocus_corner * h2)
        n = k.shape[0] // 2
        big = np.zeros((h + 2 * n, w + 2 * n))
        big[i:i + 2 * n + 1, j:j + 2 * n + 1] += e * k
        img += big[n:n + h, n:n + w]
    return img


@pytest.fixture(scope="module")
def ref():
    return reference(camera(), PTS)


def test_fft_mode_matches_the_reference(tmp_path, ref):
    cam = camera()
    sc = scene(tmp_path, PTS, cam=cam, sensor_props={"psf": "fft", "psf_oversample": 9, **OPTICS},
               rfilter={"type": "catmullrom"})
    sensor = sc.sensors()[0]
    img = render_sensor(sc, sensor)
    assert img.shape == (48, 48) and tuple(sensor.film().size()) == (48, 48)  # film restored
    assert np.max(np.abs(img - ref)) < FFT_TOL_OF_PEAK * ref.max()
    assert img.sum() == pytest.approx(ref.sum(), rel=FFT_TOTAL_REL_TOL)
    # The accuracy knob: coarser oversampling, larger (but bounded) error.
    sc = scene(tmp_path, PTS, cam=cam, sensor_props={"psf": "fft", "psf_oversample": 3, **OPTICS},
               rfilter={"type": "catmullrom"})
    err3 = np.max(np.abs(render_sensor(sc, sc.sensors()[0]) - ref)) / ref.max()
    assert FFT_TOL_OF_PEAK < err3 < FFT_COARSE_TOL_OF_PEAK


def test_jitter_particle_tracing_matches_the_reference(tmp_path, ref):
    cam = camera()
    sc = scene(tmp_path, PTS, cam=cam, sensor_props={"psf": "jitter", **OPTICS},
               integrator={"type": "particle_tracer", "rays_per_particle": 65536})
    img = render_sensor(sc, sc.sensors()[0])
    assert np.max(np.abs(img - ref)) < JITTER_TOL_OF_PEAK * ref.max()
    ours, theirs = window_stats(img, cam.project(PTS), 5), window_stats(ref, cam.project(PTS), 5)
    np.testing.assert_allclose(ours[:, 0], theirs[:, 0], rtol=JITTER_WINDOW_SUM_RTOL)
    # Centroids [px]: 5 standard errors sqrt(second moment per axis / rays).
    yy, xx = np.mgrid[0:48, 0:48] + 0.5
    for (u, v), (_, cu, cv), (_, ou, ov) in zip(cam.project(PTS), theirs, ours, strict=True):
        m = (np.abs(xx - u) <= 5) & (np.abs(yy - v) <= 5)
        var = np.sum(ref[m] * ((xx[m] - cu) ** 2 + (yy[m] - cv) ** 2)) / ref[m].sum() / 2
        se = np.sqrt(var / 65536)
        assert abs(ou - cu) < N_SIGMA * se and abs(ov - cv) < N_SIGMA * se


def test_jitter_camera_tracing_agrees(tmp_path, ref):
    # Four seeds pooled (CAMERA_TRACING_ABS_TOL).
    cam = camera()
    sc = scene(tmp_path, PTS, cam=cam, sensor_props={"psf": "jitter", **OPTICS}, integrator={"type": "direct"},
               proxy=0.05)
    theirs = window_stats(ref, cam.project(PTS), 5)[:, 0]
    ratios = [window_stats(render_sensor(sc, sc.sensors()[0], spp=4096, seed=s), cam.project(PTS), 5)[:, 0] / theirs
              for s in range(4)]
    assert np.mean(ratios) == pytest.approx(1.0, abs=CAMERA_TRACING_ABS_TOL)


def test_field_dependent_psf_follows_the_field_height(tmp_path):
    cam = camera()
    sc = scene(tmp_path, PTS, cam=cam, sensor_props={"psf": "jitter", "psf_defocus_corner_waves": 1.0, **OPTICS},
               integrator={"type": "particle_tracer", "rays_per_particle": 65536})
    img = render_sensor(sc, sc.sensors()[0])
    ref = reference(cam, PTS, defocus_corner=1.0)
    uv = cam.project(PTS)

    def second_moment(a):
        h, w = a.shape
        yy, xx = np.mgrid[0:h, 0:w] + 0.5
        out = []
        for (u, v), (_, cu, cv) in zip(uv, window_stats(a, uv, 5), strict=True):
            m = (np.abs(xx - u) <= 5) & (np.abs(yy - v) <= 5)
            out.append(np.sum(a[m] * ((xx[m] - cu) ** 2 + (yy[m] - cv) ** 2)) / a[m].sum())
        return np.array(out)

    m_img, m_ref = second_moment(img), second_moment(ref)
    np.testing.assert_allclose(m_img, m_ref, rtol=SECOND_MOMENT_RTOL)
    # ... and really varies: against a field-independent PSF, the particle farthest out
    # widens, the central one hardly.
    m_flat = second_moment(reference(cam, PTS))
    r = np.hypot(*(uv - 24).T)
    assert m_ref[np.argmax(r)] > 1.3 * m_flat[np.argmax(r)]
    assert m_ref[np.argmin(r)] < 1.05 * m_flat[np.argmin(r)]


def test_describe_and_render_scene_metadata(tmp_path):
    sc = scene(tmp_path, PTS, sensor_props={"psf": "jitter", "psf_zernike": "11:0.05, 8:0.02", "psf_f_number": 11.0})
    d = sc.sensors()[0].describe()["psf"]
    assert d["mode"] == "jitter" and d["zernike_coefficients"] == {"noll8": 0.02, "noll11": 0.05}
    assert d["f_number"] == 11.0 and d["indexing"] == "noll"
    sc = scene(tmp_path, PTS)
    assert sc.sensors()[0].describe()["psf"] is None


@pytest.mark.parametrize(
    "props, rfilter, match",
    [
        ({"psf": "gauss", "psf_f_number": 8.0}, None, "must be one of"),
        ({"psf": "fft", "psf_f_number": 8.0}, {"type": "box"}, "catmullrom"),
        ({"psf": "jitter", "psf_f_number": 8.0}, {"type": "gaussian"}, "box"),
        ({"psf_f_number": 8.0}, None, "psf is 'none'"),
        ({"psf": "fft", "psf_f_number": 8.0, "psf_defocus_corner_waves": 0.5}, {"type": "tent"}, "jitter"),
        ({"psf": "jitter"}, None, "psf_f_number"),
        ({"psf": "jitter", "psf_f_number": 8.0, "psf_zernike": "11=0.1"}, None, "noll:waves"),
        ({"psf": "fft", "psf_f_number": 8.0, "psf_oversample": 4}, {"type": "tent"}, "odd"),
        ({"psf": "jitter", "psf_f_number": -8.0}, None, "f_number"),
    ],
)
def test_bad_psf_parameters(tmp_path, props, rfilter, match):
    with pytest.raises(ConfigError, match=match):
        scene(tmp_path, PTS, sensor_props=props, rfilter=rfilter)
