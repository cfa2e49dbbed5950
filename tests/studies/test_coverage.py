"""The measurement volume in the cameras' view (issue 54, item 3): ``box_coverage`` against
a closed form, and ``mitpiv run --check`` and a run refusing a volume no camera sees and
warning about one a camera cuts, with the numbers of the committed scenes."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from mitpiv.cli import main
from mitpiv.errors import ConfigError, MitpivWarning
from mitpiv.physics.camera import PinholeCamera, box_coverage

from .helpers import ROOT, tiny_experiment


def _down(x_mm: float = 0.0) -> PinholeCamera:
    """A camera 100 mm above (x_mm, 0, 0) looking down -z (rotation: camera z = world -z):
    100 x 100 px of 10 um behind a 10 mm lens, so its field at z = 0 is
    +-(0.5 mm / 10 mm) * 100 mm = +-5 mm about x_mm."""
    rot = np.diag([1.0, -1.0, -1.0])
    return PinholeCamera((100, 100), 10.0, 10.0, rotation=rot, position_mm=np.array([x_mm, 0.0, 100.0]))


def test_box_coverage_against_the_field_of_view():
    # a thin box from x = 0 to 10 mm: the camera's field ends at x = 5 mm, a cell boundary of
    # the 16 cells, so exactly half the cell centres are seen (no cell straddles the edge)
    thin = ((0.0, -1.0, -1e-3), (10.0, 1.0, 1e-3))
    cov = box_coverage({"a": _down()}, *thin)
    assert cov["cameras"]["a"]["fraction"] == pytest.approx(0.5, abs=1e-12)
    # the corners: x = 0 at the image centre column 50, x = 10 mm at column 150, off the sensor
    uv = cov["cameras"]["a"]["corners_px"]
    # (the corners' +-1 um depth moves them by 1e-3 px)
    np.testing.assert_allclose(uv[:, 0], [50.0, 150.0] * 4, atol=2e-3)
    np.testing.assert_allclose(uv[:, 1], [60.0, 60.0, 40.0, 40.0] * 2, atol=2e-3)
    assert cov["cameras"]["a"]["corners_visible"].tolist() == [True, False] * 4
    # two cameras, fields [-5, 5] and [1.25, 11.25]: every camera sees x in [1.25, 5], 3/8 of the box
    two = box_coverage({"a": _down(), "b": _down(6.25)}, *thin)
    assert two["cameras"]["b"]["fraction"] == pytest.approx(7 / 8, abs=1e-12)
    assert two["common"] == pytest.approx(3 / 8, abs=1e-12)
    lo, hi = two["common_box_mm"]
    assert (lo[0], hi[0]) == pytest.approx((1.25, 5.0), abs=1e-9)
    # a box behind the camera is seen by nobody
    behind = box_coverage({"a": _down()}, (-1, -1, 150), (1, 1, 160))
    assert behind["common"] == 0.0 and behind["common_box_mm"] is None
    assert np.isnan(behind["cameras"]["a"]["corners_px"]).all()


@pytest.mark.parametrize("bad", [{"box_min_mm": (0, 0, 0), "box_max_mm": (1, -1, 1)},
                                 {"box_min_mm": (0, 0), "box_max_mm": (1, 1)},
                                 {"box_min_mm": (0, 0, np.nan), "box_max_mm": (1, 1, 1)},
                                 {"box_min_mm": (0, 0, 0), "box_max_mm": (1, 1, 1), "samples": 0}])
def test_box_coverage_refuses_bad_boxes(bad):
    with pytest.raises(ConfigError, match="box_coverage"):
        box_coverage({"a": _down()}, **bad)


def test_check_refuses_a_volume_no_camera_sees_and_warns_about_a_cut_one(tmp_path, capsys):
    from mitpiv.studies.runner import check_experiment

    exp = tiny_experiment(tmp_path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the tiny volume lies in the view of both cameras: no message
        check_experiment(exp)
    # the issue's case: a volume far larger than the cameras' field (+-60 mm against about
    # +-4 mm) is a warning that names each camera's share and a box every camera sees
    with pytest.warns(MitpivWarning, match=r"\[reconstruction\] bounds_mm .* camera 'cam0' sees [0-9] % of it .*"
                                           r"corners off its 80x80 sensor.* every camera, within about x"):
        check_experiment(exp, {"reconstruction.bounds_mm": [-60, 60, -60, 60, -1.6, 1.6]})
    # a volume beside the view: refused, before anything runs
    with pytest.raises(ConfigError, match=r"bounds_mm .* sees 0 % .* no point of it is seen by every camera"):
        check_experiment(exp, {"reconstruction.bounds_mm": [200, 240, -4, 4, -1.6, 1.6]})
    assert main(["run", str(exp), "--check", "--set", "reconstruction.bounds_mm=[200,240,-4,4,-1.6,1.6]"]) == 2
    assert "mitpiv: error: experiment 'tiny': [reconstruction] bounds_mm" in capsys.readouterr().err


def test_a_run_checks_the_rendered_cameras_before_reconstructing(tmp_path):
    """Without --check, the reconstruction stage checks the volume against the cameras of
    the rendered images, before the reconstruction (the render ran; no volume is written)."""
    from mitpiv.studies import load_experiment, run_config

    cfg = load_experiment(tiny_experiment(tmp_path), {"reconstruction.bounds_mm": [200, 240, -4, 4, -1.6, 1.6]})
    with pytest.raises(ConfigError, match=r"sees 0 %"):
        run_config(cfg, tmp_path / "run")
    assert (tmp_path / "run" / "render").is_dir() and not (tmp_path / "run" / "reconstruct").exists()


def test_tracking_check_uses_the_measurement_box(tmp_path):
    from mitpiv.studies.runner import check_experiment

    exp = ROOT / "scenes" / "tracking_lpt" / "tiny.toml"
    with pytest.raises(ConfigError, match=r"\[tracking\] bounds_mm .* sees 0 %"):
        check_experiment(exp, {"tracking.bounds_mm": [200, 240, -10, 10, -10, 10]})


def test_committed_paper_scene_is_warned_about_as_measured():
    """The multi-plenoptic paper scene's volume (2.0 x 2.0 x 3.4 mm) is larger than the
    two light-field cameras' common view: --check says so (70 % seen by both, each 85 %);
    every other committed tomo scene's volume lies in its cameras' view."""
    from mitpiv.studies.runner import check_experiment

    with pytest.warns(MitpivWarning, match=r"camera 'plen0' sees (8[0-9]) % .* ([67][0-9]) % of it is seen by every"):
        check_experiment(ROOT / "scenes" / "multiplenoptic_paper" / "experiment.toml")
    with warnings.catch_warnings():
        warnings.simplefilter("error", MitpivWarning)
        for name in ("tomo4", "lfpiv_tomo_paper", "sapiv_paper"):
            check_experiment(ROOT / "scenes" / name / "experiment.toml")


def test_a_scene_names_files_beside_itself_wherever_the_run_starts(tmp_path, monkeypatch):
    """A relative file name in the scene XML (a sensor's OpenCV calibration) is found beside
    the XML when the run renders its copy of the XML in the run folder, from any working
    folder (it was looked up beside the copy and in the working folder)."""
    import re

    from mitpiv.io.opencv import write_opencv_camera
    from mitpiv.studies import load_experiment, run_config
    from mitpiv.studies.shared import scene_cameras

    scene = tmp_path / "rig"
    scene.mkdir()
    cfg = load_experiment(tiny_experiment(tmp_path))
    write_opencv_camera(scene / "cam0.yml", scene_cameras(cfg)["cam0"])
    xml = (ROOT / "scenes" / "tomo4" / "scene.xml").read_text()
    # cam0 from the calibration file (its pose included) instead of its placement
    cam0 = re.search(r'<sensor type="distorted_pinhole" id="cam0">.*?</sensor>', xml, re.S).group(0)
    new = re.sub(r'\s*<float name="(azimuth_deg|elevation_deg|distance_mm|focal_length_mm|pixel_pitch_um|distortion_percent)"[^>]*/>', "",
                 cam0).replace('<ref id="film"/>', '<string name="calibration" value="cam0.yml"/>\n<ref id="film"/>')
    (scene / "scene.xml").write_text(xml.replace(cam0, new))
    exp = tiny_experiment(tmp_path, xml=scene / "scene.xml", name="calibrated.toml")
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    res = run_config(load_experiment(exp), tmp_path / "run", until="render")
    assert "render" in res.stages and len(list((tmp_path / "run" / "render").glob("cam0_frame*.exr"))) == 2
    # the calibration file is an input of the render: part of its key
    from mitpiv.studies.shared import scene_files

    assert (scene / "cam0.yml").resolve() in [f.resolve() for f in scene_files(load_experiment(exp))]
