"""The camera of an image, from its metadata: one reader for every camera model.

A rendered EXR stores its camera under ``meta["camera"]`` (the sensor plugin's
``describe()``: the model's ``to_dict()`` plus a ``"type"`` naming the plugin).
:func:`camera_from_metadata` turns that entry back into the camera model, a
:class:`~mitpiv.physics.camera.PinholeCamera` or a
:class:`~mitpiv.physics.plenoptic.PlenopticCamera`; both satisfy the camera contract
(:class:`mitpiv.physics.camera.Camera`).
"""

from __future__ import annotations

from collections.abc import Mapping

from mitpiv.errors import ConfigError, FileFormatError
from mitpiv.physics.camera import PinholeCamera
from mitpiv.physics.plenoptic import PlenopticCamera

__all__ = ["camera_from_metadata", "CAMERA_MODELS"]

#: Camera models by the ``"model"`` key of their ``to_dict()``.
CAMERA_MODELS = {"pinhole_brown_conrady": PinholeCamera, "plenoptic_1.0_thin_lens": PlenopticCamera}
#: Sensor plugins (the ``"type"`` key of ``describe()``) and the model each writes.
_SENSOR_TYPES = {"distorted_pinhole": "pinhole_brown_conrady", "plenoptic": "plenoptic_1.0_thin_lens"}


def camera_from_metadata(meta: Mapping) -> PinholeCamera | PlenopticCamera:
    """Build the camera of an image from its metadata.

    Parameters
    ----------
    meta : dict
        An image's metadata (as :func:`mitpiv.io.read_exr` returns it) whose ``"camera"``
        entry describes the camera, or that entry itself (a sensor's ``describe()`` or a
        camera's ``to_dict()``).

    Returns
    -------
    PinholeCamera or PlenopticCamera
        The model named by the entry's ``"type"`` (``distorted_pinhole``, ``plenoptic``)
        or ``"model"`` (``pinhole_brown_conrady``, ``plenoptic_1.0_thin_lens``).

    Raises
    ------
    FileFormatError
        The metadata holds no usable camera: no ``"camera"`` entry, a sensor mitpiv does not
        model (Mitsuba's own ``perspective`` or ``thinlens`` store no camera model), or an
        entry with keys missing.
    ConfigError
        ``meta`` is not a dict, or the stored values are not a valid camera.
    """
    if not isinstance(meta, Mapping):
        raise ConfigError(f"camera_from_metadata: 'meta' must be an image's metadata dict, got {type(meta).__name__}.")
    cam = meta.get("camera", meta)
    if not isinstance(cam, Mapping):
        raise FileFormatError(
            f"camera_from_metadata: the metadata's 'camera' entry is a {type(cam).__name__}, not a camera "
            f"description (a dict)."
        )
    model = cam.get("model")
    kind = cam.get("type")
    if model is None and kind in _SENSOR_TYPES:
        model = _SENSOR_TYPES[kind]
    if model not in CAMERA_MODELS:
        if cam is meta and not ({"type", "model"} & set(meta)):
            what = f"no 'camera' entry (its keys: {sorted(meta)[:12]})"
        else:
            what = f"a camera of type {kind!r}" + ("" if model is None else f", model {model!r}")
        raise FileFormatError(
            f"camera_from_metadata: the metadata has {what}; mitpiv models the sensors "
            f"{sorted(_SENSOR_TYPES)} (models {sorted(CAMERA_MODELS)}). Render with a mitpiv sensor, or build "
            f"the camera yourself (PinholeCamera, PlenopticCamera) from a calibration."
        )
    cls = CAMERA_MODELS[model]
    try:
        return cls.from_dict(dict(cam))
    except KeyError as e:
        raise FileFormatError(
            f"camera_from_metadata: the {model!r} camera description lacks the key {e.args[0]!r}; it was not "
            f"written by {cls.__name__}.to_dict() (the metadata is incomplete or from another program)."
        ) from None
    except TypeError as e:
        raise FileFormatError(f"camera_from_metadata: the {model!r} camera description is malformed ({e}).") from None
