"""Progress and logging: every loop a user waits for reports through the one ``progress=``
argument (silent, a tqdm bar, or a callback); library code never prints.

The callback checks use small synthetic inputs (random images and volumes: only the loop
structure matters here, not the numbers): a callable receives ``done`` increasing to
``total`` under one description per loop. The silence checks capture the file descriptors
(``capfd``), so anything written to stdout/stderr by Python or by a compiled kernel shows;
a positive control (a bar with MITPIV_QUIET=0) shows that the capture sees the bars.
"""

import ast
import logging
from pathlib import Path

import numpy as np
import pytest

import mitpiv
import mitpiv.progress
from mitpiv import holography as ho
from mitpiv.analysis import piv3d
from mitpiv.lightfield import decode, focal_stack
from mitpiv.physics.plenoptic import PlenopticCamera
from mitpiv.reconstruct import VoxelGrid, mart, mlos, sapiv_refocus
from mitpiv.reconstruct.images import reconstruct_images
from mitpiv.reconstruct.plenoptic import drt_mart
from tests.reconstruct.helpers import cameras

PACKAGE = Path(mitpiv.__file__).resolve().parent

# Modules that still print and that other people convert (the lead empties this list).
_OWNED_ELSEWHERE: tuple[str, ...] = ()  # every library module is covered
_MAY_PRINT = ("cli.py",)  # the command line is the one place that writes to the terminal

RNG = np.random.default_rng(11)
SMALL = VoxelGrid.from_bounds((-0.5, -0.5, -0.2), (0.5, 0.5, 0.2), (0.1, 0.1, 0.1))  # 4 planes
CAMS = cameras(2, res=24)
IMGS = [RNG.random((24, 24)) + 0.1 for _ in CAMS]
PIV_GRID = VoxelGrid((0.0, 0.0, 0.0), (0.1, 0.1, 0.1), (24, 24, 24))
VOL = RNG.random(PIV_GRID.shape).astype(np.float32)
VOL_B = np.roll(VOL, 1, axis=2)
PLENOPTIC = PlenopticCamera((110, 110), pixel_pitch_um=5.5, focal_length_mm=50.0, f_number=2.8,
                            focus_distance_mm=250.0, mla_pitch_um=55.0)
RAW = RNG.random((110, 110))
DRT_GRID = VoxelGrid.from_bounds((-2.0, -2.0, 248.0), (2.0, 2.0, 252.0), (1.0, 1.0, 1.0))  # in front of the lens

# name -> (call with a progress argument, {description: total steps})
CASES = {
    "mart": (lambda p: mart(IMGS, CAMS, SMALL, iterations=4, progress=p),
             {"mart: MLOS planes": 4, "mart: iterations": 4}),
    "smart": (lambda p: mart(IMGS, CAMS, SMALL, iterations=3, smart=True, progress=p),
              {"smart: MLOS planes": 4, "smart: iterations": 3}),
    "mlos": (lambda p: mlos(IMGS, CAMS, SMALL, progress=p), {"mlos: planes": 4}),
    "sapiv": (lambda p: sapiv_refocus(IMGS, CAMS, SMALL, progress=p), {"sapiv_refocus: planes": 4}),
    "piv3d": (lambda p: piv3d(VOL, VOL_B, PIV_GRID, windows=(16, 12, 8), overlap=0.5, progress=p),
              {"piv3d: passes": 3}),
    "focal_stack": (lambda p: focal_stack(decode(RAW, optics=PLENOPTIC), np.linspace(-2.0, 2.0, 6), progress=p),
                    {"focal stack: planes": 6}),
    "drt_mart": (lambda p: drt_mart(RAW, PLENOPTIC, DRT_GRID, iterations=2, rays_per_pixel=2, progress=p),
                 {"drt_weights: pixels": 110 * 110, "drt_mart: iterations": 2}),
    "hologram": (lambda p: ho.record(np.array([[0.0, 0.0, -5.0], [0.05, 0.0, -4.0], [0.0, 0.05, -3.0]]), 0.03,
                                     sensor_z_mm=0.0, pixel_um=5.5, resolution=(32, 32), guard_mm=0.2, progress=p),
                 {"hologram: planes": 3}),
}


def record():
    calls = []
    return calls, lambda done, total, desc: calls.append((done, total, desc))


@pytest.mark.parametrize("name", list(CASES))
def test_callable_progress_counts_up_to_total(name):
    run, expected = CASES[name]
    calls, cb = record()
    run(cb)
    assert {d for _, _, d in calls} == set(expected)
    for desc, total in expected.items():
        seen = [(done, t) for done, t, d in calls if d == desc]
        done = [s[0] for s in seen]
        assert all(t == total for _, t in seen)
        assert all(b > a for a, b in zip(done, done[1:], strict=False)) and done[-1] == total


def test_reconstruct_images_passes_progress_down(monkeypatch):
    """The one reconstruction entry point hands ``progress`` to the method it runs."""
    metas = [{"camera": c.to_dict()} for c in CAMS]
    calls, cb = record()
    reconstruct_images(IMGS, metas, SMALL, "smart", iterations=2, progress=cb)
    assert [d for d, _, desc in calls if desc == "smart: iterations"] == [1, 2]


@pytest.mark.parametrize("name", list(CASES))
def test_silent_without_progress_and_when_quiet(name, capfd, monkeypatch):
    run, _ = CASES[name]
    monkeypatch.setattr(mitpiv.progress, "_quiet", None)
    run(None)  # warm-up (kernel compilation) outside the checks below
    capfd.readouterr()
    run(None)
    assert capfd.readouterr() == ("", "")
    monkeypatch.setenv("MITPIV_QUIET", "1")
    run(True)
    assert capfd.readouterr() == ("", "")
    monkeypatch.setenv("MITPIV_QUIET", "0")
    mitpiv.progress.set_quiet(True)  # the CLI's --quiet
    run(True)
    assert capfd.readouterr() == ("", "")


def test_bar_is_drawn_when_asked_for(capfd, monkeypatch):
    """Positive control of the silence checks: with bars on and stderr a terminal, the
    captured stderr shows one; stderr redirected to a file (not a terminal) gets none."""
    import sys

    monkeypatch.setattr(mitpiv.progress, "_quiet", None)
    monkeypatch.setenv("MITPIV_QUIET", "0")
    CASES["mart"][0](True)
    assert capfd.readouterr() == ("", "")  # not a terminal: no carriage-return noise in a log
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True)
    CASES["mart"][0](True)
    out, err = capfd.readouterr()
    assert out == "" and "mart: iterations" in err and "/4 [" in err


def test_messages_go_to_logging(caplog):
    with caplog.at_level(logging.DEBUG, logger="mitpiv"):
        CASES["piv3d"][0](None)
    names = {r.name for r in caplog.records}
    assert "mitpiv.analysis.piv3d" in names
    assert sum("pass" in r.getMessage() and r.levelno == logging.DEBUG for r in caplog.records) == 3
    assert any(r.levelno == logging.INFO and "3 passes" in r.getMessage() for r in caplog.records)


# ---------------------------------------------------------------------- no print in library code
def _writes_to_terminal(source: str) -> list[int]:
    """Line numbers of ``print(...)`` calls and ``sys.stdout``/``sys.stderr`` writes (parsed,
    so comments and docstrings do not count)."""
    lines = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Call):
            continue
        f = node.func
        if isinstance(f, ast.Name) and f.id == "print":
            lines.append(node.lineno)
        elif (isinstance(f, ast.Attribute) and f.attr == "write" and isinstance(f.value, ast.Attribute)
              and f.value.attr in ("stdout", "stderr") and isinstance(f.value.value, ast.Name) and f.value.value.id == "sys"):
            lines.append(node.lineno)
    return lines


def test_the_detector_finds_prints_and_ignores_text():
    src = '"""print(1) in a docstring"""\n# print(2)\nx = "print(3)"\nprint(4)\nimport sys\nsys.stderr.write("5")\n'
    assert _writes_to_terminal(src) == [4, 6]


def test_no_print_in_library_code():
    files = sorted(PACKAGE.rglob("*.py"))
    assert len(files) > 30
    offenders = {}
    for path in files:
        rel = path.relative_to(PACKAGE).as_posix()
        if rel in _MAY_PRINT or rel in _OWNED_ELSEWHERE:
            continue
        lines = _writes_to_terminal(path.read_text())
        if lines:
            offenders[rel] = lines
    assert offenders == {}, f"library code writes to the terminal (use logging or mitpiv.progress): {offenders}"
