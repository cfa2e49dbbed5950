"""EXR + metadata, particle PLY and truth files: round trips, bad input, atomic writes."""

import numpy as np
import pytest

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.io import (
    read_exr,
    read_exr_metadata,
    read_particles_ply,
    read_truth,
    write_exr,
    write_particles_ply,
    write_truth,
)


def test_exr_round_trip_with_metadata(tmp_path):
    img = np.random.default_rng(0).random((7, 9)).astype(np.float32)
    meta = {"camera": {"K": np.eye(3)}, "frame": 1, "seed": np.int64(3), "units": "mm"}
    write_exr(tmp_path / "a.exr", img, meta)
    back, m = read_exr(tmp_path / "a.exr")
    np.testing.assert_array_equal(back, img)
    assert m == {"camera": {"K": np.eye(3).tolist()}, "frame": 1, "seed": 3, "units": "mm"}
    rgb = np.random.default_rng(1).random((4, 5, 3)).astype(np.float32)
    write_exr(tmp_path / "c.exr", rgb, {})
    np.testing.assert_array_equal(read_exr(tmp_path / "c.exr")[0], rgb)
    # the header alone gives the same metadata
    assert read_exr_metadata(tmp_path / "a.exr") == m
    assert read_exr_metadata(tmp_path / "c.exr") == {}


def test_exr_bad_input_writes_nothing(tmp_path):
    bad = np.ones((4, 4))
    bad[1, 1] = np.nan
    with pytest.raises(ConfigError, match="non-finite"):
        write_exr(tmp_path / "b.exr", bad, {})
    with pytest.raises(ConfigError, match="JSON"):
        write_exr(tmp_path / "b.exr", np.ones((2, 2)), {"x": object()})
    with pytest.raises(ConfigError, match="shape"):
        write_exr(tmp_path / "b.exr", np.ones(5), {})
    assert list(tmp_path.iterdir()) == []


def test_exr_overwrite_failure_keeps_old_file(tmp_path):
    write_exr(tmp_path / "a.exr", np.ones((2, 2)), {"v": 1})
    with pytest.raises(ConfigError):
        write_exr(tmp_path / "a.exr", np.full((2, 2), np.inf), {"v": 2})
    assert read_exr(tmp_path / "a.exr")[1] == {"v": 1}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.exr"]


def test_read_exr_errors(tmp_path):
    with pytest.raises(FileFormatError, match="does not exist"):
        read_exr(tmp_path / "none.exr")
    (tmp_path / "junk.exr").write_bytes(b"not an exr")
    with pytest.raises(FileFormatError, match="not a readable EXR"):
        read_exr(tmp_path / "junk.exr")
    with pytest.raises(FileFormatError, match="read_exr_metadata: .*not a readable EXR"):
        read_exr_metadata(tmp_path / "junk.exr")
    with pytest.raises(FileFormatError, match="read_exr_metadata: .*does not exist"):
        read_exr_metadata(tmp_path / "none.exr")


def test_ply_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    pos = rng.normal(size=(50, 3)) * 10
    d = rng.uniform(0.5, 3, 50)
    write_particles_ply(tmp_path / "p.ply", pos, d, proxy_radius_mm=0.02)
    back = read_particles_ply(tmp_path / "p.ply")
    np.testing.assert_allclose(back["positions_mm"], pos, rtol=1e-7, atol=1e-6)  # float32 storage
    np.testing.assert_allclose(back["diameters_um"], d, rtol=1e-7)
    np.testing.assert_allclose(back["proxy_radius_mm"], 0.02, rtol=1e-6)


def test_ply_malformed(tmp_path):
    with pytest.raises(FileFormatError, match="does not exist"):
        read_particles_ply(tmp_path / "x.ply")
    (tmp_path / "t.ply").write_bytes(b"hello")
    with pytest.raises(FileFormatError, match="not a PLY"):
        read_particles_ply(tmp_path / "t.ply")
    write_particles_ply(tmp_path / "p.ply", np.zeros((3, 3)), 1.0, proxy_radius_mm=0.01)
    raw = (tmp_path / "p.ply").read_bytes()
    (tmp_path / "cut.ply").write_bytes(raw[:-5])
    with pytest.raises(FileFormatError, match="truncated"):
        read_particles_ply(tmp_path / "cut.ply")
    with pytest.raises(ConfigError, match="proxy_radius_mm"):
        write_particles_ply(tmp_path / "q.ply", np.zeros((3, 3)), 1.0, proxy_radius_mm=0)
    with pytest.raises(ConfigError, match="diameters_um"):
        write_particles_ply(tmp_path / "q.ply", np.zeros((3, 3)), -1.0, proxy_radius_mm=0.1)
    assert not (tmp_path / "q.ply").exists()


def test_truth_npz_and_csv(tmp_path):
    p0 = np.random.default_rng(3).normal(size=(20, 3))
    p1 = p0 + 0.1
    write_truth(tmp_path / "t.npz", positions_mm=[p0, p1], times_s=[0, 0.001], diameters_um=1.0, flow={"kind": "uniform"})
    t = read_truth(tmp_path / "t.npz")
    np.testing.assert_allclose(t["displacements_mm"][0], 0.1)
    assert t["flow"] == {"kind": "uniform"}
    write_truth(tmp_path / "t.csv", positions_mm=[p0, p1], times_s=[0, 0.001], diameters_um=1.0)
    rows = np.loadtxt(tmp_path / "t.csv", delimiter=",", skiprows=1)
    np.testing.assert_allclose(rows[:, 2:5], p0)
    np.testing.assert_allclose(rows[:, -3:], 0.1)
    with pytest.raises(ConfigError, match="npz or .csv"):
        write_truth(tmp_path / "t.txt", positions_mm=[p0], times_s=[0], diameters_um=1.0)


def test_atomic_files_get_plain_permissions(tmp_path):
    import os
    import stat

    from mitpiv.io.atomic import atomic_path

    with atomic_path(tmp_path / "a.txt") as tmp:
        tmp.write_text("x")
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE((tmp_path / "a.txt").stat().st_mode) == 0o666 & ~umask
