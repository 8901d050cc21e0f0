"""Part 2 of the benchmark: the scaling series, generate, build and step cost against n.

Each scheme at each n of scaling_scene(n), and es of uneven_scene(n), is generated, built and
timed in a child process of its own (so that a size over the time limit can be stopped, with
the compiler it started), with MuJoCo RK4 on the same chain beside it.
"""
from __future__ import annotations

import json
import os
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...generate.package import model_c_bytes, render_package
from ...runtime.build import compiler
from ...scene import Scene
from .config import HARNESS_FLAGS, SCALING_DTS, VARIANTS, BenchConfig
from .harness import Harness, HarnessError
from .runs import method_label, mujoco_step_seconds
from .scenes import SCALING_CHAINS, scaling_scene  # noqa: F401  (docs/studies import it from here)


@dataclass(frozen=True)
class ScalingRow:
    """One scheme at one n of the scaling series (one row per Newton variant)."""

    method: str
    n: int
    variant: str
    generate_seconds: float | None = None
    build_seconds: float | None = None
    generate_peak_mb: float | None = None
    compile_peak_mb: float | None = None
    model_c_bytes: int | None = None
    dt: float | None = None
    step_seconds: float | None = None
    newton_iterations: float | None = None
    mujoco_step_seconds: float | None = None
    failure: str | None = None
    chain: str = "identical"     # scenes.SCALING_CHAINS: "identical" or "uneven"
    gradient: str = "exact"      # es's discrete gradient of the springs

    @property
    def generate_and_build_seconds(self) -> float | None:
        if self.generate_seconds is None or self.build_seconds is None:
            return None
        return self.generate_seconds + self.build_seconds

    @property
    def ratio(self) -> float | None:
        if self.step_seconds is None or not self.mujoco_step_seconds:
            return None
        return self.step_seconds / self.mujoco_step_seconds



def _numeric_initial_state(scheme, scene: Scene) -> np.ndarray:
    return np.array(scheme.initial_function()(*scene.initial_angles, *scene.initial_velocities),
                    float).ravel()


def peak_resident_kib() -> int | None:
    """Peak resident memory of this process image (VmHWM of /proc/self/status, KiB).

    Not getrusage's ru_maxrss: Linux carries that over fork and execve, so a process started
    from a large one (subprocess uses vfork) reports its parent's peak as its own."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1])
    except (OSError, ValueError, IndexError):
        pass
    return None


def _compiler_with_peak(directory: Path) -> tuple[Path, Path] | None:
    """A wrapper of the C compiler that appends the compiler's peak RSS (KiB, gcc and the
    passes it waits for) to a file, by GNU time run from a small process; (wrapper, file),
    or None without /usr/bin/time."""
    program = shutil.which("time", path="/usr/bin:/bin")
    if program is None:
        return None
    wrapper, peaks = directory / "cc-with-peak", directory / "compiler-peaks"
    wrapper.write_text(f"#!/bin/sh\nexec {shlex.quote(program)} -f %M -a -o "
                       f"{shlex.quote(str(peaks))} {shlex.quote(compiler())} \"$@\"\n")
    wrapper.chmod(0o755)
    return wrapper, peaks


def measure_scaling_point(method: str, quadrature: int, n: int, *, n_steps: int,
                          repeats: int, chain: str = "identical",
                          gradient: str = "exact") -> dict:
    """Generate, build and time the scaling chain of n links (`chain`: scaling_scene(n),
    "identical", or uneven_scene(n), "uneven") with one scheme; run in a child process.

    generate_seconds: SymPy scheme, CasADi functions and rendering (generate_package's work,
    done as build_scheme + render_package to keep the scheme for the initial state).
    generate_peak_kb: this process's peak RSS after generating (Python, SymPy, CasADi and the
    expressions); compile_peak_kb: the compiler's peak RSS (via _compiler_with_peak; None if
    it cannot be measured). Per-step time at the first of SCALING_DTS at which no step fails,
    median of `repeats` rounds, each followed by a round of MuJoCo RK4 on the same model (the
    same dt and number of steps from the same state).
    """
    from ...symbolic.schemes import build_scheme

    scene = SCALING_CHAINS[chain](n)
    started = time.perf_counter()
    scheme = build_scheme(scene, method, quadrature, gradient=gradient)
    package = render_package(scheme, sensitivities=False)
    generate_seconds = time.perf_counter() - started
    generate_peak = peak_resident_kib()
    x0 = _numeric_initial_state(scheme, scene)
    timings = {}
    scratch = Path(tempfile.mkdtemp(prefix="compiler-peak-"))
    measured_compiler = _compiler_with_peak(scratch)
    previous_cc = os.environ.get("CC")
    try:
        if measured_compiler is not None:
            os.environ["CC"] = str(measured_compiler[0])   # read by the harness's build
        harness = Harness(package, flags=HARNESS_FLAGS)
    finally:
        if previous_cc is None:
            os.environ.pop("CC", None)
        else:
            os.environ["CC"] = previous_cc
    compile_peak = None
    if measured_compiler is not None and measured_compiler[1].exists():
        compile_peak = max(int(line) for line in measured_compiler[1].read_text().split())
    shutil.rmtree(scratch, ignore_errors=True)
    with harness:
        for variant in VARIANTS:
            failures = []
            for dt in SCALING_DTS:
                try:
                    rounds = [harness.time(x0, dt, n_steps=n_steps, repeats=1,
                                           options=variant.options)]
                except HarnessError as error:
                    failures.append(f"dt = {dt:g} s: {error}")
                    continue
                # MuJoCo RK4 on the same model, dt and steps from the same state, round by
                # round with ours: side by side, on a machine whose speed drifts.
                mujoco = [mujoco_step_seconds(scene, "RK4", dt, n_steps, 1)]
                for _ in range(repeats - 1):
                    rounds.append(harness.time(x0, dt, n_steps=n_steps, repeats=1,
                                               options=variant.options))
                    mujoco.append(mujoco_step_seconds(scene, "RK4", dt, n_steps, 1))
                timings[variant.label] = {
                    "dt": dt, "step_ns": float(np.median([r.step_ns for r in rounds])),
                    "iterations": rounds[-1].mean_iterations,
                    "mujoco_step_seconds": float(np.median(mujoco)),
                    "failures": failures}
                break
            else:
                timings[variant.label] = {"failures": failures}
        build_seconds = harness.build_seconds
    return {"generate_seconds": generate_seconds, "build_seconds": build_seconds,
            "generate_peak_kb": generate_peak, "compile_peak_kb": compile_peak,
            "model_c_bytes": model_c_bytes(package),
            "timings": timings}


#: Seconds the timing of one scaling point may take beyond the limit of generate + build.
TIMING_ALLOWANCE = 300.0


def run_scaling_point(method: str, quadrature: int, n: int, config: BenchConfig,
                      chain: str = "identical", gradient: str = "exact") -> dict:
    """measure_scaling_point in a child process (its own session, so that on timeout the
    compiler it started is stopped with it); {"failure": ...} if it fails or runs over."""
    # Beyond 20 links a step costs milliseconds: fewer steps and repeats keep the timing within
    # TIMING_ALLOWANCE, so that the limit is that of generating and building.
    n_steps = config.scaling_steps if n <= 20 else max(100, config.scaling_steps * 20 // n)
    repeats = config.repeats if n <= 20 else min(config.repeats, 3)
    program = ("import json\nfrom chaingen.studies.bench.scaling import measure_scaling_point\n"
               f"print(json.dumps(measure_scaling_point({method!r}, {quadrature}, {n}, "
               f"n_steps={n_steps}, repeats={repeats}, chain={chain!r}, "
               f"gradient={gradient!r})))\n")
    # The child's temporary files (the harness's build directory) go to a directory of ours,
    # removed afterwards even when the child had to be killed before cleaning up.
    with tempfile.TemporaryDirectory(prefix="chaingen-bench-") as scratch:
        child = subprocess.Popen([sys.executable, "-c", program], stdout=subprocess.PIPE,
                                 stderr=subprocess.PIPE, text=True,
                                 env={**os.environ, "TMPDIR": scratch}, start_new_session=True)
        try:
            stdout, stderr = child.communicate(timeout=config.timeout + TIMING_ALLOWANCE)
        except subprocess.TimeoutExpired:
            os.killpg(child.pid, signal.SIGKILL)
            child.communicate()
            return {"failure": f"over limit: generate, build and timing did not finish within "
                               f"{config.timeout + TIMING_ALLOWANCE:g} s"}
    if child.returncode != 0:
        last = (stderr.strip().splitlines() or ["no message"])[-1]
        return {"failure": f"exit {child.returncode}: {last}"}
    point = json.loads(stdout.strip().splitlines()[-1])
    seconds = point["generate_seconds"] + point["build_seconds"]
    if seconds > config.timeout:
        return {"failure": f"over limit: generate + build took {seconds:.0f} s, over "
                           f"{config.timeout:g} s"}
    return point


def _mebibytes(kib: int | None) -> float | None:
    return None if kib is None else kib / 1024


def _predicted_over_limit(n: int, seconds: float, config: BenchConfig) -> str | None:
    """Why the next n of the series cannot fit the limit, or None if it may.

    The generated code grows linearly with n (docs/model.md, section 17), and so at least do
    generating and building: t(n') >= t(n) n'/n is a lower bound, and a size it puts over the
    limit is not started."""
    larger = [m for m in config.scaling_ns if m > n]
    if not larger:
        return None
    bound = seconds * larger[0] / n
    if bound <= config.timeout:
        return None
    return (f"not run: generate + build took {seconds:.0f} s at n = {n}, and grows at least "
            f"like n, so n = {larger[0]} would need >= {bound:.0f} s, over the "
            f"{config.timeout:g} s limit")


def scaling_study(config: BenchConfig, note) -> list[ScalingRow]:
    """Part 2: each (chain, scheme) of config.scaling_series at each n, with MuJoCo RK4 at the
    same n and dt. A scheme that runs over the time limit at some n is not run at larger n on
    that chain."""
    rows = []
    for chain, method, quadrature, gradient in config.scaling_series:
        skip_reason = None
        tags = {"chain": chain, "gradient": gradient}
        for n in config.scaling_ns:
            label = method_label(SCALING_CHAINS[chain](n), method, quadrature)
            label += "" if gradient == "exact" or method != "es" else f" {gradient}"
            if skip_reason is not None:
                rows += [ScalingRow(label, n, variant.label, failure=skip_reason, **tags)
                         for variant in VARIANTS]
                note(f"scaling {chain} {label} n={n}: {skip_reason}")
                continue
            started = time.perf_counter()
            point = run_scaling_point(method, quadrature, n, config, chain, gradient)
            if "failure" not in point:
                seconds = point["generate_seconds"] + point["build_seconds"]
                skip_reason = _predicted_over_limit(n, seconds, config)
            if "failure" in point:
                if point["failure"].startswith("over limit"):
                    skip_reason = f"not run: over the limit at n = {n}"
                rows += [ScalingRow(label, n, variant.label, failure=point["failure"],
                                    **tags) for variant in VARIANTS]
                note(f"scaling {chain} {label} n={n}: {point['failure']}")
                continue
            for variant in VARIANTS:
                timing = point["timings"][variant.label]
                common = dict(
                    generate_seconds=point["generate_seconds"],
                    build_seconds=point["build_seconds"],
                    generate_peak_mb=_mebibytes(point["generate_peak_kb"]),
                    compile_peak_mb=_mebibytes(point["compile_peak_kb"]),
                    model_c_bytes=point["model_c_bytes"], **tags)
                if "dt" not in timing:
                    rows.append(ScalingRow(label, n, variant.label, **common,
                                           failure="; ".join(timing["failures"])))
                    continue
                failures = ("; ".join(timing["failures"]) or None)
                rows.append(ScalingRow(
                    label, n, variant.label, **common, dt=timing["dt"],
                    step_seconds=timing["step_ns"] * 1e-9,
                    newton_iterations=timing["iterations"],
                    mujoco_step_seconds=timing["mujoco_step_seconds"], failure=failures))
            note(f"scaling {chain} {label} n={n}: generate {point['generate_seconds']:.1f} s, "
                 f"build {point['build_seconds']:.1f} s "
                 f"({time.perf_counter() - started:.0f} s in all)")
    return rows

