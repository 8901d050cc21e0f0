"""Steps of order 4 and 6 by symmetric composition (docs/model.md, section 14): the measured
orders in angles and rates, what each stage keeps (es: energy and constraints, the energy
balance), the step sensitivities through the stages, and what is refused."""
from __future__ import annotations

import math
from functools import cache

import numpy as np
import pytest

from chaingen.errors import SceneError, SettingsError
from chaingen.generate.package import generate_package, scheme_label
from chaingen.scene import ORDERS, parse_scene
from chaingen.symbolic.composition import COMPOSITIONS, FROM_ORDER_4
from chaingen.symbolic.schemes import build_scheme, es, galerkin

from helpers import load, scene_path

#: Newton to round-off, so that the measured errors are the steps' own.
TIGHT = {"reuse_jacobian": 0, "residual_tol": 1e-14, "update_rtol": 1e-14,
         "update_atol": 1e-14, "max_iterations": 50}
T_END = 1.0
#: Two steps where every composed order is above the reference's error floor (1e-14 rad); es at
#: order 6, the most accurate, is at 2e-15 rad at dt = 0.05 s on three_link_multi, so it
#: takes two longer steps: 0.25 and 0.125 s, where its error is 4.6e-11 and 7.6e-13 rad (at
#: 0.2 and 0.1 s, 1.5e-11 and 1.5e-13 rad in the angles give 6.65 on that scene, though the
#: fit over six steps from 1/3 to 0.1 s is 6.05; model.md 14).
DTS = (0.1, 0.05)
LONGER_DTS = {("es", 6): (0.25, 0.125)}
CASES = [("es", 4), ("es", 6), ("vi", 4), ("vi", 6), ("midpoint", 4), ("midpoint", 6)]


@cache
def solver(name: str, method: str, order: int, quadrature: int = 3, sensitivities=False):
    from chaingen.simulation import build_solver
    return build_solver(load(name), method, quadrature, order=order,
                        sensitivities=sensitivities)


@cache
def reference(name: str):
    from chaingen.reference.scipy_peer import reference_solution
    return reference_solution(load(name), T_END)


def wrapped(angle):
    return (np.asarray(angle) + math.pi) % (2 * math.pi) - math.pi


# -- the compositions themselves (no compiler) ------------------------------------------------

@pytest.mark.parametrize("order", ORDERS)
def test_compositions_are_symmetric_and_consistent(order):
    """Fractions summing to 1, palindromic; order 4 and 6 also meet sum g^3 = 0 (and g^5)."""
    fractions = np.array(COMPOSITIONS[order])
    assert math.isclose(fractions.sum(), 1.0, abs_tol=1e-15)
    np.testing.assert_array_equal(fractions, fractions[::-1])
    for power in range(3, order, 2):
        assert abs((fractions ** power).sum()) < 1e-15, power


def test_a_scene_names_its_order_and_a_bad_one_is_refused():
    text = scene_path("three_link_mono").read_text()
    scene = parse_scene(text.replace("[simulation]", "[simulation]\norder = 4"), "s.toml", "s")
    assert scene.simulation.order == 4
    with pytest.raises(SceneError, match=r"simulation.order: must be one of 2, 4, 6"):
        parse_scene(text.replace("[simulation]", "[simulation]\norder = 3"), "s.toml", "s")


def test_es_composes_its_galerkin_step_to_order_6_and_refuses_k_1():
    """es at order 6: Suzuki's 5 stages of the k = 1 Galerkin step (order 4) in joint space;
    at order 4 its own COM step composed; K = 1 is too few nodes for the Galerkin step."""
    scene = load("three_link_mono")
    sixth = build_scheme(scene, "es", 3, order=6)
    fourth = build_scheme(scene, "es", 3, order=4)
    assert sixth.summary == galerkin.SUMMARY and fourth.summary == es.SUMMARY
    assert sixth.composition == FROM_ORDER_4 and len(fourth.composition) == 5
    assert sixth.unknowns.shape[0] == 4 * scene.n
    assert sixth.state_from_joint_space and not fourth.state_from_joint_space
    assert "4-point Gauss-Lobatto quadrature of every term (K = 3)" in scheme_label(sixth)
    assert "3-point Gauss-Legendre quadrature of the spring terms" in scheme_label(fourth)
    with pytest.raises(SettingsError, match=r"--quadrature: es at order 6 .* needs K >= 2"):
        build_scheme(scene, "es", 1, order=6)


def test_composed_es_chains_its_sensitivities_in_the_whole_state():
    """es's state is more than s = (phi, omega): its stages chain dx1/dx0, and joint_maps
    takes the product to joint space; vi chains in s and has no joint_maps."""
    scene = load("four_link_actuated")
    es = generate_package(scene, "es", 3, order=4, sensitivities=True)
    vi = generate_package(scene, "vi", 3, order=4, sensitivities=True)
    assert "_model_joint_maps," in es.files[f"{es.prefix}.c"]
    assert ".chain_state = 1," in es.files[f"{es.prefix}.c"]
    assert ".joint_maps = NULL," in vi.files[f"{vi.prefix}.c"]
    assert ".chain_state = 0," in vi.files[f"{vi.prefix}.c"]


def test_order_2_generates_no_composition_and_4_does():
    scene = load("three_link_mono")
    plain = generate_package(scene, "midpoint", 3, sensitivities=False)
    composed = generate_package(scene, "midpoint", 3, order=4, sensitivities=False)
    assert "STAGES" not in plain.files[f"{plain.prefix}.c"]
    assert ".nstage = 0," in plain.files[f"{plain.prefix}.c"]
    assert ".nstage = 5," in composed.files[f"{composed.prefix}.c"]
    assert composed.manifest["order"] == 4
    assert composed.manifest["input_hash"] != plain.manifest["input_hash"]


# -- measured -------------------------------------------------------------------------------

@pytest.mark.compile
@pytest.mark.parametrize("name", ["three_link_mono", "three_link_multi"])
@pytest.mark.parametrize("method, order", CASES)
def test_composed_steps_reach_their_order_in_angles_and_rates(name, method, order):
    """Error at t = 1 s against DOP853 at its tightest tolerances, for dt and dt/2: the
    observed order in the angles and in the rates within 0.2 of 4 and 0.3 of 6."""
    phi_ref, omega_ref = reference(name)
    scene = load(name)
    built = solver(name, method, order)
    angle_errors, rate_errors = [], []
    for dt in LONGER_DTS.get((method, order), DTS):
        run = built.simulate(scene.initial_angles, scene.initial_velocities, dt=dt,
                             n_steps=round(T_END / dt), every=round(T_END / dt), options=TIGHT)
        angle_errors.append(np.abs(wrapped(run.phi[-1] - phi_ref)).max())
        rate_errors.append(np.abs(run.omega[-1] - omega_ref).max())
    tolerance = 0.2 if order == 4 else 0.3
    for errors in (angle_errors, rate_errors):
        assert abs(math.log2(errors[0] / errors[1]) - order) <= tolerance, (errors, order)


@pytest.mark.compile
@pytest.mark.parametrize("order", [4, 6])
def test_composed_es_keeps_energy_and_constraints(order):
    """es of order 4 and 6 (K = 5) over 10 s at dt = 0.05 s: energy error <= 1e-12 J,
    constraint error <= 1e-13 (none at order 6: joint angles), though one stage in five steps
    backwards."""
    scene = load("three_link_mono")
    run = solver("three_link_mono", "es", order, quadrature=5).simulate(
        scene.initial_angles, scene.initial_velocities, dt=0.05, n_steps=200, every=1)
    assert np.abs(run.energy_error).max() <= 1e-12
    assert run.constraint_error.max() <= 1e-13


@pytest.mark.compile
@pytest.mark.parametrize("order", [4, 6])
def test_composed_es_keeps_the_energy_balance_with_torques_and_damping(order):
    """four_link_actuated (damping, actuation): per step H_1 - H_0 = work - dissipated, the
    flows summed over the stages, to round-off of H (49 J). At order 6 with the default K = 3
    and the package's Newton defaults: the Galerkin step's energy correction (model.md 16)
    closes what its quadrature leaves (without it, 2.5e-8 of H over 10 s)."""
    scene = load("four_link_actuated")
    built = solver("four_link_actuated", "es", order, quadrature=5 if order == 4 else 3)
    rng = np.random.default_rng(16)
    torques = rng.uniform(-1.0, 1.0, (400, len(scene.actuated_joints)))
    run = built.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01, n_steps=400,
                         every=1, torques=torques)
    balance = np.diff(run.energy) - np.diff(run.column("input_work")) \
        + np.diff(run.column("dissipated"))
    assert np.abs(balance).max() <= 1e-12
    assert np.abs(run.column("dissipated")[-1]) > 1e-3     # the damping did something


@pytest.mark.compile
@pytest.mark.parametrize("name, method, order", [
    ("three_link_multi", "vi", 4), ("three_link_multi", "vi", 6),
    ("four_link_actuated", "midpoint", 4), ("four_link_actuated", "midpoint", 6),
    ("three_link_multi", "es", 4), ("four_link_actuated", "es", 4),
    ("three_link_multi", "es", 6), ("four_link_actuated", "es", 6)])
@pytest.mark.slow
def test_composed_sensitivities_match_central_differences(name, method, order):
    """d s1/d s0 and d s1/d u of the composed step, by the chain rule through the stages,
    against central differences of the composed step (to 1e-6)."""
    scene = load(name)
    built = solver(name, method, order, sensitivities=True)
    n, nu = scene.n, len(scene.actuated_joints)
    phi = np.asarray(scene.initial_angles) + 0.1
    omega = np.asarray(scene.initial_velocities) + 0.2
    u = 0.3 * np.ones(nu) if nu else None
    dt, h = 0.02, 1e-6

    def s1(phi, omega, u=u):
        x1 = built.step(built.initial_state(phi, omega), u, dt, options=TIGHT).x1
        angles, rates, _, _ = built.outputs(x1)
        return np.concatenate([angles, rates])

    sensitivities = built.step_sensitivities(built.initial_state(phi, omega), u, dt, options=TIGHT)
    for j in range(2 * n):
        e = np.zeros(2 * n)
        e[j] = h
        numeric = (s1(phi + e[:n], omega + e[n:]) - s1(phi - e[:n], omega - e[n:])) / (2 * h)
        assert np.abs(sensitivities.ds_ds[:, j] - numeric).max() <= 1e-6, j
    for j in range(nu):
        e = np.zeros(nu)
        e[j] = h
        numeric = (s1(phi, omega, u + e) - s1(phi, omega, u - e)) / (2 * h)
        assert np.abs(sensitivities.ds_du[:, j] - numeric).max() <= 1e-6, j


@pytest.mark.compile
@pytest.mark.parametrize("name", ["three_link_gravity", "three_link_mono", "three_link_multi"])
def test_vi_at_order_4_with_default_options_is_not_held_by_newton(name):
    """vi at order 4, dt = 0.001 s, t = 10 s, the package's default options, against DOP853:
    within 1e-10 rad (measured 4.2e-13 to 4.1e-12 rad with Newton-chord, its default at orders 4
    and 6; simplified Newton, the default before, stopped at 1.9e-10 to 5.4e-10 rad)."""
    from chaingen.reference.scipy_peer import reference_solution

    scene = load(name)
    phi_ref, _ = reference_solution(scene, 10.0)
    run = solver(name, "vi", 4).simulate(scene.initial_angles, scene.initial_velocities,
                                         dt=0.001, n_steps=10_000, every=10_000)
    error = np.abs(wrapped(run.phi[-1] - phi_ref)).max()
    assert error <= 1e-10, error
