"""The step sensitivities' generated functions (docs/model.md, section 11), by directions.

The Jacobians the C runtime needs for the implicit function theorem, R = [F_x0 X_s, F_u,
F_x0 X_p + F_p] and the output map's partials at fixed z, are dense blocks of n^2 entries.
Written as one CasADi expression each, their code grows as n^2 and worse (CSE across the
columns): es at order 4 on a 10-link chain had 40 MB of C. Here each is the forward
derivative of the function it differentiates (F, the output map S, the state map X) in
JACOBIAN_CHUNK directions, called by the generated C in a loop over the columns of the
identity (jacobians.swept_jacobians): O(n) code, and the same entry points and layouts as
before, so the runtime is unchanged. Each builder takes the scheme's translation `t`
(casadi_functions.SchemeTranslation, not imported: it imports this module).
"""
from __future__ import annotations

import casadi as ca

from .jacobians import (
    JACOBIAN_CHUNK,
    UNROLLED_JACOBIAN_MAX_INSTRUCTIONS,
    Sweep,
    SweptBlock,
)
from .translation import GeneratedFunction

#: A sensitivity function is generated dense, one expression per entry (CasADi's Jacobians,
#: unrolled), on chains of fewer than SWEPT_MIN_LINKS links while it takes at most
#: DENSE_MAX_INSTRUCTIONS instructions (jacobians.UNROLLED_JACOBIAN_MAX_INSTRUCTIONS, as the
#: Newton Jacobian); otherwise by directions. Dense is faster where it is small: every pass of
#: the directions evaluates the differentiated function's nominal part again (step_sensitivities
#: on the scaling chain of 3 links by directions: vi 2.6x, midpoint 1.5x, es 1.3x the time of
#: dense). From 5 links on every chain goes by directions, so that the code grows as one
#: function of n (at 5 links dense would be smaller than by directions, at 10 much larger).
#: DENSE_MAX_ENTRIES keeps the trial cheap where run-time parameters make the Jacobians wide:
#: es's joint_maps at order 4 and n = 10 (2400 entries) took CasADi 15 s dense.
SWEPT_MIN_LINKS = 5
DENSE_MAX_ENTRIES = 1024
DENSE_MAX_INSTRUCTIONS = UNROLLED_JACOBIAN_MAX_INSTRUCTIONS


def seed_matrix(rows: int, columns: int = JACOBIAN_CHUNK) -> ca.SX:
    """The seed of a swept function: `rows` x `columns` directions."""
    return ca.SX.sym("seed", rows, columns)


def blocks(names_and_sizes, tangent: int = 0, start: int = 0) -> list[SweptBlock]:
    """Consecutive column blocks of one tangent, (name, count) each; a count 0 is left out."""
    found = []
    for name, count in names_and_sizes:
        if count:
            found.append(SweptBlock(name, tangent, start, count))
        start += count
    return found


def jacobian_function(t, name: str, seeds: int, tangents_of, swept: list[SweptBlock],
                      dense_of, inputs=None, input_names=None) -> GeneratedFunction:
    """A function of Jacobian blocks of the step's arguments, or of `inputs`: dense_of() ->
    its outputs unrolled (the blocks' Jacobians) where that is small (SWEPT_MIN_LINKS,
    DENSE_MAX_ENTRIES, DENSE_MAX_INSTRUCTIONS), else by directions (jacobians.Sweep):
    tangents_of(seed) -> the
    tangents, linear in the seed matrix of `seeds` rows."""
    inputs = list(t.step_args if inputs is None else inputs)
    input_names = list(t.step_names if input_names is None else input_names)
    seed = seed_matrix(seeds)
    tangents = tangents_of(seed)
    entries = sum(tangents[block.tangent].shape[0] * block.count for block in swept)
    if t.n < SWEPT_MIN_LINKS and entries <= DENSE_MAX_ENTRIES:
        dense = [ca.densify(output) for output in dense_of()]
        if ca.Function("size", inputs, dense).n_instructions() <= DENSE_MAX_INSTRUCTIONS:
            return GeneratedFunction(name, tuple(inputs), tuple(input_names), tuple(dense),
                                     tuple(block.name for block in swept))
    return GeneratedFunction(name, tuple(inputs + [seed]), tuple(input_names + ["seed"]),
                             tuple(tangents), tuple(f"d{i}" for i in range(len(tangents))),
                             Sweep(seeds, tuple(swept)))


def sensitivity_functions(t) -> tuple[GeneratedFunction, GeneratedFunction]:
    """The controller's state is s = (phi, omega); x0 = X(s0, p) (initial_state), s1 =
    S(x1, p) (outputs). With F(z*, x0, u, p) = 0, dz*/d(s0, u, p) = -J^-1 [F_x0 X_s, F_u,
    F_x0 X_p + F_p] (the C code solves it with one LU of J at z*), and ds1/d(s0, u, p) =
    S_x1 (x1_z dz* + [x1_x0 X_s, x1_u, x1_x0 X_p + x1_p]) + [0, 0, S_p]. X is evaluated at
    s0 = S(x0, p), so the functions take x0 as the step does.

    Large ones by directions (jacobians.Sweep): R column by column as the forward derivative
    of F in the direction (dx0, du, dp) = (X_s ds0 + X_p dp, du, dp), and the map as that of
    s1 in (dz, dx0, du, dp), so that their code grows with F and S, O(n), not with the
    Jacobians' entries (docs/model.md, section 11)."""
    nchain, nu, n_p, nz = 2 * t.n, t.nu, t.n_p, t.nz
    columns = nchain + nu + n_p
    s1 = ca.vertcat(*t.joint_space(t.next_state)[:2])

    def tangent_x0(seed: ca.SX) -> ca.SX:
        """dx0 = X_s ds0 + X_p dp at s0 = S(x0), for the seed's (ds0, du, dp) rows."""
        return t.state_tangent(t.x0, seed[:nchain, :], seed[nchain + nu:, :])

    def rhs_tangent(seed):
        return [ca.jtimes(t.residual, ca.vertcat(t.x0, t.u, t.p),
                          ca.vertcat(tangent_x0(seed), seed[nchain:, :]))]

    def map_tangent(seed):
        state_seed = seed[nz:, :]
        return [ca.jtimes(s1, ca.vertcat(t.z, t.x0, t.u, t.p),
                          ca.vertcat(seed[:nz, :], tangent_x0(state_seed),
                                     state_seed[nchain:, :]))]

    def dense_rhs():
        x_s, x_p = t.state_maps()
        f_x0 = ca.jacobian(t.residual, t.x0)
        return [ca.horzcat(ca.mtimes(f_x0, x_s), ca.jacobian(t.residual, t.u),
                           ca.mtimes(f_x0, x_p) + ca.jacobian(t.residual, t.p))]

    def dense_map():
        x_s, x_p = t.state_maps()
        s1_x0 = ca.jacobian(s1, t.x0)
        return ([ca.jacobian(s1, t.z), ca.mtimes(s1_x0, x_s)]
                + ([ca.jacobian(s1, t.u)] if nu else [])
                + ([ca.mtimes(s1_x0, x_p) + ca.jacobian(s1, t.p)] if n_p else []))

    return (jacobian_function(t, "sensitivity_rhs", columns, rhs_tangent,
                              blocks([("R", columns)]), dense_rhs),
            jacobian_function(t, "sensitivity_map", nz + columns, map_tangent,
                              blocks([("s1_z", nz), ("s1_s0", nchain), ("s1_u", nu),
                                      ("s1_p", n_p)]), dense_map))


def state_chain_functions(t) -> tuple[GeneratedFunction, ...]:
    """The stage Jacobians in the whole state x (SchemeFunctions.joint_maps): with
    F(z*, x0, u, p) = 0, dx1/d(x0, u, p) = x1_z dz* + [x1_x0, x1_u, x1_p] and
    dz* = -J^-1 [F_x0, F_u, F_p]; the composed step's ds1/ds0 = S_x1 D X_s. Large ones by
    directions, as sensitivity_functions."""
    nx, nu, n_p, nz, ns = t.nx, t.nu, t.n_p, t.nz, 2 * t.n
    x1 = t.next_state
    s1 = ca.vertcat(*t.joint_space(t.x)[:2])

    def rhs_tangent(seed):
        return [ca.jtimes(t.residual, ca.vertcat(t.x0, t.u, t.p), seed)]

    def map_tangent(seed):
        return [ca.jtimes(x1, ca.vertcat(t.z, t.x0, t.u, t.p), seed)]

    def maps_tangent(seed):
        """seeds (ds0, dx1, dp): dx0 = X_s ds0 + X_p dp at s0 = S(x0), ds1 = S_x dx1 + S_p dp
        at x1."""
        return [t.state_tangent(t.x0, seed[:ns, :], seed[ns + nx:, :]),
                ca.jtimes(s1, ca.vertcat(t.x, t.p), seed[ns:, :])]

    def dense_rhs():
        return [ca.horzcat(ca.jacobian(t.residual, t.x0), ca.jacobian(t.residual, t.u),
                           ca.jacobian(t.residual, t.p))]

    def dense_map():
        return ([ca.jacobian(x1, t.z), ca.jacobian(x1, t.x0)]
                + ([ca.jacobian(x1, t.u)] if nu else [])
                + ([ca.jacobian(x1, t.p)] if n_p else []))

    def dense_maps():
        x_s, x_p = t.state_maps()
        return ([x_s, ca.jacobian(s1, t.x)]
                + ([x_p, ca.jacobian(s1, t.p)] if n_p else []))

    maps_blocks = (blocks([("x0_s0", ns)], 0) + blocks([("s1_x1", nx)], 1, ns)
                   + blocks([("x0_p", n_p)], 0, ns + nx) + blocks([("s1_p", n_p)], 1, ns + nx))
    return (jacobian_function(t, "sensitivity_rhs", nx + nu + n_p, rhs_tangent,
                              blocks([("R", nx + nu + n_p)]), dense_rhs),
            jacobian_function(t, "sensitivity_map", nz + nx + nu + n_p, map_tangent,
                              blocks([("x1_z", nz), ("x1_x0", nx), ("x1_u", nu),
                                      ("x1_p", n_p)]), dense_map),
            jacobian_function(t, "joint_maps", ns + nx + n_p, maps_tangent, maps_blocks,
                              dense_maps, [t.x0, t.x] + t.with_p[0],
                              ["x0", "x1"] + t.with_p[1]))
