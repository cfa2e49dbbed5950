"""Shake-The-Box at higher densities (issue 51, item 2, in progress): the per-camera gain
that IPR measures on the first frame, used by every shake of :func:`mitpiv.tracking.stb.stb`,
and the checks of the new options, on sequences of the OTF projector with cameras of
different gains and particle images with wings the OTF does not model (those of
tests/test_ipr_dense.py). The other rules' effect on a rendered 0.1-ppp sequence is
measured in docs/guide.md; their own tests come with the study of item 3.
"""

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.tracking import OTF, project_particles
from mitpiv.tracking.stb import stb
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


def test_new_options_are_checked():
    seq, cams, otf, *_ = sheared_sequence(0.001, 4)
    with pytest.raises(ConfigError, match="predict_points"):
        _run(seq, cams, otf, predict_points=3)
    with pytest.raises(ConfigError, match="predict_points"):
        _run(seq, cams, otf, predict_points=True)
