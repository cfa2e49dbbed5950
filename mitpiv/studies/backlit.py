"""Deprecated module (kept for one release): backlit plenoptic droplet tracking is the
experiment kind :mod:`mitpiv.studies.kinds.backlit`."""

from mitpiv.studies.kinds.backlit import STAGES, backlit_sensor

__all__ = ["STAGES", "backlit_sensor"]
