"""The log-log figure of a time-step study (chaingen.studies.order): `chaingen order --plot`."""
from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np

from ..studies.order import OrderStudy, study_label
from .figure import matplotlib_figure, save_png


def plot_order(study: OrderStudy, path: str | os.PathLike) -> Path:
    """A log-log PNG of both error curves, the fitted lines over their ranges and O(dt^p)
    reference slopes. Needs matplotlib (Agg backend, no display)."""
    path = Path(path)
    figure = matplotlib_figure((7.0, 5.0), 100, "the order plot")
    axes = figure.add_subplot()
    curves = (("energy error [J]", "energy", study.energy_fit, "C0", "o"),
              ("trajectory error [rad]", "trajectory", study.trajectory_fit, "C1", "s"))
    for label, attribute, fit, colour, marker in curves:
        points = [(row.dt, getattr(row, f"{attribute}_error")) for row in study.rows
                  if not row.failed]
        points = [(dt, error) for dt, error in points if error > 0]
        if points:
            axes.loglog(*zip(*points), marker=marker, color=colour, linestyle="-",
                        linewidth=1, label=label)
        if fit.order is not None:
            ends = np.array([min(fit.dts), max(fit.dts)])
            axes.loglog(ends, fit.predict(ends), color=colour, linestyle="--", linewidth=2,
                        label=f"{attribute} fit: slope {fit.order:.2f}")
            # A reference slope with the nearest integer order, a little below the fit.
            order = max(1, round(fit.order))
            middle = math.sqrt(ends[0] * ends[1])
            level = 0.2 * float(fit.predict(middle))
            axes.loglog(ends, level * (ends / middle) ** order, color="grey", linestyle=":",
                        linewidth=1.5)
            axes.annotate(f"$O(\\Delta t^{{{order}}})$", (middle, level), color="grey",
                          fontsize=9, xytext=(4, -14), textcoords="offset points")
    energies = [row.energy_error for row in study.rows if not row.failed]
    if energies and min(energies) < 1e3 * study.energy_floor:   # only where it is in view
        axes.axhline(study.energy_floor, color="C0", linestyle=":", linewidth=1, alpha=0.6,
                     label="energy round-off floor")
    for dt in study.failed_dts:
        axes.axvline(dt, color="red", linestyle=":", linewidth=1)
    if study.failed_dts:
        axes.plot([], [], color="red", linestyle=":", label="Newton failed")
    axes.set_xlabel("dt [s]")
    axes.set_ylabel("average error")
    axes.set_title(f"{study.scene}: {study_label(study)}, t_end {study.t_end:g} s")
    axes.grid(True, which="both", alpha=0.3)
    axes.legend(fontsize=8, loc="best")
    figure.tight_layout()
    return save_png(figure, path)
