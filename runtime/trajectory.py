"""The trajectory file of scene-format.md: a header row, then one row per sample.

Beside it, FILE.csv.json records the run that wrote it (scene, method, quadrature, dt, every,
steps): the CSV stays exactly the contract's columns, and `chaingen plot` and `animate` label
their figures from the metadata.
"""
from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

import numpy as np

from .solver import SimulationResult


def current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def metadata_path(path) -> Path:
    """The metadata file of a trajectory file: FILE.csv -> FILE.csv.json."""
    path = Path(path)
    return path.with_name(path.name + ".json")


def run_metadata(result: SimulationResult) -> dict:
    return {"scene": result.scene, "method": result.method, "quadrature": result.quadrature,
            "dt": result.dt, "every": result.every, "n_steps": result.n_steps,
            "columns": list(result.columns)}


def _staged(path: Path, write) -> str:
    """Write to a temporary file beside `path`; returns its name (the caller renames it)."""
    handle, temporary = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent or ".")
    try:
        os.chmod(temporary, 0o666 & ~current_umask())   # mkstemp's 0600 is not what users expect
        with os.fdopen(handle, "w") as stream:
            write(stream)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
    return temporary


def write_trajectory(result: SimulationResult, path, *, metadata: bool = True) -> Path:
    """Write `result` as CSV with %.17g numbers (round-trip exact) and, with `metadata`, its
    metadata file beside it.

    Both are staged in temporary files beside `path` and renamed into place only when both are
    complete, so an interrupted write never leaves a truncated trajectory or a metadata file
    without its trajectory.
    """
    path = Path(path)
    staged = []
    try:
        staged.append((_staged(path, lambda stream: np.savetxt(
            stream, result.samples, fmt="%.17g", delimiter=",",
            header=",".join(result.columns), comments="")), path))
        if metadata:
            meta = metadata_path(path)
            staged.append((_staged(meta, lambda stream: json.dump(
                run_metadata(result), stream, indent=2)), meta))
        for temporary, target in reversed(staged):   # the metadata first, the CSV last
            os.replace(temporary, target)
    except BaseException:
        for temporary, _ in staged:
            Path(temporary).unlink(missing_ok=True)
        raise
    return path


def read_trajectory(path) -> tuple[tuple[str, ...], np.ndarray]:
    """(columns, rows) of a trajectory file."""
    with open(path) as stream:
        columns = tuple(stream.readline().strip().split(","))
    rows = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return columns, rows
