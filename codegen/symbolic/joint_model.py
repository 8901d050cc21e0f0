"""Symbolic model of the chain in joint space, for "midpoint" (model.md 6) and "vi" (model.md 5).

Both describe link i by its absolute direction e_i: "midpoint" as (cos theta_i, sin theta_i),
"vi" as the product of the unit attitude vectors q_1 ... q_i (complex multiplication), which
keeps every position and M(q) polynomial. From the directions and the joint rates w follow the
joints, COMs, fastenings, the COM velocities, T (so M = d^2 T / dw^2) and V, derived by SymPy.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy as sp
from sympy import ImmutableMatrix

from ..scene import Scene
from .com_model import S, SpringTerms, dot2, number, spring_terms


@dataclass(frozen=True)
class JointSpaceModel:
    scene: Scene
    rates: ImmutableMatrix                  # w: relative joint rates phidot_i
    directions: tuple[ImmutableMatrix, ...]  # e_1 .. e_n
    joints: tuple[ImmutableMatrix, ...]      # X_1 .. X_{n+1}
    coms: tuple[ImmutableMatrix, ...]        # x_1 .. x_n
    kinetic_energy: sp.Expr
    mass_matrix: ImmutableMatrix            # M(configuration), T = 1/2 w^T M w
    gravity_potential: sp.Expr
    springs: tuple[SpringTerms, ...]

    @property
    def potential(self) -> sp.Expr:
        return self.gravity_potential + sp.Add(*(term.energy for term in self.springs))

    @property
    def energy(self) -> sp.Expr:
        return self.kinetic_energy + self.potential

    def damping_torques(self, rates) -> ImmutableMatrix:
        """-d_i w_i: viscous joint damping (model.md section 7)."""
        return ImmutableMatrix([-number(link.damping) * w
                                for link, w in zip(self.scene.links, rates)])


def joint_space_model(scene: Scene, directions, rates) -> JointSpaceModel:
    """Kinematics, energies and mass matrix from the absolute link directions e_i.

    COM velocity (model.md 1): e_k rotates with thetadot_k = w_1 + ... + w_k, so
    xdot_i = sum_{k<i} L_k thetadot_k S e_k + thetadot_i S (a_i e_i + b_i n_i).
    """
    rates = ImmutableMatrix(rates)
    joints = [ImmutableMatrix([0, 0])]
    normals = [ImmutableMatrix([0, 1])]
    coms, com_velocities, absolute_rates = [], [], []
    joint_velocity = ImmutableMatrix([0, 0])
    theta_dot = sp.Integer(0)
    for link, e, w in zip(scene.links, directions, rates):
        theta_dot = theta_dot + w
        n = S * e
        arm = number(link.com) * e + number(link.com_normal) * n
        coms.append(joints[-1] + arm)
        com_velocities.append(joint_velocity + theta_dot * (S * arm))
        absolute_rates.append(theta_dot)
        joint_velocity = joint_velocity + theta_dot * number(link.length) * n
        joints.append(joints[-1] + number(link.length) * e)
        normals.append(n)

    kinetic = sp.Integer(0)
    for link, velocity, theta_dot in zip(scene.links, com_velocities, absolute_rates):
        kinetic += number(link.mass) / 2 * dot2(velocity, velocity)
        if link.inertia:
            kinetic += number(link.inertia) / 2 * theta_dot ** 2
    mass_matrix = ImmutableMatrix(sp.hessian(kinetic, rates))
    gravity = sp.Integer(0)
    if scene.gravity:
        gravity = sp.Add(*(number(link.mass * scene.gravity) * com[1]
                           for link, com in zip(scene.links, coms)))
    springs = tuple(spring_terms(scene, spring, joints, normals) for spring in scene.springs)
    return JointSpaceModel(
        scene=scene, rates=rates, directions=tuple(directions), joints=tuple(joints),
        coms=tuple(coms), kinetic_energy=(rates.T * mass_matrix * rates)[0, 0] / 2,
        mass_matrix=mass_matrix, gravity_potential=gravity, springs=springs)


def direction_geometry(scene: Scene, directions) -> tuple[list, list, list]:
    """(joints X_1..X_{n+1}, normals n_0..n_n, COM heights) from the absolute link directions
    (expressions or symbols): what the potential is made of."""
    joints, normals, heights = [ImmutableMatrix([0, 0])], [ImmutableMatrix([0, 1])], []
    for link, e in zip(scene.links, directions):
        e = ImmutableMatrix(e)
        n = S * e
        heights.append((joints[-1] + number(link.com) * e + number(link.com_normal) * n)[1])
        joints.append(joints[-1] + number(link.length) * e)
        normals.append(n)
    return joints, normals, heights


def joint_space_potential(scene: Scene, directions) -> sp.Expr:
    """V (gravity and springs) from the absolute link directions, without the kinetic terms."""
    joints, normals, heights = direction_geometry(scene, directions)
    gravity = sp.Integer(0)
    if scene.gravity:
        gravity = sp.Add(*(number(link.mass * scene.gravity) * y
                           for link, y in zip(scene.links, heights)))
    springs = (spring_terms(scene, spring, joints, normals) for spring in scene.springs)
    return gravity + sp.Add(*(term.energy for term in springs))


def angle_directions(angles) -> list[ImmutableMatrix]:
    """e_i = (cos theta_i, sin theta_i), theta_i = phi_1 + ... + phi_i."""
    directions, theta = [], sp.Integer(0)
    for phi in angles:
        theta = theta + phi
        directions.append(ImmutableMatrix([sp.cos(theta), sp.sin(theta)]))
    return directions


def coriolis(model: JointSpaceModel, angles) -> ImmutableMatrix:
    """Mdot w - dT/dphi = (d(M w)/dphi) w - 1/2 grad_phi (w^T M w), M = M(phi)."""
    w = model.rates
    momentum = model.mass_matrix * w
    return ImmutableMatrix(momentum.jacobian(angles) * w
                           - ImmutableMatrix([model.kinetic_energy]).jacobian(angles).T)
