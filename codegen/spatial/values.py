"""The values of a spatial scene: frozen dataclasses of validated numbers.

A spatial scene is a serial chain of n rigid links on revolute joints in 3D, described with
URDF's conventions (docs/scene-format.md, "Spatial scenes"): joint i carries link i on link
i - 1 (link 0 is the base, fixed in the world); its origin `xyz`, `rpy` is in link i - 1's
frame, its unit `axis` in its own frame, and link i's frame is the joint frame turned by the
joint angle q_i about that axis. Each link has its mass, its centre of mass `com` and its
inertia tensor about the centre of mass, both in its own frame. Springs are linear elastic
elements routed through points fixed on links (MuJoCo's spatial tendons through sites); the
length of a spring is the sum of its straight segments. Its run settings are a [simulation]
table of the planar format's keys and rules (chaingen.scene.values.Simulation), with its own
default method.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

from ..scene.values import Control, Simulation

Vector = tuple[float, float, float]

#: The order of a link's inertia entries in a scene file: URDF's ixx iyy izz ixy ixz iyz.
INERTIA_KEYS = ("ixx", "iyy", "izz", "ixy", "ixz", "iyz")

#: The method of a spatial scene whose file names none ([simulation].method): midpoint, the
#: scheme every spatial feature has (orders 2, 4, 6, sensitivities, actuation, damping) and the
#: cheapest step (docs/benchmarks.md, "Spatial arm"); fixed, so that a scene file and a command
#: line keep their numbers when another scheme's spatial builder changes. The planar default,
#: es, came to spatial scenes later and at order 2 first.
SPATIAL_DEFAULT_METHOD = "midpoint"

#: The run settings of a spatial scene whose file has no [simulation] table, and the defaults of
#: the keys such a table leaves out: the planar table's (one definition), with midpoint.
SPATIAL_SIMULATION_DEFAULTS = Simulation(method=SPATIAL_DEFAULT_METHOD)


@dataclass(frozen=True)
class SpatialJoint:
    """Revolute joint i: its origin in link i - 1's frame and its unit axis in its own frame."""

    xyz: Vector               # m, origin of the joint frame in the parent's frame
    rpy: Vector               # rad, roll, pitch, yaw (fixed axes x, y, z: R = Rz Ry Rx)
    axis: Vector              # unit vector, in the joint frame


@dataclass(frozen=True)
class SpatialLink:
    """Link i (1-based) and the joint i that carries it (SI units)."""

    mass: float               # kg, > 0
    com: Vector               # m, centre of mass in the link's frame
    inertia: tuple[float, float, float, float, float, float]   # kg m^2, INERTIA_KEYS' order,
    #                           about the centre of mass, link frame; positive semi-definite
    joint: SpatialJoint
    damping: float = 0.0      # N m s/rad, viscous damping of joint i, >= 0

    def inertia_matrix(self) -> tuple[Vector, Vector, Vector]:
        """The symmetric 3 x 3 inertia tensor about the centre of mass, link frame."""
        ixx, iyy, izz, ixy, ixz, iyz = self.inertia
        return ((ixx, ixy, ixz), (ixy, iyy, iyz), (ixz, iyz, izz))


@dataclass(frozen=True)
class RoutePoint:
    """A point a spring passes through: fixed on `link` (0 = the base), `point` in its frame."""

    link: int
    point: Vector


@dataclass(frozen=True)
class SpatialSpring:
    """A linear spring through two or more route points: one elastic element whose length is
    the sum of the straight segments between consecutive points."""

    route: tuple[RoutePoint, ...]
    stiffness: float          # N/m, >= 0
    rest_length: float        # m, >= 0

    @property
    def joints(self) -> tuple[int, ...]:
        """The joints (1-based) the spring spans: those between its lowest and highest link."""
        links = [point.link for point in self.route]
        return tuple(range(min(links) + 1, max(links) + 1))


@dataclass(frozen=True)
class SpatialScene:
    """A spatial chain: what the spatial reader makes of a scene file with joint tables."""

    name: str
    gravity: Vector                           # m/s^2, in the world (base) frame
    links: tuple[SpatialLink, ...]
    springs: tuple[SpatialSpring, ...]
    initial_angles: tuple[float, ...]         # rad, one per joint
    initial_velocities: tuple[float, ...]     # rad/s, one per joint
    actuated: tuple[int, ...] = ()            # 1-based joints with a torque input, ascending
    control: Control | None = None            # a [control] table (chaingen.scene.values.Control)
    simulation: Simulation = SPATIAL_SIMULATION_DEFAULTS   # run settings ([simulation])
    #: es below order 6 takes the springs' exact discrete gradient by the chain rule (model.md
    #: 4.8): no quadrature (chaingen.scene.solver_rules.quadrature_used).
    spring_quadrature: ClassVar[bool] = False

    @property
    def n(self) -> int:
        return len(self.links)


def geometry_underflow(scene: SpatialScene) -> tuple[str, str, list] | None:
    """(key path, what is wrong, value) for a chain so small that the squares of its lengths
    are subnormal or zero in a double: its joints' xyz, COMs and route points sum to less than
    1.49e-154 m (the planar reader's rule, chaingen.scene.overflow.dynamics_underflow), named
    at the largest; None otherwise. All of spatial_three_link times 1e-300 was refused as
    'route[0] and route[1] are one point at every angle', which they are not."""
    from ..scene.kinematics import SMALLEST_SQUARED_LENGTH

    keys = [(f"links[{i}].{name}", list(vector)) for i, link in enumerate(scene.links)
            for name, vector in (("joint.xyz", link.joint.xyz), ("com", link.com))]
    keys += [(f"springs[{i}].route[{j}]", [point.link, *point.point])
             for i, spring in enumerate(scene.springs) for j, point in enumerate(spring.route)]
    sizes = [math.hypot(*value[-3:]) for _, value in keys]
    if not 0.0 < sum(sizes) < SMALLEST_SQUARED_LENGTH:   # 0: a body on its axis
        return None
    key, value = keys[max(range(len(keys)), key=sizes.__getitem__)]
    return (key, f"the largest of the chain's lengths (joints' xyz, coms, route points), which "
            f"sum to {sum(sizes):.3g} m, below {SMALLEST_SQUARED_LENGTH:.3g} m: their "
            "squares in the energies, the mass matrix and the springs' segment lengths are "
            "subnormal or zero in a double: write the scene in SI units (m)", value)
