"""A spatial scene as the text of a scene file (docs/scene-format.md, "Spatial scenes").

What `chaingen import` writes, and what a user then edits (adding springs, say). Every number
is written with repr, the shortest text that reads back as the same double, so that reading
the file gives back the scene exactly. Rendered to a string; writing it is the caller's.
"""
from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Iterable, Sequence

from ..scene.values import Simulation
from .values import SpatialLink, SpatialScene, SpatialSpring


def scene_text(scene: SpatialScene, comment_lines: Iterable[str] = (),
               link_comments: Sequence[str] = ()) -> str:
    """The TOML text of `scene`: `comment_lines` first (each a `# ` line; where the scene came
    from), then its keys in the order of docs/scene-format.md. `link_comments`, when given, has
    one entry per link, written after its `[[links]]` header (the URDF's link and joint).
    ValueError for a number that is not finite (a scene file has none)."""
    if link_comments and len(link_comments) != scene.n:
        raise ValueError(f"link_comments: one per link ({scene.n}), got {len(link_comments)}")
    lines = [f"# {part}".rstrip() for line in comment_lines for part in
             (str(line).splitlines() or [""])]
    lines += [f"name = {json.dumps(scene.name)}",
              f"gravity = {_vector(scene.gravity)}   # m/s^2, world frame"]
    for i, link in enumerate(scene.links):
        lines += [""] + _link_lines(link, link_comments[i] if link_comments else "")
    for spring in scene.springs:
        lines += [""] + _spring_lines(spring)
    lines += ["", "[initial]",
              f"angles = {_vector(scene.initial_angles)}       # rad, one per joint",
              f"velocities = {_vector(scene.initial_velocities)}   # rad/s"]
    if scene.actuated:
        lines += ["", "[actuation]",
                  f"joints = [{', '.join(str(int(j)) for j in scene.actuated)}]"]
    if scene.control is not None:
        control = scene.control
        lines += ["", "[control]", f"target = {_vector(control.target)}",
                  f"stiffness = {_vector(control.stiffness)}",
                  f"damping = {_vector(control.damping)}",
                  f"compensate = {'true' if control.compensate else 'false'}",
                  f'law = "{control.law}"']
    lines += ["", "[simulation]   # run settings; the command line's options override them"]
    lines += _simulation_lines(scene.simulation)
    return "\n".join(lines) + "\n"


def _link_lines(link: SpatialLink, comment: str) -> list[str]:
    joint = link.joint
    header = "[[links]]" + (f"   # {' '.join(comment.split())}" if comment else "")
    return [header,
            f"mass = {_number(link.mass)}",
            f"com = {_vector(link.com)}",
            f"inertia = {_vector(link.inertia)}",
            f"joint = {{ xyz = {_vector(joint.xyz)}, rpy = {_vector(joint.rpy)}, "
            f"axis = {_vector(joint.axis)} }}",
            f"damping = {_number(link.damping)}"]


def _spring_lines(spring: SpatialSpring) -> list[str]:
    route = ", ".join(f"[{int(point.link)}, {', '.join(_number(x) for x in point.point)}]"
                      for point in spring.route)
    return ["[[springs]]",
            f"route = [{route}]",
            f"stiffness = {_number(spring.stiffness)}",
            f"rest_length = {_number(spring.rest_length)}"]


def _simulation_lines(simulation: Simulation) -> list[str]:
    """Every key of the table, Simulation's fields in their order (a string as a TOML string,
    an int as an integer, a float by repr)."""
    lines = []
    for field in dataclasses.fields(simulation):
        value = getattr(simulation, field.name)
        text = (json.dumps(value) if isinstance(value, str) else str(value)
                if isinstance(value, int) else _number(value))
        lines.append(f"{field.name} = {text}")
    return lines


def _vector(values) -> str:
    return f"[{', '.join(_number(value) for value in values)}]"


def _number(value) -> str:
    """repr of the double: it reads back exactly (a TOML float; -0.0 keeps its sign)."""
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"a scene file holds finite numbers only, got {value!r}")
    return repr(value)
