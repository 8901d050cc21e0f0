"""A spatial chain's joint-space mass matrix by the composite-rigid-body algorithm, and solves
with it through its Cholesky factor, as intermediate definitions (model.md section 5.7).

SymPy's M(q) of a 7-joint arm, expanded, is far too large to generate; the momentum recursion
(spatial_recursion.momenta) gives M(q) w in O(n) but not M^-1. Here M is O(n^2) small
expressions from the frames of spatial_recursion.link_frames, and M^-1 b is two triangular
solves with its Cholesky factor L (M = L L^T), each entry of L one definition: no inverse and
no pivoting (M is symmetric positive definite where the joint axes move the chain
independently).

Composite bodies, world frame, about the world origin. Over the links j..n, accumulated from the
tip: the mass mu_j, the first moment s_j = sum m_k c_k (c_k the COM) and the rotational inertia
about the origin I_j = sum J_k + m_k (|c_k|^2 1 - c_k c_k^T). Joint j turning at unit rate
(its axis z_j through p_j, with b_j = p_j x z_j) gives links j..n the linear momentum
F_j = z_j x s_j + mu_j b_j and the angular momentum about the origin A_j = I_j z_j + s_j x b_j.
Joint i <= j moves all of them, and M_ij is the moment of that momentum about joint i's axis:

    M_ij = z_i . (A_j - p_i x F_j) = z_i . A_j + b_i . F_j       (i <= j)

six products per entry (the motion and momentum in Pluecker coordinates). Checked against
chaingen.spatial.dynamics.mass_matrix in tests/test_spatial_vi.py.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from ..spatial.values import SpatialScene
from .com_model import number
from .recursion import Definitions
from .spatial_recursion import SpatialFrames, add, apply, cross, define_vector, dot, scale


def mass_matrix(scene: SpatialScene, frames: SpatialFrames, defs: Definitions,
                tag: str = "") -> list[list]:
    """M(q) at the frames' angles (n x n rows, symmetric: one definition per entry i <= j),
    by the composite-rigid-body algorithm above."""
    n = scene.n
    total_mass = sp.Integer(0)
    moment, inertia = None, None          # s_j and I_j (rows) of links j + 1..n
    momenta = [None] * n                  # (F_j, A_j)
    for j in range(n - 1, -1, -1):
        link = scene.links[j]
        mass = number(link.mass)
        centre = add(frames.origins[j], frames.arms[j])
        weighted = scale(mass, centre)
        moment = define_vector(defs, f"{tag}crb_s{j + 1}",
                               weighted if moment is None else add(moment, weighted))
        square = dot(centre, centre)
        own = [[frames.inertias[j][r][k] + mass * ((square if r == k else 0)
                                                   - centre[r] * centre[k])
                for k in range(3)] for r in range(3)]
        rows = [[None] * 3 for _ in range(3)]
        for r in range(3):
            for k in range(r, 3):
                entry = own[r][k] if inertia is None else inertia[r][k] + own[r][k]
                rows[r][k] = rows[k][r] = defs.define(f"{tag}crb_I{j + 1}_{r}{k}", entry)
        inertia = rows
        total_mass += mass
        axis = frames.axes[j]
        line = define_vector(defs, f"{tag}crb_b{j + 1}", cross(frames.origins[j], axis))
        linear = define_vector(defs, f"{tag}crb_F{j + 1}",
                               add(cross(axis, moment), scale(total_mass, line)))
        angular = define_vector(defs, f"{tag}crb_A{j + 1}",
                                add(apply(inertia, axis), cross(moment, line)))
        momenta[j] = (line, linear, angular)
    matrix = [[None] * n for _ in range(n)]
    for j in range(n):
        _, linear, angular = momenta[j]
        for i in range(j + 1):
            line_i = momenta[i][0]
            matrix[i][j] = matrix[j][i] = defs.define(
                f"{tag}M{i + 1}_{j + 1}", dot(frames.axes[i], angular) + dot(line_i, linear))
    return matrix


@dataclass(frozen=True)
class CholeskyFactor:
    """L of matrix = L L^T (rows, zeros above the diagonal) and the reciprocals of its
    diagonal, as definitions."""

    lower: tuple
    reciprocals: tuple


def cholesky_factor(matrix, defs: Definitions, tag: str = "") -> CholeskyFactor:
    """The Cholesky factor of a symmetric positive definite matrix (n x n rows), row by row:
    O(n^3 / 6) products, each entry one definition."""
    n = len(matrix)
    lower = [[sp.Integer(0)] * n for _ in range(n)]
    reciprocals = [None] * n
    for i in range(n):
        for j in range(i + 1):
            rest = matrix[i][j] - sp.Add(*(lower[i][k] * lower[j][k] for k in range(j)))
            if i == j:
                lower[i][i] = defs.define(f"{tag}chol_L{i + 1}_{i + 1}", sp.sqrt(rest))
                reciprocals[i] = defs.define(f"{tag}chol_inv{i + 1}", 1 / lower[i][i])
            else:
                lower[i][j] = defs.define(f"{tag}chol_L{i + 1}_{j + 1}", rest * reciprocals[j])
    return CholeskyFactor(tuple(map(tuple, lower)), tuple(reciprocals))


def cholesky_solve(factor: CholeskyFactor, right, defs: Definitions, tag: str = "") -> list:
    """x with L L^T x = right: L y = right, then L^T x = y, O(n^2) products."""
    n = len(right)
    lower, reciprocals = factor.lower, factor.reciprocals
    forward = [None] * n
    for i in range(n):
        forward[i] = defs.define(f"{tag}chol_y{i + 1}", (right[i] - sp.Add(
            *(lower[i][k] * forward[k] for k in range(i)))) * reciprocals[i])
    solution = [None] * n
    for i in range(n - 1, -1, -1):
        solution[i] = defs.define(f"{tag}chol_x{i + 1}", (forward[i] - sp.Add(
            *(lower[k][i] * solution[k] for k in range(i + 1, n)))) * reciprocals[i])
    return solution
