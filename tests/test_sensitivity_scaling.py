"""Step sensitivities by directions (docs/model.md, section 11): the same Jacobians as the dense
functions, and generated code that grows linearly with the chain (issue 32 b)."""
from __future__ import annotations

import numpy as np
import pytest

from chaingen.generate import sensitivities
from chaingen.generate.casadi_functions import scheme_functions
from chaingen.generate.package import model_c_bytes, render_package
from chaingen.scene.solver_spec import SolverSpec
from chaingen.studies.bench.scenes import scaling_scene
from chaingen.symbolic.schemes import build_scheme

from helpers import load

rng = np.random.default_rng(20261205)
NAMES = ("sensitivity_rhs", "sensitivity_map", "joint_maps")


def point(functions, scheme, n_p: int) -> dict:
    """A step's arguments near a state of the scheme: z, x0, u (or None), p (the scene's own
    numbers perturbed, or None) and dt."""
    n, nu = scheme.scene.n, len(scheme.inputs)
    p = np.array(scheme.run_parameters.values, float) * rng.uniform(0.9, 1.1, n_p)
    phi = rng.uniform(-1.0, 1.0, n)
    x0 = np.array(functions.initial_state(phi, rng.normal(0, 1, n),
                                          *derived(functions, p, n_p))).ravel()
    return {"z": rng.normal(0, 0.01, len(scheme.unknowns)), "x0": x0,
            "u": rng.normal(0, 1, nu) if nu else None, "p": p if n_p else None, "dt": 0.01}


def derived(functions, p, n_p: int) -> list:
    """[q], q = Q(p) by these functions' own parameters function (each set of generated
    functions hoists its own q), or [] without parameters."""
    return [np.array(functions.parameters(p)).ravel()] if n_p else []


def step_arguments(functions, at: dict, n_p: int) -> list:
    """(z, x0, [u], [q], dt) of a step function of `functions`."""
    return ([at["z"], at["x0"]] + ([at["u"]] if at["u"] is not None else [])
            + derived(functions, at["p"], n_p) + [at["dt"]])


def functions_both_ways(spec: SolverSpec, monkeypatch):
    """The package's sensitivity functions dense and forced by directions."""
    scheme = build_scheme(spec)
    with monkeypatch.context() as patch:
        patch.setattr(sensitivities, "DENSE_MAX_ENTRIES", 10 ** 6)
        patch.setattr(sensitivities, "DENSE_MAX_INSTRUCTIONS", 10 ** 9)
        dense = scheme_functions(scheme, "t")
    with monkeypatch.context() as patch:
        patch.setattr(sensitivities, "SWEPT_MIN_LINKS", 0)
        swept = scheme_functions(scheme, "t")
    return scheme, dense, swept


CASES = [("four_link_actuated", "es", 2, ()), ("four_link_actuated", "vi", 2, ()),
         ("four_link_actuated", "midpoint", 4, ()), ("three_link_multi", "es", 4, ()),
         ("four_link_actuated", "es", 4, ("all",)), ("three_link_mono", "vi", 2, ("all",))]


@pytest.mark.parametrize(("name", "method", "order", "parameters"), CASES)
def test_sensitivities_by_directions_equal_the_dense_ones(name, method, order, parameters,
                                                          monkeypatch):
    """Forced by directions on small chains, the sensitivity functions return the dense ones'
    Jacobians to round-off, with inputs, run-time parameters and es's chain in x (order 4),
    and are the loops (MX functions) the dense ones are not."""
    spec = SolverSpec.create(load(name), method, 3, order=order, parameters=parameters)
    scheme, dense, swept = functions_both_ways(spec, monkeypatch)
    n_p = len(scheme.run_parameters.symbols)
    present = [field for field in NAMES if getattr(dense, field) is not None]
    assert present == (list(NAMES) if method == "es" and order == 4 else list(NAMES[:2]))
    for field in present:
        one, other = getattr(dense, field), getattr(swept, field)
        assert one.class_name() == "SXFunction" and other.class_name() == "MXFunction"
        assert one.name_out() == other.name_out()
        for _ in range(2):
            at = point(dense, scheme, n_p)
            if field == "joint_maps":
                x1 = at["x0"] + rng.normal(0, 1e-3, at["x0"].shape)
                arguments = [[at["x0"], x1] + derived(functions, at["p"], n_p)
                             for functions in (dense, swept)]
            else:
                arguments = [step_arguments(functions, at, n_p)
                             for functions in (dense, swept)]
            for a, b in zip(one.call(arguments[0]), other.call(arguments[1]), strict=True):
                a, b = np.array(a), np.array(b)
                assert a.shape == b.shape and a.size > 0
                np.testing.assert_allclose(b, a, rtol=1e-11, atol=1e-11 * np.abs(a).max())


def sensitivity_bytes(method: str, order: int, n: int) -> int:
    """Bytes of model C that the sensitivities add on the scaling chain of n links."""
    sizes = []
    for with_them in (True, False):
        spec = SolverSpec.create(scaling_scene(n), method, order=order,
                                 sensitivities=with_them)
        package = render_package(build_scheme(spec), sensitivities=with_them)
        sizes.append(model_c_bytes(package))
    return sizes[0] - sizes[1]


@pytest.mark.heavy
@pytest.mark.parametrize(("method", "order", "sizes", "limit"),
                         [("es", 2, (20, 40), 2.6), ("vi", 2, (20, 40), 2.6),
                          ("midpoint", 2, (20, 40), 2.6), ("es", 4, (10, 20), 2.9)])
@pytest.mark.slow
def test_the_sensitivity_code_grows_linearly_with_the_chain(method, order, sizes, limit):
    """The model C the sensitivities add on the scaling chain: doubling n from 20 to 40 at
    most 2.6x (measured: midpoint 2.37x, as the Newton Jacobian by directions grows there,
    2.2x; quadratic code would be 4x; dense, from 10 to 20, they grew 2.9x to 4.4x, and more
    with n). es at order 4, from n = 10 to
    20, up to 2.9x (measured 2.71x): its velocity projection's matrix has n^2 entries (the
    constraint Jacobian in COM coordinates), and joint_maps differentiates it; dense, its
    sensitivities grew 16x from n = 5 to 10."""
    small, large = (sensitivity_bytes(method, order, n) for n in sizes)
    assert large <= limit * small, (small, large)
