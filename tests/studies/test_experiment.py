"""The experiment runner: a small tomographic experiment end to end, exact reruns, resume
after a failed stage, only changed stages rerun, bad experiment files."""

import json
import logging
from pathlib import Path

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.studies import run_experiment

SCENE = Path(__file__).resolve().parents[2] / "scenes" / "tomo4" / "scene.xml"

BASE = f"""name = "tomo4-small"
seed = 3

[scene]
xml = "{SCENE}"
params = {{ resolution = 128, thickness_mm = 4 }}

[seeding]
box_min_mm = [-5.0, -5.0, -2.0]
box_max_mm = [5.0, 5.0, 2.0]
count = 400
diameter_um = 1.0

[flow]
kind = "uniform"
velocity_mm_s = [100.0, 0.0, 0.0]
dt_s = 0.002

[reconstruction]
method = "mart"
bounds_mm = [-4.0, 4.0, -4.0, 4.0, -1.6, 1.6]
voxel_mm = 0.1
iterations = 3

[piv]
windows = [32, 16]
overlap = 0.5
"""


def write(tmp_path, text, name="exp.toml"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_run_rerun_and_resume(tmp_path, caplog):
    exp = write(tmp_path, BASE)
    m = run_experiment(exp, tmp_path / "run")
    run = tmp_path / "run"
    for f in ("metrics.json", "timings.json", "report/report.md", "report/velocity_error.png",
              "report/volume_projections.png", "report/sensor_images.png", "piv/field.npz", "particles/truth.npz"):
        assert (run / f).is_file(), f
    assert m["evaluate"]["frame0"]["Q"] > 0.5 and m["evaluate"]["frame0"]["particles"]["detection_rate"] > 0.8
    # uniform 100 mm/s over 2 ms = 2 voxels along x; the runner's PIV gets it within 0.1 voxel RMS
    assert max(m["piv"]["rms_vox"]) < 0.1
    timings = json.loads((run / "timings.json").read_text())
    assert set(timings) == {"particles", "render", "reconstruct", "evaluate", "piv", "report"}
    report = (run / "report" / "report.md").read_text()
    assert "| 0 |" in report and "RMS error" in report
    # a rerun skips every stage and returns the same metrics
    with caplog.at_level(logging.INFO, logger="mitpiv"):
        assert run_experiment(exp, run).metrics == m.metrics
    assert caplog.text.count("done earlier, skipped") == 6
    # the same seed in a new folder reproduces the metrics exactly
    assert run_experiment(exp, tmp_path / "again").metrics == m.metrics
    # a changed PIV setting reruns only piv and report
    write(tmp_path, BASE.replace("windows = [32, 16]", "windows = [32, 24]"))
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="mitpiv"):
        m2 = run_experiment(exp, run)
    err = caplog.text
    assert err.count("done earlier, skipped") == 4 and "piv ..." in err and "report ..." in err
    assert m2["evaluate"] == m["evaluate"] and m2["piv"] != m["piv"]


def test_failed_stage_leaves_nothing_and_resumes(tmp_path, caplog, monkeypatch):
    """A stage that fails (here reconstruction, made to raise) leaves no stage folder and no
    temporary folder; the rerun resumes after the last finished stage."""
    from mitpiv.studies.kinds import tomo

    exp = write(tmp_path, BASE)

    def broken(*a, **k):
        raise ConfigError("reconstruct: simulated failure")

    monkeypatch.setattr("mitpiv.reconstruct.images.reconstruct_images", broken)
    with pytest.raises(ConfigError, match="simulated"):
        run_experiment(exp, tmp_path / "run")
    monkeypatch.undo()
    assert tomo.STAGES[:2] == ("particles", "render")
    run = tmp_path / "run"
    assert (run / "render" / "stage.json").is_file()
    assert not (run / "reconstruct").exists() and not list(run.glob(".*.mitpiv-tmp-*"))
    write(tmp_path, BASE.replace('method = "mart"', 'method = "mlos"').replace("iterations = 3\n", ""))
    with caplog.at_level(logging.INFO, logger="mitpiv"):
        m = run_experiment(exp, run)
    err = caplog.text
    assert "particles: done earlier, skipped" in err and "render: done earlier, skipped" in err
    assert m["evaluate"]["frame1"]["Q"] > 0.2


def test_cli_run(tmp_path, capsys):
    from mitpiv.cli import main

    exp = write(tmp_path, BASE.replace("iterations = 3", "iterations = 1"))
    assert main(["run", str(exp), "--out", str(tmp_path / "run")]) == 0
    assert "report.md" in capsys.readouterr().out
    assert main(["run", str(tmp_path / "missing.toml"), "--out", str(tmp_path / "x")]) == 2
    assert "does not exist" in capsys.readouterr().err and not (tmp_path / "x").exists()
    # a mistyped method fails before anything is rendered, naming the table, key, value and choices
    # a typed flag: argparse lists the choices, in one line, and main returns 2 (no SystemExit)
    assert main(["run", str(exp), "--out", str(tmp_path / "y"), "--method", "marts"]) == 2
    err = capsys.readouterr().err
    assert "'smart'" in err and len(err.strip().splitlines()) == 1 and not (tmp_path / "y").exists()
    assert main(["run", str(exp), "--out", str(tmp_path / "y"), "--set", "reconstruction.method=marts"]) == 2
    err = capsys.readouterr().err
    assert "[reconstruction] method" in err and "'marts'" in err and "'smart'" in err and not (tmp_path / "y").exists()
    # --check validates only; --set and typed flags reach the experiment
    assert main(["run", str(exp), "--check", "--set", "piv.windows=[16, 8]", "--voxel-mm", "0.2"]) == 0
    assert "valid tomo experiment" in capsys.readouterr().out


def test_cli_run_help_says_out_is_required(tmp_path, capsys):
    """`mitpiv run --help` marks the run folder as required (unless --check), and a run without
    either is refused by the parser, before the experiment is read."""
    from mitpiv.cli import main

    with pytest.raises(SystemExit) as e:
        main(["run", "--help"])
    assert e.value.code == 0
    out = " ".join(capsys.readouterr().out.split())  # whatever the terminal's width
    assert "(--out DIR | --check)" in out and "required unless --check" in out
    assert main(["run", str(tmp_path / "missing.toml")]) == 2
    err = capsys.readouterr().err
    assert "--out" in err and "--check" in err and "required" in err and "does not exist" not in err


def test_sensor_stage(tmp_path):
    # 2000 photons at 10 e- per count: the brightest pixel at 200 of 255 counts, none clipped
    exp = write(tmp_path, BASE + "\n[sensor]\nbit_depth = 8\npeak_photons = 2000\nshot_noise = true\ngain_e_per_count = 10.0\n")
    run_experiment(exp, tmp_path / "run")
    from mitpiv.io import read_exr

    img, meta = read_exr(next((tmp_path / "run" / "sensor").glob("*_frame000.exr")))
    assert meta["sensor"]["bit_depth"] == 8 and np.all(img == np.round(img)) and img.max() <= 255


def test_sensor_stage_is_scene_wide_with_independent_streams(tmp_path):
    """The sensor stage takes one exposure for all cameras and frames (mean counts keep the
    rendered brightness ratios; before, each image was scaled to its own peak) and one
    noise stream per (camera, frame): the shot-noise fields of two cameras are
    uncorrelated, a rerun in another folder is bit-identical."""
    from mitpiv.io import read_exr
    from mitpiv.photometry import pixel_etendue
    from mitpiv.studies import load_experiment, run_config

    exp = write(tmp_path, BASE + "\n[sensor]\npeak_photons = 4000\nshot_noise = true\n")
    cfg = load_experiment(exp)
    run_config(cfg, tmp_path / "a", until="sensor")
    run_config(cfg, tmp_path / "b", until="sensor")
    rendered, counts, seeds = {}, {}, set()
    for f in sorted((tmp_path / "a" / "sensor").glob("*.exr")):
        c, meta = read_exr(f)
        r, rmeta = read_exr(tmp_path / "a" / "render" / f.name)
        # the demo's cameras state their aperture (psf_f_number): each pixel is exposed to the
        # power it collects, the rendered radiance times its etendue
        assert meta["sensor"]["photometry"] == "aperture"
        rendered[f.name] = r.astype(np.float64) * pixel_etendue(rmeta["camera"])
        counts[f.name] = c.astype(np.float64)
        seeds.add(meta["sensor"]["sensor_seed"])
        np.testing.assert_array_equal(c, read_exr(tmp_path / "b" / "sensor" / f.name)[0])  # bit-identical rerun
        exposure = meta["sensor"]["exposure_used_photons_per_unit"]
    assert len(seeds) == len(counts) == 8  # 4 cameras x 2 frames, each its own stream
    peak = max(r.max() for r in rendered.values())
    assert exposure == pytest.approx(4000 / peak, rel=1e-12)
    names = sorted(rendered)
    # mean counts = exposure x collected power for every image (Poisson: 5 standard errors)
    for n in names:
        expected = exposure * rendered[n].sum()
        assert abs(counts[n].sum() - expected) < 5 * np.sqrt(expected), n
    # shot-noise residuals of two cameras are uncorrelated: |r| < 5 / sqrt(N)
    res = [(counts[n] - exposure * rendered[n]).ravel() for n in names[:2]]
    r = np.corrcoef(res[0], res[1])[0, 1]
    assert abs(r) < 5 / np.sqrt(res[0].size), r


@pytest.mark.parametrize("text, match", [
    (BASE.replace(f'xml = "{SCENE}"', 'xml = "missing.xml"'), "does not exist"),
    (BASE + "\n[plot]\nx = 1\n", "unknown key"),
    (BASE.replace("dt_s = 0.002\n", ""), "dt_s"),
    (BASE.replace("bounds_mm = [-4.0, 4.0, -4.0, 4.0, -1.6, 1.6]", "bounds_mm = [1, 2]"), "bounds_mm"),
    (BASE.replace("seed = 3", "seed = -1"), "seed"),
    (BASE.replace("[flow]", "[flow"), "not valid TOML"),
    (BASE.replace('method = "mart"', 'method = "tomo"'), r"\[reconstruction\] method: 'tomo' is not a valid choice"),
    (BASE.replace("iterations = 3", "iteration = 3"), "Did you mean 'iterations'"),
    (BASE.replace('kind = "uniform"', 'kind = "uniformm"'), "'uniform'"),
    (BASE.replace("velocity_mm_s =", "velocity_mms ="), "Did you mean 'velocity_mm_s'"),
])
def test_bad_experiment_files(tmp_path, text, match):
    with pytest.raises(ConfigError, match=match):
        run_experiment(write(tmp_path, text), tmp_path / "run")
    assert not (tmp_path / "run" / "particles").exists()


def test_sweep_on_a_local_cluster_records_a_failing_point(tmp_path, capsys):
    import pandas as pd

    from mitpiv.studies import run_sweep

    write(tmp_path, BASE.replace("iterations = 3", "iterations = 1"))
    study = write(tmp_path, """name = "iters"
experiment = "exp.toml"
[[points]]
"reconstruction.iterations" = 1
[[points]]
"reconstruction.iterations" = 3
[[points]]
"scene.params.thickness_mm" = -1.0
[plot]
x = "reconstruction.iterations"
y = "frame0.Q"
""", "study.toml")
    df = run_sweep(study, tmp_path / "sweep", workers=2)
    assert list(df["status"]) == ["ok", "ok", "error"]
    # a scene parameter is read by Mitsuba at the render: the third point fails there
    assert "thickness" in df["error"].iloc[2] and df["frame0.Q"].iloc[:2].notna().all()
    q = df["frame0.Q"].iloc[:2]
    assert q.min() > 0.5 and q.iloc[0] != q.iloc[1]  # two reconstructions of the same seeded field
    for p in df["point"].iloc[:2]:
        assert (tmp_path / "sweep" / "points" / p / "report" / "report.md").is_file()
    assert (tmp_path / "sweep" / "sweep.png").stat().st_size > 5000
    table = pd.read_parquet(tmp_path / "sweep" / "results.parquet")
    assert len(table) == 3 and set(pd.read_csv(tmp_path / "sweep" / "results.csv")["status"]) == {"ok", "error"}
    # a rerun (here through the CLI) finds the finished points; only the failed one runs again,
    # fails again, and the sweep exits non-zero listing it
    from mitpiv.cli import main

    assert main(["sweep", str(study), "--out", str(tmp_path / "sweep"), "--workers", "1"]) == 1
    out = capsys.readouterr()
    assert f"failed {df['point'].iloc[2]}" in out.out and "1 of 3 points failed" in out.err
    df2 = pd.read_csv(tmp_path / "sweep" / "results.csv")
    assert df2["frame0.Q"].iloc[:2].tolist() == df["frame0.Q"].iloc[:2].tolist()
    # (a changed base experiment reruns the points: test_faults.py, on the tiny experiment)


def test_bad_study_files(tmp_path):
    from mitpiv.studies import run_sweep

    write(tmp_path, BASE)
    for text, match in (("experiment = \"exp.toml\"\n", "neither"),
                        ("experiment = \"exp.toml\"\n[grid]\n\"seed\" = 3\n", "non-empty list"),
                        ("[grid]\n\"seed\" = [1]\n", "base experiment"),
                        ("experiment = \"exp.toml\"\nfoo = 1\n[grid]\n\"seed\" = [1]\n", "unknown key"),
                        # a bad point is found before any point runs
                        ("experiment = \"exp.toml\"\n[grid]\n\"piv.overlap\" = [0.5, 1.5]\n", "overlap"),
                        # every bad point, in one message
                        ("experiment = \"exp.toml\"\n[grid]\n\"piv.overlap\" = [0.5, 1.5, 2.5]\n",
                         r"(?s)2 of 3 points are invalid \(nothing was run\).*1\.5.*2\.5")):
        with pytest.raises(ConfigError, match=match):
            run_sweep(write(tmp_path, text, "s.toml"), tmp_path / "sw")
        assert not (tmp_path / "sw" / "points").exists()


def test_default_experiment_matches_the_scene_particles(tmp_path):
    """The README's main command runs scenes/tomo4/experiment.toml: its particles and flow
    are those of scenes/tomo4/make_particles.py (same seed, count, box, ring)."""
    import importlib.util

    from mitpiv.studies import load_experiment

    cfg = load_experiment(SCENE.parent / "experiment.toml")
    spec = importlib.util.spec_from_file_location("make_particles", SCENE.parent / "make_particles.py")
    mp = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mp)
    assert tuple(cfg.seeding.box_min_mm) == mp.BOX_MIN and tuple(cfg.seeding.box_max_mm) == mp.BOX_MAX
    assert cfg.flow.dt_s == mp.DT_S and cfg.seeding.proxy_radius_mm == mp.PROXY_RADIUS_MM
    from mitpiv.io import read_truth
    from mitpiv.physics.seeding import seed_box

    s = cfg.seeding.model_dump(exclude={"box_min_mm", "box_max_mm", "proxy_radius_mm", "density_sensor"},
                               exclude_none=True)
    p = seed_box(mp.BOX_MIN, mp.BOX_MAX, seed=cfg.seed, **s)
    mp.main(["--out", str(tmp_path)])  # the scene's own particle script, into a scratch folder
    truth = read_truth(tmp_path / "truth.npz")
    np.testing.assert_array_equal(p.positions_mm, truth["positions_mm"][0])
    flow = {k: v for k, v in cfg.flow.model_dump(exclude_none=True).items() if k != "dt_s"}
    assert all(np.allclose(truth["flow"][k], v) for k, v in flow.items() if k != "kind")


# the killed-worker sweep test is in test_faults.py (a worker killed by its PID mid-point)


def test_near_field_jet_is_a_flow_kind(tmp_path):
    """[flow] kind = "near_field_jet" (mitpiv.physics.jet.NearFieldJet, the lfpiv-vs-tomo
    replication's turbulent jet) configures an experiment: the particles move by the jet's
    velocity (mean shear plus synthetic turbulence: the experiment's 8 substeps against a
    64-step RK4 path, within 1e-4 of the displacement), and the truth file's flow rebuilds the same
    jet. A parameter of another flow kind is refused by name."""
    from mitpiv.io import read_truth
    from mitpiv.physics.flows import flow_from_dict
    from mitpiv.physics.jet import NearFieldJet
    from mitpiv.studies.runner import load_experiment, run_config

    jet = BASE.replace('kind = "uniform"\nvelocity_mm_s = [100.0, 0.0, 0.0]',
                       'kind = "near_field_jet"\ndiameter_mm = 10.0\nexit_velocity_mm_s = 200.0\n'
                       'nozzle_mm = [-10.0, 5.0, 0.0]\nseed = 4')
    cfg = load_experiment(write(tmp_path, jet))
    run_config(cfg, tmp_path / "run", until="particles")
    t = read_truth(tmp_path / "run" / "particles" / "truth.npz")
    p0, p1 = t["positions_mm"]
    ref = NearFieldJet(10.0, 200.0, nozzle_mm=(-10.0, 5.0, 0.0), seed=4)
    q, h = p0.copy(), 0.002 / 64  # the reference path: classical RK4, 64 steps
    for _ in range(64):
        k1 = ref(q)
        k2 = ref(q + 0.5 * h * k1)
        k3 = ref(q + 0.5 * h * k2)
        q = q + h / 6 * (k1 + 2 * k2 + 2 * k3 + ref(q + h * k3))
    disp = p1 - p0
    assert np.linalg.norm(disp - (q - p0)) < 1e-4 * np.linalg.norm(disp)  # measured 1.6e-6
    assert disp[:, 0].max() > 0.3 and np.std(disp[:, 1]) > 0.01  # sheared and turbulent, not uniform
    np.testing.assert_allclose(flow_from_dict(t["flow"])(p0), ref(p0), rtol=1e-12, atol=1e-9)
    with pytest.raises(ConfigError, match="velocity_mm_s"):
        load_experiment(write(tmp_path, jet.replace("seed = 4", "seed = 4\nvelocity_mm_s = [1.0, 0.0, 0.0]"), "bad.toml"))
