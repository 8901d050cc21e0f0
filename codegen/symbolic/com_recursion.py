"""es's step in COM coordinates by recursions over the links (model.md 4.3 and 17).

In COM coordinates q = (x_1..x_n, y_1..y_n) the joints are linear in q but nested: with the
constant map R_k of the arm x_k - X_k to the direction e_k (com_frame_map),

    X_1 = 0,    X_{k+1} = X_k + L_k R_k (x_k - X_k),

so X_k depends on every COM before it, and a whole-chain expression of a spring segment, a row
of C(q) or of M has O(n) terms: the residual O(n^2). Here every linear map of q the step needs
is the recursion above, applied to positions or increments (definitions, O(n)), and every
transpose of one (the gradients: M dv, C(q_m)^T mu, the springs', the joint torques') is one
sweep from the tip back to the base that pulls point forces on the joints back to q:

    g_x[k] += (L_k R_k)^T G_{k+1},      G_k = g_X[k] + (I - L_k R_k)^T G_{k+1}.
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
import sympy as sp

from ..scene import Scene
from .com_model import com_frame_map, number
from .quadrature import gauss_legendre_nodes
from .recursion import (
    Definitions,
    LinkFrames,
    absolute_rates,
    add,
    angle_directions,
    cross,
    link_frames,
    perp,
    rates_from_momenta,
    scale,
    velocities,
)

ZERO = (sp.Integer(0), sp.Integer(0))


def apply(matrix, v):
    return (matrix[0, 0] * v[0] + matrix[0, 1] * v[1], matrix[1, 0] * v[0] + matrix[1, 1] * v[1])


def apply_transpose(matrix, v):
    return (matrix[0, 0] * v[0] + matrix[1, 0] * v[1], matrix[0, 1] * v[0] + matrix[1, 1] * v[1])


def sub(a, b):
    return (a[0] - b[0], a[1] - b[1])


class ComChain:
    """The joint recursion of a scene's COM model and its transpose."""

    def __init__(self, scene: Scene, defs: Definitions):
        self.scene = scene
        self.defs = defs
        self.maps = [com_frame_map(link) for link in scene.links]
        self.lengths = [number(link.length) for link in scene.links]

    def joints(self, coms, name: str) -> list:
        """X_1 .. X_{n+1} of the COM vectors `coms` (positions or increments: the map is
        linear, X_1 = 0), as definitions."""
        joint = ZERO
        out = [joint]
        for k, (com, R, L) in enumerate(zip(coms, self.maps, self.lengths), start=2):
            joint = self.defs.vector(f"{name}{k}", add(joint, scale(L, apply(R, sub(com, joint)))))
            out.append(joint)
        return out

    def segment(self, j: int, r0, r1, arms, increments: bool) -> tuple:
        """P_{j+1} - P_j, the segment of a spring across joint j, in the arms d_k = x_k - X_k
        (or their increments): L_j R_j d_j + r1 S R_j d_j - r0 S R_{j-1} d_{j-1}, local in
        d_{j-1} and d_j (P_1 = (0, r0) on the base: constant, so no increment)."""
        direction = apply(self.maps[j - 1], arms[j - 1])
        out = add(scale(self.lengths[j - 1], direction), scale(number(r1), perp(direction)))
        if j > 1:
            return sub(out, scale(number(r0), perp(apply(self.maps[j - 2], arms[j - 2]))))
        return out if increments else sub(out, (sp.Integer(0), number(r0)))

    def segment_transpose(self, j: int, r0, r1, force) -> list:
        """The arms' share of a force on segment j (the transpose of segment()): pairs
        (k, (d P_{j+1} - d P_j / d d_k)^T F), 1-based k."""
        turned = (force[1], -force[0])   # S^T F
        out = [(j, apply_transpose(self.maps[j - 1], add(scale(self.lengths[j - 1], force),
                                                         scale(number(r1), turned))))]
        if j > 1:
            out.append((j - 1, apply_transpose(self.maps[j - 2], scale(-number(r0), turned))))
        return out

    def sweep(self, direct, through, name: str) -> list:
        """The q-gradient sum_k E_k^T direct_k + B_k^T through_k (B_k q = x_k - X_k): one
        vector per link each (None for none). Returns one (x, y) gradient per link."""
        n = self.scene.n
        on_com = [list(d) if d is not None else [0, 0] for d in direct]
        on_joint = [[sp.Integer(0), sp.Integer(0)] for _ in range(n + 2)]
        for k, t in enumerate(through, start=1):
            if t is not None:
                on_com[k - 1] = [on_com[k - 1][0] + t[0], on_com[k - 1][1] + t[1]]
                on_joint[k] = [on_joint[k][0] - t[0], on_joint[k][1] - t[1]]
        carried = ZERO
        gradient = [None] * n
        for k in range(n, 0, -1):
            R, L = self.maps[k - 1], self.lengths[k - 1]
            incoming = add(tuple(on_joint[k + 1]), carried)
            incoming = self.defs.vector(f"{name}G{k + 1}", incoming)
            back = scale(L, apply_transpose(R, incoming))
            gradient[k - 1] = add(tuple(on_com[k - 1]), back)
            carried = sub(incoming, back)
        return gradient


class EsStep(NamedTuple):
    """The es residual's parts (model.md 4.4 and 17): F = (momentum, constraint_increments)."""

    momentum: list               # M dv + dt m g + B^T h, 2n entries in q's order
    constraint_increments: list  # c_k = C_k(q_m) (q_1 - q_0), n entries
    rates: list                  # joint rates at the mid-point, n
    arm_increments: list         # w = B dv, one defined (x, y) pair per link
    forces: list                 # h(w, mu), one (x, y) pair per link, on the arms
    # h with the springs' K-point average alone, without the exact gradient's correction: the
    # chord's Newton matrix is taken of it (model.md 18); None where it is h itself
    newton_forces: list | None = None


def es_step(scene: Scene, q0, v0, dv, mu, dt, quadrature: int, torques_of,
            defs: Definitions, gradient: str = "exact", control=None,
            chord: bool = False) -> EsStep:
    """The es residual (model.md 4.4) by recursions.

    Everything but the COM masses and gravity acts on the arms d_k = x_k - X_k = (B q)_k and is
    local in them: the inertias, the constraint impulses, the joint torques and every spring
    segment P_{j+1} - P_j (a function of d_{j-1} and d_j). So with w = B dv (the arms'
    velocity increments, defined here as symbols), the momentum balance is

        M dv + dt m g + B^T h(w, mu),

    h_k a function of w_{k-1}, w_k, w_{k+1} and of the w_k over each spring's span: the
    Newton Jacobian's factors dh/dw (banded), dh/dmu and dc/dw (block diagonal) are local,
    and the dense matrix M + B^T (dh/dw) B needs never be formed (chaingen_schur.h).
    torques_of(rates): the joint torques tau_i (inputs and damping) at the mid-point rates.
    control(arms0, arm_rates0, arm_steps, rates, joints0, com_rates0): a control law's joint
    torques (one per joint),
    which may depend on the whole step (chaingen.symbolic.schemes.control); they are added to
    torques_of's."""
    n = scene.n
    chain = ComChain(scene, defs)

    def vectors(values):
        return [(values[k], values[n + k]) for k in range(n)]

    q0v, v0v, dvv = vectors(q0), vectors(v0), vectors(dv)
    joints0 = chain.joints(q0v, "X")
    joint_rates0 = chain.joints(v0v, "V")
    velocity_steps = chain.joints(dvv, "dV")
    arms0 = [defs.vector(f"arm{k}", sub(x, X))
             for k, (x, X) in enumerate(zip(q0v, joints0), start=1)]
    arm_rates0 = [defs.vector(f"arm_rate{k}", sub(v, V))
                  for k, (v, V) in enumerate(zip(v0v, joint_rates0), start=1)]
    # Named even where B dv is dv itself (link 1): the Newton factors differentiate by w.
    w = []
    for k, (d, dV) in enumerate(zip(dvv, velocity_steps), start=1):
        pair = tuple(sp.Symbol(f"{defs.prefix}w{k}_{axis}", real=True) for axis in "xy")
        defs.items += list(zip(pair, sub(d, dV)))
        w.append(pair)
    half = sp.Rational(1, 2)
    # B dq = dt (B v_0 + w / 2); the arms at the mid-point a_k = B q_0 + B dq / 2; the arms'
    # rates there B v_m = B v_0 + w / 2.
    arm_rates_mid = [defs.vector(f"arm_rate_m{k}", add(r, scale(half, wk)))
                     for k, (r, wk) in enumerate(zip(arm_rates0, w), start=1)]
    arm_steps = [defs.vector(f"darm{k}", scale(dt, r))
                 for k, r in enumerate(arm_rates_mid, start=1)]
    arms = [defs.vector(f"arm_m{k}", add(a, scale(half, d)))
            for k, (a, d) in enumerate(zip(arms0, arm_steps), start=1)]
    constraint_increments = [2 * (a[0] * d[0] + a[1] * d[1]) for a, d in zip(arms, arm_steps)]

    forces = []
    for k, link in enumerate(scene.links):
        c2 = number(link.com ** 2 + link.com_normal ** 2)
        item = scale(-2 * mu[k], arms[k])
        if link.inertia:
            item = add(item, scale(number(link.inertia) / c2, w[k]))
        forces.append(item)

    # Joint rates at the mid-point: thetadot_k = a_k x (B v_m)_k / |c_k|^2.
    absolute = [defs.define(f"thetadot_m{k}", cross(a, r)
                            / number(link.com ** 2 + link.com_normal ** 2))
                for k, (a, r, link) in enumerate(zip(arms, arm_rates_mid, scene.links), start=1)]
    rates = [after - before for before, after in zip([sp.Integer(0)] + absolute[:-1], absolute)]
    torques = torques_of(rates)
    if control is not None:
        torques = [t + c for t, c in zip(torques, control(arms0, arm_rates0, arm_steps, rates,
                                                          joints0, v0v))]
    if any(t != 0 for t in torques):
        following = list(torques[1:]) + [sp.Integer(0)]
        for k, link in enumerate(scene.links):
            weight = torques[k] - following[k]
            if weight != 0:
                c2 = number(link.com ** 2 + link.com_normal ** 2)
                forces[k] = add(forces[k], scale(-dt * weight / c2, perp(arms[k])))

    # The chord's Newton matrix needs dh/dw only approximately (the root is the residual's):
    # where the springs' gradient is the exact one, h's Jacobian is taken of the K-point rule's
    # average alone, whose derivative differs from the corrected one's by the correction's,
    # O(|dd|^(2K)), and costs 0.6 of it (model.md 18).
    # Only for the arm solve (`chord`), whose factors take it.
    newton_forces = list(forces) if chord and scene.springs and gradient == "exact" else None
    for i, spring in enumerate(scene.springs):
        offsets = scene.spring_fastenings(spring)
        js = list(range(spring.first, spring.last + 1))
        starts = [defs.vector(f"spring{i}_d{j}", chain.segment(j, r0, r1, arms0, False))
                  for j, (r0, r1) in zip(js, zip(offsets[:-1], offsets[1:]))]
        changes = [defs.vector(f"spring{i}_dd{j}", chain.segment(j, r0, r1, arm_steps, True))
                   for j, (r0, r1) in zip(js, zip(offsets[:-1], offsets[1:]))]
        averaged = None
        if gradient == "chain":
            totals = chain_rule_spring_gradient(spring, i, js, starts, changes, defs)
        else:
            averaged = averaged_spring_gradient(spring, i, js, starts, changes, quadrature, defs)
            totals = averaged
            if gradient == "exact":
                totals = exact_spring_gradient(spring, i, js, starts, changes, quadrature, defs,
                                               averaged)
        for j, total, r0, r1 in zip(js, totals, offsets[:-1], offsets[1:]):
            total = defs.vector(f"spring{i}_f{j}", scale(dt, total))
            for k, pulled in chain.segment_transpose(j, r0, r1, total):
                forces[k - 1] = add(forces[k - 1], pulled)
        if newton_forces is not None:
            for j, total, r0, r1 in zip(js, averaged, offsets[:-1], offsets[1:]):
                total = defs.vector(f"newton_spring{i}_f{j}", scale(dt, total))
                for k, pulled in chain.segment_transpose(j, r0, r1, total):
                    newton_forces[k - 1] = add(newton_forces[k - 1], pulled)

    direct = []
    for k, link in enumerate(scene.links):
        m = number(link.mass)
        term = scale(m, dvv[k])
        if scene.gravity:
            term = add(term, (sp.Integer(0), dt * m * number(scene.gravity)))
        direct.append(term)
    gradient = chain.sweep(direct, forces, "sweep_")
    momentum = [g[0] for g in gradient] + [g[1] for g in gradient]
    return EsStep(momentum, constraint_increments, rates, w, forces, newton_forces)


def exact_spring_gradient(spring, i: int, js, starts, changes, quadrature: int,
                          defs: Definitions, averaged: list | None = None) -> list:
    """An exact discrete gradient of one spring's energy V = k/2 (sum_j s_j - S_0)^2 in its
    segment vectors d_j (model.md 4.3, the exact discrete gradient): the K-point average G_j of
    averaged_spring_gradient, corrected along the step (Gonzalez's construction, in the
    Euclidean metric of the segment vectors):

        G_j + r / max(sum_j |dd_j|^2, delta^2) dd_j,     r = V(1) - V(0) - sum_j G_j . dd_j,

    so that sum_j G_j . dd_j = V(1) - V(0) holds identically for every step larger than delta.
    r is the quadrature's error, O(k L s (|dd| / s)^(2K+1)) with s the shortest segment's
    length (the segment lengths' derivatives along the step scale like |dd|^m / s^(m-1)): the
    correction is of its size and the trajectory that of the K-point rule.
    delta = c_K min_j (s_j(0) + s_j(1)) / 2 with c_K = eps^(1/(2K+1)) is the step below which
    every segment moves by less than c_K of its length, so that the quadrature is exact to
    round-off of the energy anyway; there the correction fades out as |dd|, smoothly, with
    derivatives of the K-point average's size (at rest, the Jacobians a controller takes of the
    step would otherwise be round-off divided by |dd|^2). V(1) - V(0) is taken without
    cancellation, k/2 (L_0 + L_1 - 2 S_0) (L_1 - L_0) with
    s_j(1) - s_j(0) = (2 d_j(0) + dd_j) . dd_j / (s_j(0) + s_j(1)): its round-off is
    eps |G| |dd|, not eps V. One (x, y) per segment. averaged: G_j, when defined already."""
    totals = averaged or averaged_spring_gradient(spring, i, js, starts, changes, quadrature,
                                                  defs)
    sums, increments, projected, squared = [], [], [], []
    for j, start, change, total in zip(js, starts, changes, totals):
        end = add(start, change)
        s0 = defs.define(f"spring{i}_s{j}_start", sp.sqrt(start[0] ** 2 + start[1] ** 2))
        s1 = defs.define(f"spring{i}_s{j}_end", sp.sqrt(end[0] ** 2 + end[1] ** 2))
        sums.append(s0 + s1)
        increments.append(((2 * start[0] + change[0]) * change[0]
                           + (2 * start[1] + change[1]) * change[1]) / (s0 + s1))
        projected.append(total[0] * change[0] + total[1] * change[1])
        squared.append(change[0] ** 2 + change[1] ** 2)
    length_sum = defs.define(f"spring{i}_lengths", sp.Add(*sums))
    energy_change = defs.define(
        f"spring{i}_dV", number(spring.stiffness) / 2
        * (length_sum - 2 * number(spring.rest_length)) * sp.Add(*increments))
    shortest = sp.Min(*sums) if len(sums) > 1 else sums[0]
    smallest = sp.Float(exact_gradient_scale(quadrature) ** 2 / 4)
    ratio = defs.define(f"spring{i}_correction", (energy_change - sp.Add(*projected))
                        / sp.Max(sp.Add(*squared), smallest * shortest ** 2))
    return [add(total, scale(ratio, change)) for total, change in zip(totals, changes)]


def chain_rule_spring_gradient(spring, i: int, js, starts, changes, defs: Definitions) -> list:
    """The chain rule's discrete gradient of one spring's energy V = k/2 (L - S_0)^2,
    L = sum_j s_j, s_j = |d_j| (model.md 4.3): the exact difference quotient of V in L times
    that of each |d_j| in d_j,

        G_j = k/2 (L_0 + L_1 - 2 S_0) (d_j(0) + d_j(1)) / (s_j(0) + s_j(1)),

    so that sum_j G_j . dd_j = k/2 (L_0 + L_1 - 2 S_0) (L_1 - L_0) = V(1) - V(0) identically
    (the mean of (d_0 + d_1) / (s_0 + s_1) with dd = d_1 - d_0 is s_1 - s_0). No quadrature:
    two segment lengths per segment. Symmetric in the step's ends, second order."""
    sums, means = [], []
    for j, start, change in zip(js, starts, changes):
        end = add(start, change)
        s0 = defs.define(f"spring{i}_s{j}_start", sp.sqrt(start[0] ** 2 + start[1] ** 2))
        s1 = defs.define(f"spring{i}_s{j}_end", sp.sqrt(end[0] ** 2 + end[1] ** 2))
        total = defs.define(f"spring{i}_s{j}_sum", s0 + s1)
        sums.append(total)
        means.append((start[0] + end[0], start[1] + end[1], total))
    factor = defs.define(f"spring{i}_chain", number(spring.stiffness) / 2
                         * (sp.Add(*sums) - 2 * number(spring.rest_length)))
    return [(factor * x / total, factor * y / total) for x, y, total in means]


def exact_gradient_scale(quadrature: int) -> float:
    """c_K = eps^(1/(2K+1)): a step of the spring's segments below c_K times their length has a
    K-point quadrature error below the round-off of its energy (exact_spring_gradient)."""
    return float(np.finfo(float).eps) ** (1.0 / (2 * quadrature + 1))


def averaged_spring_gradient(spring, i: int, js, starts, changes, quadrature: int,
                             defs: Definitions) -> list:
    """The average of one spring's gradient in its segment vectors on the step's segment
    d_j(tau) = d_j(0) + tau dd_j, by the K-point Gauss-Legendre rule (model.md 4, the thesis's
    quadrature): its energy error scales like dt^(2K). One list of (x, y) per segment."""
    nodes, weights = gauss_legendre_nodes(quadrature)
    totals = [ZERO for _ in js]
    for g, (tau, weight) in enumerate(zip(nodes, weights)):
        lengths, node_vectors = [], []
        for j, start, change in zip(js, starts, changes):
            point = defs.vector(f"spring{i}_d{j}_node{g}",
                                add(start, scale(sp.Float(tau), change)))
            lengths.append(defs.define(f"spring{i}_s{j}_node{g}",
                                       sp.sqrt(point[0] ** 2 + point[1] ** 2)))
            node_vectors.append(point)
        stretch = sp.Add(*lengths) - number(spring.rest_length)
        force = defs.define(f"spring{i}_force{g}", sp.Float(weight)
                            * number(spring.stiffness) * stretch)
        for s, (length, point) in enumerate(zip(lengths, node_vectors)):
            share = defs.define(f"spring{i}_scale{js[s]}_node{g}", force / length)
            totals[s] = add(totals[s], scale(share, point))
    return totals


def state_quantities(scene: Scene, q, v, defs: Definitions, projected: bool = False) -> dict:
    """The state-only expressions of es by the same recursions: relative joint angles and
    rates, H = T + V, the constraint residuals and every spring segment vector; with
    `projected`, also the joint rates of v's M-orthogonal projection onto C(q) v = 0
    ("projected_rates", see projected_rates).

    T = sum_k 1/2 m_k |v_k|^2 + J_k / (2 |c_k|^2) |v_k - V_k|^2 (model.md 4.1, the constant M
    of COM coordinates), V = gravity + springs; c_k = |x_k - X_k|^2 - |c_k|^2."""
    n = scene.n
    chain = ComChain(scene, defs)
    coms = [(q[k], q[n + k]) for k in range(n)]
    com_rates = [(v[k], v[n + k]) for k in range(n)]
    joints = chain.joints(coms, "X")
    joint_velocities = chain.joints(com_rates, "V")
    arms = [defs.vector(f"arm{k}", sub(x, X))
            for k, (x, X) in enumerate(zip(coms, joints), start=1)]
    directions = [(sp.Integer(1), sp.Integer(0))] + [
        defs.vector(f"e{k}", apply(R, a)) for k, (R, a) in enumerate(zip(chain.maps, arms),
                                                                     start=1)]
    angles = [sp.atan2(cross(a, b), a[0] * b[0] + a[1] * b[1])
              for a, b in zip(directions[:-1], directions[1:])]
    kinetic = sp.Integer(0)
    absolute = []
    constraints = []
    for k, link in enumerate(scene.links):
        c2 = number(link.com ** 2 + link.com_normal ** 2)
        relative = defs.vector(f"arm_rate{k + 1}", sub(com_rates[k], joint_velocities[k]))
        absolute.append(defs.define(f"thetadot{k + 1}", cross(arms[k], relative) / c2))
        kinetic += number(link.mass) * (com_rates[k][0] ** 2 + com_rates[k][1] ** 2) / 2
        if link.inertia:
            kinetic += number(link.inertia) / (2 * c2) * (relative[0] ** 2 + relative[1] ** 2)
        constraints.append(arms[k][0] ** 2 + arms[k][1] ** 2 - c2)
    rates = [after - before for before, after in zip([sp.Integer(0)] + absolute[:-1], absolute)]
    potential = sp.Integer(0)
    if scene.gravity:
        potential = sp.Add(*(number(link.mass * scene.gravity) * com[1]
                             for link, com in zip(scene.links, coms)))
    segments = []
    for i, spring in enumerate(scene.springs):
        offsets = scene.spring_fastenings(spring)
        lengths = []
        for j, (r0, r1) in zip(range(spring.first, spring.last + 1),
                               zip(offsets[:-1], offsets[1:])):
            d = defs.vector(f"spring{i}_d{j}", chain.segment(j, r0, r1, arms, False))
            segments += list(d)
            lengths.append(sp.sqrt(d[0] ** 2 + d[1] ** 2))
        stretch = sp.Add(*lengths) - number(spring.rest_length)
        potential += number(spring.stiffness) / 2 * stretch ** 2
    out = dict(angles=angles, rates=rates, energy=kinetic + potential,
               constraints=constraints, segment_vectors=segments)
    if projected:
        out["projected_rates"] = projected_rates(scene, joints, arms, directions[1:], com_rates,
                                                 absolute, defs)
    return out


def projected_rates(scene: Scene, joints, arms, directions, com_rates, absolute,
                    defs: Definitions) -> list:
    """The joint rates w of the M-orthogonal projection of the COM velocities v onto
    C(q) v = 0 (es's composed steps, model.md 14), in O(n): the projection is J w with
    w = argmin (v - J w)^T M (v - J w), J = dv/dw at q, so (J^T M J) w = J^T M v. J^T M J is
    the joint-space mass matrix of the chain at q, and (J^T M v)_k the angular momentum about
    the joint X_k of links k..n moving with v: m_j (x_j - X_k) x v_j + J_j thetadot_j summed,
    thetadot_j = (x_j - X_j) x (v_j - V_j) / |c_j|^2 (the inertia term of T). Both by the
    recursions of vi (model.md 17): the momenta from the tip, then the rates by the
    articulated-body recursion. Equal to the KKT solve [[M, C^T], [C, 0]] (v_t, lambda) =
    (M v, 0) to round-off (tests/test_es_projection.py), which is dense, O(n^3)."""
    n = scene.n
    vectors = [sub(joints[k + 1], joints[k]) for k in range(n)]
    frames = LinkFrames(tuple(directions), tuple(perp(e) for e in directions), tuple(arms),
                        tuple(vectors))
    linear, angular, momenta = ZERO, sp.Integer(0), []
    for k in range(n - 1, -1, -1):
        mass = number(scene.links[k].mass)
        angular = defs.define(f"proj_H{k + 1}", number(scene.links[k].inertia) * absolute[k]
                              + mass * cross(arms[k], com_rates[k]) + angular
                              + cross(vectors[k], linear))
        linear = defs.vector(f"proj_P{k + 1}", add(scale(mass, com_rates[k]), linear))
        momenta.append(angular)
    return rates_from_momenta(scene, frames, momenta[::-1], defs, tag="proj_")


def joint_space_start(scene: Scene, phi, phidot, defs: Definitions) -> list:
    """x(phi, phidot) = (q, v): the COM positions and velocities of a joint-space state, by the
    recursions of chaingen.symbolic.recursion (model.md 1)."""
    frames = link_frames(scene, angle_directions(defs, phi))
    joint = ZERO
    coms = []
    for k in range(scene.n):
        coms.append(add(joint, frames.arms[k]))
        if k + 1 < scene.n:
            joint = defs.vector(f"X{k + 2}", add(joint, frames.vectors[k]))
    com_velocities, _ = velocities(scene, frames, absolute_rates(defs, phidot), defs)
    return ([c[0] for c in coms] + [c[1] for c in coms] + [v[0] for v in com_velocities]
            + [v[1] for v in com_velocities])
