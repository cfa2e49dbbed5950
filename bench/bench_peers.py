"""Other trackers on mitpiv's images (issue 27, item 6): OpenLPT's Shake-The-Box and
OpenPTV's correspondences, against mitpiv's own STB, on one synthetic sequence.

The sequence: particles in uniform translation (a box of 20 x 20 x 10 mm, 0.3 mm per
frame, about 3 px), imaged by four 512 x 512 px cameras (10 um pixels, f = 50 mm, 530 mm
away, +-17 deg off the z axis) as diffraction-limited point images (f/16, about 2.4 px across,
:func:`mitpiv.imaging.splat_points`), no noise. The frames are exported with
:func:`mitpiv.io.openlpt.export_openlpt` and :func:`mitpiv.io.openptv.export_openptv`
exactly as ``mitpiv export RUN --openlpt/--openptv`` would write a rendered run's frames.

- OpenLPT (``pip install --no-deps openlpt``): its STB runs on the export
  (:func:`mitpiv.tracking.peers.run_openlpt`); its long tracks, regularised by mitpiv's
  :func:`~mitpiv.tracking.stb.regularise`, are scored by :func:`mitpiv.tracking.metrics.track_metrics`.
- mitpiv STB on the same float images (OTF calibrated on frame 0's true positions).
- OpenPTV (``pip install optv``): liboptv's target recognition, correspondences and
  point positions on frame 0 of the export, read with optv's own parameter and
  orientation readers; scored with :func:`mitpiv.tracking.metrics.particle_metrics`.

``python bench/bench_peers.py [--particles 200] [--frames 10] [--distortion [--undistort]] [--out DIR]``
(about 30 s for the defaults on 2 cores). Prints one row per method.
"""

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from mitpiv.imaging import PointPSFTable, splat_points  # noqa: E402
from mitpiv.io.openlpt import OpenLPTSettings, export_openlpt  # noqa: E402
from mitpiv.io.openptv import export_openptv  # noqa: E402
from mitpiv.physics.camera import PinholeCamera, look_at_rotation  # noqa: E402
from mitpiv.physics.distortion import Distortion  # noqa: E402
from mitpiv.tracking.metrics import particle_metrics, track_metrics  # noqa: E402

LOWER, UPPER = np.array([-10.0, -10.0, -5.0]), np.array([10.0, 10.0, 5.0])
VELOCITY_MM_FRAME = np.array([0.3, 0.1, -0.05])
DT_S = 1e-3
#: Match radius [mm]: about 1 px in object space (0.09 mm/px).
RADIUS_MM = 0.1


def cameras(distortion=Distortion()):
    out = []
    for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1)):
        pos = np.array([150.0 * sx, 150.0 * sy, 500.0])
        rot = look_at_rotation(pos, np.zeros(3), up=(0.0, 1.0, 0.0))
        out.append(PinholeCamera((512, 512), 50.0, 10.0, rotation=rot, position_mm=pos, distortion=distortion))
    return out


def sequence(n, n_frames, cams, seed=1):
    rng = np.random.default_rng(seed)
    p0 = rng.uniform(LOWER + 1.5, UPPER - 1.5, (n, 3))
    truth = p0[:, None, :] + VELOCITY_MM_FRAME * np.arange(n_frames)[None, :, None]
    table = PointPSFTable.build(f_number=16, pixel_pitch_um=10, magnification=0.11, window=5)
    images = [[splat_points(c.project(truth[:, f]), c.resolution, table).astype(np.float64) for f in range(n_frames)]
              for c in cams]
    return truth, images


def summary(name, m, wall):
    keys = ("yield", "ghost_fraction", "position_error_mm", "position_error_px", "velocity_error_rel",
            "correct_track_fraction")
    row = {"method": name, **{k: m.get(k) for k in keys}, "wall_s": wall}
    print(f"{name:12s} " + " ".join(f"{k}={v:.4g}" for k, v in row.items() if isinstance(v, float)))
    return row


def run_openlpt(folder, truth, images, cams, undistort=False):
    from mitpiv.tracking.peers import run_openlpt as run

    export_openlpt(folder, images, cams, lower_mm=LOWER, upper_mm=UPPER, frame_rate_hz=1 / DT_S, voxel_mm=0.02,
                   settings=OpenLPTSettings(search_radius_vox=30, tolerance_3d_vox=2.5, neighbour_spacing_vox=150,
                                            pred_search_vox=40), undistort=undistort)
    tracks, wall = run(folder)
    v = np.broadcast_to(VELOCITY_MM_FRAME / DT_S, truth.shape)
    m = track_metrics(tracks, truth, radius_mm=RADIUS_MM, truth_velocities_mm_s=v, cameras=cams)
    return summary("openlpt-stb", m, wall)


def run_mitpiv(truth, images, cams):
    from mitpiv.tracking import calibrate_otf
    from mitpiv.tracking.stb import stb

    t0 = time.perf_counter()
    otf = calibrate_otf([im[0] for im in images], cams, truth[:, 0], lower_mm=LOWER, upper_mm=UPPER)
    seq = [[im[f] for im in images] for f in range(truth.shape[1])]
    tracks = stb(seq, cams, otf, dt_s=DT_S, lower_mm=LOWER, upper_mm=UPPER, velocity_guess=VELOCITY_MM_FRAME / DT_S)
    wall = time.perf_counter() - t0
    v = np.broadcast_to(VELOCITY_MM_FRAME / DT_S, truth.shape)
    m = track_metrics(tracks, truth, radius_mm=RADIUS_MM, truth_velocities_mm_s=v, cameras=cams)
    return summary("mitpiv-stb", m, wall)


def run_openptv(folder, truth, images, cams):
    """liboptv on frame 0: targets, correspondences, 3-D positions (optv 0.3.2's API)."""
    import cv2
    from optv.calibration import Calibration
    from optv.correspondences import MatchedCoords, correspondences
    from optv.orientation import point_positions
    from optv.parameters import ControlParams, TargetParams, VolumeParams
    from optv.segmentation import target_recognition

    export_openptv(folder, [im[:1] for im in images], cams, lower_mm=LOWER, upper_mm=UPPER)
    t0 = time.perf_counter()
    par = Path(folder) / "parameters"
    cpar = ControlParams(len(cams))
    cpar.read_control_par(str(par / "ptv.par"))
    vpar = VolumeParams()
    vpar.read_volume_par(str(par / "criteria.par"))
    tpar = TargetParams()
    tpar.read(str(par / "targ_rec.par"))
    cals, targets, matched = [], [], []
    for k in range(len(cams)):
        cal = Calibration()
        cal.from_file(str(Path(folder) / f"cal/cam{k + 1}.tif.ori").encode(),
                      str(Path(folder) / f"cal/cam{k + 1}.tif.addpar").encode())
        img = cv2.imread(str(Path(folder) / f"img/cam{k + 1}.10001"), cv2.IMREAD_UNCHANGED)
        t = target_recognition(img, tpar, k, cpar)
        t.sort_y()
        cals.append(cal)
        targets.append(t)
        matched.append(MatchedCoords(t, cpar, cal))
    _sets, corr, _n = correspondences(targets, matched, cals, vpar, cpar)
    # as pyptv does: the flat (undistorted metric) coordinates of each clique's targets
    corr = np.concatenate([c for c in corr if c.size], axis=1) if any(c.size for c in corr) else np.zeros((4, 0))
    flat = np.array([matched[k].get_by_pnrs(corr[k]) for k in range(len(cams))])
    pts = [point_positions(flat.transpose(1, 0, 2), cpar, cals, vpar)[0]] if corr.shape[1] else []
    found = np.concatenate(pts) if pts else np.zeros((0, 3))
    wall = time.perf_counter() - t0
    m = particle_metrics(found, truth[:, 0], radius_mm=RADIUS_MM, cameras=cams)
    row = summary("openptv-corr", m, wall)
    row["targets_per_camera"] = [len(t) for t in targets]
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--particles", type=int, default=200)
    ap.add_argument("--frames", type=int, default=10)
    ap.add_argument("--distortion", action="store_true", help="a 2 %% barrel lens on every camera")
    ap.add_argument("--out", default=None, help="keep the exports and results.json here")
    ap.add_argument("--undistort", action="store_true", help="OpenLPT: export undistorted frames and cameras")
    ap.add_argument("--methods", default="mitpiv,openlpt,openptv", help="comma-separated subset to run")
    a = ap.parse_args(argv)
    cams = cameras(Distortion(k1=-0.02 / 0.0512**2 / 2) if a.distortion else Distortion())
    truth, images = sequence(a.particles, a.frames, cams)
    ppp = a.particles / (512 * 512)
    print(f"{a.particles} particles ({ppp:.4f} ppp), {a.frames} frames, 4 cameras, distortion={a.distortion}")
    out = Path(a.out) if a.out else Path(tempfile.mkdtemp(prefix="bench_peers_"))
    methods = a.methods.split(",")
    rows = [run_mitpiv(truth, images, cams)] if "mitpiv" in methods else []
    for name, fn in (("openlpt", run_openlpt), ("openptv", run_openptv)):
        if name not in methods:
            continue
        try:
            kw = {"undistort": a.undistort} if name == "openlpt" else {}
            rows.append(fn(out / name, truth, images, cams, **kw))
        except Exception as e:  # a peer that cannot run is a result too: record why
            print(f"{name}: could not run: {type(e).__name__}: {e}")
            rows.append({"method": name, "error": f"{type(e).__name__}: {e}"})
    for r in rows:
        r["ppp"] = ppp
    (out / "results.json").write_text(json.dumps(rows, indent=2, default=float))
    print(f"-> {out / 'results.json'}")


if __name__ == "__main__":
    main()
