"""Simulate a scene's chain with MuJoCo: the external reference of model.md section 10.

mujoco is a test and benchmark dependency, not a run-time one, so it is imported inside the
functions. The model is codegen.mjcf.mjcf_from_scene; qpos are the relative angles phi_i,
qvel the phidot_i, and ``mjData.energy`` (with the energy flag) is (V, T) of model.md
section 3, so H = energy[0] + energy[1].
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..scene import Scene
from .mjcf import mjcf_from_scene


@dataclass(frozen=True, eq=False)
class MujocoTrajectory:
    """Samples of one MuJoCo run of a scene.

    angles and velocities are read-only arrays of shape (len(sample_times), n): qpos and qvel
    after round(t/dt) steps of mj_step. The angles are MuJoCo's qpos as integrated, not wrapped
    to (-pi, pi]. energies[k] is H = V + T at sample k.
    """

    dt: float
    integrator: str
    initial_energy: float                # H at t = 0
    sample_times: tuple[float, ...]      # as requested
    steps: tuple[int, ...]               # round(t/dt) of each sample time
    angles: np.ndarray                   # phi at each sample, (len(sample_times), n)
    velocities: np.ndarray               # phidot at each sample, (len(sample_times), n)
    energies: np.ndarray                 # H at each sample, (len(sample_times),)
    final_angles: np.ndarray             # phi at t_end, (n,)
    final_velocities: np.ndarray         # phidot at t_end, (n,)
    final_energy: float                  # H at t_end


def mujoco_model_and_data(scene: Scene, dt: float, integrator: str):
    import mujoco

    model = mujoco.MjModel.from_xml_string(mjcf_from_scene(scene, dt=dt, integrator=integrator))
    data = mujoco.MjData(model)
    data.qpos[:] = scene.initial_angles
    data.qvel[:] = scene.initial_velocities
    mujoco.mj_forward(model, data)
    return model, data


def mujoco_energy(data) -> float:
    """H = V + T from mjData.energy, valid after mj_forward at the current state."""
    return float(data.energy[0] + data.energy[1])


def step_count(t: float, dt: float, what: str) -> int:
    """round(t/dt), refusing a t that is not a whole number of steps (to 1e-6 of a step)."""
    if not (t >= 0.0 and t < float("inf")):
        raise ValueError(f"{what}: must be >= 0 and finite, got {t!r}")
    steps = round(t / dt)
    if abs(steps * dt - t) > 1e-6 * dt:
        raise ValueError(f"{what}: {t!r} s is not a whole number of steps of dt = {dt!r} s")
    return steps


def _read_only(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def initial_energy_mujoco(scene: Scene) -> float:
    """MuJoCo's H = V + T (model.md section 3) at the scene's initial state."""
    _, data = mujoco_model_and_data(scene, dt=scene.simulation.dt, integrator="RK4")
    return mujoco_energy(data)


def simulate_mujoco(scene: Scene, *, dt: float, t_end: float, sample_times=(),
                    integrator: str = "RK4", torques=None) -> MujocoTrajectory:
    """Integrate `scene` with MuJoCo for round(t_end/dt) steps of `dt` with `integrator`.

    `torques` (one per actuated joint of the scene, constant) act on the joints as generalised
    forces (mjData.qfrc_applied), in the same sense as model.md 7: power tau_i phidot_i.

    Starts from qpos = initial angles, qvel = initial velocities and samples (qpos, qvel, H)
    after round(t/dt) steps for each t in `sample_times` (any order; each a whole number of
    steps and <= t_end).
    """
    step_count(t_end, dt, "t_end")
    model, data = mujoco_model_and_data(scene, dt, integrator)
    if torques is not None:
        torques = np.asarray(torques, dtype=float)
        if torques.shape != (len(scene.actuated_joints),):
            raise ValueError(f"torques: one per actuated joint {scene.actuated_joints}, got "
                             f"shape {torques.shape}")
        for joint, torque in zip(scene.actuated_joints, torques):
            data.qfrc_applied[joint - 1] = torque
    return sampled_run(model, data, dt=dt, t_end=t_end, sample_times=sample_times,
                       integrator=integrator)


def sampled_run(model, data, *, dt: float, t_end: float, sample_times=(), integrator: str,
                controls=None) -> MujocoTrajectory:
    """round(t_end/dt) MuJoCo steps of (model, data) from its state, sampling (qpos, qvel, H)
    after round(t/dt) steps for each t in `sample_times` (any order; each a whole number of
    steps and <= t_end). `controls`: None, or one row of mjData.ctrl per step, set before it
    (held over the step). The planar and the spatial references both run through it."""
    import mujoco

    n_steps = step_count(t_end, dt, "t_end")
    sample_times = tuple(float(t) for t in sample_times)
    steps = tuple(step_count(t, dt, f"sample_times[{k}]") for k, t in enumerate(sample_times))
    for k, s in enumerate(steps):
        if s > n_steps:
            raise ValueError(f"sample_times[{k}]: {sample_times[k]!r} s is after "
                             f"t_end = {t_end!r} s")
    initial_energy = mujoco_energy(data)
    angles = np.empty((len(steps), model.nq))
    velocities = np.empty((len(steps), model.nv))
    energies = np.empty(len(steps))
    by_step: dict[int, list[int]] = {}
    for k, s in enumerate(steps):
        by_step.setdefault(s, []).append(k)

    def record(step: int) -> None:
        for k in by_step.get(step, ()):
            angles[k] = data.qpos
            velocities[k] = data.qvel
            energies[k] = mujoco_energy(data)

    record(0)
    for step in range(1, n_steps + 1):
        if controls is not None:
            data.ctrl[:] = controls[step - 1]
        mujoco.mj_step(model, data)
        if step in by_step:
            # After mj_step, mjData.energy belongs to another state (Euler: the one before
            # the step; RK4: its last stage). mj_forward evaluates it at the current state
            # and changes neither qpos nor qvel; the next mj_step recomputes everything.
            mujoco.mj_forward(model, data)
            record(step)
    mujoco.mj_forward(model, data)

    return MujocoTrajectory(
        dt=float(dt),
        integrator=integrator,
        initial_energy=initial_energy,
        sample_times=sample_times,
        steps=steps,
        angles=_read_only(angles),
        velocities=_read_only(velocities),
        energies=_read_only(energies),
        final_angles=_read_only(data.qpos),
        final_velocities=_read_only(data.qvel),
        final_energy=mujoco_energy(data),
    )
