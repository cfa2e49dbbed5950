"""Every script in examples/ runs at its small size (``--small``), in this process (the
examples share its compiled kernels), and writes what its docstring promises; a few
numbers they print are checked against what the examples are there to show."""

import runpy
import sys
from pathlib import Path

import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
SCRIPTS = sorted(p.name for p in EXAMPLES.glob("*.py") if not p.name.startswith("_"))

#: What each example writes (relative to its --out folder).
OUTPUTS = {
    "mie_phase_function.py": ["mie_phase_function.png"],
    "holography.py": ["holography.png"],
    "plenoptic_refocus.py": ["plenoptic_refocus.png"],
    "tomo_experiment.py": ["run/report/report.md", "run/report/flow_slice.png", "run/vtk/run.pvd",
                           "run/vtk/piv.vts"],
    "distortion_and_q.py": ["distortion_and_q.png"],
    "sweep.py": ["results.csv", "sweep.png"],
    "score_openpiv.py": ["tiff/cam0_0000.tif", "field_16.txt", "score_32/score.md", "score_16/score.json",
                         "score_16/velocity_error.png", "score_16_up/score.json", "davis/Images.set",
                         "davis/Calibration.set", "field_16.vc7", "score_16_davis/score.json"],
    "preview_rig.py": ["tomo4/rig.png", "tomo4/views.png", "tomo4/rig.vtu", "misaimed/rig.png", "misaimed/views.png"],
}


def test_every_example_is_listed():
    assert set(SCRIPTS) == set(OUTPUTS)


@pytest.mark.parametrize("script", SCRIPTS)
def test_example_runs_small(script, tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(sys, "argv", [script, "--small", "--out", str(tmp_path)])
    runpy.run_path(str(EXAMPLES / script), run_name="__main__")
    text = capsys.readouterr().out
    for f in OUTPUTS[script]:
        assert (tmp_path / f).is_file(), f
    if script == "holography.py":
        assert "4 of 4 droplets found" in text
    if script == "distortion_and_q.py":  # 5 % uncorrected distortion costs Q, the true model does not
        q = {line.split("model ")[1].split(":")[0].strip(): float(line.rsplit("=", 1)[1])
             for line in text.splitlines() if line.startswith("distortion 5")}
        assert q["undistorted"] < q["true"] - 0.02
    if script == "preview_rig.py":  # the committed rig is seen whole, the misaimed camera warned about
        assert "cam0: sees 100 %" in text and "camera 'cam0' sees 7" in text
    if script == "score_openpiv.py":  # scored, a y-up field refused, then scored alike with --flip-y
        rms = [float(line.split("RMS error ")[1].split(" / ")[0]) for line in text.splitlines()
               if line.startswith("OpenPIV ")]
        assert len(rms) == 2 and max(rms) < 0.4 and "refused: score:" in text and "--flip-y: RMS error" in text
        davis = float(text.split("DaVis .vc7 in mm and m/s: RMS error ")[1].split(" / ")[0])
        assert abs(davis - rms[1]) < 0.02  # the same vectors, windows mapped to mm and back
    if script == "sweep.py":
        import pandas as pd

        t = pd.read_csv(tmp_path / "results.csv")
        assert len(t) == 4 and (t["status"] == "ok").all()
