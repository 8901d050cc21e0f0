"""`chaingen sweep`: many runs of one scene, its numbers varied, with one compiled solver.

The numbers a sweep varies that are compiled into a solver (masses, lengths, stiffnesses, ...)
become its run-time parameters; the run-time ones (initial state, dt, t_end) are per run anyway.
So a sweep generates and builds one solver, then runs every combination in C, on all cores or
on a Dask cluster, and stores what each run did (runs.parquet) and, if asked, its trajectory
(trajectories.zarr). See docs/sweep-format.md and docs/sweeps.md.

    from chaingen import sweep
    runs = sweep({"scene": "three_link_mono.toml", "axes": {"springs[0].stiffness": [5, 10]}})

The results' dependencies (pyarrow, xarray, zarr, dask) are the extra `sweep`.
"""
from __future__ import annotations

import importlib.util
import os
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

from ...errors import ChaingenError, install_hint
from .spec import SweepError, SweepSpec, chunk_size, load_spec, parse_spec
from .store import RUNS, TRAJECTORIES, SweepStore

__all__ = ["SweepError", "SweepOutcome", "SweepSpec", "load_spec", "parse_spec", "run_sweep",
           "sweep"]

ENGINES = ("local", "dask")


@dataclass(frozen=True)
class SweepOutcome:
    out: Path
    runs: int
    computed: int          # runs computed by this call (the others were stored already)
    build_hash: str
    generate_seconds: float


def require_extra() -> None:
    missing = [module for module in ("pyarrow", "xarray", "zarr")
               if importlib.util.find_spec(module) is None]
    if missing:
        raise ChaingenError(f"chaingen sweep needs {', '.join(missing)}, which "
                            f"{'is' if len(missing) == 1 else 'are'} not installed "
                            f"({install_hint('sweep')})")


def run_sweep(spec: SweepSpec, out: str | Path, *, engine: str = "local",
              scheduler: str | None = None, dask_local: int | None = None,
              workers: int | None = None) -> SweepOutcome:
    """Run `spec` into `out`: build its solver, run the chunks not stored yet, assemble
    runs.parquet. Resumable: a rerun of the same spec computes only what is missing."""
    from .engines import DaskSession

    require_extra()
    if engine not in ENGINES:
        raise SweepError(f"engine: must be one of {', '.join(ENGINES)}, got {engine!r}")
    if engine == "dask" and importlib.util.find_spec("distributed") is None:
        raise ChaingenError("the Dask engine needs dask[distributed], which is not installed "
                            f"({install_hint('sweep')})")
    store = SweepStore(out, spec, chunk_size(len(spec.runs)))
    store.check()
    # A Dask cluster starts (and its workers import) while the solver is generated and built.
    session = DaskSession(scheduler, dask_local) if engine == "dask" else None
    try:
        return _run(spec, store, engine, session, workers)
    finally:
        if session is not None:
            session.close()


#: Solvers this process built, by what they are built from (and the compiler asked for): a
#: second sweep of the same scene, scheme and parameters (the next study in a notebook)
#: generates and loads nothing again.
_BUILT: dict[tuple, tuple] = {}


def _build(spec: SweepSpec):
    """(package files, library, solver) of the spec's solver, built once per process."""
    from ...generate.package import GENERATE_STAGES, generate_package
    from ...progress import Progress
    from ...runtime import Solver
    from ...runtime.build import build_shared_library

    key = (spec.scene, spec.method, spec.quadrature, spec.order, spec.parameters,
           os.environ.get("CC", ""))
    if key not in _BUILT:
        with Progress(f"generate {spec.scene.name} ({spec.method})",
                      total=GENERATE_STAGES + 1, unit="stages") as progress:
            package = generate_package(spec.solver, progress=progress)
            progress.update(GENERATE_STAGES, "compiling (or loading the cached build)")
            manifest = package.manifest
            library = build_shared_library(manifest["prefix"], package.files,
                                           manifest["sources"],
                                           source_flags={name: tuple(flags) for name, flags
                                                         in manifest["source_flags"].items()})
        solver = Solver(library.path, manifest, build_hash=library.build_hash)
        _BUILT[key] = (package.files, library, solver)
    return _BUILT[key]


def _run(spec: SweepSpec, store: SweepStore, engine: str, session, workers) -> SweepOutcome:
    import time

    from .engines import run_dask, run_local

    started = time.perf_counter()
    files, library, solver = _build(spec)
    generate_seconds = time.perf_counter() - started
    with store.writing():
        stored = store.open(library.build_hash, engine)
        todo = [(first, count) for first, count in store.chunks() if first not in stored]
        if todo and engine == "local":
            run_local(spec, store, solver, library.build_hash, todo, workers=workers)
        elif todo:
            run_dask(spec, store, files, library.path, library.build_hash, todo, session)
        store.assemble()
    return SweepOutcome(store.out, len(spec.runs), sum(count for _, count in todo),
                        library.build_hash, generate_seconds)


def sweep(spec, out: str | Path | None = None, *, engine: str = "local",
          scheduler: str | None = None, dask_local: int | None = None,
          trajectories: bool = False):
    """Run a sweep from a spec file, a spec dict (paths relative to the working directory) or
    a SweepSpec, into `out` (default: a temporary directory, removed afterwards). Returns the
    runs table (pandas), and with `trajectories` also the trajectories (xarray, loaded)."""
    if isinstance(spec, (str, Path)):
        spec = load_spec(spec)
    elif isinstance(spec, dict):
        spec = parse_spec(spec)
    elif not isinstance(spec, SweepSpec):
        raise TypeError(f"sweep: spec must be a spec file's path, a dict or a SweepSpec, "
                        f"got {type(spec).__name__}")
    import pandas as pd

    scratch = None
    if out is None:
        scratch = tempfile.mkdtemp(prefix="chaingen-sweep-")
        out = Path(scratch) / "out"
    try:
        run_sweep(spec, out, engine=engine, scheduler=scheduler, dask_local=dask_local)
        runs = pd.read_parquet(Path(out) / RUNS)
        if not trajectories:
            return runs
        import xarray as xr

        path = Path(out) / TRAJECTORIES
        data = xr.open_zarr(path, consolidated=False).load() if path.exists() else None
        return runs, data
    finally:
        if scratch is not None:
            shutil.rmtree(scratch, ignore_errors=True)
