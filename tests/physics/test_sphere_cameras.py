"""Quadrant camera arrangements of the channel-tomo paper: positions on the sphere written
afresh from theta / phi, the quadrant symmetries, scattering angles, the Scheimpflug focus
on the sheet mid-plane, and the sensor XML."""

import math
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.physics.sphere_cameras import distorted_pinhole_sensors_xml, quadrant_arrangement

ATOL_MM = 1e-9  # closed forms in float64


def _position(theta, phi, r):
    t, p = math.radians(theta), math.radians(phi)
    return r * np.array([math.cos(p) * math.cos(t), math.cos(p) * math.sin(t), math.sin(p)])


@pytest.mark.parametrize("config, expect", [
    ("top", [(25, 55), (-25, 55), (155, 55), (205, 55)]),
    ("forward", [(25, 55), (-25, 55), (25, -55), (-25, -55)]),
    ("backward", [(155, 55), (205, 55), (155, -55), (205, -55)]),
    ("symmetric", [(25, 55), (155, 55), (25, -55), (155, -55)]),
])
def test_positions_and_quadrant_symmetry(config, expect):
    r = 150.0
    cams = quadrant_arrangement(config, theta_deg=25, phi_deg=55, distance_mm=r, focal_length_mm=50.0)
    pos = np.array([c["position_mm"] for c in cams])
    want = np.array([_position(t, p, r) for t, p in expect])
    assert np.allclose(pos, want, atol=ATOL_MM)
    # every camera looks at the target; scattering angle acos(cos phi cos theta)
    for c, (t, p) in zip(cams, expect, strict=True):
        axis = c["rotation"][2]
        assert np.allclose(axis, -c["position_mm"] / r, atol=1e-12)
        cos_s = math.cos(math.radians(p)) * math.cos(math.radians(t))
        assert c["scattering_angle_deg"] == pytest.approx(math.degrees(math.acos(cos_s)), abs=1e-9)
        # Scheimpflug on the mid-plane z = 0 through the target: the axis meets it at the
        # target (focus distance r) and the object plane is tilted by 90 - |phi|
        s = c["scheimpflug"]
        assert s["focus_distance_mm"] == pytest.approx(r, rel=1e-12)
        assert s["object_tilt_deg"] == pytest.approx(90 - abs(p), abs=1e-9)
        assert s["magnification"] == pytest.approx(50.0 / (r - 50.0), rel=1e-12)
    fwd = [c["scattering_angle_deg"] < 90 for c in cams]
    assert fwd == {"top": [True, True, False, False], "forward": [True] * 4, "backward": [False] * 4,
                   "symmetric": [True, False, True, False]}[config]


def test_sensor_xml_is_well_formed_and_carries_the_focus():
    cams = quadrant_arrangement("top", theta_deg=23, phi_deg=55, distance_mm=151.0, focal_length_mm=53.0)
    text = distorted_pinhole_sensors_xml(cams, distance_mm=151.0, focal_length_mm=53.0, pixel_pitch_um=10.0,
                                         f_number=8.0, extra_xml='<string name="psf" value="fft"/>')
    root = ET.fromstring(f"<scene>{text}</scene>")
    sensors = root.findall("sensor")
    assert [s.get("id") for s in sensors] == ["cam0", "cam1", "cam2", "cam3"]
    for s, c in zip(sensors, cams, strict=True):
        vals = {e.get("name"): e.get("value") for e in s}
        assert float(vals["azimuth_deg"]) == c["azimuth_deg"] and float(vals["elevation_deg"]) == 55.0
        assert float(vals["focus_distance_mm"]) == pytest.approx(151.0, rel=1e-9)
        assert np.allclose([float(x) for x in vals["focus_plane_normal"].split(",")], [0, 0, 1])
        assert vals["psf"] == "fft" and s.find("ref").get("id") == "film"
    with pytest.raises(ConfigError, match="theta_deg"):
        quadrant_arrangement("top", theta_deg=95, phi_deg=55, distance_mm=1.0)
    with pytest.raises(ConfigError, match="configuration"):
        quadrant_arrangement("side", theta_deg=25, phi_deg=55, distance_mm=1.0)
