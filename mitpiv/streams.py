"""Independent random streams of an experiment, derived from its one seed.

Every random draw of an experiment (the renderer's samples, the sensor noise, the
particle seeding, a calibration's noise, ...) takes its numbers from a stream of its own,
identified by a *purpose* string, a *camera* (sensor id) string and a *frame* index::

    SeedSequence(entropy=experiment_seed,
                 spawn_key=(purpose_hi, purpose_lo, camera_hi, camera_lo, frame))

where ``purpose_hi/lo`` and ``camera_hi/lo`` are the two 32-bit halves of a stable
64-bit hash of the UTF-8 string (BLAKE2b, 8 bytes; the same on every machine and Python
run, unlike :func:`hash`). The key has a fixed layout of five 32-bit words, so two
different (purpose, camera, frame) never share a key unless two of the strings collide
in 64 bits. Streams depend only on their own key: rendering a subset of the cameras, or
adding a camera, leaves every other camera's stream unchanged.

NumPy's :class:`~numpy.random.SeedSequence` hashes entropy and key into the generator's
state, so streams with different keys are statistically independent (O'Neill 2015;
NumPy's "parallel random number generation" notes).

Two forms of a stream:

* :func:`derived_seed` (``bits=64``) and :func:`generator`: a NumPy
  :class:`~numpy.random.Generator`; ``generator(seed, ...)`` is exactly
  ``np.random.default_rng(derived_seed(seed, ...))``, so the derived seed written into an
  image's metadata reproduces its stream on its own.
* :func:`derived_seed` with ``bits=32`` (:func:`render_seed`): the 32-bit seed that
  Mitsuba / Dr.Jit's ``mi.render(seed=...)`` takes.

Purposes used by mitpiv: ``"render"``, ``"sensor"``, ``"seeding"``, ``"calibration"``.
"""

from __future__ import annotations

import hashlib
import numbers

import numpy as np

from mitpiv.errors import ConfigError

__all__ = ["SEED_MAX", "check_seed", "spawn_key", "seed_sequence", "derived_seed", "generator",
           "render_seed", "sensor_seed"]

#: Experiment seeds are integers in ``[0, SEED_MAX)``: a TOML integer is a signed 64-bit one.
SEED_MAX = 2**63
_FRAME_MAX = 2**32


def check_seed(seed, *, name: str = "seed", upper: int = SEED_MAX) -> int:
    """Return ``seed`` as a Python int, or raise :class:`ConfigError` unless it is an integer
    in ``[0, upper)`` (booleans and floats, even integral ones, are rejected). ``upper`` is
    ``2**63`` for an experiment seed (a TOML integer), ``2**64`` for a derived seed."""
    bound = "2**63" if upper == SEED_MAX else ("2**64" if upper == 2**64 else str(upper))
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral):
        raise ConfigError(f"parameter '{name}' must be an integer in [0, {bound}), got {seed!r} "
                          f"({type(seed).__name__}). Give a whole number such as 0 or 1234.")
    s = int(seed)
    if not 0 <= s < upper:
        raise ConfigError(f"parameter '{name}' must be an integer in [0, {bound}), got {s}. "
                          f"Give a non-negative seed below {upper}.")
    return s


def _hash64(text: str, what: str) -> tuple[int, int]:
    if not isinstance(text, str):
        raise ConfigError(f"streams: '{what}' must be a string, got {text!r} ({type(text).__name__}).")
    h = int.from_bytes(hashlib.blake2b(text.encode("utf-8"), digest_size=8).digest(), "little")
    return h >> 32, h & 0xFFFFFFFF


def spawn_key(purpose: str, camera: str = "", frame: int = 0) -> tuple[int, int, int, int, int]:
    """The fixed-layout spawn key of stream (purpose, camera, frame): five 32-bit words.

    Parameters
    ----------
    purpose : str
        What the stream is for (``"render"``, ``"sensor"``, ``"seeding"``, ...); not empty.
    camera : str
        Sensor id (``""`` for a stream that belongs to no camera).
    frame : int
        Frame index in ``[0, 2**32)``.
    """
    if not isinstance(purpose, str) or not purpose:
        raise ConfigError(f"streams: 'purpose' must be a non-empty string such as 'sensor', got {purpose!r}.")
    if isinstance(frame, bool) or not isinstance(frame, numbers.Integral) or not 0 <= int(frame) < _FRAME_MAX:
        raise ConfigError(f"streams: 'frame' must be an integer in [0, 2**32), got {frame!r}.")
    return (*_hash64(purpose, "purpose"), *_hash64(camera, "camera"), int(frame))


def seed_sequence(seed, purpose: str, camera: str = "", frame: int = 0) -> np.random.SeedSequence:
    """``SeedSequence(seed, spawn_key=spawn_key(purpose, camera, frame))``; ``seed`` is
    checked by :func:`check_seed`."""
    return np.random.SeedSequence(check_seed(seed), spawn_key=spawn_key(purpose, camera, frame))


def derived_seed(seed, purpose: str, camera: str = "", frame: int = 0, *, bits: int = 64) -> int:
    """The seed of stream (purpose, camera, frame) of experiment ``seed``, as an unsigned
    ``bits``-bit integer (64: NumPy generators; 32: ``mi.render(seed=...)``)."""
    if bits not in (32, 64):
        raise ConfigError(f"derived_seed: 'bits' must be 32 or 64, got {bits!r}.")
    dtype = np.uint32 if bits == 32 else np.uint64
    return int(seed_sequence(seed, purpose, camera, frame).generate_state(1, dtype)[0])


def generator(seed, purpose: str, camera: str = "", frame: int = 0) -> np.random.Generator:
    """NumPy generator (PCG64) of stream (purpose, camera, frame) of experiment ``seed``:
    ``np.random.default_rng(derived_seed(seed, purpose, camera, frame))``."""
    return np.random.default_rng(derived_seed(seed, purpose, camera, frame))


def render_seed(seed, camera: str, frame: int) -> int:
    """32-bit seed for rendering ``camera`` at ``frame`` (``mi.render(seed=...)``)."""
    return derived_seed(seed, "render", camera, frame, bits=32)


def sensor_seed(seed, camera: str, frame: int) -> int:
    """64-bit seed of the sensor noise of ``camera`` at ``frame``; ``apply_sensor(image,
    model, seed=sensor_seed(...))`` reproduces that image's counts."""
    return derived_seed(seed, "sensor", camera, frame)
