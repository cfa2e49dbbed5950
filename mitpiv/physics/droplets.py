"""Particle fields for backlit imaging: secondary droplets of a drop impact and a sparse
pellet field. Positions in world mm, diameters in mm, velocities in mm/s; the impact's
surface normal is +y (image "up" for a camera on the z axis), so depth is z.
"""

from __future__ import annotations

import numpy as np

from mitpiv.errors import ConfigError, check_positive


def _non_overlapping(p, d, gap_mm):
    """Mask of a greedy (index-order) maximal subset of spheres with no two closer than
    (d_i + d_j)/2 + gap: in rounds, a sphere with no clashing lower-index candidate is
    kept and its clashing neighbours are removed (vectorised per round)."""
    from scipy.spatial import cKDTree

    n = p.shape[0]
    keep = np.zeros(n, bool)
    if n < 2:
        keep[:] = True
        return keep
    pairs = cKDTree(p).query_pairs(float(d.max()) + gap_mm, output_type="ndarray")
    if pairs.size:
        dist = np.linalg.norm(p[pairs[:, 0]] - p[pairs[:, 1]], axis=1)
        pairs = np.sort(pairs[dist < 0.5 * (d[pairs[:, 0]] + d[pairs[:, 1]]) + gap_mm], axis=1)
    alive = np.ones(n, bool)
    while alive.any():
        live = pairs[alive[pairs[:, 0]] & alive[pairs[:, 1]]] if pairs.size else pairs
        blocked = np.zeros(n, bool)
        if live.size:
            blocked[live[:, 1]] = True
        acc = alive & ~blocked
        keep |= acc
        alive &= ~acc
        if live.size:
            alive[live[acc[live[:, 0]], 1]] = False
            alive[live[acc[live[:, 1]], 0]] = False
    return keep


def drop_impact_field(n: int, *, crown_radius_mm: float = 1.0, crown_height_mm: float = 1.0,
                      median_diameter_mm: float = 0.12, sigma_ln: float = 0.6, d_min_mm: float = 0.05,
                      d_max_mm: float = 0.5, speed_mm_s: float = 1500.0, seed: int = 0) -> dict:
    """Secondary droplets ejected from the rim of a drop-impact crown (a Weber-number style
    splash): azimuth uniform about the impact axis (+y), radius ~ crown_radius, height up to
    crown_height; log-normal diameters clipped to [d_min, d_max]; velocities radially
    outward and upward at about ``speed_mm_s``. Overlapping droplets are removed, so fewer
    than ``n`` may be returned.

    Parameters
    ----------
    n : int
        Number of droplets drawn (>= 1) before overlapping ones are removed.
    crown_radius_mm : float
        Crown radius [mm] (> 0): each droplet's distance from the impact axis is uniform in
        0.8-1.6 times it.
    crown_height_mm : float
        Crown height [mm] (> 0): each droplet's height above the impact point (along +y) is
        uniform in 0.1-1 times it.
    median_diameter_mm : float
        Median of the log-normal droplet diameters [mm] (> 0).
    sigma_ln : float
        Standard deviation of the natural log of the diameter (dimensionless).
    d_min_mm, d_max_mm : float
        The diameters are clipped to [d_min_mm, d_max_mm] [mm] (> 0, d_min_mm < d_max_mm).
    speed_mm_s : float
        Typical droplet speed [mm/s]: each speed is uniform in 0.6-1.4 times it, radially
        outward and upward at an elevation of 15-60 degrees above the xz plane.
    seed : int
        Seed of the random draws.

    Returns
    -------
    dict
        ``positions_mm`` (M, 3), ``diameters_mm`` (M,) and ``velocities_mm_s`` (M, 3), M <= n.
    """
    if int(n) != n or n < 1:
        raise ConfigError(f"drop_impact_field: n must be a positive integer, got {n!r}.")
    for k, v in (("crown_radius_mm", crown_radius_mm), ("crown_height_mm", crown_height_mm),
                 ("median_diameter_mm", median_diameter_mm), ("d_min_mm", d_min_mm), ("d_max_mm", d_max_mm)):
        check_positive(k, v, owner="drop_impact_field", unit="mm")
    if d_min_mm >= d_max_mm:
        raise ConfigError(f"drop_impact_field: d_min_mm ({d_min_mm}) must be below d_max_mm ({d_max_mm}).")
    rng = np.random.default_rng(seed)
    phi = rng.uniform(0, 2 * np.pi, n)
    r = crown_radius_mm * rng.uniform(0.8, 1.6, n)
    h = crown_height_mm * rng.uniform(0.1, 1.0, n)
    p = np.column_stack([r * np.cos(phi), h, r * np.sin(phi)])
    d = np.clip(median_diameter_mm * np.exp(sigma_ln * rng.standard_normal(n)), d_min_mm, d_max_mm)
    elev = rng.uniform(np.radians(15), np.radians(60), n)
    s = speed_mm_s * rng.uniform(0.6, 1.4, n)
    v = np.column_stack([s * np.cos(elev) * np.cos(phi), s * np.sin(elev), s * np.cos(elev) * np.sin(phi)])
    keep = _non_overlapping(p, d, 0.0)
    return {"positions_mm": p[keep], "diameters_mm": d[keep], "velocities_mm_s": v[keep]}


def pellet_field(n: int, *, diameter_mm: float = 2.0, box_mm=((-5, 5), (-5, 5), (-5, 5)),
                 velocity_mm_s=(0.0, 0.0, 0.0), spread_mm_s: float = 0.0, min_gap_mm: float = 0.5,
                 view_axis=None, seed: int = 0) -> dict:
    """A sparse field of equal spheres (shotgun pellets) uniformly in ``box_mm`` ((x0, x1),
    (y0, y1), (z0, z1)), at least ``min_gap_mm`` apart, moving at ``velocity_mm_s`` with a
    Gaussian spread per component. With ``view_axis`` the gap is enforced between the
    projections along that axis, so no two silhouettes overlap in a camera looking along it.

    Parameters
    ----------
    n : int
        Number of pellets wanted (>= 1); a crowded box may give fewer.
    diameter_mm : float
        Diameter of every pellet [mm] (> 0).
    box_mm : ((float, float), (float, float), (float, float))
        The box the centres are drawn in, ((x0, x1), (y0, y1), (z0, z1)) [mm].
    velocity_mm_s : (float, float, float)
        Mean velocity of the pellets [mm/s].
    spread_mm_s : float
        Standard deviation of the Gaussian spread added to each velocity component [mm/s].
    min_gap_mm : float
        Smallest gap between two pellets' surfaces [mm].
    view_axis : (float, float, float), optional
        A viewing direction: the gap is enforced between the pellets' projections along it
        (no two silhouettes overlap); default None, the gap in 3D.
    seed : int
        Seed of the random draws.

    Returns
    -------
    dict
        ``positions_mm`` (M, 3), ``diameters_mm`` (M,) and ``velocities_mm_s`` (M, 3), M <= n.
    """
    if int(n) != n or n < 1:
        raise ConfigError(f"pellet_field: n must be a positive integer, got {n!r}.")
    diameter_mm = check_positive("diameter_mm", diameter_mm, owner="pellet_field", unit="mm")
    box = np.asarray(box_mm, dtype=np.float64)
    if box.shape != (3, 2) or np.any(box[:, 1] <= box[:, 0]):
        raise ConfigError(f"pellet_field: box_mm must be ((x0, x1), (y0, y1), (z0, z1)) with x0 < x1..., got {box_mm!r}.")
    rng = np.random.default_rng(seed)
    m = 20 * int(n)  # candidates; clashing ones are dropped, so a crowded box may return fewer than n
    p = rng.uniform(box[:, 0], box[:, 1], (m, 3))
    d = np.full(m, diameter_mm)
    q = p
    if view_axis is not None:
        a = np.asarray(view_axis, dtype=np.float64)
        a = a / np.linalg.norm(a)
        q = p - np.outer(p @ a, a)
    keep = np.nonzero(_non_overlapping(q, d, float(min_gap_mm)))[0][: int(n)]
    v = np.asarray(velocity_mm_s, dtype=np.float64) + spread_mm_s * rng.standard_normal((keep.size, 3))
    return {"positions_mm": p[keep], "diameters_mm": d[keep], "velocities_mm_s": v}
