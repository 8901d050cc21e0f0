"""What a solver returns: a simulation's samples and counters, one step, a step's Jacobians."""
from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from . import contract


def sample_joints(columns) -> int:
    """The number of joints of a sample row with these column names (contract.SAMPLE_COLUMNS):
    its phi<i> columns."""
    pattern = re.compile(contract.SAMPLE_COLUMNS[1].name.replace("{i}", "[0-9]+"))
    return sum(1 for name in columns if pattern.fullmatch(name))


def sample_slice(columns, name: str) -> slice:
    """The entries of the column `name` of contract.SAMPLE_COLUMNS (e.g. "phi{i}": every
    joint's) in a row with these column names."""
    column = next(column for column in contract.SAMPLE_COLUMNS if column.name == name)
    names = column.names(sample_joints(columns))
    start = list(columns).index(names[0])
    return slice(start, start + len(names))


def storage_of(manifest: dict) -> str:
    """What a package's energy column is: H_d with a [control] law in its step, else H."""
    return "H_d" if manifest.get("control") else "H"


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
    rtol: float = 0.0           # the adaptive tolerances the run took (0: fixed steps)
    atol: float = 0.0
    #: The inputs of the actuated joints at the sampled steps, row j held over step j * every
    #: (ceil(n_steps / every) rows, nu): those given, or those a controller chose (with every = 1,
    #: every step's); None for a scene without actuation.
    torques: np.ndarray | None = field(default=None, repr=False)
    actuated_joints: tuple[int, ...] = ()
    # What the energy column is: "H" = T + V, or "H_d" = T + V + V_s, the closed loop's
    # storage of a package whose step holds a [control] law (feature `control`).
    storage: str = "H"

    def column(self, name: str) -> np.ndarray:
        return self.samples[:, self.columns.index(name)]

    @property
    def n_joints(self) -> int:
        return sample_joints(self.columns)

    @property
    def t(self) -> np.ndarray:
        return self.column("t")

    @property
    def phi(self) -> np.ndarray:
        return self.samples[:, sample_slice(self.columns, "phi{i}")]

    @property
    def omega(self) -> np.ndarray:
        return self.samples[:, sample_slice(self.columns, "omega{i}")]

    @property
    def energy(self) -> np.ndarray:
        return self.column("energy")

    @property
    def energy_error(self) -> np.ndarray:
        """e_E = H - H_0 at every sample, signed (model.md section 8); with energy flows the
        scheme's error is `balance_error`."""
        return self.energy - self.energy[0]

    @property
    def constraint_error(self) -> np.ndarray:
        return self.column("constraint_error")

    @property
    def has_flows(self) -> bool:
        """True when the rows carry the energy flows (contract.FLOW_ENTRIES) of an actuated or
        damped scene."""
        return all(name in self.columns for name in contract.FLOW_ENTRIES)

    @property
    def input_work(self) -> np.ndarray:
        """Work of the joint torques since t = 0 (zero for a scene without energy flows)."""
        name = contract.FLOW_ENTRIES[0]
        return self.column(name) if name in self.columns else 0 * self.t

    @property
    def dissipated(self) -> np.ndarray:
        """Energy dissipated by joint damping since t = 0 (zero for a scene without)."""
        name = contract.FLOW_ENTRIES[1]
        return self.column(name) if name in self.columns else 0 * self.t

    @property
    def balance_error(self) -> np.ndarray:
        """e_B = H - H_0 - input_work + dissipated at every sample, signed: the energy the
        scheme created (model.md 7 and 8); e_E (energy_error) for a scene without flows."""
        return self.energy_error - self.input_work + self.dissipated

    @property
    def t_realtime(self) -> float:
        """t_computation / t_simulation (model.md section 8)."""
        return self.wall_time / (self.n_steps * self.dt) if self.n_steps else float("nan")

    @property
    def mean_newton_iterations(self) -> float:
        return self.newton_iterations / self.n_steps if self.n_steps else 0.0

    def _sampled_torques(self) -> np.ndarray | None:
        """The torques at the sample times: row j is the input of the step that starts at
        sample j (NaN on the last row of a run whose end is a sample: no step starts there)."""
        if self.torques is None:
            return None
        sampled = np.full((len(self.samples), self.torques.shape[1]), np.nan)
        rows = min(len(self.samples), len(self.torques))
        sampled[:rows] = self.torques[:rows]      # row j: the step j * every, sample j's
        return sampled

    def to_dataframe(self):
        """The samples as a pandas DataFrame indexed by t, one column per trajectory column
        (docs/scene-format.md), and u<j> for the torque of actuated joint j at each sample
        (the input of the step that starts there). Needs pandas (the sweep extra)."""
        import pandas as pd

        frame = pd.DataFrame(self.samples, columns=list(self.columns), copy=True)
        sampled = self._sampled_torques()
        if sampled is not None:
            for index, joint in enumerate(self.actuated_joints):
                frame[f"u{joint}"] = sampled[:, index]
        frame = frame.set_index("t")
        frame.attrs.update(self._attributes())
        return frame

    def to_xarray(self):
        """The samples as an xarray Dataset on the coordinates t and joint: phi and omega
        (t, joint), energy, constraint_error (and the energy flows) over t, u (t, actuated
        joint) for an actuated scene; the run's settings and counters as attributes. Its
        arrays are copies: changing the Dataset leaves the result as it was (they were views
        of `samples`). Needs xarray (the sweep extra)."""
        import xarray as xr

        joints = np.arange(1, self.n_joints + 1)
        variables = {}
        for column in contract.SAMPLE_COLUMNS[1:]:      # t is the coordinate
            units = {"units": column.unit} if column.unit else {}
            if column.per_joint:
                name = column.name.replace("{i}", "")
                variables[name] = (("t", "joint"),
                                   self.samples[:, sample_slice(self.columns,
                                                                column.name)].copy(), units)
            elif column.name in self.columns:
                variables[column.name] = ("t", self.column(column.name).copy(), units)
        coordinates = {"t": ("t", self.t.copy(), {"units": contract.SAMPLE_COLUMNS[0].unit}),
                       "joint": joints}
        sampled = self._sampled_torques()
        if sampled is not None:
            variables["u"] = (("t", "actuated_joint"), sampled, {"units": "N m"})
            coordinates["actuated_joint"] = np.array(self.actuated_joints)
        return xr.Dataset(variables, coords=coordinates, attrs=self._attributes())

    def _attributes(self) -> dict:
        attributes = {"scene": self.scene, "method": self.method, "dt": self.dt,
                      "n_steps": self.n_steps, "every": self.every, "order": self.order,
                      "newton_iterations": self.newton_iterations,
                      "max_newton_iterations": self.max_newton_iterations,
                      "wall_time": self.wall_time}
        if self.quadrature is not None:
            attributes["quadrature"] = self.quadrature
        attributes.update({f"parameter {path}": value
                           for path, value in self.parameters.items()})
        return attributes


@dataclass(frozen=True)
class StepResult:
    """One step: the next state, the Newton iterations spent, and the step's energy flows."""

    x1: np.ndarray
    iterations: int
    input_work: float = 0.0   # work of the joint torques over the step (J)
    dissipated: float = 0.0   # energy dissipated by joint damping over the step (J), >= 0


@dataclass(frozen=True)
class ControlledStep:
    """A step of a scheme with a control law (Solver.control_torques): the torque each actuated
    joint applied over it, the next state, and the Newton iterations spent."""

    tau: np.ndarray     # (nu,): in the order of the actuated joints (N m)
    x1: np.ndarray
    iterations: int


@dataclass(frozen=True)
class Sensitivities:
    """A step and its Jacobians in the joint-space state s = (phi, omega)."""

    x1: np.ndarray
    iterations: int
    ds_ds: np.ndarray   # (2n, 2n): d s_{k+1} / d s_k
    ds_du: np.ndarray   # (2n, nu): d s_{k+1} / d u_k
    ds_dp: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # (2n, np): d/dp
