"""Simulate a spatial scene's chain with MuJoCo: the external reference of the spatial schemes
(docs/spatial-mujoco.md; issue 33 a: their angles at t = 1 s against MuJoCo's).

mujoco is a test and benchmark dependency, not a run-time one, so it is imported inside the
functions. The model is codegen.reference.spatial_mjcf.spatial_mjcf_from_scene: qpos are the
joint angles q_i, qvel the rates, data.ctrl the torques of the actuated joints (its motors),
and ``mjData.energy`` (with the energy flag) is (V, T) of chaingen.spatial.dynamics, so
H = energy[0] + energy[1]. The samples are the planar reference's MujocoTrajectory.
"""
from __future__ import annotations

import numpy as np

from .mujoco_runs import MujocoTrajectory, sampled_run, step_count
from .spatial_mjcf import spatial_mjcf_from_scene


def spatial_mujoco_model_and_data(scene, dt: float, integrator: str = "RK4"):
    """MuJoCo's (MjModel, MjData) of `scene` (a chaingen.spatial.SpatialScene), at its initial
    state after mj_forward.

    Raises ValueError (one line) for what spatial_mjcf_from_scene refuses and, should MuJoCo's
    compiler refuse the model all the same, with its reason and the element it names.
    """
    import mujoco

    text = spatial_mjcf_from_scene(scene, dt=dt, integrator=integrator)
    try:
        model = mujoco.MjModel.from_xml_string(text)
    except ValueError as error:    # "Error: <reason>\nElement name 'link3', id 3, line 9"
        lines = [line.strip() for line in str(error).splitlines() if line.strip()]
        reason = lines[0].removeprefix("Error: ") if lines else "no reason given"
        where = f" ({lines[1]})" if len(lines) > 1 else ""
        raise ValueError(f"{scene.name}: MuJoCo refuses the model: {reason}{where}") from None
    data = mujoco.MjData(model)
    data.qpos[:] = scene.initial_angles
    data.qvel[:] = scene.initial_velocities
    mujoco.mj_forward(model, data)
    return model, data


def _torque_rows(scene, torques, n_steps: int) -> np.ndarray | None:
    """The torques as (n_steps, number of actuated joints) rows, row k held over step k."""
    if torques is None:
        return None
    torques = np.asarray(torques, dtype=float)
    width = len(scene.actuated)
    if torques.shape == (width,):
        return np.broadcast_to(torques, (n_steps, width))
    if torques.shape == (n_steps, width):
        return torques
    raise ValueError(f"torques: one per actuated joint {list(scene.actuated)} (shape "
                     f"({width},)) or one row per step (shape ({n_steps}, {width})), got shape "
                     f"{torques.shape}")


def simulate_spatial_mujoco(scene, *, dt: float, t_end: float,
                            integrator: str = "RK4", sample_times=(),
                            torques=None) -> MujocoTrajectory:
    """Integrate `scene` (a chaingen.spatial.SpatialScene) with MuJoCo for round(t_end/dt)
    steps of `dt` (s) with `integrator`.

    Starts from the scene's initial angles and velocities. `torques` (N m) drive the actuated
    joints through their motors (data.ctrl, set before each mj_step, so held over the step):
    one per actuated joint in the scene's order, constant, or one row per step. Joint
    damping and the springs act as the scene says.

    Samples (q, qdot, H) after round(t/dt) steps for each t in `sample_times` (any order;
    each a whole number of steps and <= t_end); the final state is always returned.
    """
    if not (dt > 0.0 and dt < float("inf")):
        raise ValueError(f"dt: must be > 0 and finite, got {dt!r}")
    rows = _torque_rows(scene, torques, step_count(t_end, dt, "t_end"))
    model, data = spatial_mujoco_model_and_data(scene, dt, integrator)
    return sampled_run(model, data, dt=dt, t_end=t_end, sample_times=sample_times,
                       integrator=integrator, controls=rows)
