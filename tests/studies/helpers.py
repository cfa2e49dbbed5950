"""A tiny tomographic experiment (2 cameras, 80 px, enough for the volume to lie in their
view; 150 particles, MLOS on 0.4 mm voxels, one PIV pass: about a second of work after
the first render) and the tools of the run
integrity and fault tests: a child ``mitpiv run`` process that pauses inside a stage, and
the comparison of two run folders."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "scenes" / "tomo4" / "scene.xml"

TINY = """name = "tiny"
seed = 3

[scene]
xml = "{xml}"
params = {{ resolution = 80, thickness_mm = 4, rays_per_particle = 4 }}

[seeding]
box_min_mm = [-5.0, -5.0, -2.0]
box_max_mm = [5.0, 5.0, 2.0]
count = 150
diameter_um = 1.0

[flow]
kind = "uniform"
velocity_mm_s = [100.0, 0.0, 0.0]
dt_s = 0.002

[render]
sensors = ["cam0", "cam1"]

[reconstruction]
method = "mlos"
bounds_mm = [-4.0, 4.0, -4.0, 4.0, -1.6, 1.6]
voxel_mm = 0.4

[piv]
windows = [8]
overlap = 0.5
"""


def tiny_experiment(folder: Path, *, xml: Path = SCENE, name: str = "exp.toml") -> Path:
    """Write the tiny experiment into ``folder`` (scene ``xml``); returns its path."""
    p = Path(folder) / name
    p.write_text(TINY.format(xml=xml))
    return p


# A child process running ``mitpiv.cli.main(argv)`` that pauses (sleeps) at a chosen point
# inside a stage, after part of the stage's output is written, so that the parent can kill
# it there by its PID. Nothing else of the run is changed.
CHILD = r"""
import sys, time
where, argv = sys.argv[1], sys.argv[2:]

def pause():
    sys.stderr.write("PAUSED\n"); sys.stderr.flush()
    time.sleep(300)

if where == "render":            # after the first image of the render stage is written
    import mitpiv.render.render as rr
    orig_exr = rr.write_exr
    def write_exr(path, *a, **k):
        out = orig_exr(path, *a, **k)
        pause()
        return out
    rr.write_exr = write_exr
elif where == "reconstruct":     # after volume_0.npz, before volume_1.npz
    import mitpiv.io
    orig_vol = mitpiv.io.write_volume
    def write_volume(path, *a, **k):
        out = orig_vol(path, *a, **k)
        if str(path).endswith("volume_0.npz"):
            pause()
        return out
    mitpiv.io.write_volume = write_volume
elif where == "piv":             # after field.npz, before velocity_error.npz
    import mitpiv.io.vectors
    orig_err = mitpiv.io.vectors.write_velocity_error
    def write_velocity_error(*a, **k):
        pause()
        return orig_err(*a, **k)
    mitpiv.io.vectors.write_velocity_error = write_velocity_error
from mitpiv.cli import main
sys.exit(main(argv))
"""


def start_paused_run(where: str, argv: list[str]) -> subprocess.Popen:
    """Start ``mitpiv <argv>`` in a child process that pauses inside stage ``where``."""
    env = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""),
           "MITPIV_QUIET": "1"}
    return subprocess.Popen([sys.executable, "-c", CHILD, where, *argv], env=env, cwd=str(ROOT),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def wait_for(path_or_fn, proc: subprocess.Popen | None = None, *, timeout_s: float = 180.0) -> None:
    """Poll (every 20 ms) until ``path_or_fn`` exists (a path or a glob function returning a
    list); fail with the child's output if it exits first."""
    t0 = time.monotonic()
    while True:
        ok = path_or_fn() if callable(path_or_fn) else Path(path_or_fn).exists()
        if ok:
            return
        if proc is not None and proc.poll() is not None:
            out, err = proc.communicate()
            raise AssertionError(f"the child ended (status {proc.returncode}) before {path_or_fn}:\n{err[-3000:]}")
        if time.monotonic() - t0 > timeout_s:
            raise AssertionError(f"timed out waiting for {path_or_fn}")
        time.sleep(0.02)


def wait_paused(proc: subprocess.Popen, *, timeout_s: float = 180.0) -> None:
    """Wait until the child prints PAUSED (it is inside the stage, part of its output written)."""
    t0 = time.monotonic()
    line = ""
    while "PAUSED" not in line:
        line = proc.stderr.readline()
        if not line and proc.poll() is not None:
            raise AssertionError(f"the child ended (status {proc.returncode}) before pausing:\n{proc.stderr.read()}")
        if time.monotonic() - t0 > timeout_s:
            raise AssertionError("timed out waiting for the child to pause")


def stage_temp(run: Path, stage: str) -> Path:
    """The one temporary folder in which ``stage`` of the run in ``run`` is being filled
    (``.<stage>.mitpiv-tmp-<lock token>``)."""
    (p,) = Path(run).glob(f".{stage}.mitpiv-tmp-*")
    return p


def hidden_temps(run: Path) -> list[Path]:
    """Temporary stage folders and files anywhere in a run folder (the lock files excepted)."""
    return [p for p in Path(run).rglob(".*") if not p.name.startswith(".mitpiv.lock")]


# --------------------------------------------------------------------- comparing two runs
#: Record entries that hold wall-clock times: they differ between any two runs.
TIMING_KEYS = ("seconds", "pass_seconds", "render_seconds")


def _strip(obj, run: Path):
    """A JSON record with the wall times removed and the run folder's own path (and its
    temporary stage-folder names) written as <run>/<stage>."""
    if isinstance(obj, dict):
        return {k: _strip(v, run) for k, v in obj.items() if k not in TIMING_KEYS}
    if isinstance(obj, list):
        return [_strip(v, run) for v in obj]
    if isinstance(obj, str) and str(run) in obj:
        rel = obj.replace(str(run), "<run>")
        for part in Path(rel).parts:
            m = re.fullmatch(r"\.(.+)\.mitpiv-tmp-[0-9a-f]{12}", part)
            if m:
                rel = rel.replace(part, m[1])
        return rel
    return obj


def file_content(path: Path, run: Path):
    """What of a stage output must be bit-identical between an interrupted and an
    uninterrupted run: the raw bytes of every file, except that in the files that record
    wall times or the run folder's path (``.npz`` JSON entries, EXR metadata, ``.json``
    records) those entries are removed before comparing; arrays and pixels are compared as
    raw bytes."""
    path = Path(path)
    if path.suffix == ".npz":
        with np.load(path, allow_pickle=False) as z:
            out = {}
            for k in z.files:
                a = z[k]
                if a.dtype.kind == "U" and a.ndim == 0:
                    try:
                        out[k] = _strip(json.loads(str(a)), run)
                        continue
                    except ValueError:
                        pass
                out[k] = (a.dtype.str, a.shape, a.tobytes())
            return out
    if path.suffix == ".exr":
        from mitpiv.io import read_exr

        img, meta = read_exr(path)
        return (img.dtype.str, img.shape, img.tobytes(), _strip(meta, run))
    if path.suffix == ".json":
        return _strip(json.loads(path.read_text()), run)
    return path.read_bytes()


def stage_files(run: Path, stage: str) -> dict:
    """The outputs that ``stage``'s completion record lists, with their SHA-256."""
    rec = json.loads((Path(run) / stage / "stage.json").read_text())
    return {k: v["sha256"] for k, v in rec["outputs"].items()}

