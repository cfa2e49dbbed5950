"""Numba kernels of the algebraic reconstructions: voxel-pixel weights, sparse (CSR)
weight assembly, MART and SMART updates.

Storage: one CSR matrix per camera, rows = pixels (row-major ``v * W + u``), columns =
active voxels, float32 weights. A voxel's weights reach at most ``span`` consecutive image
rows, so image rows ``span`` apart share no voxel: rows of one residue class modulo
``span`` are updated in parallel without races, exactly as a sequential row-action sweep
in that row order would update them.
"""

from __future__ import annotations

import math

from mitpiv._numba import numba

_K = {}

CIRCLE, GAUSSIAN = 0, 1
PIXEL_RADIUS = 1.0 / math.sqrt(math.pi)  # equal-area circle of a unit pixel (0.564 px)


def kernels() -> dict:
    if _K:
        return _K
    nb = numba()

    @nb.njit(inline="always", cache=True)
    def circle_overlap(d, r1, r2):
        """Area of the intersection of two circles of radii r1, r2 whose centres are d apart."""
        if d >= r1 + r2:
            return 0.0
        if d <= abs(r1 - r2):
            r = min(r1, r2)
            return math.pi * r * r
        c1 = min(max((d * d + r1 * r1 - r2 * r2) / (2.0 * d * r1), -1.0), 1.0)
        c2 = min(max((d * d + r2 * r2 - r1 * r1) / (2.0 * d * r2), -1.0), 1.0)
        k = (-d + r1 + r2) * (d + r1 - r2) * (d - r1 + r2) * (d + r1 + r2)
        return r1 * r1 * math.acos(c1) + r2 * r2 * math.acos(c2) - 0.5 * math.sqrt(max(k, 0.0))

    @nb.njit(inline="always", cache=True)
    def weight(model, dx, dy, p0, p1, p2, p3):
        """Weight of a pixel whose centre is (dx, dy) px from the voxel's projected centre.

        circle: p0 = voxel circle radius [px]; weight = overlap / pixel area.
        gaussian: (p0, p1, p2) = inverse covariance (xx, xy, yy), p3 = area * normalisation.
        """
        if model == 0:
            return circle_overlap(math.sqrt(dx * dx + dy * dy), p0, PIXEL_RADIUS)
        q = p0 * dx * dx + 2.0 * p1 * dx * dy + p2 * dy * dy
        return p3 * math.exp(-0.5 * q) if q < 9.0 else 0.0  # truncated at 3 sigma (Mahalanobis)

    @nb.njit(parallel=True, cache=True)
    def survives(u, v, rad, p0, p1, p2, p3, model, img, alive):
        """Zero-pixel pruning: clear ``alive`` for voxels that give weight to a zero pixel."""
        h, w = img.shape
        for a in nb.prange(u.shape[0]):
            if not alive[a]:
                continue
            r = rad[a]
            for row in range(max(int(math.floor(v[a] - r)), 0), min(int(math.floor(v[a] + r)) + 1, h)):
                for col in range(max(int(math.floor(u[a] - r)), 0), min(int(math.floor(u[a] + r)) + 1, w)):
                    if img[row, col] <= 0.0 and weight(model, col + 0.5 - u[a], row + 0.5 - v[a], p0[a], p1[a], p2[a], p3[a]) > 0.0:
                        alive[a] = False

    @nb.njit(inline="always", cache=True)
    def inside_support(model, dx, dy, r, p0, p1, p2):
        if model == 0:
            return dx * dx + dy * dy < r * r
        return p0 * dx * dx + 2.0 * p1 * dx * dy + p2 * dy * dy < 9.0

    @nb.njit(parallel=True, cache=True)
    def row_pass(u, v, rad, p0, p1, p2, p3, model, h, w, order, bucket, reach, counts, cursor, indices, data, fill):
        """Per image row, in parallel: count (``fill`` False: entries per pixel into
        ``counts[1 + pixel]``) or write (``fill`` True: at ``cursor[pixel]``) the CSR entries
        of every voxel whose support reaches the row. ``order``/``bucket``: voxels sorted by
        the image row of their projected centre; ``reach``: rows a support extends beyond
        its centre row. A row owns its pixels' entries, so rows never race."""
        for row in nb.prange(h):
            for rb in range(max(row - reach, 0), min(row + reach + 1, h)):
                for q in range(bucket[rb], bucket[rb + 1]):
                    a = order[q]
                    r = rad[a]
                    dy = row + 0.5 - v[a]
                    if abs(dy) >= r:
                        continue
                    for col in range(max(int(math.floor(u[a] - r)), 0), min(int(math.floor(u[a] + r)) + 1, w)):
                        dx = col + 0.5 - u[a]
                        if not inside_support(model, dx, dy, r, p0[a], p1[a], p2[a]):
                            continue
                        p = row * w + col
                        if fill:
                            indices[cursor[p]] = a
                            data[cursor[p]] = weight(model, dx, dy, p0[a], p1[a], p2[a], p3[a])
                            cursor[p] += 1
                        else:
                            counts[1 + p] += 1

    @nb.njit(inline="always", cache=True)
    def mart_row(p, indptr, indices, data, img, vol, mu):
        s, e = indptr[p], indptr[p + 1]
        if s == e:
            return
        if img[p] <= 0.0:
            for k in range(s, e):
                vol[indices[k]] = 0.0
            return
        proj = 0.0
        for k in range(s, e):
            proj += data[k] * vol[indices[k]]
        if proj <= 0.0:
            return  # nothing along this line of sight can be scaled up
        lr = mu * math.log(img[p] / proj)
        if lr == 0.0:
            return
        for k in range(s, e):
            vol[indices[k]] *= math.exp(lr * data[k])

    @nb.njit(parallel=True, cache=True)
    def mart_camera(indptr, indices, data, img, w, span, vol, mu):
        """One MART sweep over a camera's pixels: v_j <- v_j (I_i / sum_j w_ij v_j)^(mu w_ij)."""
        h = img.shape[0] // w
        for colour in range(span):
            n = (h - colour + span - 1) // span
            for rr in nb.prange(n):
                row = colour + rr * span
                for col in range(w):
                    mart_row(row * w + col, indptr, indices, data, img, vol, mu)

    @nb.njit(cache=True)
    def mart_sequential(indptr, indices, data, img, vol, mu):
        """MART sweep in plain pixel order (matrices whose voxels reach any pixel)."""
        for p in range(indptr.shape[0] - 1):
            mart_row(p, indptr, indices, data, img, vol, mu)

    @nb.njit(parallel=True, cache=True)
    def project(indptr, indices, data, vol, out):
        """out = W vol (one camera)."""
        for p in nb.prange(indptr.shape[0] - 1):
            acc = 0.0
            for k in range(indptr[p], indptr[p + 1]):
                acc += data[k] * vol[indices[k]]
            out[p] = acc

    @nb.njit(parallel=True, cache=True)
    def log_ratio(img, proj, out):
        """log(I / proj); -inf where I = 0 (zero pixel), 0 where nothing projects (no information)."""
        for p in nb.prange(img.shape[0]):
            if proj[p] <= 0.0:
                out[p] = 0.0
            elif img[p] <= 0.0:
                out[p] = -math.inf
            else:
                out[p] = math.log(img[p] / proj[p])

    @nb.njit(parallel=True, cache=True)
    def back_project(indptr, indices, data, w, span, values, acc):
        """acc_j += sum_i w_ij values_i (row classes modulo span in parallel)."""
        h = (indptr.shape[0] - 1) // w
        for colour in range(span):
            n = (h - colour + span - 1) // span
            for rr in nb.prange(n):
                row = colour + rr * span
                for p in range(row * w, row * w + w):
                    val = values[p]
                    if val == 0.0:
                        continue
                    for k in range(indptr[p], indptr[p + 1]):
                        acc[indices[k]] += data[k] * val

    @nb.njit(parallel=True, cache=True)
    def smart_update(vol, acc, wsum, mu):
        """v_j <- v_j exp(mu sum_i w_ij log(I_i/p_i) / sum_i w_ij) (a zero pixel gives -inf -> 0)."""
        for j in nb.prange(vol.shape[0]):
            if wsum[j] > 0.0:
                vol[j] = vol[j] * math.exp(mu * acc[j] / wsum[j]) if acc[j] > -math.inf else 0.0

    _K.update(locals())
    return _K
