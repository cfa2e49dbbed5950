"""The fused homography refocusing kernel (reconstruct._kernels.refocus_homography) against
the NumPy formulation it replaces: per camera, scipy's map_coordinates (order 1, constant 0)
at the homography's image, summed and divided by the cameras that hold the point."""

import numpy as np
from scipy import ndimage

from mitpiv.reconstruct._kernels import kernels


def _reference(imgs, hom, xy):
    n = len(xy)
    acc, cnt = np.zeros(n), np.zeros(n)
    xyh = np.column_stack([xy, np.ones(n)])
    for im, h3 in zip(imgs, hom, strict=True):
        q = xyh @ h3.T
        uv = q[:, :2] / q[:, 2:3]
        h, w = im.shape
        acc += ndimage.map_coordinates(im, [uv[:, 1] - 0.5, uv[:, 0] - 0.5], order=1, mode="constant", cval=0.0)
        cnt += (uv[:, 0] >= 0) & (uv[:, 0] <= w) & (uv[:, 1] >= 0) & (uv[:, 1] <= h)
    return np.where(cnt > 0, acc / np.maximum(cnt, 1), 0.0)


def test_fused_refocusing_equals_map_coordinates_per_camera():
    rng = np.random.default_rng(11)
    imgs = [rng.random((h, w)).astype(np.float32) for h, w in ((40, 50), (37, 61), (45, 45))]
    # homographies near a scaled identity: points land inside, on the edges and outside
    hom = np.stack([np.array([[1.1 + 0.05 * c, 0.02, 3.0 - c], [-0.03, 0.95, 1.0 + c], [1e-4, -2e-4, 1.0]])
                    for c in range(3)])
    xy = np.concatenate([rng.uniform(-5, 60, (4000, 2)),
                         np.array([[0.5, 0.5], [-0.2, 10.0], [49.5, 39.5], [50.0, 40.0], [60.0, 60.0]])])
    flat = np.concatenate([im.ravel() for im in imgs])
    offs = np.array([0, imgs[0].size, imgs[0].size + imgs[1].size], np.int64)
    hs = np.array([im.shape[0] for im in imgs], np.int64)
    ws = np.array([im.shape[1] for im in imgs], np.int64)
    out = np.empty(len(xy))
    kernels()["refocus_homography"](flat, offs, hs, ws, hom, xy[:, 0].copy(), xy[:, 1].copy(), out)
    ref = _reference(imgs, hom, xy)
    # scipy rounds each sample to float32 before the sum; the kernel sums in float64
    np.testing.assert_allclose(out, ref, rtol=0, atol=2e-7)
    assert (ref == 0).any() and (ref > 0).sum() > 2000  # the set reaches outside and inside every image
