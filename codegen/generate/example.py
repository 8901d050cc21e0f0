"""The example program of a package: what it controls, and the PD gains it starts from.

An actuated scene gets a joint-space PD controller with compensation of the potential,
    u_j = tau_hold,j(phi) + kp_j wrap(phi*_j - phi_j) - kd_j omega_j,
tau_hold = dV/dphi the torques that hold the chain still (gravity and springs). For a fully
actuated chain this is PD control with gravity compensation, asymptotically stable for any
positive gains (Takegaki and Arimoto 1981), with no steady-state error. The controller runs at
CONTROL_RATE, once a step. Each joint's gains make a critically damped loop at BANDWIDTH for the
joint's own inertia at the target, M_jj(phi*): kp_j = omega_c^2 M_jj, kd_j = 2 zeta omega_c M_jj.
Sampled velocity feedback is stable only while dt * lambda_max(M^-1 Kd) stays well below 2 (the
coupled chain can be far lighter than M_jj suggests), so omega_c is lowered until that number
is at most SAMPLING_MARGIN.

An unactuated scene gets an example that simulates the free motion and prints the energy and
constraint errors.

A package whose step holds a control law (a scene with a [control] table, the package's feature
`control`) gets an example without a PD controller: the law is the controller, and the example
calls control_torques once a step at the scene's own dt (the discrete law keeps the closed
loop's storage from rising at any dt, so the rate the scene was designed at is the one to show)
for the scene's t_end, and measures the posture error against the [control] target.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..scene import Scene, kinematics
from ..spatial import dynamics as spatial_dynamics
from ..spatial.values import SpatialScene
from ..symbolic.schemes.base import actuated_joints
from .interface import c_literal

#: Closed-loop bandwidth (rad/s) and damping ratio the gains aim at.
BANDWIDTH = 2 * math.pi * 0.5
DAMPING_RATIO = 1.0
#: The example's control and integration rate (Hz), and the bound on dt lambda_max(M^-1 Kd).
CONTROL_RATE = 1000.0
SAMPLING_MARGIN = 0.5
#: How long the example runs by default (s), and how often it prints (steps).
EXAMPLE_DURATION = 10.0


@dataclass(frozen=True)
class ExampleSettings:
    target: tuple[float, ...]   # phi* for every joint (rad)
    kp: tuple[float, ...]       # per actuated joint (N m / rad)
    kd: tuple[float, ...]       # per actuated joint (N m s / rad)
    dt: float
    duration: float
    print_every: int
    bandwidth: float            # omega_c the gains were made for (rad/s)


def example_settings(scene: Scene | SpatialScene) -> ExampleSettings:
    """The target posture and gains of the example: joint 1 raised to pi/2, the rest straight
    (a spatial chain: joint 1 turned by pi/2 about its axis)."""
    target = (math.pi / 2,) + (0.0,) * (scene.n - 1)
    spatial = isinstance(scene, SpatialScene)
    if not actuated_joints(scene):   # free motion at the scene's own step
        dt = scene.simulation.dt
        return ExampleSettings(target=target, kp=(), kd=(), dt=dt, duration=EXAMPLE_DURATION,
                               print_every=max(1, round(0.5 / dt)), bandwidth=0.0)
    dt = 1 / CONTROL_RATE
    mass = (spatial_dynamics.mass_matrix(scene, target) if spatial
            else kinematics.mass_matrix(scene, target))
    inertia = np.zeros(scene.n)
    for joint in actuated_joints(scene):
        inertia[joint - 1] = mass[joint - 1, joint - 1]
    # Largest eigenvalue of M^-1 diag(inertia) (real and >= 0: similar to a symmetric matrix).
    fastest = max(np.linalg.eigvals(np.linalg.solve(mass, np.diag(inertia))).real)
    bandwidth = min(BANDWIDTH, SAMPLING_MARGIN / (2 * DAMPING_RATIO * dt * fastest))
    chosen = [inertia[joint - 1] for joint in actuated_joints(scene)]
    return ExampleSettings(
        target=target, kp=tuple(bandwidth ** 2 * i for i in chosen),
        kd=tuple(2 * DAMPING_RATIO * bandwidth * i for i in chosen), dt=dt,
        duration=EXAMPLE_DURATION, print_every=max(1, round(0.5 / dt)), bandwidth=bandwidth)


def controlled_example_settings(scene: Scene) -> ExampleSettings:
    """The controlled example's target (the [control] target), step and duration (the
    scene's); no gains of its own."""
    dt = scene.simulation.dt
    return ExampleSettings(target=tuple(scene.control.target), kp=(), kd=(), dt=dt,
                           duration=scene.simulation.t_end,
                           print_every=max(1, round(0.5 / dt)), bandwidth=0.0)


def example_context(scene: Scene | SpatialScene, *, controlled: bool = False) -> dict:
    """The example program's numbers as C text, for the templates. controlled: the package's
    step holds the scene's control law (its feature `control`)."""
    settings = controlled_example_settings(scene) if controlled else example_settings(scene)
    actuated = actuated_joints(scene)
    passive = [joint for joint in range(1, scene.n + 1) if joint not in actuated]

    def doubles(values) -> str:
        return ", ".join(c_literal(float(value)) for value in values)

    return {
        "initial_angles": doubles(scene.initial_angles),
        "initial_velocities": doubles(scene.initial_velocities),
        "dt": c_literal(settings.dt), "duration": c_literal(settings.duration),
        "print_every": settings.print_every, "target": doubles(settings.target),
        "actuated_indices": ", ".join(str(j - 1) for j in actuated),
        "kp": doubles(settings.kp), "kd": doubles(settings.kd),
        "bandwidth_hz": f"{settings.bandwidth / (2 * math.pi):.3g}",
        "actuated_list": ", ".join(map(str, actuated)),
        "passive_note": (f"; joint{'s' if len(passive) > 1 else ''} "
                         f"{', '.join(map(str, passive))} passive, settling where the closed "
                         "loop's potential balances" if passive else ""),
        "example_run": ("the scene's control law to its target" if controlled
                        else "PD control to a target posture" if actuated else "the free motion"),
        "example_file": ("the scene's control law through control_torques, once a step"
                         if controlled else
                         "a joint-space PD controller with holding-torque feed-forward"
                         if actuated else "a free-motion run with energy and constraint errors"),
    }
