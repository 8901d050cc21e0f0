"""One request for a solver: the scene, the scheme (method, K, order), the numbers it takes at
run time and whether it computes step sensitivities, checked once when it is made.

`build_solver`, `generate_package`, `build_scheme`, the cache key (chaingen.generate.key), the
sweep spec and the order study take a SolverSpec (or the keywords it is made of); its rules
are chaingen.scene.solver_rules', which the scene reader and the command line ask too.
"""
from __future__ import annotations

from dataclasses import dataclass

from ..errors import SceneError
from ..runtime.interface import HELD_LAW_REFUSAL
from ..spatial import parameters as spatial_parameters
from ..spatial.values import SpatialScene
from . import parameters as planar_parameters
from .parameters import NumberPath
from .solver_rules import (
    GALERKIN_ORDER,
    Refusal,
    SolverSpecError,
    gradient_used,
    quadrature_used,
    request_refusal,
)
from .values import Scene


@dataclass(frozen=True)
class SolverSpec:
    """What a solver is built from, validated at construction (SolverSpecError, a
    SettingsError that names the option: --order: must be one of 2, 4, 6 ...).

    parameters: key paths of the scene's numbers the solver takes at run time, in that order
    (chaingen.scene.parameters); "all" (or ("all",)) is every number a solver can take
    (compiled_paths), stored expanded. order: of the step, 2 (the scheme's own), 4 or 6 (a
    symmetric composition of its steps). gradient: es's discrete gradient of the springs,
    "exact", "quadrature" or "chain" (solver_rules.GRADIENTS). A SolverSpec is hashable: two
    equal requests are one solver.
    """

    scene: Scene
    method: str
    quadrature: int
    order: int = 2
    parameters: tuple[str, ...] = ()
    sensitivities: bool = True
    gradient: str = "exact"

    def __post_init__(self):
        if not isinstance(self.scene, (Scene, SpatialScene)):
            raise TypeError(f"SolverSpec.scene: a Scene (chaingen.load_scene) or a "
                            f"SpatialScene, not {type(self.scene).__name__}")
        refused = request_refusal({"method": self.method, "quadrature": self.quadrature,
                                   "order": self.order, "gradient": self.gradient})
        if refused:
            raise SolverSpecError(refused)
        refused = control_refusal(self.scene, self.method, self.order)
        if refused:
            raise SolverSpecError(refused)
        paths = ((self.parameters,) if isinstance(self.parameters, str)
                 else tuple(self.parameters))
        if paths == ("all",):
            paths = numbers_of(self.scene).compiled_paths(self.scene)
        refused = parameters_refusal(self.scene, paths)
        if refused:
            raise SolverSpecError(refused)
        # Plain Python values: they enter the JSON of the input hash (numpy's ints do not).
        object.__setattr__(self, "quadrature", int(self.quadrature))
        object.__setattr__(self, "order", int(self.order))
        object.__setattr__(self, "parameters", paths)
        object.__setattr__(self, "sensitivities", bool(self.sensitivities))

    @classmethod
    def create(cls, scene: Scene, method: str | None = None, quadrature: int | None = None, *,
               order: int | None = None, parameters=(), sensitivities: bool = True,
               gradient: str | None = None) -> SolverSpec:
        """A spec with the scene's own method, quadrature, order and gradient ([simulation])
        where they are None; a spatial scene's method is midpoint unless its file names one."""
        # A spatial scene's default method is midpoint (spatial.values.SPATIAL_DEFAULT_METHOD).
        defaults = (scene.simulation if isinstance(scene, (Scene, SpatialScene)) else None)
        return cls(scene=scene,
                   method=defaults.method if method is None and defaults else method,
                   quadrature=(defaults.quadrature if quadrature is None and defaults
                               else quadrature),
                   order=defaults.order if order is None and defaults else order,
                   parameters=parameters, sensitivities=sensitivities,
                   gradient=(defaults.gradient if gradient is None and defaults
                             else gradient if gradient is not None else "exact"))

    @property
    def parameter_numbers(self) -> tuple[NumberPath, ...]:
        """The run-time parameters as numbers of the scene (path, unit, compiled)."""
        return tuple(numbers_of(self.scene).number_path(self.scene, path)
                     for path in self.parameters)

    @property
    def galerkin_step(self) -> bool:
        """Whether the step is es's k = 1 Galerkin step (es from GALERKIN_ORDER on)."""
        return self.method == "es" and self.order >= GALERKIN_ORDER

    @property
    def gradient_used(self) -> str | None:
        """es's discrete gradient, None where it plays no role (solver_rules.gradient_used)."""
        return gradient_used(self.scene, self.method, self.gradient, self.order)

    @property
    def quadrature_used(self) -> int | None:
        """The K the scheme runs with, None where K plays no role (solver_rules.quadrature_used)."""
        return quadrature_used(self.scene, self.method, self.quadrature, self.order)


#: The methods that have a controlled step (docs/controllers.md, "Passivity-based control").
CONTROLLED_METHODS = ("es", "midpoint")


def control_refusal(scene: Scene | SpatialScene, method: str, order: int,
                    rtol: float = 0.0, atol: float = 0.0) -> Refusal | None:
    """Why a scene with a [control] table cannot have this solver, or None: the control law
    is built into es's and midpoint's own step (order 2); the sampled law is held over each
    step, so adaptive steps (rtol or atol > 0) would change its hold period from dt."""
    if getattr(scene, "control", None) is None:
        return None
    if method not in CONTROLLED_METHODS:
        return Refusal("method", f"{method!r} has no controlled step: scene {scene.name!r} has "
                                 "a [control] table, which es and midpoint take")
    if order != 2:
        return Refusal("order", "a controlled scene's step is the scheme's own (order 2): the "
                                "control torque is held over one step", order)
    if scene.control.law == "sampled" and (rtol > 0 or atol > 0):
        key, value = ("rtol", rtol) if rtol > 0 else ("atol", atol)
        return Refusal(key, HELD_LAW_REFUSAL, value)
    return None


def numbers_of(scene: Scene | SpatialScene):
    """The key paths of `scene`'s kind: chaingen.scene.parameters for a planar scene,
    chaingen.spatial.parameters for a spatial one (number_path, compiled_paths, with_values,
    with_symbols)."""
    return spatial_parameters if isinstance(scene, SpatialScene) else planar_parameters


def parameters_refusal(scene: Scene | SpatialScene, paths: tuple[str, ...]) -> Refusal | None:
    """Why `paths` cannot be a solver's run-time parameters, or None: each must name a number
    of `scene` compiled into the solver (not the initial state or dt, which every solver takes
    per run), each once."""
    seen = set()
    for path in paths:
        try:
            number = numbers_of(scene).number_path(scene, path)
        except SceneError as error:
            return Refusal("parameters", str(error))
        except TypeError:
            return Refusal("parameters", "must be key paths of the scene's numbers "
                                         "(strings such as springs[0].stiffness)", path)
        if not number.compiled:
            return Refusal("parameters", f"{path}: a run-time value every solver takes per run "
                                         "(initial state, dt), not a parameter")
        if number.path in seen:
            return Refusal("parameters", f"{path}: named twice")
        seen.add(number.path)
    return None
