"""The MuJoCo reference model (model.md section 10) against the spec's own formulas.

The energies are checked against a forward kinematics written here straight from model.md
sections 1-3, independently of codegen: this is what makes MuJoCo a trustworthy reference for
the generated solvers.
"""
from __future__ import annotations

import dataclasses
import math
import pathlib

import numpy as np
import pytest

mujoco = pytest.importorskip("mujoco")

from chaingen.reference.mjcf import mjcf_from_scene  # noqa: E402
from chaingen.reference.mujoco_runs import (  # noqa: E402
    MujocoTrajectory,
    initial_energy_mujoco,
    simulate_mujoco,
)
from chaingen.scene import Scene, Spring, load_scene  # noqa: E402

ROOT = pathlib.Path(__file__).resolve().parents[1]
REFERENCE_SCENES = [ROOT / "scenes" / f"three_link_{kind}.toml"
                    for kind in ("gravity", "mono", "multi")]
OWN_SCENES = [ROOT / "tests" / "scenes" / "four_link_antagonist.toml",
              ROOT / "tests" / "scenes" / "five_link_biarticular.toml"]
ALL_SCENES = REFERENCE_SCENES + OWN_SCENES


def model_of(scene: Scene, dt: float = 1e-3, integrator: str = "RK4"):
    return mujoco.MjModel.from_xml_string(mjcf_from_scene(scene, dt=dt, integrator=integrator))


# ---------------------------------------------------------------------------------------------
# The model of model.md sections 1-3, written out in numpy (complex-safe: no abs, no hypot).

def spec_kinematics(scene: Scene, phi):
    """Absolute angles theta_i, COM positions x_i and the fastening points of every spring."""
    theta = np.cumsum(np.asarray(phi))
    e = [np.array([1.0, 0.0])] + [np.array([np.cos(t), np.sin(t)]) for t in theta]
    normal = [np.array([-v[1], v[0]]) for v in e]         # n = S e, S = [[0,-1],[1,0]]
    joints = [np.zeros(2)]                                # X_1 = 0
    coms = []
    for i, link in enumerate(scene.links, start=1):
        coms.append(joints[i - 1] + link.com * e[i] + link.com_normal * normal[i])
        joints.append(joints[i - 1] + link.length * e[i])

    def fastening(j, r):                                   # P_j = X_j + r_j n_{j-1}
        return joints[j - 1] + r * normal[j - 1]

    spring_points = [
        [fastening(j, r) for j, r in zip(range(s.first, s.last + 2), scene.spring_fastenings(s))]
        for s in scene.springs]
    return theta, np.array(coms), spring_points


def spec_potential_energy(scene: Scene, phi) -> float:
    """V = sum_i m_i g y_i + sum_springs 1/2 k (sum_j s_j - S_0)^2 (model.md sections 2, 3)."""
    _, coms, spring_points = spec_kinematics(scene, phi)
    v = sum(link.mass * scene.gravity * y for link, y in zip(scene.links, coms[:, 1]))
    for spring, points in zip(scene.springs, spring_points):
        length = sum(math.sqrt(float(np.dot(b - a, b - a))) for a, b in zip(points, points[1:]))
        v += 0.5 * spring.stiffness * (length - spring.rest_length) ** 2
    return float(v)


def spec_kinetic_energy(scene: Scene, phi, phidot) -> float:
    """T = sum_i 1/2 m_i |xdot_i|^2 + 1/2 J_i thetadot_i^2 (model.md section 3).

    xdot_i is the directional derivative of x_i(phi) along phidot by the complex step
    (exact to round-off: x is analytic and the step adds no cancellation).
    """
    h = 1e-30
    _, coms, _ = spec_kinematics(scene, np.asarray(phi) + 1j * h * np.asarray(phidot))
    com_velocities = coms.imag / h
    thetadot = np.cumsum(phidot)
    return float(sum(0.5 * link.mass * np.dot(v, v) + 0.5 * link.inertia * w ** 2
                     for link, v, w in zip(scene.links, com_velocities, thetadot)))


def mujoco_energy(scene: Scene, phi, phidot):
    model = model_of(scene)
    data = mujoco.MjData(model)
    data.qpos[:] = phi
    data.qvel[:] = phidot
    mujoco.mj_forward(model, data)
    return float(data.energy[0]), float(data.energy[1])


def scene_id(path: pathlib.Path) -> str:
    return path.stem


# ---------------------------------------------------------------------------------------------
# (a) the MJCF is the scene

@pytest.mark.parametrize("path", ALL_SCENES, ids=scene_id)
def test_mjcf_fields_match_the_scene(path):
    scene = load_scene(path)
    n = scene.n
    model = model_of(scene, dt=2.5e-4)

    assert model.opt.timestep == 2.5e-4
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4
    np.testing.assert_array_equal(model.opt.gravity, [0.0, -scene.gravity, 0.0])
    assert model.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_CONTACT
    assert model.opt.enableflags & mujoco.mjtEnableBit.mjENBL_ENERGY

    # One body per link, each the child of the previous one, at (L_{i-1}, 0, 0) in it.
    assert model.nbody == n + 1 and model.njnt == n and model.nv == n and model.nq == n
    np.testing.assert_array_equal(model.body_parentid, [0] + list(range(n)))
    lengths = [link.length for link in scene.links]
    np.testing.assert_array_equal(model.body_pos[1:], [[x, 0.0, 0.0] for x in [0.0] + lengths[:-1]])
    np.testing.assert_array_equal(model.body_quat[1:], [[1.0, 0.0, 0.0, 0.0]] * n)
    # A hinge about z at each body's origin, nothing else on it.
    assert all(t == mujoco.mjtJoint.mjJNT_HINGE for t in model.jnt_type)
    np.testing.assert_array_equal(model.jnt_bodyid, range(1, n + 1))
    np.testing.assert_array_equal(model.jnt_axis, [[0.0, 0.0, 1.0]] * n)
    np.testing.assert_array_equal(model.jnt_pos, np.zeros((n, 3)))
    assert not model.jnt_limited.any()
    np.testing.assert_array_equal(model.jnt_stiffness, np.zeros(n))
    np.testing.assert_array_equal(model.dof_armature, np.zeros(n))
    np.testing.assert_array_equal(model.dof_frictionloss, np.zeros(n))
    np.testing.assert_array_equal(model.dof_damping, [link.damping for link in scene.links])
    # Mass, COM (a_i, b_i) and J_i, exactly as written (repr round-trips).
    np.testing.assert_array_equal(model.body_mass[1:], [link.mass for link in scene.links])
    np.testing.assert_array_equal(model.body_ipos[1:],
                                  [[link.com, link.com_normal, 0.0] for link in scene.links])
    np.testing.assert_array_equal(model.body_inertia[1:],
                                  [[link.inertia] * 3 for link in scene.links])
    np.testing.assert_array_equal(model.body_iquat[1:], [[1.0, 0.0, 0.0, 0.0]] * n)

    # One spatial tendon per spring, through sites at P_first .. P_{last+1}: fastening P_j sits
    # on body j-1 at (L_{j-1}, r_j, 0) (on the world body at (0, r_1, 0)).
    assert model.ntendon == len(scene.springs)
    for k, spring in enumerate(scene.springs):
        assert model.tendon_stiffness[k] == spring.stiffness
        np.testing.assert_array_equal(model.tendon_lengthspring[k], [spring.rest_length] * 2)
        assert model.tendon_damping[k] == 0.0
        assert not model.tendon_limited[k]
        adr, num = model.tendon_adr[k], model.tendon_num[k]
        assert num == spring.last - spring.first + 2
        assert all(t == mujoco.mjtWrap.mjWRAP_SITE for t in model.wrap_type[adr:adr + num])
        sites = model.wrap_objid[adr:adr + num]
        for j, r, site in zip(range(spring.first, spring.last + 2),
                              scene.spring_fastenings(spring), sites):
            assert model.site_bodyid[site] == j - 1
            x = 0.0 if j == 1 else scene.links[j - 2].length
            np.testing.assert_array_equal(model.site_pos[site], [x, r, 0.0])


def test_hinge_damping_and_unrounded_numbers():
    scene = load_scene(ROOT / "scenes" / "three_link_mono.toml")
    odd = 0.1 + 0.2                       # 0.30000000000000004: survives only if not rounded
    links = (dataclasses.replace(scene.links[0], damping=0.25, mass=odd),) + scene.links[1:]
    scene = dataclasses.replace(scene, links=links)
    model = model_of(scene, dt=1.0 / 3.0, integrator="implicitfast")
    np.testing.assert_array_equal(model.dof_damping, [0.25, 0.0, 0.0])
    assert model.body_mass[1] == odd
    assert model.opt.timestep == 1.0 / 3.0
    assert model.opt.integrator == mujoco.mjtIntegrator.mjINT_IMPLICITFAST


def test_zero_inertia_is_refused_clearly():
    scene = load_scene(ROOT / "scenes" / "three_link_mono.toml")
    links = scene.links[:1] + (dataclasses.replace(scene.links[1], inertia=0.0),) + scene.links[2:]
    with pytest.raises(ValueError, match=r"links\[1\]\.inertia: MuJoCo cannot represent"):
        mjcf_from_scene(dataclasses.replace(scene, links=links), dt=1e-3)


def test_unknown_integrator_is_refused():
    scene = load_scene(ROOT / "scenes" / "three_link_mono.toml")
    with pytest.raises(ValueError, match="integrator"):
        mjcf_from_scene(scene, dt=1e-3, integrator="rk4")


# ---------------------------------------------------------------------------------------------
# (b), (c) MuJoCo's energies are the spec's

@pytest.mark.parametrize("path", ALL_SCENES, ids=scene_id)
def test_potential_energy_is_the_spec_potential(path):
    scene = load_scene(path)
    rng = np.random.default_rng(20240611)
    for _ in range(5):
        phi = rng.uniform(-math.pi, math.pi, scene.n)
        potential, kinetic = mujoco_energy(scene, phi, np.zeros(scene.n))
        assert kinetic == 0.0
        expected = spec_potential_energy(scene, phi)
        assert potential == pytest.approx(expected, rel=1e-12, abs=1e-12)


@pytest.mark.parametrize("path", ALL_SCENES, ids=scene_id)
def test_kinetic_energy_is_the_spec_kinetic_energy(path):
    scene = load_scene(path)
    rng = np.random.default_rng(7)
    for _ in range(5):
        phi = rng.uniform(-math.pi, math.pi, scene.n)
        phidot = rng.uniform(-2.0, 2.0, scene.n)
        _, kinetic = mujoco_energy(scene, phi, phidot)
        assert kinetic == pytest.approx(spec_kinetic_energy(scene, phi, phidot), rel=1e-12)


@pytest.mark.parametrize("path", ALL_SCENES, ids=scene_id)
def test_initial_energy_is_the_spec_energy(path):
    scene = load_scene(path)
    expected = (spec_potential_energy(scene, scene.initial_angles)
                + spec_kinetic_energy(scene, scene.initial_angles, scene.initial_velocities))
    assert initial_energy_mujoco(scene) == pytest.approx(expected, rel=1e-12)


# ---------------------------------------------------------------------------------------------
# (d) the reference is converged, and sampling does not disturb it

def test_rk4_converges_as_model_md_section_10_claims():
    scene = load_scene(ROOT / "scenes" / "three_link_mono.toml")
    coarse = simulate_mujoco(scene, dt=1e-4, t_end=1.0, sample_times=(0.5, 1.0))
    fine = simulate_mujoco(scene, dt=2.5e-5, t_end=1.0, sample_times=(0.5, 1.0))
    assert isinstance(coarse, MujocoTrajectory)
    assert coarse.steps == (5000, 10000) and fine.steps == (20000, 40000)
    np.testing.assert_allclose(coarse.angles, fine.angles, rtol=0.0, atol=1e-10)
    np.testing.assert_allclose(coarse.velocities, fine.velocities, rtol=0.0, atol=1e-9)
    # No damping: RK4 at this step keeps H to round-off level.
    np.testing.assert_allclose(coarse.energies, coarse.initial_energy, rtol=0.0, atol=1e-11)


@pytest.mark.parametrize("path", OWN_SCENES, ids=scene_id)
def test_sampling_does_not_change_the_trajectory(path):
    scene = load_scene(path)
    sampled = simulate_mujoco(scene, dt=1e-3, t_end=0.3, sample_times=(0.3, 0.0, 0.1))
    unsampled = simulate_mujoco(scene, dt=1e-3, t_end=0.3)
    np.testing.assert_array_equal(sampled.angles[0], unsampled.final_angles)
    np.testing.assert_array_equal(sampled.angles[1], scene.initial_angles)
    np.testing.assert_array_equal(sampled.velocities[1], scene.initial_velocities)
    assert sampled.energies[1] == sampled.initial_energy
    assert sampled.energies[0] == unsampled.final_energy
    assert sampled.angles.shape == (3, scene.n) and not sampled.angles.flags.writeable


def test_sample_times_must_be_whole_steps_within_the_run():
    scene = load_scene(ROOT / "scenes" / "three_link_mono.toml")
    with pytest.raises(ValueError, match="whole number of steps"):
        simulate_mujoco(scene, dt=1e-3, t_end=0.01, sample_times=(0.0005,))
    with pytest.raises(ValueError, match="after t_end"):
        simulate_mujoco(scene, dt=1e-3, t_end=0.01, sample_times=(0.02,))


# ---------------------------------------------------------------------------------------------
# The test scenes are what they claim to be

def _shortest_reachable_length(scene: Scene, spring: Spring) -> float:
    """Sum over segments of | sqrt(L_j^2 + r_{j+1}^2) - |r_j| | (model.md section 2)."""
    r = scene.spring_fastenings(spring)
    return sum(abs(math.hypot(scene.links[j - 1].length, r[k + 1]) - abs(r[k]))
               for k, j in enumerate(spring.joints))


@pytest.mark.parametrize("path", OWN_SCENES, ids=scene_id)
def test_own_scenes_cover_offaxis_multiarticular_and_antagonistic_springs(path):
    scene = load_scene(path)
    assert scene.n >= 4 and scene.gravity > 0.0
    assert any(link.com_normal != 0.0 for link in scene.links)
    assert all(link.inertia > 0.0 for link in scene.links)
    assert any(s.is_multi_articular for s in scene.springs)
    assert any(v != 0.0 for v in scene.initial_velocities)
    sides = {}
    for s in scene.springs:
        r = scene.spring_fastenings(s)
        side = 1 if all(x > 0 for x in r) else -1 if all(x < 0 for x in r) else 0
        sides.setdefault(s.joints, set()).add(side)
    assert any({1, -1} <= found for found in sides.values()), "no antagonistic pair"
    # Always in tension, whatever the configuration: no segment can come near zero length.
    for s in scene.springs:
        assert _shortest_reachable_length(scene, s) > s.rest_length
        r = scene.spring_fastenings(s)
        for k, j in enumerate(s.joints):
            assert math.hypot(scene.links[j - 1].length, r[k + 1]) - abs(r[k]) > 0.25
