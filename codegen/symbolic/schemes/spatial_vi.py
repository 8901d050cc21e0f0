"""Method "vi" for a spatial scene: the discrete Euler-Lagrange equations in joint angles, in
position-momentum form (model.md section 5.7), with the spatial recursions
(chaingen.symbolic.spatial_recursion) and the mass matrix's Cholesky factor
(chaingen.symbolic.spatial_mass).

The planar vi's discrete Lagrangian and forcing, in joint angles instead of unit attitude
vectors (a revolute joint's angle is its coordinate on S^1 either way):
L_d(q_0, q_1) = dt [T(q_m, v) - V(q_m)], q_m = q_0 + theta/2, v = theta/dt, theta = q_1 - q_0,
and the torques f = tau - d v as mid-point discrete Lagrange-d'Alembert forces dt/2 f at each end.
The discrete Legendre transforms

    p_0 = M(q_m) v - dt/2 (dT/dq(q_m, v) - dV/dq(q_m) + f),   p_1 = 2 M(q_m) v - p_0

are the step. The state is the runtime's joint-space state (q, w) and the momenta are
p = M(q) w. Newton solves the first transform for v alone (n unknowns, residual in N m s)

    M(q_m) v - dt/2 (dT/dq - dV/dq + f) - M(q_0) w_0 = 0,

and the update solves M(q_1) w_1 = p_1 once, after convergence, through the Cholesky factor of
M(q_1) by the composite-rigid-body algorithm. Every M(q) w and dT/dq in the residual is the
momentum recursion (spatial_recursion.momenta), dV/dq the gravity and routed springs'
recursions: O(n) definitions; the update's M(q_1) and its factor O(n^2) and O(n^3) small ones.
"""
from __future__ import annotations

import sympy as sp
from sympy import ImmutableMatrix

from ...runtime.contract import JACOBIAN_PER_STEP
from ...spatial.values import SpatialScene
from .. import spatial_mass, spatial_recursion
from ..com_model import number
from ..recursion import Definitions
from .base import (
    DiscreteScheme,
    Layout,
    has_energy_flows,
    input_symbols,
    joint_torques,
)
from .spatial_midpoint import joint_space_fields, state_energy
from .vi import FLOWS

SUMMARY = ("Variational integrator in joint angles, discrete Euler-Lagrange equations in "
           "position-momentum form, spatial chain (docs/model.md, section 5.7).")


def build(scene: SpatialScene, quadrature: int | None = None, order: int = 2) -> DiscreteScheme:
    """The spatial vi scheme of `scene`. quadrature plays no role (the discrete Lagrangian is
    the midpoint rule); order: of the composed step, the outputs are the same at every order."""
    n = scene.n
    dt = sp.Symbol("dt", positive=True)
    q0 = ImmutableMatrix(sp.symbols(f"phi1:{n + 1}", real=True))
    w0 = ImmutableMatrix(sp.symbols(f"w1:{n + 1}", real=True))
    v = ImmutableMatrix(sp.symbols(f"v1:{n + 1}", real=True))

    step = Definitions("step_")
    theta = [step.define(f"theta{k}", dt * rate) for k, rate in enumerate(v, start=1)]
    qm = [step.define(f"phim{k}", q + t / 2) for k, (q, t) in enumerate(zip(q0, theta), start=1)]
    start = spatial_recursion.link_frames(scene, q0, step, "a")
    p0, _ = spatial_recursion.momenta(scene, start, w0, step, "a")
    middle = spatial_recursion.link_frames(scene, qm, step, "m")
    pm, kinetic_gradient = spatial_recursion.momenta(scene, middle, v, step, "m")
    gravity = spatial_recursion.gravity_gradient(scene, middle, step, "m")
    springs, _, _ = spatial_recursion.spring_gradient(scene, middle, step, "m")
    inputs = input_symbols(scene)
    torques = joint_torques(scene, inputs)
    # dL/dq + f = dT/dq - dV/dq + tau - d v at the mid-point
    forces = [dT - weight - spring + tau - number(link.damping) * rate
              for dT, weight, spring, tau, link, rate
              in zip(kinetic_gradient, gravity, springs, torques, scene.links, v)]
    transform = [m - dt / 2 * force - p for m, force, p in zip(pm, forces, p0)]
    # The update, after convergence: w_1 = M(q_1)^-1 p_1 through M(q_1)'s Cholesky factor.
    end = spatial_recursion.link_frames(
        scene, [step.define(f"phie{k}", q + t) for k, (q, t) in enumerate(zip(q0, theta), 1)],
        step, "e")
    p1 = [step.define(f"p1_{k}", 2 * m - p) for k, (m, p) in enumerate(zip(pm, p0), start=1)]
    factor = spatial_mass.cholesky_factor(spatial_mass.mass_matrix(scene, end, step, "e"),
                                          step, "e")
    w1 = spatial_mass.cholesky_solve(factor, p1, step, "e")

    # The energy H = T + V of the state, by the recursions at (q_0, w_0), as the midpoint's.
    at_state, kinetic, energy, segments = state_energy(scene, q0, w0)

    return DiscreteScheme.of(
        method="vi", quadrature=None, scene=scene, summary=SUMMARY, dt=dt,
        unknowns=v,
        residual=ImmutableMatrix(transform),
        next_state=ImmutableMatrix([q + t for q, t in zip(q0, theta)] + w1),
        # First guess: the step at the current rates, v = w_0.
        predictor=w0,
        **joint_space_fields(scene, q0, w0, energy),
        unknowns_layout=Layout(
            tuple(f"v_{i}" for i in range(1, n + 1)),
            "the mean joint rates v = (q_1 - q_0)/dt of the step (rad/s)"),
        residual_description=(
            "discrete Legendre transform: M(q_m) v - dt/2 (dT/dq - dV/dq + f) - M(q_0) w_0, "
            "v = (q_1 - q_0)/dt, spatial chain (N m s)"),
        inputs=inputs, definitions=tuple(step.items), state_definitions=tuple(at_state.items),
        segment_vectors=segments,
        input_work=sp.Add(*(tau * t for tau, t in zip(torques, theta))),
        dissipated=sp.Add(*(number(link.damping) * t ** 2 for link, t in zip(scene.links, theta)
                            if link.damping)) / dt,
        flow_description=FLOWS if has_energy_flows(scene) else None,
        # Full Newton at every order: the momentum maps are kept to the Newton tolerance, and
        # simplified Newton stops within a tenth of it (model.md 5.7).
        jacobian_reuse=JACOBIAN_PER_STEP, kinetic_energy=kinetic,
    )
