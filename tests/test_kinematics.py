"""Numeric forward kinematics and energy (model.md sections 1-3): fast, no compiler."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from chaingen.scene import Link, Scene, Simulation, Spring, kinematics, load_scene

SCENES = Path(__file__).resolve().parent.parent / "scenes"


def make_scene(links, springs=(), base_fastening=0.0, gravity=9.81) -> Scene:
    n = len(links)
    return Scene(name="test", gravity=gravity, base_fastening=base_fastening,
                 links=tuple(links), springs=tuple(springs), initial_angles=(0.0,) * n,
                 initial_velocities=(0.0,) * n, simulation=Simulation())


def link(length=1.0, com=0.5, com_normal=0.0, fastening=0.0, mass=1.0, inertia=0.1):
    return Link(mass=mass, inertia=inertia, length=length, com=com, com_normal=com_normal,
                fastening=fastening, damping=0.0)


THREE = make_scene(
    [link(1.0, 0.5, 0.0, 0.2), link(2.0, 0.8, 0.1, -0.3), link(0.5, 0.25, -0.05, 0.1)],
    base_fastening=0.4)


def test_straight_chain():
    chain = kinematics.chain_geometry(THREE, [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(chain.theta, [0.0, 0.0, 0.0])
    np.testing.assert_allclose(chain.joints, [[0, 0], [1, 0], [3, 0], [3.5, 0]])
    np.testing.assert_allclose(chain.coms, [[0.5, 0], [1.8, 0.1], [3.25, -0.05]])
    np.testing.assert_allclose(chain.fastenings, [[0, 0.4], [1, 0.2], [3, -0.3], [3.5, 0.1]])
    np.testing.assert_allclose(chain.directions, [[1, 0]] * 3)
    np.testing.assert_allclose(chain.normals, [[0, 1]] * 4)


def test_ninety_degree_joints():
    chain = kinematics.chain_geometry(THREE, [math.pi / 2] * 3)
    np.testing.assert_allclose(chain.theta, [math.pi / 2, math.pi, 3 * math.pi / 2])
    # e_1 = (0, 1), e_2 = (-1, 0), e_3 = (0, -1); n_1 = (-1, 0), n_2 = (0, -1), n_3 = (1, 0).
    np.testing.assert_allclose(chain.directions, [[0, 1], [-1, 0], [0, -1]], atol=1e-15)
    np.testing.assert_allclose(chain.normals, [[0, 1], [-1, 0], [0, -1], [1, 0]], atol=1e-15)
    np.testing.assert_allclose(chain.joints, [[0, 0], [0, 1], [-2, 1], [-2, 0.5]], atol=1e-15)
    np.testing.assert_allclose(chain.fastenings,
                               [[0, 0.4], [-0.2, 1], [-2, 1.3], [-1.9, 0.5]], atol=1e-15)


def test_off_axis_com():
    # x_i = X_i + a_i e_i + b_i n_i; link 2 at theta_2 = pi: e_2 = (-1, 0), n_2 = (0, -1).
    chain = kinematics.chain_geometry(THREE, [math.pi / 2] * 3)
    np.testing.assert_allclose(chain.coms[0], [0, 0.5], atol=1e-15)
    np.testing.assert_allclose(chain.coms[1], [0 - 0.8, 1 - 0.1], atol=1e-15)
    np.testing.assert_allclose(chain.coms[2], [-2 - 0.05 * 1, 1 - 0.25], atol=1e-15)
    # Away from right angles: |x_i - X_i| = sqrt(a_i^2 + b_i^2), at angle theta_i + alpha_i.
    phi = [0.3, -1.1, 2.0]
    chain = kinematics.chain_geometry(THREE, phi)
    for i, current in enumerate(THREE.links):
        arm = chain.coms[i] - chain.joints[i]
        assert np.hypot(*arm) == pytest.approx(math.hypot(current.com, current.com_normal))
        expected = chain.theta[i] + math.atan2(current.com_normal, current.com)
        assert math.atan2(arm[1], arm[0]) == pytest.approx(expected)


def test_geometry_arrays_are_read_only():
    chain = kinematics.chain_geometry(THREE, [0.1, 0.2, 0.3])
    with pytest.raises(ValueError):
        chain.joints[0, 0] = 1.0


def test_angles_of_the_wrong_length_are_refused():
    with pytest.raises(ValueError, match=r"shape \(3,\)"):
        kinematics.chain_geometry(THREE, [0.1, 0.2])


def test_spring_points_follow_the_chain_or_the_override():
    chain_spring = Spring(first=2, last=3, stiffness=1.0, rest_length=0.0, offsets=None)
    own_spring = Spring(first=2, last=3, stiffness=1.0, rest_length=0.0,
                        offsets=(-0.5, 0.5, 0.0))
    phi = [0.0, 0.0, 0.0]
    chained = kinematics.spring_geometry(THREE, chain_spring, phi)
    np.testing.assert_allclose(chained.points, [[1, 0.2], [3, -0.3], [3.5, 0.1]])
    np.testing.assert_allclose(chained.segment_lengths,
                               [math.hypot(2, 0.5), math.hypot(0.5, 0.4)])
    own = kinematics.spring_geometry(THREE, own_spring, phi)
    np.testing.assert_allclose(own.points, [[1, -0.5], [3, 0.5], [3.5, 0.0]])
    np.testing.assert_allclose(own.segment_lengths, [math.hypot(2, 1), math.hypot(0.5, 0.5)])
    assert own.total_length == pytest.approx(math.hypot(2, 1) + math.hypot(0.5, 0.5))


def test_mono_segment_reaches_its_stated_minimum():
    # model.md section 2: min over phi_j of s_j is | sqrt(L_j^2 + r_{j+1}^2) - |r_j| |.
    scene = make_scene([link(1.0, fastening=0.3), link(0.7, fastening=-0.6)], base_fastening=0.4)
    for j, r_j, r_next, length in [(1, 0.4, 0.3, 1.0), (2, 0.3, -0.6, 0.7)]:
        spring = Spring(first=j, last=j, stiffness=1.0, rest_length=0.0, offsets=None)

        def segment(angle, j=j, spring=spring):
            phi = [angle, 0.0] if j == 1 else [0.2, angle]
            return kinematics.spring_geometry(scene, spring, phi).segment_lengths[0]

        # A coarse scan, then golden-section refinement around its minimum.
        angles = np.linspace(-math.pi, math.pi, 361)
        best = angles[np.argmin([segment(angle) for angle in angles])]
        low, high = best - 2 * math.pi / 360, best + 2 * math.pi / 360
        ratio = (math.sqrt(5) - 1) / 2
        for _ in range(60):
            left, right = high - ratio * (high - low), low + ratio * (high - low)
            if segment(left) < segment(right):
                high = right
            else:
                low = left
        expected = abs(math.hypot(length, r_next) - abs(r_j))
        assert segment((low + high) / 2) == pytest.approx(expected, abs=1e-12)


def test_simple_pendulum_energy_by_hand():
    m, J, a, b, g = 2.0, 0.3, 0.6, 0.2, 9.81
    scene = make_scene([link(1.5, a, b, mass=m, inertia=J)], gravity=g)
    theta, omega = 0.7, -1.3
    parts = kinematics.energy(scene, [theta], [omega])
    # |xdot|^2 = (a^2 + b^2) omega^2;  y = a sin(theta) + b cos(theta).
    kinetic = 0.5 * m * (a * a + b * b) * omega ** 2 + 0.5 * J * omega ** 2
    gravitational = m * g * (a * math.sin(theta) + b * math.cos(theta))
    assert parts.kinetic == pytest.approx(kinetic, rel=1e-14)
    assert parts.gravitational == pytest.approx(gravitational, rel=1e-14)
    assert parts.elastic == 0.0
    assert kinematics.total_energy(scene, [theta], [omega]) == pytest.approx(
        kinetic + gravitational, rel=1e-14)


def test_two_link_kinetic_energy_by_hand():
    # Link 2's COM: x_2 = L_1 e_1 + a_2 e_2, |xdot_2|^2 = L_1^2 w_1^2 + a_2^2 w_2^2
    #   + 2 L_1 a_2 w_1 w_2 cos(theta_2 - theta_1), with w the absolute rates.
    m1, m2, J1, J2, L1, a1, a2 = 1.0, 2.0, 0.1, 0.2, 1.2, 0.4, 0.5
    scene = make_scene([link(L1, a1, mass=m1, inertia=J1), link(1.0, a2, mass=m2, inertia=J2)],
                       gravity=0.0)
    phi, phidot = [0.4, 0.9], [0.7, -0.2]
    w1, w2 = phidot[0], phidot[0] + phidot[1]
    expected = (0.5 * m1 * a1 ** 2 * w1 ** 2 + 0.5 * J1 * w1 ** 2
                + 0.5 * m2 * (L1 ** 2 * w1 ** 2 + a2 ** 2 * w2 ** 2
                              + 2 * L1 * a2 * w1 * w2 * math.cos(phi[1]))
                + 0.5 * J2 * w2 ** 2)
    assert kinematics.kinetic_energy(scene, phi, phidot) == pytest.approx(expected, rel=1e-14)
    assert kinematics.energy(scene, phi, phidot).potential == 0.0


def test_spring_energy_by_hand():
    # One unit link, r_1 = r_2 = 0.4 at phi = 0: s = |(1, 0.4) - (0, 0.4)| = 1.
    spring = Spring(first=1, last=1, stiffness=3.0, rest_length=0.2, offsets=None)
    scene = make_scene([link(1.0, fastening=0.4)], [spring], base_fastening=0.4, gravity=0.0)
    assert kinematics.spring_energy(scene, spring, [0.0]) == pytest.approx(0.5 * 3.0 * 0.8 ** 2)
    # At phi = pi/2: P_2 = (0, 1) + 0.4 (-1, 0), s = |(-0.4, 0.6)|.
    s = math.hypot(0.4, 0.6)
    assert kinematics.elastic_energy(scene, [math.pi / 2]) == pytest.approx(
        0.5 * 3.0 * (s - 0.2) ** 2)


def test_multi_articular_energy_uses_the_total_length():
    scene = load_scene(SCENES / "three_link_multi.toml")
    spring = scene.springs[0]
    phi = [0.0, 0.0, 0.0]
    # Straight chain with all r = 0.4: three segments of length 1.
    geometry = kinematics.spring_geometry(scene, spring, phi)
    np.testing.assert_allclose(geometry.segment_lengths, [1.0, 1.0, 1.0])
    assert kinematics.spring_energy(scene, spring, phi) == pytest.approx(0.5 * (3.0 - 0.6) ** 2)
    # Not the sum of per-segment energies 3 * 1/2 (1 - 0.2)^2.
    assert kinematics.spring_energy(scene, spring, phi) != pytest.approx(1.5 * 0.8 ** 2)


def positions(scene, phi):
    chain = kinematics.chain_geometry(scene, phi)
    return chain.joints, chain.coms


@pytest.mark.parametrize("seed", range(5))
def test_analytic_velocities_match_finite_differences(seed):
    rng = np.random.default_rng(seed)
    phi = rng.uniform(-math.pi, math.pi, THREE.n)
    phidot = rng.uniform(-2.0, 2.0, THREE.n)
    h = 1e-6
    joints_plus, coms_plus = positions(THREE, phi + h * phidot)
    joints_minus, coms_minus = positions(THREE, phi - h * phidot)
    np.testing.assert_allclose(kinematics.com_velocities(THREE, phi, phidot),
                               (coms_plus - coms_minus) / (2 * h), atol=1e-8)
    np.testing.assert_allclose(kinematics.joint_velocities(THREE, phi, phidot),
                               (joints_plus - joints_minus) / (2 * h), atol=1e-8)


def test_com_velocity_is_a_sum_of_rotations_about_the_joints():
    # xdot_i = sum_{j <= i} phidot_j S (x_i - X_j): joint j turns all that is distal to it.
    phi, phidot = [0.3, -0.8, 1.7], [0.5, -1.5, 2.5]
    chain = kinematics.chain_geometry(THREE, phi)
    expected = [sum(phidot[j] * kinematics.S @ (chain.coms[i] - chain.joints[j])
                    for j in range(i + 1)) for i in range(THREE.n)]
    np.testing.assert_allclose(kinematics.com_velocities(THREE, phi, phidot), expected,
                               atol=1e-14)


def test_energy_is_conserved_along_a_fine_trajectory():
    # A free chain with gravity and springs: H stays put under a fine RK4 of the Lagrangian
    # equations built from these functions by finite differences (a consistency check of T, V).
    scene = load_scene(SCENES / "three_link_mono.toml")
    n = scene.n

    def mass_matrix(phi):
        eye = np.eye(n)
        columns = [kinematics.com_velocities(scene, phi, eye[k]) for k in range(n)]
        masses = np.array([current.mass for current in scene.links])
        inertias = np.array([current.inertia for current in scene.links])
        lower = np.tril(np.ones((n, n)))  # thetadot = lower @ phidot
        result = lower.T @ np.diag(inertias) @ lower
        for i in range(n):
            block = np.array([columns[k][i] for k in range(n)])  # (n, 2): d xdot_i / d phidot
            result = result + masses[i] * block @ block.T
        return result

    def lagrangian_rhs(state):
        phi, phidot = state[:n], state[n:]
        h = 1e-6
        M = mass_matrix(phi)
        dM = [(mass_matrix(phi + h * e) - mass_matrix(phi - h * e)) / (2 * h) for e in np.eye(n)]
        dV = np.array([(kinematics.potential_energy(scene, phi + h * e)
                        - kinematics.potential_energy(scene, phi - h * e)) / (2 * h)
                       for e in np.eye(n)])
        Mdot = sum(dM[k] * phidot[k] for k in range(n))
        dT = np.array([0.5 * phidot @ dM[k] @ phidot for k in range(n)])
        phiddot = np.linalg.solve(M, dT - dV - Mdot @ phidot)
        return np.concatenate([phidot, phiddot])

    state = np.concatenate([scene.initial_angles, [0.5, -0.3, 0.2]])
    h0 = kinematics.total_energy(scene, state[:n], state[n:])
    dt = 0.01
    for _ in range(50):
        k1 = lagrangian_rhs(state)
        k2 = lagrangian_rhs(state + dt / 2 * k1)
        k3 = lagrangian_rhs(state + dt / 2 * k2)
        k4 = lagrangian_rhs(state + dt * k3)
        state = state + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    assert kinematics.total_energy(scene, state[:n], state[n:]) == pytest.approx(h0, abs=1e-6)


def mujoco_xml(scene: Scene) -> str:
    """The chain as MuJoCo bodies, sites and spatial tendons (model.md section 10)."""
    lines = ['<mujoco><option gravity="0 %r 0" integrator="RK4">' % -scene.gravity,
             '<flag contact="disable" energy="enable"/></option><worldbody>']
    for s, spring in enumerate(scene.springs):
        if spring.first == 1:
            r = scene.spring_fastenings(spring)[0]
            lines.append(f'<site name="s{s}_1" pos="0 {r!r} 0"/>')
    closing = []
    for i, current in enumerate(scene.links, start=1):
        offset = 0.0 if i == 1 else scene.links[i - 2].length
        lines.append(f'<body pos="{offset!r} 0 0"><joint type="hinge" axis="0 0 1"/>')
        lines.append(f'<inertial pos="{current.com!r} {current.com_normal!r} 0" '
                     f'mass="{current.mass!r}" diaginertia="{current.inertia!r} '
                     f'{current.inertia!r} {current.inertia!r}"/>')
        for s, spring in enumerate(scene.springs):
            if spring.first <= i + 1 <= spring.last + 1:
                r = scene.spring_fastenings(spring)[i + 1 - spring.first]
                lines.append(f'<site name="s{s}_{i + 1}" pos="{current.length!r} {r!r} 0"/>')
        closing.append("</body>")
    lines += closing + ["</worldbody><tendon>"]
    for s, spring in enumerate(scene.springs):
        lines.append(f'<spatial stiffness="{spring.stiffness!r}" '
                     f'springlength="{spring.rest_length!r}">')
        lines += [f'<site site="s{s}_{j}"/>' for j in range(spring.first, spring.last + 2)]
        lines.append("</spatial>")
    lines.append("</tendon></mujoco>")
    return "\n".join(lines)


OFF_AXIS = make_scene(
    [link(1.0, 0.5, 0.1, 0.3, mass=1.5, inertia=0.2), link(0.8, 0.3, -0.2, -0.2, inertia=0.3),
     link(0.6, 0.2, 0.05, 0.25, mass=0.7, inertia=0.05)],
    springs=[Spring(1, 1, 2.0, 0.3, None), Spring(1, 3, 1.5, 1.0, (-0.3, 0.2, 0.4, -0.1)),
             Spring(3, 3, 4.0, 0.1, (0.2, -0.15))],
    base_fastening=0.35, gravity=2.5)


@pytest.mark.parametrize("scene", [OFF_AXIS] + [load_scene(SCENES / f"three_link_{s}.toml")
                                               for s in ("gravity", "mono", "multi")],
                         ids=["off_axis", "gravity", "mono", "multi"])
def test_geometry_and_energy_agree_with_mujoco(scene):
    mujoco = pytest.importorskip("mujoco")
    model = mujoco.MjModel.from_xml_string(mujoco_xml(scene))
    data = mujoco.MjData(model)
    rng = np.random.default_rng(1)
    for _ in range(5):
        phi = rng.uniform(-math.pi, math.pi, scene.n)
        phidot = rng.uniform(-2.0, 2.0, scene.n)
        data.qpos[:] = phi
        data.qvel[:] = phidot
        mujoco.mj_forward(model, data)
        chain = kinematics.chain_geometry(scene, phi)
        np.testing.assert_allclose(data.xipos[1:, :2], chain.coms, atol=1e-12)
        np.testing.assert_allclose(data.ten_length,
                                   [kinematics.spring_geometry(scene, spring, phi).total_length
                                    for spring in scene.springs], atol=1e-12)
        parts = kinematics.energy(scene, phi, phidot)
        assert data.energy[0] == pytest.approx(parts.potential, abs=1e-12)
        assert data.energy[1] == pytest.approx(parts.kinetic, abs=1e-12)
