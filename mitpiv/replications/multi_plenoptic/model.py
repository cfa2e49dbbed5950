"""The multi-plenoptic PIV study of Fahringer & Thurow as a simulation: the paper's system,
its light-ray image model, its reconstructions and its fidelity metrics (used by
:mod:`mitpiv.replications.multi_plenoptic.study`).

* System (Table 1): :func:`plenoptic_camera` (10 mm f/2 main lens of 5 mm aperture,
  14 um f/2 lenslets focused at infinity, 1.4 um pixels, 328 x 328 lenslets; a crop keeps
  the central ``n x n`` lenslets) focused at ``S_o = (S_o/p_M) p_M``; the standard cameras
  (:func:`standard_camera`) have the same main lens at f/2 or f/20 and one 14 um pixel per
  lenslet. The volume fills the (full) field of view, thickness = width x ratio (1:4).
* Images (:func:`render_plenoptic`, :func:`render_standard`): the paper's light-ray
  simulation. Each particle is a Gaussian source (sigma 0.7 voxel) sampled by rays whose
  source points are uniform within the 1 %-of-peak radius and weighted by the Gaussian, and
  whose directions are uniform over the main lens; rays are traced by
  :meth:`PlenopticCamera.trace_to_sensor` (our exact thin-lens geometry, the ``plenoptic``
  Mitsuba sensor's, which agrees with the paper's paraxial matrices in the paraxial limit:
  tests/physics/test_plenoptic_paper_optics.py) and split over the four nearest pixels by
  area (the paper's square ray profile); the images are stored as 16-bit integers. Hand-
  written (NumPy): the paper's own image model, cheaper than Mitsuba's particle tracer for
  thousands of particles on a 3280 x 3280 sensor, and it lets the study sample exactly the
  paper's sources; ``scenes/multiplenoptic_paper`` renders the same system with Mitsuba.
* Reconstructions: eq. 14 / eq. 13 per plenoptic camera (:func:`mitpiv.reconstruct.paper_refocus`
  with the white-image weights of :func:`mitpiv.reconstruct.paper_view_weights`), eq. 15
  across cameras (:func:`mitpiv.reconstruct.fuse`); MART on the standard cameras.
* Metrics: Q (eq. 16), Q* (eq. 17), the z position 95 % uncertainty, the RMS velocity
  error (eq. 18) and the UOD outlier ratio of a two-pass PIV on a vortex ring.
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from mitpiv.errors import CalibrationError, ConfigError
from mitpiv.grid import VoxelGrid
from mitpiv.physics.camera import CV_TO_MITSUBA, PinholeCamera, place_camera
from mitpiv.physics.plenoptic import PRESETS, PlenopticCamera

log = logging.getLogger(__name__)

#: Table 1 (the sensor pitch is 1.4 um: 3280 pixels span the 328 lenslets of 14 um)
MAIN_FOCAL_MM = 10.0
MAIN_APERTURE_MM = 5.0
LENSLET_PITCH_UM = 14.0
LENSLET_FOCAL_UM = 28.0
PIXEL_UM = 1.4
N_LENSLETS_FULL = 328
WAVELENGTH_UM = 0.532  # the paper's experiment: 532 nm laser
SIGMA_VOXELS = 0.7  # particle Gaussian, the paper's "0.7 times the voxel diameter"
ONE_PERCENT_RADIUS = math.sqrt(2.0 * math.log(100.0))  # sources within the 1 %-of-peak radius [sigma]
BIT_DEPTH = 16
#: one-to-one gates [voxels] of the z-uncertainty study beside the paper's gate-free nearest-particle rule (issue 56)
Z_GATES_VOXELS = (3.0, 10.0, 20.0)


def image_distance_mm(so_mm: float) -> float:
    return MAIN_FOCAL_MM * so_mm / (so_mm - MAIN_FOCAL_MM)


def voxel_mm(so_over_pm: float) -> float:
    """Object-space size of one lenslet at the focal plane: the reconstructed pixel (cubic voxels)."""
    so = so_over_pm * MAIN_APERTURE_MM
    return LENSLET_PITCH_UM * 1e-3 * so / image_distance_mm(so)


def volume_box(so_over_pm: float, thickness_ratio: float, n_lenslets: int) -> tuple[np.ndarray, np.ndarray, float]:
    """(lower, upper, full width) [mm] of the reconstructed volume: the crop's ``n`` lenslets
    wide, the full field of view's width x ``thickness_ratio`` thick, centred on the origin."""
    vox = voxel_mm(so_over_pm)
    full_w = N_LENSLETS_FULL * vox
    w = n_lenslets * vox
    th = full_w * thickness_ratio
    return np.array([-w / 2, -w / 2, -th / 2]), np.array([w / 2, w / 2, th / 2]), full_w


def volume_grid(so_over_pm: float, thickness_ratio: float, n_lenslets: int) -> VoxelGrid:
    lo, hi, _ = volume_box(so_over_pm, thickness_ratio, n_lenslets)
    vox = voxel_mm(so_over_pm)
    nz = max(int(round((hi[2] - lo[2]) / vox)), 1)
    return VoxelGrid(origin_mm=(lo[0], lo[1], -nz * vox / 2), voxel_mm=vox, shape=(nz, n_lenslets, n_lenslets))


def _pose(so_mm: float, angle_deg: float, azimuth_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV rotation and position of a camera ``so_mm`` from the origin, ``angle_deg`` from
    the volume's z axis, at ``azimuth_deg`` about it (0: in the x-z plane on +x)."""
    return place_camera(target_mm=(0.0, 0.0, 0.0), azimuth_deg=azimuth_deg, elevation_deg=90.0 - angle_deg,
                        distance_mm=so_mm, laser_direction=(1.0, 0.0, 0.0), sheet_normal=(0.0, 0.0, 1.0))


def plenoptic_camera(so_over_pm: float, angle_deg: float, azimuth_deg: float, n_lenslets: int) -> PlenopticCamera:
    """The paper's plenoptic camera (Table 1), focused on the origin from ``S_o = (S_o/p_M) p_M``,
    its sensor cropped to the central ``n_lenslets`` x ``n_lenslets`` lenslets."""
    so = so_over_pm * MAIN_APERTURE_MM
    rot, pos = _pose(so, angle_deg, azimuth_deg)
    m = np.eye(4)
    m[:3, :3] = rot.T @ CV_TO_MITSUBA
    m[:3, 3] = pos
    n = int(n_lenslets)
    return PlenopticCamera(**{**PRESETS["multiplenoptic_paper"], "focus_distance_mm": so, "resolution": (10 * n, 10 * n),
                              "mla_count": (n, n), "to_world_mitsuba": m})


def standard_camera(so_over_pm: float, angle_deg: float, azimuth_deg: float, n_lenslets: int, f_number: float):
    """A standard camera with the same main lens at ``f_number`` and one 14 um pixel per lenslet
    of the plenoptic camera (the same field of view and reconstructed resolution)."""
    so = so_over_pm * MAIN_APERTURE_MM
    rot, pos = _pose(so, angle_deg, azimuth_deg)
    n = int(n_lenslets)
    return PinholeCamera(resolution=(n, n), focal_length_mm=image_distance_mm(so), pixel_pitch_um=LENSLET_PITCH_UM,
                         rotation=rot, position_mm=pos)


# ---------------------------------------------------------------------- particles and flow
def vortex_ring():
    """The study's vortex ring (the paper's analytic ring of its ref. [22], parameters ours):
    radius 1.5 mm, core 0.5 mm, circulation 60 mm^2/s, translating along +x through the volume
    centre; with ``DT_S`` the largest displacement is about 4 voxels at S_o/p_M = 8."""
    from mitpiv.physics.flows import VortexRing

    return VortexRing(ring_radius_mm=1.5, core_radius_mm=0.5, circulation_mm2_s=60.0, center=(0.0, 0.0, 0.0),
                      axis=(1.0, 0.0, 0.0))


DT_S = 0.01


def particles(so_over_pm: float, thickness_ratio: float, n_lenslets: int, ppp: float, seed: int):
    """Particle positions of frames 0 and 1 (N, 3) [mm]: ``ppp`` particles per reconstructed
    pixel (lenslet) of the crop, uniform in the volume, advected by :func:`vortex_ring`."""
    from mitpiv.physics.advection import advect

    lo, hi, _ = volume_box(so_over_pm, thickness_ratio, n_lenslets)
    n = max(int(round(ppp * n_lenslets**2)), 1)
    rng = np.random.default_rng(seed)
    p0 = lo + rng.random((n, 3)) * (hi - lo)
    p1 = advect(p0, vortex_ring().velocity, dt_s=DT_S, substeps=4)
    return p0, p1


# ---------------------------------------------------------------------- images
def _sources(points_mm, sigma_mm: float, rays: int, rng):
    """Ray source points around each particle (uniform within the 1 % radius of its Gaussian,
    a ball) and their Gaussian weights: (N, rays, 3), (N, rays)."""
    r_max = ONE_PERCENT_RADIUS * sigma_mm
    d = rng.normal(size=(len(points_mm), rays, 3))
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    r = r_max * rng.random((len(points_mm), rays, 1)) ** (1.0 / 3.0)
    off = d * r
    return points_mm[:, None, :] + off, np.exp(-0.5 * np.sum(off * off, axis=-1) / sigma_mm**2)


def _lens_points(n, rays, radius_mm, rng):
    r = radius_mm * np.sqrt(rng.random((n, rays)))
    a = 2.0 * math.pi * rng.random((n, rays))
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=-1)


def _splat(shape_hw, uv_px, weight):
    """Each ray a square of one pixel, split over the four nearest pixels by area."""
    h, w = shape_hw
    x = uv_px[:, 0] - 0.5
    y = uv_px[:, 1] - 0.5
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = x - x0, y - y0
    img = np.zeros(h * w)
    for dx, dy, wt in ((0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy), (1, 1, fx * fy)):
        xi, yi = x0 + dx, y0 + dy
        ok = (xi >= 0) & (xi < w) & (yi >= 0) & (yi < h)
        img += np.bincount(yi[ok] * w + xi[ok], weights=(weight * wt)[ok], minlength=h * w)
    return img.reshape(h, w)


def quantise(images, bits: int = BIT_DEPTH):
    """The images as unsigned integers of ``bits``, the brightest pixel of the set at full scale
    (the paper processes its 16-bit images)."""
    top = max(float(np.max(im)) for im in images)
    full = 2**bits - 1
    if top <= 0:
        raise ConfigError("multi-plenoptic model: the rendered images are dark (no particle in view).")
    return [np.round(np.asarray(im) * (full / top)).astype(np.float32) for im in images]


def render_plenoptic(cam: PlenopticCamera, points_mm, *, sigma_mm: float, rays: int, seed: int,
                     chunk: int = 200) -> np.ndarray:
    """Raw plenoptic image (H, W) float64 of Gaussian particles (the paper's light-ray model)."""
    rng = np.random.default_rng(seed)
    w, h = cam.resolution
    img = np.zeros((h, w))
    pts = np.asarray(points_mm, dtype=float)
    for s in range(0, len(pts), chunk):
        src, wt = _sources(pts[s : s + chunk], sigma_mm, rays, rng)
        loc = cam.world_to_local(src)
        lens = _lens_points(len(loc), rays, cam.aperture_radius_mm, rng)
        xs, _, ok = cam.trace_to_sensor(loc, lens)
        uv = cam.sensor_mm_to_px(xs[ok])
        img += _splat((h, w), uv, wt[ok])
    return img


def render_standard(cam: PinholeCamera, f_number: float, points_mm, *, sigma_mm: float, rays: int, seed: int,
                    chunk: int = 200) -> np.ndarray:
    """Image (H, W) float64 of a standard camera: the same rays through a thin lens of aperture
    ``f / f_number`` onto a sensor at the image distance, then the diffraction blur of the
    aperture (an Airy pattern's Gaussian equivalent, sigma = 0.42 lambda N (1 + M))."""
    from scipy.ndimage import gaussian_filter

    rng = np.random.default_rng(seed)
    w, h = cam.resolution
    si = cam.focal_length_mm  # the pinhole distance of the projection is the image distance
    img = np.zeros((h, w))
    pts = np.asarray(points_mm, dtype=float)
    radius = 0.5 * MAIN_FOCAL_MM / f_number
    pp = cam.pixel_pitch_um * 1e-3
    cx, cy = cam.principal_point_px
    for s in range(0, len(pts), chunk):
        src, wt = _sources(pts[s : s + chunk], sigma_mm, rays, rng)
        q = cam.world_to_camera(src)  # OpenCV frame, z forward
        a = _lens_points(len(q), rays, radius, rng)
        t1 = (a - q[..., :2]) / q[..., 2:3]
        xs = a + si * (t1 - a / MAIN_FOCAL_MM)  # real, inverted image on the sensor
        uv = np.stack([cx - xs[..., 0] / pp, cy - xs[..., 1] / pp], axis=-1)  # read out upright
        img += _splat((h, w), uv.reshape(-1, 2), wt.ravel())
    m = si / (si * MAIN_FOCAL_MM / (si - MAIN_FOCAL_MM))  # lateral magnification s_i / s_o
    sigma_px = 0.42 * WAVELENGTH_UM * f_number * (1.0 + m) / cam.pixel_pitch_um
    return gaussian_filter(img, sigma_px, mode="constant") if sigma_px > 0.05 else img


def white_weights(so_over_pm: float) -> np.ndarray:
    """The paper's view weights w(u, v) from a white image of the camera (a uniformly bright
    background: each pixel's value is the fraction of its rays, uniform over the pixel and its
    lenslet, that pass the main-lens aperture), on the central 24 x 24 lenslets."""
    from mitpiv.lightfield import decode
    from mitpiv.reconstruct import paper_view_weights

    cam = plenoptic_camera(so_over_pm, 0.0, 0.0, 24)
    w, h = cam.resolution
    rng = np.random.default_rng(0)
    spp = 16
    v, u = np.mgrid[0:h, 0:w]
    uv = np.stack([u, v], -1)[:, :, None, :] + rng.random((h, w, spp, 2))
    _, _, ok = cam.camera_rays(uv, rng.random((h, w, spp, 2)))
    white = ok.mean(axis=-1).astype(np.float32)
    return paper_view_weights(decode(white, optics=cam))


# ---------------------------------------------------------------------- metrics
def fidelity(volumes, grid: VoxelGrid, truths, *, windows, radius_voxels: float = 3.0) -> dict:
    """The paper's four metrics of a reconstructed pair of frames: Q (eq. 16), Q* (eq. 17) of
    frame 0 against the Gaussian truth (sigma 0.7 voxel), the z position 95 % uncertainty
    [voxels] (1.96 standard deviations of the z error, Gaussian peak fits) of a one-to-one match
    within ``radius_voxels`` (``z_u95_vox``), of the paper's nearest-particle rule without a gate
    (``z_u95_vox_paper``, :func:`~mitpiv.analysis.particles.match_nearest`) and of one-to-one matches
    within each of :data:`Z_GATES_VOXELS` (``z_u95_vox_g<gate>``), each with its detection rate, and from a two-pass PIV (UOD threshold 2, outliers
    replaced after the first pass) the RMS velocity error (eq. 18) [voxels per frame] and the
    second pass's outlier ratio."""
    from mitpiv.analysis import piv3d, velocity_error
    from mitpiv.analysis.particles import find_particles, match, match_nearest
    from mitpiv.analysis.quality import quality_q, quality_q_zero_mean, truth_volume

    v0, v1 = (np.asarray(v, dtype=np.float64) for v in volumes)
    tv = truth_volume(truths[0], grid, SIGMA_VOXELS)
    out = {"Q": quality_q(v0, tv), "Qstar": quality_q_zero_mean(v0, tv)}
    try:
        found = find_particles(v0, grid, method="gauss3", threshold_rel=0.1)
        res = match(found, truths[0], grid=grid, radius_voxels=radius_voxels)
        s = res.summary()
        out.update(z_u95_vox=s["u95_vox"][2], x_u95_vox=s["u95_vox"][0], detection_rate=s["detection_rate"],
                   ghost_fraction=s["ghost_fraction"], n_found=s["n_found"])
        # the z uncertainty by the paper's nearest-particle rule (no gate) and by one-to-one
        # matches within wider gates, each with its detection rate (issue 56: a 3-voxel gate caps
        # the errors it keeps)
        near = match_nearest(found, truths[0], grid=grid)
        out.update(z_u95_vox_paper=float(near.u95(voxels=True)[2]), detection_paper=float(near.detection_rate))
        for g in Z_GATES_VOXELS:
            rg = res if g == radius_voxels else match(found, truths[0], grid=grid, radius_voxels=g)
            out[f"z_u95_vox_g{g:g}"] = float(rg.u95(voxels=True)[2])
            out[f"detection_g{g:g}"] = float(rg.detection_rate)
    except (ConfigError, ValueError, IndexError) as e:  # no particle found: no position metric
        log.info("fidelity: no particle statistics (%s)", e)
        out.update(z_u95_vox=math.nan, x_u95_vox=math.nan, detection_rate=0.0, ghost_fraction=math.nan, n_found=0,
                   z_u95_vox_paper=math.nan, detection_paper=0.0)
        for g in Z_GATES_VOXELS:
            out[f"z_u95_vox_g{g:g}"], out[f"detection_g{g:g}"] = math.nan, 0.0
    try:
        fld = piv3d(v0, v1, grid, windows=windows, overlap=0.5, threshold=2.0, replace="median", dt_s=DT_S)
        ve = velocity_error(fld, vortex_ring(), dt_s=DT_S)
        out.update(rms_vox=float(np.sqrt(np.sum(np.square(ve["rms_vox"])))), outlier_ratio=float(fld.outlier_ratio),
                   n_vectors=int(ve["n"]))
    except (ConfigError, ValueError) as e:
        log.info("fidelity: no PIV (%s)", e)
        out.update(rms_vox=math.nan, outlier_ratio=math.nan, n_vectors=0)
    return {k: (float(v) if isinstance(v, float | np.floating) else v) for k, v in out.items()}


def timed(fn, *a, **k):
    t0 = time.process_time()
    r = fn(*a, **k)
    return r, time.process_time() - t0


def calibrate_standard(so_over_pm: float, thickness_ratio: float, angle_deg: float, azimuth_deg: float,
                       n_lenslets: int, f_number: float, *, rays: int = 4000, seed: int = 0):
    """A standard camera's mapping calibrated from rendered dot targets, as the paper does for
    its MART reconstructions ("a series of calibration images are generated").

    Targets: planes of Gaussian dots (sigma 1 voxel, pitch 8 voxels / cos(angle)) at five depths through
    the volume's thickness, rendered by :func:`render_standard` (the same light rays, defocus
    and diffraction as the particle images); dots located by
    :func:`mitpiv.reconstruct.calibration.detect_dots`, labelled by the design pose and
    fitted by a pinhole model without distortion terms (an ideal thin lens has none), or by
    Soloff's polynomial where OpenCV's pinhole fit fails; where both fail (at 60 deg and f/2
    the oblique target planes are out of focus but for two depths) the true camera model,
    named in the report's ``model``.

    Returns
    -------
    (CameraMapping, report dict: markers, rms_px, dot location error against the true
    projections [px])
    """
    from mitpiv.reconstruct.calibration import calibrate, detect_dots, label_markers

    cam = standard_camera(so_over_pm, angle_deg, azimuth_deg, n_lenslets, f_number)
    vox = voxel_mm(so_over_pm)
    lo, hi, _ = volume_box(so_over_pm, thickness_ratio, n_lenslets)
    # an oblique camera sees the planes foreshortened by cos(angle) and a wider strip of them
    stretch = 1.0 / math.cos(math.radians(angle_deg))
    pitch = 8 * vox * stretch
    half = 0.5 * (hi[0] - lo[0]) * 1.6 * stretch  # beyond the crop: an oblique camera sees past its edge
    g = np.arange(-math.floor(half / pitch), math.floor(half / pitch) + 1) * pitch
    px, world, true_px = [], [], []
    w, h = cam.resolution
    for k, z in enumerate(np.linspace(lo[2], hi[2], 5)):
        xx, yy = np.meshgrid(g, g)
        m = np.column_stack([xx.ravel(), yy.ravel(), np.full(xx.size, z)])
        pred = cam.project(m)
        inside = (pred[:, 0] > 4) & (pred[:, 0] < w - 4) & (pred[:, 1] > 4) & (pred[:, 1] < h - 4)
        m, pred = m[inside], pred[inside]
        if len(m) == 0:
            continue
        img = render_standard(cam, f_number, m, sigma_mm=vox, rays=rays, seed=seed + k)
        try:
            det = detect_dots(img, threshold=0.1 * float(img.max()))  # noise-free: a tenth of the peak
        except (ConfigError, CalibrationError):
            continue
        mi, di = label_markers(det, pred)
        px.append(det[di])
        world.append(m[mi])
        true_px.append(pred[mi])
    if not px:
        raise ConfigError(f"calibrate_standard: no target dot found (camera at {angle_deg} deg, f/{f_number}).")
    px, world, true_px = np.concatenate(px), np.concatenate(world), np.concatenate(true_px)
    try:
        mapping = calibrate(px, world, model="pinhole", resolution=cam.resolution, distortion="none",
                            pixel_pitch_um=cam.pixel_pitch_um, max_rms_px=1.0)
    except CalibrationError as e:  # e.g. OpenCV's pinhole fit at 60 deg, f/2 (few, blurred dots): Soloff's polynomial
        log.info("calibrate_standard: pinhole fit failed (%s); fitting the polynomial model", e)
        try:
            mapping = calibrate(px, world, model="polynomial", resolution=cam.resolution, max_rms_px=1.0)
        except CalibrationError as e2:  # the targets' dots too blurred at too few depths: the true model
            from mitpiv.reconstruct.mapping import PinholeMapping

            log.warning("calibrate_standard: no calibration at %g deg, f/%g (%s); using the true camera model",
                        angle_deg, f_number, e2)
            mapping = PinholeMapping(cam)
            mapping.fit_report = {"model": "true (no calibration: " + str(e2)[:80] + ")", "rms_px": 0.0}
    err = np.linalg.norm(px - true_px, axis=1)
    return mapping, {"markers": int(len(px)), "rms_px": float(mapping.fit_report["rms_px"]),
                     "model": str(mapping.fit_report["model"]), "locate_rms_px": float(np.sqrt(np.mean(err**2)))}
