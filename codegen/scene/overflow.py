"""Finite numbers whose products are not: the planar reader's checks of a scene's dynamics at
its start against the range of a double (docs/scene-format.md, sections 5, 6 and 8), as the
spatial reader's refuse_overflowing_dynamics. Each returns the refusal as (key path, what is
wrong[, value]) for SceneReader.fail, or None."""
from __future__ import annotations

import math

import numpy as np

from . import kinematics
from .values import Scene


def dynamics_overflow(scene: Scene) -> tuple | None:
    """A chain whose mass matrix or gravity torques at the initial angles are beyond the range
    of a double, though every number is finite (a com 1e200 m out, links 1e300 m long, a mass
    of 1e308 kg at 10 m): every step of it would fail on inf or NaN, and es's COM coordinates
    square the com (com^2 + com_normal^2) when the code is generated. Bounded without forming
    the matrix: with R_i the largest distance of link i's COM from a joint at or before it,
    |M_jk| <= sum_i m_i R_i^2 + J_i, and the gravity torques and energy are at most
    g sum_i m_i R_i."""
    geometry = kinematics.chain_geometry(scene, scene.initial_angles)
    masses = np.array([link.mass for link in scene.links])
    inertias = np.array([link.inertia for link in scene.links])
    with np.errstate(over="ignore", invalid="ignore"):
        arms = geometry.coms[:, None, :] - geometry.joints[None, :-1, :]
        reach = np.hypot(arms[..., 0], arms[..., 1])       # link i's COM from joint j
        reach = np.where(np.tri(scene.n, dtype=bool), reach, 0.0).max(axis=1)
        # The square first: es squares the com alone, whatever the mass.
        inertia_bound = np.sum(masses * (reach * reach) + inertias)
        gravity_bound = scene.gravity * np.sum(masses * reach)
    if np.all(np.isfinite(geometry.coms)) and math.isfinite(inertia_bound) \
            and math.isfinite(gravity_bound):
        return None
    return ("links", "the chain's mass matrix or gravity torques at the initial angles are "
            "beyond the range of a double (a length, a com, a mass or an inertia far too "
            "large, or gravity): write the scene in SI units (m, kg, kg m^2)")


def energy_overflow(scene: Scene) -> tuple | None:
    """A spring whose energy 1/2 k (s - S_0)^2 at the initial angles, or an initial state whose
    kinetic energy, is beyond the range of a double (a rest length of 1e300 m, a rate of
    1e160 rad/s): the energy every step balances would be inf."""
    phi = scene.initial_angles
    with np.errstate(over="ignore", invalid="ignore"):
        for index, spring in enumerate(scene.springs):
            if not math.isfinite(kinematics.spring_energy(scene, spring, phi)):
                return (f"springs[{index}]", "its energy 1/2 k (s - S_0)^2 at the initial "
                        "angles is beyond the range of a double (a stiffness or a rest length "
                        "far too large): write the scene in SI units (N/m, m)")
        kinetic = kinematics.kinetic_energy(scene, phi, scene.initial_velocities)
    if math.isfinite(kinetic):
        return None
    return ("initial.velocities", "the kinetic energy of the initial state is beyond the range "
            "of a double: write the rates in rad/s", list(scene.initial_velocities))
