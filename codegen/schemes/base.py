"""What every time-stepping scheme hands to code generation: a plain, immutable value.

A scheme is a state x_k, unknowns z, a residual F(z; x_k, dt) = 0 solved by Newton's method, the
map to the next state, a predictor for the first Newton guess, and the maps between its state
and joint space. Templates, Newton loop, build and runtime are shared by all schemes: they see
only this value.
"""
from __future__ import annotations

from dataclasses import dataclass

import sympy as sp
from sympy import ImmutableMatrix

from ..scene import Scene


@dataclass(frozen=True)
class Layout:
    """The layout of one vector that crosses the C boundary: a name and a meaning per entry."""

    entries: tuple[str, ...]
    description: str

    def __len__(self) -> int:
        return len(self.entries)


@dataclass(frozen=True)
class LinearSolve:
    """Symbols defined implicitly by matrix * symbols = rhs, all functions of the state.

    "vi" stores momenta, so its joint rates are w = M(q)^-1 p: the outputs use the symbols w
    and the C code solves for them, instead of SymPy inverting M symbolically.
    """

    symbols: ImmutableMatrix
    matrix: ImmutableMatrix
    rhs: ImmutableMatrix


@dataclass(frozen=True)
class DiscreteScheme:
    method: str
    quadrature: int
    scene: Scene
    dt: sp.Symbol
    state: ImmutableMatrix             # symbols of x_k
    unknowns: ImmutableMatrix          # symbols of z
    residual: ImmutableMatrix          # F(z; x_k, dt), one entry per unknown
    next_state: ImmutableMatrix        # x_{k+1}(z; x_k, dt)
    predictor: ImmutableMatrix         # first Newton guess z(x_k, dt)
    joint_angles: ImmutableMatrix      # phi(x), relative angles wrapped to (-pi, pi]
    joint_velocities: ImmutableMatrix  # omega(x), relative angular velocities
    energy: sp.Expr                    # H(x) = T + V
    constraint_residuals: ImmutableMatrix  # structural errors of x; C reports max |.|
    initial_angles: ImmutableMatrix    # symbols phi of initial_state
    initial_velocities: ImmutableMatrix  # symbols phidot of initial_state
    initial_state: ImmutableMatrix     # x(phi, phidot)
    state_layout: Layout
    unknowns_layout: Layout
    residual_description: str
    output_solve: LinearSolve | None = None   # symbols the outputs use beside the state

    def __post_init__(self) -> None:
        if self.residual.shape[0] != self.unknowns.shape[0]:
            raise ValueError(f"{self.method}: {self.residual.shape[0]} residual entries for "
                             f"{self.unknowns.shape[0]} unknowns")
        if self.next_state.shape[0] != self.state.shape[0]:
            raise ValueError(f"{self.method}: next_state does not match the state")
