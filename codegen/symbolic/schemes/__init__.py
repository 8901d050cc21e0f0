"""The time-stepping schemes, by the name a scene or the command line gives them
(chaingen.scene.METHODS): each module derives its DiscreteScheme from a scene."""
from __future__ import annotations

from ...errors import SettingsError
from ...scene import METHODS, Scene
from . import es, midpoint, vi
from .base import DiscreteScheme, FlowDescription, Layout, LinearSolve

BUILDERS = {"es": es.build, "vi": vi.build, "midpoint": midpoint.build}
if tuple(BUILDERS) != METHODS:
    raise ImportError(f"schemes {tuple(BUILDERS)} do not match the methods {METHODS}")


def build_scheme(scene: Scene, method: str, quadrature: int) -> DiscreteScheme:
    """The discrete scheme `method` for `scene` (quadrature: Gauss points for spring terms)."""
    try:
        builder = BUILDERS[method]
    except KeyError:
        raise SettingsError(
            f"method {method!r} is not available in this version of chaingen "
            f"(available: {', '.join(METHODS)})") from None
    return builder(scene, quadrature)


__all__ = ["DiscreteScheme", "FlowDescription", "Layout", "LinearSolve", "build_scheme"]
