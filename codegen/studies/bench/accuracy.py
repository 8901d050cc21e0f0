"""Part 1, the accurate end: our steps of order 4 and 6 and our adaptive steps, then the whole
reference study (every scheme and peer on each reference scene).

- Composed steps (docs/model.md, section 14) are timed like the order-2 rows (runs.scheme_rows):
  the harness's step loop, with the package's default Newton options, at HIGHER_ORDER_DTS.
- Adaptive steps (docs/model.md, section 15) vary their step, so there is no step loop to time:
  their CPU is time.process_time() around Solver.simulate (the C loop, one call, samples every
  ADAPTIVE_SAMPLE s), median of `repeats` runs. The per-step time is that over the accepted
  steps. The samples' outputs are a small part of it (one per ADAPTIVE_SAMPLE s against steps
  of milliseconds).
"""
from __future__ import annotations

import statistics
import time

from ...errors import NewtonError
from ...generate.package import generate_package
from ...runtime import Solver
from ...scene import Scene, load_reference_scene, quadrature_used
from ...scene.labels import scheme_label
from .config import (
    ADAPTIVE_SAMPLE,
    EARLY_T,
    HARNESS_FLAGS,
    BenchConfig,
    steps,
)
from .harness import Harness, HarnessError
from .runs import (
    RunRow,
    compiled_rows,
    mujoco_rows,
    reference_angles_at_end,
    run_errors,
    scheme_rows,
    scipy_rows,
)


def order_label(scene: Scene, method: str, quadrature: int, order: int) -> str:
    """The line of a configuration of ours: "es K=5 order 4"; order 2 as runs.method_label."""
    return scheme_label(method, quadrature_used(scene, method, quadrature, order), order,
                        style="short")


def higher_order_rows(scene: Scene, name: str, config: BenchConfig, t_end: float,
                      reference_angles, note) -> list[RunRow]:
    """Composed steps of order 4 and 6 (config.higher_orders), default Newton options."""
    rows = []
    phi0, omega0 = scene.initial_angles, scene.initial_velocities
    for method, order, quadrature in config.higher_orders:
        label = order_label(scene, method, quadrature, order)
        package = generate_package(scene, method, quadrature, sensitivities=False, order=order)
        solver = Solver.from_files(package.files)
        x0 = solver.initial_state(phi0, omega0)
        with Harness(package, flags=HARNESS_FLAGS) as harness:
            for dt in config.higher_order_dts:
                n_steps = steps(t_end, dt)
                base = dict(scene=name, family="chaingen", method=label,
                            variant="default options", setting=f"dt = {dt:g} s", t_end=t_end,
                            dt=dt, n_steps=n_steps)
                try:
                    solver.reset()
                    result = solver.simulate(phi0, omega0, dt=dt, n_steps=n_steps)
                    timings = harness.time(x0, dt, n_steps=n_steps, repeats=config.repeats)
                except (NewtonError, HarnessError) as error:
                    rows.append(RunRow(**base, failure=str(error).splitlines()[0]))
                    note(f"{name} {label} dt={dt:g}: failed: {error}")
                    continue
                step = timings.step_ns * 1e-9
                row = RunRow(**base, step_seconds=step, run_seconds=step * n_steps,
                             newton_iterations=timings.mean_iterations,
                             step_over_evaluation=timings.step_over_evaluation,
                             **run_errors(result, method, t_end, dt, reference_angles))
                rows.append(row)
                note(f"{name} {label} dt={dt:g}: {step * 1e6:.2f} us/step, "
                         f"energy {row.energy_error:.1e}")
    return rows


def adaptive_rows(scene: Scene, name: str, config: BenchConfig, t_end: float,
                  reference_angles, note) -> list[RunRow]:
    """Adaptive steps (config.adaptive_runs: method, order, K, tolerances), rtol = atol,
    samples every ADAPTIVE_SAMPLE s."""
    rows = []
    phi0, omega0 = scene.initial_angles, scene.initial_velocities
    dt = ADAPTIVE_SAMPLE
    n_steps = steps(t_end, dt)
    for method, order, quadrature, tolerances in config.adaptive_runs:
        label = f"{order_label(scene, method, quadrature, order)} adaptive"
        package = generate_package(scene, method, quadrature, sensitivities=False, order=order)
        solver = Solver.from_files(package.files)
        for tolerance in tolerances:
            base = dict(scene=name, family="chaingen", method=label, variant="default options",
                        setting=f"rtol = atol = {tolerance:g}, samples every {dt:g} s",
                        t_end=t_end, dt=dt, n_steps=n_steps)
            options = {"rtol": tolerance, "atol": tolerance}
            cpu = []
            try:
                for _ in range(config.repeats):
                    solver.reset()
                    started = time.process_time()
                    result = solver.simulate(phi0, omega0, dt=dt, n_steps=n_steps,
                                             options=options)
                    cpu.append(time.process_time() - started)
            except NewtonError as error:
                rows.append(RunRow(**base, failure=str(error).splitlines()[0]))
                note(f"{name} {label} rtol={tolerance:g}: failed: {error}")
                continue
            run = statistics.median(cpu)
            row = RunRow(**base, step_seconds=run / result.accepted_steps, run_seconds=run,
                         newton_iterations=result.newton_iterations / result.accepted_steps,
                         **run_errors(result, method, t_end, dt, reference_angles))
            rows.append(row)
            note(f"{name} {label} rtol={tolerance:g}: {run * 1e3:.1f} ms, "
                     f"{result.accepted_steps} steps ({result.rejected_steps} refused, dt "
                     f"{result.smallest_dt:.2g} .. {result.largest_dt:.2g} s), energy "
                     f"{row.energy_error:.1e}")
    return rows


def reference_study(config: BenchConfig, note, emit) -> dict[str, list[RunRow]]:
    """Part 1: every scheme and peer on each reference scene; emit(name, t_end, rows) after
    each scene."""
    study = {}
    for name in config.scenes:
        scene = load_reference_scene(name)
        t_end = config.t_end or scene.simulation.t_end
        reference = (reference_angles_at_end(scene, t_end, note),
                     reference_angles_at_end(scene, min(EARLY_T, t_end), note))
        rows = scheme_rows(scene, name, config, t_end, reference, note)
        rows += higher_order_rows(scene, name, config, t_end, reference, note)
        rows += adaptive_rows(scene, name, config, t_end, reference, note)
        rows += mujoco_rows(scene, name, config, t_end, reference, note)
        rows += scipy_rows(scene, name, config, t_end, reference, note)
        rows += compiled_rows(scene, name, config, t_end, reference, note)
        study[name] = rows
        emit(name, t_end, rows)
    return study
