"""Spatial scene files (docs/scene-format.md, "Spatial scenes"): reading, every refusal in its
one line, mutations of good files (hypothesis), the shipped spatial scenes, the planar loader's
refusal of a spatial file (and the command line's), and the spatial form of three_link_multi
against the planar model. Fast: no compiler."""
from __future__ import annotations

import math
import re
import tomllib
from dataclasses import replace
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import sympy as sp
from hypothesis import HealthCheck, event, given, note, settings
from hypothesis import strategies as st
from test_scene_properties import all_paths, at, names_path, render, toml_dumps

from chaingen.errors import SceneError, UnsupportedSceneError
from chaingen.scene import kinematics, load_scene, parse_scene
from chaingen.spatial import (
    RoutePoint,
    SpatialJoint,
    SpatialLink,
    SpatialScene,
    SpatialSpring,
    dynamics,
    load_spatial_scene,
    parse_spatial_scene,
)
from chaingen.spatial.reader import DEFAULT_GRAVITY
from chaingen.symbolic.joint_model import angle_directions, joint_space_potential

from helpers import require_module

ROOT = Path(__file__).resolve().parent.parent
SCENES = ROOT / "scenes"
SOURCE = "scenes/test.toml"

# A valid spatial scene using every key; each bad case below edits one line of it. Link 3 has
# a point mass (inertia 0), its joint's keys out of order; joint 2's axis is not unit length.
VALID = """\
name = "test-arm"
gravity = [0.5, 0.0, -9.81]

[[links]]
mass = 2.0
com = [0.01, 0.02, 0.15]
inertia = [0.0267741, 0.0254607, 0.00414017, -0.000334005, 0.00134851, 0.00562588]
joint = { xyz = [0.0, 0.0, 0.1], rpy = [0.1, 0.2, 0.3], axis = [0.0, 0.0, 2.0] }
damping = 0.1

[[links]]
mass = 1.5
com = [0.12, 0.0, -0.01]
inertia = [0.002, 0.01, 0.011, 0.0, 0.0, 0.0]
joint = { xyz = [0.0, 0.0, 0.3], axis = [0.0, 3.0, 4.0] }

[[links]]
mass = 1
com = [0, 0.1, 0]
inertia = [0, 0, 0, 0, 0, 0]
joint = { axis = [1, 0, 0], rpy = [0.0, -0.2, 0.0], xyz = [0.25, 0.0, 0.0] }

[[springs]]
route = [[0, 0.05, 0.0, 0.05], [1, 0.05, 0.0, 0.2]]
stiffness = 200.0
rest_length = 0.1

[[springs]]
route = [[1, 0.04, 0.03, 0.25], [2, 0.1, 0.04, 0.0], [3, 0.0, 0.15, 0.02]]
stiffness = 50
rest_length = 0

[actuation]
joints = [1, 3]

[initial]
angles = [0.3, -0.4, 0.5]
velocities = [0.0, 0.1, -0.2]
"""

MINIMAL = """\
[[links]]
mass = 1
com = [0, 0, 0.1]
inertia = [0.01, 0.01, 0.01, 0, 0, 0]
joint = { axis = [0, 0, 1] }
"""


def edited(old: str, new: str, text: str = VALID) -> str:
    assert text.count(old) == 1, f"test setup: {old!r} must occur exactly once"
    return text.replace(old, new)


def spatial_error(text: str, source: str = SOURCE) -> str:
    with pytest.raises(SceneError) as caught:
        parse_spatial_scene(text, source)
    message = str(caught.value)
    assert "\n" not in message, message
    return message


# -- good files -------------------------------------------------------------------------------

def test_every_key_is_read():
    scene = parse_spatial_scene(VALID, SOURCE)
    assert scene == SpatialScene(
        name="test-arm",
        gravity=(0.5, 0.0, -9.81),
        links=(
            SpatialLink(mass=2.0, com=(0.01, 0.02, 0.15),
                        inertia=(0.0267741, 0.0254607, 0.00414017, -0.000334005, 0.00134851,
                                 0.00562588),
                        joint=SpatialJoint(xyz=(0.0, 0.0, 0.1), rpy=(0.1, 0.2, 0.3),
                                           axis=(0.0, 0.0, 1.0)),
                        damping=0.1),
            SpatialLink(mass=1.5, com=(0.12, 0.0, -0.01),
                        inertia=(0.002, 0.01, 0.011, 0.0, 0.0, 0.0),
                        joint=SpatialJoint(xyz=(0.0, 0.0, 0.3), rpy=(0.0, 0.0, 0.0),
                                           axis=(0.0, 3.0 / 5.0, 4.0 / 5.0))),
            SpatialLink(mass=1.0, com=(0.0, 0.1, 0.0), inertia=(0.0,) * 6,
                        joint=SpatialJoint(xyz=(0.25, 0.0, 0.0), rpy=(0.0, -0.2, 0.0),
                                           axis=(1.0, 0.0, 0.0))),
        ),
        springs=(
            SpatialSpring(route=(RoutePoint(0, (0.05, 0.0, 0.05)), RoutePoint(1, (0.05, 0.0, 0.2))),
                          stiffness=200.0, rest_length=0.1),
            SpatialSpring(route=(RoutePoint(1, (0.04, 0.03, 0.25)), RoutePoint(2, (0.1, 0.04, 0.0)),
                                 RoutePoint(3, (0.0, 0.15, 0.02))),
                          stiffness=50.0, rest_length=0.0),
        ),
        initial_angles=(0.3, -0.4, 0.5),
        initial_velocities=(0.0, 0.1, -0.2),
        actuated=(1, 3),
    )
    assert all(type(value) is float for value in floats_of(scene))
    assert all(type(point.link) is int for spring in scene.springs for point in spring.route)
    assert scene.springs[0].joints == (1,) and scene.springs[1].joints == (2, 3)


def test_defaults_apply():
    scene = parse_spatial_scene(MINIMAL, "dir/one_link.toml")
    assert scene.name == "one_link"
    assert scene.gravity == DEFAULT_GRAVITY == (0.0, 0.0, -9.81)
    assert scene.links[0].joint == SpatialJoint(xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0),
                                                axis=(0.0, 0.0, 1.0))
    assert scene.links[0].damping == 0.0
    assert scene.springs == () and scene.actuated == ()
    assert scene.initial_angles == (0.0,) and scene.initial_velocities == (0.0,)


def test_a_joint_may_be_its_own_table():
    """[links.joint] below a [[links]] table is the same joint as the inline table."""
    text = MINIMAL.replace("joint = { axis = [0, 0, 1] }\n", "") + \
        "[links.joint]\naxis = [0, 0, 1]\nxyz = [0, 0, 0]\n"
    assert parse_spatial_scene(text, "one_link.toml") == parse_spatial_scene(MINIMAL,
                                                                            "one_link.toml")


def test_load_spatial_scene_uses_the_file_stem_and_finds_shipped_scenes(tmp_path):
    path = tmp_path / "arm_1.toml"
    path.write_text(MINIMAL, encoding="utf-8")
    assert load_spatial_scene(path).name == "arm_1"
    assert load_spatial_scene("spatial_three_link") == load_spatial_scene(
        SCENES / "spatial_three_link.toml")


def test_spatial_three_link_has_what_it_ships_for():
    """Skew axes, off-axis COMs, full tensors, a mono- and a multi-articular spring through a
    via point, a damped and an actuated joint, gravity (scenes/spatial_three_link.toml)."""
    scene = load_spatial_scene(SCENES / "spatial_three_link.toml")
    assert scene.n == 3 and scene.gravity == (0.0, 0.0, -9.81)
    poses = dynamics.link_poses(scene, scene.initial_angles)
    axes = dynamics.joint_axes(scene, poses)
    for i in range(3):
        for j in range(i + 1, 3):
            cosine = abs(axes[i] @ axes[j])
            assert 0.05 < cosine < 0.95, (i, j, cosine)      # neither parallel nor square
    for link in scene.links:
        assert math.hypot(*link.com[:2]) > 0.0 and link.com[2] != 0.0
        assert all(product != 0.0 for product in link.inertia[3:])
    mono, multi = scene.springs
    assert [point.link for point in mono.route] == [0, 1] and mono.joints == (1,)
    assert [point.link for point in multi.route] == [1, 2, 3] and multi.joints == (2, 3)
    assert [link.damping > 0 for link in scene.links] == [False, True, False]
    assert scene.actuated == (3,)
    assert np.all(np.linalg.eigvalsh(dynamics.mass_matrix(scene, scene.initial_angles)) > 0)


# -- refusals, one per rule -------------------------------------------------------------------

REFUSALS = [
    ('mass zero', 'mass = 2.0',
     'mass = 0.0',
     'links[0].mass: must be > 0 (mass in kg, link 1), got 0.0'),
    ('mass not a number', 'mass = 1.5',
     'mass = "heavy"',
     'links[1].mass: must be a number (mass in kg, link 2), not a string, got "heavy"'),
    ('com length', 'com = [0.12, 0.0, -0.01]',
     'com = [0.12, 0.0]',
     'links[1].com: must have 3 entries (x, y, z), not 2, got [0.12, 0.0]'),
    ('com entry', 'com = [0.12, 0.0, -0.01]',
     'com = [0.12, true, -0.01]',
     "links[1].com[1]: must be a number (centre of mass in m, link 2's frame), not a"
     ' boolean, got true'),
    ('inertia length', 'inertia = [0.002, 0.01, 0.011, 0.0, 0.0, 0.0]',
     'inertia = [0.002, 0.01, 0.011]',
     'links[1].inertia: must have 6 entries (ixx iyy izz ixy ixz iyz), not 3, got [0.002,'
     ' 0.01, 0.011]'),
    ('inertia scalar', 'inertia = [0.002, 0.01, 0.011, 0.0, 0.0, 0.0]',
     'inertia = 0.01',
     'links[1].inertia: must be an array of numbers (kg m^2 about the centre of mass,'
     " link 2's frame), not a float, got 0.01"),
    ('inertia negative moment', 'inertia = [0.002, 0.01, 0.011, 0.0, 0.0, 0.0]',
     'inertia = [0.002, 0.01, 0.011, 0.0, 0.0, 0.02]',
     'links[1].inertia: must be a physically valid inertia tensor (kg m^2 about the'
     " centre of mass, link 2's frame): its principal moments (-0.00950625, 0.002,"
     ' 0.0305062) must be >= 0, got [0.002, 0.01, 0.011, 0.0, 0.0, 0.02]'),
    ('inertia triangle', 'inertia = [0.002, 0.01, 0.011, 0.0, 0.0, 0.0]',
     'inertia = [0.002, 0.01, 0.013, 0.0, 0.0, 0.0]',
     'links[1].inertia: must be a physically valid inertia tensor (kg m^2 about the'
     " centre of mass, link 2's frame): its largest principal moment must be at most the"
     ' sum of the other two (principal moments 0.002, 0.01, 0.013), got [0.002, 0.01,'
     ' 0.013, 0.0, 0.0, 0.0]'),
    ('axis zero', 'axis = [0.0, 3.0, 4.0]',
     'axis = [0.0, 0.0, 0.0]',
     'links[1].joint.axis: must not be zero (axis of joint 2, in its frame), got [0.0,'
     ' 0.0, 0.0]'),
    ('axis missing', 'joint = { xyz = [0.0, 0.0, 0.3], axis = [0.0, 3.0, 4.0] }',
     'joint = { xyz = [0.0, 0.0, 0.3] }',
     'links[1].joint.axis: missing: every joint needs its axis (joint 2)'),
    ('joint not a table', 'joint = { xyz = [0.0, 0.0, 0.3], axis = [0.0, 3.0, 4.0] }',
     'joint = [0.0, 3.0, 4.0]',
     'links[1].joint: must be a table (joint = {xyz, rpy, axis}), not an array, got [0.0,'
     ' 3.0, 4.0]'),
    ('joint unknown key', 'joint = { xyz = [0.0, 0.0, 0.3], axis = [0.0, 3.0, 4.0] }',
     'joint = { xyz = [0.0, 0.0, 0.3], axes = [0.0, 3.0, 4.0] }',
     "links[1].joint.axes: unknown key (did you mean 'axis'? allowed here: xyz, rpy,"
     ' axis), got [0.0, 3.0, 4.0]'),
    ('xyz not finite', 'xyz = [0.0, 0.0, 0.3]',
     'xyz = [0.0, nan, 0.3]',
     "links[1].joint.xyz[1]: must be finite (origin of joint 2 in m, link 1's frame), got"
     ' nan'),
    ('link missing joint', 'joint = { xyz = [0.0, 0.0, 0.3], axis = [0.0, 3.0, 4.0] }\n',
     '',
     'links[1].joint: missing: required for every link of a spatial scene (link 2)'),
    ('link missing com', 'com = [0.12, 0.0, -0.01]\n',
     '',
     'links[1].com: missing: required for every link of a spatial scene (link 2)'),
    ('link unknown key', 'damping = 0.1',
     'dampng = 0.1',
     "links[0].dampng: unknown key (did you mean 'damping'? allowed here: mass, com,"
     ' inertia, joint, damping), got 0.1'),
    ('link planar key', 'damping = 0.1',
     'length = 0.3',
     "links[0].length: a key of planar scenes, not of spatial ones: the next link's"
     ' joint.xyz places joint i + 1 on link i (allowed here: mass, com, inertia, joint,'
     ' damping), got 0.3'),
    ('damping negative', 'damping = 0.1',
     'damping = -0.1',
     'links[0].damping: must be >= 0 (damping in N m s/rad, joint 1), got -0.1'),
    ('gravity length', 'gravity = [0.5, 0.0, -9.81]',
     'gravity = [0.5, -9.81]',
     'gravity: must have 3 entries (x, y, z), not 2, got [0.5, -9.81]'),
    ('gravity entry', 'gravity = [0.5, 0.0, -9.81]',
     'gravity = [0.5, 0.0, "down"]',
     'gravity[2]: must be a number (acceleration of gravity in m/s^2, world frame), not a'
     ' string, got "down"'),
    ('simulation dt', '[initial]',
     '[simulation]\ndt = 0.0\n\n[initial]',
     'simulation.dt: must be > 0 (step in s), got 0.0'),
    ('top unknown key', 'name = "test-arm"',
     'name = "test-arm"\ngravty = 1.0',
     "gravty: unknown key (did you mean 'gravity'? allowed here: name, gravity, links,"
     ' springs, actuation, control, initial, simulation), got 1.0'),
    ('name invalid', 'name = "test-arm"',
     'name = "3arm"',
     "name: must start with a letter and contain only letters, digits, '_' and '-' (it"
     ' prefixes generated C names), got "3arm"'),
    ('route one point', 'route = [[0, 0.05, 0.0, 0.05], [1, 0.05, 0.0, 0.2]]',
     'route = [[0, 0.05, 0.0, 0.05]]',
     'springs[0].route: must have at least 2 points [link, x, y, z]: a point on link'
     ' `link` (0 = the base) at x, y, z in m in its frame, not 1, got [[0, 0.05, 0.0,'
     ' 0.05]]'),
    ('route not an array', 'route = [[0, 0.05, 0.0, 0.05], [1, 0.05, 0.0, 0.2]]',
     'route = 1',
     'springs[0].route: must be an array of points [link, x, y, z]: a point on link'
     ' `link` (0 = the base) at x, y, z in m in its frame, got 1'),
    ('route point short', 'route = [[0, 0.05, 0.0, 0.05], [1, 0.05, 0.0, 0.2]]',
     'route = [[0, 0.05, 0.0, 0.05], [1, 0.05, 0.0]]',
     'springs[0].route[1]: must be a point [link, x, y, z]: a point on link `link` (0 ='
     ' the base) at x, y, z in m in its frame, got [1, 0.05, 0.0]'),
    ('route link float', 'route = [[0, 0.05, 0.0, 0.05], [1, 0.05, 0.0, 0.2]]',
     'route = [[0, 0.05, 0.0, 0.05], [1.0, 0.05, 0.0, 0.2]]',
     'springs[0].route[1][0]: must be an integer (the link the point is on, 0 = the'
     ' base), got 1.0'),
    ('route link beyond', '[3, 0.0, 0.15, 0.02]',
     '[4, 0.0, 0.15, 0.02]',
     'springs[1].route[2][0]: link 4 does not exist: the chain has 3 links (1..3) and the'
     ' base (0), got 4'),
    ('route link negative', 'route = [[0, 0.05, 0.0, 0.05], [1, 0.05, 0.0, 0.2]]',
     'route = [[-1, 0.05, 0.0, 0.05], [1, 0.05, 0.0, 0.2]]',
     'springs[0].route[0][0]: link -1 does not exist: the chain has 3 links (1..3) and'
     ' the base (0), got -1'),
    ('route same link', '[2, 0.1, 0.04, 0.0], [3, 0.0, 0.15, 0.02]',
     '[2, 0.1, 0.04, 0.0], [2, 0.0, 0.15, 0.02]',
     'springs[1].route[2]: is on link 2, as the point before it: a segment between two'
     ' points of one link has a fixed length and is no spring; leave one of them out, got'
     ' [2, 0.0, 0.15, 0.02]'),
    ('route coordinate', '[2, 0.1, 0.04, 0.0]',
     '[2, 0.1, "0.04", 0.0]',
     "springs[1].route[1][2]: must be a number (y in m, link 2's frame), not a string,"
     ' got "0.04"'),
    ('stiffness zero', 'stiffness = 200.0',
     'stiffness = 0.0',
     'springs[0].stiffness: must be > 0 (k in N/m), got 0.0'),
    ('rest length negative', 'rest_length = 0.1',
     'rest_length = -0.1',
     'springs[0].rest_length: must be >= 0 (L_0 in m, over all segments), got -0.1'),
    ('spring missing route', 'route = [[0, 0.05, 0.0, 0.05], [1, 0.05, 0.0, 0.2]]\n',
     '',
     'springs[0].route: missing: required for every spring'),
    ('spring planar key', 'route = [[0, 0.05, 0.0, 0.05], [1, 0.05, 0.0, 0.2]]',
     'joints = [1, 1]',
     "springs[0].joints: a key of planar scenes, not of spatial ones: a spring's route"
     ' gives the links it passes (allowed here: route, stiffness, rest_length), got [1, 1]'),
    ('zero segment', 'route = [[0, 0.05, 0.0, 0.05], [1, 0.05, 0.0, 0.2]]',
     'route = [[0, 0.0, 0.0, 0.1], [1, 0.0, 0.0, 0.0]]',
     'springs[0]: route[0] and route[1] are one point at every angle (on the axis of joint'
     " 1): segment 1 has no length, and its length's gradient is undefined; move one of them"
     ' (limit 7.5e-10 m), got [[0, 0.0, 0.0, 0.1], [1, 0.0, 0.0, 0.0]]'),
    ('angles count', 'angles = [0.3, -0.4, 0.5]',
     'angles = [0.3, -0.4]',
     'initial.angles: must have 3 entries (one per joint), not 2, got [0.3, -0.4]'),
    ('velocities count', 'velocities = [0.0, 0.1, -0.2]',
     'velocities = [0.0, 0.1, -0.2, 0.0]',
     'initial.velocities: must have 3 entries (one per joint), not 4, got [0.0, 0.1,'
     ' -0.2, 0.0]'),
    ('initial unknown key', 'angles = [0.3, -0.4, 0.5]',
     'angle = [0.3, -0.4, 0.5]',
     "initial.angle: unknown key (did you mean 'angles'? allowed here: angles,"
     ' velocities), got [0.3, -0.4, 0.5]'),
    ('actuation order', 'joints = [1, 3]',
     'joints = [3, 1]',
     'actuation.joints[1]: joints must be listed in ascending order, each once (after'
     ' joint 3), got 1'),
    ('actuation beyond', 'joints = [1, 3]',
     'joints = [1, 4]',
     'actuation.joints[1]: joint 4 does not exist: the chain has 3 joints (1..3), got 4'),
    ('planar key base', 'velocities = [0.0, 0.1, -0.2]\n',
     'velocities = [0.0, 0.1, -0.2]\n\n[base]\nfastening = 0.1\n',
     'base: a key of planar scenes, not of spatial ones: a spring is fastened to the base'
     ' by a route point on link 0 (allowed here: name, gravity, links, springs,'
     ' actuation, control, initial, simulation), got {fastening = 0.1}'),
    ('rpy length', 'rpy = [0.1, 0.2, 0.3]',
     'rpy = [0.1, 0.2]',
     'links[0].joint.rpy: must have 3 entries (roll, pitch, yaw), not 2, got [0.1, 0.2]'),
]


@pytest.mark.parametrize("old, new, expected", [case[1:] for case in REFUSALS],
                         ids=[case[0] for case in REFUSALS])
def test_each_rule_refuses_in_one_line(old, new, expected):
    assert spatial_error(edited(old, new)) == f"{SOURCE}: {expected}"


def test_links_missing_or_empty():
    assert spatial_error('name = "a"\n') == f"{SOURCE}: links: missing: at least one [[links]] " \
                                             "table is required"
    assert spatial_error("gravity = [0, 0, -1]\nlinks = []\n") == \
        f"{SOURCE}: links: at least one link is required, got []"


@pytest.mark.parametrize("literal", ["nan", "inf", "-inf"])
def test_non_finite_numbers_are_refused(literal):
    message = spatial_error(edited("mass = 1.5", f"mass = {literal}"))
    assert message == f"{SOURCE}: links[1].mass: must be finite (mass in kg, link 2), got {literal}"


def test_a_number_beyond_a_double_is_refused():
    message = spatial_error(edited("stiffness = 50", "stiffness = " + "9" * 400))
    assert message.startswith(f"{SOURCE}: springs[1].stiffness: must be finite (k in N/m), out "
                              "of the range of a double, got 999")


def test_a_segment_beyond_a_double_is_refused():
    text = edited("route = [[0, 0.05, 0.0, 0.05], [1, 0.05, 0.0, 0.2]]",
                  "route = [[0, 1e308, 0.0, 0.0], [1, -1e308, 0.0, 0.0]]")
    assert spatial_error(text) == (
        f"{SOURCE}: springs[0].route: a segment's length at the initial angles is beyond the "
        "range of a double; write the chain in metres")


def test_an_inertia_tensor_at_its_limits_is_accepted():
    """A rod (one moment zero, the others equal) and a lamina (Izz = Ixx + Iyy), turned so that
    their products of inertia are not zero: the limits hold within round-off."""
    rotation = dynamics.rpy_matrix((0.3, -0.7, 1.1))
    for moments in ((0.0, 2.0, 2.0), (0.5, 0.75, 1.25)):
        tensor = rotation @ np.diag(moments) @ rotation.T
        entries = [tensor[0, 0], tensor[1, 1], tensor[2, 2], tensor[0, 1], tensor[0, 2],
                   tensor[1, 2]]
        text = edited("inertia = [0.002, 0.01, 0.011, 0.0, 0.0, 0.0]",
                      f"inertia = [{', '.join(repr(float(e)) for e in entries)}]")
        assert parse_spatial_scene(text, SOURCE).links[1].inertia == tuple(entries)


def test_a_huge_inertia_tensor_is_checked_without_overflow():
    """The check scales the tensor first: moments near a double's limit are compared, not
    summed to inf (and no overflow warning, which the tests turn into errors). Such a tensor
    is a rigid body's, but the chain's mass matrix overflows: that is the refusal."""
    old = "inertia = [0.002, 0.01, 0.011, 0.0, 0.0, 0.0]"
    message = spatial_error(edited(old, "inertia = [1e308, 1e308, 1.5e308, 0, 0, 0]"))
    assert message.startswith(f"{SOURCE}: links: the chain's mass matrix or gravity torques at "
                              "the initial angles are beyond the range of a double"), message
    scene = parse_spatial_scene(edited(old, "inertia = [1e307, 1e307, 1.5e307, 0, 0, 0]"), SOURCE)
    assert scene.links[1].inertia == (1e307, 1e307, 1.5e307, 0.0, 0.0, 0.0)
    message = spatial_error(edited(old, "inertia = [1e308, 1e308, 1e308, 1e308, 0.0, 0.0]"))
    assert message.startswith(
        f"{SOURCE}: links[1].inertia: must be a physically valid inertia tensor (kg m^2 about "
        "the centre of mass, link 2's frame): its largest principal moment must be at most the "
        "sum of the other two (principal moments 0, 1e+308, ")


def test_first_error_in_file_order_is_reported():
    text = edited("mass = 1.5", "mass = -1", edited("stiffness = 50", "stiffness = -1"))
    assert spatial_error(text).startswith(f"{SOURCE}: links[1].mass: ")


def test_route_and_actuation_are_checked_against_links_that_come_later():
    text = ("[actuation]\njoints = [2]\n\n[[springs]]\nroute = [[0, 0, 0, 0], [2, 0, 0, 0]]\n"
            "stiffness = 1\nrest_length = 0\n\n" + MINIMAL)
    assert spatial_error(text) == f"{SOURCE}: actuation.joints[0]: joint 2 does not exist: the " \
                                  "chain has 1 joint (1..1), got 2"
    text = text.replace("joints = [2]", "joints = [1]")
    assert spatial_error(text) == f"{SOURCE}: springs[0].route[1][0]: link 2 does not exist: " \
                                  "the chain has 1 link (1..1) and the base (0), got 2"


def test_zero_segment_only_at_the_initial_angles_is_refused():
    """Route points that meet at one posture only: refused when the chain starts there."""
    text = MINIMAL + ("[[springs]]\nroute = [[0, 0.1, 0, 0], [1, 0.1, 0, 0]]\nstiffness = 1\n"
                      "rest_length = 0\n[initial]\nangles = [0.5]\n")
    scene = parse_spatial_scene(text, SOURCE)
    assert dynamics.spring_lengths(scene, [0.0]) == [0.0]
    assert spatial_error(text.replace("angles = [0.5]", "angles = [0.0]")) == (
        f"{SOURCE}: springs[0]: segment 1 (route[0] to route[1]) has zero length at the initial "
        "angles (initial.angles), where its direction is undefined; move a route point or change "
        "the initial angles (limit 2e-10 m), got 0.0")


@pytest.mark.parametrize("offset", ["1e150", "1e100"])
def test_a_joint_offset_that_dwarfs_a_spring_is_named_with_the_reason(offset):
    """Link 3's joint 1e150 m out makes the geometry's size G, and so the zero-length limit
    1e-9 G, dwarf spring 0's segment of 0.307 m, which joins the base and link 1 and does not
    involve that joint. The refusal said 'route[0] and route[1] are one point at every angle
    (on the axis of joint 1) ... (limit 1e+141 m)', which they are not; it names the joint's
    xyz and the real reason now."""
    text = (SCENES / "spatial_three_link.toml").read_text()
    old = "xyz = [0.3, 0.0, 0.0]"
    assert text.count(old) == 1
    message = spatial_error(text.replace(old, f"xyz = [{offset}, 0.0, 0.0]"))
    limit = f"{1e-9 * (float(offset) + 0.1 + math.hypot(0.02, 0.35)):.3g}"
    assert message == (
        f"{SOURCE}: links[2].joint.xyz: {float(offset):.3g} m dwarfs segment 1 of springs[0] "
        "(route[0] to route[1]), 0.307 m long at the initial angles: it makes the geometry's "
        f"size G so large that the segment is below 1e-9 G = {limit} m, where a segment counts "
        "as zero length (and a run stops below 1e-6 G); every segment must be at least 1e-9 of "
        "the geometry's size: write links[2].joint.xyz in metres, got "
        f"[{float(offset)!r}, 0.0, 0.0]")


def test_toml_syntax_error_names_the_line():
    assert spatial_error("gravity = [0, 0,\n\n[[links]]\n").startswith(f"{SOURCE}:3: TOML "
                                                                        "syntax error: ")


def test_unreadable_file_is_a_scene_error(tmp_path):
    with pytest.raises(SceneError) as caught:
        load_spatial_scene(tmp_path / "none.toml")
    assert str(caught.value).startswith(f"{tmp_path / 'none.toml'}: cannot read scene file: ")


# -- planar and spatial files, each to the other's loader --------------------------------------

PLANAR_REFUSAL = ("links[0].joint: missing, and no link has a joint: a planar scene (or spatial "
                  "links without their joints); chaingen.scene.load_scene reads a planar scene")


@pytest.mark.parametrize("stem", ["three_link_multi", "four_link_actuated"])
def test_a_planar_file_is_refused_by_the_spatial_loader(stem):
    path = SCENES / f"{stem}.toml"
    with pytest.raises(SceneError) as caught:
        load_spatial_scene(path)
    assert str(caught.value) == f"{path}: {PLANAR_REFUSAL}"


def spatial_refusal(marker: str, source: str = SOURCE) -> str:
    return (f"{source}: {marker}: a spatial scene (scene-format.md, \"Spatial scenes\"), which "
            "the bench and the other planar-only readers do not take yet; read it with "
            "chaingen.spatial.load_spatial_scene")


@pytest.mark.parametrize("text, marker", [
    (VALID, "gravity"),
    (MINIMAL, "links[0].joint"),
    (edited("gravity = [0.5, 0.0, -9.81]", "gravity = 9.81"), "links[0].joint"),
    # planar links with one joint among them, and a gravity vector after the links
    ("[[links]]\nmass = 1\ninertia = 0\nlength = 1\ncom = 0.5\n"
     "[[links]]\nmass = 1\ninertia = 0\nlength = 1\ncom = 0.5\njoint = {axis = [0, 0, 1]}\n",
     "links[1].joint"),
    ("links = [{mass = 1}]\ngravity = [0, 0, -1]\n", "gravity"),
])
def test_a_spatial_file_is_refused_by_the_planar_loader(text, marker):
    """Not a half-valid Scene: one line naming the key that makes the file spatial, an error
    that is both a SceneError (a file the planar loader cannot use) and an
    UnsupportedSceneError (a scene the planar-only features do not take yet)."""
    with pytest.raises(UnsupportedSceneError) as caught:
        parse_scene(text, SOURCE, "test")
    assert isinstance(caught.value, SceneError)
    assert str(caught.value) == spatial_refusal(marker)


def test_load_scene_refuses_the_shipped_spatial_scenes():
    for stem in ("spatial_three_link", "spatial_three_link_multi_planar"):
        path = SCENES / f"{stem}.toml"
        with pytest.raises(UnsupportedSceneError) as caught:
            load_scene(path)
        assert str(caught.value) == spatial_refusal("gravity", str(path))


# -- three_link_multi as a spatial scene --------------------------------------------------------

@cache
def planar_potential_gradients():
    """dV_g/dphi and dV_s/dphi of the planar three_link_multi, by SymPy from the planar
    model's potential (chaingen.symbolic.joint_model): a path independent of
    chaingen.spatial.dynamics."""
    scene = load_scene(SCENES / "three_link_multi.toml")
    phi = sp.symbols("phi1:4")
    directions = angle_directions(phi)
    gradients = []
    for part in (replace(scene, springs=()), replace(scene, gravity=0.0)):
        potential = joint_space_potential(part, directions)
        gradients.append(sp.lambdify(phi, [sp.diff(potential, p) for p in phi], "numpy"))
    return scene, gradients


@settings(max_examples=25, deadline=None, derandomize=True, database=None)
@given(angles=st.lists(st.floats(-math.pi, math.pi), min_size=3, max_size=3))
def test_spatial_three_link_multi_planar_is_three_link_multi(angles):
    """The mass matrix, gravity and spring torques, spring length and potential of the spatial
    scene equal the planar model's at random angles (issue 33, must-show b's premise)."""
    planar, (gravity_gradient, spring_gradient) = planar_potential_gradients()
    spatial = load_spatial_scene(SCENES / "spatial_three_link_multi_planar.toml")
    q = np.array(angles)
    assert spatial.initial_angles == planar.initial_angles
    assert spatial.initial_velocities == planar.initial_velocities
    np.testing.assert_allclose(dynamics.mass_matrix(spatial, q),
                               kinematics.mass_matrix(planar, q), rtol=0, atol=1e-12)
    np.testing.assert_allclose(dynamics.gravity_torques(spatial, q), gravity_gradient(*q),
                               rtol=0, atol=1e-12)
    np.testing.assert_allclose(dynamics.spring_torques(spatial, q), spring_gradient(*q),
                               rtol=0, atol=1e-12)
    (length,) = dynamics.spring_lengths(spatial, q)
    planar_length = kinematics.spring_geometry(planar, planar.springs[0], q).total_length
    assert abs(length - planar_length) <= 1e-12
    assert abs(dynamics.potential_energy(spatial, q) - kinematics.potential_energy(planar, q)) \
        <= 1e-12


# -- mutations of good files (hypothesis) -------------------------------------------------------

SEEDS = {"VALID": VALID, "MINIMAL": MINIMAL,
         **{stem: (SCENES / f"{stem}.toml").read_text(encoding="utf-8")
            for stem in ("spatial_three_link", "spatial_three_link_multi_planar")}}

REQUIRED = {"links": ("mass", "com", "inertia", "joint"), "springs": ("route", "stiffness",
                                                                      "rest_length")}


def floats_of(scene: SpatialScene) -> list[Any]:
    values = [*scene.gravity, *scene.initial_angles, *scene.initial_velocities]
    for link in scene.links:
        values += [link.mass, *link.com, *link.inertia, *link.joint.xyz, *link.joint.rpy,
                   *link.joint.axis, link.damping]
    for spring in scene.springs:
        values += [spring.stiffness, spring.rest_length]
        values += [x for point in spring.route for x in point.point]
    return values


def check_invariants(scene: SpatialScene) -> None:
    n = scene.n
    assert n >= 1 and len(scene.initial_angles) == n == len(scene.initial_velocities)
    assert all(type(value) is float and math.isfinite(value) for value in floats_of(scene))
    for link in scene.links:
        assert link.mass > 0 and link.damping >= 0
        assert abs(math.hypot(*link.joint.axis) - 1.0) < 1e-15
        scale = max(map(abs, link.inertia)) or 1.0
        moments = np.linalg.eigvalsh(np.array(link.inertia_matrix()) / scale)
        assert moments[0] >= -1e-12 and moments[2] <= moments[0] + moments[1] + 1e-12
    for spring in scene.springs:
        assert spring.stiffness > 0 and spring.rest_length >= 0 and len(spring.route) >= 2
        links = [point.link for point in spring.route]
        assert all(type(link) is int and 0 <= link <= n for link in links)
        assert all(a != b for a, b in zip(links, links[1:]))
    assert list(scene.actuated) == sorted(set(scene.actuated))
    assert all(1 <= joint <= n for joint in scene.actuated)


def error_paths(document: dict[str, Any]) -> list[tuple]:
    """Every key path an error about `document` may name: its own, missing required keys, a
    missing axis, and links[0].joint for a file without joints."""
    paths = all_paths(document) + [("name",), ("links",), ("actuation", "joints"),
                                   ("links", 0, "joint")]
    for section, required in REQUIRED.items():
        tables = document.get(section)
        if isinstance(tables, list):
            paths += [(section, index, key) for index in range(len(tables)) for key in required]
    links = document.get("links")
    if isinstance(links, list):
        paths += [("links", index, "joint", "axis") for index in range(len(links))]
    return paths


VALUES = st.one_of(
    st.booleans(), st.integers(-5, 5), st.integers(), st.floats(),
    st.sampled_from([0.0, -0.0, -1.0, 1e-300, 1e308, 10 ** 400]),
    st.text(max_size=5), st.lists(st.floats(-2, 2), max_size=7),
    st.lists(st.lists(st.integers(-1, 4) | st.floats(-1, 1), max_size=5), max_size=4),
    st.dictionaries(st.sampled_from(["xyz", "rpy", "axis", "axes", "mass"]),
                    st.lists(st.floats(-1, 1), max_size=4), max_size=3),
)


def mutated(data, document: dict[str, Any]) -> str:
    """One edit of a random place: delete it, set a value of a random type or range, add an
    unknown key to a table, or drop or repeat a list's entry; what was done, for the note."""
    paths = all_paths(document)
    if not paths:
        return "nothing left to edit"
    path = data.draw(st.sampled_from(paths), label="path")
    parent, last = at(document, path[:-1]), path[-1]
    action = data.draw(st.sampled_from(["delete", "set", "unknown", "resize"]), label="action")
    if action == "unknown" and isinstance(at(document, path), dict):
        at(document, path)[data.draw(st.sampled_from(["lenght", "joints", "base", "x"]))] = 1.0
    elif action == "resize" and isinstance(at(document, path), list) and at(document, path):
        items = at(document, path)
        if data.draw(st.booleans(), label="drop"):
            items.pop()
        else:
            items.append(items[-1])
    elif action == "delete":
        del parent[last]
    else:
        parent[last] = data.draw(VALUES, label="value")
    return f"{action} {render(path)}"


@settings(max_examples=400, deadline=None, derandomize=True, database=None,
          suppress_health_check=[HealthCheck.too_slow])
@pytest.mark.heavy
@given(seed=st.sampled_from(sorted(SEEDS)), data=st.data())
def test_mutations_load_or_raise_a_scene_error_naming_a_key_path(seed, data):
    """Every mutation of a good file loads (to a scene that keeps the format's rules) or
    raises a one-line SceneError that starts with the file and names a key path of the
    document; never another exception."""
    document = tomllib.loads(SEEDS[seed])
    for _ in range(data.draw(st.integers(1, 3), label="edits")):
        note(mutated(data, document))
    text = toml_dumps(document, inline=data.draw(st.booleans(), label="inline"))
    note(text)
    try:
        scene = parse_spatial_scene(text, SOURCE, "mutant")
    except SceneError as error:
        message = str(error)
        note(message)
        event("SceneError")
        assert "\n" not in message and message.startswith(f"{SOURCE}: "), message
        rest = message[len(SOURCE) + 2:]
        assert any(names_path(rest, path) for path in error_paths(tomllib.loads(text))), message
        return
    event("loaded")
    check_invariants(scene)


# -- docs/scene-format.md, section 13 -----------------------------------------------------------

DOC_VARIANTS = [   # the edits of scenes/spatial_three_link.toml behind section 13's examples
    ("com = [0.01, 0.12, 0.015]\ninertia = [0.00569524, 0.00119696, 0.00548279, 0.00111923, "
     "-0.000353708, 0.00150473]",
     "com = [0.5, 0.15, 0.1]\ninertia = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]"),
    ("mass = 1.8", "mass = -1.8"),
    ("axis = [0.0, 1.0, 0.2]", "axis = [0.0, 0.0, 0.0]"),
    ("rpy = [0.3, 0.0, 0.1]", "rpy = [0.0, 90.0, 0.0]"),
    ("xyz = [0.0, 0.02, 0.35]", "xyz = [1e200, 0.02, 0.35]"),
    ("inertia = [0.00311114, 0.012999, 0.0134399, 0.0033765, 0.00296193, -0.000935878]",
     "inertia = [0.003, 0.013, 0.018, 0.0, 0.0, 0.0]"),
    ("[2, 0.15, 0.05, 0.04]", "[1, 0.15, 0.05, 0.04]"),
    ("[3, 0.02, 0.15, 0.03]", "[4, 0.02, 0.15, 0.03]"),
    ("damping = 0.05", "length = 0.3"),
    ("route = [[0, 0.08, 0.0, 0.05], [1, 0.06, 0.04, 0.25]]",
     "route = [[0, 0.0, 0.0, 0.2], [1, 0.0, 0.0, 0.1]]"),
]


def test_the_docs_show_the_spatial_scene_and_the_messages_the_reader_prints():
    section = (ROOT / "docs" / "scene-format.md").read_text(encoding="utf-8") \
        .split("## 13. Spatial scenes")[1]
    shipped = (SCENES / "spatial_three_link.toml").read_text(encoding="utf-8")
    assert section.split("```toml\n")[1].split("```")[0] == shipped[shipped.index("name = "):]
    shown = [" ".join(block.split("\n")).strip() for block in
             re.findall(r"```\n((?:arm|three_link_mono)\.toml: .*?)```", section, re.DOTALL)]
    printed = []
    for old, new in DOC_VARIANTS:
        with pytest.raises(SceneError) as caught:
            parse_spatial_scene(edited(old, new, shipped), "arm.toml")
        printed.append(str(caught.value))
    with pytest.raises(SceneError) as caught:
        parse_spatial_scene((SCENES / "three_link_mono.toml").read_text(encoding="utf-8"),
                            "three_link_mono.toml")
    printed.append(str(caught.value))
    with pytest.raises(SceneError) as caught:
        parse_scene(shipped, "arm.toml", "arm")
    printed.append(str(caught.value))
    assert shown == printed


# -- the reader's conventions against URDF's (Pinocchio's URDF parser) -------------------------

def urdf_of(document: dict[str, Any]) -> str:
    """The chain of a spatial scene document as URDF, written from the file's own numbers (the
    axis as written, not normalised): what the reader's conventions claim to be."""
    def triple(values) -> str:
        return " ".join(repr(float(value)) for value in values)

    parts = ['<robot name="chain">', '<link name="link0"/>']
    for i, link in enumerate(document["links"], 1):
        ixx, iyy, izz, ixy, ixz, iyz = (float(value) for value in link["inertia"])
        joint = link["joint"]
        parts += [
            f'<link name="link{i}"><inertial><origin xyz="{triple(link["com"])}" rpy="0 0 0"/>'
            f'<mass value="{float(link["mass"])!r}"/><inertia ixx="{ixx!r}" iyy="{iyy!r}" '
            f'izz="{izz!r}" ixy="{ixy!r}" ixz="{ixz!r}" iyz="{iyz!r}"/></inertial></link>',
            f'<joint name="joint{i}" type="revolute"><parent link="link{i - 1}"/>'
            f'<child link="link{i}"/><origin xyz="{triple(joint.get("xyz", [0, 0, 0]))}" '
            f'rpy="{triple(joint.get("rpy", [0, 0, 0]))}"/><axis xyz="{triple(joint["axis"])}"/>'
            '<limit lower="-10" upper="10" effort="1" velocity="1"/></joint>']
    return "\n".join(parts + ["</robot>"])


@pytest.mark.parametrize("text", [VALID, (SCENES / "spatial_three_link.toml").read_text()],
                         ids=["VALID", "spatial_three_link"])
def test_the_reader_reads_a_chain_as_urdf_means_it(text):
    """M(q) and the gravity torques of the scene the reader makes equal those of Pinocchio's
    model of the same numbers written as URDF (origin xyz then rpy, axis in the joint frame,
    inertia ixx iyy izz ixy ixz iyz about the COM in the link frame), at random angles."""
    pin = require_module("pinocchio", "robots")
    document = tomllib.loads(text)
    scene = parse_spatial_scene(text, SOURCE)
    model = pin.buildModelFromXML(urdf_of(document))
    model.gravity.linear = np.array(scene.gravity)
    data = model.createData()
    rng = np.random.default_rng(33)
    for q in rng.uniform(-np.pi, np.pi, size=(20, scene.n)):
        np.testing.assert_allclose(dynamics.mass_matrix(scene, q), pin.crba(model, data, q),
                                   rtol=0, atol=1e-12)
        np.testing.assert_allclose(dynamics.gravity_torques(scene, q),
                                   pin.computeGeneralizedGravity(model, data, q),
                                   rtol=0, atol=1e-11)
