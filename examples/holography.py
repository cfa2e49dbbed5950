"""Digital in-line holography: record the hologram of a few opaque droplets lit by a
collimated 532 nm laser, reconstruct it at several distances (angular spectrum), and find
the droplets in 3D (position and size) from the focal stack.

    .venv/bin/python examples/holography.py            # 16 droplets, 600 x 600 px sensor (~20 s)
    .venv/bin/python examples/holography.py --small    # 4 droplets, 256 x 256 px (a few seconds)

Writes holography.png: the hologram, the reconstruction at one droplet's depth, and the
detected against the true droplets.
"""

import argparse
from pathlib import Path

import matplotlib

matplotlib.use("Agg")  # write PNG files, no window
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from mitpiv import holography as ho  # noqa: E402
from mitpiv.analysis.backlit import evaluate_detections  # noqa: E402

cli = argparse.ArgumentParser(description="digital in-line holography of droplets")
cli.add_argument("--small", action="store_true", help="4 droplets on a 256 px sensor (the test suite's quick run)")
cli.add_argument("--out", default="out/examples/holography", help="output folder")
args = cli.parse_args()
out = Path(args.out)
out.mkdir(parents=True, exist_ok=True)

# Droplets of 50-120 um, 5-9 mm in front of the sensor (the sensor plane is z = 0, light
# travels along +z). Positions in mm, diameters in mm.
n_side, pixels = (2, 256) if args.small else (4, 600)
rng = np.random.default_rng(3)
half = 0.25 if args.small else 0.6
gx, gy = np.meshgrid(np.linspace(-half, half, n_side), np.linspace(-half, half, n_side))
pos = np.column_stack([gx.ravel(), gy.ravel(), -rng.uniform(5.0, 9.0, n_side**2)])
diam = rng.uniform(0.05, 0.12, n_side**2)

# The hologram: a plane wave through opaque disks, propagated plane by plane to a sensor
# of 3 um pixels (simulated 2x finer and integrated over each pixel).
h = ho.record(pos, diam, sensor_z_mm=0.0, pixel_um=3.0, resolution=(pixels, pixels), oversample=2)

# Reconstruct at distances 4..10 mm from the sensor and detect: minimum intensity over the
# stack for position and shape, edge sharpness for depth.
z = np.arange(4.0, 10.0, 0.05)
det = ho.detect(h, z)
ev = evaluate_detections(det, pos, diam, axis=(0, 0, 1))
print(f"{ev['n_found']} of {len(pos)} droplets found ({100 * ev['detected_fraction']:.0f} %); "
      f"depth RMS {ev['depth_rms_diameters']:.2f} diameters, size RMS {1e3 * ev['size_rms_mm']:.1f} um")

# One refocused plane, at the first droplet's distance from the sensor.
plane = ho.focal_stack(h, [-pos[0, 2]])[0]
ext = np.array([-1, 1, -1, 1]) * 0.5 * pixels * 3e-3  # sensor extent [mm]
fig, ax = plt.subplots(1, 3, figsize=(14, 4.4), constrained_layout=True)
ax[0].imshow(h.image, cmap="gray", extent=ext, origin="lower")
ax[0].set_title("hologram (sensor intensity)")
ax[1].imshow(plane, cmap="gray", extent=ext, origin="lower")
ax[1].set_title(f"amplitude refocused at {-pos[0, 2]:.2f} mm")
for a in ax[:2]:
    a.set_xlabel("x [mm]")
    a.set_ylabel("y [mm]")
ax[2].scatter(pos[:, 0], -pos[:, 2], s=(diam * 400) ** 2 / 10, facecolors="none", edgecolors="k", label="true")
if len(det):
    ax[2].scatter(det.positions_mm[:, 0], -det.positions_mm[:, 2], s=(det.diameters_mm * 400) ** 2 / 10,
                  c="C3", alpha=0.5, label="detected")
ax[2].set_xlabel("x [mm]")
ax[2].set_ylabel("distance from the sensor [mm]")
ax[2].set_title("droplets: marker area ~ diameter$^2$")
ax[2].legend(fontsize=8)
fig.savefig(out / "holography.png", dpi=100)
print(f"-> {out / 'holography.png'}")
