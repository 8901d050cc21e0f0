"""The control loops of `chaingen bench`: what a controller costs a step, from Python and from C.

On the headline scene with every joint actuated (three_link_mono, n = 3, es K = 3 at the
headline dt), one PD controller about a posture held by its holding torques,
u = tau_hold + kp (phi_ref - phi) - kd omega, closes the loop four ways, round by round in
alternating order (the machine's speed drifts):

- a Python loop over `Solver.stepper` (the state in place, one step per call), first with the
  torques held (the step's own cost from Python, the issue's target), then with the controller
  in numpy, against the same loops over MuJoCo's `mj_step` (RK4, the torques through
  qfrc_applied): CPU per step;
- `simulate(controller=...)` with the controller compiled in C (a function pointer called in
  the C loop) against open-loop `simulate` with the torques it recorded: the ratio of the C
  loop's times;
- `simulate(controller=...)` with the Python controller, for scale.

And the embedded controller's cost per call (issue 34): on four_link_pbc (its [control] law
inside es's step, K = 3, the scene's dt), a C program (templates/bench_control.c.j2) times
chained calls of `control_torques` against chained calls of `step` and the open-loop
`simulate`, per call, round by round in rotating order in one process.
"""
from __future__ import annotations

import ctypes
import dataclasses
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...runtime.build import STRICT_FLAGS, compiler
from ...scene import load_reference_scene
from .config import HARNESS_FLAGS, HEADLINE_DT, HEADLINE_SCENE, BenchConfig

#: The issue's targets: a step from a Python loop (stepper.step) at n = 3, and the C
#: controller's closed loop against the open loop.
TARGET_PYTHON_LOOP_SECONDS = 10e-6
TARGET_C_CONTROLLER_RATIO = 1.5
#: PD gains (N m / rad, N m s / rad) and the posture: the scene's initial angles.
GAINS = (20.0, 2.0)

#: The PD controller in C, of the package's <prefix>_controller type (context: PdGains).
C_CONTROLLER = r"""
typedef struct {
    int n;
    double kp, kd;
    double reference[32];
    double hold[32];
} pd_gains;

int pd_control(long step, double t, const double *phi, const double *omega, double *u,
               void *context)
{
    const pd_gains *gains = (const pd_gains *)context;
    int i;
    (void)step;
    (void)t;
    for (i = 0; i < gains->n; ++i) {
        u[i] = gains->hold[i] + gains->kp * (gains->reference[i] - phi[i])
               - gains->kd * omega[i];
    }
    return 0;
}
"""


class PdGains(ctypes.Structure):
    _fields_ = [("n", ctypes.c_int), ("kp", ctypes.c_double), ("kd", ctypes.c_double),
                ("reference", ctypes.c_double * 32), ("hold", ctypes.c_double * 32)]


@dataclass(frozen=True)
class ControlRow:
    """One way of closing the loop: its CPU per step, and its peer's (median of rounds)."""

    loop: str
    peer: str
    seconds: float
    peer_seconds: float

    @property
    def ratio(self) -> float:
        return self.seconds / self.peer_seconds


def control_scene():
    """The headline scene with every joint actuated."""
    scene = load_reference_scene(HEADLINE_SCENE)
    return dataclasses.replace(scene, name=f"{scene.name}-actuated",
                               actuated_joints=tuple(range(1, scene.n + 1)))


def _c_controller(directory: Path):
    source = directory / "pd_control.c"
    source.write_text(C_CONTROLLER)
    library = directory / "libpd_control.so"
    import subprocess

    subprocess.run([compiler(), *STRICT_FLAGS, "-O2", "-shared", "-fPIC", str(source), "-o",
                    str(library)], check=True, capture_output=True, text=True)
    return ctypes.CDLL(str(library)).pd_control


def control_study(config: BenchConfig, note) -> list[ControlRow]:
    """The rows of the module docstring, median of config.repeats rounds."""
    import mujoco

    from ...simulation import build_solver
    from .runs import mujoco_model

    scene = control_scene()
    dt = HEADLINE_DT
    n_steps = 2000
    note("control loops: build")
    solver = build_solver(scene, "es", 3, sensitivities=False)
    reference = np.array(scene.initial_angles, dtype=float)
    omega0 = np.array(scene.initial_velocities, dtype=float)
    hold = solver.holding_torques(reference)
    kp, kd = GAINS

    def controller(t, phi, omega):
        return hold + kp * (reference - phi) - kd * omega

    model, data = mujoco_model(scene, dt, "RK4")

    def mujoco_loop(closed: bool) -> float:
        mujoco.mj_resetData(model, data)
        data.qpos[:] = reference
        data.qvel[:] = omega0
        mujoco.mj_forward(model, data)
        step, applied, qpos, qvel = mujoco.mj_step, data.qfrc_applied, data.qpos, data.qvel
        applied[:] = hold
        started = time.process_time()
        if closed:
            for _ in range(n_steps):
                applied[:] = controller(data.time, qpos, qvel)
                step(model, data)
        else:
            for _ in range(n_steps):
                step(model, data)
        return (time.process_time() - started) / n_steps

    stepper = solver.stepper(reference, omega0, dt)

    def python_loop(closed: bool) -> float:
        stepper.reset(reference, omega0)
        stepper.u = hold
        step, phi, omega = stepper.step, stepper.phi, stepper.omega
        started = time.process_time()
        if closed:
            for _ in range(n_steps):
                step(controller(stepper.t, phi, omega))
        else:
            for _ in range(n_steps):
                step()
        return (time.process_time() - started) / n_steps

    gains = PdGains(n=scene.n, kp=kp, kd=kd)
    gains.reference[:scene.n] = reference
    gains.hold[:scene.n] = hold
    rounds: dict[str, list[float]] = {key: [] for key in
                                      ("step", "mujoco step", "python", "mujoco", "c",
                                       "open", "callable")}
    with tempfile.TemporaryDirectory(prefix="chaingen-control-") as directory:
        c_controller = _c_controller(Path(directory))
        for index in range(config.repeats):
            note(f"control loops: round {index + 1} of {config.repeats}")
            rounds["step"].append(python_loop(closed=False))
            rounds["mujoco step"].append(mujoco_loop(closed=False))
            rounds["python"].append(python_loop(closed=True))
            rounds["mujoco"].append(mujoco_loop(closed=True))
            closed = solver.simulate(reference, omega0, dt=dt, n_steps=n_steps,
                                     controller=c_controller,
                                     controller_context=ctypes.addressof(gains))
            rounds["c"].append(closed.wall_time / n_steps)
            opened = solver.simulate(reference, omega0, dt=dt, n_steps=n_steps,
                                     torques=closed.torques)
            rounds["open"].append(opened.wall_time / n_steps)
            rounds["callable"].append(solver.simulate(
                reference, omega0, dt=dt, n_steps=n_steps,
                controller=controller).wall_time / n_steps)
    median = {key: float(np.median(values)) for key, values in rounds.items()}
    return [ControlRow("Python loop: stepper.step(), torques held", "MuJoCo RK4 loop: mj_step, "
                       "torques held", median["step"], median["mujoco step"]),
            ControlRow("Python loop: stepper.step + PD in numpy", "MuJoCo RK4 loop: mj_step "
                       "+ the same PD", median["python"], median["mujoco"]),
            ControlRow("simulate, PD in C (function pointer)", "simulate, open loop (the "
                       "recorded torques)", median["c"], median["open"]),
            ControlRow("simulate, PD as a Python callable", "simulate, open loop (the "
                       "recorded torques)", median["callable"], median["open"])]


def control_table(rows: list[ControlRow], config: BenchConfig) -> str:
    scene = control_scene()
    lines = [f"Control loops ({scene.name}: {HEADLINE_SCENE} with every joint actuated, "
             f"es K = 3, dt = {HEADLINE_DT} s, PD about the initial posture with its holding "
             f"torques; 2000 steps a round, {config.repeats} rounds in alternating order, "
             "medians; CPU per step):", "",
             "| loop | per step | peer | peer per step | ratio |", "|---|---|---|---|---|"]
    for row in rows:
        lines.append(f"| {row.loop} | {row.seconds * 1e6:.2f} us | {row.peer} | "
                     f"{row.peer_seconds * 1e6:.2f} us | {row.ratio:.2f} |")
    return "\n".join(lines)


#: The controlled scene of the embedded controller's timing, and its calls a round.
CONTROLLED_SCENE = "four_link_pbc"
CONTROLLED_STEPS = 2000


@dataclass(frozen=True)
class ControlCallTimings:
    """CPU per call of control_torques and step, and per step of the open-loop simulate
    (medians over rounds, seconds), their Newton iterations per call (last round), and whether
    the three loops ended in the same state bit for bit."""

    scene: str
    dt: float
    rounds: int
    control_torques: float
    step: float
    simulate: float
    iterations: tuple[float, float, float]
    same_end: bool


def control_call_study(config: BenchConfig, note) -> ControlCallTimings:
    """The embedded controller's call against step and simulate (module docstring)."""
    import subprocess

    from ...generate.package import generate_package, template_environment, write_package
    from ...scene import load_scene
    from ...simulation import build_solver
    from .harness import build_timing_program, call_arguments, timing_report

    scene = load_scene(CONTROLLED_SCENE)
    dt = scene.simulation.dt
    note("control_torques: build")
    solver = build_solver(scene, "es", 3, sensitivities=False)
    x0 = solver.initial_state(scene.initial_angles, scene.initial_velocities)
    package = generate_package(scene, "es", 3, sensitivities=False)
    manifest = package.manifest
    P = package.prefix.upper()
    values = ", ".join(repr(float(entry["value"])) for entry in manifest["parameters"])
    source = template_environment().get_template("bench_control.c.j2").render(
        prefix=package.prefix, PREFIX=P,
        p_arguments=call_arguments(package.prefix, manifest)["p_arguments"],
        p_declaration=(f"static const double p[{P}_NP] = {{ {values} }};\n" if values else ""))
    with tempfile.TemporaryDirectory(prefix="chaingen-control-calls-") as directory:
        folder = write_package(package, Path(directory) / "package")
        (folder / "bench_control.c").write_text(source)
        program = build_timing_program(folder, "bench_control.c", manifest, HARNESS_FLAGS)
        note(f"control_torques: {config.repeats} rounds")
        result = subprocess.run([str(program), str(CONTROLLED_STEPS), str(config.repeats),
                                 repr(float(dt))], input=" ".join(map(repr, x0.tolist())),
                                capture_output=True, text=True)
    report = timing_report(result, "bench_control")
    medians = [float(np.median(values)) for values in report["seconds"]]
    return ControlCallTimings(
        scene=scene.name, dt=dt, rounds=config.repeats, control_torques=medians[0],
        step=medians[1], simulate=medians[2],
        iterations=tuple(count / CONTROLLED_STEPS for count in report["iterations"]),
        same_end=all(report["same_end"]))


def control_call_table(timings: ControlCallTimings) -> str:
    lines = [f"The embedded controller's call ({timings.scene}: its [control] law inside es's "
             f"step, K = 3, dt = {timings.dt:g} s; {CONTROLLED_STEPS} chained calls a round "
             f"from the scene's initial state, fresh workspace, {timings.rounds} rounds in "
             "rotating order in one C program, medians; CPU per call, per step for simulate; "
             "final states bit for bit equal: " + ("yes" if timings.same_end else "no") + "):",
             "", "| call | per call | / step | Newton iterations per call |", "|---|---|---|---|"]
    for label, seconds, iterations in (
            ("control_torques (tau and x1)", timings.control_torques, timings.iterations[0]),
            ("step (x1)", timings.step, timings.iterations[1]),
            ("simulate, open loop (per step)", timings.simulate, timings.iterations[2])):
        lines.append(f"| {label} | {seconds * 1e6:.2f} us | {seconds / timings.step:.2f} | "
                     f"{iterations:.3f} |")
    return "\n".join(lines)
