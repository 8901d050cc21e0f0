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
from .figure import matplotlib_figure, save_png


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
    figure = matplotlib_figure((7.5, 5.5), 120, "the sweep plot")
    axis = figure.add_subplot()
    title = f"{record.get('method', '')}: {metric} over {len(runs)} runs"
    if len(axes) == 1:
        x = runs[axes[0]].to_numpy(dtype=float)
        order = np.argsort(x)
        axis.plot(x[order], values[order], marker="o", markersize=3)
        axis.set_xlabel(label(axes[0]))
        axis.set_ylabel(metric)
        _scale(axis.set_xscale, x, spacing.get(axes[0]))
        if np.all(values[np.isfinite(values)] > 0) and _spans(values, 2):
            axis.set_yscale("log")
    else:
        from matplotlib.colors import LogNorm

        finite = values[np.isfinite(values)]
        norm = LogNorm() if finite.size and np.all(finite > 0) and _spans(finite, 2) else None
        if record.get("spec", {}).get("mode") == "sample":
            # Scattered points, not a grid: each run a dot coloured by its metric.
            x = runs[axes[0]].to_numpy(dtype=float)
            y = runs[axes[1]].to_numpy(dtype=float)
            image = axis.scatter(x, y, c=values, s=12, norm=norm)
        else:
            frame = pd.DataFrame({"x": runs[axes[0]], "y": runs[axes[1]], "value": values})
            grid = frame.groupby(["y", "x"])["value"].mean().unstack("x")
            x = grid.columns.to_numpy(dtype=float)
            y = grid.index.to_numpy(dtype=float)
            image = axis.pcolormesh(x, y, grid.to_numpy(dtype=float), shading="nearest",
                                    norm=norm)
        figure.colorbar(image, ax=axis, label=metric)
        axis.set_xlabel(label(axes[0]))
        axis.set_ylabel(label(axes[1]))
        _scale(axis.set_xscale, x, spacing.get(axes[0]))
        _scale(axis.set_yscale, y, spacing.get(axes[1]))
        if len(axes) > 2:
            title += f" (mean over {', '.join(axes[2:])})"
    axis.set_title(title, fontsize=9)
    axis.grid(True, alpha=0.3)
    figure.tight_layout()
    return save_png(figure, target)


def _scale(set_scale, values: np.ndarray, spacing: str | None) -> None:
    """A log axis for an axis swept with log spacing, or for positive values over 2 decades."""
    if spacing == "log" or (np.all(values > 0) and _spans(values, 2)):
        set_scale("log")


def _spans(values: np.ndarray, decades: float) -> bool:
    finite = values[np.isfinite(values) & (values > 0)]
    return finite.size > 1 and np.log10(finite.max() / finite.min()) > decades
