"""The step's constants (generate/step_constants.py): what the residual and the Newton factors
compute from the step's start alone, taken out into one function the runtime evaluates once a
Newton solve. A differential test: a package with them against the same scheme's package
without them, every entry point that evaluates those functions, bit for bit. A stale y (an entry
point that evaluated the residual at another start than its constants') would differ."""
import numpy as np
import pytest

from chaingen.generate import package as package_module
from chaingen.generate.package import generate_package
from chaingen.generate.step_constants import with_step_constants
from chaingen.runtime import Solver
from chaingen.studies.bench.scenes import uneven_scene
from tests.helpers import load

SCENES = {
    # es's arm solve with the exact gradient's chord factors, COMs off the axes
    "uneven": (lambda: uneven_scene(5), ()),
    # joint torques u and damping
    "actuated": (lambda: load("four_link_actuated"), ()),
    # run-time parameters: y depends on q = Q(p)
    "parameters": (lambda: load("four_link_actuated"), ("links[1].mass",
                                                         "springs[0].stiffness")),
}


def both_packages(monkeypatch, scene, parameters, order=2):
    hoisted = generate_package(scene, "es", 3, parameters=parameters, order=order)
    monkeypatch.setattr(package_module, "with_step_constants", lambda functions, prefix:
                        functions)
    whole = generate_package(scene, "es", 3, parameters=parameters, order=order)
    return hoisted, whole


def test_es_packages_of_the_arm_solve_have_them_and_others_do_not():
    """Generated only where Newton's functions are the arm solve's (planar es from 4 links)."""
    from chaingen.generate.casadi_functions import scheme_functions
    from chaingen.symbolic.schemes import build_scheme

    arm = with_step_constants(scheme_functions(build_scheme(uneven_scene(5), "es", 3), "t",
                                               sensitivities=False), "t")
    assert arm.step_constants is not None and arm.step_constants.size1_out(0) > 0
    assert arm.residual.name_in()[-1] == "y" and arm.chord_factors.name_in()[-1] == "y"
    dense = scheme_functions(build_scheme(load("three_link_mono"), "es", 3), "t",
                             sensitivities=False)
    assert with_step_constants(dense, "t") is dense


@pytest.mark.compile
@pytest.mark.parametrize("name", sorted(SCENES))
def test_the_step_constants_change_no_bit(monkeypatch, name):
    make, parameters = SCENES[name]
    scene = make()
    hoisted, whole = both_packages(monkeypatch, scene, parameters)
    assert ".ny = 0," in whole.files[f"{whole.prefix}.c"]
    assert ".ny = 0," not in hoisted.files[f"{hoisted.prefix}.c"]
    a, b = Solver.from_files(hoisted.files), Solver.from_files(whole.files)
    p = None
    if parameters:
        p = a.parameter_values() * 1.1
    x0 = a.initial_state(scene.initial_angles, scene.initial_velocities, parameters=p)
    u = np.linspace(0.2, -0.3, a.nu) if a.nu else None
    # A run: every step a Newton solve at a new start (and its splits, if any).
    run_a = a.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01, n_steps=300,
                       parameters=p)
    run_b = b.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01, n_steps=300,
                       parameters=p)
    np.testing.assert_array_equal(run_a.samples, run_b.samples)
    assert run_a.mean_newton_iterations == run_b.mean_newton_iterations
    # The entry points, one after another on one workspace at different starts: each must
    # evaluate the constants of its own start.
    rng = np.random.default_rng(7)
    start = x0
    for k in range(4):
        z = rng.normal(scale=1e-2, size=a.nz)
        dt = 0.01 * (1 + k)
        np.testing.assert_array_equal(a.residual(z, start, u, dt, parameters=p),
                                      b.residual(z, start, u, dt, parameters=p))
        for got, want in zip(a.residual_jacobian(z, start, u, dt, parameters=p),
                             b.residual_jacobian(z, start, u, dt, parameters=p)):
            np.testing.assert_array_equal(got, want)
        step_a, step_b = a.step(start, u, dt, parameters=p), b.step(start, u, dt, parameters=p)
        np.testing.assert_array_equal(step_a.x1, step_b.x1)
        sa = a.step_sensitivities(start, u, dt, parameters=p)
        sb = b.step_sensitivities(start, u, dt, parameters=p)
        for got, want in zip((sa.x1, sa.ds_ds, sa.ds_du, sa.ds_dp),
                             (sb.x1, sb.ds_ds, sb.ds_du, sb.ds_dp)):
            np.testing.assert_array_equal(got, want)
        start = step_a.x1


@pytest.mark.compile
def test_a_composed_step_and_a_split_step_keep_every_bit(monkeypatch):
    """Order 4 (stages of other dt at other starts) and a step too long for the chain (split
    into halves: solves at the halves' starts) on the uneven chain."""
    scene = uneven_scene(5)
    hoisted, whole = both_packages(monkeypatch, scene, (), order=4)
    a, b = Solver.from_files(hoisted.files), Solver.from_files(whole.files)
    for dt in (0.01, 0.2):
        run_a = a.simulate(scene.initial_angles, scene.initial_velocities, dt=dt, n_steps=40)
        run_b = b.simulate(scene.initial_angles, scene.initial_velocities, dt=dt, n_steps=40)
        np.testing.assert_array_equal(run_a.samples, run_b.samples)
        assert run_a.split_steps == run_b.split_steps
    x0 = a.initial_state(scene.initial_angles, scene.initial_velocities)
    sa, sb = a.step_sensitivities(x0, dt=0.02), b.step_sensitivities(x0, dt=0.02)
    np.testing.assert_array_equal(sa.ds_ds, sb.ds_ds)
