"""The rules of a solver request, stated once: which methods, Gauss points K, orders of the step
and adaptive tolerances a request may name, and the rule between them (es at order 6 needs
K >= 2). Every reader of a request asks `request_refusal`: the scene reader
(simulation.method ...), `run_settings` and the command line (--method ...), the sweep spec,
the order study, the schemes and SolverSpec (chaingen.scene.solver_spec); each names the key
its own way and raises its own error type, with the same sentence after the key.
"""
from __future__ import annotations

import numbers
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from ..errors import SettingsError
from ..runtime.contract import ADAPTIVE_TOLERANCE_RULE, ADAPTIVE_TOLERANCES, is_adaptive_tolerance
from .display import shown

#: The time-stepping schemes a scene (simulation.method) or the command line may name.
METHODS = ("es", "vi", "midpoint")
#: Gauss-Legendre points of the spring terms (simulation.quadrature, --quadrature).
QUADRATURE_RANGE = (1, 20)
#: Orders of the step (simulation.order, --order): the scheme itself (2), or a symmetric
#: composition of it (chaingen.symbolic.composition).
ORDERS = (2, 4, 6)
#: The order from which "es" takes its k = 1 Galerkin step in joint angles (docs/model.md,
#: section 16), whose quadrature rule integrates every term of the step.
GALERKIN_ORDER = 6
#: The fewest Gauss points K es takes at GALERKIN_ORDER: its Galerkin step's Gauss-Lobatto rule
#: has K + 1 >= 3 nodes, exact to degree 3, which its equations of order 4 need.
GALERKIN_MIN_QUADRATURE = 2
#: es's discrete gradient of the spring energy (simulation.gradient, --gradient): "exact", the
#: K-point average corrected so that the energy balance holds identically (docs/model.md,
#: section 4), "quadrature", the K-point average alone (the thesis's scheme: its energy
#: error scales like dt^(2K)), or "chain", the chain rule's discrete gradient of each spring,
#: exact too and without quadrature (K plays no role for the springs).
GRADIENTS = ("exact", "quadrature", "chain")
#: The fields of a request that have a rule of their own, in the order they are checked.
REQUEST_KEYS = ("method", "quadrature", "order", "gradient", *ADAPTIVE_TOLERANCES)

_NO_VALUE = object()


@dataclass(frozen=True)
class Refusal:
    """Why a request is refused: its key (a field name: method, quadrature, order, rtol, atol,
    parameters), the rule it breaks, and the refused value (none for a rule that names it)."""

    key: str
    rule: str
    value: Any = _NO_VALUE

    @property
    def message(self) -> str:
        """The rule and the value, e.g. 'must be one of 2, 4, 6 (the order of the step),
        got 3': what every reader of a request says after the key."""
        if self.value is _NO_VALUE:
            return self.rule
        return f"{self.rule}, got {shown(self.value)}"

    @property
    def stated(self) -> str:
        """The key and its value first, then the rule: 'order 3: must be one of 2, 4, 6 (the
        order of the step)', as the order study has always said it."""
        if self.value is _NO_VALUE:
            return f"{self.key}: {self.rule}"
        return f"{self.key} {shown(self.value)}: {self.rule}"

    @property
    def option(self) -> str:
        """The command-line option of the key (--order, --t-end)."""
        return "--" + self.key.replace("_", "-")


class SolverSpecError(SettingsError):
    """A solver request that breaks a rule; `refusal` says which. Its text names the
    command-line option (--order: must be one of ...), as build_solver and the command line
    always have."""

    def __init__(self, refusal: Refusal):
        super().__init__(f"{refusal.option}: {refusal.message}")
        self.refusal = refusal


def is_integer(value: Any) -> bool:
    """An integer, not a bool (numpy's integers too)."""
    return isinstance(value, numbers.Integral) and not isinstance(value, bool)


def _is_number(value: Any) -> bool:
    return isinstance(value, numbers.Real) and not isinstance(value, bool)


def method_rule() -> str:
    return "must be one of " + ", ".join(f'"{method}"' for method in METHODS)


def quadrature_rule() -> str:
    low, high = QUADRATURE_RANGE
    return f"must be an integer from {low} to {high} (Gauss-Legendre points)"


def order_rule() -> str:
    return "must be one of " + ", ".join(map(str, ORDERS)) + " (the order of the step)"


def gradient_rule() -> str:
    return ("must be one of " + ", ".join(f'"{gradient}"' for gradient in GRADIENTS)
            + " (es's discrete gradient of the springs)")


def tolerance_rule() -> str:
    return f"must be {ADAPTIVE_TOLERANCE_RULE} (the local error tolerance of adaptive steps)"


def galerkin_quadrature_rule(order: int) -> str:
    return (f"es at order {order} takes its k = 1 Galerkin step, whose Gauss-Lobatto rule "
            f"needs K >= {GALERKIN_MIN_QUADRATURE} (K + 1 nodes, exact to degree 2K - 1; "
            "docs/model.md, section 16)")


def _field_refusal(key: str, value: Any) -> Refusal | None:
    low, high = QUADRATURE_RANGE
    if key == "method":
        good = isinstance(value, str) and value in METHODS
        rule = method_rule()
    elif key == "quadrature":
        good = is_integer(value) and low <= value <= high
        rule = quadrature_rule()
    elif key == "order":
        good = is_integer(value) and value in ORDERS
        rule = order_rule()
    elif key == "gradient":
        good = isinstance(value, str) and value in GRADIENTS
        rule = gradient_rule()
    elif key in ADAPTIVE_TOLERANCES:
        good = _is_number(value) and is_adaptive_tolerance(float(value))
        rule = tolerance_rule()
    else:
        raise ValueError(f"{key!r}: not a field of a solver request ({', '.join(REQUEST_KEYS)})")
    return None if good else Refusal(key, rule, value)


def request_refusal(fields: Mapping[str, Any]) -> Refusal | None:
    """The first rule `fields` break, or None: each field's own rule in the mapping's order
    (a scene file's order of keys), then the rule between fields: es at order GALERKIN_ORDER
    takes its Galerkin step, whose Gauss-Lobatto rule needs K >= GALERKIN_MIN_QUADRATURE
    (docs/model.md, section 16). fields: any of REQUEST_KEYS; a field left out is not checked.
    """
    for key, value in fields.items():
        refused = _field_refusal(key, value)
        if refused:
            return refused
    if (fields.get("method") == "es" and fields.get("order", 0) >= GALERKIN_ORDER
            and "quadrature" in fields and fields["quadrature"] < GALERKIN_MIN_QUADRATURE):
        return Refusal("quadrature", galerkin_quadrature_rule(fields["order"]),
                       fields["quadrature"])
    return None


def require(**fields: Any) -> None:
    """request_refusal of `fields`, raised as SolverSpecError (a SettingsError naming the
    option: --order: ...)."""
    refused = request_refusal(fields)
    if refused:
        raise SolverSpecError(refused)


def orders_taken(method: str) -> tuple[int, ...]:
    """The orders of the step `method` takes (every method takes every order today; es at
    GALERKIN_ORDER with K >= GALERKIN_MIN_QUADRATURE)."""
    return tuple(order for order in ORDERS if request_refusal({"method": method, "order": order})
                 is None)


def quadrature_used(scene, method: str, quadrature: int, order: int = 2) -> int | None:
    """The quadrature a scheme of `scene` runs with, None where K plays no role.

    Only "es" uses K: up to order 4 the planar one averages the spring gradient over the step
    by Gauss-Legendre quadrature (docs/model.md, section 4), so without springs there is
    nothing to average, and the spatial one takes none; at order 6 its Galerkin step
    integrates every term by the (K + 1)-point Gauss-Lobatto rule (section 16).
    """
    if method != "es":
        return None
    if order >= GALERKIN_ORDER:
        return quadrature
    # The spatial es below order 6 takes the springs' exact discrete gradient by the chain
    # rule (section 4.8): no quadrature, and its manifest says so.
    return quadrature if scene.springs and scene.spring_quadrature else None


def gradient_used(scene, method: str, gradient: str, order: int = 2) -> str | None:
    """The discrete gradient a scheme of `scene` runs with, None where the choice plays no
    role: only es's own step (up to order 4, composed) has one, and only for springs (gravity's
    gradient is constant: every average of it is exact). The spatial es has one: the chain
    rule's exact gradient (model.md 4.8), whichever is asked for."""
    if method != "es" or order >= GALERKIN_ORDER or not scene.springs:
        return None
    return gradient if scene.spring_quadrature else "chain"
