"""`chaingen import` (chaingen.spatial.urdf, issue 33 Build 5 and Must show c): the scene of a
robot's chain from its URDF file against Pinocchio's model of the same chain.

Two independent paths to M(q) and g(q): the imported scene through our numpy dynamics
(chaingen.spatial.dynamics), and Pinocchio's CRBA and generalized gravity on the URDF with the
links beyond the tip deleted from the file (so Pinocchio never has to take a link out again,
which is what the importer does). On the Panda (to panda_link8), the UR5 and the Z1 of
example-robot-data, at 20 configurations each, and on random chains drawn by hypothesis
(skew axes, rpy origins, fixed links merged before and beside moving ones, a hand with a
finger and a slider beyond the tip). Then the writer's exact round trip, the refusals and the
command line.
"""
from __future__ import annotations

import importlib.metadata
import math
import os
import subprocess
import sys
import tomllib
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from test_output_paths import Flag, make_hazard, snapshot
from test_spatial_dynamics import random_scene

from chaingen.spatial import dynamics
from chaingen.spatial.values import (
    RoutePoint,
    SpatialJoint,
    SpatialLink,
    SpatialScene,
    SpatialSpring,
)
from chaingen.spatial.writer import scene_text

from helpers import ROOT, chaingen, chaingen_in_process, require_module

#: (file, tip) of the robots of Must show c; None: the single leaf.
ROBOTS = (("panda_description/urdf/panda.urdf", "panda_link8"),
          ("ur_description/urdf/ur5_robot.urdf", "tool0"),
          ("z1_description/urdf/z1.urdf", None))
CONFIGURATIONS = 20
TOLERANCE = 1e-10


def robot_urdf(relative: str) -> Path:
    """A URDF file the example-robot-data wheel installs (found through its file list)."""
    require_module("pinocchio", "robots")
    try:
        files = importlib.metadata.files("example-robot-data") or []
    except importlib.metadata.PackageNotFoundError:
        files = []
    for file in files:
        if str(file).endswith("example-robot-data/robots/" + relative):
            return Path(file.locate())
    message = f"example-robot-data does not install {relative} (the `robots` extra)"
    if os.environ.get("CHAINGEN_REQUIRE_TOOLS") == "1":
        pytest.fail(message, pytrace=False)
    pytest.skip(message)


def truncated_urdf(source: Path, tip: str | None, out: Path) -> Path:
    """A copy of `source` without the links beyond `tip` and the joints to them (for the
    reference model only: the importer reads the XML only for loops of joints)."""
    tree = ElementTree.parse(source)
    robot = tree.getroot()
    children: dict[str, list[str]] = {}
    for joint in robot.findall("joint"):
        children.setdefault(joint.find("parent").get("link"), []).append(
            joint.find("child").get("link"))
    beyond, todo = set(), list(children.get(tip, [])) if tip else []
    while todo:
        link = todo.pop()
        beyond.add(link)
        todo += children.get(link, [])
    for joint in robot.findall("joint"):
        if joint.find("child").get("link") in beyond:
            robot.remove(joint)
    for link in robot.findall("link"):
        if link.get("name") in beyond:
            robot.remove(link)
    tree.write(out)
    return out


def numpy_dynamics(scene):
    """M(q) and g(q) of a scene by chaingen.spatial.dynamics."""
    return lambda angles: (dynamics.mass_matrix(scene, angles),
                           dynamics.gravity_torques(scene, angles))


def mujoco_dynamics(scene):
    """M(q) (mj_fullM) and g(q) (the bias force at zero velocity) of MuJoCo on the scene's
    MJCF (chaingen.reference.spatial_mjcf)."""
    mujoco = require_module("mujoco", "test")
    from chaingen.reference.spatial_mjcf import spatial_mjcf_from_scene

    model = mujoco.MjModel.from_xml_string(spatial_mjcf_from_scene(scene, dt=1e-3))
    data = mujoco.MjData(model)

    def evaluate(angles):
        data.qpos[:] = angles
        data.qvel[:] = 0.0
        mujoco.mj_forward(model, data)
        mass = np.zeros((model.nv, model.nv))
        try:
            mujoco.mj_fullM(model, data, mass)       # MuJoCo 4
        except TypeError:
            mujoco.mj_fullM(model, mass, data.qM)    # MuJoCo 3
        return mass, data.qfrc_bias.copy()
    return evaluate


def reference_agreement(urdf: Path, tip: str | None, work: Path, samples: int,
                        seed: int, ours=numpy_dynamics) -> tuple[float, float]:
    """The largest differences of M(q) and g(q) between the imported scene (by `ours`, numpy
    dynamics or MuJoCo on its MJCF) and Pinocchio on the truncated URDF, relative to the
    largest entry (or 1), over `samples` random q."""
    pin = require_module("pinocchio", "robots")
    from chaingen.spatial.urdf import import_chain

    chain = import_chain(urdf, tip=tip)
    evaluate = ours(chain.scene)
    model = pin.buildModelFromUrdf(str(truncated_urdf(urdf, tip, work / "reference.urdf")))
    data = model.createData()
    ids = [model.getJointId(name) for name in chain.joints]
    assert sorted(ids) == list(range(1, model.njoints)), (chain.joints, list(model.names))
    order = [model.idx_vs[j] for j in ids]
    rng = np.random.default_rng(seed)
    worst_mass = worst_gravity = 0.0
    for _ in range(samples):
        angles = np.empty(len(ids))
        q = np.empty(model.nq)
        for i, j in enumerate(ids):
            start = model.idx_qs[j]
            if model.nqs[j] == 2:         # continuous: cos, sin
                angles[i] = rng.uniform(-np.pi, np.pi)
                q[start:start + 2] = np.cos(angles[i]), np.sin(angles[i])
            else:
                angles[i] = rng.uniform(model.lowerPositionLimit[start],
                                        model.upperPositionLimit[start])
                q[start] = angles[i]
        mass = pin.crba(model, data, q)
        mass = (np.triu(mass) + np.triu(mass, 1).T)[np.ix_(order, order)]
        gravity = pin.computeGeneralizedGravity(model, data, q)[order]
        our_mass, our_gravity = evaluate(angles)
        worst_mass = max(worst_mass, np.abs(our_mass - mass).max() / max(1.0, np.abs(mass).max()))
        worst_gravity = max(worst_gravity, np.abs(our_gravity - gravity).max()
                            / max(1.0, np.abs(gravity).max()))
    return worst_mass, worst_gravity


@pytest.mark.parametrize("relative, tip", ROBOTS, ids=[r[0].split("/")[-1] for r in ROBOTS])
def test_robots_agree_with_pinocchio(relative, tip, tmp_path):
    """Must show c: M(q) and g(q) of the imported Panda, UR5 and Z1 at 20 configurations
    within the joint limits agree with Pinocchio's to 1e-10."""
    worst_mass, worst_gravity = reference_agreement(robot_urdf(relative), tip, tmp_path,
                                                    CONFIGURATIONS, seed=33)
    assert worst_mass <= TOLERANCE and worst_gravity <= TOLERANCE, (worst_mass, worst_gravity)


@pytest.mark.parametrize("relative, tip", ROBOTS, ids=[r[0].split("/")[-1] for r in ROBOTS])
def test_the_imported_robots_mjcf_gives_mujoco_pinocchios_dynamics(relative, tip, tmp_path):
    """Must show c, its MJCF half: the MJCF written from the imported scene
    (spatial_mjcf_from_scene) gives MuJoCo Pinocchio's M(q) and g(q) at 20 configurations
    within the joint limits, to 1e-10."""
    worst_mass, worst_gravity = reference_agreement(robot_urdf(relative), tip, tmp_path,
                                                    CONFIGURATIONS, seed=34, ours=mujoco_dynamics)
    assert worst_mass <= TOLERANCE and worst_gravity <= TOLERANCE, (worst_mass, worst_gravity)


@pytest.mark.parametrize("tip", ("panda_hand", "panda_link7"))
def test_other_tips_of_the_panda_agree_with_pinocchio(tip, tmp_path):
    """To panda_hand (the hand kept, the fingers left out) and to panda_link7 (link 8 and all
    after it left out): the same agreement at 20 configurations."""
    worst_mass, worst_gravity = reference_agreement(robot_urdf(ROBOTS[0][0]), tip, tmp_path,
                                                    CONFIGURATIONS, seed=7)
    assert worst_mass <= TOLERANCE and worst_gravity <= TOLERANCE, (worst_mass, worst_gravity)


def test_a_tip_past_a_branch_of_the_panda_is_refused():
    """panda_hand_tcp hangs off the hand beside the fingers: they would branch off the chain."""
    require_module("pinocchio", "robots")
    from chaingen.errors import ChaingenError
    from chaingen.spatial.urdf import import_chain

    with pytest.raises(ChaingenError, match="joint 'panda_finger_joint1' branches off the chain "
                                            "at joint 'panda_joint7'"):
        import_chain(robot_urdf(ROBOTS[0][0]), tip="panda_hand_tcp")


def test_panda_to_link8_leaves_out_the_hand_and_keeps_the_rest(tmp_path):
    """The Panda's hand (0.73 kg, merged by Pinocchio into joint 7's body) and fingers are
    left out; the damping of <dynamics> and the limits' rule for the initial angles hold."""
    pin = require_module("pinocchio", "robots")
    from chaingen.spatial.urdf import import_chain

    urdf = robot_urdf(ROBOTS[0][0])
    chain = import_chain(urdf, tip="panda_link8")
    full = pin.buildModelFromUrdf(str(urdf))
    assert chain.joints == tuple(f"panda_joint{i}" for i in range(1, 8))
    assert (chain.root, chain.tip) == ("panda_link0", "panda_link8")
    assert set(chain.left_out) == {"panda_hand", "panda_leftfinger", "panda_rightfinger",
                                   "panda_hand_tcp"}
    hand = full.frames[full.getFrameId("panda_hand_joint")].inertia.mass
    assert hand > 0.5     # it is there to be left out
    assert math.isclose(chain.scene.links[-1].mass,
                        full.inertias[full.getJointId("panda_joint7")].mass - hand,
                        rel_tol=1e-14)
    for i, link in enumerate(chain.scene.links):
        j = full.getJointId(chain.joints[i])
        assert link.damping == full.damping[full.idx_vs[j]] > 0.0
        lower, upper = (full.lowerPositionLimit[full.idx_qs[j]],
                        full.upperPositionLimit[full.idx_qs[j]])
        expected = 0.0 if lower <= 0.0 <= upper else 0.5 * (lower + upper)
        assert chain.scene.initial_angles[i] == expected
    assert chain.scene.initial_angles[3] != 0.0     # panda_joint4's limits exclude 0
    assert chain.scene.actuated == tuple(range(1, 8))
    assert chain.scene.gravity == (0.0, 0.0, -9.81) and chain.scene.springs == ()


def test_the_ur5_has_two_leaves_and_starts_at_its_base_link():
    require_module("pinocchio", "robots")
    from chaingen.errors import ChaingenError
    from chaingen.spatial.urdf import import_chain

    urdf = robot_urdf(ROBOTS[1][0])
    with pytest.raises(ChaingenError, match=r"2 leaves \(ee_link, tool0\): choose the chain's "
                                            "tip with --tip LINK"):
        import_chain(urdf)
    chain = import_chain(urdf, tip="tool0")
    assert (chain.root, chain.joints[0], chain.joints[-1]) == ("base_link", "shoulder_pan_joint",
                                                               "wrist_3_joint")
    assert chain.left_out == () and chain.scene.name == "ur5"


def test_inertia_kept_twice_by_pinocchio_is_caught(monkeypatch):
    """The guard on Pinocchio's layout: were the hand's inertia on its BODY frame as well as on
    its fixed joint's frame, taking it out twice would go unseen; the import stops instead."""
    pin = require_module("pinocchio", "robots")
    from chaingen.spatial import urdf as importer

    load = importer._load_model

    def doubled(pin_module, path):
        model = load(pin_module, path)
        hand = model.frames[model.getFrameId("panda_hand_joint")].inertia
        model.frames[model.getFrameId("panda_hand", pin.FrameType.BODY)].inertia = hand
        return model

    monkeypatch.setattr(importer, "_load_model", doubled)
    with pytest.raises(RuntimeError, match="inertia of panda_hand on two frames"):
        importer.import_chain(robot_urdf(ROBOTS[0][0]), tip="panda_link8")


# -- random chains ----------------------------------------------------------------------------

def _numbers(values) -> str:
    return " ".join(repr(float(value)) for value in values)


def _inertial(rng, mass_scale: float = 1.0) -> str:
    # A rigid body's: point masses' (|r|^2 1 - r r^T), so the principal moments keep the
    # triangle inequality, as the scene reader asks; plus a sphere's 0.01 1.
    points = 0.3 * rng.normal(size=(4, 3))
    inertia = sum(point @ point * np.eye(3) - np.outer(point, point) for point in points) \
        + 0.01 * np.eye(3)
    return (f'<inertial><origin xyz="{_numbers(0.1 * rng.normal(size=3))}" '
            f'rpy="{_numbers(rng.uniform(-np.pi, np.pi, 3))}"/>'
            f'<mass value="{mass_scale * rng.uniform(0.1, 3.0)!r}"/>'
            f'<inertia ixx="{float(inertia[0, 0])!r}" iyy="{float(inertia[1, 1])!r}" '
            f'izz="{float(inertia[2, 2])!r}" ixy="{float(inertia[0, 1])!r}" '
            f'ixz="{float(inertia[0, 2])!r}" iyz="{float(inertia[1, 2])!r}"/>'
            "</inertial>")


def _origin(rng) -> str:
    return (f'<origin xyz="{_numbers(0.3 * rng.normal(size=3))}" '
            f'rpy="{_numbers(rng.uniform(-np.pi, np.pi, 3))}"/>')


def random_chain_urdf(seed: int) -> tuple[str, int]:
    """A robot of 1 to 6 revolute or continuous joints on skew or x/y/z axes, with massive
    fixed links before moving joints and beside the chain, a massive tip link `tip` fixed to
    the last, and beyond it a hand (fixed) with a finger (revolute) and a slider (prismatic).
    Returns the URDF text and the number of chain joints."""
    rng = np.random.default_rng(seed)
    parts = ['<robot name="random">', '<link name="base"/>']

    def joint(name, kind, parent, child, extra=""):
        parts.append(f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
                     f'<child link="{child}"/>{_origin(rng)}{extra}</joint>')

    def link(name, massive=True):
        parts.append(f'<link name="{name}">{_inertial(rng) if massive else ""}</link>')

    parent, n = "base", int(rng.integers(1, 7))
    for i in range(n):
        if rng.random() < 0.4:
            link(f"spacer{i}")
            joint(f"fix{i}", "fixed", parent, f"spacer{i}")
            parent = f"spacer{i}"
        axis = rng.normal(size=3) if rng.random() < 0.6 else np.eye(3)[rng.integers(3)] * \
            rng.choice([-1.0, 1.0])
        axis = axis / np.linalg.norm(axis)
        if rng.random() < 0.3:
            kind, limit = "continuous", ""
        else:
            lower = rng.uniform(-3.0, 1.0)
            kind, limit = "revolute", (f'<limit lower="{lower!r}" upper='
                                       f'"{lower + rng.uniform(0.2, 2.0)!r}" effort="10" '
                                       'velocity="1"/>')
        damping = f'<dynamics damping="{rng.uniform(0.0, 0.5)!r}"/>'
        link(f"link{i}")
        joint(f"joint{i}", kind, parent, f"link{i}",
              f'<axis xyz="{_numbers(axis)}"/>{limit}{damping}')
        parent = f"link{i}"
        if rng.random() < 0.3:
            link(f"beside{i}")
            joint(f"fix_beside{i}", "fixed", parent, f"beside{i}")
    link("tip", massive=bool(rng.random() < 0.5))
    joint("fix_tip", "fixed", parent, "tip")
    link("hand")
    joint("fix_hand", "fixed", "tip", "hand")
    link("finger")
    joint("finger_joint", "revolute", "hand", "finger",
          '<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>')
    link("slider")
    joint("slider_joint", "prismatic", "hand", "slider",
          '<axis xyz="1 0 0"/><limit lower="0" upper="0.1" effort="1" velocity="1"/>')
    parts.append("</robot>")
    return "\n".join(parts), n


@settings(max_examples=30, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1))
def test_random_chains_agree_with_pinocchio(seed, tmp_path_factory):
    """Random robots imported to their tip: M(q) and g(q) as Pinocchio's on the truncated
    file at 5 configurations; the hand's, finger's and slider's links left out."""
    require_module("pinocchio", "robots")
    from chaingen.spatial.urdf import import_chain

    work = tmp_path_factory.mktemp("chain")
    text, n = random_chain_urdf(seed)
    urdf = work / "random.urdf"
    urdf.write_text(text)
    chain = import_chain(urdf, tip="tip")
    assert chain.joints == tuple(f"joint{i}" for i in range(n))
    assert set(chain.left_out) == {"hand", "finger", "slider"}
    worst_mass, worst_gravity = reference_agreement(urdf, "tip", work, 5, seed)
    assert worst_mass <= TOLERANCE and worst_gravity <= TOLERANCE, (worst_mass, worst_gravity)


# -- refusals ---------------------------------------------------------------------------------

def small_urdf(*joints: tuple[str, str, str, str]) -> str:
    """A robot of massive links `base` .. and the joints (name, type, parent, child)."""
    links = {"base"} | {joint[3] for joint in joints}
    inertial = ('<inertial><mass value="1.0"/><inertia ixx="0.1" iyy="0.1" izz="0.1" '
                'ixy="0" ixz="0" iyz="0"/></inertial>')
    text = ['<robot name="small">'] + [f'<link name="{name}">{inertial}</link>'
                                       for name in sorted(links)]
    for name, kind, parent, child in joints:
        limit = ('<limit lower="-1" upper="1" effort="1" velocity="1"/>'
                 if kind in ("revolute", "prismatic") else "")
        text.append(f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
                    f'<child link="{child}"/><axis xyz="0 1 0"/>{limit}</joint>')
    return "\n".join(text + ["</robot>"])


REFUSED = {
    "prismatic in the chain": (
        small_urdf(("shoulder", "revolute", "base", "a"), ("slide", "prismatic", "a", "b"),
                   ("elbow", "revolute", "b", "c")), None,
        "joint 'slide' on the chain to 'c' is prismatic"),
    "floating in the chain": (
        small_urdf(("free", "floating", "base", "a"), ("elbow", "revolute", "a", "b")), None,
        "joint 'free' on the chain to 'b' is floating"),
    "planar in the chain": (
        small_urdf(("shoulder", "revolute", "base", "a"), ("plane", "planar", "a", "b")), None,
        "joint 'plane' on the chain to 'b' is planar"),
    "two leaves": (
        small_urdf(("shoulder", "revolute", "base", "a"), ("left", "revolute", "a", "b"),
                   ("right", "revolute", "a", "c")), None,
        "2 leaves (b, c): choose the chain's tip with --tip LINK"),
    "unknown tip": (
        small_urdf(("shoulder", "revolute", "base", "a")), "hand",
        "--tip: no link 'hand'; its links: base, a"),
    "branch off the chain": (
        small_urdf(("shoulder", "revolute", "base", "a"), ("left", "revolute", "a", "b"),
                   ("right", "revolute", "a", "c"), ("wrist", "revolute", "b", "d")), "d",
        "joint 'right' branches off the chain at joint 'shoulder'"),
    "a link without mass": (
        '<robot name="r"><link name="base"/><link name="a"/><joint name="j" type="continuous">'
        '<parent link="base"/><child link="a"/><axis xyz="0 0 1"/></joint></robot>', None,
        "link 'a' (joint 'j') has no mass"),
    "tip on the base": (
        small_urdf(("shoulder", "revolute", "base", "a")), "base",
        "no joint between the root and the tip 'base'"),
}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_refusals_name_what_is_wrong(case, tmp_path):
    require_module("pinocchio", "robots")
    from chaingen.errors import ChaingenError
    from chaingen.spatial.urdf import import_urdf

    text, tip, expected = REFUSED[case]
    urdf = tmp_path / "robot.urdf"
    urdf.write_text(text)
    with pytest.raises(ChaingenError) as error:
        import_urdf(urdf, tip=tip)
    assert str(error.value).startswith(f"{urdf}: {expected}"), str(error.value)
    assert "\n" not in str(error.value)


def test_continuous_joints_are_revolute_and_fixed_ones_merge(tmp_path):
    """A continuous joint is a revolute one starting at 0; a massive fixed link on the tip's
    side of the chain is merged into its body (the scene's total mass is every link's)."""
    require_module("pinocchio", "robots")
    from chaingen.spatial.urdf import import_chain

    urdf = tmp_path / "robot.urdf"
    urdf.write_text(small_urdf(("turn", "continuous", "base", "a"),
                               ("fix", "fixed", "a", "b"), ("bend", "revolute", "b", "c"),
                               ("fix_tool", "fixed", "c", "tool")))
    chain = import_chain(urdf)
    assert chain.tip == "tool" and chain.joints == ("turn", "bend")
    assert [link.mass for link in chain.scene.links] == [2.0, 2.0]
    assert chain.scene.initial_angles == (0.0, 0.0)
    assert chain.scene.links[0].joint.axis == (0.0, 1.0, 0.0)


# -- the writer -------------------------------------------------------------------------------

def scene_from_toml(text: str) -> SpatialScene:
    """The scene a file in the issue's format holds, read with tomllib alone (the spatial
    reader is not on this branch yet)."""
    data = tomllib.loads(text)

    def vector(values):
        return tuple(values)

    links = tuple(SpatialLink(mass=link["mass"], com=vector(link["com"]),
                              inertia=vector(link["inertia"]),
                              joint=SpatialJoint(xyz=vector(link["joint"]["xyz"]),
                                                 rpy=vector(link["joint"]["rpy"]),
                                                 axis=vector(link["joint"]["axis"])),
                              damping=link["damping"]) for link in data["links"])
    springs = tuple(SpatialSpring(route=tuple(RoutePoint(point[0], vector(point[1:]))
                                              for point in spring["route"]),
                                  stiffness=spring["stiffness"],
                                  rest_length=spring["rest_length"])
                    for spring in data.get("springs", ()))
    return SpatialScene(name=data["name"], gravity=vector(data["gravity"]), links=links,
                        springs=springs, initial_angles=vector(data["initial"]["angles"]),
                        initial_velocities=vector(data["initial"]["velocities"]),
                        actuated=vector(data.get("actuation", {}).get("joints", ())))


def same_bits(a, b) -> bool:
    """Equal as written: every number the same double (the sign of 0.0 too), every int an
    int."""
    if isinstance(a, float) or isinstance(b, float):
        return type(a) is type(b) is float and (a == b and math.copysign(1.0, a)
                                                == math.copysign(1.0, b))
    if isinstance(a, tuple | list):
        return len(a) == len(b) and all(same_bits(x, y) for x, y in zip(a, b))
    if hasattr(a, "__dataclass_fields__"):
        return type(a) is type(b) and all(same_bits(getattr(a, field), getattr(b, field))
                                          for field in a.__dataclass_fields__)
    return type(a) is type(b) and a == b


def exact_floats(scene: SpatialScene) -> SpatialScene:
    """random_scene's numbers as Python floats (it may hold numpy's)."""
    def floats(values):
        return tuple(float(value) for value in values)
    return SpatialScene(
        name=scene.name, gravity=floats(scene.gravity),
        links=tuple(SpatialLink(float(link.mass), floats(link.com), floats(link.inertia),
                                SpatialJoint(floats(link.joint.xyz), floats(link.joint.rpy),
                                             floats(link.joint.axis)), float(link.damping))
                    for link in scene.links),
        springs=tuple(SpatialSpring(tuple(RoutePoint(point.link, floats(point.point))
                                          for point in spring.route),
                                    float(spring.stiffness), float(spring.rest_length))
                      for spring in scene.springs),
        initial_angles=floats(scene.initial_angles),
        initial_velocities=floats(scene.initial_velocities), actuated=scene.actuated)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 7), springs=st.booleans(),
       tiny=st.floats(min_value=5e-324, max_value=1e-300), negative_zero=st.booleans())
def test_writer_round_trip_is_exact(seed, n, springs, tiny, negative_zero):
    """Every number of a random scene (springs through via points, subnormal and -0.0 values,
    some joints actuated) reads back from scene_text with tomllib as the same double."""
    scene = exact_floats(random_scene(seed, n, springs=springs))
    rng = np.random.default_rng(seed)
    first = scene.links[0]
    links = (SpatialLink(tiny, first.com, first.inertia,
                         SpatialJoint((-0.0 if negative_zero else 0.0,) + first.joint.xyz[1:],
                                      first.joint.rpy, first.joint.axis),
                         float(rng.uniform(0.0, 2.0))),) + scene.links[1:]
    scene = SpatialScene(scene.name, scene.gravity, links, scene.springs,
                         tuple(float(x) for x in rng.uniform(-3, 3, n)),
                         tuple(float(x) for x in rng.normal(size=n)),
                         tuple(j for j in range(1, n + 1) if rng.random() < 0.5))
    text = scene_text(scene, comment_lines=("a comment", "over\ntwo lines"))
    assert text.startswith("# a comment\n# over\n# two lines\n")
    assert same_bits(scene_from_toml(text), scene)


def test_writer_refuses_numbers_that_are_not_finite():
    scene = exact_floats(random_scene(1, 2))
    bad = SpatialScene(scene.name, (0.0, 0.0, float("nan")), scene.links, scene.springs,
                       scene.initial_angles, scene.initial_velocities)
    with pytest.raises(ValueError, match="finite"):
        scene_text(bad)


def test_imported_panda_round_trips(tmp_path):
    """The Panda's scene, written and read back: the same scene, bit for bit."""
    require_module("pinocchio", "robots")
    from chaingen.spatial.urdf import import_chain

    urdf = robot_urdf(ROBOTS[0][0])
    chain = import_chain(urdf, tip="panda_link8")
    text = scene_text(chain.scene, chain.comment_lines(), chain.link_comments())
    assert same_bits(scene_from_toml(text), chain.scene)
    assert "from panda.urdf" in text and str(urdf.parent) not in text   # no paths of this machine


@pytest.mark.parametrize("robot, tip", [(robot, tip) for robot, tip, *_ in ROBOTS])
def test_imported_robots_read_back_through_the_scene_reader(robot, tip, tmp_path):
    """What `chaingen import` writes, read by the spatial scene reader: the imported scene,
    bit for bit (names, numbers, actuation, initial state)."""
    require_module("pinocchio", "robots")
    from chaingen.spatial import parse_spatial_scene
    from chaingen.spatial.urdf import import_chain

    chain = import_chain(robot_urdf(robot), tip=tip)
    text = scene_text(chain.scene, chain.comment_lines(), chain.link_comments())
    assert same_bits(parse_spatial_scene(text, source="imported.toml"), chain.scene)


# -- the command line -------------------------------------------------------------------------

def test_cli_writes_the_scene(tmp_path):
    require_module("pinocchio", "robots")
    urdf = robot_urdf(ROBOTS[0][0])
    result = chaingen_in_process("import", urdf, "-o", "panda.toml", "--tip", "panda_link8",
                                 "--name", "panda_arm", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("wrote panda.toml: panda_arm, 7 revolute joints "
                                     "(panda_joint1 .. panda_joint7), 16.0621 kg"), result.stdout
    assert "tip panda_link8" in result.stdout and "panda_hand" in result.stdout
    data = tomllib.loads((tmp_path / "panda.toml").read_text())
    assert data["name"] == "panda_arm" and len(data["links"]) == 7
    assert sorted(path.name for path in tmp_path.iterdir()) == ["panda.toml"]


def test_cli_replaces_an_existing_output_whole_and_never_the_input(tmp_path):
    """An existing file that is not an unedited output of chaingen import (a scene a user
    wrote, an import with springs added) is refused without --force, one line, unchanged; with
    --force it is replaced by rename (the commands' convention, tests/test_output_paths.py),
    and an import's own output is replaced without. The URDF itself, by any spelling, is
    refused even with --force."""
    require_module("pinocchio", "robots")
    from chaingen.spatial.urdf import is_unedited_import

    urdf = tmp_path / "robot.urdf"
    urdf.write_text(small_urdf(("shoulder", "revolute", "base", "a")))
    out = tmp_path / "scene.toml"
    out.write_text("old")
    os.link(out, tmp_path / "other_name")
    before = snapshot(tmp_path)
    result = chaingen_in_process("import", urdf, "-o", out, cwd=tmp_path)
    assert result.returncode == 2 and result.stderr.count("\n") == 1, result
    assert result.stderr.startswith(f"chaingen: error: -o: {out} exists and is not a scene "
                                    "chaingen import wrote (or it was edited since): give "
                                    "--force to replace it"), result.stderr
    assert snapshot(tmp_path) == before
    result = chaingen_in_process("import", urdf, "-o", out, "--force", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert out.read_text().startswith("# Imported by `chaingen import` from robot.urdf")
    assert "base to a, 1 revolute joint, each actuated;" in out.read_text()
    assert (tmp_path / "other_name").read_text() == "old"
    assert is_unedited_import(out) and not is_unedited_import(tmp_path / "other_name")
    # Its own output: replaced without --force, the same bytes.
    written = out.read_bytes()
    result = chaingen_in_process("import", urdf, "-o", out, cwd=tmp_path)
    assert result.returncode == 0 and out.read_bytes() == written, result.stderr
    # Edited (a spring added, or one byte of a number): refused again.
    for edit in (written + b"\n[[springs]]\n", written.replace(b"mass = ", b"mass = 1", 1)):
        out.write_bytes(edit)
        assert not is_unedited_import(out)
        assert chaingen_in_process("import", urdf, "-o", out, cwd=tmp_path).returncode == 2
        assert out.read_bytes() == edit
    before = snapshot(tmp_path)
    for spelling in ("robot.urdf", "./robot.urdf", tmp_path / "robot.urdf"):
        result = chaingen_in_process("import", "robot.urdf", "-o", spelling, "--force",
                                     cwd=tmp_path)
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 2 and len(lines) == 1, (spelling, result.stderr)
        assert snapshot(tmp_path) == before


IMPORT = Flag("import -o", ("import", "robot.urdf", "-o", "TARGET"), "robot.toml",
              ("robot.urdf",))


@pytest.mark.parametrize("hazard", ("input", "hard link to an input", "directory", "fifo",
                                    "symlink to an input", "symlink to a directory",
                                    "dangling symlink", "name too long",
                                    "in a loop of symlinks"))
def test_cli_output_hazards_change_nothing(hazard, tmp_path):
    """import -o against test_output_paths' hazards: exit 2, one line, nothing changed."""
    require_module("pinocchio", "robots")
    (tmp_path / "robot.urdf").write_text(small_urdf(("shoulder", "revolute", "base", "a")))
    target = make_hazard(tmp_path, IMPORT, hazard, "robot.urdf")
    before = snapshot(tmp_path)
    result = chaingen_in_process("import", "robot.urdf", "-o", target, cwd=tmp_path)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1, (hazard, result.stderr)
    assert lines[0].startswith("chaingen: error: -o: ") or hazard in (
        "name too long", "in a loop of symlinks"), lines
    assert snapshot(tmp_path) == before


BAD_INPUTS = {
    "no such file": (None, (), "chaingen: error: missing.urdf: no such file"),
    "not a URDF": ("this is not XML", (),
                   "chaingen: error: robot.urdf: not a URDF file Pinocchio can read: "),
    "a revolute joint without limits": (
        '<robot name="r"><link name="a"/><link name="b"/><joint name="j" type="revolute">'
        '<parent link="a"/><child link="b"/></joint></robot>', (),
        "chaingen: error: robot.urdf: not a URDF file Pinocchio can read: Joint [j] is of "
        "type REVOLUTE but it does not specify limits"),
    "prismatic in the chain": (
        REFUSED["prismatic in the chain"][0], (),
        "chaingen: error: robot.urdf: joint 'slide' on the chain to 'c' is prismatic"),
    "unknown tip": (REFUSED["unknown tip"][0], ("--tip", "hand"),
                    "chaingen: error: robot.urdf: --tip: no link 'hand'"),
    "bad name": (REFUSED["unknown tip"][0], ("--name", "2arm"),
                 "chaingen: error: --name: must start with a letter"),
}


@pytest.mark.parametrize("case", sorted(BAD_INPUTS))
def test_cli_bad_input_is_one_line_exit_2_and_writes_nothing(case, tmp_path):
    """Run as a user runs it (a process: URDF's C++ parser writes to file descriptor 2, and
    only our one line may reach the user)."""
    require_module("pinocchio", "robots")
    text, extra, expected = BAD_INPUTS[case]
    name = "missing.urdf" if text is None else "robot.urdf"
    if text is not None:
        (tmp_path / name).write_text(text)
    before = snapshot(tmp_path)
    result = chaingen("import", name, "-o", "scene.toml", *extra, cwd=tmp_path)
    lines = result.stderr.splitlines()
    assert result.returncode == 2 and len(lines) == 1, (case, result.stderr)
    assert lines[0].startswith(expected), lines[0]
    assert result.stdout == "" and snapshot(tmp_path) == before


def test_cli_without_pinocchio_names_the_extra(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "pinocchio", None)      # import pinocchio: ImportError
    (tmp_path / "robot.urdf").write_text(small_urdf(("shoulder", "revolute", "base", "a")))
    result = chaingen_in_process("import", "robot.urdf", "-o", "scene.toml", cwd=tmp_path)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert "Pinocchio" in lines[0] and "`robots` extra" in lines[0] and ".[robots]" in lines[0]
    assert not (tmp_path / "scene.toml").exists()


def test_the_core_imports_no_pinocchio():
    """Only `chaingen import` imports Pinocchio: the command line, the simulate path and the
    spatial values, dynamics and writer run without the extra."""
    code = ("import sys, chaingen.cli, chaingen.simulation, chaingen.spatial.dynamics, "
            "chaingen.spatial.writer; chaingen.cli.parser(); "
            "print(sorted(m for m in ('pinocchio', 'pin') if m in sys.modules))")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0 and result.stdout.strip() == "[]", result.stderr


def test_shipped_panda_springs_is_the_imported_panda_with_its_springs():
    """scenes/panda_springs.toml: its links are the Panda imported to panda_link8 today, bit
    for bit; its springs are what its head comment says (two mono-articular, one through a
    via point across joints 2 to 4, rest lengths 0.9 of their lengths at the initial posture to
    the millimetre) and none of their segments is short at the initial posture."""
    require_module("pinocchio", "robots")
    from chaingen.spatial.urdf import import_chain

    shipped = scene_from_toml((ROOT / "scenes" / "panda_springs.toml").read_text())
    imported = import_chain(robot_urdf(ROBOTS[0][0]), tip="panda_link8").scene
    assert same_bits(shipped.links, imported.links) and shipped.name == "panda_springs"
    assert [spring.joints for spring in shipped.springs] == [(2,), (4,), (2, 3, 4)]
    assert [len(spring.route) for spring in shipped.springs] == [2, 2, 3]
    lengths = dynamics.spring_lengths(shipped, shipped.initial_angles)
    assert [spring.rest_length for spring in shipped.springs] == \
        [round(0.9 * length, 3) for length in lengths]
    for points in dynamics.route_positions(shipped, shipped.initial_angles):
        assert np.linalg.norm(np.diff(points, axis=0), axis=1).min() > 0.05
