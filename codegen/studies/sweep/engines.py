"""Who runs a sweep's chunks: the threads of this machine, or the workers of a Dask cluster.

Local: a thread pool of one thread per core. A chaingen Solver gives each thread a workspace of
its own and ctypes releases the GIL during the C loop, so the threads run the chunks truly in
parallel, each on one solver loaded once.

Dask: every chunk is a task. The compiled library travels to each worker once (scattered with
broadcast) together with the package's sources, and a worker loads it from a cache of its own
keyed by the build hash; a worker of another architecture builds the package from the sources
instead. Workers write their chunks into OUT themselves (a file system they share with the
client), so a worker that dies loses only its unfinished chunk, which Dask runs again elsewhere;
a worker that does not see OUT returns its chunk to the client, which stores it.
"""
from __future__ import annotations

import json
import logging
import os
import platform
import signal
import tempfile
import threading
import uuid
from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait
from pathlib import Path

from ...errors import ChaingenError
from ...progress import Progress
from ...runtime import Solver, StopSignal
from .runs import ChunkResult, run_chunk
from .spec import SweepSpec
from .store import SPEC_FILE, SweepStore

#: Per-worker cache of loaded solvers, by build hash (a Dask worker keeps its solver).
_WORKER_SOLVERS: dict[str, Solver] = {}


def local_workers() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:
        return os.cpu_count() or 1


def _report(bar: Progress, done: int, failed: int, total: int) -> None:
    bar.update(done, f"{failed} failed" if failed else None)


def run_local(spec: SweepSpec, store: SweepStore, solver: Solver, build_hash: str,
              todo: list[tuple[int, int]], *, workers: int | None = None) -> None:
    """Run the chunks `todo` on this machine's cores; each is committed as it finishes."""
    workers = workers or local_workers()
    total = sum(count for _, count in todo)    # the runs of this call (a rerun: the missing)
    done = failed = 0
    stop = StopSignal()
    with Progress(f"sweep {spec.scene.name}", total=total, unit="runs") as bar, \
            ThreadPoolExecutor(max_workers=workers) as pool:
        pending = {pool.submit(run_chunk, spec, solver, first, count, build_hash, stop)
                   for first, count in todo}
        try:
            while pending:
                finished, pending = wait(pending, timeout=0.2, return_when=FIRST_COMPLETED)
                for future in finished:
                    result = future.result()
                    store.commit(result)
                    done += len(result.rows)
                    failed += sum(row["status"] != "ok" for row in result.rows)
                _report(bar, done, failed, total)
        except BaseException:
            # Ctrl-C, or a chunk that could not be stored: the running runs stop within a
            # step, their chunks are not stored, the others do not start.
            stop.stop()
            for future in pending:
                future.cancel()
            raise


def _worker_solver(build_hash: str, library: bytes, files: dict[str, str],
                   machine: str) -> Solver:
    """The solver on a Dask worker: loaded once per process, from the shipped library bytes on
    the same architecture, else built from the package's sources."""
    solver = _WORKER_SOLVERS.get(build_hash)
    if solver is not None:
        return solver
    manifest = json.loads(files["chaingen.json"])
    solver = None
    if machine == platform.machine():
        # Loaded from a private temporary copy, removed at once: the mapping outlives the file.
        with tempfile.TemporaryDirectory(prefix="chaingen-worker-") as directory:
            path = Path(directory) / f"lib{manifest['prefix']}-{build_hash}.so"
            path.write_bytes(library)
            try:
                solver = Solver(path, manifest, build_hash=build_hash)
            except OSError:     # same architecture, another system (libc): build it here
                solver = None
    if solver is None:
        solver = Solver.from_files(files)
    _WORKER_SOLVERS[build_hash] = solver
    return solver


def _sees_out(out: Path, digest: str, store_id: str) -> bool:
    """Whether this worker sees the client's OUT (the record of this very sweep and OUT)."""
    try:
        record = json.loads((out / SPEC_FILE).read_text())
        return record.get("digest") == digest and record.get("store") == store_id
    except (OSError, ValueError, AttributeError):
        return False


def _dask_chunk(spec: SweepSpec, out: str, chunk: int, store_id: str, first: int, count: int,
                build_hash: str, library: bytes, files: dict[str, str], machine: str):
    """One chunk on a Dask worker. Where the worker sees OUT (a file system shared with the
    client) it commits the chunk there and returns its failed runs; elsewhere it returns the
    chunk for the client to commit."""
    solver = _worker_solver(build_hash, library, files, machine)
    store = SweepStore(out, spec, chunk, store_id)
    shared = _sees_out(Path(out), store.digest, store_id)
    if shared and first in store.stored():       # already committed (a retry)
        return 0
    result = run_chunk(spec, solver, first, count, build_hash)
    if not shared:
        return result
    store.commit(result)
    return sum(row["status"] != "ok" for row in result.rows)


def _preload() -> None:
    """What a worker needs for its chunks, imported ahead of the first one."""
    import pyarrow.parquet  # noqa: F401
    import xarray  # noqa: F401
    import zarr  # noqa: F401


def _local_worker() -> None:
    """A worker of the LocalCluster that --dask-local starts: Ctrl-C at a terminal reaches the
    whole process group, and only the sweep's process answers it (it stops the sweep and the
    cluster, one line), not every worker with a traceback; the cancelled tasks of a cluster
    being closed are not logged."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    logging.getLogger("distributed").setLevel(logging.ERROR)


class DaskSession:
    """A Dask client, and the LocalCluster it started, set up in a thread of its own: the
    cluster starts and its workers import what they need while this process generates and
    builds the solver. `client()` waits for it; `close()` shuts down what it started."""

    def __init__(self, scheduler: str | None = None, local_workers_count: int | None = None):
        self.scheduler = scheduler
        self.workers = local_workers_count or local_workers()
        self._client = self._cluster = self._error = None
        self._thread = threading.Thread(target=self._start, name="chaingen dask start",
                                        daemon=True)
        self._thread.start()

    def _start(self) -> None:
        from distributed import Client, LocalCluster

        try:
            if self.scheduler is None:
                # The scheduler's HTTP server on a free port of this machine: with None it
                # takes 8787 (or warns that the port is in use and takes another).
                self._cluster = LocalCluster(n_workers=self.workers, threads_per_worker=1,
                                             processes=True, dashboard_address="127.0.0.1:0")
                self._client = Client(self._cluster)
            else:
                self._client = Client(self.scheduler, timeout=CONNECT_SECONDS)
            self._client.run(_preload)
            if self._cluster is not None:
                self._client.run(_local_worker)
        except Exception as error:    # raised again in the waiting thread
            self._error = error

    def client(self):
        self._thread.join()
        if self._error is not None:
            where = (f"the Dask scheduler at {self.scheduler}" if self.scheduler
                     else f"a Dask LocalCluster of {self.workers} workers")
            raise ChaingenError(f"{where}: {type(self._error).__name__}: {self._error}")
        return self._client

    def close(self) -> None:
        self._thread.join()
        if self._cluster is not None:
            # Closing the cluster this call started cancels its running tasks: that is the
            # point (an interrupted or failed sweep), not news to log.
            logging.getLogger("distributed").setLevel(logging.ERROR)
        if self._client is not None:
            self._client.close()
        if self._cluster is not None:
            self._cluster.close()


#: Seconds to wait for a scheduler given by --scheduler.
CONNECT_SECONDS = 30


def run_dask(spec: SweepSpec, store: SweepStore, files: dict[str, str], library: Path,
             build_hash: str, todo: list[tuple[int, int]], session: DaskSession) -> None:
    """Run the chunks `todo` on the Dask cluster of `session`."""
    from distributed import as_completed

    client = session.client()
    # Task keys unique to this call: two sweeps of one spec on one scheduler (into two OUTs,
    # or one resumed while the other's tasks linger) never share a task.
    token = f"{store.digest[:12]}-{store.store_id[:12]}-{uuid.uuid4().hex[:12]}"
    # The library and the spec travel once to every worker, not with every task.
    shipped = client.scatter(library.read_bytes(), broadcast=True)
    shipped_spec = client.scatter(spec, broadcast=True)
    total = sum(count for _, count in todo)
    done = failed = 0
    futures = [client.submit(_dask_chunk, shipped_spec, str(store.out), store.chunk,
                             store.store_id, first, count, build_hash, shipped, files,
                             platform.machine(), pure=False, retries=3,
                             key=f"chunk-{token}-{first}")
               for first, count in todo]
    counts = {future.key: count for future, (_, count) in zip(futures, todo)}
    with Progress(f"sweep {spec.scene.name} (dask)", total=total, unit="runs") as bar:
        for future in as_completed(futures):
            outcome = future.result()
            if isinstance(outcome, ChunkResult):     # a worker without OUT
                store.commit(outcome)
                outcome = sum(row["status"] != "ok" for row in outcome.rows)
            failed += outcome
            done += counts[future.key]
            _report(bar, done, failed, total)
