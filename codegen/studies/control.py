"""The passivity study: the discrete-gradient control law against the sampled one, measured.

    python -m chaingen.studies.control [SCENE] [--t-end T] [--quick] [--rows]

For a scene with a [control] table (default: scenes/four_link_pbc.toml), runs the closed loop at
several dt and gain scales (every stiffness and damping gain times s) with the discrete law in es
and the sampled law (zero-order hold from the step's start) in es and midpoint, and prints one
Markdown table: the final posture error against the target, the largest rise of the closed
loop's storage max_k H_d(k) - H_d(0) (the discrete law's is zero: H_d never increases), and the
worst closed-loop balance |H_d(k+1) - H_d(k) - work + dissipated| of a step. A run whose step
fails, or whose posture error grows past 1 rad, is marked unstable. Nothing is hard-coded: every
figure is the run's. docs/controllers.md shows its output.

Also `predicted_equilibrium`: where the theory says a partly actuated closed loop settles, the
stationary point of V + V_s near a guess, from the scene's numpy potential
(chaingen.scene.kinematics), independent of the generated code.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
from dataclasses import dataclass

import numpy as np

from ..errors import ChaingenError, NewtonError
from ..runtime.solver import MAX_SAMPLE_BYTES
from ..scene import Scene, kinematics
from ..simulation import build_solver
from ..spatial import dynamics
from ..spatial.reader import load_either_scene
from ..spatial.values import SpatialScene
from ..symbolic.schemes.base import actuated_joints

#: The runs of the table: (label, method, law).
LAWS = (("discrete, es", "es", "discrete"), ("sampled, es", "es", "sampled"),
        ("discrete, midpoint", "midpoint", "discrete"),
        ("sampled, midpoint", "midpoint", "sampled"))
DTS = (0.001, 0.01, 0.05, 0.1, 0.2)
SCALES = (1.0, 10.0, 100.0)
#: A posture error beyond this (rad) is a lost loop.
UNSTABLE_ERROR = 1.0


def potential(scene: Scene | SpatialScene, phi) -> float:
    """V (gravity and springs) in numpy: chaingen.scene.kinematics, or chaingen.spatial.dynamics
    for a spatial scene."""
    if isinstance(scene, SpatialScene):
        return float(dynamics.potential_energy(scene, np.asarray(phi, dtype=float)))
    return kinematics.potential_energy(scene, phi)


def shaping_potential(scene: Scene | SpatialScene, phi) -> float:
    """V_s(phi) in numpy (chaingen.symbolic.shaping's, independently): the quadratic about the
    target on the actuated joints minus, with compensate, V at the actuated angles with the
    others at their target."""
    control = scene.control
    actuated = np.array(actuated_joints(scene)) - 1
    phi = np.asarray(phi, dtype=float)
    target = np.array(control.target, dtype=float)
    offsets = np.angle(np.exp(1j * (phi[actuated] - target[actuated])))   # wrapped, as V_d's
    value = 0.5 * float(np.sum(np.array(control.stiffness) * offsets ** 2))
    if control.compensate:
        held = target.copy()
        held[actuated] = phi[actuated]
        value -= potential(scene, held)
    return value


def closed_loop_potential(scene: Scene | SpatialScene, phi) -> float:
    """V + V_s: the closed loop's potential."""
    return potential(scene, phi) + shaping_potential(scene, phi)


def _gradient(function, phi, h: float = 1e-4) -> np.ndarray:
    """Five-point central differences (error O(h^4))."""
    out = np.zeros(len(phi))
    for i in range(len(phi)):
        e = np.zeros(len(phi))
        e[i] = h
        out[i] = (-function(phi + 2 * e) + 8 * function(phi + e) - 8 * function(phi - e)
                  + function(phi - 2 * e)) / (12 * h)
    return out


def predicted_equilibrium(scene: Scene | SpatialScene, guess, iterations: int = 50):
    """(phi_e, hessian): the stationary point of V + V_s that Newton's method reaches from
    `guess` (differences of the numpy potential), and the Hessian there; the equilibrium is
    stable if the Hessian is positive definite (docs/controllers.md)."""
    def closed(phi):
        return closed_loop_potential(scene, phi)

    phi = np.array(guess, dtype=float)
    for _ in range(iterations):
        gradient = _gradient(closed, phi)
        hessian = np.array([_gradient(lambda x, i=i: _gradient(closed, x)[i], phi, 1e-3)
                            for i in range(len(phi))])
        hessian = (hessian + hessian.T) / 2
        step = np.linalg.solve(hessian, -gradient)
        phi = phi + step
        if np.abs(step).max() < 1e-12:
            break
    # V + V_s is 2 pi-periodic in a passive joint's angle: give it in (-pi, pi], as a run's.
    passive = [j for j in range(len(phi)) if j + 1 not in actuated_joints(scene)]
    phi[passive] = np.arctan2(np.sin(phi[passive]), np.cos(phi[passive]))
    return phi, hessian


@dataclass(frozen=True)
class Row:
    law: str
    dt: float
    scale: float
    error: float | None        # final max |phi - phi*| (rad); None: unstable
    rise: float | None         # max_k H_d(k) - H_d(0) (J)
    balance: float | None      # worst step's |dH_d - work + dissipated| (J)
    note: str = ""


def with_law(scene: Scene | SpatialScene, law: str) -> Scene | SpatialScene:
    """`scene` with its control law set to `law`."""
    return dataclasses.replace(scene, control=dataclasses.replace(scene.control, law=law))


def run_table(scene: Scene | SpatialScene, dts=DTS, scales=SCALES,
              t_end: float = 20.0) -> list[Row]:
    """Every (law, dt, scale) run of the table, one build per law (the gains as run-time
    parameters)."""
    control = scene.control
    count = len(control.stiffness)
    paths = ([f"control.stiffness[{i}]" for i in range(count)]
             + [f"control.damping[{i}]" for i in range(count)])
    target = np.array(control.target)
    rows = []
    for label, method, law in LAWS:
        solver = build_solver(with_law(scene, law), method, 3, parameters=paths,
                              sensitivities=False)
        for scale in scales:
            gains = [k * scale for k in control.stiffness] + [d * scale for d in control.damping]
            for dt in dts:
                steps = int(round(t_end / dt))
                try:
                    # No energy check (midpoint's default splits a step that misses its
                    # balance by 1 % of T): the sampled law misses it by design, and near rest
                    # T -> 0; the table measures the balance instead.
                    result = solver.simulate(scene.initial_angles, scene.initial_velocities,
                                             dt=dt, n_steps=steps, parameters=gains,
                                             options={"energy_tol": 0.0})
                    note = ""
                except NewtonError as error:
                    result, note = error.result, f"step failed at t = {error.time:.3g} s"
                if result is None or len(result.t) < 2:
                    rows.append(Row(label, dt, scale, None, None, None, note))
                    continue
                storage = result.energy
                errors = np.abs(result.phi - target).max(axis=1)
                lost = note or not np.all(np.isfinite(errors)) or errors.max() > UNSTABLE_ERROR
                if lost and not note:
                    note = "posture error past 1 rad"
                balance = np.diff(storage - result.input_work + result.dissipated)
                rows.append(Row(label, dt, scale, None if lost else float(errors[-1]),
                                float(np.nanmax(storage - storage[0])),
                                float(np.nanmax(np.abs(balance))) if len(balance) else 0.0,
                                note))
    return rows


def _number(value: float | None) -> str:
    return "-" if value is None else f"{value:.1e}"


def table(rows: list[Row]) -> str:
    """One line per row."""
    lines = ["| law | dt (s) | gains x | final error (rad) | max H_d(k) - H_d(0) (J) | "
             "worst step balance (J) | note |", "|---|---|---|---|---|---|---|"]
    for row in rows:
        lines.append(f"| {row.law} | {row.dt:g} | {row.scale:g} | {_number(row.error)} | "
                     f"{_number(row.rise)} | {_number(row.balance)} | {row.note} |")
    return "\n".join(lines)


def _cell(row: Row) -> str:
    if row.error is None:
        where = row.note.replace("step failed at ", "") if "failed" in row.note else "lost"
        return f"unstable ({where}); {_number(row.rise)}"
    return f"{_number(row.error)}; {_number(row.rise)}"


def pivot(rows: list[Row]) -> str:
    """One line per (dt, gains), one column per law: 'final error (rad); max H_d rise (J)'."""
    laws = list(dict.fromkeys(row.law for row in rows))
    cells = {(row.law, row.dt, row.scale): row for row in rows}
    settings = list(dict.fromkeys((row.scale, row.dt) for row in rows))
    lines = ["| gains x | dt (s) | " + " | ".join(laws) + " |",
             "|---|---|" + "---|" * len(laws)]
    for scale, dt in settings:
        lines.append(f"| {scale:g} | {dt:g} | " + " | ".join(
            _cell(cells[(law, dt, scale)]) for law in laws) + " |")
    return "\n".join(lines)


#: t_end / dt is a whole number of steps when within this relative distance of one (as a
#: sweep's, chaingen.studies.sweep.spec.WHOLE_STEPS_RTOL).
WHOLE_STEPS_RTOL = 1e-9


def t_end_refusal(t_end: float, dts, n: int) -> str | None:
    """Why the study cannot run every dt for t_end, or None: t_end must be finite and > 0, a
    whole number of steps of each dt (a run takes round(t_end / dt) steps, so another t_end
    would run for another time than the table says), and its samples must fit in memory."""
    if not (np.isfinite(t_end) and t_end > 0):
        return f"must be > 0 and finite (s), got {t_end!r}"
    for dt in dts:
        steps = t_end / dt
        if abs(steps - round(steps)) > WHOLE_STEPS_RTOL * steps:
            return (f"{t_end!r} s is not a whole number of steps of dt = {dt:g} s (the study "
                    f"runs dt = {', '.join(f'{dt:g}' for dt in dts)} s): t_end / dt = {steps:.12g}")
    steps = round(t_end / min(dts))
    if (steps + 1) * (2 * n + 3) * 8 > MAX_SAMPLE_BYTES:
        return (f"{t_end!r} s at dt = {min(dts):g} s is {steps} steps, whose samples would "
                f"take more than {MAX_SAMPLE_BYTES / 2 ** 30:.0f} GiB")
    return None


def main(argv=None) -> int:
    program = "python -m chaingen.studies.control"
    parser = argparse.ArgumentParser(prog=program, description=__doc__.split("\n\n")[0])
    parser.add_argument("scene", nargs="?", default="four_link_pbc")
    parser.add_argument("--t-end", type=float, default=None,
                        help="the length of every run in s, a whole number of steps of every "
                             "dt (default: 20, with --quick 2)")
    parser.add_argument("--quick", action="store_true", help="two dt, two scales, 2 s")
    parser.add_argument("--rows", action="store_true",
                        help="one line per run (with the worst step balance), not per setting")
    args = parser.parse_args(argv)

    def refuse(message: str) -> int:     # one line, exit status 2, as chaingen's commands
        print(f"{program}: error: {message}", file=sys.stderr)
        return 2

    try:
        scene = load_either_scene(args.scene)
    except ChaingenError as error:
        return refuse(str(error))
    if scene.control is None:
        return refuse(f"{args.scene}: the scene has no [control] table")
    dts, scales = ((0.01, 0.1), (1.0, 100.0)) if args.quick else (DTS, SCALES)
    t_end = args.t_end if args.t_end is not None else (2.0 if args.quick else 20.0)
    refused = t_end_refusal(t_end, dts, scene.n)
    if refused:
        return refuse(f"--t-end: {refused}")
    rows = run_table(scene, dts, scales, t_end)
    print(f"scene {scene.name}, t_end {t_end:g} s, gains x s (stiffness and damping)")
    print(table(rows) if args.rows else pivot(rows))
    balances = [row.balance for row in rows if row.law.startswith("discrete, es")
                and row.balance is not None]
    worst = f"{max(balances):.1e} J" if balances else "no run of it took a step"
    print(f"\nworst step balance |H_d(k+1) - H_d(k) - work + dissipated| of the discrete law "
          f"in es: {worst}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
