"""One request type (issue 31, item 5): every reader of a solver request accepts and refuses
exactly what chaingen.scene.solver_rules does, and says the same sentence after its own key.

The oracle is `request_refusal` (and `parameters_refusal` for run-time parameters). The entry
points are stopped right after their checks (a patched next step raises Checked), so nothing
is generated or compiled: build_solver, generate_package, build_scheme, SolverSpec,
run_settings, the sweep spec, the scene reader, the order study and `chaingen generate`.
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import chaingen
from chaingen.errors import OrderStudyError, SceneError, SettingsError
from chaingen.scene import SolverSpec, SolverSpecError, load_scene, parse_scene
from chaingen.scene.display import shown
from chaingen.scene.solver_rules import (
    GALERKIN_MIN_QUADRATURE,
    METHODS,
    ORDERS,
    QUADRATURE_RANGE,
    REQUEST_KEYS,
    request_refusal,
)
from chaingen.scene.solver_spec import parameters_refusal
from chaingen.studies.sweep import SweepError, parse_spec

from helpers import ROOT, chaingen_in_process

SCENE_FILE = ROOT / "scenes" / "three_link_mono.toml"
SCENE = load_scene(SCENE_FILE)

METHOD_VALUES = st.sampled_from([*METHODS, "rk4", "ES", "", "es ", 3, None, True])
QUADRATURE_VALUES = st.one_of(st.integers(-2, QUADRATURE_RANGE[1] + 3),
                              st.sampled_from([3.0, True, "3", None]))
ORDER_VALUES = st.one_of(st.sampled_from(ORDERS), st.integers(-1, 9),
                         st.sampled_from([4.0, True, "6", None]))
TOLERANCE_VALUES = st.sampled_from([0, 0.0, 1e-14, 1e-8, 0.5, 1e-15, -1e-8, math.nan,
                                    math.inf, True, "tight", None])
PATHS = ["springs[0].stiffness", "links[1].mass", "gravity", "base.fastening",
         "links[0].damping", "initial.angles[0]", "simulation.dt", "links[7].mass",
         "links[0].weight", "springs[0].joints", "Gravity"]
PARAMETER_VALUES = st.one_of(st.lists(st.sampled_from(PATHS), max_size=3).map(tuple),
                             st.just(("all",)))


class Checked(Exception):
    """Raised by the step after an entry point's checks: the request was accepted."""


def checked(*_, **__):
    raise Checked


def requests():
    return st.fixed_dictionaries({"method": METHOD_VALUES, "quadrature": QUADRATURE_VALUES,
                                  "order": ORDER_VALUES, "rtol": TOLERANCE_VALUES,
                                  "atol": TOLERANCE_VALUES})


def scheme_refusal(request, parameters=()):
    """The oracle for a solver's request (method, quadrature, order, parameters)."""
    refused = request_refusal({key: request[key] for key in ("method", "quadrature", "order")})
    if refused is None:
        paths = SCENE_PATHS_ALL if tuple(parameters) == ("all",) else tuple(parameters)
        refused = parameters_refusal(SCENE, paths)
    return refused


SCENE_PATHS_ALL = SolverSpec(SCENE, "es", 3, parameters="all").parameters


def outcome(call):
    """'accepted', or the refusal's exception."""
    try:
        call()
    except Checked:
        return "accepted"
    except (SettingsError, SceneError, SweepError, OrderStudyError) as error:
        return error
    raise AssertionError("the entry point neither refused the request nor went on")


def assert_same(result, refused, text: str):
    """Accepted exactly when the oracle accepts; refused with `text` (the site's key, then
    the oracle's sentence) when it refuses."""
    if refused is None:
        assert result == "accepted", f"refused what the rules take: {result}"
    else:
        assert result != "accepted", f"accepted what the rules refuse: {refused.message}"
        assert str(result) == text, (str(result), text)


FAST = settings(max_examples=150, deadline=None,
                suppress_health_check=[HealthCheck.function_scoped_fixture])


# -- the Python entry points of a solver request ----------------------------------------------

@FAST
@given(request=requests(), parameters=PARAMETER_VALUES)
def test_solver_spec_build_solver_generate_and_build_scheme_agree(request, parameters,
                                                                  monkeypatch):
    import chaingen.generate.key as key
    import chaingen.generate.package as package
    import chaingen.symbolic.schemes as schemes

    fields = {name: request[name] for name in ("method", "quadrature", "order")}
    # build_solver and build_scheme take None as the scene's own ([simulation]); SolverSpec
    # takes the values.
    defaults = {name: getattr(SCENE.simulation, name) if value is None else value
                for name, value in fields.items()}
    monkeypatch.setattr(key, "solver_key", checked)
    monkeypatch.setattr(package, "build_scheme", checked)
    monkeypatch.setattr(schemes, "with_symbols", checked)

    def spec():
        SolverSpec(SCENE, **fields, parameters=parameters)
        raise Checked
    for call, oracle in (
            (spec, fields),
            (lambda: chaingen.build_solver(SCENE, **fields, parameters=parameters), defaults),
            (lambda: package.generate_package(SCENE, **fields, parameters=parameters), fields),
            (lambda: schemes.build_scheme(SCENE, **fields, parameters=parameters), defaults)):
        refused = scheme_refusal(oracle, parameters)
        result = outcome(call)
        assert_same(result, refused, refused and f"{refused.option}: {refused.message}")
        if refused:
            assert isinstance(result, SolverSpecError) and result.refusal == refused


@FAST
@given(request=requests())
def test_run_settings_agrees(request):
    given_fields = {key: value for key, value in request.items() if value is not None}
    refused = request_refusal({key: given_fields.get(key, getattr(SCENE.simulation, key))
                               for key in REQUEST_KEYS})

    def run():
        chaingen.run_settings(SCENE, **given_fields, source="s.toml")
        raise Checked
    where = refused and (refused.option if refused.key in given_fields
                         else f"s.toml: simulation.{refused.key}")
    assert_same(outcome(run), refused, refused and f"{where}: {refused.message}")


@FAST
@given(request=requests())
def test_the_sweep_spec_agrees(request):
    given_fields = {key: value for key, value in request.items() if value is not None}
    refused = request_refusal({key: given_fields.get(key, getattr(SCENE.simulation, key))
                               for key in REQUEST_KEYS})
    document = {"scene": str(SCENE_FILE), "axes": {"springs[0].stiffness": [5.0, 10.0]},
                **given_fields}

    def parse():
        spec = parse_spec(document, "sweep.toml")
        assert spec.solver == SolverSpec(SCENE, spec.method, spec.quadrature, spec.order,
                                         ("springs[0].stiffness",), sensitivities=False)
        raise Checked
    assert_same(outcome(parse), refused,
                refused and f"sweep.toml: {refused.key}: {refused.message}")


@FAST
@given(request=requests())
def test_the_scene_reader_agrees(request):
    """A scene file's [simulation] table: each key's rule in the file's order, then the rule
    between keys (es at order 6 needs K >= 2)."""
    given_fields = {key: value for key, value in request.items() if value is not None}
    text = SCENE_FILE.read_text()
    text = re.sub(r"\[simulation\][^\[]*", "", text)
    table = "".join(f"{key} = {shown(value)}\n" for key, value in given_fields.items())
    defaults = chaingen.Simulation()
    refused = request_refusal(given_fields) or request_refusal(
        {key: given_fields.get(key, getattr(defaults, key))
         for key in ("method", "quadrature", "order")})

    def read():
        parse_scene(text + "\n[simulation]\n" + table, "s.toml", "s")
        raise Checked
    where = refused and f"simulation.{refused.key}"
    assert_same(outcome(read), refused, refused and f"s.toml: {where}: {refused.message}")


class _Solver:
    @property
    def manifest(self):
        raise Checked


@FAST
@given(request=requests())
def test_the_order_study_agrees(request):
    from chaingen.studies.order import order_study

    refused = scheme_refusal(request)

    def study():
        order_study(SCENE, request["method"], request["quadrature"], order=request["order"],
                    solver=_Solver(), dts=(0.1, 0.2))
    assert_same(outcome(study), refused, refused and refused.stated)


# -- the command line ------------------------------------------------------------------------

def _text(value) -> str | None:
    """A value as a command-line word, None for one a command line cannot give."""
    if isinstance(value, bool) or value is None:
        return None
    if isinstance(value, str):
        return value if value and not value.startswith("-") else None
    return repr(value)


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("cli")


@FAST
@given(request=requests(), parameters=st.lists(st.sampled_from(PATHS), max_size=3))
def test_chaingen_generate_agrees(request, parameters, workdir, monkeypatch):
    """`chaingen generate` refuses (exit 2) exactly the requests the rules refuse, naming the
    option; argparse refuses a method or order outside the rules' tuples (its choices), the
    rest is refused with the rules' own sentence."""
    import chaingen.generate.package as package

    words = {key: _text(request[key]) for key in ("method", "quadrature", "order")}
    if None in words.values() or any(key in ("quadrature", "order") and not isinstance(
            request[key], int) for key in words):
        return
    monkeypatch.setattr(package, "generate_package", checked)
    arguments = [option for key, word in words.items() for option in (f"--{key}", word)]
    if parameters:
        arguments += ["--parameters", ",".join(parameters)]
    refused = scheme_refusal(request, parameters)
    result = chaingen_in_process("generate", SCENE_FILE, *arguments, "-o", workdir / "pkg",
                                 cwd=workdir)
    if "internal error: Checked" in result.stderr:      # generate_package was reached
        assert refused is None, refused.message
        return
    assert refused is not None and result.returncode == 2, result.stderr
    message = result.stderr.strip().splitlines()[-1]
    # argparse reads the options in their order: it may name a bad --order before a bad
    # --quadrature that the rules name first; each named option is one the rules refuse.
    refusing = {f"--{key}" for key in words if request_refusal({key: request[key]})}
    assert refused.option in message or any(option in message for option in refusing), message
    if refused.option in message and "invalid choice" not in message:
        assert message.endswith(f"{refused.option}: {refused.message}"), message


@FAST
@given(value=TOLERANCE_VALUES)
def test_command_line_tolerances_agree(value):
    from chaingen.arguments import adaptive_tolerance

    word = _text(value)
    if word is None:
        return
    refused = request_refusal({"rtol": value})
    try:
        adaptive_tolerance(word)
    except Exception as error:     # argparse.ArgumentTypeError
        # A word that is no number is refused as such before the rule.
        assert refused is not None and str(error) in (refused.message,
                                                      f"must be a number, got {word!r}")
    else:
        assert refused is None


# -- the rules themselves, as the issue states them --------------------------------------------

def test_es_at_order_6_needs_galerkin_quadrature_and_every_method_takes_every_order():
    assert request_refusal({"method": "es", "order": 6,
                            "quadrature": GALERKIN_MIN_QUADRATURE - 1}).key == "quadrature"
    assert request_refusal({"method": "es", "order": 6,
                            "quadrature": GALERKIN_MIN_QUADRATURE}) is None
    for method in ("vi", "midpoint"):
        assert request_refusal({"method": method, "order": 6, "quadrature": 1}) is None


def test_a_spec_is_one_value_the_cache_key_and_generation_take():
    """Equal requests are one SolverSpec and one cache key: "all" is stored expanded, numpy
    integers as ints; the keyword forms of input_hash and solver_key give the spec's."""
    import numpy as np

    from chaingen.generate.key import input_hash, solver_key

    spec = SolverSpec.create(SCENE, parameters="all", order=np.int64(4))
    assert spec == SolverSpec(SCENE, SCENE.simulation.method, SCENE.simulation.quadrature, 4,
                              SCENE_PATHS_ALL)
    assert type(spec.order) is int and hash(spec) == hash(dataclass_copy(spec))
    assert input_hash(spec) == input_hash(SCENE, spec.method, spec.quadrature, True,
                                          SCENE_PATHS_ALL, 4)
    assert solver_key(spec) == solver_key(SCENE, spec.method, spec.quadrature,
                                          sensitivities=True, parameters=["all"], order=4)
    with pytest.raises(TypeError, match="SolverSpec"):
        chaingen.build_solver(spec, "es")


def dataclass_copy(spec):
    import dataclasses

    return dataclasses.replace(spec)


def test_no_other_module_states_the_rules():
    """The methods, orders and K range are written once, in solver_rules.py: elsewhere they
    are imported (compiled_peers' methods are the peers' own, not chaingen's)."""
    literals = re.compile(r"\(\s*\"es\",\s*\"vi\",\s*\"midpoint\"\s*\)|\(2, 4, 6\)|"
                          r"QUADRATURE_RANGE = |GALERKIN_MIN_QUADRATURE = |GALERKIN_ORDER = ")
    found = [str(path.relative_to(ROOT)) for folder in ("codegen", "runtime")
             for path in (ROOT / folder).rglob("*.py") if literals.search(path.read_text())]
    assert found == ["codegen/scene/solver_rules.py"]
