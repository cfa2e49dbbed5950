"""Other trackers on mitpiv's images: run OpenLPT's Shake-The-Box on a folder written by
:func:`mitpiv.io.openlpt.export_openlpt` and return its tracks as :class:`~mitpiv.tracking.stb.Tracks`,
to be scored with :func:`mitpiv.tracking.metrics.track_metrics` like mitpiv's own.

OpenLPT is an optional benchmark dependency (``pip install mitpiv[peers]``: PyPI ``openlpt``,
whose C++ core is the module ``pyopenlpt``). It runs in a child process
(``python -c "import pyopenlpt; pyopenlpt.run('config.txt')"`` in the export folder): its C++
core prints to the terminal and can abort the process on a bad input, which must not take the
caller down; its log is kept as ``openlpt.log`` in the folder. The child dies with its caller
(:func:`run_python_child`: its own process group, killed on a timeout or an exception, and
``PR_SET_PDEATHSIG`` on Linux when the caller is killed outright).

What OpenLPT gives: positions per frame per track (``results/ConvergeTrack/*.csv``); no
velocities. The tracks returned are its long tracks (active, inactive and exited; the
unconfirmed short tracks are left out), with velocities and accelerations from mitpiv's own
:func:`~mitpiv.tracking.stb.regularise` when ``regularise=True`` (the same regularisation as
mitpiv's STB, so the comparison is of positions and linking, not of the smoothing).

Observed with openlpt 2.2.4 (bench/bench_peers.py: 4 cameras 512 x 512 px, 200 particles,
0.0008 ppp, 10 frames of uniform translation, f/16 point images, no noise): yield 0.960,
ghost fraction 0.0005, position error 0.005 mm = 0.026 px, velocity error 1.3 % of the speed,
99.5 % correct tracks, 6 - 8 s on one thread; its 3-D positions are unbiased (1e-4 mm against
0.045 mm for a half-pixel convention error), which checks the export's pixel convention. On
distorted camera files its stereo matching fails (see :mod:`mitpiv.io.openlpt`); with a 2 %
barrel lens exported with ``undistort=True`` it reaches yield 0.961, no ghosts, 0.032 px.
"""

from __future__ import annotations

import logging
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from mitpiv.errors import BackendError, ConfigError, check_positive

__all__ = ["run_openlpt", "openlpt_tracks", "openlpt_available"]

log = logging.getLogger(__name__)


def openlpt_available() -> bool:
    """Whether OpenLPT's core (``pyopenlpt``) can be imported here."""
    import importlib.util

    return importlib.util.find_spec("pyopenlpt") is not None


def openlpt_tracks(folder, *, n_frames: int, dt_s: float, regularise: bool = True):
    """OpenLPT's long tracks in an export folder (after a run) as :class:`Tracks`.

    Parameters
    ----------
    folder : the export folder (its ``results/ConvergeTrack``).
    n_frames : frames of the sequence; dt_s : time between frames [s].
    regularise : add velocities and accelerations by :func:`~mitpiv.tracking.stb.regularise`.
    """
    from mitpiv.io.openlpt import read_openlpt_tracks
    from mitpiv.tracking.stb import Tracks
    from mitpiv.tracking.stb import regularise as smooth

    res = Path(folder) / "results" / "ConvergeTrack"
    files = sorted(f for f in res.glob("*.csv") if not f.name.startswith("ShortTrack"))
    if not files:
        raise BackendError(f"openlpt_tracks: no OpenLPT track files in {str(res)!r}; did OpenLPT run (see "
                           f"{str(Path(folder) / 'openlpt.log')!r})?")
    pos = read_openlpt_tracks(files, n_frames=n_frames)["positions_mm"]
    t = Tracks(positions_mm=pos, intensities=np.where(np.isfinite(pos[..., 0]), 1.0, np.nan),
               dt_s=check_positive("dt_s", dt_s, owner="openlpt_tracks", unit="s"))
    return smooth(t) if regularise else t


# Run first in the child: ask the kernel to SIGKILL it when the thread that started it dies
# (prctl PR_SET_PDEATHSIG = 1, Linux), and exit if that parent is already gone (the race
# between fork and prctl). Elsewhere the prctl call is skipped and the process group below
# still covers a timeout or an exception in the parent.
_CHILD_PRELUDE = """\
import os, signal, sys
if sys.platform.startswith("linux"):
    import ctypes
    ctypes.CDLL(None, use_errno=True).prctl(1, int(signal.SIGKILL))
    if os.getppid() != int(os.environ["MITPIV_PARENT_PID"]):
        os._exit(1)
"""


def run_python_child(code: str, *, cwd, log, timeout_s: float) -> int:
    """Run ``code`` in a child Python process (its own process group) and return its exit status.

    The child dies with the caller: on a timeout (:class:`subprocess.TimeoutExpired`,
    re-raised) or any exception in the caller, including ``KeyboardInterrupt``, the child's
    whole process group (the child and anything it started) is killed and reaped; if the caller
    is killed outright (a sweep's Dask worker stopped, ``kill -9``), Linux kills the child
    itself through ``PR_SET_PDEATHSIG`` (its own children, if any, are not covered; OpenLPT
    starts none). Without this, a killed sweep left OpenLPT running for half an hour.
    """
    import os
    import signal

    def kill(proc):
        try:
            if hasattr(os, "killpg"):
                os.killpg(proc.pid, signal.SIGKILL)
            else:  # no process groups (Windows): the child alone
                proc.kill()
        except (ProcessLookupError, PermissionError):
            pass

    env = dict(os.environ, MITPIV_PARENT_PID=str(os.getpid()))
    proc = None
    try:
        proc = subprocess.Popen([sys.executable, "-c", _CHILD_PRELUDE + code], cwd=cwd, stdout=log,
                                stderr=subprocess.STDOUT, env=env, start_new_session=True)
        return proc.wait(timeout=timeout_s)
    except BaseException:
        if proc is not None:
            kill(proc)
            while True:  # reap it, even through a second Ctrl-C
                try:
                    proc.wait()
                    break
                except KeyboardInterrupt:
                    kill(proc)
        raise


def run_openlpt(folder, *, timeout_s: float = 600.0, regularise: bool = True):
    """Run OpenLPT's STB on an export folder and return (tracks, wall time [s]).

    Raises
    ------
    BackendError
        OpenLPT is not installed, failed (its exit status and the end of its log in the
        message) or ran past ``timeout_s``.
    ConfigError
        ``folder`` is not an OpenLPT export (no ``config.txt`` / ``mitpiv_export.json``).
    """
    from mitpiv.io import read_json

    folder = Path(folder)
    if not (folder / "config.txt").is_file() or not (folder / "mitpiv_export.json").is_file():
        raise ConfigError(f"run_openlpt: {str(folder)!r} is not an OpenLPT export (no config.txt / "
                          "mitpiv_export.json); write one with mitpiv.io.openlpt.export_openlpt or "
                          "'mitpiv export RUN --openlpt DIR'.")
    if not openlpt_available():
        raise BackendError("run_openlpt: OpenLPT is not installed (no module pyopenlpt); install the optional "
                           "benchmark dependency: pip install 'mitpiv[peers]' (PyPI openlpt).")
    manifest = read_json(folder / "mitpiv_export.json")
    timeout_s = check_positive("timeout_s", timeout_s, owner="run_openlpt", unit="s")
    t0 = time.perf_counter()
    with open(folder / "openlpt.log", "w") as logf:
        try:
            returncode = run_python_child("import pyopenlpt; pyopenlpt.run('config.txt')", cwd=folder, log=logf,
                                          timeout_s=timeout_s)
        except subprocess.TimeoutExpired:
            raise BackendError(f"run_openlpt: OpenLPT ran past {timeout_s:g} s on {str(folder)!r}.") from None
    wall = time.perf_counter() - t0
    tail = (folder / "openlpt.log").read_text(errors="replace")[-800:]
    if returncode != 0 or "OpenLPT finish" not in tail:
        raise BackendError(f"run_openlpt: OpenLPT failed on {str(folder)!r} (exit status {returncode}); the "
                           f"end of its log:\n{tail}")
    log.info("OpenLPT ran in %.1f s on %s", wall, folder)
    tracks = openlpt_tracks(folder, n_frames=int(manifest["n_frames"]), dt_s=1.0 / float(manifest["frame_rate_hz"]),
                            regularise=regularise)
    return tracks, wall
