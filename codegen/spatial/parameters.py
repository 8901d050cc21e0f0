"""The numbers of a spatial scene by their key path, as run-time parameters and sweep axes.

A spatial scene's solver takes as run-time parameters the numbers that scale its model without
shaping it: each component of gravity (`gravity[0]` .. `gravity[2]`, m/s^2), a link's `mass`
(kg) and `damping` (N m s/rad), a spring's `stiffness` (N/m) and `rest_length` (m). Indices
are 0-based, as the reader's error messages name keys (`links[0]` is link 1). The rest of the
scene is compiled geometry: a link's `com` and `inertia`, a joint's `xyz`, `rpy` and `axis`,
and a spring's `route` place the frames and points whose products the generated code folds
(the recursions of chaingen.symbolic.spatial_recursion multiply them out once); they are
refused as parameters in one line. A study may vary the run-time numbers too
(`initial.angles[i]`, `initial.velocities[i]`, `simulation.dt`, `simulation.t_end`).

The planar counterpart is chaingen.scene.parameters; `NumberPath` is shared. `with_values`
judges a changed scene by the spatial reader's own rules and messages (through its text).
"""
from __future__ import annotations

import dataclasses
import re

from ..errors import SceneError
from ..scene.parameters import (
    CONTROL_PATH,
    NumberPath,
    control_number_path,
    control_paths,
    control_replaced,
    control_value,
    path_match,
    run_number_path,
)
from .reader import parse_spatial_scene
from .values import SpatialScene
from .writer import scene_text

#: The numbers of a link and of a spring a spatial solver may take as parameters, with units.
LINK_NUMBERS = {"mass": "kg", "damping": "N m s/rad"}
SPRING_NUMBERS = {"stiffness": "N/m", "rest_length": "m"}
#: Keys of a spatial scene that shape the generated code: never run-time parameters.
GEOMETRY = {"links": ("com", "inertia", "joint"), "springs": ("route",)}

_PATH = re.compile(r"(?P<table>links|springs)\[(?P<index>[0-9]+)\]\.(?P<key>\w+)(?P<rest>.*)"
                   r"|gravity\[(?P<axis>[0-9]+)\]|(?P<vector>gravity)"
                   r"|(?P<run>initial\.angles|initial\.velocities)\[(?P<joint>[0-9]+)\]"
                   r"|(?P<setting>simulation\.dt|simulation\.t_end)" + CONTROL_PATH, re.ASCII)
_STRUCTURE = re.compile(r"actuation(?:\.joints(?:\[[0-9]+\])?)?|links|springs|name", re.ASCII)
_NUMBERS = ("gravity[0..2], links[i].mass, links[i].damping, springs[i].stiffness, "
            "springs[i].rest_length")


def number_path(scene: SpatialScene, path: str, *, where: str = "") -> NumberPath:
    """The number of the spatial `scene` at `path`, or SceneError naming the path and why it
    names no number a solver or a study can vary (compiled geometry, structure, an index beyond
    the chain, another spelling)."""
    prefix = f"{where}: " if where else ""
    match = path_match(path, prefix, _STRUCTURE, _PATH, "n, the actuated joints",
                       f"the spatial scene (its numbers: {_NUMBERS}, initial.angles[i], "
                       "initial.velocities[i], simulation.dt, simulation.t_end)")
    if match["vector"]:
        raise SceneError(f"{prefix}{path}: a vector; name one component, gravity[0], "
                         "gravity[1] or gravity[2] (m/s^2, world frame)")
    if match["axis"] is not None:
        if int(match["axis"]) > 2:
            raise SceneError(f"{prefix}{path}: gravity has 3 components (indices 0..2)")
        return NumberPath(path, "m/s^2", True)
    run = run_number_path(scene.n, path, match, prefix)
    if run:
        return run
    if match["gain"]:
        return control_number_path(scene, path, match, prefix)
    table, index, key = match["table"], int(match["index"]), match["key"]
    rows = scene.links if table == "links" else scene.springs
    if index >= len(rows):
        raise SceneError(f"{prefix}{path}: {table}[{index}] does not exist: the scene has "
                         f"{len(rows)} {table}")
    if key in GEOMETRY[table]:
        raise SceneError(f"{prefix}{path}: compiled geometry of a spatial scene (it shapes the "
                         f"generated code); its run-time numbers: {_NUMBERS}")
    numbers = LINK_NUMBERS if table == "links" else SPRING_NUMBERS
    if key not in numbers or match["rest"]:
        raise SceneError(f"{prefix}{path}: names no number of a spatial {table[:-1]} (its "
                         f"numbers: {', '.join(numbers)})")
    return NumberPath(path, numbers[key], True)


def compiled_paths(scene: SpatialScene) -> tuple[str, ...]:
    """Every number of `scene` a solver can take as a parameter, in a stable order: gravity's
    components, each link's mass and damping, each spring's stiffness and rest length."""
    paths = [f"gravity[{axis}]" for axis in range(3)]
    for index, _ in enumerate(scene.links):
        paths += [f"links[{index}].{key}" for key in LINK_NUMBERS]
    for index, _ in enumerate(scene.springs):
        paths += [f"springs[{index}].{key}" for key in SPRING_NUMBERS]
    return tuple(paths) + control_paths(scene)


def value(scene: SpatialScene, path: str):
    """The number (or symbol) of `scene` at the checked key path `path`."""
    match = _PATH.fullmatch(path)
    if match["axis"] is not None:
        return scene.gravity[int(match["axis"])]
    if match["setting"]:
        return getattr(scene.simulation, path.split(".")[1])
    if match["run"]:
        values = (scene.initial_angles if match["run"] == "initial.angles"
                  else scene.initial_velocities)
        return values[int(match["joint"])]
    if match["gain"]:
        return control_value(scene, match["gain"], int(match["gain_entry"]))
    rows = scene.links if match["table"] == "links" else scene.springs
    return getattr(rows[int(match["index"])], match["key"])


def _replaced(scene: SpatialScene, path: str, number) -> SpatialScene:
    """`scene` with the number at the checked `path` replaced (no validation)."""
    match = _PATH.fullmatch(path)
    if match["axis"] is not None:
        gravity = list(scene.gravity)
        gravity[int(match["axis"])] = number
        return dataclasses.replace(scene, gravity=tuple(gravity))
    if match["setting"]:
        return dataclasses.replace(scene, simulation=dataclasses.replace(
            scene.simulation, **{path.split(".")[1]: number}))
    if match["run"]:
        name = "initial_angles" if match["run"] == "initial.angles" else "initial_velocities"
        values = list(getattr(scene, name))
        values[int(match["joint"])] = number
        return dataclasses.replace(scene, **{name: tuple(values)})
    if match["gain"]:
        return control_replaced(scene, match["gain"], int(match["gain_entry"]), number)
    field = match["table"]
    rows = list(getattr(scene, field))
    index = int(match["index"])
    rows[index] = dataclasses.replace(rows[index], **{match["key"]: number})
    return dataclasses.replace(scene, **{field: tuple(rows)})


def with_symbols(scene: SpatialScene, symbols: dict[str, object]) -> SpatialScene:
    """`scene` with SymPy symbols in place of the numbers at the given (checked, compiled)
    paths: the scene a parameterised spatial solver is derived from."""
    for path, symbol in symbols.items():
        scene = _replaced(scene, path, symbol)
    return scene


def with_values(scene: SpatialScene, values: dict[str, float], *,
                where: str = "") -> SpatialScene:
    """`scene` with the numbers at `values`' paths replaced, judged by the spatial reader (its
    rules and messages: a mass > 0, a segment of zero length at the initial angles); SceneError
    names the path and value."""
    changed = scene
    for path, number in values.items():
        number_path(scene, path, where=where)
        changed = _replaced(changed, path, float(number))
    return parse_spatial_scene(scene_text(changed), where or "values", scene.name)
