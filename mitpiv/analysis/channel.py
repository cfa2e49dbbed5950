"""Wall-unit statistics of measured (or true) velocity fields in a channel, binned in
wall-normal slabs, and their percentage errors against a reference.

The quantities follow the replicated paper (channel-tomo, Sect. 3): the mean streamwise
velocity U+ and the r.m.s. fluctuations, here named by role: ``u_rms`` (streamwise),
``v_rms`` (wall-normal) and ``w_rms`` (spanwise), plus ``uv`` = <u'v'>+ (the paper writes
v for spanwise and w for wall-normal). The mean and fluctuations of a slab are taken over
all its vectors (the paper's single snapshot: spatial averages in the wall-parallel
plane). The fair reference for a PIV measurement is the same statistic of the true field
averaged over each interrogation window (:meth:`mitpiv.physics.flows.Channel.window_average`).
"""

from __future__ import annotations

import numpy as np

from mitpiv.errors import ConfigError

__all__ = ["STAT_NAMES", "wall_statistics", "field_wall_statistics", "statistics_error_percent"]

#: The statistics returned per slab, in wall units.
STAT_NAMES = ("U", "u_rms", "v_rms", "w_rms", "uv")


def wall_statistics(points_mm, velocity_mm_s, channel, *, edges_y_plus=None, mask=None) -> dict:
    """Statistics in wall units of velocities at points, binned by wall distance.

    Parameters
    ----------
    points_mm : (N, 3) array
        Positions [mm] (world frame).
    velocity_mm_s : (N, 3) array
        Velocities [mm/s] (world frame).
    channel : mitpiv.physics.flows.Channel
        Supplies the frame (streamwise, wall-normal, spanwise), the wall position and the
        wall units (``friction_velocity_mm_s``, ``viscous_length_mm``).
    edges_y_plus : 1-D array, optional
        Slab edges in y+. Default: one slab per distinct wall distance of the points
        (rounded to 1e-6 wall units), e.g. one per vector layer of a PIV field.
    mask : (N,) bool array, optional
        Vectors to use (e.g. valid and not outliers).

    Returns
    -------
    dict
        ``y_plus`` (slab centres: mean y+ of its points), ``n`` (vectors per slab) and
        ``U``, ``u_rms``, ``v_rms``, ``w_rms``, ``uv`` (1-D arrays, wall units); slabs
        without vectors are dropped.
    """
    p = np.asarray(points_mm, dtype=float).reshape(-1, 3)
    u = np.asarray(velocity_mm_s, dtype=float).reshape(-1, 3)
    if p.shape != u.shape:
        raise ConfigError(f"wall_statistics: points_mm {p.shape} and velocity_mm_s {u.shape} must match.")
    keep = np.all(np.isfinite(u), axis=1)
    if mask is not None:
        keep &= np.asarray(mask, dtype=bool).reshape(-1)
    x = channel.to_plus(p[keep])
    vel = (u[keep] @ channel.frame.T) / channel.friction_velocity_mm_s  # local (stream, normal, span)
    y = x[:, 1]
    if edges_y_plus is None:
        _, idx = np.unique(np.round(y, 6), return_inverse=True)
        nb = int(idx.max()) + 1 if idx.size else 0
    else:
        e = np.asarray(edges_y_plus, dtype=float)
        if e.ndim != 1 or e.size < 2 or np.any(np.diff(e) <= 0):
            raise ConfigError(f"wall_statistics: edges_y_plus must be >= 2 increasing values, got {e.tolist()}.")
        idx = np.searchsorted(e, y, side="right") - 1
        inside = (idx >= 0) & (idx < e.size - 1)
        idx, y, vel = idx[inside], y[inside], vel[inside]
        nb = e.size - 1
    n = np.bincount(idx, minlength=nb).astype(float)
    has = n > 0
    ns = np.where(has, n, 1.0)

    def mean(a):
        return np.bincount(idx, weights=a, minlength=nb) / ns

    m = np.stack([mean(vel[:, k]) for k in range(3)], axis=1)
    f = vel - m[idx]
    out = {"y_plus": mean(y), "n": n.astype(int), "U": m[:, 0],
           "u_rms": np.sqrt(mean(f[:, 0] ** 2)), "v_rms": np.sqrt(mean(f[:, 1] ** 2)),
           "w_rms": np.sqrt(mean(f[:, 2] ** 2)), "uv": mean(f[:, 0] * f[:, 1])}
    return {k: v[has] for k, v in out.items()}


def field_wall_statistics(field, channel, *, dt_s: float | None = None, include_outliers: bool = True,
                          edges_y_plus=None) -> dict:
    """:func:`wall_statistics` of a :class:`~mitpiv.analysis.piv3d.VectorField` (its valid
    vectors; outliers too unless ``include_outliers`` is False). A displacement field (mm)
    is divided by ``dt_s`` (default the field's own)."""
    dt = field.dt_s if dt_s is None else dt_s
    vel = np.stack([field.u, field.v, field.w], axis=-1).reshape(-1, 3)
    if field.dt_s is None:
        if dt is None:
            raise ConfigError("field_wall_statistics: the field holds displacements; give dt_s [s].")
        vel = vel / float(dt)
    use = field.valid.copy()
    if not include_outliers:
        use &= ~field.outlier
    return wall_statistics(field.points_mm().reshape(-1, 3), vel, channel, edges_y_plus=edges_y_plus,
                           mask=use.reshape(-1))


def statistics_error_percent(measured: dict, reference: dict, *, band_y_plus=(100.0, 200.0)) -> dict:
    """Percentage error of each statistic in a wall-normal band: the mean over the slabs with
    ``band[0] < y+ < band[1]`` of ``100 |measured - reference| / |reference|`` (the paper's
    Table 1 quantity, whose exact averaging it does not state). Slabs are matched by their
    position in the two dicts, which must share ``y_plus`` (to 1e-6)."""
    ym, yr = np.asarray(measured["y_plus"]), np.asarray(reference["y_plus"])
    if ym.shape != yr.shape or np.any(np.abs(ym - yr) > 1e-6):
        raise ConfigError("statistics_error_percent: the two statistics must have the same slabs (y_plus); "
                          "compute both from the same vector positions.")
    sel = (ym > band_y_plus[0]) & (ym < band_y_plus[1])
    if not sel.any():
        raise ConfigError(f"statistics_error_percent: no slab lies in {band_y_plus} (slabs at y+ {ym.tolist()}).")
    return {k: float(np.mean(100 * np.abs(np.asarray(measured[k])[sel] - np.asarray(reference[k])[sel])
                             / np.abs(np.asarray(reference[k])[sel]))) for k in STAT_NAMES}
