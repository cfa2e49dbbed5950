"""A focal stack's size is estimated and refused up front: an absurd plane count (1e7
planes of a 3 x 3 x 8 x 8 light field: 2.4 GiB and most of an hour) is refused at once in
the CLI and the library, naming the parameter, its value, the estimate and the fix; a stack
larger than the available memory (in memory) or the free disk (streamed to a ``.npy``) is
refused before anything is allocated or written. The refusals never reach the stack's
output (``stack_output`` is replaced by one that fails the test)."""

from __future__ import annotations

import shutil
from collections import namedtuple

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.lightfield import LightField, focal_stack, refocus_volume
from mitpiv.physics.plenoptic import PlenopticCamera


@pytest.fixture
def lf():
    optics = PlenopticCamera(resolution=(40, 40), pixel_pitch_um=5.0, focal_length_mm=50.0, f_number=4.0,
                             focus_distance_mm=250.0, mla_pitch_um=25.0)
    return LightField(data=np.ones((3, 3, 8, 8), np.float32), s_px=np.arange(8.0) * 5 + 2.5,
                      t_px=np.arange(8.0) * 5 + 2.5, du_px=np.array([-1.0, 0.0, 1.0]), view_weights=np.ones((3, 3)),
                      valid=np.ones((8, 8), bool), optics=optics)


@pytest.fixture
def no_output(monkeypatch):
    import importlib

    rf = importlib.import_module("mitpiv.lightfield.refocus")  # the module (the package exports a function of its name)

    def stack_output(*a, **k):
        raise AssertionError("the stack's output was made before its size was checked")

    monkeypatch.setattr(rf, "stack_output", stack_output)


def test_cli_refuses_an_absurd_plane_count_at_once(lf, tmp_path, capsys, no_output):
    from mitpiv.cli import main

    src = lf.save(tmp_path / "lf.npz")
    out = tmp_path / "out"
    out.mkdir()
    rc = main(["refocus", str(src), "--out", str(out / "s.npy"), "--z-range", "0", "1", "10000000"])
    err = capsys.readouterr().err
    assert rc == 2 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    assert "--z-range COUNT 10000000" in err and "100000" in err, err  # the parameter, its value, the limit
    assert "2.38 GiB" in err and "fewer planes" in err, err  # the estimate and the fix
    assert list(out.iterdir()) == []


def test_library_refuses_an_absurd_plane_count(lf, tmp_path, no_output):
    z = np.linspace(0.0, 1.0, 10_000_000)
    for out in (None, tmp_path / "s.npy"):
        with pytest.raises(ConfigError, match=r"focal_stack: z_mm has 10 M planes, more than the 100000 .*"
                                              r"(2.53 GiB of memory|2.38 GiB on disk).*fewer planes"):
            focal_stack(lf, z, out=out)
    assert list(tmp_path.iterdir()) == []


def test_a_stack_beyond_the_available_memory_is_refused(lf, monkeypatch, no_output):
    monkeypatch.setattr("mitpiv.costs.available_memory_bytes", lambda: 2**20)  # 1 MiB available
    with pytest.raises(ConfigError, match=r"focal_stack: z_mm of 10 k planes: .*2.6 MiB of memory.*"
                                          r"fewer planes, or give out="):
        focal_stack(lf, np.linspace(0.0, 1.0, 10_000))
    with pytest.raises(ConfigError, match=r"refocus_volume: z_mm of 1 k planes: .*16 MiB of memory.*fewer planes"):
        refocus_volume(lf, np.linspace(0.0, 1.0, 64), np.linspace(0.0, 1.0, 64), np.linspace(400.0, 500.0, 1000))


def test_a_streamed_stack_beyond_the_free_disk_is_refused(lf, tmp_path, monkeypatch, no_output):
    usage = namedtuple("usage", "total used free")
    monkeypatch.setattr(shutil, "disk_usage", lambda p: usage(2**30, 2**30 - 2**20, 2**20))  # 1 MiB free
    with pytest.raises(ConfigError, match=r"focal_stack: z_mm of 10 k planes: .*2.44 MiB on disk, more than the "
                                          r"1 MiB free in .*fewer planes"):
        focal_stack(lf, np.linspace(0.0, 1.0, 10_000), out=tmp_path / "s.npy")
    assert list(tmp_path.iterdir()) == []


def test_a_legal_stack_still_runs(lf, tmp_path):
    a = focal_stack(lf, np.linspace(0.0, 1.0, 5))
    b = focal_stack(lf, np.linspace(0.0, 1.0, 5), out=tmp_path / "s.npy")
    np.testing.assert_array_equal(a, np.asarray(b))
