"""render_scene and the CLI: files, metadata, the `mitpiv info` printout, bad input.

A small two-frame scene XML (one placed camera, a Gaussian sheet, a few particles) is
written to a temporary folder; the particle tracer is deterministic for a pinhole, so
the EXR written by render_scene must equal a direct render of the loaded scene.
"""

import json

import mitsuba as mi
import numpy as np
import pytest

import mitpiv
from mitpiv.cli import main
from mitpiv.errors import ConfigError
from mitpiv.io import read_exr, write_particles_ply, write_truth
from mitpiv.render.scene import load_scene

from .helpers import particle_scene_xml

SCENE = particle_scene_xml("""    <sensor type="distorted_pinhole" id="camA">
        <float name="azimuth_deg" value="30"/>
        <float name="elevation_deg" value="50"/>
        <float name="distance_mm" value="600"/>
        <float name="focal_length_mm" value="85"/>
        <float name="pixel_pitch_um" value="20"/>
        <float name="distortion_percent" value="0.5"/>
        <film type="hdrfilm">
            <integer name="width" value="$resolution"/>
            <integer name="height" value="$resolution"/>
            <string name="pixel_format" value="luminance"/>
        </film>
    </sensor>
""", laser='<float name="thickness" value="3"/><float name="wavelength_nm" value="532"/>',
                           defaults='\n    <default name="resolution" value="32"/>')
TIMES = [0.0, 0.004]


@pytest.fixture
def xml(tmp_path):
    rng = np.random.default_rng(5)
    p0 = rng.uniform(-1.5, 1.5, (40, 3))
    p1 = p0 + [0.1, 0.05, 0.0]
    for k, p in enumerate((p0, p1)):
        write_particles_ply(tmp_path / f"particles_{k}.ply", p, 1.5, proxy_radius_mm=0.01)
    write_truth(tmp_path / "truth.npz", positions_mm=[p0, p1], times_s=TIMES, diameters_um=np.full(40, 1.5))
    path = tmp_path / "scene.xml"
    path.write_text(SCENE)
    return path


def test_render_scene_files_and_metadata(xml, tmp_path):
    out = tmp_path / "out"
    files = mitpiv.render_scene(xml, out_dir=out, frames=(0, 1), params={"resolution": 24}, seed=3, progress=False)
    assert [f.name for f in files] == ["camA_frame000.exr", "camA_frame001.exr"]
    assert all(f.with_suffix(".png").is_file() for f in files)
    assert json.loads((out / "render.json").read_text())["frames"] == [0, 1]
    for f, path in enumerate(files):
        img, meta = read_exr(path)
        assert img.dtype == np.float32 and img.shape == (24, 24)
        ref = np.array(mi.render(load_scene(xml, frame=f, params={"resolution": 24}), seed=3))[..., 0]
        np.testing.assert_array_equal(img, ref)
        assert img.sum() > 0
        assert meta["frame"] == f and meta["time_s"] == TIMES[f]
        assert meta["sensor_id"] == "camA" and meta["seed"] == 3
        assert meta["parameters"] == {"resolution": 24}
        assert meta["variant"] == mi.variant() and meta["mitsuba_version"] == mi.__version__
        assert meta["truth_file"] == str((xml.parent / "truth.npz").resolve())
        assert len(meta["scene_sha256"]) == 64
        assert meta["integrator"]["type"] == "particle_tracer"
        cam = meta["camera"]
        assert cam["distortion"]["k1"] < 0  # 0.5 % barrel
        assert cam["focal_length_mm"] == 85.0 and cam["pixel_pitch_um"] == 20.0
        assert meta["illumination"][0]["thickness_mm"] == 3.0
        assert meta["particles"][0]["type"] == "tracer_particles"
    # frame 1 is frame 0 moved: the images differ
    assert not np.array_equal(read_exr(files[0])[0], read_exr(files[1])[0])


def test_cli_render_and_info(xml, tmp_path, capsys):
    out = tmp_path / "cli"
    assert main(["render", str(xml), "--out", str(out), "--frames", "1", "-D", "resolution=16"]) == 0
    exr = out / "camA_frame001.exr"
    assert exr.is_file() and not (out / "camA_frame000.exr").exists()
    capsys.readouterr()
    assert main(["info", str(exr)]) == 0
    text = capsys.readouterr().out
    head, body = text.split("\n", 1)
    assert "16x16 float32" in head
    meta = json.loads(body)
    assert meta["frame"] == 1 and meta["parameters"] == {"resolution": "16"}


def test_frame_without_particle_file_writes_nothing(xml, tmp_path):
    out = tmp_path / "out"
    with pytest.raises(ConfigError, match=r"frame 7: particle file .*particles_7\.ply"):
        mitpiv.render_scene(xml, out_dir=out, frames=(0, 7), progress=False)
    assert not out.exists() or not any(out.iterdir())


def test_malformed_particle_file_writes_nothing(xml, tmp_path):
    (xml.parent / "particles_1.ply").write_text("ply\nformat ascii 1.0\nend_header\n1 2 3\n")
    out = tmp_path / "out"
    with pytest.raises(ConfigError, match=r"frame 1: .*particles_1\.ply"):
        mitpiv.render_scene(xml, out_dir=out, frames=(0, 1), progress=False)
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize(
    "argv, match",
    [
        (["-D", "resolution"], "-D expects name=value"),
        (["--frames", "9"], "particle file"),
        (["--spp", "0"], "'spp' must be a positive integer"),
        (["-D", "resolution=-4"], "scene"),
    ],
    ids=["define_without_value", "missing_frame", "zero_spp", "bad_resolution"],
)
def test_cli_errors_are_one_line_and_exit_2(xml, tmp_path, capsys, argv, match):
    out = tmp_path / "o"
    assert main(["render", str(xml), "--out", str(out), *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("mitpiv: error:") and match in err and "\n" not in err
    assert not out.exists() or not any(out.iterdir())


def test_render_scene_rejects_missing_scene(tmp_path):
    with pytest.raises(ConfigError, match="scene file .*nope.xml.* does not exist"):
        mitpiv.render_scene(tmp_path / "nope.xml", out_dir=tmp_path / "o")


def test_cli_sensor_writes_integer_images(xml, tmp_path, capsys):
    out = tmp_path / "r"
    assert main(["render", str(xml), "--out", str(out), "--frames", "0", "-D", "resolution=16"]) == 0
    exr = out / "camA_frame000.exr"
    img, _ = read_exr(exr)
    sens = tmp_path / "s"
    assert main(["sensor", str(exr), "--out", str(sens), "--format", "exr", "--bit-depth", "8",
                 "--peak-photons", "200"]) == 0
    from mitpiv.io.counts import read_counts

    counts, meta = read_counts(sens / "camA_frame000.exr")
    expected = np.clip(np.rint(img.astype(np.float64) * 200 / img.max()), 0, 255)
    assert np.array_equal(counts, expected) and meta["sensor_model"]["bit_depth"] == 8
    assert meta["sensor_id"] == "camA"  # the render metadata travels along
    assert main(["sensor", str(exr), "--out", str(sens), "--format", "png", "--bit-depth", "16", "--peak-photons", "1000",
                 "--shot-noise", "--read-noise", "3"]) == 0
    assert read_counts(sens / "camA_frame000.png")[0].dtype == np.uint16
    # Bad input: one line, status 2, nothing written.
    bad = tmp_path / "bad"
    capsys.readouterr()
    assert main(["sensor", str(exr), str(tmp_path / "missing.exr"), "--out", str(bad)]) == 2
    assert main(["sensor", str(exr), "--out", str(bad), "--bit-depth", "9"]) == 2
    assert "bit_depth" in capsys.readouterr().err
    assert not bad.exists()


def test_the_metadata_says_what_a_pixel_value_is_per_camera(xml, tmp_path):
    """A pinhole records radiance averaged over the pixel; a plenoptic camera records sensor
    irradiance (its own model says so): the EXR's units follow the camera, not one string."""
    from mitpiv.render.render import PIXEL_UNITS

    plen = particle_scene_xml("""    <sensor type="plenoptic" id="plen">
        <float name="pixel_pitch_um" value="5.5"/>
        <float name="focal_length_mm" value="50"/>
        <float name="f_number" value="2.8"/>
        <float name="focus_distance_mm" value="250"/>
        <float name="mla_pitch_um" value="55"/>
        <transform name="to_world"><lookat origin="0, 0, 250" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm">
            <integer name="width" value="40"/>
            <integer name="height" value="40"/>
            <string name="pixel_format" value="luminance"/>
            <rfilter type="box"/>
        </film>
    </sensor>
""", laser='<float name="thickness" value="3"/>')
    (xml.parent / "plen.xml").write_text(plen)
    _, meta_pin = read_exr(mitpiv.render_scene(xml, out_dir=tmp_path / "a", frames=(0,), progress=False)[0])
    _, meta_plen = read_exr(mitpiv.render_scene(xml.parent / "plen.xml", out_dir=tmp_path / "b", frames=(0,),
                                                progress=False)[0])
    assert meta_pin["units"]["pixel_value"] == PIXEL_UNITS and "radiance" in PIXEL_UNITS
    assert meta_plen["units"]["pixel_value"] == meta_plen["camera"]["pixel_value"]
    assert meta_plen["units"]["pixel_value"].startswith("sensor irradiance [W/mm^2]")
