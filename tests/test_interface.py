"""The C interface is stated once (chaingen.runtime.contract) and rendered everywhere: the
generated header's status codes, Jacobian modes, option and stats structs and prototypes, the
manifest's entry points and the loader's ctypes all equal the contract.

`header_differences` reads a rendered header back and compares it with a contract; the second
test shows that it notices a contract that differs from what was rendered.
"""
from __future__ import annotations

import dataclasses
import re
from types import SimpleNamespace

import pytest

from chaingen.generate.package import generate_package
from chaingen.runtime import contract
from chaingen.runtime.contract import Features
from chaingen.runtime.interface import OptionsStruct, StatsStruct

from helpers import load

SCENES = {"three_link_gravity": "es", "four_link_actuated": "es"}


@pytest.fixture(scope="module", params=sorted(SCENES))
def package(request):
    return generate_package(load(request.param), SCENES[request.param], 3, sensitivities=True)


def struct_fields(header: str, name: str) -> list[tuple[str, str, str]]:
    """(C type, field, comment) of `typedef struct { ... } name;`."""
    body = re.search(r"typedef struct \{\n([^{}]*)\n\} " + re.escape(name) + ";",
                     header).group(1)
    return [match.groups() for match in
            re.finditer(r"^\s+(int|long|double) (\w+);\s*(?:/\* (.*?) \*/)?$", body, re.M)]


def prototypes(header: str, prefix: str) -> dict[str, tuple[str, list[list[str]]]]:
    """{entry point: (result type, [[parameter, C type], ...])} of the header's declarations."""
    found = {}
    pattern = re.compile(r"^(\w[\w ]*?\**) ?" + re.escape(prefix) + r"_(\w+)\(([^)]*)\);",
                         re.M | re.S)
    for returns, name, parameters in pattern.findall(header):
        parameters = " ".join(parameters.split())
        parsed = [] if parameters == "void" else [
            [re.fullmatch(r"(.*?[\s*])(\w+)", p.strip()).group(2),
             re.fullmatch(r"(.*?[\s*])(\w+)", p.strip()).group(1).strip()]
            for p in parameters.split(",")]
        found[name] = (returns.strip(), parsed)
    return found


def header_differences(header: str, prefix: str, features: Features, facts) -> list[str]:
    """Where the rendered `header` (a package's header after the runtime's contract header,
    which declares the structs) disagrees with the interface facts `facts` (a contract)."""
    PREFIX = prefix.upper()
    problems = []
    macros = dict(re.findall(r"^#define " + PREFIX + r"_(\w+) (-?\d+)\b", header, re.M))
    for status in facts.STATUSES:
        expected = str(status.code)
        if macros.get(status.name) != expected:
            problems.append(f"status {status.name}: {macros.get(status.name)} != {expected}")
    for mode in facts.JACOBIAN_MODES:
        if macros.get(mode.name) != str(mode.value):
            problems.append(f"mode {mode.name}: {macros.get(mode.name)} != {mode.value}")
    options = struct_fields(header, "chaingen_options")
    if [(c_type, name) for c_type, name, _ in options] != [
            (field.c_type, field.name) for field in facts.NEWTON_OPTIONS]:
        problems.append(f"options struct {options} != {facts.NEWTON_OPTIONS}")
    stats = struct_fields(header, "chaingen_stats")
    if [(c_type, name) for c_type, name, _ in stats] != [
            (field.c_type, field.name) for field in facts.STATS_FIELDS]:
        problems.append(f"stats struct {stats} != {facts.STATS_FIELDS}")
    declared = prototypes(header, prefix)
    expected = {name: (entry["returns"], entry["parameters"])
                for name, entry in facts.manifest_entry_points(prefix, features).items()}
    for name in ("options", "stats", "control", "observer", "controller"):
        if f"typedef chaingen_{name} {prefix}_{name};" not in header:
            problems.append(f"{prefix}_{name} is not chaingen_{name}")
    if declared != expected:
        problems.append(f"prototypes {sorted(set(declared) ^ set(expected)) or declared} != "
                        f"{expected}")
    return problems


def package_header(package) -> str:
    """The package's header after the runtime's contract header it includes."""
    return (package.files["chaingen_contract.h"] + "\n"
            + package.files[f"{package.prefix}.h"])


def test_the_header_equals_the_contract(package):
    prefix = package.prefix
    features = Features.from_manifest(package.manifest)
    header = package_header(package)
    assert header_differences(header, prefix, features, contract) == []
    # The defaults the header documents are the package's (the contract's, the scheme's reuse).
    text = " ".join(re.search(r"The defaults of this package:\s*(.*?)\. \*/", header,
                              re.S).group(1).replace("*", " ").split())
    defaults = dict(item.split() for item in text.split(", "))
    assert {name: float(value) for name, value in defaults.items()} == {
        name: float(value) for name, value in package.manifest["newton_defaults"].items()}
    assert package.manifest["entry_points"] == contract.manifest_entry_points(prefix, features)


@pytest.mark.parametrize("change", ["rename an option", "retype an option", "renumber a status",
                                    "add a parameter", "drop an entry point"])
def test_a_contract_that_differs_from_the_header_is_noticed(package, change):
    facts = SimpleNamespace(**{name: getattr(contract, name) for name in (
        "STATUSES", "JACOBIAN_MODES", "NEWTON_OPTIONS", "STATS_FIELDS")})
    entries = contract.ENTRY_POINTS
    if change == "rename an option":
        facts.NEWTON_OPTIONS = (dataclasses.replace(contract.NEWTON_OPTIONS[0], name="max_its"),
                                *contract.NEWTON_OPTIONS[1:])
    elif change == "retype an option":
        facts.NEWTON_OPTIONS = (*contract.NEWTON_OPTIONS[:-1],
                                dataclasses.replace(contract.NEWTON_OPTIONS[-1], c_type="long"))
    elif change == "renumber a status":
        last = len(contract.STATUSES) - 1
        facts.STATUSES = tuple(dataclasses.replace(status, code=status.code + 100)
                               if i == last else status
                               for i, status in enumerate(contract.STATUSES))
    elif change == "add a parameter":
        step = contract.ENTRY_POINTS_BY_NAME["step"]
        extra = dataclasses.replace(step, parameters=(*step.parameters,
                                                      contract.Parameter("t", "double")))
        entries = tuple(extra if entry.name == "step" else entry for entry in entries)
    else:
        entries = tuple(entry for entry in entries if entry.name != "sample_count")

    def manifest_entry_points(prefix, features):
        return {entry.name: {"returns": entry.returns,
                             "parameters": [[p.name, contract.resolved(p.c_type, prefix)]
                                            for p in entry.parameters]}
                for entry in entries}

    facts.manifest_entry_points = manifest_entry_points
    header = package_header(package)
    features = Features.from_manifest(package.manifest)
    assert header_differences(header, package.prefix, features, facts)


def test_the_loader_structs_are_the_contract():
    assert [name for name, _ in OptionsStruct._fields_] == [
        field.name for field in contract.NEWTON_OPTIONS]
    assert [name for name, _ in StatsStruct._fields_] == [
        field.name for field in contract.STATS_FIELDS]


def test_status_messages_come_from_the_contract():
    assert contract.status_message(6, 1e-6).startswith(
        "a spring segment came within 1e-06 of the geometry's size")
    assert contract.status_message(1) == contract.STATUSES[1].message
    assert contract.status_message(99) == "unknown status 99"
