"""Results a user can trust (issue 30): sensors that differ only in id both render, same-seed
renders are bit-identical, cameras and frames draw independent Monte Carlo noise, and both
transport strategies agree at the edge of a strongly distorted field of view."""

import mitsuba as mi
import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.io import read_exr, write_particles_ply
from mitpiv.render.render import render_scene
from mitpiv.render.scene import check_sensor_ids, load_dict, load_scene

from .helpers import particle_scene_xml

_SENSOR = """    <sensor type="distorted_pinhole" id="{sid}">
        <float name="azimuth_deg" value="{az}"/>
        <float name="elevation_deg" value="50"/>
        <float name="distance_mm" value="600"/>
        <float name="focal_length_mm" value="85"/>
        <float name="pixel_pitch_um" value="20"/>
        {lens}
        <film type="hdrfilm">
            <integer name="width" value="{res}"/>
            <integer name="height" value="{res}"/>
            <string name="pixel_format" value="luminance"/>
            <rfilter type="{rfilter}"/>
        </film>
    </sensor>
"""
THIN_LENS = '<float name="f_number" value="2"/><float name="focus_distance_mm" value="560"/>'


def _xml(tmp_path, cams, *, n=60, res=32, lens=THIN_LENS, rfilter="box", rays=8, same_frames=False):
    rng = np.random.default_rng(8)
    pts = rng.uniform(-1.5, 1.5, (n, 3))
    for k in (0, 1):
        write_particles_ply(tmp_path / f"particles_{k}.ply", pts if same_frames else rng.uniform(-1.5, 1.5, (n, 3)),
                            1.5, proxy_radius_mm=0.01)
    sensors = "".join(_SENSOR.format(sid=s, az=az, lens=lens, res=res, rfilter=rfilter) for s, az in cams)
    xml = particle_scene_xml(sensors, integrator=f'<integrator type="particle_tracer"><integer '
                                                 f'name="rays_per_particle" value="{rays}"/></integrator>')
    path = tmp_path / "scene.xml"
    path.write_text(xml)
    return path


# ------------------------------------------------------------------ item 6: sensors differing only in id
def test_two_sensors_differing_only_in_id_both_render(tmp_path):
    xml = _xml(tmp_path, [("camA", 30), ("camB", 30)])
    sc = load_scene(xml)
    assert [s.id() for s in sc.sensors()] == ["camA", "camB"]
    assert sc.sensors()[0] is not sc.sensors()[1]
    files = render_scene(xml, out_dir=tmp_path / "out", frames=(0,), seed=2, progress=False)
    assert sorted(p.name for p in files) == ["camA_frame000.exr", "camB_frame000.exr"]
    a, b = (read_exr(p)[0] for p in sorted(files))
    # the same view with its own stream each: equal totals within noise, different noise
    assert a.sum() > 0 and b.sum() > 0 and not np.array_equal(a, b)
    # scene dictionaries too
    s = {"type": "perspective", "fov": 30.0, "film": {"type": "hdrfilm", "width": 8, "height": 8}}
    d = load_dict({"type": "scene", "c0": {**s, "id": "c0"}, "c1": {**s, "id": "c1"}})
    assert check_sensor_ids(d) == ["c0", "c1"]


def test_sensors_merged_by_mitsuba_are_refused(tmp_path):
    xml = _xml(tmp_path, [("camA", 30), ("camB", 30)])
    merged = mi.load_file(str(xml), frame="0")  # Mitsuba's default parser merges the two
    with pytest.raises(ConfigError, match="not distinct"):
        check_sensor_ids(merged)
