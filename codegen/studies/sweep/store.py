"""A sweep's results on disk, written as runs finish and safe to interrupt.

    OUT/sweep.json            the spec as expanded, its digest, this store's id, versions,
                              machine, start, end: written first, it marks OUT as this sweep's
    OUT/parts/runs-<first>.parquet   one file per finished chunk of runs: the commit record
    OUT/trajectories.zarr     when the spec keeps trajectories (every > 0): an xarray Dataset
                              with dims (run, t, joint), written chunk by chunk
    OUT/runs.parquet          every run, one row each, assembled when the sweep completes

A chunk's trajectories are written before its part file, and the part file is renamed into place
whole: a part file means the chunk is complete. A killed sweep therefore keeps every chunk whose
part file exists and nothing else counts; run again, it computes only the chunks without one
(writing a chunk's trajectories again is idempotent), so no run is stored twice. A different
spec into the same OUT is refused (its digest differs).

OUT never loses a file the sweep did not write: an OUT that holds anything the sweep does not
know as its own (or a symbolic link) is refused before any work, and the sweep removes only
what it wrote: its own staged leftovers, whose names carry this OUT's store id and a random
token (`.sweep.json.<store id>.<token>`), never a name a user could have chosen alike.

Every part file records a digest of the trajectory rows its chunk wrote (the samples as they
were written); a resumed sweep, and assembly, read each stored chunk's rows back and compare,
so a lost or garbled zarr chunk is found (one line saying what to remove), never a run marked
done whose trajectory reads back NaN.
"""
from __future__ import annotations

import contextlib
import json
import os
import platform
import shutil
import stat
import time
import uuid
from pathlib import Path

import numpy as np

from ...errors import ChaingenError, RunFailedError
from ...runtime.files import directory_lock
from .outfiles import (
    FIGURE,
    PART_NAME,
    PARTS,
    RUNS,
    SPEC_FILE,
    TRAJECTORIES,
    enclosing_sweep,
    energy_record,
    leftover,
    lexists,
    removed_on_failure,
    staged,
    trajectory_digest,
    versions,
)
from .runs import ChunkResult, sample_count
from .spec import SweepSpec

__all__ = ["PARTS", "RUNS", "SPEC_FILE", "TRAJECTORIES", "IncompleteSweepError", "StoreError",
           "StoreWriteError", "SweepStore"]
#: The key of a part file's metadata: which sweep (digest) and which OUT (store id) wrote it.
PART_KEY = b"chaingen_sweep"


class StoreError(ChaingenError):
    """OUT cannot take this sweep (another spec's results, not a sweep directory, something
    the sweep did not write, a damaged part)."""


class StoreWriteError(RunFailedError):
    """Writing into OUT failed (a full disk, an I/O error): nothing of the chunk is stored."""


class IncompleteSweepError(RunFailedError):
    """Assembly found a chunk missing or not this sweep's: no runs.parquet is written."""


@contextlib.contextmanager
def writes(path: Path, what: str):
    """OSError while writing `path` (ENOSPC, EIO, a read-only file system) -> StoreWriteError,
    one line."""
    try:
        yield
    except OSError as error:
        raise StoreWriteError(f"{path}: cannot write {what}: {error.strerror or error}; "
                              "nothing of it is kept (free space and run the sweep again "
                              "to resume)") from None


class SweepStore:
    """The result directory of one spec."""

    def __init__(self, out: str | Path, spec: SweepSpec, chunk: int, store_id: str | None = None):
        self.out = Path(out)
        self.spec = spec
        self.chunk = chunk
        self.digest = spec.digest
        self.store_id = store_id    # this OUT's id (sweep.json), once read or set up
        self._group = None          # the zarr group of the trajectories, once opened
        self._reader = None         # the same, opened to read back what is stored
        self._read_back: set[int] = set()   # chunks whose trajectories were read back

    # -- opening ------------------------------------------------------------------------------

    def check(self) -> None:
        """StoreError unless OUT is new, empty, or holds this spec's results and nothing the
        sweep does not know as its own; and OUT (or where it will be made) is writable.
        Writes nothing."""
        out = self.out
        enclosing = enclosing_sweep(out)
        if enclosing is not None:
            raise StoreError(f"{out}: lies inside the sweep directory {enclosing} (it holds "
                             f"{SPEC_FILE}); give an OUT outside every sweep's OUT")
        if os.path.islink(out) and not out.is_dir():
            raise StoreError(f"{out}: is a symbolic link to no directory; give a directory")
        if lexists(out) and not out.is_dir():
            raise StoreError(f"{out}: exists and is not a directory")
        if not out.exists():
            parent = out.parent
            while not parent.exists() and parent != parent.parent:
                parent = parent.parent
            if not parent.is_dir() or not os.access(parent, os.W_OK | os.X_OK):
                raise StoreError(f"{out}: cannot be created: {parent} is not a writable "
                                 "directory")
            return
        if not os.access(out, os.W_OK | os.X_OK):
            raise StoreError(f"{out}: is not writable (a read-only directory or file system)")
        entries = sorted(entry.name for entry in out.iterdir())
        record_path = out / SPEC_FILE
        if SPEC_FILE not in entries:
            if entries:
                raise StoreError(f"{out}: is not empty and holds no {SPEC_FILE} (not a sweep "
                                 f"directory: {entries[0]}, ...); give a new or empty "
                                 "directory")
            return
        if not stat.S_ISREG(os.lstat(record_path).st_mode):
            raise StoreError(f"{record_path}: is not a regular file; give another OUT")
        try:
            record = json.loads(record_path.read_text())
        except (OSError, ValueError) as error:
            raise StoreError(f"{record_path}: unreadable sweep record ({error}); remove {out} "
                             "or give another OUT") from None
        if not isinstance(record, dict) or record.get("digest") != self.digest:
            source = record.get("source", "?") if isinstance(record, dict) else "?"
            raise StoreError(f"{out}: holds the results of another sweep spec "
                             f"({source}); give another OUT")
        if record.get("chunk") != self.chunk:
            raise StoreError(f"{out}: was written in chunks of {record.get('chunk')} "
                             f"runs, not {self.chunk}")
        if not isinstance(record.get("store"), str):
            raise StoreError(f"{record_path}: has no store id (written by an older chaingen); "
                             f"remove {out} or give another OUT")
        self.store_id = record["store"]
        for name in entries:
            self._check_entry(out / name)

    def _check_entry(self, path: Path) -> None:
        """An entry of OUT that the sweep knows as its own, or StoreError."""
        name = path.name
        mode = os.lstat(path).st_mode
        if stat.S_ISLNK(mode):
            raise StoreError(f"{path}: is a symbolic link; a sweep writes only into files it "
                             "made (remove the link or give another OUT)")
        regular, directory = stat.S_ISREG(mode), stat.S_ISDIR(mode)
        if name == PARTS and directory:
            for part in sorted(path.iterdir()):
                part_mode = os.lstat(part).st_mode
                if not (stat.S_ISREG(part_mode) and (PART_NAME.fullmatch(part.name)
                                                     or self._part_leftover(part.name))):
                    raise StoreError(f"{part}: was not written by this sweep; move it out of "
                                     f"{path} or give another OUT")
            return
        if name == TRAJECTORIES and directory and self.spec.every:
            for root, directories, files in os.walk(path):
                for entry in directories + files:
                    if os.path.islink(os.path.join(root, entry)):
                        raise StoreError(f"{os.path.join(root, entry)}: is a symbolic link; "
                                         f"remove {path} and {self.out / PARTS} to compute "
                                         "the sweep anew")
            return
        if name == self._staging_name() and directory:
            return
        if regular and (name in (SPEC_FILE, RUNS) or self._top_leftover(name)
                        or FIGURE.fullmatch(name)):
            return
        raise StoreError(f"{path}: was not written by this sweep; move it out of {self.out} "
                         "or give another OUT")

    def _staging_name(self) -> str:
        return f".{TRAJECTORIES}.{self.store_id}.staging"

    def _top_leftover(self, name: str) -> bool:
        return bool(leftover(self.store_id, r"sweep\.json|runs\.parquet").fullmatch(name))

    def _part_leftover(self, name: str) -> bool:
        return bool(leftover(self.store_id, r"runs-[0-9]{9}\.parquet").fullmatch(name))

    def _staged(self, path: Path, suffix: str = ""):
        return staged(path, self.store_id, suffix)

    def _write_text(self, path: Path, text: str) -> None:
        with self._staged(path) as temporary:
            temporary.write_text(text)

    @contextlib.contextmanager
    def writing(self):
        """OUT created and held for this sweep alone (a lock on the directory, released when
        the block ends, or by the system when the process dies)."""
        self.check()
        with writes(self.out, "the directory"):
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
        if not record_path.is_file():
            self.store_id = uuid.uuid4().hex
            record = {"source": self.spec.source, "digest": self.digest, "chunk": self.chunk,
                      "store": self.store_id,
                      "spec": self.spec.document, "scene": str(self.spec.scene_path),
                      "method": self.spec.method, "quadrature": self.spec.quadrature,
                      "order": self.spec.order, "rtol": self.spec.rtol, "atol": self.spec.atol,
                      "parameters": list(self.spec.parameters),
                      "axes": [axis.path for axis in self.spec.axes],
                      "spacing": {axis.path: axis.spacing for axis in self.spec.axes},
                      "units": {axis.path: axis.number.unit for axis in self.spec.axes},
                      "runs": len(self.spec.runs), "solver": build_hash,
                      "versions": versions(), "machine": platform.platform(),
                      "processor": platform.processor() or platform.machine(),
                      "engine": engine, "started": time.strftime("%Y-%m-%dT%H:%M:%S%z")}
            record.update(energy_record(self.spec))
            # The record first: it marks OUT as this sweep's; what follows is its own.
            with writes(record_path, "the sweep record"):
                self._write_text(record_path, json.dumps(record, indent=2, default=str) + "\n")
        self._remove_leftovers()
        with writes(self.out / PARTS, "the parts directory"):
            (self.out / PARTS).mkdir(exist_ok=True)
        stored = self.stored(verify=True)
        if self.spec.every:
            if (self.out / TRAJECTORIES).is_dir():
                self._check_trajectories()
                counts = dict(self.chunks())
                for first in sorted(stored):
                    self._verify_rows(first, counts[first])
            elif stored:
                raise StoreError(f"{self.out / TRAJECTORIES}: missing while {len(stored)} "
                                 f"chunks are stored; remove {self.out / PARTS} to compute "
                                 "the sweep anew")
            else:
                self._create_trajectories()
        return stored

    def _remove_leftovers(self) -> None:
        """What this sweep wrote half-way before it was killed (its staged files, named by this
        OUT's store id: never a file of the user's)."""
        candidates = [(path, self._top_leftover) for path in self.out.iterdir()]
        if (self.out / PARTS).is_dir():
            candidates += [(path, self._part_leftover) for path in (self.out / PARTS).iterdir()]
        for path, ours in candidates:
            if ours(path.name) and path.is_file() and not path.is_symlink():
                path.unlink()
        staging = self.out / self._staging_name()
        if staging.is_dir() and not staging.is_symlink():
            shutil.rmtree(staging)

    def stored(self, *, verify: bool = False) -> set[int]:
        """The first run of every chunk whose part file exists; with `verify`, each read and
        checked (a damaged or foreign one: StoreError saying to remove it)."""
        firsts = set()
        expected = dict(self.chunks())
        for path in (self.out / PARTS).glob("runs-*.parquet"):
            match = PART_NAME.fullmatch(path.name)
            if not match:
                continue
            first = int(match.group(1))
            if verify:
                self._verify_part(path, first, expected.get(first))
            firsts.add(first)
        return firsts

    def _verify_part(self, path: Path, first: int, count: int | None) -> dict:
        import pyarrow.parquet as pq

        try:
            metadata = pq.read_metadata(path)
            key = json.loads((metadata.metadata or {}).get(PART_KEY, b"null"))
            rows = metadata.num_rows
        except Exception as error:       # pyarrow's errors for a truncated or garbled file
            raise StoreError(f"{path}: damaged ({type(error).__name__}); remove it and run "
                             "the sweep again (its runs are computed anew)") from None
        if count is None or rows != count or not isinstance(key, dict) \
                or key.get("digest") != self.digest or key.get("first") != first:
            raise StoreError(f"{path}: is not a part of this sweep ({rows} rows); remove it "
                             "and run the sweep again (its runs are computed anew)")
        if key.get("store") != self.store_id:
            raise StoreError(f"{path}: was written for another OUT (store "
                             f"{key.get('store')}); remove it and run the sweep again")
        if self.spec.every and not isinstance(key.get("trajectories"), str):
            raise StoreError(f"{path}: records no digest of its trajectories (written by an "
                             "older chaingen, or without them); remove it and run the sweep "
                             "again (its runs are computed anew)")
        return key

    def _verify_rows(self, first: int, count: int) -> None:
        """The trajectory rows of a stored chunk read back as its part file says they were
        written (the digest it records); else StoreError naming the part file to remove, so
        that the chunk is computed and written again."""
        import zarr

        part = self.part_path(first)
        key = self._verify_part(part, first, count)
        path = self.out / TRAJECTORIES
        remove = (f"remove {part} and run the sweep again (runs {first}..{first + count - 1} "
                  "are computed and written anew)")
        try:
            if self._reader is None:
                self._reader = zarr.open_group(path, mode="r")
            group, rows = self._reader, slice(first, first + count)
            found = trajectory_digest({name: group[name][rows] for name in self._variables()})
        except Exception as error:       # a lost or garbled chunk: zarr's, numcodecs' errors
            raise StoreError(f"{path}: the trajectories of runs {first}..{first + count - 1} "
                             f"are unreadable ({type(error).__name__}); {remove}") from None
        if found != key["trajectories"]:
            raise StoreError(f"{path}: the trajectories of runs {first}..{first + count - 1} "
                             f"are not those the sweep wrote (a lost or altered chunk); {remove}")
        self._read_back.add(first)

    def chunks(self) -> list[tuple[int, int]]:
        """(first, count) of every chunk of the sweep."""
        total = len(self.spec.runs)
        return [(first, min(self.chunk, total - first)) for first in range(0, total, self.chunk)]

    # -- trajectories -------------------------------------------------------------------------

    def _create_trajectories(self) -> None:
        """The empty store: coordinates written, data arrays created (filled with NaN until
        their chunks are written), chunked by the sweep's chunks of runs. Written with zarr
        alone in the layout xarray reads (zarr v3 dimension names, a `coordinates` attribute
        naming the axes' values on `run`), so a sweep never imports xarray. Built in a staging
        directory of this store's and renamed into place whole."""
        import zarr

        spec, n = self.spec, self.spec.scene.n
        runs, samples = len(spec.runs), sample_count(spec)
        staging = self.out / self._staging_name()
        with writes(self.out / TRAJECTORIES, "the trajectories"), removed_on_failure(staging):
            group = zarr.open_group(staging, mode="w-", zarr_format=3)
            group.attrs.update({"scene": spec.scene.name, "method": spec.method,
                                "sweep_digest": self.digest,
                                "units": "phi rad, omega rad/s, energy J, constraint_error m, "
                                         "t s", **energy_record(spec)})

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
                coordinate(axis.path, spec.runs.column(axis.path), "run")
            for name, dimensions in self._variables().items():
                shape = tuple(self._sizes()[dimension] for dimension in dimensions)
                array = group.create_array(name, shape=shape, dtype="f8",
                                           chunks=(self.chunk,) + shape[1:], fill_value=np.nan,
                                           dimension_names=list(dimensions))
                array.attrs["coordinates"] = " ".join(axis.path for axis in spec.axes)
            os.replace(staging, self.out / TRAJECTORIES)

    def _sizes(self) -> dict[str, int]:
        return {"run": len(self.spec.runs), "t": sample_count(self.spec),
                "joint": self.spec.scene.n}

    def _variables(self) -> dict[str, tuple[str, ...]]:
        variables = {"phi": ("run", "t", "joint"), "omega": ("run", "t", "joint"),
                     "energy": ("run", "t"), "constraint_error": ("run", "t")}
        if not self._shared_time():
            variables["time"] = ("run", "t")
        return variables

    def _check_trajectories(self) -> None:
        """The store of a resumed sweep: this sweep's, with its arrays' shapes; else one line
        saying what to remove."""
        import zarr

        path = self.out / TRAJECTORIES
        remove = (f"remove {path} and {self.out / PARTS} to compute the sweep anew")
        try:
            group = zarr.open_group(path, mode="r")
            attrs = dict(group.attrs)
            shapes = {name: tuple(group[name].shape) for name in self._variables()}
        except Exception as error:       # zarr's errors for missing or garbled metadata
            raise StoreError(f"{path}: damaged ({type(error).__name__}); {remove}") from None
        if attrs.get("sweep_digest") != self.digest:
            raise StoreError(f"{path}: is not this sweep's trajectories; {remove}")
        sizes = self._sizes()
        for name, dimensions in self._variables().items():
            if shapes[name] != tuple(sizes[dimension] for dimension in dimensions):
                raise StoreError(f"{path}: damaged ({name} has shape {shapes[name]}); {remove}")

    def write_trajectories(self, result: ChunkResult) -> None:
        """A chunk's samples into its rows of the arrays (whole zarr chunks: chunks of runs
        are the store's chunks, so writers of different chunks never share a file)."""
        import zarr

        if self._group is None:
            self._group = zarr.open_group(self.out / TRAJECTORIES, mode="r+")
        rows = slice(result.first, result.first + len(result.rows))
        for name, values in self._trajectory_arrays(result).items():
            self._group[name][rows] = values

    def _trajectory_arrays(self, result: ChunkResult) -> dict[str, np.ndarray]:
        """A chunk's rows of each trajectory variable (float64, as stored)."""
        arrays = {"phi": result.phi, "omega": result.omega, "energy": result.energy,
                  "constraint_error": result.constraint_error, "time": result.time}
        return {name: np.asarray(arrays[name], dtype=np.float64) for name in self._variables()}

    def _shared_time(self) -> bool:
        return not any(axis.path.startswith("simulation.") for axis in self.spec.axes)

    # -- runs ---------------------------------------------------------------------------------

    def part_path(self, first: int) -> Path:
        return self.out / PARTS / f"runs-{first:09d}.parquet"

    def commit(self, result: ChunkResult) -> None:
        """Store a finished chunk: its trajectories, then its part file (the commit), marked
        with the sweep's digest and this OUT's store id."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        path = self.part_path(result.first)
        with writes(path, f"runs {result.first}..{result.first + len(result.rows) - 1}"):
            key = {"digest": self.digest, "store": self.store_id, "first": result.first}
            if self.spec.every and result.phi is not None:
                self.write_trajectories(result)
                key["trajectories"] = trajectory_digest(self._trajectory_arrays(result))
            table = pa.Table.from_pylist(result.rows)
            table = table.replace_schema_metadata({**(table.schema.metadata or {}),
                                                   PART_KEY: json.dumps(key).encode()})
            with self._staged(path, suffix=".parquet") as temporary:
                pq.write_table(table, temporary)

    def assemble(self) -> Path:
        """runs.parquet from the part files, ordered by run, once every chunk's part is there
        and this sweep's (IncompleteSweepError naming the missing ones otherwise); and the end
        time in sweep.json."""
        import pyarrow as pa
        import pyarrow.parquet as pq

        missing = [(first, count) for first, count in self.chunks()
                   if not self.part_path(first).is_file()]
        if missing:
            first, count = missing[0]
            raise IncompleteSweepError(
                f"{self.out}: {len(missing)} of {len(self.chunks())} chunks are not stored "
                f"(the first: runs {first}..{first + count - 1}, "
                f"{self.part_path(first).name}); no runs.parquet written; run the sweep "
                "again to compute them")
        tables = []
        for first, count in self.chunks():
            path = self.part_path(first)
            self._verify_part(path, first, count)
            if self.spec.every and first not in self._read_back:   # not read back on open
                self._verify_rows(first, count)
            table = pq.read_table(path)
            runs = table.column("run").to_numpy()
            if not np.array_equal(runs, np.arange(first, first + count)):
                raise IncompleteSweepError(f"{path}: holds runs other than {first}.."
                                           f"{first + count - 1}; remove it and run the sweep "
                                           "again")
            tables.append(table.replace_schema_metadata(None))
        table = pa.concat_tables(tables)
        target = self.out / RUNS
        record_path = self.out / SPEC_FILE
        with writes(target, "the runs table"):
            with self._staged(target, suffix=".parquet") as temporary:
                pq.write_table(table, temporary)
            record = json.loads(record_path.read_text())
            record["finished"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
            self._write_text(record_path, json.dumps(record, indent=2, default=str) + "\n")
        return target
