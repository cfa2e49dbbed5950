"""Planar calibration targets: dot grids and checkerboards, their marker coordinates and textures.

Target frame: x to the right and y up on the target's face, z its normal (towards the
cameras), origin at the pattern centre. Patterns are centred and symmetric, so marker
positions do not depend on how a renderer orients the texture. A pose places the target
in the world: ``p_world = centre + R_target @ p_target``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mitpiv.errors import ConfigError, check_positive

__all__ = ["CalibrationTarget", "target_rotation", "target_pose", "markers_world"]


@dataclass(frozen=True)
class CalibrationTarget:
    """A planar target.

    kind : "dots" (white dots on black) or "checkerboard".
    rows, cols : markers (dots) or inner corners (checkerboard: (rows + 1) x (cols + 1) squares).
    spacing_mm : marker pitch (dot spacing or square size).
    dot_diameter_mm : dot diameter (dots only; default 0.4 spacing).
    margin_mm : border around the pattern (default one spacing).
    """

    kind: str
    rows: int
    cols: int
    spacing_mm: float
    dot_diameter_mm: float | None = None
    margin_mm: float | None = None

    def __post_init__(self):
        if self.kind not in ("dots", "checkerboard"):
            raise ConfigError(f"target: parameter 'kind' must be 'dots' or 'checkerboard', got {self.kind!r}.")
        for name in ("rows", "cols"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 2:
                raise ConfigError(f"target: parameter '{name}' must be an integer >= 2, got {v!r}.")
        check_positive("spacing_mm", self.spacing_mm, owner="target", unit="mm")
        if self.kind == "dots":
            d = self.dot_diameter if self.dot_diameter_mm is None else self.dot_diameter_mm
            check_positive("dot_diameter_mm", d, owner="target", unit="mm")
            if d >= self.spacing_mm:
                raise ConfigError(f"target: dot_diameter_mm ({d}) must be smaller than spacing_mm ({self.spacing_mm}).")
        elif self.dot_diameter_mm is not None:
            raise ConfigError("target: 'dot_diameter_mm' applies to dot grids only.")

    @property
    def dot_diameter(self) -> float:
        return 0.4 * self.spacing_mm if self.dot_diameter_mm is None else self.dot_diameter_mm

    @property
    def margin(self) -> float:
        return self.spacing_mm if self.margin_mm is None else self.margin_mm

    @property
    def size_mm(self) -> tuple[float, float]:
        """(width, height) of the whole target."""
        if self.kind == "dots":
            return ((self.cols - 1) * self.spacing_mm + 2 * self.margin, (self.rows - 1) * self.spacing_mm + 2 * self.margin)
        return ((self.cols + 1) * self.spacing_mm + 2 * self.margin, (self.rows + 1) * self.spacing_mm + 2 * self.margin)

    def markers_local(self) -> np.ndarray:
        """(rows * cols, 3) marker positions in the target frame, row-major from the top-left."""
        x = (np.arange(self.cols) - (self.cols - 1) / 2) * self.spacing_mm
        y = ((self.rows - 1) / 2 - np.arange(self.rows)) * self.spacing_mm
        xx, yy = np.meshgrid(x, y)
        return np.column_stack([xx.ravel(), yy.ravel(), np.zeros(xx.size)])

    def texture(self, texel_mm: float | None = None, *, supersample: int = 4) -> np.ndarray:
        """Reflectance/radiance pattern in [0, 1], (rows, cols) of texels, row 0 at the top.

        Edges are antialiased by ``supersample^2`` samples per texel.
        """
        texel = (self.spacing_mm / 40 if self.kind == "checkerboard" else self.dot_diameter / 16) if texel_mm is None else texel_mm
        w, h = self.size_mm
        nx, ny = int(math.ceil(w / texel)), int(math.ceil(h / texel))
        if nx * ny > 64e6:
            raise ConfigError(f"target: texture of {nx}x{ny} texels is too large; give a larger texel_mm.")
        s = (np.arange(supersample) + 0.5) / supersample
        out = np.zeros((ny, nx))
        xs = (np.arange(nx) * w / nx) - w / 2
        ys = h / 2 - (np.arange(ny) * h / ny)
        for sy in s:  # supersample loop (a few passes over the whole texture, vectorised)
            for sx in s:
                x = xs[None, :] + sx * w / nx
                y = ys[:, None] - sy * h / ny
                out += self._pattern(x, y)
        return out / supersample**2

    def _pattern(self, x, y):
        sp = self.spacing_mm
        if self.kind == "dots":
            gx = np.clip(np.round(x / sp + (self.cols - 1) / 2), 0, self.cols - 1) - (self.cols - 1) / 2
            gy = np.clip(np.round(y / sp + (self.rows - 1) / 2), 0, self.rows - 1) - (self.rows - 1) / 2
            r = np.hypot(x - gx * sp, y - gy * sp)
            return (r <= self.dot_diameter / 2).astype(float)
        # Checkerboard: squares of side sp, corners at the marker positions; white margin.
        i = np.floor(x / sp + (self.cols + 1) / 2)
        j = np.floor(y / sp + (self.rows + 1) / 2)
        inside = (i >= 0) & (i <= self.cols) & (j >= 0) & (j <= self.rows)
        return np.where(inside, ((i + j) % 2 == 0).astype(float), 1.0)

    def to_dict(self) -> dict:
        return {"kind": self.kind, "rows": self.rows, "cols": self.cols, "spacing_mm": self.spacing_mm,
                "dot_diameter_mm": self.dot_diameter if self.kind == "dots" else None, "margin_mm": self.margin,
                "size_mm": list(self.size_mm)}


def target_rotation(tilt_x_deg: float = 0.0, tilt_y_deg: float = 0.0) -> np.ndarray:
    """Rotation of a target lying in the world x-y plane, tilted about x, then about y [deg]."""
    ax, ay = math.radians(tilt_x_deg), math.radians(tilt_y_deg)
    rx = np.array([[1, 0, 0], [0, math.cos(ax), -math.sin(ax)], [0, math.sin(ax), math.cos(ax)]])
    ry = np.array([[math.cos(ay), 0, math.sin(ay)], [0, 1, 0], [-math.sin(ay), 0, math.cos(ay)]])
    return ry @ rx


def target_pose(z_mm: float = 0.0, *, centre_xy_mm=(0.0, 0.0), tilt_x_deg: float = 0.0, tilt_y_deg: float = 0.0) -> np.ndarray:
    """4x4 target-to-world matrix: the target centred at (x, y, z_mm), tilted."""
    m = np.eye(4)
    m[:3, :3] = target_rotation(tilt_x_deg, tilt_y_deg)
    m[:3, 3] = [float(centre_xy_mm[0]), float(centre_xy_mm[1]), float(z_mm)]
    return m


def markers_world(target: CalibrationTarget, pose: np.ndarray) -> np.ndarray:
    """World coordinates [mm] of the target's markers at ``pose`` (4x4)."""
    pose = np.asarray(pose, dtype=float)
    return target.markers_local() @ pose[:3, :3].T + pose[:3, 3]
