"""Shake-The-Box (Schanz, Gesemann & Schroeder 2016): time-resolved particle tracking.

Steps
-----
1. Initialisation: IPR (:func:`~mitpiv.tracking.ipr.ipr`) on each of the first four
   frames; particles are linked into four-frame chains (:func:`link_four`): a
   nearest-neighbour search from frame 0 to 1 (around an optional velocity guess), then
   linear and quadratic extrapolation to frames 2 and 3, each within a search radius;
   chains are kept in order of their smallest acceleration, each particle used once.
2. Each later frame: every active track predicts its position by a polynomial fit
   through its last positions (a line through 4-5, a parabola through 6-8: the fit's
   noise amplification against its bias); the predicted particles are shaken in the
   frame's images (:func:`~mitpiv.tracking.ipr.shake`) with their last intensity and the
   per-camera gain IPR measured on frame 0 (``track_gain``: then on the established tracks
   of the frame before).
3. New particles: IPR on the residual images (images minus the tracked particles) with
   the frame's own detection threshold; all particles are shaken together again, and the
   per-camera gain is measured on the established tracks.
4. Termination, after the first shake (``joint_check``: after the joint one): a track
   ends when its particle fades (intensity below ``min_intensity`` times the median), lies
   farther than ``max_shake_px`` from the prediction, leaves the box, merges with another
   track's particle (the shorter ends) or, with ``joint_check`` and ``track_support``,
   loses its image support in some camera (its particle then joins the untracked).
   Untracked particles of the last four frames are linked into new tracks as in step 1,
   around the velocity of the nearest tracks; then (``back_shake``) pairs of untracked
   particles of the last two frames, linked around that velocity, are extended two frames
   back by shaking their extrapolated positions in those frames' images less the tracked
   particles; a pair links within ``predict_px`` of that velocity's prediction, and starts
   a track where the shaken particle stays within ``predict_px`` of the extrapolation, is
   brighter than ``min_intensity`` times the tracked particles' median and lies on no
   tracked particle (IPR need find a particle in 2 frames, not 4).
5. :func:`regularise`: a local polynomial (order 2, a window of ``2 h + 1`` frames) fitted
   to every track at every time gives position, velocity and acceleration; windows are
   truncated at track ends (the fit needs ``order + 1`` points).

Tracks are stored as (n_tracks, n_frames, 3) arrays with NaN where a track is absent, so
every step is vectorised over tracks (NumPy; SciPy KD-trees for the searches).
Hand-written because no kept Python library offers STB.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field

import numpy as np

from mitpiv.errors import ConfigError, check_positive
from mitpiv.progress import bar
from mitpiv.tracking.ipr import _camera_gain, _check_images, _prune, _screen, auto_threshold, ipr, mm_per_px, shake
from mitpiv.tracking.otf import OTF, project_particles

__all__ = ["Tracks", "link_four", "predict", "predict_adaptive", "regularise", "stb"]

log = logging.getLogger(__name__)


@dataclass
class Tracks:
    """Particle tracks over a sequence of frames.

    Attributes
    ----------
    positions_mm : (n_tracks, n_frames, 3) positions [mm], NaN where a track is absent
        (each track is one contiguous run of frames).
    intensities : (n_tracks, n_frames) particle intensities (NaN where absent).
    dt_s : time between frames [s].
    velocities_mm_s, accelerations_mm_s2 : (n_tracks, n_frames, 3) from
        :func:`regularise` (None before); positions are then the regularised ones and
        ``raw_positions_mm`` keeps the shaken ones.
    history : per frame, a dict of counts: active, new (``new_back`` of them from the back
        shake) and ended tracks, the ended ones by reason (``ended_left_box``,
        ``ended_deviation`` from the prediction by more than ``max_shake_px``,
        ``ended_intensity``, ``ended_merged`` into another track, ``ended_support``) and
        untracked particles; the first frame's also ``camera_gain``, the per-camera gain IPR
        measured on it, and with ``track_gain`` every frame's where the tracks measured it again
        (the gain the next frame's shakes use).
    """

    positions_mm: np.ndarray
    intensities: np.ndarray
    dt_s: float
    velocities_mm_s: np.ndarray | None = None
    accelerations_mm_s2: np.ndarray | None = None
    raw_positions_mm: np.ndarray | None = field(default=None, repr=False)
    history: list = field(default_factory=list, repr=False)

    @property
    def n_tracks(self) -> int:
        return int(self.positions_mm.shape[0])

    @property
    def n_frames(self) -> int:
        return int(self.positions_mm.shape[1])

    @property
    def present(self) -> np.ndarray:
        """(n_tracks, n_frames) True where the track has a particle."""
        return np.all(np.isfinite(self.positions_mm), axis=2)

    @property
    def lengths(self) -> np.ndarray:
        """(n_tracks,) number of frames of each track."""
        return self.present.sum(axis=1)

    def frame(self, index: int) -> tuple[np.ndarray, np.ndarray]:
        """Particles of one frame: (positions (K, 3) [mm], track indices (K,))."""
        ids = np.flatnonzero(self.present[:, index])
        return self.positions_mm[ids, index], ids


# ---------------------------------------------------------------------- linking
def _guess_at(velocity_guess, p):
    """The velocity guess at points ``p`` (N, 3) [mm/s]: zero, a constant or ``v(p)``."""
    p = np.asarray(p, dtype=np.float64).reshape(-1, 3)
    if velocity_guess is None:
        return np.zeros_like(p)
    if callable(velocity_guess):
        return np.asarray(velocity_guess(p), dtype=np.float64).reshape(-1, 3)
    return np.broadcast_to(np.asarray(velocity_guess, dtype=np.float64).reshape(1, 3), p.shape).copy()


def _greedy_unique(chains, cost):
    """Keep chains in order of increasing cost so that no particle is used twice."""
    order = np.argsort(cost, kind="stable")
    chains, keep_all = chains[order], []
    alive = np.ones(chains.shape[0], bool)
    while alive.any():
        idx = np.flatnonzero(alive)
        first = np.ones(idx.size, bool)
        for col in range(chains.shape[1]):
            _, pos = np.unique(chains[idx, col], return_index=True)
            f = np.zeros(idx.size, bool)
            f[pos] = True
            first &= f
        # a chain first in every column among the alive is better than all its rivals
        kept = idx[first]
        keep_all.append(kept)
        alive[kept] = False
        for col in range(chains.shape[1]):
            alive &= ~np.isin(chains[:, col], chains[kept, col])
    kept = np.sort(np.concatenate(keep_all)) if keep_all else np.zeros(0, np.int64)
    return chains[kept], cost[order][kept]


def link_four(frames, *, search_mm: float, predict_mm: float, velocity_guess=None, dt_s: float = 1.0):
    """Link particles of four consecutive frames into chains.

    Parameters
    ----------
    frames : four (N_f, 3) position arrays [mm].
    search_mm : radius around ``x0 + velocity_guess(x0) dt`` searched in frame 1.
    predict_mm : radius around the linear (frame 2) and quadratic (frame 3) extrapolation.
    velocity_guess : None (zero), a (3,) velocity [mm/s] or a callable ``v(p_mm) -> (N, 3)``.
    dt_s : frame interval [s] (only scales ``velocity_guess``).

    Returns
    -------
    (K, 4) particle indices, one chain per row, no particle in two chains.
    """
    from scipy.spatial import cKDTree

    if len(frames) != 4:
        raise ConfigError(f"link_four: need 4 frames, got {len(frames)}.")
    f = [np.asarray(x, dtype=np.float64).reshape(-1, 3) for x in frames]
    if any(x.shape[0] == 0 for x in f):
        return np.zeros((0, 4), np.int64)
    rs = check_positive("search_mm", search_mm, owner="link_four", unit="mm")
    rp = check_positive("predict_mm", predict_mm, owner="link_four", unit="mm")
    guess = f[0] + _guess_at(velocity_guess, f[0]) * dt_s
    m = cKDTree(guess).sparse_distance_matrix(cKDTree(f[1]), rs, output_type="coo_matrix")
    chains = np.stack([m.row, m.col], axis=1).astype(np.int64)
    for k in (2, 3):
        if chains.shape[0] == 0:
            return np.zeros((0, 4), np.int64)
        x = [f[j][chains[:, j]] for j in range(k)]
        pred = 2 * x[1] - x[0] if k == 2 else 3 * x[2] - 3 * x[1] + x[0]
        m = cKDTree(pred).sparse_distance_matrix(cKDTree(f[k]), rp, output_type="coo_matrix")
        chains = np.concatenate([chains[m.row], m.col[:, None].astype(np.int64)], axis=1)
    if chains.shape[0] == 0:
        return np.zeros((0, 4), np.int64)
    x = [f[j][chains[:, j]] for j in range(4)]
    cost = np.linalg.norm(x[2] - 2 * x[1] + x[0], axis=1) + np.linalg.norm(x[3] - 2 * x[2] + x[1], axis=1)
    return _greedy_unique(chains, cost)[0]


# ---------------------------------------------------------------------- prediction
def predict(positions_mm, *, points: int = 4, order: int = 2) -> np.ndarray:
    """Extrapolate tracks one frame ahead by a least-squares polynomial of ``order``
    through their last ``points`` positions.

    positions_mm : (K, L, 3) last positions of K tracks (L >= points, oldest first, no
    NaN in the last ``points``). Returns (K, 3).
    """
    x = np.asarray(positions_mm, dtype=np.float64)
    if x.shape[1] < points or points <= order:
        raise ConfigError(f"predict: need at least {points} > order={order} positions per track, got {x.shape[1]}.")
    t = np.arange(-points + 1, 1, dtype=np.float64)
    v = np.vander(t, order + 1, increasing=True)
    w = np.vander(np.array([1.0]), order + 1, increasing=True) @ np.linalg.pinv(v)  # (1, points)
    return np.einsum("p,kpc->kc", w[0], x[:, -points:])


def predict_adaptive(positions_mm) -> np.ndarray:
    """One frame ahead of each track, by a fit whose order follows the track's length: a
    line through its last 4 or 5 positions, a parabola through 6 or more.

    The order-2 fit through 4 points (:func:`predict` ``points=4``) amplifies the position
    noise 2.8 times (its extrapolation weights 0.75, -1.25, -0.75, 2.25), a line through 4
    points 1.2 times and a parabola through 8 points 1.4 times, while the bias of a line
    grows with the acceleration: on the rendered LPT sequence at 0.1 ppp the shaken positions
    carry about 0.1 px of noise, against a prediction bias of 0.04 px (parabola through 4)
    to 0.1 px (line through 4) on the true trajectories.

    positions_mm : (K, L, 3) the last L positions of K tracks, oldest first, NaN before a
    track's start (tracks are contiguous; at least 4 finite positions each). Returns (K, 3).
    """
    x = np.asarray(positions_mm, dtype=np.float64)
    if x.ndim != 3 or x.shape[2] != 3:
        raise ConfigError(f"predict_adaptive: need (K, L, 3) positions, got shape {x.shape}.")
    n_pts = np.all(np.isfinite(x), axis=2).sum(axis=1)
    if n_pts.size and n_pts.min() < 4:
        raise ConfigError(f"predict_adaptive: need (K, L, 3) positions with at least 4 finite per track, got shape "
                          f"{x.shape} and {int(n_pts.min()) if n_pts.size else 0} finite.")
    out = np.empty((x.shape[0], 3))
    for m in np.unique(n_pts):
        sel = n_pts == m
        out[sel] = predict(x[sel, x.shape[1] - m:], points=int(m), order=2 if m >= 6 else 1)
    return out


# ---------------------------------------------------------------------- regularisation
def regularise(tracks: Tracks, *, half_window: int = 3, order: int = 2) -> Tracks:
    """Local polynomial fit along every track (see the module notes, step 5).

    Returns a new :class:`Tracks` with regularised positions, velocities [mm/s] and
    accelerations [mm/s^2] (NaN where the track is absent or shorter than ``order + 1``).
    """
    from scipy.ndimage import correlate1d

    h = int(half_window)
    if h < 1 or int(order) not in (1, 2, 3) or 2 * h + 1 <= order:
        raise ConfigError(f"regularise: 'half_window' must be >= 1 and 'order' 1, 2 or 3 with 2 h + 1 > order, "
                          f"got {half_window!r}, {order!r}.")
    order = int(order)
    x = tracks.positions_mm
    w = np.all(np.isfinite(x), axis=2).astype(np.float64)
    x0 = np.where(w[..., None] > 0, x, 0.0)
    k = np.arange(-h, h + 1, dtype=np.float64)
    s = np.stack([correlate1d(w, k**m, axis=1, mode="constant") for m in range(2 * order + 1)], axis=-1)
    tm = np.stack([correlate1d(x0, k**m, axis=1, mode="constant") for m in range(order + 1)], axis=-1)  # (T, F, 3, o+1)
    idx = np.arange(order + 1)
    a = s[..., idx[:, None] + idx[None, :]]  # (T, F, o+1, o+1)
    n_pts = s[..., 0]
    ok = (w > 0) & (n_pts >= order + 1)
    a = np.where(ok[..., None, None], a, np.eye(order + 1))
    coef = np.linalg.solve(a[:, :, None], tm[..., None])[..., 0]  # (T, F, 3, o+1)
    coef = np.where(ok[..., None, None], coef, np.nan)
    dt = tracks.dt_s
    pos = coef[..., 0]
    vel = coef[..., 1] / dt
    acc = 2 * coef[..., 2] / dt**2 if order >= 2 else np.where(ok[..., None], 0.0, np.nan)
    return Tracks(pos, tracks.intensities, dt, vel, acc, tracks.positions_mm, tracks.history)


# ---------------------------------------------------------------------- STB
def stb(sequence, cameras, otf: OTF, *, dt_s: float, lower_mm, upper_mm, search_px: float = 10.0,
        predict_px: float = 1.5, max_shake_px: float = 1.0, velocity_guess=None, shake_iterations: int = 4,
        min_intensity: float = 0.1, threshold=None, ipr_options: dict | None = None,
        regularise_window: int = 3, predict_points: int = 8, joint_check: bool = False,
        link_from_tracks: bool = True, camera_gain: bool = True, frame_threshold: bool = True,
        track_support: float = 0.0, back_shake: bool = True, capped_residual: bool = True,
        track_gain: bool = True, progress=None) -> Tracks:
    """Track particles through a time-resolved image sequence with Shake-The-Box.

    Parameters
    ----------
    sequence : list of frames, each a list of per-camera (H, W) images (at least 4 frames).
    cameras : the cameras (camera contract plus ``pixel_to_ray``); otf : particle image model.
    dt_s : frame interval [s].
    lower_mm, upper_mm : measurement box [mm].
    search_px : search radius from frame 0 to 1 around the velocity guess [px, object
        space equivalent]; must exceed the largest displacement error of the guess.
    predict_px : search radius around extrapolated positions (initialisation) [px].
    max_shake_px : a shaken particle farther than this from its prediction ends its track [px].
    velocity_guess : None, a (3,) velocity [mm/s] or ``v(p_mm)``: the initial link predictor.
    shake_iterations : shaking of tracked particles per frame.
    min_intensity : fraction of the median intensity below which a particle is dropped.
    threshold : peak threshold for IPR (see :func:`~mitpiv.tracking.ipr.ipr`).
    ipr_options : more keyword arguments for the IPR calls.
    regularise_window : half window of :func:`regularise` (0 to skip the regularisation).
    predict_points : a track predicts its next position from up to this many of its last
        positions: a line through 4-5, a parabola through 6 or more (4: the parabola through
        the last 4, as before issue 51).
    joint_check : test a track (deviation from its prediction, intensity) after the joint
        shake with the particles IPR found in the residual, not after its own first shake in
        the full images, where the light of its untracked neighbours pulls it; the particle
        of a failed track joins the untracked ones. Off by default: on the rendered 0.1-ppp
        sequence it lowered the yield before ``capped_residual`` (72.1 against 75.2 %) and
        is neutral with it (94.9 against 94.7 %, docs/guide.md).
    link_from_tracks : new chains start from the median velocity of the nearest tracks (up to
        8 within 20 px, at least 3) instead of ``velocity_guess`` where there are such tracks.
    camera_gain : every shake uses the per-camera gain IPR measured on the first frame's
        full images (:func:`~mitpiv.tracking.ipr.ipr` ``camera_gain``), or with
        ``track_gain`` the latest the tracks measured.
    track_gain : with ``camera_gain``, the gain is measured again on every frame from the
        established tracks (those at least 6 frames old, when there are 100 or more; the
        median image support per camera after the joint shake, as IPR measures it): in a dense
        first frame IPR's particles are half ghosts, and its gains were off by up to 22 % at
        0.15 ppp (the tracks' 0.83 / 1.19 / 1.18 / 0.85 from frame 9 on, the values of the
        0.1-ppp sequence, against IPR's 1.03 / 1.12 / 1.26 / 0.69 on the rendered sequence).
        ``history[f]["camera_gain"]`` records each frame's new gain.
    frame_threshold : when ``threshold`` is None, the residual's IPR detects against the
        threshold of the frame's own images (``auto_threshold(noise="background")``), not of
        the residual, whose spread is the tracked particles' misfit.
    track_support : with ``joint_check``, end tracks whose particle some camera supports
        below this fraction after the joint shake (IPR's image-support screen; 0: off).
    back_shake : start tracks also from pairs of untracked particles extended back by shaking
        (module notes, step 4).
    capped_residual : the residual that IPR searches subtracts each tracked particle with its
        intensity capped at the track's median over its last 6 frames (a tracked particle
        shaken beside an untracked one takes in part of its light).

    Returns
    -------
    :class:`Tracks` (regularised unless ``regularise_window`` is 0).
    """
    from scipy.spatial import cKDTree

    n_frames = len(sequence)
    if n_frames < 4:
        raise ConfigError(f"stb: a sequence of {n_frames} frame(s) is too short; Shake-The-Box initialises tracks "
                          f"over 4 frames. Give at least 4 frames, or use mitpiv.tracking.ipr for single frames.")
    frames = [_check_images(f, cameras, f"stb (frame {i})") for i, f in enumerate(sequence)]
    dt = check_positive("dt_s", dt_s, owner="stb", unit="s")
    lo = np.asarray(lower_mm, dtype=np.float64)
    hi = np.asarray(upper_mm, dtype=np.float64)
    if lo.shape != (3,) or hi.shape != (3,) or np.any(hi <= lo):
        raise ConfigError(f"stb: 'upper_mm' {upper_mm!r} must exceed 'lower_mm' {lower_mm!r} on every axis.")
    scale = mm_per_px(cameras, 0.5 * (lo + hi))
    search_mm = check_positive("search_px", search_px, owner="stb", unit="px") * scale
    predict_mm = check_positive("predict_px", predict_px, owner="stb", unit="px") * scale
    max_shake_mm = check_positive("max_shake_px", max_shake_px, owner="stb", unit="px") * scale
    if isinstance(predict_points, bool) or not isinstance(predict_points, (int, np.integer)) or predict_points < 4:
        raise ConfigError(f"stb: 'predict_points' must be an integer >= 4, got {predict_points!r}.")
    n_pred = int(predict_points)
    adaptive = n_pred > 4
    if not (isinstance(track_support, (int, float)) and 0 <= track_support < 1):
        raise ConfigError(f"stb: 'track_support' must be a fraction in [0, 1), got {track_support!r}.")
    opts = dict(ipr_options or {})
    opts.setdefault("min_intensity", min_intensity)

    def run_ipr(images, thr):
        return ipr(images, cameras, otf, lower_mm=lo, upper_mm=hi, threshold=thr, **opts)

    pos = np.full((0, n_frames, 3), np.nan)
    inten = np.full((0, n_frames), np.nan)
    active = np.zeros(0, bool)
    free = {}  # frame -> (positions, intensities) of untracked particles
    history = []
    gains = np.ones(len(cameras))
    first_gains = gains.copy()

    def start_tracks(f_last):
        nonlocal pos, inten, active
        fs = [f_last - 3 + j for j in range(4)]
        chains = link_four([free[f][0] for f in fs], search_mm=search_mm, predict_mm=predict_mm,
                           velocity_guess=link_velocity(fs[0]), dt_s=dt)
        if chains.shape[0] == 0:
            return 0
        new_p = np.full((chains.shape[0], n_frames, 3), np.nan)
        new_e = np.full((chains.shape[0], n_frames), np.nan)
        for j, f in enumerate(fs):
            new_p[:, f] = free[f][0][chains[:, j]]
            new_e[:, f] = free[f][1][chains[:, j]]
            keep = np.ones(free[f][0].shape[0], bool)
            keep[chains[:, j]] = False
            free[f] = (free[f][0][keep], free[f][1][keep])
        pos = np.concatenate([pos, new_p])
        inten = np.concatenate([inten, new_e])
        active = np.concatenate([active, np.ones(chains.shape[0], bool)])
        return int(chains.shape[0])

    def back_tracks(f_last):
        """Pairs of untracked particles of the last two frames, linked around the nearest
        tracks' velocity, extended two frames back by shaking their extrapolated positions
        in those frames' images less the tracked particles: a new track then needs IPR to
        find its particle in 2 frames, not 4 (at a yield p per frame, p^2 of the particles
        start instead of p^4)."""
        nonlocal pos, inten, active
        fa, fb = f_last - 1, f_last
        (pa, ea), (pb, eb) = free[fa], free[fb]
        if pa.shape[0] == 0 or pb.shape[0] == 0:
            return 0
        guess = pa + _guess_at(link_velocity(fa), pa) * dt
        m = cKDTree(guess).sparse_distance_matrix(cKDTree(pb), predict_mm, output_type="coo_matrix")
        if m.nnz == 0:
            return 0
        pairs, _ = _greedy_unique(np.stack([m.row, m.col], axis=1).astype(np.int64), m.data)
        chain = [pb[pairs[:, 1]], pa[pairs[:, 0]]]  # newest first
        e_cur = 0.5 * (ea[pairs[:, 0]] + eb[pairs[:, 1]])
        ok = np.ones(pairs.shape[0], bool)
        es = []
        for back in (2, 3):
            fr = f_last - back
            x = np.stack(chain[::-1], axis=1)  # oldest first
            pred = predict(x[:, ::-1], points=x.shape[1], order=1)  # the line, backwards in time
            present = np.all(np.isfinite(pos[:, fr]), axis=1)
            res = [i - pr for i, pr in zip(frames[fr], project_particles(pos[present, fr], inten[present, fr],
                                                                           cameras, otf), strict=True)]
            q, qe, _ = shake(res, cameras, otf, pred, e_cur, step_mm=0.5 * predict_mm, iterations=shake_iterations)
            ref = np.median(inten[present, fr]) if present.any() else np.median(e_cur)
            # within the initialisation's radius of the extrapolation, as link_four's chains
            ok &= (np.all(np.isfinite(q), axis=1) & (np.linalg.norm(q - pred, axis=1) <= predict_mm)
                   & np.all((q >= lo) & (q <= hi), axis=1) & (qe > min_intensity * ref))
            # no particle twice: not on a tracked one, and of two candidates on one, the brighter
            if present.any() and ok.any():
                d, _ = cKDTree(pos[present, fr]).query(q, k=1)
                ok &= d > scale
            if ok.sum() > 1:
                idx = np.flatnonzero(ok)
                prs = cKDTree(q[idx]).query_pairs(scale, output_type="ndarray")
                if prs.size:
                    ok[idx[np.where(qe[idx[prs[:, 0]]] >= qe[idx[prs[:, 1]]], prs[:, 1], prs[:, 0])]] = False
            chain.append(q)
            es.append(qe)
            e_cur = qe
        if not ok.any():
            return 0
        k = int(ok.sum())
        new_p = np.full((k, n_frames, 3), np.nan)
        new_e = np.full((k, n_frames), np.nan)
        for j, fr in enumerate((fb, fa, fb - 2, fb - 3)):
            new_p[:, fr] = chain[j][ok]
        new_e[:, fb], new_e[:, fa] = eb[pairs[ok, 1]], ea[pairs[ok, 0]]
        new_e[:, fb - 2], new_e[:, fb - 3] = es[0][ok], es[1][ok]
        for fr, col in ((fa, 0), (fb, 1)):
            keep = np.ones(free[fr][0].shape[0], bool)
            keep[pairs[ok, col]] = False
            free[fr] = (free[fr][0][keep], free[fr][1][keep])
        if fb - 2 in free and free[fb - 2][0].shape[0]:
            d, _ = cKDTree(chain[2][ok]).query(free[fb - 2][0], k=1)
            free[fb - 2] = (free[fb - 2][0][d > scale], free[fb - 2][1][d > scale])
        pos = np.concatenate([pos, new_p])
        inten = np.concatenate([inten, new_e])
        active = np.concatenate([active, np.ones(k, bool)])
        return k

    def predict_tracks(ids, f):
        if not adaptive:
            return predict(pos[ids, f - 4:f])
        return predict_adaptive(pos[ids, max(0, f - n_pred):f])

    def link_velocity(f0):
        """The link predictor for chains starting at ``f0``: the median velocity of the
        (up to 8) nearest tracks present at f0 and f0 + 1 within 20 px, else the guess."""
        ids = np.flatnonzero(np.all(np.isfinite(pos[:, f0, :]), axis=1) & np.all(np.isfinite(pos[:, f0 + 1, :]), axis=1))
        if not link_from_tracks or ids.size < 8:
            return velocity_guess
        base = pos[ids, f0]
        vel = (pos[ids, f0 + 1] - base) / dt
        tree = cKDTree(base)

        def v(p):
            d, j = tree.query(np.asarray(p, dtype=np.float64).reshape(-1, 3), k=8, distance_upper_bound=20 * scale)
            ok = np.isfinite(d)
            enough = ok.sum(axis=1) >= 3  # a median of fewer than 3 tracks is not trusted
            out = _guess_at(velocity_guess, p)
            if enough.any():
                vv = np.where(ok[enough, :, None], vel[np.where(ok[enough], j[enough], 0)], np.nan)
                out[enough] = np.nanmedian(vv, axis=1)
            return out

        return v

    with bar(n_frames, desc="STB", progress=progress) as pb:
        for f in range(n_frames):
            imgs = frames[f]
            n_end = 0
            reasons = {"ended_left_box": 0, "ended_deviation": 0, "ended_intensity": 0, "ended_merged": 0,
                       "ended_support": 0}
            tracked = np.flatnonzero(active)
            if f >= 4 and tracked.size:
                pred = predict_tracks(tracked, f)
                e0 = inten[tracked, f - 1]
                ps, es, _ = shake(imgs, cameras, otf, pred, e0, step_mm=0.5 * max_shake_mm, iterations=shake_iterations)
                inside = np.all((ps >= lo) & (ps <= hi), axis=1) & np.all((pred >= lo) & (pred <= hi), axis=1)
                reasons["ended_left_box"] = int((~inside).sum())
                if not joint_check:
                    near = np.all(np.isfinite(ps), axis=1) & (np.linalg.norm(ps - pred, axis=1) <= max_shake_mm)
                    ok = near & inside
                    ref = np.median(es[ok]) if ok.any() else 0.0
                    bright = es > min_intensity * ref
                    reasons["ended_deviation"] = int((inside & ~near).sum())
                    reasons["ended_intensity"] = int((ok & ~bright).sum())
                    inside = ok & bright
                active[tracked[~inside]] = False
                n_end = int((~inside).sum())
                tracked, ps, es, pred = tracked[inside], ps[inside], es[inside], pred[inside]
            else:
                tracked = np.zeros(0, np.int64)
                ps, es, pred = np.zeros((0, 3)), np.zeros(0), np.zeros((0, 3))
            # new particles from the residual images, then everything shaken together
            if tracked.size and capped_residual:
                # a tracked particle's shake takes in the light of an untracked neighbour that
                # overlaps it: its intensity grows, and its subtraction would remove part of
                # the neighbour from the residual that IPR searches; capped at the track's
                # median over its last frames, the neighbour's light stays
                med = np.nanmedian(inten[tracked, max(0, f - 6):f], axis=1)  # a track has its last 4 frames
                e_res = np.minimum(es, med)
            else:
                e_res = es
            res = [i - pr for i, pr in zip(imgs, project_particles(ps, e_res, cameras, otf), strict=True)] if tracked.size else imgs
            # the detection threshold from the frame's own images: the residual's spread is the
            # tracked particles' misfit, which would raise it above the untracked particles
            thr = threshold if threshold is not None or not frame_threshold else \
                [auto_threshold(i, noise="background") for i in imgs]
            new = run_ipr(res, thr)
            if f == 0 and camera_gain and new.positions_mm.shape[0] >= 20:
                # the cameras' brightness relative to the OTF, as IPR measured it on the whole
                # first frame: every later shake (the tracked particles' first, in the full
                # images) uses it, else a part of each particle stays in some camera's residual
                g = np.asarray(new.camera_gain, dtype=np.float64)
                otf = OTF(otf.lower_mm, otf.upper_mm, otf.a, otf.b, otf.c, otf.peak * g[:, None, None, None])
                gains = g
                first_gains = g.copy()
            allp = np.concatenate([ps, new.positions_mm])
            alle = np.concatenate([es, new.intensities])
            jres = None
            if allp.shape[0]:
                allp, alle, jres = shake(imgs, cameras, otf, allp, alle, step_mm=0.2 * max_shake_mm,
                                         iterations=shake_iterations)
            nt = tracked.size
            freed = np.zeros(0, np.int64)
            if joint_check and nt:
                # the track's test after its neighbours found in the residual have taken their
                # light back: a young track among untracked particles is pulled off its path by
                # their light in the first shake, not in this one
                q = allp[:nt]
                near = np.all(np.isfinite(q), axis=1) & (np.linalg.norm(q - pred, axis=1) <= max_shake_mm)
                inside = np.all((q >= lo) & (q <= hi), axis=1)
                ref = np.median(alle[:nt][near & inside]) if (near & inside).any() else 0.0
                bright = alle[:nt] > min_intensity * ref
                ok = near & inside & bright
                if track_support and jres is not None:
                    # IPR's image-support screen on the tracked particles: a ghost track (its
                    # particle made of other particles' light) loses its support in some camera
                    # once those particles are tracked or found in the residual
                    sup = _screen(jres, cameras, otf, allp, alle, support=track_support, weak_intensity=0.0,
                                  established=np.zeros(allp.shape[0], bool))[:nt]
                    reasons["ended_support"] = int((ok & ~sup).sum())
                    ok &= sup
                reasons["ended_left_box"] += int((~inside).sum())
                reasons["ended_deviation"] = int((inside & ~near).sum())
                reasons["ended_intensity"] = int((inside & near & ~bright).sum())
                n_end += int((~ok).sum())
                active[tracked[~ok]] = False
                # the particle of a track that failed its test is still a particle: it joins
                # the untracked ones (a new track may start from it)
                freed = np.flatnonzero(~ok)
                keepj = np.concatenate([ok, np.ones(allp.shape[0] - nt, bool)])
                fp_extra, fe_extra = allp[freed], alle[freed]
                allp, alle, tracked = allp[keepj], alle[keepj], tracked[ok]
                nt = tracked.size
            else:
                fp_extra, fe_extra = np.zeros((0, 3)), np.zeros(0)
            gain_now = None
            if camera_gain and track_gain and nt and jres is not None:
                # the cameras' gain from the established tracks (mostly true particles once
                # tracks have lived 6 frames), after the joint shake with every particle found
                # (after the tracks' tests: the support screen reads jres with the OTF it was made with)
                old = np.isfinite(pos[tracked, max(0, f - 6), 0]) if f >= 6 else np.zeros(nt, bool)
                q, qe = allp[:nt][old], alle[:nt][old]
                fine = np.all(np.isfinite(q), axis=1) & np.isfinite(qe) & (qe > 0)
                if fine.sum() >= 100:
                    g = _camera_gain(jres, cameras, otf, q[fine], qe[fine])
                    gains = gains * g
                    otf = OTF(otf.lower_mm, otf.upper_mm, otf.a, otf.b, otf.c, otf.peak * g[:, None, None, None])
                    gain_now = gains.tolist()
            # merged tracks: two tracked particles closer than 1 px end the shorter track
            if nt > 1:
                pairs = cKDTree(allp[:nt]).query_pairs(scale, output_type="ndarray")
                if pairs.size:
                    lens = np.isfinite(pos[tracked, :, 0]).sum(axis=1)
                    loser = np.where(lens[pairs[:, 0]] >= lens[pairs[:, 1]], pairs[:, 1], pairs[:, 0])
                    gone = np.zeros(nt, bool)
                    gone[loser] = True
                    active[tracked[gone]] = False
                    pos[tracked[gone], f] = np.nan
                    inten[tracked[gone], f] = np.nan
                    n_end += int(gone.sum())
                    reasons["ended_merged"] = int(gone.sum())
                    keepm = np.concatenate([~gone, np.ones(allp.shape[0] - nt, bool)])
                    allp, alle, tracked = allp[keepm], alle[keepm], tracked[~gone]
                    nt = tracked.size
            pos[tracked, f], inten[tracked, f] = allp[:nt], alle[:nt]
            fp, fe = _prune(np.concatenate([allp[nt:], fp_extra]), np.concatenate([alle[nt:], fe_extra]), lo, hi,
                            min_intensity, scale)
            if fp.shape[0] and nt:
                d, _ = cKDTree(allp[:nt]).query(fp, k=1)
                fp, fe = fp[d > scale], fe[d > scale]
            free[f] = (fp, fe)
            n_new = start_tracks(f) if f >= 3 else 0
            n_back = back_tracks(f) if (f >= 3 and back_shake) else 0
            free.pop(f - 3, None)
            history.append({"frame": f, "active": int(active.sum()), "new": n_new + n_back, "new_back": n_back,
                            "ended": n_end, **reasons,
                            "untracked": int(free[f][0].shape[0]) if f in free else 0})
            if gain_now is not None:
                history[-1]["camera_gain"] = gain_now
            log.debug("STB frame %d: %s", f, history[-1])
            pb.update()
    if history:
        history[0]["camera_gain"] = first_gains.tolist()
    tracks = Tracks(pos, inten, dt, history=history)
    return regularise(tracks, half_window=regularise_window) if regularise_window else tracks
