"""es's composed steps report the rates of the velocity projected onto C(q) v = 0: by recursions
over the links (com_recursion.projected_rates, O(n)), which must equal the dense KKT solve
[[M, C^T], [C, 0]] (v_t, lambda) = (M v, 0) of model.md 14 for velocities off the tangent space,
on chains with uneven links, off-axis centres of mass and zero inertias."""
from __future__ import annotations

import numpy as np
import pytest
import sympy as sp
from hypothesis import example, given, settings
from hypothesis import strategies as st

from chaingen.scene import parse_scene
from chaingen.symbolic.com_model import com_model
from chaingen.symbolic.schemes import build_scheme

from helpers import load

pytestmark = pytest.mark.fast


def chain_text(links) -> str:
    lines = ['name = "projection"', "gravity = 9.81", "", "[base]", "fastening = 0.05", ""]
    for mass, length, com, normal, inertia in links:
        lines += ["[[links]]", f"mass = {mass!r}", f"inertia = {inertia!r}",
                  f"length = {length!r}", f"com = {com!r}", f"com_normal = {normal!r}",
                  "fastening = 0.05", ""]
    n = len(links)
    lines += ["[initial]", f"angles = [{', '.join(['0.1'] * n)}]",
              f"velocities = [{', '.join(['0.0'] * n)}]"]
    return "\n".join(lines)


def kkt_rates(model, q, v) -> np.ndarray:
    """Joint rates of the dense projection: v_t from the KKT system, then its rates."""
    n = model.n
    values = dict(zip(model.q, q))
    mass = np.array(model.mass_matrix, dtype=float)
    jacobian = np.array(model.constraint_jacobian.xreplace(values), dtype=float)
    system = np.block([[mass, jacobian.T], [jacobian, np.zeros((n, n))]])
    tangent = np.linalg.solve(system, np.concatenate([mass @ v, np.zeros(n)]))[:2 * n]
    absolute = [float(rate.xreplace({**values, **dict(zip(model.v, tangent))}))
                for rate in model.absolute_rates()]
    return np.diff(np.concatenate([[0.0], absolute]))


def exact_kkt_rates(model, q, v) -> np.ndarray:
    """kkt_rates in exact rational arithmetic at the given numbers (the model's coefficients
    as rationals): the reference where the KKT system is ill-conditioned."""
    n = model.n
    rational = lambda expression: sp.nsimplify(expression, rational=True)   # noqa: E731
    values = {symbol: sp.Rational(float(x)) for symbol, x in zip(model.q, q)}
    mass = sp.Matrix(model.mass_matrix).applyfunc(rational)
    jacobian = sp.Matrix(model.constraint_jacobian).applyfunc(rational).xreplace(values)
    system = sp.BlockMatrix([[mass, jacobian.T], [jacobian, sp.zeros(n, n)]]).as_explicit()
    moved = mass * sp.Matrix([sp.Rational(float(x)) for x in v])
    tangent = system.LUsolve(sp.Matrix(list(moved) + [0] * n))[:2 * n]
    absolute = [float(rational(rate).xreplace({**values, **dict(zip(model.v, tangent))}))
                for rate in model.absolute_rates()]
    return np.diff(np.concatenate([[0.0], absolute]))


def recursion_rates(scheme, q, v) -> np.ndarray:
    n = scheme.scene.n
    rates = scheme.state_function(list(scheme.maps.joint_velocities))
    return np.asarray(rates(*q, *v), float).ravel()[:n]


def on_manifold(scheme, rng):
    """A state of the scheme (q on the constraints) with v off the tangent space."""
    n = scheme.scene.n
    start = scheme.initial_function()
    x = np.asarray(start(*rng.uniform(-1.5, 1.5, n), *rng.uniform(-2, 2, n)), float).ravel()
    q, v = x[:2 * n], x[2 * n:]
    return q, v + 0.05 * rng.standard_normal(2 * n)


@settings(max_examples=12, deadline=None)
@given(links=st.lists(st.tuples(st.floats(0.2, 5.0), st.floats(0.1, 1.0), st.floats(0.02, 0.9),
                                st.floats(-0.2, 0.2), st.sampled_from([0.0, 0.01, 0.3])),
                      min_size=1, max_size=4),
       seed=st.integers(0, 2 ** 32 - 1))
@example(links=[(1.0, 0.625, 0.75, 0.0, 0.0), (1.0, 0.75, 0.375, 0.0, 0.0),
                (1.0, 1.0, 0.0234375, 0.0, 0.0), (1.0, 1.0, 0.0234375, 0.0, 0.3)], seed=0)
@pytest.mark.heavy
def test_projected_rates_equal_the_kkt_solve(links, seed):
    """To 1e-10 of the largest rate; where the two differ by more, the draw is ill-conditioned
    (the example: links 3 and 4 with their COMs 0.023 m from their joints, link 3 without
    inertia, KKT condition number 2.5e12), and both are compared with the exact solve: the
    recursion must be within 1e-10 of the largest rate plus 100 times the dense LU's own error.
    Measured on the example: the recursion 5.1e-8 rad/s from the exact rates (-249 rad/s the
    largest), the dense solve 2.0e-9; a wrong recursion is off by O(1)."""
    scene = parse_scene(chain_text(links), "<projection>", "projection")
    scheme = build_scheme(scene, "es", 1, order=4)
    model = com_model(scene)
    q, v = on_manifold(scheme, np.random.default_rng(seed))
    expected = kkt_rates(model, q, v)
    got = recursion_rates(scheme, q, v)
    scale = np.abs(expected).max()
    if np.all(np.abs(got - expected) <= 1e-10 * (np.abs(expected) + scale)):
        return
    exact = exact_kkt_rates(model, q, v)
    dense_error = np.abs(expected - exact).max()
    assert np.abs(got - exact).max() <= 1e-10 * scale + 100 * dense_error, (got, expected, exact)


def test_projected_rates_differ_from_the_plain_ones_off_the_tangent_space():
    """The projection is not the identity there (so the test above can fail), and on the
    tangent space it is (the order-2 rates)."""
    scene = load("three_link_multi")
    composed, plain = build_scheme(scene, "es", 3, order=4), build_scheme(scene, "es", 3)
    q, v = on_manifold(composed, np.random.default_rng(1))
    assert np.abs(recursion_rates(composed, q, v) - recursion_rates(plain, q, v)).max() > 1e-3
    model = com_model(scene)
    q_symbols = dict(zip(model.q, q))
    jacobian = np.array(model.constraint_jacobian.xreplace(q_symbols), dtype=float)
    tangent = v - jacobian.T @ np.linalg.lstsq(jacobian.T, v, rcond=None)[0]
    np.testing.assert_allclose(recursion_rates(composed, q, tangent),
                               recursion_rates(plain, q, tangent), rtol=1e-10, atol=1e-12)
