"""Silent black results (issue 30 item 8): sensor images without particle signal are refused
(CLI, experiment) or reported, and metrics without a value are null with a reason, never NaN."""

import math

import numpy as np
import pytest

from mitpiv.errors import ConfigError, MitpivWarning
from mitpiv.imaging import SensorModel, apply_sensor_set
from mitpiv.io import write_exr


def _particle_image(rng, shape=(48, 48), n=30, peak=2e-5):
    """A rendered-looking image: Gaussian spots of radiance ~1e-5 (W sr^-1 mm^-2), as the
    renderer gives for micron particles."""
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]] + 0.5
    img = np.zeros(shape)
    for u, v in rng.uniform(4, shape[0] - 4, (n, 2)):
        img += peak * np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / 2.0)
    return img


def test_cli_sensor_without_exposure_refuses_all_black_images(tmp_path, capsys):
    from mitpiv.cli import main

    rng = np.random.default_rng(1)
    files = []
    for cam in ("cam0", "cam1"):
        files.append(tmp_path / f"{cam}_frame000.exr")
        write_exr(files[-1], _particle_image(rng).astype(np.float32), {"sensor_id": cam, "frame": 0})
    out = tmp_path / "counts"
    # radiance taken as photons (no --exposure): the brightest pixel is 2e-5 counts, all round to 0
    assert main(["sensor", *map(str, files), "--out", str(out), "--bit-depth", "8", "--noise-percent", "5"]) == 2
    err = capsys.readouterr().err
    assert "no particle signal" in err and "--exposure" in err
    assert not out.exists() or not any(out.iterdir())  # nothing written
    # with an exposure the same images are fine
    assert main(["sensor", *map(str, files), "--out", str(out), "--bit-depth", "8", "--peak-photons", "200"]) == 0
    assert len(list(out.iterdir())) == 2


def test_sensor_set_reports_degenerate_images():
    rng = np.random.default_rng(2)
    bright, dark = _particle_image(rng), np.zeros((48, 48))
    images = {("cam0", 0): bright, ("cam1", 0): dark}
    m = SensorModel(peak_photons=200.0, bit_depth=8)
    with pytest.warns(MitpivWarning, match="1 of 2 sensor image"):
        res = apply_sensor_set(images, m, seed=0)
    assert set(res.degenerate) == {("cam1", 0)} and "rendered image is black" in res.degenerate[("cam1", 0)]
    # saturated everywhere
    res = apply_sensor_set({("c", 0): np.ones((8, 8))}, SensorModel(exposure=1e4, bit_depth=8), seed=0,
                           on_degenerate="ignore")
    assert "saturates at 255" in res.degenerate[("c", 0)]
    # every image black: "raise" refuses, naming the fix
    with pytest.raises(ConfigError, match="exposure"):
        apply_sensor_set({("cam0", 0): bright}, SensorModel(bit_depth=8, gaussian_noise_percent=5.0), seed=0,
                         on_degenerate="raise")


def test_metrics_without_a_value_are_null_with_a_reason():
    from mitpiv.studies.kinds.tomo import headline
    from mitpiv.studies.shared import null_metrics

    m = {"Q": 0.5, "piv": {"rms_vox": [math.nan, 0.1, math.inf], "n": 0, "bias": math.nan}, "ok": None}
    with pytest.warns(MitpivWarning, match="2 metric"):
        out = null_metrics(m, {"piv": "0 valid vectors"}, where="piv")
    assert out["piv"]["rms_vox"] == [None, 0.1, None] and out["piv"]["bias"] is None and out["Q"] == 0.5
    assert out["null_reasons"] == {"piv.rms_vox": "0 valid vectors", "piv.bias": "0 valid vectors"}
    assert "nan" not in repr(out).lower()
    text = headline({"name": "x", "evaluate": {"frame0": {"Q": None, "particles": {"detection_rate": None},
                                                          "null_reasons": {"Q": "empty volume"}}},
                     "piv": {"rms_vox": [None, None, None]}})
    assert "Q n/a" in text and "empty volume" in text and "nan" not in text.lower()


def test_experiment_with_8_bit_noise_and_no_exposure_is_refused_before_rendering(tmp_path):
    """The issue's case: 8-bit output and 5 % noise without an exposure used to round every
    image to 0 and end with Q 0.000 and a NaN PIV error, exit 0."""
    from pathlib import Path

    from mitpiv.studies import load_experiment, run_config

    scene = Path(__file__).resolve().parents[1] / "scenes" / "tomo4" / "scene.xml"
    exp = tmp_path / "exp.toml"
    exp.write_text(f"""name = "black"
seed = 1
[scene]
xml = "{scene}"
params = {{ resolution = 48, thickness_mm = 4 }}
[seeding]
box_min_mm = [-3.0, -3.0, -1.0]
box_max_mm = [3.0, 3.0, 1.0]
count = 60
[flow]
kind = "uniform"
velocity_mm_s = [100.0, 0.0, 0.0]
dt_s = 0.002
[render]
sensors = ["cam0", "cam1"]
[reconstruction]
bounds_mm = [-3.0, 3.0, -3.0, 3.0, -1.0, 1.0]
voxel_mm = 0.2
[piv]
windows = [8]
[sensor]
bit_depth = 8
gaussian_noise_percent = 5.0
""")
    # refused when the experiment is validated (mitpiv run --check), before anything renders
    with pytest.raises(ConfigError, match="bit_depth = 8 with noise .*no 'exposure', 'peak_photons' or 'illumination_time_s'"):
        run_config(load_experiment(exp), tmp_path / "run", until="sensor")
    assert not (tmp_path / "run").exists()


def test_an_empty_volume_has_null_quality_not_zero(tmp_path):
    """The evaluate stage of a run whose reconstruction is empty: Q is null with the reason
    (it read 0.000 before, as if measured), and nothing is NaN."""
    from pathlib import Path

    from mitpiv.io import write_truth, write_volume
    from mitpiv.studies import load_experiment
    from mitpiv.studies.kinds.tomo import stage_evaluate
    from mitpiv.studies.shared import StageContext, grid_of

    scene = Path(__file__).resolve().parents[1] / "scenes" / "tomo4" / "scene.xml"
    exp = tmp_path / "exp.toml"
    exp.write_text(f"""name = "empty"
[scene]
xml = "{scene}"
[seeding]
box_min_mm = [-1.0, -1.0, -1.0]
box_max_mm = [1.0, 1.0, 1.0]
count = 5
[flow]
kind = "uniform"
velocity_mm_s = [100.0, 0.0, 0.0]
dt_s = 0.002
[reconstruction]
bounds_mm = [-1.0, 1.0, -1.0, 1.0, -1.0, 1.0]
voxel_mm = 0.2
[piv]
windows = [8]
""")
    cfg = load_experiment(exp)
    grid = grid_of(cfg)
    run = tmp_path / "run"
    pts = np.random.default_rng(3).uniform(-0.8, 0.8, (5, 3))
    write_truth(run / "particles" / "truth.npz", positions_mm=[pts, pts + [0.2, 0, 0]], times_s=[0.0, 0.002],
                diameters_um=np.ones(5))
    for frame in (0, 1):
        write_volume(run / "reconstruct" / f"volume_{frame}.npz", np.zeros(grid.shape), {"grid": grid.to_dict()})
    (run / "evaluate").mkdir()
    ctx = StageContext(cfg=cfg, run_dir=run, out=run / "evaluate", results={}, timings={})
    with pytest.warns(MitpivWarning, match="metric"):
        m = stage_evaluate(ctx)
    assert m["frame0"]["Q"] is None and "volume of frame 0 is empty" in m["frame0"]["null_reasons"]["Q"]
    assert "nan" not in repr(m).lower()
