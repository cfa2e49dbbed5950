"""Numba kernels of the algebraic reconstructions: voxel-pixel weights, sparse (CSR)
weight assembly, MART and SMART updates.

Pinhole fast path: for :class:`~mitpiv.reconstruct.mapping.PinholeMapping` cameras the
projection (pinhole + Brown-Conrady), its Jacobian and the voxel footprints are evaluated
per voxel inside compiled kernels (:func:`camera_row` packs a camera into 20 numbers), so
the MLOS pass and the weight footprints need no NumPy temporaries; they replicate
``PinholeCamera.project``/``jacobian`` and ``tomo._footprints`` operation for operation
(tests compare them). Any other mapping takes the generic NumPy path.

Storage: one CSR matrix per camera, rows = pixels (row-major ``v * W + u``), columns =
active voxels, float32 weights. A voxel's weights reach at most ``span`` consecutive image
rows, so image rows ``span`` apart share no voxel: rows of one residue class modulo
``span`` are updated in parallel without races, exactly as a sequential row-action sweep
in that row order would update them.
"""

from __future__ import annotations

import math

import numpy as np

from mitpiv._numba import numba

_K = {}

CIRCLE, GAUSSIAN = 0, 1
PIXEL_RADIUS = 1.0 / math.sqrt(math.pi)  # equal-area circle of a unit pixel (0.564 px)


CAMERA_FIELDS = 20  # R (9), position (3), focal [px], cx, cy, k1, k2, k3, p1, p2


def camera_row(camera) -> np.ndarray:
    """The 20 numbers of a PinholeCamera the compiled projection uses (float64)."""
    d = camera.distortion
    return np.concatenate([np.asarray(camera.rotation, np.float64).ravel(), np.asarray(camera.position_mm, np.float64),
                           [camera.focal_px, *camera.principal_point_px, d.k1, d.k2, d.k3, d.p1, d.p2]]).astype(np.float64)


def kernels() -> dict:
    if _K:
        return _K
    # helpers called by other kernels: module globals, not closure cells (see mitpiv._numba)
    global circle_overlap, weight, inside_support, mart_log_ratio, mart_row, mart_row_f32, pinhole, sample_linear, footprint
    global voxel_centre
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

    @nb.njit(parallel=True, cache=True)
    def row_pass_sorted(u, v, rad, p0, p1, p2, p3, model, h, w, order, bucket, reach, counts, cursor, indices, data,
                        fill):
        """:func:`row_pass` on footprints already sorted by bucket (``u[q]`` is voxel
        ``order[q]``): the inner loop reads them sequentially instead of gathering."""
        for row in nb.prange(h):
            for rb in range(max(row - reach, 0), min(row + reach + 1, h)):
                for q in range(bucket[rb], bucket[rb + 1]):
                    r = rad[q]
                    dy = row + 0.5 - v[q]
                    if abs(dy) >= r:
                        continue
                    uq = u[q]
                    for col in range(max(int(math.floor(uq - r)), 0), min(int(math.floor(uq + r)) + 1, w)):
                        dx = col + 0.5 - uq
                        if not inside_support(model, dx, dy, r, p0[q], p1[q], p2[q]):
                            continue
                        p = row * w + col
                        if fill:
                            indices[cursor[p]] = order[q]
                            data[cursor[p]] = weight(model, dx, dy, p0[q], p1[q], p2[q], p3[q])
                            cursor[p] += 1
                        else:
                            counts[1 + p] += 1

    @nb.njit(inline="always", cache=True)
    def mart_log_ratio(p, indptr, indices, data, img, vol):
        """(update, log(I_p / sum_j w_pj v_j)) of pixel ``p``'s row; no update for an empty row or
        one along which nothing projects (nothing can be scaled up), and none after a zero
        pixel, whose row's voxels are set to 0 here."""
        s, e = indptr[p], indptr[p + 1]
        if s == e:
            return False, 0.0
        if img[p] <= 0.0:
            for k in range(s, e):
                vol[indices[k]] = 0.0
            return False, 0.0
        proj = 0.0
        for k in range(s, e):
            proj += data[k] * vol[indices[k]]
        if proj <= 0.0:
            return False, 0.0
        return True, math.log(img[p] / proj)

    @nb.njit(inline="always", cache=True)
    def mart_row(p, indptr, indices, data, img, vol, mu):
        update, r = mart_log_ratio(p, indptr, indices, data, img, vol)
        if not update:
            return
        lr = mu * r
        if lr == 0.0:
            return
        for k in range(indptr[p], indptr[p + 1]):
            vol[indices[k]] *= math.exp(lr * data[k])

    @nb.njit(inline="always", cache=True)
    def mart_row_f32(p, indptr, indices, data, img, vol, mu, lrmax):
        """:func:`mart_row` with the multiplicative factor ``exp(lr w)`` evaluated in single
        precision (the weights are float32 and the volume is returned as float32; measured
        difference to the float64 factor after 2 iterations: 4e-6 relative; about 20 % less
        CPU time per weight entry).

        Rows with ``|lr| <= lrmax`` take the factor from its degree-7 Taylor polynomial in
        float32 instead of ``exp`` (issue 50): the caller sets ``lrmax = 0.4 / max(w)``, so
        ``|lr w| <= 0.4`` and the truncation error is below 0.4^8 / 8! = 1.6e-8 relative,
        under float32's half ulp. Such rows hold most of the weight entries once MART has
        converged a little (|lr| <= 0.1 for 60 % of them after 5-10 iterations in
        bench/bench_mart_bandwidth.py); ``lrmax = 0`` keeps ``exp`` everywhere."""
        update, r = mart_log_ratio(p, indptr, indices, data, img, vol)
        if not update:
            return
        lr = np.float32(mu * r)
        if lr == 0.0:
            return
        if abs(lr) <= lrmax:
            one = np.float32(1.0)
            c2 = np.float32(0.5)
            c3 = np.float32(1.0 / 6.0)
            c4 = np.float32(1.0 / 24.0)
            c5 = np.float32(1.0 / 120.0)
            c6 = np.float32(1.0 / 720.0)
            c7 = np.float32(1.0 / 5040.0)
            for k in range(indptr[p], indptr[p + 1]):
                x = lr * data[k]
                vol[indices[k]] *= one + x * (one + x * (c2 + x * (c3 + x * (c4 + x * (c5 + x * (c6 + x * c7))))))
            return
        for k in range(indptr[p], indptr[p + 1]):
            vol[indices[k]] *= math.exp(lr * data[k])

    @nb.njit(parallel=True, cache=True)
    def mart_sweep(indptr, indices, data, img, w, span, vol, mu, single, lrmax):
        """One MART sweep over a camera's pixels: v_j <- v_j (I_i / sum_j w_ij v_j)^(mu w_ij),
        the factor in single precision (:func:`mart_row_f32`, Taylor polynomial for rows with
        ``|lr| <= lrmax``) when ``single``."""
        h = img.shape[0] // w
        for colour in range(span):
            n = (h - colour + span - 1) // span
            for rr in nb.prange(n):
                row = colour + rr * span
                for col in range(w):
                    if single:
                        mart_row_f32(row * w + col, indptr, indices, data, img, vol, mu, lrmax)
                    else:
                        mart_row(row * w + col, indptr, indices, data, img, vol, mu)

    def mart_camera(indptr, indices, data, img, w, span, vol, mu):
        """:func:`mart_sweep` with the float64 factor."""
        mart_sweep(indptr, indices, data, img, w, span, vol, mu, False, 0.0)

    def mart_camera_f32(indptr, indices, data, img, w, span, vol, mu, wmax=math.inf):
        """:func:`mart_sweep` with the float32 factor; ``wmax``: the largest weight of
        ``data`` (the Taylor factor for rows with ``|mu log ratio| <= 0.4 / wmax``; the default
        ``inf`` calls ``exp`` for every entry)."""
        lrmax = 0.4 / wmax if wmax > 0 else 0.0
        mart_sweep(indptr, indices, data, img, w, span, vol, mu, True, lrmax)

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

    # ------------------------------------------------------------ pinhole fast path
    @nb.njit(inline="always", cache=True)
    def pinhole(cam, x, y, z):
        """Camera-frame point, normalised coordinates and pixel of a world point:
        (zc, xn, yn, u, v, radial, d_radial); u = v = -1e9 behind the pinhole."""
        px = x - cam[9]
        py = y - cam[10]
        pz = z - cam[11]
        xc = cam[0] * px + cam[1] * py + cam[2] * pz
        yc = cam[3] * px + cam[4] * py + cam[5] * pz
        zc = cam[6] * px + cam[7] * py + cam[8] * pz
        xn = xc / zc
        yn = yc / zc
        r2 = xn * xn + yn * yn
        k1, k2, k3, p1, p2 = cam[15], cam[16], cam[17], cam[18], cam[19]
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        d_radial = k1 + r2 * (2.0 * k2 + r2 * (3.0 * k3))
        xy2 = 2.0 * xn * yn
        xd = xn * radial + p1 * xy2 + p2 * (r2 + 2.0 * xn * xn)
        yd = yn * radial + p1 * (r2 + 2.0 * yn * yn) + p2 * xy2
        if zc > 0.0:
            u = cam[12] * xd + cam[13]
            v = cam[12] * yd + cam[14]
        else:
            u = -1e9
            v = -1e9
        return zc, xn, yn, u, v, radial, d_radial

    @nb.njit(inline="always", cache=True)
    def sample_linear(img, off, h, w, u, v):
        """Bilinear sample at pixel position (u, v) (centres at i + 0.5), as
        scipy.ndimage.map_coordinates(order=1, mode="constant"): 0 unless 0 <= v - 0.5 <= h - 1
        and 0 <= u - 0.5 <= w - 1."""
        r = v - 0.5
        c = u - 0.5
        if not (r >= 0.0 and r <= h - 1 and c >= 0.0 and c <= w - 1):
            return 0.0
        r0 = min(int(math.floor(r)), h - 2) if h > 1 else 0
        c0 = min(int(math.floor(c)), w - 2) if w > 1 else 0
        fr = r - r0
        fc = c - c0
        r1 = min(r0 + 1, h - 1)
        c1 = min(c0 + 1, w - 1)
        return ((1.0 - fr) * ((1.0 - fc) * img[off + r0 * w + c0] + fc * img[off + r0 * w + c1])
                + fr * ((1.0 - fc) * img[off + r1 * w + c0] + fc * img[off + r1 * w + c1]))

    @nb.njit(parallel=True, cache=True)
    def refocus_homography(img, offs, hs, ws, hom, xs, ys, out):
        """One plane of additive synthetic-aperture refocusing (eq. 2.3 of the SAPIV study):
        ``out[q]`` = the mean, over the cameras whose image holds the point, of each camera's
        bilinear sample (:func:`sample_linear`) at the homography's image ``H_c (x_q, y_q, 1)``
        (0 where no camera holds it). ``hom``: (n_cam, 3, 3); ``img``: the images raveled one
        after another from ``offs``. The same sum and count as ``refocus_planes``' NumPy path
        (map_coordinates per camera), fused, in parallel over the points."""
        n = xs.shape[0]
        nc = hom.shape[0]
        for q in nb.prange(n):
            x = xs[q]
            y = ys[q]
            acc = 0.0
            cnt = 0
            for c in range(nc):
                den = hom[c, 2, 0] * x + hom[c, 2, 1] * y + hom[c, 2, 2]
                u = (hom[c, 0, 0] * x + hom[c, 0, 1] * y + hom[c, 0, 2]) / den
                v = (hom[c, 1, 0] * x + hom[c, 1, 1] * y + hom[c, 1, 2]) / den
                h = hs[c]
                w = ws[c]
                acc += sample_linear(img, offs[c], h, w, u, v)
                if u >= 0.0 and u <= w and v >= 0.0 and v <= h:
                    cnt += 1
            out[q] = acc / cnt if cnt > 0 else 0.0

    @nb.njit(parallel=True, cache=True)
    def mlos_pinhole(xs, ys, z, cams, img, offs, hs, ws, exponent, prune, val, keep):
        """MLOS value of every voxel of the plane at depth ``z`` (flat (y, x) order) and
        whether it is a candidate: ``val = exp(exponent sum_c log I_c(P_c(x)))`` (0 when a
        camera does not see the voxel or samples 0); ``keep`` = val > 0 (``prune``) or seen
        by every camera. ``img``: the images raveled one after another from ``offs``."""
        ny, nx = ys.shape[0], xs.shape[0]
        nc = cams.shape[0]
        for j in nb.prange(ny):
            for i in range(nx):
                lg = 0.0
                seen = True
                for c in range(nc):
                    _, _, _, u, v, _, _ = pinhole(cams[c], xs[i], ys[j], z)
                    h = hs[c]
                    w = ws[c]
                    if u >= 0.0 and u <= w and v >= 0.0 and v <= h:
                        s = sample_linear(img, offs[c], h, w, u, v)
                        lg += math.log(s) if s > 0.0 else -math.inf
                    else:
                        seen = False
                        lg += -math.inf
                e = math.exp(exponent * lg)
                val[j * nx + i] = e
                keep[j * nx + i] = (e > 0.0) if prune else seen

    @nb.njit(inline="always", cache=True)
    def footprint(cam, x, y, z, d0, d1, d2, model, psf2):
        """Projection and weight-model footprint of the voxel at (x, y, z): (u, v, support
        radius, p0, p1, p2, p3), float64 (see ``tomo._footprints``)."""
        f = cam[12]
        pp1, pp2 = cam[18], cam[19]
        zc, xn, yn, uu, vv, radial, d_radial = pinhole(cam, x, y, z)
        # Jacobian d(u, v)/d(x, y, z) = f D dn R (tomo._footprints uses PinholeCamera.jacobian)
        a = radial + 2.0 * xn * xn * d_radial + 6.0 * pp2 * xn + 2.0 * pp1 * yn
        e = radial + 2.0 * yn * yn * d_radial + 6.0 * pp1 * yn + 2.0 * pp2 * xn
        b = 2.0 * xn * yn * d_radial + 2.0 * pp1 * xn + 2.0 * pp2 * yn
        iz = 1.0 / zc
        # dd @ dn: rows (f a, f b) and (f b, f e) times [[1/z, 0, -x/z], [0, 1/z, -y/z]]
        m00 = f * a * iz
        m01 = f * b * iz
        m02 = -(f * a * xn + f * b * yn) * iz
        m10 = f * b * iz
        m11 = f * e * iz
        m12 = -(f * b * xn + f * e * yn) * iz
        j00 = (m00 * cam[0] + m01 * cam[3] + m02 * cam[6]) * d0
        j01 = (m00 * cam[1] + m01 * cam[4] + m02 * cam[7]) * d1
        j02 = (m00 * cam[2] + m01 * cam[5] + m02 * cam[8]) * d2
        j10 = (m10 * cam[0] + m11 * cam[3] + m12 * cam[6]) * d0
        j11 = (m10 * cam[1] + m11 * cam[4] + m12 * cam[7]) * d1
        j12 = (m10 * cam[2] + m11 * cam[5] + m12 * cam[8]) * d2
        area = (abs(j00 * j11 - j01 * j10) + abs(j01 * j12 - j02 * j11) + abs(j00 * j12 - j02 * j10))
        if model == 0:
            rv = math.sqrt(area / math.pi)
            return uu, vv, rv + PIXEL_RADIUS, rv, 0.0, 0.0, 0.0
        cxx = (j00 * j00 + j01 * j01 + j02 * j02) / 12.0 + psf2
        cxy = (j00 * j10 + j01 * j11 + j02 * j12) / 12.0
        cyy = (j10 * j10 + j11 * j11 + j12 * j12) / 12.0 + psf2
        det = cxx * cyy - cxy * cxy
        lam = 0.5 * (cxx + cyy) + math.sqrt(0.25 * (cxx - cyy) ** 2 + cxy * cxy)
        return (uu, vv, 3.0 * math.sqrt(lam) + 0.75, cyy / det, -cxy / det, cxx / det,
                area / (2.0 * math.pi * math.sqrt(det)))

    @nb.njit(inline="always", cache=True)
    def voxel_centre(flat, xs, ys, zs):
        """World centre (x, y, z) of the voxel with flat (z, y, x) index ``flat``."""
        nx = xs.shape[0]
        nyx = ys.shape[0] * nx
        k = flat // nyx
        rest = flat - k * nyx
        j = rest // nx
        return xs[rest - j * nx], ys[j], zs[k]

    @nb.njit(parallel=True, cache=True)
    def footprints_pinhole(idx, xs, ys, zs, cam, d0, d1, d2, model, psf2, u, v, rad, p0, p1, p2, p3):
        """Projection (rounded to float32, as stored) and weight-model footprint (support
        radius and the four model parameters, see ``tomo._footprints``) of voxels ``idx``."""
        for q in nb.prange(idx.shape[0]):
            x, y, z = voxel_centre(idx[q], xs, ys, zs)
            uu, vv, rr, q0, q1, q2, q3 = footprint(cam, x, y, z, d0, d1, d2, model, psf2)
            # rounded to float32 also when the outputs are float64 (the assembly reads them so)
            u[q], v[q], rad[q] = np.float32(uu), np.float32(vv), np.float32(rr)
            p0[q], p1[q], p2[q], p3[q] = np.float32(q0), np.float32(q1), np.float32(q2), np.float32(q3)

    @nb.njit(parallel=True, cache=True)
    def survives_pinhole(idx, xs, ys, zs, cam, d0, d1, d2, model, psf2, img, zero_dist, alive):
        """:func:`survives` with the footprints computed in place (rounded to float32 and
        evaluated in the same precision as :func:`survives` on the float32 arrays of
        :func:`footprints_pinhole`): no footprint arrays are written and read back.
        ``zero_dist``: per pixel, the chessboard distance to the nearest zero pixel; a voxel
        whose projected centre lies farther than its support reaches is not checked pixel
        by pixel (it cannot touch a zero pixel)."""
        h, w = img.shape
        for a in nb.prange(idx.shape[0]):
            if not alive[a]:
                continue
            x, y, z = voxel_centre(idx[a], xs, ys, zs)
            uu, vv, rr, q0, q1, q2, q3 = footprint(cam, x, y, z, d0, d1, d2, model, psf2)
            ua, va, r = np.float32(uu), np.float32(vv), np.float32(rr)
            if ua >= 0.0 and va >= 0.0 and ua < w and va < h and zero_dist[int(va), int(ua)] > r + 2.0:
                continue
            f0, f1, f2, f3 = np.float32(q0), np.float32(q1), np.float32(q2), np.float32(q3)
            for row in range(max(int(math.floor(va - r)), 0), min(int(math.floor(va + r)) + 1, h)):
                for col in range(max(int(math.floor(ua - r)), 0), min(int(math.floor(ua + r)) + 1, w)):
                    if img[row, col] <= 0.0 and weight(model, col + 0.5 - ua, row + 0.5 - va, f0, f1, f2, f3) > 0.0:
                        alive[a] = False

    @nb.njit(parallel=True, cache=True)
    def pinhole_image_rows(idx, xs, ys, zs, cam, h, crow):
        """Image row (clamped onto 0..h-1) of the projected centre of voxels ``idx``, from
        the projection rounded to float32 as :func:`footprints_pinhole` stores it."""
        for q in nb.prange(idx.shape[0]):
            x, y, z = voxel_centre(idx[q], xs, ys, zs)
            _, _, _, _, vv, _, _ = pinhole(cam, x, y, z)
            r = math.floor(np.float64(np.float32(vv)))
            crow[q] = 0 if not r > 0 else (h - 1 if r > h - 1 else np.int32(r))

    @nb.njit(cache=True)
    def support_extent(v, rad):
        """(largest support radius, largest number of image rows a support spans):
        ``rad.max()`` and ``(floor(v + rad) - floor(v - rad)).max() + 1`` without temporaries."""
        rmax = 0.0
        span = 1
        for q in range(v.shape[0]):
            r = rad[q]
            if r > rmax:
                rmax = r
            s = int(math.floor(v[q] + r) - math.floor(v[q] - r)) + 1
            if s > span:
                span = s
        return rmax, span

    @nb.njit(cache=True)
    def counting_order(keys, n_keys, order, bucket):
        """Stable counting sort of small non-negative integer keys: ``order`` as
        ``np.argsort(keys, kind="stable")`` and ``bucket`` (n_keys + 1) the start of each key's
        run (O(n), where NumPy sorts 32-bit keys by comparison)."""
        bucket[:] = 0
        for q in range(keys.shape[0]):
            bucket[keys[q] + 1] += 1
        for r in range(n_keys):
            bucket[r + 1] += bucket[r]
        pos = bucket[:-1].copy()
        for q in range(keys.shape[0]):
            r = keys[q]
            order[pos[r]] = q
            pos[r] += 1

    _K.update(locals())
    return _K
