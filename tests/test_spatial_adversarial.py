"""Adversarial input to the spatial readers and commands: route points that coincide, numbers
that are not finite, zero axes, rpy in degrees, a chain whose mass matrix overflows, outputs
that would overwrite an input or a file a user wrote. Each is refused in one line (exit status
2 on the command line), with nothing written and no input changed, or runs to the right number.
Fast: no compiler."""
from __future__ import annotations

import hashlib
import math

import pytest

from chaingen.errors import SceneError
from chaingen.spatial import dynamics, parse_spatial_scene

from helpers import ROOT, chaingen_in_process

SPATIAL = ROOT / "scenes" / "spatial_three_link.toml"
MONO = "route = [[0, 0.08, 0.0, 0.05], [1, 0.06, 0.04, 0.25]]"
MULTI = "route = [[1, 0.05, 0.04, 0.3], [2, 0.15, 0.05, 0.04], [3, 0.02, 0.15, 0.03]]"


def snapshot(directory) -> dict[str, str]:
    return {str(path.relative_to(directory)): hashlib.sha256(path.read_bytes()).hexdigest()
            for path in sorted(directory.rglob("*")) if path.is_file()}


def edited(old: str, new: str) -> str:
    text = SPATIAL.read_text()
    assert text.count(old) == 1, old
    return text.replace(old, new)


def error_of(text: str) -> str:
    with pytest.raises(SceneError) as caught:
        parse_spatial_scene(text, "arm.toml")
    assert "\n" not in str(caught.value)
    return str(caught.value)


def one_line_exit_2(result) -> str:
    lines = result.stderr.splitlines()
    assert result.returncode == 2 and result.stdout == "" and len(lines) == 1, result
    assert lines[0].startswith("chaingen: error: ") and "Traceback" not in result.stderr
    return lines[0]


# -- route points that coincide ---------------------------------------------------------------

@pytest.mark.parametrize("old, new, spring, points, joints", [
    # both on joint 1's axis, 0.1 m above its origin (joint 1 sits at z = 0.1 on the base)
    (MONO, "route = [[0, 0.0, 0.0, 0.2], [1, 0.0, 0.0, 0.1]]", 0, (0, 1), "the axis of joint 1"),
    # a via point on link 2 at joint 3's origin, then link 3's origin: the middle segment
    (MULTI, "route = [[1, 0.05, 0.04, 0.3], [2, 0.3, 0.0, 0.0], [3, 0.0, 0.0, 0.0], "
            "[2, 0.1, 0.0, 0.0]]", 1, (1, 2), "the axis of joint 3"),
    # the base's point at link 2's origin, which lies on the axes of joints 1 and 2
    (MONO, "route = [[0, 0.0, 0.0, 0.1], [2, 0.0, 0.0, 0.0]]", 0, (0, 1),
     "the axes of joints 1 to 2"),
])
def test_route_points_that_coincide_at_every_angle_are_refused_naming_spring_and_points(
        old, new, spring, points, joints):
    """A zero-length segment has no direction: the gradient of its length is undefined at any
    posture. The reader names the spring, both points (as written) and the joints."""
    base = edited(old, new)
    if "[2, 0.0, 0.0, 0.0]]" in new:   # put joint 2 on joint 1's axis for the third case
        base = base.replace("xyz = [0.0, 0.02, 0.35]", "xyz = [0.0, 0.0, 0.0]")
    message = error_of(base)
    a, b = points
    route = new.split("= ", 1)[1]
    assert message.startswith(f"arm.toml: springs[{spring}]: route[{a}] and route[{b}] are one "
                              f"point at every angle (on {joints}): segment {b} has no length, "
                              "and its length's gradient is undefined; move one of them"), message
    shown = message.rsplit(", got ", 1)[1]
    written = route.strip("[]").split("], [")
    assert shown == f"[[{written[a]}], [{written[b]}]]", (shown, written)


def test_route_points_that_meet_at_the_initial_angles_only_get_the_posture_message():
    """Points off the axis that meet at one posture: refused when the chain starts there, and
    the message says to change the initial angles (which mends it)."""
    text = edited(MONO, "route = [[0, 0.1, 0.0, 0.1], [1, 0.1, 0.0, 0.0]]").replace(
        "angles = [0.3, -0.5, 0.8]", "angles = [0.0, -0.5, 0.8]")
    message = error_of(text)
    assert message.startswith("arm.toml: springs[0]: segment 1 (route[0] to route[1]) has zero "
                              "length at the initial angles (initial.angles)"), message
    scene = parse_spatial_scene(text.replace("angles = [0.0, -0.5", "angles = [0.3, -0.5"))
    assert dynamics.spring_lengths(scene, (0.3, -0.5, 0.8))[0] > 0.01


# -- numbers that are not finite, zero axes -----------------------------------------------------

@pytest.mark.parametrize("old, new, path", [
    ("mass = 2.5", "mass = nan", "links[0].mass"),
    ("mass = 2.5", "mass = inf", "links[0].mass"),
    ("com = [0.01, 0.005, 0.17]", "com = [0.01, nan, 0.17]", "links[0].com[1]"),
    ("gravity = [0.0, 0.0, -9.81]", "gravity = [0.0, 0.0, -inf]", "gravity[2]"),
    ("angles = [0.3, -0.5, 0.8]", "angles = [0.3, nan, 0.8]", "initial.angles[1]"),
    ("velocities = [0.0, 0.2, 0.0]", "velocities = [0.0, inf, 0.0]", "initial.velocities[1]"),
    ("stiffness = 300.0", "stiffness = nan", "springs[0].stiffness"),
    ("rest_length = 0.2\n", "rest_length = inf\n", "springs[0].rest_length"),
    ("axis = [0.0, 0.0, 1.0]", "axis = [0.0, 0.0, 0.0]", "links[0].joint.axis"),
    ("axis = [0.0, 0.0, 1.0]", "axis = [0.0, 0.0, -0.0]", "links[0].joint.axis"),
    ("axis = [0.0, 0.0, 1.0]", "axis = [nan, 0.0, 1.0]", "links[0].joint.axis[0]"),
    ("xyz = [0.0, 0.0, 0.1]", "xyz = [0.0, 0.0, 1e309]", "links[0].joint.xyz[2]"),
    (MONO, "route = [[0, 0.08, 0.0, nan], [1, 0.06, 0.04, 0.25]]", "springs[0].route[0][3]"),
    ("[simulation]", "[simulation]", None),
])
def test_a_bad_number_is_one_line_exit_2_from_every_command(tmp_path, old, new, path):
    if path is None:
        text = SPATIAL.read_text() + "\n[simulation]\ndt = nan\n"
        path = "simulation.dt"
    else:
        text = edited(old, new)
    scene = tmp_path / "arm.toml"
    scene.write_text(text)
    before = snapshot(tmp_path)
    for command in (["simulate", scene, "--out", "run.csv"], ["generate", scene, "-o", "pkg"],
                    ["check", scene], ["order", scene], ["export", scene, "--mjcf", "arm.xml"],
                    ["animate", scene, "-o", "arm.gif"]):
        line = one_line_exit_2(chaingen_in_process(*command, cwd=tmp_path))
        assert line.startswith(f"chaingen: error: {scene}: {path}: "), (command, line)
    assert snapshot(tmp_path) == before


def test_a_tiny_axis_is_normalised_not_refused():
    """An axis of subnormal length is a direction all the same: normalised exactly."""
    scene = parse_spatial_scene(edited("axis = [0.0, 0.0, 1.0]", "axis = [0.0, 0.0, 1e-320]"))
    assert scene.links[0].joint.axis == (0.0, 0.0, 1.0)


# -- the spatial scene reader: numbers in other units ----------------------------------------

ELBOW = "joint = { xyz = [0.0, 0.02, 0.35], rpy = [0.3, 0.0, 0.1], axis = [0.0, 1.0, 0.2] }"

SCENE_REFUSALS = {
    # rpy in degrees (MJCF's default unit): 90 rad read as an orientation, exit 0.
    "rpy in degrees": (
        ELBOW.replace("rpy = [0.3, 0.0, 0.1]", "rpy = [0.0, 90.0, 0.0]"),
        "links[1].joint.rpy[1]: must be within [-2 pi, 2 pi] rad (no orientation needs more "
        "than a turn): degrees? 90.0 deg is 1.5708 rad, got 90.0"),
    "rpy past a turn": (
        ELBOW.replace("rpy = [0.3, 0.0, 0.1]", "rpy = [0.3, 0.0, -6.3]"),
        "links[1].joint.rpy[2]: must be within [-2 pi, 2 pi] rad"),
    # Finite numbers whose mass matrix overflows: read, then every step failed on NaN (exit 1).
    "a joint 1e200 m away": (
        ELBOW.replace("xyz = [0.0, 0.02, 0.35]", "xyz = [1e200, 0.02, 0.35]"),
        "links: the chain's mass matrix or gravity torques at the initial angles are beyond "
        "the range of a double (a joint's xyz, a com, a mass or an inertia far too large): "
        "write the scene in SI units (m, kg, kg m^2)"),
}


@pytest.mark.parametrize("case", sorted(SCENE_REFUSALS))
def test_spatial_scenes_in_other_units_are_refused(case):
    text = SPATIAL.read_text()
    assert text.count(ELBOW) == 1
    edited, expected = SCENE_REFUSALS[case]
    with pytest.raises(SceneError) as error:
        parse_spatial_scene(text.replace(ELBOW, edited), "arm.toml")
    assert str(error.value).startswith(f"arm.toml: {expected}"), str(error.value)
    assert "\n" not in str(error.value)


def test_angles_within_a_turn_still_read():
    """rpy of +-2 pi exactly, and of +-pi (what `chaingen import` writes), are read as
    written."""
    text = SPATIAL.read_text()
    for rpy in ((2 * math.pi, -2 * math.pi, 0.0), (math.pi, -math.pi / 2, -math.pi)):
        edited = ELBOW.replace("rpy = [0.3, 0.0, 0.1]", f"rpy = [{', '.join(map(repr, rpy))}]")
        scene = parse_spatial_scene(text.replace(ELBOW, edited), "arm.toml")
        assert scene.links[1].joint.rpy == rpy


def test_a_scene_in_degrees_on_the_command_line_exit_2_and_write_nothing(tmp_path):
    edited, expected = SCENE_REFUSALS["rpy in degrees"]
    (tmp_path / "arm.toml").write_text(SPATIAL.read_text().replace(ELBOW, edited))
    before = snapshot(tmp_path)
    result = chaingen_in_process("simulate", "arm.toml", "--out", "run.csv", cwd=tmp_path)
    lines = result.stderr.strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert lines[0] == f"chaingen: error: arm.toml: {expected}", lines[0]
    assert snapshot(tmp_path) == before


# -- a mass matrix that is singular: read, then the first step failed ---------------------------

TIP = ("com = [0.01, 0.12, 0.015]\n"
       "inertia = [0.00569524, 0.00119696, 0.00548279, 0.00111923, -0.000353708, 0.00150473]")
COAXIAL = """\
[[links]]
mass = 1.0
com = [0.0, 0.0, 0.3]
inertia = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
joint = { xyz = [0.0, 0.0, 0.0], rpy = [0.0, 0.0, 0.0], axis = [0.0, 0.0, 1.0] }

[[links]]
mass = 1.0
com = [0.2, 0.0, 0.0]
inertia = [0.01, 0.01, 0.01, 0.0, 0.0, 0.0]
joint = { xyz = [0.0, 0.0, 0.5], rpy = [0.0, 0.0, 0.0], axis = [0.0, 0.0, 2.0] }
"""

SINGULAR = {
    # The tip a point mass on its joint's axis [1.0, 0.3, 0.2]: joint 3 moves no mass (M's
    # column 3 is 0 but for round-off).
    "a point mass on its axis": (
        SPATIAL.read_text().replace(TIP, "com = [0.5, 0.15, 0.1]\n"
                                         "inertia = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]"),
        "links[2]: joint 3 moves no mass: link 3 has no inertia about its axis (a point mass "
        "on it, or a rod along it), so the mass matrix is singular; give link 3 an inertia "
        "about the axis or move its com off it"),
    # Two joints on one axis, a point mass on it between them: each moves link 2, together.
    "two joints on one axis": (
        COAXIAL,
        "links: the mass matrix at the initial angles is singular (smallest eigenvalue "),
}


@pytest.mark.parametrize("case", sorted(SINGULAR))
def test_a_singular_mass_matrix_is_refused(case):
    text, expected = SINGULAR[case]
    assert text != SPATIAL.read_text()
    message = error_of(text)
    assert message.startswith(f"arm.toml: {expected}"), message


def test_a_singular_mass_matrix_on_the_command_line_exit_2_and_write_nothing(tmp_path):
    """Before: the scene was read and simulate failed at its first step, 'the Newton Jacobian
    is singular (no usable pivot)', which named nothing of the scene."""
    text, expected = SINGULAR["a point mass on its axis"]
    (tmp_path / "arm.toml").write_text(text)
    before = snapshot(tmp_path)
    result = chaingen_in_process("simulate", "arm.toml", "--out", "run.csv", cwd=tmp_path)
    assert one_line_exit_2(result) == f"chaingen: error: arm.toml: {expected}"
    assert snapshot(tmp_path) == before


def test_light_links_are_not_singular():
    """A tip a thousand million times lighter than the shipped one, off its axis, still reads."""
    light = SPATIAL.read_text().replace("mass = 1.1", "mass = 1.1e-9").replace(
        TIP, "com = [0.01, 0.12, 0.015]\ninertia = [5e-12, 1e-12, 5e-12, 0.0, 0.0, 0.0]")
    assert parse_spatial_scene(light, "arm.toml").links[2].mass == 1.1e-9
