"""The C layer refuses what the scene format refuses, and hostile numbers, with a status.

- Run-time parameters out of the scene format's range (one table, contract.NUMBER_BOUNDS, which
  the reader uses too and the manifest records) or not finite: BAD_PARAMETER from every entry
  point that takes p.
- NaN or Inf where a state or posture goes in, dt <= 0 or not finite, step counts whose sample
  rows cannot exist (sample_count -1, no signed overflow): BAD_ARGUMENT.
- A start state or posture the scene reader refuses (a spring segment of zero length):
  SEGMENT_COLLAPSED from initial_state, holding_torques, step, step_sensitivities and simulate,
  whatever the round-off of the angles; outputs does not refuse it.
- simulate takes u NULL as zero torques; simulate_controlled records its torques once a sample.
- Scene names up to the format's longest generate and build; longer ones are refused.
- A cache index entry whose manifest was altered is not trusted.
- The CMake build without a build type optimises as the Makefile does.

The C calls go through tests/c_driver.py's driver (a C program over the package's sources).
"""
from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from c_driver import (
    BAD_ARGUMENT,
    BAD_PARAMETER,
    INTERRUPTED,
    LONG_MAX,
    OK,
    SEGMENT_COLLAPSED,
    Case,
    build_driver,
    generate,
    mismatches,
    run_driver,
)

from chaingen.runtime.contract import MAX_SCENE_NAME_LENGTH, NUMBER_BOUNDS, lower_bound

from helpers import ROOT, require_tools

#: The run-time parameters of the driven package: one of every kind of bound, and none.
PARAMETERS = ("links[0].mass", "links[1].inertia", "links[2].length", "links[2].com",
              "springs[0].stiffness", "springs[1].rest_length", "gravity", "links[0].damping",
              "base.fastening")
PHI = (0.3, 0.2, 0.1, 0.0)
U = (0.5, 0.1, 0.0, -0.2)
NAN, INF = math.nan, math.inf
#: The C columns of the driver that take p.
TAKES_P = ("initial_state", "outputs", "holding_torques", "residual", "residual_jacobian",
           "step", "step_sensitivities", "simulate", "simulate_null_u", "simulate_controlled")


@pytest.fixture(scope="module")
def package(tmp_path_factory):
    """four_link_actuated, midpoint at order 4 (inputs, energy flows, springs, sensitivities,
    the energy check, composed stages) with PARAMETERS, and the driver built on it."""
    directory = tmp_path_factory.mktemp("guards") / "package"
    generate(directory, "four_link_actuated", "midpoint", 4, PARAMETERS)
    return build_driver(directory, ["-O2"])


def case(package, **changes) -> Case:
    values = dict(dt=0.01, t0=0.0, n_steps=12, every=3, hold=2, stop=False, poison=0.0, phi=PHI,
                  u=U, p=tuple(package.defaults))
    return Case(**{**values, **changes})


def with_parameter(package, path: str, value: float) -> tuple:
    values = list(package.defaults)
    values[package.paths.index(path)] = value
    return tuple(values)


def drive(package, cases: list[Case]) -> list[dict]:
    results, process = run_driver(package, cases)
    assert process.returncode == 0, process.stderr
    assert mismatches(package, cases, results) == []
    return results


# --- Point 4: parameters the scene format refuses ----------------------------------------------

@pytest.mark.compile
def test_the_manifest_records_each_parameters_bound_from_the_one_table(package):
    for entry in package.manifest["parameters"]:
        bound = lower_bound(entry["path"])
        if bound is None:
            assert (entry["lower"], entry["lower_inclusive"]) == (None, True), entry
        else:
            assert (entry["lower"], entry["lower_inclusive"]) == (bound.value, bound.inclusive)
    recorded = {entry["path"]: entry["lower"] for entry in package.manifest["parameters"]}
    assert recorded["links[0].mass"] == 0.0 and recorded["links[2].com"] is None
    header = (package.directory / f"{package.prefix}.h").read_text()
    assert f"{package.prefix.upper()}_BAD_PARAMETER 10" in header
    assert "p[0] links[0].mass (kg; 1.0; > 0)" in header


@pytest.mark.compile
@pytest.mark.parametrize("path", PARAMETERS)
def test_every_entry_point_refuses_a_parameter_the_scene_format_refuses(package, path):
    bound = lower_bound(path)
    refused = [NAN, INF, -INF]
    admitted = [package.defaults[package.paths.index(path)]]
    if bound is not None:
        below = math.nextafter(bound.value, -math.inf)
        refused += [below, bound.value - 1.0] + ([] if bound.inclusive else [bound.value])
        admitted += [bound.value] if bound.inclusive else []
    else:
        admitted += [-1.0]
    cases = [case(package, p=with_parameter(package, path, value)) for value in refused]
    for result in drive(package, cases):
        assert {column: result[column] for column in TAKES_P} == dict.fromkeys(TAKES_P,
                                                                              BAD_PARAMETER)
    for result in drive(package, [case(package, p=with_parameter(package, path, value))
                                  for value in admitted]):
        assert result["initial_state"] == result["outputs"] == OK
        assert BAD_PARAMETER not in result.values()


def test_the_scene_reader_uses_the_same_bounds():
    """Each bound of the table, at and below it, as the scene reader judges it."""
    from chaingen import load_reference_scene
    from chaingen.errors import SceneError
    from chaingen.scene.parameters import with_values

    scene = load_reference_scene("three_link_multi")
    paths = {"gravity": "gravity", "dt": "simulation.dt", "t_end": "simulation.t_end",
             "stiffness": "springs[0].stiffness", "rest_length": "springs[0].rest_length"}
    for key, bound in NUMBER_BOUNDS.items():
        path = paths.get(key, f"links[0].{key}")
        assert lower_bound(path) == bound
        with pytest.raises(SceneError, match=re.escape(f"{path}: must be {bound.rule}")):
            with_values(scene, {path: math.nextafter(bound.value, -math.inf)})
        if bound.inclusive:
            with_values(scene, {path: bound.value})
        else:
            with pytest.raises(SceneError, match=re.escape(f"must be {bound.rule}")):
                with_values(scene, {path: bound.value})


# --- A start state the scene reader refuses: a spring segment of zero length --------------------

#: four_link_actuated's segment s_1 runs from P_1 = (0, b) (base.fastening b) to
#: P_2 = X_2 + 0.3 n_1; at phi_1 = atan2(1, 0.3) P_2 = (0, hypot(1, 0.3)): with that b, it has
#: zero length.
COLLAPSE_PHI1 = math.atan2(1.0, 0.3)
COLLAPSE_FASTENING = math.hypot(1.0, 0.3)
#: The angle and its neighbouring doubles: whether the start is refused must not hang on round-off.
COLLAPSE_ANGLES = (COLLAPSE_PHI1, math.nextafter(COLLAPSE_PHI1, 0.0),
                   math.nextafter(COLLAPSE_PHI1, 4.0))


def collapsing(package, phi1: float, shift: float = 0.0, **changes) -> Case:
    return case(package, phi=(phi1,) + PHI[1:],
                p=with_parameter(package, "base.fastening", COLLAPSE_FASTENING + shift),
                collapsed=shift == 0.0, **changes)


def test_the_collapsing_start_is_one_the_scene_reader_refuses():
    from chaingen import load_reference_scene
    from chaingen.errors import SceneError
    from chaingen.scene.parameters import with_values

    scene = load_reference_scene("four_link_actuated")
    angles = {f"initial.angles[{i}]": value for i, value in enumerate(PHI[1:], start=1)}
    for phi1 in COLLAPSE_ANGLES:
        with pytest.raises(SceneError, match="segment s_1 .* has zero length at the initial"):
            with_values(scene, {"base.fastening": COLLAPSE_FASTENING,
                                "initial.angles[0]": phi1, **angles})
        # 1e-7 m away: far above the reader's limit (1e-9 of the geometry's size, ~5 nm).
        with_values(scene, {"base.fastening": COLLAPSE_FASTENING + 1e-7,
                            "initial.angles[0]": phi1, **angles})


@pytest.mark.compile
def test_every_entry_point_refuses_a_start_whose_spring_segment_has_zero_length(package):
    """Before: initial_state and holding_torques returned OK (joint-1 torques of either sign
    for neighbouring doubles of phi_1), step and simulate ran from that state (checking only
    each step's new state), finishing OK or not by round-off."""
    cases = [collapsing(package, phi1, stop=stop) for phi1 in COLLAPSE_ANGLES
             for stop in (False, True)]
    started = ("initial_state", "holding_torques", "step", "step_sensitivities", "simulate",
               "simulate_null_u", "simulate_controlled")
    for result in drive(package, cases):
        assert {column: result[column] for column in started} \
            == dict.fromkeys(started, SEGMENT_COLLAPSED)
        assert result["outputs"] == OK     # a state's outputs are defined at zero length
    # A segment 1e-7 m long, which the scene reader accepts, is a start (its first step may
    # still stop, under the run's limit of 1e-6 of the size).
    for result in drive(package, [collapsing(package, phi1, shift=1e-7)
                                  for phi1 in COLLAPSE_ANGLES]):
        assert result["initial_state"] == result["holding_torques"] == OK


# --- Point 12: hostile numbers ------------------------------------------------------------------

@pytest.mark.compile
def test_nan_and_inf_inputs_are_refused(package):
    results = drive(package, [case(package, phi=(NAN,) + PHI[1:]),
                              case(package, phi=PHI[:3] + (INF,)),
                              case(package, poison=NAN),
                              case(package, poison=-INF)])
    for result in results[:2]:
        assert result["initial_state"] == result["holding_torques"] == BAD_ARGUMENT
    for result in results[2:]:
        assert result["outputs"] == result["simulate"] == BAD_ARGUMENT


@pytest.mark.compile
@pytest.mark.parametrize("dt", [0.0, -0.0, -0.01, NAN, INF, -INF])
def test_residual_step_and_simulate_refuse_a_bad_dt(package, dt):
    (result,) = drive(package, [case(package, dt=dt)])
    for column in ("residual", "residual_jacobian", "step", "step_sensitivities", "simulate",
                   "simulate_null_u", "simulate_controlled"):
        assert result[column] == BAD_ARGUMENT, column


@pytest.mark.compile
def test_sample_count_of_huge_counts_is_minus_one_not_an_overflow(package):
    nsample = package.manifest["nsample"]
    cases = [case(package, n_steps=n, every=every, stop=True)
             for n, every in [(LONG_MAX, 1), (LONG_MAX, 2), (LONG_MAX, nsample),
                              (LONG_MAX, 10 ** 6), (LONG_MAX - 1, 1), (LONG_MAX, LONG_MAX),
                              (0, LONG_MAX), (-1, 1), (5, 0), (-(2 ** 63), -(2 ** 63))]]
    results = drive(package, cases)
    counts = [result["sample_count"] for result in results]
    assert counts[:3] == [-1, -1, -1]
    assert counts[3] == LONG_MAX // 10 ** 6 + 1
    assert counts[4:] == [-1, 2, 1, 0, 0, 0]
    assert [result["simulate"] for result in results[:3]] == [BAD_ARGUMENT] * 3
    assert results[3]["simulate"] == INTERRUPTED     # rows that fit: it would run


# --- Point 10: u NULL, torques by sample --------------------------------------------------------

@pytest.mark.compile
@pytest.mark.parametrize("n_steps, every, hold", [(12, 3, 2), (10, 3, 1), (10, 4, 3), (7, 1, 2),
                                                  (5, 9, 1), (1, 1, 1), (0, 2, 1)])
def test_null_u_is_zero_torques_and_torques_are_recorded_once_a_sample(package, n_steps, every,
                                                                       hold):
    (result,) = drive(package, [case(package, n_steps=n_steps, every=every, hold=hold)])
    assert result["simulate_null_u"] == OK and result["null_u_is_zero_u"] == 1
    assert result["simulate_controlled"] == OK and result["torques_by_sample"] == 1


@pytest.mark.compile
def test_header_documents_null_u_and_the_torques_rows(package):
    header = (package.directory / f"{package.prefix}.h").read_text()
    assert "(u NULL: zero torques at every step)" in header
    assert "torques[ceil(n_steps / every) * NU]" in header


# --- Point 11: long scene names -----------------------------------------------------------------

def test_a_long_scene_name_generates_and_a_too_long_one_is_refused_in_one_line():
    """A name of 62 characters and more left no room for the status macros' comments (an
    internal error); names beyond MAX_SCENE_NAME_LENGTH would not fit the file system's 255
    bytes in the build cache's file names: the reader refuses them, and so does generation
    for a Scene made in Python, before any SymPy work."""
    from chaingen import load_reference_scene
    from chaingen.errors import SceneError
    from chaingen.generate.package import generate_package
    from chaingen.scene import parse_scene

    scene = load_reference_scene("three_link_gravity")
    for length in (62, 100):
        package = generate_package(dataclasses.replace(scene, name="x" * length), "es", 1,
                                   sensitivities=False)
        assert f"x{'x' * (length - 1)}_es_BAD_ARGUMENT".upper() in package.files[
            f"{package.prefix}.h"]
    text = (ROOT / "scenes" / "three_link_gravity.toml").read_text()
    text = re.sub(r'(?m)^name = .*$', f'name = "{"y" * (MAX_SCENE_NAME_LENGTH + 1)}"', text)
    with pytest.raises(SceneError) as refused:
        parse_scene(text, "long.toml", "long")
    assert str(refused.value).startswith("long.toml: name: must be at most 128 characters")
    assert "\n" not in str(refused.value)
    with pytest.raises(SceneError, match="name: must be at most 128 characters"):
        generate_package(dataclasses.replace(scene, name="z" * 129), "es", 1)


@pytest.mark.compile
def test_a_scene_name_of_the_longest_length_builds_and_runs(tmp_path):
    from chaingen import build_solver, load_reference_scene

    scene = load_reference_scene("three_link_gravity")
    scene = dataclasses.replace(scene, name="n" * MAX_SCENE_NAME_LENGTH)
    solver = build_solver(scene, "es", 1, sensitivities=False)
    result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01, n_steps=20)
    assert result.samples.shape[0] == 21 and abs(result.energy_error).max() < 1e-12


# --- Point 6: an altered manifest in the cache index --------------------------------------------

CHILD = """
import json, sys
import chaingen
scene = chaingen.load_reference_scene("three_link_gravity")
solver = chaingen.build_solver(scene, "midpoint", 3, sensitivities=False)
result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01, n_steps=50)
print(json.dumps({"phi": result.phi[-1].tolist(), "sympy": "sympy" in sys.modules,
                  "nsample": solver.nsample}))
"""


def child(cache: Path) -> dict:
    result = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True,
                            env={**os.environ, "CHAINGEN_CACHE_DIR": str(cache)}, timeout=600)
    assert result.returncode == 0, result.stderr[-2000:]
    return json.loads(result.stdout.strip().splitlines()[-1])


@pytest.mark.compile
@pytest.mark.parametrize("change", [{"nsample": 1}, {"nx": 2}])
def test_an_altered_manifest_in_the_index_is_regenerated_not_trusted(tmp_path, change):
    from chaingen.runtime.build import INDEX

    first = child(tmp_path)
    (entry,) = (tmp_path / INDEX).glob("*.json")
    record = json.loads(entry.read_text())
    record["manifest"].update(change)
    entry.write_text(json.dumps(record))
    again = child(tmp_path)
    assert again["sympy"]                        # the entry was broken: generated again ...
    assert again == {**first, "sympy": True}     # ... to the same solver
    assert not child(tmp_path)["sympy"]          # and the entry repaired


# --- Point 15: the CMake build without a build type is optimised --------------------------------

@pytest.mark.tools
def test_cmake_without_a_build_type_compiles_every_source_optimised(tmp_path):
    require_tools("cmake")
    source = ROOT / "generated" / "four_link_actuated_es"
    build = tmp_path / "build"
    result = subprocess.run(["cmake", "-S", str(source), "-B", str(build),
                             "-DCMAKE_EXPORT_COMPILE_COMMANDS=ON"], capture_output=True,
                            text=True)
    assert result.returncode == 0, result.stdout + result.stderr
    commands = json.loads((build / "compile_commands.json").read_text())
    flags = {Path(entry["file"]).name: entry["command"].split() for entry in commands}
    assert set(flags) == {"four_link_actuated_es.c", "four_link_actuated_es_model.c",
                          "four_link_actuated_es_derivatives.c", "example.c"}
    for name, words in flags.items():
        levels = [word for word in words if re.fullmatch(r"-O[0-3s]?", word)]
        assert levels and levels[-1] in ("-O2", "-O3"), (name, words)
    assert [w for w in flags["four_link_actuated_es.c"] if w.startswith("-O")][-1] == "-O3"
    # A build type given keeps its own flags.
    debug = tmp_path / "debug"
    subprocess.run(["cmake", "-S", str(source), "-B", str(debug), "-DCMAKE_BUILD_TYPE=Debug",
                    "-DCMAKE_EXPORT_COMPILE_COMMANDS=ON"], capture_output=True, check=True)
    model = [entry["command"] for entry in json.loads((debug / "compile_commands.json")
                                                      .read_text())
             if entry["file"].endswith("_model.c")]
    assert "-O2" not in model[0].split() and "-g" in model[0].split()


def optimisation_of(build: Path, name: str) -> list[list[str]]:
    """The -O and -g words of each compile command of the source `name` (one per configuration)."""
    commands = json.loads((build / "compile_commands.json").read_text())
    return [[word for word in entry["command"].split() if re.fullmatch(r"-O[0-3s]?|-g", word)]
            for entry in commands if Path(entry["file"]).name == name]


@pytest.mark.tools
def test_cmake_build_types_keep_their_flags_and_the_solver_gets_O3_where_they_optimise(tmp_path):
    """Before: the solver got -O3 in every build type, Debug included, though the comment said a
    build type keeps its own flags. Now: -O3 with no build type, Release and RelWithDebInfo;
    Debug and MinSizeRel keep theirs; a multi-configuration generator alike, per configuration."""
    require_tools("cmake")
    source = ROOT / "generated" / "three_link_mono_es"
    solver, model = "three_link_mono_es.c", "three_link_mono_es_model.c"
    wanted = {"": ["-O2", "-O3"], "Release": ["-O3", "-O3"], "RelWithDebInfo": ["-O2", "-g", "-O3"],
              "Debug": ["-g"], "MinSizeRel": ["-Os"]}
    for build_type, flags in wanted.items():
        build = tmp_path / (build_type or "none")
        result = subprocess.run(["cmake", "-S", str(source), "-B", str(build),
                                 f"-DCMAKE_BUILD_TYPE={build_type}",
                                 "-DCMAKE_EXPORT_COMPILE_COMMANDS=ON"], capture_output=True,
                                text=True)
        assert result.returncode == 0, result.stdout + result.stderr
        assert optimisation_of(build, solver) == [flags], build_type
        # The model file: the build type's own flags (-O2 of the Makefile's with none).
        assert optimisation_of(build, model) == [flags[:-1] if flags[-1] == "-O3" else flags]
    if shutil.which("ninja"):
        build = tmp_path / "multi"
        subprocess.run(["cmake", "-S", str(source), "-B", str(build), "-G", "Ninja Multi-Config",
                        "-DCMAKE_CONFIGURATION_TYPES=Debug;Release;RelWithDebInfo;MinSizeRel",
                        "-DCMAKE_EXPORT_COMPILE_COMMANDS=ON"], capture_output=True, check=True)
        assert optimisation_of(build, solver) == [wanted[name] for name in
                                                  ("Debug", "Release", "RelWithDebInfo",
                                                   "MinSizeRel")]
    text = (source / "CMakeLists.txt").read_text()
    assert "Debug and MinSizeRel keep their own flags for every file." in text
