"""Photometry: how much of a rendered image's light a real camera pixel collects.

A rendered pixel value ``V`` (docs/radiometry.md) is a radiance [W mm^-2 sr^-1] for a
``distorted_pinhole`` (averaged over the pixel footprint and, with a thin lens, the lens
pupil) and a sensor irradiance [W mm^-2] for a ``plenoptic`` camera. Neither depends on
how much light the camera's aperture lets through, so the power a real pixel receives is
the value times the pixel's *étendue* ``G`` (:func:`pixel_etendue`)::

    P = V G  [W]

- radiance cameras: ``G = A_pupil cos(alpha) Omega_pix`` [mm^2 sr], the lens pupil's area
  ``pi R^2`` (``R = f / 2N``, the radius the renderer samples) seen at the angle ``alpha``
  of the pixel's line of sight to the optical axis, times the pixel's solid angle
  ``Omega_pix = p^2 cos^3(alpha) / (f^2 |det J|)`` (``J`` the Jacobian of the
  Brown-Conrady distortion there). On the axis ``G = pi p^2 / 4N^2``; off the axis it
  falls as ``cos^4 alpha / |det J|`` (natural vignetting). For one particle of intensity
  ``I`` [W/sr] at distance ``r`` the collected power sums to ``I A_pupil cos(alpha) / r^2``,
  the intensity times the pupil's solid angle.
- irradiance cameras (``plenoptic``): ``G = p^2`` [mm^2], the pixel area; the main lens's
  aperture, the lenslets' fill and their crosstalk are in the rendered irradiance already.

A pinhole camera has no aperture: its photometric f-number is the thin lens's
``f_number``, else the diffraction PSF's ``psf_f_number``, else the
``photometric_f_number`` the scene states for it; a camera with none of them has no
étendue, and photometry that needs one refuses it with that fix.

The photons a pixel records are ``P t lambda / (h c)`` for an illumination time ``t`` (the
pulse duration of a pulsed laser, the exposure time of a continuous one) at the vacuum
wavelength ``lambda``, with ``V`` rendered at the sheet's real irradiance
(:func:`mitpiv.physics.sheet.peak_irradiance` from the pulse energy):
:func:`photons_per_watt`.

Written by hand: the étendue of a pixel of a distorted pinhole / thin-lens camera and of a
plenoptic camera as mitpiv renders them is specific to these camera models.
"""

from __future__ import annotations

import math

import numpy as np

from mitpiv.errors import ConfigError, check_positive

__all__ = ["photometric_f_number", "pixel_etendue", "axis_etendue", "photons_per_watt", "cameras_from_metadata",
           "wavelength_from_metadata", "PLANCK_J_S", "LIGHT_SPEED_M_S"]

#: Planck's constant [J s] and the speed of light [m/s] (exact, SI 2019).
PLANCK_J_S = 6.62607015e-34
LIGHT_SPEED_M_S = 299792458.0

_RADIANCE_CAMERAS = ("distorted_pinhole",)
_IRRADIANCE_CAMERAS = ("plenoptic",)

FIX = ("give the camera an aperture: 'f_number' (a thin lens), or, to keep the pinhole's infinite depth of field, "
       "'photometric_f_number' (<float name=\"photometric_f_number\" value=\"8\"/> in its distorted_pinhole; "
       "mitpiv sensor --photometric-f-number), or use photometry = 'image'")


def _camera(camera, where: str) -> dict:
    if not isinstance(camera, dict):
        raise ConfigError(f"{where}: a camera must be its image metadata's 'camera' record (a dict), "
                          f"got {type(camera).__name__}.")
    return camera


def photometric_f_number(camera: dict) -> float | None:
    """The f-number a radiance camera collects light through (None: a pinhole without one).

    ``camera`` is a camera record of the image metadata (``meta["camera"]``). A plenoptic
    camera's is its main lens's.
    """
    cam = _camera(camera, "photometric_f_number")
    for key in ("f_number", "photometric_f_number"):
        v = cam.get(key)
        if v is not None:
            return check_positive(key, v, owner=f"camera {cam.get('type', '?')}")
    psf = cam.get("psf")
    if isinstance(psf, dict) and psf.get("f_number") is not None:
        return check_positive("psf_f_number", psf["f_number"], owner=f"camera {cam.get('type', '?')}")
    return None


def axis_etendue(camera: dict) -> float | None:
    """Étendue of a pixel on the optical axis [mm^2 sr] (radiance cameras) or its area
    [mm^2] (irradiance cameras); None for a pinhole without a photometric f-number."""
    cam = _camera(camera, "axis_etendue")
    kind = cam.get("type")
    pitch_mm = check_positive("pixel_pitch_um", cam.get("pixel_pitch_um"), owner=f"camera {kind}") * 1e-3
    if kind in _IRRADIANCE_CAMERAS:
        return pitch_mm * pitch_mm
    if kind not in _RADIANCE_CAMERAS:
        return None
    n = photometric_f_number(cam)
    return None if n is None else math.pi * pitch_mm * pitch_mm / (4.0 * n * n)


def pixel_etendue(camera: dict, *, camera_id: str = "?") -> np.ndarray:
    """Étendue of every pixel of a camera, (H, W) float64: [mm^2 sr] for radiance cameras
    (``distorted_pinhole``: ``pi R^2 cos(alpha) Omega_pix``, see the module docstring),
    [mm^2] for irradiance cameras (``plenoptic``: the pixel area).

    Raises
    ------
    ConfigError
        When the camera states no aperture (a pinhole without ``f_number``,
        ``psf_f_number`` or ``photometric_f_number``) or is a camera type mitpiv cannot
        describe (a native Mitsuba sensor).
    """
    from mitpiv.physics.camera import PinholeCamera
    from mitpiv.physics.distortion import distort_jacobian, undistort

    cam = _camera(camera, "pixel_etendue")
    kind = cam.get("type")
    if kind not in _RADIANCE_CAMERAS + _IRRADIANCE_CAMERAS:
        raise ConfigError(f"photometry: camera {camera_id!r} is a {kind!r} sensor, whose aperture mitpiv does not know; "
                          f"render it with a distorted_pinhole or a plenoptic camera, or use photometry = 'image'.")
    w, h = (int(v) for v in cam["resolution"])
    g0 = axis_etendue(cam)
    if g0 is None:
        raise ConfigError(f"photometry: camera {camera_id!r} is a pinhole without an aperture, so the light it "
                          f"collects is not defined; {FIX}.")
    if kind in _IRRADIANCE_CAMERAS:
        return np.full((h, w), g0)
    pc = PinholeCamera.from_dict(cam)
    cx, cy = pc.principal_point_px
    fx = pc.focal_px
    u = (np.arange(w) + 0.5 - cx) / fx
    v = (np.arange(h) + 0.5 - cy) / fx
    xd, yd = np.meshgrid(u, v)
    x, y = undistort(xd, yd, pc.distortion, iterations=int(cam.get("newton_iterations") or 20))
    _, _, a, b, c, e = distort_jacobian(x, y, pc.distortion)
    cos2 = 1.0 / (1.0 + x * x + y * y)
    # pi R^2 cos(alpha) * p^2 cos^3(alpha) / (f^2 |det J|) = G_axis cos^4(alpha) / |det J|
    return g0 * cos2 * cos2 / np.abs(a * e - b * c)


def photons_per_watt(illumination_time_s: float, wavelength_nm: float) -> float:
    """Photons per watt of collected power lit for ``illumination_time_s`` [s] at the vacuum
    wavelength ``wavelength_nm`` [nm]: ``t lambda / (h c)``."""
    t = check_positive("illumination_time_s", illumination_time_s, owner="sensor", unit="s")
    lam = check_positive("wavelength_nm", wavelength_nm, owner="sensor", unit="nm") * 1e-9
    return t * lam / (PLANCK_J_S * LIGHT_SPEED_M_S)


def cameras_from_metadata(metas, *, photometric_f_number: float | None = None) -> dict:
    """Each camera's record from image metadata, for :func:`mitpiv.imaging.apply_sensor_set`.

    Parameters
    ----------
    metas : mapping {camera_id: metadata dict of one of its images}
    photometric_f_number : float, optional
        Given to every pinhole camera that states no aperture (``mitpiv sensor
        --photometric-f-number``).
    """
    out = {}
    for cid, meta in metas.items():
        cam = (meta or {}).get("camera")
        if not isinstance(cam, dict):
            raise ConfigError(f"photometry: the image of camera {cid!r} has no camera record in its metadata; render it "
                              f"with mitpiv (mitpiv render), or use photometry = 'image'.")
        if photometric_f_number is not None and cam.get("type") in _RADIANCE_CAMERAS and axis_etendue(cam) is None:
            cam = {**cam, "photometric_f_number": check_positive("photometric_f_number", photometric_f_number,
                                                                 owner="sensor")}
        out[cid] = cam
    return out


def wavelength_from_metadata(metas) -> float | None:
    """The one laser wavelength [nm] of a set of images' metadata (``illumination``), None
    when no image records one; refused when the images record different wavelengths."""
    waves = {float(e["wavelength_nm"]) for m in metas for e in ((m or {}).get("illumination") or [])
             if isinstance(e, dict) and e.get("wavelength_nm") is not None}
    if len(waves) > 1:
        raise ConfigError(f"photometry: the images record several laser wavelengths {sorted(waves)} nm; "
                          f"'illumination_time_s' converts one wavelength's power to photons. Expose each "
                          f"wavelength's images as their own set.")
    return waves.pop() if waves else None
