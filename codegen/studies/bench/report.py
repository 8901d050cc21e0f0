"""The benchmark's document: its tables, the machine, how it was measured."""
from __future__ import annotations

import importlib.metadata
import os
import platform
import subprocess
import time
from pathlib import Path

from ...generate.interface import c_literal
from ...generate.package import LARGE_MODEL_BYTES
from ...runtime import contract
from ...runtime.build import STRICT_FLAGS, compiler
from .config import (
    EARLY_T,
    HARNESS_FLAGS,
    HEADLINE_DT,
    HEADLINE_SCENE,
    MUJOCO_TIMED_STEPS,
    QUICK_MARK,
    REPORT_TITLE,
    STIFF_FIGURE,
    VARIANTS,
    BenchConfig,
)
from .control import control_call_table, control_table
from .headlines import Headline
from .knobs import knob_table
from .runs import COMPILED_FAMILY, RunRow
from .scaling import ScalingRow
from .stiff import StiffStudy, cheapest
from .studies import study_tables


def _time(seconds: float | None) -> str:
    if seconds is None:
        return "-"
    if seconds < 1e-6:
        return f"{seconds * 1e9:.0f} ns"
    if seconds < 1e-3:
        return f"{seconds * 1e6:.2f} us"
    if seconds < 1.0:
        return f"{seconds * 1e3:.2f} ms"
    return f"{seconds:.2f} s"


def _sci(value: float | None) -> str:
    return "-" if value is None else f"{value:.1e}"


def _fixed(value: float | None, digits: int = 2) -> str:
    return "-" if value is None else f"{value:.{digits}f}"


def _megabytes(value: float | None) -> str:
    return "-" if value is None else f"{value:.0f} MB"


def _cell(text: str) -> str:
    return text.replace("|", "\\|")


def reference_table(rows: list[RunRow]) -> str:
    lines = ["| method | variant | setting | per step | run CPU | t_realtime | max energy error "
             "[J] | max constraint error | trajectory error at t_end [rad] | trajectory error at "
             f"t = {min(EARLY_T, rows[0].t_end):g} s [rad] | Newton it. | step / (res+Jac) | "
             "note |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        lines.append(
            f"| {row.method} | {row.variant} | {row.setting} | {_time(row.step_seconds)} | "
            f"{_time(row.run_seconds)} | {_sci(row.t_realtime)} | {_sci(row.energy_error)} | "
            f"{_sci(row.constraint_error)} | {_sci(row.trajectory_error)} | "
            f"{_sci(row.early_trajectory_error)} | {_fixed(row.newton_iterations)} | "
            f"{_fixed(row.step_over_evaluation)} | "
            f"{_cell('failed: ' + row.failure) if row.failure else ''} |")
    return "\n".join(lines)


def scaling_table(rows: list[ScalingRow]) -> str:
    lines = ["| method | n | variant | generate | build | generate + build | peak RSS generate | "
             "peak RSS compile | model C | dt | per step | Newton it. | MuJoCo RK4 per step | "
             "ratio | note |",
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for row in rows:
        size = "-" if row.model_c_bytes is None else f"{row.model_c_bytes / 1024:.0f} KiB"
        lines.append(
            f"| {row.method} | {row.n} | {row.variant} | {_time(row.generate_seconds)} | "
            f"{_time(row.build_seconds)} | {_time(row.generate_and_build_seconds)} | "
            f"{_megabytes(row.generate_peak_mb)} | {_megabytes(row.compile_peak_mb)} | "
            f"{size} | {'-' if row.dt is None else f'{row.dt:g} s'} | "
            f"{_time(row.step_seconds)} | {_fixed(row.newton_iterations)} | "
            f"{_time(row.mujoco_step_seconds)} | {_fixed(row.ratio)} | "
            f"{_cell(row.failure) if row.failure else ''} |")
    return "\n".join(lines)


def headline_table(found: list[Headline]) -> str:
    lines = ["| | claim | variant | measured | target | |", "|---|---|---|---|---|---|"]
    for h in found:
        lines.append(f"| {h.key} | {h.claim} | {h.variant} | {_cell(h.measured)} | {h.target} "
                     f"| {h.mark} |")
    return "\n".join(lines)


def _first_line(command: list[str]) -> str:
    try:
        result = subprocess.run(command, capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired):
        return "unknown"
    return (result.stdout.strip().splitlines() or ["unknown"])[0]


def machine_description() -> list[tuple[str, str]]:
    """What the numbers were measured on: CPU, cores, memory, OS, compiler and versions."""
    cpu = "unknown"
    memory = "unknown"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal"):
                memory = f"{int(line.split()[1]) / 1024 ** 2:.1f} GiB"
                break
    except OSError:
        pass
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:
        usable = os.cpu_count()

    def version(package: str) -> str:
        try:
            return importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            return "not installed"

    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    return [
        ("CPU", cpu),
        ("cores", f"{os.cpu_count()} ({usable} usable by this process); load average at the "
                  f"start {load} (the machine is shared)"),
        ("memory", memory),
        ("OS", platform.platform()),
        ("C compiler", f"{compiler()}: {_first_line([compiler(), '--version'])}"),
        ("our flags", " ".join(STRICT_FLAGS + HARNESS_FLAGS) + ", and the package's own "
                      "per-source flags in their place (the solver source -O3, a generated "
                      f"model over {LARGE_MODEL_BYTES / 1e6:g} MB -O1), each source in its own "
                      "compiler process, as "
                      "chaingen's build does; the Solver used for the errors is that build"),
        ("MuJoCo", f"{version('mujoco')} (PyPI wheel, its own build flags)"),
        ("SciPy", f"{version('scipy')} (right-hand side and Jacobian: CasADi C compiled by "
                  "chaingen.reference.scipy_peer with the runtime's default flags; integrator in "
                  "Python)"),
        ("compiled peers", (f"numbalsoda {version('numbalsoda')} with numba "
                            f"{version('numba')} (LSODA, DOP853; right-hand side: the SciPy "
                            "peer's compiled C, called from a numba cfunc)"
                            if version("numbalsoda") != "not installed" else
                            "numbalsoda's LSODA and DOP853 not run (numbalsoda and numba, the "
                            "`peers` extra, are not installed)") + ", CVODES of CasADi "
                           f"{version('casadi')} (the ODE and its Jacobian as CasADi C, built "
                           "with the runtime's default flags)"),
        ("Python", platform.python_version()),
        ("numpy, sympy, casadi, matplotlib",
         f"{version('numpy')}, {version('sympy')}, {version('casadi')}, "
         f"{version('matplotlib')}"),
    ]



def _link(figure: Path, document: Path) -> str:
    return Path(os.path.relpath(figure, document.parent)).as_posix()


HOW_MEASURED = """\
- CPU time is process time of the compiled loop only, the median of repeats: ours from a C
  program calling the generated step over the whole run (`chaingen.studies.bench.harness`),
  MuJoCo from one `mj_step(model, data, nstep=N)` call (at most {mujoco_steps} steps a repeat:
  its cost per step does not depend on the state), SciPy from `solve_ivp` alone (right-hand side and
  Jacobian compiled; its steps and their error control run in Python), the compiled peers from
  their one integrator call (`chaingen.reference.compiled_peers`: numbalsoda's LSODA and DOP853
  on the same compiled right-hand side, CVODES BDF with Newton and Adams with functional
  iteration through CasADi; the whole loop compiled, numba's compilation done before). Run
  CPU = per step x steps for ours and MuJoCo; t_realtime = run CPU / simulated time.
- Max energy error: max |H - H_0| over every step of the run (SciPy: over its accepted steps;
  the compiled peers: over their output every 0.01 s, which they interpolate in the timed call).
  Trajectory error: max_i |phi_i(t) - phi_ref,i(t)|, each difference wrapped to [-pi, pi),
  against SciPy DOP853 at rtol = atol = 2.2e-14 (`chaingen.reference.scipy_peer`), at t_end and at
  t = {early_t:g} s (the plots use the latter; SciPy's run to it is a second, untimed one).
  Max constraint error: es max_i |c_i|, vi max_i ||q_i| - 1|; "-" for minimal coordinates.
- Over 50 s the reference scenes amplify small differences strongly, so a trajectory error of
  order 1 rad means a run has lost the phase, not that its model is wrong: second-order
  schemes (ours, MuJoCo's Euler) get there at every dt of the series while their energy error
  stays small. The energy error and the trajectory error measure different things. At
  t = {early_t:g} s the reference is good to about 1e-14 rad and the errors order the methods.
- Newton it.: mean iterations per step; step / (res+Jac): the step's time in units of one
  residual-and-Jacobian evaluation, the least a Newton step can cost.
- Variant: the Newton options ours ran with ({variants}). K (es only) is the Gauss-Legendre
  quadrature of the spring terms; a scene without springs has no K.
- The machine is shared, so single timings carry noise of some ten percent: compare ratios
  measured side by side, as the headline does.
"""



def markdown(config: BenchConfig, found: list[Headline], reference, scaling,
             figures: dict[str, Path], machine, wall_seconds: float, knobs=(),
             studies=None, control=None, stiff=None, control_calls=None) -> str:
    lines = [REPORT_TITLE, "",
             f"Written by `{config.command}` in {wall_seconds / 60:.1f} min of wall time on "
             f"{time.strftime('%Y-%m-%d')}. Every number and figure comes from that run; nothing "
             "is edited by hand." + (f" {QUICK_MARK}: a smoke test with short runs and few "
                                     "series, not the benchmark." if config.quick else ""),
             "", "## Headline", "",
             "The issue's targets, measured side by side in this run (a-c, e-h on "
             f"{HEADLINE_SCENE}, standard run; d on the scaling series). f and g compare the "
             "cheapest measured runs that hold both errors (not interpolated), h interpolates "
             "each method's CPU at a trajectory error as c does at an energy error; j is on the "
             "control loops (last section).", "",
             headline_table(found), "", "## Machine", ""]
    lines += [f"- {key}: {value}" for key, value in machine]
    lines += ["", "## How it is measured", "",
              HOW_MEASURED.format(mujoco_steps=MUJOCO_TIMED_STEPS, early_t=EARLY_T,
                                  variants="; ".join(f"{v.label}: "
                                                     f"{v.options or 'the package defaults'}"
                                                     for v in VARIANTS)).rstrip()]
    if reference:
        lines += ["", "## Reference scenes", ""]
        for name, rows in reference.items():
            lines += [f"### {name}", "",
                      f"From the scene's initial state to t_end = {rows[0].t_end:g} s.", "",
                      f"![{name} work-precision]({_link(figures[name], config.out)})", "",
                      reference_table(rows), ""]
    if stiff is not None:
        lines += [stiff_section(stiff, config, figures.get(STIFF_FIGURE))]
    if scaling is not None:
        lines += ["## Scaling", "",
                  "`chaingen.studies.bench.scenes.scaling_scene(n)`: n identical links "
                  "(1 kg, 0.4 m), g = 9.81, "
                  "a mono-articular spring across every joint, a multi-articular spring "
                  "over joints 1..min(n, 3) and, for n >= 6, one over joints n-2..n. Generate "
                  "(SymPy, CasADi, rendering) and build "
                  "(gcc with the package's per-source flags, sources compiled side by side) "
                  "run in a child process with a limit of "
                  f"{config.timeout:g} s; a scheme over the limit, or that the lower bound "
                  "t(n') >= t(n) n'/n puts over it, is not run at larger n. "
                  "Peak RSS: of the generating Python process (VmHWM), and of the compiler "
                  "with the passes it runs (GNU time). "
                  f"Per step: {config.scaling_steps} steps from the initial state "
                  f"({config.scaling_steps} x 20 / n, at least 100, and at most 3 repeats "
                  "beyond n = 20, so that timing stays within its own allowance of 300 s), "
                  "median of the repeats; each repeat is followed by one of MuJoCo RK4 on the "
                  "same model, dt and steps, and the ratio is of the two medians.",
                  "",
                  f"![scaling]({_link(figures['scaling'], config.out)})", "",
                  scaling_table([row for row in scaling if row.chain == "identical"
                                 and row.gradient == "exact"]), ""]
        if any(row.chain == "uneven" for row in scaling):
            lines += [uneven_section(scaling, config)]
    if knobs:
        tolerances = ", ".join(f"{field.name} = {c_literal(field.default)}"
                               for field in contract.NEWTON_OPTIONS
                               if field.name.endswith(("_rtol", "_atol", "_tol")))
        lines += ["## Speed knobs", "", KNOBS_TEXT.format(scene=HEADLINE_SCENE, dt=HEADLINE_DT,
                  tolerances=tolerances, large=f"{LARGE_MODEL_BYTES / 1e6:g}"),
                  "", knob_table(knobs), ""]
    if studies is not None:
        lines += ["## Studies: run-time parameters and sweeps", "",
                  " ".join(STUDIES_TEXT.split("\n")), "", study_tables(studies), ""]
    if control:
        lines += ["## Control loops", "", control_table(control, config), ""]
    if control_calls is not None:
        lines += [control_call_table(control_calls), ""]
    return "\n".join(lines).rstrip() + "\n"


KNOBS_TEXT = """\
One knob changed at a time against the package defaults, on {scene} at dt = {dt} s (step time
of the C loop, median of repeats; energy error over the standard run with the same options), and
the compiler knobs again on the largest chain of the scaling series (up to 20 links), where the
LU (es: of the n x n reduced system, docs/model.md section 18) and the size of the generated
model dominate. The package defaults are warm start, Newton-chord (the
Jacobian evaluated and factorised once a step, reused within it) for "es" and "midpoint" and
simplified Newton (reused across steps) for "vi", tolerances {tolerances}, the solver
source at -O3 and a generated model larger than {large} MB at -O1. "step / (F, dF/dz)" is the step's
time in units of one residual-and-Jacobian evaluation. Run-time parameters against constants
compiled in are measured in the next section."""

STUDIES_TEXT = """\
What a study costs. First the per-step price of run-time parameters: the solver of the headline
scene with its numbers as parameters against the one with them compiled in, both linked into one
timing program and run block by block in alternating order, so that a slow spell of the machine
falls on both. Two sets of parameters: every number the scene sets (the non-zero ones), and every
number with the zeros too, which brings in code the scene without parameters does not have
(damping, COMs off the link axis). Then a sweep of the headline scene (stiffness of its first
spring x mass of its second link, trajectories every 10 steps), each run of it a fresh `chaingen
sweep` process as a user starts it: the local engine (one thread per core) with a cold build
cache, so that the wall time includes generating and building its one solver, then with the
build cached, and the Dask engine on a LocalCluster of one worker process per core, started
within the command; and the same with runs ten times as long. "equal" compares runs.parquet with
the local engine's, every column but cpu_seconds, bit for bit. Last, the way without parameters:
one scene file per run and `chaingen simulate` on each, a fresh process and a fresh build each
time, timed on a subset of the files and scaled to all runs."""



# --------------------------------------------------------------------------------------------
# The stiff chain's work-precision
# --------------------------------------------------------------------------------------------

#: The heading of the stiff chain's section; `chaingen bench --stiff-only` replaces the section
#: it starts (up to the next "## ") in an existing report.
STIFF_HEADING = "## Stiff chain: work-precision"


def stiff_table(study: StiffStudy) -> str:
    lines = ["| method | setting | steps | per step | run CPU | trajectory error at t_end [rad] "
             "| max energy error [J] | energy error / E_ref | Newton it. | note |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for row in study.rows:
        lines.append(
            f"| {row.method} | {row.setting} | {row.n_steps or '-'} | "
            f"{_time(row.step_seconds)} | {_time(row.run_seconds)} | "
            f"{_sci(row.trajectory_error)} | {_sci(row.energy_error)} | "
            f"{_sci(row.relative_energy_error)} | {_fixed(row.newton_iterations)} | "
            f"{_cell(row.failure) if row.failure else ''} |")
    return "\n".join(lines)


def _level(trajectory: float | None, energy: float | None) -> str:
    parts = ([f"trajectory <= {trajectory:.0e} rad"] if trajectory is not None else []) + \
            ([f"energy <= {energy:.0e} E_ref"] if energy is not None else [])
    return " and ".join(parts)


def _run(row) -> str:
    return "none measured holds it" if row is None else \
        f"{row.method}, {row.setting}: {_time(row.run_seconds)}"


def stiff_summary_table(study: StiffStudy) -> str:
    """Per level of study.settings.levels: the cheapest measured run (not interpolated) of
    ours, of the compiled peers and of MuJoCo that holds it, and who is cheaper by how much."""
    lines = ["| held errors | ours | compiled peers | MuJoCo | cheapest |",
             "|---|---|---|---|---|"]
    for trajectory, energy in study.settings.levels:
        ours = cheapest(study.rows, ("chaingen",), trajectory, energy)
        compiled = cheapest(study.rows, (COMPILED_FAMILY,), trajectory, energy)
        mujoco = cheapest(study.rows, ("MuJoCo",), trajectory, energy)
        peers = [row for row in (compiled, mujoco) if row is not None]
        peer = min(peers, key=lambda row: row.run_seconds, default=None)
        if ours is None and peer is None:
            verdict = "no run holds it"
        elif peer is None:
            verdict = "ours (no peer run holds it)"
        elif ours is None:
            verdict = f"{peer.method} (no run of ours holds it)"
        elif ours.run_seconds <= peer.run_seconds:
            ratio = peer.run_seconds / ours.run_seconds
            verdict = f"ours, {ratio:.1f}x less CPU than {peer.method}"
        else:
            ratio = ours.run_seconds / peer.run_seconds
            verdict = f"{peer.method}, {ratio:.1f}x less CPU than ours"
        lines.append(f"| {_level(trajectory, energy)} | {_cell(_run(ours))} | "
                     f"{_cell(_run(compiled))} | {_cell(_run(mujoco))} | {_cell(verdict)} |")
    return "\n".join(lines)


def stiff_section(study: StiffStudy, config: BenchConfig, figure: Path | None,
                  measured: str | None = None) -> str:
    """The section of the report (STIFF_HEADING); `measured`: a line naming the run that wrote
    it, where it was written apart from the rest of the report."""
    s = study.settings
    schemes = ", ".join(dict.fromkeys(row.method for row in study.rows
                                      if row.family == "chaingen"))
    spread = ("" if study.reference_spread is None else
              f" (it differs from DOP853 at SciPy's tightest tolerance by "
              f"{study.reference_spread:.1e} rad: trajectory errors near that say nothing)")
    lines = [STIFF_HEADING, ""]
    if measured:
        lines += [measured, ""]
    lines += [
        f"`chaingen.studies.bench.stiff.stiff_scene({s.n}, {s.stiffness:g})` ({study.scene_name}): "
        f"the scaling chain of {s.n} links with every spring, mono- and multi-articular, at "
        f"{s.stiffness:g} N/m, {s.t_end:g} s from its initial state. Trajectory error: "
        f"max_i |phi_i - phi_ref,i| at t = {s.t_end:g} s, wrapped to [-pi, pi), against SciPy "
        f"DOP853 at rtol = atol = {s.reference_rtol:g}{spread}. Energy error: max |H - H_0| "
        f"over the run over E_ref = {study.energy_scale:.4g} J, the largest |H| along the "
        "reference (one scale for every row): ours and MuJoCo over every step, adaptive es over "
        f"its samples every {s.adaptive_sample:g} s, the compiled peers over samples every "
        f"{s.energy_sample:g} s of a second, untimed run with the same tolerance. CPU as on the "
        "reference scenes (How it is measured; adaptive es: process time of Solver.simulate, "
        f"median of {config.repeats}). Ours: {schemes}; \"quadrature\" is es with the "
        "quadrature's average alone (docs/model.md 4.3), the others es with the exact discrete "
        "gradient, its default. A failed or unstable run is a row with its note.", ""]
    if figure is not None:
        lines += [f"![stiff chain work-precision]({_link(figure, config.out)})", ""]
    lines += ["The cheapest measured run (not interpolated) of each side that holds the "
              "errors:", "", stiff_summary_table(study), "", stiff_table(study), ""]
    return "\n".join(lines)


def replace_stiff_section(document: str, section: str) -> str:
    """`document` with its stiff chain section replaced by `section` (up to the next "## "
    heading), or, without one, with `section` put before "## Scaling" or at the end."""
    section = section.rstrip() + "\n"
    start = document.find(f"\n{STIFF_HEADING}\n")
    if start >= 0:
        end = document.find("\n## ", start + 1)
        tail = "" if end < 0 else document[end + 1:]
        return document[:start + 1] + section + ("\n" + tail if tail else "")
    before = document.find("\n## Scaling\n")
    if before >= 0:
        return document[:before + 1] + section + "\n" + document[before + 1:]
    return document.rstrip() + "\n\n" + section



# --------------------------------------------------------------------------------------------
# The uneven scaling chain (a subsection of the scaling section)
# --------------------------------------------------------------------------------------------

#: The heading of the uneven chain's subsection; `chaingen bench --uneven-only` replaces the
#: subsection it starts (up to the next "## " or "### ") in an existing report.
UNEVEN_HEADING = "### Uneven links, centres of mass off the axis"


def uneven_comparison_table(rows: list[ScalingRow]) -> str:
    """es per step / MuJoCo RK4 per step at each n, on the two chains side by side (the rows
    of es of both chains, one line per gradient and Newton variant)."""
    lines = ["| n | method | variant | identical: per step | RK4 | ratio | uneven: per step | "
             "RK4 | ratio | Newton it. (identical / uneven) |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    ns = sorted({row.n for row in rows if row.chain == "uneven"})
    methods = list(dict.fromkeys(row.method for row in rows if row.chain == "uneven"))
    for n in ns:
        for method, variant in ((m, v) for m in methods for v in VARIANTS):
            pair = {row.chain: row for row in rows if row.n == n and row.method == method
                    and row.variant == variant.label}
            same, uneven = pair.get("identical"), pair.get("uneven")
            cells = []
            for row in (same, uneven):
                cells += ([_time(row.step_seconds), _time(row.mujoco_step_seconds),
                           _fixed(row.ratio)] if row is not None else ["-", "-", "-"])
            iterations = " / ".join(_fixed(None if row is None else row.newton_iterations)
                                    for row in (same, uneven))
            lines.append(f"| {n} | {method} | {variant.label} | {' | '.join(cells)} | "
                         f"{iterations} |")
    return "\n".join(lines)


def uneven_section(rows: list[ScalingRow], config: BenchConfig,
                   measured: str | None = None) -> str:
    """The uneven chain's subsection (UNEVEN_HEADING): es on it beside es on the chain of
    identical links, and its rows of the scaling table; `measured`: a line naming the run that
    wrote it, where it was written apart from the rest of the report."""
    lines = [UNEVEN_HEADING, ""]
    if measured:
        lines += [measured, ""]
    lines += [
        "`chaingen.studies.bench.scenes.uneven_scene(n)`: the scaling chain's springs, initial "
        "state and gravity on n uneven links. Link i (from 0) takes entry i mod the table's "
        "length of fixed tables: mass (1.0, 1.6, 0.7, 1.3, 0.5) kg, length (0.4, 0.3, 0.5, "
        "0.35) m, COM along the link (0.5, 0.35, 0.65) of the length, COM normal to the link "
        "(0.03, -0.02, 0.05, -0.04, 0.01) m (every COM off the axis), inertia (1.0, 1.8, 0.6) "
        "x m L^2 / 12, distal fastening (0.05, 0.04, 0.06, 0.045) m; rest lengths 95 % of the "
        "straight posture's. Parsed from TOML like a user's file; MuJoCo runs its MJCF export "
        "(`chaingen.reference.mjcf`; es agrees with MuJoCo on it at n = 5, "
        "tests/test_mujoco_agreement.py). Measured as the rest of the scaling series (es K=3, "
        "each n in a child process, each repeat followed by one of MuJoCo RK4 on the same "
        "model), the chain of identical links measured in the same run. \"es K=3\" is es with "
        "its default gradient of the springs (exact, docs/model.md 4.3), \"es K=3 chain\" with "
        "the chain rule's (`gradient = \"chain\"`, exact too, without quadrature).", "",
        uneven_comparison_table(rows), "",
        scaling_table([row for row in rows if row.chain == "uneven" or row.gradient != "exact"]),
        ""]
    return "\n".join(lines)


def replace_uneven_section(document: str, section: str) -> str:
    """`document` with its uneven chain subsection replaced by `section` (up to the next "## "
    or "### " heading); without one, `section` put at the end of the scaling section, or at the
    end of the document."""
    section = section.rstrip() + "\n"
    start = document.find(f"\n{UNEVEN_HEADING}\n")
    if start >= 0:   # the next heading of either level
        end = min([i for i in (document.find("\n## ", start + 1),
                               document.find("\n### ", start + 1)) if i >= 0], default=-1)
    else:
        scaling = document.find("\n## Scaling\n")
        if scaling < 0:
            return document.rstrip() + "\n\n" + section
        start = end = document.find("\n## ", scaling + 1)
        if start < 0:
            return document.rstrip() + "\n\n" + section
    tail = "" if end < 0 else document[end + 1:]
    return document[:start + 1] + section + ("\n" + tail if tail else "")
