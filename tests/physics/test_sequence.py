"""Time-resolved particle sequences (mitpiv.physics.sequence): the RK4 integrator against
closed-form trajectories, persistent identities, a constant particle count with particles
leaving and entering the box, and the material acceleration."""

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.physics.flows import SolidBody, Uniform
from mitpiv.physics.sequence import advect_sequence

# RK4 with 8 substeps per frame of omega dt = 0.05 rad: local error ~ (omega h)^5 / 120 r
# ~ 1e-15 mm per step; the issue asks 1e-6 mm after N frames
POSITION_TOL_MM = 1e-6


def rotated(p, omega, t):
    """Closed-form solid-body rotation about the z axis through the origin (float64)."""
    c, s = np.cos(omega * t), np.sin(omega * t)
    return np.stack([c * p[:, 0] - s * p[:, 1], s * p[:, 0] + c * p[:, 1], p[:, 2]], axis=1)


def test_solid_body_rotation_matches_the_closed_form_and_ids_persist():
    omega, dt, n = 2.0, 0.025, 200  # ten radians: more than a full turn and a half
    seq = advect_sequence(SolidBody(omega_rad_s=omega), box_min_mm=(-10, -10, -2), box_max_mm=(10, 10, 2),
                          n_frames=n, dt_s=dt, count=400, seed=3)
    p0 = seq.positions_mm[0]
    first = np.flatnonzero(seq.present[0])
    # particles inside the inscribed circle never leave: the same identity in every frame
    inner = first[np.hypot(p0[first, 0], p0[first, 1]) < 9.9]
    assert inner.size > 250 and np.all(seq.present[:, inner])
    for f in (1, 57, n - 1):
        ref = rotated(p0[inner], omega, f * dt)
        assert np.max(np.abs(seq.positions_mm[f, inner] - ref)) < POSITION_TOL_MM
    # velocities and material accelerations (centripetal) of the truth, written afresh
    f = n - 1
    p = seq.positions_mm[f, inner]
    v_ref = omega * np.stack([-p[:, 1], p[:, 0], np.zeros(len(p))], axis=1)
    a_ref = -omega**2 * np.stack([p[:, 0], p[:, 1], np.zeros(len(p))], axis=1)
    np.testing.assert_allclose(seq.velocities_mm_s[f, inner], v_ref, atol=1e-9)
    # central difference along the pathline, h = dt / 128: relative error ~ (omega h)^2 / 6
    np.testing.assert_allclose(seq.accelerations_mm_s2[f, inner], a_ref, atol=1e-6 * omega**2 * 10)


def test_constant_count_with_particles_leaving_and_entering_at_the_inflow():
    u = 40.0  # mm/s along x: 1 mm per frame through a 10 mm box, the whole box renewed in 10 frames
    seq = advect_sequence(Uniform(velocity_mm_s=(u, 0, 0)), box_min_mm=(0, 0, 0), box_max_mm=(10, 5, 5),
                          n_frames=30, dt_s=0.025, count=300, seed=5)
    present = seq.present
    assert np.all(present.sum(axis=1) == 300)  # the count stays constant
    assert seq.ids.size > 300 + 500  # particles left and others entered
    # each identity is one contiguous run of frames, and moves u dt per frame while present
    runs = np.diff(present.astype(np.int8), axis=0)
    assert np.all((runs == 1).sum(axis=0) + present[0] <= 1) and np.all((runs == -1).sum(axis=0) <= 1)
    both = present[1:] & present[:-1]
    step = seq.positions_mm[1:] - seq.positions_mm[:-1]
    np.testing.assert_allclose(step[both], np.broadcast_to([u * 0.025, 0, 0], step[both].shape), atol=1e-12)
    # entering particles appear within one frame's displacement of the inflow face x = 0
    born = np.flatnonzero(~present[0])
    f_birth = np.argmax(present[:, born], axis=0)
    x_birth = seq.positions_mm[f_birth, born, 0]
    assert x_birth.max() <= u * 0.025 + 1e-12
    # and uniformly over the face (y, z): no clustering
    yz = seq.positions_mm[f_birth, born, 1:]
    assert abs(yz[:, 0].mean() - 2.5) < 0.3 and abs(yz[:, 1].mean() - 2.5) < 0.3


def test_one_frame_and_bad_arguments():
    seq = advect_sequence(Uniform(), box_min_mm=(0, 0, 0), box_max_mm=(1, 1, 1), n_frames=1, dt_s=0.1, count=10)
    assert seq.positions_mm.shape == (1, 10, 3) and np.all(seq.present)
    with pytest.raises(ConfigError, match="n_frames"):
        advect_sequence(Uniform(), box_min_mm=(0, 0, 0), box_max_mm=(1, 1, 1), n_frames=0, dt_s=0.1, count=10)
    with pytest.raises(ConfigError, match="box_max_mm"):
        advect_sequence(Uniform(), box_min_mm=(0, 0, 0), box_max_mm=(1, 0, 1), n_frames=2, dt_s=0.1, count=10)
    with pytest.raises(ConfigError, match="reseed"):
        advect_sequence(Uniform(), box_min_mm=(0, 0, 0), box_max_mm=(1, 1, 1), n_frames=2, dt_s=0.1, count=10,
                        reseed="nowhere")
