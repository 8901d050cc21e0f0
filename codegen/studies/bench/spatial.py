"""The spatial arm's part of the benchmark (issue 33 d): scenes/panda_springs.toml, the Panda
imported from example-robot-data with three springs, at dt = 1e-3 s.

`chaingen bench --spatial-only` runs it alone and writes its section into an existing report
in place (as --stiff-only does). Three sides, timed round by round in one process, so that a
machine whose speed drifts treats them alike:

- each scheme of SPATIAL_BUILDERS in the C loop of the timing program (harness.Harness: N calls
  of <prefix>_step, process CPU clock, no Python in between), Newton's default options;
- MuJoCo RK4 on the model of spatial_mjcf_from_scene (one mj_step(nstep=N) call: MuJoCo's own
  C loop);
- Pinocchio's ABA with RK4: pin.aba four times a step (C++), the springs' generalized forces
  from chaingen.spatial.dynamics (numpy), the loop in Python. Pinocchio has no C loop one can
  call from Python, so this row carries the interpreter's cost and is not a peer of the C
  loops; beside it, the four pin.aba calls alone (still called from Python) bound from below
  what Pinocchio's compiled part costs per step.

And each scheme's generate seconds (scheme, CasADi functions, rendering: generate_package) and
build seconds (build_shared_library into an empty cache: chaingen's own build), with and
without step sensitivities, each in a fresh child process.
"""
from __future__ import annotations

import importlib.util
import json
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...scene.shipped import scene_file
from ...spatial import dynamics
from ...spatial.reader import load_spatial_scene
from .config import HARNESS_FLAGS, BenchConfig
from .harness import Harness

#: The scene and step of issue 33 d.
SPATIAL_SCENE = "panda_springs"
SPATIAL_DT = 1e-3

#: The section of the report; `--spatial-only` replaces what it starts (up to the next "## ").
SPATIAL_HEADING = "## Spatial arm: the Panda with three springs"

#: Issue 33 d's targets: per step over MuJoCo RK4's, and seconds of generate + build.
STEP_TARGETS = {"es": 0.5, "vi": 1.0, "midpoint": 1.0}
BUILD_TARGETS = {False: 30.0, True: 60.0}     # by sensitivities


@dataclass(frozen=True)
class BuildRow:
    """Generate and build seconds of one scheme, with or without step sensitivities."""

    method: str
    sensitivities: bool
    generate_seconds: float
    build_seconds: float

    @property
    def total_seconds(self) -> float:
        return self.generate_seconds + self.build_seconds


@dataclass(frozen=True)
class StepRow:
    """CPU seconds per step of one side, one entry per round, and the C loop's Newton
    iterations per step (None for the peers)."""

    name: str
    loop: str                           # what runs the steps
    rounds: tuple[float, ...]
    iterations: float | None = None

    @property
    def step_seconds(self) -> float:
        return statistics.median(self.rounds)


@dataclass(frozen=True)
class SpatialStudy:
    scene: str
    dt: float
    n_steps: int                        # steps of each C loop round
    python_steps: int                   # steps of each Python loop round
    steps: tuple[StepRow, ...]
    builds: tuple[BuildRow, ...]
    pinocchio: str | None               # why Pinocchio's rows are missing, or None
    #: max |q_Pinocchio - q_MuJoCo| (rad) after python_steps of RK4 (check_pinocchio_model)
    pinocchio_agreement: float | None = None

    def ratio(self, row: StepRow) -> float:
        """Median over rounds of row / MuJoCo RK4 in the same round."""
        mujoco = next(r for r in self.steps if r.name == "MuJoCo RK4")
        return statistics.median(a / b for a, b in zip(row.rounds, mujoco.rounds))


def pinocchio_version() -> str:
    """"pin <version>" of the installed Pinocchio, or that it is not installed."""
    import importlib.metadata

    try:
        return f"pin {importlib.metadata.version('pin')}"
    except importlib.metadata.PackageNotFoundError:
        return "pin not installed"


def pinocchio_model(scene):
    """The scene's chain in Pinocchio, joint by joint (revolute about the scene's unit axis,
    its origin turned by rpy, the link's inertia about its COM) with the scene's gravity."""
    import pinocchio as pin

    model = pin.Model()
    parent = 0
    for i, link in enumerate(scene.links):
        placement = pin.SE3(pin.rpy.rpyToMatrix(*link.joint.rpy), np.array(link.joint.xyz))
        parent = model.addJoint(parent, pin.JointModelRevoluteUnaligned(
            np.array(link.joint.axis)), placement, f"joint{i + 1}")
        model.appendBodyToJoint(parent, pin.Inertia(link.mass, np.array(link.com),
                                                    np.array(link.inertia_matrix())),
                                pin.SE3.Identity())
    model.gravity.linear = np.array(scene.gravity)
    return model


def pinocchio_rk4_seconds(scene, model, dt: float, n_steps: int, *,
                          springs: bool = True) -> float:
    """CPU seconds per step of pinocchio_rk4."""
    return pinocchio_rk4(scene, model, dt, n_steps, springs=springs)[0] / n_steps


def pinocchio_rk4(scene, model, dt: float, n_steps: int, *,
                  springs: bool = True) -> tuple[float, np.ndarray]:
    """(CPU seconds, final angles) of n_steps of RK4 on qddot = ABA(q, qdot, tau),
    tau = -d qdot - dV_s/dq (no torques on the motors, as the other sides), in a Python loop
    from the initial state. springs=False: the four pin.aba calls alone (with tau = 0)."""
    import pinocchio as pin

    data = model.createData()
    damping = np.array([link.damping for link in scene.links])
    zero = np.zeros(scene.n)

    def acceleration(q, v):
        tau = -damping * v - dynamics.spring_torques(scene, q) if springs else zero
        return pin.aba(model, data, q, v, tau)

    q, v = np.array(scene.initial_angles), np.array(scene.initial_velocities)
    start = time.process_time()
    for _ in range(n_steps):
        a1 = acceleration(q, v)
        a2 = acceleration(q + dt / 2 * v, v + dt / 2 * a1)
        v2 = v + dt / 2 * a1
        a3 = acceleration(q + dt / 2 * v2, v + dt / 2 * a2)
        v3 = v + dt / 2 * a2
        a4 = acceleration(q + dt * v3, v + dt * a3)
        v4 = v + dt * a3
        q = q + dt / 6 * (v + 2 * v2 + 2 * v3 + v4)
        v = v + dt / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
    seconds = time.process_time() - start
    if not np.all(np.isfinite(q)):
        raise RuntimeError("Pinocchio ABA RK4: the state turned non-finite")
    return seconds, q


#: How far (rad) Pinocchio's RK4 may end from MuJoCo's over the same steps: the same method on
#: the same equations, so only round-off parts them.
PINOCCHIO_AGREEMENT = 1e-9


def check_pinocchio_model(scene, model, dt: float, n_steps: int) -> float:
    """max |q_Pinocchio - q_MuJoCo| (rad) after n_steps of RK4 at dt from the initial state;
    RuntimeError if over PINOCCHIO_AGREEMENT: the timed model must be the scene's."""
    import mujoco

    from ...reference.spatial_mujoco import spatial_mujoco_model_and_data

    mj_model, data = spatial_mujoco_model_and_data(scene, dt, "RK4")
    mujoco.mj_step(mj_model, data, nstep=n_steps)
    difference = float(np.abs(pinocchio_rk4(scene, model, dt, n_steps)[1] - data.qpos).max())
    if not difference <= PINOCCHIO_AGREEMENT:
        raise RuntimeError(f"Pinocchio ABA RK4 ends {difference:.2e} rad from MuJoCo RK4 after "
                           f"{n_steps} steps: not the same model")
    return difference


def mujoco_rk4_seconds(scene, dt: float, n_steps: int) -> float:
    """CPU seconds per step of one mj_step(nstep=n_steps) call of RK4 from the initial state."""
    import mujoco

    from ...reference.spatial_mujoco import spatial_mujoco_model_and_data

    model, data = spatial_mujoco_model_and_data(scene, dt, "RK4")
    start = time.process_time()
    mujoco.mj_step(model, data, nstep=n_steps)
    return (time.process_time() - start) / n_steps


def measure_build(method: str, sensitivities: bool) -> dict:
    """Generate and build the Panda's package of `method` from a cold start; run in a child
    process of its own (run_build), so that no SymPy or CasADi cache of an earlier scheme in
    the process shortens the next. generate: generate_package's work (scheme, CasADi functions,
    rendering); build: build_shared_library into an empty cache."""
    from ...generate.package import generate_package
    from ...runtime.build import build_shared_library
    from ...scene.solver_spec import SolverSpec

    scene = load_spatial_scene(scene_file(SPATIAL_SCENE))
    started = time.perf_counter()
    package = generate_package(SolverSpec.create(scene, method, None,
                                                 sensitivities=sensitivities))
    generated = time.perf_counter() - started
    with tempfile.TemporaryDirectory(prefix="chaingen-spatial-build-") as cache:
        started = time.perf_counter()
        build_shared_library(package.prefix, package.files, package.manifest["sources"],
                             source_flags=package.manifest["source_flags"], cache=Path(cache))
        built = time.perf_counter() - started
    return {"generate_seconds": generated, "build_seconds": built}


def run_build(method: str, sensitivities: bool, timeout: float) -> BuildRow:
    """measure_build in a child process; RuntimeError naming the scheme if it fails or runs
    over `timeout` seconds."""
    program = ("import json\nfrom chaingen.studies.bench.spatial import measure_build\n"
               f"print(json.dumps(measure_build({method!r}, {sensitivities!r})))\n")
    try:
        child = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True,
                               timeout=timeout)
    except subprocess.TimeoutExpired:
        raise RuntimeError(f"spatial {method}: generate and build ran over {timeout:g} s") \
            from None
    if child.returncode != 0:
        last = (child.stderr.strip().splitlines() or ["no message"])[-1]
        raise RuntimeError(f"spatial {method}: generate and build failed: {last}")
    point = json.loads(child.stdout.strip().splitlines()[-1])
    return BuildRow(method, sensitivities, point["generate_seconds"], point["build_seconds"])


def spatial_study(config: BenchConfig, note) -> SpatialStudy:
    """Generate and build every scheme of SPATIAL_BUILDERS with and without sensitivities (each
    in a child process), then time the C loops, MuJoCo RK4 and Pinocchio round by round
    (config.repeats rounds)."""
    from ...generate.package import render_package
    from ...symbolic.schemes import SPATIAL_BUILDERS, build_scheme

    scene = load_spatial_scene(scene_file(SPATIAL_SCENE))
    dt = SPATIAL_DT
    n_steps = 500 if config.quick else 2000
    python_steps = 50 if config.quick else 200
    builds, harnesses = [], {}
    try:
        for method in sorted(SPATIAL_BUILDERS):
            for sensitivities in (False, True):
                note(f"spatial: generate and build {method}"
                     f"{' with sensitivities' if sensitivities else ''}")
                builds.append(run_build(method, sensitivities, config.timeout))
            # the timed package again, here, with its scheme (the initial state in the
            # package's layout)
            scheme = build_scheme(scene, method)
            x0 = np.array(scheme.initial_function()(*scene.initial_angles,
                                                    *scene.initial_velocities), float).ravel()
            harnesses[method] = (Harness(render_package(scheme, sensitivities=False),
                                         flags=HARNESS_FLAGS), x0)
        pinocchio, agreement = None, None
        if importlib.util.find_spec("pinocchio") is None:
            pinocchio = "Pinocchio (the pin package) is not installed: its rows are missing"
            model = None
        else:
            model = pinocchio_model(scene)
            agreement = check_pinocchio_model(scene, model, dt, python_steps)
        rounds: dict[str, list[float]] = {}
        iterations = {}
        for k in range(config.repeats):
            note(f"spatial: timing round {k + 1} of {config.repeats}")
            for method, (harness, x0) in harnesses.items():
                timing = harness.time(x0, dt, n_steps=n_steps, repeats=1)
                rounds.setdefault(method, []).append(timing.step_ns * 1e-9)
                iterations[method] = timing.mean_iterations
            rounds.setdefault("MuJoCo RK4", []).append(mujoco_rk4_seconds(scene, dt, n_steps))
            if model is not None:
                rounds.setdefault("Pinocchio ABA RK4", []).append(
                    pinocchio_rk4_seconds(scene, model, dt, python_steps))
                rounds.setdefault("pin.aba x 4", []).append(
                    pinocchio_rk4_seconds(scene, model, dt, python_steps, springs=False))
    finally:
        for harness, _ in harnesses.values():
            harness.close()
    loops = {"MuJoCo RK4": "C (mj_step, nstep)",
             "Pinocchio ABA RK4": "Python: pin.aba x 4 (C++) + springs (numpy)",
             "pin.aba x 4": "Python: pin.aba x 4 (C++) alone, no springs"}
    steps = tuple(StepRow(name, loops.get(name, "C (timing program)"), tuple(values),
                          iterations.get(name)) for name, values in rounds.items())
    return SpatialStudy(SPATIAL_SCENE, dt, n_steps, python_steps, steps, tuple(builds),
                        pinocchio, agreement)


def _microseconds(seconds: float) -> str:
    return f"{seconds * 1e6:.2f} us"


def step_table(study: SpatialStudy) -> str:
    lines = ["| side | loop | per step | / MuJoCo RK4 | Newton iterations per step | target | |",
             "|---|---|---|---|---|---|---|"]
    for row in study.steps:
        target = STEP_TARGETS.get(row.name)
        if row.loop.startswith("Python"):     # not a peer of the C loops: no ratio
            ratio, verdict = "not compared (Python loop)", ""
        else:
            ratio = f"{study.ratio(row):.3g}"
            verdict = "" if target is None else (
                "pass" if study.ratio(row) <= target else "FAIL")
        iterations = "" if row.iterations is None else f"{row.iterations:.2f}"
        lines.append(f"| {row.name} | {row.loop} | {_microseconds(row.step_seconds)} | "
                     f"{ratio} | {iterations} | "
                     f"{'' if target is None else f'<= {target:g}'} | {verdict} |")
    return "\n".join(lines)


def build_table(study: SpatialStudy) -> str:
    lines = ["| scheme | sensitivities | generate | build | generate + build | target | |",
             "|---|---|---|---|---|---|---|"]
    for row in study.builds:
        target = BUILD_TARGETS[row.sensitivities]
        lines.append(f"| {row.method} | {'yes' if row.sensitivities else 'no'} | "
                     f"{row.generate_seconds:.1f} s | {row.build_seconds:.1f} s | "
                     f"{row.total_seconds:.1f} s | <= {target:g} s | "
                     f"{'pass' if row.total_seconds <= target else 'FAIL'} |")
    return "\n".join(lines)


def findings(study: SpatialStudy) -> str:
    """What the tables show, in sentences made from the numbers."""
    said = []
    for row in study.steps:
        target = STEP_TARGETS.get(row.name)
        if target is not None:
            ratio = study.ratio(row)
            said.append(f"{row.name}'s step costs {ratio:.2f} of MuJoCo RK4's "
                        f"({_microseconds(row.step_seconds)} against "
                        f"{_microseconds(_named(study, 'MuJoCo RK4').step_seconds)}): "
                        f"{'within' if ratio <= target else 'over'} the target of {target:g}.")
    for row in study.builds:
        target = BUILD_TARGETS[row.sensitivities]
        said.append(f"{row.method} {'with' if row.sensitivities else 'without'} sensitivities "
                    f"generates and builds in {row.total_seconds:.1f} s, "
                    f"{'within' if row.total_seconds <= target else 'over'} {target:g} s.")
    missing = [method for method in STEP_TARGETS if _named(study, method) is None]
    if missing:
        said.append(f"{' and '.join(missing)}: no spatial scheme yet (SPATIAL_BUILDERS), "
                    "not measured.")
    pinocchio = _named(study, "Pinocchio ABA RK4")
    aba = _named(study, "pin.aba x 4")
    if pinocchio is not None and aba is not None:
        said.append(f"Pinocchio's RK4 in a Python loop takes "
                    f"{_microseconds(pinocchio.step_seconds)} a step, of which the four "
                    f"pin.aba calls alone take {_microseconds(aba.step_seconds)} (with Python's "
                    "call overhead); the rest "
                    "is the springs in numpy and the loop. Neither is a C loop: the row says "
                    "what a Python user of Pinocchio pays, not what Pinocchio's C++ costs, and "
                    "it is not held to a target. Its model is the scene's: after "
                    f"{study.python_steps} steps it ends {study.pinocchio_agreement:.1e} rad "
                    "from MuJoCo's RK4.")
    elif study.pinocchio:
        said.append(study.pinocchio + ".")
    return " ".join(said)


def _named(study: SpatialStudy, name: str) -> StepRow | None:
    return next((row for row in study.steps if row.name == name), None)


def spatial_section(study: SpatialStudy, config: BenchConfig, measured: str) -> str:
    """The report's section (SPATIAL_HEADING); `measured`: the line naming the run."""
    return "\n".join([
        SPATIAL_HEADING, "", measured, "",
        f"scenes/{study.scene}.toml (the Panda imported by `chaingen import` to panda_link8, "
        "seven revolute joints, damping 0.003 N m s/rad on each, three springs: two "
        "mono-articular and one multi-articular through a via point) at dt = "
        f"{study.dt:g} s from its initial state, no torques on the motors. Each round times "
        f"every side once, in turn: our schemes in the C loop of the timing program "
        f"({study.n_steps} steps, process CPU time, Newton's default options, "
        f"{' '.join(HARNESS_FLAGS)}), MuJoCo RK4 on the MJCF of spatial_mjcf_from_scene (one "
        f"mj_step call of {study.n_steps} steps), and Pinocchio's ABA with RK4 "
        f"({study.python_steps} steps of a Python loop: Pinocchio offers no C loop to call "
        "from Python). Per step: the median over "
        f"{config.repeats} rounds; / MuJoCo RK4: the median over rounds of the ratio to "
        "MuJoCo's step of the same round.", "",
        step_table(study), "",
        "Generate: the scheme (SymPy), the CasADi functions and the rendering "
        "(generate_package); build: build_shared_library into an empty cache (chaingen's "
        "build of the shared library, each source in its own compiler process); each pair in "
        "a fresh Python process, so that no cache of an earlier one helps it. Wall time.", "",
        build_table(study), "",
        findings(study), ""])


def spatial_section_of(document: str) -> str | None:
    """The spatial section of `document` (from SPATIAL_HEADING up to the next "## "
    heading), or None without one."""
    start = document.find(f"\n{SPATIAL_HEADING}\n")
    if start < 0:
        return None
    end = document.find("\n## ", start + 1)
    return document[start + 1:] if end < 0 else document[start + 1:end]


def replace_spatial_section(document: str, section: str) -> str:
    """`document` with its spatial section replaced by `section` (up to the next "## "
    heading), or, without one, with `section` at the end."""
    start = document.find(f"\n{SPATIAL_HEADING}\n")
    if start < 0:
        return document.rstrip("\n") + "\n\n" + section
    end = document.find("\n## ", start + 1)
    rest = "" if end < 0 else document[end:]
    return document[:start + 1] + section + rest
