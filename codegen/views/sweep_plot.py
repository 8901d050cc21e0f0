"""The figure of a sweep: a metric against one axis as curves, against two as a heat map.

A metric is a numeric column of runs.parquet (max_energy_error, newton_mean, phi2 at the end,
...) or the largest amplitude of a joint over the run, `amplitude_phi<i>` (from the
trajectories: max over t of |phi_i|). With one axis the runs are drawn as one curve; with two
or more, the first axis is the x axis and the second the y axis of a heat map (further axes are
averaged over, and the title says so).
"""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from ..errors import PlotError
from ..runtime.files import check_output_file
from ..studies.sweep.runs import metric_columns
from ..studies.sweep.store import (
    PARTS,
    RUNS,
    SPEC_FILE,
    TRAJECTORIES,
)
from .figure import LOG_AXIS_LIMITS, matplotlib_figure, save_png


def check_metric(metric: str, n: int, axes, trajectories: bool) -> None:
    """PlotError unless `metric` is a numeric column of runs.parquet (an axis too) or
    amplitude_phi<i> of a joint of the chain, with trajectories kept."""
    match = re.fullmatch(r"amplitude_phi(\d+)", metric)
    if match:
        if not 1 <= int(match.group(1)) <= n:
            raise PlotError(f"--metric {metric}: the chain has joints 1..{n}")
        if not trajectories:
            raise PlotError(f"--metric {metric}: needs the trajectories (a sweep with every > 0)")
        return
    columns = metric_columns(n) + tuple(axes)
    if metric not in columns:
        raise PlotError(f"--metric {metric}: not a metric of a sweep (one of "
                        f"{', '.join(columns)}, or amplitude_phi<i>)")


def _metric(out: Path, runs, name: str) -> np.ndarray:
    match = re.fullmatch(r"amplitude_phi(\d+)", name)
    if match:
        import xarray as xr

        data = xr.open_zarr(out / "trajectories.zarr", consolidated=False)
        amplitude = np.abs(data["phi"].sel(joint=int(match.group(1)))).max("t").values
        return amplitude[runs["run"].to_numpy()]
    return runs[name].to_numpy(dtype=float)


def sweep_inputs(out: Path, record: dict) -> list[Path]:
    """What a figure of the sweep in `out` must not overwrite: its record, table, parts and
    trajectories, and the spec and scene files the record names."""
    inputs = [out / name for name in (SPEC_FILE, RUNS, PARTS, TRAJECTORIES)]
    inputs += [Path(record[key]) for key in ("source", "scene")
               if isinstance(record.get(key), str) and record[key]]
    return inputs


def figure_path(out: Path, metric: str, path: str | Path | None) -> Path:
    """Where the figure of `metric` goes: `path` (a .png file, or else an existing directory
    to put <metric>.png in, as `chaingen plot -o` takes them), by default OUT/<metric>.png."""
    name = re.sub(r"[^\w.-]", "_", metric) + ".png"
    if path is None:
        return out / name
    path = Path(path)
    if path.suffix.lower() == ".png":
        return path
    if not path.is_dir() or path.is_symlink():
        raise PlotError(f"-o: {path}: give a .png file name or an existing directory")
    return path / name


def plot_sweep(out: str | Path, metric: str, path: str | Path | None = None) -> Path:
    """Draw `metric` of the sweep in `out` against its axes; PNG at `path` (default
    OUT/<metric>.png), checked like every output (check_output_file) before anything is
    read."""
    import pandas as pd

    out = Path(out)
    record_path = out / SPEC_FILE
    if not record_path.is_file() or not (out / RUNS).is_file():
        raise PlotError(f"{out}: not a completed sweep directory (no {SPEC_FILE} or "
                        f"{RUNS})")
    try:
        record = json.loads(record_path.read_text())
    except (OSError, ValueError) as error:
        raise PlotError(f"{record_path}: cannot read the sweep record: {error}") from None
    if not isinstance(record, dict) or not isinstance(record.get("axes"), list):
        raise PlotError(f"{record_path}: not a sweep record (no list of axes)")
    target = check_output_file(figure_path(out, metric, path), "-o" if path is not None
                               else "--plot", sweep_inputs(out, record))
    axes = record["axes"]
    spacing = record.get("spacing", {})
    units = record.get("units", {})

    def label(path: str) -> str:
        return f"{path} ({units[path]})" if path in units else path
    runs = pd.read_parquet(out / "runs.parquet")
    n = sum(1 for column in runs.columns if re.fullmatch(r"phi\d+", column))
    check_metric(metric, n, axes, (out / "trajectories.zarr").exists())
    values = _metric(out, runs, metric)
    title = f"{record.get('method', '')}: {metric} over {len(runs)} runs"
    # A failed run's metrics are those of the steps it completed (max_energy_error 0 for one
    # that failed at step 1): drawn among the others they would read as a result.
    failed = (runs["status"] != "ok").to_numpy() if "status" in runs.columns else None
    if failed is not None and failed.any() and metric not in axes:
        values = np.where(failed, np.nan, values)
        title += f", {int(failed.sum())} failed (not drawn)"
    figure = matplotlib_figure((7.5, 5.5), 120, "the sweep plot")
    axis = figure.add_subplot()
    if len(axes) == 1:
        x, x_label = _logged(runs[axes[0]].to_numpy(dtype=float), label(axes[0]),
                             axis.set_xscale, spacing.get(axes[0]) == "log")
        values, metric_label = _logged(values, metric, axis.set_yscale, False)
        order = np.argsort(x)
        axis.plot(x[order], values[order], marker="o", markersize=3)
        axis.set_xlabel(x_label)
        axis.set_ylabel(metric_label)
    else:
        from matplotlib.colors import LogNorm

        values, metric_label = _logged(values, metric, None, False)
        finite = values[np.isfinite(values)]
        norm = (LogNorm() if metric_label == metric and finite.size and np.all(finite > 0)
                and _spans(finite, 2) else None)     # log10 values themselves: linear
        if record.get("spec", {}).get("mode") == "sample":
            # Scattered points, not a grid: each run a dot coloured by its metric.
            x = runs[axes[0]].to_numpy(dtype=float)
            y = runs[axes[1]].to_numpy(dtype=float)
        else:
            frame = pd.DataFrame({"x": runs[axes[0]], "y": runs[axes[1]], "value": values})
            grid = frame.groupby(["y", "x"])["value"].mean().unstack("x")
            x = grid.columns.to_numpy(dtype=float)
            y = grid.index.to_numpy(dtype=float)
        x, x_label = _logged(x, label(axes[0]), axis.set_xscale, spacing.get(axes[0]) == "log")
        y, y_label = _logged(y, label(axes[1]), axis.set_yscale, spacing.get(axes[1]) == "log")
        if record.get("spec", {}).get("mode") == "sample":
            image = axis.scatter(x, y, c=values, s=12, norm=norm)
        else:
            image = axis.pcolormesh(x, y, grid.to_numpy(dtype=float), shading="nearest",
                                    norm=norm)
        figure.colorbar(image, ax=axis, label=metric_label)
        axis.set_xlabel(x_label)
        axis.set_ylabel(y_label)
        if len(axes) > 2:
            title += f" (mean over {', '.join(axes[2:])})"
    axis.set_title(title, fontsize=9)
    axis.grid(True, alpha=0.3)
    figure.tight_layout()
    return save_png(figure, target)


def _logged(values: np.ndarray, label: str, set_scale, log_spacing: bool):
    """(values, label) as drawn: on a log axis (set_scale("log"); None for a colour bar) for an
    axis swept with log spacing or positive values over 2 decades, and as log10 of the values
    on a linear axis, labelled so, where they reach beyond LOG_AXIS_LIMITS."""
    finite = values[np.isfinite(values)]
    if not (finite.size and np.all(finite > 0) and (log_spacing or _spans(finite, 2))):
        return values, label
    if finite.min() < LOG_AXIS_LIMITS[0] or finite.max() > LOG_AXIS_LIMITS[1]:
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.log10(values), f"log10 {label}"
    if set_scale is not None:
        set_scale("log")
    return values, label


def _spans(values: np.ndarray, decades: float) -> bool:
    finite = values[np.isfinite(values) & (values > 0)]
    # The logarithms' difference: the ratio of 1e300 to 1e-300 overflows.
    return finite.size > 1 and np.log10(finite.max()) - np.log10(finite.min()) > decades
