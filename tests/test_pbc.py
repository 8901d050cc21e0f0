"""Passivity-based control, compiled (issue 34; docs/controllers.md, "Passivity-based control"):
the closed loop's balance on every step at any dt, regulation, the equilibrium a partly
actuated chain settles at, the sampled law for comparison, and gains as run-time parameters."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import chaingen
from chaingen.errors import NewtonError
from chaingen.runtime.contract import STATUS_CODES
from chaingen.scene import load_scene
from chaingen.scene.parameters import with_values
from chaingen.studies.control import closed_loop_potential, predicted_equilibrium

pytestmark = pytest.mark.compile

SCENES = {name: load_scene(name) for name in ("four_link_pbc", "four_link_pbc_partial")}
GAINS = {name: [f"control.stiffness[{i}]" for i in range(len(scene.control.stiffness))]
         + [f"control.damping[{i}]" for i in range(len(scene.control.damping))]
         for name, scene in SCENES.items()}


@pytest.fixture(scope="module")
def solvers():
    return {name: chaingen.build_solver(scene, "es", 3, sensitivities=False,
                                        parameters=GAINS[name])
            for name, scene in SCENES.items()}


def _gains(scene, scale):
    control = scene.control
    return [k * scale for k in control.stiffness] + [d * scale for d in control.damping]


@pytest.mark.parametrize("name", sorted(SCENES))
@pytest.mark.parametrize("dt", [1e-3, 1e-2, 0.1])
@pytest.mark.parametrize("scale", [1.0, 100.0])
def test_the_discrete_law_keeps_the_closed_loop_balance_on_every_step(solvers, name, dt, scale):
    """H_d(k+1) - H_d(k) - work + dissipated at round-off on every step (H_d = T + V + V_s,
    u = 0 so work = 0), the dissipation of each step >= 0, so H_d never increases: at dt from
    1e-3 to 0.1 s and with gains x1 and x100."""
    scene = SCENES[name]
    steps = min(int(round(5.0 / dt)), 2000)
    result = solvers[name].simulate(scene.initial_angles, scene.initial_velocities, dt=dt,
                                    n_steps=steps, parameters=_gains(scene, scale))
    storage = result.energy
    balance = np.diff(storage - result.input_work + result.dissipated)
    size = np.abs(storage).max()
    assert np.abs(balance).max() <= 1e-13 * max(size, 1.0) * 10, np.abs(balance).max()
    assert np.all(np.diff(result.dissipated) >= 0)
    assert np.diff(storage).max() <= 1e-12 * max(size, 1.0)
    assert not np.any(result.input_work)


def test_a_fully_actuated_chain_is_regulated_to_the_target(solvers):
    scene = SCENES["four_link_pbc"]
    result = solvers["four_link_pbc"].simulate(scene.initial_angles, scene.initial_velocities,
                                               dt=0.01, n_steps=4000,
                                               parameters=_gains(scene, 1.0))
    assert np.abs(result.phi[-1] - scene.control.target).max() < 1e-6
    assert np.abs(result.omega[-1]).max() < 1e-6


def test_a_partly_actuated_chain_settles_where_the_theory_predicts(solvers):
    """The passive joint 3 cannot be held at its target: the loop settles at the stationary
    point of V + V_s (predicted from the numpy potential, from the target as the guess),
    which is a strict minimum (positive definite Hessian)."""
    scene = SCENES["four_link_pbc_partial"]
    predicted, hessian = predicted_equilibrium(scene, scene.control.target)
    assert np.linalg.eigvalsh(hessian).min() > 0
    assert abs(predicted[2] - scene.control.target[2]) > 1e-2
    result = solvers["four_link_pbc_partial"].simulate(
        scene.initial_angles, scene.initial_velocities, dt=0.01, n_steps=4000,
        parameters=_gains(scene, 1.0))
    assert np.abs(result.phi[-1] - predicted).max() < 1e-6
    assert closed_loop_potential(scene, result.phi[-1]) <= closed_loop_potential(
        scene, scene.initial_angles)


def test_the_sampled_law_gains_energy_where_the_discrete_one_does_not():
    """At dt = 0.05 s the zero-order hold of the same law raises H_d and loses the arm; the
    discrete law on the same scene, dt and gains keeps H_d falling and regulates."""
    scene = SCENES["four_link_pbc"]
    sampled = chaingen.build_solver(
        dataclasses.replace(scene, control=dataclasses.replace(scene.control, law="sampled")),
        "es", 3, sensitivities=False)
    try:
        result = sampled.simulate(scene.initial_angles, scene.initial_velocities, dt=0.05,
                                  n_steps=400)
    except NewtonError as error:
        result = error.result
    assert (result.energy - result.energy[0]).max() > 1.0
    discrete = chaingen.build_solver(scene, "es", 3, sensitivities=False)
    result = discrete.simulate(scene.initial_angles, scene.initial_velocities, dt=0.05,
                               n_steps=400)
    assert np.diff(result.energy).max() <= 1e-12 * np.abs(result.energy).max()


def test_the_midpoint_scheme_takes_both_laws():
    """Regulated to the target, with the energy check on by default under the discrete law
    (model.md 13) all the way to rest: there H_d = T + V + V_s cancels joules of its terms to
    1e-13 J and T is 1e-13 J, and the check allows the round-off of the terms, not of H_d.
    Before, with energy_tol = 0.01, step 2643 (t = 26.42 s) failed with ENERGY_JUMP. The
    sampled law misses the balance by design: no check by default."""
    scene = SCENES["four_link_pbc"]
    solver = chaingen.build_solver(scene, "midpoint", 3, sensitivities=False)
    assert solver.newton_options().energy_tol == 0.01
    result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                             n_steps=4000)
    assert np.abs(result.phi[-1] - scene.control.target).max() < 1e-6
    assert result.split_steps == 0 and abs(result.energy[-1]) < 1e-12
    # From rest at dt = 0.1 s the first step misses its balance by more than 1 % of T: step
    # splits it, control_torques refuses it with its own status (before: NOT_CONVERGED, "did
    # not converge within max_iterations", which it had), and takes it without the check.
    x0 = solver.initial_state(scene.initial_angles, scene.initial_velocities)
    with pytest.raises(NewtonError, match="energy balance") as refused:
        solver.control_torques(x0, None, 0.1)
    assert refused.value.status == STATUS_CODES["ENERGY_JUMP"]
    assert np.isfinite(solver.control_torques(x0, None, 0.1, options={"energy_tol": 0.0}).tau).all()
    sampled = chaingen.build_solver(
        dataclasses.replace(scene, control=dataclasses.replace(scene.control, law="sampled")),
        "midpoint", 3, sensitivities=False)
    assert sampled.newton_options().energy_tol == 0.0


def test_gains_as_run_time_parameters_equal_a_scene_with_those_gains(solvers):
    """A differential check of the run-time gains: the same run from a scene whose table has
    the gains compiled in gives the same samples."""
    scene = SCENES["four_link_pbc"]
    values = {"control.stiffness[0]": 90.0, "control.damping[2]": 1.5,
              "control.stiffness[3]": 12.0}
    changed = with_values(scene, values)
    compiled = chaingen.build_solver(changed, "es", 3, sensitivities=False)
    expected = compiled.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                                 n_steps=300)
    gains = _gains(changed, 1.0)
    got = solvers["four_link_pbc"].simulate(scene.initial_angles, scene.initial_velocities,
                                            dt=0.01, n_steps=300, parameters=gains)
    assert np.allclose(got.phi, expected.phi, rtol=0, atol=1e-11)
    assert np.allclose(got.energy, expected.energy, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("method", ["es", "midpoint"])
@pytest.mark.parametrize("name", sorted(SCENES))
def test_the_controllers_torque_applied_to_the_plant_reproduces_the_closed_loop(name, method):
    """What a robot's controller does with the package: control_torques(x_k) gives the torque
    of the controlled step from the measured state; applied as the input of the same scene
    without its control law (the plant model) it gives the same next state, to the Newton
    tolerance, along 40 steps of the loop; and the loop's states are those of simulate."""
    scene = SCENES[name]
    dt, steps = 0.02, 40
    controlled = chaingen.build_solver(scene, method, 3, sensitivities=False)
    plant = chaingen.build_solver(dataclasses.replace(scene, control=None), method, 3,
                                  sensitivities=False)
    run = controlled.simulate(scene.initial_angles, scene.initial_velocities, dt=dt,
                              n_steps=steps)
    x = controlled.initial_state(scene.initial_angles, scene.initial_velocities)
    worst = 0.0
    for k in range(steps):
        step = controlled.control_torques(x, None, dt)
        assert np.all(np.isfinite(step.tau))
        plant_next = plant.step(x, step.tau, dt, options={"warm_start": False}).x1
        worst = max(worst, np.abs(plant_next - step.x1).max() / np.abs(step.x1).max())
        phi = controlled.outputs(step.x1)[0]
        assert np.abs(phi - run.phi[k + 1]).max() <= 1e-12
        x = step.x1
    assert worst < 1e-9, worst


def test_a_target_near_pi_is_reached_through_the_wrap():
    """es measures angles in (-pi, pi]; the target 3.1 rad of joint 4, lightly damped, is
    overshot through pi. V_d's quadratic is in the wrapped offset, so V_s has no jump there:
    the balance stays at round-off and the loop settles at the target (it did not, 2.8 rad
    and 97 J of balance error, with the plain quadratic)."""
    scene = SCENES["four_link_pbc"]
    control = dataclasses.replace(scene.control, target=(np.pi / 2, 0.0, 0.0, 3.1),
                                  damping=(20.0, 10.0, 5.0, 0.05))
    scene = dataclasses.replace(scene, control=control)
    result = chaingen.build_solver(scene, "es", 3, sensitivities=False).simulate(
        scene.initial_angles, scene.initial_velocities, dt=0.01, n_steps=3000)
    assert np.any(result.phi[:, 3] < 0)       # it went through pi
    offset = np.angle(np.exp(1j * (result.phi[-1] - np.array(control.target))))
    assert np.abs(offset).max() < 1e-4
    balance = np.diff(result.energy - result.input_work + result.dissipated)
    assert np.abs(balance).max() <= 1e-12 * np.abs(result.energy).max()


def test_a_controlled_runs_files_say_what_its_energy_is(tmp_path):
    """The energy column of a controlled scene is H_d: the metadata file and the summary say so
    (docs/scene-format.md, section 12), so that it is not read as H = T + V."""
    import json
    import subprocess
    import sys
    out = tmp_path / "run.csv"
    result = subprocess.run([sys.executable, "-m", "chaingen", "simulate", "four_link_pbc",
                             "--t-end", "0.2", "--out", str(out)], capture_output=True,
                            text=True, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "(H_d - H_d_0 - work + dissipated)" in result.stdout
    energy_line, = (line for line in result.stdout.splitlines() if "max |energy error|" in line)
    assert energy_line.rstrip().endswith("J (|H_d - H_d_0|)"), energy_line
    assert json.loads((tmp_path / "run.csv.json").read_text())["energy"].startswith("H_d = ")


def test_the_compensation_follows_the_run_time_model_parameters():
    """With gravity and a spring's stiffness as run-time parameters, the law cancels the
    potential of the values the run takes (the shaping is derived from the same symbols): the
    loop regulates to the target with any of them, at round-off balance."""
    scene = SCENES["four_link_pbc"]
    solver = chaingen.build_solver(scene, "es", 3, sensitivities=False,
                                   parameters=["gravity", "springs[1].stiffness"])
    for values in ([9.81, 10.0], [3.0, 50.0], [20.0, 1.0]):
        result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                                 n_steps=4000, parameters=values)
        assert np.abs(result.phi[-1] - scene.control.target).max() < 1e-6
        balance = np.diff(result.energy - result.input_work + result.dissipated)
        assert np.abs(balance).max() <= 1e-12 * np.abs(result.energy).max()


def test_the_sampled_law_is_refused_with_adaptive_steps(tmp_path):
    """The sampled law is held over each step: with adaptive steps its hold period would be
    the adaptive step, not dt, and a study of sampling at dt would read another controller
    (stable at about 5 ms steps where it is lost at dt). Refused, named where the tolerance came
    from: the option, the scene's [simulation], or the sweep spec's key; the discrete law takes
    adaptive steps."""
    from importlib.resources import files

    from chaingen.errors import SettingsError
    from chaingen.simulation import run_settings
    from chaingen.studies.control import with_law
    from chaingen.studies.sweep.spec import SweepError, load_spec

    sampled = with_law(SCENES["four_link_pbc"], "sampled")
    with pytest.raises(SettingsError, match=r"^--rtol: adaptive steps would hold the sampled "):
        run_settings(sampled, rtol=1e-6)
    with pytest.raises(SettingsError, match=r"^--atol: adaptive steps would hold"):
        run_settings(sampled, atol=1e-6)
    in_scene = dataclasses.replace(
        sampled, simulation=dataclasses.replace(sampled.simulation, rtol=1e-6))
    with pytest.raises(SettingsError, match=r"^pbc\.toml: simulation\.rtol: adaptive steps"):
        run_settings(in_scene, source="pbc.toml")
    assert run_settings(sampled).rtol == 0.0
    assert run_settings(SCENES["four_link_pbc"], rtol=1e-6).rtol == 1e-6
    text = (files("chaingen.scenes") / "four_link_pbc.toml").read_text()
    assert text.count('\nlaw = "discrete"\n') == 1
    (tmp_path / "pbc.toml").write_text(text.replace('\nlaw = "discrete"\n',
                                                    '\nlaw = "sampled"\n'))
    (tmp_path / "spec.toml").write_text('scene = "pbc.toml"\nrtol = 1e-6\n'
                                        '[axes]\n"control.damping[0]" = [1.0, 2.0]\n')
    with pytest.raises(SweepError, match=r"spec\.toml: rtol: adaptive steps would hold"):
        load_spec(tmp_path / "spec.toml")


@pytest.fixture(scope="module")
def loaded_laws(tmp_path_factory):
    """four_link_pbc's es package with each law, written out and loaded as a user loads a
    package (Solver.from_directory: no SolverSpec, no run_settings on the way)."""
    from chaingen.generate.package import generate_package, write_package
    from chaingen.runtime import Solver
    from chaingen.studies.control import with_law

    loaded = {}
    for law in ("discrete", "sampled"):
        package = generate_package(with_law(SCENES["four_link_pbc"], law), "es", 3,
                                   sensitivities=False)
        directory = write_package(package, tmp_path_factory.mktemp(law) / package.prefix)
        loaded[law] = (Solver.from_directory(directory), package)
    return loaded


def _held_start():
    scene = SCENES["four_link_pbc"]
    return scene.initial_angles, scene.initial_velocities


@pytest.mark.parametrize("name", ["rtol", "atol"])
def test_a_loaded_sampled_package_refuses_adaptive_steps(loaded_laws, name):
    """The package's own fact, not the scene's: a loaded sampled package refuses rtol or atol
    > 0 in simulate (open loop and with a controller) in one line naming the option and why.
    Before the package stated its law, simulate(options={"rtol": 1e-8}) of this package at
    dt = 0.05 s ran silently: 7032 adaptive steps (13 refused, the shortest 2.3e-5 s) over 40
    sample intervals, each holding the law, a controller whose H_d never rose where the law
    sampled at dt raises it by 516 J, ending 3.0 rad from the fixed-step run. The discrete law
    takes the same options; the sampled one takes fixed steps."""
    phi0, omega0 = _held_start()
    solver, package = loaded_laws["sampled"]
    assert package.manifest["control_law"] == "sampled"
    assert "    .held_control = 1," in package.files[f"{package.prefix}.c"]
    message = (rf"^simulate: {name}: adaptive steps would hold the sampled law \(control\.law = "
               r"\"sampled\"\) over each adaptive step instead of the sample period dt; take "
               r"fixed steps, got 1e-08$")
    with pytest.raises(ValueError, match=message):
        solver.simulate(phi0, omega0, dt=0.05, n_steps=40, options={name: 1e-8})
    with pytest.raises(ValueError, match=message):
        solver.simulate(phi0, omega0, dt=0.05, n_steps=40, options={name: 1e-8},
                        controller=lambda t, phi, omega: np.zeros(4))
    fixed = solver.simulate(phi0, omega0, dt=0.05, n_steps=40)
    assert fixed.n_steps == 40 and not fixed.adaptive
    discrete, package = loaded_laws["discrete"]
    assert package.manifest["control_law"] == "discrete"
    assert "    .held_control = 0," in package.files[f"{package.prefix}.c"]
    adaptive = discrete.simulate(phi0, omega0, dt=0.05, n_steps=40, options={name: 1e-8})
    assert adaptive.adaptive and adaptive.accepted_steps > 40


def _c_run(solver, entry: str, options: dict) -> tuple[int, int]:
    """(status, steps) of a C simulate entry point called straight through the loader's
    ctypes binding (bypassing Solver.simulate's own refusal): 5 steps of 0.05 s."""
    import ctypes

    from chaingen.runtime.interface import StatsStruct

    pointer = ctypes.POINTER(ctypes.c_double)
    x0 = solver.initial_state(*_held_start())
    samples = np.zeros((6, solver.nsample))
    stats, c_options = StatsStruct(), solver.newton_options(options).as_c()
    arguments = dict(x0=x0.ctypes.data_as(pointer), t0=0.0, dt=0.05, n_steps=5, every=1,
                     u=None, p=None, options=ctypes.byref(c_options),
                     workspace=solver._workspace, samples=samples.ctypes.data_as(pointer),
                     x_final=None, stats=ctypes.byref(stats), observer=None, context=None,
                     interval=1, control=None)
    callback = None
    if entry == "simulate_controlled":
        callback = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_long, ctypes.c_double,
                                    ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p,
                                    ctypes.c_void_p)(lambda *arguments: 0)
        arguments.update(controller=ctypes.cast(callback, ctypes.c_void_p).value, hold=1,
                         torques=None)
    return solver._call(entry, **arguments), int(stats.steps)


@pytest.mark.parametrize("entry", ["simulate_observed", "simulate_controlled"])
def test_the_c_entry_points_refuse_adaptive_steps_of_a_held_law(loaded_laws, entry):
    """C itself refuses (the model table's held_control): BAD_ARGUMENT before any step for
    rtol or atol > 0 with the sampled law; the discrete law's package runs the same call."""
    from chaingen.runtime.contract import STATUS_CODES

    sampled, discrete = loaded_laws["sampled"][0], loaded_laws["discrete"][0]
    for name in ("rtol", "atol"):
        assert _c_run(sampled, entry, {name: 1e-8}) == (STATUS_CODES["BAD_ARGUMENT"], 0)
        assert _c_run(discrete, entry, {name: 1e-8}) == (STATUS_CODES["OK"], 5)
    assert _c_run(sampled, entry, {}) == (STATUS_CODES["OK"], 5)


def test_a_stepper_takes_no_adaptive_steps_of_any_law(loaded_laws):
    """No gap on this path: a Stepper (and step, control_torques) takes the dt it is given and
    refuses rtol and atol for every package, whatever its law; with fixed steps the sampled
    package's Stepper steps."""
    phi0, omega0 = _held_start()
    for law in ("sampled", "discrete"):
        solver = loaded_laws[law][0]
        for name in ("rtol", "atol"):
            with pytest.raises(ValueError, match=r"^Stepper: rtol and atol \(adaptive steps\) "
                                                 r"apply to simulate only"):
                solver.stepper(phi0, omega0, 0.05, options={name: 1e-8})
            with pytest.raises(ValueError, match=r"^control_torques: rtol and atol"):
                solver.control_torques(solver.initial_state(phi0, omega0), None, 0.05,
                                       options={name: 1e-8})
    stepper = loaded_laws["sampled"][0].stepper(phi0, omega0, 0.05)
    stepper.step(np.zeros(4))
    assert np.all(np.isfinite(stepper.phi))


def _law(solver, x):
    """The sampled law's torque at the state x: control_torques with u = 0 over a step short
    enough never to split (the law reads the step's start alone, not its length)."""
    solver.reset()
    return solver.control_torques(x, None, 1e-6).tau


def _held_pieces(solver, x, torque, dt, options, pieces):
    """The end of a step of the sampled law holding `torque` over dt, split as the runtime
    splits it (a piece that would split, control_torques' NewtonError, into two halves): each
    piece an unsplit step whose inputs carry torque - law(its start). Each piece's (length,
    applied torque) into `pieces`."""
    inputs = torque - _law(solver, x)
    solver.reset()
    try:
        step = solver.control_torques(x, inputs, dt, options=options)
    except NewtonError:
        middle = _held_pieces(solver, x, torque, dt / 2, options, pieces)
        return _held_pieces(solver, middle, torque, dt / 2, options, pieces)
    pieces.append((dt, step.tau))
    return step.x1


@pytest.fixture(scope="module")
def sampled_midpoint():
    from chaingen.studies.control import with_law

    return chaingen.build_solver(with_law(SCENES["four_link_pbc"], "sampled"), "midpoint", 3,
                                 sensitivities=False)


@pytest.mark.parametrize("method, dt, options", [("es", 0.3, {}),
                                                 ("es", 0.1, {"max_iterations": 5}),
                                                 ("midpoint", 0.3, {})])
def test_a_split_step_of_the_sampled_law_holds_the_start_s_torque(loaded_laws, sampled_midpoint,
                                                                  method, dt, options):
    """The sampled law is held over the step dt, the controller's sample period. A step that
    Newton fails on whole is split into halves; each half used to sample the law at its own
    start, so the split step held it over dt/2 and less (at dt = 0.3 s the first step's later
    pieces applied torques up to 192 N m from the start's, and it ended 2.4 rad and 37 rad/s
    from the held step; at dt = 0.1 s, max_iterations = 5, 0.47 rad), without a word. Now the
    halves hold the start's torque: the run's first step is the pieces' whose torque is the law
    at the start (to round-off), and that law differs from the one sampled at the middle.
    midpoint's sampled law likewise."""
    solver = loaded_laws["sampled"][0] if method == "es" else sampled_midpoint
    phi0, omega0 = _held_start()
    solver.reset()
    run = solver.simulate(phi0, omega0, dt=dt, n_steps=1, options=options)
    assert run.split_steps == 1
    x0 = solver.initial_state(phi0, omega0)
    torque, pieces = _law(solver, x0), []
    x1 = _held_pieces(solver, x0, torque, dt, options, pieces)
    assert len(pieces) >= 2 and sum(length for length, _ in pieces) == pytest.approx(dt)
    for _, applied in pieces:
        np.testing.assert_allclose(applied, torque, rtol=0, atol=1e-12 * np.abs(torque).max())
    phi, omega, *_ = solver.outputs(x1)
    np.testing.assert_allclose(run.phi[-1], phi, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.omega[-1], omega, rtol=0, atol=1e-8)
    middle = _held_pieces(solver, x0, torque, pieces[0][0], options, [])
    assert np.abs(_law(solver, middle) - torque).max() > 1.0


def test_the_discrete_law_keeps_its_balance_across_split_steps(solvers):
    """The discrete law is a law of both ends of its step: a split step is two (or more)
    steps of the discrete law, each of which keeps the closed loop's balance, so the split step
    keeps it too (docs/controllers.md): at dt = 0.1 s with max_iterations = 4, 12 of 50 steps
    of four_link_pbc_partial split, the balance at round-off, H_d never rising."""
    scene = SCENES["four_link_pbc_partial"]
    result = solvers["four_link_pbc_partial"].simulate(
        scene.initial_angles, scene.initial_velocities, dt=0.1, n_steps=50,
        options={"max_iterations": 4}, parameters=_gains(scene, 1.0))
    assert result.split_steps >= 5
    size = np.abs(result.energy).max()
    balance = np.diff(result.energy - result.input_work + result.dissipated)
    assert np.abs(balance).max() <= 1e-13 * max(size, 1.0) * 10, np.abs(balance).max()
    assert np.diff(result.energy).max() <= 1e-12 * max(size, 1.0)
    assert not np.any(result.input_work)
