"""The simulated SAPIV system of the aberration study (Kubaczyk, MIT S.M. thesis, section 3.3):
a 5 x 5 pinhole camera array imaging static particles, radial distortion and spherical
aberration applied to every image (calibration targets included), a pinhole calibration
fitted to rendered targets, homography refocusing, thresholding and the chapter-4 measures.

The paper renders with "a linear pinhole camera model" and then applies distortion and
the aberration PSF to the images; this module does the same in NumPy (no Mitsuba): each
point (particle or target dot) is projected through the true camera (pinhole + the
percent-distortion k1 of appendix A, so the distortion moves light exactly as the paper's
image warp does) and spread by the pixel-integrated Fourier-optics PSF with the Zernike
spherical aberration (:class:`mitpiv.imaging.PointPSFTable`). Hand-written because the
paper's pipeline is a 2D image model, not a light-transport one; the Mitsuba scene of the
same system is ``scenes/sapiv_paper``.

Choices the paper leaves open (written down, not tuned):

- the pinhole sits at the lens; with an 85 mm lens at M = -0.2 the image distance is
  ``f (1 + |M|) = 102 mm`` and the object distance ``f (1 + 1/|M|) = 510 mm`` (the array's
  plane is 510 mm from the volume centre, every camera aimed at it);
- the PSF: f/2.8 (the aperture of the paper's Fig. 3-3), working f-number ``N (1 + |M|)``,
  532 nm, 5 x 5 px window renormalised to 1 (the paper's Table 3.2 window); the 4 um
  geometric image of a 20 um particle is left out (smaller than the Airy disc and the pixel);
- targets: dots of Gaussian profile (sigma 0.1 mm) on a 5 mm grid over 50 x 50 mm at five
  depths z = -5, -2.5, 0, 2.5, 5 mm; each dot located by the normal fit (intensity-weighted
  mean) of its image, labelled by construction;
- no sensor noise (the paper has none); particle energy 1;
- the threshold and the true volume ``V_S``, which the paper leaves open, are scored under
  six readings on every point (:data:`READINGS`); the study's rows use :data:`ADOPTED`
  (each plane's mean + 3 std; each 20 um particle voxelised by volume fraction), chosen for
  its literalness.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from mitpiv.errors import ConfigError
from mitpiv.grid import VoxelGrid
from mitpiv.physics.camera import PinholeCamera, planar_array
from mitpiv.physics.distortion import Distortion, percent_to_k1

__all__ = ["SapivSystem", "PercentWarpCamera", "locate_dots", "render_dot_windows", "calibrate_from_targets",
           "evaluate_point", "seed_field", "score_images", "patch_centres", "mapping_error", "LAWS", "READINGS"]

#: the distortion laws: eq. A.3 (shift p/100 r_n^3 r_max, the thesis's equations; a Brown-Conrady
#: k1 of the true camera) and Table 3.1's columns (shift p/100 r_n^2 r_max, a pixel warp)
LAWS = ("A.3", "T3.1")

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class SapivSystem:
    """The paper's system (section 3.3); every field in the paper's units."""

    rows: int = 5
    cols: int = 5
    spacing_mm: float = 153.0
    resolution: int = 1000
    pixel_pitch_um: float = 10.0
    focal_length_mm: float = 85.0
    magnification: float = 0.2  # |M|; the image is inverted (M = -0.2)
    volume_mm: tuple = (50.0, 50.0, 10.0)
    particle_diameter_um: float = 20.0
    f_number: float = 2.8
    wavelength_nm: float = 532.0
    voxel_mm: float = 0.05
    n_planes: int = 201
    target_pitch_mm: float = 5.0
    target_depths_mm: tuple = (-5.0, -2.5, 0.0, 2.5, 5.0)
    target_dot_sigma_mm: float = 0.1
    truth_sigma_voxels: float = 0.7
    extra: dict = field(default_factory=dict)

    @property
    def image_distance_mm(self) -> float:
        return self.focal_length_mm * (1.0 + self.magnification)

    @property
    def object_distance_mm(self) -> float:
        return self.focal_length_mm * (1.0 + 1.0 / self.magnification)

    @property
    def z_planes_mm(self) -> np.ndarray:
        """The refocused planes: ``n_planes`` spanning the depth (0.05 mm apart)."""
        h = self.volume_mm[2] / 2
        return np.linspace(-h, h, self.n_planes)

    def cameras(self, distortion_percent: float = 0.0, law: str = "A.3") -> list:
        """The 25 true cameras (row-major from the top-left), with the percent distortion
        of appendix A on each: ``law`` "A.3" is eq. A.3 with A.8 (``K1 = -p / (100 r_max^2)``,
        r_max the corner radius: a :class:`PinholeCamera` with that k1, as the
        ``distorted_pinhole`` sensor renders it), "T3.1" the law of Table 3.1's columns
        (a radial shift ``p/100 r_n^2 r_max``: :class:`PercentWarpCamera`)."""
        if law not in LAWS:
            raise ConfigError(f"SapivSystem.cameras: 'law' must be one of {LAWS}, got {law!r}.")
        if law == "T3.1" and distortion_percent:
            return [PercentWarpCamera(c, distortion_percent, exponent=2) for c in self.cameras(0.0)]
        res = (self.resolution, self.resolution)
        arr = planar_array(self.rows, self.cols, spacing_mm=self.spacing_mm, distance_mm=self.object_distance_mm)
        probe = PinholeCamera(res, self.image_distance_mm, self.pixel_pitch_um)
        d = Distortion(k1=percent_to_k1(distortion_percent, r_max=probe.corner_radius)) if distortion_percent else Distortion()
        return [PinholeCamera(res, self.image_distance_mm, self.pixel_pitch_um, rotation=e["rotation"],
                              position_mm=e["position_mm"], distortion=d) for e in arr]

    @property
    def reference_index(self) -> int:
        """The central camera (the reference view)."""
        return (self.rows // 2) * self.cols + self.cols // 2

    def max_parallax_mm(self) -> float:
        """Largest lateral reach of a camera ray across the volume's depth [mm]: the seeding
        margin around a reconstructed patch that holds every particle whose light can reach it."""
        off = np.hypot((self.cols - 1) / 2, (self.rows - 1) / 2) * self.spacing_mm
        return float(self.volume_mm[2] * off / (self.object_distance_mm - self.volume_mm[2] / 2))

    def psf_table(self, spherical_waves: float):
        from mitpiv.imaging import PointPSFTable

        return PointPSFTable.build(f_number=self.f_number, pixel_pitch_um=self.pixel_pitch_um,
                                   magnification=self.magnification, spherical_waves=spherical_waves,
                                   wavelength_nm=self.wavelength_nm)

    def target_markers(self) -> np.ndarray:
        """(n, 3) dot centres of the calibration target at every depth [mm]."""
        hx, hy = self.volume_mm[0] / 2, self.volume_mm[1] / 2
        gx = np.arange(-hx, hx + 1e-9, self.target_pitch_mm)
        gy = np.arange(-hy, hy + 1e-9, self.target_pitch_mm)
        xx, yy = np.meshgrid(gx, gy)
        return np.concatenate([np.column_stack([xx.ravel(), yy.ravel(), np.full(xx.size, z)])
                               for z in self.target_depths_mm])


class PercentWarpCamera:
    """A distortion-free pinhole camera whose image is warped radially about the principal
    point by the percent law with the shift ``p/100 r_n^m r_max`` (``r_n = r_u / r_max``,
    ``r_max`` the corner radius in pixels; positive p inwards, barrel):
    ``r_d = r_u (1 - p/100 r_n^(m-1))``. ``m = 3`` is eq. A.3 (the same map as a k1 of
    :class:`PinholeCamera`, tested), ``m = 2`` the law Table 3.1's columns follow. The
    thesis warps its images the same way, in pixels after the pinhole projection.
    Provides what the study uses of a camera: ``project``, ``jacobian``, ``resolution``,
    ``pixel_pitch_um``."""

    def __init__(self, base: PinholeCamera, percent: float, *, exponent: int = 2):
        if not base.distortion.is_zero:
            raise ConfigError("PercentWarpCamera: the base camera must be distortion-free (the warp is the distortion).")
        if exponent < 1:
            raise ConfigError(f"PercentWarpCamera: 'exponent' must be >= 1, got {exponent!r}.")
        self.base, self.percent, self.exponent = base, float(percent), int(exponent)
        self.resolution, self.pixel_pitch_um = base.resolution, base.pixel_pitch_um
        self.r_max_px = base.corner_radius * base.focal_px

    def _warp(self, uv):
        c = np.asarray(self.base.principal_point_px)
        d = uv - c
        r = np.hypot(d[..., 0], d[..., 1])
        s = 1.0 - self.percent / 100.0 * (r / self.r_max_px) ** (self.exponent - 1)
        return c, d, r, s

    def project(self, p_world_mm) -> np.ndarray:
        c, d, _, s = self._warp(self.base.project(p_world_mm))
        return c + d * s[..., None]

    def jacobian(self, p_world_mm) -> np.ndarray:
        """``d(u, v)/d(x, y, z)`` [px/mm]: the warp's Jacobian ``s I + d (grad s)^T`` times the pinhole's."""
        _, d, r, s = self._warp(self.base.project(p_world_mm))
        m = self.exponent
        with np.errstate(divide="ignore", invalid="ignore"):
            g = -self.percent / 100.0 * (m - 1) * r ** (m - 2) / self.r_max_px ** (m - 1)  # ds/dr
            unit = np.where(r[..., None] > 0, d / r[..., None], 0.0)
        w = s[..., None, None] * np.eye(2) + (d[..., :, None] * (g[..., None] * unit)[..., None, :])
        return w @ self.base.jacobian(p_world_mm)


def mapping_error(system: SapivSystem, cameras, mappings, *, n: int = 4096, seed: int = 0) -> list[float]:
    """RMS distance [px] between each camera's true projection and its calibrated mapping's,
    over ``n`` points uniform in the volume (the thesis ties Q = 0.75 to 0.45 px of mapping
    error, citing Belden et al.)."""
    p = np.random.default_rng(seed).uniform(-np.asarray(system.volume_mm) / 2, np.asarray(system.volume_mm) / 2, (n, 3))
    return [float(np.sqrt(np.mean(np.sum((c.project(p) - m.project(p)) ** 2, axis=1)))) for c, m in zip(cameras, mappings, strict=True)]


# ---------------------------------------------------------------------- targets and calibration
def render_dot_windows(camera: PinholeCamera, markers_mm, table, *, dot_sigma_mm: float, window: int = 25):
    """Images of target dots, one ``window x window`` patch per dot around its pixel.

    Each dot (a Gaussian of ``dot_sigma_mm`` on a target plane z = const) is imaged with its
    local affine map (the camera's Jacobian, distortion included) at its projected centre,
    then convolved with the PSF footprint of ``table`` (the aberration). Returns ``(i0, j0,
    windows)``: window ``[a, b]`` is image pixel (row ``j0 + a``, column ``i0 + b``).
    """
    from scipy.signal import fftconvolve

    m = np.asarray(markers_mm, dtype=float)
    uv = camera.project(m)
    jac = camera.jacobian(m)[:, :, :2]  # d(u, v)/d(x, y) on the target plane
    cov = dot_sigma_mm**2 * jac @ np.swapaxes(jac, 1, 2)
    inv = np.linalg.inv(cov)
    h = window // 2
    base = np.floor(uv).astype(np.int64)
    d = np.arange(-h, h + 1)
    dx = (base[:, 0:1] + d[None, :] + 0.5) - uv[:, 0:1]  # (n, w): column centres - dot centre
    dy = (base[:, 1:2] + d[None, :] + 0.5) - uv[:, 1:2]
    qx = dx[:, None, :]
    qy = dy[:, :, None]
    e = inv[:, 0, 0, None, None] * qx * qx + 2 * inv[:, 0, 1, None, None] * qx * qy + inv[:, 1, 1, None, None] * qy * qy
    win = np.exp(-0.5 * e)
    _, _, k = table.footprints(np.array([[0.5, 0.5]]))
    win = fftconvolve(win, k, mode="same", axes=(1, 2))
    win = np.maximum(win, 0.0)
    win /= win.sum(axis=(1, 2), keepdims=True)
    return base[:, 0] - h, base[:, 1] - h, win


def locate_dots(i0, j0, windows, *, half: int = 6) -> np.ndarray:
    """Dot centres [px] from their image windows: the mean of a normal distribution fitted
    to the intensities (maximum likelihood: the intensity-weighted mean) within ``half`` px
    of each window's brightest pixel."""
    w = np.asarray(windows, dtype=float)
    n, s, _ = w.shape
    flat = w.reshape(n, -1).argmax(axis=1)
    a0, b0 = np.clip(flat // s, half, s - half - 1), np.clip(flat % s, half, s - half - 1)
    d = np.arange(-half, half + 1)
    rows = a0[:, None] + d[None, :]
    cols = b0[:, None] + d[None, :]
    sub = w[np.arange(n)[:, None, None], rows[:, :, None], cols[:, None, :]]
    tot = sub.sum(axis=(1, 2))
    u = i0 + (sub.sum(axis=1) * (cols + 0.5)).sum(axis=1) / tot
    v = j0 + (sub.sum(axis=2) * (rows + 0.5)).sum(axis=1) / tot
    return np.column_stack([u, v])


def calibrate_from_targets(system: SapivSystem, cameras, table, *, distortion: str = "none") -> tuple[list, dict]:
    """Fit a camera mapping per camera to its rendered, aberrated target images.

    distortion : "none" (the paper: an idealised pinhole, blind to the aberrations) or
        "radial" / "brown" (a pinhole with Brown-Conrady terms, OpenCV).
    Returns ``(mappings, report)``; report: per-camera RMS/max reprojection error [px],
    the error of the located dot centres against their true (distorted) projections [px]
    and the wall time [s].
    """
    from mitpiv.reconstruct.calibration import calibrate

    t0 = time.perf_counter()
    mk = system.target_markers()
    maps, rms, mx, loc = [], [], [], []
    for cam in cameras:
        uv = cam.project(mk)
        keep = np.all((uv >= 8) & (uv <= np.asarray(cam.resolution) - 8), axis=1)  # dots wholly on the sensor
        i0, j0, win = render_dot_windows(cam, mk[keep], table, dot_sigma_mm=system.target_dot_sigma_mm)
        px = locate_dots(i0, j0, win)
        loc.append(float(np.sqrt(np.mean(np.sum((px - uv[keep]) ** 2, axis=1)))))
        m = calibrate(px, mk[keep], model="pinhole", resolution=cam.resolution, distortion=distortion,
                      pixel_pitch_um=cam.pixel_pitch_um, max_rms_px=100.0)
        maps.append(m)
        rms.append(m.fit_report["rms_px"])
        mx.append(m.fit_report["max_px"])
    rep = {"distortion_model": distortion, "rms_px": rms, "max_px": mx, "locate_rms_px": loc,
           "markers": int(len(mk)), "wall_s": time.perf_counter() - t0}
    return maps, rep


# ---------------------------------------------------------------------- one point
#: k of the paper's threshold mu + k sigma (section 2.4: "three standard deviations")
THRESHOLD_K = 3.0
#: thresholds of the density-trend diagnosis: mu + k sigma (0: none) and fixed intensities
DIAGNOSIS_K = (0.0, 1.0, 2.0, 3.0, 5.0, 8.0)
DIAGNOSIS_ABS = (0.02, 0.05, 0.1, 0.2)
#: the readings of the thesis's threshold and true volume scored on every point:
#: threshold "plane" = mean + 3 std of each whole plane (a normal distribution fitted to the
#: plane's intensities by maximum likelihood, what MATLAB's normfit returns), "fit" = mean +
#: 3 sigma of a normal fitted to the noise part of the histogram only (Fig. 2-10's picture);
#: truth "sphere" = each 20 um particle voxelised by the fraction of its volume in each
#: 50 um voxel, "point" = its intensity in the voxel holding its centre, "blob" = a Gaussian
#: of 0.7 voxel (the tomographic-PIV convention)
THRESHOLDS = ("plane", "fit")
TRUTHS = ("sphere", "point", "blob")
READINGS = tuple(f"{t}/{v}" for t in THRESHOLDS for v in TRUTHS)
#: the reading the study's rows use, chosen for its literalness (see the report): the
#: thesis fits "a Gaussian normal distribution to the normalized intensity distribution" of
#: each plane and voxelises particles "with a diameter of 20 um" on 1/8000 mm^3 voxels
ADOPTED = "plane/sphere"


def _threshold(raw, mu, sigma, k: float):
    """Zero every voxel of each plane at or below ``mu + k sigma`` of that plane (rows: planes)."""
    t = (np.asarray(mu) + k * np.asarray(sigma))[:, None]
    return np.where(raw > t, raw, 0.0).astype(raw.dtype, copy=False)


def patch_centres(n_side: int, pitch_mm: float) -> list[tuple[float, float]]:
    """``n_side x n_side`` patch centres on a square lattice of ``pitch_mm`` centred on the axis."""
    c = (np.arange(n_side) - (n_side - 1) / 2) * pitch_mm
    return [(float(x), float(y)) for y in c for x in c]


def evaluate_point(system: SapivSystem, cameras, mappings, table, *, density_per_mm3: float, seed: int,
                   patches, patch_mm: float, warp: str = "homography", progress=None) -> dict:
    """Seed, image, refocus, threshold and score one configuration at one density.

    Particles are seeded uniformly in the whole volume (a Poisson number for
    ``density_per_mm3``); those within the largest parallax
    (:meth:`SapivSystem.max_parallax_mm`) of a patch are imaged by every camera
    (the true cameras: distortion; ``table``: the aberration), refocused on the patches'
    voxels (0.05 mm, 201 planes) through ``mappings`` (the calibration), thresholded per
    plane at mean + 3 std under each threshold reading and compared with each true volume
    (:data:`READINGS`).

    Returns a dict with, for the adopted reading (:data:`ADOPTED`): Q (eq. 4.1), Qprime
    (eq. 4.2), SNR (eq. 4.3) with that reading's mean and std, mu / sigma (their means over
    the planes), kept_fraction, Q_patch (Q of each patch alone); ``readings``: Q, Qprime,
    kept_fraction of every reading (and SNR, mu, sigma per threshold); mu_fit / sigma_fit
    and mu_all / sigma_all (the two thresholds' statistics); Q_by_k / Q_by_abs (the density
    diagnosis: mu + k sigma of the noise fit, k = 0 meaning no threshold, and fixed
    intensity thresholds, against the blob truth); particles, voxels and wall times [s].
    """
    from mitpiv.imaging import splat_points

    t0 = time.perf_counter()
    c0 = time.process_time()
    field = seed_field(system, density_per_mm3=density_per_mm3, seed=seed, patches=patches, patch_mm=patch_mm)
    res = (system.resolution, system.resolution)
    imgs = [splat_points(cam.project(field["imaged"]), res, table) for cam in cameras]
    out = score_images(system, imgs, mappings, field, warp=warp, progress=progress)
    out["t_render_s"] = time.perf_counter() - t0 - out["t_refocus_s"] - out["t_metrics_s"]
    out["t_total_s"] = time.perf_counter() - t0
    out["cpu_s"] = time.process_time() - c0
    return out


def seed_field(system: SapivSystem, *, density_per_mm3: float, seed: int, patches, patch_mm: float) -> dict:
    """The particle field of one point and the patches' voxels: particles seeded uniformly in
    the whole volume (a Poisson number for ``density_per_mm3``); ``imaged``: those within the
    largest parallax (:meth:`SapivSystem.max_parallax_mm`) of a patch, whose light can reach
    it; per patch its VoxelGrid, the particles inside it (``parts``) and its voxels' x, y."""
    if density_per_mm3 <= 0:
        raise ConfigError(f"evaluate_point: density_per_mm3 must be > 0, got {density_per_mm3!r}.")
    rng = np.random.default_rng(seed)
    vx = system.voxel_mm
    n_side = int(round(patch_mm / vx))
    margin = system.max_parallax_mm() + 0.5
    hz = system.volume_mm[2] / 2
    vol = np.asarray(system.volume_mm, dtype=float)
    n = rng.poisson(density_per_mm3 * np.prod(vol))
    p_all = rng.uniform(-vol / 2, vol / 2, size=(n, 3))
    keep = np.zeros(n, bool)
    grids, parts, xy = [], [], []
    for (cx, cy) in patches:
        keep |= (np.abs(p_all[:, 0] - cx) <= patch_mm / 2 + margin) & (np.abs(p_all[:, 1] - cy) <= patch_mm / 2 + margin)
        g = VoxelGrid((cx - patch_mm / 2, cy - patch_mm / 2, -hz - vx / 2), vx, (system.n_planes, n_side, n_side))
        grids.append(g)
        inside = (np.abs(p_all[:, 0] - cx) <= patch_mm / 2 + 4 * vx) & (np.abs(p_all[:, 1] - cy) <= patch_mm / 2 + 4 * vx)
        parts.append(p_all[inside])
        xs = g.origin_mm[0] + (np.arange(n_side) + 0.5) * vx
        ys = g.origin_mm[1] + (np.arange(n_side) + 0.5) * vx
        xx, yy = np.meshgrid(xs, ys)
        xy.append(np.column_stack([xx.ravel(), yy.ravel()]))
    return {"imaged": p_all[keep], "grids": grids, "parts": parts, "xy": np.concatenate(xy), "n_side": n_side}


def score_images(system: SapivSystem, imgs, mappings, field: dict, *, warp: str = "homography", progress=None) -> dict:
    """Refocus ``imgs`` (one per camera, in the order of ``mappings``) on the patches of
    ``field`` (:func:`seed_field`), threshold under each reading and score against each
    true volume: the dict :func:`evaluate_point` describes (without its render time)."""
    from mitpiv.analysis.quality import (
        average_ranks,
        occupancy_volume,
        quality_q,
        snr_from_fits,
        sphere_volume,
        truth_volume,
    )
    from mitpiv.reconstruct.sapiv import refocus_planes

    t0 = time.perf_counter()
    grids, parts, n_side, p = field["grids"], field["parts"], field["n_side"], field["imaged"]
    rf = refocus_planes(imgs, mappings, field["xy"], system.z_planes_mm, warp=warp, progress=progress,
                        threshold_k=None)
    raw = rf.planes
    stats = {"plane": (rf.mean, rf.std), "fit": (rf.mu, rf.sigma)}
    vols = {t: _threshold(raw, *stats[t], THRESHOLD_K) for t in THRESHOLDS}
    t_refocus = time.perf_counter() - t0
    # the true volumes, patch by patch, in the same voxel order as the refocused points
    maker = {"sphere": lambda pp, g: sphere_volume(pp, g, system.particle_diameter_um * 1e-3),
             "point": occupancy_volume,
             "blob": lambda pp, g: truth_volume(pp, g, system.truth_sigma_voxels)}
    truths = {v: np.concatenate([maker[v](pp, g).reshape(system.n_planes, -1) for g, pp in zip(grids, parts, strict=True)],
                                axis=1) for v in TRUTHS}
    t_m = time.perf_counter()
    readings = {}
    ranks = {name: average_ranks(vol) for name, vol in (*vols.items(), *truths.items())}
    for t in THRESHOLDS:
        for v in TRUTHS:
            # Q' (eq. 4.2) from each volume ranked once: rank_correlation would rank both volumes
            # again for every pair (12 sorts of every voxel instead of 5); the same ranks and sum
            readings[f"{t}/{v}"] = {"Q": quality_q(vols[t], truths[v]), "Qprime": quality_q(ranks[t], ranks[v])}
        readings[t] = {"SNR": snr_from_fits(rf.peak, *stats[t]), "mu": float(np.mean(stats[t][0])),
                       "sigma": float(np.mean(stats[t][1])), "kept_fraction": float(np.mean(vols[t] > 0))}
    t_a, v_a = ADOPTED.split("/")
    npp = n_side * n_side
    out = {
        "Q": readings[ADOPTED]["Q"],
        "Qprime": readings[ADOPTED]["Qprime"],
        "SNR": readings[t_a]["SNR"],
        "mu": readings[t_a]["mu"],
        "sigma": readings[t_a]["sigma"],
        "kept_fraction": readings[t_a]["kept_fraction"],
        "Q_patch": [quality_q(vols[t_a][:, i * npp:(i + 1) * npp], truths[v_a][:, i * npp:(i + 1) * npp])
                    for i in range(len(grids))],
        # each patch's own refocused background and what the union's per-plane threshold keeps of
        # it (the threshold is one per plane over the union of the patches)
        "mu_patch": [float(np.mean(raw[:, i * npp:(i + 1) * npp])) for i in range(len(grids))],
        "kept_patch": [float(np.mean(vols[t_a][:, i * npp:(i + 1) * npp] > 0)) for i in range(len(grids))],
        "particles_patch": [int(len(pp)) for pp in parts],
        "readings": readings,
        "mu_fit": float(np.mean(rf.mu)),
        "sigma_fit": float(np.mean(rf.sigma)),
        "mu_all": float(np.mean(rf.mean)),
        "sigma_all": float(np.mean(rf.std)),
        "Q_by_k": {f"{k:g}": quality_q(raw if k == 0 else _threshold(raw, rf.mu, rf.sigma, k), truths["blob"])
                   for k in DIAGNOSIS_K},
        "Q_by_abs": {f"{t:g}": quality_q(np.where(raw > t, raw, 0.0), truths["blob"]) for t in DIAGNOSIS_ABS},
        "threshold_k3_mean": float(np.mean(rf.mu + THRESHOLD_K * rf.sigma)),
        "raw_peak_mean": float(np.mean(rf.peak)),
        "particles": int(len(p)),
        "voxels": int(raw.size),
        "t_refocus_s": t_refocus,
        "t_metrics_s": time.perf_counter() - t_m,
    }
    return out
