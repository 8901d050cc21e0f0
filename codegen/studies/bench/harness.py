"""Time a generated package's C loop: steps, and the evaluations a step cannot avoid.

A small C program (templates/bench_harness.c.j2) is compiled with the package's sources and
times, with the process CPU clock and no Python in between, N calls of <prefix>_step, one
residual-and-Jacobian evaluation, one residual evaluation and one LU factorisation and solve of
dF/dz. Each is the median of repeats. The ratio step / (residual and Jacobian) is how close a
step is to its floor: a Newton step cannot do with less than one such evaluation.
"""
from __future__ import annotations

import json
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...generate.interface import c_literal
from ...generate.package import GeneratedPackage, template_environment
from ...runtime import contract
from ...runtime.build import STRICT_FLAGS, compiler


class HarnessError(RuntimeError):
    """The harness did not build, or a step failed while timing."""


def build_timing_program(folder: Path, program: str, manifest: dict,
                         flags: tuple[str, ...] = ("-O2",)) -> Path:
    """Compile the timing program `program` (a .c file in `folder`, beside the package's files)
    with the package's sources, each in its own compiler process at once, the package's own
    flags for its sources (manifest source_flags: the solver's -O3, a large model's -O1) as
    chaingen's build does and `flags` elsewhere, and link it; its path, or HarnessError naming
    the failed command."""
    source_flags = manifest.get("source_flags", {})
    sources = [program, *manifest["sources"]]
    executable = folder / Path(program).stem
    commands = [[compiler(), *STRICT_FLAGS, *source_flags.get(name, flags), "-c", name, "-o",
                 f"{name}.o"] for name in sources]
    processes = [subprocess.Popen(command, cwd=folder, stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True) for command in commands]
    results = [(command, process, process.communicate()[1])
               for command, process in zip(commands, processes)]
    if all(process.returncode == 0 for _, process, _ in results):
        command = [compiler(), "-o", str(executable), *(f"{name}.o" for name in sources), "-lm"]
        link = subprocess.run(command, cwd=folder, capture_output=True, text=True)
        results.append((command, link, link.stderr))
    for command, process, stderr in results:
        if process.returncode != 0:
            raise HarnessError(f"building {program} failed: {' '.join(command)}\n{stderr}")
    return executable


def timing_report(result: subprocess.CompletedProcess, what: str) -> dict:
    """The JSON report a timing program printed, or HarnessError naming `what` and why."""
    try:
        report = json.loads(result.stdout)
    except json.JSONDecodeError:
        raise HarnessError(f"{what} failed: {result.stderr}") from None
    if report["status"] != 0:
        raise HarnessError(f"{what}: status {report['status']} while timing "
                           f"(step {report.get('failed_step', '?')})")
    return report


@dataclass(frozen=True)
class LoopTimings:
    """CPU time of one step and of its building blocks, in nanoseconds (medians of repeats)."""

    step_ns: float
    residual_jacobian_ns: float
    residual_ns: float
    lu_ns: float
    mean_iterations: float

    @property
    def step_over_evaluation(self) -> float:
        """Step time in units of one residual-and-Jacobian evaluation."""
        return self.step_ns / self.residual_jacobian_ns


def call_arguments(prefix: str, manifest: dict) -> dict:
    """The u and p arguments of a step call in a timing program: the arrays u and p with their
    sizes, or NULL, 0 where the package has none."""
    P = prefix.upper()
    return {"u_arguments": f"u, {P}_NU" if manifest["nu"] else "NULL, 0",
            "p_arguments": f"p, {P}_NP" if manifest["parameters"] else "NULL, 0"}


class Harness:
    """A compiled timing program for one package; call `time` as often as needed."""

    def __init__(self, package: GeneratedPackage, *, flags: tuple[str, ...] = ("-O2",),
                 workdir: Path | None = None):
        self.package = package
        self._owned = workdir is None
        self.workdir = Path(workdir or tempfile.mkdtemp(prefix=f"bench-{package.prefix}-"))
        for name, text in package.files.items():
            (self.workdir / name).write_text(text)
        manifest = package.manifest
        environment = template_environment()
        source = environment.get_template("bench_harness.c.j2").render(
            **call_arguments(package.prefix, manifest),
            prefix=package.prefix, PREFIX=package.prefix.upper(), nu=manifest["nu"],
            flows=manifest["energy_flows"],
            parameters=[c_literal(entry["value"]) for entry in manifest["parameters"]],
            option_fields=[(field.name, field.c_type) for field in contract.NEWTON_OPTIONS])
        (self.workdir / "bench_harness.c").write_text(source)
        start = time.perf_counter()
        self.program = build_timing_program(self.workdir, "bench_harness.c", manifest, flags)
        #: wall time of compiling and linking package and harness (the model dominates)
        self.build_seconds = time.perf_counter() - start

    def time(self, x0, dt: float, *, n_steps: int = 2000, repeats: int = 7,
             options: dict[str, float] | None = None) -> LoopTimings:
        """Timings of `n_steps` steps from state x0 (repeated), and of the evaluations."""
        x0 = np.asarray(x0, dtype=float)
        arguments = [str(self.program), str(n_steps), str(repeats), repr(float(dt))]
        arguments += [f"{key}={value!r}" for key, value in (options or {}).items()]
        result = subprocess.run(arguments, input=" ".join(map(repr, x0.tolist())),
                                capture_output=True, text=True)
        report = timing_report(result, f"{self.package.prefix}: harness")
        return LoopTimings(step_ns=report["step_ns"],
                           residual_jacobian_ns=report["residual_jacobian_ns"],
                           residual_ns=report["residual_ns"], lu_ns=report["lu_ns"],
                           mean_iterations=report["iterations"] / n_steps)

    def close(self) -> None:
        if self._owned:
            shutil.rmtree(self.workdir, ignore_errors=True)

    def __enter__(self) -> Harness:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


@dataclass(frozen=True)
class PairedTimings:
    """Per-step CPU times of two packages in paired blocks (seconds), and their iterations."""

    a: tuple[float, ...]
    b: tuple[float, ...]
    iterations_a: float          # Newton iterations per step of the last block
    iterations_b: float

    @property
    def ratios(self) -> tuple[float, ...]:
        """b / a of each round."""
        return tuple(b / a for a, b in zip(self.a, self.b))


def time_pair(first: GeneratedPackage, second: GeneratedPackage, x0, dt: float, *,
              n_steps: int = 2000, rounds: int = 21,
              flags: tuple[str, ...] = ("-O2",)) -> PairedTimings:
    """Time `first` and `second` (packages of one scheme with one state layout, distinct
    prefixes) in one process, block by block in alternating order (templates/bench_pair.c.j2):
    the fair comparison on a machine whose speed drifts."""
    if first.prefix == second.prefix:
        raise ValueError(f"time_pair needs two prefixes, got {first.prefix} twice")
    blocks = []
    for package in (first, second):
        manifest = package.manifest
        environment = template_environment()
        blocks.append(environment.get_template("bench_pair_block.c.j2").render(
            **call_arguments(package.prefix, manifest), prefix=package.prefix,
            PREFIX=package.prefix.upper(), nu=manifest["nu"],
            parameters=[c_literal(entry["value"]) for entry in manifest["parameters"]]))
    source = template_environment().get_template("bench_pair.c.j2").render(
        a=first.prefix, A=first.prefix.upper(), b=second.prefix, blocks="\n".join(blocks))
    with tempfile.TemporaryDirectory(prefix="bench-pair-") as directory:
        workdir = Path(directory)
        objects = []
        commands = []
        for package in (first, second):
            folder = workdir / package.prefix
            folder.mkdir()
            for name, text in package.files.items():
                (folder / name).write_text(text)
            source_flags = package.manifest.get("source_flags", {})
            for name in package.manifest["sources"]:
                objects.append(str(folder / f"{name}.o"))
                commands.append([compiler(), *STRICT_FLAGS, *source_flags.get(name, flags), "-c",
                                 str(folder / name), "-o", objects[-1]])
        (workdir / "bench_pair.c").write_text(source)
        objects.append(str(workdir / "bench_pair.o"))
        commands.append([compiler(), *STRICT_FLAGS, *flags, f"-I{workdir / first.prefix}",
                         f"-I{workdir / second.prefix}", "-c", str(workdir / "bench_pair.c"),
                         "-o", objects[-1]])
        processes = [subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                      text=True) for command in commands]
        for command, process in zip(commands, processes):
            stderr = process.communicate()[1]
            if process.returncode != 0:
                raise HarnessError(f"building the paired harness failed: {' '.join(command)}"
                                   f"\n{stderr}")
        program = workdir / "bench_pair"
        link = subprocess.run([compiler(), "-o", str(program), *objects, "-lm"],
                              capture_output=True, text=True)
        if link.returncode != 0:
            raise HarnessError(f"linking the paired harness failed: {link.stderr}")
        result = subprocess.run([str(program), str(n_steps), str(rounds), repr(float(dt))],
                                input=" ".join(map(repr, np.asarray(x0, float).tolist())),
                                capture_output=True, text=True)
    report = timing_report(result, "paired harness")
    return PairedTimings(tuple(report["a"]), tuple(report["b"]),
                         report["iterations_a"] / n_steps, report["iterations_b"] / n_steps)
