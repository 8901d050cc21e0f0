"""es at order 6 for spatial scenes (issue 33, build point 4): the k = 1 Petrov-Galerkin step in
joint angles and canonical momenta with the spatial recursions
(chaingen.symbolic.schemes.spatial_galerkin, docs/model.md section 16, "Spatial chains"),
composed by Suzuki's 5 stages.

Independent paths: the node quantities against chaingen.spatial.dynamics (numpy: M(q), the
gradients by central differences); the step by a numpy Newton on its SymPy residual
(test_galerkin.NumpyStep); the compiled solver against scipy's DOP853 (Pinocchio's rnea), MuJoCo's
RK4, spatial vi and midpoint at order 6, and central differences (`chaingen check`).
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, assume, given, settings
from hypothesis import strategies as st
from test_galerkin import NumpyStep
from test_spatial_dynamics import random_scene

from chaingen.errors import UnsupportedSceneError
from chaingen.scene.solver_rules import SolverSpecError
from chaingen.spatial import dynamics
from chaingen.spatial.reader import load_spatial_scene
from chaingen.symbolic.composition import FROM_ORDER_4
from chaingen.symbolic.schemes import (
    SPATIAL_BUILDERS,
    build_scheme,
    orders_taken,
    spatial_galerkin,
)

from helpers import passed_check, require_tools, run_example_checked, scene_path


def shipped(name: str):
    return load_spatial_scene(scene_path(name))


def conservative(scene):
    """`scene` without torques or damping: its energy is a constant of the motion."""
    return dataclasses.replace(scene, actuated=(), links=tuple(
        dataclasses.replace(link, damping=0.0) for link in scene.links))


def damped_actuated(seed: int, n: int):
    """random_scene with springs, damping on every joint and motors on the first and last."""
    plain = random_scene(seed, n, springs=True)
    rng = np.random.default_rng(seed)
    return dataclasses.replace(plain, actuated=(1, n), links=tuple(
        dataclasses.replace(link, damping=float(d))
        for link, d in zip(plain.links, rng.uniform(0.1, 0.5, n))))


def lagrangian_at(scene, q, w) -> float:
    """L = T - V by chaingen.spatial.dynamics."""
    return dynamics.kinetic_energy(scene, q, w) - dynamics.potential_energy(scene, q)


# -- the scheme, without a compiler -----------------------------------------------------------

@pytest.mark.heavy
def test_spatial_es_takes_order_6_by_its_galerkin_step_with_the_scenes_k():
    """orders_taken asks the builder: es now studies 2, 4 and 6 on a spatial scene. Order 6
    is the Galerkin step (4n unknowns, joint-space state, K nodes after the start, Suzuki's
    stages from order 4), K the scene's (3) or --quadrature's; K < 2 is refused as for a
    planar scene."""
    scene = shipped("spatial_three_link")
    assert orders_taken(scene, "es") == (2, 4, 6)
    n = scene.n
    for quadrature in (None, 5):
        scheme = build_scheme(scene, "es", quadrature, order=6)
        K = quadrature or scene.simulation.quadrature
        assert scheme.step.unknowns.shape == (4 * n, 1) and scheme.maps.state.shape == (2 * n, 1)
        assert scheme.metadata.composition == FROM_ORDER_4 and scheme.order == 6
        assert scheme.quadrature == K and len(scheme.step.node_space.inputs) == K
        assert f"{K + 1}-point Gauss-Lobatto" in scheme.metadata.quadrature_rule
        assert "spatial chain" in scheme.metadata.summary
        assert scheme.segments.vectors.shape[0] == 3 * 3      # 1 + 2 route segments
        assert scheme.maps.holding_torques.shape == (n, 1)    # joint 3 is actuated
    # order 4 is still the composed director step (24 coordinates a link)
    assert build_scheme(scene, "es", order=4).maps.state.shape == (24 * n, 1)
    with pytest.raises(SolverSpecError, match="--quadrature: .* K >= 2"):
        build_scheme(scene, "es", 1, order=6)


def test_a_controlled_spatial_scene_is_refused_at_order_6():
    """The control law is built into the order-2 steps (as for a planar scene): SolverSpec
    refuses order 6, and the builder itself refuses a scene with a [control] table."""
    scene = shipped("panda_pbc")
    assert scene.control is not None
    with pytest.raises(SolverSpecError, match="--order: a controlled scene's step"):
        build_scheme(scene, "es", order=6)
    with pytest.raises(UnsupportedSceneError, match="order 6: a controlled scene's step"):
        SPATIAL_BUILDERS["es"](scene, 3, 6)


@pytest.mark.heavy
def test_the_nodes_are_the_numpy_chains_mass_matrix_and_lagrangian():
    """At a random step (unknowns, state, torques): every node's rates solve
    M(q_g) w_g = p_g with chaingen.spatial.dynamics' M, and its force is dL/dq + tau - D w
    with dT/dq and dV/dq by central differences of the numpy energies."""
    scene = damped_actuated(7, 3)
    n = scene.n
    scheme = spatial_galerkin.build(scene, 3)
    nodes = scheme.step.node_space
    evaluate = scheme.step_function([entry for g in nodes.inputs + nodes.outputs for entry in g])
    rng = np.random.default_rng(7)
    z, x, u = rng.uniform(-0.5, 0.5, 4 * n), rng.uniform(-1.0, 1.0, 2 * n), rng.normal(size=2)
    values = np.array(evaluate(*z, *x, *u, 0.05), float).reshape(2 * len(nodes.inputs), 2 * n)
    torques = np.zeros(n)
    torques[[0, n - 1]] = u
    damping = np.array([link.damping for link in scene.links])
    h = 1e-6
    for (q, p), (w, force) in zip(values[:len(nodes.inputs)].reshape(-1, 2, n),
                                  values[len(nodes.inputs):].reshape(-1, 2, n)):
        np.testing.assert_allclose(dynamics.mass_matrix(scene, q) @ w, p, rtol=0,
                                   atol=1e-12 * np.abs(p).max())
        lagrangian = np.array([(lagrangian_at(scene, q + h * e, w)
                                - lagrangian_at(scene, q - h * e, w)) / (2 * h)
                               for e in np.eye(n)])
        np.testing.assert_allclose(force, lagrangian + torques - damping * w, rtol=0,
                                   atol=1e-7 * max(1.0, np.abs(force).max()))


@pytest.mark.heavy
def test_one_step_is_symmetric_and_keeps_the_balance_that_the_rule_alone_misses():
    """The numpy Newton on the SymPy residual (independent of code generation), a damped
    chain with torques, one step of 0.05 s: Phi_-h(Phi_h(x)) = x (what makes Suzuki's
    composition of it of order 6); H_1 - H_0 = tau . (q_1 - q_0) - dissipated to 1e-14 of H
    with the energy correction, and missed by more than 1e-10 of H by the rule alone."""
    scene = damped_actuated(3, 3)
    corrected = NumpyStep(scene, 3, build=spatial_galerkin.build)
    alone = NumpyStep(scene, 3, exact_energy=False, build=spatial_galerkin.build)
    rng = np.random.default_rng(3)
    x0 = np.concatenate([rng.uniform(-1.0, 1.0, 3), rng.uniform(-2.0, 2.0, 3)])
    u = rng.uniform(-1.0, 1.0, 2)
    scale = abs(corrected.energy(*x0))
    defects = []
    for stepper in (corrected, alone):
        x1, (work, dissipated) = stepper.step(x0, 0.05, u)
        assert dissipated > 0 and abs(work) > 0
        defects.append(stepper.energy(*x1) - stepper.energy(*x0) - work + dissipated)
    assert abs(defects[0]) <= 1e-14 * scale, defects
    assert abs(defects[1]) >= 1e-10 * scale, defects
    free = NumpyStep(conservative(scene), 3, build=spatial_galerkin.build)
    x1, _ = free.step(x0, 0.1)
    back, _ = free.step(x1, -0.1)
    assert np.abs(x1 - x0).max() > 0.01
    np.testing.assert_allclose(back, x0, rtol=0, atol=1e-12)


# -- compiled -----------------------------------------------------------------------------------

@pytest.mark.compile
@pytest.mark.parametrize("name", ["spatial_three_link", "panda_springs"])
@pytest.mark.slow
def test_conservative_energy_to_round_off_and_the_balance_step_by_step(name):
    """200 steps of 0.01 s from the scene's start. No torques, no damping: |H - H_0| <=
    1e-12 H_0 (measured 9.3e-14 and 5.1e-14; the chains turn at up to 42 and 47 rad/s). The
    scene's damping and random torques on its motors: the balance H - H_0 - work + dissipated
    moves by at most 1e-13 H_0 in a step (measured 3.5e-15 and 1.8e-14) and both flows are
    there."""
    from chaingen.simulation import build_solver

    scene = shipped(name)
    free = build_solver(conservative(scene), "es", sensitivities=False, order=6)
    run = free.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01, n_steps=200)
    energy = np.asarray(run.energy)
    assert np.abs(run.omega).max() > 10.0     # not a chain at rest
    assert np.abs(energy - energy[0]).max() <= 1e-12 * abs(energy[0])
    solver = build_solver(scene, "es", sensitivities=False, order=6)
    torques = np.random.default_rng(1).uniform(-1.0, 1.0, (200, len(scene.actuated)))
    run = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01, n_steps=200,
                          torques=torques)
    balance = np.asarray(run.balance_error)
    assert run.dissipated[-1] > 1.0 and abs(run.input_work[-1]) > 0.1
    assert np.abs(np.diff(balance)).max() <= 1e-13 * abs(energy[0]), np.abs(np.diff(balance))


@pytest.mark.compile
@pytest.mark.slow
def test_composed_step_converges_at_order_6_to_dop853_and_meets_vi_and_midpoint():
    """The chain of spatial vi's order test (springs a tenth of random_scene's): the error at
    t = 1 s against DOP853 falls by 2^6 per halving of dt, in the angles and in the rates
    (measured 5.8e-8 and 8.6e-10 rad at dt = 10 and 5 ms, 67.7-fold; rates 71-fold). At
    dt = 1.25 ms the angles meet spatial vi's and midpoint's at order 6 within 1e-9 rad
    (measured 2.5e-10 and 2.1e-10, their own error: es's is 1.4e-11 there, DOP853's floor)."""
    from test_spatial_midpoint import reference_run, wrapped

    from chaingen.simulation import build_solver

    plain = random_scene(51, 3, springs=True)
    scene = dataclasses.replace(plain, springs=tuple(
        dataclasses.replace(spring, stiffness=spring.stiffness / 10) for spring in plain.springs))
    rng = np.random.default_rng(51)
    q0, w0 = rng.uniform(-1.0, 1.0, 3), rng.uniform(-1.0, 1.0, 3)
    angles, rates = reference_run(scene, q0, w0, np.zeros(3), 1.0, with_rates=True)

    def final(solver, dt):
        steps = round(1.0 / dt)
        result = solver.simulate(q0, w0, dt=dt, n_steps=steps, every=steps)
        return result.phi[-1], result.omega[-1]

    solver = build_solver(scene, "es", sensitivities=False, order=6)
    errors = []
    for dt in (1e-2, 5e-3):
        phi, omega = final(solver, dt)
        errors.append((np.abs(wrapped(phi - angles)).max(), np.abs(omega - rates).max()))
    for part in range(2):
        ratio = errors[0][part] / errors[1][part]
        assert 0.7 * 2 ** 6 <= ratio <= 1.3 * 2 ** 6, (part, errors)
    ours = final(solver, 1.25e-3)[0]
    for method in ("vi", "midpoint"):
        other = final(build_solver(scene, method, sensitivities=False, order=6), 1.25e-3)[0]
        assert np.abs(wrapped(ours - other)).max() <= 1e-9, method


@pytest.mark.compile
@pytest.mark.parametrize("name", ["spatial_three_link", "panda_springs"])
@pytest.mark.slow
def test_shipped_scenes_agree_with_mujoco_at_forty_times_its_step(name):
    """test_spatial_agreement's comparison (MuJoCo's RK4 at dt = 2.5e-4 s, angles at t = 1 s
    within 1e-4 rad), the composed step at dt = 0.01 s (measured 8.0e-8 and 6.9e-10 rad), and
    spatial_three_link driven by half its holding torque, where order 2 misses the bound at
    2.5e-4 s (model.md 6.7): 4.6e-6 rad at 0.01 s."""
    from test_spatial_agreement import (
        DT,
        TOLERANCE,
        holding_torques,
        mujoco_run,
        our_final_angles,
        wrapped,
    )

    from chaingen.simulation import build_solver

    pytest.importorskip("mujoco")
    scene = shipped(name)
    solver = build_solver(scene, "es", sensitivities=False, order=6)
    cases = [np.zeros(len(scene.actuated))]
    if name == "spatial_three_link":
        cases.append(0.5 * holding_torques(scene))
    for torques in cases:
        reference = mujoco_run(scene, torques, dt=DT).final_angles
        assert np.abs(wrapped(reference - np.array(scene.initial_angles))).max() > 0.05
        ours = our_final_angles(solver, scene, torques, dt=0.01)
        assert np.abs(wrapped(ours - reference)).max() <= TOLERANCE


@pytest.mark.compile
# Each example generates and compiles a solver: a few, drawn the same on every run, no shrinking
# (test_spatial_agreement's settings).
@settings(max_examples=3, deadline=None, derandomize=True,
          phases=(Phase.explicit, Phase.reuse, Phase.generate),
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
# Deferred: test_spatial_agreement skips at import without MuJoCo, and only this test needs it.
@given(case=st.deferred(lambda: __import__("test_spatial_agreement").drawn_cases()))
@pytest.mark.slow
def test_drawn_chains_agree_with_mujoco_at_eight_times_its_step(case):
    """test_spatial_agreement's drawn chains (3 to 7 links, skew axes, turned joint origins,
    full inertias, routed springs, tilted gravity, damping, torques on drawn joints) against
    MuJoCo's RK4 at dt = 2.5e-4 s: the composed step at dt = 2e-3 s within 1e-4 rad at
    t = 1 s (measured 3.3e-11 to 3.8e-11 rad on 3, 4 and 5 links)."""
    from test_spatial_agreement import (
        DT,
        SHORTEST_SEGMENT,
        TOLERANCE,
        mujoco_run,
        our_final_angles,
        shortest_segment,
        wrapped,
    )

    from chaingen.simulation import build_solver

    scene, torques = case
    reference = mujoco_run(scene, torques, dt=DT)
    assume(shortest_segment(scene, reference.angles) >= SHORTEST_SEGMENT)
    assert np.abs(wrapped(reference.final_angles - np.array(scene.initial_angles))).max() > 0.05
    solver = build_solver(scene, "es", sensitivities=False, order=6)
    ours = our_final_angles(solver, scene, torques, dt=2e-3)
    difference = np.abs(wrapped(ours - reference.final_angles)).max()
    print(f"\n{scene.n} links, es order 6 at 2 ms: max |q - q_MuJoCo| = {difference:.2e} rad")
    assert difference <= TOLERANCE


@pytest.mark.compile
@pytest.mark.slow
def test_sensitivities_and_generated_functions_pass_the_check():
    """chaingen check's comparisons on spatial_three_link (joint 2 damped, joint 3 actuated):
    the residual Jacobian (through one node's, NodeSpace) and the composed step's
    sensitivities against central differences, every generated function against SymPy."""
    passed_check(shipped("spatial_three_link"), "es", order=6)


@pytest.mark.compile
@pytest.mark.slow
def test_a_run_with_parameters_is_the_run_with_the_numbers_compiled_in():
    """Every run-time number a parameter (the Jacobian then goes by forward directions in the
    angles' and the momenta's blocks instead of through one node's): 40 steps with other
    values equal the run of the solver built with them."""
    from chaingen.simulation import build_solver
    from chaingen.spatial.parameters import with_values

    scene = shipped("spatial_three_link")
    values = {"gravity[0]": 1.5, "gravity[2]": -8.0, "links[1].mass": 2.2,
              "links[2].damping": 0.3, "springs[0].stiffness": 250.0,
              "springs[1].rest_length": 0.3}
    solver = build_solver(scene, "es", parameters="all", sensitivities=False, order=6)
    run = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.005, n_steps=40,
                          parameters=values)
    compiled = build_solver(with_values(scene, values), "es", sensitivities=False, order=6)
    reference = compiled.simulate(scene.initial_angles, scene.initial_velocities, dt=0.005,
                                  n_steps=40)
    assert np.abs(run.phi[-1] - np.array(scene.initial_angles)).max() > 0.05
    np.testing.assert_allclose(run.phi, reference.phi, rtol=0, atol=1e-12)
    np.testing.assert_allclose(run.omega, reference.omega, rtol=0, atol=1e-11)
    np.testing.assert_allclose(run.energy, reference.energy, rtol=1e-12, atol=1e-12)


@pytest.mark.tools
@pytest.mark.slow
def test_spatial_es_order_6_example_is_clean_under_valgrind_and_the_sanitizers(tmp_path):
    """The order-6 es package of an actuated, damped spatial chain as a user gets it: its
    example program, compiled with the strict flags, runs clean under memcheck and under
    ASan/UBSan (the nodes' Cholesky solves and the Jacobian through one node's among what
    they watch)."""
    require_tools("gcc", "valgrind")
    from chaingen.generate.package import generate_package, write_package

    scene = dataclasses.replace(damped_actuated(121, 3), name="spatial-es6-example",
                                actuated=(1, 3))
    package = write_package(generate_package(scene, "es", 3, sensitivities=False, order=6),
                            tmp_path / "package")
    for output in run_example_checked(package, tmp_path, "0.2"):
        assert "final tracking error" in output, output
