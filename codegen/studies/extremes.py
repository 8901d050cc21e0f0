"""The extremes study: what each scheme does at the edges of its use, measured.

    python -m chaingen.studies.extremes [--out docs/extremes.md] [--quick]

Runs every edge of issue 5 and writes a Markdown table, one row per edge and scheme, with what
happened: the errors when it works, the message when it stops. Nothing is hard-coded: every
figure in the table comes from the run that writes it. `--quick` shortens the long runs and the
n search (for the test that exercises the script). The benchmark marker's test runs it.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import NewtonError, UnsupportedSceneError
from ..runtime import NewtonOptions
from ..runtime.files import write_text
from ..scene import METHODS, Link, Scene, Simulation, Spring, load_reference_scene, quadrature_used
from ..simulation import build_solver


@dataclass(frozen=True)
class Outcome:
    edge: str
    method: str
    setting: str
    result: str          # "works", "stops", "refused"
    details: str


def chain(n: int, *, masses=None, inertias=None, stiffness: float = 1.0,
          gravity: float = 1.0) -> Scene:
    """The thesis's chain made n links long: unit links, a mono-articular spring per joint."""
    masses = masses or [1.0] * n
    inertias = inertias if inertias is not None else [1.0] * n
    links = tuple(Link(mass=m, inertia=j, length=1.0, com=0.5, com_normal=0.0, fastening=0.4,
                       damping=0.0) for m, j in zip(masses, inertias))
    springs = tuple(Spring(first=i, last=i, stiffness=stiffness, rest_length=0.2, offsets=None)
                    for i in range(1, n + 1))
    angles = (math.pi / 4,) + (0.3,) * (n - 1)
    return Scene(name=f"chain-{n}", gravity=gravity, base_fastening=0.4, links=links,
                 springs=springs, initial_angles=angles, initial_velocities=(0.0,) * n,
                 simulation=Simulation())


def run(scene: Scene, method: str, *, dt: float, t_end: float, every: int = 1,
        quadrature: int = 3, options: NewtonOptions | dict | None = None, solver=None):
    """(result "works"/"stops", details) of one simulation."""
    solver = solver or build_solver(scene, method, quadrature, sensitivities=False)
    steps = round(t_end / dt)
    try:
        result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=dt,
                                 n_steps=steps, every=every, options=options)
    except NewtonError as error:
        return "stops", f"{error}"
    energy = np.abs(result.energy_error).max()
    scale = max(abs(result.energy[0]), 1.0)
    # Adaptive steps count Newton iterations and time per sample interval, not per step.
    step = "interval" if result.adaptive else "step"
    details = (f"max abs energy error {energy:.2e} J ({energy / scale:.1e} relative), "
               f"constraint {result.constraint_error.max():.1e}, Newton mean "
               f"{result.mean_newton_iterations:.2f} / max {result.max_newton_iterations} "
               f"per {step}, {result.wall_time / max(steps, 1) * 1e6:.2f} us/{step}")
    if result.full_newton_fallbacks or result.split_steps:
        details += (f"; fallbacks: {result.full_newton_fallbacks} steps by full Newton, "
                    f"{result.split_steps} split")
    if result.adaptive:
        details += (f"; adaptive steps: {result.accepted_steps} accepted, "
                    f"{result.rejected_steps} rejected, dt from {result.smallest_dt:.2g} to "
                    f"{result.largest_dt:.2g} s")
    return "works", details


def edge_large_steps(quick: bool) -> list[Outcome]:
    scene = load_reference_scene("three_link_mono")
    rows = []
    for method in METHODS:
        solver = build_solver(scene, method, 3, sensitivities=False)
        for dt in (0.05, 0.1, 0.2):
            result, details = run(scene, method, dt=dt, t_end=10.0 if quick else 50.0,
                                  solver=solver)
            rows.append(Outcome("large step", method, f"three_link_mono, dt = {dt} s",
                                result, details))
    return rows


def edge_stiff_springs(quick: bool) -> list[Outcome]:
    rows = []
    for stiffness in (1e4, 1e6):
        scene = chain(3, stiffness=stiffness)
        for method in METHODS:
            for dt in (0.01, 0.001):
                result, details = run(scene, method, dt=dt, t_end=1.0 if quick else 5.0)
                rows.append(Outcome("stiff springs", method,
                                    f"k = {stiffness:.0e} N/m, dt = {dt} s", result, details))
    return rows


def edge_adaptive_steps(quick: bool) -> list[Outcome]:
    """Where fixed steps of 0.01 s stop or struggle, es with adaptive steps (rtol = atol =
    1e-8, the sample interval 0.01 s): the spring of k = 1e6 (fixed steps collapse a segment
    in the first step), and the 1:1000:1 chain with the default options and with full Newton
    (which needed a split step at fixed steps)."""
    adaptive = {"rtol": 1e-8, "atol": 1e-8}
    masses = [1.0, 1e3, 1.0]
    ratio = chain(3, masses=masses, inertias=list(masses))
    cases = [("k = 1e+06 N/m", chain(3, stiffness=1e6), {}, 0.5 if quick else 5.0),
             ("links 1:1000:1", ratio, {}, 10.0 if quick else 50.0),
             ("links 1:1000:1, full Newton", ratio, {"reuse_jacobian": 0},
              10.0 if quick else 50.0)]
    return [Outcome("adaptive steps", "es", f"{label}, rtol = atol = 1e-8, samples every "
                    f"0.01 s, {t_end:g} s", *run(scene, "es", dt=0.01, t_end=t_end,
                                                 options={**adaptive, **options}))
            for label, scene, options, t_end in cases]


def edge_mass_ratios(quick: bool) -> list[Outcome]:
    rows = []
    for ratio in (1e-3, 1e3):
        masses = [1.0, ratio, 1.0]
        scene = chain(3, masses=masses, inertias=[m for m in masses])
        for method in METHODS:
            result, details = run(scene, method, dt=0.01, t_end=10.0 if quick else 50.0)
            rows.append(Outcome("mass and inertia ratio", method,
                                f"links 1:2:3 = 1:{ratio:g}:1, dt = 0.01 s", result, details))
    return rows


def edge_hard_newton(quick: bool) -> list[Outcome]:
    """The steps that made Newton give up before the fallback ladder and the scaled tests: an
    ill-conditioned 1:1000:1 chain with full Newton, masses of 1e12 kg, the 20-link scaling
    chain over 200 s and a 40-link chain, all with the default options otherwise."""
    from .bench.scenes import scaling_scene

    rows = []
    masses = [1.0, 1e3, 1.0]
    ratio = chain(3, masses=masses, inertias=list(masses))
    rows.append(Outcome("hard Newton steps", "es", "links 1:1000:1, full Newton, dt = 0.01 s, "
                        "50 s", *run(ratio, "es", dt=0.01, t_end=10.0 if quick else 50.0,
                                     options={"reuse_jacobian": 0})))
    heavy = chain(3, masses=[1e12] * 3, inertias=[1e12] * 3)
    rows.append(Outcome("hard Newton steps", "es", "masses and inertias 1e12, dt = 0.01 s, 50 s",
                        *run(heavy, "es", dt=0.01, t_end=10.0 if quick else 50.0)))
    n_long = 5 if quick else 20
    rows.append(Outcome("hard Newton steps", "es", f"scaling chain n = {n_long}, dt = 0.01 s, "
                        f"{20 if quick else 200} s",
                        *run(scaling_scene(n_long), "es", dt=0.01,
                             t_end=20.0 if quick else 200.0, every=10)))
    n_chain = 6 if quick else 40
    rows.append(Outcome("hard Newton steps", "es", f"chain of {n_chain} unit links, dt = 0.01 s, "
                        "10 s", *run(chain(n_chain), "es", dt=0.01, t_end=10.0, every=10)))
    return rows


def edge_zero_inertia(quick: bool) -> list[Outcome]:
    scene = chain(3, inertias=[0.0, 0.0, 0.0])
    return [Outcome("zero inertia", method, "J = 0 on every link (point masses), dt = 0.01 s",
                    *run(scene, method, dt=0.01, t_end=10.0 if quick else 50.0))
            for method in METHODS]


def timed_chain_run(n: int, method: str, timeout: float) -> tuple[float | None, str, str]:
    """Generate, build and run chain(n) in a subprocess with an empty build cache: (seconds to
    generate and build, or None past `timeout`; result; details). A subprocess, so that a size
    that takes too long can be stopped."""
    program = (
        "import json, sys, time\n"
        "from chaingen.studies.extremes import chain, run\n"
        "from chaingen.simulation import build_solver\n"
        f"scene = chain({n})\n"
        "started = time.perf_counter()\n"
        f"solver = build_solver(scene, {method!r}, 3, sensitivities=False)\n"
        "seconds = time.perf_counter() - started\n"
        f"result, details = run(scene, {method!r}, dt=0.01, t_end=10.0, solver=solver)\n"
        "print(json.dumps([seconds, result, details]))\n")
    # A build cache of its own, empty: the time is always that of a first build.
    with tempfile.TemporaryDirectory(prefix="chaingen-extremes-") as cache:
        try:
            finished = subprocess.run([sys.executable, "-c", program], capture_output=True,
                                      text=True, timeout=timeout,
                                      env={**os.environ, "CHAINGEN_CACHE_DIR": cache})
        except subprocess.TimeoutExpired:
            return None, "stops", f"generate + build did not finish within {timeout:.0f} s"
    if finished.returncode != 0:
        last = (finished.stderr.strip().splitlines() or ["no message"])[-1]
        return None, "stops", f"exit {finished.returncode}: {last}"
    seconds, result, details = json.loads(finished.stdout.strip().splitlines()[-1])
    return seconds, result, details


def edge_chain_length(quick: bool) -> list[Outcome]:
    rows = []
    sizes = (1, 5) if quick else (1, 20)
    for method in METHODS:
        for n in sizes:
            seconds, result, details = timed_chain_run(n, method, 120.0 if quick else 300.0)
            if seconds is not None:
                details = f"generate + build {seconds:.1f} s; {details}"
            rows.append(Outcome("chain length", method, f"n = {n}, dt = 0.01 s, 10 s",
                                result, details))
    return rows


def edge_largest_n(quick: bool, budget: float = 120.0) -> list[Outcome]:
    """Grow n until generating and building takes more than `budget` seconds."""
    rows = []
    candidates = (3, 6) if quick else (5, 10, 20, 50, 100, 150, 200)
    for method in METHODS:
        largest, largest_time, over = None, None, None
        for n in candidates:
            seconds, _, _ = timed_chain_run(n, method, budget)
            if seconds is None or seconds > budget:
                over = n
                break
            largest, largest_time = n, seconds
        details = (f"largest n tried within {budget:.0f} s: n = {largest} "
                   f"({largest_time:.1f} s)" if largest else "none of the sizes tried")
        details += (f"; n = {over} did not finish within {budget:.0f} s" if over
                    else f"; every size tried ({', '.join(map(str, candidates))}) fits")
        rows.append(Outcome("largest n in two minutes", method,
                            "chain of n unit links, one spring per joint, sizes "
                            + ", ".join(map(str, candidates)), "works", details))
    return rows


def edge_long_run(quick: bool) -> list[Outcome]:
    """1e6 steps: does the energy error of es K = 3 and vi stay bounded, or drift?"""
    scene = load_reference_scene("three_link_mono")
    steps = 100_000 if quick else 1_000_000
    rows = []
    for method, quadrature in (("es", 3), ("es", 1), ("vi", 3), ("midpoint", 3)):
        solver = build_solver(scene, method, quadrature, sensitivities=False)
        result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                                 n_steps=steps, every=100)
        error = np.abs(result.energy_error)
        tenth = max(len(error) // 10, 1)
        first, last = error[:tenth].max(), error[-tenth:].max()
        if last <= 2 * first:
            verdict = "bounded"
        elif last <= 1e-10 * abs(result.energy[0]):
            verdict = (f"grows by {last / first:.1f}x at round-off level (a random walk of "
                       "rounding errors, about sqrt(steps))")
        else:
            verdict = f"grows by {last / first:.1f}x"
        used = quadrature_used(scene, method, quadrature)
        label = method + ("" if used is None else f" K = {used}")
        rows.append(Outcome("long run", label, f"three_link_mono, {steps:.0e} steps of 0.01 s",
                            "works",
                            f"max abs energy error {first:.2e} J in the first tenth, {last:.2e} J "
                            f"in the last: {verdict}; constraint "
                            f"{result.constraint_error.max():.1e}"
                            f"; {result.wall_time:.1f} s"))
    return rows


def edge_com_at_joint(quick: bool) -> list[Outcome]:
    base = chain(3)
    links = (dataclasses.replace(base.links[0], com=0.0),) + base.links[1:]
    scene = dataclasses.replace(base, links=links)
    rows = []
    for method in METHODS:
        try:
            result, details = run(scene, method, dt=0.01, t_end=10.0)
        except UnsupportedSceneError as error:
            result, details = "refused", str(error)
        rows.append(Outcome("COM at the proximal joint", method, "link 1: com = com_normal = 0",
                            result, details))
    return rows


def edge_collapsing_spring(quick: bool) -> list[Outcome]:
    scene = load_reference_scene("collapsing_spring")
    return [Outcome("spring segment reaching zero length", method,
                    "collapsing_spring: the link spins through the zero-length angle",
                    *run(scene, method, dt=0.01, t_end=5.0)) for method in METHODS]


def edge_newton_failure(quick: bool) -> list[Outcome]:
    scene = load_reference_scene("three_link_mono")
    rows = []
    for method in METHODS:
        result, details = run(scene, method, dt=0.01, t_end=1.0,
                              options=NewtonOptions(max_iterations=1))
        rows.append(Outcome("Newton not converging", method,
                            "three_link_mono, max_iterations = 1", result, details))
    return rows


EDGES = (edge_large_steps, edge_stiff_springs, edge_adaptive_steps, edge_mass_ratios,
         edge_hard_newton,
         edge_zero_inertia,
         edge_chain_length, edge_largest_n, edge_long_run, edge_com_at_joint,
         edge_collapsing_spring, edge_newton_failure)


def study(quick: bool = False, note=print) -> list[Outcome]:
    rows = []
    for edge in EDGES:
        started = time.perf_counter()
        found = edge(quick)
        note(f"{edge.__name__}: {len(found)} rows in {time.perf_counter() - started:.0f} s")
        rows.extend(found)
    return rows


def markdown(rows: list[Outcome], quick: bool) -> str:
    lines = [
        "# The extremes",
        "",
        "Written by `python -m chaingen.studies.extremes`" + (" --quick" if quick else "")
        + f" on {platform.machine()} ({platform.processor() or 'unknown cpu'}), Python "
        f"{platform.python_version()}. Every figure comes from that run. Unless stated, es uses "
        "K = 3 and Newton the default options (at most 20 iterations).",
        "",
        "| edge | method | setting | result | what happened |",
        "|---|---|---|---|---|",
    ]
    for row in rows:
        details = row.details.replace("|", "\\|")
        lines.append(f"| {row.edge} | {row.method} | {row.setting} | {row.result} | {details} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m chaingen.studies.extremes",
                                     description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("docs") / "extremes.md",
                        help="the document to write (default: docs/extremes.md, from the "
                             "checkout's root)")
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args(argv)
    rows = study(args.quick)
    write_text(args.out, markdown(rows, args.quick))
    print(f"wrote {args.out} ({len(rows)} rows)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
