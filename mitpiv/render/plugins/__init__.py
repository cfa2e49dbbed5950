"""mitpiv's Mitsuba plugins, one per module; each registers itself when imported.

:func:`register_all` imports them for the active variant, and reloads a module whose
classes were built for another variant (its base classes belong to that variant).

A plugin module subclasses the active variant's classes when it is imported, so it needs a
variant: importing this package selects the default one
(:func:`mitpiv.render.variant.ensure_variant`) when no supported variant is active. Nothing
else in mitpiv imports this package before the first render.
"""

from __future__ import annotations

import importlib
import sys

# _endpoint first: the sensor and emitter plugins subclass its variant-specific bases.
PLUGINS = ("_endpoint", "laser_sheet", "mie_phase", "tracer_particles", "distorted_pinhole", "plenoptic", "particle_tracer")


def register_all() -> None:
    import mitsuba as mi

    for name in PLUGINS:
        full = f"{__name__}.{name}"
        mod = sys.modules.get(full)
        if mod is None:
            importlib.import_module(full)
        elif getattr(mod, "_VARIANT", None) != mi.variant():
            importlib.reload(mod)


def _need_variant() -> None:
    from mitpiv.render.variant import SUPPORTED, current_variant, ensure_variant

    if current_variant() not in SUPPORTED:
        ensure_variant()


_need_variant()
