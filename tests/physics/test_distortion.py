"""Brown-Conrady distortion: forward/inverse, percent parametrisation, fold detection.

References: the model's closed form written afresh here in float64 (finite differences for
the Jacobian, the k1-only radial shift for the percent model).
"""

import numpy as np
import pytest

from mitpiv.errors import ConfigError
from mitpiv.physics.camera import PinholeCamera
from mitpiv.physics.distortion import (
    Distortion,
    check_distortion,
    distort,
    distort_jacobian,
    percent_shift,
    percent_to_k1,
    undistort,
)

RES = (1024, 768)
F_PX = 8500.0 * 0.25  # a wide-ish lens: corner at ~0.3 normalised radius
PP = (512.0, 384.0)
R_MAX = np.hypot(512, 384) / F_PX
ROUND_TRIP_TOL_PX = 1e-4  # the requirement, float64
# At the largest non-folding barrel the Newton inverse still converges to check_distortion's
# own tolerance_px default (1e-6 px).
FOLD_LIMIT_ROUND_TRIP_TOL_PX = 1e-6
# Jacobian against central differences with h = 1e-6 (normalised coordinates ~0.3): truncation
# h^2 |f'''| / 6 ~ 1e-12, rounding eps |f| / h ~ 1e-10.
FD_RTOL, FD_ATOL = 1e-7, 1e-9
# The bisection's last accepted k1 against the analytic fold: the fold's image 2/3 r_f sits at
# check_distortion's 2 % margin past the corner radius. Measured: equal to 2e-12 relative; this
# tolerance is far looser than needed.
FOLD_RADIUS_REL_TOL = 2e-2


def image_grid(n=41):
    u, v = np.meshgrid(np.linspace(0, RES[0], n), np.linspace(0, RES[1], n))
    return (u.ravel() - PP[0]) / F_PX, (v.ravel() - PP[1]) / F_PX


@pytest.mark.parametrize("pct", [-2.0, -1.0, -0.1, 0.1, 0.5, 1.0, 2.0])
@pytest.mark.parametrize("tangential", [(0.0, 0.0), (2e-4, -3e-4)])
def test_round_trip_over_image(pct, tangential):
    d = Distortion(k1=percent_to_k1(pct, r_max=R_MAX), k2=0.02 * np.sign(pct), p1=tangential[0], p2=tangential[1])
    n = check_distortion(d, resolution=RES, focal_px=F_PX, principal_point_px=PP)
    xd, yd = image_grid()
    x, y = undistort(xd, yd, d, iterations=n)
    x2, y2 = distort(x, y, d)
    err = np.hypot(x2 - xd, y2 - yd) * F_PX
    assert err.max() < ROUND_TRIP_TOL_PX
    # and the other way round, starting from undistorted points
    xb, yb = undistort(*distort(xd, yd, d), d, iterations=n)
    assert np.hypot(xb - xd, yb - yd).max() * F_PX < ROUND_TRIP_TOL_PX


def test_jacobian_matches_finite_differences():
    d = Distortion(k1=-0.3, k2=0.1, k3=-0.05, p1=1e-3, p2=-2e-3)
    rng = np.random.default_rng(1)
    x, y = rng.uniform(-0.3, 0.3, (2, 200))
    h = 1e-6
    _, _, a, b, c, e = distort_jacobian(x, y, d)
    fxp, fyp = distort(x + h, y, d)
    fxm, fym = distort(x - h, y, d)
    gxp, gyp = distort(x, y + h, d)
    gxm, gym = distort(x, y - h, d)
    np.testing.assert_allclose(a, (fxp - fxm) / (2 * h), rtol=FD_RTOL, atol=FD_ATOL)
    np.testing.assert_allclose(c, (fyp - fym) / (2 * h), rtol=FD_RTOL, atol=FD_ATOL)
    np.testing.assert_allclose(b, (gxp - gxm) / (2 * h), rtol=FD_RTOL, atol=FD_ATOL)
    np.testing.assert_allclose(e, (gyp - gym) / (2 * h), rtol=FD_RTOL, atol=FD_ATOL)


@pytest.mark.parametrize("pct", [-2.0, 0.5, 2.0])
def test_percent_model_shift_matches_closed_form(pct):
    k1 = percent_to_k1(pct, r_max=R_MAX)
    r_u = np.linspace(0, R_MAX, 50)
    xd, _ = distort(r_u, np.zeros_like(r_u), Distortion(k1=k1))
    shift_px = (xd - r_u) * F_PX
    np.testing.assert_allclose(shift_px, percent_shift(r_u, pct, r_max=R_MAX) * F_PX, atol=1e-9)
    # at the corner the shift is pct % of the corner radius, inward for barrel (pct > 0)
    assert shift_px[-1] == pytest.approx(-pct / 100 * R_MAX * F_PX, rel=1e-12)


def test_barrel_beyond_fold_is_rejected_with_coefficients_named():
    k1 = -1.0 / (3 * (0.8 * R_MAX) ** 2)  # slope 1 + 3 k1 r^2 reaches 0 at 0.8 r_max
    with pytest.raises(ConfigError, match=r"k1=.*folds over"):
        check_distortion(Distortion(k1=k1), resolution=RES, focal_px=F_PX, principal_point_px=PP)


def test_tangential_fold_is_rejected():
    with pytest.raises(ConfigError, match="p1"):
        check_distortion(Distortion(p1=2.0), resolution=RES, focal_px=F_PX, principal_point_px=PP)


def test_largest_non_folding_barrel_stays_stable():
    # Fold starts where 1 + 3 k1 r^2 = 0; bisect the last k1 accepted for this image.
    lo, hi = -1e-3, -10.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        try:
            check_distortion(Distortion(k1=mid), resolution=RES, focal_px=F_PX, principal_point_px=PP)
            lo = mid
        except ConfigError:
            hi = mid
    d = Distortion(k1=lo)
    n = check_distortion(d, resolution=RES, focal_px=F_PX, principal_point_px=PP)
    xd, yd = image_grid()
    x, y = undistort(xd, yd, d, iterations=n)
    assert np.all(np.isfinite(x))
    x2, y2 = distort(x, y, d)
    assert np.hypot(x2 - xd, y2 - yd).max() * F_PX < FOLD_LIMIT_ROUND_TRIP_TOL_PX
    # analytic fold radius: r_f = 1/sqrt(-3 k1); its image r_f (1 + k1 r_f^2) = 2/3 r_f
    r_f = 1 / np.sqrt(-3 * lo)
    assert 2 / 3 * r_f == pytest.approx(1.02 * R_MAX, rel=FOLD_RADIUS_REL_TOL)


def test_camera_project_inverts_pixel_to_ray():
    cam = PinholeCamera(RES, 50.0, 10.0, distortion=Distortion(k1=-0.2, p1=1e-4), position_mm=[1, 2, 3])
    cam.validate_distortion()
    uv = np.stack(np.meshgrid(np.linspace(1, 1023, 9), np.linspace(1, 767, 7)), -1).reshape(-1, 2)
    o, d = cam.pixel_to_ray(uv)
    np.testing.assert_allclose(cam.project(o + 300 * d), uv, atol=1e-7)
