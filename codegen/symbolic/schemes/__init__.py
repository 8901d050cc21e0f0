"""The time-stepping schemes, by the name a scene or the command line gives them
(chaingen.scene.METHODS): each module derives its DiscreteScheme from a scene.

A scheme may take some of the scene's numbers as run-time parameters: they enter the derivation
as symbols (chaingen.scene.parameters.with_symbols), every other number as a constant."""
from __future__ import annotations

import math
import sys

import sympy as sp
from sympy import ImmutableMatrix

from ...errors import UnsupportedSceneError
from ...scene import METHODS, ORDERS, Scene, SolverSpec
from ...scene.kinematics import RUN_SEGMENT_RELATIVE_TOLERANCE
from ...scene.parameters import with_symbols
from ...scene.solver_rules import orders_taken as rules_orders_taken
from ...spatial import parameters as spatial_parameters
from ...spatial.values import SpatialScene
from ..composition import FROM_ORDER_4, composition
from . import es, galerkin, midpoint, spatial_es, spatial_midpoint, spatial_vi, vi
from .base import DiscreteScheme, FlowDescription, Layout, segment_tolerances

BUILDERS = {"es": es.build, "vi": vi.build, "midpoint": midpoint.build}
if tuple(BUILDERS) != METHODS:
    raise ImportError(f"schemes {tuple(BUILDERS)} do not match the methods {METHODS}")
#: The schemes a spatial scene (chaingen.spatial.values) has so far.
SPATIAL_BUILDERS = {"midpoint": spatial_midpoint.build, "es": spatial_es.build,
                    "vi": spatial_vi.build}


def orders_taken(scene: Scene | SpatialScene, method: str) -> tuple[int, ...]:
    """The orders of the step the scheme of `method` takes for `scene`: those of the request
    rules (solver_rules.orders_taken), and of a spatial scene only those its builder takes (the
    builder module's ORDERS, the tuple its own refusal tests; every order where it has none).
    Asked, not restated, so that a spatial scheme that gains an order is studied at it."""
    orders = rules_orders_taken(method)
    if isinstance(scene, SpatialScene) and method in SPATIAL_BUILDERS:
        module = sys.modules[SPATIAL_BUILDERS[method].__module__]
        orders = tuple(order for order in orders if order in getattr(module, "ORDERS", ORDERS))
    return orders


def build_scheme(scene: Scene | SolverSpec, method: str | None = None,
                 quadrature: int | None = None, parameters=(), order: int = 2,
                 gradient: str = "exact") -> DiscreteScheme:
    """The discrete scheme of a SolverSpec, or of `scene` with `method`, `quadrature` (Gauss
    points for spring terms; both the scene's own when None), the numbers at the key paths
    `parameters` as run-time parameters p, in that order ("all": every number of the scene a
    solver can take, chaingen.scene.parameters.compiled_paths), its step composed to `order`
    (chaingen.symbolic.composition; es at order 6 composes its k = 1 Galerkin step,
    chaingen.symbolic.schemes.galerkin), es's springs by the discrete `gradient` ("exact" or
    "quadrature", docs/model.md section 4). SolverSpecError (a SettingsError) for a request
    the rules refuse."""
    spec = scene if isinstance(scene, SolverSpec) else SolverSpec.create(
        scene, method, quadrature, order=order, parameters=parameters, gradient=gradient)
    scene, quadrature, order = spec.scene, spec.quadrature, spec.order
    if isinstance(scene, SpatialScene):
        return build_spatial_scheme(spec)
    stages = composition_stages(spec)
    builder = galerkin.build if spec.galerkin_step else BUILDERS[spec.method]
    numbers = spec.parameter_numbers
    # Dummies: a parameter can never be mistaken for a symbol of the model (vi calls its
    # momenta p1, p2, ...).
    symbols = {number.path: sp.Dummy(f"parameter{index}", real=True)
               for index, number in enumerate(numbers)}
    scene_with_symbols = with_symbols(scene, symbols)
    if spec.method == "es" and not spec.galerkin_step:
        scheme = builder(scene_with_symbols, quadrature, order, gradient=spec.gradient)
    else:
        scheme = builder(scene_with_symbols, quadrature, order)
    return scheme.replaced(
        scene=scene, segment_tolerances=segment_tolerances(scene),
        parameters=ImmutableMatrix(list(symbols.values()))
        if symbols else ImmutableMatrix.zeros(0, 1),
        parameter_paths=tuple(number.path for number in numbers),
        parameter_units=tuple(number.unit for number in numbers),
        parameter_values=tuple(number.value(scene) for number in numbers),
        order=order, composition=stages)


def build_spatial_scheme(spec: SolverSpec) -> DiscreteScheme:
    """The scheme of a spatial scene's SolverSpec, its run-time parameters (gravity, masses,
    damping, the springs' stiffness and rest length: chaingen.spatial.parameters) as symbols
    in the scene's place, its step composed to the spec's order (es at order 6: its k = 1
    Galerkin step with the spec's K, chaingen.symbolic.schemes.spatial_galerkin, composed from
    order 4); UnsupportedSceneError for a method that has no spatial scheme yet."""
    scene = spec.scene
    if spec.method not in SPATIAL_BUILDERS:
        raise UnsupportedSceneError(
            f"method {spec.method!r}: not available for a spatial scene (scene {scene.name!r}) "
            f"yet; use {', '.join(map(repr, SPATIAL_BUILDERS))}")
    numbers = spec.parameter_numbers
    symbols = {number.path: sp.Dummy(f"parameter{index}", real=True)
               for index, number in enumerate(numbers)}
    scheme = SPATIAL_BUILDERS[spec.method](spatial_parameters.with_symbols(scene, symbols),
                                           spec.quadrature, spec.order)
    return scheme.replaced(
        scene=scene, segment_tolerances=spatial_segment_tolerances(scene),
        parameters=ImmutableMatrix(list(symbols.values()))
        if symbols else ImmutableMatrix.zeros(0, 1),
        parameter_paths=tuple(number.path for number in numbers),
        parameter_units=tuple(number.unit for number in numbers),
        parameter_values=tuple(float(spatial_parameters.value(scene, number.path))
                               for number in numbers),
        order=spec.order, composition=composition_stages(spec))


def composition_stages(spec: SolverSpec) -> tuple[float, ...]:
    """The step fractions the spec's step is composed of: es's k = 1 Galerkin step (its
    order 4) by Suzuki's 5 stages to order 6 (FROM_ORDER_4), every other step from order 2
    (chaingen.symbolic.composition)."""
    return FROM_ORDER_4 if spec.galerkin_step else composition(spec.order)


def spatial_segment_tolerances(scene: SpatialScene) -> tuple[float, ...]:
    """The run tolerance of every route segment of a spatial scene's springs, spring by
    spring: RUN_SEGMENT_RELATIVE_TOLERANCE times the size of the geometry, the sum of |xyz|
    over the joints' origins and of |point| over the spring's route points (the planar rule,
    chaingen.scene.kinematics.geometry_size, in 3D)."""
    chain = sum(math.dist(link.joint.xyz, (0.0, 0.0, 0.0)) for link in scene.links)
    return tuple(RUN_SEGMENT_RELATIVE_TOLERANCE
                 * (chain + sum(math.dist(point.point, (0.0, 0.0, 0.0))
                                for point in spring.route))
                 for spring in scene.springs for _ in spring.route[1:])


__all__ = ["DiscreteScheme", "FlowDescription", "Layout", "build_scheme"]
