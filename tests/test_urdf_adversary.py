"""Fourth adversarial pass over `chaingen import`: URDF inputs that gave a wrong scene without
an error (a joint's limits upside down, an axis Pinocchio could not normalise, a mimic joint
on a Pinocchio without `mimic=`), each refused now in one line naming the file, the joint and
the key; and the property behind all of them, drawn by hypothesis: whatever number any key of
a small robot holds, the import is either refused in one line or agrees with Pinocchio's
model of the same file. Fast: no compiler (Pinocchio is the `robots` extra).
"""
from __future__ import annotations

import math
from decimal import Decimal

import numpy as np
import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st
from test_output_paths import snapshot
from test_urdf_import import random_chain_urdf, reference_agreement

from helpers import chaingen, require_module

LIMIT = '<limit lower="{lower}" upper="{upper}" effort="1" velocity="1"/>'
_LINK = ('<link name="{name}"><inertial><mass value="1"/><inertia ixx="0.01" iyy="0.01" '
         'izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>')
_JOINT = ('<joint name="{name}" type="revolute"><parent link="{parent}"/><child link="{child}"/>'
          '<origin xyz="0 0 0.2"/><axis xyz="0 1 0"/>' + LIMIT.format(lower=-1, upper=1)
          + '</joint>')


def two_link_urdf(elbow: str = '<axis xyz="0 1 0"/>' + LIMIT.format(lower=-1, upper=1),
                  kind: str = "revolute", **keys: str) -> str:
    """Two massive links on a revolute shoulder and an `elbow` of `kind` holding `elbow`; the
    `keys` replace the numbers of the lower link's <inertial> and the elbow's <origin>
    (mass, ixx .. iyz, com_xyz, com_rpy, xyz, rpy)."""
    value = {"mass": "1.0", "ixx": "0.01", "iyy": "0.01", "izz": "0.01", "ixy": "0",
             "ixz": "0", "iyz": "0", "com_xyz": "0 0 0.1", "com_rpy": "0 0 0",
             "xyz": "0 0 0.2", "rpy": "0 0 0"} | keys

    def link(name, v):
        return (f'<link name="{name}"><inertial><origin xyz="{v["com_xyz"]}" '
                f'rpy="{v["com_rpy"]}"/><mass value="{v["mass"]}"/><inertia ixx="{v["ixx"]}" '
                f'iyy="{v["iyy"]}" izz="{v["izz"]}" ixy="{v["ixy"]}" ixz="{v["ixz"]}" '
                f'iyz="{v["iyz"]}"/></inertial></link>')
    plain = {key: value for key, value in value.items()} | {
        "mass": "1.0", "ixx": "0.01", "iyy": "0.01", "izz": "0.01", "ixy": "0", "ixz": "0",
        "iyz": "0", "com_xyz": "0 0 0.1", "com_rpy": "0 0 0"}
    return ('<robot name="r"><link name="base"/>' + link("upper", plain) + link("lower", value)
            + '<joint name="shoulder" type="revolute"><parent link="base"/>'
              '<child link="upper"/><origin xyz="0 0 0.2"/><axis xyz="0 1 0"/>'
            + LIMIT.format(lower=-1, upper=1) + "</joint>"
            + f'<joint name="elbow" type="{kind}"><parent link="upper"/><child link="lower"/>'
              f'<origin xyz="{value["xyz"]}" rpy="{value["rpy"]}"/>{elbow}</joint></robot>')


REFUSED = {
    # Imported as a free joint starting at 0 (the limits' "middle" when 0 was out of them:
    # 1.5 for lower 2, upper 1), exit 0.
    "lower above upper": (
        two_link_urdf('<axis xyz="0 1 0"/>' + LIMIT.format(lower=1, upper=-1)),
        "joint 'elbow': <limit lower> 1.0 is above upper -1.0"),
    "lower above upper, both positive": (
        two_link_urdf('<axis xyz="0 1 0"/>' + LIMIT.format(lower=2, upper=1)),
        "joint 'elbow': <limit lower> 2.0 is above upper 1.0"),
    "lower of 1e308": (
        two_link_urdf('<axis xyz="0 1 0"/>' + LIMIT.format(lower="1e308", upper=1)),
        "joint 'elbow': <limit lower> 1e+308 is above upper 1.0"),
    # Pinocchio divides the axis by its length, which overflows (its model's axis is zero) or
    # underflows (its model keeps the tiny axis, and its dynamics scale by it): refused, but
    # "has no axis (<axis xyz> is (0.0, 0.0, 0.0))" named an axis the file does not have.
    "axis too long to normalise": (
        two_link_urdf('<axis xyz="0 1e300 0"/>' + LIMIT.format(lower=-1, upper=1)),
        "joint 'elbow' has no axis (Pinocchio holds (0.0, 0.0, 0.0) of its <axis xyz>: zero, "
        "or too long to normalise)"),
    "axis too short to normalise": (
        two_link_urdf('<axis xyz="0 1e-300 0"/>' + LIMIT.format(lower=-1, upper=1)),
        "joint 'elbow': <axis xyz> too short for Pinocchio to normalise (it holds (0.0, "
        "1e-300, 0.0), of length 1e-300)"),
    # A point mass on the elbow's axis: imported, then simulate failed at its first step
    # ("internal error: LinAlgError: Singular matrix" or "the Newton Jacobian is singular").
    "a point mass on its joint's axis": (
        two_link_urdf(ixx="0", iyy="0", izz="0", com_xyz="0 0.1 0"),
        "link 'lower' (joint 'elbow'): a scene cannot take it: links[1]: joint 2 moves no "
        "mass: link 2 has no inertia about its axis (a point mass on it, or a rod along it), "
        "so the mass matrix is singular"),
    # Joints that close a loop: Pinocchio 4.1 crashed the process on the first (segmentation
    # fault, exit 139: chaingen import too), and on a loop of another shape said only "Model
    # does not have any body named 'b'"; the second it refused as no valid tree.
    "a link the child of two joints": (
        two_link_urdf().replace("</robot>", _JOINT.format(name="back", parent="lower",
                                                           child="upper") + "</robot>"),
        "link 'upper' is the child of 2 joints ('shoulder', 'back'): a closed loop; chaingen "
        "imports serial chains only"),
    "joints in a cycle, no root": (
        '<robot name="cycle">' + _LINK.format(name="a") + _LINK.format(name="b")
        + _JOINT.format(name="ab", parent="a", child="b")
        + _JOINT.format(name="ba", parent="b", child="a") + "</robot>",
        "every link is the child of a joint, so the joints close a loop and no link is the "
        "root; chaingen imports serial chains only"),
    # A joint from a link the file does not have is no loop: the parser's own words name it.
    "a joint from a missing link": (
        two_link_urdf().replace("</robot>", _JOINT.format(name="stray", parent="ghost",
                                                           child="lower") + "</robot>"),
        "not a URDF file Pinocchio can read: Failed to build tree: parent link [ghost] of "
        "joint [stray] not found"),
}


@pytest.mark.parametrize("case", sorted(REFUSED))
def test_wrong_urdfs_are_refused_naming_file_joint_and_key(case, tmp_path):
    require_module("pinocchio", "robots")
    from chaingen.errors import ChaingenError
    from chaingen.spatial.urdf import import_chain

    text, expected = REFUSED[case]
    urdf = tmp_path / "robot.urdf"
    urdf.write_text(text)
    with pytest.raises(ChaingenError) as error:
        import_chain(urdf)
    assert str(error.value).startswith(f"{urdf}: {expected}"), str(error.value)
    assert "\n" not in str(error.value)


def test_limits_upside_down_on_the_command_line_exit_2_and_write_nothing(tmp_path):
    """As a user runs it: one line, exit status 2, no scene written, the URDF unchanged."""
    require_module("pinocchio", "robots")
    (tmp_path / "robot.urdf").write_text(REFUSED["lower above upper"][0])
    before = snapshot(tmp_path)
    result = chaingen("import", "robot.urdf", "-o", "scene.toml", cwd=tmp_path)
    lines = result.stderr.splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert lines[0].startswith("chaingen: error: robot.urdf: joint 'elbow': <limit lower> 1.0 "
                               "is above upper -1.0"), lines[0]
    assert result.stdout == "" and snapshot(tmp_path) == before


def test_limits_that_are_legitimate_still_import(tmp_path):
    """A continuous joint's <limit> is not its range (URDF: it has none; Pinocchio ignores it),
    upside down or not: it imports, starting at 0. A revolute joint whose lower equals its
    upper (a joint locked by its limits) imports starting there; the scene has no limits."""
    require_module("pinocchio", "robots")
    from chaingen.spatial.urdf import import_chain

    urdf = tmp_path / "robot.urdf"
    urdf.write_text(two_link_urdf('<axis xyz="0 1 0"/>' + LIMIT.format(lower=1, upper=-1),
                                  kind="continuous"))
    assert import_chain(urdf).scene.initial_angles == (0.0, 0.0)
    urdf.write_text(two_link_urdf('<axis xyz="0 1 0"/>' + LIMIT.format(lower=0.5, upper=0.5)))
    assert import_chain(urdf).scene.initial_angles == (0.0, 0.5)


def test_mimic_joints_on_a_pinocchio_without_the_mimic_keyword_are_refused(tmp_path,
                                                                           monkeypatch):
    """Pinocchio before 3.4 has no `mimic=` keyword and reads a mimic joint as an independent
    one (another robot, exit 0): on such a Pinocchio a file with a <mimic> is refused; one
    without imports as before."""
    pin = require_module("pinocchio", "robots")
    from chaingen.errors import ChaingenError
    from chaingen.spatial.urdf import import_chain

    build = pin.buildModelFromUrdf

    def old_build(filename, *args, **keywords):
        if keywords:
            raise TypeError("buildModelFromUrdf() got an unexpected keyword argument 'mimic'")
        return build(filename, *args)

    monkeypatch.setattr(pin, "buildModelFromUrdf", old_build)
    urdf = tmp_path / "robot.urdf"
    urdf.write_text(two_link_urdf('<axis xyz="0 1 0"/>' + LIMIT.format(lower=-1, upper=1)
                                  + '<mimic joint="shoulder" multiplier="2"/>'))
    with pytest.raises(ChaingenError) as error:
        import_chain(urdf)
    assert str(error.value).startswith(
        f"{urdf}: it has a <mimic> joint, and this Pinocchio ({pin.__version__}) cannot read "
        "one (it would be an independent joint)"), str(error.value)
    urdf.write_text(two_link_urdf())
    assert import_chain(urdf).joints == ("shoulder", "elbow")


# -- non-unit axes: normalised, as Pinocchio does ----------------------------------------------

@settings(max_examples=25, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(seed=st.integers(0, 2**32 - 1), exponent=st.integers(-330, 330))
def test_axes_of_any_length_normalise_as_pinocchio_or_are_refused(seed, exponent,
                                                                  tmp_path_factory):
    """A random chain of test_urdf_import with every <axis xyz> scaled by 10^exponent (in its
    decimals): the import agrees with Pinocchio on the scaled file (M(q) and g(q) to 1e-10,
    axes unit), or, only where the length is past what a double, or a double's square, holds
    (Pinocchio cannot normalise it), it is refused in one line naming a joint's axis."""
    require_module("pinocchio", "robots")
    from chaingen.errors import ChaingenError
    from chaingen.spatial.urdf import import_chain

    work = tmp_path_factory.mktemp("axes")
    text, _ = random_chain_urdf(seed)
    parts = text.split('<axis xyz="')
    for k in range(1, len(parts)):
        numbers, rest = parts[k].split('"', 1)
        parts[k] = " ".join(str(Decimal(x).scaleb(exponent)) for x in numbers.split()) + \
            '"' + rest
    urdf = work / "random.urdf"
    urdf.write_text('<axis xyz="'.join(parts))
    try:
        chain = import_chain(urdf, tip="tip")
    except ChaingenError as error:
        assert not -150 < exponent < 150, (exponent, str(error))
        assert "\n" not in str(error) and "axis" in str(error), str(error)
        event("refused")
        return
    event("imported")
    for link in chain.scene.links:
        assert abs(math.hypot(*link.joint.axis) - 1.0) <= 1e-15
    worst_mass, worst_gravity = reference_agreement(urdf, "tip", work, 3, seed)
    assert worst_mass <= 1e-10 and worst_gravity <= 1e-10, (exponent, worst_mass, worst_gravity)


# -- any number anywhere: refused in one line, or Pinocchio's robot -----------------------------

KEYS = ("mass", "ixx", "iyy", "izz", "ixy", "ixz", "iyz", "com_xyz", "com_rpy", "xyz", "rpy",
        "axis", "lower", "upper", "damping")
ODD_TEXTS = ("nan", "-nan", "NaN", "inf", "-inf", "infinity", "1e309", "-1e309", "1e-400",
             "4.9e-324", "0", "-0", "-1", "1e308", "-1e308", "", "abc", "1,5", "0x10", "1 ",
             " 1", "+1", ".5", "1.", "1e")


def _number_text():
    floats = st.floats(allow_nan=True, allow_infinity=True).map(repr)
    return st.one_of(st.sampled_from(ODD_TEXTS), floats)


@pytest.mark.parametrize("key", KEYS)
@settings(max_examples=30, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(texts=st.lists(_number_text(), min_size=3, max_size=3), component=st.integers(0, 2))
def test_any_number_in_any_key_is_refused_in_one_line_or_is_pinocchios_robot(
        key, texts, component, tmp_path_factory):
    """One number of the lower link's <inertial>, the elbow's <origin>, <axis>, <limit> or
    <dynamics> replaced by any text (a double's repr, NaN, inf, an overflow, a malformed
    number): `chaingen import` either refuses in one line naming the file, or its scene
    reads back through the scene reader and is Pinocchio's model of the same file: M(q) and
    g(q) to 1e-10, each joint's damping, and an initial angle within each revolute joint's
    limits (which hold lower <= upper)."""
    pin = require_module("pinocchio", "robots")
    from chaingen.errors import ChaingenError
    from chaingen.spatial.reader import parse_spatial_scene
    from chaingen.spatial.urdf import import_chain
    from chaingen.spatial.writer import scene_text

    vector = " ".join(texts if key in ("com_xyz", "com_rpy", "xyz", "rpy", "axis")
                      else ["0.0", "1.0", "0.0"])
    if key in ("lower", "upper", "axis", "damping"):
        limits = {"lower": "-1", "upper": "1"} | ({key: texts[component]}
                                                  if key in ("lower", "upper") else {})
        elbow = (f'<axis xyz="{vector if key == "axis" else "0 1 0"}"/>'
                 + LIMIT.format(**limits)
                 + (f'<dynamics damping="{texts[component]}"/>' if key == "damping" else ""))
        text = two_link_urdf(elbow)
    elif key in ("com_xyz", "com_rpy", "xyz", "rpy"):
        text = two_link_urdf(**{key: vector})
    else:
        text = two_link_urdf(**{key: texts[component]})
    work = tmp_path_factory.mktemp("odd")
    urdf = work / "robot.urdf"
    urdf.write_text(text)
    try:
        chain = import_chain(urdf)
    except ChaingenError as error:
        assert str(error).startswith(f"{urdf}: ") and "\n" not in str(error), str(error)
        event(f"refused: {key}")
        return
    event(f"imported: {key}")
    scene = chain.scene
    assert parse_spatial_scene(scene_text(scene), "imported.toml") == scene
    model = pin.buildModelFromUrdf(str(urdf))
    for i, name in enumerate(chain.joints):
        j = model.getJointId(name)
        assert scene.links[i].damping == model.damping[model.idx_vs[j]]
        lower, upper = (model.lowerPositionLimit[model.idx_qs[j]],
                        model.upperPositionLimit[model.idx_qs[j]])
        assert lower <= scene.initial_angles[i] <= upper, (name, lower, upper)
    worst_mass, worst_gravity = reference_agreement(urdf, None, work, 3, seed=1)
    assert np.isfinite(worst_mass) and np.isfinite(worst_gravity)
    assert worst_mass <= 1e-10 and worst_gravity <= 1e-10, (worst_mass, worst_gravity)

