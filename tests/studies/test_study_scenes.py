"""The study scenes in scenes/: every point of every study (reduced and --full) is a valid
experiment, and the published qualitative conclusions hold where they are cheap to check:
forward scatter is brighter than backward scatter (Mie), two plenoptic cameras beat one,
uncorrected lens distortion lowers Q. Also: ppp seeding, sensor subsets, a killed worker."""

from pathlib import Path

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.studies import load_experiment, run_config
from mitpiv.studies.sweep import load_study

SCENES = Path(__file__).resolve().parents[2] / "scenes"
STUDIES = sorted(SCENES.glob("*/study*.toml"))


def test_study_scenes_exist():
    assert {p.parent.name for p in STUDIES} >= {"tomo_mie", "multiplenoptic", "sa5x5", "lfpiv_jet", "backlit_droplets",
                                               "tracking_lpt"}


@pytest.mark.parametrize("study", STUDIES, ids=lambda p: f"{p.parent.name}/{p.stem}")
@pytest.mark.parametrize("full", [False, True])
def test_every_point_is_a_valid_experiment(study, full):
    import tomllib

    if full and "full" not in tomllib.loads(study.read_text()):
        # a paper's own rig (e.g. lfpiv_tomo_paper: two arms, no reduced size) has no [full] table
        with pytest.raises(ConfigError, match=r"--full needs a \[full\] table"):
            load_study(study, full=True)
        return
    st = load_study(study, full=full)
    assert len(st["points"]) >= 2
    for ov in st["points"]:
        cfg = load_experiment(st["experiment"], {k: v for k, v in ov.items() if k != "label"})
        assert cfg.kind == "backlit" or Path(cfg.scene.xml).is_file()
    assert "label" in st["points"][0] or st["plot"]


def _small(path, overrides, out):
    return run_config(load_experiment(path, overrides), out)


def test_forward_scatter_is_brighter_than_backward(tmp_path):
    """tomo_mie: the cameras at 25 deg azimuth (scattering angle 59 deg) collect more light
    from 1 um DEHS droplets than those at 155 deg (121 deg), as the Mie phase function says."""
    from mitpiv.io import read_exr

    ov = {"scene.params.resolution": 64, "seeding.box_min_mm": [-2.0, -2.0, -1.0], "seeding.box_max_mm": [2.0, 2.0, 1.0],
          "reconstruction.bounds_mm": [-2.0, 2.0, -2.0, 2.0, -1.0, 1.0], "render.sensors": ["cam0", "cam2"]}
    cfg = load_experiment(SCENES / "tomo_mie" / "experiment.toml", ov)
    run_config(cfg, tmp_path, until="render")
    fwd = read_exr(tmp_path / "render" / "cam0_frame000.exr")[0].sum()
    back = read_exr(tmp_path / "render" / "cam2_frame000.exr")[0].sum()
    assert not (tmp_path / "render" / "cam1_frame000.exr").exists()  # only the sensors asked for
    assert fwd > 2.0 * back


def _imaged_per_pixel(particles_dir, cfg, sensor_id, res):
    """Truth particles of frame 0 that project inside a pinhole sensor, per pixel."""
    import shutil

    from mitpiv.io import read_truth
    from mitpiv.reconstruct import mapping_from_metadata
    from mitpiv.render.render import sensor_model
    from mitpiv.render.scene import load_scene

    pts = read_truth(particles_dir / "truth.npz")["positions_mm"][0]
    # the scene reads particles_$frame.ply beside itself: a copy of it in the particles folder
    # (the run keeps its scene copy in the render stage, which this test does not run)
    shutil.copy(cfg.scene.xml, particles_dir / "scene.xml")
    sc = load_scene(particles_dir / "scene.xml", params=cfg.scene.params)
    sensor = next(s for s in sc.sensors() if s.id() == sensor_id)
    uv = mapping_from_metadata({"camera": sensor_model(sensor)}).project(pts)
    return np.all((uv >= 0) & (uv < res), axis=1).sum() / res**2


def test_ppp_seeding_gives_the_density_asked_for(tmp_path):
    """seeding.ppp = 0.05 in tomo_mie: the particles imaged inside camera 0, counted by
    projecting the truth through the camera's own mapping, are 0.05 per pixel within three
    binomial standard deviations (the count inside is a binomial draw: 8 % at 1280)."""
    from mitpiv.io import read_truth

    cfg = load_experiment(SCENES / "tomo_mie" / "experiment.toml", {"scene.params.resolution": 160})
    run_config(cfg, tmp_path, until="particles")
    inside = _imaged_per_pixel(tmp_path / "particles", cfg, "cam0", 160) * 160**2
    expected = 0.05 * 160**2
    assert inside == pytest.approx(expected, abs=3 * np.sqrt(expected))
    pts = read_truth(tmp_path / "particles" / "truth.npz")["positions_mm"][0]
    assert len(pts) > 1.1 * inside  # the camera sees part of the box: more particles are seeded in all


MP_SMALL = {"scene.params.lenslets": 32, "scene.params.resolution": 320, "scene.params.rays_per_particle": 5000,
            "seeding.box_min_mm": [-2.0, -2.0, -2.0], "seeding.box_max_mm": [2.0, 2.0, 2.0], "seeding.count": 120,
            "reconstruction.bounds_mm": [-2.0, 2.0, -2.0, 2.0, -2.0, 2.0], "flow.ring_radius_mm": 1.0,
            "flow.core_radius_mm": 0.4, "flow.circulation_mm2_s": 100.0, "piv.windows": [16], "piv.overlap": 0.5}


def test_two_plenoptic_cameras_beat_one(tmp_path):
    path = SCENES / "multiplenoptic" / "experiment.toml"
    one = _small(path, {**MP_SMALL, "render.sensors": ["plen0"], "scene.params.elevation_deg": 90}, tmp_path / "one")
    two = _small(path, {**MP_SMALL, "render.sensors": ["plen0", "plen1"], "scene.params.elevation_deg": 75},
                 tmp_path / "two")
    e1, e2 = one["evaluate"]["frame0"], two["evaluate"]["frame0"]
    assert e2["Q*"] > e1["Q*"] + 0.05
    assert e2["particles"]["u95_vox"][2] < e1["particles"]["u95_vox"][2]  # depth uncertainty
    assert (tmp_path / "two" / "report" / "subaperture_mosaic.png").is_file()
    # a tomographic method on plenoptic raw images is refused, naming the way out
    with pytest.raises(ConfigError, match="plenoptic"):
        _small(path, {**MP_SMALL, "reconstruction.method": "mart"}, tmp_path / "bad")


LF_SMALL = {"scene.params.plen_resolution": 384, "scene.params.rays_per_particle": 5000,
            "seeding.box_min_mm": [-1.9, -1.9, -1.5], "seeding.box_max_mm": [1.9, 1.9, 1.5],
            "reconstruction.bounds_mm": [-1.9, 1.9, -1.9, 1.9, -1.5, 1.5], "piv.windows": [16], "piv.overlap": 0.5}


def test_lfpiv_velocity_error_grows_with_pmr(tmp_path):
    """lfpiv_jet: on a fixed sensor a larger pixels-per-microlens ratio buys angular samples
    with lenslets (lateral resolution): at 0.5 particles per microlens the PMR 28 camera
    (14 lenslets across) measures the jet far worse than PMR 7 (55 across)."""
    path = SCENES / "lfpiv_jet" / "experiment.toml"
    m = {pmr: _small(path, {**LF_SMALL, "scene.params.mla_pitch_um": 5.5 * pmr}, tmp_path / f"p{pmr}") for pmr in (7, 28)}
    assert m[7]["piv"]["rms_magnitude"] < 0.5 * m[28]["piv"]["rms_magnitude"]
    assert m[7]["evaluate"]["frame0"]["Q"] > m[28]["evaluate"]["frame0"]["Q"]
    # the same density per microlens: 16x the lenslets seed about 16x the particles
    assert 10 < m[7]["n_particles"] / m[28]["n_particles"] < 22
    # the camera budget LTPR compares: one plenoptic camera of 384 x 384 px
    assert m[7]["cameras"] == {"n": 1, "types": ["plenoptic"], "pixels": 384 * 384}
    assert m[7].row()["cameras.pixels"] == 384 * 384 and m[7].row()["cameras.type"] == "plenoptic"
    # with both densities given, a pinhole density sensor takes ppp
    cfg = load_experiment(path, {**LF_SMALL, "seeding.density_sensor": "t0", "scene.params.tomo_resolution": 64})
    run_config(cfg, tmp_path, until="particles")
    assert _imaged_per_pixel(tmp_path / "particles", cfg, "t0", 64) == pytest.approx(0.05, abs=3 * np.sqrt(0.05 / 64**2))


def test_more_tomographic_cameras_raise_q_at_high_density(tmp_path):
    """lfpiv_jet at 0.1 ppp: eight cameras leave fewer ghost particles than four (measured on
    the reduced study: Q 0.52 -> 0.62)."""
    path = SCENES / "lfpiv_jet" / "experiment.toml"
    ov = {**LF_SMALL, "scene.params.tomo_resolution": 128, "seeding.density_sensor": "t0", "seeding.ppp": 0.1,
          "reconstruction.method": "mart"}
    q = {n: _small(path, {**ov, "render.sensors": [f"t{k}" for k in range(0, 8, 8 // n)]}, tmp_path / f"c{n}")
         for n in (4, 8)}
    assert q[8]["evaluate"]["frame0"]["Q"] > q[4]["evaluate"]["frame0"]["Q"] + 0.03
    assert {n: (q[n]["cameras"]["n"], q[n]["cameras"]["pixels"]) for n in q} == {4: (4, 4 * 128**2), 8: (8, 8 * 128**2)}
    assert "plenoptic" not in q[4]["cameras"]["types"]
    assert q[8]["evaluate"]["frame0"]["particles"]["u95_vox"][2] < q[4]["evaluate"]["frame0"]["particles"]["u95_vox"][2]


SA_SMALL = {"scene.params.resolution": 128, "seeding.box_min_mm": [-5.0, -5.0, -2.0],
            "seeding.box_max_mm": [5.0, 5.0, 2.0], "reconstruction.bounds_mm": [-5.0, 5.0, -5.0, 5.0, -2.0, 2.0],
            "reconstruction.voxel_mm": 0.1, "flow.ring_radius_mm": 2.0, "flow.core_radius_mm": 0.8, "flow.circulation_mm2_s": 300.0,
            "piv.windows": [16], "piv.overlap": 0.5}


def test_sweep_table_gets_ltpr_per_rig():
    """add_ltpr: Shi et al.'s Table 1 LTPRs from the camera budgets a sweep records (800 and
    1600 px light-field cameras against 4, 6, 8 cameras of 160 px), checked against
    mitpiv.physics.plenoptic.ltpr and the printed 6.25 / 4.17 / 3.13 / 25 / 16.67 / 12.5;
    tomographic rows get no LTPR, and a table without camera budgets is left alone."""
    import pandas as pd

    from mitpiv.physics.plenoptic import ltpr
    from mitpiv.studies.sweep import add_ltpr

    rows = [{"point": f"lf{r}", "cameras.n": 1, "cameras.type": "plenoptic", "cameras.pixels": r * r} for r in (800, 1600)]
    rows += [{"point": f"t{n}", "cameras.n": n, "cameras.type": "distorted_pinhole", "cameras.pixels": n * 160**2}
             for n in (4, 6, 8)]
    df = add_ltpr(pd.DataFrame(rows))
    printed = {(800, 4): 6.25, (800, 6): 4.17, (800, 8): 3.13, (1600, 4): 25.0, (1600, 6): 16.67, (1600, 8): 12.5}
    for (r, n), v in printed.items():
        got = df.loc[df["point"] == f"lf{r}", f"ltpr_vs_nc{n}"].item()
        assert got == pytest.approx(ltpr((r, r), (160, 160), n), rel=1e-12)
        assert got == pytest.approx(v, abs=0.005)  # printed to two decimals
    assert df.loc[df["point"].str.startswith("t"), [f"ltpr_vs_nc{n}" for n in (4, 6, 8)]].isna().all().all()
    # two four-camera rigs of different sensors: the column names carry the pixels
    two = add_ltpr(pd.DataFrame(rows[:1] + [{**rows[2], "cameras.pixels": 4 * 320**2}, rows[2]]))
    assert {"ltpr_vs_nc4_102400px", "ltpr_vs_nc4_409600px"} <= set(two.columns)
    bare = pd.DataFrame([{"point": "a", "frame0.Q": 0.5}])
    assert add_ltpr(bare).equals(bare)


def test_uncorrected_distortion_lowers_q(tmp_path):
    path = SCENES / "sa5x5" / "experiment.toml"
    q = [_small(path, {**SA_SMALL, "scene.params.distortion_percent": d}, tmp_path / f"d{d}")["evaluate"]["frame0"]["Q"]
         for d in (0.0, 2.0)]
    assert q[1] < q[0] - 0.01  # measured 0.593 -> 0.570
    # with the true (distorted) camera model the distortion costs nothing (0.596)
    qt = _small(path, {**SA_SMALL, "scene.params.distortion_percent": 2.0, "reconstruction.camera_model": "true"},
                tmp_path / "true")["evaluate"]["frame0"]["Q"]
    assert qt > q[1] + 0.01


def test_bad_study_inputs(tmp_path):
    with pytest.raises(ConfigError, match="density_sensor"):
        _small(SCENES / "tomo_mie" / "experiment.toml", {"seeding.density_sensor": "cam9"}, tmp_path / "a")
    with pytest.raises(ConfigError, match="not in the scene"):
        _small(SCENES / "tomo_mie" / "experiment.toml", {"render.sensors": ["cam0", "camX"],
                                                           "scene.params.resolution": 32}, tmp_path / "b")
    with pytest.raises(ConfigError, match="camera_model"):
        _small(SCENES / "sa5x5" / "experiment.toml", {**SA_SMALL, "reconstruction.camera_model": "ideal",
                                                       "scene.params.resolution": 32}, tmp_path / "c")
    s = tmp_path / "s.toml"
    s.write_text(f'experiment = "{SCENES / "sa5x5" / "experiment.toml"}"\n[[points]]\nlabel = "a"\n')
    with pytest.raises(ConfigError, match=r"\[full\]"):
        load_study(s, full=True)


def test_plot_against_labels_keeps_the_study_order(tmp_path):
    import pandas as pd

    from mitpiv.studies.sweep import plot_sweep

    df = pd.DataFrame({"param.label": ["b", "a", "b", "a"], "param.seeding.ppp": [0.05, 0.05, 0.1, 0.1],
                       "frame0.Q": [0.6, 0.5, 0.4, 0.3], "status": ["ok"] * 4})
    plot_sweep(df, "label", "frame0.Q", tmp_path / "l.png")
    plot_sweep(df, "seeding.ppp", "frame0.Q", tmp_path / "g.png", group="label")
    assert (tmp_path / "l.png").stat().st_size > 5000 and (tmp_path / "g.png").stat().st_size > 5000
    with pytest.raises(ConfigError, match="no column"):
        plot_sweep(df, "label", "frame0.Qx", tmp_path / "x.png")
