"""Reconstruction quality: Q, zero-mean Q*, rank correlation Q', per-plane SNR and its
normalised form nSNR, and the true intensity volume they compare against.

The definitions follow the SAPIV aberration study (D. M. Kubaczyk, "Assessment of radial
image distortion and spherical aberration on three-dimensional synthetic aperture particle
image velocimetry measurements", S.M. thesis, MIT; chapter 4, eqs. 4.1-4.4), with ``V_R`` the reconstructed and ``V_S`` the synthetic (true)
volume, sums over all voxels ``(X, Y, Z)``:

* ``Q`` (eq. 4.1; Elsinga et al. 2006)::

      Q = sum V_R V_S / sqrt(sum V_R^2 * sum V_S^2)

  At dense seeding a reconstruction full of ghost particles still scores high because
  both volumes are mostly positive where particles are: Q rewards any overlap.
* ``Q*``: the same with both volumes' means removed (the Pearson correlation), which does
  not reward a uniformly bright (ghost-filled) volume.
* ``Q'`` (eq. 4.2): Q of the rank volumes ``G_R``, ``G_S`` (each voxel's intensity replaced
  by its rank 1..N within its own volume, in increasing order, tied voxels given the
  average of the ranks they span), in the same uncentred form::

      Q' = sum G_R G_S / sqrt(sum G_R^2 * sum G_S^2)

  ``rank_correlation(..., centred=True)`` is Spearman's coefficient instead (the
  centred, Pearson form on the same ranks). Both are invariant to monotonic maps of
  either volume. Because ranks are positive, eq. 4.2 has a high floor on sparse volumes
  (the study reports values above 0.97): see :func:`rank_correlation`.
* ``SNR`` (eq. 4.3), :func:`plane_snr`::

      SNR(V_R) = 1/N sum_j max(I_j) / (mu(I_j) + sigma(I_j))

  over the ``N`` planes ``I_j`` of the volume, ``mu`` and ``sigma`` the mean and standard
  deviation of the normal fit (maximum likelihood) of the plane's intensity histogram.
* ``nSNR`` (eq. 4.4), :func:`normalised_snr` / ``plane_snr(reference=)``: the SNR of a
  configuration divided by the SNR of the reference configuration at the same seeding
  density (the study: zero distortion ``D = 0``)::

      nSNR(V_R(D, gamma), V_R(D=0, gamma)) = SNR(V_R(D, gamma)) / SNR(V_R(D=0, gamma))

  It needs the reference configuration's reconstruction (or its SNR), which a
  volume-versus-truth evaluation does not have: a study computes it across its points.

Every metric is computed in float64. A volume with no variation (all zero for Q, constant
for Q* and Spearman's Q') has nothing to correlate: those return 0.0 for it, never NaN.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from scipy.special import erf

from mitpiv.errors import ConfigError
from mitpiv.grid import VoxelGrid

__all__ = ["quality_q", "quality_q_zero_mean", "rank_correlation", "rank_correlations", "average_ranks", "plane_snr", "normalised_snr", "snr_from_fits",
           "truth_volume", "occupancy_volume", "sphere_volume"]


def _pair(rec, truth, what):
    a = np.asarray(rec, dtype=np.float64)
    b = np.asarray(truth, dtype=np.float64)
    if a.shape != b.shape:
        raise ConfigError(f"{what}: 'rec' has shape {a.shape} but 'truth' has shape {b.shape}; both must be on the same grid.")
    if a.size == 0:
        raise ConfigError(f"{what}: the volumes are empty (shape {a.shape}).")
    for name, v in (("rec", a), ("truth", b)):
        if not np.all(np.isfinite(v)):
            raise ConfigError(f"{what}: '{name}' contains NaN or infinite values ({int(np.sum(~np.isfinite(v)))} voxels).")
    return a.ravel(), b.ravel()


def _correlation(a, b) -> float:
    den = np.sqrt(np.dot(a, a) * np.dot(b, b))
    return float(np.dot(a, b) / den) if den > 0 else 0.0


def quality_q(rec, truth) -> float:
    """Reconstruction quality ``Q`` (normalised correlation) of ``rec`` against ``truth``.

    Parameters
    ----------
    rec, truth : array, same shape
        Reconstructed and true intensity volumes (any shape).

    Returns
    -------
    float in [-1, 1] (in [0, 1] for non-negative volumes); 0.0 when either volume is zero.
    """
    a, b = _pair(rec, truth, "quality_q")
    return _correlation(a, b)


def quality_q_zero_mean(rec, truth) -> float:
    """Zero-mean reconstruction quality ``Q*`` (Pearson correlation of the voxel values).

    Returns 0.0 when either volume is constant.
    """
    a, b = _pair(rec, truth, "quality_q_zero_mean")
    return _correlation(a - a.mean(), b - b.mean())


def rank_correlation(rec, truth, *, centred: bool = False) -> float:
    """Rank correlation ``Q'`` of ``rec`` against ``truth``: eq. 4.2 of the SAPIV study.

    Each volume's voxels are replaced by their ranks within that volume (1 for the
    smallest value; tied voxels, e.g. the many zeros, get the average of the ranks they
    span: ``scipy.stats.rankdata``), and the rank volumes ``G_R``, ``G_S`` are correlated
    as in Q (eq. 4.1), uncentred::

        Q' = sum G_R G_S / sqrt(sum G_R^2 * sum G_S^2)        (eq. 4.2)

    Parameters
    ----------
    rec, truth : array, same shape
        Reconstructed and true intensity volumes (any shape).
    centred : bool
        False (default): eq. 4.2. True: Spearman's coefficient, the Pearson correlation of
        the same ranks (``G - mean(G)``); 0.0 when either volume is constant.

    Returns
    -------
    float
        Eq. 4.2: in (0, 1]. Ranks are positive, so eq. 4.2 has a floor: a constant (e.g.
        all-zero) reconstruction scores ``sum G_S / sqrt(N sum G_S^2)``, which for a truth
        whose voxels are a fraction ``z`` of tied zeros (the rest distinct) tends, for
        large N, to ``sqrt(3 / (4 - z^3))``: 0.87 without ties, 0.96 at z = 0.9, 0.995 at
        z = 0.99. Read differences between configurations, not the level. Spearman: in
        [-1, 1].
    """
    q, spearman = rank_correlations(rec, truth)
    return spearman if centred else q


def rank_correlations(rec, truth) -> tuple[float, float]:
    """``(Q' of eq. 4.2, Spearman's coefficient)`` of :func:`rank_correlation` from one
    ranking of each volume (ranking is the cost: a sort of every voxel). A float32 volume
    is ranked in float32 (the same order and ties as its float64 values, a faster sort)."""
    a, b = _pair(rec, truth, "rank_correlation")
    ra, rb = (average_ranks(x if np.asarray(x).dtype == np.float32 else y) for x, y in ((rec, a), (truth, b)))
    return _correlation(ra, rb), _correlation(ra - ra.mean(), rb - rb.mean())


def average_ranks(x) -> np.ndarray:
    """Ranks 1..N of ``x`` (1-D), tied values sharing the average of the ranks they span:
    ``scipy.stats.rankdata(x, method="average")``, float64.

    A volume is mostly one tied value, its minimum (the zeros outside particles): those
    voxels take the rank ``(n_min + 1) / 2`` without being sorted, and only the rest is
    sorted (their ranks start after ``n_min``). On the demo's 12.8 M-voxel truth (73 % zeros)
    that is 2.7x faster than ``rankdata`` (0.82 s vs 2.24 s). A float32 volume (a
    reconstruction) is sorted as packed 64-bit keys (:func:`_argsort_float32`): the demo's
    MART volume, 12.8 M voxels and no zeros, ranks in 0.87 s against 1.6 s for ``argsort``
    of its float64 values and 3.5 s for ``rankdata``."""
    x = np.asarray(x)
    x = (x if x.dtype == np.float32 else x.astype(np.float64)).ravel()
    n = x.size
    lo = x.min() if n else 0.0
    rest = np.flatnonzero(x != lo)
    n_min = n - rest.size
    ranks = np.full(n, (n_min + 1) / 2.0)
    if rest.size:
        v = x[rest]
        order = _argsort_float32(v) if v.dtype == np.float32 else np.argsort(v)  # ties averaged below
        vs = v[order]
        start = np.flatnonzero(np.concatenate(([True], vs[1:] != vs[:-1])))  # first index of each tie group
        if start.size == vs.size:  # no ties
            ranks[rest[order]] = np.arange(n_min + 1, n + 1, dtype=np.float64)
        else:
            count = np.diff(np.append(start, vs.size))
            ranks[rest[order]] = np.repeat(n_min + start + (count + 1) / 2.0, count)
    return ranks


def _argsort_float32(v) -> np.ndarray:
    """``np.argsort`` of finite float32 values (ties in index order) as one sort of 64-bit
    keys, the value's order-preserving bit pattern above its index: NumPy sorts integers with
    SIMD but argsorts by comparison, 0.3 s against 1.2 s for the demo's 12.8 M voxels. -0.0
    is keyed as 0.0 (they are equal)."""
    bits = (v + np.float32(0.0)).view(np.uint32).astype(np.uint64)  # + 0.0 turns -0.0 into 0.0
    if v.size and v.min() < 0:
        neg = bits >= np.uint64(1 << 31)
        bits = np.where(neg, np.uint64(0xFFFFFFFF) - bits, bits | np.uint64(1 << 31))
    bits <<= np.uint64(32)
    bits |= np.arange(v.size, dtype=np.uint64)
    bits.sort()
    return (bits & np.uint64(0xFFFFFFFF)).astype(np.int64)


def _snr(volume, axis: int) -> float:
    v = np.asarray(volume, dtype=np.float64)
    if v.ndim != 3:
        raise ConfigError(f"plane_snr: 'volume' must be 3D, got shape {v.shape}.")
    if not np.all(np.isfinite(v)):
        raise ConfigError("plane_snr: 'volume' contains NaN or infinite values.")
    if axis not in (0, 1, 2, -1, -2, -3):
        raise ConfigError(f"plane_snr: 'axis' must be 0, 1 or 2, got {axis!r}.")
    planes = np.moveaxis(v, axis, 0).reshape(v.shape[axis], -1)
    mu = planes.mean(axis=1)
    sigma = planes.std(axis=1)  # normal MLE fit of the plane's histogram
    peak = planes.max(axis=1)
    den = mu + sigma
    snr = np.where(den > 0, peak / np.where(den > 0, den, 1.0), 0.0)
    return float(snr.mean())


def plane_snr(volume, *, axis: int = 0, reference=None) -> float:
    """Per-plane signal-to-noise ratio of a reconstruction, averaged over planes (eq. 4.3).

    The ratio is::

        SNR(V_R) = 1/N sum_j max(I_j) / (mu(I_j) + sigma(I_j))

    Parameters
    ----------
    volume : (n_z, n_y, n_x) array
    axis : int
        Axis the planes ``I_j`` are stacked along (0: z planes of a mitpiv volume).
    reference : volume or float, optional
        The reference configuration's volume (or its SNR): the result is then the
        normalised SNR of eq. 4.4, this volume's SNR divided by the reference's.

    Returns
    -------
    float
        Mean over planes of ``max / (mu + sigma)``, ``mu`` and ``sigma`` the mean and
        standard deviation of the plane's normal fit (a plane with ``mu + sigma = 0``, all
        zero, contributes 0); or the ratio to the reference.
    """
    s = _snr(volume, axis)
    if reference is None:
        return s
    ref = float(reference) if np.ndim(reference) == 0 else _snr(reference, axis)
    return normalised_snr(s, ref)


def snr_from_fits(peak, mu, sigma) -> float:
    """SNR of a reconstruction from its planes' histogram fits (eq. 4.3 of the SAPIV study).

    The equation::

        SNR(V_R) = 1/N sum_j max(I_j) / (mu(I_j) + sigma(I_j))                  (eq. 4.3)

    Parameters
    ----------
    peak : (N,) ``max(I_j)`` of each refocused plane ``I_j``.
    mu, sigma : (N,) mean and standard deviation of the normal fit of each plane's
        intensity histogram (e.g. :func:`mitpiv.reconstruct.sapiv.noise_normal_fit`, the fit
        to the noise part that also sets the threshold; :func:`plane_snr` uses the plain
        mean and standard deviation of the whole plane instead).

    Returns
    -------
    float; a plane with ``mu + sigma <= 0`` (all zero) contributes 0.
    """
    pk, m, s = (np.asarray(a, dtype=np.float64).ravel() for a in (peak, mu, sigma))
    if not (pk.shape == m.shape == s.shape) or pk.size == 0:
        raise ConfigError(f"snr_from_fits: 'peak', 'mu', 'sigma' must be equal-length non-empty arrays, got "
                          f"{pk.shape}, {m.shape}, {s.shape}.")
    den = m + s
    return float(np.mean(np.where(den > 0, pk / np.where(den > 0, den, 1.0), 0.0)))


def normalised_snr(snr: float, reference_snr: float) -> float:
    """Normalised SNR (eq. 4.4): ``nSNR = SNR(V_R(D, gamma)) / SNR(V_R(D=0, gamma))``.

    Parameters
    ----------
    snr : float
        :func:`plane_snr` of the configuration (e.g. distortion ``D``, density ``gamma``).
    reference_snr : float
        :func:`plane_snr` of the reference configuration at the same seeding density (the
        study: no distortion, no aberration), finite and > 0.
    """
    s, ref = float(snr), float(reference_snr)
    if not (np.isfinite(ref) and ref > 0):
        raise ConfigError(f"plane_snr: the reference SNR must be finite and > 0, got {reference_snr!r}.")
    if not (np.isfinite(s) and s >= 0):
        raise ConfigError(f"normalised_snr: 'snr' must be finite and >= 0, got {snr!r}.")
    return s / ref


def _particle_positions(particles) -> np.ndarray:
    p = particles.get("positions_mm") if isinstance(particles, dict) else particles
    p = np.asarray(p, dtype=np.float64)
    if p.ndim == 3 and p.shape[0] == 1:
        p = p[0]
    if p.ndim != 2 or p.shape[1] != 3:
        raise ConfigError(
            f"truth_volume: 'particles' must be positions (N, 3) [mm] (or a truth dict of one frame), got shape {p.shape}. "
            f"For a multi-frame truth file pass truth['positions_mm'][frame]."
        )
    if not np.all(np.isfinite(p)):
        raise ConfigError("truth_volume: particle positions contain NaN or infinite values.")
    return p


def truth_volume(particles, grid: VoxelGrid, sigma_voxels=0.7, *, intensities=None, chunk: int = 20000) -> np.ndarray:
    """The true intensity volume: each particle a 3D Gaussian blob on ``grid``.

    Each particle's Gaussian (standard deviation ``sigma_voxels`` voxels along each axis,
    i.e. anisotropic in millimetres on an anisotropic grid) is integrated over every voxel
    it reaches (product of error-function differences, support +-4 sigma), so a blob keeps
    its total ``intensity`` whatever its sub-voxel position. Parts of a blob outside the
    grid are dropped.

    Parameters
    ----------
    particles : (N, 3) array [mm] or dict with ``positions_mm``
    grid : VoxelGrid
    sigma_voxels : float or (3,) floats (x, y, z)
    intensities : (N,) array, optional
        Total intensity per particle (default 1).

    Returns
    -------
    (n_z, n_y, n_x) float64 volume
    """
    if not isinstance(grid, VoxelGrid):
        raise ConfigError(f"truth_volume: 'grid' must be a VoxelGrid, got {type(grid).__name__}.")
    p = _particle_positions(particles)
    sig = np.broadcast_to(np.asarray(sigma_voxels, dtype=float), (3,))
    if not np.all(np.isfinite(sig)) or np.any(sig <= 0):
        raise ConfigError(f"truth_volume: 'sigma_voxels' must be > 0, got {sigma_voxels!r}.")
    amp = np.ones(len(p)) if intensities is None else np.broadcast_to(np.asarray(intensities, dtype=float), (len(p),))
    if not np.all(np.isfinite(amp)):
        raise ConfigError("truth_volume: 'intensities' must be finite.")
    nz, ny, nx = grid.shape
    out = np.zeros(grid.n_voxels)
    half = np.ceil(4 * sig).astype(int)
    q = grid.to_voxel(p)  # continuous voxel coordinates (i, j, k)
    for s in range(0, len(p), max(int(chunk), 1)):
        qc, ac = q[s : s + chunk], amp[s : s + chunk]
        idx, wts = [], []
        for axis, n in enumerate((nx, ny, nz)):
            off = np.arange(-half[axis], half[axis] + 1)
            c = np.floor(qc[:, axis] + 0.5).astype(np.int64)[:, None] + off  # voxel indices near the centre
            lo = (c - 0.5 - qc[:, axis : axis + 1]) / (np.sqrt(2) * sig[axis])
            w = 0.5 * (erf(lo + 1 / (np.sqrt(2) * sig[axis])) - erf(lo))
            w[(c < 0) | (c >= n)] = 0.0
            idx.append(np.clip(c, 0, n - 1))
            wts.append(w)
        flat = (idx[2][:, :, None, None] * ny + idx[1][:, None, :, None]) * nx + idx[0][:, None, None, :]
        val = ac[:, None, None, None] * wts[2][:, :, None, None] * wts[1][:, None, :, None] * wts[0][:, None, None, :]
        keep = val > 0
        out += np.bincount(flat[keep], weights=val[keep], minlength=out.size)
    return out.reshape(grid.shape)


def occupancy_volume(particles, grid: VoxelGrid, *, intensities=None) -> np.ndarray:
    """The true volume of point-like particles: each particle's intensity (default 1) in
    the voxel holding its centre, zero elsewhere (particles outside the grid are dropped).

    The truth for particles much smaller than a voxel (the SAPIV study: 20 um particles,
    50 um voxels), where :func:`truth_volume`'s blobs would be wider than the particles.

    Returns
    -------
    (n_z, n_y, n_x) float64 volume
    """
    if not isinstance(grid, VoxelGrid):
        raise ConfigError(f"occupancy_volume: 'grid' must be a VoxelGrid, got {type(grid).__name__}.")
    p = _particle_positions(particles)
    amp = np.ones(len(p)) if intensities is None else np.broadcast_to(np.asarray(intensities, dtype=float), (len(p),))
    nz, ny, nx = grid.shape
    q = np.floor(grid.to_voxel(p) + 0.5).astype(np.int64)  # (i, j, k) of the voxel holding each centre (centres at integers)
    ok = (q[:, 0] >= 0) & (q[:, 0] < nx) & (q[:, 1] >= 0) & (q[:, 1] < ny) & (q[:, 2] >= 0) & (q[:, 2] < nz)
    flat = (q[ok, 2] * ny + q[ok, 1]) * nx + q[ok, 0]
    return np.bincount(flat, weights=amp[ok], minlength=grid.n_voxels).reshape(grid.shape)



#: nodes per axis of the tabulated octant fraction F (sphere_volume), and lattice cells per node
#: spacing of the midpoint rule that fills it
_OCTANT_NODES = 64
_OCTANT_CELLS = 3


@lru_cache(maxsize=1)
def _octant_table() -> np.ndarray:
    """F[i, j, k]: volume fraction of the unit ball with x < t_i, y < t_j, z < t_k, on the
    nodes ``t = -1 + 2 m / 64``: a midpoint rule on a lattice of 192 cells per axis whose
    cell faces fall on the nodes, so the only error is the cells straddling the sphere's
    surface (about 3e-4 of the volume)."""
    nb, nc = _OCTANT_NODES, _OCTANT_CELLS
    n = nb * nc
    c = (np.arange(n) + 0.5) / n * 2.0 - 1.0
    counts = np.zeros((nb, nb, nb))
    for iz in range(n):  # one slab of cells at a time (memory)
        x, y = np.meshgrid(c, c, indexing="ij")
        inside = x * x + y * y + c[iz] ** 2 <= 1.0
        ii = np.nonzero(inside)
        h = np.bincount((ii[0] // nc) * nb + ii[1] // nc, minlength=nb * nb).reshape(nb, nb)
        counts[:, :, iz // nc] += h
    f = np.zeros((nb + 1, nb + 1, nb + 1))
    f[1:, 1:, 1:] = counts.cumsum(0).cumsum(1).cumsum(2)
    return f / f[-1, -1, -1]


def sphere_volume(particles, grid: VoxelGrid, diameter_mm: float, *, intensities=None) -> np.ndarray:
    """The true volume of spherical particles voxelised by volume: each voxel holds the
    fraction of every particle's sphere (``diameter_mm``) inside it, times the particle's
    intensity (default 1), so a particle's voxels sum to its intensity when it is wholly
    inside the grid (parts outside the grid are dropped).

    Each voxel's fraction is an inclusion-exclusion of the octant fraction F(tx, ty, tz)
    (the part of the ball below three axis-aligned planes at tx, ty, tz radii from its
    centre), tabulated once on 65^3 nodes and interpolated trilinearly: within 1e-3 of the
    exact spherical cap (tests/analysis/test_sphere_volume.py). A particle much smaller
    than a voxel lands in the voxel holding its centre (as with :func:`occupancy_volume`);
    one larger spreads over the voxels it reaches, on anisotropic grids too.
    Hand-written: no kept library voxelises spheres by volume fraction.

    Returns
    -------
    (n_z, n_y, n_x) float64 volume
    """
    from scipy.ndimage import map_coordinates

    if not isinstance(grid, VoxelGrid):
        raise ConfigError(f"sphere_volume: 'grid' must be a VoxelGrid, got {type(grid).__name__}.")
    if not (np.isfinite(diameter_mm) and diameter_mm > 0):
        raise ConfigError(f"sphere_volume: 'diameter_mm' must be > 0, got {diameter_mm!r}.")
    p = _particle_positions(particles)
    amp = np.ones(len(p)) if intensities is None else np.broadcast_to(np.asarray(intensities, dtype=float), (len(p),))
    if not np.all(np.isfinite(amp)):
        raise ConfigError("sphere_volume: 'intensities' must be finite.")
    f = _octant_table()
    nz, ny, nx = grid.shape
    q = grid.to_voxel(p)  # continuous voxel coordinates (x, y, z); voxel k spans [k - 0.5, k + 0.5)
    r = 0.5 * diameter_mm / np.asarray(grid.voxel_mm, dtype=float)  # radius in voxels per axis
    m = np.ceil(2 * r).astype(int) + 1  # voxels a sphere can reach per axis
    k0 = np.floor(q - r + 0.5).astype(np.int64)  # first voxel each sphere reaches
    t = []  # the planes bounding those voxels, in radii from the centre, clipped to the ball
    for a in range(3):
        b = k0[:, a : a + 1] + np.arange(m[a] + 1)[None, :] - 0.5
        t.append(np.clip((b - q[:, a : a + 1]) / r[a], -1.0, 1.0))
    nodes = (np.stack(np.broadcast_arrays(t[0][:, :, None, None], t[1][:, None, :, None], t[2][:, None, None, :]), 0)
             + 1.0) * (_OCTANT_NODES / 2.0)
    fv = map_coordinates(f, nodes.reshape(3, -1), order=1, mode="nearest").reshape(nodes.shape[1:])
    frac = np.diff(np.diff(np.diff(fv, axis=1), axis=2), axis=3)  # (N, mx, my, mz)
    ix = k0[:, 0:1] + np.arange(m[0])
    iy = k0[:, 1:2] + np.arange(m[1])
    iz = k0[:, 2:3] + np.arange(m[2])
    ok = ((ix >= 0) & (ix < nx))[:, :, None, None] & ((iy >= 0) & (iy < ny))[:, None, :, None] & \
         ((iz >= 0) & (iz < nz))[:, None, None, :]
    flat = (iz[:, None, None, :] * ny + iy[:, None, :, None]) * nx + ix[:, :, None, None]
    w = frac * amp[:, None, None, None]
    ok &= w > 0
    return np.bincount(flat[ok], weights=w[ok], minlength=grid.n_voxels).reshape(grid.shape)
