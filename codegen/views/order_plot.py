"""The log-log figure of time-step studies (chaingen.studies.order): `chaingen order --plot`.

One figure, three panels: the angle (trajectory), rate and energy (or balance) error against
dt, one line per order option with its fitted slope in the legend.
"""
from __future__ import annotations

import os
from pathlib import Path

from ..scene.labels import scheme_label
from ..studies.order import OrderStudy
from .figure import matplotlib_figure, save_png

#: The panels: title, y label, OrderRow attribute, fit and floor attributes of OrderStudy.
_PANELS = (
    ("angles", "trajectory error [rad]", "trajectory_error", "trajectory_fit",
     "trajectory_floor"),
    ("rates", "rate error [rad/s]", "rate_error", "rate_fit", "rate_floor"),
    ("energy", "energy error [J]", "mean_balance_error", "energy_fit", "energy_floor"),
)
_MARKERS = {2: "o", 4: "s", 6: "^"}


def plot_order(studies: OrderStudy | tuple[OrderStudy, ...] | list[OrderStudy],
               path: str | os.PathLike) -> Path:
    """A PNG of the studies of one scene and scheme (one per order option): each panel shows
    one error curve per order on log-log axes, its fitted line dashed over the fitted range,
    the slope in the legend, and the round-off floor where a curve comes near it. Needs
    matplotlib (Agg backend, no display)."""
    studies = (studies,) if isinstance(studies, OrderStudy) else tuple(studies)
    if not studies:
        raise ValueError("plot_order: no studies")
    path = Path(path)
    figure = matplotlib_figure((13.0, 4.6), 100, "the order plot")
    first = studies[0]
    energy = first.energy_name
    for column, (title, ylabel, attribute, fit_name, floor_name) in enumerate(_PANELS):
        axes = figure.add_subplot(1, len(_PANELS), column + 1)
        if attribute == "mean_balance_error":
            title, ylabel = energy, f"{energy} error [J]"
        lowest = []
        for index, study in enumerate(studies):
            colour = f"C{index}"
            fit = getattr(study, fit_name)
            points = [(row.dt, getattr(row, attribute)) for row in study.rows
                      if not row.failed and getattr(row, attribute) is not None]
            points = [(dt, error) for dt, error in points if error > 0]
            slope = f"slope {fit.order:.2f}" if fit.order is not None else "no fit"
            if points:
                axes.loglog(*zip(*points), marker=_MARKERS.get(study.order, "o"), color=colour,
                            linestyle="-", linewidth=1, label=f"order {study.order}: {slope}")
                lowest.append(min(error for _, error in points))
            if fit.order is not None:
                ends = [min(fit.dts), max(fit.dts)]
                axes.loglog(ends, fit.predict(ends), color=colour, linestyle="--",
                            linewidth=2.5, alpha=0.5)
            for dt in study.failed_dts:
                axes.axvline(dt, color=colour, linestyle=":", linewidth=1)
        floor = max(getattr(study, floor_name) for study in studies)
        if lowest and min(lowest) < 1e3 * floor:      # only where it is in view
            axes.axhline(floor, color="grey", linestyle=":", linewidth=1,
                         label="round-off floor")
        if any(study.failed_dts for study in studies):
            axes.plot([], [], color="grey", linestyle=":", label="dt where Newton failed")
        axes.set_title(title)
        axes.set_xlabel("dt [s]")
        axes.set_ylabel(f"average {ylabel}")
        axes.grid(True, which="both", alpha=0.3)
        axes.legend(fontsize=8, loc="best")
    label = scheme_label(first.method, first.quadrature)
    figure.suptitle(f"{first.scene}: {label}, t_end {first.t_end:g} s (dashed: the fitted ranges)")
    figure.tight_layout()
    return save_png(figure, path)
