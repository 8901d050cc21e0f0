"""The numeric spatial dynamics (chaingen.spatial.dynamics) against Pinocchio: the mass matrix
and the generalized gravity of random chains (skew axes, full inertia tensors, off-axis centres
of mass, joint origins turned by rpy) built in Pinocchio from the same numbers; the spring
forces against central differences of the spring potential."""
from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from chaingen.spatial import dynamics
from chaingen.spatial.values import (
    RoutePoint,
    SpatialJoint,
    SpatialLink,
    SpatialScene,
    SpatialSpring,
)

from helpers import require_module


def random_scene(seed: int, n: int, springs: bool = False, physical: bool = True) -> SpatialScene:
    """A random chain of n links (skew axes, joint origins turned by rpy, off-axis COMs, full
    inertia tensors), with springs through route points when asked. physical: each tensor a
    solid box's principal moments, turned at random (a rigid body's, as the reader and es's
    director mass matrix need); False: any positive definite tensor, which the joint-space
    dynamics take (the spatial midpoint's tests and model.md 6.7's figures use those chains)."""
    rng = np.random.default_rng(seed)
    links = []
    for _ in range(n):
        if physical:
            mass = float(rng.uniform(0.2, 5.0))
            a, b, c = rng.uniform(0.02, 0.5, 3) ** 2
            turn, _ = np.linalg.qr(rng.normal(size=(3, 3)))
            moments = np.diag([mass * (b + c), mass * (a + c), mass * (a + b)]) / 12
            inertia = turn @ moments @ turn.T
            axis = rng.normal(size=3)
        else:
            root = rng.normal(size=(3, 3))
            inertia = 0.1 * root @ root.T + 0.01 * np.eye(3)
            axis = rng.normal(size=3)
            mass = float(rng.uniform(0.2, 5.0))
        links.append(SpatialLink(
            mass=mass, com=tuple(0.1 * rng.normal(size=3)),
            inertia=(inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1], inertia[0, 2],
                     inertia[1, 2]),
            joint=SpatialJoint(xyz=tuple(0.3 * rng.normal(size=3)),
                               rpy=tuple(rng.uniform(-np.pi, np.pi, 3)),
                               axis=tuple(axis / np.linalg.norm(axis)))))
    spring_list = []
    if springs:
        for first in range(n):
            last = min(n, first + 1 + int(rng.integers(0, 3)))
            route = tuple(RoutePoint(link, tuple(0.1 * rng.normal(size=3)))
                          for link in range(first, last + 1))
            spring_list.append(SpatialSpring(route, float(rng.uniform(10, 500)),
                                             float(rng.uniform(0.0, 0.3))))
    return SpatialScene(name="random", gravity=tuple(rng.normal(size=3) + (0, 0, -9.81)),
                        links=tuple(links), springs=tuple(spring_list),
                        initial_angles=(0.0,) * n, initial_velocities=(0.0,) * n)


def pinocchio_model(scene: SpatialScene):
    """The same chain built in Pinocchio, joint by joint (an independent implementation)."""
    pin = require_module("pinocchio", "robots")
    model = pin.Model()
    parent = 0
    for i, link in enumerate(scene.links):
        placement = pin.SE3(pin.rpy.rpyToMatrix(*link.joint.rpy), np.array(link.joint.xyz))
        parent = model.addJoint(parent, pin.JointModelRevoluteUnaligned(np.array(link.joint.axis)),
                                placement, f"joint{i + 1}")
        model.appendBodyToJoint(parent, pin.Inertia(link.mass, np.array(link.com),
                                                    np.array(link.inertia_matrix())),
                                pin.SE3.Identity())
    model.gravity.linear = np.array(scene.gravity)
    return pin, model


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 7))
def test_mass_matrix_and_gravity_agree_with_pinocchio(seed, n):
    scene = random_scene(seed, n)
    pin, model = pinocchio_model(scene)
    data = model.createData()
    q = np.random.default_rng(seed + 1).uniform(-np.pi, np.pi, n)
    mass = pin.crba(model, data, q)
    mass = np.triu(mass) + np.triu(mass, 1).T
    ours = dynamics.mass_matrix(scene, q)
    assert np.abs(ours - mass).max() <= 1e-12 * max(1.0, np.abs(mass).max())
    gravity = pin.computeGeneralizedGravity(model, data, q)
    assert np.abs(dynamics.gravity_torques(scene, q) - gravity).max() <= \
        1e-12 * max(1.0, np.abs(gravity).max())
    # the kinetic energy is Pinocchio's too
    velocities = np.random.default_rng(seed + 2).normal(size=n)
    assert np.isclose(dynamics.kinetic_energy(scene, q, velocities),
                      pin.computeKineticEnergy(model, data, q, velocities), rtol=1e-12)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 6))
def test_spring_and_gravity_torques_are_the_potentials_gradient(seed, n):
    scene = random_scene(seed, n, springs=True)
    q = np.random.default_rng(seed + 3).uniform(-np.pi, np.pi, n)
    step = 1e-6
    numeric = np.array([(dynamics.potential_energy(scene, q + step * e)
                         - dynamics.potential_energy(scene, q - step * e)) / (2 * step)
                        for e in np.eye(n)])
    analytic = dynamics.spring_torques(scene, q) + dynamics.gravity_torques(scene, q)
    assert np.abs(numeric - analytic).max() <= 1e-6 * max(1.0, np.abs(analytic).max())


def test_a_planar_chain_has_the_planar_mass_matrix():
    """Parallel z axes, links along x: the spatial chain is the planar pendulum chain of
    docs/model.md. Two links, point masses at the tips: M_11 = (m1 + m2) L1^2 + m2 L2^2 +
    2 m2 L1 L2 cos q2, M_12 = m2 L2^2 + m2 L1 L2 cos q2, M_22 = m2 L2^2."""
    m1, m2, l1, l2 = 1.3, 0.7, 0.5, 0.4
    zero = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    scene = SpatialScene(
        name="planar", gravity=(0.0, -9.81, 0.0),
        links=(SpatialLink(m1, (l1, 0.0, 0.0), zero, SpatialJoint((0, 0, 0), (0, 0, 0), (0, 0, 1))),
               SpatialLink(m2, (l2, 0.0, 0.0), zero,
                           SpatialJoint((l1, 0, 0), (0, 0, 0), (0, 0, 1)))),
        springs=(), initial_angles=(0.0, 0.0), initial_velocities=(0.0, 0.0))
    q = np.array([0.3, -0.8])
    c2 = np.cos(q[1])
    expected = np.array([[(m1 + m2) * l1**2 + m2 * l2**2 + 2 * m2 * l1 * l2 * c2,
                          m2 * l2**2 + m2 * l1 * l2 * c2],
                         [m2 * l2**2 + m2 * l1 * l2 * c2, m2 * l2**2]])
    assert np.allclose(dynamics.mass_matrix(scene, q), expected, rtol=1e-14, atol=1e-14)
    gravity = 9.81 * np.array([(m1 + m2) * l1 * np.cos(q[0]) + m2 * l2 * np.cos(q.sum()),
                               m2 * l2 * np.cos(q.sum())])
    assert np.allclose(dynamics.gravity_torques(scene, q), gravity, rtol=1e-14, atol=1e-14)
