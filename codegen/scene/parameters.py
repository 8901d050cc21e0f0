"""Numbers of a scene by their key path: `links[1].mass`, `springs[0].offsets[2]`, `gravity`.

A key path names one number exactly as the reader's error messages name it. Paths serve two
purposes: a compiled solver can take some of a scene's numbers as run-time parameters
(`parameter_paths` lists which may be), and a study can vary any number, the run-time ones too
(`initial.angles[0]`, `simulation.dt`). `with_values` applies values to a scene and validates
the result by the scene format's own rules, so a study's value out of range gets the same
one-line message a scene file would.
"""
from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass

from ..errors import SceneError
from ..runtime.keypaths import canonical_path, spelling_error
from .values import LINK_FIELDS, Scene

#: The numbers of a link and of a spring that a solver may take as parameters, with their unit.
LINK_NUMBERS = {field.key: field.unit for field in LINK_FIELDS}
SPRING_NUMBERS = {"stiffness": "N/m", "rest_length": "m"}
#: Run-time numbers: every solver takes them per run; a study may vary them.
RUN_NUMBERS = {"initial.angles": "rad", "initial.velocities": "rad/s", "simulation.dt": "s",
               "simulation.t_end": "s"}

#: A [control] table's key path, for the planar and the spatial patterns.
CONTROL_PATH = r"|control\.(?P<gain>target|stiffness|damping)\[(?P<gain_entry>[0-9]+)\]"

_PATH = re.compile(r"(?P<table>links|springs)\[(?P<index>[0-9]+)\]\.(?P<key>\w+)"
                   r"(?:\[(?P<entry>[0-9]+)\])?|(?P<top>gravity|base\.fastening)"
                   r"|(?P<run>initial\.angles|initial\.velocities)\[(?P<joint>[0-9]+)\]"
                   r"|(?P<setting>simulation\.dt|simulation\.t_end)"
                   + CONTROL_PATH, re.ASCII)
#: The numbers of a [control] table, one per joint (target) or per actuated joint (the gains).
CONTROL_NUMBERS = {"target": "rad", "stiffness": "N m/rad", "damping": "N m s/rad"}

#: Keys that are the structure of a solver, not numbers: named as such when a study tries them.
_STRUCTURE = re.compile(r"springs\[[0-9]+\]\.joints(?:\[[0-9]+\])?|actuation(?:\.joints"
                        r"(?:\[[0-9]+\])?)?|simulation\.(?:method|quadrature)|links|springs"
                        r"|name", re.ASCII)


@dataclass(frozen=True)
class NumberPath:
    """One number of a scene: its key path (canonical: chaingen.runtime.keypaths, so equal
    paths are the same number and different ones different numbers), its unit, and whether it
    is compiled into a solver (a structural number never is: n, the joints a spring spans, the
    actuated joints)."""

    path: str
    unit: str
    compiled: bool

    def value(self, scene: Scene) -> float:
        return float(_get(scene, self.path))



def path_match(path: str, prefix: str, structure: re.Pattern, pattern: re.Pattern,
               compiled: str, numbers: str) -> re.Match:
    """The match of the canonical `path` against `pattern`, or SceneError (prefixed): another
    spelling of a number, a structural path (`compiled`: what the solver compiles in) or a path
    that names no number (`numbers`: of what, and what its numbers are). Planar and spatial
    number paths share it."""
    refused = spelling_error(path)
    if refused:
        raise SceneError(f"{prefix}{refused}")
    if structure.fullmatch(path):
        raise SceneError(f"{prefix}{path}: is structure, compiled into the solver ({compiled}): "
                         "a study varies numbers only; make a scene per structure")
    match = pattern.fullmatch(path) if canonical_path(path) == path else None
    if not match:
        raise SceneError(f"{prefix}{path}: names no number of {numbers}")
    return match


def run_number_path(n: int, path: str, match: re.Match, prefix: str) -> NumberPath | None:
    """The run's own numbers (a simulation setting, an initial angle or rate of a joint of the
    n) that `match` names, or None when it names a number of the scene's model."""
    if match["setting"]:
        return NumberPath(path, RUN_NUMBERS[path], False)
    if match["run"]:
        joint = int(match["joint"])
        if joint >= n:
            raise SceneError(f"{prefix}{path}: joint {joint + 1} does not exist: the chain has "
                             f"{n} (indices 0..{n - 1})")
        return NumberPath(path, RUN_NUMBERS[match["run"]], False)
    return None

def number_path(scene: Scene, path: str, *, where: str = "") -> NumberPath:
    """The number of `scene` at `path`, or SceneError naming the path and why it names no
    number (an unknown key, an index beyond the chain, a structural integer) or why it is
    not the number's one spelling (chaingen.runtime.keypaths: written otherwise, it names
    the canonical spelling)."""
    prefix = f"{where}: " if where else ""
    match = path_match(path, prefix, _STRUCTURE, _PATH,
                       "n, the joints a spring spans, the actuated joints, the method, K",
                       "the scene (a key path such as links[0].mass, springs[1].stiffness, "
                       "springs[0].offsets[1], base.fastening, gravity, initial.angles[0], "
                       "control.stiffness[0] or simulation.dt)")
    if match["top"]:
        return NumberPath(path, "m/s^2" if path == "gravity" else "m", True)
    if match["gain"]:
        return control_number_path(scene, path, match, prefix)
    run = run_number_path(scene.n, path, match, prefix)
    if run:
        return run
    table, index, key, entry = match["table"], int(match["index"]), match["key"], match["entry"]
    rows = scene.links if table == "links" else scene.springs
    if index >= len(rows):
        raise SceneError(f"{prefix}{path}: {table}[{index}] does not exist: the scene has "
                         f"{len(rows)} {table}")
    if table == "links":
        if key not in LINK_NUMBERS or entry is not None:
            raise SceneError(f"{prefix}{path}: names no number of a link (numbers: "
                             f"{', '.join(LINK_NUMBERS)})")
        return NumberPath(path, LINK_NUMBERS[key], True)
    spring = rows[index]
    if key == "offsets" and entry is not None:
        count = spring.last - spring.first + 2
        if spring.offsets is None:
            raise SceneError(f"{prefix}{path}: springs[{index}] has no offsets of its own (it "
                             "uses the chain's fastenings: vary base.fastening or "
                             "links[i].fastening)")
        if int(entry) >= count:
            raise SceneError(f"{prefix}{path}: springs[{index}] has {count} offsets "
                             f"(indices 0..{count - 1})")
        return NumberPath(path, "m", True)
    if key not in SPRING_NUMBERS or entry is not None:
        raise SceneError(f"{prefix}{path}: names no number of a spring (numbers: "
                         f"{', '.join(SPRING_NUMBERS)}, offsets[j]; joints is structure)")
    return NumberPath(path, SPRING_NUMBERS[key], True)


def _split(path: str) -> list:
    """links[1].mass -> ["links", 1, "mass"]; springs[0].offsets[2] -> [..., "offsets", 2]."""
    parts: list = []
    for name, index in re.findall(r"(\w+)|\[([0-9]+)\]", path):
        parts.append(name if name else int(index))
    return parts


def _get(scene: Scene, path: str):
    parts = _split(path)
    if parts[0] == "gravity":
        return scene.gravity
    if parts[:2] == ["base", "fastening"]:
        return scene.base_fastening
    if parts[0] == "initial":
        values = scene.initial_angles if parts[1] == "angles" else scene.initial_velocities
        return values[parts[2]]
    if parts[0] == "simulation":
        return getattr(scene.simulation, parts[1])
    if parts[0] == "control":
        return control_value(scene, parts[1], parts[2])
    row = (scene.links if parts[0] == "links" else scene.springs)[parts[1]]
    value = getattr(row, parts[2])
    return value[parts[3]] if len(parts) > 3 else value


def _replaced(scene: Scene, path: str, value) -> Scene:
    """`scene` with the number at `path` replaced (no validation)."""
    parts = _split(path)
    if parts[0] == "gravity":
        return dataclasses.replace(scene, gravity=value)
    if parts[:2] == ["base", "fastening"]:
        return dataclasses.replace(scene, base_fastening=value)
    if parts[0] == "initial":
        name = "initial_angles" if parts[1] == "angles" else "initial_velocities"
        values = list(getattr(scene, name))
        values[parts[2]] = value
        return dataclasses.replace(scene, **{name: tuple(values)})
    if parts[0] == "simulation":
        return dataclasses.replace(
            scene, simulation=dataclasses.replace(scene.simulation, **{parts[1]: value}))
    if parts[0] == "control":
        return control_replaced(scene, parts[1], parts[2], value)
    field = "links" if parts[0] == "links" else "springs"
    rows = list(getattr(scene, field))
    row = rows[parts[1]]
    if len(parts) > 3:
        entries = list(getattr(row, parts[2]))
        entries[parts[3]] = value
        rows[parts[1]] = dataclasses.replace(row, **{parts[2]: tuple(entries)})
    else:
        rows[parts[1]] = dataclasses.replace(row, **{parts[2]: value})
    return dataclasses.replace(scene, **{field: tuple(rows)})


def with_symbols(scene: Scene, symbols: dict[str, object]) -> Scene:
    """`scene` with SymPy symbols in place of the numbers at the given paths: the scene the
    symbolic stage derives a parameterised solver from (its other numbers stay constants)."""
    for path, symbol in symbols.items():
        scene = _replaced(scene, path, symbol)
    return scene


def with_values(scene: Scene, values: dict[str, float], *, where: str = "") -> Scene:
    """`scene` with the numbers at `values`' paths replaced, validated by the scene format's
    rules (the reader's own checks and messages); SceneError names the path and value."""
    from .document import scene_document
    from .reader import SceneReader

    changed = scene
    for path, value in values.items():
        number_path(scene, path, where=where)
        changed = _replaced(changed, path, float(value))
    source = where or "values"
    return SceneReader(source, scene.name).read(scene_document(changed))


def compiled_paths(scene: Scene) -> tuple[str, ...]:
    """Every number of `scene` a solver can take as a parameter, in a stable order: gravity,
    the base fastening, each link's numbers, each spring's (its offsets when it has its own)."""
    paths = ["gravity", "base.fastening"]
    for index, _ in enumerate(scene.links):
        paths += [f"links[{index}].{key}" for key in LINK_NUMBERS]
    for index, spring in enumerate(scene.springs):
        paths += [f"springs[{index}].{key}" for key in SPRING_NUMBERS]
        if spring.offsets is not None:
            paths += [f"springs[{index}].offsets[{entry}]"
                      for entry in range(len(spring.offsets))]
    return tuple(paths) + control_paths(scene)


def control_number_path(scene, path: str, match: re.Match, prefix: str) -> NumberPath:
    """The [control] number `match` names (planar or spatial scene), or SceneError."""
    if scene.control is None:
        raise SceneError(f"{prefix}{path}: the scene has no [control] table")
    count = len(getattr(scene.control, match["gain"]))
    if int(match["gain_entry"]) >= count:
        raise SceneError(f"{prefix}{path}: control.{match['gain']} has {count} entries "
                         f"(indices 0..{count - 1})")
    return NumberPath(path, CONTROL_NUMBERS[match["gain"]], True)


def control_paths(scene) -> tuple[str, ...]:
    """The key paths of a scene's [control] numbers (none without the table)."""
    if scene.control is None:
        return ()
    return tuple(f"control.{key}[{entry}]" for key in CONTROL_NUMBERS
                 for entry in range(len(getattr(scene.control, key))))


def control_value(scene, key: str, entry: int):
    return getattr(scene.control, key)[entry]


def control_replaced(scene, key: str, entry: int, value):
    """`scene` with control.<key>[entry] replaced (no validation)."""
    entries = list(getattr(scene.control, key))
    entries[entry] = value
    return dataclasses.replace(scene, control=dataclasses.replace(
        scene.control, **{key: tuple(entries)}))
