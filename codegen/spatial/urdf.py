"""The serial chain of a robot from its URDF file: what `chaingen import` makes a scene of.

Pinocchio (the `robots` extra, imported here only) parses the file; this module reads its
model, it does not read the XML. Pinocchio has already merged every fixed joint into the
moving body before it, with the fixed link's inertia, and composed the fixed joints' origins
into the next moving joint's placement. What is left to decide is the chain:

- the tip: a link named by the caller, or the single leaf of the tree (a link with no child);
- the joints: those from the root to the tip, each revolute (URDF's `revolute`, or
  `continuous`, taken as revolute without limits); any other kind in the chain (prismatic,
  floating, planar, ...) is refused, naming the joint, and so is a moving joint that branches
  off a link of the chain short of the tip (its links would move the chain);
- the links: the moving body of each joint with the fixed links merged into it, less what lies
  beyond the tip. A fixed link beyond the tip (the Panda's hand behind panda_link8) is part of
  Pinocchio's body of the last joint, with its inertia on its own frame (Frame.inertia, at
  Frame.placement in the joint's frame): that inertia is taken out again. Moving joints beyond
  the tip (the fingers) and their links are left out.

URDF's and our conventions agree (chaingen.spatial.values): a joint's placement is in the
frame of the joint before it, its axis in its own frame, the link's frame is the joint frame
turned by the angle, and the centre of mass and the inertia about it are in the link's frame.
"""
from __future__ import annotations

import argparse
import contextlib
import hashlib
import math
import os
import re
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ChaingenError, SceneError, install_hint
from ..runtime.contract import MAX_SCENE_NAME_LENGTH
from ..runtime.files import check_output_file, reported_write, write_text
from ..scene.reader import NAME_PATTERN
from .reader import parse_spatial_scene
from .urdf_checks import (
    check_axis,
    check_limits,
    check_no_branch,
    check_revolute,
    loop_reason,
    refuse_unseen_mimic,
)
from .values import SpatialJoint, SpatialLink, SpatialScene
from .writer import scene_text

#: The gravity of an imported scene, m/s^2 in the world frame (URDF's z is up).
GRAVITY = (0.0, 0.0, -9.81)

#: The relative round-off of an inertia left after taking the links beyond the tip out of a
#: body, relative to the largest moment about the joint's origin of the parts: below it the
#: inertia about the centre of mass is zero.
INERTIA_ROUND_OFF = 1e-12

@dataclass(frozen=True)
class ImportedChain:
    """A robot's chain as a scene, with the URDF's names of what was kept and left out."""

    scene: SpatialScene
    source: str                         # the URDF's file name (no directory)
    robot: str                          # the URDF's robot name
    root: str                           # the link the chain starts from (the base)
    tip: str                            # the link it ends at
    joints: tuple[str, ...]             # the chain's joints, root to tip
    links: tuple[str, ...]              # the moving link of each joint
    left_out: tuple[str, ...]           # the links beyond the tip, not in the scene

    @property
    def total_mass(self) -> float:
        """kg, of the chain's links (the base's not counted: it does not move)."""
        return sum(link.mass for link in self.scene.links)

    def comment_lines(self) -> tuple[str, ...]:
        """Where the scene came from, for the head of its file."""
        lines = [f"Imported by `chaingen import` from {self.source} (robot {self.robot!r}):",
                 f"the serial chain from {self.root} to {self.tip}, {len(self.joints)} revolute "
                 f"joint{'s' if len(self.joints) > 1 else ''}, each actuated;",
                 "fixed links merged into the link before them with their inertia."]
        if self.left_out:
            lines.append(f"Left out beyond the tip: {', '.join(self.left_out)}.")
        lines += ["Gravity is URDF's -z; no springs (add [[springs]] tables, "
                  "docs/scene-format.md).",
                  "Units: m, kg, kg m^2 (about the centre of mass, link frame), rad, N m s/rad."]
        return tuple(lines)

    def link_comments(self) -> tuple[str, ...]:
        """The URDF's names of each link of the scene and the joint that carries it."""
        return tuple(f"{link} on {joint}" for link, joint in zip(self.links, self.joints))

    def summary(self) -> str:
        """One line for the command line: the scene, its joints, its mass, what was left out."""
        joints = (f"{len(self.joints)} revolute joints ({self.joints[0]} .. {self.joints[-1]})"
                  if len(self.joints) > 1 else f"1 revolute joint ({self.joints[0]})")
        left_out = f"; left out beyond the tip: {', '.join(self.left_out)}" if self.left_out \
            else ""
        return (f"{self.scene.name}, {joints}, {self.total_mass:.6g} kg of links, from "
                f"{self.root} to the tip {self.tip}{left_out}")


def import_urdf(path: str | os.PathLike, tip: str | None = None,
                name: str | None = None) -> SpatialScene:
    """The scene of the serial chain from the root of the URDF at `path` to `tip` (a link's
    name; default: the single leaf). ChaingenError (one line) for what cannot be imported."""
    return import_chain(path, tip=tip, name=name).scene


def import_chain(path: str | os.PathLike, tip: str | None = None,
                 name: str | None = None) -> ImportedChain:
    """import_urdf, with the names of the joints and links kept and of the links left out."""
    path = Path(path)
    if name is not None:
        _check_name(name)
    pin = require_pinocchio()
    model = _load_model(pin, path)
    shown = str(path)        # errors name the file as the user gave it
    tip_frame = _tip_frame(pin, model, tip, shown)
    tip_name = model.frames[tip_frame].name
    chain = _chain(model, model.frames[tip_frame].parentJoint)
    if not chain:
        raise ChaingenError(f"{shown}: no joint between the root and the tip {tip_name!r}: "
                            "give a --tip further out")
    beyond = {index for index in range(len(model.frames))
              if _is_beyond(model, index, tip_frame)}
    for j in chain:
        check_revolute(model, j, shown, tip_name)
        check_limits(model, j, shown)
    check_no_branch(pin, model, chain, beyond, shown)
    links = tuple(_link(pin, model, j, beyond, shown) for j in chain)
    body_names = tuple(_body_name(pin, model, j) for j in chain)
    scene = SpatialScene(
        name=name if name is not None else _default_name(model.name),
        gravity=GRAVITY, links=links, springs=(),
        initial_angles=tuple(_initial_angle(model, j) for j in chain),
        initial_velocities=(0.0,) * len(chain),
        actuated=tuple(range(1, len(chain) + 1)))
    joint_names = tuple(model.names[j] for j in chain)
    _check_readable(scene, body_names, joint_names, shown)
    left_out = tuple(model.frames[index].name for index in sorted(beyond)
                     if model.frames[index].type == pin.FrameType.BODY)
    root = _root_name(pin, model, chain[0])
    return ImportedChain(scene=scene, source=path.name, robot=model.name, root=root, tip=tip_name,
                         joints=joint_names, links=body_names, left_out=left_out)


def _check_readable(scene: SpatialScene, links: tuple[str, ...], joints: tuple[str, ...],
                    shown: str) -> None:
    """Refuse a chain whose scene the scene reader would refuse (an inertia that is no rigid
    body's, a negative damping, ...): its rules are the reader's, asked of the scene's text,
    and the message names the URDF's link and joint."""
    try:
        parse_spatial_scene(scene_text(scene), "<import>")
    except SceneError as error:
        reason = str(error).removeprefix("<import>: ")
        index = re.match(r"links\[(\d+)\]", reason)
        where = (f"link {links[int(index[1])]!r} (joint {joints[int(index[1])]!r}): "
                 if index else "")
        raise ChaingenError(f"{shown}: {where}a scene cannot take it: {reason}") from None


def write_scene(urdf: str | os.PathLike, output: str | os.PathLike, tip: str | None = None,
                name: str | None = None, force: bool = False) -> ImportedChain:
    """Import the chain of `urdf` and write its scene file to `output`, all or nothing; the
    output is checked first as every command's (never the URDF itself, a directory, a link).
    An existing `output` is replaced only when it is an import's output as written (its last
    line, IMPORT_DIGEST, holds the sha256 of the text above it), or with `force`: a scene a
    user wrote, or an import edited since (springs added), is never replaced unasked."""
    check_output_file(output, "-o", [urdf])
    if not force and os.path.lexists(output) and not is_unedited_import(output):
        raise ChaingenError(f"-o: {output} exists and is not a scene chaingen import wrote "
                            "(or it was edited since): give --force to replace it, or another "
                            "file name")
    chain = import_chain(urdf, tip=tip, name=name)
    text = scene_text(chain.scene, comment_lines=chain.comment_lines(),
                      link_comments=chain.link_comments())
    with reported_write(output, "the scene"):
        write_text(output, text + IMPORT_DIGEST.format(_digest(text)) + "\n")
    return chain


#: The last line of a scene `chaingen import` writes: the sha256 of the text above it, which
#: tells an import's unedited output (which a new import may replace) from any other file.
IMPORT_DIGEST = "# chaingen import: sha256 of the lines above {}"
#: Larger files are no import's output (the Panda's is 3 kB): not read to be hashed.
_LARGEST_IMPORT = 1 << 20


def _digest(text: str) -> str:
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def is_unedited_import(path: str | os.PathLike) -> bool:
    """Whether the file at `path` is a scene `chaingen import` wrote, unchanged since."""
    try:
        if os.path.getsize(path) > _LARGEST_IMPORT:
            return False
        text = Path(path).read_text(encoding="utf-8")
    except (OSError, UnicodeError):
        return False
    body, _, last = text.rstrip("\n").rpartition("\n")
    return bool(body) and last == IMPORT_DIGEST.format(_digest(body + "\n"))


# -- the command: `chaingen import ROBOT.urdf -o SCENE.toml [--tip LINK] [--name NAME]` ---------
# Here rather than in cli.py, which test_layout keeps under 500 lines; cli.py registers it.

def add_import_arguments(command: argparse.ArgumentParser) -> None:
    command.add_argument("urdf", type=Path, metavar="ROBOT.urdf", help="the robot's URDF file")
    command.add_argument("-o", "--output", type=Path, required=True, metavar="SCENE.toml",
                         help="the spatial scene to write (docs/importing.md)")
    command.add_argument("--tip", metavar="LINK",
                         help="the chain's last link (default: the single leaf of the tree)")
    command.add_argument("--name", help="the scene's name (default: the robot's)")
    command.add_argument("--force", action="store_true",
                         help="replace SCENE.toml even if it is not an unedited output of "
                              "chaingen import (an input is never replaced)")


def command_import(args) -> int:
    chain = write_scene(args.urdf, args.output, tip=args.tip, name=args.name, force=args.force)
    print(f"wrote {args.output}: {chain.summary()}")
    return 0


def require_pinocchio():
    """The pinocchio module, or a one-line ChaingenError naming the extra that installs it."""
    try:
        import pinocchio
    except ImportError:
        raise ChaingenError("chaingen import needs Pinocchio to read URDF files: install the "
                            f"`robots` extra ({install_hint('robots')})") from None
    return pinocchio


@contextlib.contextmanager
def _stderr_captured() -> Iterator[list[str]]:
    """File descriptor 2 into a list of lines while the block runs: URDF's C++ parser prints its
    complaints there, and a command's error is one line of ours (they become part of it)."""
    lines: list[str] = []
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile(mode="w+b") as capture:
        os.dup2(capture.fileno(), 2)
        try:
            yield lines
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            capture.seek(0)
            lines += capture.read().decode(errors="replace").splitlines()


def _load_model(pin, path: Path):
    """Pinocchio's model of the URDF (fixed base); ChaingenError when there is no such file or
    it is not a URDF Pinocchio reads, with the parser's first complaint, and also when the
    parser complained of an element and read the file without it (urdfdom reads a link whose
    <inertial> it cannot parse, a NaN or a malformed number, as a point mass or as no mass)."""
    if not path.exists():
        raise ChaingenError(f"{path}: no such file")
    if not path.is_file():
        raise ChaingenError(f"{path}: not a file (give a URDF file)")
    loop = loop_reason(path)     # before Pinocchio, which crashes on a loop without a root
    if loop:
        raise ChaingenError(f"{path}: {loop}; chaingen imports serial chains only")
    model, failure = None, ""
    with _stderr_captured() as complaints:
        try:
            # mimic: a mimic joint becomes Pinocchio's JointModelMimic, which check_revolute
            # refuses (without it, Pinocchio makes it an independent revolute joint).
            try:
                model = pin.buildModelFromUrdf(str(path), mimic=True)
            except TypeError:     # a Pinocchio without the keyword (before 3.4)
                refuse_unseen_mimic(pin, path)
                model = pin.buildModelFromUrdf(str(path))
        except (ValueError, RuntimeError) as error:
            failure = str(error).strip()
    details = [line.strip() for line in complaints
               if line.strip() and not line.strip().startswith("at line ")]
    errors = [line.removeprefix("Error:").strip() for line in details
              if line.startswith("Error:")]
    if model is not None:
        if not errors:
            return model
        raise ChaingenError(f"{path}: the URDF parser could not read part of it (and would "
                            f"leave it out): {'; '.join(errors[:2])}")
    reason = details[0].removeprefix("Error:").strip() if details else failure
    raise ChaingenError(f"{path}: not a URDF file Pinocchio can read: {reason}")


def _is_beyond(model, index: int, tip_frame: int) -> bool:
    """Whether frame `index` hangs off the tip's frame (through the frames' parents)."""
    while index != 0:
        parent = model.frames[index].parentFrame
        if parent == tip_frame:
            return True
        if parent == index:
            return False
        index = parent
    return False


def _link_names(pin, model) -> list[str]:
    return [frame.name for frame in model.frames if frame.type == pin.FrameType.BODY]


def _tip_frame(pin, model, tip: str | None, shown: str) -> int:
    """The BODY frame of the tip link: the one named, or the single leaf of the tree."""
    bodies = [index for index, frame in enumerate(model.frames)
              if frame.type == pin.FrameType.BODY]
    if tip is not None:
        found = [index for index in bodies if model.frames[index].name == tip]
        if not found:
            raise ChaingenError(f"{shown}: --tip: no link {tip!r}; its links: "
                                f"{_listed(_link_names(pin, model))}")
        return found[0]
    leaves = [index for index in bodies if model.frames[index].parentJoint != 0
              and not any(_is_beyond(model, other, index) for other in bodies)]
    if len(leaves) != 1:
        what = (f"{len(leaves)} leaves ({_listed(model.frames[i].name for i in leaves)})"
                if leaves else "no link beyond a joint")
        raise ChaingenError(f"{shown}: {what}: choose the chain's tip with --tip LINK")
    return leaves[0]


def _root_name(pin, model, first: int) -> str:
    """The link the chain's first joint hangs from (the base, fixed to the world)."""
    index = next(index for index, frame in enumerate(model.frames)
                 if frame.parentJoint == first and frame.type == pin.FrameType.JOINT)
    while index != 0:
        index = model.frames[index].parentFrame
        if model.frames[index].type == pin.FrameType.BODY:
            return model.frames[index].name
    return model.frames[0].name


def _listed(names, most: int = 20) -> str:
    """Names for a one-line message: the first `most`, then how many more."""
    names = list(names)
    more = f", ... ({len(names) - most} more)" if len(names) > most else ""
    return ", ".join(names[:most]) + more


def _chain(model, last: int) -> list[int]:
    """The joints from the root to joint `last`, in order (0, the world, not included)."""
    chain = []
    while last != 0:
        chain.append(last)
        last = model.parents[last]
    return chain[::-1]


def _body_name(pin, model, j: int) -> str:
    """The URDF link a moving joint carries (its first BODY frame)."""
    return next(frame.name for frame in model.frames
                if frame.parentJoint == j and frame.type == pin.FrameType.BODY)


def _link(pin, model, j: int, beyond: set[int], shown: str) -> SpatialLink:
    """Link j: its joint's placement and axis, the body's inertia less the fixed links beyond
    the tip, and the joint's damping."""
    inertia = model.inertias[j]
    carried = [index for index, frame in enumerate(model.frames)
               if frame.parentJoint == j and _has_inertia(frame)]
    # A guard on where Pinocchio keeps a merged link's inertia: on one frame of it, the fixed
    # joint's (4.1; the moving link's own inertia is on no frame, only in the body's). Were it
    # on the link's BODY frame too, it would be taken out twice below.
    twice = [model.frames[index].name for index in carried
             if model.frames[index].type == pin.FrameType.BODY
             and _has_inertia(model.frames[model.frames[index].parentFrame])]
    if twice:
        raise RuntimeError(f"{shown}: Pinocchio keeps the inertia of {', '.join(twice)} on two "
                           "frames, a layout chaingen import does not know")
    removed = [model.frames[index].placement.act(model.frames[index].inertia)
               for index in carried if index in beyond]
    if removed:
        mass, com, about_com = _less(inertia, removed)
    else:        # Pinocchio's numbers as they are
        mass, com, about_com = inertia.mass, np.array(inertia.lever), np.array(inertia.inertia)
    link = f"link {_body_name(pin, model, j)!r} (joint {model.names[j]!r})"
    placement = model.jointPlacements[j]
    for what, values in (("<inertial> (mass, origin or inertia)",
                          (mass, *np.ravel(com), *np.ravel(about_com))),
                         ("joint's <origin> (composed with the fixed joints' before it)",
                          (*np.ravel(placement.translation), *np.ravel(placement.rotation)))):
        if not all(math.isfinite(float(value)) for value in values):
            raise ChaingenError(f"{shown}: {link}: its {what} is beyond the range of a double in "
                                "Pinocchio's model (it holds inf or nan): write the URDF in SI "
                                "units (m, kg, kg m^2)")
    if not mass > 0.0:
        raise ChaingenError(f"{shown}: {link} has no mass, with the fixed links merged "
                            "into it up to the tip; chaingen needs a mass > 0 for every link")
    data = model.joints[j].createData()
    model.joints[j].calc(data, pin.neutral(model))
    subspace = np.asarray(data.S).ravel()         # (linear, angular) of a unit joint velocity
    axis = subspace[3:]
    check_axis(axis, model.names[j], shown)
    return SpatialLink(
        mass=float(mass), com=_floats(com),
        inertia=tuple(float(about_com[a, b]) for a, b in ((0, 0), (1, 1), (2, 2), (0, 1),
                                                           (0, 2), (1, 2))),
        joint=SpatialJoint(xyz=_floats(placement.translation),
                           rpy=_floats(pin.rpy.matrixToRpy(placement.rotation)),
                           axis=_floats(axis / np.linalg.norm(axis))),
        damping=float(model.damping[model.idx_vs[j]]))


def _has_inertia(frame) -> bool:
    return frame.inertia.mass != 0.0 or bool(np.any(np.asarray(frame.inertia.inertia)))


def _less(inertia, removed) -> tuple[float, np.ndarray, np.ndarray]:
    """Mass, centre of mass and inertia about it of `inertia` less the `removed` ones (all in
    one frame). Mass, first moment and inertia about the frame's origin add; the inertia about
    the centre of mass follows from the parallel-axis theorem."""
    def moments(part):
        mass, com = part.mass, np.array(part.lever)
        return mass, mass * com, np.array(part.inertia) + mass * (com @ com * np.eye(3)
                                                                  - np.outer(com, com))
    mass, first, about_origin = moments(inertia)
    scale = np.abs(about_origin).max()
    for part in removed:
        part_mass, part_first, part_about_origin = moments(part)
        mass, first, about_origin = (mass - part_mass, first - part_first,
                                     about_origin - part_about_origin)
        scale = max(scale, np.abs(part_about_origin).max())
    if not mass > 0.0:
        return mass, np.zeros(3), np.zeros((3, 3))
    com = first / mass
    about_com = about_origin - mass * (com @ com * np.eye(3) - np.outer(com, com))
    # A link whose own inertia is zero (a point mass) keeps the round-off of the moments
    # subtracted, of either sign, which the reader's rules (relative to the tensor's own
    # size) would refuse: within that round-off the tensor is zero.
    if np.abs(about_com).max() <= INERTIA_ROUND_OFF * scale:
        about_com = np.zeros((3, 3))
    return mass, com, about_com


def _initial_angle(model, j: int) -> float:
    """0 where the joint's limits allow it, else the middle of the limits (rad); 0 for a
    continuous joint (Pinocchio's configuration of it is cos q, sin q, without limits)."""
    if model.nqs[j] != 1:
        return 0.0
    lower = float(model.lowerPositionLimit[model.idx_qs[j]])
    upper = float(model.upperPositionLimit[model.idx_qs[j]])
    if lower <= 0.0 <= upper:
        return 0.0
    middle = 0.5 * (lower + upper)
    if not math.isfinite(middle):      # limits of one sign past half a double's range
        middle = lower + 0.5 * (upper - lower)
    return min(max(middle, lower), upper)     # subnormal limits: within them


def _floats(values) -> tuple[float, float, float]:
    x, y, z = (float(value) for value in np.asarray(values).ravel())
    return (x, y, z)


def _check_name(name: str) -> None:
    if not NAME_PATTERN.fullmatch(name) or len(name) > MAX_SCENE_NAME_LENGTH:
        raise ChaingenError(f"--name: must start with a letter and contain only letters, "
                            f"digits, '_' and '-', at most {MAX_SCENE_NAME_LENGTH} in all (it "
                            f"prefixes generated C names), got {name!r}")


def _default_name(robot: str) -> str:
    """The robot's name made a scene name: other characters become '_'."""
    name = re.sub(r"[^A-Za-z0-9_-]", "_", robot)[:MAX_SCENE_NAME_LENGTH] or "robot"
    return name if name[0].isalpha() else ("robot_" + name)[:MAX_SCENE_NAME_LENGTH]
