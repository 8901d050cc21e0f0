"""Method "midpoint" for a spatial scene: the implicit midpoint rule in joint angles (model.md
section 6) with the spatial recursions (chaingen.symbolic.spatial_recursion).

The planar scheme's equations, unchanged: state (q, w), unknown dw = w_1 - w_0, w_m = w_0 +
dw/2, q_m = q_0 + dt w_m / 2, q_1 = q_0 + dt w_m, and the residual (multiplied by dt)

    M(q_m) dw + dt [C(q_m, w_m) w_m + dV_g/dq(q_m) + dV_s/dq(q_m) - tau + d w_m] = 0,

tau the inputs of the actuated joints, d the joints' damping. Its first three terms are the
Newton-Euler inverse dynamics at (q_m, w_m) with acceleration dw / dt, times dt; the springs'
term is summed over their route segments. O(n) definitions, no mass matrix of the whole chain.
"""
from __future__ import annotations

import sympy as sp
from sympy import ImmutableMatrix

from ...runtime.contract import JACOBIAN_PER_STEP
from ...spatial.values import SpatialScene
from .. import spatial_recursion
from ..com_model import number
from ..recursion import Definitions
from .base import (
    DiscreteScheme,
    Layout,
    has_energy_flows,
    input_symbols,
    joint_space_state,
    joint_torques,
)
from .control import StepControl, sampled_law, spatial_midpoint_control, state_shaping
from .midpoint import CONTROLLED_FLOWS, FLOWS, SUMMARY


def build(scene: SpatialScene, quadrature: int | None = None, order: int = 2) -> DiscreteScheme:
    """The spatial midpoint scheme of `scene`. quadrature plays no role (as for the planar
    midpoint); order: of the composed step, the outputs are the same at every order."""
    n = scene.n
    dt = sp.Symbol("dt", positive=True)
    q0 = ImmutableMatrix(sp.symbols(f"phi1:{n + 1}", real=True))
    w0 = ImmutableMatrix(sp.symbols(f"w1:{n + 1}", real=True))
    dw = ImmutableMatrix(sp.symbols(f"dw1:{n + 1}", real=True))

    step = Definitions("step_")
    wm = [step.define(f"wm{k}", w + d / 2) for k, (w, d) in enumerate(zip(w0, dw), start=1)]
    qm = [step.define(f"phim{k}", q + dt * w / 2)
          for k, (q, w) in enumerate(zip(q0, wm), start=1)]
    frames = spatial_recursion.link_frames(scene, qm, step)
    dynamics = spatial_recursion.inverse_dynamics(scene, frames, wm, list(dw), dt, step)
    springs, _, _ = spatial_recursion.spring_gradient(scene, frames, step)
    inputs = input_symbols(scene)
    plain = joint_torques(scene, inputs)
    law = StepControl(scene, dt)
    torques = plain
    if scene.control:
        controlled = spatial_midpoint_control(scene, dt, q0, w0, wm, step, law)
        torques = [t + c for t, c in zip(plain, controlled)]
    residual = [moment + dt * (spring - torque + number(link.damping) * w)
                for moment, spring, torque, link, w
                in zip(dynamics, springs, torques, scene.links, wm)]

    at_state, kinetic, energy, segments = state_energy(scene, q0, w0)
    applied_torques = None
    if scene.control:
        energy += state_shaping(scene, q0)
        applied_torques = ImmutableMatrix([torques[joint - 1] for joint in scene.actuated])

    return DiscreteScheme.of(
        method="midpoint", quadrature=None, scene=scene, summary=SUMMARY, dt=dt, unknowns=dw,
        residual=ImmutableMatrix(residual),
        next_state=ImmutableMatrix([q + dt * w for q, w in zip(q0, wm)] + list(w0 + dw)),
        predictor=ImmutableMatrix.zeros(n, 1),
        **joint_space_fields(scene, q0, w0, energy),
        unknowns_layout=Layout(tuple(f"dw_{i}" for i in range(1, n + 1)),
                               "the increment dw = w_1 - w_0 of the joint rates (rad/s)"),
        residual_description=("dt-scaled midpoint equations of motion M(q_m) dw + dt "
                              "(Coriolis + grad V - tau) at the mid-point, spatial chain (N m s)"),
        inputs=inputs, definitions=tuple(step.items), state_definitions=tuple(at_state.items),
        segment_vectors=segments,
        input_work=dt * sp.Add(*(tau * w for tau, w in zip(plain, wm))),
        dissipated=dt * sp.Add(*(number(link.damping) * w ** 2
                                 for link, w in zip(scene.links, wm) if link.damping))
        + law.injected,
        applied_torques=applied_torques,
        flow_description=(CONTROLLED_FLOWS if scene.control else
                          FLOWS if has_energy_flows(scene) else None),
        jacobian_reuse=JACOBIAN_PER_STEP, kinetic_energy=kinetic,
        newton_overrides=(("energy_tol", 0.0),) if sampled_law(scene) else (),   # midpoint.py
    )


def state_energy(scene: SpatialScene, q0, w0) -> tuple[Definitions, sp.Expr, sp.Expr,
                                                        ImmutableMatrix]:
    """The energy H = T + V of the state (q_0, w_0) by the recursions, as the state's
    definitions: (those definitions, T, H, the springs' segment vectors as DiscreteScheme's
    segment_vectors)."""
    at_state = Definitions("state_")
    frames0 = spatial_recursion.link_frames(scene, q0, at_state)
    omegas = spatial_recursion.angular_velocities(frames0, w0, at_state)
    velocities = spatial_recursion.com_velocities(frames0, omegas, at_state)
    _, spring_energy, segments = spatial_recursion.spring_gradient(scene, frames0, at_state)
    kinetic = spatial_recursion.kinetic_energy(scene, frames0, omegas, velocities)
    energy = kinetic + spatial_recursion.gravity_potential(scene, frames0) + spring_energy
    return at_state, kinetic, energy, ImmutableMatrix([c for d in segments for c in d])


def joint_space_fields(scene: SpatialScene, q0, w0, energy) -> dict:
    """The fields of a spatial scheme whose state is (q, w) (base.joint_space_state), with
    the holding torques of an actuated scene."""
    fields = joint_space_state(scene, q0, w0, energy)
    if scene.actuated:
        fields.update(holding_torques(scene, fields["initial_angles"]))
    return fields


def holding_torques(scene: SpatialScene, angles) -> dict:
    """The fields of the holding torques dV/dq = dV_g/dq + dV_s/dq at the joint angles
    `angles` (symbols): the Newton-Euler recursion at rest (zero rates and accelerations,
    dt = 1: the gravity torques alone) and the springs' gradient, by initial definitions."""
    defs = Definitions("hold_")
    frames = spatial_recursion.link_frames(scene, angles, defs)
    zeros = [sp.Integer(0)] * scene.n
    gravity = spatial_recursion.inverse_dynamics(scene, frames, zeros, zeros, sp.Integer(1),
                                                 defs)
    springs, _, _ = spatial_recursion.spring_gradient(scene, frames, defs)
    return {"holding_torques": ImmutableMatrix([g + s for g, s in zip(gravity, springs)]),
            "initial_definitions": tuple(defs.items)}
