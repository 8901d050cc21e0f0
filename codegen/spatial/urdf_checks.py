"""The refusals of `chaingen import` (chaingen.spatial.urdf) that look at one joint of
Pinocchio's model, or at the file before Pinocchio reads it: a joint of another kind than
revolute, one that branches off the chain, limits upside down, an axis Pinocchio could not
normalise, a mimic joint a Pinocchio without `mimic=` would read as an independent one. Each
raises a one-line ChaingenError naming the file, the joint and the URDF key.
"""
from __future__ import annotations

import math
from pathlib import Path
from xml.etree import ElementTree

import numpy as np

from ..errors import ChaingenError

#: Pinocchio's joint models of URDF's revolute and continuous joints (axis along x, y or z, or
#: any other unit vector; bounded, or unbounded with (cos q, sin q) as its configuration).
REVOLUTE_MODELS = frozenset({
    "JointModelRX", "JointModelRY", "JointModelRZ", "JointModelRevoluteUnaligned",
    "JointModelRUBX", "JointModelRUBY", "JointModelRUBZ",
    "JointModelRevoluteUnboundedUnaligned"})

#: What a refused joint is, in URDF's words, by Pinocchio's joint model.
_JOINT_KINDS = {"JointModelPX": "prismatic", "JointModelPY": "prismatic",
                "JointModelPZ": "prismatic", "JointModelPrismaticUnaligned": "prismatic",
                "JointModelFreeFlyer": "floating", "JointModelPlanar": "planar",
                "JointModelSpherical": "spherical", "JointModelSphericalZYX": "spherical",
                "JointModelMimic": "a mimic joint (its angle follows another joint's, which "
                                   "a scene's independent joints cannot say)"}

#: How far from 1 the length of a joint's axis as Pinocchio normalised it may be: its round-off
#: is a few 1e-16; an <axis xyz> Pinocchio could not normalise (shorter than about 1e-154) is
#: off by far more.
AXIS_ROUND_OFF = 1e-12


def check_revolute(model, j: int, shown: str, tip: str) -> None:
    kind = model.joints[j].shortname()
    if kind in REVOLUTE_MODELS:
        return
    what = _JOINT_KINDS.get(kind, f"of Pinocchio's kind {kind}")
    raise ChaingenError(f"{shown}: joint {model.names[j]!r} on the chain to {tip!r} is "
                        f"{what}; chaingen imports revolute and continuous joints only "
                        "(choose a --tip before it)")


def check_no_branch(pin, model, chain: list[int], beyond: set[int], shown: str) -> None:
    """Refuse a moving joint that hangs off a link of the chain and is neither the chain's next
    joint nor beyond the tip: the chain would be a tree."""
    following = dict(zip(chain, chain[1:]))
    for k in range(1, model.njoints):
        parent = model.parents[k]
        if parent not in chain or k == following.get(parent):
            continue
        joint_frame = next(index for index, frame in enumerate(model.frames)
                           if frame.parentJoint == k and frame.type == pin.FrameType.JOINT)
        if joint_frame in beyond:
            continue
        raise ChaingenError(f"{shown}: joint {model.names[k]!r} branches off the chain at "
                            f"joint {model.names[parent]!r}: chaingen imports serial chains "
                            "only (choose a --tip on the branch, or remove it)")


def check_axis(axis: np.ndarray, joint: str, shown: str) -> None:
    """Refuse an axis Pinocchio did not make a unit vector: it divides <axis xyz> by its length,
    computed as the square root of its square, which overflows past a length of about 1e154
    (its axis is then zero, as that of a zero <axis xyz>) and underflows short of about 1e-154
    (it keeps the axis unchanged, and its dynamics scale by it)."""
    length = math.hypot(*(float(value) for value in axis))
    if not math.isfinite(length) or length == 0.0:
        raise ChaingenError(f"{shown}: joint {joint!r} has no axis (Pinocchio holds "
                            f"{_triple(axis)} of its <axis xyz>: zero, or too long to "
                            "normalise): a revolute joint needs a nonzero axis; write it as a "
                            "unit vector")
    if abs(length - 1.0) > AXIS_ROUND_OFF:
        raise ChaingenError(f"{shown}: joint {joint!r}: <axis xyz> too short for Pinocchio to "
                            f"normalise (it holds {_triple(axis)}, of length {length:.6g}): "
                            "write it as a unit vector")


def check_limits(model, j: int, shown: str) -> None:
    """Refuse a revolute joint whose <limit lower> is above its upper (Pinocchio keeps them as
    written): no angle is within them, and the initial angle, their middle, would be outside
    both. A continuous joint has no limits (URDF; Pinocchio ignores its <limit>)."""
    if model.nqs[j] != 1:
        return
    lower = float(model.lowerPositionLimit[model.idx_qs[j]])
    upper = float(model.upperPositionLimit[model.idx_qs[j]])
    if lower > upper:
        raise ChaingenError(f"{shown}: joint {model.names[j]!r}: <limit lower> {lower!r} is "
                            f"above upper {upper!r}: a revolute joint's range needs lower <= "
                            "upper (swap them?)")


def refuse_unseen_mimic(pin, path: Path) -> None:
    """On a Pinocchio without `mimic=` a mimic joint is read as an independent joint (another
    robot): a file that has one is refused (a look for the tag, not a reading of the XML)."""
    try:
        has_mimic = b"<mimic" in path.read_bytes()
    except OSError as error:
        raise ChaingenError(f"{path}: cannot be read: {error.strerror}") from None
    if has_mimic:
        raise ChaingenError(f"{path}: it has a <mimic> joint, and this Pinocchio "
                            f"({getattr(pin, '__version__', 'unknown version')}) cannot read one "
                            "(it would be an independent joint): install pin >= 3.4")


def loop_reason(path: Path) -> str | None:
    """What makes the joints of the URDF at `path` other than a tree (a link that is the child
    of two joints, or joints that close a loop, so no link is the root), or None. Looked for
    before Pinocchio reads the file: on a link that is the child of two joints, Pinocchio 4.1
    either says only that it has no body of some name or (a joint back to a link nearer the
    base) crashes the process with a segmentation fault."""
    try:
        root = ElementTree.parse(path).getroot()
    except (OSError, ElementTree.ParseError):
        return None
    parents: dict[str, list[str]] = {}
    links = {link.get("name") for link in root.findall("link")}
    for joint in root.findall("joint"):
        ends = [joint.find(end) for end in ("parent", "child")]
        names = [end.get("link") if end is not None else None for end in ends]
        if all(name in links for name in names):   # else Pinocchio names the missing link
            parents.setdefault(names[1], []).append(joint.get("name", "?"))
    for link, joints in parents.items():
        if len(joints) > 1:
            return (f"link {link!r} is the child of {len(joints)} joints "
                    f"({', '.join(map(repr, joints))}): a closed loop")
    if links and links <= set(parents):
        return ("every link is the child of a joint, so the joints close a loop and no link "
                "is the root")
    return None


def _triple(values) -> tuple[float, float, float]:
    x, y, z = (float(value) for value in np.asarray(values).ravel())
    return (x, y, z)
