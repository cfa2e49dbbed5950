"""decode(spatial_oversample=k): a k-times finer spatial grid over the same lenslet lattice
(LFIT's supersampling, seed paper 003): on the grid points it shares with the plain
decoding, the light field and the refocused images are the same; between them, the lattice
interpolation of the lenslet samples."""

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.lightfield import decode, refocus
from mitpiv.physics.plenoptic import paper_003_camera

SAME_ATOL = 1e-5  # float32 sums of the same terms in the same order


def test_oversampled_grid_shares_the_plain_grid():
    cam = paper_003_camera("drop_impact", crop_px=(280, 224))
    rng = np.random.default_rng(5)
    raw = (0.5 + 0.5 * rng.random((224, 280))).astype(np.float32)
    a = decode(raw, optics=cam)
    b = decode(raw, optics=cam, spatial_oversample=2)
    assert b.info["spatial_oversample"] == 2
    ds_a, ds_b = np.diff(a.s_px)[0], np.diff(b.s_px)[0]
    assert ds_b == pytest.approx(ds_a / 2) and np.diff(b.t_px)[0] == pytest.approx(np.diff(a.t_px)[0] / 2)
    assert len(b.s_px) >= 2 * len(a.s_px) - 1 and len(b.t_px) >= 2 * len(a.t_px) - 1
    # shared grid points
    si = np.array([np.argmin(np.abs(b.s_px - s)) for s in a.s_px])
    ti = np.array([np.argmin(np.abs(b.t_px - t)) for t in a.t_px])
    assert np.allclose(b.s_px[si], a.s_px) and np.allclose(b.t_px[ti], a.t_px)
    np.testing.assert_allclose(b.data[:, :, ti][:, :, :, si], a.data, atol=SAME_ATOL)
    np.testing.assert_allclose(refocus(b, 1.0)[np.ix_(ti, si)], refocus(a, 1.0), atol=SAME_ATOL)
    with pytest.raises(ConfigError, match="spatial_oversample"):
        decode(raw, optics=cam, spatial_oversample=0)
