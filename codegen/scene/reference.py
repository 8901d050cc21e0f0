"""The reference scenes that ship with chaingen (package data chaingen.scenes): the thesis's
standard runs, an actuated, damped four-link arm, and an edge case. Studies and benchmarks load
them by name, so they work from an installed chaingen in any directory."""
from __future__ import annotations

import importlib.resources

from .reader import parse_scene
from .values import Scene

#: The thesis's three standard runs (gravity only, mono-articular springs, a multi-articular one).
STANDARD_SCENES = ("three_link_gravity", "three_link_mono", "three_link_multi")
#: Every scene shipped: the standard runs, the actuated example, and a scene whose spring
#: segment reaches zero length during the run (the extremes study's collapse edge).
REFERENCE_SCENES = STANDARD_SCENES + ("four_link_actuated", "collapsing_spring")


def reference_scene_text(name: str) -> str:
    """The TOML text of the reference scene `name` (a stem of REFERENCE_SCENES)."""
    if name not in REFERENCE_SCENES:
        raise ValueError(f"no reference scene {name!r} (known: {', '.join(REFERENCE_SCENES)})")
    return importlib.resources.files("chaingen.scenes").joinpath(f"{name}.toml").read_text()


def load_reference_scene(name: str) -> Scene:
    """The reference scene `name`, read and validated like a user's file."""
    return parse_scene(reference_scene_text(name), f"{name}.toml", name)
