"""The C code of CasADi Functions: CasADi's CodeGenerator with the package prefix, the work
arrays the caller owns, and the patch that keeps the generated text clean under -Wextra."""
from __future__ import annotations

import re
from dataclasses import dataclass

import casadi as ca


@dataclass(frozen=True)
class WorkSizes:
    """Largest CasADi work arrays over a set of functions (the caller-owned workspace)."""

    arg: int
    res: int
    iw: int
    w: int


def work_sizes(functions) -> WorkSizes:
    functions = list(functions)
    return WorkSizes(arg=max(f.sz_arg() for f in functions),
                     res=max(f.sz_res() for f in functions),
                     iw=max(f.sz_iw() for f in functions),
                     w=max(f.sz_w() for f in functions))


def casadi_c_source(functions, prefix: str, part: str = "") -> tuple[str, str]:
    """C source and header of `functions` from CasADi's CodeGenerator, symbols prefixed.

    Internal symbols get `prefix` and `part` through CasADi's own prefix option (a few of
    them are not static: each source of one package takes its own `part`); the exported ones
    are the function names, which already carry the prefix. No export attributes: visibility
    is left to the build.
    """
    generator = ca.CodeGenerator(f"{prefix}_model.c", {
        "prefix": f"{prefix}_{part}", "with_header": True, "with_export": False,
        "casadi_int": "long long int"})
    for function in functions:
        generator.add(function)
    source = mark_parameters_used(generator.dump())
    header = casadi_header(functions, prefix)
    return source, header


def model_c_sources(functions, prefix: str) -> tuple[dict[str, str], str]:
    """The model C of a package's SchemeFunctions, {file name: source}, and its header. The
    step's functions are in <prefix>_model.c; those a forward run never calls (the
    sensitivities', dF/dz's factors where the chord has its own: functions.derivatives()),
    if any, in <prefix>_derivatives.c. Each file's optimisation is its own (package.py), so
    the step keeps -O2 where the sensitivities' code would make one file large."""
    derivatives = functions.derivatives()
    step = [function for function in functions.all() if function not in derivatives]
    sources = {f"{prefix}_model.c": casadi_c_source(step, prefix)[0]}
    if derivatives:
        sources[f"{prefix}_derivatives.c"] = casadi_c_source(derivatives, prefix,
                                                             "derivatives_")[0]
    return sources, casadi_header(functions.all(), prefix)


_DEFINITION = re.compile(r"^(?:static )?[A-Za-z_][\w \*]*\b(\w+)\(([^()]*)\) ?\{$")


def mark_parameters_used(source: str) -> str:
    """Add `(void)name;` for every parameter of every function CasADi defines.

    CasADi's generated functions take (arg, res, iw, w, mem) whether they use them or not, which
    -Wextra reports as unused parameters (CasADi issues 1875, 2014); acados patches the text
    the same way. Casting a parameter to void changes no behaviour.
    """
    lines = []
    for line in source.splitlines(keepends=True):
        lines.append(line)
        match = _DEFINITION.match(line.rstrip("\n"))
        if not match or match.group(2).strip() in ("", "void"):
            continue
        names = [re.split(r"[\s\*]+", parameter.strip())[-1]
                 for parameter in match.group(2).split(",")]
        lines.append("  " + " ".join(f"(void){name};" for name in names) + "\n")
    return "".join(lines)


def casadi_header(functions, prefix: str) -> str:
    """Declarations of the evaluation entry points we call (CasADi's header declares many more
    bookkeeping functions we never use)."""
    guard = f"{prefix.upper()}_MODEL_H"
    lines = [f"#ifndef {guard}", f"#define {guard}", ""]
    for function in functions:
        lines.append(f"int {function.name()}(const double** arg, double** res, "
                     "long long int* iw, double* w, int mem);")
    lines += ["", f"#endif /* {guard} */", ""]
    return "\n".join(lines)
