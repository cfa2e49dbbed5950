"""Experiment kinds: each declares its schema (one validated table per TOML table), its
stages, its summary (metrics.json) and its sweep-table row (a
:class:`~mitpiv.studies.shared.Kind`); :mod:`mitpiv.studies.runner` runs any of them.
``kind = "..."`` in an experiment file picks one (default ``"tomo"``).

A kind imports no other kind: what several need lives in :mod:`mitpiv.studies.shared`."""

from __future__ import annotations

from mitpiv.errors import ConfigError
from mitpiv.studies.shared import Kind

__all__ = ["KINDS", "get_kind"]


def _kinds() -> dict[str, Kind]:
    from mitpiv.studies.kinds import backlit, tomo, tracking

    return {k.name: k for k in (tomo.KIND, backlit.KIND, tracking.KIND)}


KINDS: tuple[str, ...] = ("tomo", "backlit", "tracking")


def get_kind(name, *, source: str = "experiment") -> Kind:
    """The experiment kind ``name`` (or one of its aliases)."""
    kinds = _kinds()
    for k in kinds.values():
        if name == k.name or name in k.aliases:
            return k
    lines = "; ".join(f'"{k.name}" ({k.describe})' for k in kinds.values())
    raise ConfigError(f"{source}: kind = {name!r} is not a known experiment kind; choose one of {lines}.")
