"""Numeric forward kinematics and energy of the chain, straight from model.md sections 1-3.

This is plain numpy, independent of the symbolic model: scene validation uses it (a spring
segment of zero length at the initial angles is refused), and tests use it as a reference for
the symbolic and generated code.

Conventions (model.md section 1): phi are the relative joint angles, theta_i = phi_1 + ... +
phi_i the absolute ones, e_i = (cos theta_i, sin theta_i), n_i = S e_i with S = [[0, -1], [1, 0]],
e_0 = (1, 0) and n_0 = (0, 1) for the base. Model indices are 1-based; array rows are 0-based,
so row k of `joints` is X_{k+1}.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .values import Scene, Spring

S = np.array([[0.0, -1.0], [1.0, 0.0]])
"""Rotation by +90 degrees: n = S e."""

ZERO_SEGMENT_RELATIVE_TOLERANCE = 1e-9
"""A spring segment shorter than this times the chain's size counts as zero length."""

SMALLEST_NORMAL = float(np.finfo(float).tiny)
"""The smallest normal double (2.2e-308)."""
SMALLEST_SQUARED_LENGTH = float(np.sqrt(SMALLEST_NORMAL))
"""1.49e-154 m: the smallest length whose square is a normal double. The generated code squares
lengths (a segment's sqrt(dx^2 + dy^2), m (a^2 + b^2) in the mass matrix); below it the square
is subnormal (digits lost) or zero, and a segment shorter counts as zero length too."""


def _frozen(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


def _vector(scene: Scene, values, what: str) -> np.ndarray:
    array = np.asarray(values, dtype=float)
    if array.shape != (scene.n,):
        raise ValueError(f"{what} must have shape ({scene.n},), one per link, got {array.shape}")
    return array


@dataclass(frozen=True, eq=False)  # numpy fields: compare them explicitly
class ChainGeometry:
    """Positions of the chain at relative angles phi (model.md section 1); read-only arrays."""

    theta: np.ndarray       # (n,) absolute angles theta_1..theta_n
    directions: np.ndarray  # (n, 2) e_1..e_n
    normals: np.ndarray     # (n + 1, 2) n_0..n_n (row 0 is the base's n_0 = (0, 1))
    joints: np.ndarray      # (n + 1, 2) X_1..X_{n+1}, X_1 = 0
    coms: np.ndarray        # (n, 2) x_1..x_n
    fastenings: np.ndarray  # (n + 1, 2) P_1..P_{n+1} with the chain's offsets r_1..r_{n+1}


@dataclass(frozen=True, eq=False)  # numpy fields: compare them explicitly
class SpringGeometry:
    """The fastenings a spring runs through and its segment lengths (model.md section 2)."""

    points: np.ndarray           # (last - first + 2, 2) P_first..P_{last+1}
    segment_lengths: np.ndarray  # (last - first + 1,) s_first..s_last

    @property
    def total_length(self) -> float:
        """sum_j s_j, the length that a spring's energy depends on."""
        return float(np.sum(self.segment_lengths))


@dataclass(frozen=True)
class Energy:
    """The parts of H = T + V (model.md section 3), in J."""

    kinetic: float        # T = sum_i 1/2 m_i |xdot_i|^2 + 1/2 J_i thetadot_i^2
    gravitational: float  # sum_i m_i g y_i
    elastic: float        # sum over springs of 1/2 k (sum_j s_j - S_0)^2

    @property
    def potential(self) -> float:
        return self.gravitational + self.elastic

    @property
    def total(self) -> float:
        return self.kinetic + self.gravitational + self.elastic


def absolute_angles(phi) -> np.ndarray:
    """theta_i = phi_1 + ... + phi_i (model.md section 1)."""
    return np.cumsum(np.asarray(phi, dtype=float))


def chain_geometry(scene: Scene, phi) -> ChainGeometry:
    """Joints, COMs and fastenings at relative angles phi (model.md section 1).

    X_1 = 0, X_{i+1} = X_i + L_i e_i;  x_i = X_i + a_i e_i + b_i n_i;
    P_1 = X_1 + r_1 n_0,  P_{i+1} = X_{i+1} + r_{i+1} n_i.
    """
    theta = absolute_angles(_vector(scene, phi, "phi"))
    directions = np.column_stack([np.cos(theta), np.sin(theta)])
    normals = np.vstack([[0.0, 1.0], directions @ S.T])
    lengths = np.array([link.length for link in scene.links])
    joints = np.vstack([[0.0, 0.0], np.cumsum(lengths[:, None] * directions, axis=0)])
    a = np.array([link.com for link in scene.links])
    b = np.array([link.com_normal for link in scene.links])
    coms = joints[:-1] + a[:, None] * directions + b[:, None] * normals[1:]
    r = np.array(scene.chain_fastenings())
    fastenings = joints + r[:, None] * normals
    return ChainGeometry(theta=_frozen(theta), directions=_frozen(directions),
                         normals=_frozen(normals), joints=_frozen(joints),
                         coms=_frozen(coms), fastenings=_frozen(fastenings))


def spring_geometry(scene: Scene, spring: Spring, phi) -> SpringGeometry:
    """P_first..P_{last+1} with the spring's offsets, and s_j = |P_{j+1} - P_j| (model.md 2).

    The offsets are `scene.spring_fastenings(spring)`: the spring's own `offsets` when given,
    otherwise the chain's r_first..r_{last+1}. Fastening j sits at X_j + r n_{j-1}.
    """
    chain = chain_geometry(scene, phi)
    rows = slice(spring.first - 1, spring.last + 1)
    r = np.array(scene.spring_fastenings(spring), dtype=float)
    points = chain.joints[rows] + r[:, None] * chain.normals[rows]
    segments = np.diff(points, axis=0)
    # hypot, not the norm: it neither overflows nor underflows for extreme offsets.
    segment_lengths = np.hypot(segments[:, 0], segments[:, 1])
    return SpringGeometry(points=_frozen(points), segment_lengths=_frozen(segment_lengths))


def spring_energy(scene: Scene, spring: Spring, phi) -> float:
    """1/2 k (sum_j s_j - S_0)^2 (model.md section 2; one segment when mono-articular)."""
    stretch = spring_geometry(scene, spring, phi).total_length - spring.rest_length
    return 0.5 * spring.stiffness * stretch * stretch


#: During a run, a segment shorter than this times the geometry's size stops the run: there the
#: spring's direction turns within a step's motion and its force is no longer trustworthy.
RUN_SEGMENT_RELATIVE_TOLERANCE = 1e-6


def geometry_size(scene: Scene, spring: Spring) -> float:
    """Sum of the link lengths, of |r| over the chain's fastenings and the spring's offsets."""
    size = sum(link.length for link in scene.links)
    size += sum(abs(r) for r in scene.chain_fastenings())
    if spring.offsets is not None:
        size += sum(abs(r) for r in spring.offsets)
    return size


def run_segment_tolerance(scene: Scene, spring: Spring) -> float:
    """The length under which a segment of `spring` stops a run (RUN_SEGMENT_RELATIVE_TOLERANCE)."""
    return RUN_SEGMENT_RELATIVE_TOLERANCE * geometry_size(scene, spring)


def zero_segment_tolerance(scene: Scene, spring: Spring) -> float:
    """The length under which a segment of `spring` counts as zero.

    ZERO_SEGMENT_RELATIVE_TOLERANCE times the size of the geometry: the sum of the link lengths,
    of |r| over the chain's fastenings and of |r| over the spring's own offsets (if any); at
    least SMALLEST_SQUARED_LENGTH, below which the generated sqrt(dx^2 + dy^2) underflows.
    """
    size = min(geometry_size(scene, spring), float(np.finfo(float).max))   # no limit of inf
    return max(ZERO_SEGMENT_RELATIVE_TOLERANCE * size, SMALLEST_SQUARED_LENGTH)


def dwarfing_size(sizes, length: float) -> int | None:
    """Which one of the terms `sizes` of a geometry's size G alone puts a segment of `length`
    below the zero-length limit ZERO_SEGMENT_RELATIVE_TOLERANCE * G: the index of the largest,
    if the segment is at least the limit of G without it; None if the segment is short by the
    rest of the geometry too (a segment that is short in its own right), or if there is no
    rest (the largest term is the whole geometry). A joint 1e150 m out
    dwarfs a spring of 0.2 m between two other links: the key to name is that joint's."""
    sizes = [float(size) for size in sizes]
    if not sizes:
        return None
    largest = max(range(len(sizes)), key=sizes.__getitem__)
    rest = sum(size for index, size in enumerate(sizes) if index != largest)
    return largest if rest > 0 and length >= ZERO_SEGMENT_RELATIVE_TOLERANCE * rest else None


def dwarfed_segment(key: str, size: float, segment: str, length: float,
                    tolerance: float) -> str:
    """The refusal of a segment dwarfed by one key's length (dwarfing_size): the real reason."""
    return (f"{size:.3g} m dwarfs {segment}, {length:.3g} m long at the initial angles: it "
            f"makes the geometry's size G so large that the segment is below 1e-9 G = "
            f"{tolerance:.3g} m, where a segment counts as zero length (and a run stops below "
            f"1e-6 G); every segment must be at least 1e-9 of the geometry's size: write {key} "
            f"in metres")


def dwarfed_by(scene: Scene, index: int, j: int, length: float,
               tolerance: float) -> tuple[str, str, float] | None:
    """(key path, what is wrong, value) of the one length or fastening whose size alone puts
    segment s_j of spring `index` below the zero-length limit (dwarfing_size): a link 1e150 m
    long, which the segment's own refusal (zero length, move a fastening) would not name."""
    spring = scene.springs[index]
    keys = ([(f"links[{i}].length", link.length) for i, link in enumerate(scene.links)]
            + [("base.fastening", scene.base_fastening)]
            + [(f"links[{i}].fastening", link.fastening) for i, link in enumerate(scene.links)]
            + [(f"springs[{index}].offsets[{k}]", r) for k, r in enumerate(spring.offsets or ())])
    largest = dwarfing_size([abs(value) for _, value in keys], length)
    if largest is None:
        return None
    key, value = keys[largest]
    return (key, dwarfed_segment(key, abs(value), f"segment s_{j} of springs[{index}] "
                                 f"(fastening P_{j} to P_{j + 1})", length, tolerance), value)


def joint_velocities(scene: Scene, phi, phidot) -> np.ndarray:
    """Xdot_1..Xdot_{n+1}, shape (n + 1, 2): Xdot_1 = 0, Xdot_{i+1} = Xdot_i + thetadot_i L_i n_i.

    From X_{i+1} = X_i + L_i e_i and d e_i/dt = thetadot_i S e_i = thetadot_i n_i.
    """
    chain = chain_geometry(scene, phi)
    thetadot = absolute_angles(_vector(scene, phidot, "phidot"))
    lengths = np.array([link.length for link in scene.links])
    steps = (thetadot * lengths)[:, None] * chain.normals[1:]
    return np.vstack([[0.0, 0.0], np.cumsum(steps, axis=0)])


def com_velocities(scene: Scene, phi, phidot) -> np.ndarray:
    """xdot_1..xdot_n, shape (n, 2): xdot_i = Xdot_i + thetadot_i S (x_i - X_i).

    Differentiating x_i = X_i + a_i e_i + b_i n_i with d e_i/dt = thetadot_i n_i and
    d n_i/dt = -thetadot_i e_i gives thetadot_i (a_i n_i - b_i e_i) = thetadot_i S (x_i - X_i).
    Equivalently xdot_i = sum_{j <= i} phidot_j S (x_i - X_j): joint j turns everything
    distal to it about X_j.
    """
    chain = chain_geometry(scene, phi)
    thetadot = absolute_angles(_vector(scene, phidot, "phidot"))
    joint_dots = joint_velocities(scene, phi, phidot)
    arms = chain.coms - chain.joints[:-1]
    return joint_dots[:-1] + thetadot[:, None] * (arms @ S.T)


def kinetic_energy(scene: Scene, phi, phidot) -> float:
    """T = sum_i 1/2 m_i |xdot_i|^2 + 1/2 J_i thetadot_i^2 (model.md section 3)."""
    masses = np.array([link.mass for link in scene.links])
    inertias = np.array([link.inertia for link in scene.links])
    xdot = com_velocities(scene, phi, phidot)
    thetadot = absolute_angles(_vector(scene, phidot, "phidot"))
    return float(0.5 * np.sum(masses * np.sum(xdot * xdot, axis=1))
                 + 0.5 * np.sum(inertias * thetadot * thetadot))


def gravitational_energy(scene: Scene, phi) -> float:
    """sum_i m_i g y_i, zero at y = 0, g along -y (model.md section 3)."""
    masses = np.array([link.mass for link in scene.links])
    return float(scene.gravity * np.sum(masses * chain_geometry(scene, phi).coms[:, 1]))


def elastic_energy(scene: Scene, phi) -> float:
    """Sum of the spring energies of model.md section 2."""
    return float(sum(spring_energy(scene, spring, phi) for spring in scene.springs))


def potential_energy(scene: Scene, phi) -> float:
    """V = sum_i m_i g y_i + the spring energies (model.md section 3)."""
    return gravitational_energy(scene, phi) + elastic_energy(scene, phi)


def energy(scene: Scene, phi, phidot) -> Energy:
    """The parts of H = T + V at (phi, phidot) (model.md section 3)."""
    return Energy(kinetic=kinetic_energy(scene, phi, phidot),
                  gravitational=gravitational_energy(scene, phi),
                  elastic=elastic_energy(scene, phi))


def total_energy(scene: Scene, phi, phidot) -> float:
    """H = T + V at (phi, phidot) (model.md section 3): the energy reported everywhere."""
    return energy(scene, phi, phidot).total


def mass_matrix(scene: Scene, phi) -> np.ndarray:
    """M(phi) in joint space, T = 1/2 phidot^T M phidot, by polarisation of the quadratic form."""
    n = scene.n
    unit = np.eye(n)
    diagonal = np.array([2 * kinetic_energy(scene, phi, unit[i]) for i in range(n)])
    matrix = np.diag(diagonal)
    for i in range(n):
        for j in range(i + 1, n):
            both = 2 * kinetic_energy(scene, phi, unit[i] + unit[j])
            matrix[i, j] = matrix[j, i] = (both - diagonal[i] - diagonal[j]) / 2
    return matrix
