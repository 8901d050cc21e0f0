"""Controller-facing features: actuated joints, damping, the energy balance, step sensitivities.

The scenes: the reference scenes (no actuation), tests/scenes/four_link_underactuated.toml
(joints 1, 2 and 4 actuated, joint 3 passive and damped) and scenes/four_link_actuated.toml.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from chaingen.generate.package import generate_package
from chaingen.runtime import NewtonOptions
from chaingen.scene import kinematics
from chaingen.simulation import build_solver

from helpers import REFERENCE_SCENES, load, solver_for

pytestmark = pytest.mark.compile

METHODS = ("es", "vi", "midpoint")
UNDERACTUATED = "four_link_underactuated"
#: Newton settings tight enough that finite differences of the step see no solver noise.
TIGHT = NewtonOptions(max_iterations=50, update_rtol=1e-14, update_atol=1e-14,
                      residual_tol=1e-12)


def actuated_damped_mono():
    """three_link_mono with every joint actuated and damped (issue 4, point a)."""
    scene = load("three_link_mono")
    links = tuple(dataclasses.replace(link, damping=d)
                  for link, d in zip(scene.links, (0.05, 0.1, 0.02)))
    return dataclasses.replace(scene, links=links, actuated_joints=(1, 2, 3))


@pytest.fixture(scope="module")
def mono_es():
    return build_solver(actuated_damped_mono(), "es", 3)


# -- energy balance ----------------------------------------------------------------------------

def test_es_energy_balance_holds_on_every_step_of_a_50_s_run(mono_es):
    """H_1 - H_0 = work - dissipated to 1e-11 on every step, dissipated >= 0 (model.md 7)."""
    scene = actuated_damped_mono()
    rng = np.random.default_rng(2024)
    x = mono_es.initial_state(scene.initial_angles, scene.initial_velocities)
    energy = mono_es.outputs(x)[2]
    worst, least_dissipated, total_work = 0.0, np.inf, 0.0
    for _ in range(5000):                                   # 50 s at dt = 0.01
        step = mono_es.step(x, rng.uniform(-1.0, 1.0, size=3), 0.01)
        next_energy = mono_es.outputs(step.x1)[2]
        worst = max(worst, abs(next_energy - energy - step.input_work + step.dissipated))
        least_dissipated = min(least_dissipated, step.dissipated)
        total_work += abs(step.input_work)
        x, energy = step.x1, next_energy
    assert worst <= 1e-11
    assert least_dissipated >= 0.0
    assert total_work > 10.0        # the torques did real work: the balance is not vacuous


def test_simulate_reports_the_energy_flows_as_columns(mono_es):
    scene = actuated_damped_mono()
    torques = np.random.default_rng(7).uniform(-1.0, 1.0, size=(1000, 3))
    # Both runs start from a fresh workspace: the warm start's choice of first guess that an
    # earlier test left in it would part them at Newton's tolerance, amplified over 1000 steps.
    mono_es.reset()
    result = mono_es.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                              n_steps=1000, every=10, torques=torques)
    assert result.columns[-2:] == ("input_work", "dissipated")
    assert np.all(np.diff(result.dissipated) >= 0.0) and result.dissipated[-1] > 0.0
    assert np.abs(result.balance_error).max() <= 1e-10
    # The same run, one step at a time: simulate applies row k of torques on step k.
    mono_es.reset()
    x = mono_es.initial_state(scene.initial_angles, scene.initial_velocities)
    work = 0.0
    for u in torques:
        step = mono_es.step(x, u, 0.01)
        x, work = step.x1, work + step.input_work
    np.testing.assert_array_equal(result.phi[-1], mono_es.outputs(x)[0])
    assert result.input_work[-1] == pytest.approx(work, rel=1e-12)


@pytest.mark.parametrize("method", ["vi", "midpoint"])
def test_joint_space_schemes_balance_energy_to_their_order(method):
    """vi and midpoint are not passive by construction: their balance error is O(dt^2)."""
    scene = actuated_damped_mono()
    solver = build_solver(scene, method, 3)
    errors = []
    for dt in (0.02, 0.01):
        steps = round(2.0 / dt)
        torques = np.tile([0.5, -0.3, 0.2], (steps, 1))
        result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=dt,
                                 n_steps=steps, torques=torques)
        assert result.dissipated[-1] > 0.0 and result.input_work[-1] != 0.0
        errors.append(np.abs(result.balance_error).max())
    assert 2.5 <= errors[0] / errors[1] <= 6.0, errors


# -- inputs: the right joints, the right sign ----------------------------------------------------

@pytest.mark.parametrize("method", METHODS)
def test_constant_torques_agree_with_mujoco(method):
    """Joint torques on the underactuated scene against MuJoCo's qfrc_applied (RK4)."""
    from chaingen.reference.mujoco_runs import simulate_mujoco
    pytest.importorskip("mujoco")
    scene = load(UNDERACTUATED)
    torques = np.array([3.0, -1.5, 0.4])
    dt, t_end = 1e-4, 1.0
    result = solver_for(UNDERACTUATED, method, 3).simulate(
        scene.initial_angles, scene.initial_velocities, dt=dt, n_steps=round(t_end / dt),
        every=round(t_end / dt), torques=np.tile(torques, (round(t_end / dt), 1)))
    reference = simulate_mujoco(scene, dt=dt, t_end=t_end, sample_times=(t_end,),
                                torques=torques)
    passive = simulate_mujoco(scene, dt=dt, t_end=t_end, sample_times=(t_end,))
    difference = np.angle(np.exp(1j * (result.phi[-1] - reference.angles[0])))
    effect = np.angle(np.exp(1j * (reference.angles[0] - passive.angles[0])))
    assert np.abs(effect).max() > 0.1                 # the torques matter
    assert np.abs(difference).max() <= 1e-5


def test_holding_torques_are_the_gradient_of_the_potential():
    scene = load(UNDERACTUATED)
    solver = solver_for(UNDERACTUATED, "es", 3)
    phi = np.array([0.4, -0.7, 1.1, 0.3])
    h = 1e-6
    numeric = [(kinematics.potential_energy(scene, phi + h * e)
                - kinematics.potential_energy(scene, phi - h * e)) / (2 * h) for e in np.eye(4)]
    np.testing.assert_allclose(solver.holding_torques(phi), numeric, rtol=1e-7, atol=1e-8)


@pytest.mark.parametrize("method", ["es", "midpoint"])   # vi's torques: the MuJoCo test above
def test_holding_torques_hold_the_chain_still(method):
    solver = solver_for("four_link_actuated", method, 3)
    phi = np.array([0.9, -0.4, 0.6, 0.2])
    result = solver.simulate(phi, np.zeros(4), dt=0.01, n_steps=200,
                             torques=np.tile(solver.holding_torques(phi), (200, 1)))
    assert np.abs(result.phi - phi).max() <= 1e-9


def test_an_unactuated_scene_generates_no_input_path():
    package = generate_package(load("three_link_mono"), "es", 3)
    header = package.files["three_link_mono_es.h"]
    # The signatures are every package's (u with its size, NULL and 0 here); the model has no
    # input path and no holding torques (that entry point returns UNAVAILABLE).
    assert "#define THREE_LINK_MONO_ES_NU 0 " in header
    assert "three_link_mono_es_model_holding_torques" not in package.files[
        "three_link_mono_es_model.c"]
    assert ".holding_torques = NULL," in package.files["three_link_mono_es.c"]
    assert ".nu = 0," in package.files["three_link_mono_es.c"]
    actuated = generate_package(load(UNDERACTUATED), "es", 3)
    header = actuated.files["four_link_underactuated_es.h"]
    assert "#define FOUR_LINK_UNDERACTUATED_ES_NU 3" in header
    assert "const double *u, int nu" in header and "double *flows" in header
    assert ".nu = 3," in actuated.files["four_link_underactuated_es.c"]


def test_inputs_are_refused_where_there_are_none_and_checked_where_there_are():
    solver = solver_for("three_link_mono", "es", 3)
    x = solver.initial_state([0.1, 0.2, 0.3], [0.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="no actuated joints"):
        solver.step(x, [1.0], 0.01)
    with pytest.raises(ValueError, match="no actuated joints"):
        solver.simulate([0.1, 0.2, 0.3], [0.0] * 3, dt=0.01, n_steps=2, torques=np.ones((2, 1)))
    actuated = solver_for(UNDERACTUATED, "es", 3)
    with pytest.raises(ValueError, match=r"shape \(5, 3\)"):
        actuated.simulate([0.0] * 4, [0.0] * 4, dt=0.01, n_steps=5, torques=np.ones((5, 4)))


# -- sensitivities -------------------------------------------------------------------------------

def joint_space_step(solver, s, u, dt):
    """The step map in s = (phi, omega), as a controller sees it."""
    n = solver.n
    x = solver.initial_state(s[:n], s[n:])
    phi, omega, _, _ = solver.outputs(solver.step(x, u, dt, options=TIGHT).x1)
    return np.concatenate([phi, omega])


def central_differences(f, point, h):
    return np.column_stack([(f(point + h * e) - f(point - h * e)) / (2 * h)
                            for e in np.eye(len(point))])


def relative_error(computed, reference):
    return np.abs(computed - reference).max() / np.abs(reference).max()


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", REFERENCE_SCENES + (UNDERACTUATED,))
def test_step_sensitivities_match_central_differences(name, method):
    """d s1/d s0 and d s1/d u against central differences of the step map, <= 1e-6.

    The truncation error is O(h^2), and the step map's round-off (about 1e-13 for vi) is
    amplified by 1/h. h = 1e-4 for the state; h = 1e-3 for the torques, whose effect on s1 is
    dt-small and nearly linear. Measured: 1e-11 to 2e-8.
    """
    scene = load(name)
    solver = solver_for(name, method, 3, sensitivities=True)
    n, dt, h, h_u = scene.n, 0.01, 1e-4, 1e-3
    rng = np.random.default_rng(11)
    s0 = np.concatenate([np.asarray(scene.initial_angles) + rng.uniform(-0.3, 0.3, n),
                         rng.uniform(-1.0, 1.0, n)])
    u = rng.uniform(-2.0, 2.0, solver.nu) if solver.nu else None
    x0 = solver.initial_state(s0[:n], s0[n:])
    # From the same workspace state (no Newton history) the two take the same step, bitwise.
    solver.reset()
    sensitivities = solver.step_sensitivities(x0, u, dt)
    solver.reset()
    np.testing.assert_array_equal(sensitivities.x1, solver.step(x0, u, dt).x1)
    numeric = central_differences(lambda s: joint_space_step(solver, s, u, dt), s0, h)
    assert relative_error(sensitivities.ds_ds, numeric) <= 1e-6
    if solver.nu:
        numeric_u = central_differences(lambda v: joint_space_step(solver, s0, v, dt), u, h_u)
        assert relative_error(sensitivities.ds_du, numeric_u) <= 1e-6
        # Torques act through the accelerations: at first order in dt, d omega1/d u is
        # dt M^-1 restricted to the actuated columns, and d phi1/d u is O(dt^2).
        mass = kinematics.mass_matrix(scene, s0[:n])
        expected = dt * np.linalg.inv(mass)[:, np.array(scene.actuated_joints) - 1]
        np.testing.assert_allclose(sensitivities.ds_du[n:], expected, rtol=0.1, atol=1e-3 * dt)
    else:
        assert sensitivities.ds_du.shape == (2 * n, 0)


def test_sensitivities_linearise_the_step_map():
    """A linear prediction with the sensitivities is second-order accurate in the perturbation."""
    solver = solver_for(UNDERACTUATED, "es", 3, sensitivities=True)
    scene = load(UNDERACTUATED)
    s0 = np.concatenate([scene.initial_angles, [0.2, -0.1, 0.4, 0.0]])
    u = np.array([1.0, -0.5, 0.25])
    sens = solver.step_sensitivities(solver.initial_state(s0[:4], s0[4:]), u, 0.01)
    base = joint_space_step(solver, s0, u, 0.01)
    direction = np.random.default_rng(3).normal(size=8)
    direction_u = np.array([0.3, 0.1, -0.2])
    errors = []
    for epsilon in (1e-2, 5e-3):
        moved = joint_space_step(solver, s0 + epsilon * direction, u + epsilon * direction_u,
                                 0.01)
        predicted = base + epsilon * (sens.ds_ds @ direction + sens.ds_du @ direction_u)
        errors.append(np.abs(moved - predicted).max())
    assert 3.0 <= errors[0] / errors[1] <= 5.0, errors


def test_a_package_without_sensitivities_has_no_sensitivity_path():
    """generate --no-sensitivities: neither the function nor its generated code exist."""
    package = generate_package(load("three_link_mono"), "vi", 3, sensitivities=False)
    assert ".sensitivities = 0," in package.files["three_link_mono_vi.c"]
    assert not package.manifest["entry_points"]["step_sensitivities"]["available"]
    assert "sensitivity" not in package.files["three_link_mono_vi_model.c"]
    assert package.manifest["sources"] == ["three_link_mono_vi.c", "three_link_mono_vi_model.c"]
    solver = solver_for("three_link_mono", "vi", 3)
    assert not solver.has_sensitivities
    with pytest.raises(ValueError, match="without step sensitivities"):
        solver.step_sensitivities(solver.initial_state([0.1] * 3, [0.0] * 3), dt=0.01)
