"""No compiler: es's exact discrete gradient of a spring (docs/model.md, section 4) against the
energy change computed in 50-digit arithmetic, for segments and steps that hypothesis draws
(one to three segments, steps from 1e-12 to 10 times the segment's size).

The gradient G of chaingen.symbolic.com_recursion.exact_spring_gradient must satisfy
sum_j G_j . dd_j = V(1) - V(0) to round-off of the terms, at any step; the K-point average
alone (the "quadrature" gradient) must not, on large steps: the check can tell them apart."""
from __future__ import annotations

import mpmath
import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from chaingen.scene.values import Spring
from chaingen.symbolic.com_recursion import (
    averaged_spring_gradient,
    chain_rule_spring_gradient,
    exact_spring_gradient,
)
from chaingen.symbolic.recursion import Definitions

mpmath.mp.dps = 50


def gradient_function(segments: int, quadrature: int, gradient: str):
    """numpy function (starts, changes, stiffness, rest) -> G (segments x 2) of one spring."""
    starts = [tuple(sp.symbols(f"d{j}_x d{j}_y", real=True)) for j in range(segments)]
    changes = [tuple(sp.symbols(f"dd{j}_x dd{j}_y", real=True)) for j in range(segments)]
    stiffness, rest = sp.symbols("k S0", positive=True)
    spring = Spring(1, segments, stiffness, rest, None)
    defs = Definitions("t_")
    js = list(range(1, segments + 1))
    if gradient == "exact":
        totals = exact_spring_gradient(spring, 0, js, starts, changes, quadrature, defs)
    elif gradient == "chain":
        totals = chain_rule_spring_gradient(spring, 0, js, starts, changes, defs)
    else:
        totals = averaged_spring_gradient(spring, 0, js, starts, changes, quadrature, defs)
    expressions = [entry for total in totals for entry in total]
    for symbol, value in reversed(defs.items):
        expressions = [sp.sympify(e).xreplace({symbol: value}) for e in expressions]
    arguments = [c for v in starts for c in v] + [c for v in changes for c in v] + [stiffness,
                                                                                  rest]
    function = sp.lambdify(arguments, expressions, "numpy")
    return lambda d, dd, k, s0: np.array(function(*d.ravel(), *dd.ravel(), k, s0),
                                         dtype=float).reshape(segments, 2)


FUNCTIONS = {(segments, quadrature, gradient): gradient_function(segments, quadrature, gradient)
             for segments in (1, 2, 3) for quadrature in (1, 3)
             for gradient in ("exact", "quadrature", "chain")}


def energy_change(d, dd, k, s0):
    """V(1) - V(0) of k/2 (sum_j |d_j| - S0)^2 in 50 digits."""
    def energy(vectors):
        total = sum(mpmath.sqrt(mpmath.mpf(x) ** 2 + mpmath.mpf(y) ** 2) for x, y in vectors)
        return mpmath.mpf(k) / 2 * (total - mpmath.mpf(s0)) ** 2
    ends = [(mpmath.mpf(a) + mpmath.mpf(b), mpmath.mpf(c) + mpmath.mpf(e))
            for (a, c), (b, e) in zip(d, dd)]
    return energy(ends) - energy(d)


def mismatch(d, dd, k, s0, segments, quadrature, gradient):
    """|sum_j G_j . dd_j - dV| in units of what round-off allows: 1e-13 of the work's terms,
    k (L + S0 + |dd|) sum_j |dd_j| (a force k (L - S0) is a difference of terms of size k L and
    k S0, whose round-off no gradient can avoid), plus 64 eps of the energy's scale
    k (L + S0 + |dd|)^2 (below the step delta = c_K min_j (s_j(0) + s_j(1)) / 2 the correction
    fades out, leaving the quadrature's error, which is there below the round-off of the energy
    itself). A value <= 1 is exact."""
    G = FUNCTIONS[segments, quadrature, gradient](d, dd, k, s0)
    work = sum(mpmath.mpf(float(g)) * mpmath.mpf(float(c)) for g, c in zip(G.ravel(),
                                                                            dd.ravel()))
    steps = np.linalg.norm(dd, axis=1)
    scale = k * (np.linalg.norm(d, axis=1).sum() + s0 + steps.sum())
    allowed = 1e-13 * scale * steps.sum() + 64 * np.finfo(float).eps * scale ** 2 / k
    error = float(abs(work - energy_change(d, dd, k, s0)))
    return error / allowed if allowed > 0 else error


vectors = st.tuples(st.floats(0.05, 2.0), st.floats(0.0, 2 * np.pi))


@st.composite
def spring_steps(draw):
    segments = draw(st.integers(1, 3))
    d = np.array([[r * np.cos(a), r * np.sin(a)] for r, a in
                  (draw(vectors) for _ in range(segments))])
    scale = 10.0 ** draw(st.floats(-12, 1))
    dd = np.array([[np.cos(a), np.sin(a)] for a in
                   (draw(st.floats(0.0, 2 * np.pi)) for _ in range(segments))])
    dd *= scale * np.array([draw(st.floats(0.1, 1.0)) for _ in range(segments)])[:, None]
    k = 10.0 ** draw(st.floats(0, 6))
    rest = draw(st.floats(0.0, 3.0))
    return d, dd, k, rest, segments


@given(spring_steps(), st.sampled_from([1, 3]))
@settings(max_examples=300, deadline=None)
def test_the_exact_gradient_is_exact_at_any_step(step, quadrature):
    d, dd, k, rest, segments = step
    assert mismatch(d, dd, k, rest, segments, quadrature, "exact") <= 1.0


@given(spring_steps())
@settings(max_examples=300, deadline=None)
def test_the_chain_rule_gradient_is_exact_at_any_step(step):
    d, dd, k, rest, segments = step
    assert mismatch(d, dd, k, rest, segments, 1, "chain") <= 1.0


def test_the_chain_rule_gradient_at_rest_is_the_gradient():
    """A step that does not move the spring: the chain rule's gradient is the spring's own
    gradient k (L - S0) d_j / s_j, finite (no division by the step)."""
    d = np.array([[0.3, 0.1], [0.2, -0.4]])
    G = FUNCTIONS[2, 1, "chain"](d, np.zeros_like(d), 100.0, 0.5)
    s = np.linalg.norm(d, axis=1)
    np.testing.assert_allclose(G, 100.0 * (s.sum() - 0.5) * d / s[:, None], rtol=1e-15)


def test_the_correction_is_smooth_at_rest():
    """At a step that hardly moves the spring the correction fades out smoothly: the gradient's
    derivative in dd (what the Newton matrix and a controller's step Jacobians take) is that of
    the K-point average to round-off, not round-off divided by |dd|^2."""
    d = np.array([[0.3, 0.1], [0.2, -0.4]])
    for size in (1e-14, 1e-10, 1e-6):
        for column in range(4):
            seed = np.zeros(4)
            seed[column] = 1e-7
            slopes = {}
            for gradient in ("exact", "quadrature"):
                g = FUNCTIONS[2, 3, gradient]
                base = np.full((2, 2), size)
                up = g(d, base + seed.reshape(2, 2), 1e4, 0.5)
                down = g(d, base - seed.reshape(2, 2), 1e4, 0.5)
                slopes[gradient] = (up - down) / 2e-7
            scale = np.abs(slopes["quadrature"]).max()
            assert np.abs(slopes["exact"] - slopes["quadrature"]).max() <= 1e-6 * scale


def test_a_step_that_does_not_move_the_spring_has_the_averaged_gradient():
    d = np.array([[0.3, 0.1], [0.2, -0.4]])
    dd = np.zeros_like(d)
    exact = FUNCTIONS[2, 3, "exact"](d, dd, 100.0, 0.5)
    averaged = FUNCTIONS[2, 3, "quadrature"](d, dd, 100.0, 0.5)
    assert np.all(np.isfinite(exact))
    np.testing.assert_array_equal(exact, averaged)


@pytest.mark.parametrize("quadrature", [1, 3])
def test_the_quadrature_alone_is_not_exact_on_large_steps(quadrature):
    """The check discriminates: the K-point average misses the energy change on a step of the
    segment's size by far more than round-off."""
    d = np.array([[0.3, 0.1], [0.2, -0.4]])
    dd = np.array([[0.25, 0.3], [-0.3, 0.2]])
    assert mismatch(d, dd, 1e3, 0.5, 2, quadrature, "quadrature") > 1e6
    assert mismatch(d, dd, 1e3, 0.5, 2, quadrature, "exact") <= 1.0
