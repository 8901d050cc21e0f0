"""Scene -> generated package -> built solver -> simulation, in one call.

The generation stage (SymPy, CasADi, Jinja2) is imported only when a solver is built, so that
reading scenes and checking settings stay quick.
"""
from __future__ import annotations

import contextlib
import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from .errors import SettingsError
from .progress import Progress
from .runtime import NewtonOptions, SimulationResult, Solver
from .runtime.interface import real_number
from .runtime.solver import MAX_SAMPLE_BYTES  # samples are held in memory before they are written
from .scene import Scene, SolverSpec
from .scene.solver_rules import REQUEST_KEYS, request_refusal
from .scene.solver_spec import control_refusal
from .spatial.values import SpatialScene

#: A run of more steps is refused: at about 1 us a step it would take days.
MAX_STEPS = 10 ** 12


@dataclass(frozen=True)
class RunSettings:
    """What `simulate` runs: the scene's [simulation] defaults with overrides applied."""

    method: str
    quadrature: int
    dt: float
    t_end: float
    every: int = 1
    order: int = 2
    rtol: float = 0.0    # adaptive steps (either > 0): local error tolerances
    atol: float = 0.0
    gradient: str = "exact"   # es's discrete gradient of the springs

    @property
    def adaptive(self) -> bool:
        return self.rtol > 0 or self.atol > 0

    @property
    def n_steps(self) -> int:
        return max(1, round(self.t_end / self.dt))

    def solver_spec(self, scene: Scene, *, sensitivities: bool = True,
                    parameters=()) -> SolverSpec:
        """The request for the solver these settings run with."""
        return SolverSpec(scene, self.method, self.quadrature, order=self.order,
                          parameters=parameters, sensitivities=sensitivities,
                          gradient=self.gradient)


def run_settings(scene: Scene | SpatialScene, *, method=None, quadrature=None, dt=None, t_end=None,
                 every=None, order=None, rtol=None, atol=None, gradient=None,
                 source: str = "") -> RunSettings:
    """Merge command-line overrides into the scene's defaults, validating each override.

    `source` (the scene file) prefixes errors about values that came from the scene.
    """
    scene_source = f"{source}: " if source else ""
    defaults = scene.simulation
    settings = RunSettings(
        method=method if method is not None else defaults.method,
        quadrature=quadrature if quadrature is not None else defaults.quadrature,
        dt=dt if dt is not None else defaults.dt,
        t_end=t_end if t_end is not None else defaults.t_end,
        every=every if every is not None else 1,
        order=order if order is not None else defaults.order,
        gradient=gradient if gradient is not None else defaults.gradient,
        rtol=rtol if rtol is not None else defaults.rtol,
        atol=atol if atol is not None else defaults.atol)
    given = {"method": method, "quadrature": quadrature, "order": order, "gradient": gradient,
             "rtol": rtol, "atol": atol}
    refused = (request_refusal({key: getattr(settings, key) for key in REQUEST_KEYS})
               or control_refusal(scene, settings.method, settings.order, settings.rtol,
                                  settings.atol))
    if refused:
        # A value from the command line is named by its option, one from the scene by its key.
        where = (refused.option if given[refused.key] is not None
                 else f"{scene_source}simulation.{refused.key}")
        raise SettingsError(f"{where}: {refused.message}")
    checked = {}
    for name in ("dt", "t_end"):
        flag = f"--{name.replace('_', '-')}"
        try:    # a bool, a string: no number of seconds (dt=True ran steps of 1 s)
            value = real_number(getattr(settings, name), flag)
        except TypeError as error:
            raise SettingsError(str(error)) from None
        if not (math.isfinite(value) and value > 0):
            raise SettingsError(f"{flag}: must be > 0 and finite, got {value}")
        checked[name] = value
    every = settings.every
    if isinstance(every, (bool, np.bool_)) or not isinstance(every, (int, np.integer)) \
            or every < 1:     # 0 was a ZeroDivisionError below; 2.5 and True passed
        raise SettingsError(f"--every: must be an integer >= 1, got {every!r}")
    settings = dataclasses.replace(settings, every=int(every), **checked)
    steps = settings.t_end / settings.dt
    if steps > MAX_STEPS:   # named where the values came from: options, or the scene's table
        where = ("--dt/--t-end" if dt is not None or t_end is not None
                 else f"{scene_source}simulation.dt/t_end")
        raise SettingsError(
            f"{where}: t_end / dt = {steps:.3g} steps, more than the {MAX_STEPS:.0e} a run "
            f"may take (dt = {settings.dt:g} s, t_end = {settings.t_end:g} s)")
    samples = (settings.n_steps // settings.every + 1) * (2 * scene.n + 3) * 8
    if samples > MAX_SAMPLE_BYTES:
        raise SettingsError(
            f"--every: {settings.n_steps} steps sampled every {settings.every} would hold "
            f"{samples / 2 ** 30:.1f} GiB of samples (limit {MAX_SAMPLE_BYTES / 2 ** 30:.0f} GiB); "
            "sample less often with a larger --every")
    return settings


def build_solver(scene: Scene | SpatialScene | SolverSpec, method: str | None = None,
                 quadrature: int | None = None, *, sensitivities: bool = True, parameters=(),
                 order: int | None = None, gradient: str | None = None) -> Solver:
    """Generate and build (or load from the cache) the solver of a SolverSpec, or of `scene`
    with the keywords a SolverSpec is made of; on a terminal a progress bar names the stage
    (SymPy, CasADi, C, compiling), which for large n takes a while.
    method, quadrature and order: the scene's own ([simulation]) by default; a spatial
    scene's method is midpoint where its file names none (SPATIAL_DEFAULT_METHOD).
    parameters: key paths of the scene's numbers the solver takes at run time (every call
    then takes their values, the scene's own by default). order: of the step, 2 (the
    scheme's own), 4 or 6 (a symmetric composition of its steps). gradient: es's discrete
    gradient of the springs, "exact", "quadrature" or "chain" (docs/model.md, section 4; the scene's
    own by default). A request the rules refuse
    raises SolverSpecError (a SettingsError) before anything is generated.

    A solver built before from the same inputs (scene, method, options, chaingen's code, the
    tool versions, the compiler: codegen/generate/key.py) loads from the build cache's index
    without running SymPy or CasADi."""
    spec = solver_spec(scene, method, quadrature, sensitivities=sensitivities,
                       parameters=parameters, order=order, gradient=gradient)
    from .generate.key import solver_key
    from .runtime.build import (
        DEFAULT_OPTIMISATION,
        BuiltLibrary,
        compiler,
        indexed_library,
        remember,
    )

    key = solver_key(spec, build=(compiler(), *DEFAULT_OPTIMISATION))
    found = indexed_library(key)
    if found is not None:
        library, manifest = found
        return Solver(library.path, manifest, build_hash=library.build_hash)
    from .generate.package import GENERATE_STAGES, generate_package

    with Progress(f"generate {spec.scene.name} ({spec.method})", total=GENERATE_STAGES + 1,
                  unit="stages") as progress:
        # The spec's fields as keywords: generate_package makes the same SolverSpec of them.
        package = generate_package(spec.scene, spec.method, spec.quadrature,
                                   sensitivities=spec.sensitivities, parameters=spec.parameters,
                                   order=spec.order, gradient=spec.gradient,
                                   progress=progress)
        progress.update(GENERATE_STAGES)
        with progress.phase("compiling (or loading the cached build)"):
            solver = Solver.from_files(package.files)
    with contextlib.suppress(OSError):      # an index that cannot be written only costs time
        remember(key, BuiltLibrary(solver.library_path, solver.build_hash), solver.manifest)
    return solver


def solver_spec(scene: Scene | SpatialScene | SolverSpec, method: str | None = None,
                quadrature: int | None = None, *, sensitivities: bool = True, parameters=(),
                order: int | None = None, gradient: str | None = None) -> SolverSpec:
    """The SolverSpec build_solver builds from its arguments: a given SolverSpec as it is
    (TypeError if method, quadrature, order or gradient are given beside it), else
    SolverSpec.create."""
    if isinstance(scene, SolverSpec):
        if method is not None or quadrature is not None or order is not None \
                or gradient is not None:
            raise TypeError("build_solver: a SolverSpec carries its method, quadrature, order "
                            "and gradient; give them to the SolverSpec")
        return scene
    return SolverSpec.create(scene, method, quadrature, order=order, parameters=parameters,
                             sensitivities=sensitivities, gradient=gradient)


def simulate_scene(scene: Scene | SpatialScene, settings: RunSettings, *,
                   solver: Solver | None = None,
                   options: NewtonOptions | dict | None = None) -> SimulationResult:
    """Simulate `scene` from its initial state; raises NewtonError if a step fails. On a
    terminal a progress bar follows the run (the samples do not depend on it). options:
    Newton options, or a dict of fields that replace the package's defaults; the settings'
    rtol and atol (adaptive steps) apply unless `options` sets them."""
    if not isinstance(options, NewtonOptions):
        options = {**{name: getattr(settings, name) for name in ("rtol", "atol")
                      if getattr(settings, name)}, **(options or {})}
    # A forward run needs no step sensitivities: leaving them out builds faster.
    solver = solver or build_solver(settings.solver_spec(scene, sensitivities=False))
    with Progress(f"simulate {scene.name}", total=settings.n_steps, unit="steps") as progress:
        return solver.simulate(scene.initial_angles, scene.initial_velocities, dt=settings.dt,
                               n_steps=settings.n_steps, every=settings.every, options=options,
                               scene=scene.name,
                               progress=progress if progress.enabled else None)
