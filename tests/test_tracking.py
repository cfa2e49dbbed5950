"""Lagrangian particle tracking (mitpiv.tracking): the OTF particle image model and its
calibration, IPR, STB, the LPT Challenge's metrics and the hard cases of issue 27.

Synthetic images come from the OTF projector itself (no renderer): four pinhole cameras
(50 mm lenses, 10 um pixels, 256 x 256, 400 mm away, +-20 deg azimuth and +-25 deg
elevation) around a 14 x 14 x 7 mm box; particle images are Gaussians of sigma 1 px.
"""

import numpy as np
import pytest

from mitpiv.analysis.particles import assign
from mitpiv.errors import CalibrationError
from mitpiv.physics.camera import PinholeCamera, place_camera
from mitpiv.tracking import OTF, calibrate_otf, detect_peaks, ipr, project_particles, triangulate
from mitpiv.tracking.metrics import track_metrics
from mitpiv.tracking.stb import stb

LO = np.array([-7.0, -7.0, -3.5])
HI = np.array([7.0, 7.0, 3.5])
RES = (256, 256)
# Issue 27's acceptance figures
IPR_YIELD = 0.99  # fraction of particles found ...
IPR_ERROR_PX = 0.05  # ... with this projected position error (largest over the cameras)


def rig(res=RES):
    cams = []
    for az, el in [(20, 25), (-20, 25), (20, -25), (-20, -25)]:
        rot, pos = place_camera(azimuth_deg=az + 90, elevation_deg=el, distance_mm=400.0)
        cams.append(PinholeCamera(resolution=res, focal_length_mm=50.0, pixel_pitch_um=10.0, rotation=rot, position_mm=pos))
    return cams


def particles(ppp, seed=1, lo=LO, hi=HI):
    rng = np.random.default_rng(seed)
    return rng.uniform(lo, hi, (int(round(ppp * RES[0] * RES[1])), 3))


def projected_error_px(cams, a, b):
    """Largest over the cameras of |project(a) - project(b)| [px], per particle."""
    return np.max([np.linalg.norm(c.project(a) - c.project(b), axis=1) for c in cams], axis=0)


# ---------------------------------------------------------------------- OTF
def test_projector_matches_the_elliptical_gaussian_written_afresh():
    cams = rig()
    otf = OTF.uniform(4, sigma_px=(1.4, 0.8), angle_deg=30.0, peak=2.5, lower_mm=LO, upper_mm=HI)
    p = np.array([[0.31, -1.17, 0.52]])
    img = project_particles(p, 1.5, cams, otf)[1]
    u0, v0 = cams[1].project(p)[0]
    t = np.radians(30.0)
    rows, cols = np.mgrid[0:256, 0:256]
    du, dv = cols + 0.5 - u0, rows + 0.5 - v0
    x = np.cos(t) * du + np.sin(t) * dv  # along the major axis
    y = -np.sin(t) * du + np.cos(t) * dv
    ref = 1.5 * 2.5 * np.exp(-0.5 * (x**2 / 1.4**2 + y**2 / 0.8**2))
    r = otf.radius_px()  # the stamp spans floor(u0) - r .. floor(u0) + r
    near = (np.abs(cols - np.floor(u0)) <= r) & (np.abs(rows - np.floor(v0)) <= r)
    np.testing.assert_allclose(img[near], ref[near], rtol=1e-12, atol=1e-15)
    assert img[~near].max() == 0.0 and ref[~near].max() < 0.02 * ref.max()


def test_otf_calibration_recovers_shape_and_peak_per_subvolume():
    cams = rig()
    p = particles(0.002, seed=3)
    # two sub-volumes along z with different particle images in camera 0
    true = OTF.uniform(4, sigma_px=(1.3, 0.9), angle_deg=25.0, peak=2.0, lower_mm=LO, upper_mm=HI, subvolumes=(1, 1, 2))
    true.a[0, :, :, 1] *= 0.7
    true.peak[0, :, :, 1] = 3.0
    inten = np.random.default_rng(4).uniform(0.5, 1.5, p.shape[0])
    # trilinear interpolation between the two cell centres: compare at the centres only
    centre = np.abs(p[:, 2] - np.where(p[:, 2] < 0, -1.75, 1.75)) < 0.6
    imgs = project_particles(p[centre], inten[centre], cams, true)
    fit = calibrate_otf(imgs, cams, p[centre], intensities=inten[centre], lower_mm=LO, upper_mm=HI, subvolumes=(1, 1, 2))
    for key in ("a", "b", "c", "peak"):
        np.testing.assert_allclose(getattr(fit, key), getattr(true, key), rtol=0.02, atol=2e-3, err_msg=key)


def test_otf_calibration_without_isolated_particles_raises():
    cams = rig()
    p = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0]])
    imgs = project_particles(p, 1.0, cams, OTF.uniform(4, lower_mm=LO, upper_mm=HI))
    with pytest.raises(CalibrationError, match="min_particles"):
        calibrate_otf(imgs, cams, p, lower_mm=LO, upper_mm=HI)


# ---------------------------------------------------------------------- IPR
def test_peaks_are_subpixel_exact_for_an_isolated_gaussian():
    img = np.zeros((32, 32))
    rows, cols = np.mgrid[0:32, 0:32]
    img += np.exp(-0.5 * ((cols + 0.5 - 12.3) ** 2 + (rows + 0.5 - 17.8) ** 2) / 1.1**2)
    uv, val = detect_peaks(img, threshold=0.1)
    np.testing.assert_allclose(uv, [[12.3, 17.8]], atol=1e-9)  # the 3-point Gaussian fit is exact


def test_triangulation_of_exact_peaks_finds_every_particle():
    cams = rig()
    p = particles(0.005, seed=2)
    x, ids, err = triangulate([c.project(p) for c in cams], cams, tolerance_px=0.5, lower_mm=LO, upper_mm=HI)
    true = np.all(ids == np.arange(p.shape[0])[:, None][ids[:, 0]], axis=1) if x.size else np.zeros(0, bool)
    assert set(ids[true, 0]) == set(range(p.shape[0]))
    np.testing.assert_allclose(x[true], p[ids[true, 0]], atol=1e-9)
    assert err.max() <= 0.5


def test_ipr_sparse_set_finds_99_percent_within_0p05_px():
    """Issue 27: 0.005 ppp, no noise, 4 pinhole cameras, Gaussian particle images."""
    cams = rig()
    p = particles(0.005)
    otf = OTF.uniform(4, sigma_px=1.0, lower_mm=LO, upper_mm=HI)
    imgs = project_particles(p, 1.0, cams, otf)
    r = ipr(imgs, cams, otf, lower_mm=LO - 0.5, upper_mm=HI + 0.5, threshold=0.1)
    pairs = assign(r.positions_mm, p, 0.08)  # 1 px in object space
    err = projected_error_px(cams, r.positions_mm[pairs[:, 0]], p[pairs[:, 1]])
    good = np.count_nonzero(err <= IPR_ERROR_PX)
    assert good >= IPR_YIELD * p.shape[0], (good, p.shape[0])
    assert len(r) - pairs.shape[0] <= 0.01 * p.shape[0]  # ghosts
    assert np.all(np.isfinite(r.positions_mm)) and np.all(r.intensities > 0)


# ---------------------------------------------------------------------- STB
# Issue 27's acceptance figures for STB
STB_VELOCITY_REL = 0.01
STB_ACCELERATION_REL = 0.05
N_FRAMES, DT_S = 8, 1e-3
BOX_LO, BOX_HI = LO - [2.5, 0.5, 0.5], HI + [2.5, 0.5, 0.5]  # reconstruction box: every particle's path


def sequence(traj, cams, otf):
    return [project_particles(traj[:, f], 1.0, cams, otf) for f in range(traj.shape[1])]


def test_stb_uniform_translation_velocity_within_1_percent():
    """Particles enter at -x and leave at +x; 3 px displacement per frame."""
    cams = rig()
    otf = OTF.uniform(4, sigma_px=1.0, lower_mm=BOX_LO, upper_mm=BOX_HI)
    rng = np.random.default_rng(5)
    p0 = rng.uniform(LO - [2.0, 0, 0], HI, (160, 3))
    u = np.array([240.0, 60.0, -30.0])  # [mm/s]: 0.25 mm = 3.1 px per frame
    traj = p0[:, None] + u * DT_S * np.arange(N_FRAMES)[None, :, None]
    tr = stb(sequence(traj, cams, otf), cams, otf, dt_s=DT_S, lower_mm=BOX_LO, upper_mm=BOX_HI, threshold=0.1)
    vel = np.broadcast_to(u, traj.shape)
    m = track_metrics(tr, traj, radius_mm=0.08, truth_velocities_mm_s=vel, truth_accelerations_mm_s2=np.zeros_like(traj),
                      lower_mm=LO, upper_mm=HI, cameras=cams)
    assert m["yield"] >= 0.95 and m["ghost_fraction"] <= 0.02, m
    assert m["velocity_error_rel"] <= STB_VELOCITY_REL, m
    # zero true acceleration: 5 % of the acceleration that would change |u| by itself over the sequence
    assert m["acceleration_error_mm_s2"] <= STB_ACCELERATION_REL * np.linalg.norm(u) / (N_FRAMES * DT_S), m
    assert m["correct_track_fraction"] >= 0.95, m
    inside = np.all((traj >= LO) & (traj <= HI), axis=2)
    entered = np.flatnonzero(~inside[:, 0] & inside[:, -1])
    assert entered.size > 0  # the set-up has particles entering the box ...
    assert np.all(np.isfinite(tr.positions_mm[tr.present])) and np.all(np.isfinite(tr.velocities_mm_s[tr.present]))


def test_stb_solid_body_rotation_velocity_1_and_acceleration_5_percent():
    cams = rig()
    otf = OTF.uniform(4, sigma_px=1.0, lower_mm=BOX_LO, upper_mm=BOX_HI)
    rng = np.random.default_rng(6)
    r = 7.0 * np.sqrt(rng.uniform(0.05, 1.0, 150))
    th0 = rng.uniform(0, 2 * np.pi, r.size)
    z = rng.uniform(LO[2], HI[2], r.size)
    w = 40.0  # [rad/s]: 0.04 rad per frame, up to 3.5 px per frame
    th = th0[:, None] + w * DT_S * np.arange(N_FRAMES)
    traj = np.stack([r[:, None] * np.cos(th), r[:, None] * np.sin(th), np.broadcast_to(z[:, None], th.shape)], axis=-1)
    vel = np.stack([-w * traj[..., 1], w * traj[..., 0], np.zeros(th.shape)], axis=-1)
    acc = np.stack([-w**2 * traj[..., 0], -w**2 * traj[..., 1], np.zeros(th.shape)], axis=-1)
    tr = stb(sequence(traj, cams, otf), cams, otf, dt_s=DT_S, lower_mm=BOX_LO, upper_mm=BOX_HI, threshold=0.1)
    m = track_metrics(tr, traj, radius_mm=0.08, truth_velocities_mm_s=vel, truth_accelerations_mm_s2=acc, cameras=cams)
    assert m["yield"] >= 0.95 and m["ghost_fraction"] <= 0.02, m
    assert m["velocity_error_rel"] <= STB_VELOCITY_REL, m
    assert m["acceleration_error_rel"] <= STB_ACCELERATION_REL, m
