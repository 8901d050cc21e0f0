"""The files of a sweep's OUT beside SweepStore: the names it writes, where a sweep may write
(not inside another sweep's OUT), its staged files (named by the store id, so a leftover is
provably the sweep's own), the digest of a chunk's trajectory rows, and the record's versions
and energy."""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import platform
import re
import shutil
import stat
import uuid
from pathlib import Path

import numpy as np

from ...runtime.trajectory import CLOSED_LOOP_ENERGY
from ...version import VERSION

SPEC_FILE = "sweep.json"
PARTS = "parts"
RUNS = "runs.parquet"
TRAJECTORIES = "trajectories.zarr"
#: A part file's name.
PART_NAME = re.compile(r"runs-([0-9]{9})\.parquet")
#: The staged files of the sweep's writes (left over when a write is killed half-way): the
#: target's name, this OUT's store id and a random token (`staged`).
TOKEN = 16
FIGURE = re.compile(r"[\w.-]+\.png|\.[\w.-]+\.png\.[A-Za-z0-9_]+(?:\.png)?")


def energy_record(spec) -> dict:
    """{"energy": what it is} for a SweepSpec of a controlled scene, whose energy (the
    trajectories' energy, runs.parquet's max_energy_error) is the closed loop's H_d, as a
    run's metadata says; {} for H."""
    return {"energy": CLOSED_LOOP_ENERGY} if getattr(spec.scene, "control", None) else {}


def versions() -> dict:
    import importlib.metadata

    found = {"chaingen": VERSION, "python": platform.python_version()}
    for package in ("numpy", "sympy", "casadi", "pyarrow", "xarray", "zarr", "dask",
                    "distributed"):
        try:
            found[package] = importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            pass
    return found


@contextlib.contextmanager
def removed_on_failure(directory: Path):
    """The directory being built, removed if the block fails."""
    try:
        yield
    except BaseException:
        shutil.rmtree(directory, ignore_errors=True)
        raise


def lexists(path: Path) -> bool:
    return os.path.lexists(path)


def leftover(store_id: str | None, names: str) -> re.Pattern:
    """The staged files of this OUT's writes of `names` (a regular expression)."""
    if not store_id:
        return re.compile(r"(?!)")
    return re.compile(rf"\.(?:{names})\.{re.escape(store_id)}\.[0-9a-f]{{{TOKEN}}}"
                      r"(?:\.parquet)?")


def enclosing_sweep(out: Path) -> Path | None:
    """The directory of another sweep that `out` would lie inside (a parent holding a
    sweep.json that is a sweep's record), or None."""
    here = Path(os.path.realpath(out))
    for parent in here.parents:
        record_path = parent / SPEC_FILE
        try:
            if not stat.S_ISREG(os.stat(record_path).st_mode):
                continue
            record = json.loads(record_path.read_text())
        except (OSError, ValueError):
            continue
        if isinstance(record, dict) and "digest" in record and "store" in record:
            return parent
    return None


def trajectory_digest(arrays: dict[str, np.ndarray]) -> str:
    """sha256 of a chunk's trajectory rows as stored (float64, every NaN alike: a zarr chunk
    that is all NaN may be left unwritten and read back as the fill value)."""
    digest = hashlib.sha256()
    for name in sorted(arrays):
        values = np.ascontiguousarray(arrays[name], dtype="<f8")
        values = np.where(np.isnan(values), np.nan, values)
        digest.update(name.encode() + b"\0" + repr(values.shape).encode() + values.tobytes())
    return digest.hexdigest()


@contextlib.contextmanager
def staged(path: Path, store_id: str, suffix: str = ""):
    """A new file beside `path`, named by the store id and a random token, renamed onto `path`
    when the block ends, removed when it raises (runtime.files.staged_file, with names only
    this OUT's writes have)."""
    temporary = path.parent / f".{path.name}.{store_id}.{uuid.uuid4().hex[:TOKEN]}{suffix}"
    os.close(os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
    try:
        yield temporary
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise
