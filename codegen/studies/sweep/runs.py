"""One chunk of a sweep's runs: simulate each with the solver, summarise it, keep its samples.

Used by every engine (local threads, Dask workers): a chunk is a contiguous range of run
indices, small enough to keep the per-task overhead low and big enough to amortise it.
"""
from __future__ import annotations

import math
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
    return spec.sample_count()


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
        steps = int(spec.steps[index])
        parameters = {path: run[path] for path in spec.parameters}
        row = {"run": index, **{axis.path: run[axis.path] for axis in spec.axes},
               "status": "ok", "message": "", "solver": build_hash}
        metric = metric_stride(steps)
        wanted = {"metrics": metric, "final": steps}
        if spec.every:
            wanted["trajectory"] = spec.every
        found: dict[str, tuple] = {}      # what -> (result, rows of it, failure)
        row["cpu_seconds"] = 0.0
        for stride, covers in sampling(steps, wanted):
            if stop is not None and stop.stopped:
                raise ChunkStopped(f"runs {first}..{first + count - 1}: stopped")
            started = time.thread_time()
            try:
                simulated = solver.simulate(phi0, omega0, dt=dt, n_steps=steps, every=stride,
                                            options=spec.options, parameters=parameters,
                                            stop=stop)
                failure = None
            except NewtonError as error:
                if stop is not None and stop.stopped:
                    raise ChunkStopped(f"runs {first}..{first + count - 1}: stopped") from None
                simulated, failure = error.result, error
            row["cpu_seconds"] += time.thread_time() - started
            for what in covers:
                found[what] = (simulated, slice(None, None, wanted[what] // stride), failure)
        simulated, rows, failure = found["metrics"]
        if failure is not None:
            row["status"] = STATUS_NAMES.get(failure.status, f"status_{failure.status}")
            row["message"] = str(failure)
        row.update(_summary(simulated, rows, n))
        final, _, failed = found["final"]
        state = (np.concatenate([final.phi[-1], final.omega[-1]])
                 if failed is None and final is not None else np.full(2 * n, np.nan))
        row.update({f"phi{i + 1}": float(state[i]) for i in range(n)})
        row.update({f"omega{i + 1}": float(state[n + i]) for i in range(n)})
        result.rows.append(row)
        if samples:
            simulated, rows, _ = found["trajectory"]
            if simulated is not None:
                valid = min(len(simulated.samples[rows]), samples)
                result.phi[offset, :valid] = simulated.phi[rows][:valid]
                result.omega[offset, :valid] = simulated.omega[rows][:valid]
                result.energy[offset, :valid] = simulated.energy[rows][:valid]
                result.constraint_error[offset, :valid] = \
                    simulated.constraint_error[rows][:valid]
                result.time[offset, :valid] = simulated.t[rows][:valid]
    return result


def metric_stride(steps: int) -> int:
    """The metrics' stride (docs/sweep-format.md): every step of a run of up to
    METRIC_SAMPLES steps, else the smallest stride that keeps at most that many."""
    return max(1, -(-steps // METRIC_SAMPLES))


#: A simulate call of a run may hold this many sample rows, beyond those its trajectory keeps.
MAX_ROWS = 4 * METRIC_SAMPLES


def sampling(steps: int, wanted: dict[str, int]) -> list[tuple[int, tuple[str, ...]]]:
    """The simulate calls of a run of `steps` steps: (stride, what it serves) for each, where
    `wanted` gives the stride each thing needs (the metrics, the trajectory, the final state:
    stride `steps`). A call of stride c serves every stride that is a multiple of c. As few
    calls as do it, each of at most MAX_ROWS samples (or the trajectory's own): one call for a
    run of up to METRIC_SAMPLES steps, and for most longer ones. The calls of one run are the
    same run (bitwise), sampled differently."""
    def fits(group: tuple[str, ...], stride: int) -> bool:
        return (steps // stride + 1 <= MAX_ROWS
                or ("trajectory" in group and stride == wanted["trajectory"]))

    best = None
    for partition in _partitions(tuple(wanted)):
        calls = [(math.gcd(*(wanted[what] for what in group)), group) for group in partition]
        if all(fits(group, stride) for stride, group in calls):
            cost = (len(calls), sum(steps // stride for stride, _ in calls))
            if best is None or cost < best[0]:
                best = (cost, calls)
    return best[1]


def _partitions(items: tuple) -> list[list[tuple]]:
    """Every partition of `items` into groups."""
    if not items:
        return [[]]
    head, rest = items[0], items[1:]
    partitions = []
    for partition in _partitions(rest):
        partitions.append([(head,)] + partition)
        for index, group in enumerate(partition):
            partitions.append(partition[:index] + [(head,) + group] + partition[index + 1:])
    return partitions


def _summary(simulated, rows: slice, n: int) -> dict:
    """The metrics of one run over the sample rows `rows` (NaN where the run has none)."""
    nan = float("nan")
    if simulated is None or not len(simulated.samples):
        return {"steps": 0, "max_energy_error": nan, "max_constraint_error": nan,
                "newton_mean": nan, "newton_max": 0}
    # max |e_B| (model.md 8): the balance error, which is H - H_0 without energy flows
    # (docs/sweep-format.md names the column max_energy_error).
    error = simulated.balance_error if simulated.has_flows else simulated.energy_error
    return {"steps": int(simulated.n_steps),
            "max_energy_error": float(np.abs(error[rows]).max()),
            "max_constraint_error": float(np.abs(simulated.constraint_error[rows]).max()),
            "newton_mean": float(simulated.mean_newton_iterations),
            "newton_max": int(simulated.max_newton_iterations)}
