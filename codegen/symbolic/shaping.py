"""The shaping potential of a controlled planar scene and its exact discrete gradient
(docs/controllers.md, "Passivity-based control"; model.md 7).

A scene's `[control]` table (chaingen.scene.values.Control) asks for energy shaping and damping
injection on its actuated joints A:

    V_s(phi_A) = 1/2 sum_{a in A} k_a (phi_a - phi*_a)^2 - c V(phi_A, phi*_U),

with V the scene's own potential (gravity and springs) in relative joint angles, taken with the
unactuated joints U at their target (c = 1 with `compensate`, else 0): V_s depends on the
actuated angles alone, so its gradient is a torque the actuators can apply. The closed loop's
storage function is H_d = T + V + V_s; with every joint actuated and c = 1 it is T + V_d, V_d the
quadratic alone.

The discrete-gradient law needs G(phi_0, phi_1) with G . (phi_1 - phi_0) = V_s(phi_1) - V_s(phi_0)
for every step, not only to its order. The quadratic term gives it by its mid-point. V is a sum of
functions of the directions e_j = (cos Theta_j, sin Theta_j) of the links (Theta_j the absolute
angles): gravity linear in them, each spring a function of segment vectors linear in them. Their
increments are exact linear forms in the angle increments,

    e(Theta_1) - e(Theta_0) = sinc(dTheta / 2) S e((Theta_0 + Theta_1) / 2) dTheta,

and a spring's length is a sum of norms whose increments are exact too,
|s_1| - |s_0| = (s_0 + s_1) . (s_1 - s_0) / (|s_0| + |s_1|), its energy quadratic in the length
(k (l_mean - S_0) (l_1 - l_0)). Composed, they give an exact discrete gradient of V in the angles
with no quadrature and no correction term: no division by the step, so no loss at rest.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy as sp
from sympy import ImmutableMatrix

from ..scene import Scene
from .com_model import number, spring_terms
from .joint_model import direction_geometry
from .recursion import Definitions

#: sinc(h) = sin(h) / h below this |h| by its Taylor polynomial (error h^6 / 5040 < 2e-22).
_SINC_SERIES_BELOW = 1e-3


def offset(phi, target) -> sp.Expr:
    """phi - phi* wrapped to (-pi, pi]: V_d's quadratic lives on the circle, its cut at the
    target's antipode (where it is continuous, its gradient not), so that a joint crossing
    +-pi, which es's and the measured angles wrap, sees no jump in V_s."""
    difference = phi - number(target)
    return sp.atan2(sp.sin(difference), sp.cos(difference))


def sinc(h) -> sp.Expr:
    """sin(h) / h without a branch and without 0 / 0: with H = max(|h|, c),
    sin(H) / H + p(h) - p(H), p the Taylor polynomial 1 - h^2/6 + h^4/120. Above c it is
    sin(h) / h exactly; below, p(h) plus sin(c)/c - p(c), which is under 2e-22."""
    c = sp.Float(_SINC_SERIES_BELOW)
    big = sp.Max(sp.Abs(h), c)

    def series(x):
        return 1 - x ** 2 / 6 + x ** 4 / 120

    return sp.sin(big) / big + series(h) - series(big)


@dataclass(frozen=True)
class PotentialTerms:
    """The scene's potential as functions of the link directions E_j (symbols): gravity, linear
    in them, and per spring its stiffness, rest length and segment vectors (linear in them)."""

    directions: tuple[tuple[sp.Symbol, sp.Symbol], ...]
    gravity: sp.Expr
    springs: tuple[tuple[sp.Expr, sp.Expr, tuple[ImmutableMatrix, ...]], ...]


def potential_terms(scene: Scene) -> PotentialTerms:
    """V of `scene` in direction symbols (the construction of joint_model.joint_space_potential)."""
    directions = tuple((sp.Symbol(f"shape_ex{j}", real=True), sp.Symbol(f"shape_ey{j}", real=True))
                       for j in range(1, scene.n + 1))
    joints, normals, heights = direction_geometry(scene, directions)
    gravity = sp.Integer(0)
    if scene.gravity:
        gravity = sp.Add(*(number(link.mass * scene.gravity) * y
                           for link, y in zip(scene.links, heights)))
    springs = []
    for spring in scene.springs:
        terms = spring_terms(scene, spring, joints, normals)
        springs.append((number(spring.stiffness), number(spring.rest_length),
                        terms.segment_vectors))
    return PotentialTerms(directions, sp.expand(gravity), tuple(springs))


def _absolute(scene: Scene, angles: dict[int, sp.Expr]) -> list[sp.Expr]:
    """Theta_j = phi_1 + ... + phi_j of the relative angles `angles` (joint -> angle)."""
    out, theta = [], sp.Integer(0)
    for joint in range(1, scene.n + 1):
        theta = theta + angles[joint]
        out.append(theta)
    return out


def _shaping_angles(scene: Scene, actuated_angles) -> dict[int, sp.Expr]:
    """Every joint's angle in V_s's cancellation term: the actuated ones' given, the others at
    their target."""
    control = scene.control
    angles = {joint: number(target) for joint, target in enumerate(control.target, start=1)}
    angles.update(zip(scene.actuated_joints, actuated_angles))
    return angles


def shaping_potential(scene: Scene, actuated_angles, defs: Definitions | None = None) -> sp.Expr:
    """V_s at the actuated joints' angles `actuated_angles` (scene order of actuation)."""
    control = scene.control
    quadratic = sp.Add(*(number(k) / 2 * offset(phi, control.target[joint - 1]) ** 2
                         for joint, k, phi in zip(scene.actuated_joints, control.stiffness,
                                                  actuated_angles)))
    if not control.compensate:
        return quadratic
    terms = potential_terms(scene)
    thetas = _absolute(scene, _shaping_angles(scene, actuated_angles))
    values = {}
    for (ex, ey), theta in zip(terms.directions, thetas):
        values[ex], values[ey] = sp.cos(theta), sp.sin(theta)
    potential = terms.gravity.xreplace(values)
    for stiffness, rest, vectors in terms.springs:
        length = sp.Add(*(sp.sqrt(v[0] ** 2 + v[1] ** 2) for v in vectors)).xreplace(values)
        potential += stiffness / 2 * (length - rest) ** 2
    return quadratic - potential


def shaping_gradient(scene: Scene, actuated_angles) -> list[sp.Expr]:
    """dV_s/dphi_a at `actuated_angles` (the sampled law's torque is its negative)."""
    symbols = sp.symbols(f"shape_phi0:{len(actuated_angles)}", real=True)
    potential = shaping_potential(scene, symbols)
    values = dict(zip(symbols, actuated_angles))
    return [sp.diff(potential, s).xreplace(values) for s in symbols]


def discrete_shaping_gradient(scene: Scene, start, increments, defs: Definitions) -> list:
    """G with G . increments = V_s(start + increments) - V_s(start) identically: the exact
    discrete gradient of the shaping potential between the actuated angles `start` and
    `start + increments` (module docstring). One entry per actuated joint."""
    control = scene.control
    actuated = scene.actuated_joints
    gradient = [number(k) * (offset(phi, control.target[joint - 1]) + d / 2)
                for joint, k, phi, d in zip(actuated, control.stiffness, start, increments)]
    if not control.compensate:
        return gradient
    terms = potential_terms(scene)
    thetas0 = _absolute(scene, _shaping_angles(scene, start))
    steps = _absolute(scene, {joint: sp.Integer(0) for joint in range(1, scene.n + 1)}
                      | dict(zip(actuated, increments)))
    start_values, end_values, slopes = {}, {}, []
    for j, ((ex, ey), theta, step) in enumerate(zip(terms.directions, thetas0, steps), start=1):
        if step == 0:              # inboard of every actuated joint: never moves
            slopes.append(None)
            continue
        theta = defs.define(f"shape_theta{j}", theta)
        step = defs.define(f"shape_dtheta{j}", step)
        middle = theta + step / 2
        factor = defs.define(f"shape_sinc{j}", sinc(step / 2))
        # d e_j = slope_j * dTheta_j exactly
        slopes.append((defs.define(f"shape_slope{j}_x", -factor * sp.sin(middle)),
                       defs.define(f"shape_slope{j}_y", factor * sp.cos(middle))))
        start_values[ex] = defs.define(f"shape_c0_{j}", sp.cos(theta))
        start_values[ey] = defs.define(f"shape_s0_{j}", sp.sin(theta))
        end_values[ex] = defs.define(f"shape_c1_{j}", sp.cos(theta + step))
        end_values[ey] = defs.define(f"shape_s1_{j}", sp.sin(theta + step))
    for (ex, ey), theta in zip(terms.directions, thetas0):
        if ex not in start_values:
            start_values[ex] = end_values[ex] = sp.cos(theta)
            start_values[ey] = end_values[ey] = sp.sin(theta)

    def increment_form(linear) -> list:
        """The coefficients of the absolute-angle increments in the exact increment of an
        expression linear in the directions."""
        out = []
        for (ex, ey), slope in zip(terms.directions, slopes):
            if slope is None:
                out.append(sp.Integer(0))
            else:
                out.append(sp.diff(linear, ex) * slope[0] + sp.diff(linear, ey) * slope[1])
        return out

    absolute = increment_form(terms.gravity)
    for i, (stiffness, rest, vectors) in enumerate(terms.springs):
        lengths0, lengths1, units = [], [], []
        for s, vector in enumerate(vectors):
            v0 = [defs.define(f"shape_spring{i}_{s}_v0{axis}", c.xreplace(start_values))
                  for axis, c in zip("xy", vector)]
            v1 = [defs.define(f"shape_spring{i}_{s}_v1{axis}", c.xreplace(end_values))
                  for axis, c in zip("xy", vector)]
            l0 = defs.define(f"shape_spring{i}_{s}_l0", sp.sqrt(v0[0] ** 2 + v0[1] ** 2))
            l1 = defs.define(f"shape_spring{i}_{s}_l1", sp.sqrt(v1[0] ** 2 + v1[1] ** 2))
            lengths0.append(l0)
            lengths1.append(l1)
            units.append([defs.define(f"shape_spring{i}_{s}_u{axis}", (a + b) / (l0 + l1))
                          for axis, a, b in zip("xy", v0, v1)])
        tension = defs.define(f"shape_spring{i}_tension", stiffness * (
            (sp.Add(*lengths0) + sp.Add(*lengths1)) / 2 - rest))
        for vector, unit in zip(vectors, units):
            along = unit[0] * vector[0] + unit[1] * vector[1]
            absolute = [a + tension * b for a, b in zip(absolute, increment_form(along))]
    # Relative angles: Theta_j moves with every phi_i, i <= j.
    for index, joint in enumerate(actuated):
        gradient[index] -= sp.Add(*absolute[joint - 1:])
    return gradient
