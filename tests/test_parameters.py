"""Run-time parameters: a solver that takes some of a scene's numbers per call computes what the
solver with those numbers compiled in computes, and its d s1/dp are the derivatives."""
from __future__ import annotations

import math

import numpy as np
import pytest

from chaingen.errors import SettingsError
from chaingen.scene.parameters import compiled_paths, with_values
from chaingen.simulation import build_solver
from chaingen.symbolic.schemes import build_scheme

from helpers import chaingen_in_process, load, scene_path

#: The scenes of the equality test: one mono-articular, one multi-articular, and one with a
#: multi-articular spring, actuation, damping and gravity.
SCENES = ("three_link_mono", "three_link_multi", "four_link_actuated")
METHODS = ("es", "vi", "midpoint")
T_END, DT = 2.0, 0.01


#: The parameters of each scene's solver: every number of the three-link scenes; a subset of
#: the four-link one's that touches every kind (gravity, damping, an off-axis COM, a link's
#: geometry, the multi-articular spring, the fastenings), its every number making the build of
#: four solvers with sensitivities the slowest part of the compile tier.
PARAMETERS = {"three_link_mono": ("all",), "three_link_multi": ("all",),
              "four_link_actuated": ("gravity", "base.fastening", "links[0].damping",
                                     "links[1].com_normal", "links[1].fastening",
                                     "links[2].mass", "links[2].damping", "links[3].length",
                                     "springs[1].stiffness", "springs[1].rest_length")}


def paths_of(name: str) -> tuple[str, ...]:
    paths = PARAMETERS[name]
    return compiled_paths(load(name)) if paths == ("all",) else paths


def changed_values(scene, paths=None) -> dict[str, float]:
    """The numbers at `paths` (default: every number the solver may take), moved off the
    scene's values (a zero to a small one), still valid by the scene rules: the parameterised
    run must see each of them."""
    values = {}
    for path, value in zip(compiled_paths(scene), _values(scene)):
        if paths is not None and path not in paths:
            continue
        if path == "gravity":
            values[path] = value * 1.05 if value else 3.0
        elif path.endswith(".damping"):
            values[path] = value * 1.2 if value else 0.05
        elif path.endswith(".com_normal"):
            values[path] = value * 0.8 if value else 0.02
        else:
            values[path] = value * 1.07
    return values


def _values(scene) -> list[float]:
    from chaingen.scene.parameters import number_path
    return [number_path(scene, path).value(scene) for path in compiled_paths(scene)]


def torques(scene, steps: int) -> np.ndarray | None:
    if not scene.actuated_joints:
        return None
    t = np.arange(steps)[:, None] * DT
    return 0.5 * np.sin(2.0 * t + np.arange(len(scene.actuated_joints))[None, :])


_parameterised: dict = {}


def parameterised(name: str, method: str):
    """The solver of a scene taking every number as a parameter (with sensitivities)."""
    if (name, method) not in _parameterised:
        _parameterised[name, method] = build_solver(load(name), method, 3, sensitivities=True,
                                                    parameters=paths_of(name))
    return _parameterised[name, method]


@pytest.mark.compile
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", SCENES)
@pytest.mark.slow
def test_parameters_equal_baked_numbers(name, method):
    scene = load(name)
    values = changed_values(scene, paths_of(name))
    baked_scene = with_values(scene, values)
    solver = parameterised(name, method)
    assert solver.parameters == paths_of(name)
    baked = build_solver(baked_scene, method, 3, sensitivities=False)
    steps = round(T_END / DT)
    u = torques(scene, steps)
    ours = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=DT,
                           n_steps=steps, torques=u, parameters=values)
    reference = baked.simulate(scene.initial_angles, scene.initial_velocities, dt=DT,
                               n_steps=steps, torques=u)
    assert ours.parameters == values
    np.testing.assert_allclose(ours.phi[-1], reference.phi[-1], rtol=0, atol=1e-10)
    np.testing.assert_allclose(ours.omega[-1], reference.omega[-1], rtol=0, atol=1e-10)
    # The runs moved: the changed numbers are not the scene's (else the test shows nothing).
    default = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=DT,
                              n_steps=steps, torques=u)
    assert np.abs(default.phi[-1] - ours.phi[-1]).max() > 1e-4


@pytest.mark.compile
@pytest.mark.parametrize("method", ["vi", "midpoint"])
def test_the_energy_check_takes_the_energy_of_the_new_parameters(method):
    """The energy check keeps (H, T) of the state the last step ended in; new parameters change
    H there, so a step that continues with them must not be checked against the old H (a
    spring 100 times stiffer would put its energy change into the balance and refuse the
    step)."""
    scene = load("three_link_mono")
    solver = parameterised("three_link_mono", method)
    path = "springs[0].stiffness"
    moving = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=DT,
                             n_steps=100, every=100)
    x0 = solver.initial_state(moving.phi[-1], moving.omega[-1])
    x1 = solver.step(x0, dt=DT).x1
    stiffer = {path: 100 * scene.springs[0].stiffness}
    assert np.all(np.isfinite(solver.step(x1, dt=DT, parameters=stiffer).x1))


@pytest.mark.compile
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", SCENES)
def test_parameter_sensitivities_match_central_differences(name, method):
    scene = load(name)
    solver = parameterised(name, method)
    values = solver.parameter_values(changed_values(scene, paths_of(name)))
    phi = np.asarray(scene.initial_angles) + 0.1
    omega = np.asarray(scene.initial_velocities) + 0.2
    u = None if not scene.actuated_joints else 0.3 * np.ones(len(scene.actuated_joints))
    options = {"reuse_jacobian": 0}

    def s1(p):
        x0 = solver.initial_state(phi, omega, p)
        x1 = solver.step(x0, u, DT, options=options, parameters=p).x1
        phi1, omega1, _, _ = solver.outputs(x1, p)
        return np.concatenate([phi1, omega1])

    x0 = solver.initial_state(phi, omega, values)
    analytic = solver.step_sensitivities(x0, u, DT, options=options, parameters=values).ds_dp
    assert analytic.shape == (2 * scene.n, len(values))
    for j, value in enumerate(values):
        # A step where truncation (h^2) and the noise of the solved steps (1e-12 / h) are both
        # far below the tolerance: 1e-8 and 1e-8.
        h = 1e-4 * max(1.0, abs(value))
        up, down = values.copy(), values.copy()
        up[j] += h
        down[j] -= h
        numeric = (s1(up) - s1(down)) / (2 * h)
        scale = max(1.0, np.abs(numeric).max())
        assert np.abs(analytic[:, j] - numeric).max() <= 1e-6 * scale, solver.parameters[j]


@pytest.mark.compile
def test_parameter_values_are_checked():
    solver = parameterised("three_link_mono", "es")
    scene = load("three_link_mono")
    with pytest.raises(ValueError, match="has no parameter 'links\\[7\\].mass'"):
        solver.parameter_values({"links[7].mass": 1.0})
    with pytest.raises(ValueError, match="parameters"):
        solver.parameter_values([1.0, 2.0])
    # The defaults are the scene's numbers.
    assert np.array_equal(solver.default_parameters, _values(scene))
    assert solver.parameters == compiled_paths(scene)


def test_build_scheme_refuses_bad_parameters():
    scene = load("three_link_mono")
    cases = {"links[9].mass": "links\\[9\\] does not exist",
             "springs[0].joints": "is structure",
             "initial.angles[0]": "run-time value",
             "simulation.dt": "run-time value",
             "links[0].colour": "names no number of a link"}
    for path, message in cases.items():
        with pytest.raises(SettingsError, match=message):
            build_scheme(scene, "es", 3, (path,))
    with pytest.raises(SettingsError, match="named twice"):
        build_scheme(scene, "es", 3, ("gravity", "gravity"))


def test_a_parameter_is_generated_code_a_constant_is_folded():
    """Gravity 0 and no damping generate nothing unless a study varies them."""
    scene = with_values(load("three_link_mono"), {"gravity": 0.0})
    assert all(link.damping == 0 for link in scene.links)
    baked = build_scheme(scene, "es", 3)
    varied = build_scheme(scene, "es", 3, ("gravity", "links[0].damping"))
    assert not baked.has_energy_flows and varied.has_energy_flows
    assert varied.parameter_paths == ("gravity", "links[0].damping")
    assert varied.parameter_units == ("m/s^2", "N m s/rad")
    assert varied.parameter_values == (0.0, 0.0)
    gravity, damping = varied.parameters
    assert gravity in varied.residual.free_symbols and damping in varied.residual.free_symbols
    assert not baked.residual.free_symbols & set(varied.parameters)


def test_generate_names_bad_parameters_in_one_line(tmp_path):
    result = chaingen_in_process("generate", scene_path("three_link_mono"), "--parameters",
                                 "links[1].mass,springs[3].stiffness", "-o", tmp_path / "pkg",
                                 cwd=tmp_path)
    assert result.returncode == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "springs[3]" in lines[0]
    assert not (tmp_path / "pkg").exists()


@pytest.mark.compile
def test_header_documents_parameters(tmp_path):
    from chaingen.generate.package import generate_package

    scene = load("three_link_mono")
    package = generate_package(scene, "es", 3, sensitivities=False,
                               parameters=("springs[0].stiffness", "links[1].mass"))
    header = package.files[f"{package.prefix}.h"]
    assert "springs[0].stiffness" in header and "N/m" in header
    assert "links[1].mass" in header and "kg" in header
    entries = package.manifest["parameters"]
    assert [entry["path"] for entry in entries] == ["springs[0].stiffness", "links[1].mass"]
    assert math.isclose(entries[0]["value"], scene.springs[0].stiffness)


@pytest.mark.parametrize("name", ["three_link_mono", "three_link_multi", "four_link_actuated",
                                  "four_link_antagonist", "five_link_biarticular"])
def test_scene_toml_reads_back_as_the_scene(name, tmp_path):
    from chaingen.scene import load_scene
    from chaingen.scene.document import scene_toml

    scene = with_values(load(name), {"links[0].mass": 1.2345678901234567})
    path = tmp_path / "scene.toml"
    path.write_text(scene_toml(scene))
    assert load_scene(path) == scene


def test_all_names_every_compiled_number():
    scene = load("four_link_actuated")
    scheme = build_scheme(scene, "midpoint", 3, ("all",))
    assert scheme.parameter_paths == compiled_paths(scene)
    assert len(scheme.parameter_paths) == 2 + 7 * 4 + 2 * 2
