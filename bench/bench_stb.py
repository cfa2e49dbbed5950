"""Issue 51 benchmark: Shake-The-Box per frame at 0.1 particles per pixel, ours beside the
pre-issue code (a git worktree of ``--baseline``) on the same rendered sequence, and a
profile of ours; writes block ``stb`` of docs/benchmarks.md.

The sequence: ``scenes/tracking_lpt/experiment.toml`` at ``--ppp`` (default 0.1), ``--frames``
frames (default 16), rendered once by ``mitpiv run --until calibrate`` into a temporary
folder, the OTF of the 0.01-ppp recording (``scenes/tracking_lpt/otf_sparse.json``: at 0.1
ppp the images cannot calibrate their own). Each code runs STB with the experiment's
``[tracking]`` values and its own defaults for the rest, in a subprocess whose import path
is its tree; the tracks are scored by today's LPT-Challenge metrics (yield, ghosts, position
error). The profile (cProfile, the first ``--profile-frames`` frames, a separate run) lists
the functions with the most own time; a compiled kernel (Numba) is one entry.

``python bench/bench_stb.py [--ppp 0.1] [--frames 16] [--baseline 5a38e3d]``
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import docblocks  # noqa: E402
from bench_speed import head_commit, machine  # noqa: E402

SCENE = "scenes/tracking_lpt/experiment.toml"
OTF_FILE = ROOT / "scenes" / "tracking_lpt" / "otf_sparse.json"

#: The driver each code runs (its tree first on the import path): STB on the run's frames,
#: the tracks saved for scoring, the wall time of STB alone (optionally under cProfile).
DRIVER = r"""
import cProfile, io, json, pstats, sys, time
import numpy as np
from pathlib import Path
run, frames, out, profile = Path(sys.argv[1]), int(sys.argv[2]), Path(sys.argv[3]), sys.argv[4] == "1"
from mitpiv.io import read_json
from mitpiv.studies.runner import load_experiment
from mitpiv.studies.shared import bounds_of, frame_images
from mitpiv.studies.kinds.tracking.scoring import load_cameras
from mitpiv.studies.kinds.tracking import track_images
from mitpiv.tracking import OTF
cfg = load_experiment(sys.argv[5], json.loads(sys.argv[6]))
cams = load_cameras(run)
otf = OTF.from_dict(read_json(Path(sys.argv[7])))
lo, hi = bounds_of(cfg)
seq = [frame_images(run, f)[0] for f in range(frames)]

def stb(seq, cams, otf):  # the track stage's call: the experiment's [tracking], the code's own defaults
    return track_images(seq, cams, otf, dt_s=cfg.flow.dt_s, lower_mm=lo, upper_mm=hi, tracking=cfg.tracking)

stb(seq[:4], cams, otf)  # compile the kernels before the clock starts
prof = cProfile.Profile() if profile else None
t0 = time.perf_counter()
if prof:
    prof.enable()
tr = stb(seq, cams, otf)
if prof:
    prof.disable()
wall = time.perf_counter() - t0
np.savez(out / "tracks.npz", pos=tr.positions_mm, raw=tr.raw_positions_mm, vel=tr.velocities_mm_s,
         acc=tr.accelerations_mm_s2, inten=tr.intensities, dt=tr.dt_s)
top = []
if prof:
    st = pstats.Stats(prof)
    rows = sorted(st.stats.items(), key=lambda kv: -kv[1][2])[:10]
    top = [{"function": f"{Path(k[0]).name}:{k[1]}({k[2]})", "calls": v[1], "own_s": v[2], "cum_s": v[3]}
           for k, v in rows]
(out / "result.json").write_text(json.dumps({"wall_s": wall, "top": top}))
"""


def run_code(tree, run_dir, frames, out, overrides, *, profile=False):
    out.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, PYTHONPATH=str(tree))
    subprocess.run([sys.executable, "-c", DRIVER, str(run_dir), str(frames), str(out), "1" if profile else "0",
                    str(ROOT / SCENE), json.dumps(overrides), str(OTF_FILE)], cwd=tree, env=env, check=True)
    return json.loads((out / "result.json").read_text())


def score(run_dir, overrides, tracks_npz, frames):
    from mitpiv.studies.kinds.tracking import scoring
    from mitpiv.studies.runner import load_experiment
    from mitpiv.tracking import Tracks

    d = np.load(tracks_npz)
    tr = Tracks(d["pos"], d["inten"], float(d["dt"]), d["vel"], d["acc"], d["raw"])
    cfg = load_experiment(ROOT / SCENE, overrides)
    return scoring.score_tracks(cfg, run_dir, tr)["metrics"]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ppp", type=float, default=0.1, help="particles per pixel (default 0.1)")
    ap.add_argument("--frames", type=int, default=16, help="frames of the sequence (default 16, at least 4)")
    ap.add_argument("--profile-frames", type=int, default=8, help="frames of the profiled run (default 8)")
    ap.add_argument("--baseline", default="5a38e3d", help="git commit of the pre-issue code (default 5a38e3d)")
    ap.add_argument("--out", default=str(ROOT / "docs" / "benchmarks.md"))
    a = ap.parse_args(argv)
    if not 0 < a.ppp <= 0.3:
        ap.error(f"--ppp {a.ppp}: give a density in (0, 0.3] particles per pixel")
    if a.frames < 4 or not 4 <= a.profile_frames <= a.frames:
        ap.error(f"--frames {a.frames} / --profile-frames {a.profile_frames}: STB needs 4 frames or more, and the "
                 "profiled run at most the sequence's")
    rev = subprocess.run(["git", "rev-parse", "--verify", "--quiet", f"{a.baseline}^{{commit}}"], cwd=ROOT,
                         capture_output=True, text=True)
    if rev.returncode:
        ap.error(f"--baseline {a.baseline}: not a commit of this repository (git log --oneline lists them)")
    base_sha = rev.stdout.strip()[:7]
    head = head_commit()
    overrides = {"seeding.ppp": a.ppp, "sequence.frames": a.frames}
    # the truth and the cameras of the whole sequence; scoring reads them from the run folder
    with tempfile.TemporaryDirectory(prefix="mitpiv-bench-stb-") as tmp:
        tmp = Path(tmp)
        run_dir = tmp / "run"
        t0 = time.perf_counter()
        subprocess.run([sys.executable, "-m", "mitpiv.cli", "run", str(ROOT / SCENE), "--out", str(run_dir),
                        "--until", "calibrate", "--ppp", str(a.ppp), "--set", f"sequence.frames={a.frames}"],
                       cwd=ROOT, check=True)
        render_s = time.perf_counter() - t0
        wt = tmp / "baseline"
        subprocess.run(["git", "worktree", "add", "--detach", "--quiet", str(wt), base_sha], cwd=ROOT, check=True)
        try:
            print(f"baseline {base_sha} ...", flush=True)
            rb = run_code(wt, run_dir, a.frames, tmp / "base", overrides)
            mb = score(run_dir, overrides, tmp / "base" / "tracks.npz", a.frames)
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(wt)], cwd=ROOT, check=False)
        print("ours ...", flush=True)
        ro = run_code(ROOT, run_dir, a.frames, tmp / "ours", overrides)
        mo = score(run_dir, overrides, tmp / "ours" / "tracks.npz", a.frames)
        print("ours, profiled ...", flush=True)
        rp = run_code(ROOT, run_dir, a.profile_frames, tmp / "prof", overrides, profile=True)
    def cells(m, r):
        per_frame = r["wall_s"] / a.frames
        return (f"{100 * m['yield']:.1f} % | {100 * m['ghost_fraction']:.1f} % | {m['position_error_px']:.3f} | "
                f"{per_frame:.2f} s | {m['n_matched'] / r['wall_s']:,.0f}")

    lines = [f"`python bench/bench_stb.py --ppp {a.ppp} --frames {a.frames} --baseline {a.baseline}`. "
             f"Machine: {machine(head)}.", "",
             f"`{SCENE}` at {a.ppp} ppp, {a.frames} frames (320 x 200 px, 4 cameras; field and render "
             f"{render_s:.0f} s, not counted), the OTF of the 0.01-ppp recording; STB's wall time after a warm-up "
             "run that compiles the kernels. Tracked particles per second: the true particles matched "
             "by the tracks, summed over the frames, over STB's wall time.", "",
             "| code | yield | ghosts | position error [px] | s per frame | tracked particles per s |",
             "|---|---|---|---|---|---|",
             f"| pre-issue ({base_sha}) | {cells(mb, rb)} |",
             f"| ours ({head}) | {cells(mo, ro)} |",
             "", f"Ours, profiled over {a.profile_frames} frames (cProfile; own time, the ten largest):", "",
             "| function | calls | own [s] | cumulative [s] |", "|---|---|---|---|"]
    lines += [f"| `{t['function']}` | {t['calls']} | {t['own_s']:.2f} | {t['cum_s']:.2f} |" for t in rp["top"]]
    body = "\n".join(lines) + "\n"
    docblocks.update_file(a.out, "stb", body, heading="Shake-The-Box at 0.1 ppp (bench_stb.py)")
    print(body)
    print(f"written: block stb of {a.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
