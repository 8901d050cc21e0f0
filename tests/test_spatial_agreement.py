"""Issue 33, must-show a: every spatial scheme agrees with MuJoCo.

Differential tests of the compiled solvers (chaingen.simulation.build_solver) against MuJoCo
(chaingen.reference.simulate_spatial_mujoco, RK4 at the same dt, the MJCF of
spatial_mjcf_from_scene): the joint angles at t = 1 s at dt = 2.5e-4 s agree within 1e-4 rad,
on chains drawn by hypothesis (3 to 7 links, skew joint axes, joint origins turned by rpy,
centres of mass off the axes, full inertia tensors of turned boxes, mono- and multi-articular
springs routed through via points, gravity off the vertical, torques held on the actuated
joints, damped joints) and on the shipped scenes spatial_three_link and panda_springs.

Every scheme SPATIAL_BUILDERS takes is tested, so that each one added there is held to the same
bound. The two runs are independent: MuJoCo's RK4 on its own recursive dynamics against our
Newton-Euler residual solved by Newton's method.
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, assume, given, settings
from hypothesis import strategies as st

from chaingen.spatial import dynamics
from chaingen.spatial.reader import load_spatial_scene
from chaingen.spatial.values import (
    RoutePoint,
    SpatialJoint,
    SpatialLink,
    SpatialScene,
    SpatialSpring,
)
from chaingen.symbolic.schemes import SPATIAL_BUILDERS

from helpers import scene_path

mujoco = pytest.importorskip("mujoco")

#: The agreement issue 33 a asks for: rad at T, at DT (s).
TOLERANCE, T, DT = 1e-4, 1.0, 2.5e-4

#: Shortest route segment (m) a drawn scene may reach on MuJoCo's run: a segment through zero
#: length has no direction, and both runs would stop or jump there.
SHORTEST_SEGMENT = 0.02

METHODS = sorted(SPATIAL_BUILDERS)


def drawn_scene(seed: int, n: int, actuated: tuple[int, ...], damped: tuple[bool, ...],
                multi: bool) -> SpatialScene:
    """A chain of n links from `seed`: masses 0.5 to 3 kg; each inertia a solid box's
    principal moments (sides 0.05 to 0.4 m, so physically possible: A + B >= C) turned at
    random; centres of mass up to about 0.1 m off the joint axes; joint origins 0.1 to 0.3 m
    away, turned by a random rpy, about a random unit axis; gravity 9.81 m/s^2 tilted at
    random. A mono-articular spring across every joint (route points on links i - 1 and i),
    and, if `multi`, a multi-articular one from the base through a via point on a middle link
    to the last; stiffness 20 to 200 N/m, rest length 0.5 to 0.9 of the initial length."""
    rng = np.random.default_rng(seed)
    links = []
    for i in range(n):
        mass = float(rng.uniform(0.5, 3.0))
        a, b, c = rng.uniform(0.05, 0.4, 3) ** 2
        turn, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        inertia = turn @ np.diag([b + c, a + c, a + b]) @ turn.T * mass / 12
        axis = rng.normal(size=3)
        offset = rng.normal(size=3)
        links.append(SpatialLink(
            mass=mass, com=tuple(0.06 * rng.normal(size=3)),
            inertia=(inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1],
                     inertia[0, 2], inertia[1, 2]),
            joint=SpatialJoint(xyz=tuple(offset / np.linalg.norm(offset)
                                         * rng.uniform(0.1, 0.3)),
                               rpy=tuple(rng.uniform(-np.pi, np.pi, 3)),
                               axis=tuple(axis / np.linalg.norm(axis))),
            damping=float(rng.uniform(0.05, 0.5)) if damped[i] else 0.0))
    routes = [(RoutePoint(i, tuple(0.12 * rng.normal(size=3))),
               RoutePoint(i + 1, tuple(0.12 * rng.normal(size=3)))) for i in range(n)]
    if multi:
        routes.append((RoutePoint(0, tuple(0.12 * rng.normal(size=3))),
                       RoutePoint(n // 2, tuple(0.12 * rng.normal(size=3))),
                       RoutePoint(n, tuple(0.12 * rng.normal(size=3)))))
    q0 = tuple(rng.uniform(-1.0, 1.0, n))
    tilt = rng.normal(size=3) * 0.3 + (0.0, 0.0, -1.0)
    scene = SpatialScene(name="drawn", gravity=tuple(9.81 * tilt / np.linalg.norm(tilt)),
                         links=tuple(links), springs=(), initial_angles=q0,
                         initial_velocities=tuple(rng.uniform(-1.0, 1.0, n)),
                         actuated=actuated)
    unstretched = scene_with_springs(scene, routes, np.ones(len(routes)), np.ones(len(routes)))
    lengths = dynamics.spring_lengths(unstretched, q0)
    return scene_with_springs(scene, routes, rng.uniform(20.0, 200.0, len(routes)),
                              lengths * rng.uniform(0.5, 0.9, len(routes)))


def scene_with_springs(scene: SpatialScene, routes, stiffness, rest_lengths) -> SpatialScene:
    return dataclasses.replace(scene, springs=tuple(
        SpatialSpring(route, float(k), float(rest))
        for route, k, rest in zip(routes, stiffness, rest_lengths)))


def shortest_segment(scene: SpatialScene, angles) -> float:
    """The shortest route segment (m) over the rows of `angles`."""
    return min(float(np.linalg.norm(np.diff(points, axis=0), axis=1).min())
               for q in angles for points in dynamics.route_positions(scene, q))


def wrapped(angles) -> np.ndarray:
    return np.angle(np.exp(1j * np.asarray(angles)))


def holding_torques(scene: SpatialScene) -> np.ndarray:
    """The torques (N m) on the actuated joints that hold the initial posture against gravity
    and the springs: the size a motor of this arm works at."""
    q0 = np.array(scene.initial_angles)
    holding = dynamics.gravity_torques(scene, q0) + dynamics.spring_torques(scene, q0)
    return holding[[joint - 1 for joint in scene.actuated]]


def mujoco_run(scene: SpatialScene, torques, dt: float = DT):
    from chaingen.reference.spatial_mujoco import simulate_spatial_mujoco

    return simulate_spatial_mujoco(scene, dt=dt, t_end=T, integrator="RK4",
                                   torques=torques if scene.actuated else None,
                                   sample_times=np.linspace(0.0, T, 101))


def our_final_angles(solver, scene: SpatialScene, torques, dt: float = DT) -> np.ndarray:
    steps = round(T / dt)
    result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=dt,
                             n_steps=steps, every=steps,
                             torques=np.tile(torques, (steps, 1)) if scene.actuated else None)
    assert result.t[-1] == pytest.approx(T)
    return result.phi[-1]


def angle_difference(scene: SpatialScene, method: str, torques, *, drawn: bool) -> float:
    """max |q_ours(T) - q_MuJoCo(T)| (rad, wrapped) at DT with `torques` (N m, one per actuated
    joint) held over the run by both. A `drawn` scene whose route segment comes near zero
    length on MuJoCo's run is rejected (hypothesis draws another); a shipped one fails."""
    from chaingen.simulation import build_solver

    reference = mujoco_run(scene, torques)
    fair = shortest_segment(scene, reference.angles) >= SHORTEST_SEGMENT
    if drawn:
        assume(fair)
    assert fair, f"{scene.name}: a route segment comes within {SHORTEST_SEGMENT} m of zero"
    # Both runs moved, by more than the agreement asked (not a comparison of two rests).
    assert np.abs(wrapped(reference.final_angles - np.array(scene.initial_angles))).max() > 0.05
    solver = build_solver(scene, method, sensitivities=False)
    ours = our_final_angles(solver, scene, torques)
    difference = float(np.abs(wrapped(ours - reference.final_angles)).max())
    print(f"\n{scene.name} ({scene.n} links, {len(scene.springs)} springs), {method}: "
          f"max |q - q_MuJoCo| at t = {T:g} s = {difference:.2e} rad, max |qdot| = "
          f"{np.abs(reference.velocities).max():.1f} rad/s")
    return difference


@st.composite
def drawn_cases(draw):
    n = draw(st.integers(3, 7))
    actuated = tuple(sorted(draw(st.sets(st.integers(1, n), min_size=1, max_size=n))))
    damped = tuple(draw(st.lists(st.booleans(), min_size=n, max_size=n)))
    # each torque a fraction of the one that holds the initial posture at that joint
    fractions = draw(st.lists(st.floats(-0.5, 0.5), min_size=len(actuated),
                              max_size=len(actuated)))
    scene = drawn_scene(draw(st.integers(0, 2**32 - 1)), n, actuated, damped,
                        multi=draw(st.booleans()))
    return scene, np.array(fractions) * holding_torques(scene)


@pytest.mark.compile
@pytest.mark.parametrize("method", METHODS)
# Each example generates and compiles a solver (tens of seconds): a few examples, drawn the
# same on every run, and no shrinking (a failing example is reported as drawn).
@settings(max_examples=4, deadline=None, derandomize=True,
          phases=(Phase.explicit, Phase.reuse, Phase.generate),
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much])
@given(case=drawn_cases())
@pytest.mark.slow
def test_drawn_chains_agree_with_mujoco_at_one_second(method, case):
    scene, torques = case
    assert angle_difference(scene, method, torques, drawn=True) <= TOLERANCE


@pytest.mark.compile
@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", ["spatial_three_link", "panda_springs"])
@pytest.mark.slow
def test_shipped_scenes_agree_with_mujoco_at_one_second(method, name):
    """The scene's own run: its initial state, damping and springs, the motors idle (zero
    torque on the actuated joints)."""
    scene = load_spatial_scene(scene_path(name))
    assert angle_difference(scene, method, np.zeros(len(scene.actuated)),
                            drawn=False) <= TOLERANCE


@pytest.mark.compile
@pytest.mark.parametrize("method", METHODS)
def test_driven_three_link_differs_from_mujoco_by_the_truncation_error_alone(method):
    """spatial_three_link with half the holding torque on its motor (joint 3): the third link
    spins at up to about 40 rad/s and the chain is sensitive to small changes (its order-2
    error grows about 3.5-fold each 0.1 s of the second half), so a scheme of order 2 misses
    1e-4 rad at t = 1 s at DT (midpoint: 3.7e-3 rad measured). That it is the step's
    truncation error and not a disagreement of the models: the order-2 difference falls by 4
    per halving of dt, and the step composed to order 4 agrees within TOLERANCE at DT."""
    from chaingen.simulation import build_solver

    scene = load_spatial_scene(scene_path("spatial_three_link"))
    torques = 0.5 * holding_torques(scene)
    reference = mujoco_run(scene, torques, dt=DT / 2).final_angles
    solver = build_solver(scene, method, sensitivities=False)
    differences = [np.abs(wrapped(our_final_angles(solver, scene, torques, dt)
                                  - reference)).max() for dt in (4 * DT, 2 * DT, DT)]
    ratios = np.array(differences[:-1]) / np.array(differences[1:])
    assert np.all((3.8 <= ratios) & (ratios <= 4.2)), (differences, ratios)
    composed = build_solver(scene, method, sensitivities=False, order=4)
    difference = np.abs(wrapped(our_final_angles(composed, scene, torques) - reference)).max()
    print(f"\nspatial_three_link driven, {method}: order 2 {differences} rad at dt = "
          f"{4 * DT:g}, {2 * DT:g}, {DT:g} s; order 4 {difference:.2e} rad at {DT:g} s")
    assert difference <= TOLERANCE


# -- the bench's spatial part (issue 33 d: chaingen bench --spatial-only) ---------------------

def test_spatial_only_runs_that_part_alone(tmp_path):
    from chaingen.studies.bench import bench_config

    config = bench_config(spatial_only=True, out=tmp_path / "b.md")
    assert config.spatial_only
    assert not (config.run_reference or config.run_scaling or config.run_sweep
                or config.run_stiff)
    assert config.command == f"chaingen bench --spatial-only --out {tmp_path / 'b.md'}"
    assert not bench_config(out=tmp_path / "b.md").spatial_only
    for clash in ({"stiff_only": True}, {"uneven_only": True}):
        with pytest.raises(Exception, match="--spatial-only"):
            bench_config(spatial_only=True, out=tmp_path / "b.md", **clash)


def test_spatial_section_is_replaced_in_place_and_kept_by_a_full_run():
    from chaingen.studies.bench.spatial import (
        SPATIAL_HEADING,
        replace_spatial_section,
        spatial_section_of,
    )

    section = f"{SPATIAL_HEADING}\n\nnew\n"
    old = f"# T\n\n## Scaling\n\ns\n\n{SPATIAL_HEADING}\n\nold\n\n## Speed knobs\n\nk\n"
    assert replace_spatial_section(old, section) == \
        f"# T\n\n## Scaling\n\ns\n\n{SPATIAL_HEADING}\n\nnew\n\n## Speed knobs\n\nk\n"
    assert replace_spatial_section("# T\n\nh\n", section) == \
        f"# T\n\nh\n\n{SPATIAL_HEADING}\n\nnew\n"
    assert replace_spatial_section(f"# T\n\n{SPATIAL_HEADING}\n\nold\n", section) == \
        f"# T\n\n{SPATIAL_HEADING}\n\nnew\n"
    # what a full run carries over from the report it replaces
    assert spatial_section_of(old) == f"{SPATIAL_HEADING}\n\nold\n"
    assert spatial_section_of(f"# T\n\n{SPATIAL_HEADING}\n\nold\n") == \
        f"{SPATIAL_HEADING}\n\nold\n"
    assert spatial_section_of("# T\n\n## Scaling\n\ns\n") is None


def test_spatial_tables_hold_the_targets_and_leave_python_loops_uncompared():
    from chaingen.studies.bench.spatial import (
        BuildRow,
        SpatialStudy,
        StepRow,
        build_table,
        findings,
        step_table,
    )

    study = SpatialStudy("panda_springs", 1e-3, 2000, 200, steps=(
        StepRow("midpoint", "C (timing program)", (4e-6, 6e-6, 5e-6), 2.0),
        StepRow("MuJoCo RK4", "C (mj_step, nstep)", (1e-5, 1e-5, 4e-6)),
        StepRow("Pinocchio ABA RK4", "Python: pin.aba x 4 (C++) + springs (numpy)",
                (1e-3, 1e-3, 1e-3))),
        builds=(BuildRow("midpoint", False, 2.0, 20.0), BuildRow("midpoint", True, 5.0, 70.0)),
        pinocchio=None)
    # the median of the rounds' ratios (0.4, 0.6, 1.25), not the ratio of the medians (0.5)
    assert study.ratio(study.steps[0]) == pytest.approx(0.6)
    rows = step_table(study).splitlines()
    assert rows[2] == "| midpoint | C (timing program) | 5.00 us | 0.6 | 2.00 | <= 1 | pass |"
    assert "not compared (Python loop)" in rows[4] and "pass" not in rows[4]
    builds = build_table(study).splitlines()
    assert builds[2].endswith("| 22.0 s | <= 30 s | pass |")
    assert builds[3].endswith("| 75.0 s | <= 60 s | FAIL |")
    assert "within the target of 1" in findings(study)
    assert "with sensitivities generates and builds in 75.0 s, over 60 s" in findings(study)
