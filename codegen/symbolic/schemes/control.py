"""The control law of a scene's [control] table inside a scheme's step (docs/controllers.md,
"Passivity-based control").

The actuated joints a apply, over a step, the torque

    discrete:  tau_a = -G_a(phi_0, phi_1) * r_a - D_a phidot_a(m)
    sampled:   tau_a = -dV_s/dphi_a(phi_0) - D_a phidot_a(0)

G the exact discrete gradient of the shaping potential V_s (chaingen.symbolic.shaping), and r_a
the ratio of the angle's increment to the increment dt phidot_a(m) through which the scheme's
torques do work. Then the discrete law's work over the step is exactly
-(V_s(phi_1) - V_s(phi_0)) - dt sum D_a phidot_a(m)^2, and H_d = T + V + V_s falls by the injected
dissipation (plus the scene's own damping) on every step, at any dt. es's torques work through
the mid-point rates of its arms, dt thetadot_k(m) = e_k(0) x e_k(1) = sin(dTheta_k) on the
constraints, so r_a = (phi_a(1) - phi_a(0)) / (sin dTheta_a - sin dTheta_{a-1}) =
1 / (sinc(dphi_a / 2) cos((dTheta_a + dTheta_{a-1}) / 2)); midpoint's through
dt w(m) = phi_1 - phi_0 itself, r_a = 1. The sampled law is the continuous law held from the
step's start, the usual zero-order hold: it enters the same step as a torque of the start state.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import sympy as sp

from ...scene import Scene
from ...spatial.dynamics import rpy_matrix
from ...spatial.values import SpatialScene
from ..com_model import com_frame_map, number
from ..com_recursion import apply, projected_rates
from ..recursion import Definitions, cross
from ..shaping import discrete_shaping_gradient, shaping_gradient, shaping_potential, sinc
from ..spatial_shaping import discrete_shaping_gradient as spatial_gradient
from ..spatial_shaping import matrix_product
from ..spatial_shaping import shaping_potential as spatial_potential
from .base import actuated_joints
from .spatial_null_space import Link


@dataclass
class StepControl:
    """The law's torques of one step once a scheme asked for them: per joint (zero where not
    actuated), and the injected damping's energy over the step (>= 0 for the discrete law)."""

    scene: Scene
    dt: sp.Symbol
    torques: list = field(default_factory=list)
    injected: sp.Expr = sp.Integer(0)

    @property
    def actuated_torques(self) -> list:
        return [self.torques[joint - 1] for joint in actuated_joints(self.scene)]


def apply_law(scene, dt, discrete, sampled, ratios, rates_mid, rates0, defs: Definitions,
              law: StepControl) -> list:
    """The law's torque per joint (zero where not actuated), into `law`: discrete,
    -G_a r_a - D_a phidot_a(m) with G = discrete() and r = `ratios` (None: 1); sampled,
    -dV_s/dphi_a(phi_0) - D_a phidot_a(0) with the gradient sampled(). Also the injected
    damping's energy over the step."""
    control = scene.control
    actuated = actuated_joints(scene)
    torques = [sp.Integer(0)] * scene.n
    held = control.law != "discrete"
    gradient = sampled() if held else discrete()
    for index, (joint, g, d) in enumerate(zip(actuated, gradient, control.damping)):
        shape = defs.define(f"ctl_shape{joint}", g)
        if not held and ratios is not None:
            shape = shape * ratios[index]
        rate = rates0[joint - 1] if held else rates_mid[joint - 1]
        torques[joint - 1] = -shape - number(d) * rate
        law.injected += dt * number(d) * rate * rates_mid[joint - 1]
    law.torques = torques
    return torques


def _dot(a, b) -> sp.Expr:
    return a[0] * b[0] + a[1] * b[1]


def es_control(scene: Scene, dt, defs: Definitions, law: StepControl):
    """es_step's `control` hook for scene.control: fills `law` when es_step calls it."""
    control = scene.control
    actuated = scene.actuated_joints
    maps = [com_frame_map(link) for link in scene.links]

    def hook(arms0, arm_rates0, arm_steps, rates, joints0, com_rates0):
        n = scene.n
        base = (sp.Integer(1), sp.Integer(0))
        e0 = [base] + [defs.vector(f"ctl_e0_{k}", apply(R, a))
                       for k, (R, a) in enumerate(zip(maps, arms0), start=1)]
        angles0 = [defs.define(f"ctl_phi0_{k}", sp.atan2(cross(a, b), _dot(a, b)))
                   for k, (a, b) in enumerate(zip(e0[:-1], e0[1:]), start=1)]
        e1 = [base] + [defs.vector(f"ctl_e1_{k}", apply(R, (a[0] + d[0], a[1] + d[1])))
                       for k, (R, a, d) in enumerate(zip(maps, arms0, arm_steps), start=1)]
        turns = [sp.Integer(0)] + [
            defs.define(f"ctl_dtheta{k}", sp.atan2(cross(a, b), _dot(a, b)))
            for k, (a, b) in enumerate(zip(e0[1:], e1[1:]), start=1)]
        steps = [defs.define(f"ctl_dphi{k}", turns[k] - turns[k - 1]) for k in range(1, n + 1)]
        start = [angles0[joint - 1] for joint in actuated]
        ratios = [defs.define(f"ctl_ratio{joint}", 1 / (
            sinc(steps[joint - 1] / 2) * sp.cos((turns[joint] + turns[joint - 1]) / 2)))
            for joint in actuated]

        def measured():
            # The joint rates a controller measures: of the velocity's projection onto the
            # constraints (es's state carries a normal component that alternates in sign
            # and that no joint sees; com_recursion.projected_rates).
            absolute = [defs.define(f"ctl_thetadot0_{k}", cross(a, r)
                                    / number(link.com ** 2 + link.com_normal ** 2))
                        for k, (a, r, link) in enumerate(zip(arms0, arm_rates0, scene.links),
                                                         start=1)]
            return projected_rates(scene, joints0, arms0, e0[1:], com_rates0, absolute, defs)

        held = control.law != "discrete"
        return apply_law(
            scene, dt,
            lambda: discrete_shaping_gradient(scene, start, [steps[j - 1] for j in actuated],
                                              defs),
            lambda: shaping_gradient(scene, start), ratios, rates,
            measured() if held else None, defs, law)

    return hook


def midpoint_control(scene: Scene, dt, angles0, rates0, rates_mid, defs: Definitions,
                     law: StepControl) -> list:
    """midpoint's control torques per joint for scene.control (angles not wrapped): its
    torques work through dt w(m) = phi_1 - phi_0 itself (r = 1)."""
    actuated = scene.actuated_joints
    start = [angles0[joint - 1] for joint in actuated]
    increments = [dt * rates_mid[joint - 1] for joint in actuated]
    return apply_law(scene, dt,
                     lambda: discrete_shaping_gradient(scene, start, increments, defs),
                     lambda: shaping_gradient(scene, start), None, rates_mid, rates0, defs, law)


def _spatial_law(scene, dt, start, increments, ratios, rates_mid, rates0, defs, law) -> list:
    """A spatial scene's law per joint (apply_law with chaingen.symbolic.spatial_shaping's
    gradients; the sampled one is the discrete one at a zero step)."""
    return apply_law(scene, dt, lambda: spatial_gradient(scene, start, increments, defs),
                     lambda: spatial_gradient(scene, start, [sp.Integer(0)] * len(start), defs),
                     ratios, rates_mid, rates0, defs, law)


def spatial_midpoint_control(scene, dt, angles0, rates0, rates_mid, defs: Definitions,
                             law: StepControl) -> list:
    """The spatial midpoint's law per joint: its torques work through dt w(m) = phi_1 - phi_0
    itself (r = 1)."""
    actuated = scene.actuated
    return _spatial_law(scene, dt, [angles0[j - 1] for j in actuated],
                        [dt * rates_mid[j - 1] for j in actuated], None, rates_mid, rates0,
                        defs, law)


def _sine_vector(m) -> tuple:
    """s(X) = 1/2 vec(X - X^T): for a rotation by theta about a, sin(theta) a."""
    return ((m[2][1] - m[1][2]) / 2, (m[0][2] - m[2][0]) / 2, (m[1][0] - m[0][1]) / 2)


def spatial_es_control(scene, dt, q0, q1, angles, rates_mid, axes_mid, rates0,
                       defs: Definitions, law: StepControl) -> list:
    """Spatial es's law per joint. Its torques work through dt phidot_i(m) = n_i(m) . (s(P_i) -
    s(P_{i-1})), P_k = sum_a d_ka(1) d_ka(0)^T the turn of link k over the step (dt omega_k(m)
    = 1/2 sum_a d_a(0) x d_a(1) = s(P_k)). On the constraints P_i = P_{i-1} Rot(n_i(0), dphi_i),
    and Rot - 1 = dphi (sinc(dphi) [n] + dphi/2 sinc(dphi/2)^2 [n]^2), so that increment is
    dphi_i h_i with h_i = n_i(m) . s(P_{i-1} (sinc(dphi) [n] + ...)): r_i = 1 / h_i, no 0 / 0.
    angles: the joint angles at q0 (spatial_es.joint_angles)."""
    n = scene.n
    identity = tuple(tuple(sp.Integer(int(r == k)) for k in range(3)) for r in range(3))
    turns = [identity]
    for k in range(1, n + 1):
        start, end = Link(q0, k).d, Link(q1, k).d
        turns.append(tuple(tuple(defs.define(f"ctl_P{k}_{r}{c}", sp.Add(*(
            end[a][r] * start[a][c] for a in range(3)))) for c in range(3)) for r in range(3)))
    angles0 = [defs.define(f"ctl_phi0_{i}", a) for i, a in enumerate(angles, start=1)]
    steps, ratios = [], []
    for i, link in enumerate(scene.links, start=1):
        axis = Link(q0, i - 1).turn(rpy_matrix(link.joint.rpy) @ np.asarray(link.joint.axis))
        axis = [defs.define(f"ctl_n0_{i}{x}", c) for x, c in zip("xyz", axis)]
        parent, own = turns[i - 1], turns[i]
        transposed = tuple(tuple(parent[c][r] for c in range(3)) for r in range(3))
        relative = matrix_product(transposed, own)
        sine = _sine_vector(relative)
        cosine = (relative[0][0] + relative[1][1] + relative[2][2] - 1) / 2
        step = defs.define(f"ctl_dphi{i}", sp.atan2(sp.Add(*(a * b for a, b in zip(axis, sine))),
                                                     cosine))
        steps.append(step)
        cross = ((0, -axis[2], axis[1]), (axis[2], 0, -axis[0]), (-axis[1], axis[0], 0))
        square = matrix_product(cross, cross)
        first = defs.define(f"ctl_sinc{i}", sinc(step))
        half = defs.define(f"ctl_sinch{i}", sinc(step / 2))
        change = tuple(tuple(first * cross[r][c] + step / 2 * half ** 2 * square[r][c]
                             for c in range(3)) for r in range(3))
        h = sp.Add(*(a * b for a, b in zip(axes_mid[i - 1],
                                            _sine_vector(matrix_product(parent, change)))))
        ratios.append(defs.define(f"ctl_ratio{i}", 1 / h))
    actuated = scene.actuated
    return _spatial_law(scene, dt, [angles0[j - 1] for j in actuated],
                        [steps[j - 1] for j in actuated], [ratios[j - 1] for j in actuated],
                        rates_mid, rates0, defs, law)


def sampled_law(scene) -> bool:
    """Whether `scene` has a [control] law held from the step's start (law = "sampled"): it
    misses the energy balance by design, so its schemes take no energy check by default."""
    control = getattr(scene, "control", None)
    return control is not None and control.law == "sampled"


def state_shaping(scene, angles) -> sp.Expr:
    """V_s at the state's joint angles `angles` (every joint), planar or spatial: H_d = H +
    this."""
    potential = spatial_potential if isinstance(scene, SpatialScene) else shaping_potential
    return potential(scene, [angles[joint - 1] for joint in actuated_joints(scene)])
