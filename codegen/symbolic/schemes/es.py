"""Method "es": energy-stable discrete gradient scheme in COM coordinates (model.md section 4).

Petrov-Galerkin discretisation with k = 0 of  M vdot = -grad V + C(q)^T lambda,  qdot = v,
C(q) qdot = 0, with q_1 eliminated (q_1 = q_0 + dt (v_0 + v_1)/2). Unknowns z = (dv, mu) with
dv = v_1 - v_0 and mu = Lambda_1 - Lambda_0, so q_1 - q_0 = dt (v_0 + dv/2). The residual is
model.md's multiplied by dt:

    M dv - C(q_m)^T mu + dt (gradV~ - f~) = 0          (2n equations)
    C(q_m) (q_1 - q_0) = 0                             (n equations)

gradV~ is the average of grad V on the segment q_0 -> q_1: gravity's gradient is constant and
enters exactly; the spring part is averaged with K-point Gauss-Legendre quadrature. f~ is the
generalised force of the joint torques (inputs and damping) at the mid-point (model.md 7).
"""
from __future__ import annotations

import sympy as sp
from sympy import ImmutableMatrix

from ...runtime.contract import JACOBIAN_CHORD_ACROSS_STEPS, JACOBIAN_PER_STEP
from ...scene import Scene, quadrature_used
from ...scene.solver_rules import gradient_used, require
from ..com_model import com_frame_map, coordinates, number
from ..com_recursion import es_step, joint_space_start, state_quantities
from ..recursion import Definitions
from .base import (
    ArmSpace,
    DiscreteScheme,
    FlowDescription,
    Layout,
    common_fields,
    has_energy_flows,
    input_symbols,
    joint_torques,
)
from .control import StepControl, es_control, state_shaping

#: The composed step's Newton tolerance on the update, relative: each stage starts from its own
#: previous solution (the warm start), so the chord stops after fewer iterations, nearer the
#: tolerance, and at the contract's 1e-10 the energy balance of four_link_actuated drifts by
#: 6.4e-12 J over 400 steps of 0.01 s; at 1e-12, 1.5e-13 J for 8 % more iterations.
COMPOSED_UPDATE_RTOL = 1e-12

#: es solves its Newton systems by the Jacobian's factors (ArmSpace, O(n^2)) from this many
#: links on, by dense LU of the 3n x 3n Jacobian below (docs/benchmarks.md, the switch).
ARM_SOLVE_MIN_LINKS = 4

SUMMARY = ("Energy-stable discrete gradient scheme in COM coordinates with constraints "
           "(docs/model.md, section 4).")
FLOWS = FlowDescription(
    "dt sum_i tau_i phidot_i(m)", "dt sum_i d_i phidot_i(m)^2",
    "phidot(m) the joint rates at the step's mid-point, where the torques enter. The scheme is "
    "passive: H_1 - H_0 = flows[0] - flows[1] to quadrature and solver accuracy (docs/model.md, "
    "section 7).")

CONTROLLED_FLOWS = FlowDescription(
    "dt sum_i u_i phidot_i(m)", "dt sum_i d_i phidot_i(m)^2 + injected",
    "u the inputs added to the control law's torques, injected the control law's damping "
    "injection (docs/controllers.md). The energy is the closed loop's H_d = T + V + V_s; with "
    "the discrete law H_d1 - H_d0 = flows[0] - flows[1] to round-off at any dt.")


def build(scene: Scene, quadrature: int, order: int = 2,
          arm_solve: bool | None = None, gradient: str = "exact") -> DiscreteScheme:
    """The es step; for order > 2 (a composition of steps) the joint rates come from the
    velocity projected onto C(q) v = 0 (com_recursion.projected_rates). arm_solve: whether the
    package solves the Newton systems by the factors of the Jacobian (ArmSpace) instead of
    dense LU; None: from ARM_SOLVE_MIN_LINKS links on. gradient: the springs' discrete
    gradient, "exact" (the energy balance holds identically), "quadrature" (the K-point
    average alone) or "chain" (the chain rule's, exact without quadrature; docs/model.md,
    section 4.3)."""
    require(method="es", quadrature=quadrature, order=order, gradient=gradient)
    if order > 4:
        raise ValueError("es composes its own step to order 4 at most: order 6 is "
                         "chaingen.symbolic.schemes.galerkin's")
    n = scene.n
    if arm_solve is None:
        # A control law's torque couples its joint's arms to every arm outboard of it (its
        # compensation of gravity and the springs): H = dh/dw fills up to (2n)^2 nonzeros,
        # which the factors take as they take a banded H (the reduced system S is formed
        # densely anyway). At n = 10 a controlled step costs 16.4 us by them against 62.4 us by
        # dense LU, the same iterations (docs/controllers.md).
        arm_solve = n >= ARM_SOLVE_MIN_LINKS
    dt = sp.Symbol("dt", positive=True)
    q0, v0 = coordinates(scene)
    # The unknown is the velocity increment dv = v_1 - v_0 (then dq = dt (v_0 + dv/2), the
    # same scheme). With q_1 or dq as unknown, M (v_1 - v_0) is a difference of O(|v|) terms
    # whose round-off, eps |M v| per step, random-walks into the energy (2-4e-12 over the
    # standard gravity run); with dv it is computed without cancellation.
    dv = ImmutableMatrix(sp.symbols([f"d{s}" for s in map(str, v0)], real=True))
    mu = ImmutableMatrix(sp.symbols(f"mu1:{n + 1}", real=True))
    dq = dt * (v0 + dv / 2)
    q1 = q0 + dq
    v1 = v0 + dv
    # The residual by recursions over the links (com_recursion): O(n) definitions. Joint
    # torques, input u and damping -d_i phidot_i, enter f~ at the mid-point (model.md 7):
    # then dt f~ . v_m = dt sum_i tau_i phidot_i(m), and the discrete energy balance
    # H_1 - H_0 = work - dissipated holds to quadrature and solver accuracy.
    inputs = input_symbols(scene)
    applied = joint_torques(scene, inputs)

    def torques_of(rates):
        return [u - number(link.damping) * rate
                for u, link, rate in zip(applied, scene.links, rates)]

    step = Definitions("step_")
    law = StepControl(scene, dt)
    parts = es_step(scene, q0, v0, dv, mu, dt, quadrature if scene.springs else 1, torques_of,
                    step, gradient=gradient,
                    control=es_control(scene, dt, step, law) if scene.control else None,
                    chord=arm_solve)
    rates_mid = parts.rates
    definitions = tuple(step.items)
    input_work = dt * sp.Add(*(u * rate for u, rate in zip(applied, rates_mid)))
    dissipated = dt * sp.Add(*(number(link.damping) * rate ** 2
                               for link, rate in zip(scene.links, rates_mid) if link.damping))
    dissipated += law.injected
    residual = ImmutableMatrix(list(parts.momentum) + list(parts.constraint_increments))
    arm_space = None
    if arm_solve:
        arm_space = ArmSpace(
            arm_increments=ImmutableMatrix([c for w in parts.arm_increments for c in w]),
            forces=ImmutableMatrix([c for h in parts.forces for c in h]),
            newton_forces=None if parts.newton_forces is None else
            ImmutableMatrix([c for h in parts.newton_forces for c in h]),
            masses=ImmutableMatrix([number(link.mass) for link in scene.links]),
            maps=ImmutableMatrix([number(link.length) * entry for link in scene.links
                                  for entry in com_frame_map(link)]))

    # Joint space: phi_i is the angle from e_{i-1} to e_i, wrapped to (-pi, pi] by atan2; the
    # state's quantities by the same recursions (com_recursion.state_quantities).
    # A composed step (order > 2) reports the rates of the velocity projected onto
    # C(q) v = 0 (the nodal v meets it only to O(dt^2), which a composition cannot cancel;
    # model.md 14), by recursions in O(n) (com_recursion.projected_rates).
    at_state = Definitions("state_")
    # A controlled scene's too: at rest, the normal component's sign flips every step and
    # would show in the plain rates (docs/controllers.md).
    projected = order > 2 or scene.control is not None
    quantities = state_quantities(scene, q0, v0, at_state, projected=projected)
    velocities = quantities["projected_rates" if projected else "rates"]

    phi = ImmutableMatrix(sp.symbols(f"phi1:{n + 1}", real=True))
    phidot = ImmutableMatrix(sp.symbols(f"phidot1:{n + 1}", real=True))
    at_start = Definitions("initial_")
    initial_state = ImmutableMatrix(joint_space_start(scene, phi, phidot, at_start))

    energy = quantities["energy"]
    applied_torques = None
    if scene.control:
        energy += state_shaping(scene, quantities["angles"])
        applied_torques = ImmutableMatrix([u + t for u, t in zip(inputs, law.actuated_torques)])

    names = [f"x_{i}" for i in range(1, n + 1)] + [f"y_{i}" for i in range(1, n + 1)]
    return DiscreteScheme.of(
        method="es", quadrature=quadrature_used(scene, "es", quadrature), scene=scene,
        gradient=gradient_used(scene, "es", gradient, order),
        summary=SUMMARY, dt=dt,
        state=ImmutableMatrix.vstack(q0, v0),
        unknowns=ImmutableMatrix.vstack(dv, mu),
        residual=residual,
        next_state=ImmutableMatrix.vstack(q1, v1),
        predictor=ImmutableMatrix.zeros(3 * n, 1),
        joint_angles=ImmutableMatrix(quantities["angles"]),
        joint_velocities=ImmutableMatrix(velocities),
        energy=energy, applied_torques=applied_torques,
        constraint_residuals=ImmutableMatrix(quantities["constraints"]),
        initial_angles=phi, initial_velocities=phidot, initial_state=initial_state,
        state_layout=Layout(
            tuple(names + ["v" + c for c in names]),
            "COM positions q = (x_1..x_n, y_1..y_n) in m, then their velocities v in m/s"),
        unknowns_layout=Layout(
            tuple("dv" + c for c in names) + tuple(f"mu_{i}" for i in range(1, n + 1)),
            "the increment dv = v_1 - v_0 of the COM velocities over the step (m/s), then the "
            "constraint impulses mu = Lambda_1 - Lambda_0 (kg/s: C^T mu is a momentum)"),
        residual_description=(
            "dt-scaled momentum balance M dv - C(q_m)^T mu + dt (gradV~ - f~) (2n entries, "
            "kg m/s), then the constraint increments C(q_m) (q_1 - q_0) (n entries, m^2)"),
        inputs=inputs, input_work=input_work, dissipated=dissipated,
        segment_vectors=ImmutableMatrix(quantities["segment_vectors"]),
        definitions=definitions, state_definitions=tuple(at_state.items),
        initial_definitions=tuple(at_start.items),
        flow_description=(CONTROLLED_FLOWS if scene.control else
                          FLOWS if has_energy_flows(scene) else None),
        # Newton-chord: from the warm start the chord update is already at round-off, so a step
        # costs one Jacobian, one factorisation and two residuals, with the energy balance of
        # full Newton (docs/benchmarks.md, speed knobs). The order-2 step keeps the chord's
        # Jacobian across chained steps while it contracts (docs/model.md, section 13): on a
        # long chain the first guess is far from the root, and the last step's Jacobian serves
        # its chord as well as one evaluated at the guess.
        jacobian_reuse=JACOBIAN_CHORD_ACROSS_STEPS if order == 2 else JACOBIAN_PER_STEP,
        state_from_joint_space=False,
        newton_overrides=(("update_rtol", COMPOSED_UPDATE_RTOL),) if order > 2 else (),
        arm_space=arm_space,
        **common_fields(scene, phi),
    )
