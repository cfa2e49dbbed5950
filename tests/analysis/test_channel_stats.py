"""Wall-unit statistics and the window-averaged truth of the channel flow, against
references written here: a tensor Gauss-Legendre quadrature of the flow itself, and
per-slab means and r.m.s. computed directly."""

import numpy as np
import pytest

from mitpiv.analysis.channel import field_wall_statistics, statistics_error_percent, wall_statistics
from mitpiv.analysis.piv3d import VectorField
from mitpiv.errors import ConfigError
from mitpiv.physics.flows import Channel

# Window average: sinc factors (exact) and 24 Gauss-Legendre nodes in y against a 24^3-node
# tensor quadrature; the two quadratures agree to 3e-9 u_tau for a 20+ window (measured
# 5e-9 u_tau between them), so 1e-7 u_tau.
WINDOW_AVERAGE_ATOL_OF_UTAU = 1e-7


@pytest.fixture(scope="module")
def channel():
    return Channel(friction_velocity_mm_s=400.0, viscosity_mm2_s=15.0, center_y_plus=150.0, modes=300, seed=3)


def _gauss_box_average(flow, p, window, n=24):
    t, w = np.polynomial.legendre.leggauss(n)
    g = np.stack(np.meshgrid(t, t, t, indexing="ij"), -1).reshape(-1, 3)
    ww = (w[:, None, None] * w[None, :, None] * w[None, None, :]).ravel() / 8
    return np.array([(ww[:, None] * flow(q + 0.5 * g * window)).sum(axis=0) for q in p])


def test_window_average_is_the_box_filter_of_the_flow(channel):
    lnu = channel.viscous_length_mm
    p = np.array([[3, 5, -20], [50, -30, 40]], float) * lnu
    win = np.array([20.0, 16.0, 24.0]) * lnu
    want = _gauss_box_average(channel, p, win)
    got = channel.window_average(p, win)
    assert np.abs(got - want).max() < WINDOW_AVERAGE_ATOL_OF_UTAU * 400.0
    # a vanishing window is the point value
    assert np.allclose(channel.window_average(p, 0.0), channel(p), rtol=0, atol=1e-9 * 400.0)


def test_window_average_needs_world_aligned_axes():
    ch = Channel(streamwise=(1, 1, 0), wall_normal=(0, 0, 1), modes=50)
    with pytest.raises(ConfigError, match="world axes"):
        ch.window_average(np.zeros((1, 3)), 1.0)


def test_wall_statistics_per_slab_in_a_rotated_frame():
    # streamwise +y, wall-normal -x: spanwise = (0,1,0) x (-1,0,0) = (0,0,1)
    ch = Channel(friction_velocity_mm_s=200.0, viscosity_mm2_s=10.0, center_y_plus=150.0, center_mm=(0, 0, 0),
                 streamwise=(0, 1, 0), wall_normal=(-1, 0, 0), modes=50)
    lnu = 0.05
    rng = np.random.default_rng(0)
    layers_plus = np.array([120.0, 150.0, 180.0])
    pts, vel, expect = [], [], []
    for yp in layers_plus:
        n = 500
        p = np.column_stack([np.full(n, -(yp - 150.0) * lnu), rng.uniform(-5, 5, n), rng.uniform(-5, 5, n)])
        us, un, uz = rng.normal(15 + yp / 100, 2.0, n), rng.normal(0, 1.0, n), rng.normal(0, 1.3, n)
        un = un - 0.4 * (us - us.mean())
        v = 200.0 * np.column_stack([-un, us, uz])  # world (x, y, z) = (-normal, stream, span)
        pts.append(p)
        vel.append(v)
        fs, fn = us - us.mean(), un - un.mean()
        expect.append([us.mean(), fs.std(), fn.std(), (uz - uz.mean()).std(), (fs * fn).mean()])
    st = wall_statistics(np.concatenate(pts), np.concatenate(vel), ch)
    assert np.allclose(st["y_plus"], layers_plus) and list(st["n"]) == [500] * 3
    got = np.column_stack([st[k] for k in ("U", "u_rms", "v_rms", "w_rms", "uv")])
    assert np.allclose(got, np.array(expect), rtol=1e-12, atol=1e-12)
    # explicit slab edges: two slabs, the middle layer alone in the second
    st2 = wall_statistics(np.concatenate(pts), np.concatenate(vel), ch, edges_y_plus=[100, 140, 160])
    assert list(st2["n"]) == [500, 500] and np.allclose(st2["U"], got[:2, 0])


def test_field_wall_statistics_and_percent_errors(channel):
    lnu = channel.viscous_length_mm
    xs = np.arange(-40, 41, 10.0) * lnu
    zs = np.array([110.0, 150.0, 190.0]) * lnu - 150.0 * lnu
    shape = (zs.size, xs.size, xs.size)
    fld = VectorField(xs, xs, zs, *(np.zeros(shape),) * 3, np.ones(shape), np.ones(shape), np.ones(shape, bool),
                      np.zeros(shape, bool), np.zeros(shape, bool), (lnu,) * 3, (20, 20, 20), dt_s=1e-3)
    pts = fld.points_mm().reshape(-1, 3)
    u = channel(pts).reshape(shape + (3,))
    fld.u, fld.v, fld.w = u[..., 0], u[..., 1], u[..., 2]
    fld.valid[0, 0, 0] = False
    st = field_wall_statistics(fld, channel)
    ref = wall_statistics(pts[1:], channel(pts[1:]), channel)
    for k in ("y_plus", "U", "u_rms", "v_rms", "w_rms", "uv"):
        assert np.allclose(st[k], ref[k], rtol=1e-12)
    scaled = {**ref, "u_rms": ref["u_rms"] * 1.05, "U": ref["U"] * 0.99}
    err = statistics_error_percent(scaled, ref, band_y_plus=(100, 200))
    assert err["u_rms"] == pytest.approx(5.0) and err["U"] == pytest.approx(1.0) and err["w_rms"] == 0.0
    with pytest.raises(ConfigError, match="no slab"):
        statistics_error_percent(ref, ref, band_y_plus=(300, 400))
