"""A run's clean-up of temporary files removes only what an interrupted mitpiv write left
(names that carry mitpiv's tag), never a user's own hidden files and folders, however
temporary they look; and a user file on a name that an older mitpiv used for a stage's
temporary folder neither crashes the run nor is touched. Runs here use two trivial stages
(no rendering), so each takes milliseconds."""

import os
import signal
import subprocess
import sys
from pathlib import Path

from pydantic import BaseModel

from mitpiv.studies.runner import Stage, run_stages

ROOT = Path(__file__).resolve().parents[2]


class Cfg(BaseModel):
    name: str = "tiny"
    kind: str = "test"
    n: int = 3


def _write(ctx):
    (ctx.out / "a.txt").write_text("a" * ctx.cfg.n)
    return {"n": ctx.cfg.n}


STAGES = [Stage("render", ("n",), _write), Stage("results", ("n",), _write)]

#: A user's hidden files and folders of every shape that once passed for temporary: the
#: names of stage folders being filled or moved aside (``.<stage>.tmp``, ``.<stage>.old``,
#: also as plain files), of atomic writes (``.<name>.tmp-<x>``, ``.<name>.<8 chars>.<ext>``)
USER_FILES = (".config.settings.json", ".notes.old_2024.txt", ".x.tmp", ".results.abcdefgh.json",
              ".metrics.json.tmp-abc123.json", ".render.tmp", ".results.old", ".a.txt.k2j3h4g5.txt")
USER_DIRS = (".cache.old", ".render.old", ".results.tmp", ".work.tmp")


def _user_tree(folder: Path) -> dict[str, bytes | None]:
    folder.mkdir(parents=True, exist_ok=True)
    for i, n in enumerate(USER_FILES):
        (folder / n).write_bytes(f"user file {i}\n".encode() * (i + 1))
    for n in USER_DIRS:
        (folder / n).mkdir()
        (folder / n / "keep.txt").write_text(f"inside {n}")
    return _snapshot(folder)


def _snapshot(folder: Path) -> dict[str, bytes | None]:
    names = [*USER_FILES, *USER_DIRS, *(f"{d}/keep.txt" for d in USER_DIRS)]
    return {n: ((folder / n).read_bytes() if (folder / n).is_file() else None) for n in names
            if (folder / n).exists()}


def test_a_run_leaves_the_users_hidden_files_alone(tmp_path):
    run = tmp_path / "run"
    before = _user_tree(run)
    for st in STAGES:  # also inside the stage folders (cleaned at start too)
        _user_tree(run / st.name)
    inside = _snapshot(run / "results")
    results, _ = run_stages(Cfg(), run, STAGES)
    assert results == {"render": {"n": 3}, "results": {"n": 3}}
    assert _snapshot(run) == before and set(before) >= set(USER_FILES) | set(USER_DIRS)
    # a rerun with a change: both stage folders are replaced (moved aside, then removed);
    # what the user keeps beside them stays
    run_stages(Cfg(n=4), run, STAGES)
    assert _snapshot(run) == before
    assert (run / "results" / "a.txt").read_text() == "aaaa"
    assert sorted(p.name for p in run.iterdir() if p.name.startswith(".") and "mitpiv" in p.name) == \
        [".mitpiv.lock"]
    del inside  # a replaced stage folder is the run's own: what a user put inside it goes with it


KILLED = r"""
import os, signal, sys
from pathlib import Path
from pydantic import BaseModel
from mitpiv.io.atomic import atomic_path
from mitpiv.studies.runner import Stage, run_stages

class Cfg(BaseModel):
    name: str = "tiny"
    kind: str = "test"
    n: int = 3

def write(ctx):
    (ctx.out / "a.txt").write_text("a")
    if ctx.out.name.startswith(".results"):  # killed in the 2nd stage, inside an atomic write
        with atomic_path(ctx.run_dir / "notes.json") as tmp:
            tmp.write_text("{}")
            print("KILL", flush=True)
            os.kill(os.getpid(), signal.SIGKILL)
    return {}

run_stages(Cfg(), Path(sys.argv[1]), [Stage("render", ("n",), write), Stage("results", ("n",), write)])
"""


def test_an_interrupted_runs_leftovers_are_still_removed(tmp_path):
    """A run killed (SIGKILL: no clean-up at all) inside a stage and inside an atomic write
    leaves its temporary stage folder and file; the next run removes exactly those, and the
    user's files stay."""
    run = tmp_path / "run"
    before = _user_tree(run)
    proc = subprocess.run([sys.executable, "-c", KILLED, str(run)], capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=120)
    assert proc.returncode == -signal.SIGKILL and "KILL" in proc.stdout, proc.stderr
    left = sorted(p.name for p in run.iterdir() if p.name not in before)
    assert {"render", "experiment.json"} <= set(left)
    leftovers = [n for n in left if n.startswith(".") and not n.startswith(".mitpiv.lock")]
    assert len(leftovers) == 2, left  # the 2nd stage's folder being filled, the atomic write's file
    run_stages(Cfg(), run, STAGES)
    assert not any((run / n).exists() for n in leftovers)
    assert _snapshot(run) == before
    assert (run / "results" / "stage.json").is_file()
