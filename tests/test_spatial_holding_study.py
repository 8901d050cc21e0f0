"""Study e (docs/studies-spatial-holding.md, docs/studies/spatial_holding.py): the torques it
integrates are the generated solver's, and they are right: the generated holding torques equal
the numpy statics of chaingen.spatial.dynamics, the generated inverse dynamics (the midpoint
residual at a step centred on the state) equals Pinocchio's RNEA plus the numpy spring torques
and the damping, and with the spring's stiffness and rest length as parameters the torques are
a + k b - k L_0 c, the quadratic the closed form solves. The document's numbers are the
script's (its run with a coarse grid: they do not depend on the grid).
"""
from __future__ import annotations

import importlib.util
import re

import numpy as np
import pytest
from test_spatial_dynamics import pinocchio_model

from chaingen.spatial import dynamics
from chaingen.spatial.parameters import with_values

from helpers import ROOT

pytestmark = pytest.mark.compile
DOC = ROOT / "docs" / "studies-spatial-holding.md"


def study():
    spec = importlib.util.spec_from_file_location(
        "spatial_holding", ROOT / "docs" / "studies" / "spatial_holding.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


STUDY = study()
_built: dict = {}


def solvers():
    """(the parameterised solver of the Panda with its multi-articular spring, the one of the
    bare Panda), built once."""
    if not _built:
        from chaingen.simulation import build_solver
        multi, bare = STUDY.arm_scenes()
        _built["multi"] = build_solver(multi, "midpoint", parameters=STUDY.PARAMETERS,
                                       sensitivities=False)
        _built["bare"] = build_solver(bare, "midpoint", sensitivities=False)
    return _built["multi"], _built["bare"]


def drawn(seed: int, count: int = 6):
    rng = np.random.default_rng(seed)
    q = rng.uniform(-2.0, 2.0, (count, 7))
    return q, rng.uniform(-1.0, 1.0, (count, 7)), rng.uniform(-3.0, 3.0, (count, 7))


@pytest.mark.parametrize("values", [{}, {"springs[0].stiffness": 1234.5,
                                         "springs[0].rest_length": 0.61}])
@pytest.mark.slow
def test_the_generated_holding_torques_are_the_numpy_statics(values):
    solver, _ = solvers()
    multi, _ = STUDY.arm_scenes()
    scene = with_values(multi, values)
    q, _, _ = drawn(1)
    generated = STUDY.holding(solver, q, values or None)
    expected = np.array([dynamics.gravity_torques(scene, row) + dynamics.spring_torques(scene, row)
                         for row in q])
    scale = np.abs(expected).max()
    assert np.abs(generated - expected).max() <= 1e-13 * scale, \
        np.abs(generated - expected).max() / scale


def test_the_generated_inverse_dynamics_is_pinocchios_rnea_with_the_spring_and_damping():
    solver, bare = solvers()
    multi, plain = STUDY.arm_scenes()
    pin, model = pinocchio_model(plain)
    data = model.createData()
    q, qdot, qddot = drawn(2)
    values = {"springs[0].stiffness": 950.0, "springs[0].rest_length": 0.55}
    scene = with_values(multi, values)
    damping = np.array([link.damping for link in plain.links])
    rnea = np.array([pin.rnea(model, data, a, b, c) + damping * b
                     for a, b, c in zip(q, qdot, qddot)])
    springs = np.array([dynamics.spring_torques(scene, row) for row in q])
    without = STUDY.inverse_dynamics(bare, q, qdot, qddot)
    with_spring = STUDY.inverse_dynamics(solver, q, qdot, qddot, values)
    scale = np.abs(rnea).max()
    assert np.abs(without - rnea).max() <= 1e-12 * scale
    assert np.abs(with_spring - rnea - springs).max() <= 1e-12 * scale


def test_the_torques_are_the_quadratic_the_closed_form_solves():
    """tau(k, L_0) = a + k b - k L_0 c at drawn settings (a the bare arm's, b and c numpy's),
    and the closed form's (k, L_0) is a stationary point that no nearby setting beats."""
    solver, bare = solvers()
    multi, _ = STUDY.arm_scenes()
    t, q, qdot, qddot = STUDY.quintic_path(samples=61)
    a = STUDY.inverse_dynamics(bare, q, qdot, qddot)
    lengths, b, c = STUDY.spring_terms(multi, q)
    for k, rest in ((300.0, 0.45), (2100.0, 0.72)):
        tau = STUDY.inverse_dynamics(solver, q, qdot, qddot, {"springs[0].stiffness": k,
                                                              "springs[0].rest_length": rest})
        assert np.abs(tau - (a + k * b - k * rest * c)).max() <= 1e-12 * np.abs(tau).max()
    best = STUDY.closed_form(t, a, b, c, float(lengths.min()))
    k, rest = best["stiffness"], best["rest_length"]
    assert best["cost"] == pytest.approx(STUDY.cost(t, a + k * b - k * rest * c), rel=1e-12)
    for dk, dl in ((1.0, 0.0), (-1.0, 0.0), (0.0, 1e-3), (0.0, -1e-3), (5.0, -1e-3)):
        moved = a + (k + dk) * b - (k + dk) * (rest + dl) * c
        assert STUDY.cost(t, moved) > best["cost"]
    tension = best["tension_only"]
    assert tension["rest_length"] == lengths.min() and tension["stiffness"] >= 0.0


def numbers(text: str) -> list[float]:
    return [float(x) for x in re.findall(r"-?\d+(?:\.\d+)?", text)]


def test_the_documents_numbers_are_the_scripts(monkeypatch):
    """The study's run (a 3 x 3 grid here: the costs along the path, the closed form and the
    lengths do not depend on the grid) gives the numbers the document states."""
    monkeypatch.setattr(STUDY, "STIFFNESS", np.array([100.0, 1400.0, 2500.0]))
    monkeypatch.setattr(STUDY, "REST_LENGTH", np.array([0.3, 0.5, 0.7]))
    results = STUDY.run()
    doc = " ".join(DOC.read_text().split())
    exact, tension = results["exact"], results["exact"]["tension_only"]
    stated = [f"{results['without']:.1f}", f"{results['scene']:.1f}",
              f"{exact['cost']:.1f}", f"{exact['stiffness']:.1f} N/m",
              f"{exact['rest_length']:.4f} m", f"{results['without_rms']:.2f} N m",
              f"{results['inertial_rms']:.3f} N m", f"{results['optimum_rms']:.2f} N m",
              f"{results['length_range'][0]:.4f}", f"{results['length_range'][1]:.4f}",
              f"{100 * (results['scene'] / results['without'] - 1):+.1f}%",
              f"{100 * (exact['cost'] / results['without'] - 1):+.1f}%"]
    for text in stated:
        assert text in doc, text
    assert tension["stiffness"] == 0.0 and "never compressed" in doc
    assert results["optimum_compressed_fraction"] == 1.0 and not results["scene_compressed"]
