"""`chaingen plot`: joint angles, energy error and constraint error of trajectory files.

One file gives one figure of three panels sharing the time axis: the joint angles, the energy
error |H - H_0| (for an actuated or damped scene the balance error |H - H_0 - W + D|), and the
constraint error of the scheme's own coordinates (es: max_i |c_i|; vi: max_i ||q_i| - 1|;
midpoint has none). Several files overlay their error curves in one figure, as the thesis's
Figs. 5.3 and 5.5 compare schemes. The errors are drawn on a log scale where their positive
values span more than two decades, linearly otherwise.

Titles and legends name scene, scheme, K and dt from the trajectory's metadata file (written
by `simulate --out` beside it: FILE.csv.json); without one, dt is read off the time column and
the file name stands in for the rest.
"""
from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import PlotError
from ..runtime import contract
from ..runtime.files import check_output_file
from ..runtime.results import sample_joints, sample_slice
from ..runtime.trajectory import metadata_path, read_trajectory
from ..scene import ORDERS
from ..scene.labels import scheme_label
from .figure import LOG_AXIS_LIMITS, matplotlib_figure, save_png

#: Figure size in inches and resolution: 1500 x 1200 pixels.
FIGURE_SIZE = (10.0, 8.0)
DPI = 150
#: Errors whose positive values span more decades than this are drawn on a log scale.
LOG_DECADES = 2.0
#: The joint angles' column of the sample row, which names them in the legends.
ANGLE_COLUMN = contract.SAMPLE_COLUMNS[1].name


@dataclass(frozen=True)
class TrajectoryRun:
    """A trajectory file and what is known about the run that wrote it."""

    path: Path
    columns: tuple[str, ...]
    rows: np.ndarray
    n: int
    scene: str | None   # None: no metadata names it
    method: str | None
    quadrature: int | None
    dt: float | None
    order: int = 2        # of the step (metadata; 2 where it has none)
    #: What the energy column is: H, or H_d = T + V + V_s for a controlled package (the
    #: metadata's "energy" key, which only a run of one writes).
    storage: str = "H"
    #: The run-time parameters' values (metadata: path -> value), and those the label names.
    parameters: dict = dataclasses.field(default_factory=dict)
    named: tuple[str, ...] = ()
    #: What an overlay's legend names first to tell this run from another of the same label:
    #: its scene, or its file ("" where the label alone does).
    prefix: str = ""

    def column(self, name: str) -> np.ndarray:
        return self.rows[:, self.columns.index(name)]

    @property
    def t(self) -> np.ndarray:
        return self.column("t")

    @property
    def phi(self) -> np.ndarray:
        return self.rows[:, sample_slice(self.columns, ANGLE_COLUMN)]

    @property
    def balanced(self) -> bool:
        """True when the file carries the energy flows of an actuated or damped scene."""
        return all(name in self.columns for name in contract.FLOW_ENTRIES)

    @property
    def abs_balance_error(self) -> np.ndarray:
        """|e_B| = |H - H_0 - W + D| at every sample (model.md section 8; H_d for a
        controlled run); without energy flows in the file, |e_E| = |H - H_0|."""
        error = self.column("energy") - self.column("energy")[0]
        if self.balanced:
            work, dissipated = contract.FLOW_ENTRIES
            error = error - self.column(work) + self.column(dissipated)
        return np.abs(error)

    @property
    def constraint_error(self) -> np.ndarray:
        return np.abs(self.column("constraint_error"))

    def until(self, t_end: float) -> TrajectoryRun:
        """The samples up to t_end."""
        keep = self.t <= t_end * (1 + 1e-12)
        if keep.sum() < 1:
            raise PlotError(f"--t-end: {t_end:g} s is before the first sample of {self.path}")
        return dataclasses.replace(self, rows=self.rows[keep])

    @property
    def label(self) -> str:
        """'es K=3, dt = 0.01 s', as much of it as is known."""
        parts = [self.path.stem if self.method is None
                 else scheme_label(self.method, self.quadrature, self.order, style="short")]
        if self.dt is not None:
            parts.append(f"dt = {self.dt:g} s")
        parts += [f"{path} = {self.parameters[path]:g}" for path in self.named
                  if path in self.parameters]
        return ", ".join(parts)

    @property
    def legend(self) -> str:
        """The label, after the prefix that tells it from an overlay's other runs."""
        return f"{self.prefix}: {self.label}" if self.prefix else self.label


def named_parameters(runs: list[TrajectoryRun]) -> list[TrajectoryRun]:
    """`runs` labelled with the run-time parameters whose values differ between them (an
    overlay of runs of one solver with other masses, lengths, ...); where labels still
    coincide (two scenes with the same scheme and dt, or two files of one run), the legend
    names the scene, or else the file, of every run."""
    paths = sorted({path for run in runs for path in run.parameters})
    differing = tuple(path for path in paths
                      if len({run.parameters.get(path) for run in runs}) > 1)
    runs = [dataclasses.replace(run, named=differing) for run in runs]
    if len({run.label for run in runs}) == len(runs):
        return runs
    scenes = [run.scene or run.path.stem for run in runs]
    if len(set(zip(scenes, (run.label for run in runs)))) == len(runs):
        return [dataclasses.replace(run, prefix=scene) for run, scene in zip(runs, scenes)]
    return [dataclasses.replace(run, prefix=str(run.path)) for run in runs]


def load_run(path) -> TrajectoryRun:
    """Read a trajectory file (scene-format.md) and its metadata; PlotError names what is wrong."""
    path = Path(path)
    if not path.is_file():
        raise PlotError(f"{path}: no such trajectory file")
    try:
        columns, rows = read_trajectory(path)
    except (ValueError, UnicodeDecodeError) as error:
        raise PlotError(f"{path}: not a trajectory file (scene-format.md): {error}") from None
    n = sample_joints(columns)
    expected = list(contract.sample_column_names(n))
    if n == 0 or list(columns[:len(expected)]) != expected:
        wanted = ", ".join(expected) if n else ", ".join(
            column.name.format(i=1) + ".." + column.name.format(i="n") if column.per_joint
            else column.name for column in contract.SAMPLE_COLUMNS if not column.flows)
        raise PlotError(f"{path}: the header must start with the columns {wanted} "
                        f"(scene-format.md), got {', '.join(columns)}")
    if rows.shape[0] < 2:
        raise PlotError(f"{path}: needs at least two samples to plot, has {rows.shape[0]}")
    if not np.all(np.isfinite(rows)):
        bad = int(np.argwhere(~np.isfinite(rows))[0][0])
        raise PlotError(f"{path}: row {bad + 2} holds a value that is not finite")
    if not np.all(np.diff(rows[:, 0]) > 0):
        raise PlotError(f"{path}: the time column must increase from row to row")
    meta = read_metadata(path)
    dt = meta.get("dt")
    if dt is None:
        steps = np.diff(rows[:, 0])
        dt = float(np.median(steps)) if np.allclose(steps, steps[0], rtol=1e-9) else None
    quadrature = meta.get("quadrature")
    return TrajectoryRun(path=path, columns=tuple(columns), rows=rows, n=n,
                         scene=meta.get("scene"),
                         method=meta.get("method"),
                         quadrature=int(quadrature) if quadrature is not None else None,
                         dt=float(dt) if dt is not None else None,
                         order=meta.get("order", 2),
                         storage="H_d" if "energy" in meta else "H",
                         parameters={path: float(value)
                                     for path, value in meta.get("parameters", {}).items()})


def run_from_result(result, source) -> TrajectoryRun:
    """A TrajectoryRun of a SimulationResult in memory (source: what to call it)."""
    n = sample_joints(result.columns)
    return TrajectoryRun(path=Path(source), columns=tuple(result.columns),
                         rows=np.asarray(result.samples), n=n, scene=result.scene,
                         method=result.method, quadrature=result.quadrature,
                         dt=result.dt, order=result.order, storage=result.storage,
                         parameters=dict(result.parameters))


def plot_result(result, out: Path) -> Path:
    """`simulate --plot`: the figure of a run just made."""
    return plot_runs([run_from_result(result, out.with_suffix(".csv"))], out)


def check_png_path(path: Path, option: str) -> Path:
    if path.suffix.lower() != ".png":
        raise PlotError(f"{option}: {path}: give a .png file name")
    if not (path.parent if str(path.parent) else Path(".")).is_dir():
        raise PlotError(f"{option}: directory {path.parent} does not exist")
    return path


def _is_integer(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value) -> bool:
    return (isinstance(value, (int, float)) and not isinstance(value, bool)
            and math.isfinite(value))


#: The metadata keys the views read (docs/scene-format.md, section 12): (check, what it must be).
METADATA_KEYS = {
    "scene": (lambda v: isinstance(v, str), "a string"),
    "method": (lambda v: isinstance(v, str), "a string"),
    "quadrature": (lambda v: v is None or (_is_integer(v) and v >= 1), "an integer >= 1 or null"),
    "order": (lambda v: _is_integer(v) and v in ORDERS,
              "one of " + ", ".join(map(str, ORDERS))),
    "dt": (lambda v: _is_number(v) and v > 0, "a number > 0"),
    "every": (lambda v: _is_integer(v) and v >= 1, "an integer >= 1"),
    "n_steps": (lambda v: _is_integer(v) and v >= 0, "an integer >= 0"),
    "rtol": (lambda v: _is_number(v) and v >= 0, "a number >= 0"),
    "atol": (lambda v: _is_number(v) and v >= 0, "a number >= 0"),
    "energy": (lambda v: isinstance(v, str), "a string"),
    "parameters": (lambda v: isinstance(v, dict) and all(isinstance(path, str) and _is_number(value)
                                                         for path, value in v.items()),
                   "an object of numbers by key path"),
}


def read_metadata(path: Path) -> dict:
    """The metadata file beside a trajectory, {} when there is none; PlotError naming the file
    and the key when it is not a JSON object or a key the views read has the wrong type."""
    meta_file = metadata_path(path)
    try:
        text = meta_file.read_text()
    except FileNotFoundError:
        return {}
    except (OSError, UnicodeDecodeError) as error:
        raise PlotError(f"{meta_file}: cannot read the trajectory's metadata: "
                        f"{getattr(error, 'strerror', None) or error}") from None
    try:
        meta = json.loads(text)
    except ValueError as error:
        raise PlotError(f"{meta_file}: not JSON (scene-format.md, section 12): {error}") from None
    if not isinstance(meta, dict):
        raise PlotError(f"{meta_file}: must be a JSON object (scene-format.md, section 12), "
                        f"got {type(meta).__name__}")
    for key, (valid, wanted) in METADATA_KEYS.items():
        if key in meta and not valid(meta[key]):
            shown = json.dumps(meta[key])
            shown = shown if len(shown) <= 60 else shown[:57] + "..."
            raise PlotError(f"{meta_file}: key {key!r} must be {wanted}, got {shown}")
    return meta


def broken_at_wraps(angle: np.ndarray) -> np.ndarray:
    """The wrapped angle with NaN at the sample after each jump of more than pi (a wrap at
    +-pi), so that a plot line breaks there instead of striking across the panel."""
    shown = np.array(angle, dtype=float)
    shown[np.flatnonzero(np.abs(np.diff(shown)) > np.pi) + 1] = np.nan
    return shown


def _spans_decades(values: np.ndarray) -> bool:
    positive = values[values > 0]
    if positive.size < 2:
        return False
    # The logarithms' difference: the ratio of 1e300 to 1e-300 overflows.
    return math.log10(positive.max()) - math.log10(positive.min()) > LOG_DECADES


def _beyond_log_axis(values: np.ndarray) -> bool:
    """Positive values a log axis does not draw (figure.LOG_AXIS_LIMITS)."""
    positive = values[values > 0]
    return positive.size > 0 and (positive.min() < LOG_AXIS_LIMITS[0]
                                  or positive.max() > LOG_AXIS_LIMITS[1])


def _error_axis(axis, runs, values, ylabel: str, empty_note: str) -> None:
    drawn = False
    log = any(_spans_decades(v) for v in values)
    # Beyond a log axis's range (a constraint error from 1e-300 to 1e300): log10 of the
    # errors on a linear axis, labelled so (before: an empty panel on 1..10).
    log10 = log and any(_beyond_log_axis(v) for v in values)
    for run, value, style in zip(runs, values, _styles(len(runs))):
        if not np.any(value > 0):
            if len(runs) > 1:   # a legend entry still says why the run has no curve
                axis.plot([], [], label=f"{run.legend}: 0 at every sample", **style)
            continue
        shown = np.where(value > 0, value, np.nan) if log else value
        if log10:
            shown = np.log10(shown)
        axis.plot(run.t, shown, label=run.legend, **style)
        drawn = True
    if log10:
        ylabel = f"log10 {ylabel}"
    elif log:
        axis.set_yscale("log")
    if not drawn:
        axis.text(0.5, 0.5, empty_note, transform=axis.transAxes, ha="center", va="center",
                  color="0.4")
    axis.set_ylabel(ylabel)
    axis.grid(True, which="major", alpha=0.3)
    if drawn and len(runs) > 1:
        axis.legend(fontsize=8, loc="best")


def _styles(count: int) -> list[dict]:
    colours = ("C0", "C1", "C2", "C3", "C4", "C5", "C6", "C7", "C8", "C9")
    return [{"color": colours[i % len(colours)], "linewidth": 1.0} for i in range(count)]


def title_of(runs: list[TrajectoryRun]) -> str:
    names = [run.scene or run.path.stem for run in runs]
    scenes = ", ".join(sorted(set(names)))
    if len(runs) == 1:
        return f"{names[0]}: {runs[0].label}"
    dts = {run.dt for run in runs}
    if len(dts) == 1 and None not in dts:
        methods = list(dict.fromkeys(run.label.rsplit(", dt = ", 1)[0] for run in runs))
        return f"{scenes}: {' vs '.join(methods)}, dt = {dts.pop():g} s"
    return f"{scenes}: {len(runs)} runs compared"


#: The line styles of the first joints in an overlay; further joints get dash patterns of their
#: own (joint_line_style), so that no two joints of a run look alike.
LINE_STYLES = ("-", "--", ":", "-.")


def joint_line_style(joint: int):
    """The line style of joint `joint` (0-based) in an overlay, different for every joint:
    the four named styles, then dashes of 6 lengths followed by 1, 2, ... dots."""
    if joint < len(LINE_STYLES):
        return LINE_STYLES[joint]
    rank, length = divmod(joint - len(LINE_STYLES), 6)
    return (0, (2.0 + 1.5 * length, 1.5) + (1.0, 1.5) * (rank + 1))


def plot_runs(runs: list[TrajectoryRun], out: Path) -> Path:
    """Draw the figure of `runs` to the PNG file `out` (written atomically); returns it."""
    runs = named_parameters(runs) if len(runs) > 1 else runs
    figure = matplotlib_figure(FIGURE_SIZE, DPI, "chaingen plot")
    angles, energy, constraint = figure.subplots(3, 1, sharex=True)
    single = len(runs) == 1
    for run, style in zip(runs, _styles(len(runs))):
        for joint in range(run.n):
            angles.plot(run.t, broken_at_wraps(run.phi[:, joint]),
                        color=f"C{joint % 10}" if single else style["color"],
                        linestyle="-" if single else joint_line_style(joint), linewidth=1.0,
                        label=ANGLE_COLUMN.format(i=joint + 1) if single else None)
    if single:
        angles.legend(fontsize=8, loc="upper right", ncol=min(4, runs[0].n))
    else:
        from matplotlib.lines import Line2D
        handles = [Line2D([], [], **style, label=run.legend)
                   for run, style in zip(runs, _styles(len(runs)))]
        handles += [Line2D([], [], color="0.3", linestyle=joint_line_style(joint),
                           label=ANGLE_COLUMN.format(i=joint + 1))
                    for joint in range(max(run.n for run in runs))]
        angles.legend(handles=handles, fontsize=7, loc="upper right", ncol=2)
    angles.set_ylabel("joint angle phi_i [rad]")
    angles.grid(True, alpha=0.3)
    # Named as the run's summary names it: H, or a controlled run's H_d (both, overlaid: one
    # line each, as one line they ran past the panel's height into the panels beside it).
    balance = " - W + D" if any(run.balanced for run in runs) else ""
    energy_label = ",\n".join(f"|{storage} - {storage}0{balance}|" for storage in
                              sorted({run.storage for run in runs})) + " [J]"
    _error_axis(energy, runs, [run.abs_balance_error for run in runs], energy_label,
                "energy error 0 at every sample")
    _error_axis(constraint, runs, [run.constraint_error for run in runs],
                "constraint error", "no constraints (minimal coordinates): error 0")
    constraint.set_xlabel("t [s]")
    figure.suptitle(title_of(runs))
    figure.tight_layout()
    return save_png(figure, out)


def output_path(paths: list[Path], out: Path | None) -> Path:
    """Where `chaingen plot` writes: `out` when it names a .png file, else a file in the
    directory `out` (default: beside the first trajectory) named after the trajectories."""
    if out is not None and out.suffix.lower() == ".png":
        return check_png_path(out, "-o")
    directory = out if out is not None else (paths[0].parent if str(paths[0].parent) else Path("."))
    if directory.exists() and not directory.is_dir():
        raise PlotError(f"-o: {directory} is a file; give a directory or a .png file name")
    if not directory.exists():
        if not (directory.parent if str(directory.parent) else Path(".")).is_dir():
            raise PlotError(f"-o: directory {directory.parent} does not exist")
        directory.mkdir()
    name = "_vs_".join(path.stem for path in paths) if len(paths) > 1 else paths[0].stem
    if len(name) > 120:
        name = f"{paths[0].stem}_and_{len(paths) - 1}_more"
    return directory / f"{name}.png"


def plot_files(paths: list[Path], out: Path | None = None) -> Path:
    """`chaingen plot`: read, check and draw; returns the written PNG."""
    if not paths:
        raise PlotError("plot: give at least one trajectory file")
    runs = [load_run(path) for path in paths]
    target = output_path([Path(path) for path in paths], out)
    check_output_file(target, "-o", [*paths, *(metadata_path(path) for path in paths)])
    return plot_runs(runs, target)
