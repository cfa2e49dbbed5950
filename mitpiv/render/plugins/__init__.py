"""mitpiv's Mitsuba plugins, one per module; each registers itself when imported.

:func:`register_all` imports them for the active variant, and reloads a module whose
classes were built for another variant (its base classes belong to that variant).
"""

from __future__ import annotations

import importlib
import sys

# _sensor first: the sensor plugins subclass its variant-specific base.
PLUGINS = ("_sensor", "laser_sheet", "mie_phase", "tracer_particles", "distorted_pinhole", "plenoptic", "particle_tracer")


def register_all() -> None:
    import mitsuba as mi

    for name in PLUGINS:
        full = f"{__name__}.{name}"
        mod = sys.modules.get(full)
        if mod is None:
            importlib.import_module(full)
        elif getattr(mod, "_VARIANT", None) != mi.variant():
            importlib.reload(mod)
