"""The C text of the interface contract: macros, structs, prototypes and the package's wrappers.

chaingen.runtime.contract states each fact of the C interface once; this module writes it as C:
the runtime's contract header (runtime/c/chaingen_contract.h, `contract_header`) and, for one
package, its status macros, prototypes and the definitions of its exported functions, each a
call of the runtime library (runtime/c/chaingen_runtime.h) with the package's model table:

    prototype("step")   -> int prefix_step(const double *x0, const double *u, int nu, ...);
    wrapper("step")     -> its definition: return chaingen_step(&MODEL, x0, u, nu, ..., &view, ...)

Every package has the same entry points with the same signatures (the contract's table).
"""
from __future__ import annotations

import re
import textwrap
from dataclasses import dataclass

from ..runtime import contract

#: Width of the generated C text.
WIDTH = 100
#: A comment beside a long name (a long scene name makes long macros) is wrapped at this width at
#: least, overrunning WIDTH rather than leaving no room.
MIN_COMMENT_WIDTH = 40
#: The model table's name in a package's source.
MODEL = "MODEL"
#: Exported functions that call a runtime function of another name, with the arguments the
#: runtime's has beyond the wrapper's.
RUNTIME_CALLS = {"simulate": ("simulate_observed", ("NULL", "NULL", "1", "NULL"))}


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
    """The contract's C text for one package (prefix), or for the runtime (prefix chaingen)."""

    prefix: str

    @property
    def PREFIX(self) -> str:
        return self.prefix.upper()

    def signature(self, name: str) -> str:
        """'returns prefix_name(type name, ...)', wrapped at WIDTH with the parameters
        aligned."""
        entry = contract.ENTRY_POINTS_BY_NAME[name]
        parameters = [_declaration(contract.resolved(p.c_type, self.prefix), p.name)
                      for p in entry.parameters]
        head = f"{_declaration(entry.returns, f'{self.prefix}_{name}')}("
        return _wrap(head, parameters or ["void"], ")")

    def prototype(self, name: str) -> str:
        return self.signature(name) + ";"

    def wrapper(self, name: str) -> str:
        """The definition of the exported function `name`: the runtime's function of that name
        called with the package's model table and a view of its workspace."""
        entry = contract.ENTRY_POINTS_BY_NAME[name]
        if name == "workspace_size":
            body = [f"return sizeof({self.prefix}_workspace);"]
        elif name == "build_hash":
            body = [f"return {self.PREFIX}_BUILD_HASH;"]
        else:
            runtime, extra = RUNTIME_CALLS.get(name, (name, ()))
            arguments = [f"&{MODEL}"] + ["&view" if p.name == "workspace" else p.name
                                         for p in entry.parameters] + list(extra)
            call = _wrap(f"chaingen_{runtime}(", arguments, ");")
            result = "" if entry.returns == "void" else "return "
            body = (["const chaingen_workspace view = workspace_view(workspace);"]
                    if any(p.name == "workspace" for p in entry.parameters) else [])
            body.append(result + call.replace("\n", "\n" + " " * len(result)))
        lines = "\n".join("    " + line.replace("\n", "\n    ") for line in body)
        return f"{self.signature(name)}\n{{\n{lines}\n}}"

    def status_macros(self, segment_tolerance: str) -> str:
        """#define <PREFIX>_<status> code /* comment */ for every status of the package."""
        lines = []
        for status in contract.STATUSES:
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


def constant_macros(prefix: str) -> str:
    """The runtime's constants as #defines (the contract's values)."""
    P = prefix.upper()
    constants = (
        ("WARM_START_HISTORY", contract.WARM_START_HISTORY,
         "solutions of chained steps kept for the warm start"),
        ("REFRESH_RATE", contract.REFRESH_RATE,
         "a kept Jacobian is evaluated anew when updates shrink by less than this"),
        ("SIMPLIFIED_MARGIN", contract.SIMPLIFIED_MARGIN,
         "simplified Newton stops at this fraction of the tolerance"),
        ("CHORD_MARGIN", contract.CHORD_MARGIN,
         "Newton-chord stops at this fraction of the tolerance"),
        ("MAX_SPLIT", contract.MAX_SPLIT_DEPTH, "halvings of a step Newton fails on whole"),
        ("MIN_TOLERANCE", contract.MIN_ADAPTIVE_TOLERANCE,
         "adaptive steps: rtol and atol are 0 or at least this"),
        ("MIN_STEP_FRACTION", contract.MIN_STEP_FRACTION,
         "adaptive steps: STEP_TOO_SMALL below this fraction of dt"),
    )
    lines = []
    for name, value, comment in constants:
        head = f"#define {P}_{name} {c_literal(value)}"
        lines.append(f"{head.ljust(len(P) + 30)} /* {comment} */")
    return "\n".join(lines)


def dimension_macros(prefix: str) -> str:
    """#define <PREFIX>_DIMENSION_<name> which: the sizes <prefix>_dimension answers."""
    P = prefix.upper()
    return "\n".join(f"{f'#define {P}_DIMENSION_{name} {which}'.ljust(len(P) + 34)} "
                     f"/* {comment} */" for name, which, comment in contract.DIMENSIONS)


def contract_header() -> str:
    """runtime/c/chaingen_contract.h: the contract's C text with the runtime's prefix, included
    by the runtime and by every package's header."""
    interface = CInterface("chaingen")
    defaults = contract.NEWTON_OPTION_DEFAULTS
    sections = [
        "/* The C contract of chaingen's runtime: status codes, options, counters, callback types\n"
        " * and constants. Rendered from chaingen/runtime/contract.py by\n"
        " * chaingen.generate.interface.contract_header(). Do not edit. */",
        "#ifndef CHAINGEN_CONTRACT_H\n#define CHAINGEN_CONTRACT_H",
        "/* Status codes. */\n" + interface.status_macros("its tolerance"),
        "/* Values of the option reuse_jacobian. */\n" + interface.jacobian_mode_macros(),
        "/* Newton options (each package's defaults: <prefix>_default_options). */\n"
        + interface.struct(contract.NEWTON_OPTIONS, "options", defaults),
        "/* Counters of one simulate call. */\n"
        + interface.struct(contract.STATS_FIELDS, "stats"),
        "/* Shared with a running simulate_observed or simulate_controlled. */\n"
        + interface.struct(contract.CONTROL_FIELDS, "control"),
        interface.observer_typedef(),
        interface.controller_typedef(),
        "/* The sizes <prefix>_dimension(which) answers (-1 for another which). */\n"
        + dimension_macros("chaingen"),
        "/* Constants of the runtime's algorithms. */\n" + constant_macros("chaingen"),
        "#endif /* CHAINGEN_CONTRACT_H */",
    ]
    return "\n\n".join(sections) + "\n"
