"""A peer tracker's child process dies with its caller (``mitpiv.tracking.peers.run_python_child``).

A sweep killed while OpenLPT ran left OpenLPT running on for 30 min, holding a core. These
tests start a child that records its pid and sleeps, then end the caller three ways: a
timeout, an exception in the caller, and the caller killed outright (``SIGKILL``, as when a
sweep's Dask worker is stopped). The child must be gone within 10 s each time (it would
otherwise sleep for 120 s, and the caller would wait for it).
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import pytest

from mitpiv.tracking.peers import run_python_child

SLEEPER = "import os, time; open('child.pid', 'w').write(str(os.getpid())); time.sleep(120)"


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # a zombie still answers kill(0); read its state
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(")")[-1].split()[0] != "Z"
    except FileNotFoundError:
        return False


def _pid(folder, wait_s=30.0) -> int:
    t0 = time.monotonic()
    f = folder / "child.pid"
    while time.monotonic() - t0 < wait_s:
        if f.is_file() and f.read_text():
            return int(f.read_text())
        time.sleep(0.05)
    raise AssertionError("the child never started")


def _gone(pid: int, wait_s=10.0) -> bool:
    t0 = time.monotonic()
    while time.monotonic() - t0 < wait_s:
        if not _alive(pid):
            return True
        time.sleep(0.05)
    return False


def test_exit_status_and_log(tmp_path):
    with open(tmp_path / "log", "w") as log:
        rc = run_python_child("print('hello'); raise SystemExit(3)", cwd=tmp_path, log=log, timeout_s=60)
    assert rc == 3
    assert (tmp_path / "log").read_text().strip() == "hello"


def test_a_timeout_kills_the_child(tmp_path):
    t0 = time.monotonic()
    with open(tmp_path / "log", "w") as log, pytest.raises(subprocess.TimeoutExpired):
        run_python_child(SLEEPER, cwd=tmp_path, log=log, timeout_s=10)
    # returned long before the child's 120 s sleep would have ended on its own
    assert time.monotonic() - t0 < 60
    assert _gone(_pid(tmp_path))


def test_an_interrupt_in_the_caller_kills_the_child(tmp_path, monkeypatch):
    """A KeyboardInterrupt (Ctrl-C on a sweep) arriving while the caller waits: simulated by
    the wait raising it once the child runs (a real SIGINT reaches only the main thread, and
    pytest-xdist or a Dask worker may run the caller in another one)."""
    orig_wait = subprocess.Popen.wait
    raised = []

    def interrupted_wait(self, timeout=None):
        if timeout is not None and not raised:
            _pid(tmp_path)  # the child is running
            raised.append(True)
            raise KeyboardInterrupt
        return orig_wait(self, timeout=timeout)

    monkeypatch.setattr(subprocess.Popen, "wait", interrupted_wait)
    t0 = time.monotonic()
    with open(tmp_path / "log", "w") as log, pytest.raises(KeyboardInterrupt):
        run_python_child(SLEEPER, cwd=tmp_path, log=log, timeout_s=110)
    assert raised and time.monotonic() - t0 < 60
    assert _gone(_pid(tmp_path))


def test_the_child_dies_when_its_caller_is_killed(tmp_path):
    caller = subprocess.Popen([sys.executable, "-c", (
        "import sys; from mitpiv.tracking.peers import run_python_child\n"
        f"run_python_child({SLEEPER!r}, cwd={str(tmp_path)!r}, log=sys.stdout, timeout_s=120)")])
    try:
        pid = _pid(tmp_path)
        assert _alive(pid)
        caller.kill()
        caller.wait()
        assert _gone(pid), "the child outlived its killed caller"
    finally:
        if caller.poll() is None:
            caller.kill()
        f = tmp_path / "child.pid"
        if f.is_file() and _alive(int(f.read_text())):
            os.kill(int(f.read_text()), signal.SIGKILL)
