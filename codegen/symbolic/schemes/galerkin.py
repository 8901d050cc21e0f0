"""The k = 1 Petrov-Galerkin step of "es" in joint angles and canonical momenta (docs/model.md,
section 16): the step es composes to order 6.

Hamilton's equations of the chain in z = (phi, p), H(phi, p) = 1/2 p^T M(phi)^-1 p + V(phi),

    phidot = dH/dp = w,    pdot = -dH/dphi + tau - D w = dL/dphi(phi, w) + tau - D w,

with w = M(phi)^-1 p the joint rates and L = T - V, are discretised over a step of length dt with
continuous piecewise quadratic trial functions phi(s), p(s) (s = t / dt in [0, 1]) and piecewise
linear test functions psi in {1, 2 s - 1}:

    int_0^1 psi (phi'(s) - dt w(s)) ds = 0,    int_0^1 psi (p'(s) - dt F(s)) ds = 0,

F = dL/dphi + tau - D w, the integrals taken by the N = K + 1 point Gauss-Lobatto rule (exact to
degree 2K - 1) and w at each node s_g from M(phi_g) w_g = p_g. Testing the first equation with
the projection of dH/dphi and the second with that of dH/dp shows
H_1 - H_0 = tau . (phi_1 - phi_0) - (dissipated >= 0) up to the quadrature of int dH, the rule's
error, O(dt^(2K+1)) per step. A correction of that size along phi_1 - phi_0 in the momentum
equation tested with 1 (energy_correction, Gonzalez's construction) makes the identity exact
to round-off. The step is
symmetric, of order 4 in phi and in w (the nodes are superconvergent: 2k + 2), and there are no
constraints to keep: the chain's geometry is exact in joint angles.

Unknowns (increments from the step's start, so that nothing cancels at O(|p|)):
dphi_m = phi(1/2) - phi_0, dphi_1 = phi_1 - phi_0, dp_m, dp_1 likewise: 4n, whatever K. The
rates w_g at the N - 1 nodes after s = 0 (the last is w_1) are not unknowns: each is the solution
of M(phi_g) w_g = p_g by the articulated-body recursion (O(n), model.md 17), so Newton's system
is the Galerkin equations alone, the per-node equations eliminated exactly. Every node's
quantities are recursions over the links, no whole-chain M(phi). The state is (phi, w): p_0 =
M(phi_0) w_0 follows from it.

The step's assembly (galerkin_scheme) asks a chain for its quantities at a node: PlanarChain
here, from chaingen.symbolic.recursion; spatial_galerkin.SpatialChain for a spatial scene.
"""
from __future__ import annotations

import numpy as np
import sympy as sp
from sympy import ImmutableMatrix

from ...runtime.contract import JACOBIAN_PER_STEP
from ...scene import Scene
from ...scene.solver_rules import GALERKIN_ORDER, require
from .. import recursion
from ..com_model import number
from ..com_recursion import exact_gradient_scale
from .base import (
    DiscreteScheme,
    FlowDescription,
    Layout,
    NodeSpace,
    has_energy_flows,
    input_symbols,
    joint_space_state,
    joint_torques,
)
from .es import COMPOSED_UPDATE_RTOL

SUMMARY = ("Energy-conserving k = 1 Petrov-Galerkin step in joint angles and canonical momenta "
           "(docs/model.md, section 16).")
FLOWS = FlowDescription(
    "sum_i tau_i (phi_1 - phi_0)_i", "dt sum_g b_g sum_i d_i phidot_i(s_g)^2",
    "phidot(s_g) the rates of the quadratic trial function at the Gauss-Lobatto nodes s_g "
    "(weights b_g). H_1 - H_0 = flows[0] - flows[1] to round-off and the Newton tolerance "
    "(the energy correction closes the rule's defect; docs/model.md, section 16).")

def gauss_lobatto_nodes(points: int) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Nodes s_g in [0, 1] (both ends included) and weights b_g (summing to 1) of the
    `points`-point Gauss-Lobatto rule, exact for polynomials of degree 2 points - 3."""
    if points < 2:
        raise ValueError(f"a Gauss-Lobatto rule needs at least two points, got {points}")
    legendre = np.polynomial.legendre.Legendre.basis(points - 1)
    interior = np.sort(legendre.deriv().roots().real)
    x = np.concatenate([[-1.0], interior, [1.0]])
    weights = 2.0 / (points * (points - 1) * legendre(x) ** 2)
    return tuple((x + 1.0) / 2.0), tuple(weights / 2.0)


def energy_correction(defs: recursion.Definitions, defect, dphi_1, dt,
                      quadrature: int) -> sp.Symbol:
    """The factor of dphi_1 = phi_1 - phi_0 in the term added to the momentum equation tested
    with 1 (docs/model.md 16, 'Energy'): Gonzalez's correction of the rule's energy defect,

        dt e / max(|dphi_1|^2, delta^2) dphi_1,    e = H_1 - H_0 - sum_g b_g dH/ds(s_g),

    dH/ds = -dL/dphi . phi' + w . p' at the nodes: e is the (K + 1)-point Gauss-Lobatto rule's
    error on int dH, O(|dphi_1|^(2K+1)) relative to H, so the correction has that size and the
    trajectory stays the rule's. Tested with phi' (whose mean is dphi_1), that row enters the
    energy identity as -dphi_1 . row / dt: the correction contributes -e, and
    H_1 - H_0 = tau . dphi_1 - dissipated holds to round-off for every step with
    |dphi_1| >= delta. delta = c_K rad, c_K = eps^(1/(2K+1)) (5.8e-3 rad at K = 3: the angles
    enter H through sines and cosines of unit frequency), is the step below which the rule is
    exact to the round-off of H anyway: there the correction fades out as |dphi_1|, and e, a
    difference of energies with round-off eps H, is never divided by less than delta^2 (at rest
    the step's derivatives stay the rule's). Under the step's reversal e and dphi_1 change sign
    with dt: the step stays symmetric."""
    defect = defs.define("energy_defect", defect)
    smallest = sp.Float(exact_gradient_scale(quadrature) ** 2)
    ratio = defs.define("energy_correction",
                        dt * defect / sp.Max(sp.Add(*(d ** 2 for d in dphi_1)), smallest))
    return ratio


class PlanarChain:
    """The quantities of a planar chain at a node, by the recursions of
    chaingen.symbolic.recursion (model.md 17): what galerkin_scheme asks of a chain (the
    spatial chain's: chaingen.symbolic.schemes.spatial_galerkin.SpatialChain)."""

    summary = SUMMARY

    def __init__(self, scene: Scene):
        self.scene = scene

    def frames(self, defs: recursion.Definitions, tag: str, angles):
        return recursion.link_frames(self.scene,
                                     recursion.angle_directions(defs, angles, tag=tag))

    def rates(self, defs: recursion.Definitions, tag: str, frames, momenta) -> list:
        """w with M(phi) w = p, by the articulated-body recursion, O(n)."""
        return recursion.rates_from_momenta(self.scene, frames, momenta, defs, tag)

    def lagrangian(self, defs: recursion.Definitions, tag: str, frames, rates):
        """(M(phi) w, dL/dphi = dT/dphi - dV/dphi, V(phi)) at a node."""
        scene = self.scene
        momentum, kinetic_gradient = recursion.momenta(
            scene, frames, recursion.absolute_rates(defs, rates, f"{tag}Omega"), defs, tag)
        springs, spring_energy = recursion.spring_gradient(scene, frames, defs, tag)
        gravity = recursion.gravity_gradient(scene, frames, defs, tag)
        gradient = [dT - spring - weight
                    for dT, spring, weight in zip(kinetic_gradient, springs, gravity)]
        potential = spring_energy + recursion.gravity_potential(scene, frames, defs, tag)
        return momentum, gradient, potential

    def state_fields(self, phi0, w0) -> dict:
        """The state's fields (joint_space_state): its energy H = T + V and its segment
        vectors, by the same recursions at (phi_0, w_0)."""
        scene = self.scene
        at_state = recursion.Definitions("state_")
        frames0 = recursion.link_frames(scene, recursion.angle_directions(at_state, phi0))
        rates0 = recursion.absolute_rates(at_state, w0)
        velocities, _ = recursion.velocities(scene, frames0, rates0, at_state)
        _, spring_energy = recursion.spring_gradient(scene, frames0, at_state)
        energy = (recursion.kinetic_energy(scene, rates0, velocities)
                  + recursion.gravity_potential(scene, frames0, at_state) + spring_energy)
        return dict(**joint_space_state(scene, phi0, w0, energy),
                    segment_vectors=recursion.segment_vector_entries(scene, frames0),
                    state_definitions=tuple(at_state.items))


def build(scene: Scene, quadrature: int, order: int = GALERKIN_ORDER,
          exact_energy: bool = True) -> DiscreteScheme:
    """The k = 1 step of the planar `scene` with the (quadrature + 1)-point Gauss-Lobatto
    rule, its energy defect corrected (energy_correction) unless exact_energy is False (the
    rule's step alone, for comparison)."""
    return galerkin_scheme(scene, PlanarChain(scene), quadrature, order, exact_energy)


def galerkin_scheme(scene, chain, quadrature: int, order: int = GALERKIN_ORDER,
                    exact_energy: bool = True) -> DiscreteScheme:
    """The k = 1 step of `scene` with the (quadrature + 1)-point Gauss-Lobatto rule, every
    node's quantities from `chain` (PlanarChain, or spatial_galerkin.SpatialChain: frames,
    rates from momenta, the Lagrangian's terms and the state's fields), its energy defect
    corrected (energy_correction) unless exact_energy is False."""
    require(method="es", quadrature=quadrature, order=GALERKIN_ORDER)
    n = scene.n
    dt = sp.Symbol("dt", positive=True)
    phi0 = ImmutableMatrix(sp.symbols(f"phi1:{n + 1}", real=True))
    w0 = ImmutableMatrix(sp.symbols(f"w1:{n + 1}", real=True))
    nodes, weights = gauss_lobatto_nodes(quadrature + 1)

    def vector(name):
        return ImmutableMatrix(sp.symbols(f"{name}1:{n + 1}", real=True))

    dphi_m, dphi_1, dp_m, dp_1 = (vector(name) for name in ("dphim_", "dphi1_", "dpm_", "dp1_"))
    inputs = input_symbols(scene)
    torques = ImmutableMatrix(joint_torques(scene, inputs))
    damping = [number(link.damping) for link in scene.links]

    # Every node's quantities by the recursions over the links (model.md 17): O(n)
    # definitions a node (and the spatial M(phi_g)'s Cholesky factor), no whole-chain
    # expressions. The rates at the nodes after the start solve M(phi_g) w_g = p_g: they are
    # functions of the unknowns, not unknowns.
    step = recursion.Definitions("step_")

    def forces_at(tag, frames, rates):
        """(M(phi) w, dL/dphi + tau - D w, V(phi)) at a node, by definitions."""
        momentum, lagrangian_gradient, potential = chain.lagrangian(step, tag, frames, rates)
        forces = [step.define(f"{tag}force{k}", dL + tau - d * rate)
                  for k, (dL, tau, d, rate)
                  in enumerate(zip(lagrangian_gradient, torques, damping, rates), start=1)]
        return ImmutableMatrix(momentum), ImmutableMatrix(forces), potential

    def quadratic(start_change_mid, change_end, s):
        """Increment of the quadratic through (0, 0), (1/2, mid), (1, end) at s, and its
        derivative in s."""
        value = start_change_mid * (4 * s * (1 - s)) + change_end * (s * (2 * s - 1))
        slope = start_change_mid * (4 - 8 * s) + change_end * (4 * s - 1)
        return value, slope

    phi_rows = [ImmutableMatrix.zeros(n, 1), ImmutableMatrix.zeros(n, 1)]
    p_rows = [ImmutableMatrix.zeros(n, 1), ImmutableMatrix.zeros(n, 1)]
    dissipated = energy_rate = sp.Integer(0)
    p0 = None
    node_inputs, node_outputs = [], []
    for g, (s, b) in enumerate(zip(nodes, weights)):
        s_value, b_value = sp.Float(s), sp.Float(b)
        dphi, phi_slope = quadratic(dphi_m, dphi_1, s_value)
        dp, p_slope = quadratic(dp_m, dp_1, s_value)
        tag = f"n{g}_"
        if g == 0:
            frames = chain.frames(step, tag, list(phi0))
            w_g = list(w0)
        else:
            angles = [step.define(f"phi_node{g}_{i}", value)
                      for i, value in enumerate(phi0 + dphi, start=1)]
            p_g = [step.define(f"p_node{g}_{i}", value)
                   for i, value in enumerate(p0 + dp, start=1)]
            frames = chain.frames(step, tag, angles)
            w_g = chain.rates(step, tag, frames, p_g)
        momentum, force, potential = forces_at(tag, frames, w_g)
        if g == 0:
            p0 = momentum
            energy_start = sp.Add(*(p * w for p, w in zip(p0, w_g))) / 2 + potential
        else:
            node_inputs.append(ImmutableMatrix(angles + p_g))
            node_outputs.append(ImmutableMatrix(list(w_g) + list(force)))
        w_g = ImmutableMatrix(w_g)
        # dH/ds = -dL/dphi . phi' + w . p' at the node, dL/dphi = F - tau + D w.
        energy_rate += b_value * sp.Add(*(
            w_g[i] * p_slope[i] - (force[i] - torques[i] + damping[i] * w_g[i]) * phi_slope[i]
            for i in range(n)))
        for row, psi in enumerate((sp.Integer(1), 2 * s_value - 1)):
            phi_rows[row] += b_value * psi * (phi_slope - dt * w_g)
            p_rows[row] += b_value * psi * (p_slope - dt * force)
        dissipated += b_value * sp.Add(*(number(link.damping) * phi_slope[i] ** 2
                                         for i, link in enumerate(scene.links) if link.damping))
    w_1 = w_g
    dissipated = dissipated / dt
    scalars = ()
    if exact_energy:
        # H(phi_1, p_1) = 1/2 p_1 . w_1 + V(phi_1) from the last node's quantities.
        energy_end = sp.Add(*(p * w for p, w in zip(p_g, w_1))) / 2 + potential
        ratio = energy_correction(step, energy_end - energy_start - energy_rate, dphi_1, dt,
                                  quadrature)
        p_rows[0] += ratio * dphi_1
        scalars = (ratio,)
    residual = ImmutableMatrix.vstack(*phi_rows, *p_rows)
    unknowns = ImmutableMatrix.vstack(dphi_m, dphi_1, dp_m, dp_1)

    names = [f"{kind}_{i}" for kind in ("dphim", "dphi1", "dpm", "dp1") for i in range(1, n + 1)]
    return DiscreteScheme.of(
        method="es", quadrature=quadrature, scene=scene, summary=chain.summary, dt=dt,
        unknowns=unknowns,
        residual=residual,
        next_state=ImmutableMatrix.vstack(phi0 + dphi_1, w_1),
        predictor=ImmutableMatrix.vstack(dt * w0 / 2, dt * w0,
                                         ImmutableMatrix.zeros(2 * n, 1)),
        **chain.state_fields(phi0, w0),
        unknowns_layout=Layout(
            tuple(names),
            "increments from the step's start of the joint angles at its mid-point and end "
            "(rad), then of the momenta there (N m s)"),
        residual_description=(
            "the Galerkin equations of phi tested with 1 and 2s - 1 (2n entries, rad), then "
            "those of p (2n entries, N m s); the rates at the nodes solve M(phi_g) w_g = p_g"),
        inputs=inputs, definitions=tuple(step.items),
        input_work=sp.Add(*(tau * d for tau, d in zip(torques, dphi_1))),
        dissipated=dissipated,
        flow_description=FLOWS if has_energy_flows(scene) else None,
        jacobian_reuse=JACOBIAN_PER_STEP, order=order,
        # By directions, the angles' and the momenta's columns apart: a momentum moves neither
        # a node's frames nor its articulated inertias, and their tangents are left out (at 10
        # links, 10.7e3 instructions for 4 columns against 24.9e3 for the angles').
        jacobian_blocks=(2 * n, 2 * n),
        # The same recursions at every node after the start: (phi_g, p_g) -> (w_g, F_g), and
        # the residual linear in them but for the energy correction's factor, a scalar
        # (NodeSpace): dF/dz through one node's Jacobian.
        node_space=NodeSpace(tuple(node_inputs), tuple(node_outputs), scalars),
        # Its stages start from their own previous solutions as es's composed ones do: the
        # same tolerance (four_link_actuated, K = 7, 400 steps of 0.01 s: balance drift
        # 2.0e-11 J at 1e-10, 1.0e-12 J at 1e-12).
        newton_overrides=(("update_rtol", COMPOSED_UPDATE_RTOL),),
        quadrature_rule=(f"the k = 1 Galerkin step with {quadrature + 1}-point Gauss-Lobatto "
                         f"quadrature of every term (K = {quadrature})"),
    )
