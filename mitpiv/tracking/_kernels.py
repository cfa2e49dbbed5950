"""Numba kernels of the particle tracker: one Gauss-Seidel shake pass over all particles,
and the splatting of particle images (``splat``, used by :func:`~mitpiv.tracking.otf.project_particles`).

:func:`kernels` compiles (once, cached on disk) ``shake_pass``: for each particle in the
given order it accumulates the Gauss-Newton normal equations of its position (and
intensity) against its augmented residual (the residual plus its own image) over its
(2r+1)^2 window in every camera, solves the damped 3x3 / 4x4 system, limits each
coordinate step to ``+-s`` and updates the residual images on the same window (its old
image back in, its new one out) before the next particle reads them. This is Wieneke's
sequential shake (2013): overlapping particles share their light because each one sees
the residual left by those shaken before it, with no colouring of the particles into
non-overlapping groups.

The projection of the new position is the first-order update ``uv + J dp`` of the
projection and Jacobian evaluated once per pass (NumPy, through each camera's
``project``/``jacobian``, so any camera of the contract works). For steps of at most the
shake amplitude (<= 1 px) the second-order term of a pinhole with Brown-Conrady
distortion is below 1e-5 px. Hand-written: no kept library shakes particles against
residual images.
"""

from __future__ import annotations

import math

import numpy as np

from mitpiv._numba import numba

_K = {}


def kernels() -> dict:
    if _K:
        return _K
    # helpers called by other kernels: module globals, not closure cells (see mitpiv._numba)
    global _solve, _window
    nb = numba()

    @nb.njit(cache=True)
    def _solve(a, b, m):
        """Solve a (m x m) x = b in place by Gaussian elimination with partial pivoting;
        returns False (and leaves b) when the matrix is singular."""
        for col in range(m):
            piv = col
            big = abs(a[col, col])
            for r in range(col + 1, m):
                if abs(a[r, col]) > big:
                    big = abs(a[r, col])
                    piv = r
            if not big > 0.0:
                return False
            if piv != col:
                for j in range(m):
                    t = a[col, j]
                    a[col, j] = a[piv, j]
                    a[piv, j] = t
                t = b[col]
                b[col] = b[piv]
                b[piv] = t
            for r in range(col + 1, m):
                f = a[r, col] / a[col, col]
                if f != 0.0:
                    for j in range(col, m):
                        a[r, j] -= f * a[col, j]
                    b[r] -= f * b[col]
        for col in range(m - 1, -1, -1):
            acc = b[col]
            for j in range(col + 1, m):
                acc -= a[col, j] * b[j]
            b[col] = acc / a[col, col]
        return True

    @nb.njit(inline="always", cache=True)
    def _window(u, v, r, w, h):
        """Rows [r0, r1) and columns [c0, c1) of the (2r+1)^2 window around pixel
        ``floor(u, v)``, clipped to a W x H image."""
        i0 = int(math.floor(u))
        j0 = int(math.floor(v))
        return max(j0 - r, 0), min(j0 + r + 1, h), max(i0 - r, 0), min(i0 + r + 1, w)

    @nb.njit(cache=True)
    def shake_pass(res, wh, uv, jac, vis, a, b, c, pk, p, e, order, s, r, fixed_intensity):
        """One sequential shake of every particle (see the module notes).

        res : (K, Hmax, Wmax) residual images, updated in place; wh : (K, 2) int64 (W, H).
        uv : (K, N, 2) projections; jac : (K, N, 2, 3) d(u, v)/dp; vis : (K, N) bool.
        a, b, c, pk : (K, N) OTF parameters at each particle; p : (N, 3), e : (N,) updated
        in place; order : (N,) particle order; s : largest step per coordinate [mm];
        r : window half width [px]; fixed_intensity : only move.
        """
        n_cam = res.shape[0]
        m = 3 if fixed_intensity else 4
        jtj = np.zeros((4, 4))
        jtr = np.zeros(4)
        d = np.zeros(4)
        dp = np.zeros(3)
        for ii in range(order.shape[0]):
            i = order[ii]
            jtj[:, :] = 0.0
            jtr[:] = 0.0
            ei = e[i]
            for k in range(n_cam):
                if not vis[k, i]:
                    continue
                w, h = wh[k, 0], wh[k, 1]
                u, v = uv[k, i, 0], uv[k, i, 1]
                ak, bk, ck, pkk = a[k, i], b[k, i], c[k, i], pk[k, i]
                r0, r1, c0, c1 = _window(u, v, r, w, h)
                for row in range(r0, r1):
                    dv = row + 0.5 - v
                    for col in range(c0, c1):
                        du = col + 0.5 - u
                        g = pkk * math.exp(-0.5 * (ak * du * du + 2.0 * bk * du * dv + ck * dv * dv))
                        eg = ei * g
                        gu = eg * (ak * du + bk * dv)
                        gv = eg * (bk * du + ck * dv)
                        for q in range(3):
                            d[q] = gu * jac[k, i, 0, q] + gv * jac[k, i, 1, q]
                        d[3] = g
                        # augmented residual minus the particle's own image = the residual
                        rr = res[k, row, col]
                        for q in range(m):
                            jtr[q] += d[q] * rr
                            for q2 in range(m):
                                jtj[q, q2] += d[q] * d[q2]
            for q in range(m):
                jtj[q, q] += 1e-3 * jtj[q, q] + 1e-12
            if not _solve(jtj, jtr, m):
                continue
            ok = True
            for q in range(m):
                if not math.isfinite(jtr[q]):
                    ok = False
            if not ok:
                continue
            for q in range(3):
                dp[q] = min(max(jtr[q], -s), s)
            en = ei if fixed_intensity else max(ei + jtr[3], 0.0)
            for q in range(3):
                p[i, q] += dp[q]
            e[i] = en
            # residual update on the same windows: the old image back in, the new one out
            for k in range(n_cam):
                if not vis[k, i]:
                    continue
                w, h = wh[k, 0], wh[k, 1]
                u, v = uv[k, i, 0], uv[k, i, 1]
                un = u + jac[k, i, 0, 0] * dp[0] + jac[k, i, 0, 1] * dp[1] + jac[k, i, 0, 2] * dp[2]
                vn = v + jac[k, i, 1, 0] * dp[0] + jac[k, i, 1, 1] * dp[1] + jac[k, i, 1, 2] * dp[2]
                ak, bk, ck, pkk = a[k, i], b[k, i], c[k, i], pk[k, i]
                r0, r1, c0, c1 = _window(u, v, r, w, h)
                for row in range(r0, r1):
                    dv = row + 0.5 - v
                    dvn = row + 0.5 - vn
                    for col in range(c0, c1):
                        du = col + 0.5 - u
                        dun = col + 0.5 - un
                        old = ei * pkk * math.exp(-0.5 * (ak * du * du + 2.0 * bk * du * dv + ck * dv * dv))
                        new = en * pkk * math.exp(-0.5 * (ak * dun * dun + 2.0 * bk * dun * dvn + ck * dvn * dvn))
                        res[k, row, col] += old - new

    @nb.njit(cache=True)
    def splat(img, uv, a, b, c, amp, r):
        """Add elliptical Gaussian stamps ``amp exp(-q/2)`` on the (2r+1)^2 pixels around
        ``floor(uv)`` to ``img`` (H, W) in place; pixels off the image and non-finite
        centres are skipped (the same stamps as :func:`mitpiv.tracking.otf.stamps`)."""
        h, w = img.shape
        for i in range(uv.shape[0]):
            u, v = uv[i, 0], uv[i, 1]
            if not (math.isfinite(u) and math.isfinite(v)):
                continue
            if u < -r - 1.0 or v < -r - 1.0 or u > w + r + 1.0 or v > h + r + 1.0:
                continue
            r0, r1, c0, c1 = _window(u, v, r, w, h)
            for row in range(r0, r1):
                dv = row + 0.5 - v
                for col in range(c0, c1):
                    du = col + 0.5 - u
                    img[row, col] += amp[i] * math.exp(-0.5 * (a[i] * du * du + 2.0 * b[i] * du * dv + c[i] * dv * dv))

    _K["shake_pass"] = shake_pass
    _K["splat"] = splat
    return _K
