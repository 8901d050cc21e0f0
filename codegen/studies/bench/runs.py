"""Part 1 of the benchmark: every scheme and peer on each reference scene, one row a run.

How each side is timed (CPU time, process clock, the compiled loop only):

- ours: the harness, a C program that calls <prefix>_step for the whole run (median of
  repeats); run CPU = per step x steps. Energy and constraint errors come from a separate
  Solver.simulate run of the same package (every step sampled).
- MuJoCo: one mj_step(model, data, nstep=N) call under time.process_time(), median of repeats.
  MuJoCo's cost per step does not depend on the state (no iterations), so at most
  MUJOCO_TIMED_STEPS steps are timed per repeat. Errors from an untimed run that evaluates
  mjData.energy (energy flag) after every step.
- SciPy: ScipyRun.cpu_time of simulate_scipy (solve_ivp alone; the right-hand side and
  Jacobian are compiled C), per step = cpu_time / accepted steps; energy error over the
  accepted steps.
- compiled peers (numbalsoda LSODA and DOP853 on the same compiled right-hand side, CVODES
  BDF and Adams through CasADi): ScipyRun.cpu_time of simulate_compiled (the one integrator
  call; numba's compilation warmed up before), median of up to `repeats` runs; per step where
  the library counts steps (CVODES); energy error over samples every 0.01 s.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ...errors import NewtonError, ScipyPeerError
from ...generate.package import generate_package
from ...runtime import Solver
from ...scene import Scene, quadrature_used
from ...scene.labels import scheme_label
from .config import (
    ADAPTIVE_BRACKET_DTS,
    ADAPTIVE_SCENE,
    BRACKET_DTS,
    EARLY_T,
    HARNESS_FLAGS,
    HEADLINE_SCENE,
    MUJOCO_TIMED_STEPS,
    SCIPY_REPEAT_BELOW,
    VARIANTS,
    BenchConfig,
    divides_evenly,
    steps,
)
from .harness import Harness, HarnessError

#: The family of the compiled peers (numbalsoda, CVODES) in rows, tables and figures.
COMPILED_FAMILY = "compiled"


@dataclass(frozen=True)
class RunRow:
    """One run on a reference scene: a scheme or peer at one dt or tolerance."""

    scene: str
    family: str                      # "chaingen", "MuJoCo", "SciPy", COMPILED_FAMILY
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


def method_label(scene: Scene, method: str, quadrature: int, order: int = 2) -> str:
    return scheme_label(method, quadrature_used(scene, method, quadrature, order), style="short")


def angle_error(phi, reference) -> float:
    """max_i |phi_i - reference_i| with each difference wrapped to [-pi, pi)."""
    difference = np.asarray(phi, dtype=float) - np.asarray(reference, dtype=float)
    return float(np.max(np.abs(np.remainder(difference + np.pi, 2 * np.pi) - np.pi)))


def run_errors(result, method: str, t_end: float, dt: float, reference_angles) -> dict:
    """The error fields of a RunRow from a run of ours (samples every dt): the energy and
    constraint errors over the run, the trajectory errors at t_end and at EARLY_T against
    reference_angles (None where there is no reference or dt does not divide the time)."""
    early_t = min(EARLY_T, t_end)
    return dict(
        energy_error=float(np.abs(result.energy_error).max()),
        constraint_error=(None if method == "midpoint"
                          else float(result.constraint_error.max())),
        trajectory_error=(angle_error(result.phi[-1], reference_angles[0])
                          if reference_angles[0] is not None else None),
        early_trajectory_error=(angle_error(result.phi[steps(early_t, dt)], reference_angles[1])
                                if reference_angles[1] is not None and divides_evenly(dt, early_t)
                                else None))


def scheme_configurations(scene: Scene, config: BenchConfig) -> list[tuple[str, int]]:
    """(method, quadrature) pairs to run: es at each K if the scene has springs (K applies to
    nothing else), vi and midpoint once."""
    pairs = []
    for method in config.methods:
        if quadrature_used(scene, method, 3) is not None:
            pairs += [(method, k) for k in config.quadratures]
        else:
            pairs.append((method, max(config.quadratures)))
    return pairs


def scheme_rows(scene: Scene, name: str, config: BenchConfig, t_end: float,
                reference_angles, note) -> list[RunRow]:
    rows = []
    phi0, omega0 = scene.initial_angles, scene.initial_velocities
    for method, quadrature in scheme_configurations(scene, config):
        label = method_label(scene, method, quadrature)
        package = generate_package(scene, method, quadrature, sensitivities=False)
        solver = Solver.from_files(package.files)
        x0 = solver.initial_state(phi0, omega0)
        dts = config.dts
        if name == HEADLINE_SCENE and method == "es":
            dts = tuple(dt for dt in BRACKET_DTS if divides_evenly(dt, t_end)
                        and dt not in dts) + dts
        if name == ADAPTIVE_SCENE and method == "es" and not config.quick:
            dts = dts + tuple(dt for dt in ADAPTIVE_BRACKET_DTS if divides_evenly(dt, t_end)
                              and dt not in dts)
        with Harness(package, flags=HARNESS_FLAGS) as harness:
            for dt in dts:
                n_steps = steps(t_end, dt)
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
                        note(f"{name} {label} dt={dt:g} ({variant.label}): failed: {error}")
                        continue
                    step = timings.step_ns * 1e-9
                    row = RunRow(
                        **base, step_seconds=step, run_seconds=step * n_steps,
                        newton_iterations=timings.mean_iterations,
                        step_over_evaluation=timings.step_over_evaluation,
                        **run_errors(result, method, t_end, dt, reference_angles))
                    rows.append(row)
                    note(f"{name} {label} dt={dt:g} ({variant.label}): "
                             f"{step * 1e6:.2f} us/step, energy {row.energy_error:.1e}")
    return rows



def mujoco_model(scene: Scene, dt: float, integrator: str):
    from ...reference.mujoco_runs import mujoco_model_and_data
    return mujoco_model_and_data(scene, dt, integrator)


def mujoco_step_seconds(scene: Scene, integrator: str, dt: float, n_steps: int,
                        repeats: int) -> float:
    """CPU seconds per step of one mj_step(nstep=N) call, N = min(n_steps, MUJOCO_TIMED_STEPS),
    from the scene's initial state; median of `repeats`."""
    import mujoco

    model, data = mujoco_model(scene, dt, integrator)
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

    from ...reference.mujoco_runs import mujoco_energy

    model, data = mujoco_model(scene, dt, integrator)
    energies = np.empty(n_steps + 1)
    energies[0] = mujoco_energy(data)
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
                reference_angles, note) -> list[RunRow]:
    rows = []
    for integrator in config.mujoco_integrators:
        for dt in config.mujoco_dts:
            n_steps = steps(t_end, dt)
            base = dict(scene=name, family="MuJoCo", method=f"MuJoCo {integrator}", variant="-",
                        setting=f"dt = {dt:g} s", t_end=t_end, dt=dt, n_steps=n_steps)
            early_t = min(EARLY_T, t_end)
            early_step = steps(early_t, dt) if divides_evenly(dt, early_t) else None
            energy, angles, failure, early = mujoco_accuracy(scene, integrator, dt, n_steps,
                                                             early_step)
            if failure:
                rows.append(RunRow(**base, failure=failure))
                note(f"{name} MuJoCo {integrator} dt={dt:g}: {failure}")
                continue
            step = mujoco_step_seconds(scene, integrator, dt, n_steps, config.repeats)
            rows.append(RunRow(
                **base, step_seconds=step, run_seconds=step * n_steps, energy_error=energy,
                trajectory_error=(angle_error(angles, reference_angles[0])
                                  if reference_angles[0] is not None else None),
                early_trajectory_error=(angle_error(early, reference_angles[1])
                                        if reference_angles[1] is not None
                                        and early is not None else None)))
            note(f"{name} MuJoCo {integrator} dt={dt:g}: {step * 1e6:.2f} us/step, "
                     f"energy {energy:.1e}")
    return rows



def _tolerance_rows(scene: Scene, name: str, t_end: float, reference_angles, note, *,
                    simulate, family: str, label: str, method: str, tolerances,
                    repeats: int) -> list[RunRow]:
    """Rows of one peer that integrates to a tolerance (simulate_scipy's signature and record):
    run CPU the median of up to `repeats` runs shorter than SCIPY_REPEAT_BELOW, the early
    trajectory error from a second, untimed run to EARLY_T. A record without a step count
    (n_steps 0) gives a row without steps and per-step time."""
    rows = []
    for tolerance in tolerances:
        base = dict(scene=name, family=family, method=label, variant="-",
                    setting=f"rtol = atol = {tolerance:.0e}", t_end=t_end, tolerance=tolerance)
        try:
            run = simulate(scene, method, tolerance, tolerance, t_end)
            cpu = [run.cpu_time]
            while len(cpu) < repeats and run.cpu_time < SCIPY_REPEAT_BELOW:
                cpu.append(simulate(scene, method, tolerance, tolerance, t_end).cpu_time)
        except ScipyPeerError as error:
            rows.append(RunRow(**base, failure=str(error)))
            note(f"{name} {label} tol={tolerance:.0e}: failed: {error}")
            continue
        run_seconds = float(np.median(cpu))
        early = None
        if reference_angles[1] is not None:
            try:   # untimed: the same integrator and tolerance up to the early time
                early = angle_error(simulate(scene, method, tolerance, tolerance,
                                             min(EARLY_T, t_end)).final_angles,
                                    reference_angles[1])
            except ScipyPeerError:
                early = None
        n_steps = run.n_steps or None
        rows.append(RunRow(
            **base, n_steps=n_steps,
            step_seconds=run_seconds / n_steps if n_steps else None,
            run_seconds=run_seconds, energy_error=run.max_energy_error,
            trajectory_error=(angle_error(run.final_angles, reference_angles[0])
                              if reference_angles[0] is not None else None),
            early_trajectory_error=early))
        note(f"{name} {label} tol={tolerance:.0e}: {run_seconds * 1e3:.1f} ms, "
                 f"{run.n_steps or 'uncounted'} steps, energy {run.max_energy_error:.1e}")
    return rows


def scipy_rows(scene: Scene, name: str, config: BenchConfig, t_end: float,
               reference_angles, note) -> list[RunRow]:
    from ...reference.scipy_peer import simulate_scipy

    rows = []
    for method, tolerances in config.scipy_tolerances:
        rows += _tolerance_rows(scene, name, t_end, reference_angles, note,
                                simulate=simulate_scipy, family="SciPy",
                                label=f"SciPy {method}", method=method, tolerances=tolerances,
                                repeats=config.scipy_repeats)
    return rows


def compiled_rows(scene: Scene, name: str, config: BenchConfig, t_end: float,
                  reference_angles, note) -> list[RunRow]:
    """The compiled peers (chaingen.reference.compiled_peers), family COMPILED_FAMILY, each
    run repeated like ours (config.repeats) since they take milliseconds. Without numbalsoda
    its methods get one row each that says so instead of runs."""
    from ...reference.compiled_peers import (
        NUMBALSODA_METHODS,
        PEERS_EXTRA,
        numbalsoda_available,
        simulate_compiled,
    )

    rows = []
    for method, tolerances in config.compiled_tolerances:
        if method in NUMBALSODA_METHODS and not numbalsoda_available():
            missing = f"not run: numbalsoda is not installed (pip install -e '.[{PEERS_EXTRA}]')"
            rows.append(RunRow(scene=name, family=COMPILED_FAMILY, method=method, variant="-",
                               setting="-", t_end=t_end, failure=missing))
            note(f"{name} {method}: {missing}")
            continue
        rows += _tolerance_rows(scene, name, t_end, reference_angles, note,
                                simulate=simulate_compiled, family=COMPILED_FAMILY,
                                label=method, method=method, tolerances=tolerances,
                                repeats=config.repeats)
    return rows


def reference_angles_at_end(scene: Scene, t_end: float, note):
    """phi(t_end) by the SciPy peer's reference_solution, or None if it cannot be had."""
    from ...reference.scipy_peer import reference_solution
    try:
        angles, _ = reference_solution(scene, t_end)
    except ScipyPeerError as error:
        note(f"{scene.name}: no trajectory reference: {error}")
        return None
    return angles
