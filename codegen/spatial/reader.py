"""Reading and validating spatial scene files (docs/scene-format.md, "Spatial scenes").

A spatial scene file is a scene file whose links carry `joint` tables (URDF's origin `xyz`,
`rpy` and `axis`) and whose gravity is a vector; chaingen.scene.reader.spatial_marker tells
the two kinds apart (a joint table or a gravity vector makes a file spatial). The planar
reader's machinery does the work here too (SceneReader: the one-line errors with key paths,
numbers, lists, names, unknown keys with their did-you-mean, [actuation]), so both kinds of
file are read by the same rules and fail in the same words, e.g.
``arm.toml: links[1].joint.axis: must not be zero (axis of joint 2, in its frame), got [0.0,
0.0, 0.0]``.
"""
from __future__ import annotations

import math
import os
import sys
from pathlib import Path
from typing import Any

import numpy as np

from ..scene.kinematics import ZERO_SEGMENT_RELATIVE_TOLERANCE, dwarfed_segment, dwarfing_size
from ..scene.reader import (
    SceneReader,
    parse_scene,
    parse_toml,
    read_scene_text,
    spatial_marker,
)
from . import dynamics
from .values import (
    INERTIA_KEYS,
    SPATIAL_SIMULATION_DEFAULTS,
    RoutePoint,
    SpatialJoint,
    SpatialLink,
    SpatialScene,
    SpatialSpring,
    geometry_underflow,
)

#: Gravity when a spatial scene does not set it: 9.81 m/s^2 along the world's -z (URDF's up is z).
DEFAULT_GRAVITY = (0.0, 0.0, -9.81)

#: A mass matrix is singular when an entry of its diagonal is at most this times the largest,
#: or an eigenvalue of it scaled to a unit diagonal is at most this.
SINGULAR_RELATIVE_TOLERANCE = 1e-12

#: A principal moment of inertia may miss its rules (>= 0, at most the sum of the other two)
#: by this times the tensor's largest entry: the round-off of a tensor written in decimals.
INERTIA_RELATIVE_TOLERANCE = 1e-12

_TOP_KEYS = ("name", "gravity", "links", "springs", "actuation", "control", "initial",
             "simulation")
_LINK_KEYS = ("mass", "com", "inertia", "joint", "damping")
_LINK_REQUIRED = ("mass", "com", "inertia", "joint")
_JOINT_KEYS = ("xyz", "rpy", "axis")
_SPRING_KEYS = ("route", "stiffness", "rest_length")

# Keys of the planar format (by section: "" the top level) that a spatial scene says
# otherwise: the refusal says how.
_PLANAR_KEYS = {
    ("", "base"): "a spring is fastened to the base by a route point on link 0",
    ("links", "length"): "the next link's joint.xyz places joint i + 1 on link i",
    ("links", "com_normal"): "com is the centre of mass's 3-vector in the link's frame",
    ("links", "fastening"): "a spring's route gives the points it passes through",
    ("springs", "joints"): "a spring's route gives the links it passes",
    ("springs", "offsets"): "a spring's route gives the points it passes through",
}


def load_spatial_scene(path: str | os.PathLike[str]) -> SpatialScene:
    """Read and validate the spatial scene file at `path` (a bare name of a shipped scene: its
    file); its default name is the file's stem. A planar scene file is refused, one line."""
    source, text = read_scene_text(path)
    return parse_spatial_scene(text, source, Path(source).stem)


def load_either_scene(path: str | os.PathLike[str]):
    """The scene file at `path`, planar or spatial: its kind told by its keys (spatial_marker:
    a link's `joint` table or a gravity vector), read and validated by that kind's reader."""
    source, text = read_scene_text(path)
    if spatial_marker(parse_toml(text, source)) is None:
        return parse_scene(text, source, Path(source).stem)
    return parse_spatial_scene(text, source, Path(source).stem)


def parse_spatial_scene(text: str, source: str = "<scene>",
                        default_name: str | None = None) -> SpatialScene:
    """Parse and validate spatial scene TOML `text`; errors name `source`, the key path, the
    value and, for text that is not TOML, the line (one line each, as the planar reader's).

    `default_name` (the scene's name when the file sets none) defaults to the stem of `source`.
    """
    document = parse_toml(text, source)
    if default_name is None:
        default_name = Path(source).stem
    return SpatialSceneReader(source, default_name).read(document)


def _plural(count: int, word: str) -> str:
    return f"{count} {word}" if count == 1 else f"{count} {word}s"


class SpatialSceneReader(SceneReader):
    """Validates one parsed spatial scene document; `fail` raises the one-line SceneError."""

    INITIAL_MEANINGS = ("q_i in rad", "qdot_i in rad/s", "one per joint")
    SIMULATION_DEFAULTS = SPATIAL_SIMULATION_DEFAULTS

    def read(self, document: dict[str, Any]) -> SpatialScene:
        """The SpatialScene of a parsed document; the first violation in the file's order of
        keys fails (a planar file as a whole, first)."""
        self.refuse_planar(document)
        links_value = document.get("links")
        if isinstance(links_value, list):
            self.n = len(links_value)

        name: str | None = None
        gravity = DEFAULT_GRAVITY
        links: tuple[SpatialLink, ...] | None = None
        springs: tuple[SpatialSpring, ...] = ()
        angles: tuple[float, ...] | None = None
        velocities: tuple[float, ...] | None = None
        actuated: tuple[int, ...] = ()
        control_table: dict[str, Any] | None = None
        simulation = self.SIMULATION_DEFAULTS

        for key, value in document.items():
            if key == "name":
                name = self.name(value)
            elif key == "gravity":
                gravity = self.vector("gravity", value,
                                      "acceleration of gravity in m/s^2, world frame")
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
                simulation = self.simulation(value)    # the planar table's keys and rules
            else:
                self.unknown_key("", key, value, _TOP_KEYS)

        if name is None:
            name = self.default_scene_name()
        if links is None:
            self.fail("links", "missing: at least one [[links]] table is required")
        n = len(links)
        scene = SpatialScene(
            name=name,
            gravity=gravity,
            links=links,
            springs=springs,
            initial_angles=angles if angles is not None else (0.0,) * n,
            initial_velocities=velocities if velocities is not None else (0.0,) * n,
            actuated=actuated,
            control=(None if control_table is None
                     else self.control(control_table, n, actuated)),
            simulation=simulation,
        )
        if refused := geometry_underflow(scene):   # then the segments' lengths are 0
            self.fail(*refused)
        self.refuse_overflowing_dynamics(scene)     # first: the segments' limit scales with it
        self.refuse_zero_length_segments(scene)
        self.refuse_overflowing_energies(scene)
        return scene

    def refuse_planar(self, document: dict[str, Any]) -> None:
        """A planar scene file (links without joints, a scalar gravity) is refused whole: its
        links would fail one by one for keys it rightly has."""
        links = document.get("links")
        if (spatial_marker(document) is None and isinstance(links, list) and links
                and all(isinstance(link, dict) for link in links)):
            self.fail("links[0].joint", "missing, and no link has a joint: a planar scene "
                      "(or spatial links without their joints); chaingen.scene.load_scene "
                      "reads a planar scene")

    def unknown_key(self, path: str, key: str, value: Any, allowed: tuple[str, ...]):
        hint = _PLANAR_KEYS.get((path.split("[", 1)[0], key))
        if hint is None:
            super().unknown_key(path, key, value, allowed)
        self.fail(key if not path else f"{path}.{key}",
                  f"a key of planar scenes, not of spatial ones: {hint} (allowed here: "
                  f"{', '.join(allowed)})", value)

    # -- value checks ---------------------------------------------------------------------
    def vector(self, path: str, value: Any, meaning: str,
               parts: str = "x, y, z") -> tuple[float, float, float]:
        """Three finite numbers (`parts` names them in a message)."""
        x, y, z = self.number_list(path, value, meaning, 3, parts)
        return x, y, z

    def inertia(self, path: str, value: Any, meaning: str) -> tuple[float, ...]:
        """Six numbers, INERTIA_KEYS' order, of a physically valid inertia tensor: principal
        moments >= 0, each at most the sum of the other two (the triangle inequality of a
        body's moments), within INERTIA_RELATIVE_TOLERANCE of the largest entry."""
        entries = self.number_list(path, value, meaning, len(INERTIA_KEYS),
                                   " ".join(INERTIA_KEYS))
        ixx, iyy, izz, ixy, ixz, iyz = entries
        scale = max(abs(entry) for entry in entries)
        if scale == 0.0:      # a point mass, as a planar link of inertia 0
            return entries
        # Scaled to entries of at most 1, so that no tensor within a double's range overflows.
        tensor = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]]) / scale
        moments = np.linalg.eigvalsh(tensor)
        tolerance = INERTIA_RELATIVE_TOLERANCE
        shown = ", ".join(f"{float(moment) * scale:.6g}" for moment in moments)
        if moments[0] < -tolerance:
            self.fail(path, f"must be a physically valid inertia tensor ({meaning}): its "
                            f"principal moments ({shown}) must be >= 0", value)
        if moments[2] > moments[0] + moments[1] + tolerance:
            self.fail(path, f"must be a physically valid inertia tensor ({meaning}): its "
                            f"largest principal moment must be at most the sum of the other "
                            f"two (principal moments {shown})", value)
        return entries

    # -- sections -------------------------------------------------------------------------
    def link(self, index: int, table: dict[str, Any]) -> SpatialLink:
        path = f"links[{index}]"
        i = index + 1
        fields: dict[str, Any] = {"damping": 0.0}
        for key, item in table.items():
            where = f"{path}.{key}"
            if key == "mass":
                fields[key] = self.bounded(where, item, f"mass in kg, link {i}")
            elif key == "com":
                fields[key] = self.vector(where, item, f"centre of mass in m, link {i}'s frame")
            elif key == "inertia":
                fields[key] = self.inertia(where, item, f"kg m^2 about the centre of mass, "
                                                        f"link {i}'s frame")
            elif key == "joint":
                fields[key] = self.joint(where, item, i)
            elif key == "damping":
                fields[key] = self.bounded(where, item, f"damping in N m s/rad, joint {i}")
            else:
                self.unknown_key(path, key, item, _LINK_KEYS)
        for key in _LINK_REQUIRED:
            if key not in fields:
                self.fail(f"{path}.{key}", f"missing: required for every link of a spatial "
                                           f"scene (link {i})")
        return SpatialLink(**fields)

    def joint(self, path: str, value: Any, i: int) -> SpatialJoint:
        """joint = {xyz, rpy, axis} of joint i: URDF's origin (in link i - 1's frame, link 0
        the base) and axis (in the joint's frame, normalised here as URDF's parsers do)."""
        table = self.table(path, value, "joint = {xyz, rpy, axis}")
        xyz = rpy = axis = None
        for key, item in table.items():
            where = f"{path}.{key}"
            if key == "xyz":
                xyz = self.vector(where, item, f"origin of joint {i} in m, "
                                               f"{'the base' if i == 1 else f'link {i - 1}'}"
                                               "'s frame")
            elif key == "rpy":
                rpy = self.vector(where, item, f"rad, joint {i}'s frame turned about the fixed "
                                               "x, y, z axes", "roll, pitch, yaw")
                self.refuse_degrees(where, rpy)
            elif key == "axis":
                axis = self.axis(where, item, f"axis of joint {i}, in its frame")
            else:
                self.unknown_key(path, key, item, _JOINT_KEYS)
        if axis is None:
            self.fail(f"{path}.axis", f"missing: every joint needs its axis (joint {i})")
        return SpatialJoint(xyz=xyz or (0.0, 0.0, 0.0), rpy=rpy or (0.0, 0.0, 0.0), axis=axis)

    def refuse_degrees(self, path: str, rpy: tuple[float, float, float]) -> None:
        """Refuse an angle of rpy past a full turn: no orientation needs one (each angle within
        [-pi, pi] writes every one), and 90 is a right angle in degrees (MJCF's default unit),
        not in the radians meant here."""
        for k, angle in enumerate(rpy):
            if abs(angle) > 2.0 * math.pi:
                self.fail(f"{path}[{k}]", f"must be within [-2 pi, 2 pi] rad (no orientation "
                          f"needs more than a turn): degrees? {angle!r} deg is "
                          f"{math.radians(angle):.6g} rad", angle)

    def axis(self, path: str, value: Any, meaning: str) -> tuple[float, float, float]:
        x, y, z = self.vector(path, value, meaning)
        norm = math.hypot(x, y, z)    # neither overflows nor underflows
        if norm == 0.0:
            self.fail(path, f"must not be zero ({meaning})", value)
        if abs(norm - 1.0) <= 4 * sys.float_info.epsilon:
            return x, y, z            # a unit axis as written: a written scene reads back exactly
        return x / norm, y / norm, z / norm

    def spring(self, index: int, table: dict[str, Any]) -> SpatialSpring:
        path = f"springs[{index}]"
        found: dict[str, Any] = {}
        for key, item in table.items():
            where = f"{path}.{key}"
            if key == "route":
                found[key] = self.route(where, item)
            elif key == "stiffness":
                found[key] = self.bounded(where, item, "k in N/m")
            elif key == "rest_length":
                found[key] = self.bounded(where, item, "L_0 in m, over all segments")
            else:
                self.unknown_key(path, key, item, _SPRING_KEYS)
        for key in _SPRING_KEYS:
            if key not in found:
                self.fail(f"{path}.{key}", "missing: required for every spring")
        return SpatialSpring(**found)

    def route(self, path: str, value: Any) -> tuple[RoutePoint, ...]:
        """At least two points [link, x, y, z], no two in a row on one link."""
        form = "[link, x, y, z]: a point on link `link` (0 = the base) at x, y, z in m in its frame"
        if not isinstance(value, list):
            self.fail(path, f"must be an array of points {form}", value)
        if len(value) < 2:
            self.fail(path, f"must have at least 2 points {form}, not {len(value)}", value)
        points = []
        for index, item in enumerate(value):
            where = f"{path}[{index}]"
            if not isinstance(item, list) or len(item) != 4:
                self.fail(where, f"must be a point {form}", item)
            link = item[0]
            if not isinstance(link, int) or isinstance(link, bool):
                self.fail(f"{where}[0]", "must be an integer (the link the point is on, 0 = "
                                         "the base)", link)
            if link < 0 or (self.n is not None and link > self.n):
                chain = (f"the chain has {_plural(self.n, 'link')} (1..{self.n}) and the base (0)"
                         if self.n is not None else "links are numbered from 0, the base")
                self.fail(f"{where}[0]", f"link {link} does not exist: {chain}", link)
            if points and link == points[-1].link:
                self.fail(where, f"is on link {link}, as the point before it: a segment "
                                 "between two points of one link has a fixed length and is no "
                                 "spring; leave one of them out", item)
            point = tuple(self.number(f"{where}[{k}]", item[k], f"{axis} in m, link {link}'s "
                                      "frame") for k, axis in ((1, "x"), (2, "y"), (3, "z")))
            points.append(RoutePoint(link=link, point=point))
        return tuple(points)

    def refuse_overflowing_dynamics(self, scene: SpatialScene) -> None:
        """Refuse a chain whose mass matrix or gravity torques at the initial angles are beyond
        the range of a double (finite numbers, but a joint 1e200 m away, or a mass of 1e308 kg
        at 10 m): every step of it would fail on inf or NaN."""
        with np.errstate(over="ignore", invalid="ignore"):
            mass = dynamics.mass_matrix(scene, scene.initial_angles)
            gravity = dynamics.gravity_torques(scene, scene.initial_angles)
        if not (np.all(np.isfinite(mass)) and np.all(np.isfinite(gravity))):
            self.fail("links", "the chain's mass matrix or gravity torques at the initial angles "
                      "are beyond the range of a double (a joint's xyz, a com, a mass or an "
                      "inertia far too large): write the scene in SI units (m, kg, kg m^2)")
        self.refuse_singular_mass_matrix(scene, mass)

    def refuse_overflowing_energies(self, scene: SpatialScene) -> None:
        """Refuse a spring whose energy 1/2 k (L - L_0)^2 at the initial angles, or an initial
        state whose kinetic energy, is beyond the range of a double (a rest length of 1e300 m,
        a rate of 1e160 rad/s), as the planar reader does (scene.overflow)."""
        with np.errstate(over="ignore", invalid="ignore"):
            lengths = dynamics.spring_lengths(scene, scene.initial_angles)
            for index, (spring, length) in enumerate(zip(scene.springs, lengths)):
                stretch = length - spring.rest_length
                if not math.isfinite(0.5 * spring.stiffness * (stretch * stretch)):
                    self.fail(f"springs[{index}]", "its energy 1/2 k (L - L_0)^2 at the "
                              "initial angles is beyond the range of a double (a stiffness or "
                              "a rest length far too large): write the scene in SI units "
                              "(N/m, m)")
            kinetic = dynamics.kinetic_energy(scene, scene.initial_angles,
                                              scene.initial_velocities)
        if not math.isfinite(kinetic):
            self.fail("initial.velocities", "the kinetic energy of the initial state is beyond "
                      "the range of a double: write the rates in rad/s",
                      list(scene.initial_velocities))

    def refuse_singular_mass_matrix(self, scene: SpatialScene, mass: np.ndarray) -> None:
        """Refuse a chain whose mass matrix at the initial angles is singular (within
        SINGULAR_RELATIVE_TOLERANCE): no step can solve for its accelerations. Its diagonal
        entry k is the inertia about joint k's axis of the links it carries, the sum of each
        one's m |a x (c - o)|^2 + a . I a: where every link's share is zero against its own
        inertia about joint k's origin (m |c - o|^2 + trace I), their mass lies on the axis,
        joint k moves none, and it is named; else the matrix scaled to a unit diagonal has a
        zero eigenvalue (joints that move the same masses the same way). Link by link, not
        summed: a 1e12 kg link standing on joint 1's axis does not hide the 1 kg one it turns
        0.1 m off it (it did, summed: 'joint 1 moves no mass')."""
        poses = dynamics.link_poses(scene, scene.initial_angles)
        axes = dynamics.joint_axes(scene, poses)
        with np.errstate(over="ignore", invalid="ignore"):
            coms = [dynamics.point_position(poses, i + 1, link.com)
                    for i, link in enumerate(scene.links)]
            inertias = [poses[i + 1][0] @ np.array(link.inertia_matrix()) @ poses[i + 1][0].T
                        for i, link in enumerate(scene.links)]
            for k in range(scene.n):
                origin, axis = poses[k + 1][1], axes[k]
                moved = False
                for link, com, inertia in zip(scene.links[k:], coms[k:], inertias[k:]):
                    arm = com - origin
                    about_origin = link.mass * float(arm @ arm) + float(np.trace(inertia))
                    lever = np.cross(axis, arm)
                    share = link.mass * float(lever @ lever) + float(axis @ inertia @ axis)
                    moved = moved or not (math.isfinite(about_origin)
                                          and share <= SINGULAR_RELATIVE_TOLERANCE * about_origin)
                if moved:
                    continue
                carried, remedy = ((f"link {k + 1} has", f"give link {k + 1} an inertia "
                                    "about the axis or move its com off it")
                                   if k + 1 == scene.n else
                                   (f"links {k + 1} to {scene.n} have", "give one of them an "
                                    "inertia about the axis or move a com off it"))
                self.fail(f"links[{k}]", f"joint {k + 1} moves no mass: {carried} no inertia "
                          "about its axis (a point mass on it, or a rod along it), so the mass "
                          f"matrix is singular; {remedy}")
        diagonal = np.diag(mass)
        smallest = 0.0
        if np.all(diagonal > 0.0):
            root = np.sqrt(diagonal)      # divided one side at a time: no product overflows
            smallest = float(np.linalg.eigvalsh(mass / root[:, None] / root[None, :])[0])
        if smallest <= SINGULAR_RELATIVE_TOLERANCE:
            self.fail("links", f"the mass matrix at the initial angles is singular (smallest "
                      f"eigenvalue {smallest:.3g} of it scaled to a unit diagonal): joints that "
                      "move the same masses the same way, e.g. two joints on one axis with only "
                      "a point mass on it between them; give that link an inertia or move them "
                      "apart")

    def refuse_zero_length_segments(self, scene: SpatialScene) -> None:
        """Refuse a spring segment of (numerically) zero length at the initial angles, where
        the gradient of its length is undefined (as the planar reader does), and a route whose
        length is beyond a double's range there.

        A segment counts as zero when shorter than ZERO_SEGMENT_RELATIVE_TOLERANCE times the
        size of the geometry: the sum of |xyz| over the joints and of |point| over the route.
        """
        largest = np.finfo(float).max    # a size beyond it: no tolerance of inf
        size = min(largest, sum(math.hypot(*link.joint.xyz) for link in scene.links))
        with np.errstate(over="ignore", invalid="ignore"):
            positions = dynamics.route_positions(scene, scene.initial_angles)
            segments = [np.linalg.norm(np.diff(points, axis=0), axis=1) for points in positions]
        for index, (spring, lengths) in enumerate(zip(scene.springs, segments)):
            if not np.all(np.isfinite(lengths)):
                self.fail(f"springs[{index}].route", "a segment's length at the initial angles "
                          "is beyond the range of a double; write the chain in metres")
            tolerance = ZERO_SEGMENT_RELATIVE_TOLERANCE * min(
                largest, size + sum(math.hypot(*point.point) for point in spring.route))
            for k, length in enumerate(lengths):
                if length < tolerance:
                    self.refuse_dwarfed_segment(scene, index, k, float(length), tolerance)
                if length < tolerance and _zero_at_every_angle(scene, index, k, tolerance):
                    ends = sorted(point.link for point in spring.route[k:k + 2])
                    joints = (f"the axis of joint {ends[1]}" if ends[1] == ends[0] + 1 else
                              f"the axes of joints {ends[0] + 1} to {ends[1]}")
                    self.fail(f"springs[{index}]",
                              f"route[{k}] and route[{k + 1}] are one point at every angle (on "
                              f"{joints}): segment {k + 1} has no length, and its length's "
                              "gradient is undefined; move one of them (limit "
                              f"{tolerance:.3g} m)", [[point.link, *point.point]
                                                      for point in spring.route[k:k + 2]])
                if length < tolerance:
                    self.fail(f"springs[{index}]",
                              f"segment {k + 1} (route[{k}] to route[{k + 1}]) has zero length at "
                              "the initial angles (initial.angles), where its direction is "
                              "undefined; move a route point or change the initial angles "
                              f"(limit {tolerance:.3g} m)", float(length))



    def refuse_dwarfed_segment(self, scene: SpatialScene, index: int, k: int, length: float,
                               tolerance: float) -> None:
        """Fail at the one joint's xyz or route point whose length alone puts segment k of
        spring `index` below the zero-length limit (kinematics.dwarfing_size): a joint 1e150 m
        out, which the segment's own refusal (one point at every angle) would not name."""
        keys = ([(f"links[{i}].joint.xyz", list(link.joint.xyz))
                 for i, link in enumerate(scene.links)]
                + [(f"springs[{index}].route[{j}]", [point.link, *point.point])
                   for j, point in enumerate(scene.springs[index].route)])
        sizes = ([math.hypot(*link.joint.xyz) for link in scene.links]
                 + [math.hypot(*point.point) for point in scene.springs[index].route])
        largest = dwarfing_size(sizes, length)
        if largest is not None:
            key, value = keys[largest]
            self.fail(key, dwarfed_segment(
                key, sizes[largest], f"segment {k + 1} of springs[{index}] (route[{k}] to "
                f"route[{k + 1}])", length, tolerance), value)


def _zero_at_every_angle(scene: SpatialScene, spring: int, segment: int, tolerance: float) -> bool:
    """Whether segment `segment` of spring `spring` is shorter than `tolerance` at two generic
    postures besides the initial one: its points coincide at every angle (both on the axes of
    the joints between them), which no choice of initial angles mends."""
    for shift in (0.7, -1.9):
        q = [angle + shift * (1 + 0.31 * i) for i, angle in enumerate(scene.initial_angles)]
        points = dynamics.route_positions(scene, q)[spring]
        if np.linalg.norm(points[segment + 1] - points[segment]) >= tolerance:
            return False
    return True
