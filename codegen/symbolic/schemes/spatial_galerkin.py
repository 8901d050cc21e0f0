"""es at order 6 for a spatial scene: the k = 1 Petrov-Galerkin step in joint angles and
canonical momenta (docs/model.md, section 16, "Spatial chains"), the planar step's equations
(chaingen.symbolic.schemes.galerkin) with the spatial recursions.

The step is galerkin_scheme's, unchanged: Hamilton's equations in z = (q, p), H = 1/2 p^T
M(q)^-1 p + V(q), quadratic trial and linear test functions over the step, the (K + 1)-point
Gauss-Lobatto rule, Gonzalez's energy correction, 4n unknowns (the increments of q and p at the
step's mid-point and end) and the rates at the nodes eliminated. Per node, what changes is the
chain:

- M(q_g) w_g and dT/dq at the node by the momentum recursion (spatial_recursion.momenta), the
  gradients of the routed springs and of gravity by theirs, V(q_g) likewise: O(n + route
  points) definitions;
- w_g = M(q_g)^-1 p_g through the Cholesky factor of M(q_g) by the composite-rigid-body
  algorithm (chaingen.symbolic.spatial_mass, as spatial vi's update): O(n^2) entries and an
  O(n^3 / 6) factor a node, small expressions each, where the planar step has an O(n)
  articulated-body recursion.

The state is the runtime's joint-space state (q, w), its energy and segment vectors those of
spatial midpoint and vi. Composed to order 6 by Suzuki's 5 stages (chaingen.symbolic.
composition.FROM_ORDER_4), as the planar es at order 6.
"""
from __future__ import annotations

from ...errors import UnsupportedSceneError
from ...scene.solver_rules import GALERKIN_ORDER
from ...scene.solver_spec import control_refusal
from ...spatial.values import SpatialScene
from .. import spatial_mass, spatial_recursion
from ..recursion import Definitions
from .base import DiscreteScheme
from .galerkin import galerkin_scheme
from .spatial_midpoint import joint_space_fields, state_energy

SUMMARY = ("Energy-conserving k = 1 Petrov-Galerkin step in joint angles and canonical momenta, "
           "spatial chain (docs/model.md, section 16).")


class SpatialChain:
    """The quantities of a spatial chain at a node, by the recursions of
    chaingen.symbolic.spatial_recursion and the mass matrix's Cholesky factor
    (chaingen.symbolic.spatial_mass): what galerkin_scheme asks of a chain."""

    summary = SUMMARY

    def __init__(self, scene: SpatialScene):
        self.scene = scene

    def frames(self, defs: Definitions, tag: str, angles):
        return spatial_recursion.link_frames(self.scene, angles, defs, tag)

    def rates(self, defs: Definitions, tag: str, frames, momenta) -> list:
        """w with M(q) w = p: M by the composite-rigid-body algorithm, two triangular solves
        with its Cholesky factor."""
        factor = spatial_mass.cholesky_factor(
            spatial_mass.mass_matrix(self.scene, frames, defs, tag), defs, tag)
        return spatial_mass.cholesky_solve(factor, momenta, defs, tag)

    def lagrangian(self, defs: Definitions, tag: str, frames, rates):
        """(M(q) w, dL/dq = dT/dq - dV/dq, V(q)) at a node."""
        scene = self.scene
        momentum, kinetic_gradient = spatial_recursion.momenta(scene, frames, rates, defs, tag)
        springs, spring_energy, _ = spatial_recursion.spring_gradient(scene, frames, defs, tag)
        gravity = spatial_recursion.gravity_gradient(scene, frames, defs, tag)
        gradient = [dT - spring - weight
                    for dT, spring, weight in zip(kinetic_gradient, springs, gravity)]
        return (momentum, gradient,
                spring_energy + spatial_recursion.gravity_potential(scene, frames))

    def state_fields(self, q0, w0) -> dict:
        """The state's fields: joint space (q, w), its energy H = T + V and segment vectors
        as spatial midpoint's (spatial_midpoint.state_energy), the holding torques of an
        actuated scene."""
        at_state, _, energy, segments = state_energy(self.scene, q0, w0)
        return dict(**joint_space_fields(self.scene, q0, w0, energy),
                    segment_vectors=segments, state_definitions=tuple(at_state.items))


def build(scene: SpatialScene, quadrature: int, order: int = GALERKIN_ORDER,
          exact_energy: bool = True) -> DiscreteScheme:
    """The k = 1 step of the spatial `scene` with the (quadrature + 1)-point Gauss-Lobatto
    rule (K = quadrature >= 2), its energy defect corrected unless exact_energy is False.
    UnsupportedSceneError for a scene with a [control] table: its law is built into the
    order-2 steps of es and midpoint (chaingen.scene.solver_spec.control_refusal)."""
    refused = control_refusal(scene, "es", order)
    if refused:
        raise UnsupportedSceneError(f"order {order}: {refused.message}")
    return galerkin_scheme(scene, SpatialChain(scene), quadrature, order, exact_energy)
