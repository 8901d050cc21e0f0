"""The step's constants: what Newton's functions compute from the step's start alone.

A step's residual F(z; x0, u, q, dt) is evaluated at every Newton iterate, but much of it depends
on x0, u, q and dt only: on es's chain, the joints and arms at the start, the springs' segments
and their lengths there (docs/model.md, section 18). CasADi's extract_parametric takes every such
subexpression of the residual and of the Newton factors out into one function,

    y = step_constants(x0, u, q, dt),

which the runtime evaluates once at the start of each Newton solve (and of each entry point that
evaluates these functions: residual, residual_jacobian, the sensitivities), and the functions
take y as their last input. The arithmetic is the same, operation for operation: the results
are the same bits (tests/test_step_constants.py).
"""
from __future__ import annotations

import dataclasses

import casadi as ca

from .casadi_functions import SchemeFunctions

#: The functions that take y: those Newton evaluates at every iterate or Jacobian (the dense
#: residual_jacobian of small packages is left whole: it is built by directions).
HOISTED = ("residual", "newton_factors", "chord_factors")


def with_step_constants(functions: SchemeFunctions, prefix: str) -> SchemeFunctions:
    """`functions` with the step's constants taken out of HOISTED into step_constants, or
    `functions` itself where there are none (a scheme without the Newton factors: the step's
    constants pay there only on es's long chains)."""
    chosen = [(name, getattr(functions, name)) for name in HOISTED
              if getattr(functions, name) is not None]
    if functions.newton_factors is None or not chosen:
        return functions
    names = chosen[0][1].name_in()
    if any(function.name_in() != names for _, function in chosen) or names[0] != "z":
        raise ValueError(f"step constants: the functions {[n for n, _ in chosen]} do not take "
                         "the step's inputs (z, x0, ..., dt)")
    inputs = chosen[0][1].sx_in()
    outputs = [output for _, function in chosen for output in function.call(inputs)]
    start = ca.vertcat(*inputs[1:])
    hoisted, symbols, values = ca.extract_parametric(outputs, start,
                                                     {"extract_trivial": False, "prefix": "y_"})
    if not symbols:
        return functions
    y = ca.vertcat(*symbols)
    options = {"cse": True}
    replaced = {"step_constants": ca.Function(
        f"{prefix}_model_step_constants", inputs[1:], [ca.vertcat(*values)], names[1:], ["y"],
        options)}
    for name, function in chosen:
        count = function.n_out()
        replaced[name] = ca.Function(function.name(), [*inputs, y], hoisted[:count],
                                     [*names, "y"], function.name_out(), options)
        hoisted = hoisted[count:]
    return dataclasses.replace(functions, **replaced)
