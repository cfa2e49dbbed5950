"""Inputs that used to pass silently or fail late now refuse early or say what happened
(the open issue's items that do not fit test_bad_inputs.py's one-line CLI table): empty
particle files, sweep [plot] columns and duplicate points, sensor saturation, MART's inputs,
empty PIV volumes, NaN pixels in ``mitpiv info``, a UTF-8 BOM in a TOML file."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from mitpiv.cli import main
from mitpiv.errors import ConfigError, MitpivWarning

ROOT = Path(__file__).resolve().parents[1]
TOMO4 = ROOT / "scenes" / "tomo4"


def _experiment(tmp_path) -> Path:
    exp = tmp_path / "exp"
    shutil.copytree(TOMO4, exp, ignore=shutil.ignore_patterns("*.ply", "*.npz", "*.py", "*.md"))
    return exp / "experiment.toml"


# ------------------------------------------------------------------- empty particle sets
def test_empty_particle_file_is_refused_at_scene_load(tmp_path):
    """A PLY with no particles loaded before rendering: Dr.Jit failed later with
    'incompatible sizes'."""
    from mitpiv.io import write_particles_ply
    from mitpiv.render.scene import load_scene

    shutil.copy(TOMO4 / "scene.xml", tmp_path / "scene.xml")
    write_particles_ply(tmp_path / "particles_0.ply", np.zeros((0, 3)), 1.0, proxy_radius_mm=0.01)
    with pytest.raises(ConfigError, match=r"particles_0\.ply.*no particles"):
        load_scene(tmp_path / "scene.xml", frame=0)


# ------------------------------------------------------------------------------ sweeps
def _study(exp: Path, body: str) -> Path:
    s = exp.with_name("study.toml")
    s.write_text(f'name = "s"\nexperiment = "{exp.name}"\n{body}')
    return s


@pytest.mark.parametrize("plot, bad", [
    ('x = "reconstruction.iterations"\ny = "frame0Q"', "frame0Q"),          # a result typo
    ('x = "reconstruction.iteration"\ny = "frame0.Q"', "reconstruction.iteration"),  # a parameter typo
    ('x = "reconstruction.iterations"\ny = "frame0.Q"\ngroup = "lable"', "lable"),
])
def test_sweep_plot_columns_are_checked_before_any_point_runs(tmp_path, monkeypatch, plot, bad):
    import dask.distributed

    from mitpiv.studies import run_sweep

    def no_cluster(*a, **k):
        raise AssertionError("the sweep started its points before checking [plot]")

    monkeypatch.setattr(dask.distributed, "LocalCluster", no_cluster)
    exp = _experiment(tmp_path)
    study = _study(exp, f'[plot]\n{plot}\n[grid]\n"reconstruction.iterations" = [3, 4]\n')
    with pytest.raises(ConfigError, match=rf"\[plot\].*{bad}"):
        run_sweep(study, tmp_path / "sw", processes=False)
    assert not (tmp_path / "sw" / "points").exists()


def test_sweep_plot_of_known_columns_passes_the_check(tmp_path):
    from mitpiv.studies.kinds import get_kind
    from mitpiv.studies.sweep import check_plot, load_study

    exp = _experiment(tmp_path)
    st = load_study(_study(exp, '[plot]\nx = "reconstruction.iterations"\ny = "piv.rms_vox"\ngroup = "label"\n'
                                '[[points]]\nlabel = "a"\n"reconstruction.iterations" = 3\n'))
    check_plot(st, get_kind("tomo"), "study.toml")  # a parameter, a result, the label: fine
    st["plot"]["x"] = "param.reconstruction.iterations"  # the table's own column name
    check_plot(st, get_kind("tomo"), "study.toml")
    st["plot"]["x"] = "iterations"  # not a parameter of the points ("reconstruction.iterations" is)
    with pytest.raises(ConfigError, match="did you mean 'reconstruction.iterations'"):
        check_plot(st, get_kind("tomo"), "study.toml")


def test_duplicate_sweep_points_are_run_once_with_a_warning(tmp_path):
    from mitpiv.studies.sweep import load_study

    exp = _experiment(tmp_path)
    study = _study(exp, '[[points]]\n"reconstruction.iterations" = 3\n[[points]]\n"reconstruction.iterations" = 4\n'
                        '[[points]]\n"reconstruction.iterations" = 3\n')
    with pytest.warns(MitpivWarning, match=r"point 3 .*reconstruction\.iterations.*= 3.*point 1"):
        st = load_study(study)
    assert st["points"] == [{"reconstruction.iterations": 3}, {"reconstruction.iterations": 4}]


# ------------------------------------------------------------------------------ sensor
def test_sensor_saturation_is_reported_with_its_fraction():
    from mitpiv.imaging import SensorModel, apply_sensor_set

    img = np.zeros((20, 20))
    img[:10] = 1.0  # half the pixels bright, half dark
    img[10:, :4] = 0.01
    # full well: 1e6 photons into a 20000 e- well
    with pytest.warns(MitpivWarning, match=r"50(\.0)? % of the pixels .*full well.*lower the exposure"):
        apply_sensor_set({("cam0", 0): img}, SensorModel(exposure=1e6, full_well_e=20000.0, bit_depth=16), seed=0)
    # the ADC: 8 bits clip at 255
    with pytest.warns(MitpivWarning, match=r"50(\.0)? % of the pixels .*255"):
        apply_sensor_set({("cam0", 0): img}, SensorModel(exposure=1e4, bit_depth=8), seed=0)
    # below the stated fraction (1 %): silent
    img2 = np.full((20, 20), 0.1)
    img2[0, 0] = 1.0
    apply_sensor_set({("cam0", 0): img2}, SensorModel(exposure=1000.0, bit_depth=8), seed=0)


# ------------------------------------------------------------------------------- MART
def _mart_case():
    from mitpiv.grid import VoxelGrid
    from mitpiv.physics.camera import PinholeCamera

    cams = [PinholeCamera((24, 24), 50.0, 10.0, position_mm=(x, 0.0, -500.0)) for x in (0.0, 20.0)]
    img = np.full((24, 24), 0.05)
    img[10:13, 10:13] = 1.0
    return cams, img, VoxelGrid((0.0, 0.0, 0.0), (0.1, 0.1, 0.1), (6, 6, 6))


def test_mart_refuses_negative_pixels():
    from mitpiv.reconstruct.tomo import mart

    cams, img, grid = _mart_case()
    neg = img.copy()
    neg[0, 0] = -0.5
    with pytest.raises(ConfigError, match=r"images\[1\].*1 negative pixel"):
        mart([img, neg], cams, grid, iterations=1)


def test_mart_with_one_camera_warns_about_depth():
    from mitpiv.reconstruct.tomo import mart

    cams, img, grid = _mart_case()
    with pytest.warns(MitpivWarning, match="one camera.*depth"):
        mart([img], cams[:1], grid, iterations=1)


# -------------------------------------------------------------------------- CLI output
def test_piv_of_empty_volumes_says_they_are_empty(tmp_path, capsys):
    from mitpiv.grid import VoxelGrid
    from mitpiv.io import write_volume

    grid = VoxelGrid((0.0, 0.0, 0.0), (0.1, 0.1, 0.1), (8, 8, 8))
    for n in "ab":
        write_volume(tmp_path / f"{n}.npz", np.zeros(grid.shape, np.float32), {"grid": grid.to_dict()})
    assert main(["piv", str(tmp_path / "a.npz"), str(tmp_path / "b.npz"), "--out", str(tmp_path / "f.npz"),
                 "--windows", "4"]) == 0
    out = capsys.readouterr().out
    assert "nan %" not in out and "are empty (every voxel 0)" in out, out


def test_info_counts_nan_pixels(tmp_path, capsys):
    import OpenEXR

    img = np.ones((6, 8), np.float32)
    img[1, 2] = img[3, 4] = np.nan
    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                      {"Y": img}) as f:
        f.write(str(tmp_path / "nan.exr"))
    assert main(["info", str(tmp_path / "nan.exr")]) == 0
    out = capsys.readouterr().out
    assert "2 NaN pixel" in out and "max 1" in out, out


# ------------------------------------------------------------------------------- TOML
def test_a_utf8_bom_in_a_toml_file_is_accepted(tmp_path):
    from mitpiv.studies import load_experiment

    exp = _experiment(tmp_path)
    exp.write_bytes(b"\xef\xbb\xbf" + exp.read_bytes())
    assert load_experiment(exp).name == "tomo4"


# --------------------------------------------------------------- a stage's own check
def test_a_piv_window_larger_than_the_grid_is_refused_before_a_run_that_reaches_piv(tmp_path):
    """The tiny experiment's grid is 20x20x8 voxels: a 16^3 window cannot be correlated. A
    run that reaches the PIV is refused before any stage runs (and so is --check); a run
    stopped earlier does not need the window and goes on."""
    from mitpiv.studies import load_experiment, run_config
    from mitpiv.studies.runner import check_experiment

    from .studies.helpers import tiny_experiment

    exp = tiny_experiment(tmp_path)
    with pytest.raises(ConfigError, match=r"\[piv\] windows: 16x16x16 voxels .* grid of 20x20x8"):
        check_experiment(exp, {"piv.windows": [16]})
    cfg = load_experiment(exp, {"piv.windows": [16]})
    with pytest.raises(ConfigError, match=r"stop the run before the PIV"):
        run_config(cfg, tmp_path / "full")
    assert not (tmp_path / "full").exists() or not any((tmp_path / "full").iterdir())
    res = run_config(cfg, tmp_path / "part", until="particles")
    assert "particles" in res.stages


def test_an_unknown_sensor_id_is_refused_before_rendering(tmp_path):
    """[render] sensors naming no sensor of the scene: refused by --check and before a run's
    first stage (it failed at the render, after the particles were seeded)."""
    from mitpiv.studies import load_experiment, run_config
    from mitpiv.studies.runner import check_experiment

    from .studies.helpers import tiny_experiment

    exp = tiny_experiment(tmp_path)
    with pytest.raises(ConfigError, match=r"\['cam9'\] not in the scene .*'cam0', 'cam1', 'cam2', 'cam3'"):
        check_experiment(exp, {"render.sensors": ["cam0", "cam9"]})
    with pytest.raises(ConfigError, match="cam9"):
        run_config(load_experiment(exp, {"render.sensors": ["cam9"]}), tmp_path / "run")
    assert not (tmp_path / "run" / "particles").exists()
    assert main(["run", str(exp), "--check", "--set", 'render.sensors=["cam8"]']) == 2
