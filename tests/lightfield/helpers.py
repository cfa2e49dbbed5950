"""Small plenoptic scenes for tests."""

import math

import mitsuba as mi
import numpy as np

from mitpiv.io import write_particles_ply
from mitpiv.physics.sheet import sheet_profile
from mitpiv.render.scene import load_dict

# 5.5 um pixels, 50 mm f/2.8 focused at 250 mm (|M| = 0.25, s_i = 62.5 mm, image-side f/3.5)
BASE = {"pixel_pitch_um": 5.5, "focal_length_mm": 50.0, "f_number": 2.8, "focus_distance_mm": 250.0, "mla_pitch_um": 55.0}
DIST = 250.0  # camera on +z looking at the origin


def sensor(res=200, **props):
    s = {"type": "plenoptic", **BASE,
         "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, DIST], target=[0, 0, 0], up=[0, 1, 0]),
         "film": {"type": "hdrfilm", "width": res, "height": res, "pixel_format": "luminance", "rfilter": {"type": "box"}}}
    s.update(props)
    return s


def particle_scene(tmp_path, pts, integrator, res=200, name="p.ply", **props):
    write_particles_ply(tmp_path / name, np.asarray(pts, float), 2.0, proxy_radius_mm=0.01)
    return load_dict({
        "type": "scene", "integrator": integrator, "sensor": sensor(res, **props),
        "laser": {"type": "laser_sheet", "id": "laser", "thickness": 400.0, "origin": mi.ScalarPoint3f(0, 0, 0)},
        "particles": {"type": "ellipsoidsmesh", "filename": str(tmp_path / name), "extent": 1.0,
                      "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}},
                      "emitter": {"type": "tracer_particles", "sheet": {"type": "ref", "id": "laser"}}},
    })


def white_scene(res=200, **props):
    return load_dict({"type": "scene", "integrator": {"type": "direct"}, "sensor": sensor(res, **props),
                      "env": {"type": "constant"}})


def intensity(pts, d_um=2.0, thickness=400.0, q=2.0):
    """Closed-form intensity [W/sr] of isotropic particles in the sheet (as in tests/render)."""
    e = sheet_profile(np.asarray(pts)[:, 2], thickness)
    return e * q * math.pi / 4 * (d_um * 1e-3) ** 2 / (4 * math.pi)


def render(sc, spp=0, seed=0):
    return np.array(mi.render(sc, spp=spp, seed=seed), dtype=np.float64)[..., 0]
