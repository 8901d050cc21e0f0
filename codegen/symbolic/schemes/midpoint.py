"""Method "midpoint": implicit midpoint rule in joint angles (model.md section 6).

State (phi, w); M(phi) phiddot + Coriolis(phi, w) + grad V(phi) = tau, tau the inputs of the
actuated joints and damping -d_i w_i, with M, the Coriolis terms and grad V derived by SymPy from
T and V. Unknown: dw = w_1 - w_0, so that
w_m = w_0 + dw/2, phi_1 = phi_0 + dt w_m, phi_m = phi_0 + dt w_m / 2, and the residual (model.md's
multiplied by dt) is

    M(phi_m) dw + dt [Coriolis(phi_m, w_m) + grad V(phi_m) - tau(w_m)] = 0.
"""
from __future__ import annotations

import sympy as sp
from sympy import ImmutableMatrix

from ...runtime.contract import JACOBIAN_PER_STEP
from ...scene import Scene
from ..com_model import number
from ..joint_model import angle_directions, joint_space_model
from .base import (
    DiscreteScheme,
    FlowDescription,
    Layout,
    has_energy_flows,
    input_symbols,
    joint_space_state,
    joint_torques,
    segment_vectors,
)

SUMMARY = "Implicit midpoint rule in relative joint angles (docs/model.md, section 6)."
FLOWS = FlowDescription(
    "dt sum_i tau_i w_i(m)", "dt sum_i d_i w_i(m)^2",
    "w(m) the mid-point joint rates. H_1 - H_0 - flows[0] + flows[1] is the scheme's energy "
    "error, O(dt^2).")


def coriolis(model, angles) -> ImmutableMatrix:
    """Mdot w - dT/dphi = (d(M w)/dphi) w - 1/2 grad_phi (w^T M w), M = M(phi)."""
    w = model.rates
    momentum = model.mass_matrix * w
    return ImmutableMatrix(momentum.jacobian(angles) * w
                           - ImmutableMatrix([model.kinetic_energy]).jacobian(angles).T)


def build(scene: Scene, quadrature: int, order: int = 2) -> DiscreteScheme:
    """order: of the composed step; the state of every stage is the solution's, so the
    outputs are the same at every order."""
    n = scene.n
    dt = sp.Symbol("dt", positive=True)
    phi0 = ImmutableMatrix(sp.symbols(f"phi1:{n + 1}", real=True))
    w0 = ImmutableMatrix(sp.symbols(f"w1:{n + 1}", real=True))
    dw = ImmutableMatrix(sp.symbols(f"dw1:{n + 1}", real=True))
    model = joint_space_model(scene, angle_directions(phi0), w0)

    wm = w0 + dw / 2
    phim = phi0 + dt * wm / 2
    at_midpoint = {**dict(zip(phi0, phim)), **dict(zip(w0, wm))}
    inputs = input_symbols(scene)
    torques = joint_torques(scene, inputs)
    forces = (coriolis(model, phi0) + ImmutableMatrix([model.potential]).jacobian(phi0).T
              - ImmutableMatrix(torques))
    if any(link.damping for link in scene.links):
        forces = forces - model.damping_torques(w0)
    residual = model.mass_matrix.xreplace(at_midpoint) * dw + dt * forces.xreplace(at_midpoint)

    return DiscreteScheme(
        method="midpoint", quadrature=None, scene=scene, summary=SUMMARY, dt=dt, unknowns=dw,
        residual=ImmutableMatrix(residual),
        next_state=ImmutableMatrix.vstack(phi0 + dt * wm, w0 + dw),
        predictor=ImmutableMatrix.zeros(n, 1),
        **joint_space_state(scene, phi0, w0, model.energy),
        unknowns_layout=Layout(tuple(f"dw_{i}" for i in range(1, n + 1)),
                               "the increment dw = w_1 - w_0 of the joint rates (rad/s)"),
        residual_description=("dt-scaled midpoint equations of motion M(phi_m) dw + dt "
                              "(Coriolis + grad V - tau) at the mid-point (N m s)"),
        inputs=inputs, segment_vectors=segment_vectors(model),
        input_work=dt * sp.Add(*(tau * w for tau, w in zip(torques, wm))),
        dissipated=dt * sp.Add(*(number(link.damping) * w ** 2
                                 for link, w in zip(scene.links, wm) if link.damping)),
        flow_description=FLOWS if has_energy_flows(scene) else None,
        jacobian_reuse=JACOBIAN_PER_STEP,
    )
