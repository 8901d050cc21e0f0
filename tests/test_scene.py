"""Scene loading and validation (../shared/spec/scene-format.md): fast, no compiler."""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from chaingen.errors import SceneError
from chaingen.scene import (
    Link,
    Simulation,
    Spring,
    c_identifier,
    kinematics,
    load_scene,
    parse_scene,
)

SCENES = Path(__file__).resolve().parent.parent / "scenes"
SOURCE = "scenes/test.toml"

# A valid scene using every key of the format; each bad case below edits one line of it.
VALID = """\
name = "test-chain"
gravity = 9.81

[base]
fastening = 0.4

[[links]]
mass = 1.0
inertia = 0.1
length = 1.0
com = 0.5
com_normal = 0.05
fastening = 0.4
damping = 0.01

[[links]]
mass = 2.0
inertia = 0.2
length = 0.8
com = 0.3
fastening = 0.3

[[springs]]
joints = [1, 2]
stiffness = 10.0
rest_length = 0.5
offsets = [0.4, -0.4, 0.3]

[[springs]]
joints = [2, 2]
stiffness = 5.0
rest_length = 0.2

[initial]
angles = [0.5, 0.3]
velocities = [0.0, 0.1]

[simulation]
method = "vi"
quadrature = 2
dt = 0.005
t_end = 2.0
"""

MINIMAL = """\
[[links]]
mass = 1
inertia = 0
length = 2
com = 1
"""


def edited(old: str, new: str, text: str = VALID) -> str:
    assert text.count(old) == 1, f"test setup: {old!r} must occur exactly once"
    return text.replace(old, new)


def scene_error(text: str, source: str = SOURCE, default_name: str = "test") -> str:
    with pytest.raises(SceneError) as caught:
        parse_scene(text, source, default_name)
    message = str(caught.value)
    assert "\n" not in message, message
    return message


def assert_names(message: str, key_path: str, *fragments: str) -> None:
    assert message.startswith(f"{SOURCE}: {key_path}: "), message
    for fragment in fragments:
        assert fragment in message, message


# -- the reference scenes ----------------------------------------------------------------------

@pytest.mark.parametrize("stem, springs", [
    ("three_link_gravity", ()),
    ("three_link_mono", (Spring(1, 1, 1.0, 0.2, None), Spring(2, 2, 1.0, 0.2, None),
                         Spring(3, 3, 1.0, 0.2, None))),
    ("three_link_multi", (Spring(1, 3, 1.0, 0.6, None),)),
])
def test_reference_scenes_load_with_their_numbers(stem, springs):
    scene = load_scene(SCENES / f"{stem}.toml")
    assert scene.name == stem.replace("_", "-")
    assert scene.c_name == stem
    assert scene.gravity == 1.0
    assert scene.base_fastening == 0.4
    assert scene.links == (Link(mass=1.0, inertia=1.0, length=1.0, com=0.5, com_normal=0.0,
                                fastening=0.4, damping=0.0),) * 3
    assert scene.springs == springs
    assert scene.initial_angles == (math.pi / 4, 0.3, 0.3)
    assert scene.initial_velocities == (0.0, 0.0, 0.0)
    quadrature = 1 if stem == "three_link_gravity" else 3
    assert scene.simulation == Simulation(method="es", quadrature=quadrature, dt=0.01, t_end=50.0)
    assert scene.n == 3
    assert scene.chain_fastenings() == (0.4,) * 4
    assert all(type(value) is float for link in scene.links for value in vars(link).values())


def test_every_key_is_read():
    scene = parse_scene(VALID, SOURCE, "unused")
    assert scene.name == "test-chain"
    assert scene.c_name == "test_chain"
    assert scene.gravity == 9.81
    assert scene.links[0] == Link(1.0, 0.1, 1.0, 0.5, 0.05, 0.4, 0.01)
    assert scene.links[1] == Link(2.0, 0.2, 0.8, 0.3, 0.0, 0.3, 0.0)
    assert scene.springs == (Spring(1, 2, 10.0, 0.5, (0.4, -0.4, 0.3)),
                             Spring(2, 2, 5.0, 0.2, None))
    assert scene.spring_fastenings(scene.springs[0]) == (0.4, -0.4, 0.3)
    assert scene.spring_fastenings(scene.springs[1]) == (0.4, 0.3)
    assert scene.initial_angles == (0.5, 0.3)
    assert scene.initial_velocities == (0.0, 0.1)
    assert scene.simulation == Simulation("vi", 2, 0.005, 2.0)


def test_defaults_apply():
    scene = parse_scene(MINIMAL, SOURCE, "from-stem")
    assert scene.name == "from-stem"
    assert scene.c_name == "from_stem"
    assert scene.gravity == 9.81
    assert scene.base_fastening == 0.0
    assert scene.links == (Link(1.0, 0.0, 2.0, 1.0, 0.0, 0.0, 0.0),)
    assert all(type(value) is float for value in vars(scene.links[0]).values())
    assert scene.springs == ()
    assert scene.initial_angles == (0.0,)
    assert scene.initial_velocities == (0.0,)
    assert scene.simulation == Simulation()


def test_partial_tables_keep_the_other_defaults():
    text = MINIMAL + "[initial]\nvelocities = [2]\n[simulation]\ndt = 0.1\n[base]\n"
    scene = parse_scene(text, SOURCE, "x")
    assert scene.initial_angles == (0.0,)
    assert scene.initial_velocities == (2.0,)
    assert scene.simulation == Simulation(dt=0.1)
    assert scene.base_fastening == 0.0


def test_gravity_zero_switches_gravity_off():
    assert parse_scene("gravity = 0\n" + MINIMAL, SOURCE, "x").gravity == 0.0


def test_empty_springs_array_is_allowed():
    assert parse_scene("springs = []\n" + MINIMAL, SOURCE, "x").springs == ()


def test_load_scene_uses_the_file_stem_as_default_name(tmp_path):
    path = tmp_path / "My-Chain_2.toml"
    path.write_text(MINIMAL)
    scene = load_scene(path)
    assert scene.name == "My-Chain_2"
    assert scene.c_name == "my_chain_2"
    assert load_scene(str(path)) == scene


def test_c_identifier():
    assert c_identifier("Three-Link-Mono") == "three_link_mono"


# -- bad input: one test per kind, each naming the key path ----------------------------------

UNKNOWN_KEYS = [
    ("top level", 'gravity = 9.81', 'gravity = 9.81\ngravty = 1.0', "gravty", "'gravity'"),
    ("base", 'fastening = 0.4\n\n[[links]]', 'fastening = 0.4\nfoo = 1\n\n[[links]]',
     "base.foo", "unknown key"),
    ("link", 'mass = 2.0', 'mass = 2.0\nmas = 2.0', "links[1].mas", "'mass'"),
    ("spring", 'stiffness = 5.0', 'stiffness = 5.0\nstifness = 5.0', "springs[1].stifness",
     "'stiffness'"),
    ("initial", 'angles = [0.5, 0.3]', 'angles = [0.5, 0.3]\nangle = [0.5, 0.3]',
     "initial.angle", "'angles'"),
    ("simulation", 'dt = 0.005', 'dt = 0.005\nsteps = 100', "simulation.steps", "unknown key"),
    ("unknown table", '[simulation]', '[solver]\nx = 1\n[simulation]', "solver", "unknown key"),
]


@pytest.mark.parametrize("old, new, path, fragment", [case[1:] for case in UNKNOWN_KEYS],
                         ids=[case[0] for case in UNKNOWN_KEYS])
def test_unknown_key_is_an_error(old, new, path, fragment):
    assert_names(scene_error(edited(old, new)), path, fragment)


WRONG_TYPES = [
    ("string for number", 'mass = 2.0', 'mass = "2.0"', "links[1].mass", 'got "2.0"'),
    ("bool for number", 'mass = 2.0', 'mass = true', "links[1].mass", "got true"),
    ("bool for gravity", 'gravity = 9.81', 'gravity = false', "gravity", "got false"),
    ("bool for fastening", 'fastening = 0.4\n\n[[links]]', 'fastening = true\n\n[[links]]',
     "base.fastening", "got true"),
    ("bool in angles", 'angles = [0.5, 0.3]', 'angles = [0.5, true]', "initial.angles[1]",
     "got true"),
    ("bool in offsets", 'offsets = [0.4, -0.4, 0.3]', 'offsets = [0.4, false, 0.3]',
     "springs[0].offsets[1]", "got false"),
    ("array for number", 'dt = 0.005', 'dt = [0.005]', "simulation.dt", "got [0.005]"),
    ("number for name", 'name = "test-chain"', 'name = 3', "name", "got 3"),
    ("number for method", 'method = "vi"', 'method = 1', "simulation.method", "got 1"),
    ("float quadrature", 'quadrature = 2', 'quadrature = 2.0', "simulation.quadrature",
     "got 2.0"),
    ("bool quadrature", 'quadrature = 2', 'quadrature = true', "simulation.quadrature",
     "got true"),
    ("float joints", 'joints = [2, 2]', 'joints = [2.0, 2]', "springs[1].joints",
     "got [2.0, 2]"),
    ("bool joints", 'joints = [2, 2]', 'joints = [true, 2]', "springs[1].joints",
     "got [true, 2]"),
    ("scalar joints", 'joints = [2, 2]', 'joints = 2', "springs[1].joints", "got 2"),
    ("three joints", 'joints = [1, 2]', 'joints = [1, 2, 2]', "springs[0].joints",
     "got [1, 2, 2]"),
    ("scalar angles", 'angles = [0.5, 0.3]', 'angles = 0.5', "initial.angles", "got 0.5"),
]


@pytest.mark.parametrize("old, new, path, fragment", [case[1:] for case in WRONG_TYPES],
                         ids=[case[0] for case in WRONG_TYPES])
def test_wrong_type_is_an_error(old, new, path, fragment):
    assert_names(scene_error(edited(old, new)), path, fragment)


@pytest.mark.parametrize("prefix, path, fragment", [
    ("base = 0.4\n", "base", "must be a table ([base]), not a float, got 0.4"),
    ("initial = [0.5]\n", "initial", "must be a table ([initial]), not an array"),
    ("simulation = \"es\"\n", "simulation", 'must be a table ([simulation]), not a string'),
    ("springs = 1\n", "springs", "must be an array of tables ([[springs]])"),
    ("springs = [1]\n", "springs[0]", "must be a table ([[springs]]), not an integer, got 1"),
])
def test_section_of_the_wrong_type_is_an_error(prefix, path, fragment):
    assert_names(scene_error(prefix + MINIMAL), path, fragment)


@pytest.mark.parametrize("text, path, fragment", [
    ("links = 3\n", "links", "got 3"),
    ("links = [1, 2]\n", "links[0]", "must be a table"),
    ("links = {mass = 1}\n", "links", "not a table"),
])
def test_links_not_an_array_of_tables(text, path, fragment):
    assert_names(scene_error(text), path, fragment)


@pytest.mark.parametrize("literal", ["nan", "+nan", "-nan", "inf", "+inf", "-inf"])
@pytest.mark.parametrize("old, path", [
    ('gravity = 9.81', "gravity"),
    ('fastening = 0.4\n\n[[links]]', "base.fastening"),
    ('mass = 2.0', "links[1].mass"),
    ('inertia = 0.2', "links[1].inertia"),
    ('length = 0.8', "links[1].length"),
    ('com = 0.3', "links[1].com"),
    ('com_normal = 0.05', "links[0].com_normal"),
    ('fastening = 0.3', "links[1].fastening"),
    ('damping = 0.01', "links[0].damping"),
    ('stiffness = 10.0', "springs[0].stiffness"),
    ('rest_length = 0.5', "springs[0].rest_length"),
    ('offsets = [0.4, -0.4, 0.3]', "springs[0].offsets[2]"),
    ('angles = [0.5, 0.3]', "initial.angles[1]"),
    ('velocities = [0.0, 0.1]', "initial.velocities[0]"),
    ('dt = 0.005', "simulation.dt"),
    ('t_end = 2.0', "simulation.t_end"),
])
def test_non_finite_numbers_are_errors(old, path, literal):
    key = old.split(" = ")[0]
    if path.endswith("[2]"):
        new = f"{key} = [0.4, -0.4, {literal}]"
    elif path.endswith("[1]"):
        new = f"{key} = [0.5, {literal}]"
    elif path.endswith("[0]"):
        new = f"{key} = [{literal}, 0.1]"
    else:
        new = f"{key} = {literal}" + old[len(old.split("\n")[0]):]
    message = scene_error(edited(old, new))
    assert_names(message, path, "must be finite", f"got {float(literal)!r}")


OUT_OF_RANGE = [
    ("mass", 'mass = 2.0', 'mass = -1.0', "links[1].mass", "must be > 0", "got -1.0"),
    ("mass zero", 'mass = 2.0', 'mass = 0', "links[1].mass", "must be > 0", "got 0.0"),
    ("inertia", 'inertia = 0.2', 'inertia = -0.1', "links[1].inertia", "must be >= 0",
     "got -0.1"),
    ("length", 'length = 0.8', 'length = 0.0', "links[1].length", "must be > 0", "got 0.0"),
    ("damping", 'damping = 0.01', 'damping = -0.01', "links[0].damping", "must be >= 0",
     "got -0.01"),
    ("gravity", 'gravity = 9.81', 'gravity = -9.81', "gravity", "must be >= 0", "got -9.81"),
    ("stiffness", 'stiffness = 10.0', 'stiffness = 0.0', "springs[0].stiffness",
     "must be > 0", "got 0.0"),
    ("rest_length", 'rest_length = 0.2', 'rest_length = -0.2', "springs[1].rest_length",
     "must be >= 0", "got -0.2"),
    ("dt", 'dt = 0.005', 'dt = 0', "simulation.dt", "must be > 0", "got 0.0"),
    ("t_end", 't_end = 2.0', 't_end = -2', "simulation.t_end", "must be > 0", "got -2.0"),
    ("quadrature zero", 'quadrature = 2', 'quadrature = 0', "simulation.quadrature",
     "from 1 to 20", "got 0"),
    ("quadrature large", 'quadrature = 2', 'quadrature = 21', "simulation.quadrature",
     "from 1 to 20", "got 21"),
    ("method", 'method = "vi"', 'method = "rk4"', "simulation.method", '"es", "vi", "midpoint"',
     'got "rk4"'),
    ("method case", 'method = "vi"', 'method = "VI"', "simulation.method", "must be one of",
     'got "VI"'),
    ("joint zero", 'joints = [1, 2]', 'joints = [0, 2]', "springs[0].joints",
     "joint 0 does not exist", "got [0, 2]"),
    ("first after last", 'joints = [1, 2]', 'joints = [2, 1]', "springs[0].joints",
     "first joint 2 is after last joint 1", "got [2, 1]"),
    ("joint beyond chain", 'joints = [2, 2]', 'joints = [2, 3]', "springs[1].joints",
     "joint 3 does not exist: the chain has 2 joints", "got [2, 3]"),
    ("mono joint beyond chain", 'joints = [2, 2]', 'joints = [5, 5]', "springs[1].joints",
     "joint 5 does not exist", "got [5, 5]"),
    ("name with space", 'name = "test-chain"', 'name = "test chain"', "name",
     "must start with a letter", 'got "test chain"'),
    ("name with digit first", 'name = "test-chain"', 'name = "3link"', "name",
     "must start with a letter", 'got "3link"'),
    ("name empty", 'name = "test-chain"', 'name = ""', "name", "must start with a letter",
     'got ""'),
    ("name with newline", 'name = "test-chain"', 'name = "test\\n"', "name",
     "must start with a letter", 'got "test\\n"'),
    ("spring beyond a removed link",
     '[[links]]\nmass = 2.0\ninertia = 0.2\nlength = 0.8\ncom = 0.3\nfastening = 0.3\n', '',
     "springs[0].joints", "joint 2 does not exist: the chain has 1 joint (1..1)",
     "got [1, 2]"),
]


@pytest.mark.parametrize("old, new, path, what, got", [case[1:] for case in OUT_OF_RANGE],
                         ids=[case[0] for case in OUT_OF_RANGE])
def test_out_of_range_value_is_an_error(old, new, path, what, got):
    message = scene_error(edited(old, new))
    assert_names(message, path, what)
    assert message.endswith(got), message


def test_link_messages_give_the_model_numbers():
    message = scene_error(edited('mass = 2.0', 'mass = -1.0'))
    assert message == f"{SOURCE}: links[1].mass: must be > 0 (m_2 in kg, link 2), got -1.0"


def test_missing_links_is_an_error():
    assert_names(scene_error('name = "x"\n'), "links", "at least one [[links]]")
    assert_names(scene_error('links = []\n'), "links", "at least one link", "got []")


@pytest.mark.parametrize("key", ["mass", "inertia", "length", "com"])
def test_missing_required_link_key_is_an_error(key):
    text = "\n".join(line for line in MINIMAL.splitlines() if not line.startswith(key + " "))
    assert_names(scene_error(text), f"links[0].{key}", "missing", "link 1")


@pytest.mark.parametrize("key", ["joints", "stiffness", "rest_length"])
def test_missing_required_spring_key_is_an_error(key):
    text = MINIMAL + "[[springs]]\njoints = [1, 1]\nstiffness = 1.0\nrest_length = 0.2\n"
    text = "\n".join(line for line in text.splitlines() if not line.startswith(key + " "))
    assert_names(scene_error(text), f"springs[0].{key}", "missing")


WRONG_LENGTHS = [
    ("angles short", 'angles = [0.5, 0.3]', 'angles = [0.5]', "initial.angles", "2 entries"),
    ("angles long", 'angles = [0.5, 0.3]', 'angles = [0.5, 0.3, 0.1]', "initial.angles",
     "one per link"),
    ("angles empty", 'angles = [0.5, 0.3]', 'angles = []', "initial.angles", "not 0"),
    ("velocities", 'velocities = [0.0, 0.1]', 'velocities = [0.0]', "initial.velocities",
     "2 entries"),
    ("offsets short", 'offsets = [0.4, -0.4, 0.3]', 'offsets = [0.4, -0.4]',
     "springs[0].offsets", "3 entries, one per fastening P_1..P_3"),
    ("offsets long", 'offsets = [0.4, -0.4, 0.3]', 'offsets = [0.4, -0.4, 0.3, 0.3]',
     "springs[0].offsets", "not 4"),
    ("offsets on mono", 'rest_length = 0.2\n', 'rest_length = 0.2\noffsets = [0.1]\n',
     "springs[1].offsets", "2 entries"),
    ("joints one entry", 'joints = [2, 2]', 'joints = [2]', "springs[1].joints",
     "two integers"),
]


@pytest.mark.parametrize("old, new, path, fragment", [case[1:] for case in WRONG_LENGTHS],
                         ids=[case[0] for case in WRONG_LENGTHS])
def test_wrong_list_length_is_an_error(old, new, path, fragment):
    assert_names(scene_error(edited(old, new)), path, fragment)


def test_offsets_before_joints_are_checked_against_them():
    text = MINIMAL + "[[springs]]\noffsets = [1, 2, 3]\njoints = [1, 1]\nstiffness = 1\n" \
                     "rest_length = 0\n"
    assert_names(scene_error(text), "springs[0].offsets", "2 entries")


def test_lengths_are_checked_when_initial_comes_before_links():
    text = "[initial]\nangles = [0.1, 0.2]\n" + MINIMAL
    assert_names(scene_error(text), "initial.angles", "must have 1 entry (one per link), not 2")


def test_first_error_in_file_order_is_reported():
    text = edited('gravity = 9.81', 'gravity = -1', edited('t_end = 2.0', 't_end = 0'))
    assert_names(scene_error(text), "gravity")
    text = edited('mass = 1.0', 'mass = 0', edited('mass = 2.0', 'mass = 0'))
    assert_names(scene_error(text), "links[0].mass")


# -- names ----------------------------------------------------------------------------------

def test_invalid_default_name_asks_for_a_name():
    message = scene_error(MINIMAL, default_name="2 link arm")
    assert_names(message, "name", "file's stem", 'name = "scene_2_link_arm"', 'got "2 link arm"')


def test_invalid_stem_is_fine_when_name_is_set(tmp_path):
    path = tmp_path / "my scene.toml"
    path.write_text('name = "ok"\n' + MINIMAL)
    assert load_scene(path).name == "ok"
    path.write_text(MINIMAL)
    with pytest.raises(SceneError, match=r"my scene.toml: name: .*set it in the file"):
        load_scene(path)


# -- zero-length spring segments at the initial configuration ----------------------------------

def zero_segment_scene(spring: str, angles: str, base: float = 0.0, fastening: float = 0.0):
    """One or two unit links; at theta_1 = 90 degrees P_2 = X_2 - r_2 (1, 0) = (-r_2, 1)."""
    return f"""\
[base]
fastening = {base}
[[links]]
mass = 1
inertia = 1
length = 1
com = 0.5
fastening = {fastening}
[[links]]
mass = 1
inertia = 1
length = 1
com = 0.5
[[springs]]
{spring}
stiffness = 1
rest_length = 0.1
[initial]
angles = {angles}
"""


@pytest.mark.parametrize("spring, angles, base, fastening, path, segment", [
    # P_1 = (0, r_1) = (0, 1) and P_2 = (-r_2, 1) = (0, 1) at theta_1 = pi/2.
    ("joints = [1, 1]\noffsets = [1.0, 0.0]", f"[{math.pi / 2}, 0.0]", 0.0, 0.0,
     "springs[0]", "s_1 (fastening P_1 to P_2, joint 1)"),
    ("joints = [1, 1]", f"[{math.pi / 2}, 0.0]", 1.0, 0.0, "springs[0]", "s_1"),
    # Segment 2: P_2 = X_2 + r_2 n_1, P_3 = X_3 + r_3 n_2; at phi = 0, phi_2 = -pi/2:
    # X_2 = (1, 0), n_1 = (0, 1), X_3 = (1, -1), n_2 = (1, 0): P_2 = (1, -1) when r_2 = -1,
    # P_3 = (1, -1) when r_3 = 0.
    ("joints = [1, 2]\noffsets = [0.5, -1.0, 0.0]", f"[0.0, {-math.pi / 2}]", 0.0, 0.0,
     "springs[0]", "s_2 (fastening P_2 to P_3, joint 2)"),
])
def test_zero_length_segment_at_initial_configuration_is_refused(spring, angles, base,
                                                                 fastening, path, segment):
    message = scene_error(zero_segment_scene(spring, angles, base, fastening))
    assert_names(message, path, segment, "zero length at the initial configuration")


def test_short_but_nonzero_segment_is_accepted():
    text = zero_segment_scene("joints = [1, 1]\noffsets = [1.0, 1e-6]", f"[{math.pi / 2}, 0.0]")
    scene = parse_scene(text, SOURCE, "x")
    lengths = kinematics.spring_geometry(scene, scene.springs[0], scene.initial_angles)
    assert lengths.segment_lengths[0] == pytest.approx(1e-6, rel=1e-6)


def test_zero_segment_elsewhere_than_the_initial_configuration_is_accepted():
    # The same spring as the refused one, at angle 0: P_1 = (0, 1), P_2 = (1, 0).
    text = zero_segment_scene("joints = [1, 1]\noffsets = [1.0, 0.0]", "[0.0, 0.0]")
    parse_scene(text, SOURCE, "x")


@pytest.mark.parametrize("key, line", [("links[1].length", 19), ("links[2].fastening", 28)])
def test_a_length_that_dwarfs_a_spring_is_named_with_the_reason(key, line):
    """A link 1e150 m long (or a fastening 1e150 m off it) makes the zero-length limit 1e-9 G
    of every segment 1e141 m: spring 0's segment of 0.727 m was refused as 'segment s_1 ...
    has zero length at the initial configuration; move a fastening ... (limit 1e+141 m)'. The
    refusal names the key that dwarfs it now."""
    lines = (SCENES / "three_link_mono.toml").read_text().splitlines()
    name, _ = lines[line - 1].split(" = ")
    assert name in key
    lines[line - 1] = f"{name} = 1e150"
    message = scene_error("\n".join(lines))
    assert message == (
        f"{SOURCE}: {key}: 1e+150 m dwarfs segment s_1 of springs[0] (fastening P_1 to P_2), "
        "0.727 m long at the initial angles: it makes the geometry's size G so large that the "
        "segment is below 1e-9 G = 1e+141 m, where a segment counts as zero length (and a run "
        "stops below 1e-6 G); every segment must be at least 1e-9 of the geometry's size: write "
        f"{key} in metres, got 1e+150")


# -- syntax errors and files ---------------------------------------------------------------

@pytest.mark.parametrize("text, line", [
    ('name = "x"\ngravity = \n[[links]]\n', 2),
    ('gravity = 1\n\n\n[links\nmass = 1\n', 4),
    ('gravity = 1\ngravity = 2\n', 2),
    ('name = "unterminated', 1),
])
def test_toml_syntax_error_names_the_line(text, line):
    message = scene_error(text)
    assert message.startswith(f"{SOURCE}:{line}: TOML syntax error: "), message


def test_load_scene_syntax_error_names_the_file_and_line(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text(VALID.replace("mass = 2.0", "mass = = 2.0"))
    line = VALID.splitlines().index("mass = 2.0") + 1
    with pytest.raises(SceneError) as caught:
        load_scene(path)
    assert str(caught.value).startswith(f"{path}:{line}: TOML syntax error: ")


def test_load_scene_rejects_non_utf8(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes(b'gravity = 1\nname = "caf\xe9"\n')
    with pytest.raises(SceneError, match=r"latin1.toml:2: .*not UTF-8"):
        load_scene(path)


def test_missing_file_is_a_scene_error(tmp_path):
    path = tmp_path / "nowhere.toml"
    with pytest.raises(SceneError) as caught:
        load_scene(path)
    message = str(caught.value)
    assert message.startswith(f"{path}: cannot read scene file"), message
    assert "\n" not in message


def test_directory_is_a_scene_error(tmp_path):
    with pytest.raises(SceneError, match="cannot read scene file"):
        load_scene(tmp_path)


# -- [actuation] (docs/scene-extensions.md) --------------------------------------------------

ACTUATED = VALID.replace("[initial]", "[actuation]\njoints = [2]\n\n[initial]")


def test_actuation_lists_the_actuated_joints():
    assert parse_scene(ACTUATED, SOURCE, "unused").actuated_joints == (2,)
    both = edited("joints = [2]\n", "joints = [1, 2]\n", ACTUATED)
    assert parse_scene(both, SOURCE, "unused").actuated_joints == (1, 2)
    assert parse_scene(VALID, SOURCE, "unused").actuated_joints == ()


def test_actuation_may_come_before_the_links():
    text = "[actuation]\njoints = [1]\n\n" + MINIMAL
    assert parse_scene(text, SOURCE, "x").actuated_joints == (1,)
    assert_names(scene_error("[actuation]\njoints = [2]\n\n" + MINIMAL), "actuation.joints[0]",
                 "joint 2 does not exist", "1 joint (1..1)")


BAD_ACTUATION = [
    ("joint beyond the chain", "joints = [3]", "actuation.joints[0]",
     "joint 3 does not exist: the chain has 2 joints (1..2)"),
    ("joint zero", "joints = [0]", "actuation.joints[0]", "joint 0 does not exist"),
    ("descending", "joints = [2, 1]", "actuation.joints[1]", "ascending order"),
    ("repeated", "joints = [2, 2]", "actuation.joints[1]", "each once"),
    ("empty", "joints = []", "actuation.joints", "at least one joint"),
    ("float", "joints = [1.0]", "actuation.joints", "array of integers"),
    ("bool", "joints = [true]", "actuation.joints", "array of integers"),
    ("scalar", "joints = 1", "actuation.joints", "got 1"),
    ("unknown key", "joints = [2]\njoint = [1]", "actuation.joint", "did you mean 'joints'"),
    ("missing joints", "", "actuation.joints", "missing"),
]


@pytest.mark.parametrize("new, path, fragment", [case[1:] for case in BAD_ACTUATION],
                         ids=[case[0] for case in BAD_ACTUATION])
def test_bad_actuation_is_an_error(new, path, fragment):
    assert_names(scene_error(edited("joints = [2]", new, ACTUATED)), path, fragment)


def test_actuation_must_be_a_table():
    assert_names(scene_error("actuation = [1]\n" + MINIMAL), "actuation",
                 "must be a table ([actuation])")
