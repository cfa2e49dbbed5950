"""Loading mitpiv scenes: ``$frame``/``$param`` substitution, input checks, plugin binding.

A scene XML refers to per-frame particle files as ``particles_$frame.ply``; ``frame`` and
any ``-D name=value`` parameter are substituted by Mitsuba's own ``$name`` mechanism.
Before Mitsuba sees the file, every particle file the frame needs is checked (it exists and
is a valid mitpiv PLY), so a missing frame gives a clear :class:`ConfigError`.

Scenes are loaded with Mitsuba's parser optimisations off (``optimize=False``): its
``merge_equivalent`` pass merges plugin instances with identical properties *ignoring their
ids*, sensors included, so two cameras that differ only in id (the same view rendered twice
for independent noise) would become one object listed twice and the second camera would
never be rendered. After loading, sensor ids are checked to be unique
(:func:`check_sensor_ids`).
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET
from pathlib import Path

import mitsuba as mi
import numpy as np

from mitpiv.errors import ConfigError, FileFormatError, MitpivError
from mitpiv.io.particles import read_particles_ply
from mitpiv.render.variant import ensure_variant

__all__ = ["load_scene", "load_sensors", "load_rig", "load_dict", "bind_particle_shapes", "scene_defaults",
           "particle_files", "raise_plugin_error", "check_sensor_ids"]

#: Top-level scene elements :func:`load_sensors` leaves out (no sensor depends on them).
_NOT_SENSOR = ("shape", "emitter", "integrator", "medium", "texture")

_PARTICLE_SHAPES = ("ellipsoidsmesh", "ellipsoids")


def scene_defaults(xml_path) -> dict:
    """``<default name=... value=...>`` entries of a scene file."""
    root = _parse(xml_path)
    return {d.get("name"): d.get("value") for d in root.iter("default")}


def _parse(xml_path):
    try:
        return ET.parse(xml_path).getroot()
    except ET.ParseError as e:
        raise ConfigError(f"scene {str(xml_path)!r} is not valid XML: {e}.") from None


def _substitute(text: str, values: dict) -> str:
    return re.sub(r"\$(\w+)", lambda m: str(values.get(m.group(1), m.group(0))), text)


def particle_files(xml_path, values: dict) -> list[Path]:
    """Particle files (resolved paths) that a scene needs for the given parameter values."""
    xml_path = Path(xml_path)
    out = []
    for shape in _parse(xml_path).iter("shape"):
        if shape.get("type") not in _PARTICLE_SHAPES:
            continue
        for s in shape.findall("string"):
            if s.get("name") == "filename":
                p = Path(_substitute(s.get("value", ""), values))
                out.append(p if p.is_absolute() else xml_path.parent / p)
    return out


def bind_particle_shapes(scene) -> list:
    """Bind every ``tracer_particles`` emitter to its shape; return those emitters.

    Also checks that particle shapes have a black BSDF (the emitter already carries the
    scattered laser light; a reflective proxy would count it twice).
    """
    emitters = []
    for shape in scene.shapes():
        em = shape.emitter()
        if em is None or not hasattr(em, "bind_shape"):
            continue
        em.bind_shape(shape)
        bsdf = shape.bsdf()
        params = mi.traverse(bsdf)
        refl = [k for k in params.keys() if k.endswith("reflectance.value")]
        if bsdf.class_name() != "SmoothDiffuse" or any(np.any(np.array(params[k]) != 0) for k in refl) or not refl:
            raise ConfigError(
                f"particle shape {shape.id()!r}: its BSDF must be black, e.g. "
                f"<bsdf type=\"diffuse\"><rgb name=\"reflectance\" value=\"0\"/></bsdf>; the "
                f"tracer_particles emitter already carries the scattered light."
            )
        emitters.append(em)
    return emitters


def check_sensor_ids(scene, where: str = "scene") -> list[str]:
    """The ids of the scene's sensors (``sensor{i}`` for one without an id); raise
    :class:`ConfigError` when two sensors are one object or share an id, since each camera's
    images are named and seeded by its id."""
    return _distinct_ids(list(scene.sensors()), where)


def _distinct_ids(sensors: list, where: str) -> list[str]:
    ids = [s.id() or f"sensor{i}" for i, s in enumerate(sensors)]
    same = [i for i in range(len(sensors)) for j in range(i) if sensors[i] is sensors[j] or ids[i] == ids[j]]
    if same:
        raise ConfigError(
            f"{where}: sensors {ids} are not distinct (sensor {same[0]} repeats an earlier one); every "
            f"sensor needs its own id. If the scene was loaded with Mitsuba's optimize=True, identical "
            f"sensors were merged: load it with mitpiv.render.scene.load_scene / load_dict."
        )
    return ids


def raise_plugin_error(e: Exception, where: str):
    """Re-raise a Mitsuba loading error as the mitpiv error it wraps, else as ConfigError.

    Mitsuba turns exceptions raised in Python plugin constructors into ``RuntimeError``
    whose text holds the traceback; the original class and message are recovered from it.
    """
    import mitpiv.errors as errors

    msg = str(e)
    found = re.findall(r"^(?:mitpiv\.errors\.)?(ConfigError|FileFormatError|BackendError|MitpivError): (.*)$", msg, re.M)
    if found:
        name, text = found[-1]
        cls = getattr(errors, name, ConfigError)
        raise cls(f"{text} (in {where})") from None
    lines = msg.strip().splitlines()
    unused = [ln.strip(" -") for ln in lines[1:] if ln.strip().startswith("- $")]
    if "unused parameters" in lines[0] and unused:  # Mitsuba lists them on the following lines
        raise ConfigError(f"{where} failed to load: parameters {', '.join(unused)} are not used by the scene XML; "
                          f"remove their <default> (or the -D / [scene] params entry) or use them as $name.") from None
    raise ConfigError(f"{where} failed to load: {lines[0]}") from None


def load_dict(d: dict):
    """``mi.load_dict`` with mitpiv's error translation and particle binding (selects the
    default Mitsuba variant first if none is active, see :func:`ensure_variant`)."""
    ensure_variant()
    try:
        obj = mi.load_dict(d, optimize=False)  # no merging of identical sensors (module docstring)
    except Exception as e:
        raise_plugin_error(e, "scene dictionary")
    if isinstance(obj, mi.Scene):
        check_sensor_ids(obj, "scene dictionary")
        bind_particle_shapes(obj)
    return obj


def _check_proxy(ply: dict, path) -> None:
    """Warn when the proxy spheres are as large as the particle cloud: legal (images do not
    depend on the proxy radius) but every camera ray then hits some proxy, the render slows
    down and overlapping proxies hide one another."""
    pos = ply["positions_mm"]
    if len(pos) < 2:
        return
    extent = float(np.ptp(pos, axis=0).max())
    r = float(np.max(ply["proxy_radius_mm"]))
    if extent > 0 and r >= 0.5 * extent:
        import warnings

        from mitpiv.errors import MitpivWarning

        warnings.warn(f"{path}: proxy radius {r:.4g} mm is at least half the extent of the particle cloud "
                      f"({extent:.4g} mm): the proxy spheres overlap the whole volume. Choose a proxy radius below "
                      f"the pixel footprint in object space (write_particles_ply proxy_radius_mm, e.g. 0.01-0.05 mm).",
                      MitpivWarning, stacklevel=3)


def load_scene(xml_path, *, frame: int = 0, params: dict | None = None, search_dirs=()):
    """Load a scene XML for one frame and bind mitpiv's plugins.

    The first call selects the Mitsuba variant and registers mitpiv's plugins when no
    supported variant is active (:func:`~mitpiv.render.variant.ensure_variant`).

    Parameters
    ----------
    xml_path : path
        Scene file.
    frame : int
        Substituted for ``$frame``.
    params : dict, optional
        Further ``$name`` substitutions (values converted with ``str``).
    search_dirs : sequence of path
        Further folders in which relative file names of the scene (a sensor's
        ``calibration``) are looked up, after the scene file's own folder (which Mitsuba
        searches first).

    Returns
    -------
    mitsuba.Scene
    """
    ensure_variant()
    xml_path = Path(xml_path)
    if not xml_path.is_file():
        raise ConfigError(f"scene file {str(xml_path)!r} does not exist.")
    values = {**scene_defaults(xml_path), **{k: str(v) for k, v in (params or {}).items()}, "frame": str(int(frame))}
    for pf in particle_files(xml_path, values):
        if not pf.is_file():
            raise ConfigError(
                f"frame {frame}: particle file {str(pf)!r} does not exist. Generate the "
                f"particles for this frame (see the scene's README) or choose frames that exist."
            )
        try:
            ply = read_particles_ply(pf)
        except FileFormatError as e:
            raise ConfigError(f"frame {frame}: {e}") from None
        if len(ply["positions_mm"]) == 0:
            raise ConfigError(f"frame {frame}: particle file {str(pf)!r} holds no particles (element vertex 0); the "
                              f"renderer cannot load an empty particle set. Write at least one particle "
                              f"(write_particles_ply) or remove the particle shape from the scene.")
        _check_proxy(ply, pf)
    resolver = mi.file_resolver()
    extra = [str(Path(d).resolve()) for d in search_dirs]
    for d in reversed(extra):  # Mitsuba's load_file puts the scene's own folder before these
        resolver.prepend(d)
    try:
        scene = mi.load_file(str(xml_path), optimize=False, **values)  # no sensor merging (module docstring)
    except MitpivError:
        raise
    except Exception as e:  # Mitsuba wraps plugin errors in RuntimeError
        raise_plugin_error(e, f"scene {str(xml_path)!r} (frame {frame})")
    finally:
        for _ in extra:
            del resolver[0]
    check_sensor_ids(scene, f"scene {str(xml_path)!r}")
    bind_particle_shapes(scene)
    return scene


def load_sensors(xml_path, *, params: dict | None = None) -> dict:
    """The sensors of a scene file, loaded without its shapes, emitters or integrator.

    What a pre-flight check needs (where each camera looks, its sensor size) costs a
    fraction of a full :func:`load_scene`: no particle file is read, no Mie table built.
    The sensors are the same plugin objects a full load makes (same properties, same
    ``$name`` substitutions), so ``describe()`` and the camera models agree with a render.

    Parameters
    ----------
    xml_path : path
        Scene file. A file that includes other files (``<include>``) is loaded whole
        (:func:`load_scene` needs its particle files: this raises as it does when they are
        missing).
    params : dict, optional
        ``$name`` substitutions, as for :func:`load_scene` (values converted with ``str``).

    Returns
    -------
    dict
        ``{sensor id: mitsuba.Sensor}`` in the file's order (``sensor<i>`` for a sensor
        without an id).
    """
    return _load_stripped(xml_path, params, sheets=False)["sensors"]


def load_rig(xml_path, *, params: dict | None = None) -> dict:
    """The sensors and laser sheets of a scene file: :func:`load_sensors` that also keeps the
    top-level ``laser_sheet`` emitters (the plugin's own objects, so their defaults are the
    render's), for a picture of the rig or a check of the sheet against the cameras' focus.

    Other top-level emitters (a backlight, an environment map) are left out with the shapes:
    they may name textures and files that a rig does not need.

    Returns
    -------
    dict
        ``{"sensors": {sensor id: mitsuba.Sensor}, "sheets": {emitter id: LaserSheet}}``, in
        the file's order (``sensor<i>`` / ``sheet<i>`` for one without an id).
    """
    return _load_stripped(xml_path, params, sheets=True)


def _load_stripped(xml_path, params, *, sheets: bool) -> dict:
    """Load a scene file's sensors (and with ``sheets`` its top-level laser sheets) alone."""
    ensure_variant()
    xml_path = Path(xml_path)
    if not xml_path.is_file():
        raise ConfigError(f"scene file {str(xml_path)!r} does not exist.")
    root = _parse(xml_path)
    values = {**scene_defaults(xml_path), **{k: str(v) for k, v in (params or {}).items()}}
    if any(True for _ in root.iter("include")):
        scene = load_scene(xml_path, params=params)
    else:
        for el in list(root):
            keep = sheets and el.tag == "emitter" and el.get("type") == "laser_sheet"
            if (el.tag in _NOT_SENSOR and not keep) or el.tag == "default":
                root.remove(el)
        text = ET.tostring(root, encoding="unicode")
        used = set(re.findall(r"\$(\w+)", text))
        resolver = mi.file_resolver()
        resolver.prepend(str(xml_path.resolve().parent))  # relative paths resolve as for load_file
        try:
            scene = mi.load_string(text, optimize=False, **{k: v for k, v in values.items() if k in used})
        except MitpivError:
            raise
        except Exception as e:  # Mitsuba wraps plugin errors in RuntimeError
            raise_plugin_error(e, f"scene {str(xml_path)!r} (its {'rig' if sheets else 'sensors'})")
        finally:
            del resolver[0]
    sensors = scene.sensors()
    ids = _distinct_ids(list(sensors), f"scene {str(xml_path)!r}")
    out = {"sensors": dict(zip(ids, sensors, strict=True))}
    if sheets:
        found = [e for e in scene.emitters() if hasattr(e, "irradiance_numpy")]  # laser_sheet plugins
        out["sheets"] = {e.id() or f"sheet{i}": e for i, e in enumerate(found)}
    return out
