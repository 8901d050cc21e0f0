"""Newton's Jacobian through the Jacobian of one node (DiscreteScheme's NodeSpace; es's Galerkin
step, docs/model.md section 16): for a residual of z and the outputs of one local function
evaluated at several nodes, dF/dz = F_z + sum_g F_o_g N'(y_g) Y_g, with N' generated once."""
from __future__ import annotations

import casadi as ca
import numpy as np
import sympy as sp

from .jacobians import JACOBIAN_CHUNK, jacobian_by_directions, unrolled_jacobian
from .translation import SympyToCasadi, sx_vector


def jacobian_by_nodes(t, name: str, options: dict) -> ca.Function:
    """(F, dF/dz dense) of the SchemeTranslation t through its scheme's NodeSpace:
    F_z + sum_g F_o_g N'(y_g) Y_g. N, one node's outputs as a function of its inputs (and u),
    is node 1's, translated with its inputs as free symbols; N' is its Jacobian, unrolled
    while small (UNROLLED_JACOBIAN_MAX_INSTRUCTIONS), else by forward directions in the two
    halves of the node's inputs. F_z, F_o_g and Y_g are CasADi's sparse Jacobians of F in z
    and in the outputs, and of the inputs in z. Where F depends on z and the outputs through
    the NodeSpace's scalars r too (es's energy correction), F_z and F_o are taken at fixed r,
    and F_r (dr/dz) is added, dr/dz = R_z + sum_g R_o_g N'(y_g) Y_g: a few rows through the
    nodes instead of F_o's dense ones. Every matrix is taken at the step's own outputs.
    Raises ValueError where a node's outputs are not N of its inputs (checked at a random
    point), or the inputs are not affine in z. Packages without run-time parameters only
    (their hoisting works on whole functions)."""
    scheme, nodes = t.scheme, t.scheme.step.node_space
    size, out_size = nodes.inputs[0].shape[0], nodes.outputs[0].shape[0]
    u = [t.u] if t.nu else []

    def translated(free: dict) -> SympyToCasadi:
        local = SympyToCasadi(dict(t.bindings), t.parameters)
        for symbol, expression in scheme.step.definitions:
            if symbol in free:
                local.bind(symbol, free[symbol])
            else:
                local.bind(symbol, local(expression), local.is_parametric(expression))
        return local

    y = ca.SX.sym("y", size)
    first = translated(dict(zip(nodes.inputs[0], ca.vertsplit(y))))
    node_outputs = sx_vector(first, nodes.outputs[0])
    node = ca.Function(f"{name}_node", [y] + u, [node_outputs], options)
    # The outputs of every node free: F as a function of z, them and the scalars r, and r as
    # a function of z and the outputs.
    outputs = [symbol for g in nodes.outputs for symbol in g]
    o = ca.SX.sym("o", len(outputs))
    r = ca.SX.sym("r", len(nodes.scalars))
    free_outputs = {symbol: value for symbol, value in zip(outputs, ca.vertsplit(o))
                    if isinstance(symbol, sp.Symbol)}
    residual_free = sx_vector(translated({**free_outputs, **dict(zip(nodes.scalars,
                                                                     ca.vertsplit(r)))}),
                              scheme.step.residual)
    scalars_free = sx_vector(translated(free_outputs), sp.ImmutableMatrix(nodes.scalars))
    node_values = ca.vertcat(*[sx_vector(t.step, g) for g in nodes.outputs])
    scalar_values = sx_vector(t.step, sp.ImmutableMatrix(nodes.scalars))

    def at_step(expression):
        """`expression` at the step's own outputs and scalars."""
        return ca.substitute([expression], [o, r], [node_values, scalar_values])[0]

    f_z, f_o, f_r = (at_step(ca.jacobian(residual_free, wrt)) for wrt in (t.z, o, r))
    r_z, r_o = (at_step(ca.jacobian(scalars_free, wrt)) for wrt in (t.z, o))
    inputs = ca.vertcat(*[t.step(symbol) for g in nodes.inputs for symbol in g])
    y_z = ca.jacobian(inputs, t.z)
    if ca.depends_on(ca.vertcat(*y_z.nonzeros()), t.z):
        raise ValueError(f"{name}: the nodes' inputs are not affine in z")
    check = ca.Function("check", t.step_args, [inputs, node_values])
    arguments = [np.random.default_rng(0).uniform(0.1, 0.5, a.shape) for a in t.step_args]
    at_inputs, at_outputs = (np.array(v).ravel() for v in check(*arguments))
    for g in range(len(nodes.inputs)):
        expected = np.array(node(at_inputs[g * size:(g + 1) * size],
                                 *arguments[2:2 + len(u)])).ravel()
        got = at_outputs[g * out_size:(g + 1) * out_size]
        if not np.allclose(expected, got, rtol=1e-12, atol=1e-12 * np.abs(got).max()):
            raise ValueError(f"{name}: node {g + 1}'s outputs are not the first node's function")
    node_jacobian = unrolled_jacobian(node_outputs, y, [y] + u)
    if node_jacobian is not None:
        derivative = ca.Function(f"{name}_node_J", [y] + u, [node_jacobian], options)
    else:
        by_directions = jacobian_by_directions(
            f"{name}_node_J", [y] + u, ["y"] + (["u"] if u else []), node_outputs, 0,
            JACOBIAN_CHUNK, options, (size // 2, size - size // 2))
        derivative = ca.Function(f"{name}_node_D", [y] + u, [by_directions(y, *u)[1]])
    pieces = ca.Function(f"{name}_pieces", t.step_args,
                         [t.residual, f_z, f_o, y_z, inputs, f_r, r_z, r_o], options)
    symbols = [ca.MX.sym(label, item.shape[0], item.shape[1])
               for label, item in zip(t.step_names, t.step_args)]
    value, mx_f_z, mx_f_o, mx_y_z, mx_inputs, mx_f_r, mx_r_z, mx_r_o = pieces(*symbols)
    mx_u = [symbols[2]] if u else []
    jacobian = mx_f_z
    # dr/dz = R_z + sum_g R_o_g N'(y_g) Y_g: a few rows, put into F through F_r once.
    scalar_gradient = mx_r_z
    for g in range(len(nodes.inputs)):
        block, columns = slice(g * size, (g + 1) * size), slice(g * out_size, (g + 1) * out_size)
        local = derivative(mx_inputs[block], *mx_u)
        jacobian = jacobian + ca.mtimes(ca.mtimes(mx_f_o[:, columns], local), mx_y_z[block, :])
        if nodes.scalars:
            scalar_gradient = scalar_gradient + ca.mtimes(
                ca.mtimes(mx_r_o[:, columns], local), mx_y_z[block, :])
    if nodes.scalars:
        jacobian = jacobian + ca.mtimes(mx_f_r, scalar_gradient)
    return ca.Function(name, symbols, [value, ca.densify(jacobian)], t.step_names, ["F", "J"])
