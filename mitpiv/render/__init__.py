"""The only package that imports Mitsuba: variants, plugins, scene loading, rendering."""

from mitpiv.render.variant import current_variant, set_variant

__all__ = ["set_variant", "current_variant"]
