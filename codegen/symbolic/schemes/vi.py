"""Method "vi": Lie-group variational integrator on (S^1)^n (model.md section 5, thesis ch. 4).

State (q, p): unit attitude vectors q_i = (cos phi_i, sin phi_i), each in the frame of link i-1,
and the conjugate momenta p. Positions and M(q) are polynomial in the components of q. Discrete
Lagrangian L_d = dt [1/2 w^T M(q_m) w - V(q_m)], w = theta/dt, q_m = Rot(theta/2) q_0,
q_1 = Rot(theta) q_0. Position-momentum form with the rotation increments theta as unknowns:

    M(q_m) w - dt/2 (g(q_m, w) + f(w)) - p_0 = 0       (n equations, N m s)
    p_1 = M(q_m) w + dt/2 (g(q_m, w) + f(w))  = 2 M(q_m) w - p_0

(the second form, equal to the first wherever the residual vanishes, is the one evaluated: it
needs no second evaluation of g).

g = dL/dphi = 1/2 d(w^T M w)/dphi - dV/dphi, where d/dphi_j of a function of q is its gradient in
q_j dotted with S q_j (thesis 4.25). f = tau - d w are the joint torques, the inputs of the actuated
joints and viscous damping, entering as the midpoint discrete Lagrange-d'Alembert forces
(model.md 7). Over a step their work is tau . theta and the damping dissipates dt d w^2.
"""
from __future__ import annotations

import sympy as sp
from sympy import ImmutableMatrix

from ...runtime.contract import JACOBIAN_ACROSS_STEPS
from ...scene import Scene
from ..com_model import S, number
from ..joint_model import attitude_directions, joint_space_model, rotate
from .base import (
    DiscreteScheme,
    FlowDescription,
    Layout,
    LinearSolve,
    common_fields,
    has_energy_flows,
    input_symbols,
    joint_torques,
    segment_vectors,
)

SUMMARY = ("Lie-group variational integrator on unit attitude vectors, position-momentum form "
           "(docs/model.md, section 5).")
FLOWS = FlowDescription(
    "sum_i tau_i theta_i", "sum_i d_i theta_i^2 / dt",
    "theta the rotation increments of the step. H_1 - H_0 - flows[0] + flows[1] is the scheme's "
    "energy error, O(dt^2).")


def angle_derivative(expr, attitudes) -> ImmutableMatrix:
    """d expr / dphi_j = grad_{q_j} expr . S q_j for every joint j (thesis 4.25)."""
    return ImmutableMatrix([
        sp.diff(expr, c) * (S * q)[0] + sp.diff(expr, s) * (S * q)[1]
        for q, (c, s) in ((q, (q[0], q[1])) for q in attitudes)])


def unit(angle) -> ImmutableMatrix:
    return ImmutableMatrix([sp.cos(angle), sp.sin(angle)])


def build(scene: Scene, quadrature: int, order: int = 2) -> DiscreteScheme:
    """order: of the composed step; the state of every stage is the solution's, so the
    outputs are the same at every order."""
    n = scene.n
    dt = sp.Symbol("dt", positive=True)
    cs = sp.symbols(f"c1:{n + 1}", real=True)
    ss = sp.symbols(f"s1:{n + 1}", real=True)
    attitudes = [ImmutableMatrix([c, s]) for c, s in zip(cs, ss)]
    p0 = ImmutableMatrix(sp.symbols(f"p1:{n + 1}", real=True))
    w = ImmutableMatrix(sp.symbols(f"w1:{n + 1}", real=True))
    theta = ImmutableMatrix(sp.symbols(f"theta1:{n + 1}", real=True))
    model = joint_space_model(scene, attitude_directions(attitudes), w)

    lagrangian = model.kinetic_energy - model.potential
    g = angle_derivative(lagrangian, attitudes)
    inputs = input_symbols(scene)
    torques = joint_torques(scene, inputs)
    forces = g + ImmutableMatrix(torques)
    if any(link.damping for link in scene.links):
        forces = forces + model.damping_torques(w)
    halves = [unit(t / 2) for t in theta]
    q_mid = [rotate(q, half) for q, half in zip(attitudes, halves)]
    # Rot(theta) = Rot(theta/2)^2: the step's rotation from the half-angle's cosine and sine the
    # residual already needs, instead of two more trigonometric calls per joint.
    q_next = [rotate(q, rotate(half, half)) for q, half in zip(attitudes, halves)]
    at_midpoint = {symbol: value for q, qm in zip(attitudes, q_mid)
                   for symbol, value in zip(q, qm)}
    at_midpoint.update(zip(w, theta / dt))
    momentum = (model.mass_matrix * w).xreplace(at_midpoint)
    impulse = (dt / 2 * forces).xreplace(at_midpoint)

    state = ImmutableMatrix(list(cs) + list(ss) + list(p0))
    phi = ImmutableMatrix(sp.symbols(f"phi1:{n + 1}", real=True))
    phidot = ImmutableMatrix(sp.symbols(f"phidot1:{n + 1}", real=True))
    at_initial = {symbol: value for q, angle in zip(attitudes, phi)
                  for symbol, value in zip(q, unit(angle))}
    return DiscreteScheme(
        method="vi", quadrature=None, scene=scene, summary=SUMMARY, dt=dt,
        state=state, unknowns=theta,
        residual=ImmutableMatrix(momentum - impulse - p0),
        next_state=ImmutableMatrix([qn[0] for qn in q_next] + [qn[1] for qn in q_next]
                                   + list(2 * momentum - p0)),
        # First guess: the rotation at the current rates, theta = dt w_0 (w_0 = M(q_0)^-1 p_0).
        predictor=ImmutableMatrix(dt * w),
        joint_angles=ImmutableMatrix([sp.atan2(s, c) for c, s in zip(cs, ss)]),
        joint_velocities=w,
        energy=model.energy,
        constraint_residuals=ImmutableMatrix([sp.sqrt(c ** 2 + s ** 2) - 1
                                              for c, s in zip(cs, ss)]),
        initial_angles=phi, initial_velocities=phidot,
        initial_state=ImmutableMatrix(
            [sp.cos(a) for a in phi] + [sp.sin(a) for a in phi]
            + list((model.mass_matrix * phidot).xreplace(at_initial))),
        state_layout=Layout(
            tuple(f"c_{i}" for i in range(1, n + 1)) + tuple(f"s_{i}" for i in range(1, n + 1))
            + tuple(f"p_{i}" for i in range(1, n + 1)),
            "unit attitude vectors q_i = (c_i, s_i) = (cos phi_i, sin phi_i), then the conjugate "
            "momenta p (N m s)"),
        unknowns_layout=Layout(tuple(f"theta_{i}" for i in range(1, n + 1)),
                               "rotation increments theta of the step (rad)"),
        residual_description=("discrete Legendre transform M(q_m) w - dt/2 (g + f) - p_0, "
                              "w = theta/dt (N m s)"),
        output_solve=LinearSolve(symbols=w, matrix=model.mass_matrix, rhs=p0),
        inputs=inputs, segment_vectors=segment_vectors(model),
        input_work=sp.Add(*(tau * t for tau, t in zip(torques, theta))),
        dissipated=sp.Add(*(number(link.damping) * t ** 2 for link, t in zip(scene.links, theta)
                            if link.damping)) / dt,
        flow_description=FLOWS if has_energy_flows(scene) else None,
        # Simplified Newton: the Jacobian costs six residuals, and the scheme's energy error
        # (O(dt^2)) hides the linear convergence (docs/benchmarks.md, speed knobs).
        jacobian_reuse=JACOBIAN_ACROSS_STEPS, **common_fields(scene, phi),
    )
