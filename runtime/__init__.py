"""Thin runtime of chaingen: build, load and run generated C packages (numpy only).

It needs neither SymPy nor CasADi: a generated package directory is all it reads.
"""
from .build import BuildError, build_shared_library, cache_directory
from .solver import (JACOBIAN_ACROSS_STEPS, JACOBIAN_EVERY_ITERATE, JACOBIAN_PER_STEP,
                     NewtonError, NewtonOptions, Sensitivities, SimulationResult, Solver,
                     StepResult)
from .trajectory import write_trajectory

__all__ = ["JACOBIAN_ACROSS_STEPS", "JACOBIAN_EVERY_ITERATE", "JACOBIAN_PER_STEP", "BuildError", "NewtonError", "NewtonOptions", "Sensitivities", "SimulationResult",
           "Solver", "StepResult", "build_shared_library", "cache_directory", "write_trajectory"]
