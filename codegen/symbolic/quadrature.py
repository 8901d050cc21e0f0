"""Gauss-Legendre quadrature on [0, 1] (model.md section 4: averaged spring gradients)."""
from __future__ import annotations

import numpy as np


def gauss_legendre_nodes(points: int) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Nodes tau_g in (0, 1) and weights w_g (summing to 1) of the K-point Gauss-Legendre rule.

    Exact for polynomials of degree 2K - 1; the K = 1 rule is the midpoint rule.
    """
    if points < 1:
        raise ValueError(f"quadrature needs at least one point, got {points}")
    nodes, weights = np.polynomial.legendre.leggauss(points)
    return (tuple(float(t) for t in (nodes + 1.0) / 2.0),
            tuple(float(w) for w in weights / 2.0))
