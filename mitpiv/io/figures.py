"""Figures on disk: a Matplotlib figure saved atomically (the format from the suffix)."""

from __future__ import annotations

from pathlib import Path

from mitpiv.errors import ConfigError
from mitpiv.io.atomic import atomic_path

__all__ = ["save_figure"]

_FORMATS = {".png": "png", ".pdf": "pdf", ".svg": "svg", ".jpg": "jpeg", ".jpeg": "jpeg"}


def save_figure(fig, path, *, dpi: float = 110, close: bool = True, **savefig_kw) -> Path:
    """Save a Matplotlib ``fig`` to ``path`` (atomic: a temporary file renamed over it).

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    path : str or Path
        ``.png``, ``.pdf``, ``.svg``, ``.jpg`` or ``.jpeg``.
    dpi : float
        Resolution of raster formats [dots per inch].
    close : bool
        Close the figure afterwards (also when saving fails), freeing its memory.
    savefig_kw
        Further keyword arguments of ``Figure.savefig`` (e.g. ``bbox_inches="tight"``).
    """
    path = Path(path)
    fmt = _FORMATS.get(path.suffix.lower())
    try:
        if fmt is None:
            raise ConfigError(f"save_figure: {str(path)!r} must end in one of {sorted(_FORMATS)}.")
        with atomic_path(path, suffix=path.suffix) as tmp:
            fig.savefig(tmp, dpi=dpi, format=fmt, **savefig_kw)
    finally:
        if close:
            import matplotlib.pyplot as plt

            plt.close(fig)
    return path
