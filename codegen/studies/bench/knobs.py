"""The speed knobs of a generated solver, each measured against the package defaults.

Part of `chaingen bench`: on the headline scene at the headline dt, every scheme is timed (C
loop, the harness module) with one knob changed at a time: the first Newton guess (warm
start against the scheme's predictor), full against simplified Newton, the Newton tolerances,
and the compiler flags of the solver source. Each row also has the energy error of the standard
run with the same options, so a knob's speed is always read next to what it costs in accuracy.
On the largest scaling chain the compiler knobs are measured again, where they matter: the
optimisation level of the solver (its LU) and of the large generated model.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ...errors import NewtonError
from ...generate.package import GeneratedPackage, generate_package
from ...runtime import (
    JACOBIAN_ACROSS_STEPS,
    JACOBIAN_EVERY_ITERATE,
    JACOBIAN_PER_STEP,
    Solver,
)
from ...scene import Scene
from .harness import Harness, HarnessError

#: (label, Newton option fields) of the option knobs; {} is the package defaults.
OPTION_KNOBS = (
    ("package defaults", {}),
    ("cold start: scheme predictor", {"warm_start": 0}),
    ("full Newton", {"reuse_jacobian": JACOBIAN_EVERY_ITERATE}),
    ("simplified Newton", {"reuse_jacobian": JACOBIAN_ACROSS_STEPS}),
    ("Newton-chord: Jacobian once a step", {"reuse_jacobian": JACOBIAN_PER_STEP}),
    ("loose tolerances (1e-6)", {"update_rtol": 1e-6, "update_atol": 1e-9,
                                 "residual_tol": 1e-6}),
    ("tight tolerances (1e-12)", {"update_rtol": 1e-12, "update_atol": 1e-15,
                                  "residual_tol": 1e-10, "max_iterations": 40}),
)
#: (label, flags of the solver source) of the compiler knob; the first is the default.
SOLVER_FLAG_KNOBS = (("solver -O3 (default)", None), ("solver -O2", ("-O2",)),
                     ("solver -O3 -march=native", ("-O3", "-march=native")))
#: The large model's optimisation levels compared at the largest chain.
MODEL_FLAG_KNOBS = (("model -O1 (default when large)", None), ("model -O2", ("-O2",)))


@dataclass(frozen=True)
class KnobRow:
    scene: str
    method: str
    knob: str
    step_seconds: float | None
    iterations: float | None
    step_over_evaluation: float | None
    energy_error: float | None
    build_seconds: float | None = None
    failure: str | None = None


def with_source_flags(package: GeneratedPackage, name: str, flags) -> GeneratedPackage:
    """The package with `flags` for source `name` (None: as generated)."""
    if flags is None:
        return package
    manifest = {**package.manifest,
                "source_flags": {**package.manifest.get("source_flags", {}), name: list(flags)}}
    return dataclasses.replace(package, manifest=manifest)


def option_rows(scene: Scene, name: str, method: str, quadrature: int, dt: float,
                t_end: float, *, n_steps: int, repeats: int, note) -> list[KnobRow]:
    """The option knobs and solver flags of one scheme on one scene."""
    package = generate_package(scene, method, quadrature, sensitivities=False)
    solver = Solver.from_files(package.files)
    x0 = solver.initial_state(scene.initial_angles, scene.initial_velocities)
    steps = int(round(t_end / dt))
    rows = []
    with Harness(package) as harness:
        for label, fields in OPTION_KNOBS:
            note(f"knobs: {name} {method} {label}")
            rows.append(_row(name, method, label, harness, solver, x0, dt, fields, steps,
                             n_steps, repeats, scene))
    for label, flags in SOLVER_FLAG_KNOBS[1:]:
        note(f"knobs: {name} {method} {label}")
        variant = with_source_flags(package, f"{package.prefix}.c", flags)
        with Harness(variant) as harness:
            rows.append(_row(name, method, label, harness, None, x0, dt, {}, steps, n_steps,
                             repeats, scene))
    return rows


def _row(name, method, label, harness, solver, x0, dt, fields, steps, n_steps, repeats,
         scene, build_seconds=None) -> KnobRow:
    try:
        timing = harness.time(x0, dt, n_steps=n_steps, repeats=repeats, options=fields)
    except HarnessError as error:
        return KnobRow(name, method, label, None, None, None, None, build_seconds, str(error))
    energy = None
    if solver is not None:
        try:
            result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=dt,
                                     n_steps=steps, options=solver.newton_options(fields))
            energy = float(np.abs(result.energy_error).max())
        except NewtonError as error:
            return KnobRow(name, method, label, timing.step_ns * 1e-9, timing.mean_iterations,
                           timing.step_over_evaluation, None, build_seconds, str(error))
    return KnobRow(name, method, label, timing.step_ns * 1e-9, timing.mean_iterations,
                   timing.step_over_evaluation, energy, build_seconds)


def flag_rows_large(scene: Scene, name: str, dt: float, *, n_steps: int, repeats: int,
                    note) -> list[KnobRow]:
    """Compiler knobs of "es" K=3 on a large chain: solver and model optimisation, with the
    build time each costs."""
    package = generate_package(scene, "es", 3, sensitivities=False)
    x0 = Solver.from_files(package.files).initial_state(scene.initial_angles,
                                                         scene.initial_velocities)
    model = f"{package.prefix}_model.c"
    rows = []
    knobs = [(label, f"{package.prefix}.c", flags) for label, flags in SOLVER_FLAG_KNOBS]
    if model in package.manifest.get("source_flags", {}):
        knobs += [(label, model, flags) for label, flags in MODEL_FLAG_KNOBS[1:]]
    for label, source, flags in knobs:
        note(f"knobs: {name} es {label}")
        with Harness(with_source_flags(package, source, flags)) as harness:
            for fields, suffix in (({}, ""), ({"reuse_jacobian": JACOBIAN_ACROSS_STEPS},
                                              ", simplified Newton")):
                rows.append(_row(name, "es K=3", label + suffix, harness, None, x0, dt, fields,
                                 0, n_steps, repeats, scene, harness.build_seconds))
    return rows


def _cell(value, fmt) -> str:
    return "-" if value is None else format(value, fmt)


def knob_table(rows: list[KnobRow]) -> str:
    lines = ["| scene | method | knob | step (us) | Newton its/step | step / (F, dF/dz) | "
             "energy error (J) | build (s) |", "|---|---|---|---|---|---|---|---|"]
    for row in rows:
        step = _cell(None if row.step_seconds is None else row.step_seconds * 1e6, ".3g")
        if row.failure:
            step = f"failed: {row.failure.splitlines()[0]}"
        lines.append(f"| {row.scene} | {row.method} | {row.knob} | {step} | "
                     f"{_cell(row.iterations, '.2f')} | {_cell(row.step_over_evaluation, '.2f')} | "
                     f"{_cell(row.energy_error, '.2g')} | {_cell(row.build_seconds, '.1f')} |")
    return "\n".join(lines)
