"""A pinhole ``distorted_pinhole`` with a diffraction PSF placed around a target takes the
PSF's magnification from the placement, M = f / (d - f) with d the distance to the target
along the optical axis; given by hand it wins, and a bare ``to_world`` (no distance known)
keeps no magnification."""

import logging

import mitsuba as mi
import numpy as np
import pytest

from mitpiv.physics.camera import PinholeCamera, look_at_rotation
from mitpiv.render.scene import load_dict


def _sensor(**props):
    s = {"type": "distorted_pinhole", "focal_length_mm": 85.0, "pixel_pitch_um": 10.0, "psf": "fft",
         "psf_f_number": 8.0, "psf_oversample": 1, "psf_energy_tolerance": 0.05,
         "film": {"type": "hdrfilm", "width": 8, "height": 8, "pixel_format": "luminance",
                  "rfilter": {"type": "catmullrom"}}}
    s.update(props)
    return load_dict({"type": "scene", "integrator": {"type": "particle_tracer"}, "cam": s}).sensors()[0]


PLACE = {"target": mi.ScalarPoint3f(1.0, -2.0, 3.0), "azimuth_deg": 30.0, "elevation_deg": 50.0}


def test_pinhole_psf_magnification_follows_the_placement_distance(caplog):
    with caplog.at_level(logging.INFO, logger="mitpiv.render.plugins.distorted_pinhole"):
        near = _sensor(distance_mm=1000.0, **PLACE).describe()
    assert near["psf"]["magnification"] == pytest.approx(85.0 / 915.0, rel=1e-12)
    assert near["psf_magnification_from"] == "placement distance_mm"
    assert any("psf_magnification" in r.getMessage() and "915" in r.getMessage() for r in caplog.records)
    moved = _sensor(distance_mm=500.0, **PLACE).describe()
    assert moved["psf"]["magnification"] == pytest.approx(85.0 / 415.0, rel=1e-12)
    # a longer lens at the same distance
    assert _sensor(distance_mm=500.0, **{**PLACE, "focal_length_mm": 100.0}).describe()["psf"]["magnification"] \
        == pytest.approx(100.0 / 400.0, rel=1e-12)


def test_given_magnification_wins_and_a_bare_pose_has_none():
    given = _sensor(distance_mm=1000.0, psf_magnification=0.5, **PLACE).describe()
    assert given["psf"]["magnification"] == 0.5 and given["psf_magnification_from"] == "given"
    pos = np.array([0.0, 0.0, 1000.0])
    cam = PinholeCamera((8, 8), 85.0, 10.0, rotation=look_at_rotation(pos, [0, 0, 0], up=[0, 1, 0]), position_mm=pos)
    bare = _sensor(to_world=mi.ScalarTransform4f(cam.to_world_mitsuba())).describe()
    assert bare["psf"]["magnification"] is None and bare["psf_magnification_from"] is None
    lens = _sensor(distance_mm=1000.0, f_number=8.0, focus_distance_mm=600.0, **PLACE).describe()
    assert lens["psf"]["magnification"] == pytest.approx(85.0 / 515.0, rel=1e-12)  # a thin lens: its focus
    assert lens["psf_magnification_from"] == "thin lens focus_distance_mm"
