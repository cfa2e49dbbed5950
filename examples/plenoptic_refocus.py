"""A plenoptic (light-field) camera: render the raw image of three particles at different
depths through a microlens array, decode it into a 4D light field, and refocus it onto
each particle's depth (synthetic refocusing: one exposure, any focal plane afterwards).

    .venv/bin/python examples/plenoptic_refocus.py            # 400 x 400 px raw image (~20 s)
    .venv/bin/python examples/plenoptic_refocus.py --small    # 200 x 200 px

Writes plenoptic_refocus.png: the raw image (one small disk image per lenslet) and the
refocused images at the three particle depths, each particle sharp in its own plane.
"""

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # write PNG files, no window
import matplotlib.pyplot as plt  # noqa: E402
import mitsuba as mi  # noqa: E402
import numpy as np  # noqa: E402

import mitpiv  # noqa: E402
from mitpiv import lightfield as lfm  # noqa: E402
from mitpiv.io import write_particles_ply  # noqa: E402
from mitpiv.render.scene import load_dict  # noqa: E402

cli = argparse.ArgumentParser(description="render a plenoptic image and refocus it")
cli.add_argument("--small", action="store_true", help="200 px raw image (the test suite's quick run)")
cli.add_argument("--out", default="out/examples/plenoptic_refocus", help="output folder")
args = cli.parse_args()
out = Path(args.out)
out.mkdir(parents=True, exist_ok=True)
mitpiv.set_variant()  # cuda_ad_mono with a GPU, else llvm_ad_mono
res = 200 if args.small else 400

# Three particles (x, y, z) [mm]; the camera looks down -z from z = 250 mm and is focused on
# z = 0, so their depths are 6 mm behind, in and 6 mm in front of the focal plane.
depths = np.array([-6.0, 0.0, 6.0])
pts = np.column_stack([[-0.8, 0.0, 0.8], [0.5, -0.5, 0.4], depths])
write_particles_ply(out / "particles.ply", pts, 2.0, proxy_radius_mm=0.01)  # 2 um droplets

# The plenoptic sensor: 5.5 um pixels behind 55 um lenslets (10 pixels per lenslet), a 50 mm
# f/2.8 main lens focused at 250 mm (magnification 0.25).
sensor = {"type": "plenoptic", "pixel_pitch_um": 5.5, "focal_length_mm": 50.0, "f_number": 2.8,
          "focus_distance_mm": 250.0, "mla_pitch_um": 55.0,
          "to_world": mi.ScalarTransform4f().look_at(origin=[0, 0, 250], target=[0, 0, 0], up=[0, 1, 0]),
          "film": {"type": "hdrfilm", "width": res, "height": res, "pixel_format": "luminance",
                   "rfilter": {"type": "box"}}}
scene = load_dict({
    "type": "scene", "sensor": sensor,
    "integrator": {"type": "particle_tracer", "rays_per_particle": 100_000},  # light traced from the particles
    "laser": {"type": "laser_sheet", "id": "laser", "thickness": 400.0, "origin": mi.ScalarPoint3f(0, 0, 0)},
    "particles": {"type": "ellipsoidsmesh", "filename": str(out / "particles.ply"), "extent": 1.0,
                  "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": 0.0}},
                  "emitter": {"type": "tracer_particles", "sheet": {"type": "ref", "id": "laser"}}}})
raw = np.array(mi.render(scene, spp=0, seed=0))[..., 0]

# Decode: the camera's optics (from the sensor) place every lenslet; a real camera would
# use lfm.calibrate_mla(white_image) instead.
camera = scene.sensors()[0].camera
lf = lfm.decode(raw, optics=camera)
near, far = camera.depth_of_field()
print(f"light field {lf.data.shape} (views x views x lenslets x lenslets); depth of field of a refocused image "
      f"{near:+.1f} .. {far:+.1f} mm, depth resolution {camera.depth_resolution():.2f} mm")

# Refocus: z is the distance beyond the focal plane (positive = farther from the camera, i.e.
# world -z here). Multiplicative refocusing keeps only light all views agree on.
stack = lfm.focal_stack(lf, -depths, method="multiplicative")
zs = np.linspace(-10, 10, 41)
scan = lfm.focal_stack(lf, zs, method="multiplicative").reshape(len(zs), -1).max(axis=1)

def centre(img, half):
    """The central (2 half) x (2 half) pixels of an image (the particles sit near the axis)."""
    r, c = img.shape[0] // 2, img.shape[1] // 2
    return img[r - half:r + half, c - half:c + half]


fig, ax = plt.subplots(1, 5, figsize=(17, 3.6), constrained_layout=True)
ax[0].imshow(centre(raw, 60), cmap="gray", vmax=np.percentile(raw, 99.9))
ax[0].set_title("raw plenoptic image (centre)")
ax[0].set_xlabel("pixel")
ax[0].set_ylabel("pixel")
for k, z in enumerate(depths):
    ax[k + 1].imshow(centre(stack[k], 7), cmap="gray", origin="upper")
    ax[k + 1].set_title(f"refocused at world z = {z:+.0f} mm")
    ax[k + 1].set_xlabel("lenslet")
ax[4].plot(-zs, scan / scan.max(), "k")
for z in depths:
    ax[4].axvline(z, color="C3", lw=0.8)
ax[4].set_xlabel("refocus plane: world z [mm]")
ax[4].set_ylabel("brightest refocused pixel (normalised)")
ax[4].set_title("focal-stack scan; red: true depths")
fig.savefig(out / "plenoptic_refocus.png", dpi=90)
print(f"-> {out / 'plenoptic_refocus.png'}")
