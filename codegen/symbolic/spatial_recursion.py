"""A spatial chain in joint space by recursions over its links (model.md sections 6 and 17).

The spatial counterpart of chaingen.symbolic.recursion, for a SpatialScene (URDF's conventions,
chaingen.spatial.values): link rotations, origins, rates and the inverse dynamics by the
Newton-Euler recursion, the springs' generalized force route segment by route segment, and the
energy. Every quantity is a world-frame 3-vector (or a 3 x 3 matrix, rows listed) of small
expressions named once as intermediate symbols (recursion.Definitions): O(n) definitions in all,
no mass matrix of the whole chain. The scene's numbers enter as constants: the joints' fixed
rotations R_rpy, axes, origins, COMs and inertias; the joint angles only through cos and sin.
Gravity, masses, damping and the springs' stiffness and rest length may be SymPy symbols, a
solver's run-time parameters (chaingen.spatial.parameters): number() and constant() pass them.

Conventions: R_i, p_i the rotation and origin of link i's frame in the world (link 0 the base:
R_0 = 1, p_0 = 0); R_i = R_{i-1} R_rpy_i R_axis(q_i), p_i = p_{i-1} + R_{i-1} xyz_i; the joint
axis in the world z_i = R_i a_i (the rotation about a_i leaves a_i alone); the COM arm
r_i = R_i com_i, the world inertia about the COM J_i = R_i I_i R_i^T.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import sympy as sp

from ..spatial.dynamics import rpy_matrix
from ..spatial.values import SpatialScene
from .com_model import number
from .recursion import Definitions

ZERO = (sp.Integer(0),) * 3


def add(*vectors) -> tuple:
    return tuple(sp.Add(*(v[i] for v in vectors)) for i in range(3))


def scale(factor, v) -> tuple:
    return tuple(factor * c for c in v)


def cross(a, b) -> tuple:
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def dot(a, b) -> sp.Expr:
    return sp.Add(*(x * y for x, y in zip(a, b)))


def apply(matrix, v) -> tuple:
    """matrix v, matrix as rows."""
    return tuple(dot(row, v) for row in matrix)


def constant(values) -> tuple:
    """A vector (or rows of a matrix) of scene numbers as exact SymPy numbers; a run-time
    parameter (a SymPy symbol in a number's place: gravity[j]) passes through as it is."""
    if any(isinstance(value, (tuple, list, np.ndarray)) for value in values):
        return tuple(constant(row) for row in values)
    return tuple(number(value) for value in values)


def define_vector(defs: Definitions, name: str, v) -> tuple:
    return tuple(defs.define(f"{name}_{axis}", c) for axis, c in zip("xyz", v))


def joint_rotation_factors(joint) -> tuple:
    """(A, B, C) with R_rpy R_axis(q) = A + sin(q) B + cos(q) C (Rodrigues: R_axis = 1 +
    sin q K + (1 - cos q) K^2 with K the cross-product matrix of the unit axis)."""
    k = np.asarray(joint.axis, dtype=float)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    fixed = rpy_matrix(joint.rpy)
    return (constant(fixed @ (np.eye(3) + K @ K)), constant(fixed @ K),
            constant(-fixed @ K @ K))


@dataclass(frozen=True)
class SpatialFrames:
    """Per link i = 1..n (index i - 1): its rotation R_i (rows), origin p_i, world joint axis
    z_i, COM arm r_i = c_i - p_i and world inertia J_i about the COM (rows); all symbols of a
    Definitions or constants."""

    rotations: tuple
    origins: tuple
    axes: tuple
    arms: tuple
    inertias: tuple

    def point(self, link: int, point) -> tuple:
        """A point fixed on `link` (0 = base), in its frame, in the world."""
        if link == 0:
            return constant(point)
        return add(self.origins[link - 1], apply(self.rotations[link - 1], constant(point)))


def link_frames(scene: SpatialScene, angles, defs: Definitions, tag: str = "") -> SpatialFrames:
    """The frames of the links at the joint angles `angles`, by the recursion from the base."""
    rotation = None     # R_0 = 1, left out of the products
    origin = ZERO
    rotations, origins, axes, arms, inertias = [], [], [], [], []
    for i, (link, q) in enumerate(zip(scene.links, angles), start=1):
        joint = link.joint
        xyz = constant(joint.xyz)
        if rotation is not None:
            xyz = apply(rotation, xyz)
        origin = define_vector(defs, f"{tag}p{i}", add(origin, xyz)) if i > 1 else xyz
        c = defs.define(f"{tag}c{i}", sp.cos(q))
        s = defs.define(f"{tag}s{i}", sp.sin(q))
        A, B, C = joint_rotation_factors(joint)
        relative = [[A[r][k] + s * B[r][k] + c * C[r][k] for k in range(3)] for r in range(3)]
        if rotation is not None:
            relative = [[dot(rotation[r], [relative[m][k] for m in range(3)]) for k in range(3)]
                        for r in range(3)]
        rotation = tuple(tuple(defs.define(f"{tag}R{i}_{r}{k}", relative[r][k])
                               for k in range(3)) for r in range(3))
        rotations.append(rotation)
        origins.append(origin)
        axes.append(define_vector(defs, f"{tag}z{i}", apply(rotation, constant(joint.axis))))
        arms.append(define_vector(defs, f"{tag}r{i}", apply(rotation, constant(link.com))))
        body = constant(link.inertia_matrix())
        turned = [apply(rotation, [body[m][k] for m in range(3)]) for k in range(3)]  # (R I)^T
        inertia = [[None] * 3 for _ in range(3)]
        for r in range(3):
            for k in range(r, 3):
                # (R I R^T)_rk = sum_m (R I)_rm R_km
                inertia[r][k] = inertia[k][r] = defs.define(
                    f"{tag}J{i}_{r}{k}", dot([turned[m][r] for m in range(3)], rotation[k]))
        inertias.append(tuple(tuple(row) for row in inertia))
    return SpatialFrames(tuple(rotations), tuple(origins), tuple(axes), tuple(arms),
                         tuple(inertias))


def angular_velocities(frames: SpatialFrames, rates, defs: Definitions, tag: str = "") -> list:
    """omega_i = omega_{i-1} + z_i w_i."""
    omega, out = ZERO, []
    for i, (axis, w) in enumerate(zip(frames.axes, rates), start=1):
        omega = define_vector(defs, f"{tag}omega{i}", add(omega, scale(w, axis)))
        out.append(omega)
    return out


def com_velocities(frames: SpatialFrames, omegas, defs: Definitions, tag: str = "") -> list:
    """v(c_i) = v(p_i) + omega_i x r_i, v(p_{i+1}) = v(p_i) + omega_i x (p_{i+1} - p_i),
    v(p_1) = 0."""
    joint, out = ZERO, []
    n = len(omegas)
    for i in range(n):
        out.append(define_vector(defs, f"{tag}v{i + 1}",
                                 add(joint, cross(omegas[i], frames.arms[i]))))
        if i + 1 < n:
            link_vector = add(frames.origins[i + 1], scale(-1, frames.origins[i]))
            joint = define_vector(defs, f"{tag}V{i + 2}",
                                  add(joint, cross(omegas[i], link_vector)))
    return out


def kinetic_energy(scene: SpatialScene, frames: SpatialFrames, omegas, velocities) -> sp.Expr:
    """T = sum_i 1/2 m_i |v(c_i)|^2 + 1/2 omega_i . J_i omega_i."""
    total = sp.Integer(0)
    for link, inertia, omega, v in zip(scene.links, frames.inertias, omegas, velocities):
        total += number(link.mass) * dot(v, v) / 2 + dot(omega, apply(inertia, omega)) / 2
    return total


def gravity_potential(scene: SpatialScene, frames: SpatialFrames) -> sp.Expr:
    """V_g = -sum_i m_i g . c_i (zero at the base's origin)."""
    gravity = constant(scene.gravity)
    return -sp.Add(*(number(link.mass) * dot(gravity, add(origin, arm))
                     for link, origin, arm in zip(scene.links, frames.origins, frames.arms)))


def inverse_dynamics(scene: SpatialScene, frames: SpatialFrames, rates, increments, dt,
                     defs: Definitions, tag: str = "") -> list:
    """dt (M(q) qddot + C(q, qdot) qdot + dV_g/dq) with dt qddot = `increments`, at the joint
    rates `rates`, by the Newton-Euler recursion (world frame, every acceleration times dt).

    Outward, with gravity as an upward acceleration of the base (a(p_1) = -dt g):
    omega_i = omega_{i-1} + z_i w_i, A_i = A_{i-1} + z_i dw_i + dt omega_{i-1} x z_i w_i
    (dt alpha_i), a(c_i) = a(p_i) + A_i x r_i + dt omega_i x (omega_i x r_i), and
    a(p_{i+1}) = a(p_i) + A_i x l_i + dt omega_i x (omega_i x l_i), l_i = p_{i+1} - p_i.
    Inward, the force f_i on links i..n and the moment n_i about p_i:
    f_i = m_i a(c_i) + f_{i+1}, n_i = J_i A_i + dt omega_i x J_i omega_i + r_i x m_i a(c_i)
    + n_{i+1} + l_i x f_{i+1}; entry i is z_i . n_i."""
    n = scene.n
    omegas = angular_velocities(frames, rates, defs, tag)
    joint = scale(-dt, constant(scene.gravity))
    previous = ZERO
    angular, accelerations, link_vectors = [], [], []
    for i in range(n):
        spin = scale(rates[i], frames.axes[i])
        A = define_vector(defs, f"{tag}A{i + 1}", add(
            previous, scale(increments[i], frames.axes[i]),
            scale(dt, cross(omegas[i - 1], spin)) if i else ZERO))
        previous = A
        angular.append(A)
        omega = omegas[i]
        omega_dt = scale(dt, omega)
        accelerations.append(define_vector(defs, f"{tag}a{i + 1}", add(
            joint, cross(A, frames.arms[i]), cross(omega_dt, cross(omega, frames.arms[i])))))
        if i + 1 < n:
            link_vector = define_vector(defs, f"{tag}l{i + 1}", add(
                frames.origins[i + 1], scale(-1, frames.origins[i])))
            link_vectors.append(link_vector)
            joint = define_vector(defs, f"{tag}aP{i + 2}", add(
                joint, cross(A, link_vector), cross(omega_dt, cross(omega, link_vector))))
    force, moment = ZERO, ZERO
    torques = []
    for i in range(n - 1, -1, -1):
        link = scene.links[i]
        inertia = frames.inertias[i]
        inertial = scale(number(link.mass), accelerations[i])
        spin = apply(inertia, omegas[i])
        parts = [apply(inertia, angular[i]), scale(dt, cross(omegas[i], spin)),
                 cross(frames.arms[i], inertial)]
        if i + 1 < n:
            parts += [moment, cross(link_vectors[i], force)]
        moment = define_vector(defs, f"{tag}n{i + 1}", add(*parts))
        force = define_vector(defs, f"{tag}f{i + 1}", add(inertial, force))
        torques.append(defs.define(f"{tag}tau{i + 1}", dot(frames.axes[i], moment)))
    return torques[::-1]


def spring_gradient(scene: SpatialScene, frames: SpatialFrames, defs: Definitions,
                    tag: str = "") -> tuple[list, sp.Expr, list]:
    """(dV_s/dq (n entries), V_s, the segment vectors) of the routed springs.

    With route points P_k on links l_k, segments d_k = P_{k+1} - P_k of lengths s_k and unit
    vectors u_k, a spring's length L = sum s_k and force F = k (L - L_0), the spring pulls P_k
    by G_k = F (u_k - u_{k-1}) (F dL/dP_k = -G_k); a point of link l moves with joint j <= l by
    z_j x (P - p_j). So dV_s/dq_j = -z_j . sum_{l_k >= j} (P_k - p_j) x G_k
    = -z_j . (N_j - p_j x F_j) with the pulls' sum F_j and moment about the origin N_j over the
    points on links j..n, accumulated from the tip: O(n + points)."""
    n = scene.n
    pulls = [[] for _ in range(n + 1)]     # per link: (point, pull)
    energy = sp.Integer(0)
    segments = []
    for index, spring in enumerate(scene.springs):
        points = [frames.point(p.link, p.point) for p in spring.route]
        units, lengths = [], []
        for k in range(len(points) - 1):
            d = define_vector(defs, f"{tag}spring{index}_d{k}",
                              add(points[k + 1], scale(-1, points[k])))
            segments.append(d)
            length = defs.define(f"{tag}spring{index}_s{k}", sp.sqrt(dot(d, d)))
            lengths.append(length)
            units.append(scale(1 / length, d))
        stretch = defs.define(f"{tag}spring{index}_e",
                              sp.Add(*lengths) - number(spring.rest_length))
        force = defs.define(f"{tag}spring{index}_f", number(spring.stiffness) * stretch)
        energy += force * stretch / 2
        for k, (route_point, point) in enumerate(zip(spring.route, points)):
            before = units[k - 1] if k > 0 else ZERO
            after = units[k] if k < len(units) else ZERO
            pulls[route_point.link].append((point, scale(force, add(after, scale(-1, before)))))
    gradient = [sp.Integer(0)] * n
    total_force, total_moment = ZERO, ZERO
    for j in range(n, 0, -1):
        if pulls[j]:
            total_force = define_vector(defs, f"{tag}spring_F{j}",
                                        add(total_force, *(g for _, g in pulls[j])))
            total_moment = define_vector(defs, f"{tag}spring_N{j}", add(
                total_moment, *(cross(p, g) for p, g in pulls[j])))
        if total_force is not ZERO:
            gradient[j - 1] = -dot(frames.axes[j - 1], add(
                total_moment, scale(-1, cross(frames.origins[j - 1], total_force))))
    return gradient, energy, segments


def origin_velocities(frames: SpatialFrames, omegas, defs: Definitions, tag: str = "") -> list:
    """The velocities of the joint origins, V_1 = 0 (the base does not move) and
    V_{i+1} = V_i + omega_i x (p_{i+1} - p_i)."""
    joint, out = ZERO, [ZERO]
    for i in range(len(omegas) - 1):
        link_vector = add(frames.origins[i + 1], scale(-1, frames.origins[i]))
        joint = define_vector(defs, f"{tag}V{i + 2}", add(joint, cross(omegas[i], link_vector)))
        out.append(joint)
    return out


def momenta(scene: SpatialScene, frames: SpatialFrames, rates, defs: Definitions,
            tag: str = "") -> tuple[list, list]:
    """(dT/dqdot, dT/dq) at the joint rates `rates` (model.md 5.7): the conjugate momenta
    M(q) qdot and the kinetic energy's gradient in the angles at fixed rates, O(n).

    With the linear momenta L_i = m_i v(c_i), the angular momenta h_i = J_i omega_i about the
    COMs, and over the links j..n the linear momentum P_j = sum L_i and the angular momentum
    H_j = sum h_i + (c_i - p_j) x L_i about p_j, accumulated from the tip
    (H_j = h_j + r_j x L_j + H_{j+1} + (p_{j+1} - p_j) x P_{j+1}):

        dT/dqdot_j = z_j . H_j,    dT/dq_j = z_j . (H_j x omega_{j-1} + P_j x V_j),

    the second because turning joint j turns links j..n about z_j through p_j, and with them
    their rates relative to link j - 1 (omega_0 = 0, V_1 = 0: T does not depend on q_1)."""
    n = scene.n
    omegas = angular_velocities(frames, rates, defs, tag)
    joints = origin_velocities(frames, omegas, defs, tag)
    linear_total, angular_total = ZERO, ZERO
    momentum, gradient = [None] * n, [None] * n
    for i in range(n - 1, -1, -1):
        link = scene.links[i]
        velocity = add(joints[i], cross(omegas[i], frames.arms[i]))
        linear = define_vector(defs, f"{tag}L{i + 1}", scale(number(link.mass), velocity))
        parts = [apply(frames.inertias[i], omegas[i]), cross(frames.arms[i], linear)]
        if i + 1 < n:
            link_vector = add(frames.origins[i + 1], scale(-1, frames.origins[i]))
            parts += [angular_total, cross(link_vector, linear_total)]
        angular_total = define_vector(defs, f"{tag}H{i + 1}", add(*parts))
        linear_total = define_vector(defs, f"{tag}P{i + 1}", add(linear_total, linear))
        momentum[i] = defs.define(f"{tag}mom{i + 1}", dot(frames.axes[i], angular_total))
        parts = [cross(linear_total, joints[i])] if i else []
        if i:
            parts.append(cross(angular_total, omegas[i - 1]))
        gradient[i] = (defs.define(f"{tag}dTdq{i + 1}", dot(frames.axes[i], add(*parts)))
                       if parts else sp.Integer(0))
    return momentum, gradient


def gravity_gradient(scene: SpatialScene, frames: SpatialFrames, defs: Definitions,
                     tag: str = "") -> list:
    """dV_g/dq: with the weights W_i = m_i g, their sum F_j and moment about the world origin
    N_j over the links j..n (from the tip), dV_g/dq_j = -z_j . (N_j - p_j x F_j), the torque
    about joint j's axis that holds links j..n against gravity, negated. O(n)."""
    gravity = constant(scene.gravity)
    force, moment = ZERO, ZERO
    gradient = [None] * scene.n
    for i in range(scene.n - 1, -1, -1):
        weight = scale(number(scene.links[i].mass), gravity)
        centre = add(frames.origins[i], frames.arms[i])
        force = define_vector(defs, f"{tag}gravity_F{i + 1}", add(force, weight))
        moment = define_vector(defs, f"{tag}gravity_N{i + 1}", add(moment, cross(centre, weight)))
        gradient[i] = -dot(frames.axes[i], add(moment, scale(-1, cross(frames.origins[i], force))))
    return gradient
