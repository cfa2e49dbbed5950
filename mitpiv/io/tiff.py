"""Integer TIFF images for other tools (the exports to OpenLPT and OpenPTV): the frames of
a rendered experiment, float32 EXR radiance or sensor counts, scaled to 8 or 16 bits.

Scaling (stated in each export's manifest): ``value = round(clip(image * gain, 0, 2**bits - 1))``
with one ``gain`` for every camera and frame of an export, by default
``(2**bits - 1) / max`` over all of them (the brightest pixel of the sequence maps to the
largest value, so intensities stay comparable across cameras and frames, as a tracker's
intensity threshold needs). TIFFs are written uncompressed, one grey channel, by OpenCV
(a kept library; ``cv2.imencode``), through :func:`mitpiv.io.atomic.atomic_path`.

Hand-written here: only the frame bookkeeping (images given as arrays or EXR paths, read
lazily so that a long sequence need not fit in memory) and the scaling rule above.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from mitpiv.errors import ConfigError
from mitpiv.io.atomic import atomic_path

__all__ = ["frame_stack", "load_frame", "intensity_gain", "quantise", "write_tiff", "BITS"]

#: Bit depths the exports write.
BITS = (8, 16)


def frame_stack(images, n_cameras: int, *, owner: str) -> list[list]:
    """Check ``images``, one sequence of frames per camera (each frame a 2-D array (H, W) or
    the path of an EXR file), and return it as a list of lists. Every camera must have the
    same number of frames (at least one)."""
    if isinstance(images, np.ndarray) and images.ndim in (3, 4):
        images = list(images)
    if not isinstance(images, Sequence) or isinstance(images, str | bytes) or len(images) == 0:
        raise ConfigError(f"{owner}: 'images' must hold one sequence of frames per camera ({n_cameras} cameras), "
                          f"got {type(images).__name__}; give e.g. a list of (n_frames, H, W) arrays.")
    stack = [list(cam) if not isinstance(cam, np.ndarray) or cam.ndim == 3 else [cam] for cam in images]
    if len(stack) != n_cameras:
        raise ConfigError(f"{owner}: 'images' holds frames of {len(stack)} cameras, 'cameras' has {n_cameras}; "
                          "give one sequence of frames per camera, in the cameras' order.")
    counts = {len(s) for s in stack}
    if len(counts) != 1 or 0 in counts:
        raise ConfigError(f"{owner}: every camera needs the same number of frames (at least 1); got "
                          f"{[len(s) for s in stack]} frames. An experiment without rendered images cannot be "
                          "exported: render it first ('mitpiv run').")
    for s in stack:
        for f in s:
            if isinstance(f, str | Path):
                if not Path(f).is_file():
                    raise ConfigError(f"{owner}: image file {str(f)!r} does not exist.")
            elif np.ndim(f) != 2:
                raise ConfigError(f"{owner}: each frame must be a 2-D image (H, W) or an EXR path, got an array "
                                  f"of shape {np.shape(f)}.")
    return stack


def load_frame(frame) -> np.ndarray:
    """One frame as a float64 (H, W) array: an array as it is, an EXR path read (first
    channel of a multi-channel image)."""
    if isinstance(frame, str | Path):
        from mitpiv.io.exr import read_exr

        img = read_exr(frame)[0]
        img = img if img.ndim == 2 else img[..., 0]
        return np.asarray(img, dtype=np.float64)
    return np.asarray(frame, dtype=np.float64)


def intensity_gain(stack, *, bits: int, owner: str) -> float:
    """The default gain ``(2**bits - 1) / max`` over every frame of every camera."""
    peak = 0.0
    for cam in stack:
        for f in cam:
            img = load_frame(f)
            if not np.all(np.isfinite(img)):
                raise ConfigError(f"{owner}: an image holds NaN or infinite values; re-render it.")
            peak = max(peak, float(img.max(initial=0.0)))
    if not peak > 0:
        raise ConfigError(f"{owner}: every image is black (maximum {peak:g}); nothing to export. Check the "
                          "render (particles in view, exposure).")
    return (2**bits - 1) / peak


def quantise(image, gain: float, bits: int) -> np.ndarray:
    """``round(clip(image * gain, 0, 2**bits - 1))`` as uint8 / uint16."""
    if bits not in BITS:
        raise ConfigError(f"quantise: 'bits' must be one of {BITS}, got {bits!r}.")
    top = 2**bits - 1
    v = np.clip(np.rint(np.asarray(image, dtype=np.float64) * gain), 0, top)
    return v.astype(np.uint8 if bits == 8 else np.uint16)


def write_tiff(path, image) -> Path:
    """Write a uint8 / uint16 (H, W) image as an uncompressed grey TIFF (atomic). The name
    need not end in .tif (OpenPTV's sequences name frames ``cam1.10001``)."""
    import cv2

    a = np.asarray(image)
    if a.ndim != 2 or a.dtype not in (np.uint8, np.uint16):
        raise ConfigError(f"write_tiff: the image must be a 2-D uint8 or uint16 array, got {a.dtype} {a.shape}.")
    ok, buf = cv2.imencode(".tif", a, [cv2.IMWRITE_TIFF_COMPRESSION, 1])
    if not ok:  # pragma: no cover - OpenCV encodes any 2-D uint8 / uint16 array
        raise ConfigError(f"write_tiff: OpenCV could not encode {str(path)!r}.")
    path = Path(path)
    with atomic_path(path, suffix=".tif") as tmp:
        tmp.write_bytes(buf.tobytes())
    return path
