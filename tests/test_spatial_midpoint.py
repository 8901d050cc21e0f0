"""Method "midpoint" for spatial scenes (issue 33, build 3) against independent paths.

The scheme's residual is the Newton-Euler recursion of chaingen.symbolic.spatial_recursion;
here it is evaluated (numpy, from the DiscreteScheme's definitions) against Pinocchio's rnea
and chaingen.spatial.dynamics on random chains (skew axes, joint origins turned by rpy,
off-axis centres of mass, full inertia tensors, springs routed through via points over one to
three joints), and the compiled solver against scipy's DOP853 on the equations of motion
qddot = M^-1 (tau - d qdot - C qdot - g - dV_s/dq) with M, C, g from Pinocchio and the springs
from chaingen.spatial.dynamics.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_spatial_dynamics import pinocchio_model, random_scene

from chaingen.scene import METHODS, SolverSpecError, kinematics
from chaingen.spatial import dynamics
from chaingen.spatial.values import (
    RoutePoint,
    SpatialJoint,
    SpatialLink,
    SpatialScene,
    SpatialSpring,
)
from chaingen.symbolic.schemes import SPATIAL_BUILDERS, build_scheme, spatial_midpoint

from helpers import load, passed_check, require_module, require_tools


def residual_function(scheme):
    """(q, qdot, qddot, dt, u) -> the residual divided by dt at the mid-point (q, qdot) with
    dw = dt qddot: the step's inputs chosen so that q_m = q and w_m = qdot."""
    evaluate = scheme.step_function(list(scheme.step.residual))

    def residual(q, qdot, qddot, dt, u=()):
        dw = dt * qddot
        w0 = qdot - dw / 2
        q0 = q - dt * qdot / 2
        return np.array(evaluate(*dw, *q0, *w0, *u, dt), dtype=float).ravel() / dt

    return residual


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 7),
       dt=st.floats(1e-4, 0.1))
@pytest.mark.heavy
def test_residual_is_the_inverse_dynamics_of_pinocchio(seed, n, dt):
    """M(q) qddot + C(q, qdot) qdot + g(q) + dV_s/dq: Pinocchio's rnea and our springs."""
    pin = require_module("pinocchio", "robots")
    scene = random_scene(seed, n, springs=True, physical=False)
    _, model = pinocchio_model(scene)
    data = model.createData()
    rng = np.random.default_rng(seed + 1)
    q, qdot, qddot = rng.uniform(-np.pi, np.pi, n), rng.normal(size=n), rng.normal(size=n)
    ours = residual_function(spatial_midpoint.build(scene))(q, qdot, qddot, dt)
    expected = pin.rnea(model, data, q, qdot, qddot) + dynamics.spring_torques(scene, q)
    assert np.abs(ours - expected).max() <= 1e-10 * max(1.0, np.abs(expected).max())


@pytest.mark.heavy    # SymPy on chains of up to 6-7 links: 4-5 s, out of the fast tier
@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 6))
def test_actuated_damped_residual_subtracts_torques_and_damping(seed, n):
    """With inputs on some joints and damping on all: the residual / dt is the inverse
    dynamics + d qdot - tau, tau the inputs of the actuated joints (model.md 7)."""
    pin = require_module("pinocchio", "robots")
    rng = np.random.default_rng(seed)
    plain = random_scene(seed, n, springs=True, physical=False)
    actuated = tuple(j for j in range(1, n + 1) if rng.uniform() < 0.6) or (1,)
    damping = rng.uniform(0.0, 2.0, n)
    scene = dataclasses.replace(plain, actuated=actuated, links=tuple(
        dataclasses.replace(link, damping=float(d)) for link, d in zip(plain.links, damping)))
    _, model = pinocchio_model(scene)
    data = model.createData()
    q, qdot, qddot = rng.uniform(-np.pi, np.pi, n), rng.normal(size=n), rng.normal(size=n)
    u = rng.normal(size=len(actuated))
    ours = residual_function(spatial_midpoint.build(scene))(q, qdot, qddot, 0.01, u)
    tau = np.zeros(n)
    tau[np.array(actuated) - 1] = u
    expected = (pin.rnea(model, data, q, qdot, qddot) + dynamics.spring_torques(scene, q)
                + damping * qdot - tau)
    assert np.abs(ours - expected).max() <= 1e-10 * max(1.0, np.abs(expected).max())


@pytest.mark.heavy    # SymPy on chains of up to 6-7 links: 4-5 s, out of the fast tier
@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 7))
def test_energy_and_segments_of_a_state_are_the_numeric_ones(seed, n):
    """H = T + V by the recursion against chaingen.spatial.dynamics; the watched segment
    vectors' lengths sum to the springs' lengths."""
    scene = random_scene(seed, n, springs=True, physical=False)
    scheme = spatial_midpoint.build(scene)
    rng = np.random.default_rng(seed + 2)
    q, qdot = rng.uniform(-np.pi, np.pi, n), rng.normal(size=n)
    energy, *segments = np.array(scheme.state_function(
        [scheme.maps.energy, *scheme.segments.vectors])(*q, *qdot), dtype=float).ravel()
    expected = dynamics.kinetic_energy(scene, q, qdot) + dynamics.potential_energy(scene, q)
    assert energy == pytest.approx(expected, rel=1e-12, abs=1e-12)
    lengths = np.linalg.norm(np.reshape(segments, (-1, 3)), axis=1)
    per_spring = np.split(lengths, np.cumsum([len(s.route) - 1 for s in scene.springs])[:-1])
    np.testing.assert_allclose([part.sum() for part in per_spring],
                               dynamics.spring_lengths(scene, q), rtol=1e-12)


@pytest.mark.heavy
def test_holding_torques_are_gravity_and_springs():
    """An actuated scene's holding torques: dV/dq from the numeric gravity and spring forces."""
    scene = dataclasses.replace(random_scene(5, 4, springs=True, physical=False), actuated=(1, 3))
    scheme = spatial_midpoint.build(scene)
    maps = scheme.maps
    from chaingen.symbolic.schemes.base import numpy_function
    hold = numpy_function(list(maps.initial_angles), maps.initial_definitions,
                          list(maps.holding_torques))
    q = np.random.default_rng(3).uniform(-np.pi, np.pi, 4)
    expected = dynamics.gravity_torques(scene, q) + dynamics.spring_torques(scene, q)
    np.testing.assert_allclose(np.array(hold(*q), dtype=float).ravel(), expected,
                               rtol=1e-12, atol=1e-12)


def test_every_scheme_takes_spatial_scenes_and_their_geometry_is_no_parameter():
    scene = random_scene(1, 3, springs=True, physical=False)
    assert set(SPATIAL_BUILDERS) == set(METHODS)     # every scheme takes spatial scenes now
    with pytest.raises(SolverSpecError, match=r"parameters: links\[1\]\.inertia: compiled "
                                              "geometry of a spatial scene"):
        build_scheme(scene, "midpoint", parameters=("links[1].inertia",))


# -- compiled runs --------------------------------------------------------------------------

def reference_run(scene, q0, w0, torques, t_end, *, with_rates=False):
    """scipy's DOP853 (rtol = atol = 1e-12) on qddot = M^-1 (tau - d qdot - C qdot - g -
    dV_s/dq): M by chaingen.spatial.dynamics, C qdot + g by Pinocchio's rnea. The angles at
    t_end; with_rates: (angles, rates)."""
    pin = require_module("pinocchio", "robots")
    from scipy.integrate import solve_ivp

    _, model = pinocchio_model(scene)
    data = model.createData()
    n = scene.n
    damping = np.array([link.damping for link in scene.links])

    def rhs(_, y):
        q, qdot = y[:n], y[n:]
        force = (torques - damping * qdot - pin.rnea(model, data, q, qdot, np.zeros(n))
                 - dynamics.spring_torques(scene, q))
        return np.concatenate([qdot, np.linalg.solve(dynamics.mass_matrix(scene, q), force)])

    solution = solve_ivp(rhs, (0.0, t_end), np.concatenate([q0, w0]), method="DOP853",
                         rtol=1e-12, atol=1e-12)
    if with_rates:
        return solution.y[:n, -1], solution.y[n:, -1]
    return solution.y[:n, -1]


def wrapped(angles) -> np.ndarray:
    return np.angle(np.exp(1j * np.asarray(angles)))


@pytest.mark.compile
@pytest.mark.parametrize("n, seed", [(3, 11), (5, 12)])
def test_compiled_run_converges_at_order_2_to_dop853(n, seed):
    """A random chain with routed springs, gravity, damping on every joint and constant
    torques on some: the angle error at t = 1 s falls by 4 per halving of dt, and is below
    1e-6 rad at dt = 1.25e-4 s."""
    from chaingen.simulation import build_solver

    rng = np.random.default_rng(seed)
    plain = random_scene(seed, n, springs=True, physical=False)
    scene = dataclasses.replace(plain, actuated=(1, n), links=tuple(
        dataclasses.replace(link, damping=float(d))
        for link, d in zip(plain.links, rng.uniform(0.0, 0.5, n))))
    u = rng.uniform(-1.0, 1.0, 2)
    torques = np.zeros(n)
    torques[[0, n - 1]] = u
    q0, w0 = rng.uniform(-1.0, 1.0, n), rng.uniform(-1.0, 1.0, n)
    expected = reference_run(scene, q0, w0, torques, 1.0)
    solver = build_solver(scene, "midpoint", sensitivities=False)
    errors = []
    for dt in (2e-3, 1e-3, 5e-4, 2.5e-4, 1.25e-4):
        steps = round(1.0 / dt)
        result = solver.simulate(q0, w0, dt=dt, n_steps=steps, every=steps,
                                 torques=np.tile(u, (steps, 1)))
        errors.append(np.abs(wrapped(result.phi[-1] - expected)).max())
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((3.8 <= ratios) & (ratios <= 4.2)), (errors, ratios)
    assert errors[-1] <= 1e-6, errors


@pytest.mark.compile
def test_conservative_energy_stays_bounded_over_10_s():
    """No damping, no inputs: the energy error is O(dt^2) (a quarter at half the step) and
    does not drift (the second five seconds err no more than the first)."""
    from chaingen.simulation import build_solver

    scene = random_scene(21, 4, springs=True, physical=False)
    rng = np.random.default_rng(21)
    q0, w0 = rng.uniform(-1.0, 1.0, 4), rng.uniform(-1.0, 1.0, 4)
    solver = build_solver(scene, "midpoint", sensitivities=False)
    peaks = []
    for dt in (2e-3, 1e-3):
        result = solver.simulate(q0, w0, dt=dt, n_steps=round(10.0 / dt))
        assert result.energy[0] == pytest.approx(
            dynamics.kinetic_energy(scene, q0, w0) + dynamics.potential_energy(scene, q0),
            rel=1e-12)
        error = np.abs(result.energy_error)
        half = len(error) // 2
        assert error[half:].max() <= 1.5 * error[:half].max(), (error[:half].max(),
                                                                error[half:].max())
        peaks.append(error.max())
    assert 3.0 <= peaks[0] / peaks[1] <= 5.0, peaks
    assert peaks[1] <= 1e-3 * abs(result.energy[0]), peaks


@pytest.mark.compile
def test_energy_balance_with_damping_and_torques():
    """The flows are the scheme's own (dt tau . w_m, dt d w_m^2, recomputed from the samples),
    and the balance H - H_0 - work + dissipated is O(dt^2)."""
    from chaingen.simulation import build_solver

    plain = random_scene(31, 4, springs=True, physical=False)
    damping = np.array([0.3, 0.0, 0.8, 0.2])
    scene = dataclasses.replace(plain, actuated=(1, 2, 4), links=tuple(
        dataclasses.replace(link, damping=float(d)) for link, d in zip(plain.links, damping)))
    solver = build_solver(scene, "midpoint", sensitivities=False)
    rng = np.random.default_rng(31)
    q0, w0 = rng.uniform(-1.0, 1.0, 4), rng.uniform(-1.0, 1.0, 4)
    errors = []
    for dt in (2e-3, 1e-3):
        steps = round(2.0 / dt)
        torques = rng.uniform(-2.0, 2.0, (steps, 3))
        result = solver.simulate(q0, w0, dt=dt, n_steps=steps, torques=torques)
        mid = (result.omega[1:] + result.omega[:-1]) / 2
        work = dt * np.cumsum((torques * mid[:, [0, 1, 3]]).sum(axis=1))
        dissipated = dt * np.cumsum((damping * mid ** 2).sum(axis=1))
        np.testing.assert_allclose(result.input_work[1:], work, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(result.dissipated[1:], dissipated, rtol=1e-9, atol=1e-12)
        assert dissipated[-1] > 0.0 and abs(work[-1]) > 0.0
        errors.append(np.abs(result.balance_error).max())
    assert 3.0 <= errors[0] / errors[1] <= 5.0, errors


@pytest.mark.compile
def test_sensitivities_and_generated_functions_pass_the_check():
    """chaingen check's comparisons on an actuated spatial scene: the residual Jacobian and
    the step sensitivities against central differences, every generated function against
    the scheme's SymPy expressions; and the C holding torques against the numeric ones."""
    scene = dataclasses.replace(random_scene(41, 4, springs=True, physical=False), actuated=(1, 3))
    solver = passed_check(scene, "midpoint")
    q = np.random.default_rng(41).uniform(-np.pi, np.pi, 4)
    np.testing.assert_allclose(
        solver.holding_torques(q),
        dynamics.gravity_torques(scene, q) + dynamics.spring_torques(scene, q),
        rtol=1e-12, atol=1e-12)


@pytest.mark.compile
def test_composed_steps_of_order_4_and_6_converge_to_dop853():
    """The spatial step composed to order 4 and 6 (chaingen.symbolic.composition): the error
    at t = 1 s against DOP853 falls by 2^4 and 2^6 per halving of dt."""
    from chaingen.simulation import build_solver

    scene = random_scene(51, 3, springs=True, physical=False)
    rng = np.random.default_rng(51)
    q0, w0 = rng.uniform(-1.0, 1.0, 3), rng.uniform(-1.0, 1.0, 3)
    expected = reference_run(scene, q0, w0, np.zeros(3), 1.0)
    for order, dts in ((4, (1e-2, 5e-3)), (6, (1e-2, 5e-3))):
        solver = build_solver(scene, "midpoint", sensitivities=False, order=order)
        errors = []
        for dt in dts:
            steps = round(1.0 / dt)
            result = solver.simulate(q0, w0, dt=dt, n_steps=steps, every=steps)
            errors.append(np.abs(wrapped(result.phi[-1] - expected)).max())
        assert 0.7 * 2 ** order <= errors[0] / errors[1] <= 1.3 * 2 ** order, (order, errors)


@pytest.mark.compile
def test_simulate_scene_runs_a_spatial_scene_with_the_simulation_defaults():
    """chaingen.simulation's one-call path: a spatial scene has no [simulation] table, so the
    table's defaults apply (dt = 0.01 s), and the run starts from the scene's initial state."""
    from chaingen.simulation import run_settings, simulate_scene

    scene = dataclasses.replace(random_scene(61, 3, springs=True, physical=False),
                                initial_angles=(0.3, -0.2, 0.1),
                                initial_velocities=(0.0, 0.5, 0.0))
    settings = run_settings(scene, method="midpoint", t_end=0.1)
    result = simulate_scene(scene, settings)
    assert settings.dt == 0.01 and result.n_steps == 10
    np.testing.assert_allclose(result.phi[0], scene.initial_angles, rtol=0, atol=1e-15)
    assert result.energy[0] == pytest.approx(
        dynamics.kinetic_energy(scene, scene.initial_angles, scene.initial_velocities)
        + dynamics.potential_energy(scene, scene.initial_angles), rel=1e-12)


def spatial_twin(planar) -> SpatialScene:
    """A planar scene as a spatial one: every joint axis z, joint i at (L_{i-1}, 0, 0) in link
    i-1's frame, the COM at (a, b, 0), J about z (and about x and y, which parallel axes never
    turn), gravity -g y; spring fastening P_j at (L_{j-1}, r_j, 0) on link j-1 (model.md 1-2)."""
    lengths = [0.0] + [link.length for link in planar.links]
    links = tuple(SpatialLink(
        mass=link.mass, com=(link.com, link.com_normal, 0.0),
        inertia=(link.inertia, link.inertia, link.inertia, 0.0, 0.0, 0.0),
        joint=SpatialJoint(xyz=(lengths[i], 0.0, 0.0), rpy=(0.0, 0.0, 0.0),
                           axis=(0.0, 0.0, 1.0)), damping=link.damping)
        for i, link in enumerate(planar.links))
    springs = tuple(SpatialSpring(tuple(
        RoutePoint(j - 1, (lengths[j - 1], r, 0.0))
        for j, r in zip(range(spring.first, spring.last + 2), planar.spring_fastenings(spring))),
        spring.stiffness, spring.rest_length) for spring in planar.springs)
    return SpatialScene(name="planar-twin", gravity=(0.0, -planar.gravity, 0.0), links=links,
                        springs=springs, initial_angles=planar.initial_angles,
                        initial_velocities=planar.initial_velocities,
                        actuated=planar.actuated_joints)


@pytest.mark.compile
def test_parallel_axes_give_the_planar_three_link_multi():
    """Issue 33, must show b: the spatial twin of three_link_multi (all axes parallel) runs
    the planar midpoint's trajectory: the two agree to 1e-8 rad at t = 1 s at dt = 1e-4
    (the same scheme on the same chain: round-off and Newton's tolerance apart), and both
    approach the limit as dt -> 0."""
    from chaingen.simulation import build_solver

    planar = load("three_link_multi")
    twin = spatial_twin(planar)
    q = np.array([0.4, -0.7, 1.1])
    assert spatial_midpoint.build(twin).scene is twin
    assert dynamics.potential_energy(twin, q) == pytest.approx(
        kinematics.potential_energy(planar, q), rel=1e-13)
    np.testing.assert_allclose(dynamics.mass_matrix(twin, q), kinematics.mass_matrix(planar, q),
                               rtol=1e-13)
    planar_solver = build_solver(planar, "midpoint", sensitivities=False)
    spatial_solver = build_solver(twin, "midpoint", sensitivities=False)
    finals = []
    for dt in (1e-3, 1e-4):
        steps = round(1.0 / dt)
        runs = [solver.simulate(planar.initial_angles, planar.initial_velocities, dt=dt,
                                n_steps=steps, every=steps)
                for solver in (planar_solver, spatial_solver)]
        assert np.abs(wrapped(runs[0].phi[-1] - runs[1].phi[-1])).max() <= 1e-8
        assert runs[0].energy[0] == pytest.approx(runs[1].energy[0], rel=1e-13)
        finals.append(runs[1].phi[-1])
    # dt -> 0: the step is not the limit's (the runs moved by O(dt^2)), so agreeing was not free.
    assert 1e-8 < np.abs(wrapped(finals[0] - finals[1])).max() < 1e-4


@pytest.mark.tools
@pytest.mark.parametrize("actuated", [(), (1, 3)])
def test_spatial_example_is_clean_under_valgrind_and_the_sanitizers(tmp_path, actuated):
    """A spatial package as a user gets it (free motion, and an actuated, damped chain whose
    example closes the PD loop on the holding torques): its example program, compiled with the
    strict flags, runs clean under memcheck and under ASan/UBSan."""
    require_tools("gcc", "valgrind")
    import json
    import subprocess

    from chaingen.generate.package import generate_package, write_package
    from chaingen.runtime import contract

    plain = random_scene(71, 4, springs=True, physical=False)
    scene = dataclasses.replace(plain, name="spatial-example", actuated=actuated, links=tuple(
        dataclasses.replace(link, damping=0.2) for link in plain.links))
    package = write_package(generate_package(scene, "midpoint", 3, sensitivities=False),
                            tmp_path / "package")
    sources = [package / name for name in json.loads((package / "chaingen.json").read_text())
               ["sources"]]
    for name, flags, runner in (
            ("memcheck", ["-g", "-O1"], ["valgrind", "--error-exitcode=99",
                                         "--track-origins=yes", "--leak-check=full"]),
            ("sanitized", ["-g", "-fsanitize=address,undefined", "-fno-omit-frame-pointer",
                           "-fno-sanitize-recover=all"], [])):
        binary = tmp_path / name
        built = subprocess.run(["gcc", *flags, *contract.STRICT_FLAGS, f"-I{package}",
                                *map(str, sources), str(package / "example.c"), "-lm", "-o",
                                str(binary)], capture_output=True, text=True, timeout=300)
        assert built.returncode == 0, built.stderr
        run = subprocess.run([*runner, str(binary), "0.5"], capture_output=True, text=True,
                             timeout=300)
        assert run.returncode == 0, run.stdout + run.stderr
        if runner:
            assert "ERROR SUMMARY: 0 errors" in run.stderr, run.stderr
        assert ("final tracking error" in run.stdout) == bool(actuated), run.stdout


@pytest.mark.compile
def test_a_route_segment_passing_through_zero_length_stops_the_run():
    """A spring from the base's (0.1, 0, 0) to (0, 0.1, 0) on a link turning about z from 0 at
    -3 rad/s: its segment has zero length at q = -pi/2, reached between two steps of 0.01 s
    around t = pi/6 s; the run stops there with the segment status (model.md 12), in 3D as in
    the plane."""
    from chaingen.runtime import NewtonError
    from chaingen.simulation import build_solver

    link = SpatialLink(mass=1.0, com=(0.3, 0.0, 0.0), inertia=(0.01, 0.02, 0.02, 0, 0, 0),
                       joint=SpatialJoint((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0)))
    spring = SpatialSpring((RoutePoint(0, (0.1, 0.0, 0.0)), RoutePoint(1, (0.0, 0.1, 0.0))),
                           stiffness=0.5, rest_length=0.1)
    scene = SpatialScene(name="collapsing-route", gravity=(0.0, 0.0, -9.81), links=(link,),
                         springs=(spring,), initial_angles=(0.0,), initial_velocities=(-3.0,))
    solver = build_solver(scene, "midpoint", sensitivities=False)
    with pytest.raises(NewtonError, match="spring segment") as caught:
        solver.simulate([0.0], [-3.0], dt=0.01, n_steps=100)
    assert caught.value.status == 6
    crossing = (np.pi / 2) / 3.0
    assert caught.value.time <= crossing <= caught.value.time + 0.01
    clear = solver.simulate([0.0], [3.0], dt=0.01, n_steps=30)    # turning away from it
    assert np.all(np.isfinite(clear.samples))
