"""Light-field geometry: refocus parameter <-> depth, depth of field, depth resolution.

Thin-lens conventions: ``f`` the main-lens focal length, ``|M|`` the magnification of the
focal plane onto the MLA, so the focal plane lies at ``s_o = f (1 + M) / M`` and the MLA
at ``s_i = f (1 + M)``. Depth ``z`` is measured from the focal plane along the optical
axis, positive away from the camera. A plane at ``s_o + z`` images at ``s_i'`` and
``alpha = s_i' / s_i`` (Ng 2005): ``alpha < 1`` beyond the focal plane.
"""

from __future__ import annotations

import numpy as np

from mitpiv.errors import ConfigError, check_positive
from mitpiv.physics.plenoptic import alpha_from_z_geom, depth_resolution_geom, dof_limits_geom

__all__ = ["alpha_from_z", "z_from_alpha", "depth_resolution", "depth_of_field", "focal_plane_distance"]


def focal_plane_distance(*, focal_length_mm: float, magnification: float) -> float:
    """Object distance ``s_o = f (1 + M) / M`` of the focal plane [mm]."""
    f = check_positive("focal_length_mm", focal_length_mm, owner="lightfield", unit="mm")
    m = check_positive("magnification", abs(magnification), owner="lightfield")
    return f * (1.0 + m) / m


def alpha_from_z(z_mm, *, focal_length_mm: float, magnification: float):
    """Refocus parameter ``alpha = s_i'/s_i`` of the plane ``z_mm`` beyond the focal plane.

    The formula is :func:`mitpiv.physics.plenoptic.alpha_from_z_geom` with the focal plane at
    :func:`focal_plane_distance`; a scalar ``z_mm`` gives a float.

    Parameters
    ----------
    z_mm : float or array
        Depth from the focal plane [mm], positive away from the camera.
    focal_length_mm : float
        Main-lens focal length.
    magnification : float
        Lateral magnification of the focal plane (its sign is ignored).
    """
    so = focal_plane_distance(focal_length_mm=focal_length_mm, magnification=magnification)
    out = alpha_from_z_geom(z_mm, float(focal_length_mm), so)
    return float(out) if out.ndim == 0 else out


def z_from_alpha(alpha, *, focal_length_mm: float, magnification: float):
    """Inverse of :func:`alpha_from_z`: depth [mm] of the plane refocused by ``alpha``."""
    so = focal_plane_distance(focal_length_mm=focal_length_mm, magnification=magnification)
    f = float(focal_length_mm)
    si = f * (1.0 + abs(magnification))
    a = np.asarray(alpha, dtype=float)
    if np.any(~np.isfinite(a)) or np.any(a * si <= f):
        raise ConfigError(
            f"z_from_alpha: alpha must exceed f / s_i = {f / si:.6g} (an image behind the focal point); got "
            f"min alpha = {np.nanmin(a):.6g}."
        )
    sip = a * si
    out = f * sip / (sip - f) - so
    return float(out) if out.ndim == 0 else out


def depth_of_field(*, focal_length_mm: float, magnification: float, f_number: float, mla_pitch_um: float,
                   angular_samples: float = 1.0) -> tuple[float, float]:
    """(near, far) depth-of-field limits [mm from the focal plane] of a refocused image
    (``angular_samples=1``: blur spot of one lenslet pitch on the MLA through the full
    aperture) or of a perspective view (``angular_samples = n_u``: through ``D / n_u``)."""
    f = check_positive("focal_length_mm", focal_length_mm, owner="depth_of_field", unit="mm")
    so = focal_plane_distance(focal_length_mm=f, magnification=magnification)
    d = f / check_positive("f_number", f_number, owner="depth_of_field")
    nu = check_positive("angular_samples", angular_samples, owner="depth_of_field")
    p = check_positive("mla_pitch_um", mla_pitch_um, owner="depth_of_field", unit="um") * 1e-3
    return dof_limits_geom(f, so, d / nu, p)


def depth_resolution(*, focal_length_mm: float, magnification: float, f_number: float, mla_pitch_um: float,
                     angular_samples: float) -> float:
    """Theoretical depth resolution of a plenoptic 1.0 camera at its focal plane [mm].

    The depth step that moves a point's image by one lenslet pitch ``p`` between the two
    outermost of the ``n_u`` angular samples, whose centres are ``D (n_u - 1) / n_u``
    apart on the aperture: ``dz = p s_i n_u / (D (n_u - 1) M^2)`` (Deem et al. 2016's
    geometric construction; ``M^2`` the longitudinal magnification). It tends to the
    depth of field of a refocused image for large ``n_u``.
    """
    f = check_positive("focal_length_mm", focal_length_mm, owner="depth_resolution", unit="mm")
    so = focal_plane_distance(focal_length_mm=f, magnification=magnification)
    d = f / check_positive("f_number", f_number, owner="depth_resolution")
    p = check_positive("mla_pitch_um", mla_pitch_um, owner="depth_resolution", unit="um") * 1e-3
    nu = check_positive("angular_samples", angular_samples, owner="depth_resolution")
    if nu < 2:
        raise ConfigError(f"depth_resolution: 'angular_samples' must be >= 2 for any depth information, got {nu}.")
    return depth_resolution_geom(f, so, d, p, nu)
