"""Every file format of mitpiv.io: round trips (light field, vector field, truth with
velocities, the old backlit truth with diameters in mm, dewarp, detections, JSON records),
bad files (FileFormatError naming the file), interrupted writes (no file at the target, no
temporary file left), and imports without cycles."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mitpiv.analysis.backlit import BacklitDetections, Dewarp
from mitpiv.analysis.piv3d import VectorField
from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.io import (
    read_detections,
    read_dewarp,
    read_json,
    read_lightfield,
    read_npz,
    read_truth,
    read_vector_field,
    read_volume,
    save_figure,
    write_detections,
    write_dewarp,
    write_json,
    write_lightfield,
    write_npz,
    write_text,
    write_truth,
    write_vector_field,
    write_volume,
)
from mitpiv.io.records import to_jsonable
from mitpiv.lightfield import LightField

UM_PER_MM = 1000.0  # definition of the micrometre


# ----------------------------------------------------------------------------- sample objects


def _camera():
    from mitpiv.physics.plenoptic import PlenopticCamera

    return PlenopticCamera(resolution=(120, 100), pixel_pitch_um=5.0, focal_length_mm=50.0, focus_distance_mm=500.0,
                           mla_pitch_um=50.0, f_number=8.0)


def _lightfield(optics=True):
    from mitpiv.lightfield import decode

    raw = np.random.default_rng(0).uniform(0.0, 1.0, (100, 120))
    lf = decode(raw, optics=_camera())
    if not optics:
        lf.optics = None
    lf.info["extra"] = {"seed": np.int64(7), "gain": np.float32(0.5), "axes": (1, 2)}
    return lf


def _vector_field(dt_s=0.002):

    rng = np.random.default_rng(1)
    shape = (3, 4, 5)
    comp = {k: rng.normal(size=shape) for k in ("u", "v", "w", "snr", "peak")}
    flags = {k: rng.random(shape) < 0.3 for k in ("valid", "outlier", "replaced")}
    return VectorField(x_mm=np.linspace(0, 4, 5), y_mm=np.linspace(-1, 2, 4), z_mm=np.array([0.0, 0.5, 1.0]),
                       **comp, **flags, voxel_mm=(0.1, 0.1, 0.2), window_vox=(16, 16, 8), dt_s=dt_s,
                       info={"passes": np.int64(3), "normalised": True, "windows": [(32, 32, 16), (16, 16, 8)]})


def _dewarp_and_observations():
    from mitpiv.analysis.backlit import fit_dewarp

    rng = np.random.default_rng(2)
    uvz = np.column_stack([rng.uniform(0, 200, 300), rng.uniform(0, 150, 300), rng.choice([-1.0, 0.0, 1.0], 300)])
    # a smooth map px -> mm (0.02 mm/px, a little keystone and depth scaling)
    x = (uvz[:, 0] - 100) * 0.02 * (1 + 0.01 * uvz[:, 2])
    y = (uvz[:, 1] - 75) * 0.02 * (1 + 0.01 * uvz[:, 2]) + 1e-5 * uvz[:, 0] ** 2
    xyz = np.column_stack([x, y, uvz[:, 2]])
    return fit_dewarp(uvz, xyz, degree_xy=3, degree_z=2), uvz, xyz


def _detections(world=True, n=6):
    from mitpiv.analysis.backlit import BacklitDetections

    rng = np.random.default_rng(3)
    det = BacklitDetections(rng.uniform(0, 100, (n, 2)), rng.uniform(-2, 2, n), rng.integers(3, 50, n).astype(float),
                            rng.uniform(2, 8, n), rng.uniform(1, 1.5, n), rng.uniform(0.3, 1, n))
    if world:
        det.positions_mm, det.diameters_mm = rng.normal(size=(n, 3)), rng.uniform(0.1, 0.8, n)
    return det


def _truth_arrays(n=12):
    rng = np.random.default_rng(4)
    p0 = rng.normal(size=(n, 3))
    v = rng.normal(size=(n, 3)) * 100.0  # mm/s
    return p0, v, rng.uniform(50, 900, n)  # diameters [um]


# ----------------------------------------------------------------------------- round trips


@pytest.mark.parametrize("optics", [True, False])
def test_lightfield_round_trip(tmp_path, optics):

    lf = _lightfield(optics)
    write_lightfield(tmp_path / "lf.npz", lf)
    back = LightField.load(tmp_path / "lf.npz")
    for k in ("data", "s_px", "t_px", "du_px", "view_weights", "valid"):
        a, b = getattr(back, k), getattr(lf, k)
        assert a.dtype == b.dtype
        np.testing.assert_array_equal(a, b)
    assert back.info == json.loads(json.dumps(to_jsonable(lf.info)))
    assert back.info["extra"] == {"seed": 7, "gain": 0.5, "axes": [1, 2]}
    if optics:
        assert json.dumps(to_jsonable(back.optics.to_dict())) == json.dumps(to_jsonable(lf.optics.to_dict()))
    else:
        assert back.optics is None
    # the methods scripts use delegate to the same format
    lf.save(tmp_path / "m.npz")
    np.testing.assert_array_equal(LightField.load(tmp_path / "m.npz").data, lf.data)
    np.testing.assert_array_equal(read_lightfield(tmp_path / "m.npz")["view_weights"], lf.view_weights)


@pytest.mark.parametrize("dt_s", [None, 0.002])
def test_vector_field_round_trip(tmp_path, dt_s):

    f = _vector_field(dt_s)
    write_vector_field(tmp_path / "f.npz", f)
    g = VectorField.load(tmp_path / "f.npz")
    for k in ("x_mm", "y_mm", "z_mm", "u", "v", "w", "snr", "peak", "valid", "outlier", "replaced"):
        np.testing.assert_array_equal(getattr(g, k), getattr(f, k))
        assert getattr(g, k).dtype == getattr(f, k).dtype
    assert (g.voxel_mm, g.window_vox, g.dt_s, g.units) == ((0.1, 0.1, 0.2), (16, 16, 8), dt_s, f.units)
    assert g.info == {"passes": 3, "normalised": True, "windows": [[32, 32, 16], [16, 16, 8]]}
    f.save(tmp_path / "m.npz")
    np.testing.assert_array_equal(VectorField.load(tmp_path / "m.npz").w, f.w)


def test_truth_with_velocities_npz_and_csv(tmp_path):
    p0, v, d_um = _truth_arrays()
    dt = 1e-3
    pos = np.stack([p0, p0 + v * dt])
    write_truth(tmp_path / "t.npz", positions_mm=pos, times_s=[0.0, dt], diameters_um=d_um, velocities_mm_s=v,
                flow={"kind": "drop_impact", "speed_mm_s": np.float64(2.5)})
    t = read_truth(tmp_path / "t.npz")
    np.testing.assert_array_equal(t["positions_mm"], pos)
    np.testing.assert_array_equal(t["diameters_um"], d_um)
    np.testing.assert_array_equal(t["velocities_mm_s"], v)
    np.testing.assert_allclose(t["displacements_mm"][0], v * dt, rtol=1e-12, atol=1e-15)
    assert t["flow"] == {"kind": "drop_impact", "speed_mm_s": 2.5} and t["extra"] == {}
    # CSV: id, diameter, 2 frames x 3 positions, 3 velocities, 3 displacements (last)
    write_truth(tmp_path / "t.csv", positions_mm=pos, times_s=[0.0, dt], diameters_um=d_um, velocities_mm_s=v)
    header = (tmp_path / "t.csv").read_text().splitlines()[0].split(",")
    assert header[8:11] == ["vx_mm_s", "vy_mm_s", "vz_mm_s"] and header[-3:] == ["dx_mm", "dy_mm", "dz_mm"]
    rows = np.loadtxt(tmp_path / "t.csv", delimiter=",", skiprows=1)
    np.testing.assert_array_equal(rows[:, 1], d_um)
    np.testing.assert_array_equal(rows[:, 8:11], v)
    np.testing.assert_allclose(rows[:, -3:], v * dt, rtol=1e-12, atol=1e-15)
    # without velocities the key is there and None
    write_truth(tmp_path / "n.npz", positions_mm=pos, times_s=[0.0, dt], diameters_um=2.0)
    assert read_truth(tmp_path / "n.npz")["velocities_mm_s"] is None
    with pytest.raises(ConfigError, match=r"velocities_mm_s must have shape \(N, 3\)"):
        write_truth(tmp_path / "bad.npz", positions_mm=pos, times_s=[0.0, dt], diameters_um=2.0, velocities_mm_s=v[:3])
    with pytest.raises(ConfigError, match="diameters_um"):
        write_truth(tmp_path / "bad.npz", positions_mm=pos, times_s=[0.0, dt], diameters_um=[1.0, 2.0])
    assert not (tmp_path / "bad.npz").exists()


def test_old_backlit_truth_with_diameters_mm_reads(tmp_path):
    """A backlit run folder from before the one truth format: raw np.savez, diameters in mm."""
    p0 = np.array([[0.0, 0.0, 0.0], [1.0, -2.0, 0.5]])
    v = np.array([[100.0, 0.0, 0.0], [0.0, -50.0, 20.0]])
    d_mm = np.array([0.5, 1.25])
    dt = 2e-3
    # exactly what mitpiv.studies.backlit._stage_field wrote
    np.savez(tmp_path / "truth.npz", positions_mm=np.stack([p0, p0 + v * dt]), diameters_mm=d_mm, velocities_mm_s=v,
             times_s=np.array([0.0, dt]))
    t = read_truth(tmp_path / "truth.npz")
    np.testing.assert_allclose(t["diameters_um"], [500.0, 1250.0], rtol=1e-15)
    np.testing.assert_allclose(t["diameters_um"], d_mm * UM_PER_MM, rtol=1e-15)
    assert "diameters_mm" not in t
    np.testing.assert_array_equal(t["velocities_mm_s"], v)
    np.testing.assert_allclose(t["displacements_mm"][0], [[0.2, 0.0, 0.0], [0.0, -0.1, 0.04]], rtol=1e-12, atol=1e-15)
    np.testing.assert_array_equal(t["times_s"], [0.0, dt])
    assert t["flow"] == {} and t["extra"] == {}
    # rewriting it in the one format keeps every value
    write_truth(tmp_path / "new.npz", positions_mm=t["positions_mm"], times_s=t["times_s"],
                diameters_um=t["diameters_um"], velocities_mm_s=t["velocities_mm_s"])
    n = read_truth(tmp_path / "new.npz")
    for k in ("positions_mm", "times_s", "diameters_um", "velocities_mm_s", "displacements_mm"):
        np.testing.assert_array_equal(n[k], t[k])
    with np.load(tmp_path / "new.npz") as z:
        assert "diameters_mm" not in z.files and "diameters_um" in z.files


def test_dewarp_round_trip_and_old_file(tmp_path):
    dw, uvz, xyz = _dewarp_and_observations()
    write_dewarp(tmp_path / "dewarp.npz", dw, uvz=uvz, xyz=xyz)
    back, obs = Dewarp.load(tmp_path / "dewarp.npz"), read_dewarp(tmp_path / "dewarp.npz")
    for k in ("coef", "centre", "scale"):
        np.testing.assert_array_equal(getattr(back, k), getattr(dw, k))
    assert (back.degree_xy, back.degree_z, back.rms_mm) == (dw.degree_xy, dw.degree_z, dw.rms_mm)
    np.testing.assert_array_equal(back(uvz), dw(uvz))
    np.testing.assert_array_equal(obs["uvz"], uvz)
    np.testing.assert_array_equal(obs["xyz"], xyz)
    # the fit reproduces the smooth map it was fitted to (the file keeps a working polynomial)
    np.testing.assert_allclose(back(uvz), xyz, atol=1e-6)
    # without observations
    write_dewarp(tmp_path / "d2.npz", dw)
    rec = read_dewarp(tmp_path / "d2.npz")
    assert rec["uvz"] is None and rec["xyz"] is None
    with pytest.raises(ConfigError, match="both"):
        write_dewarp(tmp_path / "d3.npz", dw, uvz=uvz)
    assert not (tmp_path / "d3.npz").exists()
    # exactly what mitpiv.studies.backlit._stage_calibrate wrote
    np.savez(tmp_path / "old.npz", coef=dw.coef, degree_xy=dw.degree_xy, degree_z=dw.degree_z, centre=dw.centre,
             scale=dw.scale, rms_mm=dw.rms_mm, uvz=uvz, xyz=xyz)
    np.testing.assert_array_equal(Dewarp.load(tmp_path / "old.npz")(uvz), dw(uvz))


@pytest.mark.parametrize("world", [True, False])
def test_detections_round_trip(tmp_path, world):
    det = _detections(world)
    mm = np.random.default_rng(5).uniform(0, 1.2, (40, 30))
    write_detections(tmp_path / "detections_0.npz", det, min_map=mm)
    back, min_map = BacklitDetections.load(tmp_path / "detections_0.npz"), \
        read_detections(tmp_path / "detections_0.npz")["min_map"]
    assert len(back) == len(det)
    for k in ("uv_px", "z_stack_mm", "area_px", "diameter_px", "aspect", "darkness", "positions_mm", "diameters_mm"):
        if getattr(det, k) is None:
            assert getattr(back, k) is None
        else:
            np.testing.assert_array_equal(getattr(back, k), getattr(det, k))
    np.testing.assert_array_equal(min_map, mm.astype(np.float32))
    write_detections(tmp_path / "no_map.npz", det)
    assert read_detections(tmp_path / "no_map.npz")["min_map"] is None
    empty = _detections(world, n=0)
    write_detections(tmp_path / "empty.npz", empty)
    assert len(BacklitDetections.load(tmp_path / "empty.npz")) == 0


def test_old_detections_file_reads(tmp_path):
    det = _detections()
    mm = np.ones((20, 20), np.float32)
    # exactly what mitpiv.studies.backlit._stage_detect wrote
    np.savez(tmp_path / "detections_1.npz", uv_px=det.uv_px, z_stack_mm=det.z_stack_mm, area_px=det.area_px,
             diameter_px=det.diameter_px, aspect=det.aspect, darkness=det.darkness, positions_mm=det.positions_mm,
             diameters_mm=det.diameters_mm, min_map=mm)
    back, min_map = BacklitDetections.load(tmp_path / "detections_1.npz"), \
        read_detections(tmp_path / "detections_1.npz")["min_map"]
    np.testing.assert_array_equal(back.positions_mm, det.positions_mm)
    np.testing.assert_array_equal(back.diameters_mm, det.diameters_mm)
    np.testing.assert_array_equal(back.uv_px, det.uv_px)
    np.testing.assert_array_equal(min_map, mm)


def test_detections_length_mismatch_is_refused(tmp_path):
    det = _detections()
    det.darkness = det.darkness[:-1]
    with pytest.raises(ConfigError, match="darkness"):
        write_detections(tmp_path / "d.npz", det)
    assert list(tmp_path.iterdir()) == []


def test_json_records_round_trip(tmp_path):
    rec = {"name": "run", "seed": np.int64(3), "q": np.float32(0.5), "rms": np.array([0.1, 0.2, 0.3]),
           "shape": (2, 3), "nan": float("nan"), "np_nan": np.float64("nan"), "path": Path("a/b.exr"),
           "nested": {np.int64(1): [np.bool_(True), None]}}
    write_json(tmp_path / "metrics.json", rec)
    back = read_json(tmp_path / "metrics.json")
    assert np.isnan(back.pop("nan")) and np.isnan(back.pop("np_nan"))
    assert back == {"name": "run", "seed": 3, "q": 0.5, "rms": [0.1, 0.2, 0.3], "shape": [2, 3], "path": "a/b.exr",
                    "nested": {"1": [True, None]}}
    # the text is the standard library's JSON (NaN in Python's dialect), readable by json itself
    assert json.loads((tmp_path / "metrics.json").read_text())["seed"] == 3
    # non-JSON values: ConfigError naming the file, nothing written; default=str takes them
    with pytest.raises(ConfigError, match="x.json"):
        write_json(tmp_path / "x.json", {"a": object()})
    assert not (tmp_path / "x.json").exists()
    write_json(tmp_path / "x.json", {"a": "text", "b": object()}, default=lambda o: "obj")
    assert read_json(tmp_path / "x.json") == {"a": "text", "b": "obj"}
    write_text(tmp_path / "report.md", "# title\n\nµm\n")
    assert (tmp_path / "report.md").read_text(encoding="utf-8") == "# title\n\nµm\n"


def test_volume_round_trip(tmp_path):
    vol = np.random.default_rng(6).random((3, 5, 5)).astype(np.float32)
    write_volume(tmp_path / "v.npz", vol, {"grid": _grid_dict(), "method": "mart", "iterations": np.int64(5)})
    back, grid, meta = read_volume(tmp_path / "v.npz")
    np.testing.assert_array_equal(back, vol)
    assert grid.shape == (3, 5, 5) and grid.voxel_mm == (0.5, 0.5, 0.5)
    assert meta["method"] == "mart" and meta["iterations"] == 5


def test_volume_deflated_only_when_mostly_zero(tmp_path):
    """A dense volume is stored as it is (deflate saves ~5 % of float noise for seconds), a
    mostly-zero one deflated; both read back exactly."""
    import zipfile

    from mitpiv.reconstruct.grid import VoxelGrid

    dense = np.random.default_rng(7).random((4, 6, 6)).astype(np.float32)
    sparse = np.where(dense > 0.8, dense, 0.0).astype(np.float32)
    for name, vol, kind in (("d", dense, zipfile.ZIP_STORED), ("s", sparse, zipfile.ZIP_DEFLATED)):
        write_volume(tmp_path / f"{name}.npz", vol, {"grid": VoxelGrid((0.0, 0.0, 0.0), 0.5, (4, 6, 6)).to_dict()})
        with zipfile.ZipFile(tmp_path / f"{name}.npz") as zf:
            assert zf.getinfo("volume.npy").compress_type == kind
        np.testing.assert_array_equal(read_volume(tmp_path / f"{name}.npz")[0], vol)


def test_save_figure(tmp_path):
    assert save_figure(_figure(), tmp_path / "a.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert save_figure(_figure(), tmp_path / "a.pdf").read_bytes()[:5] == b"%PDF-"
    with pytest.raises(ConfigError, match="must end in"):
        save_figure(_figure(), tmp_path / "a.bmpx")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.pdf", "a.png"]


# ----------------------------------------------------------------------------- bad files


def _readers():
    return {
        "lightfield": read_lightfield,
        "vector_field": read_vector_field,
        "truth": read_truth,
        "dewarp": read_dewarp,
        "detections": read_detections,
        "volume": read_volume,
        "json": read_json,
        "npz": read_npz,
    }


@pytest.mark.parametrize("kind", list(_readers()))
@pytest.mark.parametrize("content", ["missing", "junk", "empty", "npy", "other_npz", "truncated"])
def test_bad_file_gives_file_format_error_naming_it(tmp_path, kind, content):
    path = tmp_path / f"bad_{kind}_{content}.{'json' if kind == 'json' else 'npz'}"
    if content == "junk":
        path.write_bytes(b"\x00\x01 this is not the file you are looking for \xff")
    elif content == "empty":
        path.write_bytes(b"")
    elif content == "npy":
        with open(path, "wb") as fh:
            np.save(fh, np.arange(4.0))
    elif content == "other_npz":  # a valid archive with entries of another format
        write_npz(path.with_suffix(".npz"), {"something": np.arange(3)})
        path.write_bytes(path.with_suffix(".npz").read_bytes())
    elif content == "truncated":
        write_npz(path.with_suffix(".npz"), {"coef": np.ones((30, 3)), "data": np.ones(1000)})
        raw = path.with_suffix(".npz").read_bytes()
        path.write_bytes(raw[: len(raw) // 2])
    if kind == "npz" and content == "other_npz":
        with pytest.raises(FileFormatError, match="lacks"):
            read_npz(path, required=("coef",))
        return
    with pytest.raises(FileFormatError) as e:
        _readers()[kind](path)
    assert str(path) in str(e.value)


def test_bad_json_text_names_the_file(tmp_path):
    (tmp_path / "stage.json").write_text('{"key": ')
    with pytest.raises(FileFormatError, match="stage.json.*not a JSON file"):
        read_json(tmp_path / "stage.json")


def test_corrupt_metadata_entries_name_the_file(tmp_path):
    lf = _lightfield()
    write_lightfield(tmp_path / "lf.npz", lf)
    z = dict(np.load(tmp_path / "lf.npz"))
    z["info"] = np.array("{not json")
    np.savez(tmp_path / "lf2.npz", **z)
    with pytest.raises(FileFormatError, match="lf2.npz.*'info'"):
        read_lightfield(tmp_path / "lf2.npz")
    f = _vector_field()
    write_vector_field(tmp_path / "f.npz", f)
    z = dict(np.load(tmp_path / "f.npz"))
    z["meta"] = np.array(json.dumps({"voxel_mm": [1, 1, 1]}))
    np.savez(tmp_path / "f2.npz", **z)
    with pytest.raises(FileFormatError, match="f2.npz"):
        read_vector_field(tmp_path / "f2.npz")
    dw, _, _ = _dewarp_and_observations()
    np.savez(tmp_path / "d.npz", coef=dw.coef[:-1], degree_xy=3, degree_z=2, centre=dw.centre, scale=dw.scale,
             rms_mm=0.0)
    with pytest.raises(FileFormatError, match="d.npz"):
        read_dewarp(tmp_path / "d.npz")


# ----------------------------------------------------------------------------- interrupted writes


def _grid_dict():
    from mitpiv.reconstruct.grid import VoxelGrid

    return VoxelGrid((0.0, 0.0, 0.0), 0.5, (3, 5, 5)).to_dict()


def _writers():
    p0, v, d_um = _truth_arrays()
    dw, uvz, xyz = _dewarp_and_observations()
    return {
        "lightfield": lambda p: write_lightfield(p.with_suffix(".npz"), _lightfield()),
        "vector_field": lambda p: write_vector_field(p.with_suffix(".npz"), _vector_field()),
        "truth_npz": lambda p: write_truth(p.with_suffix(".npz"), positions_mm=[p0, p0 + v], times_s=[0, 1],
                                           diameters_um=d_um, velocities_mm_s=v),
        "truth_csv": lambda p: write_truth(p.with_suffix(".csv"), positions_mm=[p0, p0 + v], times_s=[0, 1],
                                           diameters_um=d_um, velocities_mm_s=v),
        "dewarp": lambda p: write_dewarp(p.with_suffix(".npz"), dw, uvz=uvz, xyz=xyz),
        "detections": lambda p: write_detections(p.with_suffix(".npz"), _detections(), min_map=np.ones((8, 8))),
        "volume": lambda p: write_volume(p.with_suffix(".npz"), np.ones((3, 5, 5), np.float32), {"grid": _grid_dict()}),
        "json": lambda p: write_json(p.with_suffix(".json"), {"a": [1, 2, 3]}),
        "text": lambda p: write_text(p.with_suffix(".md"), "# report\n"),
        "figure": lambda p: save_figure(_figure(), p.with_suffix(".png")),
    }


def _figure():
    from matplotlib.figure import Figure

    fig = Figure(figsize=(2, 2))
    fig.add_subplot().plot([0, 1], [1, 0])
    return fig


class DiskFull(OSError):
    pass


def _fail_on_rename_in(folder, monkeypatch):
    """os.replace fails for files in ``folder`` (the data are complete, the rename is not)."""
    real = os.replace

    def replace(src, dst, *a, **k):
        if Path(dst).parent == folder:
            raise DiskFull(28, "No space left on device")
        return real(src, dst, *a, **k)

    monkeypatch.setattr(os, "replace", replace)


@pytest.mark.parametrize("kind", list(_writers()))
def test_interrupted_rename_leaves_no_file(tmp_path, monkeypatch, kind):
    write = _writers()[kind]
    _fail_on_rename_in(tmp_path, monkeypatch)
    with pytest.raises(DiskFull):
        write(tmp_path / "target")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("kind", ["lightfield", "vector_field", "truth_npz", "dewarp", "detections", "volume"])
def test_npz_writer_failing_midway_leaves_no_file(tmp_path, monkeypatch, kind):
    """The archive writer dies after some bytes (a full disk): no target, no temporary file."""

    def half_written(file, *args, **kwds):
        file.write(b"PK\x03\x04" + b"\x00" * 100)
        raise DiskFull(28, "No space left on device")

    monkeypatch.setattr(np, "savez", half_written)
    monkeypatch.setattr(np, "savez_compressed", half_written)
    monkeypatch.setattr("mitpiv.io.arrays._savez", half_written)  # write_npz's own (time-stamp-free) savez
    with pytest.raises(DiskFull):
        _writers()[kind](tmp_path / "target")
    assert list(tmp_path.iterdir()) == []


def test_json_failing_midway_leaves_no_file_and_keeps_the_old_one(tmp_path):
    write_json(tmp_path / "metrics.json", {"v": 1})

    class Late:
        pass

    # json writes "a" and "b" before it meets the object it cannot encode
    with pytest.raises(ConfigError, match="metrics.json"):
        write_json(tmp_path / "metrics.json", {"a": list(range(1000)), "b": "x" * 10_000, "z": Late()})
    assert read_json(tmp_path / "metrics.json") == {"v": 1}
    assert [p.name for p in tmp_path.iterdir()] == ["metrics.json"]


def test_failed_overwrite_keeps_the_old_file(tmp_path, monkeypatch):
    f = _vector_field()
    write_vector_field(tmp_path / "f.npz", f)
    before = (tmp_path / "f.npz").read_bytes()
    _fail_on_rename_in(tmp_path, monkeypatch)
    with pytest.raises(DiskFull):
        write_vector_field(tmp_path / "f.npz", _vector_field(None))
    assert (tmp_path / "f.npz").read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["f.npz"]


def test_streamed_stack_appears_only_when_complete(tmp_path):
    """refocus_volume(out=...) streams planes into a memory map: an error at the third plane
    leaves neither the .npy nor its temporary file; a complete run leaves only the .npy."""
    from mitpiv.lightfield import refocus_volume

    lf = _lightfield()
    out = tmp_path / "vol.npy"
    with pytest.raises(ConfigError, match="z = 10"):
        refocus_volume(lf, [0.0, 1.0], [0.0, 1.0], [500.0, 400.0, 10.0], out=out)  # 10 mm: inside the focal length
    assert list(tmp_path.iterdir()) == []
    vol = refocus_volume(lf, [0.0, 1.0], [0.0, 1.0], [500.0, 400.0], out=out)
    assert vol.shape == (2, 2, 2) and [p.name for p in tmp_path.iterdir()] == ["vol.npy"]
    np.testing.assert_array_equal(np.load(out), refocus_volume(lf, [0.0, 1.0], [0.0, 1.0], [500.0, 400.0]))


def test_suffix_checks_write_nothing(tmp_path):
    with pytest.raises(ConfigError, match=".npz"):
        write_lightfield(tmp_path / "lf.h5", _lightfield())
    with pytest.raises(ConfigError, match=".npz"):
        write_vector_field(tmp_path / "f.txt", _vector_field())
    with pytest.raises(ConfigError, match=".npz"):
        write_dewarp(tmp_path / "d.npy", _dewarp_and_observations()[0])
    assert list(tmp_path.iterdir()) == []


# ----------------------------------------------------------------------------- imports


@pytest.mark.parametrize("order", [("mitpiv.io", "mitpiv.lightfield", "mitpiv.analysis"),
                                   ("mitpiv.lightfield", "mitpiv.analysis", "mitpiv.io"),
                                   ("mitpiv.analysis", "mitpiv.io", "mitpiv.lightfield")])
def test_imports_in_any_order_without_cycles(order):
    """Each order in a fresh interpreter; mitpiv.io alone loads no lightfield/analysis code."""
    code = ("import importlib, sys\n"
            "import mitpiv.io\n"
            "assert not any(m.startswith(('mitpiv.lightfield', 'mitpiv.analysis')) for m in sys.modules), sorted(sys.modules)\n"
            if order[0] == "mitpiv.io" else "import importlib, sys\n")
    code += "".join(f"importlib.import_module({m!r})\n" for m in order)
    code += "import mitpiv.io.lightfield, mitpiv.io.vectors, mitpiv.io.backlit\n"
    root = str(Path(__file__).resolve().parents[2])
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")]))}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stderr
