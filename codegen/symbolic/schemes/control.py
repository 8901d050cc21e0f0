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

import sympy as sp

from ...scene import Scene
from ..com_model import com_frame_map, number
from ..com_recursion import apply, projected_rates
from ..recursion import Definitions, cross
from ..shaping import discrete_shaping_gradient, shaping_gradient, shaping_potential, sinc


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
        return [self.torques[joint - 1] for joint in self.scene.actuated_joints]


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
        torques = [sp.Integer(0)] * n
        if control.law == "discrete":
            e1 = [base] + [defs.vector(f"ctl_e1_{k}", apply(R, (a[0] + d[0], a[1] + d[1])))
                           for k, (R, a, d) in enumerate(zip(maps, arms0, arm_steps), start=1)]
            turns = [sp.Integer(0)] + [
                defs.define(f"ctl_dtheta{k}", sp.atan2(cross(a, b), _dot(a, b)))
                for k, (a, b) in enumerate(zip(e0[1:], e1[1:]), start=1)]
            steps = [defs.define(f"ctl_dphi{k}", turns[k] - turns[k - 1])
                     for k in range(1, n + 1)]
            start = [angles0[joint - 1] for joint in actuated]
            increments = [steps[joint - 1] for joint in actuated]
            gradient = discrete_shaping_gradient(scene, start, increments, defs)
            for joint, g, d in zip(actuated, gradient, control.damping):
                ratio = defs.define(f"ctl_ratio{joint}", 1 / (
                    sinc(steps[joint - 1] / 2) * sp.cos((turns[joint] + turns[joint - 1]) / 2)))
                rate = rates[joint - 1]
                torques[joint - 1] = -defs.define(f"ctl_shape{joint}", g) * ratio \
                    - number(d) * rate
                law.injected += dt * number(d) * rate ** 2
        else:
            absolute = [defs.define(f"ctl_thetadot0_{k}", cross(a, r)
                                    / number(link.com ** 2 + link.com_normal ** 2))
                        for k, (a, r, link) in enumerate(zip(arms0, arm_rates0, scene.links),
                                                         start=1)]
            # The joint rates a controller measures: of the velocity's projection onto the
            # constraints (es's state carries a normal component that alternates in sign
            # and that no joint sees; com_recursion.projected_rates).
            rates0 = projected_rates(scene, joints0, arms0, e0[1:], com_rates0, absolute, defs)
            gradient = shaping_gradient(scene, [angles0[joint - 1] for joint in actuated])
            for joint, g, d in zip(actuated, gradient, control.damping):
                torques[joint - 1] = -defs.define(f"ctl_shape{joint}", g) \
                    - number(d) * rates0[joint - 1]
                law.injected += dt * number(d) * rates0[joint - 1] * rates[joint - 1]
        law.torques = torques
        return torques

    return hook


def midpoint_control(scene: Scene, dt, angles0, rates0, rates_mid, defs: Definitions,
                     law: StepControl) -> list:
    """midpoint's control torques per joint for scene.control (angles not wrapped)."""
    control = scene.control
    actuated = scene.actuated_joints
    torques = [sp.Integer(0)] * scene.n
    if control.law == "discrete":
        start = [angles0[joint - 1] for joint in actuated]
        increments = [dt * rates_mid[joint - 1] for joint in actuated]
        gradient = discrete_shaping_gradient(scene, start, increments, defs)
        for joint, g, d in zip(actuated, gradient, control.damping):
            rate = rates_mid[joint - 1]
            torques[joint - 1] = -defs.define(f"ctl_shape{joint}", g) - number(d) * rate
            law.injected += dt * number(d) * rate ** 2
    else:
        gradient = shaping_gradient(scene, [angles0[joint - 1] for joint in actuated])
        for joint, g, d in zip(actuated, gradient, control.damping):
            torques[joint - 1] = -defs.define(f"ctl_shape{joint}", g) \
                - number(d) * rates0[joint - 1]
            law.injected += dt * number(d) * rates0[joint - 1] * rates_mid[joint - 1]
    law.torques = torques
    return torques


def state_shaping(scene: Scene, angles) -> sp.Expr:
    """V_s at the state's relative angles `angles` (every joint): H_d = H + this."""
    return shaping_potential(scene, [angles[joint - 1] for joint in scene.actuated_joints])
