"""A running call owns its C workspace: calls made from its callbacks get workspaces of their own.

A progress callback that calls `outputs` and `step` on the Solver whose `simulate` it watches,
and a controller that calls `simulate` for a rollout, on the main thread and off it: the
run's samples are bit for bit those of the same run undisturbed, and the callbacks' own calls
give what they give alone (with no Newton history). Each scenario runs in a subprocess, since
calls sharing a workspace may crash the interpreter (they did: a segfault, or wrong samples).
"""
from __future__ import annotations

import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from chaingen.runtime.workspaces import Workspaces

DT = 0.01


def _solver():
    from chaingen import build_solver
    from chaingen.studies.bench.control import control_scene

    scene = control_scene()
    solver = build_solver(scene, "es", 3, sensitivities=False)
    return solver, np.array(scene.initial_angles, float), np.array(scene.initial_velocities,
                                                                   float)


def _progress_calls_outputs_and_step() -> None:
    solver, phi0, omega0 = _solver()
    n_steps, every = 400_000, 2_000
    alone = solver.simulate(phi0, omega0, dt=DT, n_steps=n_steps, every=every)
    probe = solver.initial_state(phi0 + 0.3, 1.0 - omega0)
    solver.reset()
    expected_outputs = solver.outputs(probe)
    solver.reset()
    expected_x1 = solver.step(probe, dt=DT).x1
    seen = []

    def progress(done: int) -> None:
        phi, omega, energy, error = solver.outputs(probe)
        x1 = solver.step(probe, dt=DT).x1
        seen.append((done, phi, omega, energy, error, x1))

    disturbed = solver.simulate(phi0, omega0, dt=DT, n_steps=n_steps, every=every,
                                progress=progress)
    assert any(0 < done < n_steps for done, *_ in seen), "no callback during the run"
    np.testing.assert_array_equal(disturbed.samples, alone.samples)
    assert disturbed.newton_iterations == alone.newton_iterations
    for _, phi, omega, energy, error, x1 in seen:
        np.testing.assert_array_equal(phi, expected_outputs[0])
        np.testing.assert_array_equal(omega, expected_outputs[1])
        assert (energy, error) == expected_outputs[2:]
        np.testing.assert_array_equal(x1, expected_x1)


def _controller_rolls_out_with_simulate() -> None:
    solver, phi0, omega0 = _solver()
    hold = solver.holding_torques(phi0)
    horizon = 10
    rollouts = []

    def law(phi, omega, rollout):
        return hold + 40.0 * (phi0 - rollout.phi[-1]) - 5.0 * rollout.omega[-1]

    def controller(t, phi, omega):
        rollout = solver.simulate(phi, omega, dt=DT, n_steps=horizon)
        x1 = solver.step(solver.initial_state(phi, omega), dt=DT).x1    # a step too
        rollouts.append((phi, omega, rollout.samples, x1))
        return law(phi, omega, rollout)

    closed = solver.simulate(phi0, omega0, dt=DT, n_steps=300, controller=controller)
    # the run is that of its torques, undisturbed ...
    replay = solver.simulate(phi0, omega0, dt=DT, n_steps=300, torques=closed.torques)
    np.testing.assert_array_equal(closed.samples, replay.samples)
    assert len(rollouts) == 300
    # ... and each rollout, and the torques chosen from it, are those computed afterwards
    for k in (0, 1, 2, 150, 299):
        phi, omega, samples, x1 = rollouts[k]
        np.testing.assert_array_equal(phi, closed.phi[k])
        again = solver.simulate(phi, omega, dt=DT, n_steps=horizon)
        np.testing.assert_array_equal(samples, again.samples)
        solver.reset()          # the callback's step had no Newton history either
        np.testing.assert_array_equal(x1, solver.step(solver.initial_state(phi, omega),
                                                      dt=DT).x1)
        np.testing.assert_array_equal(closed.torques[k], law(phi, omega, again))


SCENARIOS = {"progress": _progress_calls_outputs_and_step,
             "rollout": _controller_rolls_out_with_simulate}


def run(scenario: str, where: str) -> None:
    """Run a scenario on the main thread or in another one (the subprocess's entry)."""
    if where == "main":
        SCENARIOS[scenario]()
        return
    failures = []

    def target() -> None:
        try:
            SCENARIOS[scenario]()
        except BaseException as error:
            failures.append(error)

    thread = threading.Thread(target=target)
    thread.start()
    thread.join()
    if failures:
        raise failures[0]


@pytest.fixture(scope="module")
def built():
    """The solver built once in this process, so that the subprocesses load it from the
    cache."""
    return _solver()


@pytest.mark.compile
@pytest.mark.parametrize("where", ["main", "thread"])
@pytest.mark.parametrize("scenario", sorted(SCENARIOS))
def test_callbacks_calling_the_solver_leave_the_run_undisturbed(built, scenario, where):
    code = f"import test_reentrancy; test_reentrancy.run({scenario!r}, {where!r})"
    result = subprocess.run([sys.executable, "-c", code], cwd=Path(__file__).parent,
                            capture_output=True, text=True, timeout=600)
    died = (f" (killed by {signal.Signals(-result.returncode).name})"
            if result.returncode < 0 else "")
    assert result.returncode == 0, f"exit {result.returncode}{died}: {result.stderr[-3000:]}"


@pytest.mark.compile
def test_reset_inside_a_callback_is_refused(built):
    solver, phi0, omega0 = built
    errors = []

    def progress(done: int) -> None:
        try:
            solver.reset()
        except RuntimeError as error:
            errors.append(str(error))

    solver.simulate(phi0, omega0, dt=DT, n_steps=10, progress=progress)
    assert errors and "inside a callback" in errors[0]
    solver.reset()     # after the run, the thread's workspace is its own again


def test_a_leased_workspace_is_held_alone_until_released():
    initialised = []
    spaces = Workspaces(64, initialised.append)
    home, is_home = spaces.lease()
    assert is_home and initialised == [home] and spaces.home_busy()
    spare, is_home = spaces.lease()          # a call from a callback of the running one
    assert not is_home and spare is not home and initialised[-1] is spare
    deeper, _ = spaces.lease()
    assert deeper is not spare and deeper is not home
    spaces.release(deeper, False)
    spaces.release(spare, False)
    again, is_home = spaces.lease()          # a spare comes back with no Newton history
    assert again in (spare, deeper) and initialised[-1] is again and not is_home
    spaces.release(again, False)
    spaces.release(home, True)
    assert not spaces.home_busy()
    count = len(initialised)
    assert spaces.lease() == (home, True) and len(initialised) == count   # history kept
    spaces.release(home, True)
    other = []
    thread = threading.Thread(target=lambda: other.append(spaces.lease()))
    thread.start()
    thread.join()
    assert other[0][1] and other[0][0] is not home      # each thread has its own home

    def worker() -> None:        # simulate's worker, running a call for another thread
        spaces.serve()
        other.append(spaces.lease())

    thread = threading.Thread(target=worker)
    thread.start()
    thread.join()
    assert not other[1][1] and initialised[-1] is other[1][0]   # its callbacks get spares
