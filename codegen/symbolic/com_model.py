"""Symbolic model of the chain in centre-of-mass coordinates (model.md sections 1-4).

Everything is derived with SymPy from the geometry, the kinetic energy T and the potential V;
no printed matrix is transcribed. The scene's numbers are baked in as exact SymPy numbers, and
terms a scene does not have (gravity with g = 0, springs, off-axis COM offsets of zero) never
enter an expression, so the generated code holds only what the scene needs.
"""
from __future__ import annotations

import math
import sys
from dataclasses import dataclass

import sympy as sp
from sympy import ImmutableMatrix

from ..errors import UnsupportedSceneError
from ..scene import Scene, Spring

#: S of model.md section 1: rotation by +90 degrees, n_i = S e_i.
S = ImmutableMatrix([[0, -1], [1, 0]])


def number(value) -> sp.Expr:
    """A scene number as an exact SymPy number (integers stay integers, so 1.0 * x is x); a
    run-time parameter (a SymPy expression in the scene's place) as it is."""
    if isinstance(value, sp.Basic):
        return value
    value = float(value)
    if value.is_integer():
        return sp.Integer(int(value))
    return sp.Float(value)


def cross2(a, b) -> sp.Expr:
    """z-component of the planar cross product a x b."""
    return a[0] * b[1] - a[1] * b[0]


def dot2(a, b) -> sp.Expr:
    return a[0] * b[0] + a[1] * b[1]


@dataclass(frozen=True)
class SpringTerms:
    """One spring's symbolic pieces: its segment lengths and its energy (model.md section 2)."""

    spring: Spring
    segment_lengths: tuple[sp.Expr, ...]   # s_first .. s_last
    energy: sp.Expr
    segment_vectors: tuple[ImmutableMatrix, ...] = ()   # P_{j+1} - P_j


@dataclass(frozen=True)
class ComModel:
    """The chain in COM coordinates q = (x_1..x_n, y_1..y_n) with velocities v (model.md 4).

    joints[i] is X_{i+1} (joints[0] = X_1 = 0), linear in q; directions[i] and normals[i] are
    e_{i+1}, n_{i+1}, linear in q (valid on the constraint manifold); the constraints
    c_i = |x_i - X_i|^2 - |c_i|^2 are quadratic in q; the mass matrix is constant.
    """

    scene: Scene
    q: ImmutableMatrix
    v: ImmutableMatrix
    joints: tuple[ImmutableMatrix, ...]
    directions: tuple[ImmutableMatrix, ...]
    normals: tuple[ImmutableMatrix, ...]
    fastenings: tuple[ImmutableMatrix, ...]     # chain fastenings P_1 .. P_{n+1}
    constraints: ImmutableMatrix
    constraint_jacobian: ImmutableMatrix
    kinetic_energy: sp.Expr
    mass_matrix: ImmutableMatrix
    gravity_potential: sp.Expr
    springs: tuple[SpringTerms, ...]

    @property
    def n(self) -> int:
        return self.scene.n

    @property
    def spring_potential(self) -> sp.Expr:
        return sp.Add(*(term.energy for term in self.springs))

    @property
    def potential(self) -> sp.Expr:
        return self.gravity_potential + self.spring_potential

    @property
    def energy(self) -> sp.Expr:
        """H = T + V (model.md section 3)."""
        return self.kinetic_energy + self.potential

    def com_position(self, i: int) -> ImmutableMatrix:
        """x_{i+1}, the COM of link i+1 (0-based i)."""
        return ImmutableMatrix([self.q[i], self.q[self.n + i]])

    def com_velocity(self, i: int) -> ImmutableMatrix:
        return ImmutableMatrix([self.v[i], self.v[self.n + i]])

    def joint_velocity(self, i: int) -> ImmutableMatrix:
        """Xdot_{i+1}: the joint map is linear in q, so its velocity is the same map of v."""
        return self.joints[i].xreplace(dict(zip(self.q, self.v)))

    def absolute_rates(self) -> tuple[sp.Expr, ...]:
        """thetadot_i = ((x_i - X_i) x (v_i - Xdot_i)) / |c_i|^2 (model.md section 4)."""
        rates = []
        for i, link in enumerate(self.scene.links):
            arm = self.com_position(i) - self.joints[i]
            arm_rate = self.com_velocity(i) - self.joint_velocity(i)
            rates.append(cross2(arm, arm_rate) / number(link.com ** 2 + link.com_normal ** 2))
        return tuple(rates)


def linear_coefficients(expressions, symbols) -> tuple[ImmutableMatrix, ImmutableMatrix]:
    """(A, c) with expressions = A symbols + c, for expressions affine in the symbols.

    The joints and fastenings of the COM model are affine in q but nested (each joint is built
    from the previous one); reading off their constant coefficients once lets every derivative
    of a spring be written down instead of differentiated through that nesting by SymPy.
    """
    index = {symbol: j for j, symbol in enumerate(symbols)}
    rows, offsets = [], []
    for expression in expressions:
        row = [sp.Integer(0)] * len(symbols)
        offset = sp.Integer(0)
        for term, coefficient in sp.expand(expression).as_coefficients_dict().items():
            # A coefficient may hold run-time parameters (a link length L1 in L1 x1 / a1).
            factor, variable = term.as_independent(*symbols, as_Add=False)
            if variable == 1:
                offset += coefficient * factor
            elif variable in index:
                row[index[variable]] += coefficient * factor
            else:
                raise ValueError(f"{expression} is not affine in the coordinates ({term})")
        rows.append(row)
        offsets.append(offset)
    return ImmutableMatrix(rows), ImmutableMatrix(offsets)


def com_frame_map(link) -> ImmutableMatrix:
    """R(-alpha_i)/|c_i|: maps the arm x_i - X_i to the unit direction e_i of the link."""
    a, b = number(link.com), number(link.com_normal)
    c2 = number(link.com ** 2 + link.com_normal ** 2)
    return ImmutableMatrix([[a, b], [-b, a]]) / c2


def spring_terms(scene: Scene, spring: Spring, joints, normals) -> SpringTerms:
    """Segment lengths s_j = |P_{j+1} - P_j| through the spring's own fastenings, and its energy.

    joints and normals are X_1..X_{n+1} and n_0..n_n (n_0 the base's (0, 1)).
    Mono-articular: 1/2 k (s - s_0)^2; multi-articular: 1/2 k (sum s_j - S_0)^2 (model.md 2).
    """
    offsets = scene.spring_fastenings(spring)
    points = [joints[j - 1] + number(r) * normals[j - 1]
              for j, r in zip(range(spring.first, spring.last + 2), offsets)]
    vectors = [ImmutableMatrix(end - start) for start, end in zip(points[:-1], points[1:])]
    lengths = [sp.sqrt(d[0] ** 2 + d[1] ** 2) for d in vectors]
    stretch = sp.Add(*lengths) - number(spring.rest_length)
    energy = number(spring.stiffness) / 2 * stretch ** 2
    return SpringTerms(spring, tuple(lengths), energy, tuple(vectors))


def coordinates(scene: Scene) -> tuple[ImmutableMatrix, ImmutableMatrix]:
    """The symbols q = (x_1..x_n, y_1..y_n) and v of COM coordinates (model.md 4.1), or
    UnsupportedSceneError for a link whose COM is at its proximal joint."""
    n = scene.n
    for i, link in enumerate(scene.links):
        if link.com == 0 and link.com_normal == 0:
            raise UnsupportedSceneError(
                f"links[{i}].com: COM coordinates need the COM away from the proximal joint "
                f"(com^2 + com_normal^2 > 0), link {i + 1} has com = com_normal = 0")
        numbers = (link.com, link.com_normal, link.inertia)
        if all(isinstance(value, (int, float)) for value in numbers):   # not parameters
            # The model divides by c^2 = com^2 + com_normal^2 (the inertia's term J / c^2):
            # a COM 5e-301 m from its joint has c^2 = 0 in a double, one 1e-160 m off J / c^2
            # = inf (before: 'com = com_normal = 0', or inf in the generated constants).
            c2 = link.com * link.com + link.com_normal * link.com_normal
            if not (c2 >= sys.float_info.min and math.isfinite(link.inertia / c2)):
                raise UnsupportedSceneError(
                    f"links[{i}].com: COM coordinates divide by com^2 + com_normal^2, which "
                    f"is {c2:.3g} in a double for link {i + 1} (com = {link.com:g}, com_normal "
                    f"= {link.com_normal:g} m, inertia {link.inertia:g} kg m^2: J / (com^2 + "
                    "com_normal^2) is beyond the range of a double); move the COM off the "
                    "proximal joint, or use vi or midpoint")
    xs = sp.symbols(f"x1:{n + 1}", real=True)
    ys = sp.symbols(f"y1:{n + 1}", real=True)
    vxs = sp.symbols(f"vx1:{n + 1}", real=True)
    vys = sp.symbols(f"vy1:{n + 1}", real=True)
    return ImmutableMatrix(list(xs) + list(ys)), ImmutableMatrix(list(vxs) + list(vys))


def com_model(scene: Scene) -> ComModel:
    """Derive the COM-coordinate model of model.md section 4 for `scene`."""
    n = scene.n
    q, v = coordinates(scene)
    xs, ys = q[:n], q[n:]

    joints = [ImmutableMatrix([0, 0])]
    directions, normals = [], [ImmutableMatrix([0, 1])]
    for i, link in enumerate(scene.links):
        com = ImmutableMatrix([xs[i], ys[i]])
        e = com_frame_map(link) * (com - joints[i])
        directions.append(e)
        normals.append(S * e)
        joints.append(joints[i] + number(link.length) * e)
    fastenings = tuple(joints[j] + number(r) * normals[j]
                       for j, r in enumerate(scene.chain_fastenings()))

    constraints = ImmutableMatrix([
        (xs[i] - joints[i][0]) ** 2 + (ys[i] - joints[i][1]) ** 2
        - number(link.com ** 2 + link.com_normal ** 2)
        for i, link in enumerate(scene.links)])
    # The joints are affine in q, X_i = A_i q + b_i: with the selector E_i of x_i, the arm
    # x_i - X_i = B_i q - b_i, B_i = E_i - A_i, gives grad c_i = 2 (x_i - X_i)^T B_i and the
    # mass matrix below without differentiating the nested joint expressions.
    arm_maps = []
    for i in range(n):
        A, b = linear_coefficients(joints[i], q)
        selector = sp.zeros(2, 2 * n)
        selector[0, i] = selector[1, n + i] = 1
        arm_maps.append((ImmutableMatrix(selector), ImmutableMatrix(selector - A), b))
    constraint_jacobian = ImmutableMatrix.vstack(*[
        2 * (B * q - b).T * B for _, B, b in arm_maps])

    # T = sum 1/2 m_i |v_i|^2 + 1/2 J_i thetadot_i^2, thetadot_i^2 = |v_i - Xdot_i|^2 / |c_i|^2
    # on the constraint manifold, so T is a constant quadratic form in v, with Xdot_i = A_i v.
    mass_matrix = sp.zeros(2 * n, 2 * n)
    for (selector, B, _), link in zip(arm_maps, scene.links):
        mass_matrix += number(link.mass) * selector.T * selector
        if link.inertia != 0:
            mass_matrix += (number(link.inertia) / number(link.com ** 2 + link.com_normal ** 2)
                            * B.T * B)
    # Mirrored, so that M is symmetric to the last bit whatever order SymPy summed in.
    mass_matrix = ImmutableMatrix(2 * n, 2 * n, lambda i, j: mass_matrix[min(i, j), max(i, j)])
    kinetic_energy = (v.T * mass_matrix * v)[0, 0] / 2

    gravity = sp.Integer(0)
    if scene.gravity != 0:
        gravity = sp.Add(*(number(link.mass * scene.gravity) * ys[i]
                           for i, link in enumerate(scene.links)))
    springs = tuple(spring_terms(scene, spring, joints, normals) for spring in scene.springs)

    return ComModel(
        scene=scene, q=q, v=v, joints=tuple(joints), directions=tuple(directions),
        normals=tuple(normals[1:]), fastenings=fastenings, constraints=constraints,
        constraint_jacobian=ImmutableMatrix(constraint_jacobian),
        kinetic_energy=kinetic_energy, mass_matrix=mass_matrix, gravity_potential=gravity,
        springs=springs)


def joint_space_positions(scene: Scene, phi) -> tuple[list, list]:
    """COM positions from relative joint angles (model.md section 1), as SymPy expressions.

    Returns (xs, ys); used to start the schemes from (phi, phidot).
    """
    theta = sp.Integer(0)
    joint = ImmutableMatrix([0, 0])
    xs, ys = [], []
    for i, link in enumerate(scene.links):
        theta = theta + phi[i]
        e = ImmutableMatrix([sp.cos(theta), sp.sin(theta)])
        com = joint + number(link.com) * e + number(link.com_normal) * (S * e)
        xs.append(com[0])
        ys.append(com[1])
        joint = joint + number(link.length) * e
    return xs, ys
