"""Method "midpoint": implicit midpoint rule in joint angles (model.md section 6).

State (phi, w); M(phi) phiddot + Coriolis(phi, w) + grad V(phi) = tau, tau the inputs of the
actuated joints and damping -d_i w_i. Unknown: dw = w_1 - w_0, so that w_m = w_0 + dw/2,
phi_1 = phi_0 + dt w_m, phi_m = phi_0 + dt w_m / 2, and the residual (model.md's multiplied by
dt) is

    M(phi_m) dw + dt [Coriolis(phi_m, w_m) + grad V(phi_m) - tau(w_m)] = 0.

Its left-hand side is evaluated by the Newton-Euler recursion over the links with gravity as an
upward acceleration of the base, and the springs' gradient segment by segment
(chaingen.symbolic.recursion, model.md 17): O(n) definitions, no M(phi) of the whole chain.
"""
from __future__ import annotations

import sympy as sp
from sympy import ImmutableMatrix

from ...runtime.contract import JACOBIAN_PER_STEP
from ...scene import Scene
from .. import recursion
from ..com_model import number
from .base import (
    DiscreteScheme,
    FlowDescription,
    Layout,
    has_energy_flows,
    input_symbols,
    joint_space_state,
    joint_torques,
)
from .control import StepControl, midpoint_control, sampled_law, state_shaping

SUMMARY = "Implicit midpoint rule in relative joint angles (docs/model.md, section 6)."
FLOWS = FlowDescription(
    "dt sum_i tau_i w_i(m)", "dt sum_i d_i w_i(m)^2",
    "w(m) the mid-point joint rates. H_1 - H_0 - flows[0] + flows[1] is the scheme's energy "
    "error, O(dt^2).")

CONTROLLED_FLOWS = FlowDescription(
    "dt sum_i u_i w_i(m)", "dt sum_i d_i w_i(m)^2 + injected",
    "u the inputs added to the control law's torques, injected the control law's damping "
    "injection (docs/controllers.md). The energy is the closed loop's H_d = T + V + V_s; "
    "H_d1 - H_d0 - flows[0] + flows[1] is the scheme's energy error, O(dt^2).")


def build(scene: Scene, quadrature: int, order: int = 2) -> DiscreteScheme:
    """order: of the composed step; the state of every stage is the solution's, so the
    outputs are the same at every order."""
    n = scene.n
    dt = sp.Symbol("dt", positive=True)
    phi0 = ImmutableMatrix(sp.symbols(f"phi1:{n + 1}", real=True))
    w0 = ImmutableMatrix(sp.symbols(f"w1:{n + 1}", real=True))
    dw = ImmutableMatrix(sp.symbols(f"dw1:{n + 1}", real=True))

    step = recursion.Definitions("step_")
    wm = [step.define(f"wm{k}", w + d / 2) for k, (w, d) in enumerate(zip(w0, dw), start=1)]
    phim = [step.define(f"phim{k}", phi + dt * w / 2)
            for k, (phi, w) in enumerate(zip(phi0, wm), start=1)]
    frames = recursion.link_frames(scene, recursion.angle_directions(step, phim))
    rates = recursion.absolute_rates(step, wm)
    increments = recursion.absolute_rates(step, dw, "A")
    moments = recursion.inverse_dynamics(scene, frames, rates, increments, dt, step)
    springs, _ = recursion.spring_gradient(scene, frames, step)
    inputs = input_symbols(scene)
    torques = joint_torques(scene, inputs)
    law = StepControl(scene, dt)
    if scene.control:
        controlled = midpoint_control(scene, dt, phi0, w0, wm, step, law)
        torques = [t + c for t, c in zip(torques, controlled)]
    residual = [moment + dt * (spring - torque + number(link.damping) * w)
                for moment, spring, torque, link, w
                in zip(moments, springs, torques, scene.links, wm)]

    # The energy H = T + V of the state, by the same recursions at (phi_0, w_0).
    at_state = recursion.Definitions("state_")
    frames0 = recursion.link_frames(scene, recursion.angle_directions(at_state, phi0))
    rates0 = recursion.absolute_rates(at_state, w0)
    velocities, _ = recursion.velocities(scene, frames0, rates0, at_state)
    _, spring_energy = recursion.spring_gradient(scene, frames0, at_state)
    kinetic = recursion.kinetic_energy(scene, rates0, velocities)
    energy = kinetic + recursion.gravity_potential(scene, frames0, at_state) + spring_energy
    applied_torques = None
    if scene.control:
        energy += state_shaping(scene, phi0)
        applied_torques = ImmutableMatrix([torques[joint - 1]
                                           for joint in scene.actuated_joints])

    return DiscreteScheme.of(
        method="midpoint", quadrature=None, scene=scene, summary=SUMMARY, dt=dt, unknowns=dw,
        residual=ImmutableMatrix(residual),
        next_state=ImmutableMatrix([phi + dt * w for phi, w in zip(phi0, wm)] + list(w0 + dw)),
        predictor=ImmutableMatrix.zeros(n, 1),
        **joint_space_state(scene, phi0, w0, energy),
        unknowns_layout=Layout(tuple(f"dw_{i}" for i in range(1, n + 1)),
                               "the increment dw = w_1 - w_0 of the joint rates (rad/s)"),
        residual_description=("dt-scaled midpoint equations of motion M(phi_m) dw + dt "
                              "(Coriolis + grad V - tau) at the mid-point (N m s)"),
        inputs=inputs, segment_vectors=recursion.segment_vector_entries(scene, frames0),
        definitions=tuple(step.items), state_definitions=tuple(at_state.items),
        input_work=dt * sp.Add(*(tau * w for tau, w in zip(joint_torques(scene, inputs), wm))),
        dissipated=dt * sp.Add(*(number(link.damping) * w ** 2
                                 for link, w in zip(scene.links, wm) if link.damping))
        + law.injected,
        applied_torques=applied_torques,
        flow_description=(CONTROLLED_FLOWS if scene.control else
                          FLOWS if has_energy_flows(scene) else None),
        jacobian_reuse=JACOBIAN_PER_STEP, kinetic_energy=kinetic,
        # The sampled law misses the balance by design (held over the step): no energy check
        # by default there (a caller may still set it). The discrete law keeps it, and at
        # rest the check allows the round-off of H_d's terms (model.md 13).
        newton_overrides=(("energy_tol", 0.0),) if sampled_law(scene) else (),
    )
