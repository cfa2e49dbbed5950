"""Bring your own PIV: render a planar PIV image pair, export it, process it with another
code (here OpenPIV, as a stand-in for yours), and score that code's field against the
truth with mitpiv's own metrics.

    .venv/bin/python examples/score_openpiv.py            # 512 px images, ~30 s
    .venv/bin/python examples/score_openpiv.py --small    # 256 px (the test suite's run)

The same from the command line (any PIV code in the middle)::

    .venv/bin/mitpiv run scenes/planar/experiment.toml --out out/planar --until sensor
    .venv/bin/mitpiv export out/planar --tiff out/planar/tiff     # cam0_0000.tif, cam0_0001.tif
    ...  your PIV on the two TIFFs, its field saved as text (x y u v [flags mask], px) ...
    .venv/bin/mitpiv score out/planar field.txt --window 32

OpenPIV's multi-pass window deformation (``openpiv.windef``) is run twice: 64 -> 32 px and
64 -> 32 -> 16 px windows (50 % overlap), each field saved with ``openpiv.tools.save``.
The two are scored against the window-averaged truth of their final window (the vortex's
flow averaged over each window on the laser sheet's mid-plane, in the camera's pixels;
``reference_spread_px`` in score.json says how far the true particles inside the windows
scatter about it). Then the 16 px field is saved again after OpenPIV's ``transform_coordinates``
(y pointing up), which ``mitpiv score`` refuses and ``--flip-y`` scores.

Last, the run goes out as a LaVision DaVis set (``mitpiv export --davis``: images with
frame times, a calibration-plate set rendered through the same camera, the truth as a
particle field), and the 16 px field comes back as a calibrated DaVis vector field (the
OpenPIV vectors mapped onto the sheet plane in mm and m/s, written by LaVision's lvpyio),
scored from the ``.vc7`` like the text file.

Writes into out/examples/score_openpiv/: run/ (the rendered run), tiff/ (the exported
frames), field_32.txt, field_16.txt, score_32/ and score_16/ (score.json, score.md,
velocity_error.png; also docs/examples/score_openpiv.png), davis/ (the DaVis export),
field_16.vc7 and score_16_davis/.
"""

import argparse
import warnings
from pathlib import Path

import cv2
import numpy as np

from mitpiv.errors import MitpivWarning
from mitpiv.studies import run_experiment
from mitpiv.studies.export import export_images
from mitpiv.studies.score import ResultMismatch, score

cli = argparse.ArgumentParser(description="render a planar PIV pair, process it with OpenPIV, score it")
cli.add_argument("--small", action="store_true", help="256 px images instead of 512 px")
cli.add_argument("--out", default="out/examples/score_openpiv", help="output folder")
args = cli.parse_args()
out = Path(args.out)
root = Path(__file__).resolve().parents[1]

# 1. the images: the planar scene rendered and turned into 12-bit camera counts, nothing more
run = out / "run"
params = {"scene.params": {"resolution": 256}} if args.small else None
run_experiment(root / "scenes" / "planar" / "experiment.toml", run, overrides=params, until="sensor")
m = export_images(run, out / "tiff")
frame_a, frame_b = (cv2.imread(str(out / "tiff" / f), cv2.IMREAD_UNCHANGED).astype(np.float64)
                    for f in m["files"]["cam0"])
print(f"exported {m['files']['cam0']} ({m['bits']}-bit, gain {m['gain']:g}) -> {out / 'tiff'}")

# 2. another PIV code: OpenPIV's window-deformation multi-pass
from openpiv import tools, windef  # noqa: E402  (the user's tool, imported where it is used)


def openpiv_field(windows, path):
    s = windef.PIVSettings()
    s.windowsizes = tuple(windows)
    s.overlap = tuple(w // 2 for w in windows)
    s.num_iterations = len(windows)
    s.show_plot = s.save_plot = False
    s.deformation_method = "symmetric"
    s.replace_vectors = True
    x, y, u, v, flags = windef.simple_multipass(frame_a, frame_b, s)[:5]
    # simple_multipass returns the field after transform_coordinates (y up): undo it for the
    # image-coordinates file, as OpenPIV's own windef.piv() saves it before the transform
    x, y, u, v = tools.transform_coordinates(x, y, u, v)
    flags = np.asarray(flags if np.ndim(flags) else np.zeros_like(u), dtype=int)
    tools.save(path, x, y, np.ma.filled(u, np.nan), np.ma.filled(v, np.nan), flags)
    return x, y, u, v, flags


results, fields = {}, {}
for windows in ((64, 32), (64, 32, 16)):
    w = windows[-1]
    fields[w] = openpiv_field(windows, out / f"field_{w}.txt")
    results[w] = score(run, out / f"field_{w}.txt", window=w, out_dir=out / f"score_{w}")
    r = results[w]
    print(f"OpenPIV {' -> '.join(map(str, windows))} px: {r['n_scored']} vectors, RMS error "
          f"{r['rms_px'][0]:.3f} / {r['rms_px'][1]:.3f} px (x / y), bias {r['bias_px'][0]:+.3f} / "
          f"{r['bias_px'][1]:+.3f} px, {100 * r['error_outlier_fraction']:.1f} % above 1 px "
          f"(~{r['particles_per_window']:.0f} particles per window) -> {out / f'score_{w}' / 'score.md'}")

# 3. the same field with its y axis up (OpenPIV's transform_coordinates): refused, then scored
x, y, u, v, flags = fields[16]
x, y, u, v = tools.transform_coordinates(x.copy(), y.copy(), np.ma.filled(u, np.nan).copy(),
                                         np.ma.filled(v, np.nan).copy())
tools.save(out / "field_16_up.txt", x, y, u, v, flags)
try:
    score(run, out / "field_16_up.txt", window=16, out_dir=out / "score_16_up")
except ResultMismatch as e:
    print(f"refused: {str(e)[:160]}...")
with warnings.catch_warnings():
    warnings.simplefilter("ignore", MitpivWarning)
    up = score(run, out / "field_16_up.txt", window=16, out_dir=out / "score_16_up", flip_y=True)
print(f"with --flip-y: RMS error {up['rms_px'][0]:.3f} / {up['rms_px'][1]:.3f} px, as the y-down file")

# 4. DaVis: the run as a DaVis project's input (image set with frame times, a calibration-plate
# set rendered through the same camera, the truth as a particle field), and a DaVis vector
# field back: the 16 px field mapped onto the sheet (z = 0) in mm and m/s, as a calibrated
# planar DaVis result holds it, written by lvpyio and scored from the .vc7
from mitpiv.io import camera_from_metadata, read_exr  # noqa: E402
from mitpiv.io.davis import read_davis_images, write_davis_vectors  # noqa: E402
from mitpiv.studies.export_davis import export_davis  # noqa: E402

d = export_davis(run, out / "davis", n_planes=1 if args.small else 3, spp=1 if args.small else 4)
back = read_davis_images(out / "davis" / "Images.set")
print(f"DaVis set: {back['images'].shape[0]} camera x {back['images'].shape[1]} frames at "
      f"{', '.join(f'{t * 1e3:g} ms' for t in back['times_s'])}; calibration plate at "
      f"{d['calibration']['z_positions_mm']} mm -> {out / 'davis' / 'README.txt'}")
cam = camera_from_metadata(read_exr(run / "render" / "cam0_frame000.exr")[1])
xs, ys = fields[16][0][0], fields[16][1][:, 0]  # OpenPIV's window centres [px]: columns, rows
o, ray = cam.pixel_to_ray(np.stack(np.meshgrid(xs, ys), axis=-1))
world = o + ray * (-o[2] / ray[..., 2:3])  # the rays met with the sheet's plane z = 0
dt = m["times_s"][1] - m["times_s"][0]
end = cam.pixel_to_ray(np.stack(np.meshgrid(xs, ys), axis=-1)
                       + np.stack([np.ma.filled(fields[16][2], np.nan), np.ma.filled(fields[16][3], np.nan)], -1))[1]
world_b = o + end * (-o[2] / end[..., 2:3])
vel_m_s = (world_b - world)[..., :2] / dt * 1e-3
# DaVis's axes ascend: the rows' world y descends (the image's y points down), so flip them
write_davis_vectors(out / "field_16.vc7", world[0, :, 0], world[::-1, 0, 1], None, vel_m_s[::-1, :, 0],
                    vel_m_s[::-1, :, 1], length_unit="mm", velocity_unit="m/s", dt_s=dt)
win_mm = 16 * float(np.median(np.diff(world[0, :, 0]))) / 8  # 16 px at the grid's 8 px step
dv = score(run, out / "field_16.vc7", window=win_mm, plane_z_mm=0.0, out_dir=out / "score_16_davis")
print(f"DaVis .vc7 in mm and m/s: RMS error {dv['rms_px'][0]:.3f} / {dv['rms_px'][1]:.3f} px, as the text file")
