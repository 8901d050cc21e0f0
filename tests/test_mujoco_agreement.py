"""The generated solvers against MuJoCo's tendon model of the same chain (model.md section 10).

MuJoCo RK4 at dt = 1e-4 agrees with itself at dt = 2.5e-5 to 1e-12 rad over 3 s, so it is a
real, external reference; our schemes are second order, so at dt = 1e-4 they must agree to 1e-5.
"""
from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mujoco")

from chaingen.reference.mujoco_runs import initial_energy_mujoco, simulate_mujoco  # noqa: E402

from helpers import OWN_SCENES, REFERENCE_SCENES, load, solver_for  # noqa: E402

pytestmark = pytest.mark.compile

DT = 1e-4
SAMPLE_TIMES = (1.0, 2.0)


def wrapped(difference):
    return (np.asarray(difference) + np.pi) % (2 * np.pi) - np.pi


@pytest.mark.parametrize("method,quadrature", [("es", 3), ("vi", 3), ("midpoint", 3)])
@pytest.mark.parametrize("name", REFERENCE_SCENES + OWN_SCENES)
@pytest.mark.slow
def test_joint_angles_agree_with_mujoco(name, method, quadrature):
    scene = load(name)
    every = round(SAMPLE_TIMES[0] / DT)
    result = solver_for(name, method, quadrature).simulate(
        scene.initial_angles, scene.initial_velocities, dt=DT,
        n_steps=round(SAMPLE_TIMES[-1] / DT), every=every)
    reference = simulate_mujoco(scene, dt=DT, t_end=SAMPLE_TIMES[-1], sample_times=SAMPLE_TIMES)
    for row, (t, angles) in enumerate(zip(SAMPLE_TIMES, reference.angles), start=1):
        assert result.t[row] == pytest.approx(t)
        error = np.abs(wrapped(result.phi[row] - angles)).max()
        assert error <= 1e-5, f"t = {t}: joint angles differ by {error:.2e} rad"


@pytest.mark.parametrize("method", ["es", "vi", "midpoint"])
@pytest.mark.parametrize("name", REFERENCE_SCENES + OWN_SCENES)
def test_initial_energy_equals_mujoco(name, method):
    scene = load(name)
    solver = solver_for(name, method, 3)
    energy = solver.outputs(solver.initial_state(scene.initial_angles,
                                                 scene.initial_velocities))[2]
    assert energy == pytest.approx(initial_energy_mujoco(scene), rel=1e-9)


def test_uneven_chain_agrees_with_mujoco():
    """The bench's uneven scaling chain (uneven masses, lengths and inertias, every COM off the
    link axis, springs on every joint and two multi-articular ones) at n = 5: es against
    MuJoCo RK4 on its MJCF export, within the tolerances above."""
    from chaingen.simulation import build_solver
    from chaingen.studies.bench.scenes import uneven_scene

    scene = uneven_scene(5)
    assert all(link.com_normal != 0 for link in scene.links)
    solver = build_solver(scene, "es", 3, sensitivities=False)
    every = round(SAMPLE_TIMES[0] / DT)
    result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=DT,
                             n_steps=round(SAMPLE_TIMES[-1] / DT), every=every)
    reference = simulate_mujoco(scene, dt=DT, t_end=SAMPLE_TIMES[-1], sample_times=SAMPLE_TIMES)
    for row, (t, angles) in enumerate(zip(SAMPLE_TIMES, reference.angles), start=1):
        assert result.t[row] == pytest.approx(t)
        error = np.abs(wrapped(result.phi[row] - angles)).max()
        assert error <= 1e-5, f"t = {t}: joint angles differ by {error:.2e} rad"
    energy = solver.outputs(solver.initial_state(scene.initial_angles,
                                                 scene.initial_velocities))[2]
    assert energy == pytest.approx(initial_energy_mujoco(scene), rel=1e-9)
