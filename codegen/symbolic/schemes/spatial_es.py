"""Method "es" for a spatial scene: the energy-momentum scheme of Betsch and Steinmann (2001) in
director coordinates (docs/model.md section 4.8), the spatial counterpart of the planar es.

Each link i is its centre of mass x_i and three directors d_i1, d_i2, d_i3 (the columns of its
rotation R_i): the state x = (q, v) has 24 entries per link, q link by link (x_i, d_i1, d_i2,
d_i3) and v = qdot in the same layout. Eleven constraints per link, linear or quadratic in q
(orthonormality 6, joint point 3, joint axis 2; chaingen.symbolic.spatial_com_model). Unknowns
z = (dv, mu), dv = v_1 - v_0 (12 per link), mu the constraint impulses (11 per link); with
v_m = v_0 + dv/2, q_1 = q_0 + dt v_m, q_m = q_0 + dt v_m/2 the residual is

    M dv + G(q_m)^T mu + dt (gradV~(q_0, q_1) - f(q_m, v_m)) = 0      (12n entries, kg m/s)
    g(q_1) = 0                                                      (11n entries)

M constant, gradV~ the chain rule's exact discrete gradient of the springs (model.md 4.3) plus
gravity's constant gradient, f the joint torques (inputs and damping) as equal and opposite
couples on the directors at the mid-point. So H_1 - H_0 = dt sum_i tau_i phidot_i(m) to
round-off and the Newton tolerance. The residual is built term by term from the structure (no
SymPy differentiation): O(n + route points) definitions; chaingen.symbolic.spatial_com_model
is the same step in numpy, which the tests hold this one to.
"""
from __future__ import annotations

import numpy as np
import sympy as sp
from sympy import ImmutableMatrix

from ...errors import UnsupportedSceneError
from ...runtime.contract import JACOBIAN_CHORD_ACROSS_STEPS
from ...spatial.dynamics import rpy_matrix
from ...spatial.values import SpatialScene
from .. import spatial_recursion as vectors
from ..com_model import number
from ..recursion import Definitions
from ..spatial_com_model import DIRECTOR_PAIRS, LINK_CONSTRAINTS, euler_tensor, orthogonal_pair
from .base import (
    DiscreteScheme,
    FlowDescription,
    Layout,
    has_energy_flows,
    input_symbols,
    joint_torques,
)
from .spatial_midpoint import holding_torques

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
#: The names of a link's 12 coordinates, in the state's order.
COORDINATE_NAMES = tuple(f"{body}_{axis}" for body in ("x", "d1", "d2", "d3") for axis in "xyz")


class Link:
    """One link's coordinates in a vector of 12n: x and the directors as 3-tuples (link 0,
    the base: x = 0 and R = 1, constants)."""

    def __init__(self, values, i: int):
        if i == 0:
            self.x = (sp.Integer(0),) * 3
            self.d = tuple(tuple(sp.Integer(int(r == c)) for r in range(3)) for c in range(3))
        else:
            block = list(values[12 * (i - 1):12 * i])
            self.x = tuple(block[:3])
            self.d = tuple(tuple(block[3 * (a + 1):3 * (a + 2)]) for a in range(3))

    def turn(self, local) -> tuple:
        """R local = sum_a local_a d_a: a vector fixed on the link, in the world."""
        return add(*(scale(number(c), d) for c, d in zip(local, self.d)))

    def point(self, local, com) -> tuple:
        """x + R (local - com): a point fixed on the link, linear in q."""
        return add(self.x, self.turn(np.asarray(local, dtype=float) - com))


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


def coms(scene: SpatialScene) -> list[np.ndarray]:
    """c_0 = 0 for the base, then the links' COMs in their frames."""
    return [np.zeros(3)] + [np.asarray(link.com, dtype=float) for link in scene.links]


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


def constraint_forces(scene: SpatialScene, q, mu) -> list:
    """G(q)^T mu: each constraint's gradient times its impulse, link by link."""
    centres = coms(scene)
    forces = Forces(scene.n)
    for i, link in enumerate(scene.links, start=1):
        own, parent = Link(q, i), Link(q, i - 1)
        m = mu[LINK_CONSTRAINTS * (i - 1):LINK_CONSTRAINTS * i]
        for k, (a, b) in enumerate(DIRECTOR_PAIRS):
            forces.on(i, a + 1, scale(m[k], own.d[b]))
            forces.on(i, b + 1, scale(m[k], own.d[a]))
        pull = tuple(m[6:9])
        forces.on_point(i, np.zeros(3), centres[i], pull)
        forces.on_point(i - 1, link.joint.xyz, centres[i - 1], scale(-1, pull))
        parent_axis = rpy_matrix(link.joint.rpy) @ np.asarray(link.joint.axis)
        axis = parent.turn(parent_axis)
        for k, normal in enumerate(orthogonal_pair(link.joint.axis)):
            for a in range(3):
                forces.on(i, a + 1, scale(m[9 + k] * number(normal[a]), axis))
                forces.on(i - 1, a + 1, scale(m[9 + k] * number(parent_axis[a]),
                                              own.turn(normal)))
    return forces.entries


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


def mass_times(scene: SpatialScene, v) -> list:
    """M v, M = diag(m_i 1, E_i (x) 1) per link, E_i the Euler tensor (spatial_com_model)."""
    out = []
    for i, link in enumerate(scene.links, start=1):
        rate = Link(v, i)
        euler = constant(euler_tensor(link.inertia_matrix()))
        out += list(scale(number(link.mass), rate.x))
        for a in range(3):
            out += list(add(*(scale(euler[a][b], rate.d[b]) for b in range(3)
                              if euler[a][b] != 0)))
    return out


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


def turned_frames(scene: SpatialScene, q0, increments, defs: Definitions) -> list:
    """dq = F(q_0, w) - q_0, the nodal reparametrisation (docs/model.md 4.8): link i turned
    by Q_i = Q_{i-1} Rot(n_i0, theta_i), n_i0 = R_{i-1,0} J_i a_i joint i's axis at the step's
    start, theta_i = 2 atan(|n_i0| w_i / 2) (w_i = 2 tan(theta_i / 2) for a unit axis). Q_i is
    the rotation of the quaternion p_i = p_{i-1} (1, w_i n_i0 / 2) taken with its norm, so
    orthogonal to round-off for any w and n_i0, with no sine, cosine or square root:
    Q - 1 = 2 (p_v p_v^T - |p_v|^2 1 + p_w [p_v]) / |p|^2, computed as the difference (no
    cancellation against 1). Then

        dd_ia = (Q_i - 1) d_ia0,    dx_i = dx_{i-1} + dR_{i-1} (o_i - c_{i-1}) + dR_i c_i,

    so the directors keep the start's orthonormality and the joints the start's errors
    (carried, not grown), whatever w. dq, not q_1: the residual's M (v_1 - v_0) takes
    v_m = dq / dt, and q_1 - q_0 recomputed from a rounded q_1 would carry eps |q| / dt into
    it, 1e-13 of |v| at dt = 1 ms, which the energy then shows."""
    centres = coms(scene)
    quaternion = (sp.Integer(1),) + (sp.Integer(0),) * 3
    shift = (sp.Integer(0),) * 3        # dx_{i-1}
    turned_parent = None                # dR_{i-1} as Link-like directors; None for the base
    dq = []
    for i, (link, w) in enumerate(zip(scene.links, increments), start=1):
        own, parent = Link(q0, i), Link(q0, i - 1)
        axis = parent.turn(rpy_matrix(link.joint.rpy) @ np.asarray(link.joint.axis))
        if i > 1:
            axis = vectors.define_vector(defs, f"n0_{i}", axis)
        half = scale(w / 2, axis)
        pw, pv = quaternion[0], quaternion[1:]
        quaternion = (defs.define(f"p{i}_w", pw - dot(pv, half)),
                      *vectors.define_vector(defs, f"p{i}", add(scale(pw, half), pv,
                                                                cross(pv, half))))
        pw, pv = quaternion[0], quaternion[1:]
        square = defs.define(f"pvv{i}", dot(pv, pv))
        twice = defs.define(f"pn{i}", 2 / (pw ** 2 + square))
        scaled = vectors.define_vector(defs, f"ps{i}", scale(twice, pv))
        rows = [[scaled[r] * pv[c] - (square * twice if r == c else 0)
                 + (0 if r == c else (1 if (c - r) % 3 == 2 else -1) * scaled[3 - r - c] * pw)
                 for c in range(3)] for r in range(3)]
        rows = [[defs.define(f"U{i}_{r}{c}", rows[r][c]) for c in range(3)] for r in range(3)]
        turns = [vectors.define_vector(defs, f"dd{i}_{a + 1}", vectors.apply(rows, d))
                 for a, d in enumerate(own.d)]
        turned = Link([], 0)
        turned.d = tuple(turns)
        arm = np.asarray(link.joint.xyz, dtype=float) - centres[i - 1]
        joint = shift if turned_parent is None else add(shift, turned_parent.turn(arm))
        shift = vectors.define_vector(defs, f"dx{i}", add(joint, turned.turn(centres[i])))
        turned_parent = turned
        dq += list(shift) + [c for d in turns for c in d]
    return dq


def joint_moments(scene: SpatialScene, qm, forces, axes, defs: Definitions,
                  tag: str = "") -> list:
    """P(q_m)^T F: the generalized force F (12n) against the joint twists at q_m, the columns of
    the null space of G(q_m) (link k >= j turned about joint j's axis n_j through its point o_j:
    xdot_k = n_j x (x_k - o_j), ddot_ka = n_j x d_ka). Link by link, F's resultant f_k (on x_k)
    and moment about the origin m_k = x_k x f_k + sum_a d_ka x F_ka, summed from the tip:
    (P^T F)_j = n_j . (sum_{k>=j} m_k - o_j x sum_{k>=j} f_k), O(n)."""
    centres = coms(scene)
    resultant = moment = (sp.Integer(0),) * 3
    rows = []
    for i in range(scene.n, 0, -1):
        link = Link(qm, i)
        block = forces[12 * (i - 1):12 * i]
        force = tuple(block[:3])
        own = add(cross(link.x, force),
                  *(cross(d, tuple(block[3 * (a + 1):3 * (a + 2)])) for a, d in enumerate(link.d)))
        resultant = vectors.define_vector(defs, f"{tag}f{i}", add(resultant, force))
        moment = vectors.define_vector(defs, f"{tag}m{i}", add(moment, own))
        joint = Link(qm, i - 1).point(scene.links[i - 1].joint.xyz, centres[i - 1])
        rows.append(dot(axes[i - 1], add(moment, scale(-1, cross(joint, resultant)))))
    return rows[::-1]


def joint_twists(scene: SpatialScene, q, axes) -> list:
    """The columns xi_j of P(q), 12n entries each: links k >= j turned about joint j's axis
    n_j through its point o_j, xdot_k = n_j x (x_k - o_j), ddot_ka = n_j x d_ka."""
    centres = coms(scene)
    twists = []
    for j, axis in enumerate(axes, start=1):
        joint = Link(q, j - 1).point(scene.links[j - 1].joint.xyz, centres[j - 1])
        column = [sp.Integer(0)] * (12 * (j - 1))
        for k in range(j, scene.n + 1):
            link = Link(q, k)
            column += list(cross(axis, add(link.x, scale(-1, joint))))
            column += [c for d in link.d for c in cross(axis, d)]
        twists.append(column)
    return twists


def projected_rates(scene: SpatialScene, q, v, axes, defs: Definitions) -> list:
    """The joint rates of v projected M-orthogonally onto the constraints' tangent space at q
    (docs/model.md 14): (P^T M P) w = P^T M v, P = P(q) the joint twists, solved by Gaussian
    elimination without pivoting (P^T M P is the joint-space mass matrix, positive definite).
    A composed step's nodal v meets G(q) v = 0 only to O(dt^2); its projected rates are of the
    composition's order."""
    n = scene.n
    twists = joint_twists(scene, q, axes)
    matrix = [joint_moments(scene, q, mass_times(scene, column), axes, defs, f"P{j}")
              for j, column in enumerate(twists, start=1)]
    matrix = [[defs.define(f"A{r}_{c}", matrix[c][r]) for c in range(n)] for r in range(n)]
    right = [defs.define(f"b{r}", e) for r, e in enumerate(
        joint_moments(scene, q, mass_times(scene, v), axes, defs, "Mv"))]
    for k in range(n):
        for r in range(k + 1, n):
            factor = defs.define(f"l{r}_{k}", matrix[r][k] / matrix[k][k])
            for c in range(k + 1, n):
                matrix[r][c] = defs.define(f"A{r}_{c}_{k}", matrix[r][c] - factor * matrix[k][c])
            right[r] = defs.define(f"b{r}_{k}", right[r] - factor * right[k])
    rates = [sp.Integer(0)] * n
    for r in range(n - 1, -1, -1):
        rates[r] = defs.define(f"wp{r}", (right[r] - sp.Add(*(matrix[r][c] * rates[c]
                                                              for c in range(r + 1, n))))
                               / matrix[r][r])
    return rates


def newton_matrix(scene: SpatialScene, qm, q1, axes, turns, dt, defs: Definitions):
    """Newton's matrix A = (2/dt P(q_m)^T M P(q_1) + diag(d)) diag(1 / (1 + w_k^2/4)), an
    approximation of dF/dw: the derivative of the residual's leading terms, P(q_m)^T 2 M dq / dt
    with dq/dw_k = P_k(q_1) dtheta_k/dw_k (the twist of joint k at the step's end; |n_k| = 1),
    and the damping; without the terms of order dt^2 (the springs' stiffness, the impulses'
    turning of P) and dt (the torques' turning).

    P(q_m)^T M P(q_1) by composite rigid bodies (Featherstone's CRBA, in the world frame about
    its origin, with the two sides at q_m and q_1): for joints j, k and the links i from
    max(j, k) on, sum_i xi_j(q_m)^T M_i xi_k(q_1) = v_j . L + n_j . H, with the twists
    (v, n) = (o x n, n), L = m v_k + n_k x h_1 and H = K n_k + h_m x v_k from the composites
    m = sum m_i, h_m = sum m_i x_im, h_1 = sum m_i x_i1 and
    K = sum m_i ((x_im . x_i1) 1 - x_i1 x_im^T) + tr(Y_i) 1 - Y_i, Y_i = D_i1 E_i D_im^T (E the
    Euler tensor, D the directors: M's rotational part in director form). O(n^2), about 2200
    operations on the Panda, half the residual's; the exact dF/dw, by forward derivatives
    through the whole residual, costs 16 residuals there, and this A's chord contracts by
    about 3e-4 per iteration (at the mid-point on both sides, 1e-3; docs/model.md 4.8). The
    joints' damping d_j adds to the diagonal (-dt P^T f with tau_j = -d_j phidot_j(m) and
    phidot_j(m) ~ theta_j / dt)."""
    n = scene.n
    centres = coms(scene)
    composites = [None] * (n + 1)
    mass, start, end, inertia = sp.Integer(0), (sp.Integer(0),) * 3, (sp.Integer(0),) * 3, None
    for i in range(n, 0, -1):
        link = scene.links[i - 1]
        middle, final = Link(qm, i), Link(q1, i)
        euler = euler_tensor(link.inertia_matrix())
        # T = E D_m^T (rows a), then Y = D_1 T
        rows = [add(*(scale(number(euler[a][b]), middle.d[b]) for b in range(3)
                      if euler[a][b] != 0)) for a in range(3)]
        rows = [vectors.define_vector(defs, f"T{i}_{a}", row) for a, row in enumerate(rows)]
        second = [[sp.Add(*(final.d[a][r] * rows[a][c] for a in range(3))) for c in range(3)]
                  for r in range(3)]
        second = [[defs.define(f"Y{i}_{r}{c}", second[r][c]) for c in range(3)]
                  for r in range(3)]
        m = number(link.mass)
        both = defs.define(f"xx{i}", dot(middle.x, final.x))
        trace = second[0][0] + second[1][1] + second[2][2]
        own = [[(trace + m * both if r == c else 0) - second[r][c] - m * final.x[r] * middle.x[c]
                for c in range(3)] for r in range(3)]
        mass = mass + m
        start = vectors.define_vector(defs, f"hm{i}", add(start, scale(m, middle.x)))
        end = vectors.define_vector(defs, f"h1{i}", add(end, scale(m, final.x)))
        inertia = [[defs.define(f"K{i}_{r}{c}", own[r][c] + (0 if inertia is None
                                                             else inertia[r][c]))
                    for c in range(3)] for r in range(3)]
        composites[i] = (mass, start, end, inertia)

    def twist(q, j, name, axis):
        joint = Link(q, j - 1).point(scene.links[j - 1].joint.xyz, centres[j - 1])
        return vectors.define_vector(defs, f"{name}{j}", cross(joint, axis)), axis

    end_axes = [Link(q1, j - 1).turn(rpy_matrix(link.joint.rpy) @ np.asarray(link.joint.axis))
                for j, link in enumerate(scene.links, start=1)]
    end_axes = [axis if j == 1 else vectors.define_vector(defs, f"n1_{j}", axis)
                for j, axis in enumerate(end_axes, start=1)]
    projections = [twist(qm, j, "vm", axes[j - 1]) for j in range(1, n + 1)]
    motions = [twist(q1, k, "v1", end_axes[k - 1]) for k in range(1, n + 1)]
    matrix = [[None] * n for _ in range(n)]
    for c in range(1, n + 1):
        mass, start, end, inertia = composites[c]
        transposed = [[inertia[r][k] for r in range(3)] for k in range(3)]
        velocity, axis = motions[c - 1]
        linear = vectors.define_vector(defs, f"L{c}", add(scale(mass, velocity),
                                                          cross(axis, end)))
        angular = vectors.define_vector(defs, f"H{c}", add(vectors.apply(inertia, axis),
                                                           cross(start, velocity)))
        for j in range(1, c + 1):           # column c, rows j <= c: composite c
            v_j, n_j = projections[j - 1]
            matrix[j - 1][c - 1] = dot(v_j, linear) + dot(n_j, angular)
        velocity, axis = projections[c - 1]
        linear = vectors.define_vector(defs, f"Lt{c}", add(scale(mass, velocity),
                                                           cross(axis, start)))
        angular = vectors.define_vector(defs, f"Ht{c}", add(vectors.apply(transposed, axis),
                                                            cross(end, velocity)))
        for k in range(1, c):               # row c, columns k < c: composite c
            v_k, n_k = motions[k - 1]
            matrix[c - 1][k - 1] = dot(v_k, linear) + dot(n_k, angular)
    turning = [defs.define(f"dtheta{k}", 1 / (1 + w ** 2 / 4))
               for k, w in enumerate(turns, start=1)]
    # the joints' damping, -dt P^T f with tau_j = -d_j phidot_j(m), phidot_j(m) ~ theta_j / dt
    return ImmutableMatrix([[(2 / dt * matrix[r][c]
                              + (number(scene.links[c].damping) if r == c else 0)) * turning[c]
                             for c in range(n)] for r in range(n)])


#: The orders of the step this builder takes (chaingen.symbolic.schemes.orders_taken asks it):
#: order 2 and its composition to order 4 (order 6 would stall at 4, docs/model.md 14).
ORDERS = (2, 4)


def build(scene: SpatialScene, quadrature: int | None = None, order: int = 2) -> DiscreteScheme:
    """The spatial es scheme of `scene`, by the discrete null space method with nodal
    reparametrisation (Betsch and Leyendecker 2006; docs/model.md 4.8): n unknowns, one turn per
    joint. quadrature plays no role (the springs' discrete gradient is exact without it).
    Order 2, and 4 by composition (chaingen.symbolic.composition); order 6 stalls at 4 as the
    planar es's composition does (model.md 14): UnsupportedSceneError."""
    if order not in ORDERS:
        raise UnsupportedSceneError(
            f"order {order}: es for a spatial scene (scene {scene.name!r}) composes its step to "
            "order 4 at most (a composition of its steps stalls at order 4, docs/model.md 14)")
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
    torques = [step.define(f"tau{i}", u - number(link.damping) * rate)
               for i, (u, link, rate) in enumerate(zip(applied, scene.links, rates), start=1)]
    momentum = [a + dt * (c - d) for a, c, d in zip(
        mass_times(scene, dv), potential_gradient(scene, q0, q1, step),
        torque_forces(scene, qm, axes, torques))]
    residual = ImmutableMatrix(joint_moments(scene, qm, momentum, axes, step))
    newton = newton_matrix(scene, qm, q1, axes, turns, dt, step)

    at_state = Definitions("state_")
    state_axes, state_rates = joint_rates(scene, q0, v0, at_state, "")
    # A composed step (order 4) reports the rates of v projected onto the tangent space
    # (model.md 14), as the planar es does.
    outputs_rates = (projected_rates(scene, q0, v0, state_axes, at_state) if order > 2
                     else state_rates)
    potential_energy, segments = potential(scene, q0, at_state)
    energy = sp.Add(*(v * f for v, f in zip(v0, mass_times(scene, v0)))) / 2 + potential_energy

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
                                 for link, rate in zip(scene.links, rates) if link.damping)),
        segment_vectors=ImmutableMatrix([c for d in segments for c in d]),
        definitions=tuple(step.items), state_definitions=tuple(at_state.items),
        flow_description=FLOWS if has_energy_flows(scene) else None,
        # Newton-chord with Newton's matrix A (newton_matrix), evaluated at each step's first
        # guess (and again when it contracts poorly, model.md 13), to a tighter update
        # tolerance than the contract's: dF/dw ~ 2 M / dt is large, so the turns' error shows
        # in the energy. On the Panda with three springs (dt = 1 ms, 2000 steps) the balance
        # error is 9.4e-11 J at update_rtol 1e-10, 9.1e-12 J at 1e-11, 2.2e-12 J at 1e-12
        # (2.95 iterations a step) and no smaller below (round-off's random walk).
        jacobian_reuse=JACOBIAN_CHORD_ACROSS_STEPS, newton_overrides=UPDATE_TOLERANCES,
        state_from_joint_space=False, **extra)
