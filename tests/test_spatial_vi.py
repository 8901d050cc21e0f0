"""Method "vi" for spatial scenes (issue 33, build 2) against independent paths.

The scheme's residual (chaingen.symbolic.schemes.spatial_vi: the discrete Legendre transforms
by the momentum recursion of chaingen.symbolic.spatial_recursion) is evaluated at a solution of
the discrete Euler-Lagrange equations built numerically from chaingen.spatial.dynamics (central
differences of L_d = dt [1/2 v^T M(q_m) v - V(q_m)]); the compiled solver is checked against
scipy's DOP853 (tests/test_spatial_midpoint.reference_run, Pinocchio's rnea), for the momentum
of a cyclic joint, for symplecticity from its step sensitivities, and for its energy.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import sympy as sp
from hypothesis import example, given, settings
from hypothesis import strategies as st
from test_spatial_dynamics import random_scene
from test_spatial_midpoint import reference_run, wrapped

from chaingen.spatial import dynamics
from chaingen.spatial.dynamics import rpy_matrix
from chaingen.symbolic import spatial_mass, spatial_recursion
from chaingen.symbolic.recursion import Definitions
from chaingen.symbolic.schemes import build_scheme, spatial_vi

from helpers import passed_check, require_tools, run_example_checked


def discrete_lagrangian(scene, q0, q1, dt):
    """L_d = dt [1/2 v^T M(q_m) v - V(q_m)], q_m = (q0 + q1)/2, v = (q1 - q0)/dt, from
    chaingen.spatial.dynamics."""
    middle, v = (q0 + q1) / 2, (q1 - q0) / dt
    return dt * (v @ dynamics.mass_matrix(scene, middle) @ v / 2
                 - dynamics.potential_energy(scene, middle))


def numeric_transforms(scene, q0, q1, dt, force, h=1e-6):
    """(p_0, p_1) of the forced discrete Legendre transforms, p_0 = -D_1 L_d - dt/2 f,
    p_1 = D_2 L_d + dt/2 f, D_1, D_2 by central differences of step h."""
    n = scene.n
    d1, d2 = np.zeros(n), np.zeros(n)
    for j in range(n):
        e = np.zeros(n)
        e[j] = h
        d1[j] = (discrete_lagrangian(scene, q0 + e, q1, dt)
                 - discrete_lagrangian(scene, q0 - e, q1, dt)) / (2 * h)
        d2[j] = (discrete_lagrangian(scene, q0, q1 + e, dt)
                 - discrete_lagrangian(scene, q0, q1 - e, dt)) / (2 * h)
    return -d1 - dt / 2 * force, d2 + dt / 2 * force


def forced_scene(seed, n):
    """random_scene with springs, inputs on some joints and damping on all."""
    rng = np.random.default_rng(seed)
    plain = random_scene(seed, n, springs=True)
    actuated = tuple(j for j in range(1, n + 1) if rng.uniform() < 0.6) or (1,)
    return dataclasses.replace(plain, actuated=actuated, links=tuple(
        dataclasses.replace(link, damping=float(d))
        for link, d in zip(plain.links, rng.uniform(0.0, 2.0, n))))


@pytest.mark.heavy  # SymPy on up to six links: tens of seconds, too slow for the fast tier
@settings(max_examples=10, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 5), dt=st.floats(1e-3, 0.05))
def test_residual_vanishes_at_a_numeric_solution_of_the_del_equations(seed, n, dt):
    """q_0, q_1 at random, p_0, p_1 by central differences of the numeric L_d (and the
    forcing dt/2 (tau - d v)), w_0 = M(q_0)^-1 p_0: the scheme's residual at
    v = (q_1 - q_0)/dt vanishes to the differences' error, and at a wrong v it does not; the
    update gives
    q_1 and w_1 = M(q_1)^-1 p_1 (through the Cholesky factor of the composite-rigid-body M)."""
    scene = forced_scene(seed, n)
    scheme = spatial_vi.build(scene)
    rng = np.random.default_rng(seed + 1)
    q0 = rng.uniform(-np.pi, np.pi, n)
    theta = dt * rng.normal(size=n)
    u = rng.normal(size=len(scene.actuated))
    tau = np.zeros(n)
    tau[np.array(scene.actuated) - 1] = u
    force = tau - np.array([link.damping for link in scene.links]) * theta / dt
    p0, p1 = numeric_transforms(scene, q0, q0 + theta, dt, force)
    w0 = np.linalg.solve(dynamics.mass_matrix(scene, q0), p0)
    residual = scheme.step_function(list(scheme.step.residual))
    scale = max(1.0, np.abs(p0).max(), np.abs(p1).max())
    ours = np.array(residual(*theta / dt, *q0, *w0, *u, dt), dtype=float).ravel()
    assert np.abs(ours).max() <= 1e-7 * scale, ours
    wrong = np.array(residual(*(theta / dt + 1e-3), *q0, *w0, *u, dt), dtype=float).ravel()
    assert np.abs(wrong).max() > 1e-6 * np.abs(p1).max()
    update = scheme.step_function(list(scheme.step.next_state))
    x1 = np.array(update(*theta / dt, *q0, *w0, *u, dt), dtype=float).ravel()
    np.testing.assert_allclose(x1[:n], q0 + theta, rtol=0, atol=1e-15)
    np.testing.assert_allclose(dynamics.mass_matrix(scene, q0 + theta) @ x1[n:], p1,
                               rtol=0, atol=1e-7 * scale)


@pytest.mark.heavy
@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 7))
@example(seed=72, n=1)     # 3.2e-13 of max |M|: the draw that showed the cancellation
@example(seed=144, n=1)    # 4.3e-13 of max |M|
def test_composite_rigid_body_mass_matrix_and_its_cholesky_solve(seed, n):
    """spatial_mass.mass_matrix against chaingen.spatial.dynamics.mass_matrix (checked against
    Pinocchio's crba in test_spatial_dynamics), and cholesky_solve against numpy's solve."""
    scene = random_scene(seed, n)
    rng = np.random.default_rng(seed + 5)
    q, b = rng.uniform(-np.pi, np.pi, n), rng.normal(size=n)
    angles = sp.symbols(f"q1:{n + 1}", real=True)
    right = sp.symbols(f"b1:{n + 1}", real=True)
    defs = Definitions("t_")
    matrix = spatial_mass.mass_matrix(
        scene, spatial_recursion.link_frames(scene, angles, defs), defs)
    solution = spatial_mass.cholesky_solve(spatial_mass.cholesky_factor(matrix, defs), right,
                                           defs)
    from chaingen.symbolic.schemes.base import numpy_function
    values = np.array(numpy_function([*angles, *right], defs.items,
                                     [*(m for row in matrix for m in row), *solution])(*q, *b),
                      dtype=float).ravel()
    expected = dynamics.mass_matrix(scene, q)
    # The composite rigid bodies are summed about the world origin: terms of size
    # m (|c| + |o|)^2 (c the COMs, o the farthest joint origin) cancel down to M's entries, so
    # round-off is relative to them, not to M. Measured over 600 draws (n = 1, 2, 4, 7): at
    # most 2.8e-15 of this scale, up to 4.3e-13 of max |M| (a single link far from the origin
    # about its own COM: M = 0.013 kg m^2 from terms of 2.2).
    poses = dynamics.link_poses(scene, q)
    far = max(np.linalg.norm(origin) for _, origin in poses)
    scale = sum(link.mass * (np.linalg.norm(com) + far) ** 2 + np.abs(link.inertia).max()
                for link, com in zip(scene.links, dynamics.com_positions(scene, q)))
    np.testing.assert_allclose(values[:n * n].reshape(n, n), expected, rtol=0,
                               atol=2e-14 * scale)
    np.testing.assert_allclose(expected @ values[n * n:], b, rtol=0, atol=1e-11)
    # O(n^2) entries of the factor and the solves, not one expanded expression per entry
    assert max(sp.count_ops(expression) for _, expression in defs.items) <= 8 * n + 40


@pytest.mark.heavy
@settings(max_examples=8, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 6))
def test_momenta_and_kinetic_gradient_are_the_numeric_ones(seed, n):
    """spatial_recursion.momenta: M(q) w against chaingen.spatial.dynamics.mass_matrix, and
    dT/dq at fixed rates against central differences of kinetic_energy."""
    scene = random_scene(seed, n)
    rng = np.random.default_rng(seed + 3)
    q, w = rng.uniform(-np.pi, np.pi, n), rng.normal(size=n)
    angles = sp.symbols(f"q1:{n + 1}", real=True)
    rates = sp.symbols(f"w1:{n + 1}", real=True)
    defs = Definitions("t_")
    momentum, gradient = spatial_recursion.momenta(
        scene, spatial_recursion.link_frames(scene, angles, defs), rates, defs)
    from chaingen.symbolic.schemes.base import numpy_function
    values = np.array(numpy_function([*angles, *rates], defs.items, momentum + gradient)(*q, *w),
                      dtype=float).ravel()
    np.testing.assert_allclose(values[:n], dynamics.mass_matrix(scene, q) @ w,
                               rtol=1e-12, atol=1e-12)
    h = 1e-6
    expected = [(dynamics.kinetic_energy(scene, q + h * e, w)
                 - dynamics.kinetic_energy(scene, q - h * e, w)) / (2 * h) for e in np.eye(n)]
    np.testing.assert_allclose(values[n:], expected, rtol=1e-6,
                               atol=1e-7 * max(1.0, np.abs(expected).max()))
    assert values[n] == 0.0     # T does not depend on the first angle


def cyclic_scene(seed, n, gravity=True):
    """random_scene with springs, none fastened to the base, and gravity along the first
    joint's axis in the world (or none): the first angle is cyclic."""
    plain = random_scene(seed, n, springs=True)
    joint = plain.links[0].joint
    axis = rpy_matrix(joint.rpy) @ np.asarray(joint.axis)
    return dataclasses.replace(
        plain, gravity=tuple(-9.81 * axis if gravity else np.zeros(3)),
        springs=tuple(s for s in plain.springs if all(p.link > 0 for p in s.route)))


def test_vi_is_offered_for_spatial_scenes_and_builds_the_scheme():
    scene = random_scene(1, 3, springs=True)
    scheme = build_scheme(scene, "vi", order=4)
    # Newton's unknowns are the increments alone: w_1 comes from the update
    assert scheme.metadata.method == "vi" and scheme.step.unknowns.shape[0] == 3
    assert scheme.order == 4


# -- compiled runs --------------------------------------------------------------------------

STRICT = {"update_rtol": 1e-15, "update_atol": 1e-15, "residual_tol": 1e-13}


@pytest.mark.compile
@pytest.mark.parametrize("n, seed", [(3, 11), (5, 12)])
@pytest.mark.slow
def test_compiled_run_converges_at_order_2_to_dop853(n, seed):
    """A random chain with routed springs, gravity, damping on every joint and constant
    torques on two: build_solver(scene, "vi") simulates, and the angle error at t = 1 s
    falls by 4 per halving of dt."""
    from chaingen.simulation import build_solver

    rng = np.random.default_rng(seed)
    plain = random_scene(seed, n, springs=True)
    scene = dataclasses.replace(plain, actuated=(1, n), links=tuple(
        dataclasses.replace(link, damping=float(d))
        for link, d in zip(plain.links, rng.uniform(0.0, 0.5, n))))
    u = rng.uniform(-1.0, 1.0, 2)
    torques = np.zeros(n)
    torques[[0, n - 1]] = u
    q0, w0 = rng.uniform(-1.0, 1.0, n), rng.uniform(-1.0, 1.0, n)
    expected = reference_run(scene, q0, w0, torques, 1.0)
    solver = build_solver(scene, "vi", sensitivities=False)
    errors = []
    for dt in (2e-3, 1e-3, 5e-4):
        steps = round(1.0 / dt)
        result = solver.simulate(q0, w0, dt=dt, n_steps=steps, every=steps,
                                 torques=np.tile(u, (steps, 1)))
        errors.append(np.abs(wrapped(result.phi[-1] - expected)).max())
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((3.7 <= ratios) & (ratios <= 4.3)), (errors, ratios)
    assert errors[-1] <= 1e-4, errors


@pytest.mark.compile
@pytest.mark.parametrize("gravity", [True, False])
def test_momentum_of_a_cyclic_first_joint_is_kept_to_round_off(gravity):
    """Gravity along the first joint's axis (or none), no spring on the base: the first
    angle is cyclic, and its momentum p_1 = (M(q) w)_1 (chaingen.spatial.dynamics) stays
    to round-off over 1000 steps, while the energy does not (so it was not free)."""
    from chaingen.simulation import build_solver

    scene = cyclic_scene(81, 4, gravity)
    assert len(scene.springs) >= 2
    rng = np.random.default_rng(81)
    q0, w0 = rng.uniform(-1.0, 1.0, 4), rng.uniform(-2.0, 2.0, 4)
    solver = build_solver(scene, "vi", sensitivities=False)
    result = solver.simulate(q0, w0, dt=2e-3, n_steps=1000, options=STRICT)
    momenta = np.array([(dynamics.mass_matrix(scene, q) @ w)[0]
                        for q, w in zip(result.phi, result.omega)])
    scale = np.abs(dynamics.mass_matrix(scene, q0)).max() * np.abs(w0).max()
    assert np.abs(momenta - momenta[0]).max() <= 1e-12 * scale, np.abs(momenta - momenta[0]).max()
    assert np.abs(result.energy_error).max() > 1e-8 * abs(result.energy[0])
    others = np.array([(dynamics.mass_matrix(scene, q) @ w)[1]
                       for q, w in zip(result.phi, result.omega)])
    assert np.abs(others - others[0]).max() > 1e-3 * scale


def momentum_jacobian(scene):
    """(q, w) -> d(q, p)/d(q, w), p = M(q) w by the momentum recursion: [[1, 0], [d(M w)/dq,
    M]], differentiated exactly by forward mode through the recursion's definitions (each
    one's partial derivatives by SymPy, chained numerically; substituting the definitions
    into one expression first grows it beyond use)."""
    n = scene.n
    angles = sp.symbols(f"q1:{n + 1}", real=True)
    rates = sp.symbols(f"w1:{n + 1}", real=True)
    variables = [*angles, *rates]
    defs = Definitions("j_")
    momentum, _ = spatial_recursion.momenta(
        scene, spatial_recursion.link_frames(scene, angles, defs), rates, defs)
    steps = []       # (symbol or None: a momentum, value, [(free symbol, partial)], free symbols)
    for symbol, expression in [*defs.items, *((None, m) for m in momentum)]:
        expression = sp.sympify(expression)
        free = sorted(expression.free_symbols, key=str)
        steps.append((symbol, sp.lambdify(free, expression, modules="numpy"),
                      [(x, sp.lambdify(free, sp.diff(expression, x), modules="numpy"))
                       for x in free], free))

    def at(q, w):
        values = dict(zip(variables, [*q, *w]))
        gradients = {x: row for x, row in zip(variables, np.eye(2 * n))}
        rows = []
        for symbol, value, partials, free in steps:
            arguments = [values[x] for x in free]
            gradient = sum((float(partial(*arguments)) * gradients[x] for x, partial in partials),
                           np.zeros(2 * n))
            if symbol is None:
                rows.append(gradient)
            else:
                values[symbol] = float(value(*arguments))
                gradients[symbol] = gradient
        return np.vstack([np.hstack([np.eye(n), np.zeros((n, n))]), np.array(rows)])

    return at


@pytest.mark.compile
@pytest.mark.slow
def test_step_map_is_symplectic_in_q_and_p():
    """The step's Jacobian in (q, w) from the step sensitivities, turned into (q, p) with
    p = M(q) w: J^T Omega J = Omega to round-off (a conservative chain with springs and
    gravity); the midpoint scheme's step, not a variational integrator, misses it."""
    from chaingen.simulation import build_solver

    scene = random_scene(91, 3, springs=True)
    n = scene.n
    to_momenta = momentum_jacobian(scene)
    omega = np.block([[np.zeros((n, n)), np.eye(n)], [-np.eye(n), np.zeros((n, n))]])
    rng = np.random.default_rng(91)
    q0, w0 = rng.uniform(-1.0, 1.0, n), rng.uniform(-2.0, 2.0, n)
    defects = {}
    for method in ("vi", "midpoint"):
        solver = build_solver(scene, method, sensitivities=True)
        sens = solver.step_sensitivities(solver.initial_state(q0, w0), dt=0.01, options=STRICT)
        q1, w1 = sens.x1[:n], sens.x1[n:]
        jacobian = (to_momenta(q1, w1) @ sens.ds_ds @ np.linalg.inv(to_momenta(q0, w0)))
        defects[method] = np.abs(jacobian.T @ omega @ jacobian - omega).max()
        assert np.abs(jacobian - np.eye(2 * n)).max() > 1e-2    # the step moved the chain
    assert defects["vi"] <= 1e-11, defects
    assert defects["midpoint"] > 1e-6, defects


@pytest.mark.compile
def test_conservative_energy_stays_bounded_over_10_s():
    """No damping, no inputs: the energy error is O(dt^2) and does not drift (the second five
    seconds err no more than the first)."""
    from chaingen.simulation import build_solver

    scene = random_scene(21, 4, springs=True)
    rng = np.random.default_rng(21)
    q0, w0 = rng.uniform(-1.0, 1.0, 4), rng.uniform(-1.0, 1.0, 4)
    solver = build_solver(scene, "vi", sensitivities=False)
    peaks = []
    for dt in (1e-3, 5e-4):
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
    """The flows are the scheme's own (tau . theta, d theta^2 / dt, theta recomputed from the
    samples), and the balance H - H_0 - work + dissipated is O(dt^2)."""
    from chaingen.simulation import build_solver

    plain = random_scene(31, 4, springs=True)
    damping = np.array([0.3, 0.0, 0.8, 0.2])
    scene = dataclasses.replace(plain, actuated=(1, 2, 4), links=tuple(
        dataclasses.replace(link, damping=float(d)) for link, d in zip(plain.links, damping)))
    solver = build_solver(scene, "vi", sensitivities=False)
    rng = np.random.default_rng(31)
    q0, w0 = rng.uniform(-1.0, 1.0, 4), rng.uniform(-1.0, 1.0, 4)
    errors = []
    for dt in (2e-3, 1e-3):
        steps = round(2.0 / dt)
        torques = rng.uniform(-2.0, 2.0, (steps, 3))
        result = solver.simulate(q0, w0, dt=dt, n_steps=steps, torques=torques)
        theta = wrapped(np.diff(result.phi, axis=0))
        work = np.cumsum((torques * theta[:, [0, 1, 3]]).sum(axis=1))
        dissipated = np.cumsum((damping * theta ** 2).sum(axis=1)) / dt
        np.testing.assert_allclose(result.input_work[1:], work, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(result.dissipated[1:], dissipated, rtol=1e-9, atol=1e-12)
        assert dissipated[-1] > 0.0 and abs(work[-1]) > 0.0
        errors.append(np.abs(result.balance_error).max())
    assert 3.0 <= errors[0] / errors[1] <= 5.0, errors


@pytest.mark.compile
@pytest.mark.slow
def test_sensitivities_and_generated_functions_pass_the_check():
    """chaingen check's comparisons on an actuated, damped spatial scene: the residual
    Jacobian and the step sensitivities against central differences, every generated function
    against the scheme's SymPy expressions."""
    passed_check(forced_scene(41, 4), "vi")


@pytest.mark.compile
@pytest.mark.slow
def test_composed_steps_of_order_4_and_6_converge_to_dop853():
    """The spatial vi step composed to order 4 and 6 (chaingen.symbolic.composition): the
    error at t = 1 s against DOP853 falls by 2^4 and 2^6 per halving of dt. The springs are
    a tenth of random_scene's: with them whole, the chain turns at up to 140 rad/s, and steps
    of 5 ms are outside the composition's asymptotic range."""
    from chaingen.simulation import build_solver

    plain = random_scene(51, 3, springs=True)
    scene = dataclasses.replace(plain, springs=tuple(
        dataclasses.replace(spring, stiffness=spring.stiffness / 10) for spring in plain.springs))
    rng = np.random.default_rng(51)
    q0, w0 = rng.uniform(-1.0, 1.0, 3), rng.uniform(-1.0, 1.0, 3)
    expected = reference_run(scene, q0, w0, np.zeros(3), 1.0)
    for order in (4, 6):
        solver = build_solver(scene, "vi", sensitivities=False, order=order)
        errors = []
        for dt in (5e-3, 2.5e-3):
            steps = round(1.0 / dt)
            result = solver.simulate(q0, w0, dt=dt, n_steps=steps, every=steps)
            errors.append(np.abs(wrapped(result.phi[-1] - expected)).max())
        assert 0.7 * 2 ** order <= errors[0] / errors[1] <= 1.3 * 2 ** order, (order, errors)


@pytest.mark.tools
@pytest.mark.parametrize("actuated", [(), (1, 3)])
@pytest.mark.slow
def test_spatial_vi_example_is_clean_under_valgrind_and_the_sanitizers(tmp_path, actuated):
    """The vi package of a spatial chain as a user gets it (free motion, and an actuated,
    damped chain): its example program, compiled with the strict flags, runs clean under
    memcheck and under ASan/UBSan (the Cholesky solve of the update among what they watch)."""
    require_tools("gcc", "valgrind")
    from chaingen.generate.package import generate_package, write_package

    plain = random_scene(121, 4, springs=True)
    scene = dataclasses.replace(plain, name="spatial-vi-example", actuated=actuated,
                                links=tuple(dataclasses.replace(link, damping=0.2)
                                            for link in plain.links))
    package = write_package(generate_package(scene, "vi", 3, sensitivities=False),
                            tmp_path / "package")
    for output in run_example_checked(package, tmp_path, "0.5"):
        assert ("final tracking error" in output) == bool(actuated), output
