"""The speed/accuracy benchmark (issue 6): our schemes against MuJoCo and SciPy, in one run.

    chaingen bench [--quick] [--out docs/benchmarks.md] [--figures DIR] [--dts 0.04,0.02,...]
                   [--scaling-n 2,3,5,10,20] [--skip-scaling] [--skip-reference]
                   [--timeout SECONDS]

Three parts, all measured side by side on one machine in one process (the scaling series in
child processes, so that a size that takes too long can be stopped):

1. Reference scenes (scenes/three_link_*.toml, the scene's own run: 50 s from its initial
   state). Every scheme at a dt series, MuJoCo (Euler, implicitfast, RK4) at its own dt series
   and SciPy's solve_ivp (DOP853, Radau) at a tolerance series. For each run: CPU time per step
   and of the whole run, t_realtime, max |H - H_0|, max constraint error, the trajectory error
   at t_end against a tight DOP853 reference (codegen.scipy_peer.reference_solution), and for
   ours the Newton iterations per step and the step's cost in residual-and-Jacobian
   evaluations.
2. A scaling series: `scaling_scene(n)` for n = 2 ... 20; generate and build seconds, peak
   memory, model C size, per-step time, and MuJoCo RK4's per-step time at the same n.
3. Headline ratios with the issue's targets, computed from parts 1 and 2.

How each side is timed (CPU time, process clock, the compiled loop only):

- ours: codegen.bench_harness, a C program that calls <prefix>_step for the whole run
  (median of repeats); run CPU = per step x steps. Energy and constraint errors come from a
  separate Solver.simulate run of the same package (every step sampled).
- MuJoCo: one mj_step(model, data, nstep=N) call under time.process_time(), median of
  repeats. MuJoCo's cost per step does not depend on the state (no iterations), so at most
  MUJOCO_TIMED_STEPS steps are timed per repeat. Errors from an untimed run that evaluates
  mjData.energy (energy flag) after every step, as codegen.mujoco_reference does.
- SciPy: ScipyRun.cpu_time of simulate_scipy (solve_ivp alone; the right-hand side and
  Jacobian are compiled C), per step = cpu_time / accepted steps; energy error over the
  accepted steps.

Newton option variants: VARIANTS is the one list of (label, options) our schemes are run with;
every row and headline names its variant. A new knob (a predictor choice, say) is one more
entry there.
"""
from __future__ import annotations

import importlib.metadata
import importlib.util
import json
import math
import os
import platform
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from chaingen_runtime import NewtonError, NewtonOptions, Solver
from chaingen_runtime.build import STRICT_FLAGS, compiler
from chaingen_runtime.trajectory import current_umask

from . import bench_knobs
from .bench_harness import Harness, HarnessError
from .package import generate_package, render_package, uses_quadrature
from .progress import Progress
from .scene import ChaingenError, Scene, load_scene, parse_scene

ROOT = Path(__file__).resolve().parent.parent
REFERENCE_SCENES = ("three_link_gravity", "three_link_mono", "three_link_multi")
#: The scene of the headline ratios.
HEADLINE_SCENE = "three_link_mono"
METHODS = ("es", "vi", "midpoint")
HARNESS_FLAGS = ("-O2",)


# --------------------------------------------------------------------------------------------
# What runs
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class Variant:
    """Newton options our schemes are timed with: a label for the tables and the fields the
    harness sets (codegen.bench_harness.OPTION_FIELDS; unset fields keep the package's
    defaults)."""

    label: str
    options: dict = field(default_factory=dict)

    def newton_options(self, solver: Solver) -> NewtonOptions:
        """The same options for Solver.simulate (the error run): the package's defaults with
        this variant's fields (codegen.bench_knobs.newton_options)."""
        return bench_knobs.newton_options(solver, self.options)


#: The Newton variants every scheme is run with: the package's defaults (warm start; Newton-chord,
#: the Jacobian once a step, for "es" and "midpoint", simplified Newton for "vi") and simplified
#: Newton (the factorised Jacobian reused across iterations and steps). codegen.bench_knobs measures the other knobs.
#: A new knob is one more entry here.
VARIANTS = (Variant("default options", {}),
            Variant("simplified Newton", {"reuse_jacobian": 1}))

DEFAULT_DTS = (0.04, 0.02, 0.01, 0.005, 0.0025)
#: es also runs at these larger steps on the headline scene, so that its energy error can reach
#: the error of headline c (1e-10 J) from above: measured, not extrapolated.
BRACKET_DTS = (0.2, 0.1, 0.05)
#: K = 5: the quadrature error, not dt, bounds es's energy error (O(dt^2K)), so a higher K reaches
#: a given energy error at a much larger dt (headline c).
QUADRATURES = (1, 2, 3, 5)
MUJOCO_INTEGRATORS = ("Euler", "implicitfast", "RK4")
MUJOCO_DTS = (0.01, 0.005, 0.0025, 0.001, 5e-4, 2.5e-4, 1e-4)
SCIPY_TOLERANCES = (("DOP853", tuple(10.0 ** -k for k in range(4, 13))),
                    ("Radau", tuple(10.0 ** -k for k in range(4, 11))))
SCALING_NS = (2, 3, 5, 10, 20)
#: (method, quadrature) of the scaling series.
SCALING_METHODS = (("es", 3), ("vi", 3), ("midpoint", 3))
#: dt of the scaling series' per-step time, and the smaller ones tried if a scheme fails at it.
SCALING_DTS = (0.01, 0.005, 0.0025)
MUJOCO_TIMED_STEPS = 20_000
#: A SciPy run shorter than this (CPU s) is repeated and its median taken.
SCIPY_REPEAT_BELOW = 1.0

#: Targets of issue 6.
TARGET_RATIO_ES = 0.3          # a: es K=3 step / MuJoCo RK4 step, mono, dt = 0.01
TARGET_ENERGY_ES = 1e-11       # a: es K=3 max energy error (J)
TARGET_RATIO_VI = 0.15         # b: vi step / MuJoCo RK4 step
TARGET_EQUAL_ERROR = 1e-10     # c: the energy error (J) at which CPU times are compared
TARGET_SCIPY_OVER_ES = 100.0   # c: DOP853 CPU / es CPU at that error
TARGET_BUILD_SECONDS = 20.0    # d: generate + build at n = 20
TARGET_SCALING_RATIO = 5.0     # d: es step / MuJoCo RK4 step at n = 20
TARGET_STEP_OVER_EVALUATION = 2.5   # e: es K=3 step / one residual-and-Jacobian evaluation
HEADLINE_DT = 0.01
#: The early time of the second trajectory error: over the standard run's 50 s the reference
#: scenes amplify differences (1e-12 rad at t = 0 becomes 1e-5 to 1e-4 at 50 s), so only an
#: error taken this early measures a method's accuracy (the reference is good to 1e-14 there).
EARLY_T = 3.0
HEADLINE_N = 20


class BenchError(ChaingenError):
    """A bad option of `chaingen bench`; the message names it."""


@dataclass(frozen=True)
class BenchConfig:
    """Everything one run of the benchmark does; `bench_config` makes and checks it."""

    quick: bool
    scenes: tuple[str, ...]
    t_end: float | None                  # None: each scene's own [simulation].t_end
    dts: tuple[float, ...]
    quadratures: tuple[int, ...]
    methods: tuple[str, ...]
    mujoco_integrators: tuple[str, ...]
    mujoco_dts: tuple[float, ...]
    scipy_tolerances: tuple[tuple[str, tuple[float, ...]], ...]
    scaling_ns: tuple[int, ...]
    scaling_methods: tuple[tuple[str, int], ...]
    timeout: float
    repeats: int                         # harness and MuJoCo timing repeats
    scipy_repeats: int
    scaling_steps: int                   # steps timed per repeat in the scaling series
    run_reference: bool
    run_scaling: bool
    out: Path
    figures: Path
    command: str


def _parse_list(text: str, option: str, kind):
    values = []
    for item in text.split(","):
        item = item.strip()
        what, example = ("an integer", "2,3,5") if kind is int else ("a number", "0.02,0.01")
        try:
            value = kind(item)
        except ValueError:
            raise BenchError(f"{option}: {item!r} is not {what} (give a comma-separated list, "
                             f"e.g. {option} {example})") from None
        values.append(value)
    return tuple(values)


def _divides(dt: float, t_end: float) -> bool:
    steps = round(t_end / dt)
    return steps >= 1 and abs(steps * dt - t_end) <= 1e-9 * t_end


def _check_divides(dt: float, t_end: float, option: str) -> None:
    if not _divides(dt, t_end):
        raise BenchError(f"{option}: dt = {dt!r} s does not divide the run's t_end = {t_end:g} s "
                         "(the trajectory error is taken at t_end)")


def bench_config(*, quick: bool = False, dts: str | None = None, scaling_n: str | None = None,
                 timeout: float = 300.0, skip_scaling: bool = False,
                 skip_reference: bool = False, out: Path | None = None,
                 figures: Path | None = None) -> BenchConfig:
    """The run's settings from the command line's values; BenchError names a bad one."""
    if skip_scaling and skip_reference:
        raise BenchError("--skip-scaling and --skip-reference: nothing left to run; drop one")
    if not (math.isfinite(timeout) and timeout > 0):
        raise BenchError(f"--timeout: must be > 0 seconds and finite, got {timeout}")
    for module in ("mujoco", "scipy", "matplotlib"):
        if importlib.util.find_spec(module) is None:
            raise BenchError(f"chaingen bench needs {module}, which is not installed "
                             "(pip install -e '.[test]')")
    scenes = (HEADLINE_SCENE,) if quick else REFERENCE_SCENES
    t_end = 2.0 if quick else None
    if dts is None:
        dt_values = (0.02, 0.01) if quick else DEFAULT_DTS
    else:
        dt_values = _parse_list(dts, "--dts", float)
        for dt in dt_values:
            if not (math.isfinite(dt) and dt > 0):
                raise BenchError(f"--dts: every dt must be > 0 and finite, got {dt!r}")
    if not skip_reference:
        for name in scenes:
            run_end = t_end or load_scene(ROOT / "scenes" / f"{name}.toml").simulation.t_end
            for dt in dt_values:
                _check_divides(dt, run_end, "--dts")
    if scaling_n is None:
        ns = (2, 3) if quick else SCALING_NS
    else:
        ns = _parse_list(scaling_n, "--scaling-n", int)
        for n in ns:
            if not 2 <= n <= 100:
                raise BenchError(f"--scaling-n: every n must be between 2 and 100 (a "
                                 f"multi-articular spring needs two joints), got {n}")
    out_default = out is None
    out = Path(out) if out is not None else ROOT / "docs" / "benchmarks.md"
    if out.is_dir():
        raise BenchError(f"--out: {out} is a directory; give a file name")
    if not (out.parent if str(out.parent) else Path(".")).is_dir():
        raise BenchError(f"--out: directory {out.parent} does not exist")
    figures_default = figures is None
    figures = Path(figures) if figures is not None else out.parent / "figures"
    if figures.exists() and not figures.is_dir():
        raise BenchError(f"--figures: {figures} exists and is not a directory")
    if not figures.exists() and not figures.parent.is_dir():
        raise BenchError(f"--figures: directory {figures.parent} does not exist")

    command = ["chaingen", "bench"]
    command += ["--quick"] if quick else []
    command += ["--dts", dts] if dts is not None else []
    command += ["--scaling-n", scaling_n] if scaling_n is not None else []
    command += ["--skip-scaling"] if skip_scaling else []
    command += ["--skip-reference"] if skip_reference else []
    command += ["--timeout", f"{timeout:g}"] if timeout != 300.0 else []
    command += [] if out_default else ["--out", str(out)]
    command += [] if figures_default else ["--figures", str(figures)]
    return BenchConfig(
        quick=quick, scenes=scenes, t_end=t_end, dts=dt_values,
        quadratures=(3,) if quick else QUADRATURES, methods=METHODS,
        mujoco_integrators=("Euler", "RK4") if quick else MUJOCO_INTEGRATORS,
        mujoco_dts=(0.01, 0.001) if quick else MUJOCO_DTS,
        scipy_tolerances=((("DOP853", (1e-6, 1e-10)), ("Radau", (1e-6,))) if quick
                          else SCIPY_TOLERANCES),
        scaling_ns=ns, scaling_methods=SCALING_METHODS, timeout=float(timeout),
        repeats=3 if quick else 7, scipy_repeats=1 if quick else 3,
        scaling_steps=200 if quick else 1000,
        run_reference=not skip_reference, run_scaling=not skip_scaling,
        out=out, figures=figures, command=" ".join(command))


# --------------------------------------------------------------------------------------------
# The scaling scene
# --------------------------------------------------------------------------------------------

SCALING_LINK = {"mass": 1.0, "length": 0.4, "com": 0.2, "fastening": 0.05}
SCALING_MONO_STIFFNESS = 200.0     # N/m: k L r = 4 N m/rad per joint, like m g L
SCALING_MULTI_STIFFNESS = 100.0
#: Rest lengths are this fraction of the straight posture's, so the springs pull from the start.
SCALING_REST_FRACTION = 0.95
#: The chain starts hanging (phi_1 = -pi/2 is straight down), deflected by this at joint 1
#: and bent by SCALING_INITIAL_ANGLE at every other joint. Released from the horizontal instead,
#: a long chain whips: MuJoCo's RK4 at dt = 0.01 s goes unstable from n = 10 on.
SCALING_HANGING_DEFLECTION = 0.2
SCALING_INITIAL_ANGLE = 0.1


def scaling_scene_text(n: int) -> str:
    """TOML of the scaling series' chain of n identical links (see scaling_scene)."""
    link = SCALING_LINK
    inertia = link["mass"] * link["length"] ** 2 / 12
    lines = [f"# chaingen bench scaling series: {n} identical links, a mono-articular spring",
             "# across every joint and one multi-articular spring over the first joints.",
             f'name = "scaling-{n}"', "gravity = 9.81", "", "[base]",
             f"fastening = {link['fastening']!r}", ""]
    for _ in range(n):
        lines += ["[[links]]", f"mass = {link['mass']!r}", f"inertia = {inertia!r}",
                  f"length = {link['length']!r}", f"com = {link['com']!r}",
                  f"fastening = {link['fastening']!r}", ""]
    # Straight posture, all offsets equal: each segment P_j -> P_{j+1} is one link long.
    for j in range(1, n + 1):
        lines += ["[[springs]]", f"joints = [{j}, {j}]",
                  f"stiffness = {SCALING_MONO_STIFFNESS!r}",
                  f"rest_length = {SCALING_REST_FRACTION * link['length']!r}", ""]
    last = min(n, 3)
    lines += ["[[springs]]", f"joints = [1, {last}]", f"stiffness = {SCALING_MULTI_STIFFNESS!r}",
              f"rest_length = {SCALING_REST_FRACTION * last * link['length']!r}", ""]
    angles = ", ".join([repr(-math.pi / 2 + SCALING_HANGING_DEFLECTION)]
                       + [repr(SCALING_INITIAL_ANGLE)] * (n - 1))
    lines += ["[initial]", f"angles = [{angles}]", f"velocities = [{', '.join(['0.0'] * n)}]",
              "", "[simulation]", 'method = "es"', "quadrature = 3", "dt = 0.01",
              "t_end = 10.0", ""]
    return "\n".join(lines)


def scaling_scene(n: int) -> Scene:
    """n identical links (1 kg, 0.4 m, COM at 0.2 m, J = m L^2 / 12, fastenings 0.05 m off the
    axis), g = 9.81, a mono-articular spring across every joint and one multi-articular spring
    over joints 1..min(n, 3), rest lengths 95 % of the straight posture's. At rest, hanging
    0.2 rad off the vertical with every other joint bent by 0.1 rad. Parsed from TOML like a
    user's file, so it is validated like one."""
    return parse_scene(scaling_scene_text(n), f"<scaling scene n={n}>", f"scaling-{n}")


# --------------------------------------------------------------------------------------------
# Rows
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class RunRow:
    """One run on a reference scene: a scheme or peer at one dt or tolerance."""

    scene: str
    family: str                      # "chaingen", "MuJoCo", "SciPy"
    method: str                      # "es K=3", "vi", "MuJoCo RK4", "SciPy DOP853", ...
    variant: str                     # Newton variant of ours, "-" for peers
    setting: str                     # "dt = 0.01 s", "rtol = atol = 1e-08"
    t_end: float
    dt: float | None = None
    tolerance: float | None = None
    n_steps: int | None = None
    step_seconds: float | None = None
    run_seconds: float | None = None
    energy_error: float | None = None
    constraint_error: float | None = None
    trajectory_error: float | None = None
    early_trajectory_error: float | None = None   # at EARLY_T
    newton_iterations: float | None = None
    step_over_evaluation: float | None = None
    failure: str | None = None

    @property
    def t_realtime(self) -> float | None:
        return None if self.run_seconds is None else self.run_seconds / self.t_end

    @property
    def line(self) -> str:
        """The curve of a plot this row belongs to."""
        return self.method if self.variant in ("-", VARIANTS[0].label) else \
            f"{self.method} ({self.variant})"


@dataclass(frozen=True)
class ScalingRow:
    """One scheme at one n of the scaling series (one row per Newton variant)."""

    method: str
    n: int
    variant: str
    generate_seconds: float | None = None
    build_seconds: float | None = None
    generate_peak_mb: float | None = None
    compile_peak_mb: float | None = None
    model_c_bytes: int | None = None
    dt: float | None = None
    step_seconds: float | None = None
    newton_iterations: float | None = None
    mujoco_step_seconds: float | None = None
    failure: str | None = None

    @property
    def generate_and_build_seconds(self) -> float | None:
        if self.generate_seconds is None or self.build_seconds is None:
            return None
        return self.generate_seconds + self.build_seconds

    @property
    def ratio(self) -> float | None:
        if self.step_seconds is None or not self.mujoco_step_seconds:
            return None
        return self.step_seconds / self.mujoco_step_seconds


def method_label(scene: Scene, method: str, quadrature: int) -> str:
    return f"{method} K={quadrature}" if uses_quadrature(scene, method) else method


def angle_error(phi, reference) -> float:
    """max_i |phi_i - reference_i| with each difference wrapped to [-pi, pi)."""
    difference = np.asarray(phi, dtype=float) - np.asarray(reference, dtype=float)
    return float(np.max(np.abs(np.remainder(difference + np.pi, 2 * np.pi) - np.pi)))


def _steps(t_end: float, dt: float) -> int:
    return round(t_end / dt)


# --------------------------------------------------------------------------------------------
# Our schemes
# --------------------------------------------------------------------------------------------

def scheme_configurations(scene: Scene, config: BenchConfig) -> list[tuple[str, int]]:
    """(method, quadrature) pairs to run: es at each K if the scene has springs (K applies to
    nothing else), vi and midpoint once."""
    pairs = []
    for method in config.methods:
        if uses_quadrature(scene, method):
            pairs += [(method, k) for k in config.quadratures]
        else:
            pairs.append((method, max(config.quadratures)))
    return pairs


def scheme_rows(scene: Scene, name: str, config: BenchConfig, t_end: float,
                reference_angles, progress) -> list[RunRow]:
    rows = []
    phi0, omega0 = scene.initial_angles, scene.initial_velocities
    for method, quadrature in scheme_configurations(scene, config):
        label = method_label(scene, method, quadrature)
        package = generate_package(scene, method, quadrature, sensitivities=False)
        solver = Solver.from_files(package.files)
        x0 = solver.initial_state(phi0, omega0)
        dts = config.dts
        if name == HEADLINE_SCENE and method == "es":
            dts = tuple(dt for dt in BRACKET_DTS if _divides(dt, t_end)
                        and dt not in dts) + dts
        with Harness(package, flags=HARNESS_FLAGS) as harness:
            for dt in dts:
                n_steps = _steps(t_end, dt)
                for variant in VARIANTS:
                    base = dict(scene=name, family="chaingen", method=label, variant=variant.label,
                                setting=f"dt = {dt:g} s", t_end=t_end, dt=dt, n_steps=n_steps)
                    try:
                        solver.reset()     # each run starts without Newton history
                        options = variant.newton_options(solver)
                        result = solver.simulate(phi0, omega0, dt=dt, n_steps=n_steps, every=1,
                                                 options=options)
                        timings = harness.time(x0, dt, n_steps=n_steps, repeats=config.repeats,
                                               options=variant.options)
                    except (NewtonError, HarnessError) as error:
                        rows.append(RunRow(**base, failure=str(error).splitlines()[0]))
                        progress(f"{name} {label} dt={dt:g} ({variant.label}): failed: {error}")
                        continue
                    step = timings.step_ns * 1e-9
                    trajectory = (angle_error(result.phi[-1], reference_angles[0])
                                  if reference_angles[0] is not None else None)
                    early_t = min(EARLY_T, t_end)
                    early = (angle_error(result.phi[_steps(early_t, dt)], reference_angles[1])
                             if reference_angles[1] is not None and _divides(dt, early_t)
                             else None)
                    row = RunRow(
                        **base, step_seconds=step, run_seconds=step * n_steps,
                        energy_error=float(np.abs(result.energy_error).max()),
                        constraint_error=(None if method == "midpoint"
                                          else float(result.constraint_error.max())),
                        trajectory_error=trajectory, early_trajectory_error=early,
                        newton_iterations=timings.mean_iterations,
                        step_over_evaluation=timings.step_over_evaluation)
                    rows.append(row)
                    progress(f"{name} {label} dt={dt:g} ({variant.label}): "
                             f"{step * 1e6:.2f} us/step, energy {row.energy_error:.1e}")
    return rows


# --------------------------------------------------------------------------------------------
# MuJoCo
# --------------------------------------------------------------------------------------------

def _mujoco_model(scene: Scene, dt: float, integrator: str):
    from .mujoco_reference import _model_and_data
    return _model_and_data(scene, dt, integrator)


def mujoco_step_seconds(scene: Scene, integrator: str, dt: float, n_steps: int,
                        repeats: int) -> float:
    """CPU seconds per step of one mj_step(nstep=N) call, N = min(n_steps, MUJOCO_TIMED_STEPS),
    from the scene's initial state; median of `repeats`."""
    import mujoco

    model, data = _mujoco_model(scene, dt, integrator)
    timed = max(1, min(n_steps, MUJOCO_TIMED_STEPS))
    times = []
    for _ in range(repeats):
        mujoco.mj_resetData(model, data)
        data.qpos[:] = scene.initial_angles
        data.qvel[:] = scene.initial_velocities
        mujoco.mj_forward(model, data)
        start = time.process_time()
        mujoco.mj_step(model, data, nstep=timed)
        times.append(time.process_time() - start)
    return float(np.median(times)) / timed


def mujoco_accuracy(scene: Scene, integrator: str, dt: float,
                    n_steps: int, early_step: int | None = None):
    """(max |H - H_0| over every step, final qpos, failure or None, qpos after early_step steps
    or None) of an untimed run.

    A run fails when the state turns non-finite or MuJoCo raises a warning (it resets the
    state on a bad acceleration and carries on, so the warning is the only trace)."""
    import mujoco

    from .mujoco_reference import _energy

    model, data = _mujoco_model(scene, dt, integrator)
    energies = np.empty(n_steps + 1)
    energies[0] = _energy(data)
    early = None
    step, forward = mujoco.mj_step, mujoco.mj_forward
    for k in range(1, n_steps + 1):
        step(model, data)
        forward(model, data)     # mjData.energy at the new state (see mujoco_reference)
        energies[k] = data.energy[0] + data.energy[1]
        if k == early_step:
            early = np.array(data.qpos)
    warnings = [name for name, warning in mujoco.mjtWarning.__members__.items()
                if name != "mjNWARNING" and data.warning[int(warning)].number]
    failure = None
    if warnings:
        failure = f"MuJoCo warning {', '.join(warnings)} (unstable)"
    elif not (np.all(np.isfinite(energies)) and np.all(np.isfinite(data.qpos))):
        failure = "NaN in the state (unstable)"
    return float(np.abs(energies - energies[0]).max()), np.array(data.qpos), failure, early


def mujoco_rows(scene: Scene, name: str, config: BenchConfig, t_end: float,
                reference_angles, progress) -> list[RunRow]:
    rows = []
    for integrator in config.mujoco_integrators:
        for dt in config.mujoco_dts:
            n_steps = _steps(t_end, dt)
            base = dict(scene=name, family="MuJoCo", method=f"MuJoCo {integrator}", variant="-",
                        setting=f"dt = {dt:g} s", t_end=t_end, dt=dt, n_steps=n_steps)
            early_t = min(EARLY_T, t_end)
            early_step = _steps(early_t, dt) if _divides(dt, early_t) else None
            energy, angles, failure, early = mujoco_accuracy(scene, integrator, dt, n_steps,
                                                             early_step)
            if failure:
                rows.append(RunRow(**base, failure=failure))
                progress(f"{name} MuJoCo {integrator} dt={dt:g}: {failure}")
                continue
            step = mujoco_step_seconds(scene, integrator, dt, n_steps, config.repeats)
            rows.append(RunRow(
                **base, step_seconds=step, run_seconds=step * n_steps, energy_error=energy,
                trajectory_error=(angle_error(angles, reference_angles[0])
                                  if reference_angles[0] is not None else None),
                early_trajectory_error=(angle_error(early, reference_angles[1])
                                        if reference_angles[1] is not None
                                        and early is not None else None)))
            progress(f"{name} MuJoCo {integrator} dt={dt:g}: {step * 1e6:.2f} us/step, "
                     f"energy {energy:.1e}")
    return rows


# --------------------------------------------------------------------------------------------
# SciPy
# --------------------------------------------------------------------------------------------

def scipy_rows(scene: Scene, name: str, config: BenchConfig, t_end: float,
               reference_angles, progress) -> list[RunRow]:
    from .scipy_peer import ScipyPeerError, simulate_scipy

    rows = []
    for method, tolerances in config.scipy_tolerances:
        for tolerance in tolerances:
            base = dict(scene=name, family="SciPy", method=f"SciPy {method}", variant="-",
                        setting=f"rtol = atol = {tolerance:.0e}", t_end=t_end,
                        tolerance=tolerance)
            try:
                run = simulate_scipy(scene, method, tolerance, tolerance, t_end)
                cpu = [run.cpu_time]
                while len(cpu) < config.scipy_repeats and run.cpu_time < SCIPY_REPEAT_BELOW:
                    cpu.append(simulate_scipy(scene, method, tolerance, tolerance,
                                              t_end).cpu_time)
            except ScipyPeerError as error:
                rows.append(RunRow(**base, failure=str(error)))
                progress(f"{name} SciPy {method} tol={tolerance:.0e}: failed: {error}")
                continue
            run_seconds = float(np.median(cpu))
            early = None
            if reference_angles[1] is not None:
                try:   # untimed: the same integrator and tolerance up to the early time
                    early = angle_error(simulate_scipy(scene, method, tolerance, tolerance,
                                                       min(EARLY_T, t_end)).final_angles,
                                        reference_angles[1])
                except ScipyPeerError:
                    early = None
            rows.append(RunRow(
                **base, n_steps=run.n_steps, step_seconds=run_seconds / max(run.n_steps, 1),
                run_seconds=run_seconds, energy_error=run.max_energy_error,
                trajectory_error=(angle_error(run.final_angles, reference_angles[0])
                                  if reference_angles[0] is not None else None),
                early_trajectory_error=early))
            progress(f"{name} SciPy {method} tol={tolerance:.0e}: {run_seconds * 1e3:.1f} ms, "
                     f"{run.n_steps} steps, energy {run.max_energy_error:.1e}")
    return rows


def reference_angles_at_end(scene: Scene, t_end: float, progress):
    """phi(t_end) by codegen.scipy_peer.reference_solution, or None if it cannot be had."""
    from .scipy_peer import ScipyPeerError, reference_solution
    try:
        angles, _ = reference_solution(scene, t_end)
    except ScipyPeerError as error:
        progress(f"{scene.name}: no trajectory reference: {error}")
        return None
    return angles


def reference_study(config: BenchConfig, progress, emit) -> dict[str, list[RunRow]]:
    """Part 1: every scheme and peer on each reference scene."""
    study = {}
    for name in config.scenes:
        scene = load_scene(ROOT / "scenes" / f"{name}.toml")
        t_end = config.t_end or scene.simulation.t_end
        reference = (reference_angles_at_end(scene, t_end, progress),
                     reference_angles_at_end(scene, min(EARLY_T, t_end), progress))
        rows = scheme_rows(scene, name, config, t_end, reference, progress)
        rows += mujoco_rows(scene, name, config, t_end, reference, progress)
        rows += scipy_rows(scene, name, config, t_end, reference, progress)
        study[name] = rows
        emit(f"\n{name} (t_end = {t_end:g} s)\n\n{reference_table(rows)}")
    return study


# --------------------------------------------------------------------------------------------
# Scaling
# --------------------------------------------------------------------------------------------

def _numeric_initial_state(scheme, scene: Scene) -> np.ndarray:
    values = dict(zip(scheme.initial_angles, scene.initial_angles))
    values.update(zip(scheme.initial_velocities, scene.initial_velocities))
    return np.array([float(entry.subs(values).evalf()) for entry in scheme.initial_state])


def peak_resident_kib() -> int | None:
    """Peak resident memory of this process image (VmHWM of /proc/self/status, KiB).

    Not getrusage's ru_maxrss: Linux carries that over fork and execve, so a process started
    from a large one (subprocess uses vfork) reports its parent's peak as its own."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return None


def _compiler_with_peak(directory: Path) -> tuple[Path, Path] | None:
    """A wrapper of the C compiler that appends the compiler's peak RSS (KiB, gcc and the
    passes it waits for) to a file, by GNU time run from a small process; (wrapper, file),
    or None without /usr/bin/time."""
    program = shutil.which("time", path="/usr/bin:/bin")
    if program is None:
        return None
    wrapper, peaks = directory / "cc-with-peak", directory / "compiler-peaks"
    wrapper.write_text(f"#!/bin/sh\nexec {shlex.quote(program)} -f %M -a -o "
                       f"{shlex.quote(str(peaks))} {shlex.quote(compiler())} \"$@\"\n")
    wrapper.chmod(0o755)
    return wrapper, peaks


def measure_scaling_point(method: str, quadrature: int, n: int, *, n_steps: int,
                          repeats: int) -> dict:
    """Generate, build and time scaling_scene(n) with one scheme; run in a child process.

    generate_seconds: SymPy scheme, CasADi functions and rendering (generate_package's work,
    done as build_scheme + render_package to keep the scheme for the initial state).
    generate_peak_kb: this process's peak RSS after generating (Python, SymPy, CasADi and the
    expressions); compile_peak_kb: the compiler's peak RSS (via _compiler_with_peak; None if
    it cannot be measured). Per-step time at the first of SCALING_DTS at which no step fails.
    """
    from .schemes import build_scheme

    scene = scaling_scene(n)
    started = time.perf_counter()
    scheme = build_scheme(scene, method, quadrature)
    package = render_package(scheme, sensitivities=False)
    generate_seconds = time.perf_counter() - started
    generate_peak = peak_resident_kib()
    x0 = _numeric_initial_state(scheme, scene)
    timings = {}
    scratch = Path(tempfile.mkdtemp(prefix="compiler-peak-"))
    measured_compiler = _compiler_with_peak(scratch)
    previous_cc = os.environ.get("CC")
    try:
        if measured_compiler is not None:
            os.environ["CC"] = str(measured_compiler[0])   # read by the harness's build
        harness = Harness(package, flags=HARNESS_FLAGS)
    finally:
        if previous_cc is None:
            os.environ.pop("CC", None)
        else:
            os.environ["CC"] = previous_cc
    compile_peak = None
    if measured_compiler is not None and measured_compiler[1].exists():
        compile_peak = max(int(line) for line in measured_compiler[1].read_text().split())
    shutil.rmtree(scratch, ignore_errors=True)
    with harness:
        for variant in VARIANTS:
            failures = []
            for dt in SCALING_DTS:
                try:
                    measured = harness.time(x0, dt, n_steps=n_steps, repeats=repeats,
                                            options=variant.options)
                except HarnessError as error:
                    failures.append(f"dt = {dt:g} s: {error}")
                    continue
                timings[variant.label] = {"dt": dt, "step_ns": measured.step_ns,
                                          "iterations": measured.mean_iterations,
                                          "failures": failures}
                break
            else:
                timings[variant.label] = {"failures": failures}
        build_seconds = harness.build_seconds
    return {"generate_seconds": generate_seconds, "build_seconds": build_seconds,
            "generate_peak_kb": generate_peak, "compile_peak_kb": compile_peak,
            "model_c_bytes": len(package.files[f"{package.prefix}_model.c"].encode()),
            "timings": timings}


def run_scaling_point(method: str, quadrature: int, n: int, config: BenchConfig) -> dict:
    """measure_scaling_point in a child process (its own session, so that on timeout the
    compiler it started is stopped with it); {"failure": ...} if it fails or runs over."""
    program = ("import json\nfrom codegen.bench import measure_scaling_point\n"
               f"print(json.dumps(measure_scaling_point({method!r}, {quadrature}, {n}, "
               f"n_steps={config.scaling_steps}, repeats={config.repeats})))\n")
    # The child's temporary files (the harness's build directory) go to a directory of ours,
    # removed afterwards even when the child had to be killed before cleaning up.
    with tempfile.TemporaryDirectory(prefix="chaingen-bench-") as scratch:
        child = subprocess.Popen([sys.executable, "-c", program], stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True, cwd=ROOT,
                                 env={**os.environ, "TMPDIR": scratch}, start_new_session=True)
        try:
            stdout, stderr = child.communicate(timeout=config.timeout)
        except subprocess.TimeoutExpired:
            os.killpg(child.pid, signal.SIGKILL)
            child.communicate()
            return {"failure": f"over limit: generate + build did not finish within "
                               f"{config.timeout:g} s"}
    if child.returncode != 0:
        last = (stderr.strip().splitlines() or ["no message"])[-1]
        return {"failure": f"exit {child.returncode}: {last}"}
    return json.loads(stdout.strip().splitlines()[-1])


def _mebibytes(kib: int | None) -> float | None:
    return None if kib is None else kib / 1024


def _predicted_over_limit(n: int, seconds: float, config: BenchConfig) -> str | None:
    """Why the next n of the series cannot fit the limit, or None if it may.

    Generating and building grow at least like n^2 (the Newton Jacobian is dense, with
    (nz)^2 entries and nz proportional to n), so t(n') >= t(n) (n'/n)^2 is a lower bound:
    a size it puts over the limit is not started."""
    larger = [m for m in config.scaling_ns if m > n]
    if not larger:
        return None
    bound = seconds * (larger[0] / n) ** 2
    if bound <= config.timeout:
        return None
    return (f"not run: generate + build took {seconds:.0f} s at n = {n}, and grows at least "
            f"like n^2 (dense Newton Jacobian), so n = {larger[0]} would need >= {bound:.0f} s, "
            f"over the {config.timeout:g} s limit")


def scaling_study(config: BenchConfig, progress, emit) -> list[ScalingRow]:
    """Part 3: each scheme at each n, with MuJoCo RK4 at the same n and dt. A scheme that runs
    over the time limit at some n is not run at larger n."""
    rows = []
    mujoco_cache: dict[tuple[int, float], float] = {}

    def mujoco_step(n: int, dt: float) -> float:
        if (n, dt) not in mujoco_cache:
            mujoco_cache[(n, dt)] = mujoco_step_seconds(
                scaling_scene(n), "RK4", dt, config.scaling_steps, config.repeats)
        return mujoco_cache[(n, dt)]

    for method, quadrature in config.scaling_methods:
        skip_reason = None
        for n in config.scaling_ns:
            label = method_label(scaling_scene(n), method, quadrature)
            if skip_reason is not None:
                rows += [ScalingRow(label, n, variant.label, failure=skip_reason)
                         for variant in VARIANTS]
                progress(f"scaling {label} n={n}: {skip_reason}")
                continue
            started = time.perf_counter()
            point = run_scaling_point(method, quadrature, n, config)
            if "failure" not in point:
                seconds = point["generate_seconds"] + point["build_seconds"]
                skip_reason = _predicted_over_limit(n, seconds, config)
            if "failure" in point:
                if point["failure"].startswith("over limit"):
                    skip_reason = f"not run: over the limit at n = {n}"
                rows += [ScalingRow(label, n, variant.label, failure=point["failure"])
                         for variant in VARIANTS]
                progress(f"scaling {label} n={n}: {point['failure']}")
                continue
            for variant in VARIANTS:
                timing = point["timings"][variant.label]
                common = dict(
                    generate_seconds=point["generate_seconds"],
                    build_seconds=point["build_seconds"],
                    generate_peak_mb=_mebibytes(point["generate_peak_kb"]),
                    compile_peak_mb=_mebibytes(point["compile_peak_kb"]),
                    model_c_bytes=point["model_c_bytes"])
                if "dt" not in timing:
                    rows.append(ScalingRow(label, n, variant.label, **common,
                                           failure="; ".join(timing["failures"])))
                    continue
                note = ("; ".join(timing["failures"]) or None)
                rows.append(ScalingRow(
                    label, n, variant.label, **common, dt=timing["dt"],
                    step_seconds=timing["step_ns"] * 1e-9,
                    newton_iterations=timing["iterations"],
                    mujoco_step_seconds=mujoco_step(n, timing["dt"]), failure=note))
            progress(f"scaling {label} n={n}: generate {point['generate_seconds']:.1f} s, "
                     f"build {point['build_seconds']:.1f} s "
                     f"({time.perf_counter() - started:.0f} s in all)")
    emit(f"\nscaling series\n\n{scaling_table(rows)}")
    return rows


# --------------------------------------------------------------------------------------------
# Headlines
# --------------------------------------------------------------------------------------------

def interpolate_cost(points, target: float) -> float | None:
    """CPU cost at error `target` by log-log interpolation along work-precision points.

    points: (cost, error) pairs, both > 0 (others are ignored). Taken in order of cost, the
    first (cheapest) pair of neighbours whose errors bracket `target` is interpolated:
    log cost is linear in log error between them. None when no pair brackets `target`, that
    is when it is outside the measured errors: never extrapolated.
    """
    usable = sorted((c, e) for c, e in points if c > 0 and e > 0)
    log_target = math.log(target)
    for (c0, e0), (c1, e1) in zip(usable, usable[1:]):
        if e0 == target:
            return c0
        if (e0 - target) * (e1 - target) <= 0:
            if e1 == e0:
                return c0
            fraction = (log_target - math.log(e0)) / (math.log(e1) - math.log(e0))
            return math.exp(math.log(c0) + fraction * (math.log(c1) - math.log(c0)))
    if len(usable) == 1 and usable[0][1] == target:
        return usable[0][0]
    return None


@dataclass(frozen=True)
class Headline:
    key: str
    claim: str
    variant: str
    measured: str          # the value with what it was computed from
    target: str
    passed: bool | None    # None: not measured

    @property
    def mark(self) -> str:
        return {True: "pass", False: "FAIL", None: "not measured"}[self.passed]


def _find(rows, **match) -> RunRow | None:
    for row in rows:
        if all(getattr(row, key) == value for key, value in match.items()):
            return row
    return None


def _us(seconds: float) -> str:
    return f"{seconds * 1e6:.2f} us"


def _step_ratio_headline(key: str, claim: str, rows, method: str, variant: Variant,
                         target: float) -> Headline:
    ours = _find(rows, method=method, variant=variant.label, dt=HEADLINE_DT)
    peer = _find(rows, method="MuJoCo RK4", dt=HEADLINE_DT)
    target_text = f"<= {target:g}"
    if ours is None or peer is None:
        missing = "our run" if ours is None else "MuJoCo RK4"
        return Headline(key, claim, variant.label, f"{missing} at dt = {HEADLINE_DT:g} s not in "
                        "this run", target_text, None)
    if ours.failure or peer.failure:
        return Headline(key, claim, variant.label,
                        f"failed: {ours.failure or peer.failure}", target_text, False)
    ratio = ours.step_seconds / peer.step_seconds
    return Headline(key, claim, variant.label,
                    f"{ratio:.3f} ({_us(ours.step_seconds)} / {_us(peer.step_seconds)})",
                    target_text, ratio <= target)


def equal_error_headline(rows, variant: Variant, es_method: str) -> Headline:
    """c: CPU time of SciPy DOP853 / CPU time of es at energy error TARGET_EQUAL_ERROR."""
    claim = (f"SciPy DOP853 CPU / {es_method} CPU at equal energy error "
             f"{TARGET_EQUAL_ERROR:.0e} J, standard run")
    target_text = f">= {TARGET_SCIPY_OVER_ES:g}"

    def points(method: str, variant_label: str):
        return [(row.run_seconds, row.energy_error) for row in rows
                if row.method == method and row.variant == variant_label and not row.failure]

    es_points = points(es_method, variant.label)
    scipy_points = points("SciPy DOP853", "-")
    if not es_points or not scipy_points:
        return Headline("c", claim, variant.label, "runs missing from this run", target_text,
                        None)
    scipy_cost = interpolate_cost(scipy_points, TARGET_EQUAL_ERROR)
    errors = [e for _, e in scipy_points]
    if scipy_cost is None:
        return Headline("c", claim, variant.label,
                        f"DOP853's energy errors ({min(errors):.1e} .. {max(errors):.1e} J) do "
                        f"not reach {TARGET_EQUAL_ERROR:.0e}: not measured", target_text, None)
    es_cost = interpolate_cost(es_points, TARGET_EQUAL_ERROR)
    if es_cost is not None:
        ratio = scipy_cost / es_cost
        return Headline("c", claim, variant.label,
                        f"{ratio:.1f} ({scipy_cost * 1e3:.2f} ms / {es_cost * 1e3:.2f} ms, both "
                        "interpolated)", target_text, ratio >= TARGET_SCIPY_OVER_ES)
    es_errors = [e for _, e in es_points]
    if max(es_errors) < TARGET_EQUAL_ERROR:
        # Every es run is more accurate than the target: the cheapest one reaches it, so its
        # cost bounds es's cost at the target from above and the ratio from below.
        cheapest_cost, cheapest_error = min(es_points)
        ratio = scipy_cost / cheapest_cost
        return Headline("c", claim, variant.label,
                        f">= {ratio:.1f} (lower bound: {scipy_cost * 1e3:.2f} ms interpolated / "
                        f"{cheapest_cost * 1e3:.2f} ms, {es_method}'s cheapest run, which is "
                        f"already at {cheapest_error:.1e} J; every {es_method} run is below "
                        f"{TARGET_EQUAL_ERROR:.0e})", target_text,
                        True if ratio >= TARGET_SCIPY_OVER_ES else None)
    return Headline("c", claim, variant.label,
                    f"{es_method}'s energy errors ({min(es_errors):.1e} .. {max(es_errors):.1e} "
                    f"J) do not reach {TARGET_EQUAL_ERROR:.0e}: not measured", target_text, None)


def headlines(reference: dict[str, list[RunRow]], scaling: list[ScalingRow] | None,
              config: BenchConfig) -> list[Headline]:
    """Rows a-e of the issue, one per Newton variant, from this run's measurements."""
    rows = reference.get(HEADLINE_SCENE, [])
    scene = load_scene(ROOT / "scenes" / f"{HEADLINE_SCENE}.toml")
    es = method_label(scene, "es", 3)
    where = f"{HEADLINE_SCENE}, dt = {HEADLINE_DT:g} s"
    found = []
    for variant in VARIANTS:
        found.append(_step_ratio_headline(
            "a", f"{es} step / MuJoCo RK4 step, {where}", rows, es, variant, TARGET_RATIO_ES))
        es_row = _find(rows, method=es, variant=variant.label, dt=HEADLINE_DT)
        if es_row is None or es_row.failure:
            measured = es_row.failure if es_row else "not in this run"
            found.append(Headline("a", f"{es} max energy error, {where}", variant.label,
                                  measured, f"<= {TARGET_ENERGY_ES:.0e} J", None))
        else:
            found.append(Headline("a", f"{es} max energy error, {where}", variant.label,
                                  f"{es_row.energy_error:.2e} J", f"<= {TARGET_ENERGY_ES:.0e} J",
                                  es_row.energy_error <= TARGET_ENERGY_ES))
        found.append(_step_ratio_headline(
            "b", f"vi step / MuJoCo RK4 step, {where}", rows, "vi", variant, TARGET_RATIO_VI))
        es_labels = [label for label in dict.fromkeys(row.method for row in rows)
                     if label.split()[0] == "es"] or [es]
        found += [equal_error_headline(rows, variant, label) for label in es_labels]
        found += scaling_headlines(scaling, variant)
        if es_row is None or es_row.failure:
            found.append(Headline("e", f"{es} step / one residual-and-Jacobian evaluation, "
                                  f"{where}", variant.label, "not in this run",
                                  f"<= {TARGET_STEP_OVER_EVALUATION:g}", None))
        else:
            ratio = es_row.step_over_evaluation
            found.append(Headline(
                "e", f"{es} step / one residual-and-Jacobian evaluation, {where}",
                variant.label, f"{ratio:.2f} ({_us(es_row.step_seconds)} / "
                f"{_us(es_row.step_seconds / ratio)})",
                f"<= {TARGET_STEP_OVER_EVALUATION:g}", ratio <= TARGET_STEP_OVER_EVALUATION))
    return sorted(found, key=lambda headline: headline.key)   # stable: variants stay in order


def scaling_headlines(scaling: list[ScalingRow] | None, variant: Variant) -> list[Headline]:
    es = "es K=3"
    claims = (f"{es} generate + build seconds, scaling series n = {HEADLINE_N}",
              f"{es} step / MuJoCo RK4 step, scaling series n = {HEADLINE_N}")
    targets = (f"<= {TARGET_BUILD_SECONDS:g} s", f"<= {TARGET_SCALING_RATIO:g}")
    row = None
    if scaling is not None:
        row = next((r for r in scaling if r.method == es and r.n == HEADLINE_N
                    and r.variant == variant.label), None)
    if row is None:
        reason = ("scaling series skipped" if scaling is None
                  else f"n = {HEADLINE_N} not in the scaling series")
        return [Headline("d", claim, variant.label, reason, target, None)
                for claim, target in zip(claims, targets)]
    found = []
    seconds = row.generate_and_build_seconds
    if seconds is None:
        found.append(Headline("d", claims[0], variant.label, f"failed: {row.failure}",
                              targets[0], False))
    else:
        found.append(Headline("d", claims[0], variant.label,
                              f"{seconds:.1f} s ({row.generate_seconds:.1f} s generate + "
                              f"{row.build_seconds:.1f} s build)", targets[0],
                              seconds <= TARGET_BUILD_SECONDS))
    ratio = row.ratio
    if ratio is None:
        found.append(Headline("d", claims[1], variant.label, f"failed: {row.failure}",
                              targets[1], False))
    else:
        found.append(Headline("d", claims[1], variant.label,
                              f"{ratio:.2f} ({_us(row.step_seconds)} / "
                              f"{_us(row.mujoco_step_seconds)}, dt = {row.dt:g} s)",
                              targets[1], ratio <= TARGET_SCALING_RATIO))
    return found


# --------------------------------------------------------------------------------------------
# Tables, figures, the document
# --------------------------------------------------------------------------------------------

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
            f"{_sci(row.early_trajectory_error)} | {_fixed(row.newton_iterations)} | {_fixed(row.step_over_evaluation)} | "
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
                      "model over 1 MB -O1), each source in its own compiler process, as "
                      "chaingen's build does; the Solver used for the errors is that build"),
        ("MuJoCo", f"{version('mujoco')} (PyPI wheel, its own build flags)"),
        ("SciPy", f"{version('scipy')} (right-hand side and Jacobian: CasADi C compiled by "
                  "codegen.scipy_peer with the runtime's default flags; integrator in Python)"),
        ("Python", platform.python_version()),
        ("numpy, sympy, casadi, matplotlib",
         f"{version('numpy')}, {version('sympy')}, {version('casadi')}, "
         f"{version('matplotlib')}"),
    ]


def _figure():
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    return Figure, FigureCanvasAgg


MARKERS = "osD^vP*Xhp<>"


def _save(figure, path: Path) -> Path:
    """Write the PNG via a temporary file in the same directory, then rename."""
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=".png", dir=path.parent)
    os.close(handle)
    try:
        figure.savefig(temporary)
        os.chmod(temporary, 0o666 & ~current_umask())   # mkstemp's 0600 is not what users expect
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
    return path


def _line_style(family: str, method_index: int, variant: str) -> dict:
    """Colour and marker per method; ours solid, MuJoCo dashed, SciPy dotted; a Newton variant
    other than the defaults dash-dotted with hollow markers."""
    style = {"color": f"C{method_index % 10}", "marker": MARKERS[method_index % len(MARKERS)],
             "linestyle": {"chaingen": "-", "MuJoCo": "--", "SciPy": ":"}[family],
             "linewidth": 1.2, "markersize": 5}
    if variant not in ("-", VARIANTS[0].label):
        style.update(linestyle="-.", markerfacecolor="none")
    return style


def plot_work_precision(name: str, rows: list[RunRow], path: Path) -> Path:
    """Two log-log panels: max energy error and the trajectory error at EARLY_T (the one that
    measures accuracy; see EARLY_T) against the CPU time of the whole run; one line per method
    and Newton variant."""
    Figure, Canvas = _figure()
    figure = Figure(figsize=(13.0, 5.5), dpi=100)
    Canvas(figure)
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
                    "MuJoCo: dashed, SciPy: dotted)")
    figure.tight_layout()
    return _save(figure, path)


def plot_scaling(rows: list[ScalingRow], path: Path) -> Path:
    """Per-step time against n (ours and MuJoCo RK4), and generate + build time against n."""
    from matplotlib.ticker import NullFormatter

    Figure, Canvas = _figure()
    figure = Figure(figsize=(13.0, 5.0), dpi=100)
    Canvas(figure)
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


def _link(figure: Path, document: Path) -> str:
    return Path(os.path.relpath(figure, document.parent)).as_posix()


HOW_MEASURED = """\
- CPU time is process time of the compiled loop only, the median of repeats: ours from a C
  program calling the generated step over the whole run (`codegen.bench_harness`), MuJoCo from
  one `mj_step(model, data, nstep=N)` call (at most {mujoco_steps} steps a repeat: its cost per
  step does not depend on the state), SciPy from `solve_ivp` alone (right-hand side and
  Jacobian compiled; its steps and their error control run in Python). Run CPU = per step x
  steps for ours and MuJoCo; t_realtime = run CPU / simulated time.
- Max energy error: max |H - H_0| over every step of the run (SciPy: over its accepted steps).
  Trajectory error: max_i |phi_i(t) - phi_ref,i(t)|, each difference wrapped to [-pi, pi),
  against SciPy DOP853 at rtol = atol = 2.2e-14 (`codegen.scipy_peer`), at t_end and at
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


def knob_study(config: BenchConfig, progress, emit) -> list:
    """The speed knobs (codegen.bench_knobs): every scheme on the headline scene at the
    headline dt, and the compiler knobs of "es" on the largest chain of the scaling series."""
    scene = load_scene(ROOT / "scenes" / f"{HEADLINE_SCENE}.toml")
    t_end = config.t_end or scene.simulation.t_end
    rows = []
    for method in METHODS:
        rows += bench_knobs.option_rows(scene, HEADLINE_SCENE, method, 3, HEADLINE_DT, t_end,
                                        n_steps=2000, repeats=config.repeats,
                                        progress=progress)
    if config.run_scaling:
        n = max(config.scaling_ns)
        rows += bench_knobs.flag_rows_large(scaling_scene(n), f"scaling n = {n}",
                                            HEADLINE_DT, n_steps=config.scaling_steps // 2,
                                            repeats=config.repeats, progress=progress)
    emit(f"\nspeed knobs\n\n{bench_knobs.knob_table(rows)}")
    return rows


def markdown(config: BenchConfig, found: list[Headline], reference, scaling,
             figures: dict[str, Path], machine, wall_seconds: float, knobs=()) -> str:
    lines = ["# Benchmarks: speed against accuracy", "",
             f"Written by `{config.command}` in {wall_seconds / 60:.1f} min of wall time on "
             f"{time.strftime('%Y-%m-%d')}. Every number and figure comes from that run; nothing "
             "is edited by hand." + (" **Quick mode**: a smoke test with short runs and few "
                                     "series, not the benchmark." if config.quick else ""),
             "", "## Headline", "",
             "The issue's targets, measured side by side in this run (a-c, e on "
             f"{HEADLINE_SCENE}, standard run; d on the scaling series).", "",
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
    if scaling is not None:
        lines += ["## Scaling", "",
                  "`codegen.bench.scaling_scene(n)`: n identical links (1 kg, 0.4 m), g = 9.81, "
                  "a mono-articular spring across every joint and one multi-articular spring "
                  "over joints 1..min(n, 3). Generate (SymPy, CasADi, rendering) and build "
                  "(gcc with the package's per-source flags, sources compiled side by side) "
                  "run in a child process with a limit of "
                  f"{config.timeout:g} s; a scheme over the limit, or that the lower bound "
                  "t(n') >= t(n) (n'/n)^2 puts over it, is not run at larger n. "
                  "Peak RSS: of the generating Python process (VmHWM), and of the compiler "
                  "with the passes it runs (GNU time). "
                  f"Per step: {config.scaling_steps} steps from the initial state.", "",
                  f"![scaling]({_link(figures['scaling'], config.out)})", "",
                  scaling_table(scaling), ""]
    if knobs:
        lines += ["## Speed knobs", "", KNOBS_TEXT.format(scene=HEADLINE_SCENE, dt=HEADLINE_DT),
                  "", bench_knobs.knob_table(knobs), ""]
    return "\n".join(lines).rstrip() + "\n"


KNOBS_TEXT = """\
One knob changed at a time against the package defaults, on {scene} at dt = {dt} s (step time
of the C loop, median of repeats; energy error over the standard run with the same options), and
the compiler knobs again on the largest chain of the scaling series, where the dense LU and the
size of the generated model dominate. The package defaults are warm start, Newton-chord (the
Jacobian evaluated and factorised once a step, reused within it) for "es" and "midpoint" and
simplified Newton (reused across steps) for "vi", tolerances update_rtol = 1e-10, update_atol =
1e-13, residual_tol = 1e-8, the solver source at -O3 and a generated model larger than 1 MB at
-O1. "step / (F, dF/dz)" is the step's time in units of one residual-and-Jacobian evaluation.
Not measured: constants baked into the code against run-time parameters; every scene number is
baked into the generated code (no parameter vector exists yet to compare against)."""


def write_atomically(path: Path, text: str) -> Path:
    """Write `text` to a temporary file next to `path`, then rename it into place."""
    handle, temporary = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    try:
        with os.fdopen(handle, "w") as stream:
            stream.write(text)
        os.chmod(temporary, 0o666 & ~current_umask())
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
    return path


@dataclass(frozen=True)
class BenchReport:
    headlines: list
    reference: dict
    scaling: list | None
    document: Path
    figures: dict
    wall_seconds: float


def run_bench(config: BenchConfig, *, progress=None, emit=print) -> BenchReport:
    """Run every part of `config`, then write the figures and the document (in that order, so
    that a failure leaves the previous document in place)."""
    started = time.perf_counter()
    with Progress("bench", total=0) as bar:
        if progress is None:   # a status line on a terminal; silent in logs, in CI, --quiet
            def progress(message: str) -> None:
                bar.stage(message)
        return _run_bench(config, progress, emit, started)


def _run_bench(config: BenchConfig, progress, emit, started: float) -> BenchReport:
    machine = machine_description()
    reference = reference_study(config, progress, emit) if config.run_reference else {}
    scaling = scaling_study(config, progress, emit) if config.run_scaling else None
    knobs = knob_study(config, progress, emit)
    found = headlines(reference, scaling, config)
    emit(f"\nheadline\n\n{headline_table(found)}")
    figures = {}
    for name, rows in reference.items():
        figures[name] = plot_work_precision(name, rows, config.figures / f"bench_{name}.png")
    if scaling is not None:
        figures["scaling"] = plot_scaling(scaling, config.figures / "bench_scaling.png")
    wall = time.perf_counter() - started
    document = write_atomically(config.out, markdown(config, found, reference, scaling,
                                                     figures, machine, wall, knobs))
    emit(f"\nwrote {document} and {len(figures)} figures in {config.figures} "
         f"({wall / 60:.1f} min)")
    return BenchReport(found, reference, scaling, document, figures, wall)
