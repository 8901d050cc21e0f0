"""Thin runtime of chaingen: build, load and run generated C packages (numpy only).

It needs neither SymPy nor CasADi: a generated package directory is all it reads.
"""
from .build import BuildError, build_shared_library, cache_directory
from .solver import (NewtonError, NewtonOptions, Sensitivities, SimulationResult, Solver,
                     StepResult)
from .trajectory import write_trajectory

__all__ = ["BuildError", "NewtonError", "NewtonOptions", "Sensitivities", "SimulationResult",
           "Solver", "StepResult", "build_shared_library", "cache_directory", "write_trajectory"]
