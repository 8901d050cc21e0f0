"""The chain in joint space by recursions over its links (model.md sections 5, 6 and 17).

A serial chain's joint-space quantities are sums over the links outboard of a joint: the joint
torque of an acceleration, the momentum conjugate to a joint rate, the solution of M w = p. Written
as whole-chain expressions they have O(n^2) terms per entry (M(phi) is dense, each entry a sum
over links), and SymPy's derivatives of them O(n^3). Written as recursions from the base to the
tip and back, each link adds a handful of small expressions, named once as intermediate symbols
(DiscreteScheme's definitions): O(n) in all, and code generation differentiates that sequence
(CasADi's algorithmic differentiation) instead of SymPy expanding it.

Conventions (model.md 1): e_k the absolute direction of link k, n_k = S e_k, X_k its proximal
joint, c_k = X_k + r_k its COM with r_k = a_k e_k + b_k n_k, X_{k+1} = X_k + l_k with l_k = L_k e_k,
Omega_k = w_1 + ... + w_k its absolute rate. Vectors are (x, y) pairs of expressions.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import sympy as sp

from ..scene import Scene
from .com_model import number

Vector = tuple


def add(*vectors) -> Vector:
    return (sp.Add(*(v[0] for v in vectors)), sp.Add(*(v[1] for v in vectors)))


def scale(factor, v) -> Vector:
    return (factor * v[0], factor * v[1])


def cross(a, b) -> sp.Expr:
    """z-component of the planar cross product a x b."""
    return a[0] * b[1] - a[1] * b[0]


def perp(v) -> Vector:
    """S v: v turned by +90 degrees."""
    return (-v[1], v[0])


def complex_product(a, b) -> Vector:
    """The planar rotation of a by the unit vector b (complex multiplication)."""
    return (a[0] * b[0] - a[1] * b[1], a[0] * b[1] + a[1] * b[0])


@dataclass
class Definitions:
    """Intermediate quantities as (symbol, expression) pairs in order of definition.

    `define(name, expr)` names expr by a new symbol (the prefix and name) and returns the symbol;
    a number or a symbol is returned as it is. Later expressions use the symbols, so that a chain's
    recursion stays a sequence of small expressions."""

    prefix: str
    items: list = field(default_factory=list)

    def define(self, name: str, expr) -> sp.Expr:
        expr = sp.sympify(expr)
        if expr.is_Atom:
            return expr
        symbol = sp.Symbol(f"{self.prefix}{name}", real=True)
        self.items.append((symbol, expr))
        return symbol

    def vector(self, name: str, v) -> Vector:
        return (self.define(f"{name}_x", v[0]), self.define(f"{name}_y", v[1]))


@dataclass(frozen=True)
class LinkFrames:
    """Per link k: its direction e_k, normal n_k, COM arm r_k and link vector l_k (world frame)."""

    directions: tuple
    normals: tuple
    arms: tuple
    vectors: tuple


def link_frames(scene: Scene, directions) -> LinkFrames:
    """The frames of the links from their absolute directions (symbols of a Definitions)."""
    normals = tuple(perp(e) for e in directions)
    arms = tuple(add(scale(number(link.com), e), scale(number(link.com_normal), n))
                 for link, e, n in zip(scene.links, directions, normals))
    vectors = tuple(scale(number(link.length), e) for link, e in zip(scene.links, directions))
    return LinkFrames(tuple(directions), normals, arms, vectors)


def angle_directions(defs: Definitions, angles, name: str = "e", tag: str = "") -> list:
    """e_k = (cos theta_k, sin theta_k), theta_k = phi_1 + ... + phi_k, as definitions (tag:
    a prefix of their names, for more than one set in one Definitions)."""
    directions, theta = [], sp.Integer(0)
    for k, phi in enumerate(angles, start=1):
        theta = defs.define(f"{tag}theta{k}", theta + phi)
        directions.append(defs.vector(f"{tag}{name}{k}", (sp.cos(theta), sp.sin(theta))))
    return directions


def attitude_directions(defs: Definitions, attitudes, name: str = "e") -> list:
    """e_k = q_1 q_2 ... q_k (complex products of unit attitude vectors, model.md 5)."""
    directions, e = [], None
    for k, q in enumerate(attitudes, start=1):
        e = tuple(q) if e is None else defs.vector(f"{name}{k}", complex_product(e, q))
        directions.append(e)
    return directions


def absolute_rates(defs: Definitions, rates, name: str = "Omega") -> list:
    """Omega_k = w_1 + ... + w_k."""
    total, out = sp.Integer(0), []
    for k, w in enumerate(rates, start=1):
        total = defs.define(f"{name}{k}", total + w)
        out.append(total)
    return out


def segment_vectors(scene: Scene, frames: LinkFrames) -> list:
    """For every spring, segment by segment: (joint j, P_{j+1} - X_j, P_{j+1} - P_j).

    Fastening P_j sits at X_j + r n_{j-1} on link j-1 (n_0 = (0, 1), the base), so segment j
    (P_j -> P_{j+1}) turns with phi_j alone: d_j = L_j e_j + r_{j+1} n_j - r_j n_{j-1}."""
    out = []
    for spring in scene.springs:
        offsets = scene.spring_fastenings(spring)
        segments = []
        for j, (r0, r1) in zip(range(spring.first, spring.last + 1),
                               zip(offsets[:-1], offsets[1:])):
            previous = (sp.Integer(0), sp.Integer(1)) if j == 1 else frames.normals[j - 2]
            arm = add(frames.vectors[j - 1], scale(number(r1), frames.normals[j - 1]))
            segments.append((j, arm, add(arm, scale(-number(r0), previous))))
        out.append(segments)
    return out


def spring_gradient(scene: Scene, frames: LinkFrames, defs: Definitions, tag: str = "") -> tuple:
    """dV_springs/dphi (n entries) and V_springs, by definitions.

    With the stretch e = sum_j s_j - S_0 and the force k e, ds_j/dphi_j = (P_{j+1} - X_j) x d_j
    / s_j and ds_j/dphi_i = 0 for i != j: segment j turns with phi_j alone (segment_vectors)."""
    gradient = [sp.Integer(0)] * scene.n
    energy = sp.Integer(0)
    for i, (spring, segments) in enumerate(zip(scene.springs, segment_vectors(scene, frames))):
        lengths, named = [], []
        for j, arm, d in segments:
            d = defs.vector(f"{tag}spring{i}_d{j}", d)
            length = defs.define(f"{tag}spring{i}_s{j}", sp.sqrt(d[0] ** 2 + d[1] ** 2))
            lengths.append(length)
            named.append((j, arm, d, length))
        stretch = defs.define(f"{tag}spring{i}_e", sp.Add(*lengths) - number(spring.rest_length))
        force = defs.define(f"{tag}spring{i}_f", number(spring.stiffness) * stretch)
        energy += force * stretch / 2
        for j, arm, d, length in named:
            gradient[j - 1] += force * cross(arm, d) / length
    return gradient, energy


def outboard_masses(scene: Scene) -> list:
    """m_k + ... + m_n for every link k, and 0 after the last."""
    totals = [sp.Integer(0)]
    for link in reversed(scene.links):
        totals.append(totals[-1] + number(link.mass))
    return totals[::-1]


def gravity_gradient(scene: Scene, frames: LinkFrames, defs: Definitions, tag: str = "") -> list:
    """dV_gravity/dphi_k = g sum_{j >= k} m_j (c_j - X_k)_x, by a recursion from the tip."""
    if not scene.gravity:
        return [sp.Integer(0)] * scene.n
    masses = outboard_masses(scene)
    moments, moment = [], sp.Integer(0)
    for k in range(scene.n - 1, -1, -1):
        link = scene.links[k]
        moment = defs.define(f"{tag}gmoment{k + 1}", number(link.mass) * frames.arms[k][0]
                             + moment + masses[k + 1] * frames.vectors[k][0])
        moments.append(number(scene.gravity) * moment)
    return moments[::-1]


def gravity_potential(scene: Scene, frames: LinkFrames, defs: Definitions,
                      tag: str = "") -> sp.Expr:
    """V_gravity = g sum_k m_k y(c_k), the joint heights by a recursion from the base."""
    if not scene.gravity:
        return sp.Integer(0)
    height, total = sp.Integer(0), sp.Integer(0)
    for k, link in enumerate(scene.links):
        total += number(link.mass) * (height + frames.arms[k][1])
        if k + 1 < scene.n:
            height = defs.define(f"{tag}height{k + 2}", height + frames.vectors[k][1])
    return number(scene.gravity) * total


def velocities(scene: Scene, frames: LinkFrames, rates, defs: Definitions,
               tag: str = "") -> tuple[list, list]:
    """(COM velocities v_k, proximal joint velocities V_k) from the absolute rates Omega_k:
    V_1 = 0, v_k = V_k + Omega_k S r_k, V_{k+1} = V_k + Omega_k S l_k."""
    joint = (sp.Integer(0), sp.Integer(0))
    coms, joints = [], []
    for k in range(scene.n):
        joints.append(joint)
        coms.append(defs.vector(f"{tag}v{k + 1}", add(joint, scale(rates[k],
                                                                    perp(frames.arms[k])))))
        if k + 1 < scene.n:
            joint = defs.vector(f"{tag}V{k + 2}", add(joint, scale(rates[k],
                                                                   perp(frames.vectors[k]))))
    return coms, joints


def kinetic_energy(scene: Scene, rates, com_velocities) -> sp.Expr:
    """T = sum_k 1/2 m_k |v_k|^2 + 1/2 J_k Omega_k^2."""
    total = sp.Integer(0)
    for link, v, omega in zip(scene.links, com_velocities, rates):
        total += number(link.mass) * (v[0] ** 2 + v[1] ** 2) / 2
        if link.inertia:
            total += number(link.inertia) * omega ** 2 / 2
    return total


def momenta(scene: Scene, frames: LinkFrames, rates, defs: Definitions,
            tag: str = "") -> tuple[list, list]:
    """(p, dT/dphi) at fixed joint rates, by recursions (model.md 17).

    p_k = dT/dw_k is H_k, the angular momentum of links k..n about X_k; with their linear
    momentum P_k and the joint velocity V_k, dT/dphi_k = P_k x V_k. From the tip:
    P_k = m_k v_k + P_{k+1}, H_k = J_k Omega_k + m_k r_k x v_k + H_{k+1} + l_k x P_{k+1}."""
    coms, joints = velocities(scene, frames, rates, defs, tag)
    linear = (sp.Integer(0), sp.Integer(0))
    angular = sp.Integer(0)
    p, dT = [], []
    for k in range(scene.n - 1, -1, -1):
        link = scene.links[k]
        mass = number(link.mass)
        angular = defs.define(f"{tag}H{k + 1}", number(link.inertia) * rates[k]
                              + mass * cross(frames.arms[k], coms[k]) + angular
                              + cross(frames.vectors[k], linear))
        linear = defs.vector(f"{tag}P{k + 1}", add(scale(mass, coms[k]), linear))
        p.append(angular)
        dT.append(cross(linear, joints[k]))
    return p[::-1], dT[::-1]


def inverse_dynamics(scene: Scene, frames: LinkFrames, rates, increments, dt,
                     defs: Definitions, tag: str = "") -> list:
    """dt (M(phi) wdot + cor(phi, w) + grad V_gravity) with dt wdot = dw, by Newton-Euler.

    rates: the absolute rates Omega_k; increments: A_k = dw_1 + ... + dw_k, dt times the
    absolute angular accelerations. Forward, dt times the point accelerations, with gravity as
    an upward acceleration of the base: a(X_1) = (0, dt g), a(c_k) = a(X_k) + A_k S r_k
    - dt Omega_k^2 r_k, a(X_{k+1}) = a(X_k) + A_k S l_k - dt Omega_k^2 l_k. Backward, the force
    F_k on links k..n and the moment N_k about X_k: F_k = m_k a(c_k) + F_{k+1}, N_k = J_k A_k
    + r_k x m_k a(c_k) + N_{k+1} + l_k x F_{k+1}, and N_k is entry k (model.md 17)."""
    joint = (sp.Integer(0), dt * number(scene.gravity)) if scene.gravity else (
        sp.Integer(0), sp.Integer(0))
    accelerations = []
    for k in range(scene.n):
        square = defs.define(f"{tag}Omega_sq{k + 1}", dt * rates[k] ** 2)
        accelerations.append(defs.vector(
            f"{tag}a{k + 1}", add(joint, scale(increments[k], perp(frames.arms[k])),
                                  scale(-square, frames.arms[k]))))
        if k + 1 < scene.n:
            joint = defs.vector(f"{tag}aX{k + 2}", add(
                joint, scale(increments[k], perp(frames.vectors[k])),
                scale(-square, frames.vectors[k])))
    force = (sp.Integer(0), sp.Integer(0))
    moment = sp.Integer(0)
    moments = []
    for k in range(scene.n - 1, -1, -1):
        link = scene.links[k]
        inertial = scale(number(link.mass), accelerations[k])
        moment = defs.define(f"{tag}N{k + 1}", number(link.inertia) * increments[k]
                             + cross(frames.arms[k], inertial) + moment
                             + cross(frames.vectors[k], force))
        force = defs.vector(f"{tag}F{k + 1}", add(inertial, force))
        moments.append(moment)
    return moments[::-1]


def spatial_inertia(link, arm) -> list:
    """The rigid link's momentum (H about X_k, P) per spatial velocity (Omega, V of X_k):
    H = (J + m |r|^2) Omega + m r x V, P = m (V + Omega S r); symmetric 3 x 3, rows listed."""
    m = number(link.mass)
    J = number(link.inertia)
    return [[J + m * (arm[0] ** 2 + arm[1] ** 2), -m * arm[1], m * arm[0]],
            [-m * arm[1], m, sp.Integer(0)],
            [m * arm[0], sp.Integer(0), m]]


def rates_from_momenta(scene: Scene, frames: LinkFrames, momenta_, defs: Definitions,
                       tag: str = "") -> list:
    """The joint rates w with M w = p, by the articulated-body recursion (model.md 17), O(n).

    The links k..n whose joints k+1..n carry the momenta p_{k+1..n} have the momentum
    I_k nu_k + b_k about X_k for a spatial velocity nu_k = (Omega_k, V(X_k)) of link k. With
    T_k = [[1, 0, 0], [-l_y, 1, 0], [l_x, 0, 1]] (the velocity of link k at X_{k+1}) and
    u = I_{k+1}[:, 0], D = I_{k+1}[0, 0]: I_k = I_body + T^T (I_{k+1} - u u^T / D) T,
    b_k = T^T (b_{k+1} + u (p_{k+1} - b_{k+1}[0]) / D). Then from the base, nu_1 = (w_1, 0, 0)
    with w_1 = (p_1 - b_1[0]) / I_1[0, 0], and nu_{k+1} = T_k nu_k + (w_{k+1}, 0, 0) with
    w_{k+1} = (p_{k+1} - u^T T_k nu_k - b_{k+1}[0]) / D."""
    n = scene.n
    inertias, biases = [None] * n, [None] * n

    def transform(k):
        lx, ly = frames.vectors[k]
        return [[1, 0, 0], [-ly, 1, 0], [lx, 0, 1]]

    def matmul(a, b):
        return [[sp.Add(*(a[i][m] * b[m][j] for m in range(3))) for j in range(3)]
                for i in range(3)]

    def transpose(a):
        return [[a[j][i] for j in range(3)] for i in range(3)]

    def named(name, matrix):
        out = [[None] * 3 for _ in range(3)]
        for i in range(3):
            for j in range(i, 3):
                out[i][j] = out[j][i] = defs.define(f"{name}_{i}{j}", matrix[i][j])
        return out

    for k in range(n - 1, -1, -1):
        body = spatial_inertia(scene.links[k], frames.arms[k])
        if k == n - 1:
            inertias[k] = named(f"{tag}IA{k + 1}", body)
            biases[k] = [sp.Integer(0)] * 3
            continue
        child, bias = inertias[k + 1], biases[k + 1]
        u = [child[i][0] for i in range(3)]
        D = child[0][0]
        reduced = [[child[i][j] - u[i] * u[j] / D for j in range(3)] for i in range(3)]
        T = transform(k)
        shifted = matmul(transpose(T), matmul(reduced, T))
        inertias[k] = named(f"{tag}IA{k + 1}",
                            [[body[i][j] + shifted[i][j] for j in range(3)] for i in range(3)])
        share = defs.define(f"{tag}share{k + 2}", (momenta_[k + 1] - bias[0]) / D)
        carried = [bias[i] + u[i] * share for i in range(3)]
        biases[k] = [defs.define(f"{tag}b{k + 1}_{i}",
                                 sp.Add(*(T[m][i] * carried[m] for m in range(3))))
                     for i in range(3)]
    rates = [defs.define(f"{tag}w1", (momenta_[0] - biases[0][0]) / inertias[0][0][0])]
    nu = (rates[0], sp.Integer(0), sp.Integer(0))
    for k in range(n - 1):
        lx, ly = frames.vectors[k]
        moved = (nu[0], nu[1] - ly * nu[0], nu[2] + lx * nu[0])
        child = inertias[k + 1]
        w = defs.define(f"{tag}w{k + 2}", (momenta_[k + 1] - sum(child[i][0] * moved[i]
                                                               for i in range(3))
                                           - biases[k + 1][0]) / child[0][0])
        rates.append(w)
        nu = tuple(defs.define(f"{tag}nu{k + 2}_{i}", value)
                   for i, value in enumerate((moved[0] + w, moved[1], moved[2])))
    return rates


def segment_vector_entries(scene: Scene, frames: LinkFrames) -> sp.ImmutableMatrix:
    """(dx, dy) of every segment of every spring, spring by spring (DiscreteScheme's
    segment_vectors)."""
    return sp.ImmutableMatrix([c for segments in segment_vectors(scene, frames)
                               for _, _, d in segments for c in d])
