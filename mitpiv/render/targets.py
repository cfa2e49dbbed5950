"""Rendering calibration targets through a scene's own cameras.

A target is a rectangle with an area emitter whose radiance is the target's pattern (white
dots or white checkerboard squares of radiance ``radiance``, black elsewhere), so the
images go through exactly the camera model (distortion, thin lens, PSF) of the experiment.
"""

from __future__ import annotations

import logging

import mitsuba as mi
import numpy as np

from mitpiv.errors import ConfigError
from mitpiv.physics.targets import CalibrationTarget, markers_world
from mitpiv.progress import Progress, track
from mitpiv.render.render import render_sensor, sensor_model
from mitpiv.render.scene import load_dict
from mitpiv.render.variant import ensure_variant

__all__ = ["target_scene", "render_target_views", "save_target_views"]

log = logging.getLogger(__name__)


def target_scene(sensors, target: CalibrationTarget, pose, *, radiance: float = 1.0, texel_mm: float | None = None):
    """A Mitsuba scene holding ``sensors`` (objects or dicts) and the target at ``pose`` (4x4)."""
    ensure_variant()
    pose = np.asarray(pose, dtype=float)
    if pose.shape != (4, 4):
        raise ConfigError(f"target_scene: pose must be a 4x4 matrix, got shape {pose.shape}.")
    w, h = target.size_mm
    to_world = pose @ np.diag([w / 2, h / 2, 1.0, 1.0])
    tex = np.ascontiguousarray(target.texture(texel_mm)[:, :, None], dtype=np.float32)
    d = {
        "type": "scene",
        "integrator": {"type": "direct"},
        "target": {
            "type": "rectangle",
            "to_world": mi.ScalarTransform4f(to_world.tolist()),
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}},
            "emitter": {"type": "area", "radiance": {"type": "bitmap", "bitmap": mi.Bitmap(tex * radiance), "raw": True,
                                                     "filter_type": "bilinear", "wrap_mode": "clamp"}},
        },
    }
    for i, s in enumerate(sensors):
        d[f"sensor{i}"] = s
    return load_dict(d)  # mitpiv's: sensors that differ only in id stay distinct


def render_target_views(sensors, target: CalibrationTarget, poses, *, spp: int = 64, seed: int = 0,
                        progress: Progress = None) -> list[dict]:
    """Render the target at each pose through each sensor.

    Returns one dict per pose: ``{"pose": 4x4, "markers_world": (n, 3), "images": [(H, W)
    float32 per sensor]}`` -- the exact marker coordinates are the calibration truth.
    ``progress``: one step per pose (see :mod:`mitpiv.progress`).
    """
    if int(spp) != spp or spp < 1:
        raise ConfigError(f"render_target_views: 'spp' must be a positive integer, got {spp!r}.")
    sensors = list(sensors)
    if not sensors:
        raise ConfigError("render_target_views: give at least one sensor.")
    out = []
    poses = list(poses)
    for k, pose in enumerate(track(poses, desc="target views", progress=progress, unit="pose")):
        sc = target_scene(sensors, target, pose)
        # each camera and pose its own stream (render_seed(seed, sensor id, pose index))
        images = [render_sensor(sc, s, spp=int(spp), seed=seed, frame=k) for s in sc.sensors()]
        out.append({"pose": np.asarray(pose, dtype=float), "markers_world": markers_world(target, pose), "images": images})
        log.debug("target pose %d/%d rendered through %d camera(s)", k + 1, len(poses), len(images))
    return out


def save_target_views(views, out_dir, *, sensors, target: CalibrationTarget) -> list:
    """Write views as ``target_pose{k:02d}_{sensor_id}.exr`` (camera model, target and pose in
    the metadata) and ``target_truth.npz`` (``poses`` (n, 4, 4), ``markers_world`` (n, m, 3),
    ``sensor_ids``); returns the paths. Files are written atomically; a bad view (shape or
    non-finite pixels) is refused before anything is written.
    """
    from pathlib import Path

    from mitpiv.io.arrays import write_npz
    from mitpiv.io.exr import write_exr

    sensors = list(sensors)
    ids = [s.id() or f"sensor{i}" for i, s in enumerate(sensors)]
    for k, v in enumerate(views):
        if len(v["images"]) != len(sensors):
            raise ConfigError(f"save_target_views: view {k} has {len(v['images'])} images for {len(sensors)} sensors.")
        for img in v["images"]:
            if not np.all(np.isfinite(img)):
                raise ConfigError(f"save_target_views: view {k} has non-finite pixels; nothing written.")
    out = Path(out_dir)
    paths = []
    for k, v in enumerate(views):
        for sid, s, img in zip(ids, sensors, v["images"], strict=True):
            meta = {"kind": "calibration_target", "target": target.to_dict(), "pose": v["pose"].tolist(),
                    "sensor_id": sid, "camera": sensor_model(s), "units": {"length": "mm"}}
            paths.append(write_exr(out / f"target_pose{k:02d}_{sid}.exr", img, meta))
    truth = out / "target_truth.npz"
    write_npz(truth, {"poses": np.stack([v["pose"] for v in views]),
                      "markers_world": np.stack([v["markers_world"] for v in views]), "sensor_ids": np.array(ids)},
              compressed=False, owner="save_target_views")
    paths.append(truth)
    return paths
