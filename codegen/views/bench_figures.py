"""The benchmark's figures: work-precision per reference scene, and the scaling series.

`chaingen bench` hands this module to chaingen.studies.bench.run_bench (its `figures`), so
that the study depends on no view."""
from __future__ import annotations

from pathlib import Path

from ..studies.bench.config import (
    EARLY_T,
    HEADLINE_N,
    TARGET_BUILD_SECONDS,
    TARGET_EQUAL_ERROR,
    VARIANTS,
)
from ..studies.bench.runs import COMPILED_FAMILY, RunRow
from ..studies.bench.scaling import ScalingRow
from ..studies.bench.stiff import StiffStudy
from .figure import matplotlib_figure, save_png

MARKERS = "osD^vP*Xhp<>"
#: Colours of the compiled peers, apart from the ten of ours and the other peers (C0..C9).
COMPILED_COLOURS = ("black", "dimgrey", "saddlebrown", "darkcyan")


def _save(figure, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    return save_png(figure, path)


def _line_style(family: str, method_index: int, variant: str) -> dict:
    """Colour and marker per method; ours solid, MuJoCo dashed, SciPy dotted, the compiled
    peers dash-dot-dotted in colours of their own; a Newton variant other than the defaults
    dash-dotted with hollow markers."""
    style = {"color": f"C{method_index % 10}", "marker": MARKERS[method_index % len(MARKERS)],
             "linestyle": {"chaingen": "-", "MuJoCo": "--", "SciPy": ":",
                           COMPILED_FAMILY: (0, (3, 1, 1, 1, 1, 1))}[family],
             "linewidth": 1.2, "markersize": 5}
    if family == COMPILED_FAMILY:
        style["color"] = COMPILED_COLOURS[method_index % len(COMPILED_COLOURS)]
    if variant not in ("-", VARIANTS[0].label):
        style.update(linestyle="-.", markerfacecolor="none")
    return style


def plot_work_precision(name: str, rows: list[RunRow], path: Path) -> Path:
    """Two log-log panels: max energy error and the trajectory error at EARLY_T (the one that
    measures accuracy; see EARLY_T) against the CPU time of the whole run; one line per method
    and Newton variant."""
    figure = matplotlib_figure((13.0, 5.5), 100, "chaingen bench")
    panels = figure.subplots(1, 2)
    methods = list(dict.fromkeys(row.method for row in rows))
    curves = list(dict.fromkeys((row.method, row.variant, row.family) for row in rows))
    for axes, attribute, ylabel in ((panels[0], "energy_error", "max |H - H_0| [J]"),
                                    (panels[1], "early_trajectory_error",
                                     f"max |phi - phi_ref| at t = "
                                     f"{min(EARLY_T, rows[0].t_end):g} s [rad]")):
        for method, variant, family in curves:
            points = sorted((row.run_seconds, getattr(row, attribute)) for row in rows
                            if (row.method, row.variant) == (method, variant)
                            and not row.failure and getattr(row, attribute) is not None
                            and getattr(row, attribute) > 0)
            if points:
                label = method if variant in ("-", VARIANTS[0].label) else f"{method}, {variant}"
                axes.loglog(*zip(*points), label=label,
                            **_line_style(family, methods.index(method), variant))
        axes.set_xlabel("CPU time of the run [s]")
        axes.set_ylabel(ylabel)
        axes.grid(True, which="major", alpha=0.3)
    panels[0].axhline(TARGET_EQUAL_ERROR, color="grey", linewidth=0.8, linestyle="-.")
    panels[0].annotate(f"{TARGET_EQUAL_ERROR:.0e} J (headline c)", (0.01, TARGET_EQUAL_ERROR),
                       xycoords=("axes fraction", "data"), xytext=(0, 3),
                       textcoords="offset points", fontsize=7, color="grey")
    panels[1].legend(fontsize=7, loc="center left", bbox_to_anchor=(1.02, 0.5))
    figure.suptitle(f"{name}: work-precision, t_end = {rows[0].t_end:g} s (ours: solid, "
                    "MuJoCo: dashed, SciPy: dotted, compiled peers: dash-dot-dot)")
    figure.tight_layout()
    return _save(figure, path)


def plot_stiff_work_precision(study: StiffStudy, path: Path) -> Path:
    """The stiff chain: the trajectory error at t_end and the energy error relative to E_ref
    against the CPU time of the run; one line per method (ours solid, MuJoCo dashed, the
    compiled peers dash-dot-dotted)."""
    rows = study.rows
    figure = matplotlib_figure((13.0, 5.5), 100, "chaingen bench")
    panels = figure.subplots(1, 2)
    methods = list(dict.fromkeys(row.method for row in rows))
    curves = list(dict.fromkeys((row.method, row.family) for row in rows))
    for axes, attribute, ylabel in (
            (panels[0], "trajectory_error",
             f"max |phi - phi_ref| at t = {study.settings.t_end:g} s [rad]"),
            (panels[1], "relative_energy_error", "max |H - H_0| / E_ref")):
        for method, family in curves:
            points = sorted((row.run_seconds, getattr(row, attribute)) for row in rows
                            if row.method == method and not row.failure
                            and row.run_seconds is not None
                            and getattr(row, attribute) is not None
                            and getattr(row, attribute) > 0)
            if points:
                axes.loglog(*zip(*points), label=method,
                            **_line_style(family, methods.index(method), "-"))
        axes.set_xlabel("CPU time of the run [s]")
        axes.set_ylabel(ylabel)
        axes.grid(True, which="major", alpha=0.3)
    panels[1].legend(fontsize=7, loc="center left", bbox_to_anchor=(1.02, 0.5))
    figure.suptitle(f"{study.scene_name} (springs {study.settings.stiffness:g} N/m): "
                    f"work-precision, t_end = {study.settings.t_end:g} s (ours: solid, MuJoCo: "
                    "dashed, compiled peers: dash-dot-dot)")
    figure.tight_layout()
    return _save(figure, path)


def plot_scaling(rows: list[ScalingRow], path: Path) -> Path:
    """Per-step time against n (ours and MuJoCo RK4), and generate + build time against n."""
    from matplotlib.ticker import NullFormatter

    figure = matplotlib_figure((13.0, 5.0), 100, "chaingen bench")
    step_axes, build_axes = figure.subplots(1, 2)
    methods = list(dict.fromkeys(row.method for row in rows))
    mujoco = {}
    for method, variant in dict.fromkeys((row.method, row.variant) for row in rows):
        mine = [row for row in rows if (row.method, row.variant) == (method, variant)]
        style = _line_style("chaingen", methods.index(method), variant)
        label = method if variant == VARIANTS[0].label else f"{method}, {variant}"
        steps = [(row.n, row.step_seconds) for row in mine if row.step_seconds]
        if steps:
            step_axes.loglog(*zip(*steps), label=label, **style)
        builds = [(row.n, row.generate_and_build_seconds) for row in mine
                  if row.generate_and_build_seconds is not None]
        if builds and variant == VARIANTS[0].label:     # the same for every variant
            build_axes.loglog(*zip(*builds), label=method, **style)
        for row in mine:
            if row.mujoco_step_seconds:
                mujoco.setdefault(row.n, row.mujoco_step_seconds)
    if mujoco:
        step_axes.loglog(*zip(*sorted(mujoco.items())), marker="x", linestyle="--",
                         color="black", label="MuJoCo RK4")
    build_axes.axhline(TARGET_BUILD_SECONDS, color="grey", linewidth=0.8, linestyle="-.",
                       label=f"target at n = {HEADLINE_N}: {TARGET_BUILD_SECONDS:g} s")
    step_axes.set_ylabel("CPU time per step [s]")
    build_axes.set_ylabel("generate + build [s] (wall)")
    ns = sorted({row.n for row in rows})
    for axes in (step_axes, build_axes):
        axes.set_xlabel("links n")
        axes.set_xticks(ns, [str(n) for n in ns])
        axes.xaxis.set_minor_formatter(NullFormatter())
        axes.grid(True, which="major", alpha=0.3)
        axes.legend(fontsize=8)
    figure.suptitle("scaling series: scaling_scene(n), per step at dt = 0.01 s unless the table "
                    "says otherwise")
    figure.tight_layout()
    return _save(figure, path)

