"""A spatial chain in director coordinates and its energy-momentum step (docs/model.md 4.8),
in numpy: the reference the generated spatial es (chaingen.symbolic.schemes.spatial_es) is
checked against, and the place to try a change of the step before generating it.

Each link i is described without rotation parameters: its centre of mass x_i and the three
directors d_i1, d_i2, d_i3, the columns of its rotation R_i (Betsch and Steinmann, 2001). The
coordinates q hold 12 numbers per link, link by link: (x_i, d_i1, d_i2, d_i3). A point fixed
on link i at p (link frame) is x_i + sum_a (p - c_i)_a d_ia, linear in q. Eleven constraints
per link, every one linear or quadratic in q:

    d_ia . d_ib - delta_ab = 0                                  (6, orthonormality)
    x_i - R_i c_i - x_{i-1} - R_{i-1} (o_i - c_{i-1}) = 0       (3, the joint point; link 0
                                                                 the base: x_0 = c_0 = 0)
    (R_{i-1} J_i a_i) . (R_i b_ik) = 0,  k = 1, 2               (2, the joint axis)

with o_i, J_i = R(rpy_i) and a_i the joint's origin, rotation and axis (URDF), b_i1, b_i2 a
unit pair orthogonal to a_i. The kinetic energy is 1/2 v . M v with the constant
M = diag(m_i I, E_i (x) I), E_i = tr(I_i)/2 I - I_i the Euler tensor about the COM.

The step (Betsch and Steinmann's energy-momentum scheme, model.md 4.8): unknowns the velocity
increment dv = v_1 - v_0 and the constraint impulses mu = dt lambda,

    M dv + G(q_m)^T mu + dt (gradV~(q_0, q_1) - f(q_m, v_m)) = 0,   g(q_1) = 0,

q_1 = q_0 + dt v_m, v_m = v_0 + dv/2, q_m = (q_0 + q_1)/2. G(q_m)(q_1 - q_0) = g(q_1) - g(q_0)
for quadratic g, so the constraint forces do no work; gravity's gradient is constant and the
springs' discrete gradient exact (model.md 4.3's in 3D), so H_1 - H_0 = dt f . v_m, the work
of the joint torques (inputs and damping) at the mid-point.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..spatial.dynamics import link_poses, rpy_matrix
from ..spatial.values import SpatialScene

#: Coordinates per link: x_i, d_i1, d_i2, d_i3.
LINK_COORDINATES = 12
#: Constraints per link: orthonormality (6), joint point (3), joint axis (2).
LINK_CONSTRAINTS = 11
#: The pairs (a, b) of the orthonormality constraints, in their order.
DIRECTOR_PAIRS = ((0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2))


def euler_tensor(inertia) -> np.ndarray:
    """E = tr(I)/2 1 - I, the second moment int rho r r^T dV about the COM (kg m^2), from the
    inertia tensor I about the COM: then 1/2 sum_ab E_ab ddot_a . ddot_b is the kinetic energy
    of the rotation."""
    inertia = np.asarray(inertia, dtype=float)
    return np.trace(inertia) / 2 * np.eye(3) - inertia


def skew(vector) -> np.ndarray:
    """[a]_x with [a]_x b = a x b."""
    return np.array([[0.0, -vector[2], vector[1]], [vector[2], 0.0, -vector[0]],
                     [-vector[1], vector[0], 0.0]])


def orthogonal_pair(axis) -> tuple[np.ndarray, np.ndarray]:
    """b_1, b_2: unit vectors with (b_1, b_2, axis) right-handed and orthonormal."""
    axis = np.asarray(axis, dtype=float)
    helper = np.eye(3)[int(np.argmin(np.abs(axis)))]
    first = np.cross(axis, helper)
    first /= np.linalg.norm(first)
    return first, np.cross(axis, first)


@dataclass(frozen=True)
class DirectorModel:
    """The numbers of a spatial scene the director coordinates need, computed once."""

    scene: SpatialScene
    mass_matrix: np.ndarray          # 12n x 12n, constant
    parent_axes: tuple[np.ndarray, ...]   # J_i a_i: the axis in link i-1's frame
    normals: tuple[tuple[np.ndarray, np.ndarray], ...]   # b_i1, b_i2 in link i's frame
    gravity_gradient: np.ndarray     # dV_g/dq, constant

    @property
    def n(self) -> int:
        return self.scene.n

    def link(self, q, i: int) -> tuple[np.ndarray, np.ndarray]:
        """(x_i, R_i) of link i (1-based; 0: the base at the origin, unturned)."""
        if i == 0:
            return np.zeros(3), np.eye(3)
        block = q[LINK_COORDINATES * (i - 1):LINK_COORDINATES * i]
        return block[:3], block[3:].reshape(3, 3).T

    def com(self, i: int) -> np.ndarray:
        return np.zeros(3) if i == 0 else np.asarray(self.scene.links[i - 1].com, dtype=float)

    def point_map(self, link: int, point) -> tuple[np.ndarray, np.ndarray]:
        """(A, b) with the world position of `point` (frame of `link`, 0 the base) A q + b."""
        A = np.zeros((3, LINK_COORDINATES * self.n))
        point = np.asarray(point, dtype=float)
        if link == 0:
            return A, point
        start = LINK_COORDINATES * (link - 1)
        A[:, start:start + 3] = np.eye(3)
        for a, offset in enumerate(point - self.com(link)):
            A[:, start + 3 * (a + 1):start + 3 * (a + 2)] = offset * np.eye(3)
        return A, np.zeros(3)


def director_model(scene: SpatialScene) -> DirectorModel:
    """The constant parts of `scene`'s director coordinates: M, the joint axes, gravity."""
    n = scene.n
    mass = np.zeros((LINK_COORDINATES * n, LINK_COORDINATES * n))
    gravity = np.zeros(LINK_COORDINATES * n)
    for i, link in enumerate(scene.links):
        block = slice(LINK_COORDINATES * i, LINK_COORDINATES * (i + 1))
        mass[block, block] = np.block([
            [link.mass * np.eye(3), np.zeros((3, 9))],
            [np.zeros((9, 3)), np.kron(euler_tensor(link.inertia_matrix()), np.eye(3))]])
        gravity[LINK_COORDINATES * i:LINK_COORDINATES * i + 3] = \
            -link.mass * np.asarray(scene.gravity, dtype=float)
    parent_axes = tuple(rpy_matrix(link.joint.rpy) @ np.asarray(link.joint.axis, dtype=float)
                        for link in scene.links)
    normals = tuple(orthogonal_pair(link.joint.axis) for link in scene.links)
    return DirectorModel(scene, mass, parent_axes, normals, gravity)


def constraints(model: DirectorModel, q) -> np.ndarray:
    """g(q), 11 per link in LINK_CONSTRAINTS' order (dimensionless, m, dimensionless)."""
    q = np.asarray(q, dtype=float)
    values = []
    for i, link in enumerate(model.scene.links, start=1):
        x, R = model.link(q, i)
        x_parent, R_parent = model.link(q, i - 1)
        values += [R[:, a] @ R[:, b] - (a == b) for a, b in DIRECTOR_PAIRS]
        values += list(x - R @ model.com(i) - x_parent
                       - R_parent @ (np.asarray(link.joint.xyz, dtype=float) - model.com(i - 1)))
        axis = R_parent @ model.parent_axes[i - 1]
        values += [axis @ (R @ normal) for normal in model.normals[i - 1]]
    return np.array(values)


def constraint_jacobian(model: DirectorModel, q) -> np.ndarray:
    """G(q) = dg/dq (11n x 12n). Linear in q (g is quadratic), so G((q_0 + q_1)/2) (q_1 - q_0)
    = g(q_1) - g(q_0) exactly."""
    q = np.asarray(q, dtype=float)
    n = model.n
    jacobian = np.zeros((LINK_CONSTRAINTS * n, LINK_COORDINATES * n))
    eye = np.eye(3)
    for i, link in enumerate(model.scene.links, start=1):
        row = LINK_CONSTRAINTS * (i - 1)
        own = LINK_COORDINATES * (i - 1)
        parent = LINK_COORDINATES * (i - 2)
        _, R = model.link(q, i)
        _, R_parent = model.link(q, i - 1)

        def director(start, a):
            return slice(start + 3 * (a + 1), start + 3 * (a + 2))

        for k, (a, b) in enumerate(DIRECTOR_PAIRS):
            jacobian[row + k, director(own, a)] += R[:, b]
            jacobian[row + k, director(own, b)] += R[:, a]
        row += 6
        jacobian[row:row + 3, own:own + 3] = eye
        for a, offset in enumerate(model.com(i)):
            jacobian[row:row + 3, director(own, a)] = -offset * eye
        if i > 1:
            jacobian[row:row + 3, parent:parent + 3] = -eye
            arm = np.asarray(link.joint.xyz, dtype=float) - model.com(i - 1)
            for a, offset in enumerate(arm):
                jacobian[row:row + 3, director(parent, a)] = -offset * eye
        row += 3
        axis_local = model.parent_axes[i - 1]
        axis = R_parent @ axis_local
        for k, normal in enumerate(model.normals[i - 1]):
            for a in range(3):
                jacobian[row + k, director(own, a)] = normal[a] * axis
                if i > 1:
                    jacobian[row + k, director(parent, a)] = axis_local[a] * (R @ normal)
    return jacobian


def constraint_hessian(model: DirectorModel, multipliers) -> np.ndarray:
    """sum_k mu_k d^2 g_k/dq^2 (12n x 12n), constant (g is quadratic): the derivative of
    G(q)^T mu in q, for Newton's Jacobian."""
    n = model.n
    hessian = np.zeros((LINK_COORDINATES * n, LINK_COORDINATES * n))
    eye = np.eye(3)

    def director(link, a):
        start = LINK_COORDINATES * (link - 1) + 3 * (a + 1)
        return slice(start, start + 3)

    for i in range(1, n + 1):
        mu = multipliers[LINK_CONSTRAINTS * (i - 1):LINK_CONSTRAINTS * i]
        for k, (a, b) in enumerate(DIRECTOR_PAIRS):
            hessian[director(i, a), director(i, b)] += mu[k] * eye
            hessian[director(i, b), director(i, a)] += mu[k] * eye
        if i == 1:
            continue
        for k, normal in enumerate(model.normals[i - 1]):
            for a, b in np.ndindex(3, 3):
                block = mu[9 + k] * model.parent_axes[i - 1][a] * normal[b] * eye
                hessian[director(i - 1, a), director(i, b)] += block
                hessian[director(i, b), director(i - 1, a)] += block
    return hessian


def spring_maps(model: DirectorModel) -> list[list[tuple[np.ndarray, np.ndarray]]]:
    """Per spring, per route segment, (A_j, b_j) with the segment vector D_j = A_j q + b_j."""
    maps = []
    for spring in model.scene.springs:
        points = [model.point_map(point.link, point.point) for point in spring.route]
        maps.append([(end[0] - start[0], end[1] - start[1])
                     for start, end in zip(points, points[1:])])
    return maps


def potential(model: DirectorModel, q, springs=None) -> float:
    """V(q) = -sum m_i g . x_i + sum 1/2 k (L - L_0)^2, L the sum of the route's segments."""
    q = np.asarray(q, dtype=float)
    springs = spring_maps(model) if springs is None else springs
    energy = float(model.gravity_gradient @ q)
    for spring, segments in zip(model.scene.springs, springs):
        length = sum(np.linalg.norm(A @ q + b) for A, b in segments)
        energy += 0.5 * spring.stiffness * (length - spring.rest_length) ** 2
    return energy


def energy(model: DirectorModel, q, v, springs=None) -> float:
    """H = 1/2 v . M v + V(q) (J)."""
    v = np.asarray(v, dtype=float)
    return float(0.5 * v @ model.mass_matrix @ v) + potential(model, q, springs)


def discrete_gradient(model: DirectorModel, q0, q1, springs=None) -> np.ndarray:
    """gradV~(q_0, q_1) with gradV~ . (q_1 - q_0) = V(q_1) - V(q_0) identically: gravity's
    constant gradient, and per spring k (L~ - L_0) sum_j A_j^T (D_j0 + D_j1) / (s_j0 + s_j1),
    L~ the mean of its lengths at q_0 and q_1 (model.md 4.3 in 3D)."""
    springs = spring_maps(model) if springs is None else springs
    gradient = model.gravity_gradient.copy()
    for spring, segments in zip(model.scene.springs, springs):
        vectors = [(A @ q0 + b, A @ q1 + b) for A, b in segments]
        lengths = [(np.linalg.norm(d0), np.linalg.norm(d1)) for d0, d1 in vectors]
        mean = sum(s0 + s1 for s0, s1 in lengths) / 2
        pull = spring.stiffness * (mean - spring.rest_length)
        for (A, _), (d0, d1), (s0, s1) in zip(segments, vectors, lengths):
            gradient += pull * A.T @ ((d0 + d1) / (s0 + s1))
    return gradient


def discrete_gradient_derivative(model: DirectorModel, q0, q1, springs=None) -> np.ndarray:
    """d gradV~(q_0, q_1) / dq_1 (12n x 12n), for Newton's Jacobian: per spring, with
    w_j = (D_j0 + D_j1) / (s_j0 + s_j1) and u_j = D_j1 / s_j1,
    k/2 (sum_j A_j^T w_j)(sum_j u_j^T A_j) + k (L~ - L_0) sum_j A_j^T (1 - w_j u_j^T) A_j
    / (s_j0 + s_j1)."""
    springs = spring_maps(model) if springs is None else springs
    size = LINK_COORDINATES * model.n
    derivative = np.zeros((size, size))
    for spring, segments in zip(model.scene.springs, springs):
        pulls, stretches, curvature, mean = np.zeros(size), np.zeros(size), 0.0, 0.0
        for A, b in segments:
            d0, d1 = A @ q0 + b, A @ q1 + b
            s0, s1 = np.linalg.norm(d0), np.linalg.norm(d1)
            w, u = (d0 + d1) / (s0 + s1), d1 / s1
            mean += (s0 + s1) / 2
            pulls += A.T @ w
            stretches += A.T @ u
            curvature = curvature + A.T @ (np.eye(3) - np.outer(w, u)) @ A / (s0 + s1)
        derivative += spring.stiffness * (np.outer(pulls, stretches) / 2
                                          + (mean - spring.rest_length) * curvature)
    return derivative


def angular_velocity(model: DirectorModel, q, v, i: int) -> np.ndarray:
    """omega_i = 1/2 sum_a d_ia x ddot_ia (rad/s, world): ddot_a = omega x d_a on the
    constraint manifold; zero for the base."""
    if i == 0:
        return np.zeros(3)
    _, R = model.link(q, i)
    _, rates = model.link(v, i)
    return 0.5 * sum(skew(R[:, a]) @ rates[:, a] for a in range(3))


def joint_rates(model: DirectorModel, q, v) -> np.ndarray:
    """phidot_i = n_i . (omega_i - omega_{i-1}), n_i = R_{i-1} J_i a_i the joint's axis."""
    return np.array([(model.link(q, i - 1)[1] @ model.parent_axes[i - 1])
                     @ (angular_velocity(model, q, v, i) - angular_velocity(model, q, v, i - 1))
                     for i in range(1, model.n + 1)])


def torque_forces(model: DirectorModel, q, torques) -> np.ndarray:
    """The generalized force of joint torques tau_i, equal and opposite couples tau_i n_i on
    links i and i-1: tau/2 n x d_a on each director of link i, minus that on link i-1's. Then
    f . v = sum_i tau_i phidot_i(q, v) (joint_rates) for any v."""
    forces = np.zeros(LINK_COORDINATES * model.n)
    for i, tau in enumerate(torques, start=1):
        axis = model.link(q, i - 1)[1] @ model.parent_axes[i - 1]
        for link, sign in ((i, 1.0), (i - 1, -1.0)):
            if link == 0:
                continue
            _, R = model.link(q, link)
            start = LINK_COORDINATES * (link - 1)
            forces[start + 3:start + 12] += sign * tau / 2 * (skew(axis) @ R).T.ravel()
    return forces


def joint_space_start(model: DirectorModel, angles, rates) -> tuple[np.ndarray, np.ndarray]:
    """(q, v) of the joint angles and rates: the links' poses, and ddot_ia = omega_i x d_ia,
    xdot_i = sum_{j <= i} phidot_j n_j x (x_i - o_j) with omega_i = sum_{j <= i} phidot_j n_j."""
    poses = link_poses(model.scene, angles)
    q, v = [], []
    omega = np.zeros(3)
    origins, spins = [], []
    for i, link in enumerate(model.scene.links, start=1):
        R, origin = poses[i]
        axis = R @ np.asarray(link.joint.axis, dtype=float)
        omega = omega + rates[i - 1] * axis
        origins.append(origin)
        spins.append(rates[i - 1] * axis)
        com = origin + R @ model.com(i)
        velocity = sum(np.cross(spin, com - o) for spin, o in zip(spins, origins))
        q += [com, *R.T]
        v += [velocity, *(np.cross(omega, R[:, a]) for a in range(3))]
    return np.concatenate(q), np.concatenate(v)


def joint_angles(model: DirectorModel, q) -> np.ndarray:
    """phi_i, wrapped to (-pi, pi]: R_i = R_{i-1} J_i Rot(a_i, phi_i), so with
    Q = (R_{i-1} J_i)^T R_i, cos phi = b_1 . Q b_1 and sin phi = b_2 . Q b_1."""
    angles = []
    for i, link in enumerate(model.scene.links, start=1):
        _, R = model.link(q, i)
        _, R_parent = model.link(q, i - 1)
        turn = (R_parent @ rpy_matrix(link.joint.rpy)).T @ R
        first, second = model.normals[i - 1]
        angles.append(np.arctan2(second @ turn @ first, first @ turn @ first))
    return np.array(angles)


@dataclass(frozen=True)
class StepResult:
    """One es step: the next state, the energy flows of the step (J) and Newton's work."""

    q: np.ndarray
    v: np.ndarray
    input_work: float       # dt sum_i u_i phidot_i(m)
    dissipated: float       # dt sum_i d_i phidot_i(m)^2
    iterations: int
    unknowns: np.ndarray    # (dv, mu): the next step's first guess


def es_step(model: DirectorModel, q0, v0, dt: float, inputs=(), springs=None,
            guess=None, max_iterations: int = 50) -> StepResult:
    """The energy-momentum step of the module docstring from (q_0, v_0), the torques `inputs`
    on the scene's actuated joints and its joint damping. Newton's method on the full
    saddle-point system (model.md 4.8), its Jacobian exact but for the turning of the torques'
    axes and couples with q (O(dt^2 |tau|)), iterated until
    the update stops shrinking: the residual at round-off, which the energy balance needs.
    guess: the first (dv, mu), the last step's (StepResult.unknowns) along a run; zero if None."""
    springs = spring_maps(model) if springs is None else springs
    scene = model.scene
    n = model.n
    size = LINK_COORDINATES * n
    applied = np.zeros(n)
    applied[[joint - 1 for joint in scene.actuated]] = inputs
    damping = np.array([link.damping for link in scene.links])
    z = np.zeros(size + LINK_CONSTRAINTS * n) if guess is None else np.array(guess, dtype=float)
    last, iterations = np.inf, 0
    while iterations < max_iterations:
        iterations += 1
        dv, mu = z[:size], z[size:]
        vm = v0 + dv / 2
        q1 = q0 + dt * vm
        qm = (q0 + q1) / 2
        G = constraint_jacobian(model, qm)
        couples = np.array([torque_forces(model, qm, np.eye(n)[i]) for i in range(n)])
        rates = couples @ vm           # phidot_i(m) = w_i . v_m (torque_forces)
        torques = applied - damping * rates
        residual = np.concatenate([
            model.mass_matrix @ dv + G.T @ mu
            + dt * (discrete_gradient(model, q0, q1, springs) - couples.T @ torques),
            constraints(model, q1)])
        jacobian = np.block([
            [model.mass_matrix + dt / 2 * couples.T @ (damping[:, None] * couples)
             + dt / 4 * constraint_hessian(model, mu)
             + dt ** 2 / 2 * discrete_gradient_derivative(model, q0, q1, springs), G.T],
            [dt / 2 * constraint_jacobian(model, q1), np.zeros((len(mu), len(mu)))]])
        update = np.linalg.solve(jacobian, -residual)
        z = z + update
        size_of_update = np.abs(update).max()
        if size_of_update <= 1e-16 * np.abs(z).max() or size_of_update >= last / 2:
            break
        last = size_of_update
    if size_of_update > 1e-8 * np.abs(z).max():
        raise RuntimeError(f"es step: Newton did not converge in {max_iterations} iterations")
    dv, mu = z[:size], z[size:]
    vm = v0 + dv / 2
    q1 = q0 + dt * vm
    rates = np.array([torque_forces(model, (q0 + q1) / 2, np.eye(n)[i]) for i in range(n)]) @ vm
    return StepResult(q1, v0 + dv, float(dt * applied @ rates),
                      float(dt * damping @ rates ** 2), iterations, z)
