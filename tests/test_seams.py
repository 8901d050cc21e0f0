"""Seams between the rooms of the package, read from the source (ast): no private name is
imported from another module, the studies import no view, and a DiscreteScheme is made of its
records."""
from __future__ import annotations

import ast
import dataclasses

from chaingen.symbolic.schemes.base import FLAT_NAMES, RECORDS, DiscreteScheme

from helpers import ROOT

#: Private imports allowed across modules: none.
KNOWN_PRIVATE_IMPORTS: set[tuple[str, str]] = set()


def sources():
    for folder in ("codegen", "runtime"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            yield path.relative_to(ROOT).as_posix(), ast.parse(path.read_text())


def test_no_private_name_is_imported_from_another_module():
    found = set()
    for name, tree in sources():
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module != "__future__":
                found |= {(name, alias.name) for alias in node.names
                          if alias.name.startswith("_")}
            elif isinstance(node, ast.Import):
                found |= {(name, alias.name) for alias in node.names
                          if any(part.startswith("_") for part in alias.name.split("."))}
    assert found <= KNOWN_PRIVATE_IMPORTS, sorted(found - KNOWN_PRIVATE_IMPORTS)


def imports_views(name: str, tree: ast.Module) -> bool:
    depth = name.count("/") - 1      # codegen/studies/x.py: 1 level below codegen
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if node.level and node.level == depth + 1 and module.split(".")[0] == "views":
                return True
            if not node.level and module.startswith("chaingen.views"):
                return True
            if node.level == depth + 1 and not module and any(
                    alias.name == "views" for alias in node.names):
                return True
        elif isinstance(node, ast.Import) and any(
                alias.name.startswith("chaingen.views") for alias in node.names):
            return True
    return False


def test_the_studies_import_no_view():
    """Views draw the studies' results; a study hands its figures to a view it is given
    (run_bench's `figures`), so there is no studies <-> views circle."""
    offenders = [name for name, tree in sources()
                 if name.startswith("codegen/studies/") and imports_views(name, tree)]
    assert not offenders


def test_a_scheme_is_its_records():
    assert tuple(field.name for field in dataclasses.fields(DiscreteScheme)) == (
        "scene", *RECORDS)
    for flat, (record, field) in FLAT_NAMES.items():
        assert field in {f.name for f in dataclasses.fields(RECORDS[record])}, flat
