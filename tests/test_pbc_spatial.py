"""Passivity-based control on spatial arms (issue 34 e): the Panda with three springs, every
joint actuated (scenes/panda_pbc.toml), and a partly actuated spatial three-link chain, in the
spatial es (director coordinates) and midpoint schemes."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import chaingen
from chaingen.scene.values import Control
from chaingen.spatial import load_spatial_scene
from chaingen.studies.control import predicted_equilibrium

pytestmark = pytest.mark.compile

PANDA = load_spatial_scene("panda_pbc")
PATHS = ([f"control.stiffness[{i}]" for i in range(7)]
         + [f"control.damping[{i}]" for i in range(7)])


def _gains(scene, scale):
    return ([k * scale for k in scene.control.stiffness]
            + [d * scale for d in scene.control.damping])


@pytest.fixture(scope="module")
def panda_es():
    return chaingen.build_solver(PANDA, "es", sensitivities=False, parameters=PATHS)


@pytest.mark.parametrize("dt", [1e-3, 1e-2, 0.1])
@pytest.mark.parametrize("scale", [1.0, 100.0])
@pytest.mark.slow
def test_the_panda_keeps_the_closed_loop_balance_on_every_step(panda_es, dt, scale):
    """H_d(k+1) - H_d(k) + dissipated at round-off on every step of the 7-joint arm with
    three springs, at dt from 1 ms to 0.1 s and gains x1 and x100; H_d never rises."""
    steps = min(int(round(3.0 / dt)), 1500)
    result = panda_es.simulate(PANDA.initial_angles, PANDA.initial_velocities, dt=dt,
                               n_steps=steps, parameters=_gains(PANDA, scale))
    storage = result.energy
    size = max(np.abs(storage).max(), 1.0)
    balance = np.diff(storage - result.input_work + result.dissipated)
    assert np.abs(balance).max() <= 1e-12 * size, np.abs(balance).max()
    assert np.all(np.diff(result.dissipated) >= 0)
    assert np.diff(storage).max() <= 1e-13 * size


def test_the_panda_is_regulated_to_its_target(panda_es):
    """With the energy check on by default (1e-6 of T) to rest, where H_d cancels its terms'
    joules: before, with it on, step 292 (t = 2.91 s) failed with ENERGY_JUMP."""
    assert panda_es.newton_options().energy_tol == 1e-6
    result = panda_es.simulate(PANDA.initial_angles, PANDA.initial_velocities, dt=0.01,
                               n_steps=1000, parameters=_gains(PANDA, 1.0))
    assert np.abs(result.phi[-1] - PANDA.control.target).max() < 1e-6
    assert np.abs(result.omega[-1]).max() < 1e-6
    assert result.split_steps == 0


def test_the_panda_controllers_torque_reproduces_the_closed_loop_on_the_plant(panda_es):
    """control_torques from the measured state, applied to the Panda without its law (the
    plant model, es), gives the closed loop's next state to the Newton tolerance."""
    plant = chaingen.build_solver(dataclasses.replace(PANDA, control=None), "es",
                                  sensitivities=False)
    x = panda_es.initial_state(PANDA.initial_angles, PANDA.initial_velocities)
    gains = _gains(PANDA, 1.0)
    for _ in range(15):
        step = panda_es.control_torques(x, None, 0.01, parameters=gains)
        following = plant.step(x, step.tau, 0.01, options={"warm_start": False}).x1
        assert np.abs(following - step.x1).max() <= 1e-10 * np.abs(step.x1).max()
        x = step.x1


@pytest.mark.parametrize("method", ["es", "midpoint"])
def test_a_partly_actuated_spatial_chain_settles_where_the_theory_predicts(method):
    """spatial_three_link with joint 2 passive (its own damping added): the loop settles at
    the stationary point of V + V_s predicted from chaingen.spatial.dynamics' potential."""
    base = load_spatial_scene("spatial_three_link")
    links = list(base.links)
    links[1] = dataclasses.replace(links[1], damping=0.5)
    scene = dataclasses.replace(base, links=tuple(links), actuated=(1, 3),
                                control=Control((0.3, -0.2, 0.5), (20.0, 5.0), (5.0, 1.0)))
    predicted, hessian = predicted_equilibrium(scene, scene.control.target)
    assert np.linalg.eigvalsh(hessian).min() > 0
    solver = chaingen.build_solver(scene, method, sensitivities=False)
    result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                             n_steps=3000)
    assert np.abs(result.phi[-1] - predicted).max() < 1e-6
    if method == "es":
        balance = np.diff(result.energy - result.input_work + result.dissipated)
        assert np.abs(balance).max() <= 1e-12 * max(np.abs(result.energy).max(), 1.0)
