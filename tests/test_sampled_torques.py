"""An actuated run holds its torques at the sampled steps only (issue 30, point 10): no
(n_steps, nu) array when the torques are zero or chosen by a controller; C takes u = NULL as
zero torques and writes a controller's choices at every `every`-th step."""
from __future__ import annotations

import tracemalloc

import numpy as np
import pytest

pytestmark = pytest.mark.compile

DT = 0.01


@pytest.fixture(scope="module")
def actuated():
    from chaingen import build_solver
    from chaingen.studies.bench.control import control_scene

    scene = control_scene()
    solver = build_solver(scene, "es", 3, sensitivities=False)
    return solver, np.array(scene.initial_angles), np.array(scene.initial_velocities)


def test_zero_torques_are_not_allocated_per_step(actuated):
    solver, phi0, omega0 = actuated
    n_steps, every = 400_000, 100_000
    tracemalloc.start()
    try:
        result = solver.simulate(phi0, omega0, dt=DT, n_steps=n_steps, every=every)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 1_000_000      # (n_steps, 3) doubles would be 9.6 MB
    np.testing.assert_array_equal(result.torques, np.zeros((4, 3)))
    explicit = solver.simulate(phi0, omega0, dt=DT, n_steps=1000, every=100,
                               torques=np.zeros((1000, 3)))
    implicit = solver.simulate(phi0, omega0, dt=DT, n_steps=1000, every=100)
    np.testing.assert_array_equal(implicit.samples, explicit.samples)    # NULL: zero torques


@pytest.mark.parametrize("n_steps, every, hold", [(100, 5, 1), (103, 5, 1), (100, 7, 3),
                                                  (10, 1, 2)])
def test_a_controller_s_torques_are_recorded_at_the_sampled_steps(actuated, n_steps, every,
                                                                  hold):
    solver, phi0, omega0 = actuated
    hold_torques = solver.holding_torques(phi0)
    chosen = []

    def controller(t, phi, omega):
        u = hold_torques + 30.0 * (phi0 - phi) - 3.0 * omega + np.sin(5.0 * t)
        chosen.append(u)
        return u

    result = solver.simulate(phi0, omega0, dt=DT, n_steps=n_steps, every=every,
                             controller=controller, hold=hold)
    per_step = np.repeat(np.array(chosen), hold, axis=0)[:n_steps]
    assert result.torques.shape == (-(-n_steps // every), 3)
    np.testing.assert_array_equal(result.torques, per_step[::every])
    # the samples are those of the same inputs given per step, every one
    replay = solver.simulate(phi0, omega0, dt=DT, n_steps=n_steps, every=every,
                             torques=per_step)
    np.testing.assert_array_equal(result.samples, replay.samples)
    np.testing.assert_array_equal(replay.torques, per_step[::every])


def test_sampled_torques_in_the_tables(actuated):
    pytest.importorskip("pandas")
    solver, phi0, omega0 = actuated
    torques = np.random.default_rng(1).normal(size=(20, 3))
    result = solver.simulate(phi0, omega0, dt=DT, n_steps=20, every=5, torques=torques)
    frame = result.to_dataframe()
    np.testing.assert_array_equal(frame["u2"].to_numpy()[:4], torques[::5, 1])
    assert np.isnan(frame["u2"].to_numpy()[4])          # no step starts at the last sample
