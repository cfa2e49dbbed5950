"""scenes/lfpiv_tomo_paper: Shi et al.'s simultaneous LF-PIV / Tomo-PIV experiment (seed paper
001, section 3, Table 4) as a simulated rig. Its cameras are Table 4's (object-space pixel,
field of view, PMR, LTPR), measured on the loaded Mitsuba sensors, not read back from the XML;
its seeding, voxels and windows are the table's; the tomographic cameras focus on the sheet
mid-plane (Scheimpflug) and image the paper's 20 um particles as particles of a few pixels."""

from pathlib import Path

import numpy as np
import pytest

from mitpiv.physics.plenoptic import ltpr
from mitpiv.studies import load_experiment

SCENE = Path(__file__).resolve().parents[2] / "scenes" / "lfpiv_tomo_paper"


@pytest.fixture(scope="module")
def sensors(tmp_path_factory):
    """The scene's sensors at the paper's whole light-field sensor (6600 x 4400 px)."""
    import shutil

    import mitsuba as mi

    from mitpiv.io.particles import write_particles_ply
    from mitpiv.render.variant import ensure_variant

    ensure_variant()
    d = tmp_path_factory.mktemp("lfpiv_tomo_paper")
    shutil.copy(SCENE / "scene.xml", d / "scene.xml")
    write_particles_ply(d / "particles_0.ply", np.zeros((1, 3)), 20.0, proxy_radius_mm=0.02)
    scene = mi.load_file(str(d / "scene.xml"), lf_width=6600, lf_height=4400, frame=0, rays_per_particle=16)
    return {s.id(): s for s in scene.sensors()}


def _pixel_mm(cam, axis) -> float:
    """Object-space pixel at the volume centre along a camera axis: a 10-pixel step at the
    origin, projected, over its length (mm per pixel)."""
    rot = np.asarray(cam.rotation)
    step = 0.5 * rot[axis]  # 0.5 mm along the camera's x (0) or y (1) axis, in world coordinates
    uv = cam.project(np.array([[0.0, 0.0, 0.0], step]))
    return 0.5 / float(np.linalg.norm(uv[1] - uv[0]))


def test_cameras_are_table_4s(sensors):
    plen = sensors["plen"].camera
    # 0.0058 mm per pixel (Table 4's p_p), PMR 14, image-side f-number matched to the f/4 lenslets
    assert plen.pixel_pitch_um * 1e-3 / plen.magnification == pytest.approx(0.0058, rel=1e-4)
    assert plen.pmr == pytest.approx(14.0)
    assert plen.image_f_number == pytest.approx(plen.mla_f_number, rel=1e-4)
    fov = np.array(plen.resolution) * 0.0058
    assert fov == pytest.approx([38.28, 25.52], rel=1e-3)  # Table 4: 38 x 26 mm
    # the hexagonal array fills the sensor: 471 x 363 lenslets (Table 4 prints 450 x 350)
    assert plen.n_lenslets == pytest.approx(471 * 363, rel=0.02)
    tomo = [sensors[f"t{i}"].camera for i in range(4)]
    for c in tomo:
        assert tuple(c.resolution) == (480, 320)
        for axis in (0, 1):  # 0.079 mm per pixel at the volume centre
            assert _pixel_mm(c, axis) == pytest.approx(0.079, rel=1e-4)
        # the optical axis 25 deg off z, meeting the volume centre (to Mitsuba's float32 pose
        # of a camera 1 m away: 1e-4 mm)
        z_axis = np.asarray(c.rotation)[2]
        assert np.degrees(np.arccos(abs(z_axis[2]))) == pytest.approx(25.0, abs=1e-4)
        assert np.cross(z_axis, -np.asarray(c.position_mm)) == pytest.approx(np.zeros(3), abs=1e-4)
    # the cross: the four cameras at azimuths 0 / 90 / 180 / 270 deg about the z axis
    az = sorted(np.degrees(np.arctan2(c.position_mm[1], c.position_mm[0])) % 360 for c in tomo)
    assert az == pytest.approx([0.0, 90.0, 180.0, 270.0], abs=1e-4)
    # each camera's 480 px side along the jet (x): Table 4's 480 x 320 x 130 volume is seen by all
    # four cameras, but for the slanted views through its 10 mm depth (25 deg: ~12 px beyond the film)
    rng = np.random.default_rng(1)
    pts = rng.uniform([-18.96, -12.64, -5.135], [18.96, 12.64, 5.135], (20000, 3))
    seen = np.ones(len(pts), bool)
    for c in tomo:
        uv = c.project(pts)
        seen &= (uv[:, 0] >= 0) & (uv[:, 0] < 480) & (uv[:, 1] >= 0) & (uv[:, 1] < 320)
    assert seen.mean() > 0.9
    mid = pts[np.abs(pts[:, 2]) < 0.5]  # the mid-plane: all of it
    for c in tomo:
        uv = c.project(mid * [0.97, 0.97, 1.0])
        assert np.all((uv[:, 0] >= 0) & (uv[:, 0] < 480) & (uv[:, 1] >= 0) & (uv[:, 1] < 320))
    # the paper's LTPR: 6600 x 4400 over 4 x 480 x 320
    assert ltpr(plen.resolution, tomo[0].resolution, 4) == pytest.approx(47.27, abs=0.005)


def test_tomographic_cameras_focus_on_the_sheet_mid_plane(sensors):
    """Scheimpflug on the sheet mid-plane z = 0 (the focus plane through the volume centre,
    normal z), the 85 mm lens's f/11 aperture (the plugin's f-number is that of its pinhole
    distance, 93 mm), and the 10 mm sheet inside the depth of field: the thin-lens blur at the
    sheet's faces (closed form, float64) is below a pixel."""
    import xml.etree.ElementTree as ET

    root = ET.parse(SCENE / "scene.xml").getroot()
    for i in range(4):
        c = sensors[f"t{i}"].camera
        axis = np.asarray(c.rotation)[2]
        focus_point = np.asarray(c.position_mm) + c.focus_distance_mm * axis
        assert focus_point == pytest.approx(np.zeros(3), abs=1e-3)
        el = root.find(f"sensor[@id='t{i}']/vector[@name='focus_plane_normal']")
        assert [float(v) for v in el.get("value").split(",")] == pytest.approx([0.0, 0.0, 1.0], abs=1e-9)
        assert c.aperture_radius_mm == pytest.approx(85.0 / 11.0 / 2.0, rel=1e-6)
        # blur of a point at the sheet's face, 5 mm off the focus plane (5 / cos 25 deg along the axis)
        f, s = 85.0, c.focus_distance_mm
        for sp in (s - 5.0 / np.cos(np.radians(25.0)), s + 5.0 / np.cos(np.radians(25.0))):
            blur_mm = 2 * c.aperture_radius_mm * f * abs(sp - s) / (sp * (s - f))
            assert 0.2 < blur_mm / (c.pixel_pitch_um * 1e-3) < 1.0


def test_experiment_and_study_are_table_4s():
    cfg = load_experiment(SCENE / "experiment.toml")
    r = cfg.reconstruction
    # DRT-MART, 400 iterations, 2:2:10 of the 0.0058 mm pixel (Table 4's 0.0116 x 0.0116 x 0.055 mm,
    # 182 voxels over the 10 mm depth)
    assert (r.method, r.iterations) == ("drt-mart", 400)
    assert r.voxel_mm[:2] == pytest.approx((2 * 0.0058, 2 * 0.0058))
    assert (r.bounds_mm[5] - r.bounds_mm[4]) / r.voxel_mm[2] == pytest.approx(182, abs=0.05)
    assert list(cfg.piv.windows[-1]) == [160, 160, 32] and cfg.piv.overlap == 0.75
    # the crop: a tenth of the sensor each way centred on the lip line (y = D/2), the bounds
    # what it sees, the seeding 1 mm wider (inflow between the frames: the exit velocity moves 0.6 mm)
    p = cfg.scene.params
    assert (p["lf_width"], p["lf_height"], p["lf_centre_y_mm"]) == (660, 440, 10.0)
    half = np.array([660, 440]) * 0.0058 / 2
    centre = np.array([0.0, 10.0])
    b = np.array(r.bounds_mm[:4]).reshape(2, 2)
    assert b.mean(axis=1) == pytest.approx(centre, abs=1e-9) and np.diff(b, axis=1).ravel() / 2 == pytest.approx(half, rel=1e-3)
    lo, hi = np.array(cfg.seeding.box_min_mm[:2]), np.array(cfg.seeding.box_max_mm[:2])
    assert (hi + lo) / 2 == pytest.approx(centre, abs=1e-9) and (hi - lo) / 2 == pytest.approx(half + 1.0, rel=1e-3)
    assert cfg.flow.exit_velocity_mm_s * cfg.flow.dt_s < 1.0
    # seeding: 0.06 ppm x 450 x 350 lenslets = 0.062 ppp x 480 x 320 px (within 1 %) in 38 x 26 x 10 mm
    n = cfg.seeding.concentration_per_mm3 * 38 * 26 * 10
    assert n == pytest.approx(0.06 * 450 * 350, rel=0.01) and n == pytest.approx(0.062 * 480 * 320, rel=0.01)
    # the jet: Re_D 2000 in water, D = 20 mm, the volume centre 2.25 D from the nozzle
    f = cfg.flow.model_dump()
    assert f["kind"] == "near_field_jet" and f["diameter_mm"] == 20.0
    assert f["exit_velocity_mm_s"] * f["diameter_mm"] / 1.0 == pytest.approx(2000.0)
    assert -f["nozzle_mm"][0] / f["diameter_mm"] == pytest.approx(2.25)

    from mitpiv.studies.sweep import load_study

    study = load_study(SCENE / "study.toml")
    tomo = [p for p in study["points"] if p.get("reconstruction.method") == "smart"]
    assert len(tomo) == 1
    t = tomo[0]
    # MLOS-SMART 40 iterations at 1:1:1 (0.079 mm) over Table 4's 480 x 320 x 130 voxels, 64^3 -> 32^3
    # windows: 57 x 37 x 13 vectors at 75 % overlap (Table 4)
    assert t["reconstruction.iterations"] == 40 and t["reconstruction.voxel_mm"] == 0.079
    b = np.array(t["reconstruction.bounds_mm"]).reshape(3, 2)
    n = np.round(np.diff(b, axis=1).ravel() / 0.079, 6)
    assert n.tolist() == [480, 320, 130] and b.mean(axis=1) == pytest.approx(np.zeros(3), abs=1e-12)
    assert [(k - 32) // 8 + 1 for k in n.astype(int)] == [57, 37, 13]
    assert t["piv.windows"] == [64, 32] and t["render.sensors"] == ["t0", "t1", "t2", "t3"]


def test_reconstruct_stage_checks_the_drt_weights_memory(tmp_path, monkeypatch):
    """The runner's reconstruct stage estimates DRT-MART by its ray-traced weights (a sample of
    the pixels traced, scaled to the sensor), not by the voxels alone: on a 220 x 220 px crop
    (110 x 110 x 182 voxels, ~30 MB of voxel arrays, ~6e7 weight entries) with 1 GB available
    the stage refuses before building anything, naming the knob and the fix, and writes no
    volume."""
    from mitpiv import costs
    from mitpiv.errors import ConfigError
    from mitpiv.studies.runner import run_config

    ov = {"scene.params.lf_width": 220, "scene.params.lf_height": 220, "scene.params.rays_per_particle": 2000,
          "seeding.box_min_mm": [-1.638, 8.362, -5.0], "seeding.box_max_mm": [1.638, 11.638, 5.0],
          "reconstruction.bounds_mm": [-0.638, 0.638, 9.362, 10.638, -5.0, 5.0], "reconstruction.iterations": 2}
    cfg = load_experiment(SCENE / "experiment.toml", ov)
    run_config(cfg, tmp_path / "run", until="sensor")
    monkeypatch.setattr(costs, "available_memory_bytes", lambda: 2**30)
    assert costs.reconstruction_cost(110 * 110 * 182, iterations=2, method="drt-mart").memory_bytes < 0.1 * 2**30
    with pytest.raises(ConfigError, match=r"weight entries .*rays_per_pixel"):
        run_config(cfg, tmp_path / "run", until="reconstruct")
    assert not list((tmp_path / "run").glob("reconstruct/volume_*.npz"))


def test_reconstruct_stage_builds_the_drt_weights_once(tmp_path):
    """The runner's DRT-MART traces its weights for the first frame and reuses them for the
    second (same camera and grid): the second frame's weights take no time and its volume is
    the one drt_mart gives the same image on its own."""
    from mitpiv.io import read_exr, read_volume
    from mitpiv.io.records import read_json
    from mitpiv.lightfield.decode import optics_from_metadata
    from mitpiv.reconstruct.plenoptic import drt_mart
    from mitpiv.studies.runner import run_config

    ov = {"scene.params.lf_width": 110, "scene.params.lf_height": 110, "scene.params.rays_per_particle": 2000,
          "seeding.box_min_mm": [-1.319, 8.681, -5.0], "seeding.box_max_mm": [1.319, 11.319, 5.0],
          "reconstruction.bounds_mm": [-0.319, 0.319, 9.681, 10.319, -5.0, 5.0], "reconstruction.iterations": 2,
          "reconstruction.rays_per_pixel": 4}
    run_config(load_experiment(SCENE / "experiment.toml", ov), tmp_path / "run", until="reconstruct")
    info = read_json(tmp_path / "run" / "reconstruct" / "stage.json")["result"]
    assert info["frame0"]["weights_s"] > 0.05 and info["frame1"]["weights_s"] < 0.01
    assert info["frame1"]["weight_entries"] == info["frame0"]["weight_entries"]
    img, meta = read_exr(next((tmp_path / "run" / "sensor").glob("*_frame001.exr")))
    vol, grid, _ = read_volume(tmp_path / "run" / "reconstruct" / "volume_1.npz")
    alone = drt_mart(np.asarray(img if img.ndim == 2 else img[..., 0], dtype=np.float64), optics_from_metadata(meta),
                     grid, iterations=2, rays_per_pixel=4, min_coverage=0.75)
    np.testing.assert_array_equal(vol, alone)
