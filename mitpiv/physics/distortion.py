"""Brown-Conrady lens distortion (OpenCV convention) and its inverse.

Coordinates are *normalised image coordinates* ``x = X_c / Z_c``, ``y = Y_c / Z_c`` in the
OpenCV camera frame (x right, y down, z forward). The model maps undistorted to
distorted coordinates::

    r2     = x^2 + y^2
    radial = 1 + k1 r2 + k2 r2^2 + k3 r2^3
    x_d    = x radial + 2 p1 x y + p2 (r2 + 2 x^2)
    y_d    = y radial + p1 (r2 + 2 y^2) + 2 p2 x y

The functions use arithmetic operators only, so the same code runs on NumPy arrays
(float64, the reference) and on Dr.Jit arrays inside Mitsuba kernels (float32). Terms whose
coefficients are zero are skipped in Python, so they are never traced.

The "percent distortion" parametrisation used in synthetic-aperture PIV studies gives the
radial shift at the image corner in percent of the corner radius; positive values are
barrel distortion (points move inwards): ``k1 = -p / (100 r_max^2)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mitpiv.errors import ConfigError

__all__ = [
    "Distortion",
    "distort",
    "distort_jacobian",
    "undistort",
    "percent_to_k1",
    "percent_shift",
    "check_distortion",
    "fold_radius",
]


@dataclass(frozen=True)
class Distortion:
    """Brown-Conrady coefficients (OpenCV order k1, k2, p1, p2, k3), dimensionless."""

    k1: float = 0.0
    k2: float = 0.0
    k3: float = 0.0
    p1: float = 0.0
    p2: float = 0.0

    @property
    def is_zero(self) -> bool:
        return self.k1 == self.k2 == self.k3 == self.p1 == self.p2 == 0.0

    @property
    def has_tangential(self) -> bool:
        return self.p1 != 0.0 or self.p2 != 0.0

    def to_dict(self) -> dict:
        return {"k1": self.k1, "k2": self.k2, "k3": self.k3, "p1": self.p1, "p2": self.p2}

    def opencv_coefficients(self) -> list[float]:
        """Coefficients in OpenCV's ``distCoeffs`` order (k1, k2, p1, p2, k3)."""
        return [self.k1, self.k2, self.p1, self.p2, self.k3]

    def __str__(self) -> str:
        return ", ".join(f"{k}={v:g}" for k, v in self.to_dict().items())


def _radial(r2, d: Distortion):
    """Radial factor 1 + k1 r2 + k2 r2^2 + k3 r2^3 and dR = k1 + 2 k2 r2 + 3 k3 r2^2."""
    if d.k3 != 0.0:
        radial = 1.0 + r2 * (d.k1 + r2 * (d.k2 + r2 * d.k3))
        d_radial = d.k1 + r2 * (2.0 * d.k2 + r2 * (3.0 * d.k3))
    elif d.k2 != 0.0:
        radial = 1.0 + r2 * (d.k1 + r2 * d.k2)
        d_radial = d.k1 + r2 * (2.0 * d.k2)
    else:
        radial = 1.0 + r2 * d.k1
        d_radial = r2 * 0.0 + d.k1
    return radial, d_radial


def distort(x, y, d: Distortion):
    """Undistorted -> distorted normalised coordinates (works on NumPy and Dr.Jit arrays)."""
    if d.is_zero:
        return x, y
    r2 = x * x + y * y
    radial, _ = _radial(r2, d)
    xd = x * radial
    yd = y * radial
    if d.has_tangential:
        xy2 = 2.0 * x * y
        xd = xd + d.p1 * xy2 + d.p2 * (r2 + 2.0 * x * x)
        yd = yd + d.p1 * (r2 + 2.0 * y * y) + d.p2 * xy2
    return xd, yd


def distort_jacobian(x, y, d: Distortion):
    """Distorted coordinates and the Jacobian entries (a, b, c, e) = d(xd, yd)/d(x, y).

    ``a = dxd/dx, b = dxd/dy, c = dyd/dx, e = dyd/dy``.
    """
    r2 = x * x + y * y
    radial, d_radial = _radial(r2, d)
    xd = x * radial
    yd = y * radial
    a = radial + 2.0 * x * x * d_radial
    e = radial + 2.0 * y * y * d_radial
    b = 2.0 * x * y * d_radial
    c = b
    if d.has_tangential:
        xy2 = 2.0 * x * y
        xd = xd + d.p1 * xy2 + d.p2 * (r2 + 2.0 * x * x)
        yd = yd + d.p1 * (r2 + 2.0 * y * y) + d.p2 * xy2
        a = a + 2.0 * d.p1 * y + 6.0 * d.p2 * x
        e = e + 6.0 * d.p1 * y + 2.0 * d.p2 * x
        b = b + 2.0 * d.p1 * x + 2.0 * d.p2 * y
        c = b
    return xd, yd, a, b, c, e


def undistort(xd, yd, d: Distortion, *, iterations: int = 8):
    """Distorted -> undistorted normalised coordinates by Newton's method.

    A fixed number of iterations keeps the function traceable by Dr.Jit. Use
    :func:`check_distortion` to validate that ``iterations`` converge over an image.
    """
    if d.is_zero:
        return xd, yd
    x = xd * 1.0
    y = yd * 1.0
    for _ in range(iterations):
        fx, fy, a, b, c, e = distort_jacobian(x, y, d)
        rx = fx - xd
        ry = fy - yd
        inv_det = 1.0 / (a * e - b * c)
        x = x - (e * rx - b * ry) * inv_det
        y = y - (a * ry - c * rx) * inv_det
    return x, y


def fold_radius(d: Distortion) -> float:
    """Undistorted normalised radius where the radial map ``r R(r^2)`` stops increasing
    (``inf`` when it never does): the edge of the model's invertible branch.

    Beyond it a strong barrel distortion folds back, so a point far outside the field of
    view would land inside the image, although no pixel's ray (the inverse, on the
    principal branch) reaches it. Cameras treat points beyond this radius as not visible,
    in both transport strategies and in reconstruction (see
    :meth:`mitpiv.physics.camera.PinholeCamera.visible`). Smallest positive root ``s = r^2``
    of ``1 + 3 k1 s + 5 k2 s^2 + 7 k3 s^3`` (the tangential terms are not part of the radial
    branch; :func:`check_distortion` checks the full Jacobian over the image).
    """
    roots = np.roots([7.0 * d.k3, 5.0 * d.k2, 3.0 * d.k1, 1.0]) if not d.is_zero else np.array([])
    s = [float(r.real) for r in np.atleast_1d(roots) if abs(r.imag) <= 1e-12 * max(1.0, abs(r)) and r.real > 0]
    return float(np.sqrt(min(s))) if s else float("inf")


def percent_to_k1(percent: float, *, r_max: float) -> float:
    """k1 giving ``percent`` radial distortion at normalised radius ``r_max`` (barrel > 0).

    The percent definition of the SAPIV aberration study (Kubaczyk, MIT S.M. thesis,
    appendix A): the second-order model maps undistorted to distorted radii ::

        r_d = r_u (1 + K1 r_u^2)                                           (eq. A.3)

    and p percent distortion moves the corner (``r_u = r_max``) to ::

        r_d = r_max (1 - p / 100)                                          (eq. A.4)

    so that ::

        K1 = -p / (100 r_max^2)                                            (eq. A.8)

    (``K1`` is this function's ``k1`` in normalised coordinates when ``r_max`` is too.)
    The paper's Table 3.1 matches eq. A.3 at the corner (14.14 px for 2 % on a 1000 x 1000
    image) but its inner columns follow ``p r_n^2 r_max`` instead of eq. A.3's
    ``p r_n^3 r_max``; tests/studies/test_replicate_sapiv_distortion.py holds both.

    Parameters
    ----------
    percent : float
        Radial shift at the image corner in percent of the corner radius. Positive is
        barrel distortion (inward shift), negative is pincushion.
    r_max : float
        Corner radius in normalised (undistorted) image coordinates, e.g.
        ``hypot(W/2, H/2) * pixel_pitch / focal_length``.
    """
    if not (r_max > 0):
        raise ConfigError(f"percent_to_k1: r_max must be > 0, got {r_max!r}.")
    return -float(percent) / (100.0 * r_max * r_max)


def percent_shift(r_u, percent: float, *, r_max: float):
    """Closed-form radial shift ``r_d - r_u = K1 r_u^3 = -p/100 r_u^3 / r_max^2`` of the
    percent model (eqs. A.3, A.8; negative = inward), in the units of ``r_u`` and ``r_max``."""
    return -float(percent) / 100.0 * np.asarray(r_u, dtype=float) ** 3 / r_max**2


def check_distortion(
    d: Distortion,
    *,
    resolution: tuple[int, int],
    focal_px: float,
    principal_point_px: tuple[float, float],
    iterations: int = 8,
    tolerance_px: float = 1e-6,
    owner: str = "distortion",
) -> int:
    """Validate a distortion over an image; return the Newton iteration count it needs.

    Raises :class:`ConfigError` naming the coefficients when the mapping folds over
    (its Jacobian determinant reaches zero) inside the pre-image of the image, or when
    the inverse does not converge to ``tolerance_px`` within 50 iterations.
    """
    if d.is_zero:
        return 0
    w, h = resolution
    cx, cy = principal_point_px
    corners = np.array([[0.0, 0.0], [w, 0.0], [0.0, h], [w, h]])
    rd_corner = np.max(np.hypot(corners[:, 0] - cx, corners[:, 1] - cy)) / focal_px
    # Radial part: r_d(r) = r R(r^2) must increase until it passes the corner radius.
    r = np.linspace(0.0, 1.5 * rd_corner + 1e-12, 400_001)
    while True:
        r2 = r * r
        rd = r * (1 + r2 * (d.k1 + r2 * (d.k2 + r2 * d.k3)))
        slope = 1 + r2 * (3 * d.k1 + r2 * (5 * d.k2 + r2 * 7 * d.k3))
        reach = np.nonzero(rd >= rd_corner * 1.02)[0]
        bad = np.nonzero(slope <= 0)[0]
        first_reach = reach[0] if reach.size else None
        first_bad = bad[0] if bad.size else None
        if first_bad is not None and (first_reach is None or first_bad <= first_reach):
            rf = r[first_bad]
            raise ConfigError(
                f"{owner}: distortion ({d}) folds over inside the image: the radial map "
                f"stops increasing at {rf * focal_px:.1f} px from the principal point "
                f"(distorted radius {rd[first_bad] * focal_px:.1f} px), before reaching "
                f"the image corner at {rd_corner * focal_px:.1f} px. Reduce |k1| (for "
                f"the percent model: a smaller percentage) or add a compensating k2."
            )
        if first_reach is not None:
            r_pre = r[first_reach]
            break
        if r[-1] > 1e3:
            raise ConfigError(f"{owner}: distortion ({d}) never reaches the image corner.")
        r = np.linspace(0.0, r[-1] * 4, 400_001)
    # Full 2D check of the Jacobian determinant on the pre-image disk.
    g = np.linspace(-r_pre, r_pre, 801)
    gx, gy = np.meshgrid(g, g)
    inside = gx * gx + gy * gy <= r_pre * r_pre
    _, _, a, b, c, e = distort_jacobian(gx[inside], gy[inside], d)
    det = a * e - b * c
    if np.min(det) <= 0:
        k = np.argmin(det)
        raise ConfigError(
            f"{owner}: distortion ({d}) folds over inside the image (Jacobian "
            f"determinant {det[k]:.3g} at undistorted ({gx[inside][k] * focal_px:.1f}, "
            f"{gy[inside][k] * focal_px:.1f}) px from the principal point). Reduce the "
            f"tangential coefficients p1, p2 or the radial coefficients."
        )
    # Round trip over the image: choose the iteration count that converges.
    u = np.concatenate([np.linspace(0, w, 129), np.linspace(0, w, 129), np.zeros(129), np.full(129, w)])
    v = np.concatenate([np.zeros(129), np.full(129, h), np.linspace(0, h, 129), np.linspace(0, h, 129)])
    uu, vv = np.meshgrid(np.linspace(0, w, 65), np.linspace(0, h, 65))
    u = np.concatenate([u, uu.ravel()])
    v = np.concatenate([v, vv.ravel()])
    xd = (u - cx) / focal_px
    yd = (v - cy) / focal_px
    for n in range(max(iterations, 1), 51):
        x, y = undistort(xd, yd, d, iterations=n)
        x2, y2 = distort(x, y, d)
        err = np.max(np.hypot(x2 - xd, y2 - yd)) * focal_px
        if np.isfinite(err) and err < tolerance_px:
            return n
    raise ConfigError(
        f"{owner}: the inverse of distortion ({d}) does not converge over the image "
        f"(round-trip error {err:.3g} px after 50 Newton iterations). Use smaller "
        f"coefficients."
    )
