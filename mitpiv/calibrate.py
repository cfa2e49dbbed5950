"""Camera calibrations that render their own targets: :func:`calibrate_dewarp`, the dot-card
calibration of a plenoptic camera's dewarp polynomial (a card rendered at several depths,
decoded and refocused, its dots detected and labelled, (u, v, z_stack) -> world fitted).

It needs the renderer (:mod:`mitpiv.render`), the light-field decoder
(:mod:`mitpiv.lightfield`), the dot detection of :mod:`mitpiv.reconstruct.calibration` and
the fit of :mod:`mitpiv.analysis.backlit`, so it sits above all of them, beside the
experiment engine: a script calibrates a camera without importing :mod:`mitpiv.studies`
(whose backlit kind calls it in its calibrate stage).
"""

from __future__ import annotations

import logging

import numpy as np

from mitpiv.progress import Progress, track

__all__ = ["calibrate_dewarp"]

log = logging.getLogger(__name__)


def calibrate_dewarp(sensor: dict, depths_mm, *, target=None, spp: int = 32, white=None, degree_xy: int = 3,
                     degree_z: int = 2, seed: int = 0, progress: Progress = None):
    """Fit a :class:`~mitpiv.analysis.backlit.Dewarp` for a plenoptic ``sensor`` (dict): a dot
    card (default 7x7 dots, 1/18 of the field of view wide at 1/9 spacing) is rendered facing the camera at each
    world depth offset in ``depths_mm`` (along the optical axis from the focal plane), the
    raw image decoded and refocused onto the card's depth, the dots detected and labelled,
    and (u_px, v_px, z_stack) -> world (x, y, z) fitted. Returns (dewarp, observations).
    ``seed``: the experiment seed (each card render takes its own stream);
    ``progress``: one step per depth (see :mod:`mitpiv.progress`).
    """
    from mitpiv.analysis.backlit import fit_dewarp
    from mitpiv.lightfield import decode, refocus
    from mitpiv.lightfield.geometry import alpha_from_z
    from mitpiv.lightfield.refocus import stack_depth, stack_pixels
    from mitpiv.physics.targets import CalibrationTarget, markers_world
    from mitpiv.reconstruct.calibration import detect_dots, label_markers
    from mitpiv.render.render import render_sensor
    from mitpiv.render.targets import target_scene
    from mitpiv.render.variant import ensure_variant
    from mitpiv.streams import derived_seed

    depths = np.asarray(depths_mm, dtype=np.float64).reshape(-1)
    ensure_variant()
    import mitsuba as mi

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
        raw = render_sensor(sc, sc.sensors()[0], spp=spp, seed=derived_seed(seed, "calibration", "dewarp_card", k, bits=32))
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
