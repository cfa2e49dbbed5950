"""DaVis interop through LaVision's lvpyio (issue 52, item 1): image sets, vector fields,
particle fields, and the export of a run.

Independent references: lvpyio itself (LaVision's reader: the files are opened with its
``read_set`` / ``read_buffer`` / ``read_particles`` and their raw components compared), its own
coordinate rule (``lvpyio.types.plot_utils.scaled_coordinate``, the vector position DaVis
plots), a DaVis-style vector buffer built here directly with lvpyio (grid 16, y pointing up:
the layout DaVis writes) rather than with mitpiv's writer, and for the export the run's own
EXR images, truth file and camera models.
"""

from __future__ import annotations

import json

import lvpyio as lv
import numpy as np
import pytest
from lvpyio.types.plot_utils import scaled_coordinate

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.io.davis import (
    read_davis_images,
    read_davis_particles,
    read_davis_vectors,
    write_davis_images,
    write_davis_particles,
    write_davis_vectors,
)

#: float32 storage of a value of magnitude ~1: relative precision of a float32.
F32 = 2e-7
#: Frame times are written with 3 decimals of a microsecond.
TIME_S = 1e-9


def _images(n_cam=3, n_frames=3, shape=(12, 16), seed=0):
    return np.random.default_rng(seed).integers(0, 4096, (n_cam, n_frames, *shape)).astype(np.uint16)


# ------------------------------------------------------------------------------------ images
def test_image_set_round_trip_pixels_times_cameras(tmp_path):
    imgs = _images()
    times = [0.0, 1.25e-4, 2.0e-3]
    m = write_davis_images(tmp_path / "d", imgs, sensors=["cam0", "cam1", "cam2"], times_s=times)
    assert m["dtype"] == "uint16" and m["n_cameras"] == 3 and m["n_frames"] == 3
    for where in (tmp_path / "d", tmp_path / "d" / "Images.set", tmp_path / "d" / "Images"):
        r = read_davis_images(where)
        assert r["images"].dtype == np.uint16 and r["images"].shape == imgs.shape
        assert np.array_equal(r["images"], imgs)
        np.testing.assert_allclose(r["times_s"], times, atol=TIME_S, rtol=0)
        assert r["sensors"] == ["cam0", "cam1", "cam2"] and r["pixel_unit"] == "pixel"
    # LaVision's reader: one buffer per time step, one frame per camera, the time attribute
    s = lv.read_set(str(tmp_path / "d" / "Images.set"))
    assert s.type_id == "SET_TYPE_ID_IMAGE" and len(s) == 3
    b = s[2]
    assert len(b) == 3
    assert np.array_equal(b[1].components["PIXEL"].planes[0], imgs[1, 2])
    assert b[1].attributes["CameraName"] == "cam1"
    assert b[1].attributes["AcqTimeSeries"] == "2000.000 µs"
    # one buffer on its own reads too
    one = read_davis_images(tmp_path / "d" / "Images" / "B00002.im7")
    assert np.array_equal(one["images"][:, 0], imgs[:, 1]) and one["times_s"][0] == pytest.approx(1.25e-4, abs=TIME_S)


def test_non_integer_images_are_kept_as_float32(tmp_path):
    radiance = np.random.default_rng(1).random((2, 1, 6, 5)) * 1e-3
    m = write_davis_images(tmp_path / "d", radiance, sensors=["a", "b"], times_s=[0.5])
    r = read_davis_images(tmp_path / "d")
    assert m["dtype"] == "float32" and r["images"].dtype == np.float32
    assert np.array_equal(r["images"], radiance.astype(np.float32))


def test_image_write_leaves_the_folder_untouched_on_failure(tmp_path, monkeypatch):
    out = tmp_path / "d"
    old = _images(1, 1, seed=5)
    write_davis_images(out, old, sensors=["a"], times_s=[0.0])  # an earlier export, to be overwritten
    with pytest.raises(ConfigError, match="times_s"):
        write_davis_images(out, _images(), sensors=["a", "b", "c"], times_s=[0.0, 1.0])
    monkeypatch.setattr(lv, "write_set", lambda *a, **k: (_ for _ in ()).throw(OSError("disk full")))
    with pytest.raises(OSError, match="disk full"):
        write_davis_images(out, _images(), sensors=["a", "b", "c"], times_s=[0.0, 1.0, 2.0])
    assert [p.name for p in tmp_path.iterdir()] == ["d"]  # no temporary folder left
    assert np.array_equal(read_davis_images(out)["images"], old)


def test_a_folder_of_other_files_is_never_replaced(tmp_path, davis_run):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("keep")
    with pytest.raises(ConfigError, match="holds other files"):
        write_davis_images(mine, _images(), sensors=["a", "b", "c"], times_s=[0.0, 1.0, 2.0])
    with pytest.raises(ConfigError, match="holds other files"):
        write_davis_particles(mine, np.zeros((1, 2, 3)), [0.0, 1.0])
    assert [p.name for p in mine.iterdir()] == ["notes.txt"]
    from mitpiv.studies.export_davis import export_davis

    run = davis_run[0]
    for out in (run, run.parent):  # the run folder itself, or a folder holding it
        with pytest.raises(ConfigError, match="is the run folder or holds it"):
            export_davis(run, out, calibration=False)
    assert (run / "experiment.json").is_file()


# ----------------------------------------------------------------------------------- vectors
def _davis_style_buffer(path, *, three_c=True, nz=3, ny=5, nx=4):
    """A vector buffer laid out as DaVis writes one, built with lvpyio alone: grid 16 px, 0.05
    mm per px, y up (negative slope), 0.02 m/s per stored unit, one disabled vector."""
    rng = np.random.default_rng(2)
    raw = np.zeros((nz, ny, nx), dtype=lv.vec3c if three_c else lv.vec2c)
    for c in ("u", "v", "w") if three_c else ("u", "v"):
        raw[c] = rng.normal(0, 5, (nz, ny, nx))
    b = lv.arrays_to_buffer(raw)
    fr = b[0]
    fr.grid.x = fr.grid.y = fr.grid.z = 16
    sx, sy, sz, si = fr.scales.x, fr.scales.y, fr.scales.z, fr.scales.i
    sx.slope, sx.offset, sx.unit = 0.05, -10.0, "mm"
    sy.slope, sy.offset, sy.unit = -0.05, 8.0, "mm"
    sz.slope, sz.offset, sz.unit = 0.05, -2.0, "mm"
    si.slope, si.offset, si.unit = 0.02, 0.0, "m/s"
    fr.components["ENABLED"].planes[0][1, 2] = 0
    b.attributes["FrameDt"] = "250 µs"
    lv.write_buffer(b, str(path))
    return raw


def test_davis_style_3d_volume_reads_in_world_units(tmp_path):
    raw = _davis_style_buffer(tmp_path / "v.vc7")
    r = read_davis_vectors(tmp_path / "v.vc7")
    fr = lv.read_buffer(str(tmp_path / "v.vc7"))[0]
    x_ref = np.array([scaled_coordinate(i, "x", fr.scales, fr.grid) for i in range(4)])
    y_ref = np.array([scaled_coordinate(j, "y", fr.scales, fr.grid) for j in range(5)])  # top row first
    z_ref = (np.arange(3) + 0.5) * 16 * 0.05 - 2.0
    np.testing.assert_allclose(r.x, x_ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(r.y, y_ref[::-1], rtol=0, atol=1e-12)  # ascending: the rows reversed
    np.testing.assert_allclose(r.z, z_ref, rtol=0, atol=1e-12)
    assert (r.length_unit, r.velocity_unit, r.n_components) == ("mm", "m/s", 3)
    assert r.dt_s == pytest.approx(2.5e-4, rel=1e-12)
    assert r.u.shape == r.v.shape == r.w.shape == r.enabled.shape == (3, 5, 4)
    # the disabled vector: plane 0, row 1 from the top = row 3 once y ascends
    assert not r.enabled[0, 3, 2] and np.isnan(r.u[0, 3, 2]) and r.enabled.sum() == 3 * 5 * 4 - 1
    ok = r.enabled
    u_ref = (raw["u"] * 0.02)[:, ::-1]
    v_ref = (-raw["v"] * 0.02)[:, ::-1]  # stored along the rows (down); world y points up
    w_ref = (raw["w"] * 0.02)[:, ::-1]
    for got, ref in ((r.u, u_ref), (r.v, v_ref), (r.w, w_ref)):
        np.testing.assert_allclose(got[ok], ref[ok], rtol=F32, atol=F32 * np.abs(ref).max())


def test_davis_style_planar_2c_field(tmp_path):
    _davis_style_buffer(tmp_path / "p.vc7", three_c=False, nz=1)
    r = read_davis_vectors(tmp_path / "p.vc7")
    assert r.n_components == 2 and r.z.shape == (1,) and r.z[0] == -2.0
    assert r.u.shape == (1, 5, 4) and np.all(r.w == 0)  # zeros, also where a vector is disabled
    assert not r.enabled[0, 3, 2] and np.isnan(r.u[0, 3, 2]) and np.isnan(r.v[0, 3, 2])


@pytest.mark.parametrize("planar", [False, True])
def test_vector_write_read_round_trip(tmp_path, planar):
    rng = np.random.default_rng(3)
    nz = 1 if planar else 4
    x, y, z = np.linspace(-6, 6, 7), np.linspace(-2.5, 3.5, 5), np.linspace(-1.2, 1.2, nz) if not planar else None
    u, v = rng.normal(0, 0.3, (2, nz, 5, 7))
    w = None if planar else rng.normal(0, 0.3, (nz, 5, 7))
    u[0, 1, 1] = np.nan
    f = write_davis_vectors(tmp_path / "f.vc7", x, y, z, u, v, w, dt_s=1e-3)
    r = read_davis_vectors(f)
    np.testing.assert_allclose(r.x, x, atol=1e-12)
    np.testing.assert_allclose(r.y, y, atol=1e-12)
    np.testing.assert_allclose(r.z, [0.0] if planar else z, atol=1e-12)
    ok = np.isfinite(u)
    assert np.array_equal(r.enabled, ok) and np.isnan(r.v[0, 1, 1])
    np.testing.assert_allclose(r.u[ok], u[ok], rtol=F32, atol=F32)
    np.testing.assert_allclose(r.v[ok], v[ok], rtol=F32, atol=F32)
    if not planar:
        np.testing.assert_allclose(r.w[ok], w[ok], rtol=F32, atol=F32)
    assert (r.length_unit, r.velocity_unit, r.n_components) == ("mm", "m/s", 2 if planar else 3)
    assert r.dt_s == pytest.approx(1e-3, rel=1e-9)
    # as LaVision's reader sees it: the top row is the largest y, v positive up
    fr = lv.read_buffer(str(f))[0]
    assert fr.scales.y.slope < 0
    top = scaled_coordinate(0, "y", fr.scales, fr.grid)
    assert top == pytest.approx(y[-1], abs=1e-12)
    np.testing.assert_allclose(fr.as_masked_array(0)["v"][0].filled(np.nan)[1:], v[0, -1, 1:], rtol=F32, atol=F32)


# --------------------------------------------------------------------------------- particles
def test_particle_tracks_round_trip(tmp_path):
    rng = np.random.default_rng(4)
    pos = rng.uniform(-5, 5, (4, 5, 3))
    vel = rng.normal(0, 100, (4, 5, 3))
    pos[1, :2] = np.nan  # starts at frame 2
    pos[2, 3:] = np.nan  # ends at frame 2
    vel[np.isnan(pos)] = np.nan
    times = np.array([0.0, 1e-3, 2e-3, 3e-3, 4.5e-3])
    f = write_davis_particles(tmp_path / "p", pos, times, velocities_mm_s=vel)
    r = read_davis_particles(f)
    assert r["positions_mm"].shape == (4, 5, 3)
    assert np.array_equal(np.isnan(r["positions_mm"]), np.isnan(pos))
    ok = np.isfinite(pos)
    np.testing.assert_allclose(r["positions_mm"][ok], pos[ok], rtol=F32, atol=F32 * 5)
    np.testing.assert_allclose(r["velocities_mm_s"][ok], vel[ok], rtol=F32, atol=F32 * 300)
    np.testing.assert_allclose(r["times_s"], times, rtol=0, atol=1e-15)
    assert list(r["track_start"]) == [0, 2, 0, 0] and r["length_unit"] == "mm"
    # LaVision's reader: the velocity scalars in m/s
    pf = lv.read_particles(str(f))
    assert pf.track_count == 4 and pf.scalar_scales["Vx"].unit == "m/s"
    t1 = pf.tracks()[1]
    assert t1.start == 2 and len(t1) == 3
    assert t1.scalars["Vy"][0] == pytest.approx(vel[1, 2, 1] / 1000, rel=1e-6)


def test_particle_track_with_a_gap_is_refused(tmp_path):
    pos = np.zeros((2, 4, 3))
    pos[1, 1] = np.nan
    with pytest.raises(ConfigError, match="track 1 .*contiguous"):
        write_davis_particles(tmp_path / "p", pos, [0, 1, 2, 3])
    assert not (tmp_path / "p").exists()


# -------------------------------------------------------------------------------- bad inputs
def test_bad_inputs_name_the_parameter_and_the_fix(tmp_path):
    with pytest.raises(FileFormatError, match="'path' .*nope.vc7.* does not exist"):
        read_davis_vectors(tmp_path / "nope.vc7")
    junk = tmp_path / "junk.vc7"
    junk.write_text("not a DaVis file")
    with pytest.raises(FileFormatError, match="not a DaVis file"):
        read_davis_vectors(junk)
    with pytest.raises(FileFormatError, match="not a DaVis set"):
        read_davis_images(tmp_path)  # a folder without a set
    write_davis_images(tmp_path / "img", _images(1, 2), sensors=["a"], times_s=[0, 1])
    with pytest.raises(FileFormatError, match="not a vector set"):
        read_davis_vectors(tmp_path / "img")
    with pytest.raises(FileFormatError, match="not a DaVis particle field"):
        read_davis_particles(tmp_path / "img")
    write_davis_particles(tmp_path / "pf", np.zeros((1, 2, 3)), [0, 1])
    with pytest.raises(FileFormatError, match="particle field.*read_davis_particles"):
        read_davis_vectors(tmp_path / "pf")
    vc = write_davis_vectors(tmp_path / "v.vc7", [0, 1], [0, 1], None, np.zeros((2, 2)), np.zeros((2, 2)))
    with pytest.raises(FileFormatError, match="read_davis_vectors"):
        read_davis_images(vc)
    with pytest.raises(ConfigError, match="'frame' must be 0"):
        read_davis_vectors(vc, frame=1)
    with pytest.raises(ConfigError, match="'v' has shape"):
        write_davis_vectors(tmp_path / "w.vc7", [0, 1], [0, 1], None, np.zeros((2, 2)), np.zeros((3, 2)))
    with pytest.raises(ConfigError, match="'x' must be ascending with a uniform spacing"):
        write_davis_vectors(tmp_path / "w.vc7", [0, 1, 3], [0, 1], None, np.zeros((2, 3)), np.zeros((2, 3)))
    with pytest.raises(ConfigError, match="'path' must end in .vc7"):
        write_davis_vectors(tmp_path / "w.txt", [0, 1], [0, 1], None, np.zeros((2, 2)), np.zeros((2, 2)))
    with pytest.raises(ConfigError, match="'sensors' must name the 3 cameras"):
        write_davis_images(tmp_path / "x", _images(), sensors=["a"], times_s=[0, 1, 2])
    with pytest.raises(ConfigError, match="one size"):
        write_davis_images(tmp_path / "x", [[np.zeros((4, 4))], [np.zeros((4, 5))]], sensors=["a", "b"], times_s=[0])
    with pytest.raises(ConfigError, match="'positions_mm' must be an"):
        write_davis_particles(tmp_path / "q", np.zeros((2, 3)), [0, 1, 2])
    assert not (tmp_path / "x").exists() and not (tmp_path / "w.vc7").exists() and not (tmp_path / "q").exists()


# ------------------------------------------------------------------------------ a real run
@pytest.fixture(scope="module")
def davis_run(tmp_path_factory):
    """The tiny experiment (about a second after its render), exported with a 2-plane plate."""
    from mitpiv.studies import run_experiment
    from mitpiv.studies.export_davis import export_davis
    from tests.studies.helpers import tiny_experiment

    d = tmp_path_factory.mktemp("davis")
    run_experiment(tiny_experiment(d), d / "run")
    m = export_davis(d / "run", d / "davis", n_planes=2, spp=4)
    return d / "run", d / "davis", m


def test_export_images_times_and_truth(davis_run):
    from mitpiv.io import read_exr, read_truth
    from mitpiv.io.tiff import quantise

    run, out, m = davis_run
    assert json.loads((out / "mitpiv_export.json").read_text())["images"]["set"] == "Images.set"
    with pytest.raises(FileFormatError, match="several sets"):  # the export folder holds three sets
        read_davis_images(out)
    r = read_davis_images(out / "Images.set")
    assert r["sensors"] == ["cam0", "cam1"] and r["images"].shape == (2, 2, 80, 80) and r["images"].dtype == np.uint16
    for c, s in enumerate(r["sensors"]):
        for f in range(2):
            exr = read_exr(run / "render" / f"{s}_frame{f:03d}.exr")[0]
            assert np.array_equal(r["images"][c, f], quantise(exr, m["gain"], 16))
    truth = read_truth(run / "particles" / "truth.npz")
    np.testing.assert_allclose(r["times_s"], truth["times_s"], atol=TIME_S, rtol=0)
    assert r["images"].max() == 2**16 - 1  # one gain: the brightest pixel of the run at full scale
    p = read_davis_particles(out / "Truth.set")
    want = np.transpose(truth["positions_mm"], (1, 0, 2))
    np.testing.assert_allclose(p["positions_mm"], want, rtol=F32, atol=F32 * np.abs(want).max())


def test_export_piv_field_as_a_vector_volume(davis_run):
    from mitpiv.analysis import VectorField

    run, out, m = davis_run
    f = VectorField.load(run / "piv" / "field.npz")
    r = read_davis_vectors(out / "piv_measured.vc7")
    assert m["piv"]["velocity_unit"] == "m/s" and r.velocity_unit == "m/s" and r.length_unit == "mm"
    np.testing.assert_allclose(r.x, f.x_mm, atol=1e-9)
    np.testing.assert_allclose(r.y, f.y_mm, atol=1e-9)
    np.testing.assert_allclose(r.z, f.z_mm, atol=1e-9)
    assert r.dt_s == pytest.approx(f.dt_s, rel=1e-9)
    ok = np.asarray(f.valid, bool)
    assert np.array_equal(r.enabled, ok) and ok.any()
    for got, want in ((r.u, f.u), (r.v, f.v), (r.w, f.w)):  # mm/s -> m/s, float32 in the file
        np.testing.assert_allclose(got[ok] * 1e3, want[ok], rtol=F32, atol=F32 * np.abs(want).max())


def test_export_calibration_plate_seen_where_the_cameras_project_it(davis_run):
    from mitpiv.io import camera_from_metadata, read_exr
    from mitpiv.physics.targets import CalibrationTarget, markers_world, target_pose

    run, out, m = davis_run
    plate = json.loads((out / "calibration_plate.json").read_text())
    assert plate["z_positions_mm"] == [-2.0, 2.0] and plate["dot_diameter_mm"] < plate["dot_spacing_mm"]
    readme = (out / "README.txt").read_text()
    assert "calibration wizard" in readme and f"dot spacing {plate['dot_spacing_mm']:g} mm" in readme
    cal = read_davis_images(out / "Calibration.set")
    assert cal["images"].shape == (2, 2, 80, 80)
    t = m["calibration"]["target"]
    target = CalibrationTarget("dots", t["rows"], t["cols"], t["spacing_mm"], dot_diameter_mm=t["dot_diameter_mm"])
    for c, s in enumerate(cal["sensors"]):
        cam = camera_from_metadata(read_exr(run / "render" / f"{s}_frame000.exr")[1])
        for k, z in enumerate(plate["z_positions_mm"]):
            img = cal["images"][c, k]
            uv = cam.project(markers_world(target, target_pose(z, centre_xy_mm=plate["origin_dot_world_mm"])))
            ij = np.floor(uv).astype(int)
            inside = np.all((ij >= 0) & (ij < 80), axis=1)
            assert inside.sum() >= 20
            # every dot centre is bright, while most of the plate (the black between dots) is dark
            assert np.all(img[ij[inside, 1], ij[inside, 0]] > 0.5 * img.max())
            assert np.median(img) < 0.05 * img.max()


def test_export_keeps_the_sensor_stage_counts(davis_run, tmp_path):
    import shutil

    from mitpiv.io import read_exr, write_exr
    from mitpiv.studies.export_davis import export_davis

    run = tmp_path / "run"
    shutil.copytree(davis_run[0] / "render", run / "render")
    shutil.copytree(davis_run[0] / "particles", run / "particles")
    shutil.copy(davis_run[0] / "experiment.json", run)
    (run / "sensor").mkdir()
    for f in sorted((run / "render").glob("*_frame*.exr")):  # counts as a sensor stage writes them
        img, meta = read_exr(f)
        write_exr(run / "sensor" / f.name, np.rint(img / img.max() * 3000).astype(np.float32), meta)
    (run / "sensor" / "stage.json").write_text("{}")
    m = export_davis(run, tmp_path / "dv", calibration=False, truth=False)
    assert m["source"] == "sensor" and m["gain"] == 1.0
    r = read_davis_images(tmp_path / "dv" / "Images.set")
    for c, s in enumerate(r["sensors"]):
        assert np.array_equal(r["images"][c, 1], read_exr(run / "sensor" / f"{s}_frame001.exr")[0].astype(np.uint16))
    assert not (tmp_path / "dv" / "Truth.set").exists()


def test_export_command_line(davis_run, tmp_path, capsys):
    import lvpyio

    from mitpiv import cli

    run = davis_run[0]
    assert cli.main(["export", str(run), "--davis", str(tmp_path / "dv"), "--plate-planes", "0"]) == 0
    line = capsys.readouterr().out.strip().splitlines()[-1]
    assert line.startswith("davis: 2 cameras x 2 frames (render images, uint16)") and line.endswith(str(tmp_path / "dv"))
    assert (tmp_path / "dv" / "Images.set").is_file() and not (tmp_path / "dv" / "Calibration.set").exists()
    # one plate position at 1 sample per film pixel: one calibration buffer, the settings recorded
    assert cli.main(["-q", "export", str(run), "--davis", str(tmp_path / "dv1"), "--plate-planes", "1",
                     "--plate-spp", "1"]) == 0
    assert "calibration plate at 1 z positions" in capsys.readouterr().out
    assert len(lvpyio.read_set(str(tmp_path / "dv1" / "Calibration.set"))) == 1
    m = json.loads((tmp_path / "dv1" / "mitpiv_export.json").read_text())
    assert m["calibration"]["spp"] == 1 and len(m["calibration"]["z_positions_mm"]) == 1
    (tmp_path / "f").write_text("")
    assert cli.main(["export", str(run), "--davis", str(tmp_path / "f")]) != 0
    assert "--davis" in capsys.readouterr().err
