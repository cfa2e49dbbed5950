"""`mitpiv evaluate` and `mitpiv piv` on volumes in the `mitpiv reconstruct` format."""

import json

import numpy as np

from mitpiv.analysis import VectorField, truth_volume
from mitpiv.cli import main
from mitpiv.io import write_truth
from mitpiv.physics.advection import advect
from mitpiv.physics.flows import SolidBody
from mitpiv.reconstruct import VoxelGrid

GRID = VoxelGrid((0.0, 0.0, 0.0), (0.05, 0.05, 0.05), (48, 48, 48))


def save_volume(path, vol, grid=GRID):
    with open(path, "wb") as fh:
        np.savez_compressed(fh, volume=vol, meta=json.dumps({"method": "test", "grid": grid.to_dict()}))
    return path


def scene(tmp_path):
    rng = np.random.default_rng(4)
    p0 = rng.uniform(-0.3, 2.7, (2500, 3))
    flow = SolidBody(omega_rad_s=1.5, center=(1.2, 1.2, 0.0), axis=(0, 0, 1))  # <= 0.7 voxel
    dt = 0.02
    p1 = advect(p0, flow, dt_s=dt)
    truth = write_truth(tmp_path / "truth.npz", positions_mm=np.stack([p0, p1]), times_s=[0.0, dt], diameters_um=2.0,
                        flow=flow.to_dict())
    a = save_volume(tmp_path / "a.npz", truth_volume(p0, GRID, sigma_voxels=1.0))
    b = save_volume(tmp_path / "b.npz", truth_volume(p1, GRID, sigma_voxels=1.0))
    return a, b, truth


def test_evaluate_and_piv(tmp_path, capsys):
    a, b, truth = scene(tmp_path)
    assert main(["evaluate", str(b), "--truth", str(truth), "--frame", "1", "--out", str(tmp_path / "m.json")]) == 0
    m = json.loads((tmp_path / "m.json").read_text())
    # blobs overlap at this seeding (0.02 per voxel); the truth blobs of evaluate are narrower (sigma 0.7)
    assert m["particles"]["detection_rate"] > 0.6 and m["Q"] > 0.9
    assert (tmp_path / "m.png").stat().st_size > 10_000
    assert "detection" in capsys.readouterr().out
    # the threshold's reference: robust by default, the brightest voxel on request (higher:
    # a blob's peak can sit on the brightest of overlapping blobs)
    assert m["particles"]["threshold_of"] == "robust"
    assert main(["evaluate", str(b), "--truth", str(truth), "--frame", "1", "--threshold-of", "max", "--out",
                 str(tmp_path / "mx.json")]) == 0
    mx = json.loads((tmp_path / "mx.json").read_text())["particles"]
    assert mx["threshold_of"] == "max" and mx["threshold_reference"] >= m["particles"]["threshold_reference"]
    out = tmp_path / "f.npz"
    assert main(["piv", str(a), str(b), "--out", str(out), "--windows", "32", "16", "--overlap", "0.5",
                 "--truth", str(truth)]) == 0
    f = VectorField.load(out)
    err = f.info["velocity_error"]
    assert f.units == "mm/s" and f.dt_s == 0.02  # dt taken from the truth file
    assert max(err["rms_vox"]) < 0.1 and (tmp_path / "f.error.png").exists()
    assert "velocity error" in capsys.readouterr().out
    assert main(["piv", str(a), str(b), "--out", str(tmp_path / "g.npz"), "--windows", "24x24x16", "--no-deform",
                 "--replace", "none", "--dt", "0.02"]) == 0
    assert VectorField.load(tmp_path / "g.npz").window_vox == (24, 24, 16)


def test_bad_inputs_write_nothing(tmp_path, capsys):
    a, b, truth = scene(tmp_path)
    other = save_volume(tmp_path / "c.npz", np.zeros((40, 48, 48)), VoxelGrid((0.0, 0.0, 0.0), (0.05,) * 3, (40, 48, 48)))
    cases = [
        ["piv", str(a), str(other), "--out", str(tmp_path / "x.npz")],
        ["piv", str(a), str(tmp_path / "missing.npz"), "--out", str(tmp_path / "x.npz")],
        ["piv", str(a), str(b), "--out", str(tmp_path / "x.npz"), "--windows", "64"],
        ["piv", str(a), str(b), "--out", str(tmp_path / "x.npz"), "--windows", "16x16"],
        ["piv", str(a), str(b), "--out", str(tmp_path / "x.vtk")],
        ["piv", str(a), str(truth), "--out", str(tmp_path / "x.npz")],
        ["evaluate", str(a), "--truth", str(truth), "--frame", "5"],
        ["evaluate", str(a), "--truth", str(truth), "--out", str(tmp_path / "x.txt")],
    ]
    for argv in cases:
        assert main(argv) == 2, argv
        msg = capsys.readouterr().err
        assert msg.startswith("mitpiv: error:") and len(msg.splitlines()) == 1, msg
    assert not any(p.name.startswith("x.") for p in tmp_path.iterdir())
