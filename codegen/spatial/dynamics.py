"""Numeric kinematics and dynamics of a spatial scene in joint coordinates (numpy).

The reference the spatial schemes and importers are checked against, and what `chaingen
import` reports: link poses, the mass matrix M(q), the generalized gravity and spring forces
(the gradient of the potential, the torques that hold a posture), the energies and the spring
lengths. Written from the definitions, not for speed: the kinetic energy of link i is
1/2 m_i |v_i|^2 + 1/2 w_i . (R_i I_i R_i^T) w_i with v_i and w_i linear in qdot through the
Jacobians of its centre of mass, so M = sum_i m_i Jv_i^T Jv_i + Jw_i^T R_i I_i R_i^T Jw_i.
"""
from __future__ import annotations

import numpy as np

from .values import SpatialScene


def rpy_matrix(rpy) -> np.ndarray:
    """URDF's rotation of roll, pitch, yaw about the fixed x, y, z axes: Rz(y) Ry(p) Rx(r)."""
    roll, pitch, yaw = rpy
    cr, sr = np.cos(roll), np.sin(roll)
    cp, sp = np.cos(pitch), np.sin(pitch)
    cy, sy = np.cos(yaw), np.sin(yaw)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def axis_rotation(axis, angle: float) -> np.ndarray:
    """Rotation by `angle` about the unit vector `axis` (Rodrigues)."""
    k = np.asarray(axis, dtype=float)
    cross = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * cross + (1.0 - np.cos(angle)) * cross @ cross


def link_poses(scene: SpatialScene, q) -> list[tuple[np.ndarray, np.ndarray]]:
    """(R_i, p_i) of links 0..n in the world: link 0 the base (identity), link i's frame
    rotation and origin (the origin of joint i)."""
    q = np.asarray(q, dtype=float)
    poses = [(np.eye(3), np.zeros(3))]
    for i, link in enumerate(scene.links):
        rotation, origin = poses[-1]
        joint = link.joint
        joint_rotation = rotation @ rpy_matrix(joint.rpy)
        poses.append((joint_rotation @ axis_rotation(joint.axis, q[i]),
                      origin + rotation @ np.asarray(joint.xyz, dtype=float)))
    return poses


def joint_axes(scene: SpatialScene, poses) -> np.ndarray:
    """The world directions of the joint axes (n x 3), from link_poses."""
    return np.array([poses[i + 1][0] @ np.asarray(link.joint.axis, dtype=float)
                     for i, link in enumerate(scene.links)])


def point_position(poses, link: int, point) -> np.ndarray:
    """A point fixed on `link` (0 = base), given in its frame, in the world."""
    rotation, origin = poses[link]
    return origin + rotation @ np.asarray(point, dtype=float)


def point_jacobian(scene: SpatialScene, poses, link: int, position: np.ndarray) -> np.ndarray:
    """d(position)/dq (3 x n) of a point of `link` at world `position`: joint j <= link moves
    it by axis_j x (position - origin_j)."""
    axes = joint_axes(scene, poses)
    jacobian = np.zeros((3, scene.n))
    for j in range(link):
        jacobian[:, j] = np.cross(axes[j], position - poses[j + 1][1])
    return jacobian


def com_positions(scene: SpatialScene, q) -> np.ndarray:
    """The centres of mass of links 1..n in the world (n x 3)."""
    poses = link_poses(scene, q)
    return np.array([point_position(poses, i + 1, link.com)
                     for i, link in enumerate(scene.links)])


def mass_matrix(scene: SpatialScene, q) -> np.ndarray:
    """M(q) (n x n), symmetric positive definite where the axes are independent."""
    poses = link_poses(scene, q)
    axes = joint_axes(scene, poses)
    mass = np.zeros((scene.n, scene.n))
    for i, link in enumerate(scene.links):
        rotation = poses[i + 1][0]
        com = point_position(poses, i + 1, link.com)
        linear = point_jacobian(scene, poses, i + 1, com)
        angular = np.zeros((3, scene.n))
        angular[:, :i + 1] = axes[:i + 1].T
        inertia = rotation @ np.array(link.inertia_matrix()) @ rotation.T
        mass += link.mass * linear.T @ linear + angular.T @ inertia @ angular
    return 0.5 * (mass + mass.T)


def gravity_torques(scene: SpatialScene, q) -> np.ndarray:
    """dV_g/dq: the joint torques that hold the chain against gravity at q (Pinocchio's
    generalized gravity g(q); M qddot + C qdot + g = tau)."""
    poses = link_poses(scene, q)
    gravity = np.asarray(scene.gravity, dtype=float)
    torques = np.zeros(scene.n)
    for i, link in enumerate(scene.links):
        com = point_position(poses, i + 1, link.com)
        torques -= link.mass * point_jacobian(scene, poses, i + 1, com).T @ gravity
    return torques


def route_positions(scene: SpatialScene, q) -> list[np.ndarray]:
    """Each spring's route points in the world (k x 3 per spring)."""
    poses = link_poses(scene, q)
    return [np.array([point_position(poses, point.link, point.point) for point in spring.route])
            for spring in scene.springs]


def spring_lengths(scene: SpatialScene, q) -> np.ndarray:
    """The length of each spring: the sum of its straight segments."""
    return np.array([np.linalg.norm(np.diff(points, axis=0), axis=1).sum()
                     for points in route_positions(scene, q)])


def spring_torques(scene: SpatialScene, q) -> np.ndarray:
    """dV_s/dq: the joint torques that hold the springs' pull at q, sum over springs of
    k (L - L_0) dL/dq, dL/dq summed over the segments' unit vectors."""
    poses = link_poses(scene, q)
    torques = np.zeros(scene.n)
    for spring in scene.springs:
        points = [(point.link, point_position(poses, point.link, point.point))
                  for point in spring.route]
        length = 0.0
        gradient = np.zeros(scene.n)
        for (link_a, a), (link_b, b) in zip(points, points[1:]):
            segment = b - a
            norm = np.linalg.norm(segment)
            length += norm
            unit = segment / norm
            gradient += unit @ (point_jacobian(scene, poses, link_b, b)
                                - point_jacobian(scene, poses, link_a, a))
        torques += spring.stiffness * (length - spring.rest_length) * gradient
    return torques


def potential_energy(scene: SpatialScene, q) -> float:
    """V = V_g + V_s: gravity (zero at the base's origin) and the springs'."""
    gravity = np.asarray(scene.gravity, dtype=float)
    coms = com_positions(scene, q)
    masses = np.array([link.mass for link in scene.links])
    lengths = spring_lengths(scene, q)
    stiffness = np.array([spring.stiffness for spring in scene.springs])
    rest = np.array([spring.rest_length for spring in scene.springs])
    return float(-(masses * (coms @ gravity)).sum()
                 + 0.5 * (stiffness * (lengths - rest) ** 2).sum())


def kinetic_energy(scene: SpatialScene, q, velocities) -> float:
    """T = 1/2 qdot . M(q) qdot."""
    velocities = np.asarray(velocities, dtype=float)
    return float(0.5 * velocities @ mass_matrix(scene, q) @ velocities)
