"""``mitpiv score`` (issue 52, item 2): another tool's result scored against a run's truth.

Independent references:

* the OpenPIV round trip: a planar run's sensor images exported as TIFFs, OpenPIV (a test
  dependency) correlating them, and the window-averaged truth recomputed here window by
  window from the truth file (each window's particles selected with boolean masks, the
  Gaussian sheet's irradiance ``exp(-ln 2 (2 z / t)^2)`` written afresh) against the score's
  integral-image version: equal to 1e-9 px (both float64 sums of the same particles);
* 3-D fields and particles on synthetic run folders whose truth is known in closed form
  (a uniform flow: the window-averaged reference is the flow itself, so the error is the
  noise the test added; particles dropped and ghosts added by construction).
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.io import write_json, write_truth
from mitpiv.studies.score import ResultMismatch, score

ROOT = Path(__file__).resolve().parents[2]
PLANAR = ROOT / "scenes" / "planar" / "experiment.toml"
WIN = 32


@pytest.fixture(scope="module")
def planar(tmp_path_factory):
    """The planar scene at 256 px, rendered to sensor counts, exported to TIFF and correlated
    by OpenPIV (one pass, 32 px windows, 50 % overlap)."""
    from openpiv import pyprocess, tools, validation

    from mitpiv.studies import run_experiment
    from mitpiv.studies.export import export_images

    d = tmp_path_factory.mktemp("planar")
    run = d / "run"
    run_experiment(PLANAR, run, overrides={"scene.params": {"resolution": 256}}, until="sensor", progress=False)
    m = export_images(run, d / "tiff", progress=False)
    a, b = (cv2.imread(str(d / "tiff" / f), cv2.IMREAD_UNCHANGED).astype(np.float64) for f in m["files"]["cam0"])
    u, v, s2n = pyprocess.extended_search_area_piv(a, b, window_size=WIN, overlap=WIN // 2, dt=1.0,
                                                   search_area_size=WIN, sig2noise_method="peak2peak")
    x, y = pyprocess.get_coordinates(a.shape, WIN, WIN // 2)
    flags = validation.sig2noise_val(s2n, threshold=1.05)
    tools.save(d / "field.txt", x, y, u, v, flags)
    xp, yp, up, vp = tools.transform_coordinates(x.copy(), y.copy(), u.copy(), v.copy())
    tools.save(d / "field_up.txt", xp, yp, up, vp, flags)
    return {"dir": d, "run": run, "manifest": m, "x": x, "y": y, "u": u, "v": v, "flags": flags}


def _truth_by_windows(run: Path, x, y, win):
    """The window-averaged image displacement, window by window (the independent reference)."""
    from mitpiv.io import camera_from_metadata, read_exr, read_truth

    truth = read_truth(run / "particles" / "truth.npz")
    cam = camera_from_metadata(read_exr(run / "render" / "cam0_frame000.exr")[1])
    pa_w, pb_w = truth["positions_mm"][0], truth["positions_mm"][1]
    pa, pb = cam.project(pa_w), cam.project(pb_w)
    t = 1.0  # the scene's sheet thickness [mm] (FWHM), about the z = 0 plane

    def intensity(p):
        return truth["diameters_um"] ** 2 * np.exp(-np.log(2.0) * (2.0 * p[:, 2] / t) ** 2)

    w = intensity(pa_w) * intensity(pb_w) * cam.visible(pa_w) * cam.visible(pb_w)
    ref = np.full((x.size, 2), np.nan)
    for k, (xc, yc) in enumerate(zip(x.ravel(), y.ravel(), strict=True)):
        sel = ((pa[:, 0] >= xc - win / 2) & (pa[:, 0] < xc + win / 2) & (pa[:, 1] >= yc - win / 2)
               & (pa[:, 1] < yc + win / 2) & (w > 0))
        if sel.any():
            ref[k] = np.sum(w[sel, None] * (pb[sel] - pa[sel]), axis=0) / w[sel].sum()
    return ref


def test_openpiv_round_trip_is_scored_as_computed_independently(planar, capsys):
    from mitpiv.cli import main

    out = planar["dir"] / "score"
    assert main(["-q", "score", str(planar["run"]), str(planar["dir"] / "field.txt"), "--window", str(WIN),
                 "--reference", "particles", "--out", str(out)]) == 0
    assert "vectors on cam0: RMS error" in capsys.readouterr().out
    m = json.loads((out / "score.json").read_text())
    ref = _truth_by_windows(planar["run"], planar["x"], planar["y"], WIN)
    meas = np.loadtxt(planar["dir"] / "field.txt")[:, 2:4]  # as saved (OpenPIV writes 5 significant digits)
    ok = (planar["flags"].ravel() == 0) & np.all(np.isfinite(ref), axis=1)
    e = meas[ok] - ref[ok]
    assert m["n_scored"] == int(ok.sum()) and m["n_vectors"] == planar["x"].size
    np.testing.assert_allclose(m["rms_px"], np.sqrt(np.mean(e**2, axis=0)), rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(m["bias_px"], e.mean(axis=0), rtol=1e-9, atol=1e-12)
    assert m["error_outlier_fraction"] == pytest.approx(np.mean(np.linalg.norm(e, axis=1) > 1.0))
    # the physics: one 32 px pass on a vortex moving up to 4.6 px is good to a few tenths of a pixel;
    # an unscaled or misplaced truth would be off by pixels
    assert max(m["rms_px"]) < 0.35
    assert m["flags"] == [] and m["particles_per_window"] > 5
    assert (out / "score.md").read_text().count("|") > 10 and (out / "velocity_error.png").stat().st_size > 10_000
    # against the flow reference (the default): the same vectors, the sample noise of the
    # particle reference gone; the two references differ by the reported spread
    f = score(planar["run"], planar["dir"] / "field.txt", window=WIN, out_dir=planar["dir"] / "score_flow")
    assert f["reference"] == "flow" and f["plane"] == "the laser sheet's mid-plane"
    assert 0.0 < f["reference_spread_px"] < 0.3 and f["n_scored"] >= m["n_scored"]
    assert max(f["rms_px"]) < 0.35


def test_flow_reference_against_closed_form(planar):
    """A uniform flow on the sheet seen by the camera normal to it (15 px per mm at the
    sheet, image y down): every window's reference is the pinhole's image of the world
    displacement, written here in closed form."""
    from mitpiv.io import camera_from_metadata, read_exr
    from mitpiv.physics.flows import LambOseen, Uniform
    from mitpiv.studies.score import flow_image_reference

    cam = camera_from_metadata(read_exr(planar["run"] / "render" / "cam0_frame000.exr")[1])
    c = np.stack([planar["x"].ravel(), planar["y"].ravel()], axis=1)
    v = np.array([120.0, -40.0, 30.0])  # mm/s; w moves particles within the plane's normal only
    ref = flow_image_reference(cam, Uniform(v), c, 32, plane_point_mm=[0, 0, 0], plane_normal=[0, 0, 1], t0_s=0.0,
                               dt_s=0.001)
    # the pinhole at height D = 400 mm, f = 6000 px: u = cx + f X / (D - Z), v = cy - f Y / (D - Z); the
    # z motion (0.03 mm) changes the scale by 7.5e-5
    (cx, cy), f, D = cam.principal_point_px, 6000.0, 400.0
    assert cam.focal_px == f and cam.position_mm[2] == pytest.approx(D)
    world0 = np.column_stack([(c[:, 0] - cx) * D / f, -(c[:, 1] - cy) * D / f, np.zeros(len(c))])
    world1 = world0 + v * 0.001
    s1 = f / (D - world1[:, 2])
    expect = np.column_stack([world1[:, 0] * s1 - world0[:, 0] * f / D, -(world1[:, 1] * s1 - world0[:, 1] * f / D)])
    np.testing.assert_allclose(ref, expect, atol=1e-9)
    # solid-body rotation in a Lamb-Oseen core is linear in position: the 4 x 4 average is the value
    # at the window centre to the rotation's second order (theta^2 / 2 of the 0.12 rad step)
    lo = LambOseen(circulation_mm2_s=12000.0, core_radius_mm=4.0)
    centre = flow_image_reference(cam, lo, np.array([[cx + 15.0, cy]]), 1e-6, plane_point_mm=[0, 0, 0],
                                  plane_normal=[0, 0, 1], t0_s=0.0, dt_s=0.001)
    r = 1.0  # mm from the axis
    omega = 12000.0 / (2 * np.pi * r**2) * (1 - np.exp(-(r**2) / 16.0))  # rad/s
    th = omega * 0.001
    np.testing.assert_allclose(centre[0], [15 * r * (np.cos(th) - 1), -15 * r * np.sin(th)], atol=1e-6)


def test_y_up_field_is_refused_and_flip_y_scores_it(planar, tmp_path):
    with pytest.raises(ResultMismatch, match="--flip-y"):
        score(planar["run"], planar["dir"] / "field_up.txt", window=WIN, out_dir=tmp_path / "a")
    assert not (tmp_path / "a").exists()  # nothing written
    a = score(planar["run"], planar["dir"] / "field.txt", window=WIN, out_dir=tmp_path / "b")
    b = score(planar["run"], planar["dir"] / "field_up.txt", window=WIN, out_dir=tmp_path / "c", flip_y=True)
    np.testing.assert_allclose(b["rms_px"], a["rms_px"], rtol=1e-9)
    f = score(planar["run"], planar["dir"] / "field_up.txt", window=WIN, out_dir=tmp_path / "d", force=True)
    assert f["flags"] and json.loads((tmp_path / "d" / "score.json").read_text())["flags"] == f["flags"]


def test_world_units_field_on_the_sheet(planar, tmp_path):
    """The flow sampled at world points of the sheet, in mm and mm/s and again in m and m/s:
    both score alike, small against the window-averaged truth; m read as mm is refused."""
    from mitpiv.io import read_truth
    from mitpiv.physics.flows import flow_from_dict

    truth = read_truth(planar["run"] / "particles" / "truth.npz")
    flow = flow_from_dict(dict(truth["flow"]))
    g = np.arange(-7.0, 7.01, 1.0)
    xx, yy = np.meshgrid(g, g)
    p = np.stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)], axis=1)
    vel = flow(p, 0.0005)  # the middle of the frame interval
    mm = {"x": p[:, 0], "y": p[:, 1], "u": vel[:, 0], "v": vel[:, 1]}
    pd.DataFrame(mm).to_csv(tmp_path / "mm.csv", index=False)
    pd.DataFrame({k: v / 1e3 for k, v in mm.items()}).to_csv(tmp_path / "m.csv", index=False)
    win_mm = WIN / 15.0 / 2  # 16 px at 15 px per mm
    a = score(planar["run"], tmp_path / "mm.csv", window=win_mm, length_unit="mm", velocity_unit="mm/s",
              plane_z_mm=0.0, out_dir=tmp_path / "a")
    b = score(planar["run"], tmp_path / "m.csv", window=win_mm / 1e3, length_unit="m", velocity_unit="m/s",
              plane_z_mm=0.0, out_dir=tmp_path / "b")
    np.testing.assert_allclose(b["rms_px"], a["rms_px"], rtol=1e-6)
    assert a["window_px"] == pytest.approx(16.0, rel=1e-6)
    # a point value against the particles of a 16 px window: in the core (solid-body rotation, 0.119 px
    # per px over the frame interval) the displacement varies by 1.9 px across a window that holds some
    # 8 particles (a sampling spread up to 1.9 / sqrt(12 x 8) = 0.19 px there, less outside); a unit or
    # plane slip errs by pixels
    assert max(a["rms_px"]) < 0.3
    with pytest.raises(ResultMismatch, match="less than one"):
        score(planar["run"], tmp_path / "m.csv", window=win_mm, length_unit="mm", velocity_unit="mm/s",
              out_dir=tmp_path / "c", plane_z_mm=0.0)


# ------------------------------------------------------------------------------ synthetic runs


def _fake_run(folder: Path, *, frames: int = 2, n: int = 400, velocity=(100.0, -50.0, 20.0), dt=0.002, seed=0):
    """A run folder reduced to what scoring reads: experiment.json and a truth of a uniform flow."""
    from mitpiv.physics.flows import Uniform

    rng = np.random.default_rng(seed)
    folder.mkdir(parents=True)
    lo, hi = np.array([-5.0, -5.0, -2.0]), np.array([5.0, 5.0, 2.0])
    write_json(folder / "experiment.json", {"kind": "tomo", "seeding": {"box_min_mm": lo.tolist(),
                                                                          "box_max_mm": hi.tolist()},
                                            "reconstruction": {"voxel_mm": 0.1}, "particles": {"radius_voxels": 2.0}})
    p0 = rng.uniform(lo + 1, hi - 1, (n, 3))
    v = np.asarray(velocity, float)
    times = dt * np.arange(frames)
    pos = p0[None] + times[:, None, None] * v
    write_truth(folder / "particles" / "truth.npz", positions_mm=pos, times_s=times, diameters_um=np.ones(n),
                velocities_mm_s=np.broadcast_to(v, pos.shape).copy(), flow=Uniform(v).to_dict())
    return folder, pos, v


def test_3d_field_error_is_the_added_noise(tmp_path):
    run, _, v = _fake_run(tmp_path / "run")
    rng = np.random.default_rng(1)
    g = np.arange(-3.0, 3.01, 0.8)
    zz, yy, xx = np.meshgrid(np.arange(-1.2, 1.21, 0.8), g, g, indexing="ij")
    noise = rng.normal(0, 2.0, xx.shape + (3,))
    u = v + noise
    cols = {"x": xx.ravel(), "y": yy.ravel(), "z": zz.ravel(), "u": u[..., 0].ravel() / 1e3,
            "v": u[..., 1].ravel() / 1e3, "w": u[..., 2].ravel() / 1e3}
    np.savez(tmp_path / "f.npz", **cols, length_unit="mm", velocity_unit="m/s")
    m = score(run, tmp_path / "f.npz", window=1.6, out_dir=tmp_path / "s")
    e = noise.reshape(-1, 3)
    np.testing.assert_allclose(m["rms"], np.sqrt(np.mean(e**2, axis=0)), rtol=1e-9)
    np.testing.assert_allclose(m["rms_vox"], np.array(m["rms"]) * 0.002 / 0.1, rtol=1e-9)
    assert m["n"] == xx.size and m["kind"] == "vectors-3d"
    # the same field as displacements in the run's voxels over the frame interval
    d = u * 0.002 / 0.1
    pd.DataFrame({"x": xx.ravel(), "y": yy.ravel(), "z": zz.ravel(), "u": d[..., 0].ravel(), "v": d[..., 1].ravel(),
                  "w": d[..., 2].ravel()}).to_csv(tmp_path / "vox.csv", index=False)
    m2 = score(run, tmp_path / "vox.csv", window=1.6, length_unit="mm", velocity_unit="vox", out_dir=tmp_path / "t")
    np.testing.assert_allclose(m2["rms"], m["rms"], rtol=1e-9)
    # displacements read as velocities: 1 / 500 of the truth, refused with the cause
    with pytest.raises(ResultMismatch, match="displacement read as a velocity"):
        score(run, tmp_path / "vox.csv", window=1.6, length_unit="mm", velocity_unit="mm/s", out_dir=tmp_path / "u")


def test_particles_yield_ghosts_and_error_by_construction(tmp_path):
    run, pos, _ = _fake_run(tmp_path / "run", n=400)
    rng = np.random.default_rng(2)
    rows = []
    for f in (0, 1):
        keep = np.flatnonzero(rng.uniform(size=400) > 0.1)
        noise = rng.normal(0, 0.01, (keep.size, 3))
        ghosts = rng.uniform([-4, -4, -1], [4, 4, 1], (30, 3))
        far = np.min(np.linalg.norm(ghosts[:, None] - pos[f][None], axis=2), axis=1) > 0.2
        ghosts = ghosts[far]
        found = np.concatenate([pos[f][keep] + noise, ghosts])
        rows.append(pd.DataFrame({"frame": f, "x": found[:, 0], "y": found[:, 1], "z": found[:, 2]}))
        rows[-1].attrs = {"kept": keep.size, "ghosts": len(ghosts), "err": np.linalg.norm(noise, axis=1)}
    pd.concat(rows).to_csv(tmp_path / "p.csv", index=False)
    m = score(run, tmp_path / "p.csv", out_dir=tmp_path / "s")
    kept = sum(r.attrs["kept"] for r in rows)
    gh = sum(r.attrs["ghosts"] for r in rows)
    assert m["kind"] == "particles" and m["match_radius_mm"] == pytest.approx(0.2)
    assert m["n_true"] == 800 and m["n_matched"] == kept and m["n_found"] == kept + gh
    assert m["yield"] == pytest.approx(kept / 800) and m["ghost_fraction"] == pytest.approx(gh / (kept + gh))
    err = np.concatenate([r.attrs["err"] for r in rows])
    assert m["position_error_mm"] == pytest.approx(err.mean(), rel=1e-9)
    assert (tmp_path / "s" / "particles.png").is_file()
    # the same positions in m, read as mm: outside the volume, refused
    df = pd.read_csv(tmp_path / "p.csv")
    df[["x", "y", "z"]] *= 1e3
    df.to_csv(tmp_path / "p_um.csv", index=False)
    with pytest.raises(ResultMismatch, match="outside the run's volume"):
        score(run, tmp_path / "p_um.csv", out_dir=tmp_path / "t")
    # a frame off by one: the nearest true particle is too far
    df = pd.read_csv(tmp_path / "p.csv")
    df[df.frame == 1].assign(frame=0).to_csv(tmp_path / "p_shift.csv", index=False)
    with pytest.raises(ResultMismatch, match="--first-frame"):  # 0.23 mm of motion, a 0.1 mm radius
        score(run, tmp_path / "p_shift.csv", out_dir=tmp_path / "u", radius_mm=0.1)
    assert score(run, tmp_path / "p_shift.csv", out_dir=tmp_path / "v", radius_mm=0.1, first_frame=1)["yield"] > 0.85


def _write_ptv_is(folder: Path, frames: list[np.ndarray], links: list[np.ndarray]):
    """liboptv's ptv_is format: a count line, then ``prev next x y z`` per particle."""
    folder.mkdir(parents=True, exist_ok=True)
    for k, (p, prev) in enumerate(zip(frames, links, strict=True)):
        lines = [str(len(p))] + [f"{int(a):4d} {-2:4d} {x:10.5f} {y:10.5f} {z:10.5f}" for a, (x, y, z) in zip(prev, p,
                                                                                                            strict=True)]
        (folder / f"ptv_is.{10001 + k}").write_text("\n".join(lines) + "\n")


def test_tracks_from_openptv_and_csv(tmp_path):
    run, pos, v = _fake_run(tmp_path / "run", frames=8, n=60)
    rng = np.random.default_rng(3)
    # OpenPTV: each frame's rows in a shuffled order, linked by 'prev' to the row of the same particle
    frames, links, prev_order = [], [], None
    for f in range(8):
        order = rng.permutation(60)
        frames.append(pos[f][order] + rng.normal(0, 0.002, (60, 3)))
        if prev_order is None:
            links.append(np.full(60, -1))
        else:
            where = np.argsort(prev_order)  # row of particle i in the previous frame
            links.append(where[order])
        prev_order = order
    _write_ptv_is(tmp_path / "res", frames, links)
    m = score(run, tmp_path / "res", out_dir=tmp_path / "s")
    assert m["kind"] == "tracks" and m["n_tracks"] == 60 and m["yield"] == pytest.approx(1.0)
    assert m["correct_track_fraction"] == pytest.approx(1.0)
    assert m["velocity_error_mm_s"] < 0.05 * np.linalg.norm(v)  # 2 um noise, 4 um motion per frame x 7
    # the same tracks as a CSV with a track column
    rows = [pd.DataFrame({"track": np.arange(60), "frame": f, "x": pos[f][:, 0], "y": pos[f][:, 1], "z": pos[f][:, 2]})
            for f in range(8)]
    pd.concat(rows).to_csv(tmp_path / "t.csv", index=False)
    c = score(run, tmp_path / "t.csv", out_dir=tmp_path / "c")
    assert c["kind"] == "tracks" and c["position_error_mm"] < 1e-9 and c["velocity_error_mm_s"] < 1e-6


@pytest.mark.parametrize("case, exc, text", [
    ("missing", FileFormatError, "does not exist"),
    ("not_a_run", FileFormatError, "not a run folder"),
    ("no_window", ConfigError, "--window"),
    ("bad_unit", ConfigError, "--velocity-unit 'furlongs'"),
    ("bad_columns", FileFormatError, "x, y[, z] and u, v[, w]"),
    ("scattered", FileFormatError, "rectilinear lattice"),
])
def test_bad_inputs_name_the_fix(tmp_path, case, exc, text):
    run, _, _ = _fake_run(tmp_path / "run")
    f = tmp_path / "f.csv"
    pd.DataFrame({"x": [0.0, 1.0], "y": [0.0, 0.0], "z": [0.0, 0.0], "u": [1.0, 1.0], "v": [0.0, 0.0],
                  "w": [0.0, 0.0]}).to_csv(f, index=False)
    kw = {"window": 1.0, "length_unit": "mm", "velocity_unit": "mm/s", "out_dir": tmp_path / "out"}
    if case == "missing":
        f = tmp_path / "nothing.csv"
    elif case == "not_a_run":
        run = tmp_path
    elif case == "no_window":
        kw["window"] = None
    elif case == "bad_unit":
        kw["velocity_unit"] = "furlongs"
    elif case == "bad_columns":
        pd.DataFrame({"x": [0.0], "y": [0.0], "vx": [1.0], "vy": [0.0]}).to_csv(f, index=False)
        kw["what"] = "vectors"
    elif case == "scattered":
        r = np.random.default_rng(0).uniform(-3, 3, (50, 3))
        pd.DataFrame({"x": r[:, 0], "y": r[:, 1], "z": r[:, 2], "u": 100.0, "v": -50.0, "w": 20.0}).to_csv(f, index=False)
    with pytest.raises(exc, match=text.replace("[", r"\[").replace("]", r"\]").replace("(", r"\(")):
        score(run, f, **kw)
    assert not (tmp_path / "out").exists()


def test_davis_vector_volume_and_tracks_are_scored(tmp_path):
    """DaVis files written by lvpyio (mitpiv.io.davis): a 3D-3C .vc7 in mm and m/s scores its
    added noise, and a particle field of the true tracks scores every particle found."""
    from mitpiv.io.davis import write_davis_particles, write_davis_vectors

    run, pos, v = _fake_run(tmp_path / "run", frames=6, n=80)
    rng = np.random.default_rng(4)
    x = np.arange(-3.0, 3.01, 0.8)
    z = np.arange(-1.2, 1.21, 0.8)
    noise = rng.normal(0, 2.0, (z.size, x.size, x.size, 3))  # mm/s
    u = v + noise
    write_davis_vectors(tmp_path / "f.vc7", x, x, z, u[..., 0] / 1e3, u[..., 1] / 1e3, u[..., 2] / 1e3,
                        length_unit="mm", velocity_unit="m/s")
    m = score(run, tmp_path / "f.vc7", window=1.6, out_dir=tmp_path / "s")
    assert m["format"] in ("davis", None) and m["kind"] == "vectors-3d"
    # float32 storage: 1e-7 of the 100 mm/s flow against 2 mm/s of noise
    np.testing.assert_allclose(m["rms"], np.sqrt(np.mean(noise.reshape(-1, 3) ** 2, axis=0)), rtol=1e-4)
    tracks = np.transpose(pos, (1, 0, 2)) + rng.normal(0, 0.003, (80, 6, 3))
    write_davis_particles(tmp_path / "tracks", tracks, 0.002 * np.arange(6))
    t = score(run, tmp_path / "tracks", out_dir=tmp_path / "t")
    assert t["kind"] == "tracks" and t["yield"] == pytest.approx(1.0) and t["ghost_fraction"] == pytest.approx(0.0)
    assert t["position_error_mm"] < 0.01 and t["correct_track_fraction"] == pytest.approx(1.0)


def test_openlpt_results_folder_is_scored(tmp_path):
    """OpenLPT's track CSVs (results/ConvergeTrack/LongTrack*.csv: TrackID, FrameID, WorldX, WorldY,
    WorldZ, ...), frames counted from the export's first image: --first-frame maps them."""
    run, pos, _ = _fake_run(tmp_path / "run", frames=8, n=50)
    d = tmp_path / "lpt" / "results" / "ConvergeTrack"
    d.mkdir(parents=True)
    rows = ["TrackID,FrameID,WorldX,WorldY,WorldZ,Error"]
    for i in range(40):  # 40 of the 50 particles, frames 2..7 of the run as OpenLPT's 0..5
        rows += [f"{i},{k},{pos[k + 2, i, 0]:.6f},{pos[k + 2, i, 1]:.6f},{pos[k + 2, i, 2]:.6f},0" for k in range(6)]
    (d / "LongTrack0.csv").write_text("\n".join(rows) + "\n")
    m = score(run, tmp_path / "lpt", first_frame=2, out_dir=tmp_path / "s")
    assert m["kind"] == "tracks" and m["format"] == "openlpt" and m["frames"] == [2, 3, 4, 5, 6, 7]
    inside = np.all((pos[2:] >= [-5, -5, -2]) & (pos[2:] <= [5, 5, 2]), axis=2)  # (frames, particles) in the box
    assert m["yield"] == pytest.approx(inside[:, :40].sum() / inside.sum(), rel=1e-12)
    assert m["ghost_fraction"] == pytest.approx(0.0)
    assert m["position_error_mm"] < 1e-5
    with pytest.raises(ResultMismatch, match="--first-frame"):  # frame 0 of OpenLPT is not run frame 0
        score(run, tmp_path / "lpt", out_dir=tmp_path / "t", radius_mm=0.1)
