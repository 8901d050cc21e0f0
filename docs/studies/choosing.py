"""The measurements of docs/choosing.md: per scheme, order (and es order 6's K) and adaptive
tolerance, the cost of a step, Newton iterations, the trajectory error against DOP853 and the
energy error, on three_link_mono. Run from the checkout: python docs/studies/choosing.py

Each run is timed five times (the C loop's wall time, the least of the five); the machine
is shared, so the times are noisy and only their ratios within one run mean much.
"""
from __future__ import annotations

import numpy as np

import chaingen
from chaingen.reference.scipy_peer import reference_solution

SCENE = "three_link_mono"
T_END = 10.0                 # s of each run: energy errors are over it
ERROR_TIMES = (1.0, 3.0)     # s: trajectory errors against DOP853 there
REPEATS = 5
FIXED = [("es", 3, 2), ("es", 3, 4), ("es", 2, 6), ("es", 3, 6), ("es", 5, 6),
         ("vi", None, 2), ("vi", None, 4), ("vi", None, 6),
         ("midpoint", None, 2), ("midpoint", None, 4), ("midpoint", None, 6)]
DTS = (0.1, 0.05, 0.01)
TOLERANCES = (1e-6, 1e-8, 1e-10)
SAMPLE_INTERVAL = 0.1        # s: the adaptive runs' dt (a step is at most half of it)


def wrapped(difference):
    return (np.asarray(difference) + np.pi) % (2 * np.pi) - np.pi


def timed(solver, scene, dt, options=None):
    """(the run, its least wall time in s) over T_END with samples every dt."""
    runs = [solver.simulate(scene.initial_angles, scene.initial_velocities, dt=dt,
                            n_steps=round(T_END / dt), options=options)
            for _ in range(REPEATS)]
    return runs[-1], min(run.wall_time for run in runs)


def errors(run, scene, dt, references):
    """Largest angle error (rad) at each of ERROR_TIMES, and max |H - H_0| (J) over the run."""
    found = []
    for t, (angles, _) in references.items():
        row = run.samples[round(t / dt)]
        assert abs(row[0] - t) < 1e-9
        found.append(np.abs(wrapped(row[1:1 + scene.n] - angles)).max())
    energy = run.column("energy")
    return found, np.abs(energy - energy[0]).max()


def main():
    scene = chaingen.load_reference_scene(SCENE)
    references = {t: reference_solution(scene, t) for t in ERROR_TIMES}
    print("| scheme | order | dt [s] | per step [us] | Newton it. a step | error at 1 s [rad] | "
          "error at 3 s [rad] | max abs H - H_0 [J] |")
    print("|---|---|---|---|---|---|---|---|")
    for method, quadrature, order in FIXED:
        solver = chaingen.build_solver(scene, method, quadrature, order=order,
                                       sensitivities=False)
        label = method + (f" K={quadrature}" if quadrature else "")
        for dt in DTS:
            run, wall = timed(solver, scene, dt)
            (at_1, at_3), energy = errors(run, scene, dt, references)
            print(f"| {label} | {order} | {dt} | {wall / run.n_steps * 1e6:.2f} | "
                  f"{run.newton_iterations / run.n_steps:.2f} | {at_1:.1e} | {at_3:.1e} | "
                  f"{energy:.1e} |", flush=True)
    print(f"\nAdaptive es K=3, samples every {SAMPLE_INTERVAL} s, rtol = atol:\n")
    print("| order | rtol = atol | CPU for 10 s [ms] | steps kept (refused) | shortest, longest "
          "[s] | error at 1 s [rad] | error at 3 s [rad] | max abs H - H_0 [J] |")
    print("|---|---|---|---|---|---|---|---|")
    for order in (2, 4):
        solver = chaingen.build_solver(scene, "es", 3, order=order, sensitivities=False)
        for tolerance in TOLERANCES:
            run, wall = timed(solver, scene, SAMPLE_INTERVAL,
                              {"rtol": tolerance, "atol": tolerance})
            (at_1, at_3), energy = errors(run, scene, SAMPLE_INTERVAL, references)
            print(f"| {order} | {tolerance:g} | {wall * 1e3:.2f} | {run.accepted_steps} "
                  f"({run.rejected_steps}) | {run.smallest_dt:.1e}, {run.largest_dt:.1e} | "
                  f"{at_1:.1e} | {at_3:.1e} | {energy:.1e} |", flush=True)


if __name__ == "__main__":
    main()
