"""Finite but extreme numbers in a planar scene: the reader refuses what no step can take (a
mass matrix, a spring's or the initial kinetic energy beyond the range of a double) in one line
at its key path, as the spatial reader does (docs/scene-format.md, sections 5, 6 and 8); what
it takes, the run either simulates or stops with its reason (exit 1), never an internal error."""
from __future__ import annotations

import re

import numpy as np
import pytest

from chaingen.errors import SceneError
from chaingen.scene import parse_scene

from helpers import chaingen_in_process, scene_path

BASE = scene_path("three_link_mono").read_text()
DYNAMICS = ("links: the chain's mass matrix or gravity torques at the initial angles are "
            "beyond the range of a double")


def edited(*replacements: tuple[str, str]) -> str:
    text = BASE
    for old, new in replacements:
        assert old in text
        text = text.replace(old, new, 1)
    return text


@pytest.mark.parametrize("replacements, message", [
    # es squared the com when generating: an internal OverflowError, exit 1 (measured).
    ([("com = 0.5", "com = 1e200")], DYNAMICS),
    # A com whose square overflows, on a mass that would bring m com^2 back into range.
    ([("mass = 1.0", "mass = 1e-300"), ("com = 0.5", "com = 1e155")], DYNAMICS),
    # The segments' zero-length limit scaled with the links and called s_2 zero (got 0.0).
    ([("length = 1.0", "length = 1e200")], DYNAMICS),
    ([("mass = 1.0", "mass = 1e308"), ("com = 0.5", "com = 1e10")], DYNAMICS),
    ([("inertia = 1.0", "inertia = 1.7e308")] * 3, DYNAMICS),
    ([("gravity = 1.0", "gravity = 1.7e308"), ("mass = 1.0", "mass = 10.0")], DYNAMICS),
    # Each method failed at step 1 (NaN, or a missed energy balance), exit 1.
    ([("rest_length = 0.2", "rest_length = 1e300")],
     "springs[0]: its energy 1/2 k (s - S_0)^2 at the initial angles is beyond the range of "
     "a double"),
    ([("stiffness = 1.0", "stiffness = 1e300"), ("rest_length = 0.2", "rest_length = 1e5")],
     "springs[0]: its energy"),
    # Fastenings whose sum overflows a double: an internal OverflowError (fsum) on main for a
    # moment, and before that '... (limit inf m)'; the limit is taken at the largest double.
    ([("fastening = 0.4", "fastening = 1.7e308")] * 2, "springs[2]: segment s_3 (fastening P_3 "
     "to P_4, joint 3) has zero length at the initial configuration (initial.angles), where its "
     "direction is undefined; move a fastening (offsets) or change the initial angles (limit "
     "1.8e+299 m)"),
    ([("velocities = [0.0, 0.0, 0.0]", "velocities = [1e160, 0.0, 0.0]")],
     "initial.velocities: the kinetic energy of the initial state is beyond the range of a "
     "double: write the rates in rad/s, got [1e+160, 0.0, 0.0]"),
])
def test_the_reader_refuses_numbers_whose_dynamics_overflow(replacements, message):
    with pytest.raises(SceneError) as refused:
        parse_scene(edited(*replacements), "arm.toml", "arm")
    assert str(refused.value).startswith(f"arm.toml: {message}")
    assert "\n" not in str(refused.value)


@pytest.mark.parametrize("replacements", [
    [("mass = 1.0", "mass = 1e300")],              # m R^2 within range: the run judges
    [("mass = 1.0", "mass = 1e-300")] * 3,
    [("length = 1.0", "length = 1e-300")],
    [("stiffness = 1.0", "stiffness = 1e300")],
    [("gravity = 1.0", "gravity = 1e300")],
    [("velocities = [0.0, 0.0, 0.0]", "velocities = [1e150, 0.0, 0.0]")],
])
def test_extreme_numbers_within_the_range_of_a_double_are_read(replacements):
    parse_scene(edited(*replacements), "arm.toml", "arm")


def test_simulate_refuses_an_overflowing_com_in_one_line_exit_2(tmp_path):
    """com = 1e200 with es: an internal OverflowError (exit 1) in the code generation before."""
    scene = tmp_path / "arm.toml"
    scene.write_text(edited(("com = 0.5", "com = 1e200")))
    result = chaingen_in_process("simulate", scene, "--method", "es", "--t-end", "0.1",
                                 "--out", "run.csv", cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert result.stderr.strip().splitlines() == [f"chaingen: error: {scene}: {DYNAMICS} (a "
                                                  "length, a com, a mass or an inertia far too "
                                                  "large, or gravity): write the scene in SI "
                                                  "units (m, kg, kg m^2)"]
    assert sorted(path.name for path in tmp_path.iterdir()) == ["arm.toml"]


# -- the bottom of a double: a chain whose squares underflow ------------------------------------

def tiny(scale: str) -> str:
    """three_link_mono with every length, com and fastening (and rest length) times `scale`."""
    text = BASE
    for key in ("length", "com", "fastening", "rest_length"):
        text = re.sub(rf"^({key} = [0-9.]+)$", rf"\g<1>{scale}", text, flags=re.M)
    return text


@pytest.mark.parametrize("scale", ["e-300", "e-200", "e-155"])
def test_the_reader_refuses_a_chain_whose_squares_underflow(scale):
    """Lengths of 1e-300 m: the generated segment length sqrt(dx^2 + dy^2) is 0, and midpoint
    and vi stopped at the initial state ('a spring segment came within 1e-06 of the geometry's
    size of zero length ...', exit 1) though the reader had taken the scene. The refusal names
    the largest of the lengths."""
    with pytest.raises(SceneError) as refused:
        parse_scene(tiny(scale), "arm.toml", "arm")
    size = 6.1 * float(f"1{scale}")     # 0.4 + 3 (1 + 0.5 + 0.4) times the scale
    assert str(refused.value) == (
        f"arm.toml: links[0].length: the largest of the chain's lengths (link lengths, coms, "
        f"fastenings), which sum to {size:.3g} m, below 1.49e-154 m: their squares in the "
        "energies, the mass matrix and the springs' segment lengths are subnormal or zero in a "
        f"double: write the scene in SI units (m), got {float(f'1{scale}')!r}")


def test_the_reader_refuses_a_mass_matrix_that_underflows():
    """Masses of 1e-200 kg at 1e-60 m, no inertia: sum m R^2 + J is 2.5e-320 kg m^2, a
    subnormal. midpoint stopped at step 1 on 'the converged step missed the energy balance
    ... (a spurious Newton root ...)', exit 1."""
    text = tiny("e-60").replace("mass = 1.0", "mass = 1e-200").replace("inertia = 1.0",
                                                                       "inertia = 0.0")
    with pytest.raises(SceneError) as refused:
        parse_scene(text, "arm.toml", "arm")
    assert str(refused.value).startswith(
        "arm.toml: links: the chain's mass matrix at the initial angles is at most ")
    assert str(refused.value).endswith(
        "kg m^2 (sum_i m_i R_i^2 + J_i), below the smallest normal double 2.23e-308: subnormal "
        "or zero, no step can solve with it (a mass, an inertia or a length far too small): "
        "write the scene in SI units (m, kg, kg m^2)")


@pytest.mark.parametrize("text", [
    tiny("e-150"),                                     # squares 1e-300: normal doubles
    BASE.replace("length = 1.0", "length = 1e-300", 1),    # beside lengths of 1 m: round-off
    BASE.replace("com = 0.5", "com = 0.0").replace("inertia = 1.0", "inertia = 1e-300"),
])
def test_the_reader_takes_small_numbers_whose_squares_are_doubles(text):
    parse_scene(text, "arm.toml", "arm")


def test_simulate_refuses_a_chain_whose_squares_underflow_in_one_line_exit_2(tmp_path):
    scene = tmp_path / "arm.toml"
    scene.write_text(tiny("e-300"))
    result = chaingen_in_process("simulate", scene, "--method", "midpoint", "--t-end", "0.1",
                                 "--out", "run.csv", cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"chaingen: error: {scene}: links[0].length: ")
    assert sorted(path.name for path in tmp_path.iterdir()) == ["arm.toml"]


# -- initial angles a double holds too coarsely for a step ------------------------------------

ANGLES = "angles = [0.7853981633974483, 0.3, 0.3]"


@pytest.mark.parametrize("angle, spacing", [("1e10", "1.9e-06"), ("-1048576.0", "2.3e-10"),
                                            ("1e300", "1.5e+284")])
def test_the_reader_refuses_an_initial_angle_beyond_2_to_the_20(angle, spacing):
    """From 1e10 rad (held to 1.9e-6 rad) midpoint's first step failed on 'a spurious Newton
    root of a step too long for the motion' (exit 1), and es ran on silently: 7.4e-7 rad off
    the same start given within its turn after 1 s (4.8e-5 at 1e12, 0.06 rad at 1e15)."""
    with pytest.raises(SceneError) as refused:
        parse_scene(edited((ANGLES, f"angles = [0.1, {angle}, 0.3]")), "arm.toml", "arm")
    assert str(refused.value) == (
        "arm.toml: initial.angles[1]: must be within +-2^20 = 1048576 rad (an angle in rad): a "
        f"double holds {float(angle):g} rad only to {spacing} rad, coarser than the 1e-10 of "
        "its unknowns a step resolves (update_rtol), so every step rounds the motion it takes; "
        f"subtract whole turns (2 pi k), from a [control] target too, got {float(angle)!r}")


def test_the_reader_refuses_a_control_target_beyond_2_to_the_20():
    """A [control] target is an angle the step works with as the start is (V_s's offset
    phi - phi*, the law's torque): 1e10 rad, held to 1.9e-6 rad, was read as it was."""
    text = scene_path("four_link_pbc").read_text()
    old = "target = [1.5707963267948966, 0.0, 0.0, 0.0]"
    assert old in text
    with pytest.raises(SceneError, match=r"^pbc\.toml: control\.target\[3\]: must be within "
                                         r"\+-2\^20 = 1048576 rad .* got 10000000000\.0$"):
        parse_scene(text.replace(old, "target = [1.5707963267948966, 0.0, 0.0, 1e10]"),
                    "pbc.toml", "pbc")
    parse_scene(text.replace(old, "target = [1.5707963267948966, 0.0, 0.0, 1e6]"), "pbc.toml",
                "pbc")


def test_a_control_target_given_at_run_time_is_held_within_2_to_the_20():
    """The same bound on a target given as a run-time parameter (Solver.simulate, step, a
    sweep's rows), checked where every parameter's range is."""
    from chaingen.runtime.parameters import parameter_vector

    paths = ("control.target[0]", "control.stiffness[0]")
    bounds = (np.array([-np.inf, 0.0]), np.array([False, False]))
    defaults = np.array([0.5, 10.0])
    assert parameter_vector({"control.target[0]": -1e6}, paths, defaults, bounds, "p")[0] == -1e6
    with pytest.raises(ValueError, match=r"^control\.target\[0\]: must be within \+-2\^20 = "
                                         r"1048576 rad .* got 10000000000\.0$"):
        parameter_vector([1e10, 10.0], paths, defaults, bounds, "p")


def test_the_spatial_reader_refuses_an_initial_angle_beyond_2_to_the_20():
    from chaingen.spatial import parse_spatial_scene

    old = "angles = [0.3, -0.5, 0.8]"
    assert old in SPATIAL
    with pytest.raises(SceneError, match=r"^arm\.toml: initial\.angles\[2\]: must be within "
                                         r"\+-2\^20 = 1048576 rad"):
        parse_spatial_scene(SPATIAL.replace(old, "angles = [0.3, -0.5, 1e10]"), "arm.toml")


@pytest.mark.compile
@pytest.mark.parametrize("method", ["es", "vi", "midpoint"])
def test_an_initial_angle_within_the_bound_runs_as_the_same_angle_within_its_turn(method):
    """phi_1 = 1e6 rad (held to 1.2e-10 rad) against 1e6 mod 2 pi, 100 steps of 0.01 s:
    measured 4.5e-11 rad apart (es), 1.9e-10 (midpoint), 0 (vi)."""
    from chaingen import build_solver

    turn = 5.925621140093852      # 1e6 mod 2 pi (mpmath, 40 digits)
    scene = parse_scene(edited((ANGLES, "angles = [1e6, 0.3, 0.3]")), "arm.toml", "arm")
    solver = build_solver(scene, method, 3, sensitivities=False)
    far, near = (solver.simulate([phi, 0.3, 0.3], [0.0] * 3, dt=0.01, n_steps=100)
                 for phi in (1e6, turn))
    apart = np.angle(np.exp(1j * (np.asarray(far.phi)[-1] - np.asarray(near.phi)[-1])))
    assert np.abs(apart).max() < 1e-9


# -- spatial: the same energies (its mass matrix and gravity torques were checked before) ------

SPATIAL = scene_path("spatial_three_link").read_text()


@pytest.mark.parametrize("old, new, message", [
    # Both failed at step 1 with 'missed the energy balance' (midpoint, es), exit 1.
    ("rest_length = 0.2", "rest_length = 1e300",
     "springs[0]: its energy 1/2 k (L - L_0)^2 at the initial angles is beyond the range of a "
     "double"),
    # Both failed at step 1 on NaN, exit 1.
    ("velocities = [0.0, 0.2, 0.0]", "velocities = [0.0, 1e160, 0.0]",
     "initial.velocities: the kinetic energy of the initial state is beyond the range of a "
     "double: write the rates in rad/s, got [0.0, 1e+160, 0.0]"),
])
def test_the_spatial_reader_refuses_energies_that_overflow(old, new, message):
    from chaingen.spatial import parse_spatial_scene

    assert old in SPATIAL
    with pytest.raises(SceneError) as refused:
        parse_spatial_scene(SPATIAL.replace(old, new, 1), "arm.toml")
    assert str(refused.value).startswith(f"arm.toml: {message}")


def test_the_spatial_reader_refuses_a_chain_whose_squares_underflow():
    """spatial_three_link with every xyz, com and route point times 1e-300: it was refused as
    'springs[0]: route[0] and route[1] are one point at every angle (on the axis of joint 1)',
    which they are not (their distance's square underflowed to 0)."""
    from chaingen.spatial import parse_spatial_scene

    def tiny(match: re.Match) -> str:
        return "[" + ", ".join(repr(float(x) * 1e-300) for x in match.group(1).split(",")) + "]"

    text = re.sub(r"(?<=xyz = )\[([^\]]*)\]|(?<=com = )\[([^\]]*)\]",
                  lambda m: tiny(re.match(r"\[([^\]]*)\]", m.group(0))), SPATIAL)
    text = re.sub(r"\[(\d), ([-0-9.e]+), ([-0-9.e]+), ([-0-9.e]+)\]", lambda m: (
        f"[{m.group(1)}, " + ", ".join(repr(float(m.group(k)) * 1e-300) for k in (2, 3, 4))
        + "]"), text)
    with pytest.raises(SceneError) as refused:
        parse_spatial_scene(text, "arm.toml")
    assert str(refused.value).startswith(
        "arm.toml: links[1].joint.xyz: the largest of the chain's lengths (joints' xyz, coms, "
        "route points), which sum to ")
    assert str(refused.value).endswith(
        "m, below 1.49e-154 m: their squares in the energies, the mass matrix and the springs' "
        "segment lengths are subnormal or zero in a double: write the scene in SI units (m), "
        "got [0.0, 2.0000000000000002e-302, 3.5e-301]")


def test_the_spatial_reader_reads_large_numbers_within_range():
    from chaingen.spatial import parse_spatial_scene

    for old, new in (("stiffness = 300.0", "stiffness = 1e300"), ("mass = 2.5", "mass = 1e300"),
                     ("velocities = [0.0, 0.2, 0.0]", "velocities = [0.0, 1e150, 0.0]")):
        parse_spatial_scene(SPATIAL.replace(old, new, 1), "arm.toml")


# -- es: a COM so near its joint that com^2 + com_normal^2 leaves a double's range ------------

@pytest.mark.parametrize("com, squared", [("5e-301", "0"), ("1e-160", "1e-320")])
def test_es_refuses_a_com_whose_square_leaves_the_range_of_a_double(com, squared):
    """com = 5e-301: c^2 = 0 was refused as 'com = com_normal = 0' (it is not); com = 1e-160:
    J / c^2 = inf went into the generated constants, and the run stopped at the initial state
    on 'a spring segment came within 1e-06 ... of zero length' (exit 1)."""
    from chaingen.errors import UnsupportedSceneError
    from chaingen.symbolic.com_model import coordinates

    scene = parse_scene(edited(("com = 0.5", f"com = {com}")), "arm.toml", "arm")
    with pytest.raises(UnsupportedSceneError) as refused:
        coordinates(scene)
    assert str(refused.value) == (
        f"links[0].com: COM coordinates divide by com^2 + com_normal^2, which is {squared} in "
        f"a double for link 1 (com = {com}, com_normal = 0 m, inertia 1 kg m^2: J / (com^2 + "
        "com_normal^2) is beyond the range of a double); move the COM off the proximal joint, "
        "or use vi or midpoint")


def test_es_takes_a_com_whose_square_is_a_double():
    from chaingen.symbolic.com_model import coordinates

    coordinates(parse_scene(edited(("com = 0.5", "com = 1e-150")), "arm.toml", "arm"))
    with pytest.raises(Exception, match="com = com_normal = 0"):
        coordinates(parse_scene(edited(("com = 0.5", "com = 0.0")), "arm.toml", "arm"))


HEAVY_ON_AXIS = """
gravity = [0.0, 0.0, -9.81]

[[links]]
mass = MASS
com = [0.0, 0.0, 0.2]
inertia = [0.01, 0.01, 0.001, 0.0, 0.0, 0.0]
joint = { xyz = [0.0, 0.0, 0.1], rpy = [0.0, 0.0, 0.0], axis = [0.0, 0.0, 1.0] }

[[links]]
mass = 1.0
com = [0.1, 0.0, 0.0]
inertia = [0.001, 0.01, 0.01, 0.0, 0.0, 0.0]
joint = { xyz = [0.0, 0.0, 0.4], rpy = [0.0, 0.0, 0.0], axis = [0.0, 1.0, 0.0] }
"""


@pytest.mark.parametrize("mass", ["1.0", "1e12", "1e300"])
def test_a_heavy_link_on_the_axis_does_not_hide_the_mass_the_joint_turns(mass):
    """Link 1 of 1e12 kg stands on joint 1's axis (its com 0.2 m up it); joint 1 turns link 1's
    izz = 0.001 kg m^2 and link 2, 1 kg 0.1 m off the axis: M_11 = 0.021 kg m^2. Against the
    links' summed inertia about joint 1's origin (4e10 kg m^2) that was below 1e-12 and the
    reader (and chaingen import of the same URDF) refused 'joint 1 moves no mass'."""
    from chaingen.spatial import parse_spatial_scene

    scene = parse_spatial_scene(HEAVY_ON_AXIS.replace("MASS", mass), "arm.toml")
    assert scene.links[0].mass == float(mass)


def test_a_point_mass_on_the_axis_is_still_refused():
    from chaingen.spatial import parse_spatial_scene

    text = (HEAVY_ON_AXIS.replace("MASS", "1.0")
            .replace("inertia = [0.01, 0.01, 0.001, 0.0, 0.0, 0.0]",
                     "inertia = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]")
            .replace("com = [0.1, 0.0, 0.0]", "com = [0.0, 0.0, 0.3]")
            .replace("inertia = [0.001, 0.01, 0.01, 0.0, 0.0, 0.0]",
                     "inertia = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0]"))
    with pytest.raises(SceneError, match=r"arm.toml: links\[0\]: joint 1 moves no mass"):
        parse_spatial_scene(text, "arm.toml")
