"""The physically based arm of the SAPIV replication (issue 47, item 6): the paper-model
arm's particle fields rendered by Mitsuba instead of splatted.

``scenes/sapiv_paper`` is the thesis's array as a Mitsuba scene: 25 ``distorted_pinhole``
sensors with the percent distortion of eq. A.3 (the same k1 as the model's cameras), the
Fourier-optics PSF of eq. 3.4 with the Zernike spherical term (``psf="fft"``, f/2.8 at
M = -0.2), and 20 um particles of index 1.45 scattering by Lorenz-Mie theory, lit through the
volume's depth by a 10 mm top-hat sheet travelling along +x. What changes against the image
model: each camera sees each particle at its own scattering angle (59-121 degrees from the
sheet's direction over the array), so the 25 views of one particle differ in brightness by
the Mie phase function's ratio, and the film's Catmull-Rom reconstruction filter replaces
the model's pixel integration. The rendered images go through the paper-model arm's own
chain: the calibration of the same distortion and aberration (the targets imaged by the
model: the true cameras are the same, checked per sensor), refocusing, the readings and
the metrics (:func:`mitpiv.replications.sapiv_distortion.model.score_images`). Table 3.1's
r^2 law is not a Brown-Conrady distortion, which the sensor renders, so this arm runs eq. A.3
only.

The sensor: the thesis images without one (its pixel values are the irradiance). A camera
records counts, so the rendered images go through the sensor model of
``scenes/sapiv_paper/experiment.toml`` (``[sensor]``, :data:`SENSOR`, read from that file):
one fixed exposure for every camera, configuration and density (photons per watt a pixel
collects: aperture photometry, each pixel's light through its own f/2.8 pupil), Poisson
photon noise, read noise, a black level (subtracted before refocusing, as a user subtracts
the camera's dark frame) and 12 bits (:func:`mitpiv.imaging.apply_sensor_set`). The thesis
names no camera, so these values are ours (a generic 12-bit scientific camera), not the
paper's. Each point is scored twice on the same render: the recorded counts (the arm's rows)
and the same exposure without noise or quantisation (``no_sensor``: the light each pixel
collects, in counts), so the report can tell what the optics change from what the sensor
changes.
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

__all__ = ["SCENE", "SENSOR", "render_field", "physical_point", "sensor_counts", "noise_free", "scene_hash"]

SCENE = Path(__file__).resolve().parents[3] / "scenes" / "sapiv_paper" / "scene.xml"


def _sensor_model():
    import tomllib

    from mitpiv.imaging import SensorModel

    path = SCENE.with_name("experiment.toml")
    table = tomllib.loads(path.read_text()).get("sensor")
    if not table:
        raise ConfigError(f"sapiv physical arm: {path} has no [sensor] table; the rendered arm records counts "
                          "through the experiment's sensor model.")
    return SensorModel(**table)


#: the sensor model of ``scenes/sapiv_paper/experiment.toml`` (its ``[sensor]`` table)
SENSOR = _sensor_model()


def scene_hash() -> str:
    """A content hash (12 hex digits) of the scene and experiment files this arm renders with:
    part of its points' cache keys, so a point rendered from other files is computed again
    (the replication frame hashes mitpiv's modules, not the scenes)."""
    import hashlib

    h = hashlib.sha256()
    for f in (SCENE, SCENE.with_name("experiment.toml")):
        h.update(f.read_bytes())
    return h.hexdigest()[:12]
#: radius of the particles' proxy spheres in the PLY [mm] (hit only by stray rays; a pinhole
#: camera's particle light is traced from the particle, not found by intersection)
PROXY_RADIUS_MM = 0.01


def _match(sensors, cameras) -> list[int]:
    """For each model camera, the index of the rendered sensor with the same pose: the true
    cameras must be the same, their projections of the volume's corners within 1e-3 px (the
    scene's poses are float32: 1.5e-5 px apart)."""
    corners = np.array([[x, y, z] for x in (-25, 25) for y in (-25, 25) for z in (-5, 5)], float)
    order = []
    for cam in cameras:
        d = [np.linalg.norm(np.asarray(s.camera.position_mm) - cam.position_mm) for s in sensors]
        i = int(np.argmin(d))
        sc = sensors[i].camera
        if sc.resolution != cam.resolution or np.max(np.abs(sc.project(corners) - cam.project(corners))) > 1e-3:
            raise ConfigError(f"sapiv physical arm: no sensor of {SCENE.name} matches the model camera at "
                              f"{cam.position_mm.tolist()} mm (nearest {d[i]:.3g} mm away); the scene and "
                              "SapivSystem.cameras() must describe the same array.")
        order.append(i)
    return order


def render_field(system, cameras, positions_mm, *, distortion_percent: float, spherical_waves: float,
                 seed: int) -> tuple[list[np.ndarray], dict]:
    """Render ``positions_mm`` (20 um particles) through the 25 sensors of :data:`SCENE` with
    the given distortion and aberration; returns the images in the order of ``cameras`` and
    a dict of the timings [s] and the sensors' ids and camera records (``ids``, ``records``,
    same order)."""
    from mitpiv.io.particles import write_particles_ply
    from mitpiv.render.render import render_sensor, sensor_model
    from mitpiv.render.scene import load_scene

    t0 = time.perf_counter()
    tmp = Path(tempfile.mkdtemp(prefix="mitpiv_sapiv_"))
    try:
        xml = tmp / SCENE.name
        shutil.copyfile(SCENE, xml)
        write_particles_ply(tmp / "particles_0.ply", positions_mm, system.particle_diameter_um,
                            proxy_radius_mm=PROXY_RADIUS_MM)
        scene = load_scene(xml, frame=0, params={"resolution": system.resolution,
                                                 "distortion_percent": distortion_percent,
                                                 "spherical_waves": spherical_waves})
        t_load = time.perf_counter() - t0
        sensors = list(scene.sensors())
        order = _match(sensors, cameras)
        imgs = [render_sensor(scene, sensors[i], seed=seed, frame=0) for i in order]
        ids = [sensors[i].id() for i in order]
        records = [sensor_model(sensors[i]) for i in order]
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    return imgs, {"t_load_s": t_load, "t_render_s": time.perf_counter() - t0 - t_load, "ids": ids,
                  "records": records}


def sensor_counts(imgs, ids, records, *, seed: int, model=None) -> tuple[list[np.ndarray], dict]:
    """The counts the cameras record of the rendered ``imgs`` (one set, with the model's
    exposure, :func:`mitpiv.imaging.apply_sensor_set` with each sensor's record for aperture
    photometry), less the black level, as float64 in the same order, and what they were taken
    with. ``model`` defaults to :data:`SENSOR`."""
    from mitpiv.imaging import apply_sensor_set

    model = SENSOR if model is None else model
    res = apply_sensor_set({(i, 0): im for i, im in zip(ids, imgs, strict=True)}, model, seed=seed,
                           cameras=dict(zip(ids, records, strict=True)), on_degenerate="raise")
    raw = [res.counts[(i, 0)] for i in ids]
    top = 2 ** model.bit_depth - 1 if model.bit_depth else math.inf
    counts = [c.astype(np.float64) - model.black_level for c in raw]
    info = {"photometry": res.photometry, "exposure": res.exposure,
            "peak_counts": [float(c.max()) for c in counts],
            "sum_counts": [float(np.sum(c)) for c in counts],
            "saturated_fraction": float(np.mean([np.mean(c >= top) for c in raw]))}
    return counts, info


def physical_point(system, cameras, mappings, *, distortion_percent: float, spherical_waves: float,
                   density_per_mm3: float, seed: int, patches, patch_mm: float) -> dict:
    """One point of the physically based arm: the particle field of the paper-model arm's
    point with the same seed (:func:`~mitpiv.replications.sapiv_distortion.model.seed_field`),
    rendered by Mitsuba (:func:`render_field`) and scored by the same chain."""
    from mitpiv.replications.sapiv_distortion.model import score_images, seed_field

    t0 = time.perf_counter()
    c0 = time.process_time()
    field = seed_field(system, density_per_mm3=density_per_mm3, seed=seed, patches=patches, patch_mm=patch_mm)
    imgs, t = render_field(system, cameras, field["imaged"], distortion_percent=distortion_percent,
                           spherical_waves=spherical_waves, seed=seed)
    t1 = time.perf_counter()
    ids, records = t.pop("ids"), t.pop("records")
    counts, info = sensor_counts(imgs, ids, records, seed=seed)
    light, light_info = sensor_counts(imgs, ids, records, seed=seed, model=noise_free(SENSOR))
    t_sensor = time.perf_counter() - t1
    out = score_images(system, counts, mappings, field)
    bare = score_images(system, light, mappings, field)
    out["no_sensor"] = {k: bare[k] for k in ("Q", "Qprime", "SNR", "mu", "sigma", "kept_fraction", "Q_patch",
                                             "readings")}
    out["no_sensor"]["sum_counts"] = light_info["sum_counts"]
    out.update(t)
    out["t_sensor_s"] = t_sensor
    out["sensor"] = info
    out["camera_energy"] = [float(np.sum(im, dtype=np.float64)) for im in imgs]
    out["t_total_s"] = time.perf_counter() - t0
    out["cpu_s"] = time.process_time() - c0
    return out
