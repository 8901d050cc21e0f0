"""`chaingen check`: passes on good packages, and catches a wrong derivative or a wrong value."""
from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest

from chaingen.studies.check import MAX_SAMPLES, check_solver
from chaingen.symbolic.schemes import build_scheme

from helpers import REFERENCE_SCENES, load, scene_path, solver_for


def report_for(name, method, solver=None, scheme=None, samples=3):
    scheme = scheme or build_scheme(load(name), method, 3)
    solver = solver or solver_for(name, method, 3, sensitivities=True)
    return check_solver(scheme, solver, samples=samples)


@pytest.mark.compile
@pytest.mark.parametrize("method", ["es", "vi", "midpoint"])
@pytest.mark.parametrize("name", REFERENCE_SCENES + ("four_link_underactuated",))
def test_check_passes_on_the_generated_packages(name, method):
    report = report_for(name, method)
    assert report.passed, report.table()
    names = {row.quantity for row in report.rows}
    assert {"residual Jacobian", "d s1 / d s0", "residual", "energy", "joint angles",
            "joint rates", "initial state", "next state"} <= names
    assert ("d s1 / d u" in names) == (name == "four_link_underactuated")
    assert ("constraint error" in names) == (method != "midpoint")
    assert "control torques" not in names     # no [control] law: no control_torques


class Perturbed:
    """A solver whose one function is wrong, the rest delegated to a good one."""

    def __init__(self, solver, **overrides):
        self._solver = solver
        self.__dict__.update(overrides)

    def __getattr__(self, name):
        return getattr(self._solver, name)


@pytest.mark.compile
def test_check_catches_a_wrong_jacobian_entry():
    good = solver_for("three_link_mono", "es", 3, sensitivities=True)

    def residual_jacobian(z, x0, u=None, dt=None, *, parameters=None):
        residual, jacobian = good.residual_jacobian(z, x0, u, dt, parameters=parameters)
        jacobian = jacobian.copy()
        jacobian[1, 4] += 1e-4 * np.abs(jacobian).max()     # one entry off by 1e-4
        return residual, jacobian

    report = report_for("three_link_mono", "es",
                        solver=Perturbed(good, residual_jacobian=residual_jacobian))
    assert not report.passed
    failed = [row.quantity for row in report.rows if not row.passed]
    assert failed == ["residual Jacobian"], report.table()


@pytest.mark.compile
def test_check_catches_wrong_sensitivities():
    good = solver_for("four_link_underactuated", "vi", 3, sensitivities=True)

    def step_sensitivities(x0, u=None, dt=None, *, options=None, parameters=None):
        result = good.step_sensitivities(x0, u, dt, options=options, parameters=parameters)
        return dataclasses.replace(result, ds_du=result.ds_du * (1 + 1e-5))

    report = report_for("four_link_underactuated", "vi",
                        solver=Perturbed(good, step_sensitivities=step_sensitivities))
    assert [row.quantity for row in report.rows if not row.passed] == ["d s1 / d u"]


@pytest.mark.compile
def test_check_catches_a_generated_energy_that_differs_from_the_model():
    """The C energy against a model whose energy is off by 1e-7: the energy row fails."""
    scheme = build_scheme(load("three_link_multi"), "midpoint", 3)
    wrong = dataclasses.replace(scheme, energy=scheme.energy * (1 + 1e-7))
    report = report_for("three_link_multi", "midpoint", scheme=wrong)
    assert [row.quantity for row in report.rows if not row.passed] == ["energy"]


@pytest.mark.compile
def test_check_command_exits_0_on_success_and_prints_the_table():
    result = subprocess.run([sys.executable, "-m", "chaingen", "check",
                             str(scene_path("three_link_gravity")), "--method", "midpoint",
                             "--samples", "2"], capture_output=True, text=True)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "residual Jacobian" in result.stdout and "passed" in result.stdout


def test_check_command_refuses_bad_options_with_status_2(tmp_path):
    result = subprocess.run([sys.executable, "-m", "chaingen", "check",
                             str(scene_path("three_link_gravity")), "--dt", "-1"],
                            capture_output=True, text=True)
    assert result.returncode == 2
    assert "--dt" in result.stderr and "Traceback" not in result.stderr


@pytest.mark.parametrize("samples", [str(MAX_SAMPLES + 1), "1000000000", str(10 ** 18)])
def test_check_refuses_more_samples_than_it_can_take_before_any_work(samples):
    """Each random state takes 4 ms to 0.15 s to check and nothing else grows with them, so
    the bound is time: --samples 10**9 ran silently for days (49 on the cheapest scene) before
    MAX_SAMPLES. Now it is exit 2 at once, naming --samples and the limit."""
    result = subprocess.run([sys.executable, "-m", "chaingen", "check",
                             str(scene_path("three_link_gravity")), "--samples", samples],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 2, result.stdout + result.stderr
    last = result.stderr.strip().splitlines()[-1]
    assert last == (f"chaingen check: error: argument --samples: must be at most {MAX_SAMPLES} "
                    f"(a random state takes milliseconds to 0.15 s to check, so {MAX_SAMPLES} "
                    f"of them take up to hours), got {samples}")
    assert "Traceback" not in result.stderr and not result.stdout


@pytest.mark.parametrize("samples", [0, -1, MAX_SAMPLES + 1, 1.5, True, "5"])
def test_check_solver_refuses_a_count_of_samples_it_cannot_honour(samples):
    """No states is no check (a report of no rows passed); too many is days (see above)."""
    with pytest.raises(ValueError, match=rf"^samples: must be an integer from 1 to {MAX_SAMPLES}"):
        check_solver(None, None, samples=samples)


def test_check_help_states_the_samples_limit():
    result = subprocess.run([sys.executable, "-m", "chaingen", "check", "--help"],
                            capture_output=True, text=True, timeout=60)
    assert f"1 to {MAX_SAMPLES}" in " ".join(result.stdout.split())


@pytest.mark.compile
def test_check_with_parameters_compares_the_parameter_derivatives():
    result = subprocess.run([sys.executable, "-m", "chaingen", "check",
                             str(scene_path("four_link_actuated")), "--method", "vi",
                             "--parameters", "springs[1].stiffness,links[2].damping,gravity",
                             "--samples", "3"], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "d s1 / d p" in result.stdout and "FAIL" not in result.stdout


@pytest.mark.compile
def test_check_catches_wrong_parameter_sensitivities():
    from chaingen.simulation import build_solver

    paths = ("springs[0].stiffness", "links[1].mass")
    scheme = build_scheme(load("three_link_mono"), "midpoint", 3, paths)
    good = build_solver(load("three_link_mono"), "midpoint", 3, parameters=paths)

    def step_sensitivities(x0, u=None, dt=None, *, options=None, parameters=None):
        result = good.step_sensitivities(x0, u, dt, options=options, parameters=parameters)
        return dataclasses.replace(result, ds_dp=result.ds_dp * (1 + 1e-5))

    assert report_for("three_link_mono", "midpoint", solver=good, scheme=scheme).passed
    report = report_for("three_link_mono", "midpoint", scheme=scheme,
                        solver=Perturbed(good, step_sensitivities=step_sensitivities))
    assert [row.quantity for row in report.rows if not row.passed] == ["d s1 / d p"]


@pytest.mark.compile
@pytest.mark.parametrize("method", ["es", "vi", "midpoint"])
def test_check_of_a_composed_step_compares_every_stage(method):
    """Order 4 composes the step with a backward stage (Yoshida's -1.70 dt), which the C entry
    points refuse; the check's reference solves the stages on the SymPy residual, so its rows
    are all there and pass (the check stopped with "residual_jacobian: bad argument"), and a
    composed step off by 1e-9 of the state fails "next state"."""
    from chaingen.simulation import build_solver
    scene = load("three_link_mono")
    scheme = build_scheme(scene, method, 3, order=4)
    solver = build_solver(scene, method, 3, order=4, sensitivities=True)
    report = check_solver(scheme, solver, samples=2)
    assert report.passed, report.table()
    assert "next state" in {row.quantity for row in report.rows}

    def step(x0, u=None, dt=None, **keywords):
        result = solver.step(x0, u, dt, **keywords)
        return dataclasses.replace(result, x1=result.x1 + 1e-8 * np.abs(result.x1).max())

    report = check_solver(scheme, Perturbed(solver, step=step), samples=2)
    failed = [row.quantity for row in report.rows if not row.passed]
    assert failed == ["next state"], report.table()


@pytest.mark.compile
@pytest.mark.slow
def test_check_with_full_newton_at_its_floor_on_a_long_vi_chain():
    """vi on 18 links: the check's step map takes the step with tolerances below the updates'
    round-off; full Newton must see its floor there. It ran out of iterations and split the step
    instead, so d s1/d s0 disagreed by 100 % with a single step's sensitivities."""
    from chaingen.simulation import build_solver
    from chaingen.studies.bench.scenes import scaling_scene
    scene = scaling_scene(18)
    report = check_solver(build_scheme(scene, "vi"), build_solver(scene, "vi"), samples=2)
    assert report.passed, report.table()


class NoisyLinear:
    """A reference whose residual A z - b carries round-off-sized noise (1e-13 of b, a
    deterministic function of z): Newton's updates stall at the noise through A^-1, above the
    1e-14 |z| of an absolute tolerance."""

    def __init__(self, size=6, noise=1e-13, seed=3):
        rng = np.random.default_rng(seed)
        self.a = rng.standard_normal((size, size)) + 3 * np.eye(size)
        self.b = rng.standard_normal(size)
        self.noise = noise
        self.size = size

    def residual(self, *args):
        z = np.array(args[:self.size])
        jitter = np.random.default_rng(abs(hash(z.tobytes())) % 2 ** 32).uniform(-1, 1, self.size)
        return self.a @ z - self.b + self.noise * np.abs(self.b).max() * jitter


def test_the_reference_newton_stops_at_the_round_off_floor():
    """chaingen check's own Newton (studies/check.py) accepts an iterate at the round-off
    floor: updates that stop shrinking once below ROUND_OFF_GATE of z (spatial es's next
    state, whose updates stall near 3e-14 |z|, failed with no reference before)."""
    from chaingen.studies.check import _converged_unknowns

    reference = NoisyLinear()
    z = _converged_unknowns(reference, [], 0.01, [], [], reference.size)
    assert z is not None
    exact = np.linalg.solve(reference.a, reference.b)
    assert np.abs(z - exact).max() <= 1e-11 * np.abs(exact).max()
    # Without noise the absolute tolerance ends it, as before; without a root it fails.
    assert _converged_unknowns(NoisyLinear(noise=0.0), [], 0.01, [], [], 6) is not None

    class NoRoot:
        def residual(self, *args):
            return np.array([(args[0] - 0.5) ** 2 + 1.0])

    assert _converged_unknowns(NoRoot(), [], 0.01, [], [], 1) is None


@pytest.mark.compile
@pytest.mark.parametrize("name, method, law", [
    ("four_link_pbc", "es", "discrete"), ("four_link_pbc", "midpoint", "discrete"),
    ("four_link_pbc", "es", "sampled"), ("four_link_pbc_partial", "es", "discrete")])
def test_check_compares_the_control_law_with_sympy(name, method, law):
    """A scene with a [control] law gets the row "control torques": control_torques' tau and
    x1 against the SymPy law evaluated at the step the reference solves on its own, for both
    laws, es and midpoint, fully and partly actuated."""
    from chaingen.simulation import build_solver
    from chaingen.studies.control import with_law

    scene = with_law(load(name), law)
    solver = build_solver(scene, method, 3, sensitivities=False)
    report = check_solver(build_scheme(scene, method, 3), solver, samples=2)
    assert report.passed, report.table()
    row = next(row for row in report.rows if row.quantity == "control torques")
    assert row.reference == "SymPy" and row.worst < 1e-12, report.table()


@pytest.mark.compile
def test_check_catches_a_wrong_control_law():
    """Mutations of the law, each caught by the "control torques" row: a reference whose
    damping gain D_1 is 1 % off (the residual and the next state, which hold the law, fail
    too); a reference whose first torque alone is off by 1e-7 of itself, and a generated
    control_torques whose tau is, each failing that row alone."""
    import sympy as sp

    scene = load("four_link_pbc")
    good = solver_for("four_link_pbc", "es", 3)
    scheme = build_scheme(scene, "es", 3)
    assert check_solver(scheme, good, samples=2).passed

    control = dataclasses.replace(scene.control, damping=(
        scene.control.damping[0] * 1.01, *scene.control.damping[1:]))
    wrong_gain = build_scheme(dataclasses.replace(scene, control=control), "es", 3)
    failed = [row.quantity for row in check_solver(wrong_gain, good, samples=2).rows
              if not row.passed]
    assert "control torques" in failed and set(failed) <= {
        "control torques", "residual", "next state"}, failed

    torques = scheme.flows.applied_torques
    wrong_torque = scheme.replaced(applied_torques=sp.ImmutableMatrix(
        [torques[0] * (1 + 1e-7), *torques[1:]]))
    report = check_solver(wrong_torque, good, samples=2)
    assert [row.quantity for row in report.rows if not row.passed] == ["control torques"]

    def control_torques(x0, u=None, dt=None, *, options=None, parameters=None):
        result = good.control_torques(x0, u, dt, options=options, parameters=parameters)
        return dataclasses.replace(result, tau=result.tau * (1 + 1e-7))

    report = check_solver(scheme, Perturbed(good, control_torques=control_torques), samples=2)
    assert [row.quantity for row in report.rows if not row.passed] == ["control torques"]


@pytest.mark.compile
@pytest.mark.parametrize("method", ["es", "vi"])
def test_check_at_a_dt_no_step_takes_says_so_in_one_line(tmp_path, method):
    """--dt 1e300: the step fails at the first random state (es on NaN, vi on a spring segment).
    Before: numpy's RuntimeWarning over two lines (es), then 'step failed after 2 Newton
    iterations: ...' without the check or the dt it was at."""
    result = subprocess.run([sys.executable, "-m", "chaingen", "check",
                             str(scene_path("three_link_mono")), "--method", method,
                             "--dt", "1e300", "--samples", "1"],
                            capture_output=True, text=True, cwd=tmp_path)
    assert result.returncode == 1, result.stderr
    (line,) = result.stderr.strip().splitlines()
    assert line.startswith("chaingen: error: check: a step of dt = 1e+300 s from a random state "
                           "near the scene's initial one failed, so nothing was compared: "
                           "step failed after ")
    assert line.endswith("; check at a dt the scene runs with (--dt)")
