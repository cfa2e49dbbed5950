"""Backlit plenoptic droplet tracking through the experiment runner (kind = "backlit"):
stages, resume, metrics, the published qualitative conclusions (depth uncertainty of about
one droplet diameter; large droplets are found, droplets under about one lenslet are
not), and bad inputs."""

import json
import logging
from pathlib import Path

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.io import read_truth
from mitpiv.studies import load_experiment, run_config

EXP = Path(__file__).resolve().parents[2] / "scenes" / "backlit_droplets" / "experiment.toml"
SMALL = {"camera.resolution": 600, "field.n": 16, "field.sigma_ln": 0.8, "render.spp": 8, "calibration.spp": 8, "detection.planes": 61}


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    out = tmp_path_factory.mktemp("backlit")
    m = run_config(load_experiment(EXP, SMALL), out)
    return out, m


def test_backlit_run_measures_droplets_and_tracks(run):
    out, m = run
    for f in ("metrics.json", "timings.json", "report/report.md", "report/images.png", "report/errors.png",
              "render/raw_frame000.exr", "render/white.exr", "calibrate/dewarp.npz"):
        assert (out / f).is_file(), f
    assert m["kind"] == "backlit" and m["n_particles"] > 10
    assert m["dewarp_rms_mm"] < 0.005  # dot card fit residual below a tenth of a refocused pixel (55 um)
    truth = read_truth(out / "field" / "truth.npz")
    d = truth["diameters_um"] / 1e3
    ev = m["evaluate"]["frame0"]
    e = np.load(out / "evaluate" / "errors_0.npz")
    found = np.zeros(d.size, bool)
    found[e["pairs"][:, 1]] = True
    lenslet_mm = 0.055  # 55 um lenslets at |M| = 1
    # isolated: no other silhouette within two lenslets in the camera's projection (x, y)
    xy = truth["positions_mm"][0][:, :2]
    gap = np.linalg.norm(xy[:, None] - xy[None], axis=2) - 0.5 * (d[:, None] + d[None]) + np.eye(d.size) * 99
    isolated = gap.min(axis=1) > 2 * lenslet_mm
    inside = np.all(np.abs(xy) < 1.5, axis=1)  # 1.65 mm half-field less a lenslet and a bit
    big, small = isolated & inside & (d > 2 * lenslet_mm), d < lenslet_mm
    assert big.sum() >= 3 and small.sum() >= 3
    # isolated silhouettes of two lenslets or more are found; droplets under one lenslet are
    # mostly lost; overlapping silhouettes merge (not asserted: it depends on the draw)
    assert found[big].all()
    assert found[small].mean() < 0.5
    # depth uncertainty of about one diameter for most droplets (merged silhouettes are outliers)
    assert ev["depth_median_abs_diameters"] < 1.5
    assert ev["lateral_rms_diameters"] < 0.5
    t = m["piv"]
    assert t["n_correct"] >= 0.5 * ev["n_matched"] and t["outlier_ratio"] < 0.5
    # in-plane velocity (0.45 mm displacements) is far better than the depth component
    assert max(t["rms"][:2]) < t["rms"][2]


def test_backlit_rerun_resumes_and_reproduces(run, caplog):
    out, m = run
    with caplog.at_level(logging.INFO, logger="mitpiv"):
        m2 = run_config(load_experiment(EXP, SMALL), out)
    assert caplog.text.count("done earlier, skipped") == 6
    assert json.dumps(m2.metrics, sort_keys=True) == json.dumps(m.metrics, sort_keys=True)


def test_backlit_bad_inputs(tmp_path):
    cases = [({"camera.pixel_size_um": 5.5}, "Did you mean 'pixel_pitch_um'"), ({"field.kind": "spray"}, "drop_impact"),
             ({"field.dt_s": 0}, "dt_s"), ({"kind": "holo"}, "backlit"), ({"detection.z_range_mm": [2.0, -2.0]}, "near"),
             ({"camera.resolution": 8}, "resolution"), ({"calibration.depths_mm": [0.0]}, "depths_mm"),
             ({"reconstruction.method": "mart"}, "unknown key")]
    for ov, msg in cases:
        with pytest.raises(ConfigError, match=msg):
            load_experiment(EXP, ov)
    # a bad field argument is refused before anything runs, with the nearest valid name
    with pytest.raises(ConfigError, match=r"\[field\] crown_size_mm: unknown key.*crown_radius_mm"):
        load_experiment(EXP, {"field.crown_size_mm": 1.0})
