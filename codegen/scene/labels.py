"""The name of a time-stepping scheme, built in one place for every output that names one.

A scheme is a method, the quadrature K it runs with (None where K plays no role:
chaingen.scene.values.quadrature_used) and the order of its step (2: the scheme's own step; 4
and 6: a symmetric composition of it, docs/model.md, section 14). Each output names it in one
style:

- "header": the generated header's banner and comments (chaingen.generate.package):
  ``method "es", 3-point Gauss-Legendre quadrature of the spring terms, order 4 by a
  symmetric composition of 3 steps``; the order only when composed;
- "summary": the command line's summaries and tables (simulate, check, order):
  ``method es, quadrature 3, order 4``; the order only when composed;
- "study": a study of one order among others (chaingen order): ``method es, quadrature 3,
  order 2``; the order always;
- "short": legends and table cells (plot, bench): ``es K=3 order 4``; the order only when
  composed.
"""
from __future__ import annotations

#: The styles of `scheme_label`.
LABEL_STYLES = ("header", "summary", "study", "short")


def scheme_label(method: str, quadrature: int | None = None, order: int = 2, *,
                 style: str = "summary", quadrature_rule: str | None = None,
                 composition_steps: int | None = None, gradient: str | None = None) -> str:
    """The name of the scheme `method` with K = `quadrature` (None: none) at `order`, in
    `style` (LABEL_STYLES). The header style also takes what K integrates (`quadrature_rule`,
    None: the spring terms by K Gauss-Legendre points), es's discrete gradient of the springs
    (`gradient`, None: none) and the stages of a composed step (`composition_steps`). The
    other styles name the gradient only where it is not the default "exact"."""
    composed = order != 2
    if style == "header":
        label = f'method "{method}"'
        if gradient == "chain":
            label += ", the springs by the chain rule's exact discrete gradient (no quadrature)"
        elif quadrature is not None:
            label += ", " + (quadrature_rule or f"{quadrature}-point Gauss-Legendre "
                                                "quadrature of the spring terms")
        if gradient == "exact":
            label += ", corrected to the exact discrete gradient"
        elif gradient == "quadrature":
            label += " (the quadrature alone: energy to quadrature accuracy)"
        if composed:
            label += (f", order {order} by a symmetric composition of "
                      f"{composition_steps} steps")
        return label
    if style == "short":
        label = method if quadrature is None else f"{method} K={quadrature}"
        if gradient in ("quadrature", "chain"):
            label += f" {gradient}"
        return f"{label} order {order}" if composed else label
    if style in ("summary", "study"):
        label = f"method {method}"
        if quadrature is not None:
            label += f", quadrature {quadrature}"
        if gradient == "quadrature":
            label += " (gradient by the quadrature alone)"
        elif gradient == "chain":
            label += " (gradient by the chain rule)"
        return f"{label}, order {order}" if composed or style == "study" else label
    raise ValueError(f"scheme_label: style {style!r} is none of {', '.join(LABEL_STYLES)}")
