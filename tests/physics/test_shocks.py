"""Pellet shock phase screens (the DIH artefact of seed paper 003's shotgun experiment):
the Rankine-Hugoniot jump and Mach angle, the phase against the shell chord written afresh,
and a hologram through the screen: bands without particles, none without the screen."""

import math

import numpy as np
import pytest

from mitpiv import holography
from mitpiv.errors import ConfigError
from mitpiv.physics.shocks import AIR_N_MINUS_1, mach_angle_deg, normal_shock_density_ratio, shock_phase


def test_jump_and_angle():
    # normal shock at M = 2 (gamma 1.4): rho2/rho1 = 2.4 * 4 / (0.4 * 4 + 2) = 2.6667 (textbook tables: 2.667)
    assert float(normal_shock_density_ratio(2.0)) == pytest.approx(2.6667, abs=1e-4)
    assert mach_angle_deg(2.0) == pytest.approx(30.0, abs=1e-12)
    with pytest.raises(ConfigError, match="M > 1"):
        mach_angle_deg(0.9)


def test_phase_is_the_shell_chord():
    m, d, lam = 1.2, 2.0, 532.0
    mu = math.asin(1 / m)
    t = 0.5
    k = 2 * math.pi / (lam * 1e-6)
    jump = 2.4 * 1.44 / (0.4 * 1.44 + 2) - 1
    # a pellet at the origin flying along -x: the cone opens towards +x
    for x, y in ((10.0, 0.0), (10.0, 10.0 * math.tan(mu) + 0.2), (10.0, 5.0), (30.0, 30 * math.tan(mu) + 0.49), (-3.0, 0.0)):
        r_in = max(x, 0.0) * math.tan(mu)
        chord = 2 * (math.sqrt(max((r_in + t) ** 2 - y * y, 0)) - math.sqrt(max(r_in**2 - y * y, 0))) if x > 0 else 0.0
        ref = k * AIR_N_MINUS_1 * jump * min(1.0, (x / d) ** -0.75) * chord if x > 0 else 0.0
        got = float(shock_phase(np.array(x), np.array(y), [[0.0, 0.0]], diameter_mm=d, mach=m, wavelength_nm=lam,
                                thickness_mm=t))
        assert got == pytest.approx(ref, rel=1e-12, abs=1e-12)
    # the phase peaks at the cone's silhouette (the shell seen edge-on): the bands
    y = np.linspace(0, 20, 2001)
    ph = shock_phase(np.full_like(y, 12.0), y, [[0.0, 0.0]], diameter_mm=d, mach=m, wavelength_nm=lam, thickness_mm=t)
    assert abs(y[np.argmax(ph)] - 12.0 * math.tan(mu)) < 0.05


def test_hologram_shows_shock_bands():
    """A screen alone modulates the hologram's background (bands); zero phase leaves it flat."""
    px, n = 7.4, 128
    centre = (3.0, 0.0)

    def screen(x, y):
        return shock_phase(x, y, [[0.0, 0.0]], diameter_mm=2.0, mach=1.2, wavelength_nm=532.0)

    flat = holography.record(np.zeros((0, 3)), [], sensor_z_mm=50.0, pixel_um=px, resolution=(n, n), centre_xy_mm=centre,
                             guard_mm=0.2, phase_screens=[(0.0, lambda x, y: 0.0 * x * y)])
    shock = holography.record(np.zeros((0, 3)), [], sensor_z_mm=50.0, pixel_um=px, resolution=(n, n), centre_xy_mm=centre,
                              guard_mm=0.2, phase_screens=[(0.0, screen)])
    assert np.allclose(flat.image, 1.0, atol=1e-9)
    assert shock.image.std() > 0.01
    assert shock.info["phase_screens"] == 1
    with pytest.raises(ConfigError, match="phase_screens"):
        holography.record(np.zeros((0, 3)), [], sensor_z_mm=0.0, resolution=(16, 16), phase_screens=[(1.0, screen)])
