"""The multi-plenoptic replication (Fahringer & Thurow): its quick run (schema, required ids,
curves) and the study's definitions written afresh: the system's geometry (Table 1,
S_o / p_M, the 1:4 volume), Q (eq. 16) and Q* (eq. 17), the density (particles per
reconstructed pixel) and the light-ray image model's energy bookkeeping."""

import math

import numpy as np
import pytest

from mitpiv.analysis.quality import quality_q, quality_q_zero_mean
from mitpiv.replications.frame import RESULTS_KEYS, replicate
from mitpiv.replications.multi_plenoptic import model as S
from mitpiv.replications.multi_plenoptic.study import STUDY

from .helpers import assert_second_edition, committed_rows

# float64 sums over ~1e4 voxels: round-off ~1e-13; 1e-12 leaves room.
EQ_RTOL = 1e-12


def test_quick_run_schema_and_ids(tmp_path):
    res = replicate("multi-plenoptic", tmp_path, quick=True)
    assert set(RESULTS_KEYS) <= set(res)
    assert_second_edition(res, tmp_path)
    assert res["scale"] == "quick" and res["study"] == "multi-plenoptic"
    ids = [r["id"] for r in res["rows"]]
    assert len(ids) == len(set(ids)) and set(STUDY.required_ids) <= set(ids)
    for r in res["rows"]:
        assert {"id", "quantity", "paper_source", "paper", "ours", "tolerance", "agrees", "note"} <= set(r)
    for name in ("Qstar_vs_So_pM", "fig8_Qstar_vs_angle", "fig8_z_u95_vox_vs_angle", "fig9_rms_vox_vs_ppp",
                 "fig9_outlier_ratio_vs_ppp", "fig4_Q_Qstar_vs_ppp"):
        c = res["curves"][name]
        assert all(len(v) == len(c["x"]) for v in c["y"].values())
    rows = {r["id"]: r for r in res["rows"]}
    report = (tmp_path / "report.md").read_text()
    q2 = res["curves"]["fig8_Qstar_vs_angle"]["y"]["2 plenoptic"]
    assert all(0.0 < q < 1.0 for q in q2)  # a reconstruction that correlates with the truth
    # two cameras see depth better than one (the paper's headline; true even on the quick crop)
    z = res["curves"]["fig8_z_u95_vox_vs_angle"]["y"]
    assert rows["z_unc_ratio_1cam_over_2cam"]["ours"] > 0 and z["2 plenoptic"][0] > 0
    # the optimum of each particle field's sweep, averaged over the fields (the note lists them)
    for rid in ("So_pM_optimum", "So_pM_optimum_gamma_hist"):
        r = rows[rid]
        opts = [float(x) for x in r["note"].split("optimum per field: ")[1].split(";")[0].split(", ")]
        assert len(opts) == r["n"] == 2 and set(opts) <= {4.0, 8.0, 16.0}
        assert r["ours"] == pytest.approx(np.mean(opts), abs=1e-12)
    # the paper's histogram rule for gamma_L is the counted Fig. 7 row (pre-registered), 1 / sum w beside it
    assert rows["So_pM_optimum_gamma_hist"]["kind"] == "physics" and rows["So_pM_optimum"]["kind"] == "info"
    # the physically based arm: its rows over the 2 fields it renders, the report's section, its curves
    pb = {i: r for i, r in rows.items() if r["arm"] == "physical"}
    assert {"So_pM_optimum_gamma_hist_pb", "z_ratio_nearest_1cam_over_2cam_pb", "Qstar_4cam_minus_2cam_pb",
            "Qstar_plenoptic2_minus_mart_f20_pb", "rms_1cam_above_2cam_pb"} <= set(pb)
    assert all(r["id"].endswith("_pb") for r in pb.values())
    assert pb["So_pM_optimum_pb"]["kind"] == "info" and pb["So_pM_optimum_gamma_hist_pb"]["kind"] == "physics"
    assert all(r["n"] == 2 for r in pb.values() if r["kind"] == "physics")
    assert "(arm physical)" in report.splitlines()[0]
    assert "## What physically based images change" in report and "| Mitsuba + sensor |" in report
    assert "## Fig. 7 per gamma_L rule and arm" in report and "| optimum of the means |" in report
    assert len(res["curves"]["pb_Qstar_vs_cameras"]["y"]) == 3
    for lab, ys in res["curves"]["Qstar_vs_So_pM_arms"]["y"].items():
        assert all(y is not None and 0.0 < y < 1.0 for y in ys), lab
    # eq. 14 against eq. 13, field by field
    assert rows["Qstar_mult_minus_add"]["n"] == 2
    # the paper's gate-free z rule, 1 camera over 2 and over 4, with an interval over the 2 fields
    for m in (2, 4):
        r = rows[f"z_ratio_nearest_1cam_over_{m}cam"]
        assert r["n"] == 2 and r["ci"] is not None and r["ours"] > 0 and r["kind"] == "physics"
    assert "## The z uncertainty by rule (25 deg)" in report and "one-to-one within 20 voxels" in report
    # the whole Fig. 8-9 comparison: the cell count, 'equal' RMS with an interval, eq. 15's ablation, cubic decoding
    cells = rows["mart_better_cells"]["ours"]
    assert int(cells.split(" of ")[1]) >= 12 and rows["mart_better_cells"]["kind"] == "physics"
    assert rows["rms_4cam_vs_2cam"]["n"] == 2 and rows["rms_4cam_vs_2cam"]["ci"] is not None
    assert "none (raw eq. 14 volumes)" in report and "cubic interpolation, as the paper does" in report
    assert (tmp_path / "report.md").is_file() and (tmp_path / "fig8_Qstar_vs_angle.png").is_file()


def test_system_geometry_is_the_papers():
    """S_o / p_M = 8: S_o = 40 mm, s_i = 1 / (1/10 - 1/40) = 13.33 mm, |M| = 1/3; a lenslet's
    footprint (the voxel) 14 um / |M| = 42 um; the full field of view 328 of them; the volume
    1:4 thick."""
    si = 1.0 / (1.0 / 10.0 - 1.0 / 40.0)
    vox = 14e-3 * 40.0 / si
    assert S.voxel_mm(8.0) == pytest.approx(vox, rel=1e-12)
    lo, hi, full_w = S.volume_box(8.0, 0.25, 96)
    assert full_w == pytest.approx(328 * vox, rel=1e-12)
    assert hi[2] - lo[2] == pytest.approx(full_w / 4, rel=1e-12) and hi[0] - lo[0] == pytest.approx(96 * vox)
    g = S.volume_grid(8.0, 0.25, 96)
    assert g.shape == (82, 96, 96)
    cam = S.plenoptic_camera(8.0, 25.0, 180.0, 96)
    assert cam.focus_distance_mm == 40.0 and cam.aperture_diameter_mm == pytest.approx(5.0)
    assert cam.resolution == (960, 960) and cam.mla_count == (96, 96)
    # 25 deg from the volume's z axis, on the -x side (azimuth 180), 40 mm from the centre
    pos = cam.to_world_mitsuba[:3, 3]
    assert np.linalg.norm(pos) == pytest.approx(40.0)
    assert math.degrees(math.acos(pos[2] / 40.0)) == pytest.approx(25.0) and pos[0] < 0
    # the volume centre is imaged on the sensor centre (chief ray)
    np.testing.assert_allclose(cam.project(np.zeros(3)), [480.0, 480.0], atol=1e-9)
    std = S.standard_camera(8.0, 25.0, 180.0, 96, 20.0)
    np.testing.assert_allclose(std.project(np.zeros(3)), [48.0, 48.0], atol=1e-9)


def test_density_is_particles_per_reconstructed_pixel():
    p0, p1 = S.particles(8.0, 0.25, 96, 0.023, seed=3)
    assert len(p0) == round(0.023 * 96**2)
    lo, hi, _ = S.volume_box(8.0, 0.25, 96)
    assert np.all(p0 >= lo) and np.all(p0 <= hi)
    d = np.linalg.norm(p1 - p0, axis=1)
    assert 0 < d.max() < 6 * S.voxel_mm(8.0)  # displacements of a few voxels


def test_q_and_q_star_eqs_16_17():
    rng = np.random.default_rng(0)
    v = rng.random((6, 7, 8)) ** 4
    t = v + 0.3 * rng.random((6, 7, 8))
    q16 = np.sum(v * t) / math.sqrt(np.sum(v * v) * np.sum(t * t))  # eq. 16
    vh, th = v - v.mean(), t - t.mean()  # eq. 17: the zero-mean fields
    q17 = np.sum(vh * th) / math.sqrt(np.sum(vh * vh) * np.sum(th * th))
    assert quality_q(v, t) == pytest.approx(q16, rel=EQ_RTOL)
    assert quality_q_zero_mean(v, t) == pytest.approx(q17, rel=EQ_RTOL)
    # Q* ignores a uniform offset; at dense seeding both fields approach a uniform level and Q
    # approaches 1 whatever the reconstruction (Fig. 4), while Q* of uncorrelated fields is ~0
    assert quality_q_zero_mean(v + 1.0, t) == pytest.approx(q17, rel=1e-9)
    a, b = 1.0 + 0.1 * rng.random((20, 20, 20)), 1.0 + 0.1 * rng.random((20, 20, 20))
    assert quality_q(a, b) > 0.99 and abs(quality_q_zero_mean(a, b)) < 0.1


def test_light_ray_images_keep_every_ray_that_reaches_the_sensor():
    """One particle in focus on the axis: every ray passes the aperture and lands on the sensor,
    so the image's sum is the sum of the rays' Gaussian weights (area splitting conserves it),
    and its light gathers under the 3 x 3 lenslets round its image (in focus)."""
    cam = S.plenoptic_camera(8.0, 0.0, 0.0, 16)
    vox = S.voxel_mm(8.0)
    p = np.array([[0.5 * vox, 0.5 * vox, 0.0]])  # imaged on a lenslet centre (the axis lies between lenslets)
    img = S.render_plenoptic(cam, p, sigma_mm=0.7 * vox, rays=20000, seed=1)
    rng = np.random.default_rng(1)
    _, wt = S._sources(p, 0.7 * vox, 20000, rng)
    assert img.sum() == pytest.approx(wt.sum(), rel=1e-9)
    centres = cam.image_centres_px().reshape(-1, 2)
    near = np.linalg.norm(centres - cam.project(p)[0], axis=1).argmin()
    c = centres[near]
    # the Gaussian source (sigma 0.7 voxel = 0.7 lenslet) puts ~93 % within +-1.5 lenslets
    box = img[int(c[1]) - 15 : int(c[1]) + 15, int(c[0]) - 15 : int(c[0]) + 15]
    assert box.sum() > 0.85 * img.sum()


def test_standard_camera_calibrated_from_rendered_targets():
    """The MART cameras' calibration (the paper's "series of calibration images"): dot targets
    rendered through the same optics, located and fitted, reproduce the true projection over
    the volume to a small fraction of a pixel."""
    n = 64
    mapping, rep = S.calibrate_standard(8.0, 0.25, 25.0, 180.0, n, 20.0, rays=2000)
    cam = S.standard_camera(8.0, 25.0, 180.0, n, 20.0)
    lo, hi, _ = S.volume_box(8.0, 0.25, n)
    pts = np.random.default_rng(1).uniform(lo, hi, (300, 3))
    err = np.linalg.norm(mapping.project(pts) - cam.project(pts), axis=1)
    assert rep["markers"] >= 20 and rep["rms_px"] < 0.2
    assert np.sqrt(np.mean(err**2)) < 0.1  # dot location ~0.04 px (measured), averaged by the fit


def test_physical_arm_collects_light_through_each_pupil(tmp_path):
    """The physically based arm's cameras (scenes/multiplenoptic_paper rendered by
    physical.render_camera, recorded by physical.record without noise): one 2 um particle at
    the volume's centre seen at 25 deg (scattering angle 65 deg). The plenoptic camera and the
    f/2 standard camera share the 5 mm pupil, so the electrons they collect agree (measured
    0.996: the lenslets conserve the light); the f/20 camera collects (1/10)^2 of the f/2
    camera's times the Mie phase function averaged over its 0.5 mm pupil over that averaged
    over the 5 mm pupil (independent: mitpiv.physics.mie in float64 over the two pupils, 0.949;
    the rendered ratio without the diffraction PSF is 0.948, with it 0.938: the PSF window keeps
    99.5 % and the film's edge). Tolerances 2 %: the renders' Monte Carlo noise (200,000 rays)
    is 0.3 %. A sensor that is not the model's camera is refused."""
    from mitpiv.errors import ConfigError
    from mitpiv.physics.mie import phase_function
    from mitpiv.replications.multi_plenoptic import physical as P

    frames = [np.zeros((1, 3))]
    e = {}
    for kind in ("plen", "f2", "f20"):
        imgs, sid, rec, _ = P.render_camera(kind, 8.0, 0.25, 24, 25.0, 0.0, frames, seed=3)
        model = P.noise_free(P.sensor(kind, 8.0))
        _, info = P.record(imgs, sid, rec, model, seed=3)
        e[kind] = info["sum_counts"][0] * model.gain_e_per_count
    assert e["plen"] / e["f2"] == pytest.approx(1.0, rel=0.02)
    # the pupils' mean phase function: the rays from the origin to a 40 mm distant pupil of radius r
    rng = np.random.default_rng(0)
    a = math.radians(25.0)
    axis, u1, u2 = np.array([math.sin(a), 0, math.cos(a)]), np.array([math.cos(a), 0, -math.sin(a)]), np.eye(3)[1]

    def pupil_mean(r_mm):
        rr, phi = r_mm * np.sqrt(rng.random(200_000)), 2 * math.pi * rng.random(200_000)
        v = 40.0 * axis + (rr * np.cos(phi))[:, None] * u1 + (rr * np.sin(phi))[:, None] * u2
        theta = np.degrees(np.arccos(v[:, 0] / np.linalg.norm(v, axis=1)))
        return float(np.mean(phase_function(P.DIAMETER_UM, 1.45, theta)))

    expect = 0.01 * pupil_mean(0.25) / pupil_mean(2.5)
    assert e["f20"] / e["f2"] == pytest.approx(expect, rel=0.02)
    assert abs(e["f20"] / e["f2"] - 0.01) > 0.04 * 0.01  # the phase function's share is resolved (5 % vs 2 %)
    # a rendered sensor that is not the model arm's camera
    import shutil

    from mitpiv.io.particles import write_particles_ply
    from mitpiv.render.scene import load_scene

    shutil.copyfile(P.SCENE, tmp_path / "scene.xml")
    write_particles_ply(tmp_path / "particles_0.ply", frames[0], 2.0, proxy_radius_mm=0.005)
    sc = load_scene(tmp_path / "scene.xml", frame=0, params=P.scene_params("plen", 8.0, 0.25, 24, 25.0, 0.0))
    sensor = {s.id(): s for s in sc.sensors()}["plen0"]
    P.check_pose(sensor, S.plenoptic_camera(8.0, 25.0, 0.0, 24), "plen")  # the same camera passes
    with pytest.raises(ConfigError, match="not the model arm's camera"):
        P.check_pose(sensor, S.plenoptic_camera(8.0, 25.0, 90.0, 24), "plen")


def test_the_physical_scene_builds_at_every_distance_of_the_sweep(tmp_path):
    """Every sensor of the scene is built for every point, so a plenoptic point's unused
    standard cameras need a lens at every S_o / p_M of the full sweep (the scene's defaults,
    S_o = 40 mm, are no lens at S_o = 12.5 mm: the full run once stopped there); a standard
    camera's own point is refused by name where its pinhole form cannot exist."""
    import shutil

    import numpy as np

    from mitpiv.errors import ConfigError
    from mitpiv.io.particles import write_particles_ply
    from mitpiv.render.scene import load_scene
    from mitpiv.replications.multi_plenoptic import physical as P
    from mitpiv.replications.multi_plenoptic.study import _scale

    shutil.copyfile(P.SCENE, tmp_path / "scene.xml")
    write_particles_ply(tmp_path / "particles_0.ply", np.zeros((1, 3)), 2.0, proxy_radius_mm=0.005)
    for so in _scale(False)["so_pm"]:
        sc = load_scene(tmp_path / "scene.xml", frame=0, params=P.scene_params("plen", so, 0.25, 24, 25.0, 0.0))
        assert {s.id(): s for s in sc.sensors()}["plen0"].camera.focus_distance_mm == pytest.approx(so * 5.0, rel=1e-6)
    # a standard camera is written as a pinhole at its image distance: S_o must exceed 2 f
    for kind in ("f2", "f20"):
        sc = load_scene(tmp_path / "scene.xml", frame=0, params=P.scene_params(kind, 8.0, 0.25, 24, 25.0, 0.0))
        assert {s.id(): s for s in sc.sensors()}["pin0"].camera.focus_distance_mm == pytest.approx(40.0, rel=1e-6)
        with pytest.raises(ConfigError, match="S_o / p_M = 4"):
            P.scene_params(kind, 4.0, 0.25, 24, 25.0, 0.0)


def test_scene_is_the_papers_system():
    """scenes/multiplenoptic_paper (the Mitsuba version of the study) carries Table 1 and
    S_o / p_M = 8 exactly, and its cropped experiment validates."""
    import xml.etree.ElementTree as ET
    from pathlib import Path

    from mitpiv.physics.plenoptic import PRESETS
    from mitpiv.render.scene import scene_defaults
    from mitpiv.studies.runner import load_experiment

    root = Path(__file__).resolve().parents[2] / "scenes" / "multiplenoptic_paper"
    d = scene_defaults(root / "scene.xml")
    assert (int(d["lenslets"]), int(d["resolution"]), float(d["focus_distance_mm"])) == (328, 3280, 40.0)
    assert float(d["thickness_mm"]) == pytest.approx(S.volume_box(8.0, 0.25, 328)[2] / 4, abs=1e-3)
    sensors = {s.get("id"): s for s in ET.parse(root / "scene.xml").getroot().iter("sensor")}
    assert {"plen0", "plen1", "plen2", "plen3", "pin0", "pin1"} <= set(sensors)
    vals = {f.get("name"): f.get("value") for f in sensors["plen0"].iter("float")}
    p = PRESETS["multiplenoptic_paper"]
    assert float(vals["focal_length_mm"]) == p["focal_length_mm"] and float(vals["aperture_diameter_mm"]) == 5.0
    assert float(vals["pixel_pitch_um"]) == p["pixel_pitch_um"] and float(vals["mla_pitch_um"]) == p["mla_pitch_um"]
    assert float(vals["mla_focal_length_um"]) == p["mla_focal_length_um"]
    cfg = load_experiment(root / "experiment.toml")
    assert cfg.reconstruction.voxel_mm == pytest.approx(S.voxel_mm(8.0), abs=1e-4)
    assert cfg.sensor.bit_depth == 16


def _committed_rows():


    return committed_rows("multi-plenoptic")


def test_committed_rows_have_kinds_and_every_cause_is_declared():
    """Every row of the committed full results gets a kind (issue 44): every KINDS key names a
    committed row, no physics row compares nothing, no row reads a paper result (the study takes
    none), the known caveats are in the rows' why, and the physics tally is the one the closing
    note states."""
    from mitpiv.replications.frame import classify_rows, tally, unused_kinds
    from mitpiv.replications.multi_plenoptic.study import INPUTS_FROM_PAPER, KINDS

    rows = classify_rows(STUDY, _committed_rows())
    assert unused_kinds(STUDY, rows) == [] and set(KINDS) <= {r.id for r in rows}
    assert STUDY.kinds is KINDS and dict(STUDY.inputs_from_paper) == INPUTS_FROM_PAPER == {}
    by = {r.id: r for r in rows}
    assert not [r.id for r in rows if r.kind == "physics" and r.agrees is None]
    assert all(not r.reads for r in rows)
    assert "plateau" in by["best_angle_deg"].why and "25 to 50 deg" in by["best_angle_deg"].why
    assert "MART f/20 is clearly better" in by["Qstar_plenoptic2_minus_mart_f20"].why
    # one-cell comparisons whose cell agrees while the committed sweep does not are not counted
    for i in ("z_unc_ratio_1cam_over_2cam", "best_angle_deg", "Qstar_plenoptic2_minus_mart_f20",
              "So_pM_optimum_gamma_typical"):
        assert by[i].kind == "info", i
    # every disagreement has its cause
    assert all(r.why for r in rows if r.agrees is False)
    # So_pM_optimum is info since the pre-registered switch to the paper's gamma_L rule (2026-12-08)
    assert tally(rows) == {"n": 11, "agree": 9, "disagree": 2, "inconclusive": 0}


def test_a_passing_rows_cause_reaches_the_report(tmp_path):
    """The causes are printed with every row, pass or fail (they used to be printed for failing
    rows only): reclassifying the committed results writes a report that carries the causes of
    passing rows; the study's own section no longer filters causes by failure."""
    import shutil
    from pathlib import Path

    from mitpiv.replications.frame import classify_rows, reclassify
    from mitpiv.replications.multi_plenoptic.study import KINDS, _causes

    src = Path(__file__).resolve().parents[2] / "docs" / "replications" / "multi-plenoptic"
    for name in ("results.json", "report.md"):
        shutil.copy(src / name, tmp_path / name)
    reclassify("multi-plenoptic", tmp_path)
    md = (tmp_path / "report.md").read_text()
    assert md.startswith("**9 of 11 physics rows agree, 2 disagree")
    rows = {r.id: r for r in _committed_rows()}
    for i in ("best_angle_deg", "Qstar_plenoptic2_minus_mart_f20", "Qstar_plenoptic2_minus_mart_f2"):
        assert rows[i].agrees is True
        assert KINDS[i].why in md, i  # a passing row's cause, printed with it
    assert "caveat: " + KINDS["Qstar_plenoptic2_minus_mart_f2"].why in md  # a passing physics row's caveat
    # the study's section names only disagreements without a declared cause
    section = _causes(classify_rows(STUDY, list(rows.values())))
    assert "no investigated cause" not in section
    from dataclasses import replace

    assert "Q_minus_Qstar_ppp0.3" not in KINDS  # a row with no declared cause, were it to disagree
    assert "`Q_minus_Qstar_ppp0.3`" in _causes([replace(rows["Q_minus_Qstar_ppp0.3"], agrees=False, verdict=None)])
