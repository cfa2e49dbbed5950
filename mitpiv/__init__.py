"""mitpiv: physically based rendering testbed for volumetric particle image velocimetry.

Importing mitpiv selects no Mitsuba variant and imports neither Mitsuba nor Dr.Jit. The
first render (any function that builds a Mitsuba scene with mitpiv's plugins) selects one
through :func:`mitpiv.render.variant.ensure_variant`: ``cuda_ad_mono`` if a CUDA device
works, else ``llvm_ad_mono``; ``MITPIV_VARIANT`` overrides; :func:`set_variant` chooses
explicitly. The NumPy parts (``mitpiv.physics``, ``mitpiv.io``, reconstruction, analysis)
work without a rendering backend.

Library code does not print: messages go to :mod:`logging` under the ``mitpiv`` logger
(silent unless the application configures logging), progress through the ``progress=``
argument (see :mod:`mitpiv.progress`).
"""

from __future__ import annotations

import logging

from mitpiv.errors import BackendError, ConfigError, MitpivError, MitpivWarning
from mitpiv.version import __version__

__all__ = ["set_variant", "render_scene", "MitpivError", "ConfigError", "BackendError", "MitpivWarning", "__version__"]

logging.getLogger(__name__).addHandler(logging.NullHandler())

# Subpackages load on first use (``mitpiv.io.read_exr`` after a bare ``import mitpiv``),
# so that importing mitpiv stays cheap and imports no renderer.
_SUBPACKAGES = ("analysis", "holography", "imaging", "io", "lightfield", "physics", "progress", "reconstruct",
                "render", "studies")


def __getattr__(name: str):
    if name in _SUBPACKAGES:
        import importlib

        return importlib.import_module(f"{__name__}.{name}")
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def set_variant(name: str | None = None) -> str:
    """Select the Mitsuba variant and register mitpiv's plugins; see :mod:`mitpiv.render.variant`."""
    from mitpiv.render.variant import set_variant as _set

    return _set(name)


def render_scene(scene, *, out_dir, frames=(0, 1), params=None, spp=None, seed=0, progress=None, sensors=None):
    """Render every sensor of ``scene`` for each frame to EXR + PNG; see :mod:`mitpiv.render.render`."""
    from mitpiv.render.variant import ensure_variant

    ensure_variant()
    from mitpiv.render.render import render_scene as _render

    return _render(scene, out_dir=out_dir, frames=frames, params=params, spp=spp, seed=seed, progress=progress,
                   sensors=sensors)
