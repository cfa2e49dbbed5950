"""Rendered multi-camera scenes for the reconstruction tests (small, fast).

Pinhole cameras (85 mm, 10 um pixels, 128 px) 500 mm from the origin in the pyramid of
scenes/tomo4 (elevation 55 deg above the sheet, azimuth +-25 and 180 -+ 25 deg), a thick
top-hat sheet and isotropic particles of one size, so every camera sees every particle
with the same intensity. Particle images are diffraction limited (PSF ``jitter``, f/16,
working f/19: Airy diameter 2.5 px).
"""

import math

import mitsuba as mi
import numpy as np

from mitpiv.io import write_particles_ply
from mitpiv.physics.camera import PinholeCamera, planar_array, scatter_arrangement
from mitpiv.physics.distortion import Distortion, percent_to_k1
from mitpiv.reconstruct import VoxelGrid
from mitpiv.render.render import render_sensor
from mitpiv.render.scene import load_dict

RES = 128
HALF = np.array([2.5, 2.5, 1.0])  # particle box half-size [mm]
GRID = VoxelGrid.from_bounds(-HALF, HALF, 0.05)  # 1 voxel per pixel (object pixel 0.049 mm)


def cameras(n=4, res=RES, distortion_percent=0.0, distance=500.0, array=None):
    """The tomographic pyramid (first n of 4), or with ``array=(rows, cols)`` a planar
    synthetic-aperture array (150 mm pitch) looking down the sheet normal."""
    if array is None:
        arr = scatter_arrangement("symmetric", n=4, azimuth_deg=25, elevation_deg=55, distance_mm=distance)[:n]
    else:
        arr = planar_array(*array, spacing_mm=150.0, distance_mm=distance)
    cams = []
    for a in arr:
        f, pitch = 85.0, 10.0
        r_max = math.hypot(res / 2, res / 2) * pitch * 1e-3 / f
        d = Distortion(k1=percent_to_k1(distortion_percent, r_max=r_max)) if distortion_percent else Distortion()
        cams.append(PinholeCamera((res, res), f, pitch, rotation=a["rotation"], position_mm=a["position_mm"], distortion=d))
    return cams


def particles(ppp, seed=0, res=RES):
    rng = np.random.default_rng(seed)
    return rng.uniform(-HALF * 0.9, HALF * 0.9, (int(round(ppp * res * res)), 3))


def render_views(tmp_path, pts, cams, *, rays=4000, psf=True, name="p.ply"):
    """One image per camera (float64), particle tracing."""
    write_particles_ply(tmp_path / name, np.asarray(pts, float), 2.0, proxy_radius_mm=0.005)
    d = {"type": "scene", "integrator": {"type": "particle_tracer", "rays_per_particle": rays},
         "laser": {"type": "laser_sheet", "id": "laser", "thickness": 400.0, "origin": mi.ScalarPoint3f(0, 0, 0)},
         "particles": {"type": "ellipsoidsmesh", "filename": str(tmp_path / name), "extent": 1.0,
                       "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}},
                       "emitter": {"type": "tracer_particles", "sheet": {"type": "ref", "id": "laser"}}}}
    for i, c in enumerate(cams):
        s = {"type": "distorted_pinhole", "to_world": mi.ScalarTransform4f(c.to_world_mitsuba()),
             "focal_length_mm": c.focal_length_mm, "pixel_pitch_um": c.pixel_pitch_um,
             "film": {"type": "hdrfilm", "width": c.resolution[0], "height": c.resolution[1],
                      "pixel_format": "luminance", "rfilter": {"type": "box"}}}
        if c.distortion.k1:
            s["k1"] = c.distortion.k1
        if psf:
            s.update({"psf": "jitter", "psf_f_number": 16.0, "psf_magnification": 0.2})
        d[f"cam{i}"] = s
    sc = load_dict(d)
    return [render_sensor(sc, s).astype(np.float64) for s in sc.sensors()]
