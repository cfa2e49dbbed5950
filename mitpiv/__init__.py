"""mitpiv: physically based rendering testbed for volumetric particle image velocimetry.

Importing mitpiv selects a Mitsuba variant (``cuda_ad_mono`` if a CUDA device works, else
``llvm_ad_mono``; ``MITPIV_VARIANT`` overrides) and registers mitpiv's plugins. If no
variant can be used (e.g. LLVM < 16), the import warns and :func:`set_variant` raises the
error with its fix; the NumPy parts (``mitpiv.physics``, ``mitpiv.io``) still work.
"""

from __future__ import annotations

import warnings

from mitpiv.errors import BackendError, ConfigError, MitpivError, MitpivWarning

__version__ = "0.1.0"

__all__ = ["set_variant", "render_scene", "MitpivError", "ConfigError", "BackendError", "__version__"]


def set_variant(name: str | None = None) -> str:
    """Select the Mitsuba variant and register mitpiv's plugins; see :mod:`mitpiv.render.variant`."""
    from mitpiv.render.variant import set_variant as _set

    return _set(name)


def render_scene(scene, *, out_dir, frames=(0, 1), params=None, spp=None, seed=0, progress=True):
    """Render every sensor of ``scene`` for each frame to EXR + PNG; see :mod:`mitpiv.render.render`."""
    from mitpiv.render.render import render_scene as _render

    return _render(scene, out_dir=out_dir, frames=frames, params=params, spp=spp, seed=seed, progress=progress)


try:
    set_variant()
except MitpivError as _e:  # pragma: no cover - depends on the machine
    warnings.warn(f"mitpiv: no rendering backend: {_e}", MitpivWarning, stacklevel=2)
