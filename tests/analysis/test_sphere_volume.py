"""The volume-fraction truth of spherical particles (analysis.quality.sphere_volume)
against closed forms: the spherical cap, the whole sphere, the point limit."""

import math

import numpy as np
import pytest

from mitpiv.analysis.quality import occupancy_volume, sphere_volume
from mitpiv.errors import ConfigError
from mitpiv.grid import VoxelGrid

GRID = VoxelGrid((0.0, 0.0, 0.0), 0.05, (6, 6, 6))  # voxel centres at 0.025 + 0.05 k


def _cap_fraction(h: float, r: float) -> float:
    """Volume fraction of a sphere of radius r beyond a plane at distance h from its centre."""
    t = r - h
    return math.pi * t * t * (3 * r - t) / 3 / (4 / 3 * math.pi * r**3)


@pytest.mark.parametrize("h_um", [0.0, 3.0, 7.0, 12.0])
def test_a_voxel_face_splits_the_sphere_as_the_cap_formula(h_um):
    d = 0.04  # 40 um, centred in y and z of its voxel (faces 25 um away): only the face x = 0.1 mm cuts it
    c = np.array([[0.1 - h_um * 1e-3, 0.125, 0.125]])
    v = sphere_volume(c, GRID, d)
    beyond = v.sum(axis=(0, 1))[2]  # x index 2 holds x in [0.1, 0.15)
    exact = _cap_fraction(h_um * 1e-3, d / 2)
    # the tabulated octant fraction: surface cells of a 192-cell lattice (3e-4) and trilinear
    # interpolation between nodes 1/32 of a radius apart (F is smooth: ~1e-4); bound 1e-3
    assert abs(beyond - exact) <= 1e-3
    assert v.sum() == pytest.approx(1.0, abs=1e-12)


def test_a_small_sphere_is_its_occupancy_voxel():
    rng = np.random.default_rng(3)
    p = rng.uniform(0.06, 0.24, size=(50, 3))
    # 2 um spheres far from every face land whole in the voxel holding their centre
    q = (p - 0.025) / 0.05
    p = p[np.all(np.abs(q - np.round(q)) < 0.4, axis=1)]
    np.testing.assert_allclose(sphere_volume(p, GRID, 0.002), occupancy_volume(p, GRID), atol=1e-12)


def test_parts_outside_the_grid_are_dropped_and_intensities_scale():
    v = sphere_volume(np.array([[0.0, 0.125, 0.125]]), GRID, 0.04, intensities=[2.0])
    assert v.sum() == pytest.approx(1.0, abs=1e-12)  # half the sphere lies at x < 0, outside


@pytest.mark.parametrize("kw", [{"diameter_mm": 0.0}, {"diameter_mm": float("nan")}, {"diameter_mm": -0.02}])
def test_bad_inputs_name_the_parameter(kw):
    with pytest.raises(ConfigError, match="diameter_mm"):
        sphere_volume(np.zeros((1, 3)), GRID, **kw)


def test_a_sphere_larger_than_a_voxel_on_an_anisotropic_grid_keeps_its_volume():
    g = VoxelGrid((0.0, 0.0, 0.0), (0.05, 0.05, 0.02), (20, 8, 8))
    v = sphere_volume(np.array([[0.2, 0.2, 0.2]]), g, 0.12)
    assert v.sum() == pytest.approx(1.0, abs=1e-9)
    # symmetric about the centre plane z = 0.2 mm (a voxel face): equal halves
    assert v[:10].sum() == pytest.approx(0.5, abs=1e-3)
    assert (v > 0).sum() > 8  # spread over many voxels
