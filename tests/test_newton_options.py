"""The Newton knobs of the generated step: warm start, simplified Newton (the Jacobian kept
across steps) and Newton-chord (evaluated once a step, or kept across chained steps).

Both change how a step reaches its solution, never which equations it solves: every variant
must agree with full Newton from the scheme's predictor within the Newton tolerances, and fail
loudly rather than return an unconverged state.
"""
from __future__ import annotations

import numpy as np
import pytest

from chaingen.runtime import (
    JACOBIAN_ACROSS_STEPS,
    JACOBIAN_CHORD_ACROSS_STEPS,
    JACOBIAN_EVERY_ITERATE,
    JACOBIAN_PER_STEP,
    NewtonError,
    NewtonOptions,
)

from helpers import load, solver_for

pytestmark = pytest.mark.compile

COLD = NewtonOptions(warm_start=False, reuse_jacobian=JACOBIAN_EVERY_ITERATE)
WARM = NewtonOptions(warm_start=True, reuse_jacobian=JACOBIAN_EVERY_ITERATE)
SIMPLIFIED = NewtonOptions(warm_start=True, reuse_jacobian=JACOBIAN_ACROSS_STEPS)
CHORD = NewtonOptions(warm_start=True, reuse_jacobian=JACOBIAN_PER_STEP)
KEPT_CHORD = NewtonOptions(warm_start=True, reuse_jacobian=JACOBIAN_CHORD_ACROSS_STEPS)
KEPT = pytest.mark.parametrize("kept", [SIMPLIFIED, CHORD, KEPT_CHORD],
                               ids=["simplified", "chord", "kept chord"])
METHODS = ("es", "vi", "midpoint")


def chained_steps(solver, x, dt, options, count):
    """`count` steps, each from the previous step's x1; returns the states and iterations."""
    states, iterations = [x], []
    for _ in range(count):
        result = solver.step(states[-1], dt=dt, options=options)
        states.append(result.x1)
        iterations.append(result.iterations)
    return states, iterations


def initial(solver, name="three_link_mono"):
    scene = load(name)
    return solver.initial_state(scene.initial_angles, scene.initial_velocities)


@pytest.mark.parametrize("method", METHODS)
def test_warm_start_saves_iterations_and_changes_nothing_else(method):
    solver = solver_for("three_link_mono", method)
    x0 = initial(solver)
    solver.reset()
    cold, cold_iterations = chained_steps(solver, x0, 0.01, COLD, 20)
    solver.reset()
    warm, warm_iterations = chained_steps(solver, x0, 0.01, WARM, 20)
    # From the fourth step on, the guess extrapolates three previous solutions.
    assert max(warm_iterations[3:]) < min(cold_iterations[3:])
    assert np.abs(np.array(warm) - np.array(cold)).max() < 1e-10


def test_warm_start_only_continues_its_own_trajectory():
    """A step from a state the workspace did not produce starts from the predictor."""
    solver = solver_for("three_link_mono", "es")
    x0 = initial(solver)
    solver.reset()
    cold = solver.step(x0, dt=0.01, options=COLD).iterations
    states, _ = chained_steps(solver, x0, 0.01, WARM, 5)
    assert solver.step(x0, dt=0.01, options=WARM).iterations == cold   # not chained: fresh start
    # Same state, other dt: not chained either.
    chained_steps(solver, x0, 0.01, WARM, 5)
    other_dt = solver.step(states[5], dt=0.005, options=WARM).iterations
    assert other_dt == solver.step(states[5], dt=0.005, options=COLD).iterations


def test_a_new_chain_on_a_used_workspace_steps_as_on_a_fresh_one():
    """A chain of steps from a state the workspace did not produce is a new trajectory on all
    its steps, not only its first: the warm start's choice measured on the old history (here the
    predictor, where simulate's run ended near rest) goes with it. Before, the chain's second
    step took that stale choice, and on four_link_pbc (dt = 0.02 s) the chain left simulate's
    run at round-off after 9 steps (1132 Newton iterations against 1133)."""
    scene = load("four_link_pbc")
    solver = solver_for("four_link_pbc", "es")
    run = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.02, n_steps=200)
    x = solver.initial_state(scene.initial_angles, scene.initial_velocities)
    iterations = 0
    for k in range(200):   # on the thread's workspace, right after simulate's run
        result = solver.step(x, dt=0.02)
        x, iterations = result.x1, iterations + result.iterations
        assert np.array_equal(solver.outputs(x)[0], run.phi[k + 1]), k + 1
    assert iterations == run.newton_iterations
    solver.reset()
    fresh, _ = chained_steps(solver, solver.initial_state(scene.initial_angles,
                                                          scene.initial_velocities),
                             0.02, None, 200)
    assert np.array_equal(fresh[-1], x)


def test_reset_forgets_the_history():
    solver = solver_for("three_link_mono", "es")
    x0 = initial(solver)
    states, _ = chained_steps(solver, x0, 0.01, WARM, 5)
    warm = solver.step(states[5], dt=0.01, options=WARM).iterations
    solver.reset()
    chained_steps(solver, x0, 0.01, WARM, 5)   # builds the same history ...
    solver.reset()                              # ... and forgets it
    assert solver.step(states[5], dt=0.01, options=WARM).iterations > warm


@KEPT
@pytest.mark.parametrize("method", METHODS)
def test_kept_jacobian_agrees_with_full_newton(method, kept):
    solver = solver_for("three_link_multi", method)
    scene = load("three_link_multi")
    full = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                           n_steps=1000, options=WARM)
    simplified = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                                 n_steps=1000, options=kept)
    assert np.abs(simplified.phi - full.phi).max() < 1e-7
    # Energy: the variant may not change the scheme's behaviour beyond the Newton tolerance.
    assert (np.abs(simplified.energy_error).max()
            <= np.abs(full.energy_error).max() + 1e-8)


@KEPT
@pytest.mark.parametrize("method", METHODS)
def test_kept_jacobian_survives_a_change_of_dt(method, kept):
    """After steps at one dt (and from another state) the kept factorisation is wrong for the
    next step; the step must still converge to the full-Newton solution."""
    solver = solver_for("three_link_mono", method)
    x0 = initial(solver)
    solver.reset()
    states, _ = chained_steps(solver, x0, 0.001, SIMPLIFIED, 3)
    for dt in (0.05, 0.001, 0.05):
        expected = solver.step(states[-1], dt=dt, options=COLD).x1
        result = solver.step(states[-1], dt=dt, options=kept)
        assert np.abs(result.x1 - expected).max() < 1e-8


@pytest.mark.parametrize("reuse", [JACOBIAN_ACROSS_STEPS, JACOBIAN_PER_STEP,
                                   JACOBIAN_CHORD_ACROSS_STEPS])
def test_kept_jacobian_reports_failure_instead_of_garbage(reuse):
    solver = solver_for("three_link_mono", "es")
    x0 = initial(solver)
    solver.reset()
    with pytest.raises(NewtonError, match="did not converge"):
        solver.step(x0, dt=0.01, options=NewtonOptions(reuse_jacobian=reuse, max_iterations=1))


@pytest.mark.parametrize("reuse", [-1, 4, 1.5, "chord"])
def test_an_unknown_jacobian_mode_is_refused(reuse):
    with pytest.raises(ValueError, match="reuse_jacobian: must be one of"):
        NewtonOptions(reuse_jacobian=reuse)


@pytest.mark.parametrize("options", [COLD, WARM, SIMPLIFIED, CHORD, KEPT_CHORD],
                         ids=["cold", "warm", "simplified", "chord", "kept chord"])
def test_simulate_does_not_depend_on_the_workspace_history(options):
    solver = solver_for("three_link_gravity", "es")
    scene = load("three_link_gravity")
    run = lambda: solver.simulate(scene.initial_angles, scene.initial_velocities,  # noqa: E731
                                  dt=0.01, n_steps=200, options=options)
    first = run()
    chained_steps(solver, initial(solver, "three_link_gravity"), 0.02, SIMPLIFIED, 4)
    assert np.array_equal(run().samples, first.samples)


def test_simplified_newton_keeps_es_energy_conservation():
    """Linear convergence leaves an error near the stopping threshold; the margin keeps es's
    energy balance (the Newton error enters it directly) far below the scheme's own bound.
    Without the margin, and with a contraction rate carried over from earlier steps, the
    standard run drifted to 3.6e-10 J."""
    solver = solver_for("three_link_mono", "es")
    scene = load("three_link_mono")
    result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                             n_steps=5000, options=SIMPLIFIED)
    assert np.abs(result.energy_error).max() < 1e-10


def test_simplified_newton_stops_at_the_round_off_floor():
    """From the scheme's predictor, where the updates shrink to round-off before the margin
    is met, simplified Newton must recognise the floor instead of running out of iterations
    (it did at step 1601 of this run before the floor test)."""
    solver = solver_for("three_link_mono", "es")
    scene = load("three_link_mono")
    result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                             n_steps=5000,
                             options=NewtonOptions(warm_start=False,
                                                   reuse_jacobian=JACOBIAN_ACROSS_STEPS))
    assert result.max_newton_iterations < 20
    assert np.abs(result.energy_error).max() < 1e-10


@pytest.mark.parametrize("name", ["three_link_gravity", "three_link_mono", "three_link_multi"])
def test_newton_chord_keeps_es_energy_at_full_newton_level(name):
    """Newton-chord (es's default) stops on a contraction measured within the step; from the
    warm start its chord update is at round-off, so es's energy balance must stay within a
    small factor of full Newton's on the standard run, in the same number of iterations.
    (Trajectories: test_kept_jacobian_agrees_with_full_newton; over 50 s the chain amplifies
    the 1e-12 differences of the Newton tolerance to 1e-7.)"""
    solver = solver_for(name, "es")
    scene = load(name)
    run = lambda options: solver.simulate(scene.initial_angles, scene.initial_velocities,  # noqa: E731
                                          dt=0.01, n_steps=5000, options=options)
    full = run(WARM)
    full_error = np.abs(full.energy_error).max()
    for options in (CHORD, KEPT_CHORD):
        chord = run(options)
        assert np.abs(chord.energy_error).max() <= max(10 * full_error, 1e-12)
        assert chord.mean_newton_iterations <= full.mean_newton_iterations + 0.05
