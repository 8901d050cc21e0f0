"""What a solver returns: a simulation's samples and counters, one step, a step's Jacobians."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class SimulationResult:
    """Samples of one simulation: rows of the trajectory file's columns, and its counters."""

    scene: str
    method: str
    quadrature: int | None
    dt: float
    n_steps: int
    every: int
    columns: tuple[str, ...]
    samples: np.ndarray = field(repr=False)
    wall_time: float            # seconds spent in the C loop
    newton_iterations: int      # total over all steps
    max_newton_iterations: int
    full_newton_fallbacks: int = 0   # steps whose kept Jacobian failed and full Newton solved
    split_steps: int = 0             # steps taken as halves after Newton failed on them whole
    parameters: dict = field(default_factory=dict)   # run-time parameters: path -> value
    order: int = 2              # of the step: 2, or 4 and 6 by composition
    # Adaptive steps (rtol or atol > 0): the steps taken and refused, the shortest and longest
    # taken (with fixed steps: n_steps, 0, dt, dt).
    accepted_steps: int = 0
    rejected_steps: int = 0
    smallest_dt: float = 0.0
    largest_dt: float = 0.0
    adaptive: bool = False

    def column(self, name: str) -> np.ndarray:
        return self.samples[:, self.columns.index(name)]

    @property
    def n_joints(self) -> int:
        return sum(1 for name in self.columns if name.startswith("phi"))

    @property
    def t(self) -> np.ndarray:
        return self.samples[:, 0]

    @property
    def phi(self) -> np.ndarray:
        return self.samples[:, 1:1 + self.n_joints]

    @property
    def omega(self) -> np.ndarray:
        return self.samples[:, 1 + self.n_joints:1 + 2 * self.n_joints]

    @property
    def energy(self) -> np.ndarray:
        return self.column("energy")

    @property
    def energy_error(self) -> np.ndarray:
        """e_E = H - H_0 (model.md section 8)."""
        return self.energy - self.energy[0]

    @property
    def constraint_error(self) -> np.ndarray:
        return self.column("constraint_error")

    @property
    def input_work(self) -> np.ndarray:
        """Work of the joint torques since t = 0 (zero for a scene without energy flows)."""
        return self.column("input_work") if "input_work" in self.columns else 0 * self.t

    @property
    def dissipated(self) -> np.ndarray:
        """Energy dissipated by joint damping since t = 0 (zero for a scene without)."""
        return self.column("dissipated") if "dissipated" in self.columns else 0 * self.t

    @property
    def balance_error(self) -> np.ndarray:
        """H - H_0 - input_work + dissipated: the energy the scheme created (model.md 7)."""
        return self.energy_error - self.input_work + self.dissipated

    @property
    def t_realtime(self) -> float:
        """t_computation / t_simulation (model.md section 8)."""
        return self.wall_time / (self.n_steps * self.dt) if self.n_steps else float("nan")

    @property
    def mean_newton_iterations(self) -> float:
        return self.newton_iterations / self.n_steps if self.n_steps else 0.0


@dataclass(frozen=True)
class StepResult:
    """One step: the next state, the Newton iterations spent, and the step's energy flows."""

    x1: np.ndarray
    iterations: int
    input_work: float = 0.0   # work of the joint torques over the step (J)
    dissipated: float = 0.0   # energy dissipated by joint damping over the step (J), >= 0


@dataclass(frozen=True)
class Sensitivities:
    """A step and its Jacobians in the joint-space state s = (phi, omega)."""

    x1: np.ndarray
    iterations: int
    ds_ds: np.ndarray   # (2n, 2n): d s_{k+1} / d s_k
    ds_du: np.ndarray   # (2n, nu): d s_{k+1} / d u_k
    ds_dp: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # (2n, np): d/dp
