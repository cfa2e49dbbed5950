"""scenes/channel: the experiment a user copies for a wall-turbulence measurement. Its
numbers are the wall-unit design its comments claim (checked here from l_nu = nu / u_tau),
and its flow, cameras and sheet are what the channel-tomo paper describes."""

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from mitpiv.physics.flows import flow_from_dict
from mitpiv.studies import load_experiment

SCENE = Path(__file__).resolve().parents[2] / "scenes" / "channel"
REL = 0.02  # the toml rounds wall-unit lengths to 3-4 significant digits


def test_channel_experiment_is_the_wall_unit_design_it_claims():
    cfg = load_experiment(SCENE / "experiment.toml")
    f = cfg.flow.model_dump()
    dt = f.pop("dt_s")
    flow = flow_from_dict(f)
    lnu = flow.viscous_length_mm
    assert lnu == pytest.approx(15.1 / 500.0)
    lo, hi = np.array(cfg.seeding.box_min_mm), np.array(cfg.seeding.box_max_mm)
    # the sheet's 100+ across the wall-normal axis at 100 < y+ < 200; 120+ wall-parallel crop
    yplus = flow.wall_distance_plus(np.array([lo, hi]))
    assert yplus == pytest.approx([100.0, 200.0], rel=REL)
    assert (hi - lo)[:2] / lnu == pytest.approx([120.0, 120.0], rel=REL)
    # voxels of l_v+ = 0.63; the final window 32 voxels = 20 wall units
    vox = cfg.reconstruction.voxel_mm
    assert vox / lnu == pytest.approx(0.63, rel=REL)
    assert cfg.piv.windows[-1] * vox / lnu == pytest.approx(20.0, rel=REL)
    assert cfg.piv.correlation == "ncc" and cfg.reconstruction.method == "smart"
    assert cfg.reconstruction.interpolation == "cubic"
    # N_I = 5 particles per (20+)^3
    assert cfg.seeding.concentration_per_mm3 * (20 * lnu) ** 3 == pytest.approx(5.0, rel=REL)
    # dt: the mean streamwise displacement at the band centre is ~25 % of the window
    disp_vox = flow.profile_table.mean_plus(150.0) * flow.friction_velocity_mm_s * dt / vox
    assert disp_vox == pytest.approx(0.25 * cfg.piv.windows[-1], rel=0.05)


def test_channel_scene_cameras_and_sheet():
    root = ET.parse(SCENE / "scene.xml").getroot()
    defaults = {d.get("name"): d.get("value") for d in root.findall("default")}
    lnu = 15.1 / 500.0
    assert float(defaults["thickness_mm"]) / lnu == pytest.approx(100.0, rel=1e-3)
    sheet = root.find("emitter[@type='laser_sheet']")
    assert {e.get("name"): e.get("value") for e in sheet}["profile"] == "tophat"
    sensors = root.findall("sensor")
    assert len(sensors) == 4
    az = [float(defaults[f"az{i}"]) for i in range(4)]
    el = [float(defaults[f"el{i}"]) for i in range(4)]
    assert az == [25.0, -25.0, 155.0, 205.0] and el == [55.0] * 4  # one per quadrant, theta 25, phi 55
    for s in sensors:
        v = {e.get("name"): e.get("value") for e in s if e.get("name")}
        assert float(v["distance_mm"]) / lnu == pytest.approx(5000.0, rel=1e-3)
        assert float(v["focus_distance_mm"]) == float(v["distance_mm"])  # focused on the mid-plane
        assert [float(x) for x in v["focus_plane_normal"].split(",")] == [0.0, 0.0, 1.0]
        # the 52 mm lens at f/16 for the diffraction PSF, its magnification f / (s - f)
        m = 52.0 / (float(v["distance_mm"]) - 52.0)
        assert float(v["psf_f_number"]) == 16.0 and float(v["psf_magnification"]) == pytest.approx(m, rel=1e-5)


def test_channel_cameras_see_the_designed_pixel_on_the_loaded_sensors(tmp_path):
    """Measured on the loaded Mitsuba sensors, not read from the XML: a 10 um pixel sees
    0.63 wall units (19 um) at the volume centre, so voxel / pixel is 1 at l_v+ = 0.63 (the
    mapping's pinhole distance is the 52 mm lens's image distance, 79.3 mm, not its focal
    length, which gave 29 um); the aperture is the 52 mm lens's f/16 (3.25 mm); the 120+
    volume lies inside the 320 px image of every camera."""
    import itertools
    import shutil

    import mitsuba as mi

    from mitpiv.io.particles import write_particles_ply
    from mitpiv.render.variant import ensure_variant

    ensure_variant()
    shutil.copy(SCENE / "scene.xml", tmp_path / "scene.xml")
    write_particles_ply(tmp_path / "particles_0.ply", np.zeros((1, 3)), 1.0, proxy_radius_mm=0.005)
    scene = mi.load_file(str(tmp_path / "scene.xml"), frame=0)
    lnu = 15.1 / 500.0
    cfg = load_experiment(SCENE / "experiment.toml")
    corners = np.array(list(itertools.product(*zip(cfg.seeding.box_min_mm, cfg.seeding.box_max_mm, strict=True))))
    for s in scene.sensors():
        cam = s.camera
        rot = np.asarray(cam.rotation)
        for axis in (0, 1):
            uv = cam.project(np.array([[0.0, 0.0, 0.0], 0.5 * rot[axis]]))
            assert 0.5 / float(np.linalg.norm(uv[1] - uv[0])) / lnu == pytest.approx(0.63, rel=REL)
        assert 2 * cam.aperture_radius_mm == pytest.approx(52.0 / 16.0, rel=1e-6)
        uv = cam.project(corners)
        assert tuple(cam.resolution) == (320, 320) and uv.min() > 0 and uv.max() < 320
