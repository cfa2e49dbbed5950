"""Analytic flows: properties each must have (independent checks by finite differences)."""

import numpy as np
import pytest

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.physics import flows as F


def divergence(flow, p, h=1e-4, t=0.0):
    div = np.zeros(len(p))
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        div += (flow(p + e, t)[:, k] - flow(p - e, t)[:, k]) / (2 * h)
    return div


def curl(flow, p, h=1e-5):
    J = np.zeros((len(p), 3, 3))  # J[:, i, k] = du_i / dx_k
    for k in range(3):
        e = np.zeros(3)
        e[k] = h
        J[:, :, k] = (flow(p + e) - flow(p - e)) / (2 * h)
    return np.stack([J[:, 2, 1] - J[:, 1, 2], J[:, 0, 2] - J[:, 2, 0], J[:, 1, 0] - J[:, 0, 1]], axis=1)


RNG = np.random.default_rng(3)
PTS = RNG.uniform(-12, 12, (400, 3))

# Tolerances and their provenance; references are the flows' analytic properties. Closed
# forms evaluated in float64 (centreline law, self-similarity, exact linear fields, dict
# round trips) are held to rounding (1e-9 .. 1e-12) inline.
# Divergence by central differences (h = 1e-4 mm): truncation O(h^2) and rounding eps |u| / h;
# relative to |u| per mm the error is < 1e-6, so 1e-5 of the largest speed (at least 1 mm/s).
DIVERGENCE_TOL_OF_SPEED = 1e-5
HILL_CONTINUITY_ATOL = 1e-6  # inside and outside formulas 1e-10 of the radius either side of the sphere
# Outside Hill's vortex the flow is potential flow round a sphere, a dipole U (a/R)^3 on the
# axis, exactly (measured 3e-11 at R = 500 mm).
HILL_FAR_FIELD_REL_TOL = 1e-6
# Round jet: trapezoid integrals on 2e5 geometric radii to 400 mm. Momentum flux K (measured
# 2e-9 relative); volume flux 8 pi nu z, whose r^-3 tail beyond 400 mm grows with z
# (measured 1.1e-5 at z = 60 mm).
JET_MOMENTUM_REL_TOL = 1e-6
JET_VOLUME_FLUX_REL_TOL = 5e-5
# Lamb-Oseen circulation G (1 - exp(-r^2/rc^2)) by the 2000-point periodic trapezoid rule,
# spectrally accurate for a smooth periodic integrand (measured 2e-16).
CIRCULATION_REL_TOL = 1e-9
# Vortex ring: the regularised core's circulation deficit on a square loop of half-width L
# falls as ~G a^2 / L^2; bound with coefficient 1.5. A loop that does not link the ring: 0.
RING_DEFICIT_COEFF = 1.5
UNLINKED_CIRCULATION_OF_G = 1e-3
CURL_FD_ATOL = 1e-8  # ABC Beltrami curl u = u by central differences (h = 1e-5): truncation ~1e-10

SOLENOIDAL = [
    F.Uniform((1, 2, 3)),
    F.SolidBody(2.0, center=(1, 0, 0), axis=(0, 1, 1)),
    F.LambOseen(500.0, 2.0, axis=(1, 0, 0)),
    F.Burgers(500.0, 0.5, 1.0),
    F.VortexRing(6.0, 800.0, 1.5, axis=(0, 1, 0), segments=512),
    F.ABC(1.0, 0.7, 0.4, length_mm=3.0, speed_mm_s=10.0),
    F.RoundJet(2.0e5, 1.0, center=(1, 2, -30), axis=(0.1, 0, 1)),
]


@pytest.mark.parametrize("flow", SOLENOIDAL, ids=lambda f: f.kind)
def test_divergence_free(flow):
    u_scale = np.abs(flow(PTS)).max()
    assert np.abs(divergence(flow, PTS)).max() < DIVERGENCE_TOL_OF_SPEED * max(u_scale, 1.0)


def test_hill_vortex_divergence_free_away_from_boundary_and_continuous_across_it():
    hv = F.HillVortex(radius_mm=5.0, speed_mm_s=100.0)
    r = np.linalg.norm(PTS, axis=1)
    away = PTS[np.abs(r - 5.0) > 1e-2]
    assert np.abs(divergence(hv, away)).max() < DIVERGENCE_TOL_OF_SPEED * 150  # speed scale 1.5 U (vortex frame)
    d = RNG.normal(size=(200, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    inside = hv(d * 5.0 * (1 - 1e-10))
    outside = hv(d * 5.0 * (1 + 1e-10))
    np.testing.assert_allclose(inside, outside, atol=HILL_CONTINUITY_ATOL)
    # the vortex moves at U in the lab frame: fluid at rest far away, 1.5 U + U at the centre
    # far field of a translating sphere is a dipole: |u| ~ U (a/R)^3
    assert np.abs(hv(np.array([[0, 0, 500.0]]))).max() == pytest.approx(100 * (5 / 500) ** 3, rel=HILL_FAR_FIELD_REL_TOL)
    np.testing.assert_allclose(hv(np.array([[0, 0, 0.0]])), [[0, 0, 250.0]], atol=1e-9)


def test_round_jet_momentum_flux_entrainment_and_self_similarity():
    k, nu = 3.0e5, 1.5
    jet = F.RoundJet(k, nu, center=(0, 0, -10), axis=(0, 0, 1))
    # geometric radii resolve the 0.06 mm wide jet at z = 5 mm as well as the far tail
    # (u_z ~ r^-4: beyond 400 mm less than 1e-9 of K)
    r = np.concatenate([[0.0], np.geomspace(1e-7, 400.0, 200_000)])
    for z in (5.0, 20.0, 60.0):
        p = np.stack([r, np.zeros_like(r), np.full_like(r, z - 10)], axis=1)
        u = jet(p)
        # momentum flux 2 pi int u_z^2 r dr = K at every z
        assert np.trapezoid(2 * np.pi * u[:, 2] ** 2 * r, r) == pytest.approx(k, rel=JET_MOMENTUM_REL_TOL)
        # volume flux 8 pi nu z grows linearly by entrainment
        q = np.trapezoid(2 * np.pi * u[:, 2] * r, r)
        assert q == pytest.approx(8 * np.pi * nu * z, rel=JET_VOLUME_FLUX_REL_TOL)
        # centreline 3K / (8 pi nu z); the radial velocity vanishes on the axis
        assert u[0, 2] == pytest.approx(3 * k / (8 * np.pi * nu * z), rel=1e-12)
        assert u[0, 0] == 0.0
        # far from the axis the entrainment flow points inwards
        assert u[-1, 0] < 0
    # self-similar: u_z(r, z) z is a function of r / z only
    a = jet(np.array([[2.0, 0, 10.0 - 10]]))[0, 2] * 10.0
    b = jet(np.array([[6.0, 0, 30.0 - 10]]))[0, 2] * 30.0
    assert a == pytest.approx(b, rel=1e-12)
    # from_centerline inverts the centreline law
    j2 = F.RoundJet.from_centerline(250.0, 40.0, viscosity_mm2_s=1.0)
    assert j2(np.array([[0, 0, 40.0]]))[0, 2] == pytest.approx(250.0, rel=1e-12)
    with pytest.raises(ConfigError, match="upstream of the virtual origin"):
        jet(np.array([[0, 0, -12.0]]))
    with pytest.raises(ConfigError, match="viscosity_mm2_s"):
        F.RoundJet(1e5, 0.0)


def test_lamb_oseen_circulation_and_core():
    g, rc = 700.0, 1.5
    lo = F.LambOseen(g, rc)
    th = np.linspace(0, 2 * np.pi, 2001)[:-1]
    for r in (0.5, 1.5, 30.0):
        p = np.stack([r * np.cos(th), r * np.sin(th), np.zeros_like(th)], 1)
        tangent = np.stack([-np.sin(th), np.cos(th), np.zeros_like(th)], 1)
        circ = np.sum(np.einsum("ij,ij->i", lo(p), tangent)) * r * (2 * np.pi / th.size)
        assert circ == pytest.approx(g * (1 - np.exp(-(r**2) / rc**2)), rel=CIRCULATION_REL_TOL)
    assert np.all(np.isfinite(lo(np.zeros((1, 3)))))


def loop_circulation(flow, center, half, n=4000):
    """Circulation around a square loop in the x-z plane (axis y)."""
    s = np.linspace(-half, half, n + 1)
    mid = 0.5 * (s[1:] + s[:-1])
    ds = s[1] - s[0]
    cx, cz = center
    total = 0.0
    for pts, t in (
        (np.stack([cx + mid, 0 * mid, cz - half + 0 * mid], 1), (1, 0, 0)),
        (np.stack([cx + half + 0 * mid, 0 * mid, cz + mid], 1), (0, 0, 1)),
        (np.stack([cx - mid, 0 * mid, cz + half + 0 * mid], 1), (-1, 0, 0)),
        (np.stack([cx - half + 0 * mid, 0 * mid, cz - mid], 1), (0, 0, -1)),
    ):
        total += np.sum(flow(pts) @ np.array(t, float)) * ds
    return total


def test_vortex_ring_circulation():
    g, big_r, a = 1000.0, 6.0, 0.5
    ring = F.VortexRing(big_r, g, a, axis=(0, 0, 1), segments=1024)
    # loop in the meridional x-z plane around the core at x = R (links the ring once)
    # The regularised core's vorticity has algebraic tails: the deficit falls as ~ G a^2 / L^2.
    deficit = {h: g - abs(loop_circulation(ring, (big_r, 0.0), half=h)) for h in (2.0, 4.0, 5.0)}
    assert 0 < deficit[5.0] < RING_DEFICIT_COEFF * g * a**2 / 5.0**2
    assert 2.5 < deficit[2.0] / deficit[4.0] < 5.0  # ~4 for a 1/L^2 law
    # a loop that does not link the ring has zero circulation
    assert abs(loop_circulation(ring, (big_r + 8.0, 0.0), half=2.0)) < UNLINKED_CIRCULATION_OF_G * g
    # Kelvin's self-induced speed is the default translation
    assert ring.speed_mm_s == pytest.approx(g / (4 * np.pi * big_r) * (np.log(8 * big_r / a) - 0.25))


def test_vortex_ring_compiled_sum_equals_numpy_sum():
    """Large calls take the compiled Biot-Savart kernel, small ones NumPy: the same terms in
    the same order, so equal to rounding (1e-13 of the largest speed)."""
    ring = F.VortexRing(8.0, 2000.0, 2.0, center=(0.0, -4.0, 0.0), axis=(0, 1, 0))
    pts = np.random.default_rng(5).uniform(-20, 20, (3000, 3))
    assert pts.shape[0] * ring.segments >= 50_000  # the kernel path
    big = ring(pts, 0.002)
    small = np.concatenate([ring(pts[i : i + 50], 0.002) for i in range(0, len(pts), 50)])
    assert 50 * ring.segments < 50_000  # the NumPy path
    np.testing.assert_allclose(big, small, rtol=0, atol=1e-13 * np.abs(small).max())


def test_abc_is_beltrami():
    abc = F.ABC(1.0, 0.8, 0.6, length_mm=1.0, speed_mm_s=1.0)
    np.testing.assert_allclose(curl(abc, PTS[:50] / 4), abc(PTS[:50] / 4), atol=CURL_FD_ATOL)


def test_burgers_components():
    b = F.Burgers(circulation_mm2_s=0.0, strain_rate_1_s=2.0, viscosity_mm2_s=1.0)
    np.testing.assert_allclose(b(np.array([[3.0, 0, 2.0]])), [[-3.0, 0.0, 4.0]], atol=1e-12)


def test_grid_flow_trilinear_is_exact_for_linear_fields(tmp_path):
    x, y, z = np.linspace(0, 4, 5), np.linspace(-2, 2, 6), np.linspace(0, 1, 3)
    X, Y, Z = np.meshgrid(x, y, z, indexing="ij")
    np.savez(tmp_path / "f.npz", x=x, y=y, z=z, u=2 * X + Y, v=-Z, w=X * 0 + 3)
    g = F.GridFlow(tmp_path / "f.npz")
    p = RNG.uniform([0, -2, 0], [4, 2, 1], (100, 3))
    np.testing.assert_allclose(g(p), np.stack([2 * p[:, 0] + p[:, 1], -p[:, 2], 3 + 0 * p[:, 0]], 1), atol=1e-12)
    with pytest.raises(ConfigError, match="outside the grid"):
        g(np.array([[10.0, 0, 0]]))
    np.testing.assert_allclose(F.GridFlow(tmp_path / "f.npz", outside="zero")(np.array([[10.0, 0, 0]])), 0)
    np.savez(tmp_path / "bad.npz", x=x, y=y, z=z, u=X)
    with pytest.raises(FileFormatError, match="x, y, z, u, v, w"):
        F.GridFlow(tmp_path / "bad.npz")
    with pytest.raises(ConfigError, match="does not exist"):
        F.GridFlow(tmp_path / "missing.npz")


@pytest.mark.parametrize("flow", SOLENOIDAL + [F.HillVortex()], ids=lambda f: f.kind)
def test_flow_round_trips_through_dict(flow):
    rebuilt = F.flow_from_dict(flow.to_dict())
    np.testing.assert_allclose(rebuilt(PTS, 0.01), flow(PTS, 0.01), rtol=1e-12)


def test_bad_flow_parameters():
    with pytest.raises(ConfigError, match="core_radius_mm"):
        F.VortexRing(5.0, 100.0, 6.0)
    with pytest.raises(ConfigError, match="axis"):
        F.LambOseen(axis=(0, 0, 0))
    with pytest.raises(ConfigError, match=r"shape \(N, 3\)"):
        F.Uniform()(np.zeros(3))
