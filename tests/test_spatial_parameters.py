"""Run-time parameters of spatial scenes (chaingen.spatial.parameters): which numbers a spatial
solver takes (gravity[j], links[i].mass and .damping, springs[i].stiffness and .rest_length),
the geometry it refuses in one line, and the differential test: a parameterised solver run with
drawn values gives the run of the solver built from the scene with those values compiled in.
"""
from __future__ import annotations

import numpy as np
import pytest
import sympy as sp
from hypothesis import given, settings
from hypothesis import strategies as st

from chaingen.errors import SceneError
from chaingen.runtime.contract import lower_bound
from chaingen.scene import SolverSpec, SolverSpecError
from chaingen.spatial import load_spatial_scene
from chaingen.spatial.parameters import (
    compiled_paths,
    number_path,
    value,
    with_symbols,
    with_values,
)
from chaingen.symbolic.spatial_recursion import constant

from helpers import ROOT, chaingen_in_process

SPATIAL = ROOT / "scenes" / "spatial_three_link.toml"
SCENE = load_spatial_scene(SPATIAL)
EXIT_BAD_INPUT = 2


# -- the numbers ---------------------------------------------------------------------------------

def test_the_run_time_numbers_of_a_spatial_scene_and_their_units():
    assert compiled_paths(SCENE) == (
        "gravity[0]", "gravity[1]", "gravity[2]",
        "links[0].mass", "links[0].damping", "links[1].mass", "links[1].damping",
        "links[2].mass", "links[2].damping",
        "springs[0].stiffness", "springs[0].rest_length",
        "springs[1].stiffness", "springs[1].rest_length")
    units = {path: number_path(SCENE, path).unit for path in compiled_paths(SCENE)}
    assert units["gravity[2]"] == "m/s^2" and units["links[1].mass"] == "kg"
    assert units["links[1].damping"] == "N m s/rad" and units["springs[1].stiffness"] == "N/m"
    assert units["springs[0].rest_length"] == "m"
    assert value(SCENE, "gravity[2]") == -9.81 and value(SCENE, "links[1].damping") == 0.05
    assert value(SCENE, "springs[1].rest_length") == 0.25
    for path in ("initial.angles[2]", "initial.velocities[0]", "simulation.dt"):
        assert not number_path(SCENE, path).compiled
    # A component of gravity may be negative (it points down); the other bounds are the reader's.
    assert lower_bound("gravity[2]") is None
    assert lower_bound("links[0].mass").rule == "> 0"


@pytest.mark.parametrize("path, fragment", [
    ("links[0].com", "links[0].com: compiled geometry of a spatial scene"),
    ("links[1].inertia", "links[1].inertia: compiled geometry"),
    ("links[2].joint", "links[2].joint: compiled geometry"),
    ("links[2].joint.axis", "links[2].joint.axis: compiled geometry"),
    ("springs[1].route[0]", "springs[1].route[0]: compiled geometry"),
    ("gravity", "gravity: a vector; name one component"),
    ("gravity[3]", "gravity has 3 components"),
    ("links[3].mass", "links[3] does not exist: the scene has 3 links"),
    ("springs[0].joints", "names no number of a spatial spring"),
    ("actuation.joints", "is structure"),
    ("initial.angles[3]", "joint 4 does not exist"),
    ("links[01].mass", "write links[1].mass"),
])
def test_what_is_no_run_time_number_is_refused_in_one_line(path, fragment):
    with pytest.raises(SceneError) as refused:
        number_path(SCENE, path)
    assert fragment in str(refused.value) and "\n" not in str(refused.value)
    if fragment.endswith("geometry of a spatial scene"):
        assert "gravity[0..2], links[i].mass, links[i].damping" in str(refused.value)
    with pytest.raises(SolverSpecError, match="parameters: "):
        SolverSpec.create(SCENE, "midpoint", parameters=(path,))


def test_with_values_judges_by_the_spatial_readers_rules():
    changed = with_values(SCENE, {"links[1].mass": 2.5, "gravity[0]": -1.5,
                                  "springs[1].rest_length": 0.0, "initial.angles[1]": 0.2,
                                  "simulation.dt": 0.001})
    assert changed.links[1].mass == 2.5 and changed.gravity == (-1.5, 0.0, -9.81)
    assert changed.springs[1].rest_length == 0.0 and changed.initial_angles[1] == 0.2
    assert changed.links[0] == SCENE.links[0] and changed.springs[0] == SCENE.springs[0]
    with pytest.raises(SceneError, match=r"^run: links\[1\]\.mass: must be > 0 .*got -1\.0$"):
        with_values(SCENE, {"links[1].mass": -1.0}, where="run")
    with pytest.raises(SceneError, match=r"springs\[0\]\.stiffness: must be > 0"):
        with_values(SCENE, {"springs[0].stiffness": 0.0}, where="run")


def test_constant_passes_a_parameters_symbol_through():
    g = sp.Dummy("g")
    assert constant((0.0, 1.5, g)) == (sp.Integer(0), sp.Float(1.5), g)
    assert constant(np.eye(2)) == ((1, 0), (0, 1))
    symbolic = with_symbols(SCENE, {"gravity[1]": g, "links[0].mass": sp.Dummy("m")})
    assert symbolic.gravity[1] is g and isinstance(symbolic.links[0].mass, sp.Dummy)
    assert symbolic.links[1] == SCENE.links[1]


def test_generate_documents_a_spatial_packages_parameters(tmp_path):
    result = chaingen_in_process("generate", SPATIAL, "--method", "vi", "--no-sensitivities",
                                 "--parameters", "gravity[2],springs[1].stiffness",
                                 "-o", "out", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    header = next((tmp_path / "out").glob("*.h")).read_text()
    assert "gravity[2]" in header and "springs[1].stiffness" in header
    bad = chaingen_in_process("generate", SPATIAL, "--parameters", "links[0].com", "-o", "bad",
                              cwd=tmp_path)
    assert bad.returncode == EXIT_BAD_INPUT and not (tmp_path / "bad").exists()
    assert bad.stderr.splitlines() == [
        "chaingen: error: --parameters: links[0].com: compiled geometry of a spatial scene (it "
        "shapes the generated code); its run-time numbers: gravity[0..2], links[i].mass, "
        "links[i].damping, springs[i].stiffness, springs[i].rest_length"]


# -- the differential test: parameters = the numbers compiled in --------------------------------

_solvers: dict = {}


def parameterised(method: str):
    """The solver of SCENE with every run-time number a parameter, built once per method."""
    if method not in _solvers:
        from chaingen.simulation import build_solver
        _solvers[method] = build_solver(SCENE, method, parameters="all", sensitivities=False)
    return _solvers[method]


def drawn_values():
    return st.fixed_dictionaries({
        "gravity[0]": st.floats(-3.0, 3.0), "gravity[2]": st.floats(-12.0, -5.0),
        "links[1].mass": st.floats(0.5, 4.0), "links[2].damping": st.floats(0.0, 0.5),
        "springs[0].stiffness": st.floats(50.0, 600.0),
        "springs[1].rest_length": st.floats(0.0, 0.5)})


@pytest.mark.compile
@pytest.mark.parametrize("method, examples", [("midpoint", 3), ("vi", 1), ("es", 1)])
@pytest.mark.slow
def test_a_run_with_parameters_is_the_run_with_the_numbers_compiled_in(method, examples):
    """Drawn values of gravity, a mass, a damping, a stiffness and a rest length: the
    parameterised solver's 40 steps equal those of the solver built from the scene with the
    values (with_values), to round-off (the constants are folded otherwise)."""
    from chaingen.simulation import build_solver

    @settings(max_examples=examples, deadline=None, derandomize=True, database=None)
    @given(values=drawn_values())
    def check(values):
        solver = parameterised(method)
        run = solver.simulate(SCENE.initial_angles, SCENE.initial_velocities, dt=0.005,
                              n_steps=40, parameters=values)
        assert run.parameters == {**dict(zip(solver.parameters,
                                             map(float, solver.parameter_values()))), **values}
        compiled = build_solver(with_values(SCENE, values), method, sensitivities=False)
        reference = compiled.simulate(SCENE.initial_angles, SCENE.initial_velocities, dt=0.005,
                                      n_steps=40)
        np.testing.assert_allclose(run.phi, reference.phi, rtol=0, atol=1e-12)
        np.testing.assert_allclose(run.omega, reference.omega, rtol=0, atol=1e-11)
        np.testing.assert_allclose(run.energy, reference.energy, rtol=1e-12, atol=1e-12)

    check()


@pytest.mark.compile
def test_a_parameter_outside_its_range_is_refused_and_a_downward_gravity_is_not():
    solver = parameterised("midpoint")
    with pytest.raises(ValueError, match=r"^links\[0\]\.mass: must be > 0, got -2\.0$"):
        solver.simulate(SCENE.initial_angles, SCENE.initial_velocities, dt=0.01, n_steps=2,
                        parameters={"links[0].mass": -2.0})
    with pytest.raises(ValueError, match=r"springs\[1\]\.rest_length: must be >= 0"):
        solver.simulate(SCENE.initial_angles, SCENE.initial_velocities, dt=0.01, n_steps=2,
                        parameters={"springs[1].rest_length": -0.1})
    run = solver.simulate(SCENE.initial_angles, SCENE.initial_velocities, dt=0.01, n_steps=2,
                          parameters={"gravity[2]": -20.0, "gravity[0]": -1.0})
    assert np.isfinite(run.phi).all()


@pytest.mark.compile
def test_check_compares_the_parameter_derivatives_of_a_spatial_solver():
    """`chaingen check --parameters all` on the spatial scene: d s1 / d p against central
    differences, gravity's zero components and the zero damping of links 1 and 3 among them
    (drawn around 0.1, within their ranges)."""
    import subprocess
    import sys

    result = subprocess.run([sys.executable, "-m", "chaingen", "check", str(SPATIAL),
                             "--method", "midpoint", "--parameters", "all", "--samples", "3"],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "d s1 / d p" in result.stdout and "FAIL" not in result.stdout
