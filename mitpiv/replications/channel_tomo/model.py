"""The simulated tomographic-PIV experiment of the channel-tomo paper (turbulent channel at
Re_tau = 934; the project's seed paper 004): four cameras on a sphere of 5000 wall units,
rendered calibration targets and a fitted third-order polynomial mapping (the paper's eqs.
1-2), 8-bit particle images with a per-camera Mie scaling and Gaussian noise at 10 % of the
global peak particle intensity, histogram-threshold pre-processing, MLOS-SMART with bicubic
image interpolation, normalised-cross-correlation 3D PIV and wall-unit statistics against
the window-averaged and the point truth.

The paper renders with the MATLAB camera toolbox (pinhole cameras, Phong-lit spheres, the
volume "considered to be in focus") and scales each camera's image by a smooth polynomial
fit of a Mie angular function; this module does the same in NumPy (no Mitsuba): each
particle is projected through its camera (:class:`mitpiv.physics.camera.PinholeCamera`)
and splatted as a pixel-integrated Gaussian (:func:`mitpiv.imaging.splat_points`) scaled
by the camera's Mie factor. Hand-written because the paper's pipeline is a 2D image model,
not a light-transport one; the Mitsuba scene of the same experiment is ``scenes/channel``.

Choices the paper leaves open (written down, not tuned):

- wall units: u_tau = 500 mm/s and nu = 15.1 mm^2/s (air), l_nu = 0.0302 mm, so the
  sphere is 151 mm and the 100+ sheet 3.02 mm; the volume centre sits at y+ = 150 (the
  paper's Table 1 band 100 < y+ < 200 is the sheet);
- cameras: ideal pinholes (the paper's volume is in focus), no lens distortion (the paper
  gives no coefficients), 10 um pixels, the focal length chosen so that one pixel sees one
  voxel at the volume centre (the paper's voxel-to-pixel ratio ~ 1); the sensor is cropped
  to the projection of the reconstructed box plus 6 px;
- particle images: Gaussian of e^-2 diameter 1.89 wall units (3 px at l_v+ = 0.63, the
  paper's "particle diameter of approximately three pixels"; a fixed physical size, so 2 px
  at 0.94 and 4 px at 0.47), all of the same energy (the Mie factor is per camera, as the
  paper's "scaling factor", not per particle);
- exposure and noise: one exposure and one noise level for every camera of every
  configuration: a single particle centred on a pixel peaks at 150 counts times the
  camera's Mie factor, which is 1 for the reference camera (the paper's Table 2
  normalisation: forward, theta 25, phi 60), and the noise sigma is 10 % of the reference
  peak, 15 counts (the paper's "10 % of the global peak particle intensity across all the
  cameras"), white and zero-mean, added after the Mie scaling of the particle light (the
  camera noise does not depend on the scattering angle, so each camera's signal-to-noise
  ratio follows its Mie factor: the paper's ~11 % / ~16 % noise-to-peak forward / backward
  at the optimum, and its lower Q for an all-backward configuration); overlapping particles
  add and saturate at 255 (a camera at theta 5 deg peaks at 230); the 8-bit ADC rounds and
  clips negative noise at 0;
- the Mie factor, ``mie="paper"``: the paper's own angular function, a quadratic in the
  azimuth theta (from the laser direction, 0-180 deg) fitted to its Table 2 maximum
  intensities (1.00, 0.62, 0.29, 0.15, 0.35, 0.68 at theta = 25, 45, 70, 110, 135, 155
  deg); ``mie="physical"``: the Lorenz-Mie differential cross-section of oil droplets (n =
  1.47) in air at 532 nm averaged over a uniform number distribution of 1-4 um
  (:mod:`mitpiv.physics.mie`) at each camera's true 3D scattering angle. They differ
  (physical: 9x between 59 and 121 deg; the paper's: 1.5x), see the replication report;
- calibration target: Gaussian dots (sigma 0.8 px) on a lattice of up to 9 x 9 spanning
  the reconstructed box (fewer where the foreshortened pitch would fall below 6 px) at five
  depths (-50, -25, 0, 25, 50 wall units), peak 150 counts on a plate of 7.5 counts, 1 % noise; dots found by :func:`mitpiv.reconstruct.calibration.detect_dots`, labelled by the
  design projection, fitted with the Soloff polynomial (cubic in x and y, quadratic in z;
  the paper's "third-order polynomial") by :func:`mitpiv.reconstruct.calibrate`;
- pre-processing: :func:`mitpiv.reconstruct.preprocess_images` at the histogram's
  background level (k = 0; the paper's "histogram-based thresholding"; a higher threshold
  cuts particle wings that SMART's zero-pixel rule turns into lost particles); reconstruction: SMART (Atkinson &
  Soria 2009) from the MLOS volume with bicubic image interpolation, 5 iterations (the
  paper gives no count), the circle weight model;
- the second frame: particles displaced by their local velocity over dt at first order
  (the paper: "determined to first-order accuracy"); dt gives 5 wall units (25 % of the
  20+ window) at y+ = 150;
- PIV: :func:`mitpiv.analysis.piv3d` with ``correlation="ncc"`` (the paper's eq. 3), a
  1.5x-larger predictor pass then the window, 75 % overlap, validation and median
  replacement; statistics per vector layer (:mod:`mitpiv.analysis.channel`).
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from mitpiv.errors import ConfigError
from mitpiv.imaging import PointPSFTable, point_images, splat_points

__all__ = ["ChannelTomoSystem", "PAPER_TABLE_2", "paper_mie_factor", "physical_mie_factor", "camera_for_pose",
           "camera_poses", "mie_factors", "to_8bit", "calibrate_pose", "evaluate_point",
           "image_statistics"]

log = logging.getLogger(__name__)

#: Table 2 of the paper (phi = 60 deg): theta -> (mean, max) image intensity, normalised
PAPER_TABLE_2 = {25: (0.81, 1.00), 45: (0.49, 0.62), 70: (0.23, 0.29), 110: (0.09, 0.15), 135: (0.27, 0.35),
                 155: (0.53, 0.68)}
#: The reference camera of the exposure and the noise (Table 2's 1.00: forward, theta 25, phi 60)
REFERENCE_THETA_DEG = 25.0
REFERENCE_PHI_DEG = 60.0


@dataclass(frozen=True)
class ChannelTomoSystem:
    """The paper's experiment; lengths in wall units unless the name says otherwise."""

    friction_velocity_mm_s: float = 500.0
    viscosity_mm2_s: float = 15.1
    center_y_plus: float = 150.0
    sheet_plus: float = 100.0
    distance_plus: float = 5000.0
    pixel_pitch_um: float = 10.0
    particle_image_plus: float = 1.89
    window_plus: float = 20.0
    displacement_plus: float = 5.0
    noise_fraction: float = 0.10
    peak_counts: float = 150.0
    full_scale: int = 255
    iterations: int = 5
    preprocess_k: float = 0.0
    #: Gaussian smoothing of the 8-bit images before the threshold [px] (not in the paper; see
    #: :func:`mitpiv.reconstruct.preprocess_images`): without it the ADC-clipped noise zeroes
    #: the particles' voxels in SMART and the PIV between two reconstructions fails at l_v+ 0.94
    image_smoothing_px: float = 0.7
    target_lattice: int = 9
    target_depths_plus: tuple = (-50.0, -25.0, 0.0, 25.0, 50.0)
    target_dot_sigma_px: float = 0.8
    modes: int = 1000
    margin_px: int = 6

    @property
    def l_nu_mm(self) -> float:
        """Viscous length nu / u_tau [mm]."""
        return self.viscosity_mm2_s / self.friction_velocity_mm_s

    def mm(self, plus) -> float:
        return float(plus) * self.l_nu_mm

    @property
    def particle_sigma_plus(self) -> float:
        """Gaussian sigma of a particle image in wall units (a quarter of its e^-2 diameter)."""
        return self.particle_image_plus / 4.0

    def channel(self, flow_seed: int):
        return _channel(self.friction_velocity_mm_s, self.viscosity_mm2_s, self.center_y_plus, self.modes,
                        int(flow_seed))

    def dt_s(self, flow_seed: int = 0) -> float:
        """Frame separation giving ``displacement_plus`` at the mean velocity of y+ = center."""
        u_plus = float(self.channel(flow_seed).profile_table.mean_plus(np.array([self.center_y_plus]))[0])
        return self.displacement_plus / u_plus * self.viscosity_mm2_s / self.friction_velocity_mm_s**2

    def box_mm(self, crop_plus: float) -> tuple[np.ndarray, np.ndarray]:
        """Reconstructed box: crop x crop in the wall-parallel plane, the sheet across [mm]."""
        h = np.array([crop_plus / 2, crop_plus / 2, self.sheet_plus / 2]) * self.l_nu_mm
        return -h, h


@lru_cache(maxsize=4)
def _channel(u_tau, nu, yc, modes, seed):
    from mitpiv.physics.flows import Channel

    return Channel(friction_velocity_mm_s=u_tau, viscosity_mm2_s=nu, center_y_plus=yc, modes=modes, seed=seed)


# ---------------------------------------------------------------------- Mie scaling
def paper_mie_factor(theta_deg) -> np.ndarray:
    """The paper's angular scaling: a quadratic in the azimuth from the laser direction
    (folded to 0-180 deg) least-squares fitted to its Table 2 maximum intensities, divided by
    its value at theta = 25 deg (the table's reference camera: 1.00)."""
    th = np.array(sorted(PAPER_TABLE_2), dtype=float)
    mx = np.array([PAPER_TABLE_2[t][1] for t in sorted(PAPER_TABLE_2)])
    c = np.polyfit(th, mx, 2)
    t = np.degrees(np.arccos(np.cos(np.radians(np.asarray(theta_deg, dtype=float)))))
    return np.polyval(c, t) / np.polyval(c, REFERENCE_THETA_DEG)


@lru_cache(maxsize=1)
def _physical_table():
    from mitpiv.physics.mie import differential_cross_section

    ang = np.linspace(0.0, 180.0, 181)
    d = np.linspace(1.0, 4.0, 61)
    dcs = np.mean([differential_cross_section(float(di), 1.47, ang) for di in d], axis=0)
    return ang, dcs / dcs.max()


def physical_mie_factor(scattering_angle_deg) -> np.ndarray:
    """Lorenz-Mie differential cross-section of 1-4 um oil droplets (n = 1.47, uniform number
    distribution, 61 sizes) in air at 532 nm, unpolarised, at the scattering angles [deg]
    (linear interpolation in a 1-degree table), relative to the reference camera (theta =
    25, phi = 60 deg: scattering angle 63.0 deg)."""
    ang, v = _physical_table()
    ref = math.degrees(math.acos(math.cos(math.radians(REFERENCE_PHI_DEG)) * math.cos(math.radians(REFERENCE_THETA_DEG))))
    return np.interp(np.asarray(scattering_angle_deg, dtype=float), ang, v) / np.interp(ref, ang, v)


# ---------------------------------------------------------------------- cameras
def camera_poses(configuration: str, theta_deg: float, phi_deg: float) -> list[tuple[float, float]]:
    """(azimuth, elevation) [deg] of the four cameras (:func:`quadrant_arrangement`)."""
    from mitpiv.physics.sphere_cameras import quadrant_arrangement

    cams = quadrant_arrangement(configuration, theta_deg=float(theta_deg), phi_deg=float(phi_deg), distance_mm=1.0)
    return [(c["azimuth_deg"], c["elevation_deg"]) for c in cams]


def camera_for_pose(system: ChannelTomoSystem, azimuth_deg: float, elevation_deg: float, voxel_plus: float,
                    crop_plus: float):
    """A pinhole camera on the sphere looking at the volume centre, one pixel per voxel at
    the centre, its sensor cropped to the projection of the reconstructed box (+ margin)."""
    from mitpiv.physics.camera import PinholeCamera, place_camera

    dist = system.mm(system.distance_plus)
    rot, pos = place_camera(azimuth_deg=azimuth_deg, elevation_deg=elevation_deg, distance_mm=dist)
    f_mm = dist * (system.pixel_pitch_um * 1e-3) / system.mm(voxel_plus)  # f_px = dist / voxel
    probe = PinholeCamera((2, 2), f_mm, system.pixel_pitch_um, rotation=rot, position_mm=pos,
                          principal_point_px=(0.0, 0.0))
    lo, hi = system.box_mm(crop_plus)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    half = np.ceil(np.abs(probe.project(corners)).max(axis=0)).astype(int) + system.margin_px
    return PinholeCamera((2 * int(half[0]), 2 * int(half[1])), f_mm, system.pixel_pitch_um, rotation=rot,
                         position_mm=pos, principal_point_px=(float(half[0]), float(half[1])))


def mie_factors(poses, model: str) -> np.ndarray:
    """Per-camera scaling of the particle light for poses (azimuth, elevation) [deg]."""
    az = np.array([p[0] for p in poses])
    el = np.array([p[1] for p in poses])
    if model == "paper":
        return paper_mie_factor(az)
    if model == "physical":
        s = np.degrees(np.arccos(np.clip(np.cos(np.radians(el)) * np.cos(np.radians(az)), -1, 1)))
        return physical_mie_factor(s)
    raise ConfigError(f"mie_factors: model={model!r} is not 'paper' or 'physical'.")


# ---------------------------------------------------------------------- images
def to_8bit(clean, sigma_counts: float, rng, full_scale: int = 255) -> np.ndarray:
    """Add white Gaussian noise, round, clip to [0, full_scale] (an 8-bit ADC)."""
    return np.clip(np.rint(clean + rng.normal(0.0, sigma_counts, clean.shape)), 0, full_scale)


def image_statistics(system: ChannelTomoSystem, configuration: str, theta_deg: float, phi_deg: float, *,
                     mie: str, voxel_plus: float, crop_plus: float, n_i: float, seed: int) -> dict:
    """Noise-free image statistics of one configuration (the paper's Table 2): per camera the
    mean of the particles' peak pixels and the largest pixel [counts], before noise, with
    every camera at ``peak_counts`` times its Mie factor (one absolute scale for all
    configurations); also the factors."""
    poses = camera_poses(configuration, theta_deg, phi_deg)
    cams = [camera_for_pose(system, a, e, voxel_plus, crop_plus) for a, e in poses]
    fac = mie_factors(poses, mie)
    rng = np.random.default_rng(seed)
    pts = _seed(system, rng, crop_plus, phi_deg, n_i, extra_plus=0.0)
    table = PointPSFTable.gaussian(system.particle_sigma_plus / voxel_plus)
    imgs = point_images(cams, pts, table, peak=system.peak_counts, factors=fac)
    means, maxes = [], []
    for cam, im in zip(cams, imgs, strict=True):
        uv = cam.project(pts)
        ij = np.floor(uv).astype(int)
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < im.shape[1]) & (ij[:, 1] >= 0) & (ij[:, 1] < im.shape[0])
        means.append(float(np.mean(im[ij[ok, 1], ij[ok, 0]])))
        maxes.append(float(im.max()))
    return {"mean_counts": means, "max_counts": maxes, "factors": fac.tolist(), "poses": poses}


# ---------------------------------------------------------------------- calibration
def calibrate_pose(system: ChannelTomoSystem, azimuth_deg: float, elevation_deg: float, voxel_plus: float,
                   crop_plus: float, *, seed: int = 0) -> dict:
    """Render the multi-plane dot target for one camera pose, locate and label the dots, fit
    the polynomial mapping. Returns the mapping (``to_dict``), the camera and the fit report."""
    from mitpiv.reconstruct.calibration import calibrate, detect_dots, label_markers

    t0 = time.perf_counter()
    cam = camera_for_pose(system, azimuth_deg, elevation_deg, voxel_plus, crop_plus)
    lo, hi = system.box_mm(crop_plus)
    # dots at least 6 px apart on the sensor: the sheet is foreshortened by sin(phi)
    min_pitch = 6.0 * voxel_plus / math.sin(math.radians(abs(elevation_deg)))
    g = np.linspace(0.0, 1.0, max(3, min(system.target_lattice, int(crop_plus / min_pitch) + 1)))
    xx, yy = np.meshgrid(lo[0] + g * (hi[0] - lo[0]), lo[1] + g * (hi[1] - lo[1]))
    table = PointPSFTable.gaussian(system.target_dot_sigma_px)
    rng = np.random.default_rng(seed)
    px, world, located = [], [], []
    for z in system.target_depths_plus:
        mk = np.column_stack([xx.ravel(), yy.ravel(), np.full(xx.size, system.mm(z))])
        uv = cam.project(mk)
        img = splat_points(uv, cam.resolution, table, dtype=np.float64) * (system.peak_counts / table.peak())
        img = to_8bit(img + 0.05 * system.peak_counts, 0.01 * system.peak_counts, rng, system.full_scale)
        det = detect_dots(img, threshold=0.3 * system.peak_counts)
        mi, di = label_markers(det, uv)
        px.append(det[di])
        world.append(mk[mi])
        located.append(np.linalg.norm(det[di] - uv[mi], axis=1))
    px, world, located = np.concatenate(px), np.concatenate(world), np.concatenate(located)
    m = calibrate(px, world, model="polynomial", resolution=cam.resolution, max_rms_px=0.5)
    return {"mapping": m.to_dict(), "camera": cam.to_dict(), "rms_px": m.fit_report["rms_px"],
            "max_px": m.fit_report["max_px"], "markers": int(len(px)),
            "locate_rms_px": float(np.sqrt(np.mean(located**2))), "wall_s": time.perf_counter() - t0}


# ---------------------------------------------------------------------- one point
def _seed(system, rng, crop_plus, phi_deg, n_i, extra_plus):
    """Particles at N_I per (window_plus)^3 in the reconstructed box widened by the largest
    lateral reach of a line of sight across the sheet (sheet / tan(phi)) and ``extra_plus``."""
    reach = system.sheet_plus / math.tan(math.radians(abs(phi_deg))) + 3 * system.particle_image_plus + extra_plus
    half = np.array([crop_plus / 2 + reach, crop_plus / 2 + reach, system.sheet_plus / 2])
    vol = float(np.prod(2 * half))
    n = rng.poisson(n_i / system.window_plus**3 * vol)
    return rng.uniform(-half, half, size=(n, 3)) * system.l_nu_mm


def _reconstruct(system, maps, cams, factors, pts, table, grid, sigma, rng):
    from mitpiv.reconstruct import mart

    clean = point_images(cams, pts, table, peak=system.peak_counts, factors=factors)
    imgs = [to_8bit(c, sigma, rng, system.full_scale) for c in clean]
    vol, info = mart(imgs, maps, grid, iterations=system.iterations, smart=True, interpolation="cubic",
                     preprocess=system.preprocess_k, smooth_px=system.image_smoothing_px, return_info=True,
                     residuals="final")
    return vol, info


def evaluate_point(system: ChannelTomoSystem, *, configuration: str, theta_deg: float, phi_deg: float,
                   voxel_plus: float, crop_plus: float, n_i: float, seed: int, flow_seed: int, mie: str,
                   calibrations: list[dict], windows_voxels=(), overlap: float = 0.75) -> dict:
    """Seed, image, pre-process, reconstruct (through the fitted mappings) and score one
    configuration; with ``windows_voxels``, also the second frame, PIV per window size and
    the wall-unit statistics.

    Returns a dict: ``Q`` (eq. 5) of the first frame against the ideal reconstruction
    (Gaussian blobs of the particle image sigma), ``noise_to_peak`` per camera, ``active``
    voxels, and per window size ``piv[str(I)]``: ``y_plus``, statistics (``meas``, ``avg``
    the window-averaged truth, ``dns`` the point truth at the vector positions; each with U,
    u_rms, v_rms, w_rms in wall units), ``vectors`` (the valid vectors' y+ and their
    measured / averaged / point velocities in wall units, local frame: streamwise,
    wall-normal, spanwise; for statistics pooled over patches), ``err_avg`` / ``err_dns`` (percent, 100 < y+ < 200),
    ``outliers``, ``n_vectors``; wall and CPU times [s] (``wall_s``, ``cpu_s``, ``reconstruct_s``).
    """
    from mitpiv.analysis.channel import field_wall_statistics, statistics_error_percent, wall_statistics
    from mitpiv.analysis.piv3d import piv3d
    from mitpiv.analysis.quality import quality_q, truth_volume
    from mitpiv.grid import VoxelGrid
    from mitpiv.physics.camera import PinholeCamera
    from mitpiv.reconstruct.mapping import CameraMapping

    t0, c0 = time.perf_counter(), time.process_time()
    poses = camera_poses(configuration, theta_deg, phi_deg)
    if len(calibrations) != len(poses):
        raise ConfigError(f"evaluate_point: {len(calibrations)} calibrations for {len(poses)} cameras.")
    cams = [PinholeCamera.from_dict(c["camera"]) for c in calibrations]
    maps = [CameraMapping.from_dict(c["mapping"]) for c in calibrations]
    factors = mie_factors(poses, mie)
    sigma = system.noise_fraction * system.peak_counts
    rng = np.random.default_rng(seed)
    table = PointPSFTable.gaussian(system.particle_sigma_plus / voxel_plus)
    lo, hi = system.box_mm(crop_plus)
    grid = VoxelGrid.from_bounds(lo, hi, system.mm(voxel_plus))
    piv = bool(windows_voxels)
    pts = _seed(system, rng, crop_plus, phi_deg, n_i, extra_plus=2 * system.displacement_plus if piv else 0.0)
    vol_a, info = _reconstruct(system, maps, cams, factors, pts, table, grid, sigma, rng)
    t_rec = time.perf_counter() - t0
    truth = truth_volume(pts, grid, system.particle_sigma_plus / voxel_plus)
    out = {"Q": float(quality_q(vol_a, truth)), "noise_to_peak": (sigma / (system.peak_counts * factors)).tolist(),
           "factors": factors.tolist(), "active": int(info["active_voxels"]), "particles": int(len(pts)),
           "grid": list(grid.shape), "reconstruct_s": t_rec}
    if piv:
        ch = system.channel(flow_seed)
        dt = system.dt_s(flow_seed)
        pts_b = pts + ch.velocity(pts, 0.0) * dt  # first order, as the paper
        vol_b, _ = _reconstruct(system, maps, cams, factors, pts_b, table, grid, sigma, rng)
        out["piv"] = {}
        for w in windows_voxels:
            w = int(w)
            field = piv3d(vol_a, vol_b, grid, windows=(int(round(1.5 * w)), w), overlap=overlap, correlation="ncc",
                          dt_s=dt, replace="median")
            p = field.points_mm().reshape(-1, 3)
            meas = field_wall_statistics(field, ch)
            win_mm = np.full(3, w * system.mm(voxel_plus))
            v_avg, v_dns = ch.window_average(p, win_mm), ch.velocity(p, 0.0)
            avg = wall_statistics(p, v_avg, ch)
            dns = wall_statistics(p, v_dns, ch)
            keys = ("y_plus", "U", "u_rms", "v_rms", "w_rms")
            use = field.valid.reshape(-1)
            vel = np.stack([field.u, field.v, field.w], axis=-1).reshape(-1, 3)

            def plus(v, use=use):  # world velocities [mm/s] -> local frame in wall units, 4 decimals
                return np.round((np.asarray(v)[use] @ ch.frame.T) / ch.friction_velocity_mm_s, 4).tolist()

            out["piv"][str(w)] = {
                "meas": {k: np.asarray(meas[k]).tolist() for k in keys},
                "avg": {k: np.asarray(avg[k]).tolist() for k in keys},
                "dns": {k: np.asarray(dns[k]).tolist() for k in keys},
                "vectors": {"y_plus": np.round(ch.wall_distance_plus(p[use]), 4).tolist(), "meas": plus(vel),
                            "avg": plus(v_avg), "dns": plus(v_dns)},
                "err_avg": statistics_error_percent(meas, avg), "err_dns": statistics_error_percent(meas, dns),
                "outliers": float(field.outlier_ratio), "n_vectors": int(field.n_vectors),
                "window_plus": w * voxel_plus}
    out["wall_s"] = time.perf_counter() - t0
    out["cpu_s"] = time.process_time() - c0
    return out
