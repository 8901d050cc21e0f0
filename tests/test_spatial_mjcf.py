"""MuJoCo as the second reference of the spatial dynamics (docs/spatial-mujoco.md).

Differential tests: the MJCF of random spatial chains (skew axes, joint origins turned by rpy,
off-axis centres of mass, full inertia tensors, springs through via points on the base and on
links near and far apart, damping, motors) gives MuJoCo the poses, mass matrix, generalized
gravity, tendon lengths, passive forces and energies of chaingen.spatial.dynamics; MuJoCo's
runs of the model (simulate_spatial_mujoco) agree with SciPy's DOP853 on the equations of
motion written from chaingen.spatial.dynamics and Pinocchio, and with a compound pendulum's ODE.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import solve_ivp
from test_spatial_dynamics import pinocchio_model, random_scene

from chaingen.reference.spatial_mjcf import spatial_mjcf_from_scene
from chaingen.reference.spatial_mujoco import (
    simulate_spatial_mujoco,
    spatial_mujoco_model_and_data,
)
from chaingen.spatial import dynamics
from chaingen.spatial.values import RoutePoint, SpatialJoint, SpatialLink, SpatialSpring

from helpers import require_module

mujoco = pytest.importorskip("mujoco")


def physical_inertias(scene):
    """`scene` with each link's inertia tensor S (positive definite) replaced by trace(S) 1 - S:
    a rigid body's tensor whose principal moments satisfy A + B >= C (random_scene's need not,
    and MuJoCo refuses those), full and skew as S."""
    links = []
    for link in scene.links:
        second = np.array(link.inertia_matrix())
        inertia = np.trace(second) * np.eye(3) - second
        links.append(dataclasses.replace(link, inertia=(
            inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2],
            inertia[1, 2])))
    return dataclasses.replace(scene, links=tuple(links))


def via_point_scene(seed: int, n: int, *, conservative: bool = False):
    """random_scene(seed, n) with physical inertias and three springs routed through 2 to 5
    points on random links (the base included, several points on one link, links far apart,
    in any order); unless `conservative`, damped joints and motors on a random subset."""
    rng = np.random.default_rng(seed + 7)
    scene = physical_inertias(random_scene(seed, n))
    springs = []
    for _ in range(3):
        links = rng.integers(0, n + 1, size=int(rng.integers(2, 6)))
        if len(set(links)) == 1:                   # a spring on one link has a fixed length
            links[-1] = (links[0] + 1) % (n + 1)
        springs.append(SpatialSpring(
            tuple(RoutePoint(int(link), tuple(0.15 * rng.normal(size=3))) for link in links),
            float(rng.uniform(10.0, 400.0)), float(rng.uniform(0.0, 0.4))))
    links = scene.links
    actuated = ()
    if not conservative:
        links = tuple(dataclasses.replace(link, damping=float(rng.uniform(0.0, 2.0)))
                      for link in links)
        actuated = tuple(j for j in range(1, n + 1) if rng.random() < 0.5)
    return dataclasses.replace(
        scene, links=links, springs=tuple(springs), actuated=actuated,
        initial_angles=tuple(rng.uniform(-np.pi, np.pi, n)),
        initial_velocities=tuple(rng.normal(size=n)))


def loaded(scene, dt: float = 1e-3, integrator: str = "RK4"):
    model = mujoco.MjModel.from_xml_string(
        spatial_mjcf_from_scene(scene, dt=dt, integrator=integrator))
    return model, mujoco.MjData(model)


def full_mass_matrix(model, data) -> np.ndarray:
    """MuJoCo's M(q) after mj_forward, dense. mj_fullM takes (model, data, M) since MuJoCo 4
    and (model, M, qM) before (pyproject admits mujoco >= 3.1)."""
    mass = np.zeros((model.nv, model.nv))
    try:
        mujoco.mj_fullM(model, data, mass)
    except TypeError:
        mujoco.mj_fullM(model, mass, data.qM)
    return mass


def relative_error(ours, theirs) -> float:
    ours, theirs = np.asarray(ours, dtype=float), np.asarray(theirs, dtype=float)
    return float(np.abs(ours - theirs).max() / max(np.abs(theirs).max(), 1e-300))


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 7))
def test_mujoco_has_the_dynamics_of_the_scene(seed, n):
    """At a random configuration and zero velocity: poses, route points, M (mj_fullM), the
    bias force (generalized gravity), tendon lengths and passive forces (-dV_s/dq) to 1e-10
    relative; at a random velocity: the damping in the passive forces and both energies."""
    scene = via_point_scene(seed, n)
    model, data = loaded(scene)
    rng = np.random.default_rng(seed + 11)
    q = rng.uniform(-np.pi, np.pi, n)
    data.qpos[:] = q
    mujoco.mj_forward(model, data)

    poses = dynamics.link_poses(scene, q)
    assert relative_error(data.xmat[1:].reshape(n, 3, 3), [r for r, _ in poses[1:]]) <= 1e-12
    assert np.abs(data.xpos[1:] - [p for _, p in poses[1:]]).max() <= 1e-12
    sites = np.concatenate(dynamics.route_positions(scene, q))
    names = [f"spring{k}_point{j}" for k, s in enumerate(scene.springs)
             for j in range(len(s.route))]
    assert np.abs(np.array([data.site(name).xpos for name in names]) - sites).max() <= 1e-12

    mass = full_mass_matrix(model, data)
    assert relative_error(mass, dynamics.mass_matrix(scene, q)) <= 1e-10
    assert relative_error(data.qfrc_bias, dynamics.gravity_torques(scene, q)) <= 1e-10
    assert relative_error(data.ten_length, dynamics.spring_lengths(scene, q)) <= 1e-10
    spring = dynamics.spring_torques(scene, q)
    assert relative_error(data.qfrc_passive, -spring) <= 1e-10
    assert relative_error(data.energy[0], dynamics.potential_energy(scene, q)) <= 1e-10

    velocities = rng.normal(size=n)
    data.qvel[:] = velocities
    mujoco.mj_forward(model, data)
    damping = np.array([link.damping for link in scene.links])
    assert relative_error(data.qfrc_passive, -spring - damping * velocities) <= 1e-10
    assert relative_error(data.energy[1],
                          dynamics.kinetic_energy(scene, q, velocities)) <= 1e-10
    assert relative_error(data.energy[0], dynamics.potential_energy(scene, q)) <= 1e-10


def test_euler_angles_are_urdfs_fixed_axis_roll_pitch_yaw():
    """One joint origin turned by each of roll, pitch, yaw alone and by all three: MuJoCo's
    body frame at q = 0 is rpy_matrix (Rz Ry Rx); MuJoCo's default sequence "xyz" (intrinsic,
    Rx Ry Rz) would give another rotation for the last."""
    for rpy in [(0.7, 0.0, 0.0), (0.0, -0.4, 0.0), (0.0, 0.0, 1.9), (0.7, -0.4, 1.9)]:
        scene = via_point_scene(3, 1)
        link = dataclasses.replace(scene.links[0], joint=dataclasses.replace(
            scene.links[0].joint, rpy=rpy))
        scene = dataclasses.replace(scene, links=(link,))
        model, data = loaded(scene)
        mujoco.mj_forward(model, data)      # qpos = 0
        expected = dynamics.rpy_matrix(rpy)
        assert np.abs(data.xmat[1].reshape(3, 3) - expected).max() <= 1e-15
    roll, pitch, yaw = rpy
    intrinsic = (dynamics.axis_rotation((1, 0, 0), roll) @ dynamics.axis_rotation((0, 1, 0), pitch)
                 @ dynamics.axis_rotation((0, 0, 1), yaw))
    assert np.abs(intrinsic - expected).max() > 0.1


def test_motors_drive_the_actuated_joints_in_the_scenes_order():
    scene = dataclasses.replace(via_point_scene(5, 4), actuated=(2, 4))
    model, data = loaded(scene)
    assert model.nu == 2 and list(model.actuator_trnid[:, 0]) == [1, 3]
    data.ctrl[:] = [1.5, -0.25]
    mujoco.mj_forward(model, data)
    assert list(data.qfrc_actuator) == [0.0, 1.5, 0.0, -0.25]
    assert list(model.dof_damping) == [link.damping for link in scene.links]


@pytest.mark.parametrize("change, message", [
    ({"mass": 0.0}, "links[1].mass: MuJoCo cannot represent link 2 with mass 0.0 kg"),
    ({"inertia": (0.0,) * 6}, "links[1].inertia: MuJoCo cannot represent link 2 with principal"),
    ({"inertia": (1.0, 1.0, 2.5, 0.0, 0.0, 0.0)}, "(A + B >= C)"),
])
def test_a_link_mujoco_refuses_is_named(change, message):
    scene = via_point_scene(1, 3)
    links = list(scene.links)
    links[1] = dataclasses.replace(links[1], **change)
    with pytest.raises(ValueError) as error:
        spatial_mjcf_from_scene(dataclasses.replace(scene, links=tuple(links)), dt=1e-3)
    assert message in str(error.value) and "\n" not in str(error.value)
    # A body on the boundary (a thin plate: A + B = C) is a rigid body; MuJoCo takes it.
    links[1] = dataclasses.replace(scene.links[1], inertia=(1.0, 1.0, 2.0, 0.0, 0.0, 0.0))
    loaded(dataclasses.replace(scene, links=tuple(links)))


def test_a_thin_plate_is_taken_or_refused_in_one_line():
    """A thin plate's principal moments are on the boundary A + B = C. Turned in the link
    frame, MuJoCo's own diagonalization decides by round-off whether it takes the body: the
    MJCF is written either way, and a refusal reaches the caller of spatial_mujoco as one
    line naming the body; a body MuJoCo takes has the scene's mass matrix."""
    scene = via_point_scene(6, 2, conservative=True)
    outcomes = set()
    for seed in range(40):
        turn, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
        plate = turn @ np.diag([0.3, 0.7, 1.0]) @ turn.T
        link = dataclasses.replace(scene.links[1], inertia=(
            plate[0, 0], plate[1, 1], plate[2, 2], plate[0, 1], plate[0, 2], plate[1, 2]))
        plated = dataclasses.replace(scene, links=(scene.links[0], link))
        spatial_mjcf_from_scene(plated, dt=1e-3)
        try:
            model, data = spatial_mujoco_model_and_data(plated, dt=1e-3)
        except ValueError as error:
            assert str(error).startswith(
                "random: MuJoCo refuses the model: inertia must satisfy A + B >= C")
            assert "(Element name 'link2'" in str(error) and "\n" not in str(error)
            outcomes.add("refused")
            continue
        mass = full_mass_matrix(model, data)
        assert relative_error(mass, dynamics.mass_matrix(scene=plated,
                                                         q=plated.initial_angles)) <= 1e-10
        outcomes.add("taken")
    print(f"a turned thin plate, 40 turns: {sorted(outcomes)}")


def test_export_adds_only_what_a_user_sees():
    """export=True: massless capsules without contacts, and the initial state as keyframe 0;
    the masses, inertias and the mass matrix are those of the reference model."""
    scene = via_point_scene(8, 5)
    reference, _ = loaded(scene)
    model = mujoco.MjModel.from_xml_string(spatial_mjcf_from_scene(scene, dt=1e-3,
                                                                   export=True))
    assert model.ngeom == 5 and model.nkey == 1
    assert all(model.geom_contype == 0) and all(model.geom_conaffinity == 0)
    np.testing.assert_array_equal(model.body_mass, reference.body_mass)
    np.testing.assert_array_equal(model.body_inertia, reference.body_inertia)
    np.testing.assert_array_equal(model.key_qpos[0], scene.initial_angles)
    np.testing.assert_array_equal(model.key_qvel[0], scene.initial_velocities)
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    mujoco.mj_forward(model, data)
    mass = full_mass_matrix(model, data)
    assert relative_error(mass, dynamics.mass_matrix(scene, scene.initial_angles)) <= 1e-10


@pytest.mark.parametrize("options, message", [
    ({"dt": 0.0}, "dt: must be > 0 and finite, got 0.0"),
    ({"dt": 1e-3, "integrator": "rk4"}, "integrator: must be one of"),
])
def test_bad_options_are_refused(options, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(")):
        spatial_mjcf_from_scene(via_point_scene(1, 2), **options)


def test_rk4_keeps_the_energy_of_a_conservative_scene():
    """A sanity check of the model, not of MuJoCo: free motion with MuJoCo's RK4 at dt = 1e-4
    over 0.5 s keeps chaingen's H = T + V (H about 350 J) to round-off, and at larger steps
    H drifts by RK4's error, which shrinks as dt^4 (by at least 12 per halving here; a model
    whose MJCF differed from the scene would drift by O(1) at any dt)."""
    scene = via_point_scene(2, 4, conservative=True)

    def drift(dt):
        run = simulate_spatial_mujoco(scene, dt=dt, t_end=0.5, sample_times=(0.5,))
        energy = [dynamics.kinetic_energy(scene, q, v) + dynamics.potential_energy(scene, q)
                  for q, v in [(scene.initial_angles, scene.initial_velocities),
                               (run.final_angles, run.final_velocities)]]
        assert np.isclose(run.energies[0], energy[1], rtol=1e-12)
        return abs(energy[1] - energy[0]) / abs(energy[0])

    fine, coarse, coarser = drift(1e-4), drift(1e-3), drift(2e-3)
    print(f"relative drift of H over 0.5 s: {fine:.1e} at dt = 1e-4, {coarse:.1e} at 1e-3, "
          f"{coarser:.1e} at 2e-3")
    assert fine <= 1e-12 and coarser / coarse >= 12.0


def test_a_compound_pendulum_follows_its_ode():
    """One link on a horizontal axis (x), its centre of mass off the axis, full inertia tensor,
    damped, driven by a constant torque u: J theta'' = u - d theta' - m g (c_y cos theta -
    c_z sin theta), J = I_xx + m (c_y^2 + c_z^2). MuJoCo's RK4 at dt = 2.5e-4 against DOP853."""
    mass, com, damping, gravity, u = 1.7, (0.05, 0.3, -0.1), 0.4, 9.81, 0.8
    inertia = (0.06, 0.05, 0.03, 0.004, -0.002, 0.003)
    scene = dataclasses.replace(
        via_point_scene(0, 1), gravity=(0.0, 0.0, -gravity), springs=(), actuated=(1,),
        initial_angles=(0.4,), initial_velocities=(-1.1,),
        links=(SpatialLink(mass, com, inertia, SpatialJoint((0.1, -0.2, 0.3), (0.0, 0.0, 0.0),
                                                            (1.0, 0.0, 0.0)), damping),))
    moment = inertia[0] + mass * (com[1] ** 2 + com[2] ** 2)

    def rate(_, state):
        theta, omega = state
        torque = u - damping * omega - mass * gravity * (com[1] * np.cos(theta)
                                                        - com[2] * np.sin(theta))
        return [omega, torque / moment]

    exact = solve_ivp(rate, (0.0, 1.0), [0.4, -1.1], method="DOP853", rtol=1e-13, atol=1e-13)
    run = simulate_spatial_mujoco(scene, dt=2.5e-4, t_end=1.0, torques=[u])
    error = np.abs(np.concatenate([run.final_angles, run.final_velocities]) - exact.y[:, -1])
    print(f"compound pendulum at t = 1 s: |theta - theta_ODE| = {error[0]:.1e} rad, "
          f"|omega - omega_ODE| = {error[1]:.1e} rad/s")
    assert error.max() <= 1e-10


@pytest.mark.heavy
def test_a_random_chain_follows_its_equations_of_motion():
    """A random 3-link chain (via-point springs, damping, two actuated joints whose torques
    change every 0.1 s): MuJoCo's RK4 at dt = 2.5e-4 against DOP853 on M qddot = tau - d qdot
    - (C qdot + g) - dV_s/dq, with M and dV_s/dq from chaingen.spatial.dynamics and C qdot + g
    from Pinocchio's RNEA at zero acceleration. Angles and rates at t = 1 s."""
    require_module("pinocchio", "robots")
    scene = dataclasses.replace(via_point_scene(4, 3), actuated=(1, 3))
    pin, model = pinocchio_model(scene)
    data = model.createData()
    damping = np.array([link.damping for link in scene.links])
    dt, hold = 2.5e-4, 400          # 10 intervals of 400 steps: t = 1 s
    levels = np.array([[2.0 * np.sin(3.0 * c), -1.0 + np.cos(5.0 * c)] for c in range(10)])

    def rate(_, state, tau):
        q, v = state[:3], state[3:]
        force = (tau - damping * v - pin.rnea(model, data, q, v, np.zeros(3))
                 - dynamics.spring_torques(scene, q))
        return np.concatenate([v, np.linalg.solve(dynamics.mass_matrix(scene, q), force)])

    # Interval by interval, so that no step of DOP853 straddles a change of the input.
    state = np.concatenate([scene.initial_angles, scene.initial_velocities])
    for c, level in enumerate(levels):
        tau = np.zeros(3)
        tau[[0, 2]] = level
        state = solve_ivp(rate, (c * hold * dt, (c + 1) * hold * dt), state, args=(tau,),
                          method="DOP853", rtol=1e-12, atol=1e-12).y[:, -1]
    run = simulate_spatial_mujoco(scene, dt=dt, t_end=1.0,
                                  torques=np.repeat(levels, hold, axis=0))
    error = np.abs(np.concatenate([run.final_angles, run.final_velocities]) - state)
    print(f"random 3-link chain at t = 1 s: max |q - q_DOP853| = {error[:3].max():.1e} rad, "
          f"max |qdot - qdot_DOP853| = {error[3:].max():.1e} rad/s")
    assert error.max() <= 1e-8


def robot_scene(urdf_name: str):
    """A real arm of example-robot-data as a SpatialScene, read off Pinocchio's model of its
    URDF joint by joint (its placements as xyz and rpy, its axes, its links' inertias), the
    Panda's fingers locked into its hand (Pinocchio's reduced model); and that model. Not
    `chaingen import`: a second path from the same file, for the MJCF's sake."""
    import importlib.metadata

    pin = require_module("pinocchio", "robots")
    robots = importlib.metadata.distribution("example-robot-data")
    path = next(robots.locate_file(file) for file in robots.files
                if file.name == urdf_name and "_description/urdf/" in str(file))
    model = pin.buildModelFromUrdf(str(path))
    locked = [j for j in range(1, model.njoints) if model.joints[j].shortname().startswith(
        ("JointModelP", "JointModelPrismatic"))]
    if locked:
        model = pin.buildReducedModel(model, locked, pin.neutral(model))
    axes = {"JointModelRX": (1.0, 0.0, 0.0), "JointModelRY": (0.0, 1.0, 0.0),
            "JointModelRZ": (0.0, 0.0, 1.0)}
    links = []
    for j in range(1, model.njoints):
        assert model.parents[j] == j - 1, "a serial chain"
        placement, inertia = model.jointPlacements[j], model.inertias[j]
        tensor = inertia.inertia
        links.append(SpatialLink(
            mass=float(inertia.mass), com=tuple(map(float, inertia.lever)),
            inertia=tuple(float(tensor[a, b]) for a, b in
                          [(0, 0), (1, 1), (2, 2), (0, 1), (0, 2), (1, 2)]),
            joint=SpatialJoint(xyz=tuple(map(float, placement.translation)),
                               rpy=tuple(map(float, pin.rpy.matrixToRpy(placement.rotation))),
                               axis=axes[model.joints[j].shortname()])))
    n = len(links)
    scene = dataclasses.replace(via_point_scene(0, 1, conservative=True), name=urdf_name,
                                gravity=tuple(map(float, model.gravity.linear)),
                                links=tuple(links), springs=(), initial_angles=(0.0,) * n,
                                initial_velocities=(0.0,) * n)
    return pin, model, scene


@pytest.mark.parametrize("urdf_name, n", [("panda.urdf", 7), ("ur5_robot.urdf", 6),
                                          ("z1.urdf", 7)])
def test_real_arms_have_pinocchios_dynamics_in_mujoco(urdf_name, n):
    """The Panda, UR5 and Z1 of example-robot-data: MuJoCo's mass matrix and generalized
    gravity of the MJCF agree with Pinocchio's CRBA and generalized gravity of the URDF at 20
    random configurations to 1e-10 relative (issue 33 c for the MJCF, apart from the import)."""
    pin, model, scene = robot_scene(urdf_name)
    assert scene.n == n
    mujoco_model, data = loaded(scene)
    pin_data = model.createData()
    rng = np.random.default_rng(n)
    for _ in range(20):
        q = rng.uniform(-np.pi, np.pi, n)
        data.qpos[:] = q
        mujoco.mj_forward(mujoco_model, data)
        mass = full_mass_matrix(mujoco_model, data)
        expected = pin.crba(model, pin_data, q)
        expected = np.triu(expected) + np.triu(expected, 1).T
        assert relative_error(mass, expected) <= 1e-10
        assert relative_error(data.qfrc_bias,
                              pin.computeGeneralizedGravity(model, pin_data, q)) <= 1e-10


@pytest.mark.parametrize("options, message", [
    ({"t_end": 0.01, "dt": 0.0}, "dt: must be > 0 and finite, got 0.0"),
    ({"t_end": 0.0105}, "t_end: 0.0105 s is not a whole number of steps of dt = 0.001 s"),
    ({"t_end": 0.01, "sample_times": (0.02,)}, "sample_times[0]: 0.02 s is after t_end"),
    ({"t_end": 0.01, "torques": [1.0, 2.0, 3.0]},
     "torques: one per actuated joint [1, 3] (shape (2,)) or one row per step (shape (10, 2)), "
     "got shape (3,)"),
])
def test_bad_run_settings_are_refused_in_one_line(options, message):
    scene = dataclasses.replace(via_point_scene(1, 3), actuated=(1, 3))
    with pytest.raises(ValueError) as error:
        simulate_spatial_mujoco(scene, **{"dt": 1e-3, **options})
    assert str(error.value).startswith(message) and "\n" not in str(error.value)
