"""Figures without a display: matplotlib's Agg backend, PNGs written all or nothing.

matplotlib is an optional dependency (the extra `plot`); without it every view says so in one
line (a ChaingenError, exit status 2) instead of a traceback.
"""
from __future__ import annotations

from pathlib import Path

from ..errors import ChaingenError, install_hint
from ..runtime.files import reported_write, staged_file

INSTALL_HINT = install_hint("plot")

#: Matplotlib's log axes draw values within these bounds; beyond them (1e300 kg, 1e-300 N/m)
#: its tick locator overflows or the axis falls back to 1..10 and the figure is empty. The
#: figures draw such values as their log10 on a linear axis, labelled so.
LOG_AXIS_LIMITS = (1e-200, 1e200)


def require_matplotlib(what: str) -> None:
    """ChaingenError (exit status 2) unless matplotlib imports: checked before a command
    writes anything, so that a missing extra leaves no files behind."""
    try:
        import matplotlib  # noqa: F401
        from matplotlib.backends import backend_agg  # noqa: F401
    except ImportError:
        raise ChaingenError(f"{what} needs matplotlib, which is not installed "
                            f"({INSTALL_HINT})") from None


def matplotlib_figure(size: tuple[float, float], dpi: float, what: str):
    """A matplotlib Figure on an Agg canvas; `what` names the view for the missing-dependency
    message."""
    require_matplotlib(what)
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    figure = Figure(figsize=size, dpi=dpi)
    FigureCanvasAgg(figure)
    return figure


def save_png(figure, path: str | Path) -> Path:
    """Write `figure` as PNG to `path` all or nothing (a failed write: RunFailedError)."""
    path = Path(path)
    with reported_write(path, "the figure"), staged_file(path, suffix=".png") as temporary:
        figure.savefig(temporary, format="png")
    return path
