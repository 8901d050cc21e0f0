"""The discrete null space method with nodal reparametrisation for the spatial es step
(Betsch and Leyendecker 2006; docs/model.md 4.8), and the director coordinates' links it works
on: a link's centre of mass and directors in a vector of 12n (Link), the constant mass matrix
(mass_times), the nodal reparametrisation q_1 = q_0 + dq(q_0, w) by exact rotations
(turned_frames), the null-space projection P(q)^T F as moments about the joints (joint_moments,
joint_twists), the projected joint rates of a composed step (projected_rates) and Newton's
matrix by composite rigid bodies (newton_matrix). chaingen.symbolic.schemes.spatial_es builds
the step from them.
"""
from __future__ import annotations

import numpy as np
import sympy as sp
from sympy import ImmutableMatrix

from ...spatial.dynamics import rpy_matrix
from ...spatial.values import SpatialScene
from .. import spatial_recursion as vectors
from ..com_model import number
from ..recursion import Definitions
from ..spatial_com_model import euler_tensor

add, scale, cross, dot, constant = (vectors.add, vectors.scale, vectors.cross, vectors.dot,
                                    vectors.constant)


class Link:
    """One link's coordinates in a vector of 12n: x and the directors as 3-tuples (link 0,
    the base: x = 0 and R = 1, constants)."""

    def __init__(self, values, i: int):
        if i == 0:
            self.x = (sp.Integer(0),) * 3
            self.d = tuple(tuple(sp.Integer(int(r == c)) for r in range(3)) for c in range(3))
        else:
            block = list(values[12 * (i - 1):12 * i])
            self.x = tuple(block[:3])
            self.d = tuple(tuple(block[3 * (a + 1):3 * (a + 2)]) for a in range(3))

    def turn(self, local) -> tuple:
        """R local = sum_a local_a d_a: a vector fixed on the link, in the world."""
        return add(*(scale(number(c), d) for c, d in zip(local, self.d)))

    def point(self, local, com) -> tuple:
        """x + R (local - com): a point fixed on the link, linear in q."""
        return add(self.x, self.turn(np.asarray(local, dtype=float) - com))


def coms(scene: SpatialScene) -> list[np.ndarray]:
    """c_0 = 0 for the base, then the links' COMs in their frames."""
    return [np.zeros(3)] + [np.asarray(link.com, dtype=float) for link in scene.links]


def mass_times(scene: SpatialScene, v) -> list:
    """M v, M = diag(m_i 1, E_i (x) 1) per link, E_i the Euler tensor (spatial_com_model)."""
    out = []
    for i, link in enumerate(scene.links, start=1):
        rate = Link(v, i)
        euler = constant(euler_tensor(link.inertia_matrix()))
        out += list(scale(number(link.mass), rate.x))
        for a in range(3):
            out += list(add(*(scale(euler[a][b], rate.d[b]) for b in range(3)
                              if euler[a][b] != 0)))
    return out


def turned_frames(scene: SpatialScene, q0, increments, defs: Definitions) -> list:
    """dq = F(q_0, w) - q_0, the nodal reparametrisation (docs/model.md 4.8): link i turned
    by Q_i = Q_{i-1} Rot(n_i0, theta_i), n_i0 = R_{i-1,0} J_i a_i joint i's axis at the step's
    start, theta_i = 2 atan(|n_i0| w_i / 2) (w_i = 2 tan(theta_i / 2) for a unit axis). Q_i is
    the rotation of the quaternion p_i = p_{i-1} (1, w_i n_i0 / 2) taken with its norm, so
    orthogonal to round-off for any w and n_i0, with no sine, cosine or square root:
    Q - 1 = 2 (p_v p_v^T - |p_v|^2 1 + p_w [p_v]) / |p|^2, computed as the difference (no
    cancellation against 1). Then

        dd_ia = (Q_i - 1) d_ia0,    dx_i = dx_{i-1} + dR_{i-1} (o_i - c_{i-1}) + dR_i c_i,

    so the directors keep the start's orthonormality and the joints the start's errors
    (carried, not grown), whatever w. dq, not q_1: the residual's M (v_1 - v_0) takes
    v_m = dq / dt, and q_1 - q_0 recomputed from a rounded q_1 would carry eps |q| / dt into
    it, 1e-13 of |v| at dt = 1 ms, which the energy then shows."""
    centres = coms(scene)
    quaternion = (sp.Integer(1),) + (sp.Integer(0),) * 3
    shift = (sp.Integer(0),) * 3        # dx_{i-1}
    turned_parent = None                # dR_{i-1} as Link-like directors; None for the base
    dq = []
    for i, (link, w) in enumerate(zip(scene.links, increments), start=1):
        own, parent = Link(q0, i), Link(q0, i - 1)
        axis = parent.turn(rpy_matrix(link.joint.rpy) @ np.asarray(link.joint.axis))
        if i > 1:
            axis = vectors.define_vector(defs, f"n0_{i}", axis)
        half = scale(w / 2, axis)
        pw, pv = quaternion[0], quaternion[1:]
        quaternion = (defs.define(f"p{i}_w", pw - dot(pv, half)),
                      *vectors.define_vector(defs, f"p{i}", add(scale(pw, half), pv,
                                                                cross(pv, half))))
        pw, pv = quaternion[0], quaternion[1:]
        square = defs.define(f"pvv{i}", dot(pv, pv))
        twice = defs.define(f"pn{i}", 2 / (pw ** 2 + square))
        scaled = vectors.define_vector(defs, f"ps{i}", scale(twice, pv))
        rows = [[scaled[r] * pv[c] - (square * twice if r == c else 0)
                 + (0 if r == c else (1 if (c - r) % 3 == 2 else -1) * scaled[3 - r - c] * pw)
                 for c in range(3)] for r in range(3)]
        rows = [[defs.define(f"U{i}_{r}{c}", rows[r][c]) for c in range(3)] for r in range(3)]
        turns = [vectors.define_vector(defs, f"dd{i}_{a + 1}", vectors.apply(rows, d))
                 for a, d in enumerate(own.d)]
        turned = Link([], 0)
        turned.d = tuple(turns)
        arm = np.asarray(link.joint.xyz, dtype=float) - centres[i - 1]
        joint = shift if turned_parent is None else add(shift, turned_parent.turn(arm))
        shift = vectors.define_vector(defs, f"dx{i}", add(joint, turned.turn(centres[i])))
        turned_parent = turned
        dq += list(shift) + [c for d in turns for c in d]
    return dq


def joint_moments(scene: SpatialScene, qm, forces, axes, defs: Definitions,
                  tag: str = "") -> list:
    """P(q_m)^T F: the generalized force F (12n) against the joint twists at q_m, the columns of
    the null space of G(q_m) (link k >= j turned about joint j's axis n_j through its point o_j:
    xdot_k = n_j x (x_k - o_j), ddot_ka = n_j x d_ka). Link by link, F's resultant f_k (on x_k)
    and moment about the origin m_k = x_k x f_k + sum_a d_ka x F_ka, summed from the tip:
    (P^T F)_j = n_j . (sum_{k>=j} m_k - o_j x sum_{k>=j} f_k), O(n)."""
    centres = coms(scene)
    resultant = moment = (sp.Integer(0),) * 3
    rows = []
    for i in range(scene.n, 0, -1):
        link = Link(qm, i)
        block = forces[12 * (i - 1):12 * i]
        force = tuple(block[:3])
        own = add(cross(link.x, force),
                  *(cross(d, tuple(block[3 * (a + 1):3 * (a + 2)])) for a, d in enumerate(link.d)))
        resultant = vectors.define_vector(defs, f"{tag}f{i}", add(resultant, force))
        moment = vectors.define_vector(defs, f"{tag}m{i}", add(moment, own))
        joint = Link(qm, i - 1).point(scene.links[i - 1].joint.xyz, centres[i - 1])
        rows.append(dot(axes[i - 1], add(moment, scale(-1, cross(joint, resultant)))))
    return rows[::-1]


def joint_twists(scene: SpatialScene, q, axes) -> list:
    """The columns xi_j of P(q), 12n entries each: links k >= j turned about joint j's axis
    n_j through its point o_j, xdot_k = n_j x (x_k - o_j), ddot_ka = n_j x d_ka."""
    centres = coms(scene)
    twists = []
    for j, axis in enumerate(axes, start=1):
        joint = Link(q, j - 1).point(scene.links[j - 1].joint.xyz, centres[j - 1])
        column = [sp.Integer(0)] * (12 * (j - 1))
        for k in range(j, scene.n + 1):
            link = Link(q, k)
            column += list(cross(axis, add(link.x, scale(-1, joint))))
            column += [c for d in link.d for c in cross(axis, d)]
        twists.append(column)
    return twists


def projected_rates(scene: SpatialScene, q, v, axes, defs: Definitions) -> list:
    """The joint rates of v projected M-orthogonally onto the constraints' tangent space at q
    (docs/model.md 14): (P^T M P) w = P^T M v, P = P(q) the joint twists, solved by Gaussian
    elimination without pivoting (P^T M P is the joint-space mass matrix, positive definite).
    A composed step's nodal v meets G(q) v = 0 only to O(dt^2); its projected rates are of the
    composition's order."""
    n = scene.n
    twists = joint_twists(scene, q, axes)
    matrix = [joint_moments(scene, q, mass_times(scene, column), axes, defs, f"P{j}")
              for j, column in enumerate(twists, start=1)]
    matrix = [[defs.define(f"A{r}_{c}", matrix[c][r]) for c in range(n)] for r in range(n)]
    right = [defs.define(f"b{r}", e) for r, e in enumerate(
        joint_moments(scene, q, mass_times(scene, v), axes, defs, "Mv"))]
    for k in range(n):
        for r in range(k + 1, n):
            factor = defs.define(f"l{r}_{k}", matrix[r][k] / matrix[k][k])
            for c in range(k + 1, n):
                matrix[r][c] = defs.define(f"A{r}_{c}_{k}", matrix[r][c] - factor * matrix[k][c])
            right[r] = defs.define(f"b{r}_{k}", right[r] - factor * right[k])
    rates = [sp.Integer(0)] * n
    for r in range(n - 1, -1, -1):
        rates[r] = defs.define(f"wp{r}", (right[r] - sp.Add(*(matrix[r][c] * rates[c]
                                                              for c in range(r + 1, n))))
                               / matrix[r][r])
    return rates


def newton_matrix(scene: SpatialScene, qm, q1, axes, turns, dt, defs: Definitions):
    """Newton's matrix A = (2/dt P(q_m)^T M P(q_1) + diag(d)) diag(1 / (1 + w_k^2/4)), an
    approximation of dF/dw: the derivative of the residual's leading terms, P(q_m)^T 2 M dq / dt
    with dq/dw_k = P_k(q_1) dtheta_k/dw_k (the twist of joint k at the step's end; |n_k| = 1),
    and the damping; without the terms of order dt^2 (the springs' stiffness, the impulses'
    turning of P) and dt (the torques' turning).

    P(q_m)^T M P(q_1) by composite rigid bodies (Featherstone's CRBA, in the world frame about
    its origin, with the two sides at q_m and q_1): for joints j, k and the links i from
    max(j, k) on, sum_i xi_j(q_m)^T M_i xi_k(q_1) = v_j . L + n_j . H, with the twists
    (v, n) = (o x n, n), L = m v_k + n_k x h_1 and H = K n_k + h_m x v_k from the composites
    m = sum m_i, h_m = sum m_i x_im, h_1 = sum m_i x_i1 and
    K = sum m_i ((x_im . x_i1) 1 - x_i1 x_im^T) + tr(Y_i) 1 - Y_i, Y_i = D_i1 E_i D_im^T (E the
    Euler tensor, D the directors: M's rotational part in director form). O(n^2), about 2200
    operations on the Panda, half the residual's; the exact dF/dw, by forward derivatives
    through the whole residual, costs 16 residuals there, and this A's chord contracts by
    about 3e-4 per iteration (at the mid-point on both sides, 1e-3; docs/model.md 4.8). The
    joints' damping d_j adds to the diagonal (-dt P^T f with tau_j = -d_j phidot_j(m) and
    phidot_j(m) ~ theta_j / dt)."""
    n = scene.n
    centres = coms(scene)
    composites = [None] * (n + 1)
    mass, start, end, inertia = sp.Integer(0), (sp.Integer(0),) * 3, (sp.Integer(0),) * 3, None
    for i in range(n, 0, -1):
        link = scene.links[i - 1]
        middle, final = Link(qm, i), Link(q1, i)
        euler = euler_tensor(link.inertia_matrix())
        # T = E D_m^T (rows a), then Y = D_1 T
        rows = [add(*(scale(number(euler[a][b]), middle.d[b]) for b in range(3)
                      if euler[a][b] != 0)) for a in range(3)]
        rows = [vectors.define_vector(defs, f"T{i}_{a}", row) for a, row in enumerate(rows)]
        second = [[sp.Add(*(final.d[a][r] * rows[a][c] for a in range(3))) for c in range(3)]
                  for r in range(3)]
        second = [[defs.define(f"Y{i}_{r}{c}", second[r][c]) for c in range(3)]
                  for r in range(3)]
        m = number(link.mass)
        both = defs.define(f"xx{i}", dot(middle.x, final.x))
        trace = second[0][0] + second[1][1] + second[2][2]
        own = [[(trace + m * both if r == c else 0) - second[r][c] - m * final.x[r] * middle.x[c]
                for c in range(3)] for r in range(3)]
        mass = mass + m
        start = vectors.define_vector(defs, f"hm{i}", add(start, scale(m, middle.x)))
        end = vectors.define_vector(defs, f"h1{i}", add(end, scale(m, final.x)))
        inertia = [[defs.define(f"K{i}_{r}{c}", own[r][c] + (0 if inertia is None
                                                             else inertia[r][c]))
                    for c in range(3)] for r in range(3)]
        composites[i] = (mass, start, end, inertia)

    def twist(q, j, name, axis):
        joint = Link(q, j - 1).point(scene.links[j - 1].joint.xyz, centres[j - 1])
        return vectors.define_vector(defs, f"{name}{j}", cross(joint, axis)), axis

    end_axes = [Link(q1, j - 1).turn(rpy_matrix(link.joint.rpy) @ np.asarray(link.joint.axis))
                for j, link in enumerate(scene.links, start=1)]
    end_axes = [axis if j == 1 else vectors.define_vector(defs, f"n1_{j}", axis)
                for j, axis in enumerate(end_axes, start=1)]
    projections = [twist(qm, j, "vm", axes[j - 1]) for j in range(1, n + 1)]
    motions = [twist(q1, k, "v1", end_axes[k - 1]) for k in range(1, n + 1)]
    matrix = [[None] * n for _ in range(n)]
    for c in range(1, n + 1):
        mass, start, end, inertia = composites[c]
        transposed = [[inertia[r][k] for r in range(3)] for k in range(3)]
        velocity, axis = motions[c - 1]
        linear = vectors.define_vector(defs, f"L{c}", add(scale(mass, velocity),
                                                          cross(axis, end)))
        angular = vectors.define_vector(defs, f"H{c}", add(vectors.apply(inertia, axis),
                                                           cross(start, velocity)))
        for j in range(1, c + 1):           # column c, rows j <= c: composite c
            v_j, n_j = projections[j - 1]
            matrix[j - 1][c - 1] = dot(v_j, linear) + dot(n_j, angular)
        velocity, axis = projections[c - 1]
        linear = vectors.define_vector(defs, f"Lt{c}", add(scale(mass, velocity),
                                                           cross(axis, start)))
        angular = vectors.define_vector(defs, f"Ht{c}", add(vectors.apply(transposed, axis),
                                                            cross(end, velocity)))
        for k in range(1, c):               # row c, columns k < c: composite c
            v_k, n_k = motions[k - 1]
            matrix[c - 1][k - 1] = dot(v_k, linear) + dot(n_k, angular)
    turning = [defs.define(f"dtheta{k}", 1 / (1 + w ** 2 / 4))
               for k, w in enumerate(turns, start=1)]
    # the joints' damping, -dt P^T f with tau_j = -d_j phidot_j(m), phidot_j(m) ~ theta_j / dt
    return ImmutableMatrix([[(2 / dt * matrix[r][c]
                              + (number(scene.links[c].damping) if r == c else 0)) * turning[c]
                             for c in range(n)] for r in range(n)])
