"""Backlit particle tracking and sizing on focal stacks (plenoptic refocusing or holographic
reconstruction alike): the hybrid detection, polynomial dewarping, two-frame matching.

Hybrid detection (as in the plenoptic vs digital-holography droplet studies): particles are
opaque silhouettes on a bright, flat background. Each refocused plane is divided by the
background (``transmittance`` 1 = background, 0 = opaque). The minimum-intensity map
over the stack shows every particle dark, so it is segmented once (darkness above
``threshold``, default half-way between background and opaque; touching silhouettes split
by a distance-transform watershed; annuli, the dark fringes of defocused planes, dropped)
to seed the particles. In every plane, the connected dark silhouette holding a seed gives
an edge sharpness (mean Tenengrad, the squared Sobel gradient, over its edge pixels); the
depth is the plane where it peaks, refined by a 3-point Gaussian between planes, and the
in-plane position (darkness-weighted centroid), area, equivalent diameter and aspect
ratio come from the silhouette in that plane. Particles touching at the same depth share
that silhouette and are reported once. A :class:`Dewarp` polynomial fitted to a dot card
imaged at several depths maps (u, v, z_stack) to world millimetres.

Everything is vectorised over particles (``scipy.ndimage`` label statistics); the only
loops run over stack planes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mitpiv.errors import ConfigError, check_positive


def tenengrad(image) -> np.ndarray:
    """Tenengrad sharpness map: squared magnitude of the 3x3 Sobel gradient."""
    from scipy import ndimage

    img = np.asarray(image, dtype=np.float64)
    return ndimage.sobel(img, axis=1, mode="nearest") ** 2 + ndimage.sobel(img, axis=0, mode="nearest") ** 2


def _poly_terms(uvz, deg_xy, deg_z, centre, scale):
    q = (np.asarray(uvz, dtype=np.float64) - centre) / scale
    u, v, z = q[..., 0], q[..., 1], q[..., 2]
    cols = [u**a * v**b * z**c for c in range(deg_z + 1) for a in range(deg_xy + 1) for b in range(deg_xy + 1 - a)]
    return np.stack(cols, axis=-1)


@dataclass
class Dewarp:
    """Polynomial map (u, v, z_stack) -> (x, y, z) world mm: all monomials u^a v^b with
    a + b <= ``degree_xy`` times z^c with c <= ``degree_z`` (normalised coordinates)."""

    coef: np.ndarray  # (n_terms, 3)
    degree_xy: int
    degree_z: int
    centre: np.ndarray
    scale: np.ndarray
    rms_mm: float

    @classmethod
    def load(cls, path) -> Dewarp:
        """Read a dewarp written by :func:`mitpiv.io.write_dewarp` (a backlit run's ``dewarp.npz``)."""
        import dataclasses

        from mitpiv.io.backlit import read_dewarp

        rec = read_dewarp(path)
        return cls(**{f.name: rec[f.name] for f in dataclasses.fields(cls)})

    def save(self, path, *, uvz=None, xyz=None):
        """Write the dewarp (and optionally its calibration observations); see :func:`mitpiv.io.write_dewarp`."""
        from mitpiv.io.backlit import write_dewarp

        return write_dewarp(path, self, uvz=uvz, xyz=xyz)

    def __call__(self, uvz) -> np.ndarray:
        return _poly_terms(uvz, self.degree_xy, self.degree_z, self.centre, self.scale) @ self.coef

    def mm_per_px(self, uvz) -> np.ndarray:
        """Local in-plane scale ``sqrt(|det d(x, y)/d(u, v)|)`` [mm per px] (central differences)."""
        p = np.atleast_2d(np.asarray(uvz, dtype=np.float64))
        h = 0.5
        du = (self(p + [h, 0, 0]) - self(p - [h, 0, 0]))[:, :2] / (2 * h)
        dv = (self(p + [0, h, 0]) - self(p - [0, h, 0]))[:, :2] / (2 * h)
        return np.sqrt(np.abs(du[:, 0] * dv[:, 1] - du[:, 1] * dv[:, 0]))


def fit_dewarp(uvz, xyz, *, degree_xy: int = 3, degree_z: int = 2) -> Dewarp:
    """Least-squares :class:`Dewarp` from marker observations (u, v, z_stack) -> (x, y, z)."""
    uvz = np.asarray(uvz, dtype=np.float64).reshape(-1, 3)
    xyz = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    if uvz.shape != xyz.shape:
        raise ConfigError(f"fit_dewarp: {uvz.shape[0]} observations but {xyz.shape[0]} world points.")
    centre = uvz.mean(axis=0)
    scale = np.maximum(uvz.std(axis=0), 1e-12)
    A = _poly_terms(uvz, degree_xy, degree_z, centre, scale)
    n_depths = np.unique(np.round(uvz[:, 2], 9)).size
    if n_depths <= degree_z:
        raise ConfigError(f"fit_dewarp: degree_z={degree_z} needs markers at >= {degree_z + 1} depths, got {n_depths}.")
    if uvz.shape[0] < 2 * A.shape[1]:
        raise ConfigError(f"fit_dewarp: {uvz.shape[0]} markers for {A.shape[1]} polynomial terms; image more dots "
                          f"or lower degree_xy/degree_z.")
    coef, *_ = np.linalg.lstsq(A, xyz, rcond=None)
    rms = float(np.sqrt(np.mean(np.sum((A @ coef - xyz) ** 2, axis=1))))
    return Dewarp(coef, degree_xy, degree_z, centre, scale, rms)


@dataclass
class BacklitDetections:
    """Particles found in a focal stack.

    uv_px : (N, 2) position in stack pixels (column, row); z_stack_mm : (N,) depth from the
    stack's depths; area_px, diameter_px (equivalent circle), aspect (major/minor axis);
    positions_mm / diameters_mm : world values when a :class:`Dewarp` was given.
    """

    uv_px: np.ndarray
    z_stack_mm: np.ndarray
    area_px: np.ndarray
    diameter_px: np.ndarray
    aspect: np.ndarray
    darkness: np.ndarray
    positions_mm: np.ndarray | None = None
    diameters_mm: np.ndarray | None = None

    def __len__(self) -> int:
        return int(self.uv_px.shape[0])

    @classmethod
    def load(cls, path) -> BacklitDetections:
        """Read detections written by :func:`mitpiv.io.write_detections`."""
        import dataclasses

        from mitpiv.io.backlit import read_detections

        rec = read_detections(path)
        return cls(**{f.name: rec[f.name] for f in dataclasses.fields(cls)})

    def save(self, path, *, min_map=None):
        """Write the detections (and optionally the minimum map); see :func:`mitpiv.io.write_detections`."""
        from mitpiv.io.backlit import write_detections

        return write_detections(path, self, min_map=min_map)


def _split_touching(mask, min_separation_px):
    """Labels of ``mask`` with touching round silhouettes separated: markers are the maxima
    of the Euclidean distance transform (one per plateau); a marker inside the inscribed
    circle of a stronger one, or closer than ``min_separation_px``, is dropped (one disk,
    one marker, however ragged its edge); the markers grow back over the mask by a
    watershed on the inverted distance (``scipy.ndimage.watershed_ift``)."""
    from scipy import ndimage
    from scipy.spatial import cKDTree

    dist = ndimage.distance_transform_edt(mask)
    peaks = mask & (dist >= ndimage.maximum_filter(dist, size=3)) & (dist >= 1.0)
    plab, n = ndimage.label(peaks, structure=np.ones((3, 3), bool))
    if n <= 1:
        return ndimage.label(mask)
    ids = np.arange(1, n + 1)
    c = np.asarray(ndimage.center_of_mass(peaks, plab, ids)).reshape(-1, 2)
    h = ndimage.maximum(dist, plab, ids)
    pairs = cKDTree(c).query_pairs(max(float(h.max()), float(min_separation_px)), output_type="ndarray")
    keep = np.ones(n, bool)
    if pairs.size:
        sep = np.linalg.norm(c[pairs[:, 0]] - c[pairs[:, 1]], axis=1)
        close = sep < np.maximum(np.maximum(h[pairs[:, 0]], h[pairs[:, 1]]), min_separation_px)
        a, b = pairs[close, 0], pairs[close, 1]
        weaker = np.where((h[a] < h[b]) | ((h[a] == h[b]) & (a > b)), a, b)
        keep[weaker] = False
    if keep.sum() <= 1:
        return ndimage.label(mask)
    remap = np.zeros(n + 1, np.int32)
    remap[ids[keep]] = np.arange(1, keep.sum() + 1)
    markers = remap[plab].astype(np.int32)
    m = int(keep.sum())
    level = np.round(65535 * (1.0 - dist / max(float(dist.max()), 1e-12))).astype(np.uint16)
    markers[~mask] = -1  # background is its own basin
    lab = ndimage.watershed_ift(level, markers)
    lab[~mask | (lab < 0)] = 0
    # parts the watershed could not reach keep their own connected-component label
    rest, r = ndimage.label(mask & (lab == 0))
    lab = np.where(rest > 0, rest + m, lab)
    return lab, m + r


def _dedupe(uv, score, radius_px=1.0):
    """Indices of points kept when, of any two closer than ``radius_px``, the lower score goes."""
    from scipy.spatial import cKDTree

    keep = np.ones(uv.shape[0], bool)
    if uv.shape[0] > 1:
        pairs = cKDTree(uv).query_pairs(radius_px, output_type="ndarray")
        if pairs.size:
            a, b = pairs[:, 0], pairs[:, 1]
            keep[np.where((score[a] < score[b]) | ((score[a] == score[b]) & (a > b)), a, b)] = False
    return np.nonzero(keep)[0]


def _plane_silhouettes(trans_k, threshold, seeds, grad_k, rows, cols):
    """In one plane: the connected dark silhouette (darkness > threshold) holding each seed
    pixel. Per seed (rows of the returned (10, N) array): mean Tenengrad over the
    silhouette's edge pixels (the edge sharpness), area, darkness sum, darkness-weighted
    first moments, area first and second moments."""
    from scipy import ndimage

    dark = np.clip(1.0 - trans_k, 0.0, 1.0)
    mask = dark > threshold
    comp, _ = ndimage.label(mask)
    cid = comp[seeds[:, 0], seeds[:, 1]]
    out = np.zeros((10, seeds.shape[0]))
    ok = cid > 0
    if not ok.any():
        return out
    c = cid[ok]
    edge = np.where(mask & ~ndimage.binary_erosion(mask), comp, 0)
    n_edge = ndimage.sum_labels(edge > 0, edge, c)
    out[0, ok] = np.where(n_edge > 0, ndimage.sum_labels(grad_k, edge, c) / np.maximum(n_edge, 1), 0.0)
    out[1, ok] = ndimage.sum_labels(mask, comp, c)
    out[2, ok] = ndimage.sum_labels(dark, comp, c)
    out[3, ok] = ndimage.sum_labels(dark * cols, comp, c)
    out[4, ok] = ndimage.sum_labels(dark * rows, comp, c)
    m = mask.astype(np.float64)
    out[5, ok] = ndimage.sum_labels(m * cols, comp, c)
    out[6, ok] = ndimage.sum_labels(m * rows, comp, c)
    out[7, ok] = ndimage.sum_labels(m * cols * cols, comp, c)
    out[8, ok] = ndimage.sum_labels(m * rows * rows, comp, c)
    out[9, ok] = ndimage.sum_labels(m * cols * rows, comp, c)
    return out


def hybrid_detect(stack, z_mm, *, background=None, threshold: float = 0.5, min_area_px: int = 2,
                  split_touching: bool = True, min_separation_px: int = 2, min_peak_darkness: float = 0.0,
                  dewarp: Dewarp | None = None, pixel_to_stack=None) -> BacklitDetections:
    """Detect, locate and size backlit particles in a focal stack (see the module notes).

    Parameters
    ----------
    stack : (n_z, H, W) refocused intensities; z_mm : (n_z,) their depths (monotonic).
    background : the same stack of the empty (white) scene, or a scalar; pixels it leaves
        at 0 (no views) count as background. Default: the stack's median.
    threshold : darkness (1 - transmittance) a particle's pixels must exceed.
    split_touching : separate touching silhouettes of the minimum map by a
        distance-transform watershed (markers at least ``min_separation_px`` apart).
    min_peak_darkness : keep only regions whose darkest pixel exceeds this (holograms: an
        opaque particle in focus is nearly black).
    dewarp, pixel_to_stack : a :class:`Dewarp` for world positions and diameters, and the
        map from stack indices to the pixel coordinates it was fitted in.

    Notes
    -----
    Steps: the minimum-intensity map is segmented (regions whose centroid falls outside
    them, the annular dark fringes of defocused planes, are dropped); each region's
    centroid seeds, in every plane, the connected dark silhouette holding it; the depth is
    the plane of the largest edge sharpness (mean Tenengrad over that silhouette's edge
    pixels), refined by a 3-point Gaussian between planes; centre (darkness-weighted),
    area, equivalent diameter and aspect ratio come from the silhouette in that plane.
    """
    from scipy import ndimage

    from mitpiv.analysis.particles import gauss3_offset as _gauss3

    # The stack (and a background stack) are read one plane at a time, in float64 per plane:
    # a memory-mapped stack (lightfield.focal_stack(out=...)) never has to fit in memory.
    st = stack if isinstance(stack, np.ndarray) else np.asarray(stack)
    z = np.asarray(z_mm, dtype=np.float64).reshape(-1)
    if st.ndim != 3 or st.shape[0] != z.size or z.size < 1:
        raise ConfigError(f"hybrid_detect: stack must be (n_z, H, W) with one depth per plane; got stack {st.shape} "
                          f"and {z.size} depths.")
    if z.size > 1 and not (np.all(np.diff(z) > 0) or np.all(np.diff(z) < 0)):
        raise ConfigError("hybrid_detect: z_mm must be strictly monotonic.")
    if not (0.0 < threshold < 1.0):
        raise ConfigError(f"hybrid_detect: threshold must be a darkness in (0, 1), got {threshold!r}.")
    bg = np.median(st) if background is None else (background if isinstance(background, np.ndarray)
                                                   else np.asarray(background, dtype=np.float64))
    bg = np.broadcast_to(bg, st.shape)
    bg_max = float(np.max(bg))

    def trans_plane(k):
        """Transmittance of plane k (float64): the plane over the background where it is lit."""
        s_k = np.asarray(st[k], dtype=np.float64)
        b_k = np.asarray(bg[k], dtype=np.float64)
        cov = b_k > 1e-6 * bg_max if bg_max > 0 else np.zeros(b_k.shape, bool)
        return np.where(cov, s_k / np.where(cov, b_k, 1.0), 1.0), cov, s_k

    t_min = None
    any_covered = False
    for k in range(z.size):
        t_k, cov, s_k = trans_plane(k)
        if not np.all(np.isfinite(s_k)):
            raise ConfigError("hybrid_detect: the stack holds NaN or infinite values.")
        any_covered |= bool(cov.any())
        t_min = t_k if t_min is None else np.minimum(t_min, t_k)
    if not any_covered:
        raise ConfigError("hybrid_detect: the background is zero everywhere; pass the stack of the empty scene.")
    dark = np.clip(1.0 - t_min, 0.0, 1.0)
    mask = dark > threshold
    labels, n = _split_touching(mask, min_separation_px) if split_touching else ndimage.label(mask)
    empty = np.zeros(0)
    nothing = BacklitDetections(np.zeros((0, 2)), empty, empty, empty, empty, empty,
                                np.zeros((0, 3)) if dewarp else None, empty if dewarp else None)
    if n == 0:
        return nothing
    ids = np.arange(1, n + 1)
    area = ndimage.sum_labels(mask, labels, ids)
    border = np.zeros(n + 1, bool)
    border[np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))] = True
    keep = (area >= int(min_area_px)) & ~border[1:]  # regions cut by the stack's edge are not measurable
    if min_peak_darkness > 0:
        keep &= ndimage.maximum(dark, labels, ids) >= min_peak_darkness
    ids = ids[keep]
    if ids.size == 0:
        return nothing
    rows, cols = np.indices(dark.shape, dtype=np.float64)
    w = ndimage.sum_labels(dark, labels, ids)
    cu = ndimage.sum_labels(dark * cols, labels, ids) / w
    cv = ndimage.sum_labels(dark * rows, labels, ids) / w
    seeds = np.column_stack([np.clip(np.rint(cv).astype(int), 0, dark.shape[0] - 1),
                             np.clip(np.rint(cu).astype(int), 0, dark.shape[1] - 1)])
    own = labels[seeds[:, 0], seeds[:, 1]] == ids  # an annulus has its centroid in its hole
    ids, seeds = ids[own], seeds[own]
    if ids.size == 0:
        return nothing
    per = np.stack([_plane_silhouettes(t_k, threshold, seeds, tenengrad(t_k), rows, cols)
                    for t_k in (trans_plane(k)[0] for k in range(z.size))])  # (n_z, 10, N)
    sharp = per[:, 0, :]
    found = sharp.max(axis=0) > 0
    k = np.argmax(sharp, axis=0)
    r = np.arange(ids.size)
    zi = k.astype(np.float64)
    if z.size >= 3:
        kc = np.clip(k, 1, z.size - 2)
        off = _gauss3(sharp[kc - 1, r], sharp[kc, r], sharp[kc + 1, r])
        zi = k + np.where(k == kc, off, 0.0)  # a maximum at the stack's end stays there
    zs = np.interp(zi, np.arange(z.size), z)
    a_, w_, su, sv, au, av, suu, svv, suv = (per[k, j, r] for j in range(1, 10))
    sel = found & (a_ >= int(min_area_px))
    a_, w_, su, sv, au, av, suu, svv, suv, zs = (x[sel] for x in (a_, w_, su, sv, au, av, suu, svv, suv, zs))
    cu, cv = su / w_, sv / w_
    # several minimum-map regions (fragments of one particle's fringes) can seed the same
    # silhouette: within one pixel in the plane, keep the sharpest
    best = sharp.max(axis=0)[sel]
    uniq = _dedupe(np.column_stack([cu, cv]), best)
    a_, w_, au, av, suu, svv, suv, zs, cu, cv = (x[uniq] for x in (a_, w_, au, av, suu, svv, suv, zs, cu, cv))
    seed_sel = seeds[sel][uniq]
    mu_u, mu_v = au / a_, av / a_
    cuu = np.maximum(suu / a_ - mu_u**2, 0.0)
    cvv = np.maximum(svv / a_ - mu_v**2, 0.0)
    cuv = suv / a_ - mu_u * mu_v
    tr, det = cuu + cvv, cuu * cvv - cuv**2
    disc = np.sqrt(np.maximum(tr**2 / 4 - det, 0.0))
    l1, l2 = tr / 2 + disc, np.maximum(tr / 2 - disc, 1e-12)
    aspect = np.sqrt(np.maximum(l1, 1e-12) / l2)
    diam = 2.0 * np.sqrt(a_ / np.pi)
    det_ = BacklitDetections(np.column_stack([cu, cv]), zs, a_, diam, aspect, dark[seed_sel[:, 0], seed_sel[:, 1]])
    if dewarp is not None:
        uv = det_.uv_px if pixel_to_stack is None else np.column_stack(pixel_to_stack(cu, cv))
        uvz = np.column_stack([uv, zs])
        det_.positions_mm = dewarp(uvz)
        uv1 = np.column_stack(pixel_to_stack(cu + 1.0, cv)) if pixel_to_stack is not None else uv + [1.0, 0.0]
        px = np.linalg.norm(uv1 - uv, axis=1)  # stack pixel in dewarp pixels
        det_.diameters_mm = diam * px * dewarp.mm_per_px(uvz)
    return det_


def _lateral(axis, owner: str):
    """The unit viewing ``axis`` (3,) and the projection onto the plane normal to it: a
    function of (N, 3) points (the depth along the axis removed), for matching with the
    depth left free."""
    ax = np.asarray(axis, dtype=np.float64).reshape(3)
    if not (np.all(np.isfinite(ax)) and np.linalg.norm(ax) > 0):
        raise ConfigError(f"{owner}: 'axis' must be a non-zero direction (3,), got {axis!r}.")
    ax = ax / np.linalg.norm(ax)
    return ax, lambda p: p - np.outer(p @ ax, ax)


def match_frames(a: BacklitDetections, b: BacklitDetections, *, dt_s: float, radius_mm: float,
                 predictor_mm=None, axis=None) -> dict:
    """Nearest-neighbour (optimal one-to-one) matching of world positions between two frames.

    Parameters
    ----------
    predictor_mm : expected displacement (3,) or (N_a, 3) added to frame a before matching.
    axis : a viewing direction (3,): match within ``radius_mm`` in the plane normal to it,
        leaving the depth free (the uncertain coordinate of a single-view technique, whose
        error would otherwise break pairs: DIH depth errors reach several mm); None matches
        in 3D.

    Notes
    -----
    Returns ``pairs`` (K, 2), ``velocity_mm_s`` (K, 3, depth included) and the matched
    positions of a.
    """
    from mitpiv.analysis.particles import assign

    if a.positions_mm is None or b.positions_mm is None:
        raise ConfigError("match_frames: both frames need world positions; detect with a dewarp.")
    dt_s = check_positive("dt_s", dt_s, owner="match_frames", unit="s")
    radius_mm = check_positive("radius_mm", radius_mm, owner="match_frames", unit="mm")
    pa = a.positions_mm + (0.0 if predictor_mm is None else np.asarray(predictor_mm, dtype=np.float64))
    pb = b.positions_mm
    if axis is not None:
        _, lateral = _lateral(axis, "match_frames")
        pa, pb = lateral(pa), lateral(pb)
    pairs = assign(pa, pb, radius_mm)
    vel = (b.positions_mm[pairs[:, 1]] - a.positions_mm[pairs[:, 0]]) / dt_s
    return {"pairs": pairs, "velocity_mm_s": vel, "positions_mm": a.positions_mm[pairs[:, 0]]}


def evaluate_detections(det: BacklitDetections, truth_mm, truth_diameters_mm, *, radius_diameters: float = 1.5,
                        axis=(0.0, 0.0, 1.0), depth_tiebreak: bool = True) -> dict:
    """Detections against the truth: detected fraction, in-plane and depth errors in
    particle diameters, size error. A detection matches a truth particle within
    ``radius_diameters`` of its diameter in the plane normal to the viewing ``axis``
    (depth is left free: it is the uncertain coordinate); depth along ``axis``.

    depth_tiebreak : where particles overlap in the image (several truth particles within
        the radius of a detection, as in a dense spray seen along the beam), choose among
        them by depth too (:func:`~mitpiv.analysis.particles.assign`'s ``tiebreak``): the
        depth never rejects a pair, it only picks which of the overlapping particles a
        detection is. False pairs by the image plane alone (a detection of the front
        particle may then be scored against the one behind it).
    """
    from mitpiv.analysis.particles import assign

    if det.positions_mm is None:
        raise ConfigError("evaluate_detections: detect with a dewarp to get world positions.")
    t = np.asarray(truth_mm, dtype=np.float64).reshape(-1, 3)
    d = np.broadcast_to(np.asarray(truth_diameters_mm, dtype=np.float64), (t.shape[0],))
    ax, lateral = _lateral(axis, "evaluate_detections")
    # match in the plane, scaled by the truth diameter: distance / d_truth <= radius
    scale = np.median(d) if d.size else 1.0
    tb = ((det.positions_mm @ ax)[:, None] / scale, (t @ ax)[:, None] / scale) if depth_tiebreak else None
    pairs = assign(lateral(det.positions_mm) / scale, lateral(t) / scale, radius_diameters, tiebreak=tb)
    ok = np.linalg.norm(lateral(det.positions_mm[pairs[:, 0]] - t[pairs[:, 1]]), axis=1) <= radius_diameters * d[pairs[:, 1]]
    pairs = pairs[ok]
    e = det.positions_mm[pairs[:, 0]] - t[pairs[:, 1]]
    dt = d[pairs[:, 1]]
    depth = (e @ ax) / dt
    lat = np.linalg.norm(lateral(e), axis=1) / dt
    size = det.diameters_mm[pairs[:, 0]] - dt
    nan = float("nan")
    return {"n_truth": int(t.shape[0]), "n_found": len(det), "n_matched": int(pairs.shape[0]),
            "detected_fraction": pairs.shape[0] / t.shape[0] if t.shape[0] else nan,
            "depth_rms_diameters": float(np.sqrt(np.mean(depth**2))) if depth.size else nan,
            "depth_bias_diameters": float(depth.mean()) if depth.size else nan,
            "depth_median_abs_diameters": float(np.median(np.abs(depth))) if depth.size else nan,
            "lateral_rms_diameters": float(np.sqrt(np.mean(lat**2))) if lat.size else nan,
            "size_bias_mm": float(size.mean()) if size.size else nan,
            "size_rms_mm": float(np.sqrt(np.mean(size**2))) if size.size else nan,
            "pairs": pairs, "depth_error_diameters": depth, "size_error_mm": size}
