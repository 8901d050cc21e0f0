"""A C driver of a generated package's entry points, and what each call must return.

The driver (DRIVER, compiled with the package's sources) reads cases from stdin, one a line,
calls every entry point with the case's numbers and prints the statuses, one line a case. The
numbers may be hostile: NaN, Inf, zero or negative dt, parameters the scene format refuses,
step counts up to LONG_MAX. `expected` says, from the same numbers, what each status must be,
so a test compares the two (test_c_guards.py, and test_c_fuzz.py under the sanitizers).

A line: dt t0 n_steps every hold stop poison phi[N] u[NU] p[NP]
- stop 1: simulate and simulate_controlled with control->stop set before the first step (the
  arguments are checked, no step is taken: any n_steps is safe); 0: they run (n_steps small);
- poison: added to x[0] of the state given to outputs, step and simulate.
The first line holds the scene's own parameters p[NP]. The state x given to outputs, step and
simulate is initial_state's of phi and p; where that is refused, of phi and the scene's own p
(so a posture whose spring segment collapses at p only reaches step and simulate), and where
that is refused too, of zero angles.

Output per case: the statuses of initial_state outputs holding_torques residual
residual_jacobian step step_sensitivities, then sample_count's result, then the statuses of
simulate (u given), simulate (u NULL) and simulate_controlled, then two checks, 1 or 0: the
NULL-u run's samples are those of zero torques, and simulate_controlled's torques rows are one
per sampled step, row j the input of step j*every; then the status of control_torques.
"""
from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from chaingen.runtime import contract
from chaingen.runtime.contract import STATUS_CODES, lower_bound

STRICT = list(contract.STRICT_FLAGS)
LONG_MAX = 2 ** 63 - 1
SIZE_MAX = 2 ** 64 - 1
OK = STATUS_CODES["OK"]
BAD_ARGUMENT = STATUS_CODES["BAD_ARGUMENT"]
BAD_PARAMETER = STATUS_CODES["BAD_PARAMETER"]
SEGMENT_COLLAPSED = STATUS_CODES["SEGMENT_COLLAPSED"]
INTERRUPTED = STATUS_CODES["INTERRUPTED"]
KNOWN = set(STATUS_CODES.values())
#: Columns of the driver's output line.
COLUMNS = ("initial_state", "outputs", "holding_torques", "residual", "residual_jacobian",
           "step", "step_sensitivities", "sample_count", "simulate", "simulate_null_u",
           "simulate_controlled", "null_u_is_zero_u", "torques_by_sample", "control_torques")
UNAVAILABLE = STATUS_CODES["UNAVAILABLE"]

DRIVER = r"""
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "PFX.h"

#define N PFXU_N_JOINTS
#define NX PFXU_NX
#define NZ PFXU_NZ
#define NU PFXU_NU
#define NP PFXU_NP
#define NSAMPLE PFXU_NSAMPLE
#define NS (2 * N)

static PFX_workspace workspace;

/* The controller of simulate_controlled: u[0] the step it is called at, the others the case's. */
static int controller(long step, double t, const double *phi, const double *omega, double *u,
                      void *context)
{
    const double *given = (const double *)context;
    int i;
    (void)t;
    (void)phi;
    (void)omega;
    for (i = 0; i < NU; ++i) {
        u[i] = i == 0 ? (double)step : given[i];
    }
    return 0;
}

static double number(void)
{
    char text[64];
    if (scanf("%63s", text) != 1) {
        exit(0);
    }
    return strtod(text, NULL);
}

static long integer(void)
{
    char text[64];
    if (scanf("%63s", text) != 1) {
        exit(0);
    }
    return strtol(text, NULL, 10);
}

static void *rows(long count, size_t row)
{
    return calloc(count > 0 ? (size_t)count : 1, row);
}

int main(void)
{
    double defaults[NP], p[NP], phi[N], zeros[N], u[NU], x[NX], x1[NX], z[NZ], residual[NZ];
    static double jacobian[NZ * NZ], ds_ds[NS * NS], ds_du[NS * NU], ds_dp[NS * NP];
    double out_phi[N], out_omega[N], tau[N], applied[NU + 1], flows[2], energy, error;
    int i;
    memset(zeros, 0, sizeof zeros);
    memset(z, 0, sizeof z);
    for (i = 0; i < NP; ++i) {
        defaults[i] = number();
    }
    for (;;) {
        double dt = number(), t0 = number();
        long n_steps = integer(), every = integer(), hold = integer(), stop = integer();
        double poison = number();
        int status[11], same = 1, recorded = 1, iterations;
        long count, controlled_rows;
        PFX_control control;
        PFX_stats stats;
        for (i = 0; i < N; ++i) {
            phi[i] = number();
        }
        for (i = 0; i < NU; ++i) {
            u[i] = number();
        }
        for (i = 0; i < NP; ++i) {
            p[i] = number();
        }
        PFX_workspace_init(&workspace);
        status[0] = PFX_initial_state(phi, zeros, p, NP, x, &workspace);
        if (status[0] != PFXU_OK && PFX_initial_state(phi, zeros, defaults, NP, x, &workspace)) {
            PFX_initial_state(zeros, zeros, defaults, NP, x, &workspace);
        }
        x[0] += poison;
        status[1] = PFX_outputs(x, p, NP, out_phi, out_omega, &energy, &error, &workspace);
        status[2] = PFX_holding_torques(phi, p, NP, tau, &workspace);
        status[3] = PFX_residual(z, x, u, NU, p, NP, dt, residual, &workspace);
        status[4] = PFX_residual_jacobian(z, x, u, NU, p, NP, dt, residual, jacobian, &workspace);
        status[5] = PFX_step(x, u, NU, p, NP, dt, x1, flows, NULL, &workspace, &iterations);
        status[6] = PFX_step_sensitivities(x, u, NU, p, NP, dt, x1, ds_ds, ds_du, ds_dp, NULL,
                                          &workspace, &iterations);
        status[10] = PFX_control_torques(x, u, NU, p, NP, dt, applied, x1, NULL, &workspace,
                                         &iterations);
        count = PFX_sample_count(n_steps, every);
        controlled_rows = n_steps > 0 && every > 0 ? (n_steps - 1) / every + 1 : 0;
        memset(&control, 0, sizeof control);
        control.stop = (int)stop;
        if (stop) {
            /* No step is taken: one row, and the inputs of none. */
            double *samples = rows(1, sizeof(double) * NSAMPLE);
            double *torques = rows(1, sizeof(double) * NU);
            status[7] = PFX_simulate_observed(x, t0, dt, n_steps, every, u, NU, p, NP, NULL,
                                              &workspace,
                                              samples, x1, &stats, NULL, NULL, 1, &control);
            status[8] = PFX_simulate_observed(x, t0, dt, n_steps, every, NULL, NU, p, NP, NULL,
                                              &workspace, samples, x1, &stats, NULL, NULL, 1,
                                              &control);
            status[9] = PFX_simulate_controlled(x, t0, dt, n_steps, every, controller, u, hold,
                                                p, NP, NULL, &workspace, samples, torques, x1,
                                                &stats, &control);
            free(samples);
            free(torques);
        } else {
            /* Buffers of exactly the size the header gives (the sanitizers see overruns). */
            double *inputs = rows(n_steps, sizeof(double) * NU);
            double *no_inputs = rows(n_steps, sizeof(double) * NU);
            double *samples = rows(count, sizeof(double) * NSAMPLE);
            double *null_samples = rows(count, sizeof(double) * NSAMPLE);
            double *zero_samples = rows(count, sizeof(double) * NSAMPLE);
            double *torques = rows(controlled_rows, sizeof(double) * NU);
            long k, j, done;
            for (k = 0; k < n_steps; ++k) {
                memcpy(inputs + k * NU, u, sizeof u);
            }
            status[7] = PFX_simulate(x, t0, dt, n_steps, every, inputs, NU, p, NP, NULL, &workspace,
                                     samples, x1, &stats);
            memset(&stats, 0, sizeof stats);
            status[8] = PFX_simulate(x, t0, dt, n_steps, every, NULL, NU, p, NP, NULL, &workspace,
                                     null_samples, x1, &stats);
            done = stats.steps;
            memset(&stats, 0, sizeof stats);
            same = PFX_simulate(x, t0, dt, n_steps, every, no_inputs, NU, p, NP, NULL, &workspace,
                                zero_samples, x1, &stats) == status[8] && stats.steps == done
                   && (count <= 0 || !memcmp(null_samples, zero_samples, sizeof(double)
                                             * NSAMPLE * (size_t)(done / every + 1)));
            memset(&stats, 0, sizeof stats);
            status[9] = PFX_simulate_controlled(x, t0, dt, n_steps, every, controller, u, hold,
                                                p, NP, NULL, &workspace, samples, torques, x1,
                                                &stats, NULL);
            for (j = 0; status[9] != PFXU_BAD_ARGUMENT && j * every < stats.steps; ++j) {
                long s = j * every;
                recorded &= torques[j * NU] == (double)(s - s % hold);
            }
            free(inputs);
            free(no_inputs);
            free(samples);
            free(null_samples);
            free(zero_samples);
            free(torques);
        }
        printf("%d %d %d %d %d %d %d %ld %d %d %d %d %d %d\n", status[0], status[1], status[2],
               status[3], status[4], status[5], status[6], count, status[7], status[8],
               status[9], same, recorded, status[10]);
        fflush(stdout);
    }
}
"""


@dataclass(frozen=True)
class Package:
    """A generated package on disk (its prefix, sizes and parameters) and its driver."""

    directory: Path
    manifest: dict
    driver: Path

    @property
    def prefix(self) -> str:
        return self.manifest["prefix"]

    @property
    def defaults(self) -> list[float]:
        return [entry["value"] for entry in self.manifest["parameters"]]

    @property
    def paths(self) -> list[str]:
        return [entry["path"] for entry in self.manifest["parameters"]]


def driver_source(prefix: str) -> str:
    return DRIVER.replace("PFXU_", prefix.upper() + "_").replace("PFX", prefix)


def build_driver(directory: Path, flags: list[str], cc: str = "gcc") -> Package:
    """Compile the driver with the package in `directory` (sources from its manifest)."""
    manifest = json.loads((directory / "chaingen.json").read_text())
    source = directory / "driver.c"
    source.write_text(driver_source(manifest["prefix"]))
    binary = directory / "driver"
    sources = [str(directory / name) for name in manifest["sources"]]
    result = subprocess.run([cc, *STRICT, *flags, f"-I{directory}", str(source), *sources,
                             "-lm", "-o", str(binary)], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    return Package(directory, manifest, binary)


@dataclass(frozen=True)
class Case:
    dt: float
    t0: float
    n_steps: int
    every: int
    hold: int
    stop: bool
    poison: float
    phi: tuple
    u: tuple
    p: tuple
    #: The case's author says: a spring segment has zero length at phi and p (the scene reader
    #: refuses them), so every entry point that takes the posture or its state refuses it.
    collapsed: bool = False

    def line(self) -> str:
        values = [self.dt, self.t0, self.n_steps, self.every, self.hold, int(self.stop),
                  self.poison, *self.phi, *self.u, *self.p]
        return " ".join(repr(float(v)) if isinstance(v, float) else str(v) for v in values)


def run_driver(package: Package, cases: list[Case], timeout: float = 600) \
        -> tuple[list[dict], subprocess.CompletedProcess]:
    """The driver's statuses of each case (a dict by COLUMNS), and the finished process."""
    text = " ".join(map(repr, map(float, package.defaults))) + "\n"
    text += "\n".join(case.line() for case in cases) + "\n"
    result = subprocess.run([str(package.driver)], input=text, capture_output=True, text=True,
                            timeout=timeout)
    lines = result.stdout.splitlines()
    return [dict(zip(COLUMNS, map(int, line.split()))) for line in lines], result


def sample_count(n_steps: int, every: int, nsample: int) -> int:
    """The header's sample_count."""
    if n_steps < 0 or every < 1:
        return 0
    whole = n_steps // every
    if whole >= LONG_MAX // nsample or whole >= SIZE_MAX // (8 * nsample):
        return -1
    return whole + 1


def parameters_ok(paths: list[str], values) -> bool:
    """Whether the scene format admits every value (contract.NUMBER_BOUNDS)."""
    for path, value in zip(paths, values):
        bound = lower_bound(path)
        if not math.isfinite(value) or (bound is not None and not bound.admits(value)):
            return False
    return True


def expected(package: Package, case: Case) -> dict:
    """What each column must be: an int, or a set of allowed ints."""
    finite = math.isfinite
    p_ok = parameters_ok(package.paths, case.p)
    phi_ok = all(map(finite, case.phi))
    x_ok = finite(case.poison)     # the state is finite otherwise (initial_state or fallback)
    dt_ok = finite(case.dt) and case.dt > 0
    inputs_ok = all(map(finite, case.u))
    count = sample_count(case.n_steps, case.every, package.manifest["nsample"])

    def guarded(*checks) -> int | set:
        for good, status in checks:
            if not good:
                return status
        return OK

    # A dt so small that a stage of the composed step, or a split half of it, rounds to zero
    # is refused there (BAD_ARGUMENT) when the step is taken.
    underflows = {BAD_ARGUMENT} if dt_ok and case.dt < 1e-300 else set()
    # A step's entry points refuse a NaN or Inf in x0 or u before any work (BAD_ARGUMENT),
    # after dt and before the parameters.
    stepped = guarded((dt_ok and x_ok and inputs_ok, BAD_ARGUMENT), (p_ok, BAD_PARAMETER))
    collapsed = case.collapsed and case.poison == 0   # a poisoned state is another one
    if stepped == OK and collapsed:
        stepped = SEGMENT_COLLAPSED
    if stepped == OK:
        stepped = KNOWN - {BAD_ARGUMENT, BAD_PARAMETER} | underflows
    arguments = (dt_ok and finite(case.t0) and case.n_steps >= 0 and case.every >= 1
                 and count >= 0)
    run = guarded((arguments, BAD_ARGUMENT), (p_ok, BAD_PARAMETER), (x_ok, BAD_ARGUMENT))
    if run == OK and collapsed:
        run = SEGMENT_COLLAPSED     # checked at the start, before a stop is looked at
    if run == OK:
        run = INTERRUPTED if case.stop else KNOWN - {BAD_ARGUMENT, BAD_PARAMETER} | underflows
    controlled = BAD_ARGUMENT if case.hold < 1 else run
    # control_torques: UNAVAILABLE without a control law; a state or an input with a NaN or
    # Inf is a bad argument (as for step); a step it would split is NOT_CONVERGED.
    law = UNAVAILABLE
    if package.manifest.get("control"):
        law = guarded((dt_ok and x_ok and inputs_ok, BAD_ARGUMENT), (p_ok, BAD_PARAMETER))
        if law == OK and collapsed:
            law = SEGMENT_COLLAPSED
        if law == OK:
            law = KNOWN - {BAD_ARGUMENT, BAD_PARAMETER, UNAVAILABLE}
    posture = guarded((phi_ok, BAD_ARGUMENT), (p_ok, BAD_PARAMETER),
                      (not case.collapsed, SEGMENT_COLLAPSED))
    return {
        "initial_state": posture,
        # outputs needs the segments' lengths only: defined at zero length, not refused.
        "outputs": guarded((x_ok, BAD_ARGUMENT), (p_ok, BAD_PARAMETER)),
        "holding_torques": posture,
        "residual": guarded((dt_ok, BAD_ARGUMENT), (p_ok, BAD_PARAMETER)),
        "residual_jacobian": guarded((dt_ok, BAD_ARGUMENT), (p_ok, BAD_PARAMETER)),
        "step": stepped, "step_sensitivities": stepped, "sample_count": count,
        "simulate": run, "simulate_null_u": run, "simulate_controlled": controlled,
        "null_u_is_zero_u": 1, "torques_by_sample": 1, "control_torques": law,
    }


def mismatches(package: Package, cases: list[Case], results: list[dict]) -> list[str]:
    """Each column of each case whose status is not the expected one."""
    problems = []
    if len(results) != len(cases):
        problems.append(f"{len(results)} result lines for {len(cases)} cases")
    for case, result in zip(cases, results):
        for column, want in expected(package, case).items():
            got = result[column]
            if not (got in want if isinstance(want, set) else got == want):
                problems.append(f"{column}: {got}, expected {want} for {case}")
    return problems


def generate(directory: Path, scene: str, method: str, order: int, parameters) -> Path:
    """Generate a package of a reference scene (or a scene file, a path ending in .toml) with
    run-time parameters into `directory`, in a child process (SymPy and CasADi stay out of the
    test process)."""
    program = ("import sys\n"
               "from chaingen import load_reference_scene, load_scene\n"
               "from chaingen.generate.package import generate_package, write_package\n"
               "scene = (load_scene(sys.argv[1]) if sys.argv[1].endswith('.toml')\n"
               "         else load_reference_scene(sys.argv[1]))\n"
               "package = generate_package(scene, sys.argv[2], 3, parameters=sys.argv[5:],\n"
               "                           order=int(sys.argv[3]))\n"
               "write_package(package, sys.argv[4])\n")
    result = subprocess.run([sys.executable, "-c", program, scene, method, str(order),
                             str(directory), *parameters], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    return directory
