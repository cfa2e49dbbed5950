"""Seeding statistics and RK4 advection against exact solutions."""

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.physics.advection import advect
from mitpiv.physics.camera import PinholeCamera, look_at_rotation
from mitpiv.physics.flows import SolidBody, Uniform
from mitpiv.physics.seeding import seed_box

LO, HI = (-10, -10, -2), (10, 10, 2)

# Tolerances and their provenance (seeded draws against their distributions; RK4 against the
# exact rotation).
# Chi-square of 32 cell counts against uniform, 31 degrees of freedom: P(chi2 > 61) = 1.0e-3
# (scipy.stats.chi2.sf; the comment this test carried said 1e-4).
CHI2_CRIT_31_DOF = 61
# Log-normal diameters: the sample median within N_SIGMA standard errors (the median's standard
# error is ~1.25 sigma / sqrt(n) in ln d, times the median 2 um and 1.26 / 1.25 of margin);
# the sample standard deviation of ln d has a relative standard error 1/sqrt(2n) = 3.5e-3 at
# n = 40000, so 2 % is 5.7 of them.
N_SIGMA = 5
LOG_STD_REL_TOL = 0.02
# Particles per pixel: Poisson count (4 sigma: two-sided p 6e-5) plus 1 % for the Monte Carlo
# estimate of the visible fraction.
N_SIGMA_POISSON = 4
VISIBLE_FRACTION_REL_TOL = 0.01
# RK4 error ratio between 4 and 8 substeps: 2^4 = 16 in the asymptotic range; bounds allow
# the pre-asymptotic 1.5 rad steps.
RK4_RATIO_RANGE = (12, 40)
# 64 steps of 0.023 rad: global truncation bound 64 x r (omega h)^5 / 120 = 1.9e-8 mm.
RK4_GLOBAL_BOUND_MM = 2.5e-8


def test_same_seed_same_particles_and_box_bounds():
    a = seed_box(LO, HI, count=500, distribution="lognormal", seed=7)
    b = seed_box(LO, HI, count=500, distribution="lognormal", seed=7)
    np.testing.assert_array_equal(a.positions_mm, b.positions_mm)
    np.testing.assert_array_equal(a.diameters_um, b.diameters_um)
    assert np.all(a.positions_mm >= LO) and np.all(a.positions_mm <= HI)


def test_concentration_and_uniformity():
    p = seed_box(LO, HI, concentration_per_mm3=10.0, seed=1)
    assert len(p) == 16000
    # chi-square of counts in 4 x 4 x 2 cells against uniform (df = 31)
    h, _ = np.histogramdd(p.positions_mm, bins=(4, 4, 2), range=list(zip(LO, HI, strict=True)))
    expect = len(p) / h.size
    assert np.sum((h - expect) ** 2 / expect) < CHI2_CRIT_31_DOF


def test_lognormal_statistics():
    p = seed_box(LO, HI, count=40000, diameter_um=2.0, distribution="lognormal", geometric_std=1.4, seed=2)
    logd = np.log(p.diameters_um)
    se = np.log(1.4) / np.sqrt(len(p))
    assert abs(np.median(p.diameters_um) - 2.0) < 2.0 * N_SIGMA * se * 1.26  # median's SE ~ 1.25 sigma/sqrt(n)
    assert np.std(logd) == pytest.approx(np.log(1.4), rel=LOG_STD_REL_TOL)


def test_min_separation():
    from scipy.spatial import cKDTree

    p = seed_box(LO, HI, count=3000, min_separation_mm=0.5, seed=4)
    d, _ = cKDTree(p.positions_mm).query(p.positions_mm, k=2)
    assert d[:, 1].min() >= 0.5
    with pytest.raises(ConfigError, match="too large"):
        seed_box(LO, HI, count=3000, min_separation_mm=3.0, seed=4)


def test_ppp_target():
    cam = PinholeCamera((256, 256), 50.0, 10.0, rotation=look_at_rotation([0, 0, 600], [0, 0, 0], up=[0, 1, 0]),
                        position_mm=[0, 0, 600])
    p = seed_box((-40, -40, -2), (40, 40, 2), ppp=0.05, camera=cam, seed=5)
    uv = cam.project(p.positions_mm)
    inside = np.all((uv >= 0) & (uv < 256), axis=1).sum()
    expect = 0.05 * 256 * 256
    assert abs(inside - expect) < N_SIGMA_POISSON * np.sqrt(expect) + VISIBLE_FRACTION_REL_TOL * expect


def test_seeding_bad_input():
    with pytest.raises(ConfigError, match="exactly one"):
        seed_box(LO, HI, count=10, concentration_per_mm3=1.0)
    with pytest.raises(ConfigError, match="box_max"):
        seed_box(HI, LO, count=10)
    with pytest.raises(ConfigError, match="needs a 'camera'"):
        seed_box(LO, HI, ppp=0.1)
    with pytest.raises(ConfigError, match="diameter_um"):
        seed_box(LO, HI, count=10, diameter_um=-1)


def test_rk4_solid_body_rotation_converges_at_fourth_order():
    omega, dt = 3.0, 0.5  # 1.5 rad: a hard case for few steps
    p0 = np.array([[5.0, 0.0, 1.0], [0.0, -2.0, 3.0]])
    flow = SolidBody(omega)
    th = omega * dt
    exact = np.stack([p0[:, 0] * np.cos(th) - p0[:, 1] * np.sin(th), p0[:, 0] * np.sin(th) + p0[:, 1] * np.cos(th), p0[:, 2]], 1)
    e4 = np.abs(advect(p0, flow, dt_s=dt, substeps=4) - exact).max()
    e8 = np.abs(advect(p0, flow, dt_s=dt, substeps=8) - exact).max()
    assert RK4_RATIO_RANGE[0] < e4 / e8 < RK4_RATIO_RANGE[1]  # 2^4 = 16 for a fourth-order method
    assert np.abs(advect(p0, flow, dt_s=dt, substeps=64) - exact).max() < RK4_GLOBAL_BOUND_MM


def test_advect_uniform_exact_and_bad_input():
    p = np.zeros((3, 3))
    np.testing.assert_allclose(advect(p, Uniform((1, 2, 3)), dt_s=0.1, substeps=1), np.tile([0.1, 0.2, 0.3], (3, 1)))
    with pytest.raises(ConfigError, match="dt_s"):
        advect(p, Uniform(), dt_s=0)
    with pytest.raises(ConfigError, match="substeps"):
        advect(p, Uniform(), dt_s=1, substeps=0)
