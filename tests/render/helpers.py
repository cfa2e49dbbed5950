"""Small scenes for rendering tests, built as dictionaries."""

import mitsuba as mi
import numpy as np

from mitpiv.io import write_particles_ply
from mitpiv.physics.camera import PinholeCamera, look_at_rotation
from mitpiv.render.scene import load_dict


def camera(res=(48, 48), offset=(0.0, 0.0, 0.0), **kw):
    pos = np.array([0.0, 0.0, 500.0]) + offset
    rot = look_at_rotation(pos, np.asarray(offset, float), up=[0, 1, 0])
    return PinholeCamera(res, 85.0, 10.0, rotation=rot, position_mm=pos, **kw)


def scene(tmp_path, positions, *, cam=None, sensor="distorted_pinhole", sensor_props=None, integrator=None,
          rfilter=None, proxy=0.01, diameters=2.0, sheet=None, name="p.ply"):
    cam = cam or camera()
    write_particles_ply(tmp_path / name, np.asarray(positions, float), diameters, proxy_radius_mm=proxy)
    s = {"type": sensor, "to_world": mi.ScalarTransform4f(cam.to_world_mitsuba()),
         "film": {"type": "hdrfilm", "width": cam.resolution[0], "height": cam.resolution[1],
                  "pixel_format": "luminance", "rfilter": rfilter or {"type": "box"}}}
    if sensor == "perspective":
        s["fov"] = float(np.degrees(2 * np.arctan(cam.resolution[0] / 2 / cam.focal_px)))
        s["near_clip"], s["far_clip"] = 0.01, 1e7
    else:
        s["focal_length_mm"], s["pixel_pitch_um"] = cam.focal_length_mm, cam.pixel_pitch_um
    s.update(sensor_props or {})
    laser = {"type": "laser_sheet", "id": "laser", "thickness": 4.0,
             "origin": mi.ScalarPoint3f(*[float(v) for v in cam.position_mm - [0, 0, 500]])}
    laser.update(sheet or {})
    return load_dict({
        "type": "scene", "integrator": integrator or {"type": "particle_tracer"}, "sensor": s, "laser": laser,
        "particles": {"type": "ellipsoidsmesh", "filename": str(tmp_path / name), "extent": 1.0,
                      "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}},
                      "emitter": {"type": "tracer_particles", "sheet": {"type": "ref", "id": "laser"}}},
    })


def render(sc, spp=1, seed=0):
    return np.array(mi.render(sc, spp=spp, seed=seed), dtype=np.float64)[..., 0]


def window_stats(img, uv, half=4):
    """Sum and centroid of the image in a window around each projected position."""
    h, w = img.shape
    yy, xx = np.mgrid[0:h, 0:w] + 0.5
    out = []
    for u, v in uv:
        m = (np.abs(xx - u) <= half) & (np.abs(yy - v) <= half)
        s = img[m].sum()
        out.append((s, (img * xx)[m].sum() / s, (img * yy)[m].sum() / s))
    return np.array(out)


def sensor_xml(sid: str, az: float, *, lens: str = "", res: int = 24, rfilter: str | None = None) -> str:
    """XML of a ``distorted_pinhole`` at azimuth ``az``, elevation 50 deg, 600 mm from the
    origin (85 mm lens, 20 um pixels, ``res`` x ``res``); ``lens``: extra property lines;
    ``rfilter``: the film's reconstruction filter (None: Mitsuba's default)."""
    rf = "" if rfilter is None else f'\n            <rfilter type="{rfilter}"/>'
    return f"""    <sensor type="distorted_pinhole" id="{sid}">
        <float name="azimuth_deg" value="{az}"/>
        <float name="elevation_deg" value="50"/>
        <float name="distance_mm" value="600"/>
        <float name="focal_length_mm" value="85"/>
        <float name="pixel_pitch_um" value="20"/>
        {lens}
        <film type="hdrfilm">
            <integer name="width" value="{res}"/>
            <integer name="height" value="{res}"/>
            <string name="pixel_format" value="luminance"/>{rf}
        </film>
    </sensor>
"""


def particle_scene_xml(sensors: str, *, integrator: str = '<integrator type="particle_tracer"/>',
                       laser: str = '<float name="thickness" value="3"/>', defaults: str = "") -> str:
    """A scene XML of tracer particles (``particles_$frame.ply`` beside it) in a 3 mm laser
    sheet, traced by ``integrator``, seen by the ``sensors`` XML."""
    return f"""<scene version="3.0.0">
    <default name="frame" value="0"/>{defaults}
    {integrator}
    <emitter type="laser_sheet" id="laser">{laser}</emitter>
    <shape type="ellipsoidsmesh">
        <string name="filename" value="particles_$frame.ply"/>
        <float name="extent" value="1"/>
        <bsdf type="diffuse"><rgb name="reflectance" value="0"/></bsdf>
        <emitter type="tracer_particles"><ref name="sheet" id="laser"/></emitter>
    </shape>
{sensors}</scene>
"""
