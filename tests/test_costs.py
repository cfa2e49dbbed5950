"""mitpiv.costs: the PIV vector count of anisotropic windows against piv3d's own grid, and
bad windows refused by name."""

import numpy as np
import pytest

from mitpiv import costs
from mitpiv.analysis.piv3d import piv3d
from mitpiv.errors import ConfigError
from mitpiv.grid import VoxelGrid


@pytest.mark.parametrize("window", [(24, 16, 8), (8, 16, 24), 16, np.int64(12)])
def test_piv_vectors_match_piv3d(window):
    """Windows (w_x, w_y, w_z) on a (n_z, n_y, n_x) grid: the count of the last pass is the
    vector grid piv3d builds (an x / z swap would miss it: the grid is 40 x 56 x 72)."""
    grid = VoxelGrid.from_bounds([0, 0, 0], [72, 56, 40], 1.0)  # (n_z, n_y, n_x) = (40, 56, 72)
    rng = np.random.default_rng(0)
    vol = rng.random(grid.shape).astype(np.float32)
    w = tuple(int(v) for v in window) if np.ndim(window) else int(window)
    f = piv3d(vol, np.roll(vol, 1, axis=2), grid, windows=[w], overlap=0.75, validate=False, replace=None)
    assert costs.piv_vectors(grid.shape, window, 0.75) == int(np.prod(f.u.shape))
    assert costs.piv_cost(grid.shape, [window], 0.75).seconds > 0


def test_piv_windows_of_the_wrong_length_are_refused():
    with pytest.raises(ConfigError, match="w_x, w_y, w_z"):
        costs.piv_vectors((10, 10, 10), (4, 4), 0.5)
