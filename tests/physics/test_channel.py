"""Channel flow: the shipped DNS table against well-known wall-turbulence facts, and the
synthetic turbulence against its own definition (solenoidal, the table's stresses, the
spectrum's streamwise integral scale), each reference written afresh here in float64."""

import math

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.physics.channel import SyntheticTurbulence, load_channel_profile
from mitpiv.physics.flows import FLOW_KINDS, Channel, flow_from_dict

# --- tolerances and their provenance -------------------------------------------------------
# Peak of u'+ in channels at Re_tau ~ 1000: 2.7-2.85 at y+ = 12-16 (Hoyas & Jimenez 2006,
# Lee & Moser 2015 give 2.8 near y+ = 15); the brief's "about 2.7".
PEAK_URMS_RANGE = (2.65, 2.9)
PEAK_Y_PLUS_RANGE = (12.0, 17.0)
# von Karman constant of a least-squares log-law fit over 60 < y+ < 0.2 Re_tau: 0.39-0.41
# (Lee & Moser 2015: 0.384; del Alamo et al. 2004: 0.39-0.41), intercept B 4.5-5.5.
KAPPA_RANGE = (0.38, 0.42)
B_RANGE = (4.5, 5.6)
# Mean momentum balance: -<u'v'>+ + dU+/dy+ = 1 - y/h exactly in a converged channel; our
# derivative is a second-order difference on the Chebyshev grid (measured residual 3e-3).
TOTAL_STRESS_ATOL = 1e-2
# Central differences with h = 1e-3 wall units: truncation (h kappa_max)^2 ~ 1e-6 of the
# gradient, rounding eps |u| / h ~ 1e-12; the analytic curl is exact (measured 2e-9 of the
# gradient scale).
DIVERGENCE_OF_GRADIENT = 1e-5
# One-point statistics over N = 20000 random points of a thin slab spread over 2e6 wall units
# (independent samples): the standard error of a variance is sqrt(2/N) = 1 %; of an r.m.s.
# half that. 4 standard errors of the r.m.s. plus the spline's between-knot error (measured
# <= 0.12 % of the largest stress). Measured with 40000 points: r.m.s. within 0.5 %.
STATS_POINTS = 20000
RMS_REL_TOL = 4 * 0.5 * math.sqrt(2 / STATS_POINTS) + 0.002
UV_ABS_TOL = 0.07  # 4 standard errors of <u'v'>+ (u'v' r.m.s. ~ 2.2 over sqrt(20000) = 0.016)
# Frozen-field advection (RK4, mitpiv.physics.advection) over the scene's dt+ = 0.29: one step
# against eight differ by 1.3e-4 wall units (measured; 2e-4 voxels at l_v+ = 0.63), far
# below PIV errors; bound 1e-3.
ADVECT_ATOL_PLUS = 1e-3
# Streamwise integral length from lines 64 integral scales long, integrated to 6 scales: one
# realisation of 500 modes and 16 lines scatters by 16 % (measured over 6 seeds: mean 0.93 of
# the analytic value, the truncated tail and negative lobes making up the bias); the mean of
# 3 realisations x 32 lines scatters by ~6 %: 0.07 bias + 3 sigma.
INTEGRAL_LENGTH_REL_TOL = 0.25


@pytest.fixture(scope="module")
def table():
    return load_channel_profile()


@pytest.fixture(scope="module")
def turb(table):
    return SyntheticTurbulence(table, center_y_plus=150.0, modes=400, seed=7)


def test_table_is_the_re934_dns_with_its_near_wall_peak_and_log_law(table):
    assert table.re_tau == pytest.approx(934.0, rel=2e-3)
    i = int(np.argmax(table.u_rms_plus))
    assert PEAK_URMS_RANGE[0] < table.u_rms_plus[i] < PEAK_URMS_RANGE[1]
    assert PEAK_Y_PLUS_RANGE[0] < table.y_plus[i] < PEAK_Y_PLUS_RANGE[1]
    # log law U+ = ln(y+) / kappa + B, least squares written here
    sel = (table.y_plus > 60) & (table.y_plus < 0.2 * table.re_tau)
    slope, b = np.polyfit(np.log(table.y_plus[sel]), table.U_plus[sel], 1)
    assert KAPPA_RANGE[0] < 1 / slope < KAPPA_RANGE[1]
    assert B_RANGE[0] < b < B_RANGE[1]
    # viscous sublayer U+ = y+ and the exact total-stress balance
    assert np.allclose(table.U_plus[table.y_plus < 1], table.y_plus[table.y_plus < 1], rtol=1e-3, atol=1e-5)
    dudy = np.gradient(table.U_plus, table.y_plus)
    total = -table.uv_plus + dudy
    assert np.abs(total - (1 - table.y_over_h)).max() < TOTAL_STRESS_ATOL


def test_profile_interpolation_and_range(table):
    y = table.y_plus[50]
    assert table.mean_plus(y) == pytest.approx(table.U_plus[50], rel=1e-12)
    r = table.stress_plus(np.array([y]))[0]
    assert r[0, 0] == pytest.approx(table.u_rms_plus[50] ** 2) and r[0, 1] == pytest.approx(table.uv_plus[50])
    assert r[1, 1] == pytest.approx(table.v_rms_plus[50] ** 2) and r[2, 2] == pytest.approx(table.w_rms_plus[50] ** 2)
    with pytest.raises(ConfigError, match="Re_tau"):
        table.mean_plus(2000.0)


def _divergence(f, p, h):
    div = np.zeros(len(p))
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        div += (f(p + e)[:, k] - f(p - e)[:, k]) / (2 * h)
    return div


def test_synthetic_turbulence_is_divergence_free(turb):
    rng = np.random.default_rng(1)
    p = np.column_stack([rng.uniform(-500, 500, 300), rng.uniform(80, 280, 300), rng.uniform(-500, 500, 300)])
    h = 1e-3
    div = _divergence(turb.fluctuation_plus, p, h)
    grad = np.abs((turb.fluctuation_plus(p + [h, 0, 0]) - turb.fluctuation_plus(p - [h, 0, 0])) / (2 * h)).mean()
    assert grad > 1e-3  # a real velocity gradient is there to compare with
    assert np.abs(div).max() < DIVERGENCE_OF_GRADIENT * grad


def test_one_point_statistics_match_the_table(turb, table):
    for y_plus in (100.0, 150.0, 200.0):
        rng = np.random.default_rng(int(y_plus))
        n = STATS_POINTS
        p = np.column_stack([rng.uniform(-1e6, 1e6, n), y_plus + rng.uniform(-0.5, 0.5, n),
                             rng.uniform(-1e6, 1e6, n)])
        u = turb.fluctuation_plus(p)
        rms = np.sqrt((u**2).mean(axis=0))
        want = np.array([np.interp(y_plus, table.y_plus, w)
                         for w in (table.u_rms_plus, table.v_rms_plus, table.w_rms_plus)])
        assert np.abs(rms / want - 1).max() < RMS_REL_TOL, y_plus
        uv = np.interp(y_plus, table.y_plus, table.uv_plus)
        assert (u[:, 0] * u[:, 1]).mean() == pytest.approx(uv, abs=UV_ABS_TOL)
        assert np.abs((u[:, 0] * u[:, 2]).mean()) < UV_ABS_TOL and np.abs((u[:, 1] * u[:, 2]).mean()) < UV_ABS_TOL


def _l11_from_spectrum(k_e, eta):
    """Longitudinal integral scale pi / (2 u'^2) int E/k, u'^2 = (2/3) int E, of the von Karman-Pao spectrum."""
    k = np.geomspace(1e-5 * k_e, 1e5 * k_e, 200001)
    x = k / k_e
    e = x**4 / (1 + x * x) ** (17 / 6) * np.exp(-2.25 * (k * eta) ** (4 / 3))
    return 0.75 * math.pi * np.trapezoid(e / k, k) / np.trapezoid(e, k)


def test_streamwise_integral_length_matches_the_spectrum(turb, table):
    l11 = _l11_from_spectrum(turb.k_e, turb.eta_plus)
    assert l11 == pytest.approx(turb.integral_length_plus, rel=1e-6)
    # the Piola map x = Abar z: the streamwise line maps to m = Abar^-1 e_x; isotropic base
    # correlations f (longitudinal, integral L11) and g (transverse, integral L11/2)
    a = turb.A_c
    q = math.sqrt(np.trace(a @ a) / 3)
    m = np.linalg.solve(a / q, [1.0, 0, 0])
    mhat = m / np.linalg.norm(m)
    want = l11 / np.linalg.norm(m) * (0.5 * (a[0] @ a[0]) + 0.5 * (a[0] @ mhat) ** 2) / (a[0] @ a[0])
    assert turb.streamwise_integral_length() == pytest.approx(want, rel=1e-9)
    measured = []
    for seed in range(3):  # three realisations of the mode set, 32 lines each
        t = SyntheticTurbulence(table, center_y_plus=150.0, modes=500, seed=seed)
        rng = np.random.default_rng(seed)
        dx, n, lines = want / 8, 512, 32
        x = np.arange(n) * dx
        starts = np.column_stack([rng.uniform(-1e6, 1e6, lines), 150 + rng.uniform(-1, 1, lines),
                                  rng.uniform(-1e6, 1e6, lines)])
        pts = (starts[:, None, :] + np.stack([x, 0 * x, 0 * x], axis=1)[None]).reshape(-1, 3)
        u = t.fluctuation_plus(pts)[:, 0].reshape(lines, n)
        u = u - u.mean()
        f = np.fft.rfft(u, 2 * n, axis=1)
        corr = np.fft.irfft(f * f.conj(), axis=1)[:, :n].sum(axis=0) / (np.arange(n, 0, -1) * lines)
        measured.append(np.trapezoid(corr[: int(6 * want / dx)] / corr[0], dx=dx))
    assert np.mean(measured) == pytest.approx(want, rel=INTEGRAL_LENGTH_REL_TOL)


def test_channel_flow_in_wall_units():
    ch = Channel(friction_velocity_mm_s=400.0, viscosity_mm2_s=15.0, center_y_plus=150.0, center_mm=(1, 2, 3),
                 streamwise=(0, 1, 0), wall_normal=(0, 0, 1), modes=200, seed=3)
    assert FLOW_KINDS["channel"] is Channel
    assert ch.viscous_length_mm == pytest.approx(15.0 / 400.0)
    assert ch.half_height_mm == pytest.approx(ch.re_tau * 15.0 / 400.0)
    lnu = 15.0 / 400.0
    p = np.array([[1.0, 2.0, 3.0], [1.0, 2.0, 3.0 + 50 * lnu], [1.0 + 10 * lnu, 2.0 - 20 * lnu, 3.0 - 40 * lnu]])
    assert np.allclose(ch.wall_distance_plus(p), [150.0, 200.0, 110.0])
    assert np.allclose(ch.to_plus(p)[2], [-20.0, 110.0, 10.0])  # spanwise = streamwise x wall_normal = +x
    u = ch(p)
    # world components: streamwise is +y; mean U+ plus fluctuation, scaled by u_tau
    up = ch.turbulence.fluctuation_plus(ch.to_plus(p))
    want_stream = 400.0 * (ch.profile_table.mean_plus(ch.wall_distance_plus(p)) + up[:, 0])
    assert np.allclose(u[:, 1], want_stream) and np.allclose(u[:, 2], 400.0 * up[:, 1])
    assert np.allclose(u[:, 0], 400.0 * up[:, 2])
    rebuilt = flow_from_dict(ch.to_dict())
    assert np.array_equal(rebuilt(p), u)
    # divergence in mm by central differences (h = 1e-4 mm = 2.7e-3 wall units)
    q = p + np.array([0, 0, 1.0])
    div = _divergence(ch, q, 1e-4)
    grad = np.abs((ch(q + [1e-4, 0, 0]) - ch(q - [1e-4, 0, 0])) / 2e-4).mean()
    assert np.abs(div).max() < 1e-4 * grad
    with pytest.raises(ConfigError, match="y\\+"):
        ch(np.array([[1.0, 2.0, 3.0 - 140 * lnu]]))  # y+ = 10: below the generator's range
    with pytest.raises(ConfigError, match="perpendicular"):
        Channel(streamwise=(1, 0, 0), wall_normal=(1, 1, 0))


def test_second_frame_by_frozen_field_advection_is_converged():
    from mitpiv.physics.advection import advect

    ch = Channel(friction_velocity_mm_s=500.0, viscosity_mm2_s=15.1, center_y_plus=150.0, modes=200, seed=1)
    lnu = ch.viscous_length_mm
    rng = np.random.default_rng(2)
    p0 = rng.uniform(-40, 40, (200, 3)) * lnu
    dt = 0.29 * 15.1 / 500.0**2  # dt+ = 0.29 viscous times: ~5 wall units streamwise
    p8 = advect(p0, ch, dt_s=dt, substeps=8)
    p1 = advect(p0, ch, dt_s=dt, substeps=1)
    assert np.abs(p8 - p1).max() / lnu < ADVECT_ATOL_PLUS
    # the displacement is the local velocity times dt to first order (5 wall units streamwise)
    d = (p8 - p0) / lnu
    assert 4.0 < d[:, 0].mean() < 6.0
    assert np.abs(d - ch(p0) * dt / lnu).max() < 0.2


def test_mode_sum_equals_the_curl_formula_in_float64(turb):
    """The fused mode sum (a Numba kernel) against the module's formula written afresh with
    NumPy: u' = sum_n [G(y) cos(theta_n) T_n + G'(y) sin(theta_n) U_n], theta_n = kappa_n . (x -
    y_c e_y) + psi_n; also the box-averaged form (modes times the two sincs). Tolerance 1e-13 of
    the largest component: the two sum 1000 modes in other orders (float64, ~1e-15 measured)."""
    rng = np.random.default_rng(5)
    lo, hi = turb.y_plus_range
    x = np.column_stack([rng.uniform(-300, 300, 257), rng.uniform(lo + 1, hi - 1, 257), rng.uniform(-300, 300, 257)])
    th = (x - [0.0, turb.center_y_plus, 0.0]) @ turb._kappa.T + turb._phase
    t, u = turb._T.reshape(turb.modes, 27), turb._U.reshape(turb.modes, 27)
    for box in (None, (20.0, 12.0)):
        if box is None:
            tf, uf = t, u
        else:
            f = np.sinc(turb._kappa[:, 0] * box[0] / (2 * math.pi)) * np.sinc(turb._kappa[:, 2] * box[1] / (2 * math.pi))
            tf, uf = t * f[:, None], u * f[:, None]
        ref = (np.einsum("pij,pija->pa", turb._g(x[:, 1]), (np.cos(th) @ tf).reshape(-1, 3, 3, 3))
               + np.einsum("pij,pija->pa", turb._dg(x[:, 1]), (np.sin(th) @ uf).reshape(-1, 3, 3, 3)))
        got = turb.fluctuation_plus(x, box_plus=box, chunk=100)  # several chunks
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-13 * np.abs(ref).max())
