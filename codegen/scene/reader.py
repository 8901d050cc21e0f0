"""Reading and validating scene files (docs/scene-format.md).

Every rule of the format is checked and the first violation, in the file's order of keys, raises
a one-line SceneError that names the file, the key with its path and the value, e.g.
``links[2].mass: must be > 0, got -1.0``.
"""
from __future__ import annotations

import dataclasses
import difflib
import json
import math
import os
import re
import tomllib
from pathlib import Path
from typing import Any, NoReturn

from ..errors import SceneError, UnsupportedSceneError
from ..runtime import contract
from ..runtime.contract import ADAPTIVE_TOLERANCES
from . import kinematics, overflow
from .control_table import read_control
from .display import kind as _kind
from .display import printable as _printable
from .display import shown as _show
from .shipped import scene_file
from .solver_rules import REQUEST_KEYS, Refusal, request_refusal
from .values import LINK_FIELDS, Control, Link, Scene, Simulation, Spring, far_angle

NAME_PATTERN = re.compile(r"[A-Za-z][A-Za-z0-9_-]*")
"""A scene name: a letter, then letters, digits, '_' or '-' (usable in C after `c_identifier`)."""

_TOP_KEYS = ("name", "gravity", "base", "links", "springs", "actuation", "control", "initial",
             "simulation")
_ACTUATION_KEYS = ("joints",)
_BASE_KEYS = ("fastening",)
_SPRING_KEYS = ("joints", "stiffness", "rest_length", "offsets")
_SPRING_REQUIRED = ("joints", "stiffness", "rest_length")
_INITIAL_KEYS = ("angles", "velocities")
_SIMULATION_KEYS = ("method", "quadrature", "order", "gradient", "dt", "t_end", "rtol", "atol")

_MISSING = object()


def load_scene(path: str | os.PathLike[str]) -> Scene:
    """Read and validate the scene file at `path` (a bare name of a shipped scene: its file,
    scene_file); its default name is the file's stem. A spatial scene file (spatial_marker) is
    refused with a SpatialSceneFileError: chaingen.spatial.load_spatial_scene reads it."""
    source, text = read_scene_text(path)
    return parse_scene(text, source, Path(source).stem)


def read_scene_text(path: str | os.PathLike[str]) -> tuple[str, str]:
    """The file a scene argument names (scene_file) and its text; SceneError for a file that
    cannot be read or is not UTF-8, naming the file (and the line of the first bad byte)."""
    source = os.fspath(scene_file(path))
    try:
        data = Path(source).read_bytes()
    except OSError as error:
        reason = error.strerror or str(error)
        raise SceneError(f"{source}: cannot read scene file: {reason}") from None
    try:
        return source, data.decode("utf-8")
    except UnicodeDecodeError as error:
        line = data[: error.start].count(b"\n") + 1
        raise SceneError(
            f"{source}:{line}: TOML syntax error: the file is not UTF-8 text "
            f"(invalid byte 0x{data[error.start]:02x})"
        ) from None


def parse_scene(text: str, source: str, default_name: str) -> Scene:
    """Parse and validate scene TOML `text`; errors name `source`, the key path and the line.

    Every rule of scene-format.md is checked and the first violation, in the file's order of
    keys, raises a one-line SceneError ``<source>: <key path>: <what is wrong>, got <value>``
    (``<source>:<line>: TOML syntax error: ...`` when the text is not TOML). List indices in
    key paths are 0-based, as in the file's arrays: ``links[0]`` is link 1 of model.md.
    A spatial scene (a `joint` table in a link, or a gravity vector) is no Scene: it raises a
    SpatialSceneFileError that names the key that makes it spatial.
    """
    document = parse_toml(text, source)
    marker = spatial_marker(document)
    if marker is not None:
        raise SpatialSceneFileError(
            f"{source}: {marker}: a spatial scene (scene-format.md, \"Spatial scenes\"), which "
            "the bench and the other planar-only readers do not take yet; read it with "
            "chaingen.spatial.load_spatial_scene")
    return SceneReader(source, default_name).read(document)


def parse_toml(text: str, source: str) -> dict[str, Any]:
    """The TOML document of a scene file's `text`; a one-line SceneError naming `source` and
    the line where it is not TOML."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        message = str(error)
        match = re.search(r"\(at line (\d+), column \d+\)", message)
        if match:
            line = int(match.group(1))
        else:  # "(at end of document)"
            line = max(1, len(text.splitlines()))
        raise SceneError(f"{source}:{line}: TOML syntax error: {message}") from None
    except ValueError as error:   # an integer literal beyond Python's digit limit
        match = re.search(r"\d{4000,}", text)
        line = text.count("\n", 0, match.start()) + 1 if match else 1
        raise SceneError(f"{source}:{line}: TOML syntax error: {_printable(str(error))}") from None
    except RecursionError:
        raise SceneError(f"{source}: TOML nested too deeply for a scene file (arrays or inline "
                         "tables within each other hundreds of levels deep)") from None


class SpatialSceneFileError(UnsupportedSceneError, SceneError):
    """A spatial scene file given to the planar reader: a scene the planar-only features
    (the bench, the Python API's Scene) cannot take yet (UnsupportedSceneError) and a
    file this reader cannot use (SceneError, naming the file and the key that makes it
    spatial). The commands tell the two kinds apart before reading (chaingen.arguments)."""


def spatial_marker(document: dict[str, Any]) -> str | None:
    """The key path that makes a parsed scene file spatial, the first in the file's order: a
    `joint` table in a [[links]] table (`links[2].joint`) or a gravity vector (`gravity`).
    None for a planar file, whose gravity is a number and whose links have no joints."""
    for key, value in document.items():
        if key == "gravity" and isinstance(value, list):
            return "gravity"
        if key == "links" and isinstance(value, list):
            for index, link in enumerate(value):
                if isinstance(link, dict) and "joint" in link:
                    return f"links[{index}].joint"
    return None


def _key(key: str) -> str:
    """A key as it would be written in a key path: bare if it can be, else quoted."""
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else json.dumps(key, ensure_ascii=False)


def _entries(count: int) -> str:
    return f"{count} entry" if count == 1 else f"{count} entries"


def _is_integer(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


class SceneReader:
    """Validates one parsed TOML document; `fail` raises the one-line SceneError."""

    #: How messages name [initial]'s numbers: an angle, a rate, and how many there are.
    INITIAL_MEANINGS = ("phi_i in rad", "phidot_i in rad/s", "one per link")
    #: The run settings of a file without [simulation], and of the keys such a table leaves
    #: out (the spatial reader's differ in the method alone).
    SIMULATION_DEFAULTS = Simulation()

    def __init__(self, source: str, default_name: str):
        self.source = source
        self.default_name = default_name
        self.n: int | None = None

    # -- errors ---------------------------------------------------------------------------
    def fail(self, path: str, what: str, value: Any = _MISSING) -> NoReturn:
        message = f"{self.source}: {path}: {what}"
        if value is not _MISSING:
            message += f", got {_show(value)}"
        raise SceneError(message)

    def refuse(self, path: str, refusal: Refusal | None) -> None:
        """Fail at `path` if a rule of a solver request (solver_rules) refuses its value."""
        if refusal is not None:
            self.fail(path, refusal.message)

    def unknown_key(self, path: str, key: str, value: Any, allowed: tuple[str, ...]) -> NoReturn:
        close = difflib.get_close_matches(key, allowed, n=1)
        hint = f"did you mean {close[0]!r}? " if close else ""
        self.fail(
            _key(key) if not path else f"{path}.{_key(key)}",
            f"unknown key ({hint}allowed here: {', '.join(allowed)})",
            value,
        )

    # -- value checks ---------------------------------------------------------------------
    def number(self, path: str, value: Any, meaning: str) -> float:
        """A finite int or float (never a boolean), as float."""
        if not isinstance(value, (int, float)) or isinstance(value, bool):
            self.fail(path, f"must be a number ({meaning}), not {_kind(value)}", value)
        try:
            result = float(value)
        except OverflowError:   # an integer beyond the range of a double
            self.fail(path, f"must be finite ({meaning}), out of the range of a double", value)
        if not math.isfinite(result):
            self.fail(path, f"must be finite ({meaning})", value)
        return result

    def bounded(self, path: str, value: Any, meaning: str) -> float:
        """A number within its key's lower bound (contract.NUMBER_BOUNDS, C's too)."""
        result = self.number(path, value, meaning)
        bound = contract.NUMBER_BOUNDS[path.rsplit(".", 1)[-1]]
        if not bound.admits(result):
            self.fail(path, f"must be {bound.rule} ({meaning})", result)
        return result

    def table(self, path: str, value: Any, header: str) -> dict[str, Any]:
        if not isinstance(value, dict):
            self.fail(path, f"must be a table ({header}), not {_kind(value)}", value)
        return value

    def array_of_tables(self, path: str, value: Any) -> list[Any]:
        """The array itself; each entry is checked with `table` when its turn comes."""
        if not isinstance(value, list):
            self.fail(path, f"must be an array of tables ([[{path}]]), not {_kind(value)}", value)
        return value

    def number_list(self, path: str, value: Any, meaning: str, length: int | None,
                    length_meaning: str) -> tuple[float, ...]:
        if not isinstance(value, list):
            self.fail(path, f"must be an array of numbers ({meaning}), not {_kind(value)}", value)
        if length is not None and len(value) != length:
            self.fail(path, f"must have {_entries(length)} ({length_meaning}), "
                            f"not {len(value)}", value)
        return tuple(self.number(f"{path}[{index}]", item, meaning)
                     for index, item in enumerate(value))

    def name(self, value: Any) -> str:
        if not isinstance(value, str):
            self.fail("name", f"must be a string, not {_kind(value)}", value)
        if not NAME_PATTERN.fullmatch(value):
            self.fail("name", "must start with a letter and contain only letters, digits, "
                              "'_' and '-' (it prefixes generated C names)", value)
        longest = contract.MAX_SCENE_NAME_LENGTH
        if len(value) > longest:
            self.fail("name", f"must be at most {longest} characters long (it prefixes "
                              f"generated C and file names), not {len(value)}")
        return value

    def default_scene_name(self) -> str:
        name = self.default_name
        if NAME_PATTERN.fullmatch(name) and len(name) <= contract.MAX_SCENE_NAME_LENGTH:
            return name
        suggestion = re.sub(r"[^A-Za-z0-9_-]", "_", name)
        if not suggestion[:1].isalpha():
            suggestion = "scene_" + suggestion
        suggestion = suggestion[:contract.MAX_SCENE_NAME_LENGTH]
        self.fail("name", "not set, and the default (the file's stem) is not a valid scene name "
                          "(a letter, then letters, digits, '_' or '-', at most "
                          f"{contract.MAX_SCENE_NAME_LENGTH} in all); set it in the file, "
                          f"e.g. name = {json.dumps(suggestion)}", name)

    # -- sections -------------------------------------------------------------------------
    def read(self, document: dict[str, Any]) -> Scene:
        links_value = document.get("links")
        if isinstance(links_value, list):
            self.n = len(links_value)

        name = _MISSING
        gravity = 9.81
        base_fastening = 0.0
        links: tuple[Link, ...] | None = None
        springs: tuple[Spring, ...] = ()
        angles: tuple[float, ...] | None = None
        velocities: tuple[float, ...] | None = None
        simulation = self.SIMULATION_DEFAULTS
        actuated: tuple[int, ...] = ()
        control_table: Any = _MISSING

        for key, value in document.items():
            if key == "name":
                name = self.name(value)
            elif key == "gravity":
                gravity = self.bounded("gravity", value, "g in m/s^2 along -y; 0 is off")
            elif key == "base":
                base_fastening = self.base(value)
            elif key == "links":
                links = self.links(value)
            elif key == "springs":
                springs = self.springs(value)
            elif key == "actuation":
                actuated = self.actuation(value)
            elif key == "control":
                control_table = self.table("control", value, "[control]")
            elif key == "initial":
                angles, velocities = self.initial(value)
            elif key == "simulation":
                simulation = self.simulation(value)
            else:
                self.unknown_key("", key, value, _TOP_KEYS)

        if name is _MISSING:
            name = self.default_scene_name()
        if links is None:
            self.fail("links", "missing: at least one [[links]] table is required")
        n = len(links)
        control = (None if control_table is _MISSING
                   else self.control(control_table, n, actuated))
        scene = Scene(
            name=name,
            gravity=gravity,
            base_fastening=base_fastening,
            links=links,
            springs=springs,
            initial_angles=angles if angles is not None else (0.0,) * n,
            initial_velocities=velocities if velocities is not None else (0.0,) * n,
            simulation=simulation,
            actuated_joints=actuated,
            control=control,
        )
        # Numbers whose products overflow (overflow.py): the chain's first, as the segments'
        # zero-length limit scales with it; the energies need the segments.
        for check in (overflow.dynamics_overflow, overflow.dynamics_underflow,
                      self.refuse_zero_length_segments, overflow.energy_overflow):
            refused = check(scene)
            if refused is not None:
                self.fail(*refused)
        return scene

    def base(self, value: Any) -> float:
        table = self.table("base", value, "[base]")
        fastening = 0.0
        for key, item in table.items():
            if key == "fastening":
                fastening = self.number("base.fastening", item, "r_1, normal offset in m")
            else:
                self.unknown_key("base", key, item, _BASE_KEYS)
        return fastening

    def links(self, value: Any) -> tuple[Link, ...]:
        tables = self.array_of_tables("links", value)
        if not tables:
            self.fail("links", "at least one link is required", value)
        return tuple(self.link(index, self.table(f"links[{index}]", table, "[[links]]"))
                     for index, table in enumerate(tables))

    def link(self, index: int, table: dict[str, Any]) -> Link:
        path = f"links[{index}]"
        i = index + 1
        known = {field.key: field for field in LINK_FIELDS}
        fields: dict[str, float] = {field.key: field.default for field in LINK_FIELDS
                                    if field.default is not None}
        for key, item in table.items():
            field = known.get(key)
            if field is None:
                self.unknown_key(path, key, item, tuple(known))
            where = f"{path}.{key}"
            if key in contract.NUMBER_BOUNDS:
                fields[key] = self.bounded(where, item, field.meaning(i))
            else:
                fields[key] = self.number(where, item, field.meaning(i))
        for field in LINK_FIELDS:
            if field.key not in fields:
                self.fail(f"{path}.{field.key}", f"missing: required for every link (link {i})")
        return Link(**fields)

    def springs(self, value: Any) -> tuple[Spring, ...]:
        tables = self.array_of_tables("springs", value)
        return tuple(self.spring(index, self.table(f"springs[{index}]", table, "[[springs]]"))
                     for index, table in enumerate(tables))

    def spring(self, index: int, table: dict[str, Any]) -> Spring:
        path = f"springs[{index}]"
        joints: tuple[int, int] | None = None
        stiffness = rest_length = None
        offsets: tuple[float, ...] | None = None
        offsets_raw: Any = None
        for key, item in table.items():
            where = f"{path}.{key}"
            if key == "joints":
                joints = self.spring_joints(where, item)
            elif key == "stiffness":
                stiffness = self.bounded(where, item, "k in N/m")
            elif key == "rest_length":
                rest_length = self.bounded(where, item, "S_0 in m, over all segments")
            elif key == "offsets":
                offsets = self.number_list(where, item, "r of a fastening in m", None, "")
                offsets_raw = item
            else:
                self.unknown_key(path, key, item, _SPRING_KEYS)
        found = {"joints": joints, "stiffness": stiffness, "rest_length": rest_length}
        for key in _SPRING_REQUIRED:
            if found[key] is None:
                self.fail(f"{path}.{key}", "missing: required for every spring")
        first, last = joints
        if offsets is not None and len(offsets) != last - first + 2:
            self.fail(f"{path}.offsets",
                      f"must have {_entries(last - first + 2)}, one per fastening "
                      f"P_{first}..P_{last + 1} passed by joints [{first}, {last}], "
                      f"not {len(offsets)}", offsets_raw)
        return Spring(first=first, last=last, stiffness=stiffness, rest_length=rest_length,
                      offsets=offsets)

    def spring_joints(self, path: str, value: Any) -> tuple[int, int]:
        if (not isinstance(value, list) or len(value) != 2
                or not all(_is_integer(item) for item in value)):
            self.fail(path, "must be an array of two integers [first, last] (1-based joints)",
                      value)
        first, last = value
        if first < 1:
            self.fail(path, f"joint {first} does not exist: joints are numbered from 1", value)
        if first > last:
            self.fail(path, f"first joint {first} is after last joint {last}; "
                            "write [first, last] with first <= last", value)
        if self.n is not None and last > self.n:
            self.fail(path, f"joint {last} does not exist: the chain has {self.n} "
                            f"joint{'s' if self.n != 1 else ''} (1..{self.n})", value)
        return first, last

    def actuation(self, value: Any) -> tuple[int, ...]:
        """[actuation] joints = [...]: 1-based joints with an input torque, ascending, unique."""
        table = self.table("actuation", value, "[actuation]")
        joints: tuple[int, ...] | None = None
        for key, item in table.items():
            where = f"actuation.{key}"
            if key == "joints":
                joints = self.actuated_joints(where, item)
            else:
                self.unknown_key("actuation", key, item, _ACTUATION_KEYS)
        if joints is None:
            self.fail("actuation.joints", "missing: list the actuated joints (1-based), "
                                          "or remove the [actuation] table")
        return joints

    def control(self, table: dict[str, Any], n: int, actuated: tuple[int, ...]) -> Control:
        """[control] (chaingen.scene.control_table)."""
        return read_control(self, table, n, actuated)

    def actuated_joints(self, path: str, value: Any) -> tuple[int, ...]:
        if not isinstance(value, list) or not all(_is_integer(item) for item in value):
            self.fail(path, "must be an array of integers (1-based actuated joints)", value)
        if not value:
            self.fail(path, "must list at least one joint; remove the [actuation] table for "
                            "an unactuated chain", value)
        for index, joint in enumerate(value):
            if joint < 1 or (self.n is not None and joint > self.n):
                chain = (f": the chain has {self.n} joint{'s' if self.n != 1 else ''} "
                         f"(1..{self.n})" if self.n is not None else ": joints are numbered from 1")
                self.fail(f"{path}[{index}]", f"joint {joint} does not exist{chain}", joint)
            if index and joint <= value[index - 1]:
                self.fail(f"{path}[{index}]", "joints must be listed in ascending order, each "
                                              f"once (after joint {value[index - 1]})", joint)
        return tuple(value)

    def initial(self, value: Any) -> tuple[tuple[float, ...] | None, tuple[float, ...] | None]:
        table = self.table("initial", value, "[initial]")
        angles = velocities = None
        for key, item in table.items():
            where = f"initial.{key}"
            angle, rate, count = self.INITIAL_MEANINGS
            if key == "angles":
                angles = self.number_list(where, item, angle, self.n, count)
                if refused := far_angle(where, angles):
                    self.fail(*refused)
            elif key == "velocities":
                velocities = self.number_list(where, item, rate, self.n, count)
            else:
                self.unknown_key("initial", key, item, _INITIAL_KEYS)
        return angles, velocities

    def simulation(self, value: Any) -> Simulation:
        table = self.table("simulation", value, "[simulation]")
        fields: dict[str, Any] = {}
        for key, item in table.items():
            where = f"simulation.{key}"
            if key in REQUEST_KEYS:
                self.refuse(where, request_refusal({key: item}))
                fields[key] = float(item) if key in ADAPTIVE_TOLERANCES else item
            elif key == "dt":
                fields[key] = self.bounded(where, item, "step in s")
            elif key == "t_end":
                fields[key] = self.bounded(where, item, "duration in s")
            else:
                self.unknown_key("simulation", key, item, _SIMULATION_KEYS)
        simulation = dataclasses.replace(self.SIMULATION_DEFAULTS, **fields)
        # The rule between keys (es at order 6 needs K >= 2), after each key's own.
        self.refuse("simulation.quadrature", request_refusal(
            {"method": simulation.method, "quadrature": simulation.quadrature,
             "order": simulation.order}))
        return simulation

    def refuse_zero_length_segments(self, scene: Scene) -> None:
        """Refuse a spring segment of (numerically) zero length at the initial angles.

        model.md section 2: the gradient of s_j = |P_{j+1} - P_j| is undefined at s_j = 0.
        """
        phi = scene.initial_angles
        for index, spring in enumerate(scene.springs):
            geometry = kinematics.spring_geometry(scene, spring, phi)
            tolerance = kinematics.zero_segment_tolerance(scene, spring)
            for j, length in zip(spring.joints, geometry.segment_lengths):
                if length < tolerance:
                    dwarfed = kinematics.dwarfed_by(scene, index, j, float(length), tolerance)
                    if dwarfed is not None:
                        self.fail(*dwarfed)
                    self.fail(f"springs[{index}]",
                              f"segment s_{j} (fastening P_{j} to P_{j + 1}, joint {j}) has zero "
                              "length at the initial configuration (initial.angles), where its "
                              "direction is undefined; move a fastening (offsets) or change "
                              f"the initial angles (limit {tolerance:.3g} m)", float(length))
