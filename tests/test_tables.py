"""One table per fact: the link fields, the sample row, the scheme labels and the adaptive
step's floor are each stated once, and everything that names them reads that table.

Two kinds of checks: the readers agree with the table (behaviour), and the facts' literals
appear nowhere else in the source (ast), so a second copy fails here before it drifts.
"""
from __future__ import annotations

import ast
import dataclasses
import re
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from chaingen.errors import SceneError
from chaingen.runtime import contract
from chaingen.runtime.results import SimulationResult, sample_joints, sample_slice
from chaingen.runtime.trajectory import write_trajectory
from chaingen.scene import Link, load_reference_scene, parse_scene
from chaingen.scene.document import scene_document
from chaingen.scene.labels import LABEL_STYLES, scheme_label
from chaingen.scene.parameters import LINK_NUMBERS, compiled_paths
from chaingen.scene.values import LINK_FIELDS
from chaingen.views.plots import load_run

from helpers import ROOT


def string_constants(path: Path) -> list[str]:
    """The string literals of a module, docstrings left out."""
    tree = ast.parse(path.read_text())
    docstrings = {id(node.body[0].value) for node in ast.walk(tree)
                  if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef))
                  and node.body and isinstance(node.body[0], ast.Expr)
                  and isinstance(node.body[0].value, ast.Constant)}
    return [node.value for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str)
            and id(node) not in docstrings]


# -- link fields ------------------------------------------------------------------------------

def scene_text(link: str) -> str:
    return f"name = \"t\"\n[[links]]\n{link}\n"


def test_link_is_the_link_field_table():
    assert tuple(field.name for field in dataclasses.fields(Link)) == tuple(
        field.key for field in LINK_FIELDS)


def test_parameters_take_every_link_field_with_its_unit():
    assert LINK_NUMBERS == {field.key: field.unit for field in LINK_FIELDS}
    scene = load_reference_scene("three_link_mono")
    paths = set(compiled_paths(scene))
    assert {f"links[0].{field.key}" for field in LINK_FIELDS} <= paths


def test_the_reader_requires_and_defaults_by_the_table():
    full = "\n".join(f"{field.key} = 0.5" for field in LINK_FIELDS)
    link = parse_scene(scene_text(full), "t.toml", "t").links[0]
    assert all(getattr(link, field.key) == 0.5 for field in LINK_FIELDS)
    for field in LINK_FIELDS:
        lines = "\n".join(f"{other.key} = 0.5" for other in LINK_FIELDS if other is not field)
        if field.default is None:
            with pytest.raises(SceneError, match=rf"links\[0\]\.{field.key}: missing"):
                parse_scene(scene_text(lines), "t.toml", "t")
        else:
            parsed = parse_scene(scene_text(lines), "t.toml", "t").links[0]
            assert getattr(parsed, field.key) == field.default


def test_the_reader_names_the_table_for_an_unknown_key():
    with pytest.raises(SceneError) as error:
        parse_scene(scene_text("mass = 1.0\nwidth = 1.0"), "t.toml", "t")
    assert ", ".join(field.key for field in LINK_FIELDS) in str(error.value)


def test_the_reader_names_each_number_by_its_symbol_and_unit():
    for field in LINK_FIELDS:
        lines = "\n".join(f"{other.key} = {'true' if other is field else '0.5'}"
                          for other in LINK_FIELDS)
        with pytest.raises(SceneError) as error:
            parse_scene(scene_text(lines), "t.toml", "t")
        assert field.meaning(1) in str(error.value)
    assert LINK_FIELDS[5].meaning(2) == "r_3 in m, link 2"
    assert LINK_FIELDS[6].meaning(2) == "d_2 in N m s/rad, joint 2"


def test_the_scene_document_writes_every_link_field():
    scene = load_reference_scene("three_link_mono")
    assert all(tuple(link) == tuple(field.key for field in LINK_FIELDS)
               for link in scene_document(scene)["links"])


def test_no_other_scene_module_lists_the_link_fields():
    """The keys only a link has appear as literals in values.py alone."""
    only_links = {"com", "com_normal", "inertia"}
    for path in sorted((ROOT / "codegen" / "scene").glob("*.py")):
        if path.name != "values.py":
            assert not only_links & set(string_constants(path)), path.name


# -- the sample row ---------------------------------------------------------------------------

def test_sample_columns_expand_the_table():
    names = contract.sample_column_names(2, flows=True)
    assert names == ("t", "phi1", "phi2", "omega1", "omega2", "energy", "constraint_error",
                     *contract.FLOW_ENTRIES)
    assert contract.sample_column_names(2) == names[:-2]
    assert dict(contract.sample_columns(2))["phi2"] == (
        "relative angle of joint 2, wrapped to (-pi, pi] (rad)")


def result_of(n: int, flows: bool) -> SimulationResult:
    columns = contract.sample_column_names(n, flows)
    samples = np.arange(3 * len(columns), dtype=float).reshape(3, len(columns))
    samples[:, 0] = [0.0, 0.1, 0.2]
    return SimulationResult(scene="t", method="es", quadrature=3, dt=0.1, n_steps=2, every=1,
                            columns=columns, samples=samples, wall_time=1e-3,
                            newton_iterations=4, max_newton_iterations=2)


@pytest.mark.parametrize("flows", [False, True])
def test_results_read_the_row_by_the_table(flows):
    result = result_of(3, flows)
    assert result.n_joints == sample_joints(result.columns) == 3
    for name, values in (("phi{i}", result.phi), ("omega{i}", result.omega)):
        column = next(c for c in contract.SAMPLE_COLUMNS if c.name == name)
        expected = [result.columns.index(entry) for entry in column.names(3)]
        np.testing.assert_array_equal(values, result.samples[:, expected])
        assert sample_slice(result.columns, name) == slice(expected[0], expected[-1] + 1)
    assert result.has_flows is flows
    np.testing.assert_array_equal(result.energy_error, result.energy - result.energy[0])
    expected = result.energy_error - result.input_work + result.dissipated
    np.testing.assert_array_equal(result.balance_error, expected)


def test_plot_reads_a_trajectory_by_the_table(tmp_path):
    result = result_of(2, True)
    run = load_run(write_trajectory(result, tmp_path / "run.csv"))
    assert run.columns == result.columns and run.n == 2
    np.testing.assert_array_equal(run.phi, result.phi)
    assert run.balanced
    np.testing.assert_array_equal(run.abs_balance_error, np.abs(result.balance_error))


def test_no_reader_of_the_row_spells_its_columns():
    """results, plots and the run summary name the row's columns through the contract."""
    names = {"phi", "omega", "phi1", "omega1", *contract.FLOW_ENTRIES}
    for path in (ROOT / "runtime" / "results.py", ROOT / "codegen" / "views" / "plots.py",
                 ROOT / "codegen" / "views" / "run_summary.py"):
        assert not names & set(string_constants(path)), path.name


# -- scheme labels ----------------------------------------------------------------------------

def test_the_header_style_is_the_generated_packages_label():
    """generate.package's label of every kind of scheme is the header style's text."""
    from chaingen.generate.package import scheme_label as package_label

    rule = "4-point Gauss-Lobatto quadrature of every term (K = 3)"
    for method, quadrature, order, steps, quadrature_rule in (
            ("es", 3, 2, 1, None), ("es", 5, 4, 3, None), ("es", 3, 6, 5, rule),
            ("vi", None, 2, 1, None), ("midpoint", None, 6, 9, None)):
        scheme = SimpleNamespace(method=method, quadrature=quadrature, order=order,
                                 composition=(1.0,) * steps, quadrature_rule=quadrature_rule)
        assert package_label(scheme) == scheme_label(
            method, quadrature, order, style="header", quadrature_rule=quadrature_rule,
            composition_steps=steps)


def test_the_styles():
    assert scheme_label("es", 3) == "method es, quadrature 3"
    assert scheme_label("es", 3, 4) == "method es, quadrature 3, order 4"
    assert scheme_label("vi", None, 2, style="study") == "method vi, order 2"
    assert scheme_label("es", 3, 2, style="short") == "es K=3"
    assert scheme_label("midpoint", None, 6, style="short") == "midpoint order 6"
    with pytest.raises(ValueError, match="style"):
        scheme_label("es", 3, style="long")
    assert len(LABEL_STYLES) == 4


def test_no_module_builds_a_label_of_its_own():
    """The label's fragments are spelled in scene/labels.py (and package.py's own copy, until
    it delegates) only."""
    fragments = re.compile(r"^ K=$|by a symmetric composition|-point Gauss-Legendre quadrature")
    for path in sorted((ROOT / "codegen").rglob("*.py")):
        if path.name in ("labels.py", "package.py"):
            continue
        found = [text for text in string_constants(path) if fragments.search(text)]
        assert not found, (path, found)


# -- the adaptive step's floor ----------------------------------------------------------------

def test_the_minimum_step_fraction_is_the_contracts():
    fraction = contract.MIN_STEP_FRACTION
    status = next(status for status in contract.STATUSES if status.name == "STEP_TOO_SMALL")
    assert f"below {fraction:g} dt" in status.comment
    assert f"below {fraction:g} of the sample interval" in status.message
    header = (ROOT / "runtime" / "c" / "chaingen_contract.h").read_text()
    macro = re.search(r"#define CHAINGEN_MIN_STEP_FRACTION (\S+)", header)
    assert macro and float(macro.group(1)) == fraction
    assert f"Below `{fraction:g} dt` the run stops" in (ROOT / "docs" / "model.md").read_text()
