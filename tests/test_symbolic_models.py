"""No compiler: the SymPy models and the three schemes, checked numerically against the
independent numpy kinematics of chaingen.scene.kinematics (straight from docs/model.md 1-3).

The three-link scenes are in the fast tier; the four- and five-link chains, whose SymPy
expressions take seconds each to derive and evaluate, are `heavy` (the default run has them)."""
from __future__ import annotations

import zlib

import casadi as ca
import numpy as np
import pytest
import sympy as sp

from chaingen.errors import UnsupportedSceneError
from chaingen.generate.casadi_functions import SympyToCasadi, scheme_functions
from chaingen.generate.casadi_source import mark_parameters_used
from chaingen.scene import kinematics
from chaingen.symbolic.com_model import com_model
from chaingen.symbolic.quadrature import gauss_legendre_nodes
from chaingen.symbolic.schemes import build_scheme

from helpers import OWN_SCENES, REFERENCE_SCENES, load

ALL_SCENES = REFERENCE_SCENES + OWN_SCENES
rng = np.random.default_rng(20261122)


@pytest.fixture(autouse=True)
def reseed(request):
    """Each test draws the same random states whichever tests ran before it (the tiers select
    different ones): the generator restarts from a seed of the test's own id."""
    global rng
    rng = np.random.default_rng([20261122, zlib.crc32(request.node.nodeid.encode())])


def numeric(expr_matrix, symbols, values):
    return np.array(sp.lambdify(list(symbols), expr_matrix, "numpy", cse=True)(*values),
                    dtype=float).reshape(-1)


HEAVY = pytest.mark.heavy


def case(name: str, method: str, heavy: bool = False):
    return pytest.param((name, method), id=f"{name}-{method}", marks=HEAVY if heavy else ())


# "es" on every scene; "vi" and "midpoint" on the reference scenes and one of our own (their
# SymPy expressions are large to lambdify for n = 5; n = 5 is covered by the compile tier).
SCHEME_CASES = ([case(name, "es", name in OWN_SCENES) for name in ALL_SCENES]
                + [case(name, method, name in OWN_SCENES) for method in ("vi", "midpoint")
                   for name in REFERENCE_SCENES + ("four_link_antagonist",)])


_schemes: dict = {}


def built(name, method):
    if (name, method) not in _schemes:
        _schemes[name, method] = build_scheme(load(name), method, 3)
    return _schemes[name, method]


@pytest.fixture(scope="module", params=SCHEME_CASES)
def scheme(request):
    return built(*request.param)


@pytest.fixture(scope="module", params=[
    pytest.param(name, marks=HEAVY if name in OWN_SCENES else ()) for name in ALL_SCENES])
def es_scheme(request):
    return built(request.param, "es")


# The CasADi translation is the same code for every scheme: n = 3 covers vi and midpoint,
# whose n = 4 residuals take minutes to lambdify. vi's n = 3 residuals take seconds: heavy.
TRANSLATION_CASES = ([case(name, "es", name in OWN_SCENES) for name in ALL_SCENES]
                     + [case(name, "midpoint") for name in REFERENCE_SCENES]
                     + [case(name, "vi", heavy=True) for name in REFERENCE_SCENES])


def output_values(scheme, x):
    """(phi, omega, energy) of the scheme at state x."""
    outputs = scheme.state_function(list(scheme.joint_angles) + list(scheme.joint_velocities)
                                    + [scheme.energy])
    values = np.array(outputs(*x), dtype=float).ravel()
    n = scheme.scene.n
    return values[:n], values[n:2 * n], values[2 * n]


def initial(scheme, phi, phidot):
    """x(phi, phidot), evaluating the scheme's initial definitions in order."""
    return np.array(scheme.initial_function()(*phi, *phidot), dtype=float).ravel()


def random_joint_state(n):
    return rng.uniform(-np.pi, np.pi, n), rng.normal(0.0, 1.5, n)


def test_mass_matrix_is_constant_symmetric_positive_definite(es_scheme):
    scheme = es_scheme
    model = com_model(scheme.scene)
    M = model.mass_matrix
    assert M.free_symbols == set()
    M = np.array(M, dtype=float)
    np.testing.assert_array_equal(M, M.T)
    assert np.linalg.eigvalsh(M).min() > 0


def test_initial_state_satisfies_the_constraints(es_scheme):
    scheme = es_scheme
    model = com_model(scheme.scene)
    for _ in range(5):
        phi, phidot = random_joint_state(scheme.scene.n)
        x = initial(scheme, phi, phidot)
        c = numeric(model.constraints, scheme.state, x)
        np.testing.assert_allclose(c, 0.0, atol=1e-13)
        # velocity constraint C(q) v = 0: the initial velocity is tangent to the manifold
        C = np.array(sp.lambdify(list(scheme.state), model.constraint_jacobian)(*x), dtype=float)
        np.testing.assert_allclose(C @ x[2 * scheme.scene.n:], 0.0, atol=1e-12)


def test_energy_equals_the_independent_kinematics(scheme):
    """H(x(phi, phidot)) of the scheme = T + V computed from model.md 1-3 in plain numpy."""
    scene = scheme.scene
    for _ in range(5):
        phi, phidot = random_joint_state(scene.n)
        energy = output_values(scheme, initial(scheme, phi, phidot))[2]
        reference = kinematics.total_energy(scene, phi, phidot)
        assert energy == pytest.approx(reference, rel=1e-12, abs=1e-12)


def test_joint_space_round_trip(scheme):
    """outputs(initial_state(phi, phidot)) = (phi wrapped to (-pi, pi], phidot)."""
    n = scheme.scene.n
    for _ in range(5):
        phi, phidot = random_joint_state(n)
        phi_unwrapped = phi + 2 * np.pi * rng.integers(-2, 3, n)
        angles, rates, _ = output_values(scheme, initial(scheme, phi_unwrapped, phidot))
        np.testing.assert_allclose(angles, phi, atol=1e-12)
        np.testing.assert_allclose(rates, phidot, atol=1e-12)


@pytest.mark.heavy
def test_spring_segment_lengths_equal_the_kinematics():
    scene = load("five_link_biarticular")
    model = com_model(scene)
    scheme = build_scheme(scene, "es", 1)
    phi, phidot = random_joint_state(scene.n)
    x = initial(scheme, phi, phidot)
    for terms in model.springs:
        lengths = numeric(sp.Matrix(terms.segment_lengths), model.q, x[:2 * scene.n])
        reference = kinematics.spring_geometry(scene, terms.spring, phi).segment_lengths
        np.testing.assert_allclose(lengths, reference, rtol=1e-13)


def test_generate_only_what_the_scene_needs():
    gravity_only = build_scheme(load("three_link_gravity"), "es", 3)
    assert not any(e.has(sp.sqrt) or any(isinstance(a, sp.Pow) and a.exp.is_Rational
                                         and not a.exp.is_Integer for a in sp.preorder_traversal(e))
                   for e in gravity_only.residual), "no spring terms without springs"
    import dataclasses
    weightless = dataclasses.replace(load("three_link_mono"), gravity=0.0)
    model = com_model(weightless)
    assert model.gravity_potential == 0


@pytest.mark.parametrize("points", [1, 2, 3, 5, 8])
def test_gauss_legendre_is_exact_to_degree_2k_minus_1(points):
    nodes, weights = gauss_legendre_nodes(points)
    assert sum(weights) == pytest.approx(1.0, abs=1e-15)
    for degree in range(2 * points):
        integral = sum(w * t ** degree for t, w in zip(nodes, weights))
        assert integral == pytest.approx(1.0 / (degree + 1), abs=1e-14)
    integral = sum(w * t ** (2 * points) for t, w in zip(nodes, weights))
    assert integral != pytest.approx(1.0 / (2 * points + 1), abs=1e-14)


@pytest.mark.parametrize("case", TRANSLATION_CASES)
def test_casadi_functions_equal_sympy(case):
    """The CasADi translation evaluates to the SymPy residual and state maps."""
    scheme = built(*case)
    functions = scheme_functions(scheme, "t")
    n, nx, nz = scheme.scene.n, len(scheme.state), len(scheme.unknowns)
    for _ in range(3):
        z, x0, dt = rng.normal(0, 0.3, nz), rng.normal(0, 1.0, nx), 0.01
        values = list(z) + list(x0) + [dt]
        # SymPy evaluates the scheme's definitions (intermediate symbols) in order, then the
        # residual: the same expressions, without CasADi.
        np.testing.assert_allclose(np.array(functions.residual(z, x0, dt)).ravel(),
                                   np.array(scheme.step_function(scheme.residual)(*values)),
                                   rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(np.array(functions.next_state(z, x0, dt)).ravel(),
                                   np.array(scheme.step_function(scheme.next_state)(*values)),
                                   rtol=1e-13, atol=1e-14)
    for _ in range(3):
        phi, phidot = random_joint_state(n)
        x = initial(scheme, phi, phidot)
        outputs = functions.outputs(x)
        angles, rates, energy = output_values(scheme, x)
        np.testing.assert_allclose(np.array(outputs[0]).ravel(), angles, atol=1e-13)
        np.testing.assert_allclose(np.array(outputs[1]).ravel(), rates, atol=1e-12)
        assert float(outputs[2]) == pytest.approx(energy, rel=1e-13)
    phi, phidot = random_joint_state(n)
    np.testing.assert_allclose(np.array(functions.initial_state(phi, phidot)).ravel(),
                               initial(scheme, phi, phidot), rtol=1e-13, atol=1e-14)


def test_translation_of_powers_and_functions():
    x, y = sp.symbols("x y")
    X, Y = ca.SX.sym("x"), ca.SX.sym("y")
    translate = SympyToCasadi({x: X, y: Y})
    expr = (sp.sqrt(x) + x ** -1 + 1 / sp.sqrt(y) + x ** 3 + x ** sp.Rational(3, 2)
            + sp.atan2(y, x) + sp.sin(x) * sp.cos(y))
    f = ca.Function("f", [X, Y], [translate(expr)])
    for a, b in [(0.7, 1.3), (2.0, 0.2)]:
        assert float(f(a, b)) == pytest.approx(float(expr.subs({x: a, y: b})), rel=1e-14)


def test_translation_of_n_argument_max_and_min():
    x, y, z = sp.symbols("x y z")
    X, Y, Z = ca.SX.sym("x"), ca.SX.sym("y"), ca.SX.sym("z")
    translate = SympyToCasadi({x: X, y: Y, z: Z})
    f = ca.Function("f", [X, Y, Z], [translate(sp.Max(x, y, z)), translate(sp.Min(x, y, z))])
    for values in [(0.7, 1.3, -2.0), (2.0, 0.2, 1.0), (-1.0, 3.0, 5.0)]:
        largest, smallest = f(*values)
        assert (float(largest), float(smallest)) == (max(values), min(values))


def test_unbound_symbol_is_an_error():
    from chaingen.generate.casadi_functions import MissingInputError, check_free_symbols
    x, y = sp.symbols("x y")
    with pytest.raises(MissingInputError, match="y"):
        check_free_symbols("f", [x + y], [x])


def test_com_at_the_proximal_joint_is_refused_clearly():
    import dataclasses
    scene = load("three_link_gravity")
    links = list(scene.links)
    links[1] = dataclasses.replace(links[1], com=0.0, com_normal=0.0)
    with pytest.raises(UnsupportedSceneError, match=r"links\[1\]\.com"):
        com_model(dataclasses.replace(scene, links=tuple(links)))


def test_unused_parameters_are_marked():
    source = ("static int casadi_f0(const casadi_real** arg, casadi_real** res, casadi_int* iw,"
              " casadi_real* w, int mem) {\n  return 0;\n}\nint g(void) {\n  return 1;\n}\n")
    marked = mark_parameters_used(source)
    assert "(void)arg; (void)res; (void)iw; (void)w; (void)mem;" in marked
    assert "int g(void) {\n  return 1;" in marked
