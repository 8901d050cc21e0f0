"""The C text of the interface contract: macros, structs, prototypes and calls.

chaingen.runtime.contract states each fact of the C interface once; this module writes it as C
for the templates. The exported entry points come from the contract; the solver's internal
functions are described here the same way, so that every C signature that changes with the
scene's features (an input u, energy flows) is written from one parameter list:

    prototype("step")              -> the declaration, prefixed, with the parameters it has
    call("step", x1="next")        -> prefix_step(x0, dt, next, options, workspace, iterations)

An argument defaults to the parameter's own name; a call is one line.
"""
from __future__ import annotations

import re
import textwrap
from dataclasses import dataclass

from ..runtime import contract
from ..runtime.contract import P_ARGUMENT, EntryPoint, Features, Parameter, _parameters

#: Width of the generated C text.
WIDTH = 100
#: A comment beside a long name (a long scene name makes long macros) is wrapped at this width at
#: least, overrunning WIDTH rather than leaving no room.
MIN_COMMENT_WIDTH = 40

#: The solver's static functions whose parameters follow the scene's features.
INTERNAL_FUNCTIONS = {entry.name: entry for entry in (
    EntryPoint("step_arguments", "static void", _parameters(
        f"const double *z, const double *x0, const double *u [inputs], {P_ARGUMENT}, "
        "const double *dt, {prefix}_workspace *workspace")),
    EntryPoint("newton_factors", "static int", _parameters(
        f"const double *z, const double *x0, const double *u [inputs], {P_ARGUMENT}, double dt, "
        "double *residual, double *jacobian, {prefix}_workspace *workspace")),
    EntryPoint("first_guess", "static int", _parameters(
        f"const double *x0, {P_ARGUMENT}, double dt, int warm, {{prefix}}_workspace *workspace")),
    EntryPoint("predict", "static int", _parameters(
        f"const double *x0, {P_ARGUMENT}, double dt, double *guess, "
        "{prefix}_workspace *workspace")),
    EntryPoint("choose_warm_start", "static int", _parameters(
        f"const double *x0, {P_ARGUMENT}, double dt, const {{prefix}}_options *options, "
        "{prefix}_workspace *workspace")),
    EntryPoint("newton", "static int", _parameters(
        f"const double *x0, const double *u [inputs], {P_ARGUMENT}, double dt, "
        "const {prefix}_options *options, int warm, {prefix}_workspace *workspace, "
        "int *iterations")),
    EntryPoint("solve_step", "static int", _parameters(
        f"const double *x0, const double *u [inputs], {P_ARGUMENT}, double dt, "
        "const {prefix}_options *options, {prefix}_workspace *workspace, int *iterations")),
    EntryPoint("finish_step", "static int", _parameters(
        f"const double *x0, const double *u [inputs], {P_ARGUMENT}, double dt, double *x1, "
        "double *flows [flows], const {prefix}_options *options [energy_check], "
        "{prefix}_workspace *workspace")),
    EntryPoint("advance", "static int", _parameters(
        f"const double *x0, const double *u [inputs], {P_ARGUMENT}, double dt, double *x1, "
        "double *flows [flows], const {prefix}_options *options, {prefix}_workspace *workspace, "
        "int *iterations, int depth")),
    EntryPoint("compose", "static int", _parameters(
        f"const double *x0, const double *u [inputs], {P_ARGUMENT}, double dt, double *x1, "
        "double *flows [flows], const {prefix}_options *options, {prefix}_workspace *workspace, "
        "int *iterations, int depth")),
    EntryPoint("joint_state", "static int", _parameters(
        f"const double *x, {P_ARGUMENT}, double *s, {{prefix}}_workspace *workspace")),
    EntryPoint("adaptive_interval", "static int", _parameters(
        f"const double *x0, const double *u [inputs], {P_ARGUMENT}, double dt, double *x1, "
        "double *flows [flows], const {prefix}_options *options, {prefix}_workspace *workspace, "
        "int *iterations, {prefix}_stats *counters")),
    EntryPoint("evaluate_residual", "static int",
               contract.ENTRY_POINTS_BY_NAME["residual"].parameters),
    EntryPoint("evaluate_residual_jacobian", "static int",
               contract.ENTRY_POINTS_BY_NAME["residual_jacobian"].parameters),
    EntryPoint("stage_sensitivities", "static int",
               contract.ENTRY_POINTS_BY_NAME["step_sensitivities"].parameters,
               when="sensitivities"),
    EntryPoint("run", "static int", _parameters(
        "const double *x0, double t0, double dt, long n_steps, long every, "
        f"const double *u [inputs], {P_ARGUMENT}, const {{prefix}}_options *options, "
        "{prefix}_workspace *workspace, double *samples, double *x_final, "
        "{prefix}_stats *stats, {prefix}_observer observer, void *context, long interval, "
        "{prefix}_control *control, {prefix}_controller controller [inputs], "
        "void *controller_context [inputs], long hold [inputs], double *torques [inputs]")),
    EntryPoint("write_sample", "static int", _parameters(
        f"const double *x, {P_ARGUMENT}, double t, const compensated_sum *totals [flows], "
        "double *row, {prefix}_workspace *workspace")),
)}


def c_literal(value: int | float) -> str:
    """A number as a C literal: integers as they are, doubles as text that round-trips, small
    ones with a plain exponent (1e-8, not 1e-08 or 0.00000001)."""
    if isinstance(value, bool) or isinstance(value, int):
        return str(int(value))
    value = float(value)
    text = repr(value)
    if value != 0.0 and abs(value) < 0.01 and "e" not in text:
        text = f"{value:.16e}"
        mantissa, exponent = text.split("e")
        digits = len(mantissa)
        while digits > 1 and float(f"{mantissa[:digits - 1]}e{exponent}") == value:
            digits -= 1
        text = f"{mantissa[:digits].rstrip('.')}e{exponent}"
    text = re.sub(r"e([+-])0*(\d)", lambda m: f"e{'-' if m.group(1) == '-' else ''}{m.group(2)}",
                  text)
    return text if any(c in text for c in ".en") else text + ".0"


def comment_lines(text: str, indent: int, width: int = WIDTH) -> list[str]:
    """`text` as the lines of a C comment starting at column `indent` ("/* ... */"), at least
    MIN_COMMENT_WIDTH wide."""
    lines = textwrap.wrap(text, width=max(width - indent - 6, MIN_COMMENT_WIDTH)) or [""]
    if len(lines) == 1:
        return [f"/* {lines[0]} */"]
    return ([f"/* {lines[0]}"] + [" " * indent + f" * {line}" for line in lines[1:-1]]
            + [" " * indent + f" * {lines[-1]} */"])


@dataclass(frozen=True)
class CInterface:
    """The contract's C text for one package: its prefix and its features."""

    prefix: str
    features: Features

    @property
    def PREFIX(self) -> str:
        return self.prefix.upper()

    def _entry(self, name: str) -> tuple[EntryPoint, str]:
        if name in contract.ENTRY_POINTS_BY_NAME:
            return contract.ENTRY_POINTS_BY_NAME[name], f"{self.prefix}_{name}"
        return INTERNAL_FUNCTIONS[name], name

    def _parameters(self, name: str) -> tuple[Parameter, ...]:
        entry, _ = self._entry(name)
        if not self.features.has(entry.when):
            raise ValueError(f"{self.prefix}_{name} does not exist in this package")
        return entry.present(self.features)

    def signature(self, name: str) -> str:
        """'returns name(type name, ...)', wrapped at WIDTH with the parameters aligned."""
        entry, c_name = self._entry(name)
        parameters = [_declaration(contract.resolved(p.c_type, self.prefix), p.name)
                      for p in self._parameters(name)]
        head = f"{_declaration(entry.returns, c_name)}("
        return _wrap(head, parameters or ["void"], ")")

    def prototype(self, name: str) -> str:
        return self.signature(name) + ";"

    def call(self, name: str, **arguments: str) -> str:
        """A call of `name` with the package's parameters; each argument is the parameter's
        name unless given."""
        _, c_name = self._entry(name)
        parameters = self._parameters(name)
        unknown = set(arguments) - {p.name for p in self._entry(name)[0].parameters}
        if unknown:
            raise ValueError(f"{name}: no parameters {', '.join(sorted(unknown))}")
        return f"{c_name}({', '.join(arguments.get(p.name, p.name) for p in parameters)})"

    def null_check(self, name: str, *optional: str) -> str:
        """'!a || !b ...' over the pointer parameters of `name` the package has, except the
        `optional` ones (which may be NULL)."""
        pointers = [p.name for p in self._parameters(name)
                    if p.c_type.endswith("*") and p.name not in optional]
        return " || ".join(f"!{pointer}" for pointer in pointers)

    def has(self, name: str) -> bool:
        """Whether the package exports (or its solver defines) `name`."""
        entry, _ = self._entry(name)
        return self.features.has(entry.when)

    def status_macros(self, segment_tolerance: str) -> str:
        """#define <PREFIX>_<status> code /* comment */ for every status of the package."""
        lines = []
        for status in contract.STATUSES:
            if not self.features.has(status.when):
                continue
            head = f"#define {self.PREFIX}_{status.name} {status.code}"
            head = head.ljust(len(self.PREFIX) + 28)
            comment = status.comment.format(segment_tolerance=segment_tolerance)
            body = comment_lines(comment, len(head) + 1)
            lines.append(f"{head} {body[0]}")
            lines += body[1:]
        return "\n".join(lines)

    def jacobian_mode_macros(self) -> str:
        lines = []
        for mode in contract.JACOBIAN_MODES:
            head = f"#define {self.PREFIX}_{mode.name} {mode.value}"
            lines.append(f"{head.ljust(len(self.PREFIX) + 34)} /* {mode.comment} */")
        return "\n".join(lines)

    def struct(self, fields, name: str, defaults: dict | None = None) -> str:
        """typedef struct { ... } <prefix>_<name>; with a comment per field (the default too,
        for the options)."""
        lines = ["typedef struct {"]
        for field in fields:
            declaration = f"    {field.c_type} {field.name};"
            notes = []
            if defaults is not None:
                notes.append(f"default {c_literal(defaults[field.name])}")
            if field.comment:
                notes.append(field.comment)
            lines.append(f"{declaration.ljust(27)} /* {'; '.join(notes)} */" if notes
                         else declaration)
        lines.append(f"}} {self.prefix}_{name};")
        return "\n".join(lines)

    def observer_typedef(self) -> str:
        parameters = ", ".join(_declaration(p.c_type, p.name)
                               for p in contract.OBSERVER_PARAMETERS)
        return f"typedef {contract.OBSERVER_RETURNS} (*{self.prefix}_observer)({parameters});"

    def controller_typedef(self) -> str:
        parameters = [_declaration(p.c_type, p.name) for p in contract.CONTROLLER_PARAMETERS]
        return _wrap(f"typedef {contract.CONTROLLER_RETURNS} (*{self.prefix}_controller)(",
                     parameters, ");")


def _declaration(c_type: str, name: str) -> str:
    """'double *x', 'long n': a parameter's declaration."""
    return f"{c_type}{name}" if c_type.endswith("*") else f"{c_type} {name}"


def _wrap(head: str, items: list[str], tail: str) -> str:
    """head item, item, ...tail, continued under the first item when longer than WIDTH."""
    indent = " " * len(head)
    lines, line = [], head
    for index, item in enumerate(items):
        piece = item + (", " if index < len(items) - 1 else tail)
        if line != head and line != indent and len(line) + len(piece.rstrip()) > WIDTH:
            lines.append(line.rstrip())
            line = indent
        line += piece
    lines.append(line)
    return "\n".join(lines)
