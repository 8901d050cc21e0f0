"""Higher order by symmetric composition (docs/model.md, section 14).

Every scheme's step Phi_h is symmetric (Phi_h o Phi_-h = id) and of order 2, so the composition
Phi_{g_s h} o ... o Phi_{g_1 h} with symmetric coefficients that satisfy the order conditions is
of order 4 or 6. Each stage is a step of the scheme itself, so the composed step keeps what the
scheme keeps on every step of any size: es its energy balance and its quadratic constraints, vi
its symplecticity and the unit norms. Every composition of order above 2 has a negative stage
(Sheng, Suzuki), a step backwards in time.

- order 4: Suzuki's fractal composition of 5 stages (p, p, 1 - 4p, p, p), p = 1 / (4 - 4^(1/3)),
  whose error constant is much smaller than the triple jump's;
- order 6: Kahan and Li's 9-stage composition s9odr6a (Hairer, Lubich and Wanner, Geometric
  Numerical Integration, V.3.2).

"es" composes its own step to order 4 only: its nodal velocities meet C(q) v = 0 to O(dt^2),
which stalls a composition of its steps there (docs/model.md, section 14). At order 6 it takes
its k = 1 Galerkin step in joint angles instead, symmetric and of order 4
(chaingen.symbolic.schemes.galerkin), composed by Suzuki's 5 stages (p, p, 1 - 4p, p, p) with
p = 1 / (4 - 4^(1/5)), the same construction one order up.
"""
from __future__ import annotations

from ..scene import ORDERS
from ..scene.solver_rules import GALERKIN_MIN_QUADRATURE as GALERKIN_MIN_QUADRATURE
from ..scene.solver_rules import request_refusal

_P = 1.0 / (4.0 - 4.0 ** (1.0 / 3.0))
_P6 = 1.0 / (4.0 - 4.0 ** (1.0 / 5.0))
_KAHAN_LI = (0.39216144400731413928, 0.33259913678935943860, -0.70624617255763935981,
             0.08221359629355080023, 0.79854399093482996340)

#: The stages' step fractions g_1..g_s of each order (they sum to 1).
COMPOSITIONS: dict[int, tuple[float, ...]] = {
    2: (1.0,),
    4: (_P, _P, 1.0 - 4.0 * _P, _P, _P),
    6: _KAHAN_LI + _KAHAN_LI[-2::-1],
}
if tuple(COMPOSITIONS) != ORDERS:
    raise ImportError(f"compositions {tuple(COMPOSITIONS)} do not match the orders {ORDERS}")

#: The step fractions that compose a symmetric step of order 4 to order 6 (Suzuki).
FROM_ORDER_4 = (_P6, _P6, 1.0 - 4.0 * _P6, _P6, _P6)


def order_error(method: str, order: int) -> str | None:
    """Why `method` cannot take `order` (a sentence), or None when it can
    (chaingen.scene.solver_rules)."""
    refused = request_refusal({"order": order})
    return refused.message if refused else None


def quadrature_error(method: str, order: int, quadrature: int) -> str | None:
    """Why `method` at `order` cannot take `quadrature` K (a sentence), or None when it can
    (the rule between fields of chaingen.scene.solver_rules)."""
    refused = request_refusal({"method": method, "order": order, "quadrature": quadrature})
    return refused.message if refused and refused.key == "quadrature" else None


def composition(order: int) -> tuple[float, ...]:
    """The step fractions of the composition of `order` from a symmetric step of order 2
    (ValueError for another order)."""
    try:
        return COMPOSITIONS[order]
    except KeyError:
        raise ValueError(f"order {order!r}: must be one of "
                         f"{', '.join(map(str, ORDERS))}") from None
