"""The time-stepping schemes, by the name a scene or the command line gives them."""
from __future__ import annotations

from ..scene import ChaingenError, Scene
from . import es, midpoint, vi
from .base import DiscreteScheme, Layout, LinearSolve

BUILDERS = {"es": es.build, "vi": vi.build, "midpoint": midpoint.build}
METHODS = tuple(BUILDERS)


class UnknownMethodError(ChaingenError):
    pass


def build_scheme(scene: Scene, method: str, quadrature: int) -> DiscreteScheme:
    """The discrete scheme `method` for `scene` (quadrature: Gauss points for spring terms)."""
    try:
        builder = BUILDERS[method]
    except KeyError:
        raise UnknownMethodError(
            f"method {method!r} is not available in this version of chaingen "
            f"(available: {', '.join(METHODS)})") from None
    return builder(scene, quadrature)


__all__ = ["DiscreteScheme", "Layout", "METHODS", "build_scheme"]
