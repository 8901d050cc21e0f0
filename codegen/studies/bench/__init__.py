"""`chaingen bench`: our schemes against MuJoCo and SciPy, speed and accuracy, in one run.

    chaingen bench [--quick] [--out FILE.md] [--figures DIR] [--dts 0.04,0.02,...]
                   [--scaling-n 2,3,5,10,20] [--skip-scaling] [--skip-reference]
                   [--skip-sweep] [--skip-stiff] [--stiff-only] [--uneven-only]
                   [--spatial-only] [--timeout SECONDS]

Four parts, all measured side by side on one machine in one process (the scaling series in
child processes, so that a size that takes too long can be stopped):

1. Reference scenes (scenes/three_link_*.toml, the scene's own run: 50 s from its initial
   state). Every scheme at a dt series, MuJoCo (Euler, implicitfast, RK4) at its own dt series,
   SciPy's solve_ivp (DOP853, Radau) and the compiled peers (numbalsoda LSODA and DOP853,
   CVODES BDF and Adams) at a tolerance series. For each run: CPU time per step
   and of the whole run, t_realtime, max |H - H_0|, max constraint error, the trajectory error
   at t_end against a tight DOP853 reference (codegen.scipy_peer.reference_solution), and for
   ours the Newton iterations per step and the step's cost in residual-and-Jacobian
   evaluations.
2. A scaling series: `scaling_scene(n)` for n = 2 ... 100; generate and build seconds, peak
   memory, model C size, per-step time, and MuJoCo RK4's per-step time at the same n; es also
   on `uneven_scene(n)` (uneven links, COMs off the axis). `--uneven-only` runs es on both
   chains alone and writes the uneven chain's subsection into an existing report in place.
3. Headline ratios with the issue's targets, computed from parts 1 and 2.
4. Studies: run-time parameters against constants compiled in, and a sweep of many runs on
   this machine's cores and on Dask against a loop of single runs (the studies module).
5. Control loops: a controller in a Python loop over `Solver.stepper` against MuJoCo's
   Python loop, and one in C closing simulate's loop against the open loop; and the embedded
   controller's call, `control_torques` on four_link_pbc, against `step` and the open-loop
   `simulate` per call (the control module).
6. The stiff chain's work-precision: a 10-link chain with springs of 2e4 N/m over 0.2 s, ours
   (es with both gradients, adaptive es, vi, midpoint, orders 2 and 4) against the compiled
   peers and MuJoCo, CPU against the trajectory error and against the energy error (the
   stiff module). `--stiff-only` runs it alone and writes its section into an existing
   report in place.
7. The spatial arm (issue 33 d): scenes/panda_springs.toml at dt = 1e-3 s, each spatial scheme's
   step in the C loop against MuJoCo RK4 and Pinocchio's ABA with RK4, round by round, and
   each scheme's generate and build seconds with and without sensitivities (the spatial
   module). Only `--spatial-only` runs it, alone, and writes its section into an existing
   report in place.

The parts live in their own modules: config (what runs), runs (part 1), scaling (part 2),
headlines (part 3), knobs (the speed knobs), harness (the C timing program), report and figures.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

from ...progress import Progress
from ...runtime.files import write_text
from ...scene import METHODS, load_reference_scene
from . import knobs
from .accuracy import reference_study
from .config import (
    HEADLINE_DT,
    HEADLINE_SCENE,
    REPORT_TITLE,
    STIFF_FIGURE,
    BenchConfig,
    bench_config,
)
from .control import control_call_study, control_call_table, control_study, control_table
from .headlines import headlines
from .report import (
    headline_table,
    machine_description,
    markdown,
    reference_table,
    replace_stiff_section,
    replace_uneven_section,
    scaling_table,
    stiff_section,
    stiff_summary_table,
    stiff_table,
    uneven_comparison_table,
    uneven_section,
)
from .scaling import scaling_study
from .scenes import scaling_scene
from .spatial import (
    build_table,
    pinocchio_version,
    replace_spatial_section,
    spatial_section,
    spatial_section_of,
    spatial_study,
    step_table,
)
from .stiff import StiffStudy, stiff_study
from .studies import study_part, study_tables

__all__ = ["BenchConfig", "BenchReport", "bench_config", "run_bench", "scaling_scene"]


def knob_study(config: BenchConfig, note, emit) -> list:
    """The speed knobs (the knobs module): every scheme on the headline scene at the
    headline dt, and the compiler knobs of "es" on the largest chain of the scaling series up
    to n = 20."""
    scene = load_reference_scene(HEADLINE_SCENE)
    t_end = config.t_end or scene.simulation.t_end
    rows = []
    for method in METHODS:
        rows += knobs.option_rows(scene, HEADLINE_SCENE, method, 3, HEADLINE_DT, t_end,
                                        n_steps=2000, repeats=config.repeats,
                                        note=note)
    if config.run_scaling:
        # The largest chain of the series up to 20 links: beyond, a step costs milliseconds and
        # each compiler knob a build of a minute.
        n = max([m for m in config.scaling_ns if m <= 20] or [min(config.scaling_ns)])
        rows += knobs.flag_rows_large(scaling_scene(n), f"scaling n = {n}",
                                            HEADLINE_DT, n_steps=config.scaling_steps // 2,
                                            repeats=config.repeats, note=note)
    emit(f"\nspeed knobs\n\n{knobs.knob_table(rows)}")
    return rows



@dataclass(frozen=True)
class BenchReport:
    headlines: list
    reference: dict
    scaling: list | None
    document: Path
    stiff: StiffStudy | None
    figures: dict
    wall_seconds: float


def run_bench(config: BenchConfig, *, note=None, emit=print, figures=None) -> BenchReport:
    """Run every part of `config`, then write the figures and the document (in that order, so
    that a failure leaves the previous document in place). figures: what draws them
    (chaingen.views.bench_figures: plot_work_precision, plot_scaling); None: none drawn."""
    started = time.perf_counter()
    with Progress("bench", total=0) as bar:
        if note is None:   # a status line on a terminal; silent in logs, in CI, --quiet
            def note(message: str) -> None:
                bar.stage(message)
        return _run_bench(config, note, emit, started, figures)


def _stiff_figure(stiff: StiffStudy, config: BenchConfig, drawing) -> Path | None:
    if drawing is None:
        return None
    return drawing.plot_stiff_work_precision(stiff, config.figures / f"bench_{STIFF_FIGURE}.png")


def _versions() -> str:
    import importlib.metadata

    found = []
    for package in ("mujoco", "numbalsoda", "numba", "casadi", "scipy"):
        try:
            found.append(f"{package} {importlib.metadata.version(package)}")
        except importlib.metadata.PackageNotFoundError:
            found.append(f"{package} not installed")
    return ", ".join(found)


def _run_stiff_only(config: BenchConfig, note, emit, started: float, drawing) -> BenchReport:
    """The stiff chain's part alone: its section replaces the one of an existing report at
    config.out (or is added to it), the rest kept; without a report there, a document of the
    title and the section."""
    machine = dict(machine_description())
    stiff = stiff_study(config, note)
    emit(f"\nstiff chain\n\n{stiff_summary_table(stiff)}\n\n{stiff_table(stiff)}")
    figure = _stiff_figure(stiff, config, drawing)
    wall = time.perf_counter() - started
    measured = (f"Written by `{config.command}` in {wall / 60:.1f} min of wall time on "
                f"{time.strftime('%Y-%m-%d')}, apart from the rest of this report (its Machine "
                f"section is not this run's). CPU: {machine['CPU']}; cores: {machine['cores']}; "
                f"{_versions()}." + (" Quick mode: a smoke test, not the benchmark."
                                     if config.quick else ""))
    section = stiff_section(stiff, config, figure, measured)
    existing = config.out.read_text(encoding="utf-8") if config.out.is_file() else ""
    if existing.startswith(REPORT_TITLE):
        text = replace_stiff_section(existing, section)
    else:
        text = f"{REPORT_TITLE}\n\n{section}"
    document = write_text(config.out, text)
    emit(f"\nwrote the stiff chain's section into {document} ({wall / 60:.1f} min)")
    return BenchReport([], {}, None, document, stiff,
                       {STIFF_FIGURE: figure} if figure else {}, wall)


def _run_uneven_only(config: BenchConfig, note, emit, started: float) -> BenchReport:
    """es on the two scaling chains alone: the uneven chain's subsection replaces the one of an
    existing report at config.out (or is added to its scaling section), the rest kept; without
    a report there, a document of the title and the subsection."""
    machine = dict(machine_description())
    scaling = scaling_study(config, note)
    emit(f"\nuneven scaling chain\n\n{uneven_comparison_table(scaling)}")
    wall = time.perf_counter() - started
    measured = (f"Written by `{config.command}` in {wall / 60:.1f} min of wall time on "
                f"{time.strftime('%Y-%m-%d')}, apart from the rest of this report (its Machine "
                f"section and the tables above are of another run). CPU: "
                f"{machine['CPU']}; cores: {machine['cores']}; {_versions()}."
                + (" Quick mode: a smoke test, not the benchmark." if config.quick else ""))
    section = uneven_section(scaling, config, measured)
    existing = config.out.read_text(encoding="utf-8") if config.out.is_file() else ""
    if existing.startswith(REPORT_TITLE):
        text = replace_uneven_section(existing, section)
    else:
        text = f"{REPORT_TITLE}\n\n{section}"
    document = write_text(config.out, text)
    emit(f"\nwrote the uneven chain's subsection into {document} ({wall / 60:.1f} min)")
    return BenchReport([], {}, scaling, document, None, {}, wall)


def _run_spatial_only(config: BenchConfig, note, emit, started: float) -> BenchReport:
    """The spatial arm's part alone: its section replaces the one of an existing report at
    config.out (or is added at its end), the rest kept; without a report there, a document of
    the title and the section."""
    machine = dict(machine_description())
    study = spatial_study(config, note)
    emit(f"\nspatial arm\n\n{step_table(study)}\n\n{build_table(study)}")
    wall = time.perf_counter() - started
    measured = (f"Written by `{config.command}` in {wall / 60:.1f} min of wall time on "
                f"{time.strftime('%Y-%m-%d')}, apart from the rest of this report (its Machine "
                f"section is not this run's). CPU: {machine['CPU']}; cores: {machine['cores']}; "
                f"{_versions()}, {pinocchio_version()}."
                + (" Quick mode: a smoke test, not the benchmark." if config.quick else ""))
    existing = config.out.read_text(encoding="utf-8") if config.out.is_file() else ""
    section = spatial_section(study, config, measured)
    text = (replace_spatial_section(existing, section) if existing.startswith(REPORT_TITLE)
            else f"{REPORT_TITLE}\n\n{section}")
    document = write_text(config.out, text)
    emit(f"\nwrote the spatial arm's section into {document} ({wall / 60:.1f} min)")
    return BenchReport([], {}, None, document, None, {}, wall)


def _run_bench(config: BenchConfig, note, emit, started: float, drawing) -> BenchReport:
    if config.spatial_only:
        return _run_spatial_only(config, note, emit, started)
    if config.stiff_only:
        return _run_stiff_only(config, note, emit, started, drawing)
    if config.uneven_only:
        return _run_uneven_only(config, note, emit, started)
    machine = machine_description()
    def emit_scene(name: str, t_end: float, rows) -> None:
        emit(f"\n{name} (t_end = {t_end:g} s)\n\n{reference_table(rows)}")

    reference = reference_study(config, note, emit_scene) if config.run_reference else {}
    scaling = None
    if config.run_scaling:
        scaling = scaling_study(config, note)
        emit(f"\nscaling series\n\n{scaling_table(scaling)}")
    stiff = None
    if config.run_stiff:
        stiff = stiff_study(config, note)
        emit(f"\nstiff chain\n\n{stiff_summary_table(stiff)}\n\n{stiff_table(stiff)}")
    knobs = knob_study(config, note, emit)
    studies = study_part(config, note)
    emit(f"\nstudies\n\n{study_tables(studies)}")
    control = control_study(config, note)
    emit(f"\ncontrol loops\n\n{control_table(control, config)}")
    control_calls = control_call_study(config, note)
    emit(f"\n{control_call_table(control_calls)}")
    found = headlines(reference, scaling, config, control)
    emit(f"\nheadline\n\n{headline_table(found)}")
    figures = {}
    for name, rows in (reference.items() if drawing is not None else ()):
        figures[name] = drawing.plot_work_precision(name, rows,
                                                    config.figures / f"bench_{name}.png")
    if scaling is not None and drawing is not None:
        figures["scaling"] = drawing.plot_scaling(
            [row for row in scaling if row.chain == "identical" and row.gradient == "exact"],
            config.figures / "bench_scaling.png")
    if stiff is not None and drawing is not None:
        figures[STIFF_FIGURE] = _stiff_figure(stiff, config, drawing)
    wall = time.perf_counter() - started
    text = markdown(config, found, reference, scaling, figures, machine, wall, knobs, studies,
                    control, stiff, control_calls)
    # The spatial arm's section is written by --spatial-only alone: a full run keeps it.
    kept = spatial_section_of(config.out.read_text(encoding="utf-8")
                              if config.out.is_file() else "")
    document = write_text(config.out, text if kept is None
                          else replace_spatial_section(text, kept))
    emit(f"\nwrote {document} and {len(figures)} figures in {config.figures} "
         f"({wall / 60:.1f} min)")
    return BenchReport(found, reference, scaling, document, stiff, figures, wall)
