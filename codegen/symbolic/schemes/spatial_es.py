"""Method "es" for a spatial scene: the energy-momentum scheme of Betsch and Steinmann (2001) in
director coordinates (docs/model.md section 4.8), the spatial counterpart of the planar es.

Each link i is its centre of mass x_i and three directors d_i1, d_i2, d_i3 (the columns of its
rotation R_i): the state x = (q, v) has 24 entries per link, q link by link (x_i, d_i1, d_i2,
d_i3) and v = qdot in the same layout. Eleven constraints per link, linear or quadratic in q
(orthonormality 6, joint point 3, joint axis 2; chaingen.symbolic.spatial_com_model). The
scheme is the energy-momentum step

    M dv + G(q_m)^T mu + dt (gradV~(q_0, q_1) - f(q_m, v_m)) = 0,    g(q_1) = 0,

dv = v_1 - v_0, v_m = (q_1 - q_0)/dt = v_0 + dv/2, M constant, gradV~ the chain rule's exact
discrete gradient of the springs (model.md 4.3) plus gravity's constant gradient, f the joint
torques (inputs and damping) as equal and opposite couples on the directors at the mid-point;
so H_1 - H_0 = dt sum_i tau_i phidot_i(m) to round-off and the Newton tolerance. It is solved by
the discrete null space method with nodal reparametrisation (chaingen.symbolic.schemes.
spatial_null_space): unknowns the n turns w of the joints, q_1 = q_0 + dq(q_0, w) on the
constraints by construction, residual P(q_m)^T (M dv + dt (gradV~ - f)), the impulses mu gone.
O(n + route points) definitions; chaingen.symbolic.spatial_com_model is the same step on the
full saddle point in numpy, which the tests hold this one to.
"""
from __future__ import annotations

import numpy as np
import sympy as sp
from sympy import ImmutableMatrix

from ...errors import UnsupportedSceneError
from ...runtime.contract import JACOBIAN_CHORD_ACROSS_STEPS
from ...scene.solver_rules import GALERKIN_ORDER
from ...scene.solver_rules import ORDERS as RULES_ORDERS
from ...spatial.dynamics import rpy_matrix
from ...spatial.values import SpatialScene
from .. import spatial_recursion as vectors
from ..com_model import number
from ..recursion import Definitions
from ..spatial_com_model import DIRECTOR_PAIRS, orthogonal_pair
from . import spatial_galerkin
from .base import (
    DiscreteScheme,
    FlowDescription,
    Layout,
    has_energy_flows,
    input_symbols,
    joint_torques,
)
from .control import StepControl, sampled_law, spatial_es_control, state_shaping
from .es import CONTROLLED_FLOWS
from .spatial_midpoint import holding_torques
from .spatial_null_space import (
    Link,
    coms,
    joint_moments,
    mass_times,
    newton_matrix,
    projected_rates,
    turned_frames,
)

add, scale, cross, dot, constant = (vectors.add, vectors.scale, vectors.cross, vectors.dot,
                                    vectors.constant)

SUMMARY = ("Energy-momentum scheme in director coordinates with quadratic constraints "
           "(Betsch and Steinmann; docs/model.md, section 4.8).")
FLOWS = FlowDescription(
    "dt sum_i tau_i phidot_i(m)", "dt sum_i d_i phidot_i(m)^2",
    "phidot_i(m) = n_i . (omega_i - omega_{i-1}) at the step's mid-point, omega = 1/2 sum_a "
    "d_a x ddot_a. The scheme is passive: H_1 - H_0 = flows[0] - flows[1] to round-off and the "
    "Newton tolerance (docs/model.md, section 4.8).")
#: The step's Newton tolerances on the update of the turns w (the contract's are 1e-10, 1e-13).
UPDATE_TOLERANCES = (("update_rtol", 1e-12), ("update_atol", 1e-15))
#: The energy check of a converged step (docs/model.md 4.8, "Spurious roots"): a root of the
#: projected residual keeps H_1 - H_0 = W - D to round-off and Newton's tolerance (1e-13 of
#: T measured) only while P(q_m) spans the null space of G(q_m); a step that turns a link by
#: close to 180 degrees is not such a root and misses it by O(T) (48 J on spatial_three_link at
#: dt = 0.05 s). Six orders above the first, far below the second: the step is refused and split.
ENERGY_TOL = 1e-6
#: The names of a link's 12 coordinates, in the state's order.
COORDINATE_NAMES = tuple(f"{body}_{axis}" for body in ("x", "d1", "d2", "d3") for axis in "xyz")


class Forces:
    """A generalized force of 12n entries, accumulated per link as forces on x and d_a."""

    def __init__(self, n: int):
        self.entries = [sp.Integer(0)] * (12 * n)

    def on(self, i: int, body: int, vector) -> None:
        """Add `vector` to link i's x (body 0) or director d_body (1..3); the base takes none."""
        if i == 0:
            return
        start = 12 * (i - 1) + 3 * body
        for k in range(3):
            self.entries[start + k] += vector[k]

    def on_point(self, i: int, local, com, vector) -> None:
        """A force at a point of link i: A^T vector with the point x + sum_a (local - com)_a d_a."""
        self.on(i, 0, vector)
        for a, c in enumerate(np.asarray(local, dtype=float) - com):
            if c != 0:
                self.on(i, a + 1, scale(number(c), vector))


def constraint_values(scene: SpatialScene, q) -> list:
    """g(q), LINK_CONSTRAINTS per link (spatial_com_model.constraints)."""
    centres = coms(scene)
    values = []
    for i, link in enumerate(scene.links, start=1):
        own, parent = Link(q, i), Link(q, i - 1)
        values += [dot(own.d[a], own.d[b]) - int(a == b) for a, b in DIRECTOR_PAIRS]
        joint = parent.point(link.joint.xyz, centres[i - 1])
        values += list(add(own.point(np.zeros(3), centres[i]), scale(-1, joint)))
        axis = parent.turn(rpy_matrix(link.joint.rpy) @ np.asarray(link.joint.axis))
        values += [dot(axis, own.turn(normal)) for normal in orthogonal_pair(link.joint.axis)]
    return values


def route_points(scene: SpatialScene, spring, q) -> list:
    centres = coms(scene)
    return [Link(q, point.link).point(point.point, centres[point.link])
            for point in spring.route]


def joint_rates(scene: SpatialScene, q, v, defs: Definitions, tag: str) -> tuple[list, list]:
    """(n_i, phidot_i): the joint axes in the world, and phidot_i = n_i . (omega_i -
    omega_{i-1}) with omega_i = 1/2 sum_a d_ia x ddot_ia (spatial_com_model.joint_rates)."""
    omegas, axes, rates = [(sp.Integer(0),) * 3], [], []
    for i, link in enumerate(scene.links, start=1):
        own, rate = Link(q, i), Link(v, i)
        omegas.append(vectors.define_vector(defs, f"{tag}omega{i}", scale(
            sp.Rational(1, 2), add(*(cross(d, dd) for d, dd in zip(own.d, rate.d))))))
        axis = Link(q, i - 1).turn(rpy_matrix(link.joint.rpy) @ np.asarray(link.joint.axis))
        axes.append(vectors.define_vector(defs, f"{tag}n{i}", axis))
        rates.append(defs.define(f"{tag}phidot{i}",
                                 dot(axes[-1], add(omegas[i], scale(-1, omegas[i - 1])))))
    return axes, rates


def potential(scene: SpatialScene, q, defs: Definitions) -> tuple[sp.Expr, list]:
    """(V(q), the route segments' vectors): gravity -sum m_i g . x_i and the springs'
    1/2 k (L - L_0)^2."""
    gravity = constant(scene.gravity)
    energy = -sp.Add(*(number(link.mass) * dot(gravity, Link(q, i).x)
                       for i, link in enumerate(scene.links, start=1)))
    segments = []
    for s, spring in enumerate(scene.springs, start=1):
        points = route_points(scene, spring, q)
        length = sp.Integer(0)
        for j, (start, end) in enumerate(zip(points, points[1:]), start=1):
            segment = vectors.define_vector(defs, f"D{s}_{j}", add(end, scale(-1, start)))
            segments.append(segment)
            length += defs.define(f"s{s}_{j}", sp.sqrt(dot(segment, segment)))
        energy += number(spring.stiffness) / 2 * (length - number(spring.rest_length)) ** 2
    return energy, segments


def potential_gradient(scene: SpatialScene, q0, q1, defs: Definitions) -> list:
    """gradV~(q_0, q_1): gravity's constant gradient and per spring the chain rule's exact
    discrete gradient k (L~ - L_0) sum_j A_j^T (D_j0 + D_j1) / (s_j0 + s_j1) (model.md 4.3)."""
    centres = coms(scene)
    forces = Forces(scene.n)
    for i, link in enumerate(scene.links, start=1):
        forces.on(i, 0, scale(-number(link.mass), constant(scene.gravity)))
    for s, spring in enumerate(scene.springs, start=1):
        ends = list(zip(route_points(scene, spring, q0), route_points(scene, spring, q1)))
        sums, total = [], sp.Integer(0)
        for j, ((a0, a1), (b0, b1)) in enumerate(zip(ends, ends[1:]), start=1):
            d0 = vectors.define_vector(defs, f"D{s}_{j}_0", add(b0, scale(-1, a0)))
            d1 = vectors.define_vector(defs, f"D{s}_{j}_1", add(b1, scale(-1, a1)))
            both = defs.define(f"s{s}_{j}", sp.sqrt(dot(d0, d0)) + sp.sqrt(dot(d1, d1)))
            sums.append((add(d0, d1), both))
            total += both
        pull = defs.define(f"F{s}", number(spring.stiffness)
                           * (total / 2 - number(spring.rest_length)))
        route = spring.route
        for j, (direction, both) in enumerate(sums, start=1):
            w = vectors.define_vector(defs, f"w{s}_{j}", scale(pull / both, direction))
            forces.on_point(route[j].link, route[j].point, centres[route[j].link], w)
            forces.on_point(route[j - 1].link, route[j - 1].point, centres[route[j - 1].link],
                            scale(-1, w))
    return forces.entries


def torque_forces(scene: SpatialScene, q, axes, torques) -> list:
    """The joint torques as couples tau_i n_i on link i and -tau_i n_i on link i-1: tau/2 n x
    d_a on each director (spatial_com_model.torque_forces)."""
    forces = Forces(scene.n)
    for i, (axis, tau) in enumerate(zip(axes, torques), start=1):
        if tau == 0:
            continue
        for link, sign in ((i, 1), (i - 1, -1)):
            for a, d in enumerate(Link(q, link).d, start=1):
                forces.on(link, a, scale(sign * tau / 2, cross(axis, d)))
    return forces.entries


def joint_angles(scene: SpatialScene, q) -> list:
    """phi_i = atan2((R_{i-1} J_i b_2) . (R_i b_1), (R_{i-1} J_i b_1) . (R_i b_1)), wrapped
    to (-pi, pi] (spatial_com_model.joint_angles)."""
    angles = []
    for i, link in enumerate(scene.links, start=1):
        first, second = orthogonal_pair(link.joint.axis)
        fixed = rpy_matrix(link.joint.rpy)
        turned = Link(q, i).turn(first)
        parent = Link(q, i - 1)
        angles.append(sp.atan2(dot(parent.turn(fixed @ second), turned),
                               dot(parent.turn(fixed @ first), turned)))
    return angles


def joint_space_start(scene: SpatialScene, phi, phidot, defs: Definitions) -> list:
    """x(phi, phidot): the links' poses by the joint-space recursion (spatial_recursion), the
    COM velocities, and ddot_ia = omega_i x d_ia."""
    frames = vectors.link_frames(scene, phi, defs)
    omegas = vectors.angular_velocities(frames, phidot, defs)
    velocities = vectors.com_velocities(frames, omegas, defs)
    q, v = [], []
    for rotation, origin, arm, omega, velocity in zip(frames.rotations, frames.origins,
                                                      frames.arms, omegas, velocities):
        columns = [tuple(rotation[r][a] for r in range(3)) for a in range(3)]
        q += list(add(origin, arm)) + [c for column in columns for c in column]
        v += list(velocity) + [c for column in columns for c in cross(omega, column)]
    return q + v


#: The orders of the step this builder takes (chaingen.symbolic.schemes.orders_taken asks it):
#: every order of the rules, order 2 and its composition to order 4, and at order 6 another
#: step composed, the k = 1 Galerkin step in joint angles (spatial_galerkin; a composition of
#: this one stalls at order 4, docs/model.md 14).
ORDERS = RULES_ORDERS


def build(scene: SpatialScene, quadrature: int | None = None, order: int = 2) -> DiscreteScheme:
    """The spatial es scheme of `scene`, by the discrete null space method with nodal
    reparametrisation (Betsch and Leyendecker 2006; docs/model.md 4.8): n unknowns, one turn per
    joint. quadrature plays no role (the springs' discrete gradient is exact without it).
    Order 2, and 4 by composition (chaingen.symbolic.composition). From order 6 (its
    composition stalls at 4, model.md 14) the k = 1 Galerkin step in joint angles with the
    (quadrature + 1)-point Gauss-Lobatto rule (chaingen.symbolic.schemes.spatial_galerkin,
    model.md 16), which build_scheme composes by Suzuki's 5 stages."""
    if order >= GALERKIN_ORDER:
        return spatial_galerkin.build(scene, quadrature, order)
    if order not in ORDERS:
        raise UnsupportedSceneError(
            f"order {order}: es for a spatial scene (scene {scene.name!r}) takes orders "
            f"{', '.join(map(str, ORDERS))}")
    n = scene.n
    dt = sp.Symbol("dt", positive=True)
    names = [f"{name[0]}{i}{name[1:]}" for i in range(1, n + 1) for name in COORDINATE_NAMES]
    q0 = ImmutableMatrix(sp.symbols(names, real=True))
    v0 = ImmutableMatrix(sp.symbols([f"v{name}" for name in names], real=True))
    turns = ImmutableMatrix(sp.symbols(f"w1:{n + 1}", real=True))

    step = Definitions("step_")
    dq = turned_frames(scene, q0, turns, step)
    q1 = [step.define(f"q1_{k}", q + d) for k, (q, d) in enumerate(zip(q0, dq))]
    vm = [step.define(f"vm_{k}", d / dt) for k, d in enumerate(dq)]
    qm = [step.define(f"qm_{k}", q + d / 2) for k, (q, d) in enumerate(zip(q0, dq))]
    dv = [step.define(f"dv_{k}", 2 * (v - w)) for k, (v, w) in enumerate(zip(vm, v0))]
    axes, rates = joint_rates(scene, qm, vm, step, "m")
    inputs = input_symbols(scene)
    applied = joint_torques(scene, inputs)
    law = StepControl(scene, dt)
    controlled = [sp.Integer(0)] * n
    if scene.control:
        start_axes, start_rates = joint_rates(scene, q0, v0, step, "c0")
        measured = projected_rates(scene, q0, v0, start_axes, step)
        controlled = spatial_es_control(scene, dt, q0, q1, joint_angles(scene, q0), rates, axes,
                                        measured, step, law)
    torques = [step.define(f"tau{i}", u - number(link.damping) * rate + c)
               for i, (u, link, rate, c) in enumerate(zip(applied, scene.links, rates,
                                                          controlled), start=1)]
    momentum = [a + dt * (c - d) for a, c, d in zip(
        mass_times(scene, dv), potential_gradient(scene, q0, q1, step),
        torque_forces(scene, qm, axes, torques))]
    residual = ImmutableMatrix(joint_moments(scene, qm, momentum, axes, step))
    newton = newton_matrix(scene, qm, q1, axes, turns, dt, step)

    at_state = Definitions("state_")
    state_axes, state_rates = joint_rates(scene, q0, v0, at_state, "")
    # A composed step (order 4) reports the rates of v projected onto the tangent space
    # (model.md 14), as the planar es does.
    outputs_rates = (projected_rates(scene, q0, v0, state_axes, at_state)
                     if order > 2 or scene.control else state_rates)
    potential_energy, segments = potential(scene, q0, at_state)
    kinetic = sp.Add(*(v * f for v, f in zip(v0, mass_times(scene, v0)))) / 2
    energy = kinetic + potential_energy
    applied_torques = None
    if scene.control:
        energy += state_shaping(scene, joint_angles(scene, q0))
        applied_torques = ImmutableMatrix([u + law.torques[j - 1]
                                           for u, j in zip(inputs, scene.actuated)])

    phi = ImmutableMatrix(sp.symbols(f"phi_init1:{n + 1}", real=True))
    phidot = ImmutableMatrix(sp.symbols(f"phidot_init1:{n + 1}", real=True))
    at_start = Definitions("initial_")
    initial_state = joint_space_start(scene, phi, phidot, at_start)
    extra = {}
    if scene.actuated:
        extra = holding_torques(scene, phi)
        extra["initial_definitions"] = tuple(at_start.items) + extra["initial_definitions"]
    else:
        extra["initial_definitions"] = tuple(at_start.items)

    layout = names + [f"v{name}" for name in names]
    return DiscreteScheme.of(
        method="es", quadrature=None, gradient="chain", scene=scene, summary=SUMMARY, dt=dt,
        quadrature_rule="none: the springs' discrete gradient is exact (chain rule)",
        state=ImmutableMatrix.vstack(q0, v0),
        unknowns=turns, residual=residual, newton_matrix=newton,
        next_state=ImmutableMatrix(q1 + [2 * v - w for v, w in zip(vm, v0)]),
        # theta_i ~ dt phidot_i: the turn of each joint at the start's rates.
        predictor=ImmutableMatrix([dt * rate for rate in state_rates]),
        joint_angles=ImmutableMatrix(joint_angles(scene, q0)),
        joint_velocities=ImmutableMatrix(outputs_rates), energy=energy,
        constraint_residuals=ImmutableMatrix(constraint_values(scene, q0)),
        initial_angles=phi, initial_velocities=phidot,
        initial_state=ImmutableMatrix(initial_state),
        state_layout=Layout(tuple(layout), (
            "per link i: COM x_i (m) and directors d_i1, d_i2, d_i3 (the columns of its "
            "rotation), world frame; then their velocities in the same layout (m/s, 1/s)")),
        unknowns_layout=Layout(tuple(f"w{i}" for i in range(1, n + 1)), (
            "per joint i, w_i = 2 tan(theta_i / 2) of the turn theta_i of link i about joint "
            "i's axis over the step (relative to link i-1; w ~ theta for a short step)")),
        residual_description=(
            "the momentum balance M dv + dt (gradV~ - f(q_m)) projected on the joint twists at "
            "the mid-point, P(q_m)^T (...): per joint, its moment about the joint's axis "
            "(kg m^2/s); the constraint impulses drop out"),
        inputs=inputs,
        input_work=dt * sp.Add(*(u * rate for u, rate in zip(applied, rates))),
        dissipated=dt * sp.Add(*(number(link.damping) * rate ** 2
                                 for link, rate in zip(scene.links, rates) if link.damping))
        + law.injected,
        applied_torques=applied_torques,
        segment_vectors=ImmutableMatrix([c for d in segments for c in d]),
        definitions=tuple(step.items), state_definitions=tuple(at_state.items),
        flow_description=(CONTROLLED_FLOWS if scene.control else
                          FLOWS if has_energy_flows(scene) else None),
        # Newton-chord with Newton's matrix A (newton_matrix), evaluated at each step's first
        # guess (and again when it contracts poorly, model.md 13), to a tighter update
        # tolerance than the contract's: dF/dw ~ 2 M / dt is large, so the turns' error shows
        # in the energy. On the Panda with three springs (dt = 1 ms, 2000 steps) the balance
        # error is 9.4e-11 J at update_rtol 1e-10, 9.1e-12 J at 1e-11, 2.2e-12 J at 1e-12
        # (2.95 iterations a step) and no smaller below (round-off's random walk).
        jacobian_reuse=JACOBIAN_CHORD_ACROSS_STEPS,
        # The energy check; not by default for the sampled law, which misses the balance by
        # design (as midpoint's, midpoint.py). A caller may still set it.
        newton_overrides=UPDATE_TOLERANCES + (("energy_tol", 0.0 if sampled_law(scene)
                                               else ENERGY_TOL),),
        kinetic_energy=kinetic, state_from_joint_space=False, **extra)
