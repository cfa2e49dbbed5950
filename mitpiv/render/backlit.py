"""Backlit scenes: opaque spheres (droplets, pellets) in front of a diffuse backlight, rendered
by camera tracing through Mitsuba's ``direct`` integrator (any sensor: plenoptic, pinhole),
and the polynomial dewarping of refocused plenoptic images from a dot card imaged at
several depths.
"""

from __future__ import annotations

import logging

import mitsuba as mi
import numpy as np

from mitpiv.errors import ConfigError, check_positive
from mitpiv.progress import Progress, track
from mitpiv.render.render import render_sensor
from mitpiv.render.variant import ensure_variant

__all__ = ["backlit_scene", "render_backlit", "calibrate_dewarp", "stack_depth", "stack_pixels"]

log = logging.getLogger(__name__)


def backlit_scene(sensor, positions_mm, diameters_mm, *, backlight_mm: float = 30.0, backlight_size_mm: float = 100.0,
                  radiance: float = 1.0):
    """Scene: ``sensor`` (dict or object), one black opaque sphere per particle, and a
    Lambertian backlight square of side ``backlight_size_mm`` a distance ``backlight_mm``
    behind the origin, facing the camera along the camera's optical axis."""
    ensure_variant()
    p = np.asarray(positions_mm, dtype=np.float64).reshape(-1, 3)
    d = np.broadcast_to(np.asarray(diameters_mm, dtype=np.float64), (p.shape[0],))
    if p.shape[0] and (not np.all(np.isfinite(p)) or not np.all(d > 0)):
        raise ConfigError("backlit_scene: positions must be finite and diameters_mm > 0.")
    check_positive("backlight_mm", backlight_mm, owner="backlit_scene", unit="mm")
    check_positive("backlight_size_mm", backlight_size_mm, owner="backlit_scene", unit="mm")
    m = sensor["to_world"].matrix if isinstance(sensor, dict) else sensor.world_transform().matrix
    fwd = np.array([float(m[i][2]) for i in range(3)])
    up = np.array([float(m[i][1]) for i in range(3)])
    centre = backlight_mm * fwd  # behind the origin as seen from the camera
    light = mi.ScalarTransform4f().look_at(origin=mi.ScalarPoint3f(*centre.tolist()),
                                           target=mi.ScalarPoint3f(*(centre - fwd).tolist()), up=mi.ScalarVector3f(*up.tolist()))
    black = {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}}
    scene = {"type": "scene", "integrator": {"type": "direct"}, "sensor": sensor,
             "light": {"type": "rectangle", "to_world": light @ mi.ScalarTransform4f().scale([backlight_size_mm / 2] * 2 + [1]),
                       "bsdf": black, "emitter": {"type": "area", "radiance": {"type": "rgb", "value": float(radiance)}}}}
    for i, (c, di) in enumerate(zip(p, d, strict=True)):
        scene[f"particle{i}"] = {"type": "sphere", "center": mi.ScalarPoint3f(*map(float, c)), "radius": float(di) / 2,
                                 "bsdf": black}
    return mi.load_dict(scene)


def render_backlit(sensor, positions_mm, diameters_mm, *, spp: int = 16, seed: int = 0, **kwargs) -> np.ndarray:
    """Render a backlit scene (see :func:`backlit_scene`); returns (H, W) float32 radiance."""
    sc = backlit_scene(sensor, positions_mm, diameters_mm, **kwargs)
    return render_sensor(sc, sc.sensors()[0], spp=int(spp), seed=seed)


def stack_depth(camera, points_world) -> np.ndarray:
    """Depth from the focal plane (+ farther, the focal-stack convention) of world points."""
    return camera.world_to_local(points_world)[..., 2] - camera.focus_distance_mm


def stack_pixels(lf, u_index, v_index):
    """Refocused-image indices (column, row; pixel centres at integers) -> sensor pixels of
    the lenslet lattice, the coordinates a :class:`Dewarp` is fitted in."""
    from mitpiv.lightfield.refocus import grid_steps

    ds, dt = grid_steps(lf)
    return lf.s_px[0] + np.asarray(u_index) * ds, lf.t_px[0] + np.asarray(v_index) * dt


def calibrate_dewarp(sensor: dict, depths_mm, *, target=None, spp: int = 32, white=None, degree_xy: int = 3,
                     degree_z: int = 2, progress: Progress = None):
    """Fit a :class:`~mitpiv.analysis.backlit.Dewarp` for a plenoptic ``sensor`` (dict): a dot
    card (default 7x7 dots, 1/18 of the field of view wide at 1/9 spacing) is rendered facing the camera at each
    world depth offset in ``depths_mm`` (along the optical axis from the focal plane), the
    raw image decoded and refocused onto the card's depth, the dots detected and labelled,
    and (u_px, v_px, z_stack) -> world (x, y, z) fitted. Returns (dewarp, observations).
    ``progress``: one step per depth (see :mod:`mitpiv.progress`).
    """
    from mitpiv.analysis.backlit import fit_dewarp
    from mitpiv.lightfield import decode, refocus
    from mitpiv.lightfield.geometry import alpha_from_z
    from mitpiv.physics.targets import CalibrationTarget, markers_world
    from mitpiv.reconstruct.calibration import detect_dots, label_markers
    from mitpiv.render.targets import target_scene

    depths = np.asarray(depths_mm, dtype=np.float64).reshape(-1)
    ensure_variant()
    probe = mi.load_dict({"type": "scene", "sensor": sensor})
    s = probe.sensors()[0]
    cam = s.camera
    m = np.array(sensor["to_world"].matrix, dtype=np.float64).reshape(4, 4)
    fwd, up, org = m[:3, 2], m[:3, 1], m[:3, 3]
    fov_mm = cam.resolution[0] * cam.pixel_pitch_um * 1e-3 / cam.magnification
    if target is None:
        target = CalibrationTarget("dots", 7, 7, fov_mm / 9.0, dot_diameter_mm=fov_mm / 18.0)
    if white is None:
        ws = mi.load_dict({"type": "scene", "integrator": {"type": "direct"}, "sensor": sensor, "env": {"type": "constant"}})
        white = render_sensor(ws, ws.sensors()[0], spp=spp)
    uvz, xyz = [], []
    for k, dz in enumerate(track(depths, desc="dewarp depths", progress=progress, unit="card")):
        centre = org + (cam.focus_distance_mm + dz) * fwd
        # the card's normal (local +z, its emitting side) faces the camera
        pose = np.array(mi.ScalarTransform4f().look_at(origin=mi.ScalarPoint3f(*centre.tolist()),
                                                        target=mi.ScalarPoint3f(*(centre - fwd).tolist()),
                                                        up=mi.ScalarVector3f(*up.tolist())).matrix, dtype=np.float64)
        sc = target_scene([sensor], target, pose)
        raw = render_sensor(sc, sc.sensors()[0], spp=spp, seed=k)
        lf = decode(raw, optics=cam, white=white)
        world = markers_world(target, pose)
        zs = float(np.mean(stack_depth(cam, world)))
        img = refocus(lf, float(alpha_from_z(zs, focal_length_mm=cam.focal_length_mm, magnification=cam.magnification)))
        # clean renders: half the dot contrast (the default noise floor assumes a noisy image)
        det = detect_dots(img, threshold=0.5 * float(np.percentile(img, 99.9) - np.median(img))) - 0.5  # indices
        det_px = np.column_stack(stack_pixels(lf, det[:, 0], det[:, 1]))
        mi_, di_ = label_markers(det_px, cam.project(world))
        uvz.append(np.column_stack([det_px[di_], np.full(mi_.size, zs)]))
        xyz.append(world[mi_])
        log.debug("dewarp card %d/%d: z %+.2f mm, %d/%d dots", k + 1, depths.size, dz, mi_.size, len(world))
    uvz, xyz = np.vstack(uvz), np.vstack(xyz)
    return fit_dewarp(uvz, xyz, degree_xy=degree_xy, degree_z=degree_z), {"uvz": uvz, "xyz": xyz, "white": white}
