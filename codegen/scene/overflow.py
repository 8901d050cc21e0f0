"""Finite numbers whose products are not: the planar reader's checks of a scene's dynamics at
its start against the range of a double (docs/scene-format.md, sections 5, 6 and 8), as the
spatial reader's refuse_overflowing_dynamics, and against its bottom: a geometry or a mass
matrix whose squares underflow (dynamics_underflow). Each returns the refusal as (key path,
what is wrong[, value]) for SceneReader.fail, or None."""
from __future__ import annotations

import math

import numpy as np

from . import kinematics
from .kinematics import SMALLEST_NORMAL, SMALLEST_SQUARED_LENGTH
from .values import LINK_FIELDS, Scene


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


def _geometry_keys(scene: Scene) -> list[tuple[str, float]]:
    """The chain's lengths by key path: each link's length, com, com_normal and fastening, and
    the base's fastening."""
    keys = [("base.fastening", scene.base_fastening)]
    for i, link in enumerate(scene.links):
        keys += [(f"links[{i}].{field.key}", getattr(link, field.key))
                 for field in LINK_FIELDS if field.unit == "m"]
    return keys


def dynamics_underflow(scene: Scene) -> tuple | None:
    """A chain so small (all of it 1e-300 m) that the squares of its lengths, which its
    energies and Jacobians hold, are subnormal or zero in a double: the generated code's
    segment lengths sqrt(dx^2 + dy^2) come out 0 and the run stopped at its initial state
    (exit 1), or a mass matrix sum_i m_i R_i^2 + J_i (the bound of dynamics_overflow) that is
    subnormal or zero though its masses sit off the joints (a mass of 1e-200 kg at 1e-60 m).
    One small length among ordinary ones is no such chain: its squares are round-off beside
    theirs."""
    keys = _geometry_keys(scene)
    size = sum(abs(value) for _, value in keys)
    if size < SMALLEST_SQUARED_LENGTH:
        key, value = max(keys, key=lambda item: abs(item[1]))
        return (key, f"the largest of the chain's lengths (link lengths, coms, fastenings), "
                f"which sum to {size:.3g} m, below {SMALLEST_SQUARED_LENGTH:.3g} m: their "
                "squares in the energies, the mass matrix and the springs' segment lengths "
                "are subnormal or zero in a double: write the scene in SI units (m)", value)
    geometry = kinematics.chain_geometry(scene, scene.initial_angles)
    masses = np.array([link.mass for link in scene.links])
    inertias = np.array([link.inertia for link in scene.links])
    arms = geometry.coms[:, None, :] - geometry.joints[None, :-1, :]
    reach = np.hypot(arms[..., 0], arms[..., 1])
    reach = np.where(np.tri(scene.n, dtype=bool), reach, 0.0).max(axis=1)
    with np.errstate(under="ignore"):
        bound = float(np.sum(masses * (reach * reach) + inertias))
    if bound >= SMALLEST_NORMAL or not np.any(masses * reach > 0):
        return None
    return ("links", f"the chain's mass matrix at the initial angles is at most {bound:.3g} kg "
            f"m^2 (sum_i m_i R_i^2 + J_i), below the smallest normal double "
            f"{SMALLEST_NORMAL:.3g}: subnormal or zero, no step can solve with it (a mass, an "
            "inertia or a length far too small): write the scene in SI units (m, kg, kg m^2)")


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
