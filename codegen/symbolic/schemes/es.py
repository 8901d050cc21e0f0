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

from ...errors import SettingsError
from ...runtime.contract import JACOBIAN_PER_STEP
from ...scene import Scene, quadrature_used
from ..com_model import (
    com_model,
    cross2,
    dot2,
    joint_space_positions,
    joint_space_velocities,
    linear_coefficients,
    number,
)
from ..composition import order_error
from ..quadrature import gauss_legendre_nodes
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

#: The composed step's Newton tolerance on the update, relative: each stage starts from its own
#: previous solution (the warm start), so the chord stops after fewer iterations, nearer the
#: tolerance, and at the contract's 1e-10 the energy balance of four_link_actuated drifts by
#: 6.4e-12 J over 400 steps of 0.01 s; at 1e-12, 1.5e-13 J for 8 % more iterations.
COMPOSED_UPDATE_RTOL = 1e-12

SUMMARY = ("Energy-stable discrete gradient scheme in COM coordinates with constraints "
           "(docs/model.md, section 4).")
FLOWS = FlowDescription(
    "dt sum_i tau_i phidot_i(m)", "dt sum_i d_i phidot_i(m)^2",
    "phidot(m) the joint rates at the step's mid-point, where the torques enter. The scheme is "
    "passive: H_1 - H_0 = flows[0] - flows[1] to quadrature and solver accuracy (docs/model.md, "
    "section 7).")


def averaged_spring_gradient(model, q0, q1, quadrature: int):
    """sum_g w_g grad V_springs(q_0 + tau_g (q_1 - q_0)) (model.md section 4), and the
    definitions it uses.

    Every segment vector d_j = P_{j+1} - P_j is affine in q, d_j = D_j q + c_j, so with
    s_j = |d_j| and the stretch e = sum_j s_j - S_0 the gradient of 1/2 k e^2 is
    k e sum_j D_j^T d_j / s_j: written down, not differentiated. At a quadrature node
    d_j(q_tau) = d_j(q_0) + tau (d_j(q_1) - d_j(q_0)); the node's segment vectors and lengths
    are defined once as symbols (DiscreteScheme.definitions), so that a long chain's gradient
    stays a sum of small terms.
    """
    nodes, weights = gauss_legendre_nodes(quadrature)
    total = [sp.Integer(0)] * len(model.q)
    increments = sp.symbols([f"d{symbol}" for symbol in map(str, model.q)], real=True)
    definitions = [(d, b - a) for d, a, b in zip(increments, q0, q1)]
    increments = ImmutableMatrix(increments)
    for i, term in enumerate(model.springs):
        segments = []
        for j, vector in enumerate(term.segment_vectors):
            D, c = linear_coefficients(vector, model.q)
            start = sp.symbols(f"spring{i}_d{j}_x spring{i}_d{j}_y", real=True)
            change = sp.symbols(f"spring{i}_dd{j}_x spring{i}_dd{j}_y", real=True)
            definitions += list(zip(start, D * q0 + c)) + list(zip(change, D * increments))
            segments.append((j, D, ImmutableMatrix(start), ImmutableMatrix(change)))
        for g, (tau, weight) in enumerate(zip(nodes, weights)):
            lengths, directions = [], []
            for j, D, start, change in segments:
                dx, dy, length = sp.symbols(f"spring{i}_d{j}_node{g}_x spring{i}_d{j}_node{g}_y "
                                            f"spring{i}_s{j}_node{g}", real=True)
                point = start + sp.Float(tau) * change
                definitions += [(dx, point[0]), (dy, point[1]),
                                (length, sp.sqrt(dx ** 2 + dy ** 2))]
                lengths.append(length)
                directions.append((j, D, dx, dy, length))
            stretch = sp.Add(*lengths) - number(term.spring.rest_length)
            force = sp.Symbol(f"spring{i}_force{g}", real=True)
            definitions.append((force, sp.Float(weight) * number(term.spring.stiffness) * stretch))
            for j, D, dx, dy, length in directions:
                # The force along the segment, (fx, fy) = w k e d_j / s_j, once per segment and
                # node: the gradient's entries are then sums of constant multiples of it.
                fx, fy = sp.symbols(f"spring{i}_f{j}_node{g}_x spring{i}_f{j}_node{g}_y",
                                    real=True)
                scale = sp.Symbol(f"spring{i}_scale{j}_node{g}", real=True)
                definitions += [(scale, force / length), (fx, scale * dx), (fy, scale * dy)]
                for k in range(len(model.q)):
                    if D[0, k] != 0 or D[1, k] != 0:
                        total[k] += D[0, k] * fx + D[1, k] * fy
    return ImmutableMatrix(total), tuple(definitions)


def relative_rates(model) -> list[sp.Expr]:
    """phidot_i = thetadot_i - thetadot_{i-1}, linear in v (model.md sections 4 and 7)."""
    rates = (sp.Integer(0),) + model.absolute_rates()
    return [after - before for before, after in zip(rates[:-1], rates[1:])]


def joint_force(model, torques) -> ImmutableMatrix:
    """Generalised force f = sum_i tau_i grad_v(phidot_i) of joint torques tau_i (model.md 7).

    Its power f . v is sum_i tau_i phidot_i, because phidot_i is linear in v.
    """
    force = sp.zeros(len(model.v), 1)
    for rate, torque in zip(relative_rates(model), torques):
        if torque != 0:
            force += torque * ImmutableMatrix([rate]).jacobian(model.v).T
    return ImmutableMatrix(force)


def tangent_velocity_solve(model) -> tuple[LinearSolve, ImmutableMatrix]:
    """The nodal velocity v_k of es satisfies the velocity constraint C(q) v = 0 only to
    O(dt^2) (the scheme imposes it at the mid-point of each step); a composition of steps
    cannot cancel that part. Its M-orthogonal projection onto C(q) v = 0,

        [M  C^T] [v_t   ]   [M v]
        [C   0 ] [lambda] = [ 0 ],

    does: the joint rates of the composed step of order 4 taken from v_t are of order 4
    (from v, of order 2). Returns the solve and v_t's symbols."""
    n = model.n
    tangent = ImmutableMatrix([sp.Dummy(f"vt{i}", real=True) for i in range(2 * n)])
    multipliers = ImmutableMatrix([sp.Dummy(f"lambda{i}", real=True) for i in range(n)])
    jacobian = model.constraint_jacobian
    matrix = ImmutableMatrix.vstack(
        ImmutableMatrix.hstack(model.mass_matrix, jacobian.T),
        ImmutableMatrix.hstack(jacobian, ImmutableMatrix.zeros(n, n)))
    rhs = ImmutableMatrix.vstack(model.mass_matrix * model.v, ImmutableMatrix.zeros(n, 1))
    return (LinearSolve(symbols=ImmutableMatrix.vstack(tangent, multipliers), matrix=matrix,
                        rhs=rhs), tangent)


def build(scene: Scene, quadrature: int, order: int = 2) -> DiscreteScheme:
    """The es step; for order > 2 (a composition of steps) the joint rates come from the
    velocity projected onto C(q) v = 0 (tangent_velocity_solve)."""
    refused = order_error("es", order)
    if refused:
        raise SettingsError(f"--order {order}: {refused}")
    if order > 4:
        raise ValueError("es composes its own step to order 4 at most: order 6 is "
                         "chaingen.symbolic.schemes.galerkin's")
    model = com_model(scene)
    n = scene.n
    dt = sp.Symbol("dt", positive=True)
    q0, v0 = model.q, model.v
    # The unknown is the velocity increment dv = v_1 - v_0 (then dq = dt (v_0 + dv/2), the
    # same scheme). With q_1 or dq as unknown, M (v_1 - v_0) is a difference of O(|v|) terms
    # whose round-off, eps |M v| per step, random-walks into the energy (2-4e-12 over the
    # standard gravity run); with dv it is computed without cancellation.
    dv = ImmutableMatrix(sp.symbols([f"d{s}" for s in map(str, model.v)], real=True))
    mu = ImmutableMatrix(sp.symbols(f"mu1:{n + 1}", real=True))
    dq = dt * (v0 + dv / 2)
    q1 = q0 + dq
    v1 = v0 + dv
    qm = q0 + dq / 2
    constraint_jacobian_mid = model.constraint_jacobian.xreplace(dict(zip(model.q, qm)))

    gradient = ImmutableMatrix([model.gravity_potential]).jacobian(model.q).T
    definitions = ()
    if model.springs:
        spring_gradient, definitions = averaged_spring_gradient(model, q0, q1, quadrature)
        gradient = gradient + spring_gradient
    momentum_balance = (model.mass_matrix * dv - constraint_jacobian_mid.T * mu
                        + dt * gradient)
    # Joint torques, input u and damping -d_i phidot_i, enter f~ at the mid-point (model.md 7):
    # then dt f~ . v_m = dt sum_i tau_i phidot_i(m), and the discrete energy balance
    # H_1 - H_0 = work - dissipated holds to quadrature and solver accuracy.
    inputs = input_symbols(scene)
    midpoint = {**dict(zip(model.q, qm)), **dict(zip(model.v, (v0 + v1) / 2))}
    rates_mid = [rate.xreplace(midpoint) for rate in relative_rates(model)]
    torques = [u - number(link.damping) * rate for u, link, rate
               in zip(joint_torques(scene, inputs), scene.links, relative_rates(model))]
    if any(torque != 0 for torque in torques):
        momentum_balance -= dt * joint_force(model, torques).xreplace(midpoint)
    input_work = dt * sp.Add(*(u * rate for u, rate in zip(joint_torques(scene, inputs),
                                                           rates_mid)))
    dissipated = dt * sp.Add(*(number(link.damping) * rate ** 2
                               for link, rate in zip(scene.links, rates_mid) if link.damping))
    constraint_increment = constraint_jacobian_mid * dq
    residual = ImmutableMatrix.vstack(momentum_balance, constraint_increment)

    # Joint space: phi_i is the angle from e_{i-1} to e_i, wrapped to (-pi, pi] by atan2.
    directions = (ImmutableMatrix([1, 0]),) + model.directions
    angles = [sp.atan2(cross2(a, b), dot2(a, b)) for a, b in zip(directions[:-1], directions[1:])]
    velocities = relative_rates(model)
    output_solve = None
    if order > 2:
        output_solve, tangent = tangent_velocity_solve(model)
        velocities = [rate.xreplace(dict(zip(model.v, tangent))) for rate in velocities]

    phi = ImmutableMatrix(sp.symbols(f"phi1:{n + 1}", real=True))
    phidot = ImmutableMatrix(sp.symbols(f"phidot1:{n + 1}", real=True))
    xs, ys = joint_space_positions(scene, phi)
    vxs, vys = joint_space_velocities(scene, phi, phidot)
    initial_state = ImmutableMatrix(xs + ys + vxs + vys)

    coordinates = [f"x_{i}" for i in range(1, n + 1)] + [f"y_{i}" for i in range(1, n + 1)]
    return DiscreteScheme(
        method="es", quadrature=quadrature_used(scene, "es", quadrature), scene=scene,
        summary=SUMMARY, dt=dt,
        state=ImmutableMatrix.vstack(q0, v0),
        unknowns=ImmutableMatrix.vstack(dv, mu),
        residual=residual,
        next_state=ImmutableMatrix.vstack(q1, v1),
        predictor=ImmutableMatrix.zeros(3 * n, 1),
        joint_angles=ImmutableMatrix(angles),
        joint_velocities=ImmutableMatrix(velocities),
        output_solve=output_solve,
        energy=model.energy,
        constraint_residuals=model.constraints,
        initial_angles=phi, initial_velocities=phidot, initial_state=initial_state,
        state_layout=Layout(
            tuple(coordinates + ["v" + c for c in coordinates]),
            "COM positions q = (x_1..x_n, y_1..y_n) in m, then their velocities v in m/s"),
        unknowns_layout=Layout(
            tuple("dv" + c for c in coordinates) + tuple(f"mu_{i}" for i in range(1, n + 1)),
            "the increment dv = v_1 - v_0 of the COM velocities over the step (m/s), then the "
            "constraint impulses mu = Lambda_1 - Lambda_0 (kg/s: C^T mu is a momentum)"),
        residual_description=(
            "dt-scaled momentum balance M dv - C(q_m)^T mu + dt (gradV~ - f~) (2n entries, "
            "kg m/s), then the constraint increments C(q_m) (q_1 - q_0) (n entries, m^2)"),
        inputs=inputs, input_work=input_work, dissipated=dissipated,
        segment_vectors=segment_vectors(model), definitions=definitions,
        flow_description=FLOWS if has_energy_flows(scene) else None,
        # Newton-chord: from the warm start the chord update is already at round-off, so a step
        # costs one Jacobian, one factorisation and two residuals, with the energy balance of
        # full Newton (docs/benchmarks.md, speed knobs).
        jacobian_reuse=JACOBIAN_PER_STEP, state_from_joint_space=False,
        newton_overrides=(("update_rtol", COMPOSED_UPDATE_RTOL),) if order > 2 else (),
        **common_fields(scene, phi),
    )
