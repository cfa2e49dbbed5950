"""The simulation of Shi, Ding, Atkinson, Soria & New, "A detailed comparison of single-camera
light-field PIV and tomographic PIV" (seed paper 001, section 2): synthetic light-field and
tomographic particle images of a round jet, DRT-MART and MLOS-SMART reconstructions, particle
centres by peak centroid, two-pass multi-grid 3D PIV against the window-filtered truth (used
by :mod:`mitpiv.replications.lfpiv_vs_tomo.study`).

The paper's set-up (Tables 1-2) and our readings of what it leaves open:

* **Volume** 12 x 12 x 10 mm (x, y, z), centred on the world origin; the light-field
  camera's optical axis is z, its sensor parallel to the jet (x-y plane).
* **Light-field cameras** (Table 1): 800 x 800 px of 15 um (low LTPR) or 1600 x 1600 px of
  7.5 um (high LTPR), hexagonal lenslets of pitch ``PMR x p_p`` with the table's MLA
  resolutions (114 x 132, 57 x 66, 29 x 33; 228 x 264, 114 x 132, 57 x 66). The table's
  ``p_p`` is both the pixel size ("the pixel size is set as 0.015 mm") and the object-space
  pixel (800 x 0.015 mm = the 12 mm field), so the magnification is 1 (as in the paper's
  experiment, 5.5 um pixels at 0.0058 mm/px); the 2:2:10 voxels are then 0.03 x 0.03 x 0.15
  mm (Table 2). The paper gives no main lens: we take its experiment's 200 mm lens at 1:1
  (object and image distance 400 mm) and the image-side f-number 4 of its in-house MLA
  (77 um lenslets, 308 um focal length; Shi et al. 2016), f-number matched ("the focal
  length of the lenslet needs to be adjusted accordingly in order to maintain the same
  f-number as the main lens"): lenslet focal length 4 p_l, aperture 100 mm, MLA-to-sensor
  distance = the lenslet focal length.
* **Light-field images**: point particles, rays from each particle spread over the main-lens
  aperture, traced through the thin lenses to the sensor
  (:meth:`mitpiv.physics.plenoptic.PlenopticCamera.trace_to_sensor`, exact for ideal thin
  lenses), pixel value = number of rays received, normalised to 0-255 and rounded (the
  paper's section 2.1). The paper uses 5 million random rays per particle; we use a
  jittered stratified grid over the aperture of ``rays_per_aperture_pixel x PMR^2`` rays
  (see :func:`render_light_field` and the replication report for the convergence).
* **Tomographic cameras**: 4, 6 or 8 pinholes of 160 x 160 px in the x-z plane, 946.5 mm from
  the volume centre, image distance 93.4 mm (85 mm lens), 0.075 mm per pixel (7.401 um
  pixels). "Equally spaced around the volume": viewing directions equally spaced over 180
  deg (``-90 + (k + 1/2) 180 / N_c`` deg from the z axis): spread over 360 deg, opposite
  cameras of an even rig would see the same lines of sight (0.7 deg of parallax at this
  distance) and a four-camera rig would be two views. Particle images are pixel-integrated
  Gaussians of e^-2 diameter 3 px (the paper's "diameter around 3 pixels"), peak 255, no
  noise (the paper adds none).
* **Seeding**: 0.5 particles per microlens (light field) and 0.05 / 0.1 particles per pixel
  (tomography) over the volume, uniform; the second frame shifts the same particles by the
  flow (RK4) over ``dt`` chosen so the largest displacement (the exit velocity) is a quarter
  of the first window (the paper's one-quarter rule).
* **Flow**: :class:`mitpiv.physics.jet.NearFieldJet` (Re_D 2500, D = 40 mm, water: exit
  velocity 62.5 mm/s), jet axis along x, the volume 1 D downstream centred on the lip line
  (r = D/2, the shear layer). The paper's station "(x = 0.5D, y = 0.5D, z = 1D) from the
  nozzle exit" read literally would put the volume 0.71 D off the axis, outside a jet one
  diameter from the nozzle; we read it as 1 D downstream in the shear layer (stated).
* **Reconstruction**: DRT-MART (:func:`mitpiv.reconstruct.plenoptic.drt_mart`) at 2:2:10
  without the voxels at the edge of the field that the sensor sees less than 75 % of
  (``min_coverage``: on a crop they become the brightest of the volume and lock the PIV),
  MLOS-SMART (:func:`mitpiv.reconstruct.mart` with ``smart=True``) at 1:1:1.
* **Particle centres**: local maxima localised by the intensity-weighted centroid of a 3^3
  box (the paper's "peak centroid"), matched one-to-one to the truth within 2 voxel edges.
* **PIV**: two passes (Table 2 windows), 75 % overlap, median replacement of the outliers
  of a universal outlier detection (the paper's 3x3x3 median filter), FFT correlation with
  window deformation; the errors against the flow box-averaged over the final window.
* **Crops** (:func:`lf_case`, :func:`tomo_case`): the light-field sensor is cropped to a
  central square (the volume likewise); the tomographic volume to a slab of y (the rows of
  every sensor), keeping the full x and z every camera sees through.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass

import numpy as np

from mitpiv.errors import ConfigError
from mitpiv.grid import VoxelGrid
from mitpiv.physics.plenoptic import ltpr

log = logging.getLogger(__name__)

__all__ = ["ltpr", "VOLUME_MM", "LF_CAMERAS", "TOMO", "LFCase", "TomoCase", "lf_camera", "tomo_cameras", "jet",
           "render_light_field", "render_tomo", "seed_particles", "particle_errors", "piv_errors", "lf_point",
           "tomo_point", "PAPER_TABLE_2", "window_plan", "ideal_piv_errors", "piv_errors_by_depth", "lf_depth_point"]

VOLUME_MM = (12.0, 12.0, 10.0)
D_MM = 40.0
RE_D = 2500.0
NU_MM2_S = 1.0  # water
EXIT_VELOCITY_MM_S = RE_D * NU_MM2_S / D_MM  # 62.5 mm/s
PPM = 0.5

#: Table 1 light-field cameras: resolution [px], pixel pitch [um], MLA resolution by PMR
LF_CAMERAS = {
    "low": {"resolution": 800, "pixel_um": 15.0, "mla": {7: (114, 132), 14: (57, 66), 28: (29, 33)}, "nz": 67},
    "high": {"resolution": 1600, "pixel_um": 7.5, "mla": {7: (228, 264), 14: (114, 132), 28: (57, 66)}, "nz": 134},
}
LF_MAIN_FOCAL_MM = 200.0  # the paper's experiment's lens (our choice: the simulation gives none)
LF_MAGNIFICATION = 1.0
LF_IMAGE_F_NUMBER = 4.0  # the in-house MLA's f-number (Shi et al. 2016), matched by the main lens

#: Tomographic cameras (section 2.2)
TOMO = {"resolution": 160, "object_distance_mm": 946.5, "image_distance_mm": 93.4, "focal_length_mm": 85.0,
        "mm_per_px": 0.075, "nz": 133, "particle_diameter_px": 3.0}

#: DRT-MART drops the voxels at the edge of the field whose ray cones the sensor catches less
#: than this share of (:func:`mitpiv.reconstruct.plenoptic.coverage`): on the cropped grids
#: they otherwise hold most of the brightest voxels' energy and lock the PIV (see the report)
MIN_COVERAGE = 0.75

#: Table 2: (first window, second window) (x, y, z) voxels per case
PAPER_TABLE_2 = {
    ("lf", 7): ((80, 80, 16), (40, 40, 8)), ("lf", 14): ((160, 160, 32), (80, 80, 16)),
    ("lf", 28): ((320, 320, 64), (160, 160, 32)),
    ("tomo", 0.05): ((64, 64, 64), (32, 32, 32)), ("tomo", 0.1): ((32, 32, 32), (16, 16, 16)),
}


def jet(seed: int = 0, modes: int = 400):
    """The study's flow: the near-field jet at Re_D 2500 with the volume 1 D downstream on
    the lip line (nozzle centre at (-D, -D/2, 0), axis +x)."""
    from mitpiv.physics.jet import NearFieldJet

    return NearFieldJet(D_MM, EXIT_VELOCITY_MM_S, nozzle_mm=(-D_MM, -0.5 * D_MM, 0.0), axis=(1.0, 0.0, 0.0),
                        modes=modes, seed=seed)


def window_plan(kind: str, key, *, fit_shape_zyx=None, scale: float = 1.0):
    """The two PIV passes (x, y, z voxels) of a case (Table 2), each window optionally scaled
    by ``scale`` (quick runs) and clipped to the volume ``fit_shape_zyx``."""
    passes = []
    for w in PAPER_TABLE_2[(kind, key)]:
        w = [max(4, int(round(v * scale))) for v in w]
        if fit_shape_zyx is not None:
            nz, ny, nx = fit_shape_zyx
            w = [min(w[0], nx), min(w[1], ny), min(w[2], nz)]
        passes.append(tuple(w))
    return passes


# ---------------------------------------------------------------------- cases
@dataclass(frozen=True)
class LFCase:
    """A light-field case: camera ("low"/"high"), PMR, the crop [mm]: ``crop_mm`` wide along x
    (the jet axis) and ``crop_y_mm`` along y (default ``crop_mm``: a central square), full depth."""

    camera: str
    pmr: int
    crop_mm: float
    crop_y_mm: float | None = None

    @property
    def spec(self) -> dict:
        return LF_CAMERAS[self.camera]

    @property
    def pixel_mm(self) -> float:
        return self.spec["pixel_um"] * 1e-3

    @property
    def mla_full(self) -> tuple[int, int]:
        return self.spec["mla"][self.pmr]

    @property
    def fracs(self) -> tuple[float, float]:
        cy = self.crop_mm if self.crop_y_mm is None else self.crop_y_mm
        return self.crop_mm / VOLUME_MM[0], cy / VOLUME_MM[1]

    @property
    def sensor_wh(self) -> tuple[int, int]:
        """Sensor crop (W, H) [px]."""
        return tuple(int(round(self.spec["resolution"] * f)) for f in self.fracs)

    @property
    def pixels(self) -> int:
        w, h = self.sensor_wh
        return w * h

    @property
    def mla_count(self) -> tuple[int, int]:
        return tuple(max(2, int(round(n * f))) for n, f in zip(self.mla_full, self.fracs, strict=True))

    @property
    def voxel_mm(self) -> tuple[float, float, float]:
        p = self.pixel_mm / LF_MAGNIFICATION
        return (2 * p, 2 * p, 10 * p)

    def grid(self) -> VoxelGrid:
        vx, vy, vz = self.voxel_mm
        fx, fy = self.fracs
        nx, ny = int(round(fx * VOLUME_MM[0] / vx)), int(round(fy * VOLUME_MM[1] / vy))
        nz = self.spec["nz"]
        return VoxelGrid(origin_mm=(-nx * vx / 2, -ny * vy / 2, -nz * vz / 2), voxel_mm=(vx, vy, vz),
                         shape=(nz, ny, nx))

    def n_particles(self) -> int:
        return int(round(PPM * self.mla_count[0] * self.mla_count[1]))

    def ltpr(self, n_cameras: int) -> float:
        r = self.spec["resolution"]
        return ltpr((r, r), (TOMO["resolution"],) * 2, n_cameras)


@dataclass(frozen=True)
class TomoCase:
    """A tomographic case: cameras, particles per pixel, the y slab of the crop [mm]."""

    n_cameras: int
    ppp: float
    crop_y_mm: float

    @property
    def rows(self) -> int:
        return int(round(TOMO["resolution"] * self.crop_y_mm / VOLUME_MM[1]))

    def grid(self) -> VoxelGrid:
        v = TOMO["mm_per_px"]
        n, nz, ny = TOMO["resolution"], TOMO["nz"], self.rows
        return VoxelGrid(origin_mm=(-n * v / 2, -ny * v / 2, -nz * v / 2), voxel_mm=v, shape=(nz, ny, n))

    def n_particles(self) -> int:
        return int(round(self.ppp * TOMO["resolution"] * self.rows))

    def azimuths_deg(self) -> np.ndarray:
        n = self.n_cameras
        return -90.0 + (np.arange(n) + 0.5) * 180.0 / n


def lf_camera(case: LFCase):
    """The light-field camera of a case (its sensor cropped to the case's central square)."""
    from mitpiv.physics.plenoptic import PlenopticCamera

    si = LF_MAIN_FOCAL_MM * (1 + LF_MAGNIFICATION)
    so = si / LF_MAGNIFICATION
    m = np.eye(4)
    m[2, 3] = -so  # main lens on the -z axis, looking along +z at the volume centre
    return PlenopticCamera(resolution=case.sensor_wh, pixel_pitch_um=case.spec["pixel_um"], focal_length_mm=LF_MAIN_FOCAL_MM,
                           aperture_diameter_mm=si / LF_IMAGE_F_NUMBER, focus_distance_mm=so,
                           mla_pitch_um=case.pmr * case.spec["pixel_um"], mla_layout="hex",
                           mla_count=case.mla_count, to_world_mitsuba=m)


def tomo_cameras(case: TomoCase):
    """The pinhole cameras of a case (x-z plane, rows cropped to the case's y slab)."""
    from mitpiv.physics.camera import PinholeCamera, look_at_rotation

    pitch_um = TOMO["mm_per_px"] * TOMO["image_distance_mm"] / TOMO["object_distance_mm"] * 1e3
    out = []
    for az in case.azimuths_deg():
        a = math.radians(az)
        pos = TOMO["object_distance_mm"] * np.array([math.sin(a), 0.0, -math.cos(a)])
        rot = look_at_rotation(pos, (0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0))
        out.append(PinholeCamera((TOMO["resolution"], case.rows), TOMO["image_distance_mm"], pitch_um, rotation=rot,
                                 position_mm=pos))
    return out


# ---------------------------------------------------------------------- particles and images
def seed_particles(grid: VoxelGrid, n: int, rng) -> np.ndarray:
    """``n`` particles uniform in the grid's box (N, 3) [mm]."""
    lo = np.asarray(grid.origin_mm)
    hi = lo + np.asarray(grid.voxel_mm) * np.array(grid.shape[::-1])
    return lo + rng.random((int(n), 3)) * (hi - lo)


def _aperture_samples(n_side: int, radius_mm: float, count: int, rng) -> np.ndarray:
    """Jittered stratified points over the aperture's bounding square: an n x n grid of cells,
    one uniform point per cell, (count, n^2, 2) [mm]; the points outside the aperture disk are
    dropped by the tracer (:meth:`PlenopticCamera.trace_to_sensor`'s ``valid``), so the
    density is uniform over the disk (about ``pi n^2 / 4`` rays reach it)."""
    c = (np.arange(n_side) + 0.5) / n_side * 2 - 1
    gx, gy = np.meshgrid(c, c)
    base = np.stack([gx.ravel(), gy.ravel()], -1)
    jit = (rng.random((count, len(base), 2)) - 0.5) * (2.0 / n_side)
    return (base[None] + jit) * radius_mm


def _n_side(cam, rays_per_aperture_pixel: float) -> int:
    """Grid side giving ``rays_per_aperture_pixel`` rays per pixel of the lenslet image of the aperture."""
    return max(4, int(math.ceil(math.sqrt(rays_per_aperture_pixel) * cam.angular_samples)))


def render_light_field(cam, points_mm, *, rays_per_aperture_pixel: float, seed: int, chunk_rays: int = 2_000_000,
                       random_rays: int | None = None) -> np.ndarray:
    """Raw light-field image (H, W) float64 [rays per pixel] of point particles.

    Each particle sends ``K`` rays through the main-lens aperture (a jittered stratified grid of
    ``n x n`` points over the aperture's bounding square, ``n = sqrt(rays_per_aperture_pixel)``
    times the aperture image's diameter in pixels, about ``pi n^2 / 4`` inside the disk; or
    ``random_rays`` uniform random points: the paper's Monte Carlo, 5 million rays), traced
    to the sensor; a pixel's value is the number of rays it receives (the paper's model).
    Normalise with :func:`to_8bit`.
    """
    rng = np.random.default_rng(seed)
    w, h = cam.resolution
    img = np.zeros(h * w)
    pts = cam.world_to_local(np.asarray(points_mm, dtype=float).reshape(-1, 3))
    r_ap = cam.aperture_radius_mm
    if random_rays is None:
        n_side = _n_side(cam, rays_per_aperture_pixel)
        k = n_side * n_side
    else:
        k = int(random_rays)
    per = max(1, chunk_rays // max(k, 1))
    for s in range(0, len(pts), per):
        p = pts[s : s + per]
        if random_rays is None:
            lens = _aperture_samples(n_side, r_ap, len(p), rng)
        else:
            rr = r_ap * np.sqrt(rng.random((len(p), k)))
            aa = 2 * math.pi * rng.random((len(p), k))
            lens = np.stack([rr * np.cos(aa), rr * np.sin(aa)], -1)
        xs, _, ok = cam.trace_to_sensor(np.broadcast_to(p[:, None, :], lens.shape[:2] + (3,)), lens)
        uv = cam.sensor_mm_to_px(xs[ok])
        i, j = np.floor(uv[:, 0]).astype(np.int64), np.floor(uv[:, 1]).astype(np.int64)
        inside = (i >= 0) & (i < w) & (j >= 0) & (j < h)
        img += np.bincount(j[inside] * w + i[inside], minlength=h * w)
    return img.reshape(h, w)


def rays_per_particle(cam, rays_per_aperture_pixel: float) -> int:
    """Rays per particle of :func:`render_light_field`'s stratified grid that reach the
    aperture (``pi n^2 / 4`` of the ``n^2`` grid points, rounded)."""
    n = _n_side(cam, rays_per_aperture_pixel)
    return int(round(math.pi * n * n / 4))


def to_8bit(images) -> list[np.ndarray]:
    """Images normalised so the brightest pixel of the set is 255, rounded (the paper's 0-255)."""
    top = max(float(np.max(im)) for im in images)
    if not top > 0:
        raise ConfigError("lfpiv-vs-tomo model: the rendered images are dark (no particle in view).")
    return [np.round(np.asarray(im, dtype=float) * (255.0 / top)) for im in images]


def render_tomo(cams, points_mm) -> list[np.ndarray]:
    """Tomographic images (H, W) float64: pixel-integrated Gaussians of e^-2 diameter 3 px,
    a particle centred on a pixel peaking at 255 (overlaps add)."""
    from mitpiv.imaging import PointPSFTable, point_images

    table = PointPSFTable.gaussian(TOMO["particle_diameter_px"] / 4.0)
    return point_images(cams, np.asarray(points_mm, dtype=float), table, peak=255.0, factors=np.ones(len(cams)))


# ---------------------------------------------------------------------- metrics
def particle_errors(volume, grid: VoxelGrid, truth_mm) -> dict:
    """Particle-centre errors (Fig. 7): local maxima above 10 % of the volume's maximum,
    localised by the intensity-weighted centroid of a 3^3 box (the paper's peak centroid),
    matched one-to-one within 2 of the largest voxel edge. RMS and mean |error| per axis [mm],
    detection rate, ghost fraction."""
    from mitpiv.analysis.particles import find_particles, match

    try:
        found = find_particles(volume, grid, method="centroid", threshold_rel=0.1)
        m = match(found, truth_mm, grid=grid, radius_voxels=2.0)
    except (ConfigError, ValueError, IndexError) as e:
        log.info("particle_errors: %s", e)
        return {"rms_mm": [math.nan] * 3, "n_matched": 0, "detection_rate": 0.0, "ghost_fraction": math.nan}
    e = m.errors_mm
    rms = np.sqrt(np.mean(e**2, axis=0)).tolist() if len(e) else [math.nan] * 3
    return {"rms_mm": rms, "n_matched": int(m.n_matched), "detection_rate": float(m.detection_rate),
            "ghost_fraction": float(m.ghost_fraction), "errors_mm_sample": np.round(e[:2000], 5).tolist()}


def _piv_vector_errors(vol_a, vol_b, grid: VoxelGrid, flow, dt_s: float, passes):
    """The PIV of :func:`piv_errors` and its scored vectors: (field, positions (n, 3) [mm], error
    (n, 3) [mm/s], truth (n, 3) [mm/s]) of the valid, non-outlier vectors."""
    from mitpiv.analysis.piv3d import piv3d

    fld = piv3d(vol_a, vol_b, grid, windows=list(passes), overlap=0.75, dt_s=dt_s, replace="median")
    p = fld.points_mm().reshape(-1, 3)
    meas = np.stack([fld.u, fld.v, fld.w], -1).reshape(-1, 3)
    ok = fld.valid.reshape(-1) & ~fld.outlier.reshape(-1)
    win_mm = np.asarray(passes[-1], dtype=float) * np.asarray(grid.voxel_mm)
    truth = flow.box_average(p[ok], win_mm, nodes=3)
    return fld, p[ok], meas[ok] - truth, truth


def piv_errors_by_depth(vol_a, vol_b, grid: VoxelGrid, flow, dt_s: float, passes, *, gross_voxels: float = 5.0) -> dict:
    """:func:`piv_errors`'s vectors binned by their depth z (one bin per plane of vectors):
    RMS and median absolute error per component [voxels], the count, and the gross errors
    (any component beyond ``gross_voxels``): how many, and how many of them lie within half a
    final window of the focal plane z = 0 (where a plenoptic 1.0 camera puts a particle's
    light under one lenslet and resolves it no finer than the lenslet)."""
    fld, p, err, _ = _piv_vector_errors(vol_a, vol_b, grid, flow, dt_s, passes)
    e = err * dt_s / np.asarray(grid.voxel_mm)
    zs = np.unique(np.round(p[:, 2], 6))
    prof = {"z_mm": zs.tolist(), "rms_vox": [], "median_abs_vox": [], "n": []}
    for z in zs:
        m = np.abs(p[:, 2] - z) < 1e-5
        prof["rms_vox"].append(np.sqrt(np.mean(e[m] ** 2, axis=0)).tolist())
        prof["median_abs_vox"].append(np.median(np.abs(e[m]), axis=0).tolist())
        prof["n"].append(int(m.sum()))
    gross = np.any(np.abs(e) > gross_voxels, axis=1)
    half_window_mm = 0.5 * passes[-1][2] * grid.voxel_mm[2]
    near = np.abs(p[:, 2]) <= half_window_mm
    prof.update({"n_vectors": int(len(e)), "n_gross": int(gross.sum()), "n_gross_near_focal_plane": int((gross & near).sum()),
                 "n_near_focal_plane": int(near.sum()), "half_window_mm": float(half_window_mm),
                 "rms_vox_all": np.sqrt(np.mean(e**2, axis=0)).tolist(),
                 "median_abs_vox_all": np.median(np.abs(e), axis=0).tolist(), "gross_voxels": float(gross_voxels)})
    return prof


def _zero_lateral_boundary(vol, trim: int) -> np.ndarray:
    """A copy of a (z, y, x) volume with its ``trim`` (>= 1) outermost voxels in x and y set to 0."""
    if int(trim) != trim or trim < 1:
        raise ConfigError(f"lfpiv-vs-tomo model: 'trim' must be a whole number >= 1, got {trim!r}.")
    v = np.array(vol, copy=True)
    v[:, :trim, :] = 0
    v[:, -trim:, :] = 0
    v[:, :, :trim] = 0
    v[:, :, -trim:] = 0
    return v


def _hot_boundary_share(vol, trim: int, top: int = 100) -> float:
    """Share of the squared intensity of the ``top`` brightest voxels that lies within ``trim``
    voxels of the lateral (x, y) boundary (the boundary holds ``~4 trim / n`` of the voxels)."""
    v = np.asarray(vol, dtype=float)
    idx = np.argsort(v.ravel())[::-1][:top]
    _, y, x = np.unravel_index(idx, v.shape)
    edge = (y < trim) | (y >= v.shape[1] - trim) | (x < trim) | (x >= v.shape[2] - trim)
    e = v.ravel()[idx] ** 2
    return float(e[edge].sum() / e.sum()) if e.sum() > 0 else math.nan


def lf_depth_point(case: LFCase, *, iterations, rays_per_aperture_pixel: float, drt_rays_per_pixel: int, seed: int,
                   flow_seed: int = 0, trim: int = 2, min_coverage: float = MIN_COVERAGE) -> dict:
    """One light-field case reconstructed at several DRT-MART iteration counts (the same images
    and weights), its PIV errors by depth for each (:func:`piv_errors_by_depth`) and on the
    ideal volumes: where the reconstruction's errors sit, and what the iterations do to them.
    Also per iteration count: the share of the brightest voxels' energy on the grid's lateral
    boundary (``trim`` voxels), the PIV errors with that boundary zeroed (a diagnostic of the
    crop's edge artefact, not a processing step of the study) and with the study's cure, the
    field's edge dropped from the reconstruction (``min_coverage``, ``"masked"``)."""
    from mitpiv.reconstruct.plenoptic import drt_mart, drt_weights

    cam = lf_camera(case)
    grid = case.grid()
    fl, passes, dt, p0, p1 = _particle_pair(case, "lf", case.pmr, grid, seed, flow_seed, 1.0)
    imgs = to_8bit([render_light_field(cam, p, rays_per_aperture_pixel=rays_per_aperture_pixel, seed=seed + k)
                    for k, p in enumerate((p0, p1))])
    a = drt_weights(cam, grid, rays_per_pixel=drt_rays_per_pixel, substeps=2, seed=seed)
    out = {"camera": case.camera, "pmr": case.pmr, "crop_mm": [case.crop_mm, case.crop_y_mm], "grid": list(grid.shape),
           "windows": [list(w) for w in passes], "by_iterations": {}}
    for it in iterations:
        vols = [drt_mart(im, cam, grid, iterations=int(it), matrix=a) for im in imgs]
        r = piv_errors_by_depth(vols[0], vols[1], grid, fl, dt, passes)
        r["hot_energy_share_at_boundary"] = float(np.mean([_hot_boundary_share(v, trim) for v in vols]))
        trimmed = [_zero_lateral_boundary(v, trim) for v in vols]
        r["trimmed"] = piv_errors_by_depth(trimmed[0], trimmed[1], grid, fl, dt, passes)
        masked = [drt_mart(im, cam, grid, iterations=int(it), matrix=a, min_coverage=min_coverage) for im in imgs]
        r["masked"] = piv_errors_by_depth(masked[0], masked[1], grid, fl, dt, passes)
        r["masked"]["hot_energy_share_at_boundary"] = float(np.mean([_hot_boundary_share(v, trim) for v in masked]))
        out["by_iterations"][str(int(it))] = r
    out["trim_voxels"] = int(trim)
    out["min_coverage"] = float(min_coverage)
    from mitpiv.analysis.quality import truth_volume

    out["ideal"] = piv_errors_by_depth(truth_volume(p0, grid, 1.0), truth_volume(p1, grid, 1.0), grid, fl, dt, passes)
    return out


def piv_errors(vol_a, vol_b, grid: VoxelGrid, flow, dt_s: float, passes) -> dict:
    """Two-pass multi-grid PIV (75 % overlap, UOD + median replacement) and the RMS error of
    the valid vectors against the flow averaged over the final window: per component, in
    voxels of the grid (displacement) and in mm/s."""
    fld, p, err, truth = _piv_vector_errors(vol_a, vol_b, grid, flow, dt_s, passes)
    vox = np.asarray(grid.voxel_mm)
    rms_mm_s = np.sqrt(np.mean(err**2, axis=0)) if len(err) else np.full(3, np.nan)
    return {"rms_vox": (rms_mm_s * dt_s / vox).tolist(), "rms_mm": (rms_mm_s * dt_s).tolist(),
            "rms_mm_s": rms_mm_s.tolist(), "n_vectors": int(fld.n_vectors), "n_valid": int(len(err)),
            "outlier_ratio": float(fld.outlier_ratio), "windows": [list(w) for w in passes],
            "truth_rms_mm_s": np.std(truth, axis=0).tolist() if len(truth) else [math.nan] * 3}


def _dt(first_window_x_vox: int, voxel_x_mm: float) -> float:
    """One-quarter rule: the exit velocity (the largest) moves a quarter of the first window."""
    return 0.25 * first_window_x_vox * voxel_x_mm / EXIT_VELOCITY_MM_S


# ---------------------------------------------------------------------- points
def _particle_pair(case, kind: str, density: float, grid: VoxelGrid, seed: int, flow_seed: int, window_scale: float):
    """The two frames' particles of one case: the jet, the case's PIV passes (Table 2), the
    frame separation from the first window, particles seeded in the grid and advected (RK4)."""
    from mitpiv.physics.advection import advect

    rng = np.random.default_rng(seed)
    fl = jet(flow_seed)
    passes = window_plan(kind, density, fit_shape_zyx=grid.shape, scale=window_scale)
    dt = _dt(passes[0][0], grid.voxel_mm[0])
    p0 = seed_particles(grid, case.n_particles(), rng)
    p1 = advect(p0, fl.velocity, dt_s=dt, substeps=4)
    return fl, passes, dt, p0, p1


def lf_point(case: LFCase, *, iterations: int, rays_per_aperture_pixel: float, drt_rays_per_pixel: int,
             window_scale: float, seed: int, flow_seed: int = 0, min_coverage: float | None = MIN_COVERAGE) -> dict:
    """Render, reconstruct (DRT-MART, the field's edge dropped below ``min_coverage``) and
    score one light-field case (two frames)."""
    from mitpiv.reconstruct.plenoptic import drt_mart, drt_weights

    t0 = time.perf_counter()
    cam = lf_camera(case)
    grid = case.grid()
    fl, passes, dt, p0, p1 = _particle_pair(case, "lf", case.pmr, grid, seed, flow_seed, window_scale)
    t_r = time.perf_counter()
    imgs = to_8bit([render_light_field(cam, p, rays_per_aperture_pixel=rays_per_aperture_pixel, seed=seed + k)
                    for k, p in enumerate((p0, p1))])
    render_s = time.perf_counter() - t_r
    t_w = time.perf_counter()
    a = drt_weights(cam, grid, rays_per_pixel=drt_rays_per_pixel, substeps=2, seed=seed)
    weights_s = time.perf_counter() - t_w
    vols, infos = [], []
    for im in imgs:
        v, info = drt_mart(im, cam, grid, iterations=iterations, matrix=a, min_coverage=min_coverage, return_info=True)
        vols.append(v)
        infos.append(info)
    rec_s = weights_s + sum(i["iterate_s"] for i in infos)
    # per frame: the weights (built once per camera and grid) and the faster frame's iterations
    # (the first call may include Numba's compilation)
    per_frame = weights_s + min(i["iterate_s"] for i in infos)
    out = {"kind": "lf", "camera": case.camera, "pmr": case.pmr, "crop_mm": case.crop_mm, "crop_y_mm": case.crop_y_mm,
           "sensor_px": list(case.sensor_wh), "mla_count": list(case.mla_count), "particles": len(p0),
           "grid": list(grid.shape), "voxel_mm": list(grid.voxel_mm), "dt_s": dt,
           "rays_per_particle": rays_per_particle(cam, rays_per_aperture_pixel),
           "lit_fraction": float(np.mean(imgs[0] > 0)), "render_s": render_s, "weights_s": weights_s,
           "reconstruct_s": rec_s, "reconstruct_s_per_frame": per_frame, "weight_entries": int(a.nnz),
           "active_entries": int(np.mean([i["active_entries"] for i in infos])),
           "active_voxels": int(np.mean([i["active_voxels"] for i in infos])), "iterations": iterations,
           "pixels": case.pixels, "full_pixels": case.spec["resolution"] ** 2, "min_coverage": min_coverage,
           "edge_voxels_dropped": int(infos[0].get("edge_voxels_dropped", 0))}
    out["particles_err"] = particle_errors(vols[0], grid, p0)
    out["piv"] = piv_errors(vols[0], vols[1], grid, fl, dt, passes)
    out["piv_ideal"] = ideal_piv_errors(p0, p1, grid, fl, dt, passes, sigma_voxels=1.0)
    out["wall_s"] = time.perf_counter() - t0
    return out


def ideal_piv_errors(p0, p1, grid: VoxelGrid, flow, dt_s: float, passes, *, sigma_voxels: float) -> dict:
    """:func:`piv_errors` on the ideal reconstructions (Gaussian blobs of ``sigma_voxels`` at
    the true particle positions): the error of the PIV and the finite windows alone, without
    the reconstruction's (a diagnostic the paper does not show)."""
    from mitpiv.analysis.quality import truth_volume

    return piv_errors(truth_volume(p0, grid, sigma_voxels), truth_volume(p1, grid, sigma_voxels), grid, flow, dt_s,
                      passes)


def tomo_point(case: TomoCase, *, iterations: int, window_scale: float, seed: int, flow_seed: int = 0) -> dict:
    """Render, reconstruct (MLOS-SMART) and score one tomographic case (two frames)."""
    from mitpiv.reconstruct import mart
    from mitpiv.reconstruct.mapping import PinholeMapping

    t0 = time.perf_counter()
    cams = tomo_cameras(case)
    maps = [PinholeMapping(c) for c in cams]
    grid = case.grid()
    fl, passes, dt, p0, p1 = _particle_pair(case, "tomo", case.ppp, grid, seed, flow_seed, window_scale)
    t_r = time.perf_counter()
    frames = [render_tomo(cams, p) for p in (p0, p1)]
    render_s = time.perf_counter() - t_r
    vols, rec = [], []
    for imgs in frames:
        t_m = time.perf_counter()
        v, info = mart(imgs, maps, grid, iterations=iterations, smart=True, return_info=True, residuals="final")
        rec.append(time.perf_counter() - t_m)
        vols.append(v)
    out = {"kind": "tomo", "n_cameras": case.n_cameras, "ppp": case.ppp, "crop_y_mm": case.crop_y_mm,
           "rows": case.rows, "particles": len(p0), "grid": list(grid.shape), "voxel_mm": list(grid.voxel_mm),
           "dt_s": dt, "render_s": render_s, "reconstruct_s": sum(rec),
           "reconstruct_s_per_frame": min(rec),  # the faster frame: the first may include compilation
           "active_voxels": int(info["active_voxels"]), "iterations": iterations,
           "voxels": int(np.prod(grid.shape)), "full_voxels": TOMO["resolution"] ** 2 * TOMO["nz"]}
    out["particles_err"] = particle_errors(vols[0], grid, p0)
    out["piv"] = piv_errors(vols[0], vols[1], grid, fl, dt, passes)
    out["piv_ideal"] = ideal_piv_errors(p0, p1, grid, fl, dt, passes, sigma_voxels=TOMO["particle_diameter_px"] / 4)
    out["wall_s"] = time.perf_counter() - t0
    return out
