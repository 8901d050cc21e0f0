"""Part 4 of the benchmark: what studies cost. Run-time parameters against constants compiled in,
and a sweep of many runs against a loop of single runs, on this machine's cores and on Dask.

Parameters: the headline scene's solver with its numbers as run-time parameters against the one
with them folded in as constants, each scheme, timed by the C harness in paired rounds. Two
sets: every number the scene sets (not zero), and every number with the zeros too (no damping,
COMs on the link axis), which brings in code the scene without parameters does not have.

Sweeps: `SWEEP_RUNS` runs of the headline scene (its first spring's stiffness x the second
link's mass, 10 s each, trajectories every 10 steps), run three times into fresh result
directories: the local engine with a cold build cache (so its wall time includes generating and
building the one solver), the local engine again with the build cached, and the Dask engine
(`--dask-local` with one worker per core, its LocalCluster started within the timed call) with
the build cached. Against it, `chaingen simulate` on one scene file per run: a subset of them,
each a fresh command with its own build (as a user without parameters would run them), scaled to
all runs.
"""
from __future__ import annotations

import dataclasses
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...generate.package import generate_package
from ...scene import METHODS, load_reference_scene
from ...scene.document import scene_toml
from ...scene.parameters import compiled_paths, number_path, with_values
from .config import HEADLINE_DT, HEADLINE_SCENE, BenchConfig
from .harness import time_pair

#: b: per-step time with every number a parameter / with them compiled in.
TARGET_PARAMETER_RATIO = 1.1
#: c: sweep wall <= SLACK x (sum of the runs' C time / cores) + ALLOWANCE seconds ...
TARGET_SWEEP_SLACK = 1.25
TARGET_SWEEP_ALLOWANCE = 10.0
#: ... and a loop of chaingen simulate over the runs' scene files >= this x the sweep's wall.
TARGET_LOOP_OVER_SWEEP = 100.0
#: d: Dask (local cluster) wall / local engine wall.
TARGET_DASK_OVER_LOCAL = 1.5
SWEEP_T_END = 10.0
SWEEP_EVERY = 10
#: The loop of single runs is timed on this many scene files, then scaled.
LOOP_SUBSET = 8
PARAMETER_ROUNDS = 41


@dataclass(frozen=True)
class ParameterRow:
    method: str
    numbers: str                 # which numbers are parameters
    parameters: int
    baked_ns: float              # medians over the rounds
    varied_ns: float
    ratio: float                 # median over the rounds of the paired ratio
    low: float                   # its quartiles
    high: float
    baked_iterations: float
    varied_iterations: float


@dataclass(frozen=True)
class SweepRow:
    engine: str
    runs: int
    wall_seconds: float
    generate_seconds: float
    cpu_seconds: float           # sum of the runs' cpu_seconds
    cores: int
    solvers: int                 # distinct `solver` values
    failed: int
    equal_to_local: bool | None  # runs.parquet equal to the first local run's (but cpu_seconds)

    @property
    def bound(self) -> float:
        return TARGET_SWEEP_SLACK * self.cpu_seconds / self.cores + TARGET_SWEEP_ALLOWANCE


@dataclass(frozen=True)
class LoopEstimate:
    files: int
    mean_seconds: float          # one `chaingen simulate` of a fresh scene file, wall
    runs: int

    @property
    def total_seconds(self) -> float:
        return self.mean_seconds * self.runs


@dataclass(frozen=True)
class StudyResults:
    parameters: list[ParameterRow]
    sweeps: list[SweepRow]
    loop: LoopEstimate | None


#: The parameter sets timed: every number the scene sets (not zero), the target's; and every
#: number, zeros too, which switches on code the scene does not have (damping, off-axis COMs).
PARAMETER_SETS = (("every non-zero number", False), ("every number, zeros too", True))


def parameter_rows(config: BenchConfig, note) -> list[ParameterRow]:
    """Per-step time with the scene's numbers as parameters against them compiled in, both
    packages in one timing program, block by block in alternating order (harness.time_pair);
    the ratio is the median of the rounds' ratios: a slow spell of the machine falls on both
    halves of a round."""
    from ...runtime import Solver

    scene = load_reference_scene(HEADLINE_SCENE)
    # The parameterised package under another name: its own prefix beside the baked one's.
    renamed = dataclasses.replace(scene, name=f"{scene.name}-parameters")
    rounds = PARAMETER_ROUNDS if not config.quick else 5
    rows = []
    for method in METHODS:
        baked = generate_package(scene, method, 3, sensitivities=False)
        x0 = Solver.from_files(baked.files).initial_state(scene.initial_angles,
                                                          scene.initial_velocities)
        for label, zeros in PARAMETER_SETS:
            note(f"studies: {method} with {label} a parameter")
            paths = tuple(path for path in compiled_paths(scene)
                          if zeros or number_path(scene, path).value(scene) != 0)
            varied = generate_package(renamed, method, 3, sensitivities=False, parameters=paths)
            timings = time_pair(baked, varied, x0, HEADLINE_DT, n_steps=2000, rounds=rounds)
            ratios = timings.ratios
            quartiles = statistics.quantiles(ratios, n=4)
            rows.append(ParameterRow(
                method, label, len(paths), statistics.median(timings.a) * 1e9,
                statistics.median(timings.b) * 1e9, statistics.median(ratios), quartiles[0],
                quartiles[2], timings.iterations_a, timings.iterations_b))
    return rows


def sweep_spec_text(scene_path: Path, runs: int, t_end: float = SWEEP_T_END) -> str:
    """The benchmark's sweep: stiffness x mass of the headline scene, about `runs` runs."""
    stiffnesses = max(1, round((runs * 1.6) ** 0.5))
    masses = max(1, runs // stiffnesses)
    return (f'scene = "{scene_path}"\nt_end = {t_end}\nevery = {SWEEP_EVERY}\n[axes]\n'
            f'"springs[0].stiffness" = {{ from = 0.5, to = 50.0, num = {stiffnesses}, '
            'spacing = "log" }\n'
            f'"links[1].mass" = {{ from = 0.5, to = 2.0, num = {masses} }}\n')


def sweep_rows(config: BenchConfig, note) -> tuple[list[SweepRow], LoopEstimate]:
    """The benchmark's sweep by `chaingen sweep`, each a process of its own as a user runs it:
    cold build cache, then cached, then on Dask; and the same with runs ten times as long."""
    import pandas as pd

    from ..sweep.engines import local_workers

    runs = 100 if config.quick else 1000
    cores = local_workers()
    rows: list[SweepRow] = []
    with tempfile.TemporaryDirectory(prefix="chaingen-bench-sweep-") as scratch:
        scratch = Path(scratch)
        scene_path = scratch / f"{HEADLINE_SCENE}.toml"
        scene_path.write_text(scene_toml(load_reference_scene(HEADLINE_SCENE)))
        environment = {**os.environ, "CHAINGEN_CACHE_DIR": str(scratch / "cache"),
                       "CHAINGEN_QUIET": "1"}
        reference: dict = {}
        for t_end in (SWEEP_T_END, 10 * SWEEP_T_END):
            spec_path = scratch / f"spec-{t_end:g}.toml"
            spec_path.write_text(sweep_spec_text(scene_path, runs, t_end))
            for engine, label in (("local", "local, cold build cache"),
                                  ("local", "local, build cached"),
                                  ("dask", f"Dask LocalCluster of {cores}, build cached")):
                if t_end != SWEEP_T_END and label.endswith("cold build cache"):
                    continue
                note(f"studies: sweep of {runs} runs of {t_end:g} s, {label}")
                out = scratch / f"out-{len(rows)}"
                command = [sys.executable, "-m", "chaingen", "sweep", str(spec_path), "-o",
                           str(out)] + (["--dask-local", str(cores)] if engine == "dask" else [])
                started = time.perf_counter()
                result = subprocess.run(command, capture_output=True, text=True,
                                        env=environment)
                wall = time.perf_counter() - started
                if result.returncode != 0:
                    raise RuntimeError(f"{' '.join(command)} failed: {result.stderr.strip()}")
                found = re.search(r"generate and build ([\d.]+) s", result.stdout)
                table = pd.read_parquet(out / "runs.parquet")
                comparable = table.drop(columns=["cpu_seconds"])
                equal = None
                if t_end not in reference:
                    reference[t_end] = comparable
                else:
                    equal = comparable.equals(reference[t_end])
                rows.append(SweepRow(f"{label}, runs of {t_end:g} s", len(table), wall,
                                     float(found.group(1)) if found else float("nan"),
                                     float(table["cpu_seconds"].sum()), cores,
                                     int(table["solver"].nunique()),
                                     int((table["status"] != "ok").sum()), equal))
        from ..sweep import load_spec

        loop = _loop_estimate(load_spec(scratch / f"spec-{SWEEP_T_END:g}.toml"), scratch,
                              note, 2 if config.quick else LOOP_SUBSET)
    return rows, loop


def _loop_estimate(spec, scratch: Path, note, subset: int) -> LoopEstimate:
    """`chaingen simulate` on the scene files of `subset` of the sweep's runs, spread over the
    sweep, each a fresh process and a fresh build: the mean wall time of one."""
    picks = np.linspace(0, len(spec.runs) - 1, subset).round().astype(int)
    seconds = []
    for count, index in enumerate(picks):
        note(f"studies: chaingen simulate, scene file {count + 1} of {len(picks)}")
        values = {path: value for path, value in spec.runs[index].items()}
        scene = with_values(spec.scene, values)
        path = scratch / f"run-{index}.toml"
        path.write_text(scene_toml(scene))
        environment = {**os.environ, "CHAINGEN_CACHE_DIR": str(scratch / "loop-cache"),
                       "CHAINGEN_QUIET": "1"}
        started = time.perf_counter()
        result = subprocess.run([sys.executable, "-m", "chaingen", "simulate", str(path),
                                 "--t-end", repr(spec.t_end), "--out",
                                 str(scratch / f"run-{index}.csv"), "--every",
                                 str(spec.every or 1)],
                                capture_output=True, text=True, env=environment)
        seconds.append(time.perf_counter() - started)
        if result.returncode != 0:
            raise RuntimeError(f"chaingen simulate {path} failed: {result.stderr.strip()}")
    return LoopEstimate(len(picks), statistics.mean(seconds), len(spec.runs))


def study_part(config: BenchConfig, note) -> StudyResults:
    parameters = parameter_rows(config, note)
    sweeps, loop = sweep_rows(config, note) if config.run_sweep else ([], None)
    return StudyResults(parameters, sweeps, loop)


def _verdict(passed: bool) -> str:
    return "yes" if passed else "**no**"


def study_tables(results: StudyResults) -> str:
    lines = [f"Run-time parameters ({HEADLINE_SCENE}, K = 3, dt = {HEADLINE_DT} s, C harness; "
             f"both in one program, {PARAMETER_ROUNDS} rounds of 2000 steps each in alternating "
             "order; ratio: the median of the rounds' ratios, with its quartiles):", "",
             "| method | parameters | step, compiled in | step, parameters | ratio | quartiles | "
             "target | met | Newton its (compiled / parameters) |",
             "|---|---|---|---|---|---|---|---|---|"]
    for row in results.parameters:
        target = row.numbers == PARAMETER_SETS[0][0]
        lines.append(f"| {row.method} | {row.numbers} ({row.parameters}) | {row.baked_ns:.0f} ns "
                     f"| {row.varied_ns:.0f} ns | {row.ratio:.3f} | {row.low:.3f} .. "
                     f"{row.high:.3f} | {f'<= {TARGET_PARAMETER_RATIO}' if target else '-'} | "
                     f"{_verdict(row.ratio <= TARGET_PARAMETER_RATIO) if target else '-'} | "
                     f"{row.baked_iterations:.2f} / {row.varied_iterations:.2f} |")
    if not results.sweeps:
        return "\n".join(lines)
    lines += ["", "Sweeps by `chaingen sweep`, each a fresh process (the wall time of the whole "
              "command: start, generate and build or load the solver, run, store):", "",
              "| sweep | runs | wall | of it generate + build | sum of runs' CPU | "
              "1.25 x CPU / cores + 10 s | met | solvers | failed | equal to local |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for row in results.sweeps:
        equal = "-" if row.equal_to_local is None else _verdict(row.equal_to_local)
        lines.append(f"| {row.engine} | {row.runs} | {row.wall_seconds:.2f} s | "
                     f"{row.generate_seconds:.2f} s | {row.cpu_seconds:.2f} s | "
                     f"{row.bound:.2f} s | {_verdict(row.wall_seconds <= row.bound)} | "
                     f"{row.solvers} | {row.failed} | {equal} |")
    lines.append("")
    for dask in (row for row in results.sweeps if row.engine.startswith("Dask")):
        runs_of = dask.engine.split(", ")[-1]
        local = next(row for row in results.sweeps
                     if row.engine == f"local, build cached, {runs_of}")
        ratio = dask.wall_seconds / local.wall_seconds
        lines.append(f"- Dask / local, {runs_of}, build cached: {ratio:.2f} (target <= "
                     f"{TARGET_DASK_OVER_LOCAL}: {_verdict(ratio <= TARGET_DASK_OVER_LOCAL)}); "
                     f"Dask's fixed cost: {dask.wall_seconds - local.wall_seconds:.2f} s.")
    if results.loop is not None:
        loop = results.loop
        cold = results.sweeps[0]
        over = loop.total_seconds / cold.wall_seconds
        lines.append(f"- A loop of `chaingen simulate` over {loop.runs} scene files: "
                     f"{loop.mean_seconds:.2f} s per file (mean of {loop.files}, each a fresh "
                     f"process and build), {loop.total_seconds:.0f} s for all; "
                     f"{over:.0f} x the cold-cache sweep (target >= "
                     f"{TARGET_LOOP_OVER_SWEEP:.0f}: {_verdict(over >= TARGET_LOOP_OVER_SWEEP)}).")
    return "\n".join(lines)
