"""One chunk of a sweep's runs: simulate each with the solver, summarise it, keep its samples.

Used by every engine (local threads, Dask workers): a chunk is a contiguous range of run
indices, small enough to keep the per-task overhead low and big enough to amortise it.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ...errors import ChaingenError, NewtonError
from ...runtime import Solver, StopSignal, contract
from .spec import SweepSpec

#: The metrics (largest energy and constraint error) are taken over every step of a run of up
#: to this many steps, over every k-th step of a longer one (k the smallest that fits).
METRIC_SAMPLES = 100_000

#: Failure names of the status column, by C status code (ok is "ok"): the contract's names.
STATUS_NAMES = {status.code: status.name.lower() for status in contract.STATUSES}


#: The numeric columns of runs.parquet beside the axes (and phi1..phin, omega1..omegan).
SUMMARY_COLUMNS = ("steps", "max_energy_error", "max_constraint_error", "newton_mean",
                   "newton_max", "cpu_seconds")


def metric_columns(n: int) -> tuple[str, ...]:
    """Every numeric column of runs.parquet but the run index and the axes."""
    return SUMMARY_COLUMNS + tuple(f"phi{i}" for i in range(1, n + 1)) \
        + tuple(f"omega{i}" for i in range(1, n + 1))


@dataclass
class ChunkResult:
    """The runs [first, first + count): one summary row per run, and their samples when the
    sweep keeps trajectories (arrays over (run, sample, ...), NaN past a run's end)."""

    first: int
    rows: list[dict]
    phi: np.ndarray | None = None
    omega: np.ndarray | None = None
    energy: np.ndarray | None = None
    constraint_error: np.ndarray | None = None
    time: np.ndarray | None = None


def sample_count(spec: SweepSpec) -> int:
    """Samples kept per run: the longest run's (0 without trajectories)."""
    if not spec.every:
        return 0
    return max(spec.n_steps(run) // spec.every + 1 for run in spec.runs)


class ChunkStopped(ChaingenError):
    """The sweep was stopped while this chunk ran: it is not stored."""


def run_chunk(spec: SweepSpec, solver: Solver, first: int, count: int,
              build_hash: str, stop: StopSignal | None = None) -> ChunkResult:
    """Simulate runs first .. first + count - 1 of `spec` with `solver` (one whose parameters
    are spec.parameters). A run that fails is a row with its status; the chunk goes on. A
    `stop` signal ends the chunk within a step of the run in progress (ChunkStopped)."""
    n = spec.scene.n
    samples = sample_count(spec)
    kept = count if samples else 0
    result = ChunkResult(first, [])
    if samples:
        result.phi = np.full((kept, samples, n), np.nan)
        result.omega = np.full((kept, samples, n), np.nan)
        result.energy = np.full((kept, samples), np.nan)
        result.constraint_error = np.full((kept, samples), np.nan)
        result.time = np.full((kept, samples), np.nan)
    for offset in range(count):
        index = first + offset
        run = spec.runs[index]
        phi0 = list(spec.scene.initial_angles)
        omega0 = list(spec.scene.initial_velocities)
        for path, value in run.items():
            if path.startswith("initial.angles["):
                phi0[int(path[len("initial.angles["):-1])] = value
            elif path.startswith("initial.velocities["):
                omega0[int(path[len("initial.velocities["):-1])] = value
        dt = run.get("simulation.dt", spec.scene.simulation.dt)
        steps = spec.n_steps(run)
        parameters = {path: run[path] for path in spec.parameters}
        row = {"run": index, **{axis.path: run[axis.path] for axis in spec.axes},
               "status": "ok", "message": "", "solver": build_hash}
        stride = metric_stride(steps, spec.every)
        if stop is not None and stop.stopped:
            raise ChunkStopped(f"runs {first}..{first + count - 1}: stopped")
        started = time.thread_time()
        try:
            simulated = solver.simulate(phi0, omega0, dt=dt, n_steps=steps, every=stride,
                                        options=spec.options, parameters=parameters, stop=stop)
            failure = None
        except NewtonError as error:
            if stop is not None and stop.stopped:
                raise ChunkStopped(f"runs {first}..{first + count - 1}: stopped") from None
            simulated, failure = error.result, error
        row["cpu_seconds"] = time.thread_time() - started
        if failure is not None:
            row["status"] = STATUS_NAMES.get(failure.status, f"status_{failure.status}")
            row["message"] = str(failure)
        row.update(_summary(simulated, n, failure is None))
        result.rows.append(row)
        if samples and simulated is not None:
            kept_rows = slice(None, None, spec.every // stride)
            valid = min(len(simulated.samples[kept_rows]), samples)
            result.phi[offset, :valid] = simulated.phi[kept_rows][:valid]
            result.omega[offset, :valid] = simulated.omega[kept_rows][:valid]
            result.energy[offset, :valid] = simulated.energy[kept_rows][:valid]
            result.constraint_error[offset, :valid] = \
                simulated.constraint_error[kept_rows][:valid]
            result.time[offset, :valid] = simulated.t[kept_rows][:valid]
    return result


def metric_stride(steps: int, every: int) -> int:
    """The sampling of a run: every step up to METRIC_SAMPLES, else the smallest stride that
    fits; a divisor of the trajectory's `every` (or `every` itself) when trajectories are kept."""
    stride = max(1, -(-steps // METRIC_SAMPLES))
    if every and every % stride:
        return every
    return stride


def _summary(simulated, n: int, completed: bool) -> dict:
    """The metrics of one run (NaN where the run has none)."""
    nan = float("nan")
    if simulated is None or not len(simulated.samples):
        values = {"steps": 0, "max_energy_error": nan, "max_constraint_error": nan,
                  "newton_mean": nan, "newton_max": 0}
        final = np.full(2 * n, nan)
    else:
        error = simulated.balance_error if "dissipated" in simulated.columns \
            else simulated.energy_error
        values = {"steps": int(simulated.n_steps),
                  "max_energy_error": float(np.abs(error).max()),
                  "max_constraint_error": float(np.abs(simulated.constraint_error).max()),
                  "newton_mean": float(simulated.mean_newton_iterations),
                  "newton_max": int(simulated.max_newton_iterations)}
        final = (np.concatenate([simulated.phi[-1], simulated.omega[-1]]) if completed
                 else np.full(2 * n, nan))
    values.update({f"phi{i + 1}": float(final[i]) for i in range(n)})
    values.update({f"omega{i + 1}": float(final[n + i]) for i in range(n)})
    return values
