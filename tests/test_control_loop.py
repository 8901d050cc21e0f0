"""Closing the loop: simulate with a controller (a Python callable or a C function pointer),
the Stepper of a Python control loop, the step's C argument order, and the results as tables.

Each closed run is checked against the open run of the torques it recorded, bit for bit: the
controller only chooses the inputs, it does not change the step."""
from __future__ import annotations

import ctypes
import threading

import numpy as np
import pytest

from chaingen import NewtonError, build_solver, load_reference_scene
from chaingen.runtime import contract
from chaingen.studies.bench.control import GAINS, PdGains, _c_controller, control_scene

pytestmark = pytest.mark.compile

DT = 0.01


@pytest.fixture(scope="module", params=["es", "vi"])
def actuated(request):
    """three_link_mono with every joint actuated, and a PD about its initial posture."""
    scene = control_scene()
    solver = build_solver(scene, request.param, 3, sensitivities=False)
    reference = np.array(scene.initial_angles, dtype=float)
    omega0 = np.array(scene.initial_velocities, dtype=float)
    hold = solver.holding_torques(reference)
    kp, kd = GAINS

    def controller(t, phi, omega):
        return hold + kp * (reference - phi) - kd * omega + np.sin(3.0 * t)

    return solver, reference, omega0, hold, controller


def test_python_controller_equals_the_open_run_of_its_torques(actuated):
    solver, phi0, omega0, _, controller = actuated
    seen = []

    def recording(t, phi, omega):
        seen.append((t, phi))
        return controller(t, phi, omega)

    closed = solver.simulate(phi0, omega0, dt=DT, n_steps=300, controller=recording)
    assert closed.torques.shape == (300, 3) and len(seen) == 300
    replay = solver.simulate(phi0, omega0, dt=DT, n_steps=300, torques=closed.torques)
    np.testing.assert_array_equal(closed.samples, replay.samples)
    # the controller saw the state each step starts from, at its time, as a sample row has it
    for k in (0, 1, 150, 299):
        assert seen[k][0] == pytest.approx(k * DT, abs=1e-12)
        np.testing.assert_array_equal(seen[k][1], closed.phi[k])
    # and copies: keeping them is safe, and they differ from step to step
    assert not np.array_equal(seen[0][1], seen[299][1])
    np.testing.assert_array_equal(closed.torques[0],
                                  controller(0.0, closed.phi[0], closed.omega[0]))


def test_hold_keeps_the_torques_between_calls(actuated):
    solver, phi0, omega0, _, controller = actuated
    calls = []

    def counting(t, phi, omega):
        calls.append(t)
        return controller(t, phi, omega)

    result = solver.simulate(phi0, omega0, dt=DT, n_steps=100, controller=counting, hold=4)
    assert len(calls) == 25
    torques = result.torques
    for block in range(25):
        rows = torques[4 * block:4 * block + 4]
        np.testing.assert_array_equal(rows, np.repeat(rows[:1], 4, axis=0))
    assert not np.array_equal(torques[0], torques[4])


def test_c_controller_equals_the_same_law_in_python(actuated, tmp_path):
    solver, phi0, omega0, hold, _ = actuated
    kp, kd = GAINS
    gains = PdGains(n=3, kp=kp, kd=kd)
    gains.reference[:3] = phi0
    gains.hold[:3] = hold
    pd_control = _c_controller(tmp_path)

    def python_pd(t, phi, omega):
        return hold + kp * (phi0 - phi) - kd * omega

    by_c = solver.simulate(phi0, omega0, dt=DT, n_steps=400, controller=pd_control,
                           controller_context=ctypes.addressof(gains))
    by_python = solver.simulate(phi0, omega0, dt=DT, n_steps=400, controller=python_pd)
    np.testing.assert_allclose(by_c.torques, by_python.torques, rtol=0, atol=1e-12)
    np.testing.assert_allclose(by_c.samples, by_python.samples, rtol=0, atol=1e-12)
    # its address works as well as the ctypes function
    address = ctypes.cast(pd_control, ctypes.c_void_p).value
    again = solver.simulate(phi0, omega0, dt=DT, n_steps=400, controller=address,
                            controller_context=ctypes.addressof(gains))
    np.testing.assert_array_equal(again.samples, by_c.samples)


def test_controller_errors_stop_the_run_and_propagate(actuated):
    solver, phi0, omega0, _, controller = actuated
    calls = []

    def failing(t, phi, omega):
        calls.append(t)
        if len(calls) == 5:
            raise RuntimeError("sensor lost")
        return controller(t, phi, omega)

    with pytest.raises(RuntimeError, match="sensor lost"):
        solver.simulate(phi0, omega0, dt=DT, n_steps=100, controller=failing)
    assert len(calls) == 5                       # stopped at once, not run to the end
    with pytest.raises(ValueError, match="must return 3 finite torques"):
        solver.simulate(phi0, omega0, dt=DT, n_steps=10, controller=lambda t, p, w: [1.0, 2.0])
    with pytest.raises(ValueError, match="must return 3 finite torques"):
        solver.simulate(phi0, omega0, dt=DT, n_steps=10,
                        controller=lambda t, p, w: [np.nan, 0.0, 0.0])


def test_controller_arguments_are_checked(actuated):
    solver, phi0, omega0, _, controller = actuated
    with pytest.raises(ValueError, match="torques or a controller"):
        solver.simulate(phi0, omega0, dt=DT, n_steps=10, controller=controller,
                        torques=np.zeros((10, 3)))
    with pytest.raises(ValueError, match="hold must be an integer >= 1"):
        solver.simulate(phi0, omega0, dt=DT, n_steps=10, controller=controller, hold=0)
    with pytest.raises(ValueError, match="got 0 \\(NULL\\)"):
        solver.simulate(phi0, omega0, dt=DT, n_steps=10, controller=0)
    with pytest.raises(ValueError, match="a callable"):
        solver.simulate(phi0, omega0, dt=DT, n_steps=10, controller="pd")
    unactuated = build_solver(load_reference_scene("three_link_mono"), "es", 3,
                              sensitivities=False)
    with pytest.raises(ValueError, match="no actuated joints"):
        unactuated.simulate(phi0, omega0, dt=DT, n_steps=10, controller=controller)


def test_c_entry_point_refuses_null_controller_and_zero_hold(actuated):
    solver, phi0, omega0, _, _ = actuated
    x0 = solver.initial_state(phi0, omega0)
    samples = np.zeros((11, solver.nsample))
    bad_argument = next(s.code for s in contract.STATUSES if s.name == "BAD_ARGUMENT")
    pointer = ctypes.POINTER(ctypes.c_double)
    common = dict(x0=x0.ctypes.data_as(pointer), t0=0.0, dt=DT, n_steps=10, every=1,
                  context=None, p=None, options=None, workspace=solver._workspace,
                  samples=samples.ctypes.data_as(pointer), torques=None, x_final=None,
                  stats=None, control=None)
    assert solver._call("simulate_controlled", controller=None, hold=1,
                        **common) == bad_argument
    callback = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_long, ctypes.c_double, ctypes.c_void_p,
                                ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p)(
        lambda *arguments: 0)
    address = ctypes.cast(callback, ctypes.c_void_p).value
    assert solver._call("simulate_controlled", controller=address, hold=0,
                        **common) == bad_argument
    assert solver._call("simulate_controlled", controller=address, hold=1, **common) == 0


def test_stepper_equals_simulate_bit_for_bit(actuated):
    solver, phi0, omega0, _, controller = actuated
    closed = solver.simulate(phi0, omega0, dt=DT, n_steps=200, controller=controller)
    loop = solver.stepper(phi0, omega0, DT)
    np.testing.assert_array_equal(loop.phi, closed.phi[0])
    assert loop.energy == closed.energy[0]
    phi = loop.phi                                   # updated in place, not replaced
    for k in range(200):
        loop.step(controller(loop.t, loop.phi, loop.omega))
        np.testing.assert_array_equal(loop.phi, closed.phi[k + 1])
        np.testing.assert_array_equal(loop.omega, closed.omega[k + 1])
    assert phi is loop.phi and loop.t == pytest.approx(2.0)
    assert loop.energy == closed.energy[-1]
    assert loop.input_work == pytest.approx(closed.input_work[-1], rel=1e-12, abs=1e-15)
    # the state for the other entry points, and reset
    step = solver.step(loop.state, loop.u, DT)
    assert np.all(np.isfinite(step.x1))
    loop.reset(phi0, omega0)
    np.testing.assert_array_equal(loop.phi, closed.phi[0])   # the state's phi, as simulate's
    assert loop.t == 0.0 and loop.input_work == 0.0


def test_stepper_holds_u_and_takes_a_new_dt(actuated):
    solver, phi0, omega0, hold, _ = actuated
    loop = solver.stepper(phi0, omega0, DT)
    loop.u = hold
    for _ in range(10):
        loop.step()                                   # held: the chain stays where it is
    np.testing.assert_allclose(loop.phi, phi0, atol=1e-9)
    loop.dt = 0.005
    loop.step()
    assert loop.t == pytest.approx(0.105)
    with pytest.raises(ValueError, match="dt: must be > 0 and finite"):
        loop.dt = 0.0
    with pytest.raises(ValueError):
        loop.u = [1.0, 2.0]                           # three actuated joints


def test_stepper_failure_raises_and_keeps_the_state(actuated):
    solver, phi0, omega0, _, _ = actuated
    loop = solver.stepper(phi0, omega0, DT, options={"max_iterations": 1,
                                                      "reuse_jacobian": 0})
    before = loop.state
    with pytest.raises(NewtonError, match="step at t = 0 s failed"):
        loop.step([1e3, -1e3, 1e3])
    np.testing.assert_array_equal(loop.state, before)
    assert loop.t == 0.0


def test_steppers_in_threads_equal_their_runs_alone(actuated):
    solver, phi0, omega0, _, controller = actuated
    alone = solver.simulate(phi0, omega0, dt=DT, n_steps=300, controller=controller).phi[-1]
    finals = {}

    def run(index: int) -> None:
        loop = solver.stepper(phi0, omega0, DT)
        for _ in range(300):
            loop.step(controller(loop.t, loop.phi, loop.omega))
        finals[index] = loop.phi.copy()

    threads = [threading.Thread(target=run, args=(index,)) for index in range(4)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    for index in range(4):
        np.testing.assert_array_equal(finals[index], alone)


def test_step_takes_cs_argument_order(actuated):
    solver, phi0, omega0, hold, _ = actuated
    x0 = solver.initial_state(phi0, omega0)
    solver.reset()                      # step() carries the thread's Newton history (warm start)
    by_position = solver.step(x0, hold, DT)
    solver.reset()
    by_name = solver.step(x0, u=hold, dt=DT)
    np.testing.assert_array_equal(by_position.x1, by_name.x1)
    with pytest.raises(TypeError, match=r"needs dt.*step\(x0, u, dt\)"):
        solver.step(x0, hold)
    unactuated = build_solver(load_reference_scene("three_link_mono"), "es", 3,
                              sensitivities=False)
    y0 = unactuated.initial_state(phi0, omega0)
    with pytest.raises(TypeError, match="needs dt"):
        unactuated.step(y0, 0.01)                     # the old order (x0, dt) fails loudly
    with pytest.raises(ValueError, match="u must be None"):
        unactuated.step(y0, 0.01, 0.01)
    assert np.all(np.isfinite(unactuated.step(y0, dt=0.01).x1))


def test_results_as_dataframe_and_xarray(actuated):
    pytest.importorskip("pandas")
    pytest.importorskip("xarray")
    solver, phi0, omega0, _, controller = actuated
    result = solver.simulate(phi0, omega0, dt=DT, n_steps=20, every=5, controller=controller)
    frame = result.to_dataframe()
    assert list(frame.index) == pytest.approx([0.0, 0.05, 0.1, 0.15, 0.2])
    assert {"phi1", "omega3", "energy", "u1", "u3"} <= set(frame.columns)
    np.testing.assert_array_equal(frame["u2"].to_numpy()[:4], result.torques[:, 1])
    assert np.isnan(frame["u2"].to_numpy()[4])        # no step starts at the last sample
    assert frame.attrs["method"] == solver.manifest["method"]
    dataset = result.to_xarray()
    np.testing.assert_array_equal(dataset["phi"].sel(joint=2).to_numpy(), result.phi[:, 1])
    assert dataset["u"].dims == ("t", "actuated_joint")
    assert dataset["phi"].attrs["units"] == "rad" and dataset.attrs["n_steps"] == 20
