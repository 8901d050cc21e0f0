"""chaingen: structure-preserving solvers for planar elastic robot arms, generated from a scene.

A scene file describes a serial chain of links on revolute joints and the springs between them;
chaingen derives its model with SymPy, generates C with CasADi, builds it, and simulates:

    import chaingen

    scene = chaingen.load_scene("three_link_mono.toml")
    solver = chaingen.build_solver(scene, "es", 3)          # generated, compiled, cached
    result = solver.simulate(scene.initial_angles, scene.initial_velocities,
                             dt=0.01, n_steps=5000)         # one C call
    step = solver.step(solver.initial_state(phi, omega), u, 0.01)   # C's order: x0, u, dt
    sens = solver.step_sensitivities(x, u, 0.01)            # d s1/d s0, d s1/d u

    # a control loop in Python: joint space in place, the warm start carried
    loop = solver.stepper(phi, omega, dt=0.01)
    for k in range(1000):
        loop.step(controller(loop.t, loop.phi, loop.omega))     # loop.phi, loop.omega updated
    # or closed inside the C loop, the torques recorded in result.torques
    result = solver.simulate(phi, omega, dt=0.01, n_steps=1000, controller=controller)

    # numbers of the scene as run-time parameters: one build, values per call
    solver = chaingen.build_solver(scene, "es", 3, parameters=["springs[0].stiffness"])
    result = solver.simulate(..., parameters={"springs[0].stiffness": 20.0})
    runs = chaingen.sweep("study.toml", out="study")        # many runs, all cores (pandas)

The pipeline runs down through the subpackages, each a stage: scene (the validated numbers),
symbolic (SymPy model and schemes), generate (CasADi and the C package), runtime (build, load,
run: the thin runtime, numpy only), with studies, reference (MuJoCo and SciPy peers) and views
(plots, animation) beside them. The names below are the public API.
"""
from .errors import (
                     BuildError,
                     ChaingenError,
                     NewtonError,
                     RunFailedError,
                     SceneError,
                     SettingsError,
                     UnsupportedSceneError,
)
from .runtime import (
                     NewtonOptions,
                     Sensitivities,
                     SimulationResult,
                     Solver,
                     Stepper,
                     StepResult,
                     StopSignal,
                     read_trajectory,
                     write_trajectory,
)
from .scene import (
                     METHODS,
                     QUADRATURE_RANGE,
                     Link,
                     Scene,
                     Simulation,
                     Spring,
                     load_reference_scene,
                     load_scene,
                     parse_scene,
)
from .simulation import RunSettings, build_solver, run_settings, simulate_scene
from .version import VERSION as __version__

__all__ = ["METHODS", "QUADRATURE_RANGE", "BuildError", "ChaingenError", "Link", "NewtonError",
           "NewtonOptions", "RunFailedError", "RunSettings", "Scene", "SceneError",
           "Sensitivities", "SettingsError", "Simulation", "SimulationResult", "Solver",
           "Spring", "StepResult", "Stepper", "StopSignal", "UnsupportedSceneError", "__version__",
           "build_solver", "load_reference_scene", "load_scene", "parse_scene",
           "read_trajectory", "run_settings", "simulate_scene", "sweep", "write_trajectory"]


def __getattr__(name: str):
    """chaingen.sweep, imported on first use: a solver loaded from the cache needs none of the
    studies' code (PEP 562)."""
    if name == "sweep":
        from .studies.sweep import sweep

        return sweep
    raise AttributeError(f"module 'chaingen' has no attribute {name!r}")
