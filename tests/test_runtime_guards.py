"""What the Python runtime refuses before C sees it, each with a one-line error: run-time parameter
values the scene format refuses (issue 30, point 4), runs whose samples would not fit in memory
(point 12), a Stepper's scalar or misplaced torques and a dt <= 0 (point 13), start angles beyond
2^20 rad (the scene reader's bound), and integer options that would wrap in the C int they land
in (point 11)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from chaingen.runtime import NewtonOptions
from chaingen.runtime.solver import MAX_SAMPLE_BYTES, Solver, _parameter_bounds

from helpers import ROOT, chaingen_in_process, load

DT = 0.01


def fake_solver(paths=("links[1].mass", "springs[0].stiffness"), values=(1.0, 10.0),
                lower=(0.0, 0.0), inclusive=(False, True), *, bounds=True, nu=0,
                nsample=11) -> Solver:
    """A Solver's Python checks without a compiled library (they run before any C call)."""
    solver = Solver.__new__(Solver)
    solver.prefix, solver.parameters = "fake", tuple(paths)
    solver.default_parameters = np.array(values, dtype=float)
    entries = [{"path": p, "value": v} for p, v in zip(paths, values)]
    if bounds:
        for entry, low, allowed in zip(entries, lower, inclusive):
            entry.update(lower=low, lower_inclusive=allowed)
    solver._bounds = _parameter_bounds(entries)
    solver.nu, solver.nsample, solver.n = nu, nsample, 3
    return solver


# -- point 4: parameter values in the scene format's ranges -----------------------------------

@pytest.mark.parametrize("given, message", [
    ({"links[1].mass": -1.0}, "links[1].mass: must be > 0, got -1.0"),
    ({"links[1].mass": 0.0}, "links[1].mass: must be > 0, got 0.0"),
    ({"springs[0].stiffness": -0.5}, "springs[0].stiffness: must be >= 0, got -0.5"),
    ({"links[1].mass": math.nan}, "links[1].mass: must be finite, got nan"),
    ({"springs[0].stiffness": math.inf}, "springs[0].stiffness: must be finite, got inf"),
    ([1.0, -2.0], "springs[0].stiffness: must be >= 0, got -2.0"),
])
def test_parameter_values_out_of_range_are_refused(given, message):
    with pytest.raises(ValueError) as refused:
        fake_solver().parameter_values(given)
    assert str(refused.value) == message


def test_parameter_values_in_range_pass():
    solver = fake_solver()
    np.testing.assert_array_equal(solver.parameter_values({"springs[0].stiffness": 0.0}),
                                  [1.0, 0.0])
    np.testing.assert_array_equal(solver.parameter_values([1e-9, 3.0]), [1e-9, 3.0])
    unbounded = fake_solver(["gravity"], [9.81], [None], [False])
    assert unbounded.parameter_values({"gravity": -50.0})[0] == -50.0


def test_a_manifest_without_ranges_is_not_trusted():
    with pytest.raises(ValueError, match="no range of its parameters.*generate the package"):
        fake_solver(bounds=False).parameter_values({"links[1].mass": 2.0})


@pytest.mark.compile
def test_the_manifest_ranges_are_the_scene_reader_s():
    """A real package: its manifest's lower bounds are those the reader enforces, and the
    Python API refuses what the reader would, before C runs."""
    from chaingen import build_solver
    from chaingen.errors import SceneError
    from chaingen.scene.parameters import with_values

    scene = load("three_link_mono")
    paths = ["links[1].mass", "links[0].inertia", "springs[0].stiffness", "gravity"]
    solver = build_solver(scene, "es", 3, sensitivities=False, parameters=paths)
    for entry in solver.manifest["parameters"]:
        lower = entry["lower"]
        if lower is None:
            continue
        if entry["lower_inclusive"]:
            with_values(scene, {entry["path"]: lower})
        else:
            with pytest.raises(SceneError):
                with_values(scene, {entry["path"]: lower})
        with pytest.raises(SceneError):
            with_values(scene, {entry["path"]: lower - 1e-3})
    phi0, omega0 = scene.initial_angles, scene.initial_velocities
    with pytest.raises(ValueError, match=r"^links\[1\]\.mass: must be > 0, got -1\.0$"):
        solver.simulate(phi0, omega0, dt=DT, n_steps=10, parameters={"links[1].mass": -1.0})
    with pytest.raises(ValueError, match=r"^springs\[0\]\.stiffness: must be > 0, got -1"):
        solver.stepper(phi0, omega0, DT, parameters={"springs[0].stiffness": -1.0})
    with pytest.raises(ValueError, match=r"^links\[0\]\.inertia: must be finite, got nan$"):
        solver.step(solver.initial_state(phi0, omega0), dt=DT,
                    parameters={"links[0].inertia": float("nan")})
    ok = solver.simulate(phi0, omega0, dt=DT, n_steps=10, parameters={"gravity": 3.0})
    assert ok.parameters["gravity"] == 3.0


# -- point 12: the samples of a run fit in memory -------------------------------------------

@pytest.mark.parametrize("n_steps, every", [(2 ** 63 - 1, 1), (2 ** 40, 1), (2 ** 62, 3)])
def test_runs_whose_samples_do_not_fit_are_refused_before_allocating(n_steps, every):
    with pytest.raises(ValueError, match="GiB of samples .limit 4 GiB.: sample less often"):
        fake_solver(nu=2).simulate([0] * 3, [0] * 3, dt=DT, n_steps=n_steps, every=every)
    with pytest.raises(ValueError, match="must be integers"):
        fake_solver().simulate([0] * 3, [0] * 3, dt=DT, n_steps=1e6)
    assert MAX_SAMPLE_BYTES == 4 * 2 ** 30


@pytest.mark.compile
def test_a_huge_run_is_refused_in_one_line():
    from chaingen.simulation import MAX_SAMPLE_BYTES as simulate_limit
    solver, phi0, omega0 = actuated_solver()
    for n_steps in (2 ** 63 - 1, 2 ** 33):
        with pytest.raises(ValueError, match="GiB of samples") as refused:
            solver.simulate(phi0, omega0, dt=DT, n_steps=n_steps, every=1)
        assert "\n" not in str(refused.value)
    assert simulate_limit is MAX_SAMPLE_BYTES    # one limit, the command line's too


# -- point 13: a Stepper takes nu torques and a dt > 0 -----------------------------------------

def actuated_solver():
    from chaingen import build_solver
    from chaingen.studies.bench.control import control_scene

    scene = control_scene()
    return (build_solver(scene, "es", 3, sensitivities=False),
            np.array(scene.initial_angles), np.array(scene.initial_velocities))


@pytest.mark.compile
def test_a_stepper_refuses_scalar_and_misshapen_torques():
    solver, phi0, omega0 = actuated_solver()
    stepper = solver.stepper(phi0, omega0, DT)
    before = stepper.phi.copy()
    for bad in (5.0, [1.0, 2.0], np.zeros((3, 1)), np.zeros(4)):
        with pytest.raises(ValueError, match="u must have 3 entries"):
            stepper.step(bad)
        with pytest.raises(ValueError, match="u must have 3 entries"):
            stepper.u = bad
    np.testing.assert_array_equal(stepper.phi, before)      # nothing was stepped
    np.testing.assert_array_equal(stepper.u, np.zeros(3))
    stepper.step([1.0, 2.0, 3.0])
    stepper.step(np.array([1.0, 2.0, 3.0]))
    np.testing.assert_array_equal(stepper.u, [1.0, 2.0, 3.0])


@pytest.mark.compile
def test_an_unactuated_stepper_refuses_torques():
    from chaingen import build_solver

    scene = load("three_link_mono")
    solver = build_solver(scene, "es", 3, sensitivities=False)
    stepper = solver.stepper(scene.initial_angles, scene.initial_velocities, DT)
    for bad in (5.0, np.zeros(3), [0.0]):
        with pytest.raises(ValueError, match="no actuated joints; u must be None"):
            stepper.step(bad)
    stepper.step()
    assert stepper.t == pytest.approx(DT)


@pytest.mark.compile
def test_a_stepper_refuses_a_dt_that_is_not_positive():
    solver, phi0, omega0 = actuated_solver()
    for bad in (-0.01, 0.0, math.nan, math.inf, -math.inf):
        with pytest.raises(ValueError, match=r"^dt: must be > 0 and finite, got"):
            solver.stepper(phi0, omega0, bad)
    stepper = solver.stepper(phi0, omega0, DT)
    for bad in (-0.01, 0.0, math.nan):
        with pytest.raises(ValueError, match=r"^dt: must be > 0 and finite"):
            stepper.dt = bad
    assert stepper.dt == DT


@pytest.mark.compile
@pytest.mark.parametrize("method", ["es", "vi", "midpoint"])
def test_the_runtime_refuses_a_start_angle_a_double_holds_too_coarsely(method):
    """The scene reader's bound on initial angles (2^20 rad) for the Python API too: before,
    simulate from phi_2 = 1e10 rad ran (es: silently 7.4e-7 rad off the same start within its
    turn after 1 s; midpoint: a spurious root at step 1), and so did a Stepper."""
    from chaingen import build_solver
    from chaingen.runtime.interface import MAX_INITIAL_ANGLE

    scene = load("three_link_mono")
    solver = build_solver(scene, method, 3, sensitivities=False)
    message = (r"^phi\[1\]: must be within \+-2\^20 = 1048576 rad \(an angle in rad\): a double "
               r"holds 1e\+10 rad only to 1\.9e-06 rad, .*, got 10000000000\.0$")
    far = [0.1, 1e10, 0.3]
    with pytest.raises(ValueError, match=message):
        solver.simulate(far, [0.0] * 3, dt=DT, n_steps=10)
    with pytest.raises(ValueError, match=message):
        solver.stepper(far, [0.0] * 3, DT)
    stepper = solver.stepper([0.1, 0.2, 0.3], [0.0] * 3, DT)
    with pytest.raises(ValueError, match=message):
        stepper.reset(far, [0.0] * 3)
    with pytest.raises(ValueError, match=r"^phi\[0\]: must be within"):
        solver.initial_state([-MAX_INITIAL_ANGLE, 0.0, 0.0], [0.0] * 3)
    within = np.nextafter(MAX_INITIAL_ANGLE, 0.0)
    solver.simulate([within, 0.2, 0.3], [0.0] * 3, dt=DT, n_steps=10)


# -- point 11: integers that land in a C int ------------------------------------------------

def test_integer_options_refuse_what_their_c_int_would_wrap(tmp_path):
    scene = ROOT / "scenes" / "three_link_mono.toml"
    for value in (2 ** 32 + 1, 2 ** 31):
        result = chaingen_in_process("simulate", scene, "--max-iterations", value,
                                     "--out", tmp_path / "run.csv", cwd=tmp_path)
        assert result.returncode == 2
        assert "--max-iterations: must be below 2^31" in result.stderr
        assert not (tmp_path / "run.csv").exists()
    with pytest.raises(ValueError, match="max_iterations: must fit a C int"):
        NewtonOptions(max_iterations=2 ** 32 + 1)
    assert NewtonOptions(max_iterations=2 ** 31 - 1).as_c().max_iterations == 2 ** 31 - 1
