"""The Python runtime against an adversary's inputs (issue 30, the review after its first fixes):
run-time parameters given as a mapping are read by name, never by position; a step of a given
dt refuses the adaptive tolerances it would ignore; one Stepper stepped by two threads at once
is a clear error, not wrong numbers; values that are no real numbers (complex, bool, strings)
are refused wherever the runtime turns a user's values into C doubles, and the Newton options'
switches take only a bool, 1 or 0."""
from __future__ import annotations

import re
import threading
import types

import numpy as np
import pytest

from chaingen.runtime import NewtonOptions, Solver
from chaingen.runtime.interface import real_array, real_number
from chaingen.runtime.parameters import parameter_bounds

from helpers import load, scene_path

DT = 0.01
PATHS = ("springs[0].stiffness", "links[1].mass")


def fake_solver(*, nu: int = 2) -> Solver:
    """A Solver's Python checks without a compiled library: every refusal here comes before
    C is called (a call that got through would fail on the missing library instead)."""
    solver = Solver.__new__(Solver)
    solver.prefix, solver.parameters = "fake", PATHS
    solver.default_parameters = np.array([10.0, 1.0])
    solver._bounds = parameter_bounds([{"path": path, "value": 1.0, "lower": 0.0,
                                        "lower_inclusive": path.startswith("springs")}
                                       for path in PATHS])
    solver.n, solver.nx, solver.nz, solver.nu, solver.nsample = 3, 6, 6, nu, 11
    solver.has_sensitivities, solver.energy_flows = True, False
    solver._entry_points = {"holding_torques": None}
    solver._workspace_size = 64
    solver.default_options = NewtonOptions()
    return solver


# -- 1: a mapping of parameters is read by name ----------------------------------------------

class KeysAndItems:
    """Neither a dict nor a Mapping: keys() and [] by label, as many labelled containers."""

    def __init__(self, values: dict):
        self._values = values

    def keys(self):
        return list(self._values)

    def __getitem__(self, key):
        return self._values[key]

    def __len__(self):
        return len(self._values)

    def __iter__(self):      # iterates its values, as a pandas Series does: a trap by position
        return iter(self._values.values())


def labelled_in_another_order():
    pd = pytest.importorskip("pandas")
    given = {"links[1].mass": 3.0, "springs[0].stiffness": 7.0}     # not PATHS' order
    return [dict(given), pd.Series(given), types.MappingProxyType(given), KeysAndItems(given)]


def test_a_series_or_mapping_of_parameters_is_read_by_name():
    solver = fake_solver()
    for given in labelled_in_another_order():
        np.testing.assert_array_equal(solver.parameter_values(given), [7.0, 3.0],
                                      err_msg=type(given).__name__)
    pd = pytest.importorskip("pandas")
    partial = pd.Series({"links[1].mass": 2.5})
    np.testing.assert_array_equal(solver.parameter_values(partial), [10.0, 2.5])


def test_labelled_parameters_that_cannot_be_read_by_name_are_refused():
    pd = pytest.importorskip("pandas")
    xr = pytest.importorskip("xarray")
    solver = fake_solver()
    twice = pd.Series([3.0, 4.0], index=["links[1].mass", "links[1].mass"])
    with pytest.raises(ValueError, match=r"^parameters: links\[1\]\.mass given twice$"):
        solver.parameter_values(twice)
    with pytest.raises(ValueError, match=r"^fake has no parameter 0 "):
        solver.parameter_values(pd.Series([7.0, 3.0]))      # labels 0, 1: no key paths
    array = xr.DataArray([3.0, 7.0], coords={"path": ["links[1].mass", "springs[0].stiffness"]})
    structured = np.array([(3.0, 7.0)], dtype=[("links[1].mass", float),
                                               ("springs[0].stiffness", float)])[0]
    for given in (array, structured):
        with pytest.raises(TypeError, match="would be read by position, not by its labels"):
            solver.parameter_values(given)
    np.testing.assert_array_equal(solver.parameter_values((7.0, 3.0)), [7.0, 3.0])
    np.testing.assert_array_equal(solver.parameter_values(np.array([7.0, 3.0])), [7.0, 3.0])


@pytest.mark.compile
def test_simulate_reads_a_series_of_parameters_by_name():
    from chaingen import build_solver

    scene = load("three_link_mono")
    solver = build_solver(scene, "es", 3, sensitivities=False, parameters=list(PATHS))
    phi0, omega0 = scene.initial_angles, scene.initial_velocities
    by_dict = solver.simulate(phi0, omega0, dt=DT, n_steps=20,
                              parameters={"springs[0].stiffness": 7.0, "links[1].mass": 3.0})
    for given in labelled_in_another_order():
        run = solver.simulate(phi0, omega0, dt=DT, n_steps=20, parameters=given)
        assert run.parameters == {"springs[0].stiffness": 7.0, "links[1].mass": 3.0}
        np.testing.assert_array_equal(run.samples, by_dict.samples)
        stepper = solver.stepper(phi0, omega0, DT, parameters=given)
        np.testing.assert_array_equal(stepper._p_values, [7.0, 3.0])


# -- 2: a step of the given dt refuses adaptive tolerances ------------------------------------

@pytest.mark.parametrize("options", [{"rtol": 1e-8}, {"atol": 1e-10},
                                     NewtonOptions(rtol=1e-8, atol=1e-10)])
def test_a_step_refuses_the_adaptive_tolerances_it_would_ignore(options):
    solver = fake_solver()
    x0, u = np.zeros(6), np.zeros(2)
    calls = {"step": lambda: solver.step(x0, u, DT, options=options),
             "step_sensitivities": lambda: solver.step_sensitivities(x0, u, DT, options=options),
             "Stepper": lambda: solver.stepper(np.zeros(3), np.zeros(3), DT, options=options)}
    for name, call in calls.items():
        with pytest.raises(ValueError, match=rf"^{name}: rtol and atol \(adaptive steps\) apply "
                                             r"to simulate only; .*\(got rtol="):
            call()


@pytest.mark.compile
def test_a_real_step_and_stepper_refuse_tolerances_and_simulate_takes_them():
    scene = load("three_link_mono")
    solver = _plain_solver()
    phi0, omega0 = scene.initial_angles, scene.initial_velocities
    x0 = solver.initial_state(phi0, omega0)
    tolerances = {"rtol": 1e-8, "atol": 1e-10}
    with pytest.raises(ValueError, match="^step: rtol and atol"):
        solver.step(x0, dt=0.5, options=tolerances)
    with pytest.raises(ValueError, match="^Stepper: rtol and atol"):
        solver.stepper(phi0, omega0, 0.5, options=tolerances)
    fixed = solver.step(x0, dt=0.5, options={"rtol": 0.0, "atol": 0.0})
    np.testing.assert_array_equal(fixed.x1, solver.step(x0, dt=0.5).x1)
    adaptive = solver.simulate(phi0, omega0, dt=0.5, n_steps=1, options=tolerances)
    assert adaptive.adaptive and adaptive.accepted_steps > 1


def _plain_solver():
    from chaingen import build_solver
    return build_solver(load("three_link_mono"), "es", 3, sensitivities=False,
                        parameters=["links[1].mass"])


# -- 3: one Stepper, two threads at once ---------------------------------------------------

@pytest.mark.compile
def test_one_stepper_stepped_by_two_threads_at_once_is_an_error_not_wrong_numbers():
    scene = load("three_link_mono")
    solver = _plain_solver()
    phi0, omega0 = scene.initial_angles, scene.initial_velocities
    stepper = solver.stepper(phi0, omega0, DT)
    start, errors = threading.Barrier(2), []

    def work() -> None:
        start.wait()
        try:
            for _ in range(50_000):
                stepper.step()
                if errors:
                    return
        except RuntimeError as error:
            errors.append(error)

    threads = [threading.Thread(target=work) for _ in range(2)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert errors, "two threads stepped one Stepper at once with no error"
    assert str(errors[0]) == (f"{solver.prefix} Stepper: used by two threads at once (a Stepper "
                              "is for one thread at a time: make one per thread)")
    # The steps that were taken were taken one at a time: the numbers of one thread alone.
    alone = solver.stepper(phi0, omega0, DT)
    for _ in range(stepper._count):
        alone.step()
    np.testing.assert_array_equal(stepper.phi, alone.phi)
    np.testing.assert_array_equal(stepper.omega, alone.omega)
    assert stepper.t == alone.t
    stepper.step()         # free again once the other thread is done


@pytest.mark.compile
def test_torques_assigned_from_another_thread_during_a_step_hold_from_the_next_step():
    """A controller thread assigns u while the loop thread's step is under way (the panda's 7
    joints, midpoint at order 6, full Newton at dt = 0.05 s: a step of about 0.4 ms, in C with
    the GIL released). The step under way keeps the torques it began with, bit for bit those
    of the same step taken alone, and the new torques hold from the next step. Before, the C
    step read u where the assignment wrote it: its later Newton iterations solved with the new
    torques, a step with neither torques and no error (measured: 0.043 and 0.555 rad from the
    step with the torques it began with, in the 2 of 30 steps the assignment landed in; the
    first also 0.51 rad from the new torques' step, a mix of both). The assignment lands
    during the step when the controller thread gets a core while the step runs: up to 500
    tries for 5 such steps."""
    from chaingen import build_solver
    from chaingen.spatial import load_spatial_scene

    scene = load_spatial_scene(scene_path("panda_springs"))
    solver = build_solver(scene, "midpoint", order=6, sensitivities=False)
    options = NewtonOptions(reuse_jacobian=0)
    phi0, omega0, dt = np.array(scene.initial_angles), np.array(scene.initial_velocities), 0.05
    first, new = np.zeros(solver.nu), np.full(solver.nu, 2.0)
    stepper = solver.stepper(phi0, omega0, dt, options=options)
    alone = solver.stepper(phi0, omega0, dt, options=options)
    tokens = stepper._take_token.__self__      # empty while a step holds it
    landed = attempts = 0
    while landed < 5 and attempts < 500:      # the machine's other load may hold a core
        attempts += 1
        stepper.reset(phi0, omega0)
        alone.reset(phi0, omega0)
        stepper.u = alone.u = first
        stepper.step()      # the torques assigned before a step are that step's
        alone.step()
        go, finished, seen = threading.Event(), threading.Event(), []

        def controller(go=go, finished=finished, seen=seen) -> None:
            go.wait()
            while tokens and not finished.is_set():
                pass        # until the loop thread's step holds the token
            stepper.u = new
            seen.append(not tokens)     # still under way after the assignment

        thread = threading.Thread(target=controller)
        thread.start()
        go.set()
        stepper.step()
        finished.set()
        thread.join()
        alone.step()
        if seen[0]:
            landed += 1
            np.testing.assert_array_equal(stepper.phi, alone.phi)
            np.testing.assert_array_equal(stepper.omega, alone.omega)
        np.testing.assert_array_equal(stepper.u, new)       # held from the next step on
        alone.u = new
        stepper.step()
        alone.step()
        np.testing.assert_array_equal(stepper.phi, alone.phi)
    assert landed == 5, f"the assignment landed during {landed} of {attempts} steps"


# -- 4: values that are no real numbers --------------------------------------------------

NOT_REAL = [(1 + 2j, "complex"), (np.complex128(1.0), "complex"), (True, "bool"),
            (np.True_, "bool"), ("2.0", "str"), (b"2", "bytes")]


@pytest.mark.parametrize("value, kind", NOT_REAL)
def test_the_one_conversion_refuses_what_is_no_real_number(value, kind):
    with pytest.raises(TypeError, match=rf"^dt: must be a real number, got .*{kind}") as refused:
        real_number(value, "dt")
    assert "\n" not in str(refused.value)
    for values in ([0.5, value, 1.0], (0.5, [value]), np.array([0.5, value], dtype=object)):
        with pytest.raises(TypeError, match=rf"^phi: must be real numbers, got .*{kind}"):
            real_array(values, "phi")
    with pytest.raises(TypeError, match="^phi: must be real numbers"):
        real_array(np.array([value, value]), "phi")        # an array of that dtype
    assert real_number(np.float32(0.5), "dt") == 0.5 and real_number(3, "dt") == 3.0
    np.testing.assert_array_equal(real_array([1, 2.5, np.int8(3)], "phi"), [1.0, 2.5, 3.0])


def test_none_is_no_number():
    """numpy takes None as NaN: a missing value would run as one."""
    for values in (None, [0.1, None], np.array([0.1, None], dtype=object)):
        with pytest.raises(TypeError, match="^phi: must be real numbers, got NoneType None$"):
            real_array(values, "phi")
    with pytest.raises(TypeError, match=r"^links\[1\]\.mass: must be a real number, got None"):
        fake_solver().parameter_values({"links[1].mass": None})


@pytest.mark.parametrize("value, kind", NOT_REAL)
def test_every_entry_point_refuses_values_that_are_no_real_numbers(value, kind):
    solver = fake_solver()
    good, bad = np.zeros(3), [0.1, value, 0.3]
    x0, z = np.zeros(6), np.zeros(6)
    calls = {
        "phi": [lambda: solver.initial_state(bad, good), lambda: solver.holding_torques(bad)],
        "phi0": [lambda: solver.simulate(bad, good, dt=DT, n_steps=3)],
        "omega0": [lambda: solver.simulate(good, bad, dt=DT, n_steps=3)],
        "phidot": [lambda: solver.initial_state(good, bad)],
        "x": [lambda: solver.outputs([0.0] * 5 + [value])],
        "x0": [lambda: solver.step([0.0] * 5 + [value], dt=DT)],
        "z": [lambda: solver.residual([value] * 6, x0, dt=DT),
              lambda: solver.residual_jacobian([value] * 6, x0, dt=DT)],
        "u": [lambda: solver.step(x0, [0.0, value], DT),
              lambda: solver.step_sensitivities(x0, [0.0, value], DT)],
        "torques": [lambda: solver.simulate(good, good, dt=DT, n_steps=2,
                                            torques=[[0.0, 0.0], [value, 0.0]])],
        "dt": [lambda: solver.step(x0, dt=value), lambda: solver.residual(z, x0, dt=value),
               lambda: solver.simulate(good, good, dt=value, n_steps=3),
               lambda: solver.stepper(good, good, value)],
        "links\\[1\\].mass": [lambda: solver.parameter_values({"links[1].mass": value}),
                              lambda: solver.step(x0, dt=DT,
                                                  parameters={"links[1].mass": value})],
        "parameters": [lambda: solver.parameter_values([10.0, value]),
                       lambda: solver.initial_state(good, good, [value, 1.0])],
    }
    for name, refused in calls.items():
        for call in refused:
            with pytest.raises(TypeError, match=rf"^{name}: must be (real numbers|a real "
                                                rf"number), got"):
                call()


def test_counts_refuse_a_bool():
    solver = fake_solver()
    for counts in ({"n_steps": True}, {"n_steps": 3, "every": True},
                   {"n_steps": 3, "hold": True}):
        with pytest.raises(ValueError, match=r"^n_steps, every and hold must be integers, got"):
            solver.simulate(np.zeros(3), np.zeros(3), dt=DT, **counts)


@pytest.mark.parametrize("value", ["no", "off", "", 2, -1, 0.0, 1.0, None, [1]])
def test_a_newton_switch_takes_a_bool_1_or_0(value):
    with pytest.raises(TypeError, match=r"^NewtonOptions\.warm_start: must be True or False"):
        NewtonOptions(warm_start=value)
    with pytest.raises(TypeError, match=r"^NewtonOptions\.warm_start: must be True or False"):
        fake_solver().newton_options({"warm_start": value})


def test_newton_options_keep_their_types():
    for value, expected in ((True, 1), (False, 0), (1, 1), (0, 0), (np.int64(0), 0)):
        options = NewtonOptions(warm_start=value)
        assert options.warm_start is bool(expected)
        assert options.as_c().warm_start == expected
    assert fake_solver().newton_options({"warm_start": 0}).warm_start is False
    for bad in (2.5, "20", 20.0):
        with pytest.raises(TypeError, match=r"^NewtonOptions\.max_iterations: must be an integer"):
            fake_solver().newton_options({"max_iterations": bad})
    for bad in (True, "1e-8", 1e-8 + 0j):
        with pytest.raises(TypeError, match=r"^NewtonOptions\.residual_tol: must be a real"):
            NewtonOptions(residual_tol=bad)
    with pytest.raises(TypeError, match=r"^NewtonOptions\.rtol: must be a real"):
        fake_solver().newton_options({"rtol": "1e-6"})
    options = fake_solver().newton_options({"max_iterations": np.int32(7), "residual_tol": 1})
    assert options.max_iterations == 7 and type(options.residual_tol) is float


@pytest.mark.parametrize("dt", [-0.01, 0.0, -0.0, np.nan, np.inf, -np.inf, 1e-320 * 0])
def test_a_dt_that_is_not_positive_and_finite_is_refused_naming_it(dt):
    """C refuses such a dt as a 'bad argument': simulate said 'step 1 (t = -0 s -> -0.01 s)
    failed after 0 Newton iterations: bad argument' (a NewtonError, a failed run), step
    'step failed after 0 Newton iterations: bad argument'; no entry point integrates
    backwards. A Stepper already refused it so."""
    solver, x0 = fake_solver(), np.zeros(6)
    for call in (lambda: solver.step(x0, dt=dt), lambda: solver.residual(x0, x0, dt=dt),
                 lambda: solver.residual_jacobian(x0, x0, dt=dt),
                 lambda: solver.step_sensitivities(x0, dt=dt),
                 lambda: solver.control_torques(x0, dt=dt),
                 lambda: solver.simulate(np.zeros(3), np.zeros(3), dt=dt, n_steps=3)):
        with pytest.raises(ValueError, match=r"^dt: must be > 0 and finite, got ") as refused:
            call()
        assert "\n" not in str(refused.value)


@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_a_nan_or_inf_in_a_state_posture_or_input_is_refused_naming_it(bad):
    """C refuses them as a 'bad argument' (simulate from a NaN angle: 'three_link_mono_es_
    initial_state: bad argument', naming no argument), and simulate's torques were not looked
    at: a NaN in row 1 failed step 2 after 11 Newton iterations with 'NaN or Inf in the
    residual or the Newton iterate' (four_link_actuated, vi, measured)."""
    solver, good, x0 = fake_solver(), np.zeros(3), np.zeros(6)
    spoilt = np.array([0.1, bad, 0.3])
    state = np.zeros(6)
    state[4] = bad
    calls = {
        "phi": [lambda: solver.initial_state(spoilt, good), lambda: solver.holding_torques(spoilt)],
        "phidot": [lambda: solver.initial_state(good, spoilt)],
        "phi0": [lambda: solver.simulate(spoilt, good, dt=DT, n_steps=3)],
        "omega0": [lambda: solver.simulate(good, spoilt, dt=DT, n_steps=3)],
        "x": [lambda: solver.outputs(state)],
        "x0": [lambda: solver.step(state, dt=DT), lambda: solver.residual(x0, state, dt=DT),
               lambda: solver.step_sensitivities(state, dt=DT)],
        "u": [lambda: solver.step(x0, [0.0, bad], DT),
              lambda: solver.step_sensitivities(x0, [bad, 0.0], DT)],
        "torques": [lambda: solver.simulate(good, good, dt=DT, n_steps=2,
                                            torques=[[0.0, 0.0], [0.0, bad]])],
    }
    for name, refused in calls.items():
        for call in refused:
            with pytest.raises(ValueError, match=rf"^{name}: must be finite, got {bad!r} at "
                                                 rf"\[[0-9, ]+\]$"):
                call()
    with pytest.raises(ValueError, match=r"^torques: must be finite, got .* at \[1, 1\]$"):
        solver.simulate(good, good, dt=DT, n_steps=2, torques=[[0.0, 0.0], [0.0, bad]])


def test_a_package_without_parameters_refuses_any_given_in_one_line():
    """A scalar got 'object of type 'float' has no len()' (naming nothing)."""
    solver = fake_solver()
    solver.parameters = ()
    for given in (0.0, np.float64(2.0), [1.0], {"links[1].mass": 2.0}, np.array(1.0)):
        with pytest.raises(ValueError, match="^fake takes no parameters$"):
            solver.initial_state(np.zeros(3), np.zeros(3), given)
    for nothing in (None, [], {}, (), np.zeros(0)):
        assert solver._p(nothing) is None


@pytest.mark.parametrize("override, message", [
    ({"every": 0}, "--every: must be an integer >= 1, got 0"),
    ({"every": 2.5}, "--every: must be an integer >= 1, got 2.5"),
    ({"every": True}, "--every: must be an integer >= 1, got True"),
    ({"dt": True}, "--dt: must be a real number, got bool True"),
    ({"t_end": "1"}, "--t-end: must be a real number, got str '1'"),
    ({"dt": -0.01}, "--dt: must be > 0 and finite, got -0.01"),
])
def test_run_settings_refuses_counts_and_times_that_are_none(override, message):
    """every = 0 was an internal ZeroDivisionError, every = 2.5 and True and dt = True (a
    step of 1 s) passed; a string t_end was 'must be real number, not str', naming nothing."""
    import chaingen
    from chaingen.errors import SettingsError

    with pytest.raises(SettingsError, match=f"^{re.escape(message)}$"):
        chaingen.run_settings(load("three_link_mono"), **{"t_end": 1.0, **override})
    settings = chaingen.run_settings(load("three_link_mono"), dt=np.float64(0.01), t_end=1,
                                     every=np.int64(10))
    assert (type(settings.dt), type(settings.t_end), type(settings.every)) == (float, float, int)
    assert settings.n_steps == 100


OUT_OF_RANGE = [("max_iterations", 0, ">= 1"), ("max_iterations", -1, ">= 1"),
                ("residual_tol", 0.0, "> 0 and finite"), ("residual_tol", np.nan, "> 0 and finite"),
                ("residual_tol", np.inf, "> 0 and finite"), ("update_atol", 0.0, "> 0 and finite"),
                ("update_rtol", -1e-10, ">= 0 and finite"), ("update_rtol", np.inf,
                                                              ">= 0 and finite"),
                ("energy_tol", -1.0, ">= 0 and finite"), ("energy_tol", np.nan, ">= 0 and finite")]


@pytest.mark.parametrize("name, value, rule", OUT_OF_RANGE)
def test_newton_options_out_of_their_range_are_refused_as_bad_input(name, value, rule, tmp_path):
    """Each of these made every step fail (a run failed at step 1, exit 1): no iteration at
    all (max_iterations 0 or -1: 'did not converge' after 0 iterations), a residual never <= 0,
    an update weight 1 / (update_atol + update_rtol |z|) infinite where an unknown is 0
    (update_atol 0: 'NaN or Inf in the residual or the Newton iterate' after 10 iterations on
    three_link_mono, es), 45 iterations on residual_tol NaN; a negative or NaN energy_tol came
    back as C's 'bad argument'. The command line took tolerances of 0 too."""
    message = rf"^NewtonOptions\.{name}: must be {rule}, got "
    with pytest.raises(ValueError, match=message):
        NewtonOptions(**{name: value})
    with pytest.raises(ValueError, match=message):
        fake_solver().newton_options({name: value})
    if not np.isfinite(value) and name != "max_iterations":
        return
    from helpers import ROOT, chaingen_in_process
    result = chaingen_in_process("simulate", ROOT / "scenes" / "three_link_mono.toml",
                                 f"--{name.replace('_', '-')}={value}", "--out",
                                 tmp_path / "run.csv", cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert f"must be {rule}" in result.stderr, result.stderr
    assert not (tmp_path / "run.csv").exists()


def test_an_integer_newton_option_takes_no_bool():
    """max_iterations=True ran as 1 iteration a rung (a run failed on it), and
    reuse_jacobian=True as simplified Newton (mode 1), without a word."""
    for name in ("max_iterations", "reuse_jacobian"):
        for value in (True, np.True_, False):
            with pytest.raises(TypeError, match=rf"^NewtonOptions\.{name}: must be an integer"):
                NewtonOptions(**{name: value})
    assert NewtonOptions(reuse_jacobian=np.int64(1)).as_c().reuse_jacobian == 1
    assert NewtonOptions(update_rtol=0, energy_tol=0).as_c().update_rtol == 0.0


@pytest.mark.compile
def test_a_stepper_and_a_controller_refuse_values_that_are_no_real_numbers():
    from chaingen import build_solver
    from chaingen.studies.bench.control import control_scene

    scene = control_scene()
    solver = build_solver(scene, "es", 3, sensitivities=False)
    phi0, omega0 = np.array(scene.initial_angles), np.array(scene.initial_velocities)
    stepper = solver.stepper(phi0, omega0, DT)
    before = stepper.phi.copy()
    for bad in (np.array([1.0, 2.0, 3.0 + 1j]), [1.0, True, 0.0], ["1", "2", "3"],
                np.array([True, False, True])):
        with pytest.raises(TypeError, match="^u: must be real numbers, got"):
            stepper.step(bad)
        with pytest.raises(TypeError, match="^u: must be real numbers, got"):
            stepper.u = bad
    for bad in (True, "0.01", 0.01 + 0j):
        with pytest.raises(TypeError, match="^dt: must be a real number"):
            stepper.dt = bad
    with pytest.raises(TypeError, match="^t: must be a real number"):
        stepper.reset(phi0, omega0, t=1j)
    with pytest.raises(TypeError, match="^phi: must be real numbers"):
        stepper.reset(phi0 + 0j, omega0)
    np.testing.assert_array_equal(stepper.phi, before)
    assert stepper.dt == DT and stepper.t == 0.0
    stepper.step(np.array([1, 2, 3]))       # integers are real numbers
    np.testing.assert_array_equal(stepper.u, [1.0, 2.0, 3.0])
    with pytest.raises(TypeError, match="^controller: its torques: must be real numbers, got "
                                        "complex"):
        solver.simulate(phi0, omega0, dt=DT, n_steps=5,
                        controller=lambda t, phi, omega: [0.0, 1j, 0.0])
    with pytest.raises(TypeError, match="^omega0: must be real numbers"):
        solver.simulate(phi0, omega0 * 1j, dt=DT, n_steps=5)


@pytest.mark.compile
def test_a_result_holds_its_own_torques_and_a_stepper_names_a_nan():
    """result.torques was a view of the torques given to simulate (the same array with every
    = 1, a strided view of it otherwise): changing that array after the run changed the
    result the caller held. A Stepper given a NaN torque or angle said 'bad argument'
    (or, from reset, named phidot for omega); hold as a numpy integer was refused."""
    from chaingen import build_solver
    from chaingen.studies.bench.control import control_scene

    scene = control_scene()
    solver = build_solver(scene, "es", 3, sensitivities=False)
    phi0, omega0 = np.array(scene.initial_angles), np.array(scene.initial_velocities)
    for every in (1, 2):
        given = np.arange(15.0).reshape(5, 3) / 100
        result = solver.simulate(phi0, omega0, dt=DT, n_steps=5, every=every, torques=given)
        kept = result.torques.copy()
        np.testing.assert_array_equal(kept, given[::every])
        given[:] = 7.0
        assert not np.shares_memory(result.torques, given)
        np.testing.assert_array_equal(result.torques, kept)
        replay = solver.simulate(phi0, omega0, dt=DT, n_steps=5, every=every,
                                 torques=np.arange(15.0).reshape(5, 3) / 100)
        np.testing.assert_array_equal(replay.samples, result.samples)
    stepper = solver.stepper(phi0, omega0, DT)
    before = stepper.phi.copy()
    with pytest.raises(ValueError, match=r"^u: must be finite, got nan at \[1\]$"):
        stepper.step(np.array([0.0, np.nan, 0.0]))
    np.testing.assert_array_equal(stepper.phi, before)
    assert stepper.t == 0.0
    with pytest.raises(ValueError, match=r"^omega: must be finite, got inf at \[2\]$"):
        stepper.reset(phi0, [0.0, 0.0, np.inf])
    with pytest.raises(ValueError, match=r"^phi: must be finite, got nan at \[0\]$"):
        solver.stepper([np.nan, 0.0, 0.0], omega0, DT)
    for t in (np.nan, np.inf):      # taken: every later t was NaN or Inf
        with pytest.raises(ValueError, match=r"^t: must be finite, got (nan|inf)$"):
            stepper.reset(phi0, omega0, t=t)
    stepper.step(np.zeros(3))
    assert stepper.t == DT
    # A package without run-time parameters: a Stepper ran with the scene's own numbers
    # whatever it was given (simulate refused them).
    for given in ({"links[1].mass": 5.0}, [5.0]):
        with pytest.raises(ValueError, match="takes no parameters$"):
            solver.stepper(phi0, omega0, DT, parameters=given)
        with pytest.raises(ValueError, match="takes no parameters$"):
            solver.simulate(phi0, omega0, dt=DT, n_steps=1, parameters=given)
    assert solver.stepper(phi0, omega0, DT, parameters={}).t == 0.0
    held = solver.simulate(phi0, omega0, dt=DT, n_steps=4, hold=np.int64(2),
                           controller=lambda t, phi, omega: -phi)
    twice = solver.simulate(phi0, omega0, dt=DT, n_steps=4, hold=2,
                            controller=lambda t, phi, omega: -phi)
    np.testing.assert_array_equal(held.samples, twice.samples)
    np.testing.assert_array_equal(held.torques[1], held.torques[0])


def test_a_results_tables_are_copies_of_its_samples():
    """to_xarray's variables and its t were views of result.samples: ds["phi"][:] = 0 changed
    the result's angles (by up to 49.7 in a sample, four_link_actuated, measured)."""
    from chaingen.runtime import SimulationResult
    from chaingen.runtime.contract import sample_column_names

    pytest.importorskip("xarray")
    pytest.importorskip("pandas")
    columns = sample_column_names(2, flows=True)
    samples = np.arange(4.0 * len(columns)).reshape(4, len(columns))
    samples[:, 0] = [0.0, 0.1, 0.2, 0.3]
    result = SimulationResult(scene="s", method="es", quadrature=3, dt=0.1, n_steps=3, every=1,
                              columns=columns, samples=samples, wall_time=0.0,
                              newton_iterations=3, max_newton_iterations=1,
                              torques=np.ones((3, 1)), actuated_joints=(2,))
    kept, torques = samples.copy(), result.torques.copy()
    dataset = result.to_xarray()
    for name in dataset.data_vars:
        dataset[name].values[...] = -1.0
    frame = result.to_dataframe()
    frame.iloc[:, :] = -1.0
    np.testing.assert_array_equal(result.samples, kept)
    np.testing.assert_array_equal(result.torques, torques)


def test_hold_and_a_context_go_with_a_controller_they_can_reach():
    """hold without a controller (torques given, or none) and a controller_context beside a
    Python controller were ignored without a word: a run asked to hold each input for 5
    steps took the torques as given, a Python controller ran without the context."""
    solver, good = fake_solver(), np.zeros(3)
    for extra in ({"hold": 5}, {"controller_context": 1234},
                  {"hold": 5, "torques": np.zeros((3, 2))}):
        with pytest.raises(ValueError, match="^hold and controller_context go with a "
                                             "controller"):
            solver.simulate(good, good, dt=DT, n_steps=3, **extra)
    with pytest.raises(ValueError, match="^controller_context: for a C controller"):
        solver.simulate(good, good, dt=DT, n_steps=3, controller=lambda t, phi, omega: phi[:2],
                        controller_context=1234)


def test_masked_entries_huge_integers_and_odd_watchers_are_refused_naming_them():
    """A masked entry ran as the value under its mask (phi0 [0.5, --, 0.0] over 9.0 started
    joint 2 at 9 rad, wrapped to 2.72); 10**400 was 'int too large to convert to float';
    progress=5 and stop=True failed once the run had started, naming neither."""
    solver, good = fake_solver(), np.zeros(3)
    masked = np.ma.masked_array([0.5, 9.0, 0.0], mask=[False, True, False])
    with pytest.raises(TypeError, match=r"^phi0: must be real numbers, got a masked entry"):
        solver.simulate(masked, good, dt=DT, n_steps=3)
    np.testing.assert_array_equal(real_array(np.ma.masked_array([0.5, 9.0], mask=False), "phi"),
                                  [0.5, 9.0])
    with pytest.raises(OverflowError, match=r"^phi0: must be real numbers \(int too large"):
        solver.simulate([10 ** 400, 0, 0], good, dt=DT, n_steps=3)
    with pytest.raises(TypeError, match=r"^progress: must be a callable progress\(steps_done\) "
                                        r"or None, got int$"):
        solver.simulate(good, good, dt=DT, n_steps=3, progress=5)
    with pytest.raises(TypeError, match=r"^stop: must be a StopSignal or None, got bool$"):
        solver.simulate(good, good, dt=DT, n_steps=3, stop=True)
