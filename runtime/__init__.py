"""The thin runtime of chaingen: build, load and run generated C packages (numpy only).

It needs neither SymPy nor CasADi, and imports nothing of the rest of chaingen: a generated
package directory is all it reads. `contract` states the C interface once; `interface` makes
ctypes of it; `build` compiles a package into the cache; `solver` loads and drives it;
`workspaces` gives each running call a C workspace of its own; `parameters` reads run-time
parameter values (a mapping by name) and checks their ranges; `runs` watches a running
simulate (progress, Ctrl-C, StopSignal); `stepper` steps a control loop; `keypaths` spells
each key path of a scene's numbers one way; `trajectory` writes and reads trajectory files;
`files` writes all or nothing.
"""
from .build import build_shared_library, cache_directory
from .contract import (
    JACOBIAN_ACROSS_STEPS,
    JACOBIAN_CHORD_ACROSS_STEPS,
    JACOBIAN_EVERY_ITERATE,
    JACOBIAN_PER_STEP,
)
from .errors import BuildError, ChaingenError, NewtonError, RunFailedError
from .interface import NewtonOptions
from .results import ControlledStep, Sensitivities, SimulationResult, StepResult
from .solver import Solver, StopSignal
from .stepper import Stepper
from .trajectory import read_trajectory, write_trajectory

__all__ = ["JACOBIAN_ACROSS_STEPS", "JACOBIAN_CHORD_ACROSS_STEPS", "JACOBIAN_EVERY_ITERATE",
           "JACOBIAN_PER_STEP",
           "BuildError", "ChaingenError", "ControlledStep", "NewtonError", "NewtonOptions",
           "RunFailedError",
           "Sensitivities", "SimulationResult", "Solver", "StepResult", "Stepper", "StopSignal",
           "build_shared_library", "cache_directory", "read_trajectory", "write_trajectory"]
