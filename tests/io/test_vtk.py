"""VTK writers (pyevtk) read back by an independent reader, the ``vtk`` package's own XML
readers: geometry, array names, values, vector layout and types; a .pvd collection parsed
with the standard library; bad inputs refused with nothing written."""

import xml.etree.ElementTree as ET

import numpy as np
import pytest
import vtk
from vtk.util.numpy_support import vtk_to_numpy

from mitpiv.errors import ConfigError
from mitpiv.grid import VoxelGrid
from mitpiv.io import vtk as mv

#: Coordinates go through float64 both ways: equal to the last bit (exact).
EXACT = 0.0


def read(path, reader):
    r = reader()
    r.SetFileName(str(path))
    r.Update()
    return r.GetOutput()


def arr(data, name, shape=None):
    a = data.GetArray(name)
    assert a is not None, name
    out = vtk_to_numpy(a)
    return out if shape is None else out.reshape(shape)


def test_image_data_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    g = VoxelGrid((-1.0, -2.0, -3.0), (0.1, 0.2, 0.3), (4, 5, 6))  # anisotropic, n_z != n_y != n_x
    vol = rng.random(g.shape).astype(np.float32)
    vec = rng.normal(size=g.shape + (3,))
    mask = vol > 0.5
    mv.write_image_data(tmp_path / "v.vti", g, {"rec": vol, "vec": vec, "mask": mask})
    d = read(tmp_path / "v.vti", vtk.vtkXMLImageDataReader)
    assert d.GetDimensions() == (6, 5, 4)                       # (n_x, n_y, n_z)
    np.testing.assert_allclose(d.GetSpacing(), (0.1, 0.2, 0.3), rtol=1e-12)
    np.testing.assert_allclose(d.GetOrigin(), (g.x_mm[0], g.y_mm[0], g.z_mm[0]), rtol=1e-12)  # voxel centres
    pd = d.GetPointData()
    # VTK's point order is x fastest: the C-order ravel of a (n_z, n_y, n_x) volume
    np.testing.assert_array_equal(arr(pd, "rec", g.shape), vol)
    assert arr(pd, "rec").dtype == np.float32
    np.testing.assert_array_equal(arr(pd, "vec").reshape(g.shape + (3,)), vec)
    assert pd.GetArray("vec").GetNumberOfComponents() == 3
    np.testing.assert_array_equal(arr(pd, "mask", g.shape), mask.astype(np.uint8))
    # a world point: voxel (k, j, i) sits at the VTK point with the same coordinates
    k, j, i = 3, 1, 4
    pid = d.FindPoint(g.x_mm[i], g.y_mm[j], g.z_mm[k])
    assert arr(pd, "rec")[pid] == vol[k, j, i]


def test_structured_grid_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    x, y, z = np.linspace(-3, 3, 7), np.array([-1.0, 0.5, 2.0]), np.array([0.0, 0.4])
    shape = (z.size, y.size, x.size)
    u = rng.normal(size=shape + (3,))
    u[0, 1, 2] = np.nan
    flag = rng.random(shape) > 0.7
    mv.write_structured_grid(tmp_path / "f.vts", x, y, z, {"velocity": u, "outlier": flag, "snr": rng.random(shape)})
    d = read(tmp_path / "f.vts", vtk.vtkXMLStructuredGridReader)
    dims = [0, 0, 0]
    d.GetDimensions(dims)
    assert dims == [7, 3, 2]
    pts = vtk_to_numpy(d.GetPoints().GetData()).reshape(shape + (3,))
    zz, yy, xx = np.meshgrid(z, y, x, indexing="ij")
    assert np.max(np.abs(pts - np.stack([xx, yy, zz], axis=-1))) <= EXACT
    got = arr(d.GetPointData(), "velocity").reshape(shape + (3,))
    np.testing.assert_array_equal(got, u)  # NaN where NaN
    np.testing.assert_array_equal(arr(d.GetPointData(), "outlier", shape), flag.astype(np.uint8))


def test_points_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    p = rng.uniform(-5, 5, (50, 3))
    err = rng.normal(size=(50, 3))
    match = rng.random(50) > 0.3
    mv.write_points(tmp_path / "p.vtu", p, {"match": match, "error_mm": err, "id": np.arange(50)})
    d = read(tmp_path / "p.vtu", vtk.vtkXMLUnstructuredGridReader)
    assert d.GetNumberOfPoints() == 50 and d.GetNumberOfCells() == 50
    assert d.GetCellType(0) == vtk.VTK_VERTEX
    assert np.max(np.abs(vtk_to_numpy(d.GetPoints().GetData()) - p)) <= EXACT
    np.testing.assert_array_equal(arr(d.GetPointData(), "error_mm"), err)
    np.testing.assert_array_equal(arr(d.GetPointData(), "match"), match.astype(np.uint8))
    np.testing.assert_array_equal(arr(d.GetPointData(), "id"), np.arange(50))


def test_tracks_round_trip(tmp_path):
    """Three tracks of 4, 1 and 3 points given interleaved and out of order: one polyline
    per track id, its points in the order given."""
    rng = np.random.default_rng(4)
    tid = np.array([7, 2, 7, 9, 9, 7, 9, 7])
    p = rng.normal(size=(8, 3))
    t = np.arange(8) * 0.1
    mv.write_tracks(tmp_path / "t.vtu", p, tid, {"time_s": t}, track_arrays={"correct": np.array([True, False, True])})
    d = read(tmp_path / "t.vtu", vtk.vtkXMLUnstructuredGridReader)
    assert d.GetNumberOfCells() == 3
    pts = vtk_to_numpy(d.GetPoints().GetData())
    times = arr(d.GetPointData(), "time_s")
    for c, track in enumerate((2, 7, 9)):
        cell = d.GetCell(c)
        assert d.GetCellType(c) == vtk.VTK_POLY_LINE
        ids = [cell.GetPointId(k) for k in range(cell.GetNumberOfPoints())]
        mine = np.flatnonzero(tid == track)
        np.testing.assert_array_equal(pts[ids], p[mine])
        np.testing.assert_array_equal(times[ids], t[mine])
    np.testing.assert_array_equal(arr(d.GetCellData(), "track_id"), [2, 7, 9])
    np.testing.assert_array_equal(arr(d.GetCellData(), "correct"), [1, 0, 1])


def test_collection_lists_files_relative_with_times(tmp_path):
    g = VoxelGrid((0, 0, 0), 1.0, (2, 2, 2))
    files = [mv.write_image_data(tmp_path / "sub" / f"v{k}.vti", g, {"a": np.full(g.shape, k, float)}) for k in (0, 1)]
    mv.write_collection(tmp_path / "sub" / "all.pvd", [(files[0], 0.0, 0, "volume"), ("v1.vti", 0.5, 0, "volume")])
    ds = ET.parse(tmp_path / "sub" / "all.pvd").getroot().findall("./Collection/DataSet")
    assert [(e.get("file"), float(e.get("timestep")), e.get("name")) for e in ds] == [
        ("v0.vti", 0.0, "volume"), ("v1.vti", 0.5, "volume")]
    for e in ds:  # every referenced file loads
        d = read(tmp_path / "sub" / e.get("file"), vtk.vtkXMLImageDataReader)
        assert d.GetNumberOfPoints() == 8


def test_collection_refuses_entries_that_do_not_resolve_from_its_folder(tmp_path, monkeypatch):
    # a path relative to the working folder, not to the collection's: ParaView would look
    # for sub/sub/v0.vti, so it is refused (naming the entry and the fix), nothing written
    g = VoxelGrid((0, 0, 0), 1.0, (2, 2, 2))
    monkeypatch.chdir(tmp_path)
    mv.write_image_data("sub/v0.vti", g, {"a": np.zeros(g.shape)})
    with pytest.raises(ConfigError, match=r"'sub/v0\.vti'.*collection's folder 'sub'.*'v0\.vti'"):
        mv.write_collection("sub/all.pvd", [("sub/v0.vti", 0.0)])
    with pytest.raises(ConfigError, match=r"'missing\.vti'"):
        mv.write_collection("sub/all.pvd", [("v0.vti", 0.0), ("missing.vti", 0.5)])
    assert sorted(p.name for p in (tmp_path / "sub").iterdir()) == ["v0.vti"]
    # the file's name (relative to the collection) or its absolute path: both stored as 'v0.vti'
    mv.write_collection("sub/all.pvd", [("v0.vti", 0.0), (tmp_path / "sub" / "v0.vti", 0.5)])
    ds = ET.parse(tmp_path / "sub" / "all.pvd").getroot().findall("./Collection/DataSet")
    assert [e.get("file") for e in ds] == ["v0.vti", "v0.vti"]


def test_bad_inputs_write_nothing(tmp_path):
    g = VoxelGrid((0, 0, 0), 1.0, (2, 3, 4))
    with pytest.raises(ConfigError, match=r"'v'.*\(2, 3, 4\)"):
        mv.write_image_data(tmp_path / "a.vti", g, {"v": np.zeros((4, 3, 2))})
    with pytest.raises(ConfigError, match=r"\.vti"):
        mv.write_image_data(tmp_path / "a.vtk", g, {"v": np.zeros(g.shape)})
    with pytest.raises(ConfigError, match="positions_mm"):
        mv.write_points(tmp_path / "p.vtu", np.zeros((5, 2)))
    with pytest.raises(ConfigError, match="track_id"):
        mv.write_tracks(tmp_path / "t.vtu", np.zeros((5, 3)), np.zeros(4, int))
    with pytest.raises(ConfigError, match="track_id"):
        mv.write_tracks(tmp_path / "t.vtu", np.zeros((5, 3)), np.zeros(5))
    assert not list(tmp_path.iterdir())
