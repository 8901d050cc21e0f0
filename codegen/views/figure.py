"""Figures without a display: matplotlib's Agg backend, PNGs written all or nothing.

matplotlib is an optional dependency (the extra `plot`); without it every view says so in one
line (a ChaingenError, exit status 2) instead of a traceback.
"""
from __future__ import annotations

from pathlib import Path

from ..errors import ChaingenError
from ..runtime.files import staged_file

INSTALL_HINT = "pip install 'chaingen[plot]'"


def matplotlib_figure(size: tuple[float, float], dpi: float, what: str):
    """A matplotlib Figure on an Agg canvas; `what` names the view for the missing-dependency
    message."""
    try:
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError:
        raise ChaingenError(f"{what} needs matplotlib, which is not installed "
                            f"({INSTALL_HINT})") from None
    figure = Figure(figsize=size, dpi=dpi)
    FigureCanvasAgg(figure)
    return figure


def save_png(figure, path: str | Path) -> Path:
    """Write `figure` as PNG to `path` all or nothing."""
    path = Path(path)
    with staged_file(path, suffix=".png") as temporary:
        figure.savefig(temporary, format="png")
    return path
