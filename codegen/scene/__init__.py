"""Stage 1 of the pipeline: scenes, the validated numbers of one chain.

- values: the frozen Scene, Link, Spring and Simulation values;
- solver_rules: the rules of a solver request (methods, K range, orders, tolerances), stated
  once; solver_spec: SolverSpec, one request for a solver, checked by them when it is made;
- reader: reading and validating scene files (docs/scene-format.md);
- kinematics: numpy kinematics and energies, independent of the symbolic model (validation and
  test reference);
- reference: the reference scenes shipped with chaingen.
"""
from .reader import load_scene, parse_scene
from .reference import REFERENCE_SCENES, STANDARD_SCENES, load_reference_scene
from .solver_rules import SolverSpecError
from .solver_spec import SolverSpec
from .values import (
                     METHODS,
                     ORDERS,
                     QUADRATURE_RANGE,
                     Link,
                     Scene,
                     Simulation,
                     Spring,
                     c_identifier,
                     quadrature_used,
)

__all__ = ["METHODS", "ORDERS", "QUADRATURE_RANGE", "REFERENCE_SCENES", "STANDARD_SCENES", "Link",
           "Scene", "Simulation", "SolverSpec", "SolverSpecError", "Spring", "c_identifier",
           "load_reference_scene", "load_scene", "parse_scene", "quadrature_used"]
