"""The templates are wiring, the runtime library holds the algorithms (issue 31).

- the Jinja directives of all templates stay within a budget, and no template holds Newton,
  adaptive-step or composition logic: those live in runtime/c/chaingen_runtime.c;
- every package, whatever its scheme and features, exports the same entry points with the same
  C signatures (its prefix aside): the ABI is fixed;
- the runtime's contract header is the rendering of runtime/contract.py.
"""
from __future__ import annotations

import re

import pytest

from chaingen.generate.interface import contract_header
from chaingen.generate.package import generate_package
from chaingen.runtime import contract

from helpers import ROOT, load

TEMPLATES = sorted((ROOT / "templates").glob("*.j2"))
#: The most Jinja directives ({% ... %}) all templates together may hold.
DIRECTIVE_BUDGET = 90
#: Names of the solver's algorithms: none of them may appear in a template.
ALGORITHM_MARKERS = (
    "factorise(", "solve_newton(", "update_norm", "residual_norm", "previous_update",
    "warm_choice", "proposed_dt", "previous_error", "stages[s]", "chaingen_arm_factor(",
    "chaingen_arm_solve(", "shorter_may_pass", "adaptive_interval", "extrapolate(", "compose(",
    "REFRESH_RATE", "MAX_SPLIT",
)


def directives(text: str) -> int:
    return len(re.findall(r"\{%", text))


def test_the_templates_hold_few_directives():
    counts = {path.name: directives(path.read_text()) for path in TEMPLATES}
    assert sum(counts.values()) <= DIRECTIVE_BUDGET, counts


def test_the_directive_count_counts_directives():
    assert directives("{% if a %}x{% endif %}{{ b }}") == 2


@pytest.mark.parametrize("path", TEMPLATES, ids=lambda path: path.name)
def test_no_template_holds_an_algorithm(path):
    text = path.read_text()
    found = [marker for marker in ALGORITHM_MARKERS if marker in text]
    assert not found, f"{path.name} holds solver logic: {found}"


def test_the_runtime_holds_the_algorithms():
    """The markers name real parts of the runtime (so that their absence above means
    something)."""
    runtime = (ROOT / "runtime" / "c" / "chaingen_runtime.c").read_text()
    missing = [marker for marker in ALGORITHM_MARKERS if marker not in runtime]
    assert not missing


def test_the_contract_header_is_the_rendered_contract():
    path = ROOT / "runtime" / "c" / "chaingen_contract.h"
    assert path.read_text() == contract_header(), (
        "runtime/c/chaingen_contract.h is stale: write chaingen.generate.interface."
        "contract_header() into it")


# --- The fixed ABI ----------------------------------------------------------------------------

#: (scene, method, order, parameters, sensitivities): every scheme, unactuated and actuated,
#: with and without run-time parameters, sensitivities and composition.
VARIANTS = [
    ("three_link_gravity", "es", 2, (), False),
    ("three_link_gravity", "vi", 2, (), False),
    ("three_link_gravity", "midpoint", 2, (), False),
    ("four_link_actuated", "es", 2, ("links[1].mass",), True),
    ("four_link_actuated", "vi", 2, ("springs[1].stiffness",), True),
    ("four_link_actuated", "midpoint", 2, ("links[2].length",), True),
    ("three_link_multi", "es", 4, ("gravity",), True),
    ("three_link_multi", "vi", 4, (), True),
    ("three_link_multi", "midpoint", 6, (), False),
]


def exported_prototypes(header: str, prefix: str) -> list[str]:
    """The declarations the header exports (<PREFIX>_API), the prefix replaced by P."""
    declarations = re.findall(rf"^{prefix.upper()}_API\n(.*?\);)", header, flags=re.M | re.S)
    return [" ".join(declaration.replace(prefix, "P").split()) for declaration in declarations]


@pytest.fixture(scope="module")
def headers():
    found = {}
    for name, method, order, parameters, sensitivities in VARIANTS:
        package = generate_package(load(name), method, 3, order=order, parameters=parameters,
                                   sensitivities=sensitivities)
        found[(name, method, order, parameters, sensitivities)] = exported_prototypes(
            package.files[f"{package.prefix}.h"], package.prefix)
    return found


@pytest.mark.heavy
def test_every_package_exports_the_same_signatures(headers):
    reference = next(iter(headers.values()))
    assert len(reference) == len(contract.ENTRY_POINTS)
    different = {variant: prototypes for variant, prototypes in headers.items()
                 if prototypes != reference}
    assert not different, different


@pytest.mark.heavy
def test_the_signatures_take_inputs_and_parameters_with_their_sizes(headers):
    reference = next(iter(headers.values()))
    step = next(p for p in reference if " P_step(" in p)
    assert "const double *u, int nu, const double *p, int np" in step


def test_the_comparison_sees_a_changed_signature():
    header = ("P_API\nint P_step(const double *x0, double dt);\n"
              "P_API\nint P_outputs(const double *x);\n")
    other = header.replace("double dt", "double dt, const double *u")
    assert exported_prototypes(header, "P") != exported_prototypes(other, "P")


def test_runtime_files_are_shipped():
    """Every file a package copies from the runtime exists there."""
    from chaingen.generate.package import RUNTIME_FILES
    assert "chaingen_runtime.c" in RUNTIME_FILES
    assert all((ROOT / "runtime" / "c" / name).is_file() for name in RUNTIME_FILES)
