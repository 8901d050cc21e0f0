"""The embedded controller's entry point, control_torques (issue 34): the step `step` takes, and
the torque each actuated joint applies over it (EnergyFlows.applied_torques at the converged z).

Stand-in laws put into a scheme of scenes/four_link_actuated.toml (es, K = 3) with
DiscreteScheme.replaced(applied_torques=...) check the generated function and the runtime's
entry point against known expressions; the last test takes the schemes' own passivity law
(scenes/four_link_pbc*.toml, docs/controllers.md). The runtime's own suite
(runtime/c/tests, group control_torques) checks the refused split, the untouched outputs on
failure, the bad arguments and UNAVAILABLE for a composed step, also under valgrind and the
sanitizers (tests/test_c_runtime.py).
"""
from __future__ import annotations

import ctypes
import threading

import numpy as np
import pytest
import sympy as sp

from chaingen.generate.package import render_package
from chaingen.runtime import NewtonError, Solver
from chaingen.runtime.contract import STATUS_CODES
from chaingen.scene.solver_spec import SolverSpec
from chaingen.symbolic.schemes import build_scheme

from helpers import load, solver_for

pytestmark = pytest.mark.compile

SCENE = "four_link_actuated"
DT = 0.01


@pytest.fixture(scope="module")
def scheme():
    return build_scheme(SolverSpec.create(load(SCENE), "es", 3, sensitivities=False))


def controlled_solver(scheme, torques) -> Solver:
    """The package of `scheme` with applied_torques = `torques`, built and loaded."""
    package = render_package(scheme.replaced(applied_torques=sp.ImmutableMatrix(torques)),
                             sensitivities=False)
    assert package.manifest["control"] and package.manifest["entry_points"][
        "control_torques"]["available"]
    return Solver.from_files(package.files)


def nontrivial(scheme) -> list:
    """tau_j = u_j + z_j / dt + x0_j^2: in z, x0, u and dt."""
    z, x0, u, dt = (scheme.step.unknowns, scheme.maps.state, scheme.flows.inputs,
                    scheme.step.dt)
    return [u[j] + z[j] / dt + x0[j] ** 2 for j in range(len(u))]


@pytest.fixture(scope="module")
def identity_solver(scheme):
    return controlled_solver(scheme, list(scheme.flows.inputs))


@pytest.fixture(scope="module")
def nontrivial_solver(scheme):
    return controlled_solver(scheme, nontrivial(scheme))


def start(solver: Solver) -> np.ndarray:
    scene = load(SCENE)
    return solver.initial_state(scene.initial_angles, scene.initial_velocities)


def inputs(k: int) -> np.ndarray:
    return np.array([3.0 * np.sin(0.7 * k + j) for j in range(4)])


def test_with_the_inputs_as_torques_tau_is_u_and_x1_is_steps_bit_for_bit(identity_solver):
    """20 chained steps (warm starts): tau is u, and x1 and the iterations are those of step
    from the same workspace history (reset before each run), bit for bit; and those of the plain
    package's step (the model functions are the same)."""
    solver, plain = identity_solver, solver_for(SCENE, "es", 3)
    runs = {}
    for name, call in (("control", lambda x, k: solver.control_torques(x, inputs(k), DT)),
                       ("step", lambda x, k: solver.step(x, inputs(k), DT)),
                       ("plain", lambda x, k: plain.step(x, inputs(k), DT))):
        for each in (solver, plain):
            each.reset()
        x, states, iterations = start(solver), [], []
        for k in range(20):
            result = call(x, k)
            if name == "control":
                assert result.tau.dtype == float and result.tau.shape == (4,)
                assert np.array_equal(result.tau, inputs(k)), k
            x = result.x1
            states.append(x)
            iterations.append(result.iterations)
        runs[name] = (np.array(states), iterations)
    for name in ("step", "plain"):
        assert np.array_equal(runs["control"][0], runs[name][0]), name
        assert runs["control"][1] == runs[name][1], name
    assert max(runs["control"][1]) <= 6 and min(runs["control"][1]) >= 1


def converged_unknowns(scheme, solver: Solver, x0, u, dt) -> np.ndarray:
    """z with F(z; x0, u, dt) = 0 by Newton's method in Python on the scheme's own residual
    (SymPy's expressions evaluated by numpy), its Jacobian from the package (which only steers
    the iteration: the root is the numpy residual's), to round-off."""
    residual = scheme.step_function(list(scheme.step.residual))
    predictor = scheme.state_function(list(scheme.step.predictor), extra=[scheme.step.dt])
    z = np.array(predictor(*x0, dt), dtype=float).ravel()
    for _ in range(30):
        f = np.array(residual(*z, *x0, *u, dt), dtype=float).ravel()
        _, jacobian = solver.residual_jacobian(z, x0, u, dt)
        update = np.linalg.solve(jacobian, -f)
        z = z + update
        if np.abs(update).max() <= 1e-15 * max(1.0, np.abs(z).max()):
            break
    final = np.array(residual(*z, *x0, *u, dt), dtype=float).ravel()
    assert np.abs(final).max() < 1e-12, np.abs(final).max()
    return z


def test_a_law_in_z_x0_u_and_dt_is_evaluated_at_the_converged_step(scheme, nontrivial_solver):
    """tau_j = u_j + z_j / dt + x0_j^2 from C equals numpy's evaluation of the same SymPy
    expressions at the root of the scheme's residual found in Python, within 1e-12 relative,
    on a cold step and on warm-started ones; x1 is step's."""
    solver = nontrivial_solver
    law = scheme.step_function(nontrivial(scheme))
    solver.reset()
    x = start(solver)
    for k in range(4):
        u = inputs(k)
        result = solver.control_torques(x, u, DT)
        z = converged_unknowns(scheme, solver, x, u, DT)
        expected = np.array(law(*z, *x, *u, DT), dtype=float).ravel()
        assert np.abs(z[:4] / DT).max() > 1e-2 * np.abs(expected).max()   # z matters in tau
        np.testing.assert_allclose(result.tau, expected, rtol=1e-12, atol=0)
        x = result.x1
    solver.reset()
    x = start(solver)
    for k in range(4):
        x = solver.step(x, inputs(k), DT).x1
    np.testing.assert_array_equal(x, result.x1)


def test_a_package_without_a_control_law_refuses(scheme):
    """The plain package: the manifest says so, Python raises ValueError, and the C function,
    called with good arguments, returns UNAVAILABLE and writes nothing."""
    plain = solver_for(SCENE, "es", 3)
    assert plain.manifest["control"] is False
    assert plain.manifest["entry_points"]["control_torques"]["available"] is False
    assert not plain.has_entry_point("control_torques")
    x0 = start(plain)
    with pytest.raises(ValueError, match="no control law"):
        plain.control_torques(x0, np.zeros(4), DT)
    function = getattr(ctypes.CDLL(str(plain.library_path)), f"{plain.prefix}_control_torques")
    function.restype = ctypes.c_int
    double_p = ctypes.POINTER(ctypes.c_double)
    tau, x1, u = np.full(4, 7.0), np.full(plain.nx, 7.0), np.zeros(4)
    status = function(x0.ctypes.data_as(double_p), u.ctypes.data_as(double_p), ctypes.c_int(4),
                      None, ctypes.c_int(0), ctypes.c_double(DT), tau.ctypes.data_as(double_p),
                      x1.ctypes.data_as(double_p), None, plain._workspace, None)
    assert status == STATUS_CODES["UNAVAILABLE"]
    assert np.all(tau == 7.0) and np.all(x1 == 7.0)


def test_arguments_are_checked_as_steps(identity_solver):
    solver = identity_solver
    x0 = start(solver)
    with pytest.raises(TypeError, match="needs dt"):
        solver.control_torques(x0, np.zeros(4))
    with pytest.raises(ValueError, match="adaptive steps"):
        solver.control_torques(x0, np.zeros(4), DT, options={"rtol": 1e-6})
    with pytest.raises(ValueError, match="^dt: must be > 0 and finite"):
        solver.control_torques(x0, np.zeros(4), -DT)
    with pytest.raises(ValueError, match="^x0: must be finite"):
        solver.control_torques(np.full(solver.nx, np.nan), np.zeros(4), DT)
    # A NaN or Inf in x0 or u is a bad argument in every entry point that takes a step, before
    # any Newton iteration (step said NONFINITE after 10 iterations on a NaN x0, and a NaN u
    # came back NONFINITE or NOT_CONVERGED from both); the Python runtime names it first.
    bad_start = x0.copy()
    bad_start[1] = np.inf
    for take in (solver.step, solver.control_torques):
        for arguments, name in (((bad_start, np.zeros(4)), "x0"),
                                ((x0, np.array([0.0, np.nan, 0.0, 0.0])), "u")):
            with pytest.raises(ValueError, match=f"^{name}: must be finite"):
                take(*arguments, DT)
    double_p = ctypes.POINTER(ctypes.c_double)
    for state, u in ((bad_start, np.zeros(4)), (x0, np.array([0.0, np.nan, 0.0, 0.0]))):
        iterations, tau, x1 = ctypes.c_int(0), np.zeros(4), np.zeros(solver.nx)
        status = solver._call("control_torques", x0=state.ctypes.data_as(double_p),
                              u=u.ctypes.data_as(double_p), dt=DT,
                              tau=tau.ctypes.data_as(double_p), x1=x1.ctypes.data_as(double_p),
                              options=None, workspace=solver._workspace,
                              iterations=ctypes.byref(iterations))
        assert status == STATUS_CODES["BAD_ARGUMENT"]      # C's own refusal, before any work
        assert iterations.value == 0 and not x1.any() and not tau.any()
    # u omitted: zero torques, as step
    assert np.array_equal(solver.control_torques(x0, dt=DT).tau, np.zeros(4))


def test_a_step_that_step_splits_is_not_converged(identity_solver):
    """With at most 4 Newton iterations a rung, a cold step of 0.1 s fails whole: step takes
    it as halves (more iterations than the whole step's three rungs can spend), control_torques
    refuses it (NOT_CONVERGED). One of 0.05 s passes whole: both take it alike."""
    solver = identity_solver
    options = {"max_iterations": 4, "warm_start": False}
    x0 = start(solver)
    solver.reset()
    whole = solver.control_torques(x0, inputs(0), 0.05, options=options)
    assert whole.iterations == solver.step(x0, inputs(0), 0.05, options=options).iterations
    split = solver.step(x0, inputs(0), 0.1, options=options)
    assert split.iterations > 3 * options["max_iterations"]
    with pytest.raises(NewtonError) as failure:
        solver.control_torques(x0, inputs(0), 0.1, options=options)
    assert failure.value.status == STATUS_CODES["NOT_CONVERGED"]


def test_threads_get_their_own_workspaces(identity_solver):
    """Two threads chaining control_torques on one Solver get what each gets alone."""
    solver = identity_solver

    def run(offset: float, out: list) -> None:
        x = start(solver) + offset
        for k in range(30):
            x = solver.control_torques(x, inputs(k), DT).x1
        out.append(x)

    alone = []
    for offset in (0.0, 0.01):
        solver.reset()
        run(offset, alone)
    together: dict[float, list] = {0.0: [], 0.01: []}
    threads = [threading.Thread(target=run, args=(offset, together[offset]))
               for offset in together]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert np.array_equal(together[0.0][0], alone[0])
    assert np.array_equal(together[0.01][0], alone[1])


@pytest.mark.parametrize(("name", "method"), [("four_link_pbc", "es"),
                                              ("four_link_pbc_partial", "midpoint")])
def test_the_passivity_law_is_evaluated_at_the_converged_step(name, method):
    """The schemes' own law (a scene's [control] table, es and midpoint; all joints actuated and
    three of four): tau equals numpy's evaluation of the scheme's applied_torques at the root of
    its residual found in Python, within 1e-12 relative (measured: about 1e-15), over five
    warm-started steps, and x1 is step's bit for bit."""
    scene = load(name)
    scheme = build_scheme(SolverSpec.create(scene, method, 3, sensitivities=False))
    package = render_package(scheme, sensitivities=False)
    assert package.manifest["control"]
    solver = Solver.from_files(package.files)
    law = scheme.step_function(list(scheme.flows.applied_torques))
    u = np.zeros(solver.nu)
    x = solver.initial_state(scene.initial_angles, scene.initial_velocities)
    controlled = []
    for _ in range(5):
        result = solver.control_torques(x, u, DT)
        z = converged_unknowns(scheme, solver, x, u, DT)
        expected = np.array(law(*z, *x, *u, DT), dtype=float).ravel()
        assert np.abs(expected).max() > 0.1
        np.testing.assert_allclose(result.tau, expected, rtol=1e-12,
                                   atol=1e-12 * np.abs(expected).max())
        x = result.x1
        controlled.append(x)
    solver.reset()
    x = solver.initial_state(scene.initial_angles, scene.initial_velocities)
    for expected_x in controlled:
        x = solver.step(x, u, DT).x1
        assert np.array_equal(x, expected_x)


def test_a_controller_may_call_it_inside_a_running_simulate(identity_solver):
    """A Python controller that calls control_torques on the Solver whose simulate runs it: the
    run's samples are those of the same run undisturbed, and each call inside gives what it
    gives alone (a spare workspace, no Newton history)."""
    solver = identity_solver
    scene = load(SCENE)
    probe = start(solver) + 0.05
    solver.reset()
    lone = solver.control_torques(probe, inputs(1), DT)
    seen = []

    def quiet(t, phi, omega):
        return inputs(int(round(t / DT)))

    def probing(t, phi, omega):
        seen.append(solver.control_torques(probe, inputs(1), DT))
        return quiet(t, phi, omega)

    runs = [solver.simulate(scene.initial_angles, scene.initial_velocities, dt=DT, n_steps=30,
                            controller=controller) for controller in (quiet, probing)]
    np.testing.assert_array_equal(runs[1].samples, runs[0].samples)
    assert len(seen) == 30
    for call in seen:
        assert np.array_equal(call.tau, lone.tau) and np.array_equal(call.x1, lone.x1)
        assert call.iterations == lone.iterations
