"""The shape of the package: stages that import down the pipeline, no import circle, modules of a
readable size, nothing that reaches into the checkout or outside the repository.

Read from the source files (ast), so a change that breaks the layout fails here, whatever it
does at run time.
"""
from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest

from helpers import ROOT

#: Folder -> the package it installs as (setup.py).
FOLDERS = {"codegen": "chaingen", "runtime": "chaingen.runtime"}
#: The pipeline's stages, bottom first: a module may import its own stage and the ones below.
STAGES = (
    ("chaingen.version", "chaingen.runtime", "chaingen.errors"),
    ("chaingen.scene", "chaingen.spatial", "chaingen.progress"),
    ("chaingen.symbolic",),
    ("chaingen.generate",),
    ("chaingen.simulation",),
    ("chaingen.reference",),
    ("chaingen.studies", "chaingen.views"),
    ("chaingen.cli", "chaingen.__main__", "chaingen"),
)
MAX_LINES = 500


def module_files() -> dict[str, Path]:
    """Every module of the installed package, by its dotted name."""
    modules = {}
    for folder, package in FOLDERS.items():
        for path in sorted((ROOT / folder).rglob("*.py")):
            parts = list(path.relative_to(ROOT / folder).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            modules[".".join([package, *parts])] = path
    return modules


MODULES = module_files()


def imported_modules(name: str, path: Path) -> set[str]:
    """The chaingen modules `name` imports (a from-import of a submodule counts as it)."""
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[:len(package.split(".")) - node.level + 1]
                module = ".".join(base + ([node.module] if node.module else []))
            else:
                module = node.module or ""
            # `from package import submodule` imports the submodule; names import the module.
            targets = [f"{module}.{alias.name}" if f"{module}.{alias.name}" in MODULES
                       else module for alias in node.names]
        else:
            continue
        found |= {target for target in targets if target in MODULES and target != name}
    return found


GRAPH = {name: imported_modules(name, path) for name, path in MODULES.items()}


def stage(name: str) -> int:
    best = None
    for rank, prefixes in enumerate(STAGES):
        for prefix in prefixes:
            if name == prefix or name.startswith(prefix + "."):
                if best is None or len(prefix) > best[1]:
                    best = (rank, len(prefix))
    assert best is not None, f"{name} belongs to no stage"
    return best[0]


def test_every_module_belongs_to_a_stage_and_imports_down_the_pipeline():
    upward = [f"{name} ({stage(name)}) imports {target} ({stage(target)})"
              for name, targets in GRAPH.items() for target in sorted(targets)
              if stage(target) > stage(name)]
    assert upward == []


def test_there_is_no_import_circle():
    state: dict[str, int] = {}
    circles = []

    def visit(name: str, trail: list[str]) -> None:
        state[name] = 1
        for target in sorted(GRAPH[name]):
            if state.get(target) == 1:
                circles.append(" -> ".join(trail[trail.index(target):] + [target]))
            elif target not in state:
                visit(target, trail + [target])
        state[name] = 2

    for name in sorted(GRAPH):
        if name not in state:
            visit(name, [name])
    assert circles == []


def test_the_runtime_imports_nothing_of_the_rest_of_chaingen():
    outside = {f"{name} -> {target}" for name, targets in GRAPH.items()
               if name.startswith("chaingen.runtime") for target in targets
               if not target.startswith("chaingen.runtime")}
    assert outside == set()


@pytest.mark.parametrize("name", sorted(MODULES))
def test_modules_stay_readable(name):
    assert len(MODULES[name].read_text().splitlines()) <= MAX_LINES


def test_nothing_reaches_into_the_checkout_or_the_folder_names():
    """An installed chaingen works from any directory: no path relative to the source file's
    parents, and imports by the installed names (chaingen), never by the folders'."""
    problems = []
    for name, path in MODULES.items():
        text = path.read_text()
        if re.search(r"parents?\b[\[.]", text) and "__file__" in text:
            problems.append(f"{name}: a path from __file__'s parents")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                names = ([alias.name for alias in node.names] if isinstance(node, ast.Import)
                         else [node.module or ""])
                if any(n.split(".")[0] in ("codegen", "chaingen_runtime", "chaingen_templates")
                       for n in names if node.__class__ is ast.Import or not node.level):
                    problems.append(f"{name}: imports {names}")
    assert problems == []


def test_nothing_links_outside_the_repository():
    files = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md")),
             *MODULES.values(), *sorted((ROOT / "templates").glob("*.j2"))]
    outside = [f"{path.relative_to(ROOT)}:{number}" for path in files
               for number, line in enumerate(path.read_text().splitlines(), start=1)
               if "../shared" in line or "shared/spec" in line]
    assert outside == []
    for document in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        for target in re.findall(r"\]\((?!https?:|#)([^)#]+)", document.read_text()):
            assert (document.parent / target).exists(), f"{document.name} links {target}"


def test_the_core_path_imports_no_extra():
    """import chaingen, read a scene, derive and render a package: none of the extras (the
    sweep's results and engines, plotting, the reference peers) is imported."""
    import subprocess
    import sys

    code = ("import sys, chaingen\n"
            "from chaingen.generate.package import generate_package\n"
            "scene = chaingen.load_reference_scene('three_link_mono')\n"
            "generate_package(scene, 'es', 1, sensitivities=False,\n"
            "                 parameters=('springs[0].stiffness',))\n"
            "extras = ('pandas', 'pyarrow', 'xarray', 'zarr', 'dask', 'distributed',\n"
            "          'matplotlib', 'mujoco', 'scipy')\n"
            "print(' '.join(m for m in extras if m in sys.modules))\n")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=300)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == ""
