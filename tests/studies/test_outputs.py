"""What a finished tomo run gives a user beyond metrics: the ParaView / VTK export (the
``[output] vtk = true`` stage and ``mitpiv export RUN --vtk``), every file read back with the
``vtk`` package and compared with the run's own files, and the flow figures of the report."""

import logging
import os
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
import vtk
from vtk.util.numpy_support import vtk_to_numpy

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.studies import run_experiment

SCENE = Path(__file__).resolve().parents[2] / "scenes" / "tomo4" / "scene.xml"

#: A small tomo run in a Lamb-Oseen vortex (about 2 voxels of displacement at the core
#: radius), so the field has vorticity; 128 px cameras, 400 particles (~15 s).
EXPERIMENT = f"""name = "outputs"
seed = 5
[scene]
xml = "{SCENE}"
params = {{ resolution = 128, thickness_mm = 4 }}
[seeding]
box_min_mm = [-5.0, -5.0, -2.0]
box_max_mm = [5.0, 5.0, 2.0]
count = 400
[flow]
kind = "lamb_oseen"
circulation_mm2_s = 1000.0
core_radius_mm = 1.5
dt_s = 0.002
[reconstruction]
method = "mart"
bounds_mm = [-4.0, 4.0, -4.0, 4.0, -1.6, 1.6]
voxel_mm = 0.1
iterations = 3
[piv]
windows = [32, 16]
overlap = 0.5
[output]
vtk = true
"""

#: float64 arrays through pyevtk's raw binary: bit-exact; float32 volumes: exact after the cast.
EXACT = 0.0
#: The exported true tracks (16 RK4 steps) against the truth file's frame-1 positions (8
#: steps) in a vortex turning particles by < 0.3 rad: RK4 truncation differences ~1e-9 mm.
TRACK_END_TOL_MM = 1e-6


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    d = tmp_path_factory.mktemp("outputs")
    exp = d / "exp.toml"
    exp.write_text(EXPERIMENT)
    res = run_experiment(exp, d / "run")
    return exp, d / "run", res


def _read(path):
    reader = {".vti": vtk.vtkXMLImageDataReader, ".vts": vtk.vtkXMLStructuredGridReader,
              ".vtu": vtk.vtkXMLUnstructuredGridReader}[Path(path).suffix]()
    reader.SetFileName(str(path))
    reader.Update()
    return reader.GetOutput()


def _arr(ds, name, shape=None, cells=False):
    data = ds.GetCellData() if cells else ds.GetPointData()
    a = data.GetArray(name)
    assert a is not None, f"{name} missing"
    a = vtk_to_numpy(a)
    return a if shape is None else a.reshape(shape)


def test_vtk_stage_writes_every_file_and_they_hold_the_run(run):
    from mitpiv.analysis import MatchResult, VectorField, truth_volume, vorticity
    from mitpiv.io import read_truth, read_volume
    from mitpiv.io.vectors import read_velocity_error

    _, rd, res = run
    vt = rd / "vtk"
    assert (vt / "stage.json").is_file() and "vtk" in res.timings
    truth = read_truth(rd / "particles" / "truth.npz")
    # every file the collection names loads; times are the frame times
    ds = ET.parse(vt / "run.pvd").getroot().findall("./Collection/DataSet")
    names = {e.get("name") for e in ds}
    assert names == {"volume", "particles_true", "particles_found", "piv", "tracks_true"}
    assert sorted({float(e.get("timestep")) for e in ds}) == [0.0, 0.002]
    for e in ds:
        assert _read(vt / e.get("file")).GetNumberOfPoints() > 0, e.get("file")
    for frame in (0, 1):
        vol, grid, _ = read_volume(rd / "reconstruct" / f"volume_{frame}.npz")
        d = _read(vt / f"volume_{frame}.vti")
        np.testing.assert_allclose(d.GetOrigin(), [grid.x_mm[0], grid.y_mm[0], grid.z_mm[0]], rtol=1e-12)
        assert np.max(np.abs(_arr(d, "reconstructed", grid.shape) - vol.astype(np.float32))) <= EXACT
        tv = truth_volume(truth["positions_mm"][frame], grid).astype(np.float32)
        assert np.max(np.abs(_arr(d, "true", grid.shape) - tv)) <= EXACT
        # particles: the matched ones carry the run's match errors, the others NaN
        m = MatchResult.load(rd / "evaluate" / f"matches_{frame}.npz")
        pt = _read(vt / f"particles_true_{frame}.vtu")
        pts = vtk_to_numpy(pt.GetPoints().GetData())
        assert np.max(np.abs(pts - truth["positions_mm"][frame])) <= EXACT
        match, err = _arr(pt, "match"), _arr(pt, "error_mm").reshape(-1, 3)
        assert match.sum() == m.n_matched and m.n_matched > 100
        np.testing.assert_array_equal(err[m.pairs[:, 1]], m.errors_mm)
        assert np.all(np.isnan(err[match == 0]))
        np.testing.assert_allclose(_arr(pt, "error_magnitude_mm")[m.pairs[:, 1]],
                                   np.linalg.norm(m.errors_mm, axis=1), rtol=1e-12)
        pf = _read(vt / f"particles_found_{frame}.vtu")
        assert pf.GetNumberOfPoints() == m.n_found
        found = vtk_to_numpy(pf.GetPoints().GetData())
        # found - true of each pair, from the two exported point sets
        tidx = _arr(pf, "truth_index")
        ok = tidx >= 0
        np.testing.assert_allclose(found[ok] - truth["positions_mm"][frame][tidx[ok]],
                                   _arr(pf, "error_mm").reshape(-1, 3)[ok], atol=1e-12)
        assert _arr(pf, "match").sum() == m.n_matched
    field = VectorField.load(rd / "piv" / "field.npz")
    e = read_velocity_error(rd / "piv" / "velocity_error.npz")
    p = _read(vt / "piv.vts")
    sh = field.shape
    assert p.GetNumberOfPoints() == field.n_vectors
    grid_pts = vtk_to_numpy(p.GetPoints().GetData()).reshape(sh + (3,))
    np.testing.assert_array_equal(grid_pts, field.points_mm())
    meas = np.stack([field.u, field.v, field.w], axis=-1)
    np.testing.assert_array_equal(_arr(p, "velocity_measured").reshape(sh + (3,)), meas)
    np.testing.assert_array_equal(_arr(p, "velocity_true").reshape(sh + (3,)), e["reference"])
    np.testing.assert_array_equal(_arr(p, "velocity_error").reshape(sh + (3,)), e["error"])
    np.testing.assert_array_equal(_arr(p, "outlier", sh), field.outlier.astype(np.uint8))
    np.testing.assert_array_equal(_arr(p, "vorticity").reshape(sh + (3,)), vorticity(field))
    # the true field's vorticity along z peaks near the core: Lamb-Oseen omega_z(0) = Gamma / (pi r_c^2)
    wz = _arr(p, "vorticity_true").reshape(sh + (3,))[..., 2]
    assert 0.3 * 1000 / (np.pi * 1.5**2) < wz.max() < 1000 / (np.pi * 1.5**2)
    # true tracks: one polyline per particle from its frame-0 to its frame-1 position
    t = _read(vt / "tracks_true.vtu")
    n = truth["positions_mm"].shape[1]
    assert t.GetNumberOfCells() == n
    tp = vtk_to_numpy(t.GetPoints().GetData())
    last = [t.GetCell(c).GetPointId(t.GetCell(c).GetNumberOfPoints() - 1) for c in (0, n // 2, n - 1)]
    first = [t.GetCell(c).GetPointId(0) for c in (0, n // 2, n - 1)]
    idx = [0, n // 2, n - 1]
    assert np.max(np.abs(tp[first] - truth["positions_mm"][0][idx])) <= EXACT
    assert np.max(np.abs(tp[last] - truth["positions_mm"][1][idx])) < TRACK_END_TOL_MM


def test_export_command_and_rerun(run, tmp_path, capsys, caplog):
    from mitpiv.cli import main

    exp, rd, res = run
    assert main(["export", str(rd), "--vtk", "--out", str(tmp_path / "x")]) == 0
    assert "run.pvd" in capsys.readouterr().out
    a, b = _read(tmp_path / "x" / "piv.vts"), _read(rd / "vtk" / "piv.vts")
    np.testing.assert_array_equal(_arr(a, "velocity_error"), _arr(b, "velocity_error"))
    assert main(["export", str(rd)]) == 2 and "--vtk" in capsys.readouterr().err
    assert main(["export", str(tmp_path), "--vtk"]) == 2 and "not a run folder" in capsys.readouterr().err
    # a rerun skips the vtk stage too
    with caplog.at_level(logging.INFO, logger="mitpiv"):
        assert run_experiment(exp, rd).metrics == res.metrics
    assert "vtk: done earlier, skipped" in caplog.text


def test_export_command_says_its_result_once(run, tmp_path):
    """`mitpiv export RUN --vtk` as a user runs it (a terminal shows stdout and stderr together):
    the result line once, on stdout; the library's own message no longer repeats it on stderr."""
    import subprocess
    import sys

    _, rd, _ = run
    r = subprocess.run([sys.executable, "-m", "mitpiv.cli", "export", str(rd), "--vtk", "--out", str(tmp_path / "v")],
                       capture_output=True, text=True, env={**os.environ, "MITPIV_QUIET": "1"})
    assert r.returncode == 0, r.stderr
    said = [line for line in (r.stdout + r.stderr).splitlines() if "run.pvd" in line or "VTK files" in line]
    assert len(said) == 1 and said[0] in r.stdout, (r.stdout, r.stderr)
    assert said[0].endswith(f" VTK files -> {tmp_path / 'v'} (open run.pvd in ParaView)"), said


def test_export_refuses_unfinished_and_other_runs(run, tmp_path):
    import shutil

    from mitpiv.io import write_json
    from mitpiv.studies.export import export_vtk

    _, rd, _ = run
    part = tmp_path / "part"
    shutil.copytree(rd, part, ignore=shutil.ignore_patterns("piv", "vtk", "report"))
    with pytest.raises(FileFormatError, match=r"\['piv'\]"):
        export_vtk(part)
    write_json(tmp_path / "b" / "experiment.json", {"kind": "backlit"})
    with pytest.raises(ConfigError, match="backlit"):
        export_vtk(tmp_path / "b")


def test_export_of_matches_without_found_positions_finds_them_again(run, tmp_path):
    """Matches saved before they kept the found positions: the export detects the particles
    again with the run's settings and gets the same points."""
    import shutil

    from mitpiv.analysis import MatchResult
    from mitpiv.studies.export import export_vtk

    _, rd, _ = run
    old = tmp_path / "old"
    shutil.copytree(rd, old, ignore=shutil.ignore_patterns("vtk"))
    for frame in (0, 1):
        m = MatchResult.load(old / "evaluate" / f"matches_{frame}.npz")
        m.found_mm = None
        m.save(old / "evaluate" / f"matches_{frame}.npz")
        assert MatchResult.load(old / "evaluate" / f"matches_{frame}.npz").found_mm is None
    export_vtk(old)
    for frame in (0, 1):
        a = vtk_to_numpy(_read(old / "vtk" / f"particles_found_{frame}.vtu").GetPoints().GetData())
        b = vtk_to_numpy(_read(rd / "vtk" / f"particles_found_{frame}.vtu").GetPoints().GetData())
        np.testing.assert_array_equal(a, b)


def test_report_shows_the_flow(run):
    """The report embeds the flow slice, the velocity profiles and the 3D particle view."""
    _, rd, _ = run
    md = (rd / "report" / "report.md").read_text()
    for f in ("flow_slice.png", "velocity_profiles.png", "particles_3d.png"):
        assert f"({f})" in md, f
        assert (rd / "report" / f).stat().st_size > 20_000, f  # a drawn figure, not an empty canvas


def _setup_rows(md: str) -> dict:
    """The set-up table of a report: {quantity: value}."""
    block = md[md.index("## Set-up"):md.index("## Reconstruction and particles")]
    return dict(re.findall(r"^\| ([^|]+?) \| ([^|]+?) \|$", block, re.M))


def _row(md: str, start: str) -> list[str]:
    """The cells after ``start`` of the report's table row that begins with it."""
    line = next(x for x in md.splitlines() if x.startswith(start))
    return [c.strip() for c in line[len(start):].strip().strip("|").split("|")]


def test_report_stands_alone(run, tmp_path, caplog):
    """The report states the set-up (from the experiment, the truth file and the images'
    metadata), every error in voxels and in physical units, each frame's detection
    threshold, and the plane of flow_slice.png with why; [report] picks another plane and
    reruns only the report."""
    import shutil

    from mitpiv.analysis import VectorField
    from mitpiv.io import camera_from_metadata, read_exr_metadata, read_truth

    _, rd, res = run
    md = (rd / "report" / "report.md").read_text()
    rows = _setup_rows(md)
    truth = read_truth(rd / "particles" / "truth.npz")
    p0 = truth["positions_mm"][0]
    inside = int(np.all((p0 >= (-4, -4, -1.6)) & (p0 <= (4, 4, 1.6)), axis=1).sum())
    assert rows["volume (reconstructed)"] == "x -4 .. 4, y -4 .. 4, z -1.6 .. 1.6 mm"
    assert rows["voxel size"] == "0.1 mm" and rows["grid"] == "80 x 80 x 32 voxels (x, y, z)"
    assert rows["time between the frames dt"] == "2 ms"
    assert rows["particles"].startswith(f"400 seeded, {inside} inside the volume; diameter 1 um monodisperse")
    assert rows["flow"] == "lamb_oseen: circulation_mm2_s = 1000, core_radius_mm = 1.5, center = [0, 0, 0], " \
                           "axis = [0, 0, 1]"
    assert rows["reconstruction"] == "mart, 3 iterations, relaxation 1"
    assert rows["PIV"].startswith("windows 32 -> 16 voxels (last 1.6 x 1.6 x 1.6 mm), overlap 50 %, deformed windows")
    assert "threshold_of = 'robust'" in rows["particle detection"] and "0.1 x the robust peak level" in \
        rows["particle detection"]
    # cameras: the images' own metadata; ppp = the frame-0 particles each images per pixel
    metas = [read_exr_metadata(f) for f in sorted((rd / "render").glob("*_frame000.exr"))]
    assert len(metas) == 4 and rows["images"].startswith("4 cameras, rendered")
    pixels = []
    for meta in metas:
        cells = _row(md, f"| {meta['sensor_id']} |")
        cam = camera_from_metadata(meta)
        ppp = cam.visible(p0).sum() / (128 * 128)
        assert cells[0] == meta["camera"]["type"] and cells[1] == "128 x 128", cells
        assert float(cells[-1]) == pytest.approx(ppp, abs=6e-5), (cells, ppp)
        sv = np.linalg.svd(cam.jacobian(np.zeros((1, 3)))[0], compute_uv=False)
        pixels.append(1 / np.sqrt(np.mean(sv ** 2)))
    pix = float(np.mean(pixels))
    assert rows["object-space pixel (cameras' mean, volume centre)"] == f"{pix:.4f} mm = {pix / 0.1:.2f} voxels"
    # particle position errors in voxels, mm and object pixels; the threshold each frame used
    ev = res.metrics["evaluate"]
    for frame in (0, 1):
        pr = ev[f"frame{frame}"]["particles"]
        cells = _row(md, f"| {frame} | RMS |")
        assert cells[0] == " / ".join(f"{v:.3f}" for v in pr["rms_vox"])
        assert cells[1] == " / ".join(f"{v:.4f}" for v in pr["rms_mm"])
        assert cells[2] == " / ".join(f"{v / pix:.3f}" for v in pr["rms_mm"])
        np.testing.assert_allclose(pr["rms_mm"], 0.1 * np.asarray(pr["rms_vox"]), rtol=1e-12)
        assert pr["threshold_of"] == "robust" and pr["threshold"] == pytest.approx(0.1 * pr["threshold_reference"])
        assert _row(md, f"| {frame} | ")[-1] == f"{pr['threshold']:.3g} = 0.1 x {pr['threshold_reference']:.3g} (robust)"
    # velocity errors in voxels per frame and mm/s: 1 voxel/frame = 0.1 mm / 2 ms = 50 mm/s
    pv = res.metrics["piv"]
    assert _row(md, "| RMS error [voxels/frame] |") == [f"{v:.4f}" for v in pv["rms_vox"]]
    assert _row(md, "| RMS error [mm/s] |") == [f"{v:.3f}" for v in pv["rms"]]
    np.testing.assert_allclose(pv["rms"], 50.0 * np.asarray(pv["rms_vox"]), rtol=1e-9)
    assert "1 voxel/frame = 0.1 x 0.1 x 0.1 mm / dt = 50 mm/s." in md
    # flow_slice.png: a vortex along z, so "auto" takes the z mid-plane, and says why
    field = VectorField.load(rd / "piv" / "field.npz")
    z = field.z_mm[field.z_mm.size // 2]
    assert f"flow_slice.png: the plane z = {z:+.2f} mm ([report] slice_axis = 'auto': " in md
    assert "the one with the largest mean |vorticity| normal to it" in md
    # another plane: only the report reruns
    other = tmp_path / "run"
    shutil.copytree(rd, other, ignore=shutil.ignore_patterns("vtk"))
    exp = other.parent / "exp.toml"
    exp.write_text(EXPERIMENT)
    caplog.clear()
    with caplog.at_level(logging.INFO, logger="mitpiv"):
        run_experiment(exp, other, overrides={"report.slice_axis": "x", "report.slice_mm": 1.0, "output.vtk": False})
    assert caplog.text.count("done earlier, skipped") == 5 and "report ..." in caplog.text
    md = (other / "report" / "report.md").read_text()
    x = field.x_mm[np.argmin(np.abs(field.x_mm - 1.0))]
    assert f"flow_slice.png: the plane x = {x:+.2f} mm ([report] slice_axis = 'x', slice_mm = 1: the PIV plane " \
           "nearest it)." in md
    assert (other / "report" / "flow_slice.png").stat().st_size > 20_000


def test_sweep_plot_has_error_bars_over_seeds(tmp_path, monkeypatch):
    """Three seeds per x: the plotted points are the mean and the bars one standard
    deviation (ddof 1) over the seeds, computed here afresh; points that differ in another
    parameter stay separate."""
    import pandas as pd

    from mitpiv.studies import report

    figs = []
    monkeypatch.setattr(report, "save_figure", lambda fig, path, **kw: figs.append(fig))
    rng = np.random.default_rng(0)
    xs, seeds = [1, 3, 10], [0, 1, 2]
    q = {(x, s): 0.5 + 0.02 * x + 0.05 * rng.normal() for x in xs for s in seeds}
    df = pd.DataFrame({"param.reconstruction.iterations": [x for x in xs for _ in seeds],
                       "param.seed": [s for _ in xs for s in seeds],
                       "frame0.Q": [q[x, s] for x in xs for s in seeds], "status": ["ok"] * 9})
    report.plot_sweep(df.sample(frac=1, random_state=1), "reconstruction.iterations", "frame0.Q", tmp_path / "s.png")
    ax = figs[-1].axes[0]
    (line,) = ax.lines[:1]
    np.testing.assert_array_equal(np.asarray(line.get_xdata(), float), xs)
    np.testing.assert_allclose(np.asarray(line.get_ydata(), float), [np.mean([q[x, s] for s in seeds]) for x in xs], rtol=1e-12)
    bars = ax.collections[0].get_segments()  # one vertical segment per x: mean -+ sd
    sd = [np.std([q[x, s] for s in seeds], ddof=1) for x in xs]
    np.testing.assert_allclose([b[1, 1] - b[0, 1] for b in bars], 2 * np.asarray(sd), rtol=1e-12)
    assert "3 seeds" in ax.get_legend().get_texts()[0].get_text()
    # the same x with another parameter changing: points drawn one by one, no bars
    df2 = df.assign(**{"param.seeding.ppp": [0.05, 0.1, 0.2] * 3})
    report.plot_sweep(df2, "reconstruction.iterations", "frame0.Q", tmp_path / "t.png")
    assert len(figs[-1].axes[0].collections) == 0 and len(figs[-1].axes[0].lines[0].get_xdata()) == 9


def test_particle_csv_drives_an_experiment(tmp_path, caplog):
    """[seeding] file: the run's particles are the file's (frame 0), advected by the flow;
    a changed file reruns the particles stage; file and a count together are refused."""
    import logging
    from pathlib import Path

    from mitpiv.io import read_truth
    from mitpiv.studies import load_experiment, run_config

    scene = Path(__file__).resolve().parents[2] / "scenes" / "tomo4" / "scene.xml"
    pts = np.random.default_rng(2).uniform([-2, -2, -1], [2, 2, 1], (30, 3))
    np.savetxt(tmp_path / "mine.csv", np.column_stack([pts, np.full(30, 1.5)]), delimiter=",",
               header="x_mm,y_mm,z_mm,diameter_um", comments="")
    exp = tmp_path / "exp.toml"
    exp.write_text(f"""name = "csv"
[scene]
xml = "{scene}"
params = {{ resolution = 32 }}
[seeding]
file = "mine.csv"
[flow]
kind = "uniform"
velocity_mm_s = [100.0, 0.0, 0.0]
dt_s = 0.002
[reconstruction]
bounds_mm = [-2.0, 2.0, -2.0, 2.0, -1.0, 1.0]
voxel_mm = 0.1
""")
    res = run_config(load_experiment(exp), tmp_path / "run", until="render")
    truth = read_truth(tmp_path / "run" / "particles" / "truth.npz")
    np.testing.assert_array_equal(truth["positions_mm"][0], pts)
    np.testing.assert_allclose(truth["positions_mm"][1] - pts, [[0.2, 0.0, 0.0]] * 30, atol=1e-12)
    np.testing.assert_array_equal(truth["diameters_um"], 1.5)
    assert res.stages["particles"]["n_particles"] == 30 and len(res.stages["render"]["images"]) == 8
    np.savetxt(tmp_path / "mine.csv", np.column_stack([pts[:20], np.full(20, 1.5)]), delimiter=",",
               header="x_mm,y_mm,z_mm,diameter_um", comments="")
    with caplog.at_level(logging.INFO, logger="mitpiv"):
        res = run_config(load_experiment(exp), tmp_path / "run", until="particles")
    assert res.stages["particles"]["n_particles"] == 20 and "particles: done earlier" not in caplog.text
    with pytest.raises(ConfigError, match="file gives the particles"):
        load_experiment(exp, {"seeding.count": 10})
    with pytest.raises(ConfigError, match="box_min_mm and box_max_mm are required"):
        load_experiment(exp, {"seeding.file": None, "seeding.count": 10})


def test_images_name_the_scene_the_experiment_gave(run):
    """The render stage renders a copy of the scene in its temporary folder; the images'
    metadata names the experiment's own XML (a path that exists after the run), not the copy."""
    import tomllib

    from mitpiv.io import read_exr_metadata

    exp, run_dir, _ = run
    xml = (exp.parent / tomllib.loads(exp.read_text())["scene"]["xml"]).resolve()
    for f in sorted((run_dir / "render").glob("*.exr")):
        md = read_exr_metadata(f)
        assert md["scene_file"] == str(xml) and Path(md["scene_file"]).is_file()
