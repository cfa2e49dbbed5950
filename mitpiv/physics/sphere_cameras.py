"""Four cameras on a sphere placed by azimuth theta and elevation phi, symmetric in the four
quadrants, Scheimpflug-focused on the laser-sheet mid-plane, as in the channel-tomo paper
(Fig. 1, 13, 14, 18, 19, 22), and the ``distorted_pinhole`` sensor XML of a scene.

Angles are those of :func:`mitpiv.physics.camera.place_camera`: theta from the laser's
propagation direction in the sheet plane, phi from the sheet plane towards its normal. The
paper's configurations, by its figures:

- ``"top"`` (Fig. 14, "top view / bottom view"): all four on one side of the sheet, one per
  quadrant: (theta, phi), (-theta, phi), (180 - theta, phi), (180 + theta, phi).
- ``"forward"`` (Fig. 18): all facing the illumination source: (+-theta, +-phi).
- ``"backward"`` (Fig. 19): the mirror image about the plane normal to the laser:
  (180 -+ theta, +-phi).
- ``"symmetric"`` (Fig. 22, symmetric with respect to the sheet and the illumination
  direction): (theta, phi), (180 - theta, phi), (theta, -phi), (180 - theta, -phi); two in
  forward and two in backward scatter, two above and two below the sheet. The paper shows
  this only as a sketch: this reading is ours.
"""

from __future__ import annotations

import numpy as np

from mitpiv.errors import ConfigError, check_positive
from mitpiv.physics.camera import place_camera, scheimpflug

__all__ = ["CONFIGURATIONS", "quadrant_arrangement", "distorted_pinhole_sensors_xml"]

#: Camera configurations of :func:`quadrant_arrangement`.
CONFIGURATIONS = ("top", "forward", "backward", "symmetric")


def _angles(configuration: str, t: float, p: float):
    if configuration == "top":
        return [t, -t, 180 - t, 180 + t], [p, p, p, p]
    if configuration == "forward":
        return [t, -t, t, -t], [p, p, -p, -p]
    if configuration == "backward":
        return [180 - t, 180 + t, 180 - t, 180 + t], [p, p, -p, -p]
    if configuration == "symmetric":
        return [t, 180 - t, t, 180 - t], [p, p, -p, -p]
    raise ConfigError(f"quadrant_arrangement: configuration={configuration!r} is not one of {CONFIGURATIONS}.")


def quadrant_arrangement(configuration: str = "top", *, theta_deg: float, phi_deg: float, distance_mm: float,
                         focal_length_mm: float | None = None, target_mm=(0.0, 0.0, 0.0),
                         laser_direction=(1.0, 0.0, 0.0), sheet_normal=(0.0, 0.0, 1.0)) -> list[dict]:
    """Four camera poses on a sphere of radius ``distance_mm`` around ``target_mm``.

    Parameters
    ----------
    configuration : {"top", "forward", "backward", "symmetric"}
        See the module docstring.
    theta_deg, phi_deg : float
        Azimuth from the laser direction (0 < theta < 90) and elevation from the sheet
        (0 < phi < 90) [deg].
    distance_mm : float
        Sphere radius: lens centre to target [mm] (the paper: 5000 wall units).
    focal_length_mm : float, optional
        When given, each entry also carries the Scheimpflug focus on the sheet mid-plane
        (the plane through ``target_mm`` normal to ``sheet_normal``):
        :func:`mitpiv.physics.camera.scheimpflug`'s dict under ``"scheimpflug"``.

    Returns
    -------
    list of dict
        Per camera: ``azimuth_deg``, ``elevation_deg``, ``rotation`` (3, 3) world-to-camera,
        ``position_mm`` (3,), ``scattering_angle_deg`` (laser direction to the direction of
        the camera from the target) and optionally ``scheimpflug``.
    """
    t, p = float(theta_deg), float(phi_deg)
    if not (0 < t < 90) or not (0 < p < 90):
        raise ConfigError(f"quadrant_arrangement: theta_deg={theta_deg} and phi_deg={phi_deg} must lie in (0, 90) "
                          "(the other quadrants follow by symmetry).")
    check_positive("distance_mm", distance_mm, owner="quadrant_arrangement", unit="mm")
    az, el = _angles(configuration, t, p)
    e1 = np.asarray(laser_direction, float) / np.linalg.norm(laser_direction)
    target = np.asarray(target_mm, float)
    out = []
    for a, e in zip(az, el, strict=True):
        rot, pos = place_camera(target_mm=target, azimuth_deg=a, elevation_deg=e, distance_mm=distance_mm,
                                laser_direction=laser_direction, sheet_normal=sheet_normal)
        d = (pos - target) / np.linalg.norm(pos - target)
        entry = {"azimuth_deg": float(a), "elevation_deg": float(e), "rotation": rot, "position_mm": pos,
                 "scattering_angle_deg": float(np.degrees(np.arccos(np.clip(d @ e1, -1, 1))))}
        if focal_length_mm is not None:
            entry["scheimpflug"] = scheimpflug(rot, pos, focal_length_mm=focal_length_mm, plane_point_mm=target,
                                               plane_normal=sheet_normal)
        out.append(entry)
    return out


def _vec(v) -> str:
    return ", ".join(f"{float(x):.10g}" for x in v)


def distorted_pinhole_sensors_xml(cameras: list[dict], *, distance_mm: float, focal_length_mm: float,
                                  pixel_pitch_um: float, f_number: float | None = None, film_id: str = "film",
                                  target_mm=(0.0, 0.0, 0.0), laser_direction=(1.0, 0.0, 0.0),
                                  sheet_normal=(0.0, 0.0, 1.0), ids=None, extra_xml: str = "",
                                  indent: str = "    ") -> str:
    """``<sensor type="distorted_pinhole">`` elements (XML text) for cameras from
    :func:`quadrant_arrangement`: placed by ``azimuth_deg`` / ``elevation_deg`` /
    ``distance_mm`` around ``target``; with ``f_number``, a thin lens focused by
    Scheimpflug on the sheet mid-plane (``focus_distance_mm`` and ``focus_plane_normal``
    from each camera's ``scheimpflug`` entry, computed here when absent). ``extra_xml`` is
    inserted in every sensor (e.g. PSF properties); ``ids`` default ``cam0..cam3``.
    """
    check_positive("distance_mm", distance_mm, owner="distorted_pinhole_sensors_xml", unit="mm")
    check_positive("focal_length_mm", focal_length_mm, owner="distorted_pinhole_sensors_xml", unit="mm")
    check_positive("pixel_pitch_um", pixel_pitch_um, owner="distorted_pinhole_sensors_xml", unit="um")
    ids = ids or [f"cam{i}" for i in range(len(cameras))]
    if len(ids) != len(cameras):
        raise ConfigError(f"distorted_pinhole_sensors_xml: {len(ids)} ids for {len(cameras)} cameras.")
    i2 = indent * 2
    blocks = []
    for cid, cam in zip(ids, cameras, strict=True):
        lines = [f'{indent}<sensor type="distorted_pinhole" id="{cid}">',
                 f'{i2}<point name="target" value="{_vec(target_mm)}"/>',
                 f'{i2}<vector name="laser_direction" value="{_vec(laser_direction)}"/>',
                 f'{i2}<vector name="sheet_normal" value="{_vec(sheet_normal)}"/>',
                 f'{i2}<float name="azimuth_deg" value="{cam["azimuth_deg"]:.10g}"/>',
                 f'{i2}<float name="elevation_deg" value="{cam["elevation_deg"]:.10g}"/>',
                 f'{i2}<float name="distance_mm" value="{float(distance_mm):.10g}"/>',
                 f'{i2}<float name="focal_length_mm" value="{float(focal_length_mm):.10g}"/>',
                 f'{i2}<float name="pixel_pitch_um" value="{float(pixel_pitch_um):.10g}"/>']
        if f_number is not None:
            s = cam.get("scheimpflug") or scheimpflug(cam["rotation"], cam["position_mm"],
                                                      focal_length_mm=focal_length_mm, plane_point_mm=target_mm,
                                                      plane_normal=sheet_normal)
            lines += [f'{i2}<float name="f_number" value="{float(f_number):.10g}"/>',
                      f'{i2}<float name="focus_distance_mm" value="{s["focus_distance_mm"]:.10g}"/>',
                      f'{i2}<vector name="focus_plane_normal" value="{_vec(s["focus_plane_normal"])}"/>']
        if extra_xml:
            lines += [i2 + ln.strip() for ln in extra_xml.strip().splitlines()]
        lines += [f'{i2}<ref id="{film_id}"/>', f"{indent}</sensor>"]
        blocks.append("\n".join(lines))
    return "\n\n".join(blocks) + "\n"
