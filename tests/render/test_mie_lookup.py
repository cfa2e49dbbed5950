"""The Mie table's interval lookup (a uniform grid, then a fixed-step binary search).

Reference: ``mi.math.find_interval`` over all nodes, the lookup the grid replaces. The
grid must give the same interval, and so bitwise the same fraction and width, for every
float32 angle: the real default tables (nodes crowded at deep minima), fixed-grid tables,
and angles at and one ulp beside every node and every cell boundary.
"""

import math

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

from mitpiv.physics import mie
from mitpiv.render.plugins.mie_phase import AngleNodes, interval

F32 = np.float32


def find_interval(nodes: mi.Float, n: int, theta):
    """The former lookup: a binary search over all nodes."""
    i = mi.math.find_interval(n, lambda k: dr.gather(mi.Float, nodes, k) <= theta)
    t0 = dr.gather(mi.Float, nodes, i)
    width = dr.gather(mi.Float, nodes, i + 1) - t0
    return i, dr.clip((theta - t0) / width, 0.0, 1.0), width


def mismatches(table: AngleNodes, theta: np.ndarray) -> int:
    """Angles whose (i, t, width) differ from find_interval's (t, width compared bitwise)."""
    th = mi.Float(np.asarray(theta, F32))
    new = interval(table, th)
    ref = find_interval(table.nodes, table.n, th)
    dr.eval(new, ref)
    i1, i0 = np.array(new[0]), np.array(ref[0])
    bad = i1 != i0
    for a, b in zip(new[1:], ref[1:], strict=True):
        bad |= np.array(a).view(np.uint32) != np.array(b).view(np.uint32)
    return int(np.count_nonzero(bad))


def probe_angles(table: AngleNodes, nodes: np.ndarray) -> np.ndarray:
    """Random angles, every node and its float32 neighbours, every cell boundary +-2 ulp,
    0, pi, the ends +-1 ulp and angles outside the table."""
    nodes = np.asarray(nodes, F32)
    rng = np.random.default_rng(1)
    lo, hi = nodes[0], nodes[-1]
    edges = (np.float64(table.lo) + np.arange(table.cells + 1) / np.float64(table.scale)).astype(F32)
    near, up, down = [edges], edges, edges
    for _ in range(2):
        up, down = np.nextafter(up, F32(np.inf)), np.nextafter(down, F32(-np.inf))
        near += [up, down]
    parts = [
        rng.uniform(lo, hi, 200_000).astype(F32),
        nodes, np.nextafter(nodes, F32(np.inf)), np.nextafter(nodes, F32(-np.inf)),
        *near,
        np.array([0.0, math.pi, -0.0, -1e-30, -1.0, 3.2, 10.0, np.nextafter(lo, F32(-1)), np.nextafter(hi, F32(9)),
                  -np.inf, np.inf], F32),
    ]
    return np.concatenate(parts).astype(F32)


def default_theta(d_um: float, **kw) -> np.ndarray:
    """Ascending angles of a DEHS / oil droplet's table (as tracer_particles and mie upload them)."""
    return mie.phase_table(d_um, 1.45, **kw).theta[::-1].copy()


@pytest.mark.parametrize("d_um", [1.0, 5.0, 20.0])
@pytest.mark.parametrize("angles", [None, 1024])
def test_grid_lookup_equals_find_interval(d_um, angles):
    kw = {} if angles is None else {"angles": angles}
    theta = default_theta(d_um, **kw)
    table = AngleNodes(theta)
    assert table.n == theta.size and table.cells >= AngleNodes.CELLS_PER_NODE * table.n
    assert table.steps <= 4  # the point of the grid: a few steps instead of ~log2(n) (10-14)
    assert mismatches(table, probe_angles(table, theta.astype(F32))) == 0


def test_grid_of_the_plugins():
    """Both call sites use the grid built with the table they upload."""
    from mitpiv.render.scene import load_dict

    phase = load_dict({"type": "mie", "diameter_um": 5.0, "index": 1.45})
    nodes = np.array(phase._nodes.nodes)
    assert np.array_equal(nodes, np.array(phase._theta))
    assert mismatches(phase._nodes, probe_angles(phase._nodes, nodes)) == 0
    x = np.linspace(0.0, math.pi, 4001)
    pdf = np.array(phase.pdf_theta(mi.Float(x.astype(F32))))
    assert np.all(np.isfinite(pdf)) and np.all(pdf >= 0)


@pytest.mark.parametrize("cells", [None, 1, 2, 64, 1 << 16])
def test_any_grid_size_and_odd_nodes(cells):
    """Coarse and fine grids, repeated float32 nodes, a short table: still find_interval's result."""
    rng = np.random.default_rng(0 if cells is None else cells)  # fixed: the same nodes on every run
    nodes = np.sort(np.concatenate([rng.uniform(0, 1, 300) ** 3, [0.0, 1.0, 0.25, 0.25, 0.25]])).astype(F32)
    for nd in (nodes, nodes[:2], nodes[:3]):
        table = AngleNodes(nd, cells=cells)
        assert mismatches(table, probe_angles(table, nd)) == 0


def test_a_too_narrow_search_is_caught():
    """The check detects a grid whose search is one step short (so the tests above can fail)."""
    theta = default_theta(5.0)
    table = AngleNodes(theta)
    probes = probe_angles(table, theta.astype(F32))
    table.steps -= 1
    assert mismatches(table, probes) > 0


def test_nan_gives_the_first_interval():
    table = AngleNodes(default_theta(1.0))
    i, _, _ = interval(table, mi.Float([math.nan, 1.0]))
    i_ref, _, _ = find_interval(table.nodes, table.n, mi.Float([math.nan, 1.0]))
    assert np.array_equal(np.array(i), np.array(i_ref)) and int(np.array(i)[0]) == 0
