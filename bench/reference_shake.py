"""Frozen copy of mitpiv.tracking.ipr.shake as of commit c5714a9 (before the compiled
sequential shake): particles coloured into non-overlapping groups (Jones-Plassmann in
NumPy), each group shaken by one vectorised damped Gauss-Newton step with the residual
updated between groups. The baseline bench/bench_speed.py prints beside today's shake in
the same run. Bench-only."""

import numpy as np

from mitpiv.errors import check_positive
from mitpiv.tracking.otf import OTF, project_particles, stamps


def _windows(res, cam, otf, k, p, e, r):
    """Per-particle window of camera k: cols, rows, in-image mask, augmented residual."""
    w, h = cam.resolution
    uv = cam.project(p)
    vis = cam.in_front(p) & np.all(np.isfinite(uv), axis=1)
    uv = np.where(vis[:, None], uv, -10.0 * r)
    a, b, c, pk = otf.params(k, p)
    cols, rows, own = stamps(uv, a, b, c, pk * e, r)
    inside = (cols >= 0) & (cols < w) & (rows >= 0) & (rows < h) & vis[:, None, None]
    aug = np.where(inside, res[np.clip(rows, 0, h - 1), np.clip(cols, 0, w - 1)] + own, 0.0)
    return cols, rows, inside, aug, (a, b, c, pk)


def _stamp_on(cam, p, cols, rows, inside, params):
    """Unit-intensity particle image at positions p sampled on given windows (the OTF
    parameters of the window's particle, which vary slowly with position)."""
    uv = cam.project(p)
    a, b, c, pk = params
    du = cols + 0.5 - uv[:, 0, None, None]
    dv = rows + 0.5 - uv[:, 1, None, None]
    q = a[:, None, None] * du * du + 2 * b[:, None, None] * du * dv + c[:, None, None] * dv * dv
    return np.where(inside, pk[:, None, None] * np.exp(-0.5 * q), 0.0)


def colour_groups(positions_mm, cameras, radius_px: float, *, seed: int = 0) -> list[np.ndarray]:
    """Split particles into groups whose images do not overlap in any camera (projections
    at least ``radius_px`` apart): a vectorised Jones-Plassmann colouring with random
    priorities. Returns index arrays, one per group."""
    from scipy.spatial import cKDTree

    n = positions_mm.shape[0]
    if n == 0:
        return []
    edges = [np.zeros((0, 2), np.int64)]
    for cam in cameras:
        uv = cam.project(positions_mm)
        ok = np.flatnonzero(np.all(np.isfinite(uv), axis=1))
        if ok.size > 1:
            pr = cKDTree(uv[ok]).query_pairs(radius_px, output_type="ndarray")
            edges.append(ok[pr])
    e = np.concatenate(edges)
    e = np.concatenate([e, e[:, ::-1]])
    prio = np.random.default_rng(seed).permutation(n)
    colour = np.full(n, -1)
    c = 0
    while np.any(colour < 0):
        open_ = colour < 0
        live = open_[e[:, 0]] & open_[e[:, 1]]
        beaten = np.zeros(n, bool)
        el = e[live]
        beaten[el[prio[el[:, 1]] > prio[el[:, 0]], 0]] = True
        colour[open_ & ~beaten] = c
        c += 1
    order = np.argsort(colour, kind="stable")
    return np.split(order, np.flatnonzero(np.diff(colour[order])) + 1)


def _shake_group(res, cameras, otf, pc, ec, s, r, fixed_intensity):
    """One damped Gauss-Newton step of position (and intensity) per particle against its
    augmented residual in every camera, each coordinate step limited to +-s [mm]; the
    residual images ``res`` are updated in place on the particles' windows."""
    wins = [_windows(res[k], cam, otf, k, pc, ec, r) for k, cam in enumerate(cameras)]
    own_old = [w[3] - np.where(w[2], res[k][np.clip(w[1], 0, res[k].shape[0] - 1), np.clip(w[0], 0, res[k].shape[1] - 1)], 0.0)
               for k, w in enumerate(wins)]
    m = 3 if fixed_intensity else 4
    jtj = np.zeros((pc.shape[0], m, m))
    jtr = np.zeros((pc.shape[0], m))
    for k, cam in enumerate(cameras):
        cols, rows, inside, aug, (a, b, c, pk) = wins[k]
        uv = cam.project(pc)
        jac = cam.jacobian(pc)
        du = cols + 0.5 - uv[:, 0, None, None]
        dv = rows + 0.5 - uv[:, 1, None, None]
        q = a[:, None, None] * du * du + 2 * b[:, None, None] * du * dv + c[:, None, None] * dv * dv
        g = np.where(inside, pk[:, None, None] * np.exp(-0.5 * q), 0.0)
        eg = ec[:, None, None] * g
        gu = eg * (a[:, None, None] * du + b[:, None, None] * dv)
        gv = eg * (b[:, None, None] * du + c[:, None, None] * dv)
        cols_j = [gu * jac[:, 0, i, None, None] + gv * jac[:, 1, i, None, None] for i in range(3)]
        if not fixed_intensity:
            cols_j.append(g)
        dm = np.stack([x.reshape(x.shape[0], -1) for x in cols_j], axis=2)  # (N, P, m)
        rr = (aug - eg).reshape(pc.shape[0], -1)
        jtj += np.einsum("npi,npj->nij", dm, dm)
        jtr += np.einsum("npi,np->ni", dm, rr)
    diag = np.einsum("nii->ni", jtj)
    damp = jtj + (1e-3 * diag + 1e-12)[:, :, None] * np.eye(m)
    step = np.linalg.solve(damp, jtr[..., None])[..., 0]
    step = np.nan_to_num(step)
    pn = pc + np.clip(step[:, :3], -s, s)
    en = ec if fixed_intensity else np.maximum(ec + step[:, 3], 0.0)
    # residual update on the same windows: old image back in, new image out
    for k, cam in enumerate(cameras):
        cols, rows, inside, aug, prm = wins[k]
        new = en[:, None, None] * _stamp_on(cam, pn, cols, rows, inside, prm)
        np.add.at(res[k], (rows[inside], cols[inside]), (own_old[k] - new)[inside])
    return pn, en


def shake(images, cameras, otf: OTF, positions_mm, intensities, *, step_mm: float, iterations: int = 6,
          chunk: int = 20_000, fixed_intensity: bool = False) -> tuple[np.ndarray, np.ndarray, list[np.ndarray]]:
    """Shake particles against the residual images (see the module notes).

    Particles whose images overlap are never moved together: they are split into groups
    of non-overlapping particles (:func:`colour_groups`), each group is shaken at once
    (vectorised) and the residual images are updated before the next group, so two
    overlapping particles share their light as in a sequential (Gauss-Seidel) shake.

    Parameters
    ----------
    images : per-camera (H, W) images; cameras : the cameras; otf : the particle image model.
    positions_mm : (N, 3) start positions [mm]; intensities : (N,) start intensities.
    step_mm : first shake amplitude (largest step per coordinate) [mm]; it shrinks by 0.6
        per iteration (floor 5 %).
    iterations : shake iterations.
    chunk : particles per vectorised batch (bounds memory).
    fixed_intensity : keep the intensities (only move).

    Returns
    -------
    positions_mm (N, 3), intensities (N,) (>= 0), residual images (list of (H, W)).
    """
    imgs = [np.asarray(i, dtype=np.float64) for i in images]
    p = np.array(positions_mm, dtype=np.float64).reshape(-1, 3)
    e = np.array(np.broadcast_to(np.asarray(intensities, dtype=np.float64), (p.shape[0],)))
    s0 = check_positive("step_mm", step_mm, owner="shake", unit="mm")
    r = otf.radius_px()
    res = [img - pr for img, pr in zip(imgs, project_particles(p, e, cameras, otf), strict=True)]
    for it in range(int(iterations)):
        s = s0 * max(0.6**it, 0.05)
        for group in colour_groups(p, cameras, r + 1, seed=it):
            for lo_i in range(0, group.size, chunk):
                g = group[lo_i:lo_i + chunk]
                pn, en = _shake_group(res, cameras, otf, p[g], e[g], s, r, fixed_intensity)
                p[g], e[g] = pn, en
    res = [img - pr for img, pr in zip(imgs, project_particles(p, e, cameras, otf), strict=True)]
    return p, e, res
