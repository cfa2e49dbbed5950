"""Light-field geometry written once: ``lightfield.alpha_from_z`` (focal plane given by the
magnification), ``PlenopticCamera.alpha`` and ``physics.plenoptic.alpha_from_z_geom`` are
one formula; so are the two depth-of-field calculators. Reference: the thin-lens equation
1/f = 1/s_o + 1/s_i written afresh in float64."""

import numpy as np
import pytest

import mitpiv.lightfield as lfm
from mitpiv.errors import ConfigError
from mitpiv.physics.plenoptic import PlenopticCamera, alpha_from_z_geom, dof_limits_geom

REL = 1e-12  # float64 evaluation of the same closed form, different operation order
# The inverse z(alpha) and the depth-of-field limits subtract nearly equal distances
# (s_o' - s_o, s_i - s_i'): float64 cancellation of a few digits.
CANCELLATION_REL = 1e-9


@pytest.mark.parametrize("f, so", [(50.0, 250.0), (10.0, 100.0), (85.0, 400.0)])
def test_alpha_is_one_formula(f, so):
    cam = PlenopticCamera(resolution=(400, 400), pixel_pitch_um=5.5, focal_length_mm=f, f_number=2.8,
                          focus_distance_mm=so, mla_pitch_um=55.0)
    z = np.linspace(-0.6 * (so - f), 3.0 * so, 41)
    si = 1.0 / (1.0 / f - 1.0 / so)
    ref = 1.0 / (1.0 / f - 1.0 / (so + z)) / si  # thin lens: alpha = s_i(s_o + z) / s_i(s_o)
    a_lf = lfm.alpha_from_z(z, focal_length_mm=f, magnification=cam.magnification)
    np.testing.assert_allclose(a_lf, ref, rtol=REL)
    np.testing.assert_allclose(cam.alpha(z), ref, rtol=REL)
    np.testing.assert_allclose(alpha_from_z_geom(z, f, so), ref, rtol=REL)
    assert isinstance(lfm.alpha_from_z(1.0, focal_length_mm=f, magnification=cam.magnification), float)
    np.testing.assert_allclose(lfm.z_from_alpha(a_lf, focal_length_mm=f, magnification=cam.magnification), z,
                               rtol=CANCELLATION_REL, atol=CANCELLATION_REL * so)
    # one validation: the same error from every entry point
    bad = f - so - 1.0
    for call in (lambda: cam.alpha(bad), lambda: alpha_from_z_geom([0.0, bad], f, so),
                 lambda: lfm.alpha_from_z(bad, focal_length_mm=f, magnification=cam.magnification),
                 lambda: cam.alpha(np.nan)):
        with pytest.raises(ConfigError, match="every z must be finite"):
            call()


def test_depth_of_field_is_one_formula():
    cam = PlenopticCamera(resolution=(400, 400), pixel_pitch_um=5.5, focal_length_mm=50.0, f_number=2.8,
                          focus_distance_mm=250.0, mla_pitch_um=55.0)
    for kind, nu in (("refocused", 1.0), ("perspective", cam.angular_samples)):
        lf = lfm.depth_of_field(focal_length_mm=50.0, magnification=cam.magnification, f_number=2.8,
                                mla_pitch_um=55.0, angular_samples=nu)
        np.testing.assert_allclose(lf, cam.depth_of_field(kind), rtol=REL)
    # thin lens afresh: the blur D |s_i - s_i'| / s_i' on the MLA reaches one pitch p
    f, so, d, p = 50.0, 250.0, 50.0 / 2.8, 0.055
    si = 1 / (1 / f - 1 / so)
    near, far = dof_limits_geom(f, so, d, p)
    for dz in (near, far):
        sip = 1 / (1 / f - 1 / (so + dz))
        assert d * abs(si - sip) / sip == pytest.approx(p, rel=CANCELLATION_REL)
