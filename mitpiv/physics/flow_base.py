"""The base of every flow (:class:`Flow`): a callable ``u = flow(p_world_mm, t_s)`` in mm/s,
points (N, 3) [mm] in, velocities (N, 3) [mm/s] out, and ``to_dict`` for truth files.

The flows themselves and their registry (:data:`mitpiv.physics.flows.FLOW_KINDS`,
:func:`mitpiv.physics.flows.flow_from_dict`) are in :mod:`mitpiv.physics.flows`; flows kept in
modules of their own (:mod:`mitpiv.physics.jet`) derive from this class without importing
the registry, which imports them.
"""

from __future__ import annotations

import numpy as np

from mitpiv.errors import ConfigError

__all__ = ["Flow"]


class Flow:
    """Base class: subclasses implement ``velocity(p, t)``."""

    kind = "flow"

    def __call__(self, p_world_mm, t_s: float = 0.0) -> np.ndarray:
        p = np.asarray(p_world_mm, dtype=float)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ConfigError(f"flow: points must have shape (N, 3), got {p.shape}.")
        return self.velocity(p, float(t_s))

    def velocity(self, p: np.ndarray, t: float) -> np.ndarray:  # pragma: no cover - abstract
        raise NotImplementedError

    def to_dict(self) -> dict:
        d = {"kind": self.kind}
        for k, v in self.__dict__.items():
            if k.startswith("_"):
                continue
            d[k] = v.tolist() if isinstance(v, np.ndarray) else v
        return d
