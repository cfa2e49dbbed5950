"""Shake-The-Box at higher densities (issue 51, item 2): the rules of
:func:`mitpiv.tracking.stb.stb` that carry it from 47 % to 95 % yield on the rendered 0.1-ppp
LPT sequence (docs/guide.md), each against the rule off: new tracks from two frames of
untracked particles extended back by shaking (``back_shake``), the residual with the
tracked particles' intensities capped at their tracks' median (``capped_residual``), the
per-camera gain IPR measures on the first frame (``camera_gain``), predictions whose order
follows the track's length (:func:`~mitpiv.tracking.stb.predict_adaptive`), new pairs
linked around the nearest tracks' velocity (``link_from_tracks``). Sequences of the OTF
projector with cameras of different gains and particle images with wings the OTF does not
model (those of tests/test_ipr_dense.py).

Levels measured on 2026-12-07 (``sheared_sequence(0.03, 8)``, 1966 particles): yield
0.588 with every rule, 0.334 without ``back_shake``, 0.505 without ``capped_residual``;
ghosts 0.141, 0.055 and 0.141 (at 0.02 ppp half the "ghosts" were true particles placed
1-2 px off in depth by the unmodelled wings, no other track's).
"""

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.tracking import OTF, project_particles
from mitpiv.tracking.metrics import track_metrics
from mitpiv.tracking.stb import predict, predict_adaptive, stb
from tests.test_ipr_dense import GAIN
from tests.test_tracking import HI, LO, rig

DT_S = 1e-3
U = np.array([240.0, 60.0, -30.0])  # [mm/s]: about 3 px per frame


def sheared_sequence(ppp, frames, seed=7, gain=GAIN):
    """Particles carried by U scaled by 1 +- 0.3 across the box's depth, lognormal
    intensities, cameras of gains ``gain``, Gaussian cores (the OTF) plus wings (8 % of the
    peak, sigma 2.5 px). Returns (sequence, cameras, otf, trajectories, velocities)."""
    cams = rig()
    rng = np.random.default_rng(seed)
    n = int(round(ppp * 256 * 256))
    p0 = rng.uniform(LO - [U[0] * DT_S * frames, 0, 0], HI, (n, 3))
    u = U[None, :] * (1 + 0.3 * p0[:, 2:3] / HI[2])
    traj = p0[:, None] + u[:, None] * (np.arange(frames) * DT_S)[None, :, None]
    e = rng.lognormal(0.0, 0.3, n)
    core = OTF.uniform(4, sigma_px=1.0, lower_mm=LO, upper_mm=HI)
    wing = OTF.uniform(4, sigma_px=2.5, peak=0.08, lower_mm=LO, upper_mm=HI)
    seq = [[g * (a + b) for g, a, b in zip(gain, project_particles(traj[:, f], e, cams, core),
                                           project_particles(traj[:, f], e, cams, wing), strict=True)]
           for f in range(frames)]
    return seq, cams, core, traj, np.broadcast_to(u[:, None], traj.shape)


def _run(seq, cams, otf, **kw):
    return stb(seq, cams, otf, dt_s=DT_S, lower_mm=LO, upper_mm=HI, velocity_guess=U, ipr_options={"outer_loops": 2},
               **kw)


def test_every_shake_uses_the_camera_gain_ipr_measured_on_the_first_frame():
    seq, cams, otf, traj, vel = sheared_sequence(0.004, 5)
    on = _run(seq, cams, otf)
    want = GAIN / np.exp(np.mean(np.log(GAIN)))  # IPR keeps the geometric mean at 1
    np.testing.assert_allclose(on.history[0]["camera_gain"], want, rtol=0.03)
    off = _run(seq, cams, otf, camera_gain=False)
    np.testing.assert_array_equal(off.history[0]["camera_gain"], np.ones(4))
    # the shakes use it: without it a part of every particle stays in the residual of the
    # brighter cameras and the positions follow it (0.045 px against 0.055 px, 2026-12-07)
    err = [track_metrics(t, traj, radius_mm=0.08, truth_velocities_mm_s=vel, lower_mm=LO, upper_mm=HI,
                         cameras=cams)["position_error_px"] for t in (on, off)]
    assert err[0] < 0.9 * err[1], err


def test_the_gain_is_measured_again_on_the_established_tracks():
    """``track_gain``: a first frame recorded with other gains than the rest (in a dense
    first frame IPR's ghost-laden particles misjudge them: by up to 22 % at 0.15 ppp on the
    rendered sequence) is corrected once tracks have lived 6 frames: the last frames' gain
    is the sequence's within 3 % (the cores' supports of some 200 tracks; the wings the OTF
    lacks are the same in every camera). Off, the first frame's gain stays."""
    seq, cams, otf, traj, vel = sheared_sequence(0.004, 10)
    other = np.array([1.0, 0.8, 1.25, 1.0])
    seq[0] = [i * o for i, o in zip(seq[0], other, strict=True)]
    norm = lambda g: g / np.exp(np.mean(np.log(g)))  # noqa: E731  (geometric mean 1)
    on = _run(seq, cams, otf)
    np.testing.assert_allclose(on.history[0]["camera_gain"], norm(GAIN * other), rtol=0.03)
    last = [h["camera_gain"] for h in on.history if h["frame"] > 0 and "camera_gain" in h]
    assert len(last) >= 3
    np.testing.assert_allclose(last[-1], norm(GAIN), rtol=0.03)
    off = _run(seq, cams, otf, track_gain=False)
    assert not any("camera_gain" in h for h in off.history[1:])
    # the shakes use it: with the first frame's gains the positions of the frames after the
    # new measurement follow the light left in the residual of the cameras they misjudge
    # (0.056 px against 0.070 px, 2026-12-07)
    after = list(range(8, 10))
    err = [track_metrics(t, traj, radius_mm=0.08, truth_velocities_mm_s=vel, lower_mm=LO, upper_mm=HI,
                         cameras=cams, frames=after)["position_error_px"] for t in (on, off)]
    assert err[0] < 0.9 * err[1], err


def test_the_joint_check_and_the_support_screen_keep_a_sparse_sequence_whole():
    """The optional track test after the joint shake with IPR's image-support screen (off by
    default, docs/guide.md) ends no true track of a sparse sequence."""
    seq, cams, otf, traj, vel = sheared_sequence(0.004, 5)
    tr = _run(seq, cams, otf, joint_check=True, track_support=0.5)
    m = track_metrics(tr, traj, radius_mm=0.08, truth_velocities_mm_s=vel, lower_mm=LO, upper_mm=HI, cameras=cams)
    assert m["yield"] > 0.93 and m["ghost_fraction"] < 0.02, m
    assert all("ended_support" in h for h in tr.history[4:])


def test_new_options_are_checked():
    seq, cams, otf, *_ = sheared_sequence(0.001, 4)
    with pytest.raises(ConfigError, match="predict_points"):
        _run(seq, cams, otf, predict_points=3)
    with pytest.raises(ConfigError, match="predict_points"):
        _run(seq, cams, otf, predict_points=True)
    with pytest.raises(ConfigError, match="predict_points"):
        _run(seq, cams, otf, predict_points=5.5)
    with pytest.raises(ConfigError, match="track_support"):
        _run(seq, cams, otf, track_support=1.0)
    with pytest.raises(ConfigError, match=r"\(K, L, 3\)"):
        predict_adaptive(np.zeros((4, 3)))


def test_back_shake_and_the_capped_residual_start_the_tracks_of_a_dense_sequence():
    """IPR finds a particle in each frame of a dense sequence with some probability p < 1:
    chains of 4 IPR frames start p^4 of the particles, pairs extended back by shaking p^2
    (``back_shake``); and IPR finds an untracked particle in the residual only when its
    tracked neighbours are subtracted with their tracks' intensity, not with the light the
    shake let them take from it (``capped_residual``)."""
    seq, cams, otf, traj, vel = sheared_sequence(0.03, 8)

    def score(**kw):
        tr = _run(seq, cams, otf, **kw)
        return track_metrics(tr, traj, radius_mm=0.08, truth_velocities_mm_s=vel, lower_mm=LO, upper_mm=HI,
                             cameras=cams), tr

    on, tr = score()
    no_back, _ = score(back_shake=False)
    no_cap, _ = score(capped_residual=False)
    assert on["yield"] > 0.55 and on["ghost_fraction"] < 0.2, on
    assert no_back["yield"] < 0.45, no_back
    assert no_cap["yield"] < 0.545, no_cap
    assert sum(h.get("new_back", 0) for h in tr.history) > 100  # the back shake started tracks


def test_adaptive_prediction_halves_the_noise_of_young_tracks_and_follows_curvature():
    rng = np.random.default_rng(2)
    t = np.arange(8, dtype=np.float64)
    # straight tracks with 0.1 mm position noise: 4 and 8 points known
    line = np.stack([np.outer(np.ones(4000), 3 * t), np.zeros((4000, 8)), np.zeros((4000, 8))], axis=-1)
    noisy = line + rng.normal(0.0, 0.1, line.shape)
    want = np.array([24.0, 0.0, 0.0])
    for n in (4, 8):
        x = noisy.copy()
        x[:, :8 - n] = np.nan
        err_new = np.linalg.norm(predict_adaptive(x) - want, axis=1)
        err_old = np.linalg.norm(predict(x[:, -4:]) - want, axis=1)
        assert np.sqrt(np.mean(err_new**2)) < 0.6 * np.sqrt(np.mean(err_old**2)), n  # 0.44 (4 points), 0.50 (8)
    # a parabola without noise is followed exactly by 6 points or more, a line through 4 misses it
    par = np.stack([t**2, t, np.zeros(8)], axis=-1)[None]
    np.testing.assert_allclose(predict_adaptive(par[:, -6:])[0], [64.0, 8.0, 0.0], atol=1e-9)
    assert abs(predict_adaptive(par[:, -4:])[0, 0] - 64.0) > 1.0
    with pytest.raises(ConfigError, match="at least 4 finite"):
        predict_adaptive(par[:, -3:])


def test_new_pairs_take_the_velocity_of_the_nearest_tracks():
    """Without a velocity guess, a pair of untracked particles 3 px apart in consecutive
    frames lies beyond the 1.5 px link radius around zero motion: only the nearest tracks'
    velocity (``link_from_tracks``) links it for the back shake."""
    seq, cams, otf, traj, vel = sheared_sequence(0.01, 6)
    on = stb(seq, cams, otf, dt_s=DT_S, lower_mm=LO, upper_mm=HI, ipr_options={"outer_loops": 2})
    off = stb(seq, cams, otf, dt_s=DT_S, lower_mm=LO, upper_mm=HI, ipr_options={"outer_loops": 2},
              link_from_tracks=False)
    n_on = sum(h["new_back"] for h in on.history)
    n_off = sum(h["new_back"] for h in off.history)
    assert n_on > 20 and n_off < 0.2 * n_on, (n_on, n_off)
