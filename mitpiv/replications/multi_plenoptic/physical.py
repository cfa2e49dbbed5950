"""The physically based arm of the multi-plenoptic replication (issue 56, item 5): the
paper-model arm's particle fields rendered by Mitsuba instead of traced by the paper's
light-ray model, and recorded by a camera sensor.

``scenes/multiplenoptic_paper`` is the paper's system as a Mitsuba scene: ``plenoptic``
sensors with Table 1's main lens (10 mm, 5 mm pupil) and lenslets (14 um, f/2, 28 um from a
sensor of 1.4 um pixels), ``distorted_pinhole`` standard cameras with the same lens at f/2 or
f/20 (a thin lens focused on the volume, the Fourier-optics diffraction PSF at the working
f-number), 2 um particles of index 1.45 scattering by Lorenz-Mie theory, lit through the
volume's thickness (times :data:`SHEET_MARGIN`) by a top-hat sheet travelling along +x. Each camera point of this arm
loads the scene with the point's distance, angle and azimuth, checks that the rendered
sensor is the model arm's camera (:func:`check_pose`), renders the two frames of the model
arm's particle field of the same seed, and records them through :func:`sensor`.

What changes against the paper's image model:

* **Mie scattering.** A camera at 25 deg from the volume axis sees the sheet's light
  scattered through 65 deg (azimuth 0, forward), 90 deg (azimuths 90, 270) or 115 deg
  (azimuth 180, backward); a 2 um droplet sends about 5 times more light forward than
  backward, so the cameras of one configuration differ in brightness, and the phase
  function varies across the 5 mm pupil (the plenoptic camera resolves it: a particle's
  lenslet image is not uniform).
* **Aperture photometry.** Each pixel collects the power through its own pupil
  (:mod:`mitpiv.photometry`): a 14 um standard pixel at f/2 collects what the 100 pixels of a
  lenslet share, and an f/20 camera 1/100 of an f/2 one at the same exposure, the
  depth-of-field trade-off the paper's normalised images leave out.
* **A sensor.** Photon (Poisson) noise, read noise, a black level (subtracted, negative
  values clipped at zero as a user's dark-frame subtraction does) and 16 bits. The paper
  names no camera; the two sensors (:func:`sensor`) are ours: the same technology for both
  pixel sizes (quantum efficiency 0.6, read noise 2.5 e-, a full well of 2300 e- per um^2 of
  pixel: 4,500 e- for 1.4 um, 450,000 e- for 14 um, 16 bits spanning the well, less a black
  level of 1000 counts).
* **The exposure** is one number of photons per watt for every camera and configuration
  (:data:`EXPOSURE_PER_W`), set once (from renders of the 25 deg pair at 96 x 96 lenslets,
  seeds 3 and 4, before any point of this arm was scored) so that the brightest plenoptic
  pixel of the forward camera sits near half its full well. Fig. 7 moves one camera from
  S_o = 12.5 to 100 mm, which changes the light each particle sends into the pupil as
  1 / S_o^2; there the exposure scales as (S_o / 40 mm)^2 (the experimenter keeps the photons
  per particle, raising the laser energy as the camera moves away), so the sweep compares
  geometry, not light.

The rendered counts go through the model arm's own chain: decoding with the model's
:class:`~mitpiv.physics.plenoptic.PlenopticCamera` (cubic), eq. 14 with the same white-image
weights and floor, eq. 15 or MART on the standard cameras with the mapping the model arm
calibrates for the same camera (the same targets and seed). Optionally the same render is also recorded without noise
or quantisation (``no_sensor``: the light each pixel collects, in counts), so the report can
tell what the optics change from what the sensor changes.
"""

from __future__ import annotations

import math
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError
from mitpiv.imaging import noise_free

__all__ = ["SCENE", "RAYS", "DIAMETER_UM", "EXPOSURE_PER_W", "sensor", "noise_free", "scene_hash", "check_pose",
           "scene_params", "render_camera", "record"]

SCENE = Path(__file__).resolve().parents[3] / "scenes" / "multiplenoptic_paper" / "scene.xml"
#: rays per particle: more than the photons a particle sends into the brightest camera's pupil
#: (about 61,000 at the exposure below), so the Monte Carlo noise stays below the photon noise
RAYS = 200_000
#: particle diameter [um] (the scene's experiment seeds 2 um; the paper's Gaussian sources have no size)
DIAMETER_UM = 2.0
#: radius of the particles' proxy spheres [mm] (hit only by stray camera rays)
PROXY_RADIUS_MM = 0.005
#: photons per watt a pixel collects, at S_o/p_M = 8 (module docstring): the forward plenoptic
#: camera's brightest pixel at 1.5-2.0e-10 W (96 x 96 lenslets, 25 deg, 2 um particles) -> 3,000-3,900
#: photons, 1,800-2,300 e- of its 4,500 e- well
EXPOSURE_PER_W = 2.0e13
#: the top-hat sheet's thickness over the volume's: the model arm's particles are all seen in both
#: frames, and frame 1's particles advected out of the volume's thickness (2.3 % at S_o/p_M = 4) stay lit
SHEET_MARGIN = 1.5
#: the sensors' technology (ours; the paper names no camera)
QE = 0.6
READ_NOISE_E = 2.5
WELL_E_PER_UM2 = 2300.0
BIT_DEPTH = 16
BLACK_LEVEL = 1000.0


def sensor(kind: str, so_over_pm: float):
    """The sensor model of a plenoptic (``"plen"``: 1.4 um pixels) or standard (``"f2"``,
    ``"f20"``: 14 um pixels) camera at ``S_o/p_M``: aperture photometry at
    :data:`EXPOSURE_PER_W` x (S_o/p_M / 8)^2, 16 bits spanning the full well."""
    from mitpiv.imaging import SensorModel
    from mitpiv.replications.multi_plenoptic.model import LENSLET_PITCH_UM, PIXEL_UM

    pitch = PIXEL_UM if kind == "plen" else LENSLET_PITCH_UM
    well = WELL_E_PER_UM2 * pitch**2
    return SensorModel(exposure=EXPOSURE_PER_W * (so_over_pm / 8.0) ** 2, photometry="aperture",
                       quantum_efficiency=QE, shot_noise=True, read_noise_e=READ_NOISE_E, full_well_e=well,
                       gain_e_per_count=well / (2**BIT_DEPTH - 1), black_level=BLACK_LEVEL, bit_depth=BIT_DEPTH)


def scene_hash() -> str:
    """A content hash (12 hex digits) of the scene this arm renders: part of its points' cache
    keys (the replication frame hashes mitpiv's modules, not the scenes)."""
    import hashlib

    return hashlib.sha256(SCENE.read_bytes()).hexdigest()[:12]


def scene_params(kind: str, so_over_pm: float, thickness_ratio: float, n_lenslets: int, angle_deg: float,
                 azimuth_deg: float) -> dict:
    """The ``$name`` substitutions of :data:`SCENE` for one camera: sensor ``plen0`` or
    ``pin0`` at the point's distance, angle and azimuth, the crop, the sheet SHEET_MARGIN times as thick as the
    volume, and for a standard camera its f-number written for ``distorted_pinhole``'s thin
    lens (a pinhole at the image distance with the 5 mm / N pupil; the scene's comment); for
    a plenoptic point the unused standard cameras get a lens that images S_o."""
    from mitpiv.replications.multi_plenoptic import model as S

    so = so_over_pm * S.MAIN_APERTURE_MM
    si = S.image_distance_mm(so)
    _, _, full_w = S.volume_box(so_over_pm, thickness_ratio, n_lenslets)
    p = {"lenslets": n_lenslets, "resolution": 10 * n_lenslets, "pin_resolution": n_lenslets,
         "focus_distance_mm": f"{so:.9g}", "thickness_mm": f"{SHEET_MARGIN * full_w * thickness_ratio:.9g}",
         "elevation_deg": f"{90.0 - angle_deg:.9g}", "az0": f"{azimuth_deg:.9g}", "rays_per_particle": RAYS}
    if kind == "plen":
        # every sensor of the scene is built: the unused standard cameras get a lens that images
        # S_o (the scene's defaults, S_o = 40 mm, are no lens at S_o < 13.3 mm)
        p.update(pin_image_distance_mm=f"{0.5 * so:.9g}")
    else:
        if si >= so:
            raise ConfigError(f"scene_params: a standard camera at S_o / p_M = {so_over_pm:g} (S_o {so:g} mm) has its "
                              f"image distance {si:g} mm >= S_o, which distorted_pinhole's pinhole-at-the-image-distance "
                              "form cannot write (it needs S_o > 2 f, S_o / p_M > 4); place it farther.")
        fnum = float(kind[1:])
        p.update(pinhole_f_number=f"{fnum:.9g}", pin_image_distance_mm=f"{si:.9g}",
                 pin_image_f_number=f"{si / (S.MAIN_FOCAL_MM / fnum):.9g}",
                 pin_magnification=f"{S.MAIN_FOCAL_MM / (so - S.MAIN_FOCAL_MM):.9g}")
    return p


def _differences(a, b, path: str = "") -> list[str]:
    """The entries of two camera records (nested dicts / lists of numbers and strings) that
    differ: numbers beyond a relative 1e-6, anything else when unequal."""
    if isinstance(a, dict) and isinstance(b, dict):
        return [d for k in sorted(set(a) | set(b)) for d in _differences(a.get(k), b.get(k), f"{path}.{k}".lstrip("."))]
    if isinstance(a, list | tuple) and isinstance(b, list | tuple) and len(a) == len(b):
        return [d for i, (x, y) in enumerate(zip(a, b, strict=True)) for d in _differences(x, y, f"{path}[{i}]")]
    if isinstance(a, int | float) and isinstance(b, int | float) and not isinstance(a, bool):
        return [] if abs(a - b) <= 1e-6 * max(abs(a), abs(b), 1e-12) else [f"{path}: {a!r} vs {b!r}"]
    return [] if a == b else [f"{path}: {a!r} vs {b!r}"]


def check_pose(sensor_obj, model_camera, kind: str, *, so_over_pm: float | None = None) -> None:
    """Refuse a rendered sensor that is not the model arm's camera. Plenoptic: every entry of
    the two cameras' records (main lens, lenslets, sensor, crop) within a relative 1e-6, the
    rotation within 1e-6 and the position within 1e-6 of its distance (float32 poses: about
    1e-7). Standard: the projections of an 8 x 8 x 4 mm box about the origin within 1e-3 px,
    the same resolution, and (with ``so_over_pm``) the thin lens's f-number relative to the
    image distance, the focus distance and the diffraction f-number and magnification those of
    the model's lens."""
    problems: list[str] = []
    cam = sensor_obj.camera
    if kind == "plen":
        a, b = cam.to_dict(), model_camera.to_dict()
        a.pop("to_world_mitsuba", None)
        b.pop("to_world_mitsuba", None)
        problems = _differences(a, b)
        m1, m2 = np.asarray(cam.to_world_mitsuba, float), np.asarray(model_camera.to_world_mitsuba, float)
        dr = float(np.max(np.abs(m1[:3, :3] - m2[:3, :3])))
        dt = float(np.max(np.abs(m1[:3, 3] - m2[:3, 3])))
        if dr > 1e-6 or dt > 1e-6 * max(1.0, float(np.linalg.norm(m2[:3, 3]))):
            problems.append(f"pose: rotation differs by {dr:.3g}, position by {dt:.3g} mm")
    else:
        c = np.array([[x, y, z] for x in (-4, 4) for y in (-4, 4) for z in (-2, 2)], float)
        d = float(np.max(np.abs(cam.project(c) - model_camera.project(c))))
        if tuple(cam.resolution) != tuple(model_camera.resolution) or d > 1e-3:
            problems.append(f"projections differ by {d:.3g} px (resolution {tuple(cam.resolution)} vs "
                            f"{tuple(model_camera.resolution)})")
        if so_over_pm is not None:
            from mitpiv.render.render import sensor_model
            from mitpiv.replications.multi_plenoptic import model as S

            so = so_over_pm * S.MAIN_APERTURE_MM
            fnum = float(kind[1:])
            rec = sensor_model(sensor_obj)
            want = {"f_number": S.image_distance_mm(so) * fnum / S.MAIN_FOCAL_MM, "focus_distance_mm": so,
                    "psf": {"f_number": fnum, "magnification": S.MAIN_FOCAL_MM / (so - S.MAIN_FOCAL_MM)}}
            got = {"f_number": rec.get("f_number"), "focus_distance_mm": rec.get("focus_distance_mm"),
                   "psf": {k: (rec.get("psf") or {}).get(k) for k in ("f_number", "magnification")}}
            problems += _differences(got, want)
    if problems:
        raise ConfigError(f"multi-plenoptic physical arm: sensor {sensor_obj.id()!r} of {SCENE} is not the model arm's "
                          f"camera ({'; '.join(problems[:4])}); the scene and model.plenoptic_camera / standard_camera "
                          "must describe the same system.")


def render_camera(kind: str, so_over_pm: float, thickness_ratio: float, n_lenslets: int, angle_deg: float,
                  azimuth_deg: float, frames_mm, *, seed: int) -> tuple[list[np.ndarray], str, dict, dict]:
    """Render the particle positions of each frame (``frames_mm``: a sequence of (N, 3) [mm])
    through one camera of :data:`SCENE` (``plen0`` for ``kind = "plen"``, ``pin0`` at f/N for
    ``"fN"``); returns the images, the sensor id, its camera record (for aperture photometry)
    and the timings [s]."""
    from mitpiv.io.particles import write_particles_ply
    from mitpiv.render.render import render_sensor, sensor_model
    from mitpiv.render.scene import load_scene
    from mitpiv.replications.multi_plenoptic import model as S

    model_cam = (S.plenoptic_camera(so_over_pm, angle_deg, azimuth_deg, n_lenslets) if kind == "plen"
                 else S.standard_camera(so_over_pm, angle_deg, azimuth_deg, n_lenslets, float(kind[1:])))
    sid = "plen0" if kind == "plen" else "pin0"
    params = scene_params(kind, so_over_pm, thickness_ratio, n_lenslets, angle_deg, azimuth_deg)
    t_load = t_render = 0.0
    imgs, rec = [], None
    tmp = Path(tempfile.mkdtemp(prefix="mitpiv_mp_"))
    try:
        xml = tmp / SCENE.name
        shutil.copyfile(SCENE, xml)
        for k, pts in enumerate(frames_mm):
            write_particles_ply(tmp / f"particles_{k}.ply", np.asarray(pts, float), DIAMETER_UM,
                                proxy_radius_mm=PROXY_RADIUS_MM)
        for k in range(len(frames_mm)):
            t0 = time.perf_counter()
            scene = load_scene(xml, frame=k, params=params)
            sens = {s.id(): s for s in scene.sensors()}[sid]
            if rec is None:
                check_pose(sens, model_cam, kind, so_over_pm=so_over_pm)
                rec = sensor_model(sens)
            t1 = time.perf_counter()
            imgs.append(render_sensor(scene, sens, seed=seed, frame=k))
            t_load += t1 - t0
            t_render += time.perf_counter() - t1
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return imgs, sid, rec, {"t_load_s": t_load, "t_render_s": t_render}


def record(imgs, sid: str, rec: dict, model, *, seed: int) -> tuple[list[np.ndarray], dict]:
    """The counts one camera records of its rendered frames with ``model``
    (:func:`mitpiv.imaging.apply_sensor_set`, aperture photometry from ``rec``), less the black
    level and clipped at zero, as float32, and what they were taken with (peak and summed
    counts, the saturated fraction)."""
    from mitpiv.imaging import apply_sensor_set

    res = apply_sensor_set({(sid, k): im for k, im in enumerate(imgs)}, model, seed=seed, cameras={sid: rec},
                           on_degenerate="raise")
    raw = [res.counts[(sid, k)] for k in range(len(imgs))]
    top = 2**model.bit_depth - 1 if model.bit_depth else math.inf
    counts = [np.clip(c.astype(np.float64) - model.black_level, 0.0, None).astype(np.float32) for c in raw]
    return counts, {"peak_counts": [float(c.max()) for c in counts], "sum_counts": [float(np.sum(c, dtype=np.float64))
                                                                                  for c in counts],
                    "saturated_fraction": float(np.mean([np.mean(c >= top) for c in raw])),
                    "exposure": float(model.exposure), "photometry": res.photometry}
