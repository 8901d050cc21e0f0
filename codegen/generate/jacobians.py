"""How the Newton Jacobian dF/dz and the step sensitivities' Jacobians are generated: unrolled
entry by entry, or by forward directions in a loop (docs/model.md, sections 11 and 17).

CasADi's symbolic Jacobian of a residual is fast to evaluate, but its generated code has one
expression per entry: for a chain in joint space, whose Jacobian is dense, O(n^2), and gcc's
time on one function grows faster than its size. By directions, the generated code is one
forward derivative of F in a few directions, called in a loop over the columns: O(n).
"""
from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

#: Forward directions per pass of a Jacobian evaluated by directions (jacobian_by_directions,
#: swept_jacobians).
JACOBIAN_CHUNK = 4
#: The Newton Jacobian is generated entry by entry (CasADi's symbolic Jacobian, unrolled) while
#: that takes at most this many instructions; above, by forward directions in a loop: the code
#: then grows with the residual, O(n), not with the Jacobian's n^2 entries, and gcc -O2 compiles
#: it in seconds instead of minutes (gcc's time grows faster than the size of one function).
#: Measured on the bench's scaling chain of 20 links: midpoint's unrolled Jacobian has 9.9e3
#: instructions (build 7.0 s, 10.2 us a step), vi's 2.1e4 (21.4 s, 11.1 us); by directions
#: vi builds in 9.4 s and steps in 22.9 us. es's Galerkin step at K = 7 (n = 3) has 1.8e4.
UNROLLED_JACOBIAN_MAX_INSTRUCTIONS = 20_000
#: More unknowns than this go by directions without trying the unrolled Jacobian.
UNROLLED_JACOBIAN_MAX_UNKNOWNS = 64


def unrolled_jacobian(residual: ca.SX, z: ca.SX, inputs) -> ca.SX | None:
    """dF/dz dense and unrolled, or None where it is too large (see
    UNROLLED_JACOBIAN_MAX_INSTRUCTIONS): then the Jacobian is evaluated by directions."""
    if z.shape[0] > UNROLLED_JACOBIAN_MAX_UNKNOWNS:
        return None
    jacobian = ca.densify(ca.jacobian(residual, z))
    size = ca.Function("size", inputs, [residual, jacobian]).n_instructions()
    return jacobian if size <= UNROLLED_JACOBIAN_MAX_INSTRUCTIONS else None


def jacobian_by_directions(name: str, inputs, input_names, residual: ca.SX, unknown: int,
                           chunk: int, options: dict, blocks=()) -> ca.Function:
    """(F, dF/dz dense) with dF/dz computed `chunk` columns at a time: the forward derivative
    of F in `chunk` directions, mapped serially over the passes with the columns of the
    identity as seeds. The generated C is a loop over the passes around one forward
    derivative, so it grows with F, not with the nz^2 entries of the Jacobian; the cost is
    one evaluation of F's nominal part per pass more than the unrolled Jacobian's.

    blocks: sizes of consecutive blocks of z (empty: one block). Each block has its own
    forward derivative, with respect to that block alone (CasADi's jtimes), so that the
    tangents of the quantities the block does not move are not computed."""
    z = inputs[unknown]
    nz = z.shape[0]
    blocks = tuple(blocks) or (nz,)
    if sum(blocks) != nz or min(blocks) < 1:
        raise ValueError(f"{name}: blocks {blocks} do not partition {nz} unknowns")
    symbols = [ca.MX.sym(label, item.shape[0], item.shape[1])
               for label, item in zip(input_names, inputs)]
    value = ca.Function(f"{name}_F", inputs, [residual], options)(*symbols)
    columns, start = [], 0
    for index, size in enumerate(blocks):
        passes = -(-size // chunk)
        seeds = ca.SX.sym("seeds", size, chunk)
        tangent = ca.jtimes(residual, z[start:start + size], seeds)
        forward = ca.Function(f"{name}_D{index}", list(inputs) + [seeds], [tangent],
                              options).map(passes, "serial")
        identity = ca.horzcat(ca.DM.eye(size), ca.DM(size, passes * chunk - size))
        columns.append(forward(*symbols, identity)[:, :size])
        start += size
    return ca.Function(name, symbols, [value, ca.horzcat(*columns)], input_names, ["F", "J"])


@dataclass(frozen=True)
class SweptBlock:
    """One output of a function evaluated by directions: columns `first` to `first + count`
    of the tangent `tangent` (an index into the directional function's outputs), over the
    sweep's unit seeds."""

    name: str
    tangent: int
    first: int
    count: int


@dataclass(frozen=True)
class Sweep:
    """A function whose outputs are Jacobians (dense blocks), generated as a directional
    derivative called in a loop (docs/model.md, section 11): the GeneratedFunction's last input
    is a seed matrix of `seeds` rows and JACOBIAN_CHUNK columns, its outputs are the tangents in
    those directions (linear in the seed), and the function the package gets takes the other
    inputs and returns `blocks`, the tangents over the columns of the identity."""

    seeds: int
    blocks: tuple[SweptBlock, ...]


def swept_jacobians(name: str, directional: ca.Function, sweep: Sweep, input_names,
                    chunk: int = JACOBIAN_CHUNK) -> ca.Function:
    """The Jacobian blocks of `sweep` by `directional` (inputs..., seed[seeds x chunk]) ->
    tangents[. x chunk], mapped serially over ceil(seeds / chunk) passes with the columns of
    the identity as seeds. The generated C is a loop around one directional derivative, so it
    grows with the function differentiated, O(n), not with the Jacobian's entries; a pass
    costs one evaluation of that function's nominal part and `chunk` tangents."""
    passes = -(-sweep.seeds // chunk)
    count = directional.n_in() - 1
    symbols = [ca.MX.sym(label, directional.size1_in(i), directional.size2_in(i))
               for i, label in zip(range(count), input_names)]
    seeds = ca.horzcat(ca.DM.eye(sweep.seeds), ca.DM(sweep.seeds, passes * chunk - sweep.seeds))
    tangents = directional.map(passes, "serial")(*symbols, seeds)
    tangents = tangents if isinstance(tangents, (list, tuple)) else [tangents]
    outputs = [ca.densify(tangents[block.tangent][:, block.first:block.first + block.count])
               for block in sweep.blocks]
    return ca.Function(name, symbols, outputs, list(input_names),
                       [block.name for block in sweep.blocks])
