"""The stiff chain's work-precision (issue 32 g): ours against the compiled peers and MuJoCo on
the scaling chain of config.stiff.n links with every spring at config.stiff.stiffness, over
config.stiff.t_end s from its initial state.

Two errors per run, each against its CPU time:

- the trajectory error: max_i |phi_i(t_end) - phi_ref,i|, each difference wrapped to
  [-pi, pi), against SciPy DOP853 at rtol = atol = config.stiff.reference_rtol;
- the energy error: max |H - H_0| over the run, relative to the energy: divided by E_ref, the
  largest |H| along the reference (one scale for every row, so that MuJoCo's own potential
  datum plays no role). Ours and MuJoCo: over every step (adaptive es: over its samples);
  the compiled peers: over samples every config.stiff.energy_sample s of a second, untimed
  run with the same tolerance.

CPU as on the reference scenes (runs module): ours the harness's step loop (median of
repeats), adaptive es process time around Solver.simulate (median of repeats), MuJoCo one
mj_step(nstep) call, the compiled peers their one integrator call (samples every 0.01 s).
"""
from __future__ import annotations

import dataclasses
import statistics
import time
from dataclasses import dataclass

import numpy as np

from ...errors import NewtonError, ScipyPeerError
from ...generate.package import generate_package
from ...runtime import Solver
from ...scene import Scene
from ...scene.labels import scheme_label
from ...scene.solver_rules import gradient_used, quadrature_used
from .config import HARNESS_FLAGS, SCIPY_REPEAT_BELOW, BenchConfig, StiffSettings, steps
from .harness import Harness, HarnessError
from .runs import COMPILED_FAMILY, angle_error, mujoco_accuracy, mujoco_step_seconds
from .scenes import scaling_scene

#: The peers of the stiff chain, in the order of the table.
PEER_METHODS = ("CVODES-BDF", "CVODES-Adams", "numbalsoda-LSODA", "numbalsoda-DOP853")


def stiff_scene(n: int, stiffness: float) -> Scene:
    """scaling_scene(n) (the scaling series' chain) with every spring, mono- and
    multi-articular, at `stiffness` N/m; named stiff-chain-<n>."""
    scene = scaling_scene(n)
    springs = tuple(dataclasses.replace(spring, stiffness=float(stiffness))
                    for spring in scene.springs)
    return dataclasses.replace(scene, springs=springs, name=f"stiff-chain-{n}")


@dataclass(frozen=True)
class StiffRow:
    """One run on the stiff chain."""

    family: str                       # "chaingen", "MuJoCo", COMPILED_FAMILY
    method: str                       # "es K=3", "es K=3 quadrature order 4", "CVODES-BDF", ...
    setting: str                      # "dt = 0.001 s", "rtol = atol = 1e-08"
    dt: float | None = None
    tolerance: float | None = None
    n_steps: int | None = None
    step_seconds: float | None = None
    run_seconds: float | None = None
    trajectory_error: float | None = None
    energy_error: float | None = None            # J
    relative_energy_error: float | None = None   # energy_error / E_ref
    newton_iterations: float | None = None
    failure: str | None = None

    def holds(self, trajectory: float | None, energy: float | None) -> bool:
        """Whether the run completed with both errors at most the given levels (None: any)."""
        if self.failure or self.run_seconds is None:
            return False
        for level, value in ((trajectory, self.trajectory_error),
                             (energy, self.relative_energy_error)):
            if level is not None and (value is None or value > level):
                return False
        return True


@dataclass(frozen=True)
class StiffStudy:
    """The part's rows and what they are measured against."""

    scene_name: str
    settings: StiffSettings
    energy_scale: float               # E_ref, J
    reference_spread: float | None    # |phi_ref - phi(DOP853 at SciPy's tightest)| [rad]
    rows: list[StiffRow]
    seconds: float                    # wall time of the part


def stiff_label(scene: Scene, method: str, order: int, quadrature: int, gradient: str) -> str:
    return scheme_label(method, quadrature_used(scene, method, quadrature, order), order,
                        style="short", gradient=gradient_used(scene, method, gradient, order))


def _our_rows(scene: Scene, settings: StiffSettings, config: BenchConfig, reference, scale,
              note) -> list[StiffRow]:
    rows = []
    phi0, omega0 = scene.initial_angles, scene.initial_velocities
    for method, order, quadrature, gradient, dts in settings.schemes:
        label = stiff_label(scene, method, order, quadrature, gradient)
        package = generate_package(scene, method, quadrature, sensitivities=False, order=order,
                                   gradient=gradient)
        solver = Solver.from_files(package.files)
        x0 = solver.initial_state(phi0, omega0)
        with Harness(package, flags=HARNESS_FLAGS) as harness:
            for dt in dts:
                n_steps = steps(settings.t_end, dt)
                base = dict(family="chaingen", method=label, setting=f"dt = {dt:g} s", dt=dt,
                            n_steps=n_steps)
                try:
                    solver.reset()
                    result = solver.simulate(phi0, omega0, dt=dt, n_steps=n_steps)
                    timings = harness.time(x0, dt, n_steps=n_steps, repeats=config.repeats)
                except (NewtonError, HarnessError) as error:
                    rows.append(StiffRow(**base, failure=str(error).splitlines()[0]))
                    note(f"stiff chain {label} dt={dt:g}: failed: {error}")
                    continue
                step = timings.step_ns * 1e-9
                energy = float(np.abs(result.energy_error).max())
                rows.append(StiffRow(
                    **base, step_seconds=step, run_seconds=step * n_steps,
                    trajectory_error=angle_error(result.phi[-1], reference),
                    energy_error=energy, relative_energy_error=energy / scale,
                    newton_iterations=timings.mean_iterations))
                note(f"stiff chain {label} dt={dt:g}: {step * n_steps * 1e3:.2f} ms")
    for method, order, quadrature, tolerances in settings.adaptive:
        label = f"{stiff_label(scene, method, order, quadrature, 'exact')} adaptive"
        package = generate_package(scene, method, quadrature, sensitivities=False, order=order)
        solver = Solver.from_files(package.files)
        dt = settings.adaptive_sample
        n_steps = steps(settings.t_end, dt)
        for tolerance in tolerances:
            base = dict(family="chaingen", method=label, tolerance=tolerance,
                        setting=f"rtol = atol = {tolerance:.0e}, samples every {dt:g} s")
            cpu = []
            try:
                for _ in range(config.repeats):
                    solver.reset()
                    started = time.process_time()
                    result = solver.simulate(phi0, omega0, dt=dt, n_steps=n_steps,
                                             options={"rtol": tolerance, "atol": tolerance})
                    cpu.append(time.process_time() - started)
            except NewtonError as error:
                rows.append(StiffRow(**base, failure=str(error).splitlines()[0]))
                note(f"stiff chain {label} rtol={tolerance:g}: failed: {error}")
                continue
            run = statistics.median(cpu)
            energy = float(np.abs(result.energy_error).max())
            rows.append(StiffRow(
                **base, n_steps=result.accepted_steps, step_seconds=run / result.accepted_steps,
                run_seconds=run, trajectory_error=angle_error(result.phi[-1], reference),
                energy_error=energy, relative_energy_error=energy / scale,
                newton_iterations=result.newton_iterations / result.accepted_steps))
            note(f"stiff chain {label} rtol={tolerance:g}: {run * 1e3:.2f} ms")
    return rows


def _mujoco_rows(scene: Scene, settings: StiffSettings, config: BenchConfig, reference, scale,
                 note) -> list[StiffRow]:
    rows = []
    for integrator, dts in settings.mujoco:
        for dt in dts:
            n_steps = steps(settings.t_end, dt)
            base = dict(family="MuJoCo", method=f"MuJoCo {integrator}", setting=f"dt = {dt:g} s",
                        dt=dt, n_steps=n_steps)
            energy, angles, failure, _ = mujoco_accuracy(scene, integrator, dt, n_steps)
            if failure:
                rows.append(StiffRow(**base, failure=failure))
                note(f"stiff chain MuJoCo {integrator} dt={dt:g}: {failure}")
                continue
            step = mujoco_step_seconds(scene, integrator, dt, n_steps, config.repeats)
            rows.append(StiffRow(**base, step_seconds=step, run_seconds=step * n_steps,
                                 trajectory_error=angle_error(angles, reference),
                                 energy_error=energy, relative_energy_error=energy / scale))
            note(f"stiff chain MuJoCo {integrator} dt={dt:g}: {step * n_steps * 1e3:.2f} ms")
    return rows


def _peer_rows(scene: Scene, settings: StiffSettings, config: BenchConfig, reference, scale,
               note) -> list[StiffRow]:
    from ...reference.compiled_peers import (
        NUMBALSODA_METHODS,
        PEERS_EXTRA,
        numbalsoda_available,
        simulate_compiled,
    )

    rows = []
    t_end = settings.t_end
    grid = np.linspace(0.0, t_end, steps(t_end, settings.energy_sample) + 1)
    for method in PEER_METHODS:
        if method in NUMBALSODA_METHODS and not numbalsoda_available():
            missing = f"not run: numbalsoda is not installed (pip install -e '.[{PEERS_EXTRA}]')"
            rows.append(StiffRow(family=COMPILED_FAMILY, method=method, setting="-",
                                 failure=missing))
            note(f"stiff chain {method}: {missing}")
            continue
        for tolerance in settings.peer_tolerances:
            base = dict(family=COMPILED_FAMILY, method=method, tolerance=tolerance,
                        setting=f"rtol = atol = {tolerance:.0e}")
            try:
                run = simulate_compiled(scene, method, tolerance, tolerance, t_end)
                cpu = [run.cpu_time]
                while len(cpu) < config.repeats and run.cpu_time < SCIPY_REPEAT_BELOW:
                    cpu.append(simulate_compiled(scene, method, tolerance, tolerance,
                                                 t_end).cpu_time)
                sampled = simulate_compiled(scene, method, tolerance, tolerance, t_end, grid)
            except ScipyPeerError as error:
                rows.append(StiffRow(**base, failure=str(error)))
                note(f"stiff chain {method} tol={tolerance:.0e}: failed: {error}")
                continue
            seconds = float(np.median(cpu))
            energy = max(run.max_energy_error, sampled.max_energy_error)
            n_steps = run.n_steps or None
            rows.append(StiffRow(
                **base, n_steps=n_steps, step_seconds=seconds / n_steps if n_steps else None,
                run_seconds=seconds, trajectory_error=angle_error(run.final_angles, reference),
                energy_error=energy, relative_energy_error=energy / scale))
            note(f"stiff chain {method} tol={tolerance:.0e}: {seconds * 1e3:.2f} ms")
    return rows


def stiff_study(config: BenchConfig, note) -> StiffStudy:
    """The part: the reference, then ours, MuJoCo and the compiled peers (config.stiff)."""
    from ...reference.scipy_peer import reference_solution, simulate_scipy

    started = time.perf_counter()
    settings = config.stiff
    scene = stiff_scene(settings.n, settings.stiffness)
    note(f"stiff chain: reference (DOP853 at {settings.reference_rtol:g})")
    grid = np.linspace(0.0, settings.t_end, steps(settings.t_end, settings.energy_sample) + 1)
    run = simulate_scipy(scene, "DOP853", settings.reference_rtol, settings.reference_rtol,
                         settings.t_end, grid)
    reference = np.array(run.final_angles)
    scale = float(np.abs(run.energies).max())
    try:
        tighter, _ = reference_solution(scene, settings.t_end)
        spread = angle_error(tighter, reference)
    except ScipyPeerError:
        spread = None
    arguments = (scene, settings, config, reference, scale, note)
    rows = _our_rows(*arguments) + _peer_rows(*arguments) + _mujoco_rows(*arguments)
    return StiffStudy(scene.name, settings, scale, spread, rows,
                      time.perf_counter() - started)


def cheapest(rows: list[StiffRow], families: tuple[str, ...], trajectory: float | None,
             energy: float | None) -> StiffRow | None:
    """The measured run of `families` with the least CPU that holds both levels (None: any),
    or None where none does."""
    held = [row for row in rows if row.family in families and row.holds(trajectory, energy)]
    return min(held, key=lambda row: row.run_seconds, default=None)
