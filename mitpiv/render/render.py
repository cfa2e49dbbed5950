"""Rendering scenes to float32 EXR files with metadata, and PNG previews.

Reproducibility (:data:`DETERMINISM`): on one machine, with one Mitsuba variant and the
same versions, a render is a function of its scene and seed.

* Particle tracing (mitpiv's ``particle_tracer``, every mitpiv scene): bit-identical images
  on LLVM variants; the splats are summed on one thread in ray order (see
  :mod:`mitpiv.render.plugins.particle_tracer`).
* Camera tracing (Mitsuba's ``direct`` and other sampling integrators): bit-identical with a
  ``box`` film filter (each sample lands in one pixel and Mitsuba sums a pixel's samples in
  a fixed order). With a wider filter (``gaussian``, Mitsuba's default, ``catmullrom``, ...)
  a sample is splatted into several pixels by atomic float additions from several threads,
  so a pixel's sum, and its weight, are rounded in a run-dependent order: a pixel of ``k``
  non-negative contributions may differ by at most ``2 (k - 1) 2^-24`` of its value in the
  sum and as much in the weight (``k`` = samples per pixel times the filter's footprint in
  pixels, ``(2 radius)^2``). Measured (128-256 px, gaussian filter, 4 spp, 2 threads):
  0.4-4 % of the pixels differ between runs, by at most 5e-7 of their value (a few float32
  ulps), against the bound 1.5e-5.
* CUDA variants: GPU atomics have no fixed order in either strategy; the same bound holds.

Seeds: :func:`render_scene` renders each sensor and frame with its own 32-bit seed
``mitpiv.streams.render_seed(seed, sensor_id, frame)``; :func:`render_sensor` does the same
when given ``frame``. The particle tracer also hashes the sensor id into its stream, so
cameras differ even when one seed is passed to ``mi.render`` for all.
"""

from __future__ import annotations

import hashlib
import logging
import time
import warnings
from pathlib import Path

import drjit as dr
import mitsuba as mi
import numpy as np

from mitpiv.errors import ConfigError, MitpivWarning
from mitpiv.io.atomic import atomic_path
from mitpiv.io.exr import write_exr
from mitpiv.io.records import write_json
from mitpiv.progress import bar
from mitpiv.render.scene import load_scene
from mitpiv.streams import check_seed, render_seed
from mitpiv.version import __version__

_log = logging.getLogger(__name__)

__all__ = ["render_scene", "render_sensor", "sensor_model", "write_preview", "PIXEL_UNITS", "DETERMINISM",
           "filter_rounding_bound", "black_image_hints"]

#: What a rendered pixel value is, as written to each image's metadata (``units.pixel_value``)
#: unless the camera states its own (``camera.pixel_value``, as the plenoptic sensor does).
PIXEL_UNITS = (
    "radiance [W sr^-1 mm^-2] averaged over the pixel footprint and the aperture "
    "(Mitsuba's convention); particle intensities in W/sr, irradiance in W/mm^2"
)


#: What "same seed, same image" means, per transport strategy (see the module docstring).
DETERMINISM = {
    "particle_tracer": "bit-identical (LLVM variants); CUDA: float32 rounding of each pixel's sum",
    "camera_tracing_box_filter": "bit-identical",
    "camera_tracing_other_filters": "each pixel within filter_rounding_bound(spp, filter radius) of its value",
}


def filter_rounding_bound(spp: int, radius_px: float) -> float:
    """Largest relative difference of one pixel between two same-seed camera-tracing renders
    with a film filter of ``radius_px`` [px]: ``4 (k - 1) 2^-24``, ``k = spp (2 radius)^2``
    non-negative contributions summed in another order (the pixel's value and its weight,
    2 (k - 1) 2^-24 each; first order in the float32 unit roundoff 2^-24)."""
    k = int(spp) * max(1, int(np.ceil(2.0 * float(radius_px)))) ** 2
    return 4.0 * max(k - 1, 1) * 2.0**-24


def sensor_model(sensor) -> dict:
    """JSON-ready camera model of a sensor (mitpiv sensors describe themselves)."""
    if hasattr(sensor, "describe"):
        return sensor.describe()
    params = mi.traverse(sensor)
    return {
        "type": sensor.class_name(),
        "to_world_mitsuba": np.array(sensor.world_transform().matrix).reshape(4, 4).tolist(),
        "resolution": list(sensor.film().size()),
        "parameters": {k: str(params[k]) for k in params.keys()},
    }


def render_sensor(scene, sensor, *, spp: int = 0, seed: int = 0, frame: int | None = None) -> np.ndarray:
    """Render one sensor to a float32 (H, W) array, with the sensor's PSF if it asks for one.

    Without ``frame``, ``seed`` is passed to ``mi.render`` as it is (a 32-bit seed). With
    ``frame`` (an int), ``seed`` is the experiment seed and the render uses this sensor's and
    frame's own stream, ``mitpiv.streams.render_seed(seed, sensor.id(), frame)``, as
    :func:`render_scene` does: cameras and frames then draw independent noise.

    A ``distorted_pinhole`` with ``psf="fft"`` is rendered on a film ``oversample`` times
    finer (the film is restored afterwards) and convolved with its PSF
    (:meth:`mitpiv.imaging.RenderPSF.apply`); ``psf="jitter"`` happens inside the sensor.
    """
    if frame is not None:
        seed = render_seed(seed, sensor.id() or "", int(frame))

    def render(dtype):
        img = mi.render(scene, sensor=sensor, spp=spp, seed=seed)
        dr.eval(img)
        arr = np.array(img, dtype=dtype)
        return arr[:, :, 0] if arr.ndim == 3 else arr

    psf = getattr(sensor, "psf", None)
    if psf is None or psf.mode != "fft":
        return render(np.float32)
    params = mi.traverse(sensor.film())
    size = mi.ScalarVector2u(sensor.film().size())
    params["size"] = mi.ScalarVector2u(size[0] * psf.oversample, size[1] * psf.oversample)
    params.update()
    try:
        fine = render(np.float64)
    finally:
        params["size"] = size
        params.update()
    return psf.apply(fine).astype(np.float32)


def _integrator_info(scene) -> dict:
    """The integrator and, for the particle tracer, what its last render really used."""
    integ = scene.integrator()
    info = {"type": integ.class_name() if hasattr(integ, "class_name") else type(integ).__name__}
    if hasattr(integ, "rays_for"):
        info["type"] = "particle_tracer"
        stats = getattr(integ, "last_stats", {}) or {}
        info["rays_per_particle_setting"] = integ.rays_per_particle
        for key in ("rays_per_particle", "passes", "samples_per_particle", "occlusion"):
            if key in stats:
                info[key] = stats[key]
        info.setdefault("occlusion", integ.occlusion)
    else:
        for key in ("rays_per_particle", "occlusion"):
            if hasattr(integ, key):
                info[key] = getattr(integ, key)
    return info


def _spp_used(scene, sensor, spp) -> int:
    """Samples per pixel a render really used: the particle tracer's passes (see
    :mod:`mitpiv.render.plugins.particle_tracer`), else ``spp`` or the sensor sampler's count."""
    integ = scene.integrator()
    if hasattr(integ, "rays_for"):
        return int(integ.last_stats.get("passes", 1))
    return int(spp) if spp is not None else int(sensor.sampler().sample_count())


def write_preview(path, image: np.ndarray, *, percentile: float = 99.9) -> Path:
    """8-bit grey PNG preview: linear scaling to the given percentile, then sRGB gamma."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    img = np.asarray(image, dtype=np.float64)
    nz = img[img > 0]
    top = np.percentile(nz, percentile) if nz.size else 1.0
    x = np.clip(img / (top if top > 0 else 1.0), 0, 1) ** (1 / 2.2)
    with atomic_path(path, suffix=".png") as tmp:
        plt.imsave(tmp, x, cmap="gray", vmin=0, vmax=1, format="png")
    return Path(path)


def black_image_hints(scene, sensor) -> list[str]:
    """Likely reasons why ``sensor`` renders ``scene`` black (every pixel 0), for the warning
    of :func:`render_scene`: no particles, a camera inside the particles' bounding box, no
    particle on the sensor (a principal point far outside the image, say), a microlens
    array off the sensor."""
    from mitpiv.physics.camera import on_sensor

    hints = []
    centres = [np.array(e.particle_arrays()[0], dtype=np.float64).reshape(3, -1).T
               for e in (sh.emitter() for sh in scene.shapes()) if e is not None and hasattr(e, "particle_arrays")]
    pts = np.concatenate(centres) if centres else np.zeros((0, 3))
    cam = getattr(sensor, "camera", None)
    if not len(pts):
        hints.append("the scene has no tracer particles")
    else:
        pos = np.array(sensor.world_transform().matrix, dtype=np.float64).reshape(4, 4)[:3, 3]
        lo, hi = pts.min(axis=0), pts.max(axis=0)
        if np.all(pos >= lo) and np.all(pos <= hi):
            hints.append(f"the camera at {np.round(pos, 3).tolist()} mm is inside the particles' bounding box "
                         f"{np.round(lo, 3).tolist()}..{np.round(hi, 3).tolist()} mm: move it out")
        if cam is not None and hasattr(cam, "visible") and not np.any(cam.visible(pts)):
            hints.append(f"none of the {len(pts)} particles projects onto the sensor")
    pp = getattr(cam, "principal_point_px", None)
    if pp is not None and not on_sensor(np.asarray(pp, dtype=float), cam.resolution):
        hints.append(f"the principal point {tuple(round(v, 1) for v in pp)} px is outside the "
                     f"{cam.resolution[0]}x{cam.resolution[1]} image")
    if cam is not None and hasattr(cam, "image_centres_px") and not np.any(on_sensor(cam.image_centres_px(), cam.resolution)):
        hints.append(f"no microlens image lies on the sensor (mla_offset_um {list(cam.mla_offset_um)})")
    return hints


def _truth_info(xml_path: Path, params: dict) -> tuple[str | None, np.ndarray | None]:
    name = params.get("truth")
    cand = xml_path.parent / (name or "truth.npz")
    if cand.is_file():
        with np.load(cand) as z:
            times = z["times_s"] if "times_s" in z else None
        return str(cand.resolve()), times
    return None, None


def render_scene(scene, *, out_dir, frames=(0, 1), params=None, spp=None, seed=0, progress=None,
                 sensors=None, search_dirs=(), source_file=None) -> list[Path]:
    """Render every sensor of a scene XML for each frame.

    Writes ``{sensor_id}_frame{frame:03d}.exr`` (float32, metadata in the header) and a
    PNG preview beside it into ``out_dir``.

    Parameters
    ----------
    scene : path
        Scene XML file.
    out_dir : path
        Output folder (created).
    frames : sequence of int
        Frames to render (substituted for ``$frame``).
    params : dict, optional
        Further ``$name`` substitutions.
    spp : int, optional
        Samples per pixel for camera-tracing integrators (default: the scene's sampler);
        for the particle tracer, independent passes of ``rays_per_particle`` rays each
        (default one; a deterministic pinhole sensor always renders one). The metadata's
        ``spp`` is what was used, ``spp_requested`` what was asked.
    seed : int
        The experiment seed, in [0, 2**63). Each sensor and frame is rendered with its own
        32-bit seed ``mitpiv.streams.render_seed(seed, sensor_id, frame)``, so cameras and
        frames have independent Monte Carlo noise, and rendering a subset of the sensors
        leaves each one's image unchanged. The metadata keeps ``seed`` (the experiment
        seed) and ``render_seed`` (the derived one).
    progress : None, bool or callable
        One step per image (see :mod:`mitpiv.progress`).
    sensors : sequence of str, optional
        Ids of the sensors to render (default every sensor of the scene); an id the scene
        does not have is an error that lists the ids it has.
    search_dirs : sequence of path
        Further folders in which the scene's relative file names are looked up, after the
        scene file's own folder (:func:`~mitpiv.render.scene.load_scene`): an experiment
        renders a copy of its XML placed beside its particle files, and the files the XML
        names (a calibration) are found beside the original.
    source_file : path, optional
        The scene file the metadata's ``scene_file`` names (default ``scene``): an
        experiment renders a copy of its XML in a stage's temporary folder and records the
        XML it was given.

    Returns
    -------
    list of Path
        The EXR files written.

    Warns
    -----
    MitpivWarning
        An image rendered black (every pixel 0), with the likely reasons
        (:func:`black_image_hints`); they are also kept in its metadata's ``"warnings"``.
    """
    xml_path = Path(scene)
    out = Path(out_dir)
    params = dict(params or {})
    frames = [int(f) for f in frames]
    if not frames:
        raise ConfigError("render_scene: 'frames' must name at least one frame.")
    if "frame" in params:
        raise ConfigError(f"render_scene: params 'frame' = {params['frame']!r} (mitpiv render -D frame=...): $frame is "
                          f"set for each rendered frame from 'frames' ({frames}), so it would be ignored while the "
                          f"files' metadata name the frames rendered; give frames=[{params['frame']}] (mitpiv render "
                          f"--frames {params['frame']}) instead.")
    if spp is not None and (int(spp) != spp or spp < 1):
        raise ConfigError(f"render_scene: 'spp' must be a positive integer, got {spp!r}.")
    seed = check_seed(seed)
    if not xml_path.is_file():
        raise ConfigError(f"render_scene: scene file {str(xml_path)!r} does not exist.")
    # Load every frame first: a missing frame fails before anything is written.
    scenes = {f: load_scene(xml_path, frame=f, params=params, search_dirs=search_dirs) for f in frames}
    sha = hashlib.sha256(xml_path.read_bytes()).hexdigest()
    truth, times = _truth_info(xml_path, params)
    written = []
    ids = [s.id() or f"sensor{i}" for i, s in enumerate(next(iter(scenes.values())).sensors())]
    if sensors is not None:
        sensors = [str(s) for s in ([sensors] if isinstance(sensors, str) else sensors)]
        missing = [s for s in sensors if s not in ids]
        if missing or not sensors:
            raise ConfigError(f"render_scene: sensors={sensors!r}: {missing or 'none named'} not in the scene; "
                              f"its sensors are {ids}.")
    chosen = set(ids if sensors is None else sensors)
    total = len(chosen) * len(scenes)
    with bar(total, desc="render", progress=progress, unit="image") as pbar:
        for f, sc in scenes.items():
            laser = [e.describe() for e in sc.emitters() if hasattr(e, "irradiance_numpy")]
            particles = [sh.emitter().describe() for sh in sc.shapes()
                         if sh.emitter() is not None and hasattr(sh.emitter(), "particle_arrays")]
            for i, sensor in enumerate(sc.sensors()):
                sid = sensor.id() or f"sensor{i}"
                if sid not in chosen:
                    continue
                rseed = render_seed(seed, sid, f)
                t0 = time.perf_counter()
                arr = render_sensor(sc, sensor, spp=spp or 0, seed=rseed)
                dt = time.perf_counter() - t0
                camera = sensor_model(sensor)  # a plenoptic camera records irradiance, the others radiance
                meta = {
                    "mitpiv_version": __version__,
                    "mitsuba_version": mi.__version__,
                    "drjit_version": dr.__version__,
                    "variant": mi.variant(),
                    "scene_file": str(Path(source_file if source_file is not None else xml_path).resolve()),
                    "scene_sha256": sha,
                    "parameters": params,
                    "seed": seed,
                    "render_seed": rseed,
                    "spp": _spp_used(sc, sensor, spp),
                    "spp_requested": spp,
                    "integrator": _integrator_info(sc),
                    "sensor_id": sid,
                    "camera": camera,
                    "illumination": laser,
                    "particles": particles,
                    "frame": f,
                    "time_s": None if times is None or f >= len(times) else float(times[f]),
                    "units": {"length": "mm", "pixel_value": camera.get("pixel_value", PIXEL_UNITS)},
                    "truth_file": truth,
                    "render_seconds": dt,
                }
                if not np.any(arr > 0):  # a black image is never a result: say so, and why
                    hints = black_image_hints(sc, sensor)
                    meta["warnings"] = [f"black image (every pixel 0); {'; '.join(hints) or 'no reason found'}"]
                    warnings.warn(f"render: camera {sid!r} frame {f} rendered black (every pixel 0): "
                                  f"{'; '.join(hints) or 'no particle reaches its sensor'}.", MitpivWarning, stacklevel=2)
                path = out / f"{sid}_frame{f:03d}.exr"
                write_exr(path, arr, meta)
                write_preview(path.with_suffix(".png"), arr)
                written.append(path)
                _log.info("frame %d %s: %dx%d in %.2f s -> %s", f, sid, arr.shape[1], arr.shape[0], dt, path)
                pbar.update()
    index = out / "render.json"
    write_json(index, {"scene": str(xml_path), "frames": frames, "files": [str(p) for p in written]})
    return written
