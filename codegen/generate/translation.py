"""SymPy expressions into CasADi SX: the translation every generated function uses.

SymPy expressions are translated node by node into CasADi SX, memoised on the expression so
that a subexpression SymPy shares is built once; CasADi's CSE then shares the rest. Before an
expression is translated, its free symbols are checked against the inputs of the function it
goes into (check_free_symbols, style.md).
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import sympy as sp

from .jacobians import Sweep

#: SymPy functions with a CasADi counterpart of the same meaning.
_FUNCTIONS = {
    sp.sin: ca.sin, sp.cos: ca.cos, sp.tan: ca.tan, sp.exp: ca.exp, sp.log: ca.log,
    sp.atan: ca.atan, sp.Abs: ca.fabs, sp.atan2: ca.atan2,
}


class MissingInputError(ValueError):
    """An expression has a free symbol that is not an input of the function being built."""


def check_free_symbols(name: str, expressions, inputs) -> None:
    """Every free symbol of `expressions` must be one of `inputs` (style.md), or raise."""
    declared = set(inputs)
    missing = set()
    for expr in expressions:
        missing |= set(expr.free_symbols) - declared
    if missing:
        names = ", ".join(sorted(map(str, missing)))
        raise MissingInputError(f"{name}: free symbols {names} are not inputs of the function")


class SympyToCasadi:
    """Translate SymPy expressions into CasADi SX over given symbol -> SX bindings.

    `parametric`: symbols of run-time parameters. A sum or product then combines its terms that
    depend on parameters alone first, so that they form subexpressions of their own (m1 * m2 *
    x as (m1 * m2) * x): those are what `extract_parametric` hoists out of the step.
    """

    def __init__(self, bindings: dict[sp.Symbol, ca.SX], parametric=()):
        self._memo: dict[sp.Basic, ca.SX] = dict(bindings)
        self._parametric: set[sp.Basic] = set(parametric)
        self._grouping = bool(self._parametric)

    def bind(self, symbol: sp.Symbol, value: ca.SX, parametric: bool = False) -> None:
        """Bind one more symbol (an intermediate defined by earlier bindings)."""
        self._memo[symbol] = value
        if parametric:
            self._parametric.add(symbol)

    def is_parametric(self, expr: sp.Basic) -> bool:
        """Whether a translated expression depends on the parameters (and numbers) alone."""
        return expr in self._parametric or expr.is_Number

    def __call__(self, expr: sp.Basic) -> ca.SX:
        # Iterative post-order walk: deep recursive expressions (long chains) must not hit
        # Python's recursion limit.
        memo = self._memo
        stack = [(expr, False)]
        while stack:
            node, expanded = stack.pop()
            if node in memo:
                continue
            if node.is_Number:
                memo[node] = ca.SX(float(node))
                continue
            if node.is_Symbol:
                raise MissingInputError(f"symbol {node} has no binding")
            if not expanded:
                stack.append((node, True))
                stack.extend((arg, False) for arg in node.args if arg not in memo)
                continue
            args = node.args
            if self._grouping:
                flags = [self.is_parametric(arg) for arg in args]
                if all(flags):
                    self._parametric.add(node)
                elif (node.is_Add or node.is_Mul) and any(flags):
                    # parameter-only terms first: they combine into one hoistable subtotal
                    args = tuple(arg for arg, flag in zip(args, flags) if flag) + tuple(
                        arg for arg, flag in zip(args, flags) if not flag)
            memo[node] = self._combine(node, [memo[arg] for arg in args])
        return memo[expr]

    @staticmethod
    def _combine(node: sp.Basic, args: list[ca.SX]) -> ca.SX:
        if node.is_Add:
            total = args[0]
            for term in args[1:]:
                total = total + term
            return total
        if node.is_Mul:
            product = args[0]
            for factor in args[1:]:
                product = product * factor
            return product
        if node.is_Pow:
            base, exponent = args
            e = node.exp
            if e == sp.Rational(1, 2):
                return ca.sqrt(base)
            if e == -sp.Rational(1, 2):
                return 1 / ca.sqrt(base)
            if e == -1:
                return 1 / base
            if e.is_Integer and e > 0:
                return ca.constpow(base, exponent)
            return ca.power(base, exponent)
        if isinstance(node, (sp.Max, sp.Min)):     # n arguments, CasADi's fmax takes two
            pair = ca.fmax if isinstance(node, sp.Max) else ca.fmin
            extreme = args[0]
            for arg in args[1:]:
                extreme = pair(extreme, arg)
            return extreme
        for sympy_function, casadi_function in _FUNCTIONS.items():
            if isinstance(node, sympy_function):
                return casadi_function(*args)
        raise NotImplementedError(f"no CasADi translation for {type(node).__name__}: {node}")


def sx_vector(translate: SympyToCasadi, matrix) -> ca.SX:
    """The entries of a SymPy matrix (or sequence), translated, as a CasADi column."""
    entries = [translate(e) for e in matrix]
    return ca.vertcat(*entries) if entries else ca.SX(0, 1)


@dataclass(frozen=True)
class GeneratedFunction:
    """One function of the generated C, as SymPy's Routine is one routine: its name (without
    the package prefix), its arguments and its results, each with its name. The builders of
    casadi_functions and sensitivities make one each, from expressions that
    `SchemeTranslation.translated` checked for free symbols before translating them."""

    name: str
    inputs: tuple[ca.SX, ...]
    input_names: tuple[str, ...]
    outputs: tuple[ca.SX, ...]
    output_names: tuple[str, ...]
    # A function of Jacobian blocks evaluated by directions (jacobians.Sweep): then the last
    # input is the seed matrix, the outputs are the tangents, and the package's function
    # takes the other inputs and returns sweep.blocks.
    sweep: Sweep | None = None
