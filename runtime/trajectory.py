"""The trajectory file of scene-format.md: a header row, then one row per sample."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from .solver import SimulationResult


def current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def write_trajectory(result: SimulationResult, path) -> Path:
    """Write `result` as CSV with %.17g numbers (round-trip exact), atomically.

    The rows go to a temporary file beside `path` that replaces it only when complete, so an
    interrupted write never leaves a truncated trajectory.
    """
    path = Path(path)
    handle, temporary = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent or ".")
    try:
        os.chmod(temporary, 0o666 & ~current_umask())   # mkstemp's 0600 is not what users expect
        with os.fdopen(handle, "w") as stream:
            np.savetxt(stream, result.samples, fmt="%.17g", delimiter=",",
                       header=",".join(result.columns), comments="")
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
    return path


def read_trajectory(path) -> tuple[tuple[str, ...], np.ndarray]:
    """(columns, rows) of a trajectory file."""
    with open(path) as stream:
        columns = tuple(stream.readline().strip().split(","))
    rows = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
    return columns, rows
