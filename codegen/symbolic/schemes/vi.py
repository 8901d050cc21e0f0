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

M(q_m) w is the momentum recursion, dT/dphi_j = P_j x V_j, dV/dphi by the recursion of gravity
and segment by segment for the springs, and the rates of a state w = M(q)^-1 p by the
articulated-body recursion (chaingen.symbolic.recursion, model.md 17): O(n) definitions, no
M(q) of the whole chain.
"""
from __future__ import annotations

import sympy as sp
from sympy import ImmutableMatrix

from ...runtime.contract import JACOBIAN_ACROSS_STEPS, JACOBIAN_PER_STEP
from ...scene import Scene
from .. import recursion
from ..com_model import number
from .base import (
    DiscreteScheme,
    FlowDescription,
    Layout,
    common_fields,
    has_energy_flows,
    input_symbols,
    joint_torques,
)

SUMMARY = ("Lie-group variational integrator on unit attitude vectors, position-momentum form "
           "(docs/model.md, section 5).")
FLOWS = FlowDescription(
    "sum_i tau_i theta_i", "sum_i d_i theta_i^2 / dt",
    "theta the rotation increments of the step. H_1 - H_0 - flows[0] + flows[1] is the scheme's "
    "energy error, O(dt^2).")


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
    theta = ImmutableMatrix(sp.symbols(f"theta1:{n + 1}", real=True))

    step = recursion.Definitions("step_")
    halves = [step.vector(f"h{k}", unit(t / 2)) for k, t in enumerate(theta, start=1)]
    q_mid = [step.vector(f"qm{k}", recursion.complex_product(q, half))
             for k, (q, half) in enumerate(zip(attitudes, halves), start=1)]
    # Rot(theta) = Rot(theta/2)^2: the step's rotation from the half-angle's cosine and sine the
    # residual already needs, instead of two more trigonometric calls per joint.
    q_next = [recursion.complex_product(q, recursion.complex_product(half, half))
              for q, half in zip(attitudes, halves)]
    frames = recursion.link_frames(scene, recursion.attitude_directions(step, q_mid))
    w = [step.define(f"w{k}", t / dt) for k, t in enumerate(theta, start=1)]
    momentum, kinetic_gradient = recursion.momenta(
        scene, frames, recursion.absolute_rates(step, w), step)
    springs, _ = recursion.spring_gradient(scene, frames, step)
    gravity = recursion.gravity_gradient(scene, frames, step)
    inputs = input_symbols(scene)
    torques = joint_torques(scene, inputs)
    # g + f = dT/dphi - dV/dphi + tau - d w at the mid-point
    forces = [dT - spring - weight + tau - number(link.damping) * rate
              for dT, spring, weight, tau, link, rate
              in zip(kinetic_gradient, springs, gravity, torques, scene.links, w)]
    impulse = [dt / 2 * force for force in forces]

    # The state's rates w = M(q)^-1 p and energy H = 1/2 w . p + V, by recursions.
    at_state = recursion.Definitions("state_")
    frames0 = recursion.link_frames(scene, recursion.attitude_directions(at_state, attitudes))
    rates0 = recursion.rates_from_momenta(scene, frames0, p0, at_state)
    _, spring_energy = recursion.spring_gradient(scene, frames0, at_state)
    kinetic = sp.Add(*(rate * p for rate, p in zip(rates0, p0))) / 2
    energy = kinetic + recursion.gravity_potential(scene, frames0, at_state) + spring_energy

    state = ImmutableMatrix(list(cs) + list(ss) + list(p0))
    phi = ImmutableMatrix(sp.symbols(f"phi1:{n + 1}", real=True))
    phidot = ImmutableMatrix(sp.symbols(f"phidot1:{n + 1}", real=True))
    # p = M(q(phi)) phidot at the start, by the momentum recursion.
    at_start = recursion.Definitions("initial_")
    frames_start = recursion.link_frames(scene, recursion.angle_directions(at_start, phi))
    start_momenta, _ = recursion.momenta(scene, frames_start,
                                         recursion.absolute_rates(at_start, phidot), at_start)
    return DiscreteScheme.of(
        method="vi", quadrature=None, scene=scene, summary=SUMMARY, dt=dt,
        state=state, unknowns=theta,
        residual=ImmutableMatrix([m - i - p for m, i, p in zip(momentum, impulse, p0)]),
        next_state=ImmutableMatrix([qn[0] for qn in q_next] + [qn[1] for qn in q_next]
                                   + [2 * m - p for m, p in zip(momentum, p0)]),
        # First guess: the rotation at the current rates, theta = dt w_0 (w_0 = M(q_0)^-1 p_0).
        predictor=ImmutableMatrix([dt * rate for rate in rates0]),
        joint_angles=ImmutableMatrix([sp.atan2(s, c) for c, s in zip(cs, ss)]),
        joint_velocities=ImmutableMatrix(rates0),
        energy=energy,
        constraint_residuals=ImmutableMatrix([sp.sqrt(c ** 2 + s ** 2) - 1
                                              for c, s in zip(cs, ss)]),
        initial_angles=phi, initial_velocities=phidot,
        initial_state=ImmutableMatrix(
            [sp.cos(a) for a in phi] + [sp.sin(a) for a in phi] + start_momenta),
        state_layout=Layout(
            tuple(f"c_{i}" for i in range(1, n + 1)) + tuple(f"s_{i}" for i in range(1, n + 1))
            + tuple(f"p_{i}" for i in range(1, n + 1)),
            "unit attitude vectors q_i = (c_i, s_i) = (cos phi_i, sin phi_i), then the conjugate "
            "momenta p (N m s)"),
        unknowns_layout=Layout(tuple(f"theta_{i}" for i in range(1, n + 1)),
                               "rotation increments theta of the step (rad)"),
        residual_description=("discrete Legendre transform M(q_m) w - dt/2 (g + f) - p_0, "
                              "w = theta/dt (N m s)"),
        inputs=inputs, segment_vectors=recursion.segment_vector_entries(scene, frames0),
        definitions=tuple(step.items), state_definitions=tuple(at_state.items),
        initial_definitions=tuple(at_start.items),
        input_work=sp.Add(*(tau * t for tau, t in zip(torques, theta))),
        dissipated=sp.Add(*(number(link.damping) * t ** 2 for link, t in zip(scene.links, theta)
                            if link.damping)) / dt,
        flow_description=FLOWS if has_energy_flows(scene) else None,
        # Order 2, simplified Newton: the Jacobian costs six residuals, and the scheme's energy
        # error (O(dt^2)) hides the linear convergence (docs/benchmarks.md, speed knobs). A
        # composed step, Newton-chord as es and midpoint: simplified Newton stops within a tenth
        # of the tolerance, an error that its stages accumulate above the error of order 4 or 6
        # (docs/model.md, section 14), and the chord stops within a thousandth for no more
        # iterations.
        jacobian_reuse=JACOBIAN_ACROSS_STEPS if order == 2 else JACOBIAN_PER_STEP,
        kinetic_energy=kinetic,
        **common_fields(scene, phi),
    )
