"""The trajectory file (docs/scene-format.md): a header row, then one row per sample.

Beside it, FILE.csv.json records the run that wrote it (scene, method, quadrature, order, dt,
every, steps, the adaptive tolerances and, for adaptive steps, their counters, the run-time
parameters' values): the CSV stays
exactly the contract's columns, and `chaingen plot` and `animate` label their figures from the
metadata.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from .files import staged_files
from .results import SimulationResult


def metadata_path(path) -> Path:
    """The metadata file of a trajectory file: FILE.csv -> FILE.csv.json."""
    path = Path(path)
    return path.with_name(path.name + ".json")


#: What a controlled package's energy is, where a run's records name it (the trajectory's
#: metadata, a sweep's record and trajectories).
CLOSED_LOOP_ENERGY = ("H_d = T + V + V_s: the closed loop's storage (a [control] law, "
                      "docs/controllers.md)")


def run_metadata(result: SimulationResult) -> dict:
    metadata = {"scene": result.scene, "method": result.method, "quadrature": result.quadrature,
                "order": result.order, "dt": result.dt, "every": result.every,
                "n_steps": result.n_steps, "rtol": result.rtol, "atol": result.atol,
                "columns": list(result.columns)}
    if result.storage != "H":      # the energy column of a controlled package
        metadata["energy"] = CLOSED_LOOP_ENERGY
    if result.parameters:          # a solver's run-time parameters: the values the run took
        metadata["parameters"] = {path: float(value) for path, value in result.parameters.items()}
    if result.adaptive:
        metadata["adaptive_steps"] = {
            "accepted": result.accepted_steps, "rejected": result.rejected_steps,
            "smallest_dt": result.smallest_dt, "largest_dt": result.largest_dt}
    return metadata


def write_trajectory(result: SimulationResult, path, *, metadata: bool = True) -> Path:
    """Write `result` as CSV with %.17g numbers (round-trip exact) and, with `metadata`, its
    metadata file beside it.

    Both are staged beside their targets and renamed into place only when both are complete
    (the metadata first, the CSV last), so an interrupted write never leaves a truncated
    trajectory or a metadata file without its trajectory.
    """
    path = Path(path)
    targets = [path] + ([metadata_path(path)] if metadata else [])
    with staged_files(targets) as staged:
        np.savetxt(staged[0], result.samples, fmt="%.17g", delimiter=",",
                   header=",".join(result.columns), comments="")
        if metadata:
            staged[1].write_text(json.dumps(run_metadata(result), indent=2))
    return path


def read_trajectory(path) -> tuple[tuple[str, ...], np.ndarray]:
    """(columns, rows) of a trajectory file."""
    with open(path) as stream:
        columns = tuple(stream.readline().strip().split(","))
    rows = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return columns, rows
