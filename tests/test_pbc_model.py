"""Passivity-based control without a compiler: the [control] table, the refusals, and the exact
discrete gradient of the shaping potential (docs/controllers.md, "Passivity-based control")."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import sympy as sp
from hypothesis import assume, example, given, settings
from hypothesis import strategies as st

from chaingen.errors import SceneError
from chaingen.scene import SolverSpec, SolverSpecError, load_scene, parse_scene
from chaingen.scene.document import scene_toml
from chaingen.scene.values import Control
from chaingen.studies.control import shaping_potential as numpy_shaping_potential
from chaingen.symbolic.recursion import Definitions
from chaingen.symbolic.shaping import discrete_shaping_gradient, shaping_potential, sinc

FULL = load_scene("four_link_pbc")
PARTIAL = load_scene("four_link_pbc_partial")


def _off_the_cut(scene, phi0, step, actuated) -> bool:
    """Whether no actuated joint's step crosses its target's antipode, the cut of V_d's
    wrapped quadratic (docs/controllers.md), where the identity is not asked."""
    target = np.array(scene.control.target)[actuated]
    offsets = np.angle(np.exp(1j * (phi0[actuated] - target)))
    return bool(np.all(np.abs(offsets + step[actuated]) < np.pi))


def _numeric_gradient(scene):
    """numpy (start, increments) -> G of discrete_shaping_gradient, definitions substituted."""
    count = len(scene.actuated_joints)
    start = sp.symbols(f"a0:{count}", real=True)
    steps = sp.symbols(f"d0:{count}", real=True)
    defs = Definitions("t_")
    gradient = sp.Matrix(discrete_shaping_gradient(scene, start, steps, defs))
    for symbol, expr in reversed(defs.items):
        gradient = gradient.xreplace({symbol: expr})
    return sp.lambdify([start, steps], list(gradient), modules="numpy")


GRADIENTS = {scene.name: _numeric_gradient(scene) for scene in (FULL, PARTIAL)}


@settings(max_examples=60, deadline=None)
@given(which=st.sampled_from([FULL, PARTIAL]),
       start=st.lists(st.floats(-3.0, 3.0), min_size=4, max_size=4),
       direction=st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4),
       size=st.floats(-12.0, 0.0))
@example(which=FULL, start=[0.421875, 0.0, 0.0, -0.25], direction=[1.0, 0.0, 0.0, 0.0], size=0.0)
def test_the_discrete_gradient_is_exact_for_any_step(which, start, direction, size):
    """G . (phi_1 - phi_0) = V_s(phi_1) - V_s(phi_0) to round-off of V_s, for steps from
    1e-12 rad to 1 rad (no quadrature, no division by the step), and V_s is the numpy one of
    the study (an independent construction from chaingen.scene.kinematics). Off the cut of V_d's
    wrapped quadratic, the target's antipode. Round-off is of the largest term compared: the
    example, a 1 rad step with G . dphi = -57.4 J against V_s(phi_0) = 0.48 J, misses by 1.5e-13 J,
    2.6e-15 of the terms (the scale was |V_s(phi_0)| + 1 alone: 1.48e-13)."""
    count = len(which.actuated_joints)
    actuated = np.array(which.actuated_joints) - 1
    phi0 = np.array(which.control.target, dtype=float)
    phi0[actuated] = np.array(start)[:count]
    step = np.zeros(4)
    step[actuated] = np.array(direction)[:count] * 10.0 ** size
    assume(_off_the_cut(which, phi0, step, actuated))
    g = np.array(GRADIENTS[which.name](phi0[actuated], step[actuated]), dtype=float)
    change = (numpy_shaping_potential(which, phi0 + step)
              - numpy_shaping_potential(which, phi0))
    scale = (abs(numpy_shaping_potential(which, phi0))
             + abs(numpy_shaping_potential(which, phi0 + step))
             + np.abs(g * step[actuated]).sum() + 1.0)
    assert abs(g @ step[actuated] - change) <= 1e-13 * scale


def test_the_symbolic_and_numpy_shaping_potentials_agree():
    rng = np.random.default_rng(3)
    for scene in (FULL, PARTIAL):
        symbols = sp.symbols(f"p0:{len(scene.actuated_joints)}", real=True)
        potential = sp.lambdify([symbols], shaping_potential(scene, symbols))
        actuated = np.array(scene.actuated_joints) - 1
        for _ in range(5):
            phi = rng.uniform(-3, 3, scene.n)
            phi[[j for j in range(scene.n) if j not in actuated]] = \
                np.array(scene.control.target)[[j for j in range(scene.n) if j not in actuated]]
            assert potential(phi[actuated]) == pytest.approx(
                numpy_shaping_potential(scene, phi), rel=1e-12, abs=1e-12)


def test_at_a_zero_step_the_discrete_gradient_is_the_gradient():
    symbols = sp.symbols("p0:4", real=True)
    phi = np.array([0.4, -0.7, 1.1, 0.2])
    exact = [float(sp.diff(shaping_potential(FULL, symbols), s).subs(dict(zip(symbols, phi))))
             for s in symbols]
    assert np.allclose(GRADIENTS[FULL.name](phi, np.zeros(4)), exact, rtol=1e-13, atol=1e-13)


@pytest.mark.parametrize("h", [0.0, 1e-12, 1e-4, 9.99e-4, 1e-3, 1.001e-3, 0.3, 1.5])
def test_sinc_has_no_branch_and_no_zero_over_zero(h):
    value = float(sinc(sp.Float(h)))
    expected = 1.0 if h == 0 else np.sin(h) / h
    assert value == pytest.approx(expected, rel=1e-15)


def test_a_controlled_scene_reads_and_writes_back():
    assert FULL.control.target[0] == pytest.approx(np.pi / 2)
    assert FULL.control.stiffness == (40.0, 20.0, 10.0, 5.0)
    assert PARTIAL.actuated_joints == (1, 2, 4) and len(PARTIAL.control.damping) == 3
    again = parse_scene(scene_toml(PARTIAL), "again.toml", "again")
    assert again.control == PARTIAL.control


def _with_control(table: str) -> str:
    text = scene_toml(dataclasses.replace(FULL, control=None))
    return text + "\n[control]\n" + table + "\n"


@pytest.mark.parametrize("table, message", [
    ("stiffness = [1.0, 1.0, 1.0, 1.0]", "control.target: missing"),
    ("target = [0.0, 0.0, 0.0]\nstiffness = [1.0, 1.0, 1.0, 1.0]",
     "control.target: must have 4 entries"),
    ("target = [0.0, 0.0, 0.0, 0.0]\nstiffness = [1.0, 1.0]",
     "control.stiffness: must have 4 entries (one per actuated joint [1, 2, 3, 4])"),
    ("target = [0.0, 0.0, 0.0, 0.0]\nstiffness = [1.0, 0.0, 1.0, 1.0]",
     "control.stiffness[1]: must be > 0"),
    ("target = [0.0, 0.0, 0.0, 0.0]\nstiffness = [1.0, 1.0, 1.0, 1.0]\n"
     "damping = [1.0, -1.0, 1.0, 1.0]", "control.damping[1]: must be >= 0"),
    ("target = [0.0, 0.0, 0.0, 0.0]\nstiffness = [1.0, 1.0, 1.0, 1.0]\nlaw = \"zoh\"",
     'control.law: must be one of "discrete", "sampled"'),
    ("target = [0.0, 0.0, 0.0, 0.0]\nstiffness = [1.0, 1.0, 1.0, 1.0]\ncompensate = 1",
     "control.compensate: must be true or false"),
    ("target = [0.0, 0.0, 0.0, 0.0]\nstiffness = [1.0, 1.0, 1.0, 1.0]\ngain = 2",
     "control.gain: unknown key"),
])
def test_a_bad_control_table_is_one_line_naming_the_key(table, message):
    with pytest.raises(SceneError) as raised:
        parse_scene(_with_control(table), "bad.toml", "bad")
    assert message in str(raised.value) and "\n" not in str(raised.value)


def test_control_without_actuation_is_refused():
    text = scene_toml(dataclasses.replace(FULL, control=None, actuated_joints=()))
    text += "\n[control]\ntarget = [0.0, 0.0, 0.0, 0.0]\nstiffness = [1.0]\n"
    with pytest.raises(SceneError, match="control: needs actuated joints"):
        parse_scene(text, "bad.toml", "bad")


@pytest.mark.parametrize("method, order, key", [("vi", 2, "method"), ("es", 4, "order"),
                                                ("midpoint", 6, "order")])
def test_solvers_without_a_controlled_step_are_refused(method, order, key):
    with pytest.raises(SolverSpecError, match=key):
        SolverSpec.create(FULL, method, 3, order=order)


def test_the_quadratic_is_wrapped_so_that_plus_minus_pi_is_no_jump():
    """V_d's quadratic is in phi - phi* wrapped to (-pi, pi]: a joint at pi and at -pi (the
    same posture, which es's state reports either way) has one V_s."""
    symbols = sp.symbols("p0:4", real=True)
    potential = sp.lambdify([symbols], shaping_potential(FULL, symbols))
    here = np.array([0.4, -0.7, 1.1, np.pi - 1e-12])
    there = here.copy()
    there[3] -= 2 * np.pi
    assert potential(here) == pytest.approx(potential(there), rel=1e-12)


def test_a_scene_without_control_keeps_its_cache_key():
    """Adding the control field changed no other package (generated/ is byte for byte)."""
    from chaingen.generate.key import input_hash
    plain = dataclasses.replace(FULL, control=None)
    assert input_hash(plain, "es", 3) != input_hash(FULL, "es", 3)
    other = dataclasses.replace(FULL, control=Control((0.0,) * 4, (1.0,) * 4, (0.0,) * 4))
    assert input_hash(other, "es", 3) != input_hash(FULL, "es", 3)


# -- spatial scenes -----------------------------------------------------------------------

def _spatial_scene():
    from chaingen.spatial import load_spatial_scene
    base = load_spatial_scene("spatial_three_link")
    return dataclasses.replace(base, actuated=(1, 3),
                               control=Control((0.3, -0.2, 0.5), (20.0, 5.0), (5.0, 1.0)))


SPATIAL = _spatial_scene()


def _spatial_gradient(scene):
    from chaingen.symbolic.schemes.base import numpy_function
    from chaingen.symbolic.spatial_shaping import discrete_shaping_gradient as spatial_gradient
    count = len(scene.actuated)
    start = sp.symbols(f"a0:{count}", real=True)
    steps = sp.symbols(f"d0:{count}", real=True)
    defs = Definitions("t_")
    gradient = spatial_gradient(scene, start, steps, defs)
    return numpy_function(list(start) + list(steps), tuple(defs.items), gradient)


SPATIAL_GRADIENT = _spatial_gradient(SPATIAL)


@settings(max_examples=60, deadline=None)
@given(start=st.lists(st.floats(-3.0, 3.0), min_size=2, max_size=2),
       direction=st.lists(st.floats(-1.0, 1.0), min_size=2, max_size=2),
       size=st.floats(-12.0, 0.0))
def test_the_spatial_discrete_gradient_is_exact_for_any_step(start, direction, size):
    """The telescoping product rule over the rotation factors: G . dphi = V_s(phi_1) -
    V_s(phi_0) to round-off, V_s from chaingen.spatial.dynamics' numpy potential."""
    actuated = np.array(SPATIAL.actuated) - 1
    phi0 = np.array(SPATIAL.control.target, dtype=float)
    phi0[actuated] = start
    step = np.zeros(3)
    step[actuated] = np.array(direction) * 10.0 ** size
    assume(_off_the_cut(SPATIAL, phi0, step, actuated))
    g = np.array(SPATIAL_GRADIENT(*phi0[actuated], *step[actuated]), dtype=float)
    change = (numpy_shaping_potential(SPATIAL, phi0 + step)
              - numpy_shaping_potential(SPATIAL, phi0))
    scale = abs(numpy_shaping_potential(SPATIAL, phi0)) + 1.0
    assert abs(g @ step[actuated] - change) <= 1e-13 * scale


def test_a_spatial_control_table_reads_writes_back_and_takes_key_paths():
    from chaingen.spatial import parameters as spatial_parameters
    from chaingen.spatial.reader import parse_spatial_scene
    from chaingen.spatial.writer import scene_text
    again = parse_spatial_scene(scene_text(SPATIAL), "again.toml", "again")
    assert again.control == SPATIAL.control
    assert "control.damping[1]" in spatial_parameters.compiled_paths(SPATIAL)
    changed = spatial_parameters.with_values(SPATIAL, {"control.stiffness[1]": 7.5})
    assert changed.control.stiffness == (20.0, 7.5)
    with pytest.raises(SceneError, match=r"control\.stiffness\[1\]: must be > 0"):
        spatial_parameters.with_values(SPATIAL, {"control.stiffness[1]": -1.0})
    with pytest.raises(SceneError, match="has 2 entries"):
        spatial_parameters.number_path(SPATIAL, "control.damping[2]")


@pytest.mark.parametrize("scene, links", [("four_link_pbc", 4), ("panda_pbc", 7),
                                          ("three_link_mono", 3), ("spatial_three_link", 3)])
def test_exporting_a_controlled_scene_says_the_mjcf_is_the_plant(scene, links, tmp_path):
    """MJCF has no counterpart of the [control] law: the export writes the plant and says so,
    on the command line and in a comment at the head of the file (which outlives the command's
    output), so that a MuJoCo run of it is not taken for the closed loop; a scene without a
    law gets neither. MuJoCo reads the file as before."""
    from helpers import chaingen_in_process
    out = tmp_path / "arm.xml"
    result = chaingen_in_process("export", scene, "--mjcf", out, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    controlled = scene.endswith("_pbc")
    said = "the plant only: the scene's [control] law is not in the MJCF" in result.stdout
    assert said == controlled, result.stdout
    head = out.read_text().splitlines()[1]
    comment = ('  <!-- The plant only, no controller: the scene\'s [control] law (law = '
               '"discrete": energy shaping to its target with damping injection, '
               'docs/controllers.md) is not in this model. Its motors are the inputs: drive '
               'data.ctrl with the law yourself. -->')
    assert (head == comment) == controlled, head
    assert ("<!--" in out.read_text()) == controlled
    mujoco = pytest.importorskip("mujoco")
    assert mujoco.MjModel.from_xml_path(str(out)).nq == links
