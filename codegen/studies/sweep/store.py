"""A sweep's results on disk, written as runs finish and safe to interrupt.

    OUT/sweep.json            the spec as expanded, its digest, versions, machine, start, end
    OUT/parts/runs-<first>.parquet   one file per finished chunk of runs: the commit record
    OUT/trajectories.zarr     when the spec keeps trajectories (every > 0): an xarray Dataset
                              with dims (run, t, joint), written chunk by chunk
    OUT/runs.parquet          every run, one row each, assembled when the sweep completes

A chunk's trajectories are written before its part file, and the part file is renamed into place
whole: a part file means the chunk is complete. A killed sweep therefore keeps every chunk whose
part file exists and nothing else counts; run again, it computes only the chunks without one
(writing a chunk's trajectories again is idempotent), so no run is stored twice. A different
spec into the same OUT is refused (its digest differs).
"""
from __future__ import annotations

import contextlib
import json
import platform
import time
from pathlib import Path

import numpy as np

from ...errors import ChaingenError
from ...runtime.files import directory_lock, staged_file, write_text
from ...version import VERSION
from .runs import ChunkResult, sample_count
from .spec import SweepSpec

SPEC_FILE = "sweep.json"
PARTS = "parts"
RUNS = "runs.parquet"
TRAJECTORIES = "trajectories.zarr"


class StoreError(ChaingenError):
    """OUT cannot take this sweep (another spec's results, or not a sweep directory)."""


def _versions() -> dict:
    import importlib.metadata

    versions = {"chaingen": VERSION, "python": platform.python_version()}
    for package in ("numpy", "sympy", "casadi", "pyarrow", "xarray", "zarr", "dask",
                    "distributed"):
        try:
            versions[package] = importlib.metadata.version(package)
        except importlib.metadata.PackageNotFoundError:
            pass
    return versions


class SweepStore:
    """The result directory of one spec."""

    def __init__(self, out: str | Path, spec: SweepSpec, chunk: int):
        self.out = Path(out)
        self.spec = spec
        self.chunk = chunk
        self.digest = spec.digest
        self._group = None          # the zarr group of the trajectories, once opened

    # -- opening ------------------------------------------------------------------------------

    def check(self) -> None:
        """StoreError unless OUT is new, empty, or holds this spec's results (writes nothing)."""
        record_path = self.out / SPEC_FILE
        if self.out.exists() and not self.out.is_dir():
            raise StoreError(f"{self.out}: exists and is not a directory")
        if record_path.is_file():
            try:
                record = json.loads(record_path.read_text())
            except (OSError, ValueError) as error:
                raise StoreError(f"{record_path}: unreadable sweep record ({error}); give "
                                 "another OUT") from None
            if not isinstance(record, dict) or record.get("digest") != self.digest:
                source = record.get("source", "?") if isinstance(record, dict) else "?"
                raise StoreError(f"{self.out}: holds the results of another sweep spec "
                                 f"({source}); give another OUT")
            if record.get("chunk") != self.chunk:
                raise StoreError(f"{self.out}: was written in chunks of {record.get('chunk')} "
                                 f"runs, not {self.chunk}")
        elif self.out.exists() and not {entry.name for entry in self.out.iterdir()} <= {
                PARTS, TRAJECTORIES}:
            # (A sweep killed as it began leaves at most these, without its record.)
            raise StoreError(f"{self.out}: exists and is not a sweep directory (no "
                             f"{SPEC_FILE}); give a new or empty directory")

    @contextlib.contextmanager
    def writing(self):
        """OUT created and held for this sweep alone (a lock on the directory, released when
        the block ends, or by the system when the process dies)."""
        self.check()
        self.out.mkdir(parents=True, exist_ok=True)
        try:
            with directory_lock(self.out, wait=False):
                yield self
        except BlockingIOError:
            raise StoreError(f"{self.out}: another sweep is writing into it; wait for it or "
                             "give another OUT") from None

    def open(self, build_hash: str, engine: str) -> set[int]:
        """Set OUT up, or reopen it for the same spec (inside `writing`); the first runs of the
        chunks stored."""
        self.check()
        record_path = self.out / SPEC_FILE
        if not record_path.is_file() and any((self.out / PARTS).glob("runs-*.parquet")):
            raise StoreError(f"{self.out}: holds runs without their {SPEC_FILE}; give another "
                             "OUT")
        for leftover in (self.out / PARTS).glob(".runs-*"):
            leftover.unlink()       # a part being written when a sweep was killed
        (self.out / PARTS).mkdir(parents=True, exist_ok=True)
        if not record_path.is_file():
            record = {"source": self.spec.source, "digest": self.digest, "chunk": self.chunk,
                      "spec": self.spec.document, "scene": str(self.spec.scene_path),
                      "method": self.spec.method, "quadrature": self.spec.quadrature,
                      "order": self.spec.order, "rtol": self.spec.rtol, "atol": self.spec.atol,
                      "parameters": list(self.spec.parameters),
                      "axes": [axis.path for axis in self.spec.axes],
                      "spacing": {axis.path: axis.spacing for axis in self.spec.axes},
                      "units": {axis.path: axis.number.unit for axis in self.spec.axes},
                      "runs": len(self.spec.runs), "solver": build_hash,
                      "versions": _versions(), "machine": platform.platform(),
                      "processor": platform.processor() or platform.machine(),
                      "engine": engine, "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
            # The record last: it marks OUT as set up (a sweep killed before it starts anew).
            if self.spec.every:
                self._create_trajectories()
            write_text(record_path, json.dumps(record, indent=2, default=str) + "\n")
        return self.stored()

    def stored(self) -> set[int]:
        """The first run of every chunk whose part file exists."""
        return {int(path.stem.split("-")[1]) for path in (self.out / PARTS).glob("runs-*.parquet")}

    def chunks(self) -> list[tuple[int, int]]:
        """(first, count) of every chunk of the sweep."""
        total = len(self.spec.runs)
        return [(first, min(self.chunk, total - first)) for first in range(0, total, self.chunk)]

    # -- trajectories -------------------------------------------------------------------------

    def _create_trajectories(self) -> None:
        """The empty store: coordinates written, data arrays created (filled with NaN until
        their chunks are written), chunked by the sweep's chunks of runs. Written with zarr
        alone in the layout xarray reads (zarr v3 dimension names, a `coordinates` attribute
        naming the axes' values on `run`), so a sweep never imports xarray."""
        import zarr

        spec, n = self.spec, self.spec.scene.n
        runs, samples = len(spec.runs), sample_count(spec)
        group = zarr.open_group(self.out / TRAJECTORIES, mode="w", zarr_format=3)
        group.attrs.update({"scene": spec.scene.name, "method": spec.method,
                            "sweep_digest": self.digest,
                            "units": "phi rad, omega rad/s, energy J, constraint_error m, t s"})

        def coordinate(name: str, values: np.ndarray, dimension: str) -> None:
            array = group.create_array(name, shape=values.shape, dtype=values.dtype,
                                       chunks=values.shape, dimension_names=[dimension])
            array[...] = values

        coordinate("run", np.arange(runs), "run")
        coordinate("joint", np.arange(1, n + 1), "joint")
        shared_time = self._shared_time()
        coordinate("t", np.arange(samples) * spec.every * spec.scene.simulation.dt
                   if shared_time else np.arange(samples), "t")
        for axis in spec.axes:
            coordinate(axis.path, np.array([run[axis.path] for run in spec.runs]), "run")
        variables = {"phi": ("run", "t", "joint"), "omega": ("run", "t", "joint"),
                     "energy": ("run", "t"), "constraint_error": ("run", "t")}
        if not shared_time:
            variables["time"] = ("run", "t")
        sizes = {"run": runs, "t": samples, "joint": n}
        for name, dimensions in variables.items():
            shape = tuple(sizes[dimension] for dimension in dimensions)
            array = group.create_array(name, shape=shape, dtype="f8",
                                       chunks=(self.chunk,) + shape[1:], fill_value=np.nan,
                                       dimension_names=list(dimensions))
            array.attrs["coordinates"] = " ".join(axis.path for axis in spec.axes)

    def write_trajectories(self, result: ChunkResult) -> None:
        """A chunk's samples into its rows of the arrays (whole zarr chunks: chunks of runs
        are the store's chunks, so writers of different chunks never share a file)."""
        import zarr

        if self._group is None:
            self._group = zarr.open_group(self.out / TRAJECTORIES, mode="r+")
        rows = slice(result.first, result.first + len(result.rows))
        arrays = {"phi": result.phi, "omega": result.omega, "energy": result.energy,
                  "constraint_error": result.constraint_error}
        if not self._shared_time():
            arrays["time"] = result.time
        for name, values in arrays.items():
            self._group[name][rows] = values

    def _shared_time(self) -> bool:
        return not any(axis.path.startswith("simulation.") for axis in self.spec.axes)

    # -- runs ---------------------------------------------------------------------------------

    def commit(self, result: ChunkResult) -> None:
        """Store a finished chunk: its trajectories, then its part file (the commit)."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        if self.spec.every and result.phi is not None:
            self.write_trajectories(result)
        table = pa.Table.from_pylist(result.rows)
        path = self.out / PARTS / f"runs-{result.first:09d}.parquet"
        with staged_file(path, suffix=".parquet") as temporary:
            pq.write_table(table, temporary)

    def assemble(self) -> Path:
        """runs.parquet from the part files, ordered by run; and the end time in sweep.json."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        parts = sorted((self.out / PARTS).glob("runs-*.parquet"))
        table = pa.concat_tables([pq.read_table(path) for path in parts])
        table = table.sort_by("run")
        target = self.out / RUNS
        with staged_file(target, suffix=".parquet") as temporary:
            pq.write_table(table, temporary)
        record_path = self.out / SPEC_FILE
        record = json.loads(record_path.read_text())
        record["finished"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        write_text(record_path, json.dumps(record, indent=2, default=str) + "\n")
        return target
