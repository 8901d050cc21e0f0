"""The size and build time of the step sensitivities' generated code against n (docs/model.md,
section 11; issue 32 b), on the bench's scaling chain (chaingen.studies.bench.scaling_scene).
Run from the checkout:

    python docs/studies/sensitivity_scaling.py sizes [--n 5,10,15,20] [--build] [--timeout S]
    python docs/studies/sensitivity_scaling.py per-step [--n 3,20] [--steps N]

`sizes` prints, per method, order and n, the model C (<prefix>_model.c) with and without the
sensitivities, the time to generate it with them and, with --build, the time of
build_solver's default (sensitivities on) from an empty build cache: generate and compile, in a
child process of its own that is stopped after --timeout s. `per-step` times
<prefix>_step_sensitivities along the scene's run from its start (order 2, dt = 0.01 s) in a C loop
compiled as the package is (-O2, the solver's source -O3): the median over five rounds of the
mean over --steps steps. The machine is shared: times are noisy, sizes are not.
"""
from __future__ import annotations

import argparse
import os
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from chaingen.generate.package import generate_package, model_c_bytes, write_package
from chaingen.scene.solver_spec import SolverSpec
from chaingen.studies.bench.scaling import scaling_scene

METHODS = ("es", "vi", "midpoint")
ORDERS = (2, 4)
DT = 0.01

BUILD_CHILD = """
import sys, time
from chaingen import build_solver
from chaingen.studies.bench.scaling import scaling_scene
start = time.perf_counter()
build_solver(scaling_scene(int(sys.argv[2])), sys.argv[1], order=int(sys.argv[3]))
print(time.perf_counter() - start)
"""

TIMING_C = r"""
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <string.h>
#include <time.h>
#include "{prefix}.h"
#define N {upper}_N_JOINTS
#define NX {upper}_NX
static struct {{
    {prefix}_workspace workspace;
    {prefix}_options options;
    double x[NX], next[NX], ds[4 * N * N];
}} e;
static double now(void)
{{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}}
int main(void)
{{
    static const double phi[N] = {{ {angles} }}, phidot[N] = {{ 0.0 }};
    int k, round, iterations = 0, status = 0;
    {prefix}_default_options(&e.options);
    {prefix}_workspace_init(&e.workspace);
    for (round = 0; round < 6 && !status; ++round) {{
        double start = now();
        status = {prefix}_initial_state(phi, phidot, NULL, 0, e.x, &e.workspace);
        for (k = 0; k < {steps} && !status; ++k) {{
            status = {prefix}_step_sensitivities(e.x, NULL, 0, NULL, 0, {dt}, e.next, e.ds,
                                                 NULL, NULL, &e.options, &e.workspace,
                                                 &iterations);
            memcpy(e.x, e.next, sizeof e.x);
        }}
        if (round > 0) {{   /* the first round warms up */
            printf("%.1f\n", 1e9 * (now() - start) / {steps});
        }}
    }}
    if (status) {{
        printf("status %d at step %d\n", status, k);
    }}
    return status;
}}
"""


def model_bytes(package) -> int:
    return model_c_bytes(package)


def build_seconds(method: str, n: int, order: int, timeout: float) -> float | None:
    """build_solver's wall time from an empty cache in a child process; None past timeout
    (the child and its compiler, its process group, are stopped)."""
    with tempfile.TemporaryDirectory() as cache:
        child = subprocess.Popen([sys.executable, "-c", BUILD_CHILD, method, str(n), str(order)],
                                 stdout=subprocess.PIPE, text=True, start_new_session=True,
                                 env={**os.environ, "CHAINGEN_CACHE_DIR": cache})
        try:
            out, _ = child.communicate(timeout=timeout)
        except subprocess.TimeoutExpired:
            os.killpg(child.pid, signal.SIGKILL)
            child.communicate()
            return None
        return float(out.strip().splitlines()[-1]) if child.returncode == 0 else None


def sizes(args) -> None:
    print(f"{'method':9} {'order':>5} {'n':>3} {'model C kB':>11} {'kB / n':>7} "
          f"{'without kB':>11} {'generate s':>11} {'build_solver s':>15}", flush=True)
    for method in args.methods:
        for order in args.orders:
            for n in args.n:
                scene = scaling_scene(n)
                start = time.perf_counter()
                package = generate_package(SolverSpec.create(scene, method, order=order))
                generate = time.perf_counter() - start
                without = generate_package(SolverSpec.create(scene, method, order=order,
                                                             sensitivities=False))
                built = "-"
                if args.build:
                    seconds = build_seconds(method, n, order, args.timeout)
                    built = f"> {args.timeout:.0f}" if seconds is None else f"{seconds:.1f}"
                size = model_bytes(package) / 1e3
                print(f"{method:9} {order:5d} {n:3d} {size:11.1f} {size / n:7.1f} "
                      f"{model_bytes(without) / 1e3:11.1f} {generate:11.1f} {built:>15}",
                      flush=True)


def per_step(args) -> None:
    compiler = shutil.which(os.environ.get("CC", "cc"))
    print(f"{'method':9} {'n':>3} {'ns per step_sensitivities':>26} {'spread':>8}", flush=True)
    for n in args.n:
        scene = scaling_scene(n)
        for method in args.methods:
            package = generate_package(SolverSpec.create(scene, method, order=2))
            with tempfile.TemporaryDirectory() as folder:
                folder = Path(folder)
                write_package(package, folder / "package")
                source = folder / "package" / "timing.c"
                source.write_text(TIMING_C.format(
                    prefix=package.prefix, upper=package.prefix.upper(), steps=args.steps,
                    dt=DT, angles=", ".join(repr(a) for a in scene.initial_angles)))
                flags = package.manifest["source_flags"]
                objects = []
                for name in package.manifest["sources"]:
                    objects.append(str(folder / f"{name}.o"))
                    subprocess.run([compiler, "-O2", "-std=c99", *flags.get(name, []), "-c",
                                    str(folder / "package" / name), "-o", objects[-1]],
                                   check=True)
                subprocess.run([compiler, "-O2", "-std=c99", "-o", str(folder / "timing"),
                                str(source), *objects, "-lm"], check=True)
                run = subprocess.run([str(folder / "timing")], capture_output=True, text=True)
                if run.returncode:
                    print(f"{method:9} {n:3d} failed: {run.stdout.splitlines()[-1]}")
                    continue
                rounds = [float(line) for line in run.stdout.split()]
            median = statistics.median(rounds)
            spread = (max(rounds) - min(rounds)) / median
            print(f"{method:9} {n:3d} {median:26.0f} {spread:8.2f}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("what", choices=("sizes", "per-step"))
    parser.add_argument("--n", type=lambda text: [int(v) for v in text.split(",")])
    parser.add_argument("--methods", type=lambda text: text.split(","), default=METHODS)
    parser.add_argument("--orders", type=lambda text: [int(v) for v in text.split(",")],
                        default=ORDERS)
    parser.add_argument("--build", action="store_true")
    parser.add_argument("--timeout", type=float, default=120.0)
    parser.add_argument("--steps", type=int, default=300)
    args = parser.parse_args()
    if args.what == "sizes":
        args.n = args.n or [5, 10, 15, 20]
        sizes(args)
    else:
        args.n = args.n or [3, 20]
        per_step(args)


if __name__ == "__main__":
    main()
