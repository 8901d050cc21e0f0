"""Compiled peers of the benchmark: integrators whose whole loop runs in compiled code.

The SciPy peer (scipy_peer) pays Python for every step; a user who wants the joint-space ODE
of model.md 6 integrated fast would pick one of these instead. All integrate the same ODE,

    y = (phi, w),    ydot = (w, M(phi)^-1 f(phi, w)),

from the scene's initial state, and return the SciPy peer's record (ScipyRun).

- "numbalsoda-LSODA", "numbalsoda-DOP853": numbalsoda's LSODA (Adams/BDF switching, its
  Jacobian by finite differences of the right-hand side) and Hairer's DOP853, both compiled.
  Their right-hand side is the SciPy peer's own compiled `peer_rhs` (CompiledODE.library_path),
  called from a numba `cfunc` of numbalsoda's signature (t, u, du, p) through a ctypes function
  pointer: no Python in the loop. numbalsoda and numba are the `peers` extra.
- "CVODES-BDF", "CVODES-Adams": SUNDIALS CVODES through CasADi's `integrator` ("cvodes"
  plugin), variable-order BDF with Newton's method (dense Jacobian from CasADi's algorithmic
  differentiation, CSparse) or Adams-Moulton with functional iteration (no Jacobian). The ODE is
  CasADi SX, ydot = (w, solve(M, f)) with M and f from scipy_peer.ode_functions; it and its
  Jacobian are generated as C and built into chaingen's cache (`external_ode`), then loaded
  with `casadi.external`.

  Why compiled C and not the SX virtual machine or CasADi's "jit" option: on three_link_mono
  over 50 s (one call, 5001 samples, median of 5, a shared 2-core machine) BDF at
  rtol = atol = 1e-10 took 55 ms on the SX virtual machine, 26 ms with "jit" (CasADi's shell
  compiler, -O2) and 29 ms with the external library; Adams 34, 20 and 22 ms. "jit" is 5 to 15
  percent faster than the external library, but it compiles again for
  every integrator (0.7 s, at every tolerance) and writes its C source into the working
  directory whatever `jit_name` and `jit_options.directory` say (CasADi 3.8.2); the external
  library is built once per scene content, content-addressed like every chaingen build.
  Adams is faster than BDF at tight tolerances (1e-12: 32 ms against 66 ms; a third of the
  steps), about as fast at 1e-6. Either way CVODES through CasADi costs some 4 us per
  right-hand side evaluation, about ten times what a numbalsoda run costs per evaluation.

Samples. Each run is one call of the integrator with an output grid: the sample times (default
every DEFAULT_SAMPLE_INTERVAL, as the thesis's dt) with t = 0 and t_end added. Interpolating
to the grid is inside the timed region (DOP853's dense output costs about 3 right-hand sides
per step, CVODES's and LSODA's interpolation next to nothing).

Counts reported (0 where the library does not report one):

    method               nfev                         njev             nlu            n_steps
    numbalsoda-LSODA     every call of the RHS (1)    0                0              0
    numbalsoda-DOP853    every call of the RHS (1)    0                0              0
    CVODES-BDF           CVODES nfevals (2)           Jacobian calls   nlinsetups     nsteps
    CVODES-Adams         CVODES nfevals               0                0              nsteps

(1) counted by the cfunc itself, warm-up excluded; LSODA's finite-difference Jacobians
included. (2) without the evaluations of the Jacobian function.

The numbalsoda runs do not stop on a non-finite right-hand side (the library has no way to be
told), so the cfunc records the first one and returns ydot = 0 from then on, which lets the
integrator finish; the run is then reported as failed. DOP853 counts its steps against
MAX_STEPS for the whole run, LSODA and CVODES per output interval.
"""
from __future__ import annotations

import ctypes
import hashlib
import importlib
import time
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

from ..errors import ScipyPeerError
from ..generate.casadi_source import mark_parameters_used
from ..runtime.build import build_shared_library, cache_directory
from ..scene import Scene
from .scipy_peer import CompiledODE, ScipyRun, compile_ode, ode_functions, read_only_array

NUMBALSODA_METHODS = ("numbalsoda-LSODA", "numbalsoda-DOP853")
CVODES_METHODS = ("CVODES-BDF", "CVODES-Adams")
METHODS = NUMBALSODA_METHODS + CVODES_METHODS
#: The pip extra that installs numbalsoda and numba (pyproject.toml).
PEERS_EXTRA = "peers"
#: Default spacing of the samples (s): the thesis's dt.
DEFAULT_SAMPLE_INTERVAL = 0.01
#: Step limit: DOP853's for the whole run, LSODA's and CVODES's per output interval.
MAX_STEPS = 1_000_000

_CVODES_OPTIONS = {
    "CVODES-BDF": {"linear_multistep_method": "bdf", "nonlinear_solver_iteration": "newton"},
    "CVODES-Adams": {"linear_multistep_method": "adams",
                     "nonlinear_solver_iteration": "functional"},
}

# Entries of the cfunc's parameter array p (numbalsoda passes it through to the RHS).
_CALLS, _NOT_FINITE, _NOT_FINITE_AT = 0, 1, 2


def _read_counts(data) -> tuple[int, float | None]:
    """(right-hand side calls, t of the first non-finite one or None) from the cfunc's p."""
    return int(data[_CALLS]), (float(data[_NOT_FINITE_AT]) if data[_NOT_FINITE] else None)


# --------------------------------------------------------------------------------------------
# numbalsoda: our compiled peer_rhs in a numba cfunc
# --------------------------------------------------------------------------------------------

def _numbalsoda():
    """The numbalsoda module, or ScipyPeerError naming the extra that installs it."""
    try:
        return importlib.import_module("numbalsoda")
    except ImportError as error:
        raise ScipyPeerError(f"the numbalsoda peers need numbalsoda and numba, which are not "
                             f"installed ({error.name or error}): pip install -e "
                             f"'.[{PEERS_EXTRA}]'") from None


def numbalsoda_available() -> bool:
    """Whether the numbalsoda methods can run (the `peers` extra is installed)."""
    try:
        _numbalsoda()
    except ScipyPeerError:
        return False
    return True


@dataclass(frozen=True, eq=False)
class NumbaRHS:
    """A numba cfunc around one library's peer_rhs; keeps the objects its address needs
    alive. `address` is what numbalsoda's solvers take."""

    cfunc: object
    library: ctypes.CDLL
    warmed: set            # numbalsoda solver names already compiled by numba for it

    @property
    def address(self) -> int:
        return self.cfunc.address


_NUMBA_RHS: dict[str, NumbaRHS] = {}


def numba_rhs(compiled: CompiledODE) -> NumbaRHS:
    """The cfunc (t, u, du, p) -> du = peer_rhs(u), once per process per library.

    p[0] counts the calls; a call whose ydot is not finite (peer_rhs returns the number of
    such entries) sets p[1] = 1 and p[2] = t, and that call and every later one return
    du = 0, so that the integrator finishes instead of refining its step for ever.
    """
    key = str(compiled.library_path)
    if key in _NUMBA_RHS:
        return _NUMBA_RHS[key]
    numbalsoda = _numbalsoda()
    import numba

    library = ctypes.CDLL(key)     # our own handle: scipy_peer's binds other argtypes
    peer_rhs = library.peer_rhs
    peer_rhs.argtypes = [ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_double)]
    peer_rhs.restype = ctypes.c_int
    size = 2 * compiled.n

    def rhs(t, u, du, p):
        p[_CALLS] += 1.0
        if p[_NOT_FINITE] == 0.0 and peer_rhs(u, du) == 0:
            return
        if p[_NOT_FINITE] == 0.0:
            p[_NOT_FINITE] = 1.0
            p[_NOT_FINITE_AT] = t
        for i in range(size):
            du[i] = 0.0

    cfunc = numba.cfunc(numbalsoda.lsoda_sig)(rhs)
    _NUMBA_RHS[key] = NumbaRHS(cfunc=cfunc, library=library, warmed=set())
    return _NUMBA_RHS[key]


def _numbalsoda_solver(method: str):
    return getattr(_numbalsoda(), method.split("-")[1].lower())


def _numbalsoda_call(solver, rhs: NumbaRHS, y0, grid, rtol, atol):
    """One solver call with the argument types of every call (numba compiles per type
    signature: an omitted default is another signature)."""
    data = np.zeros(3)
    states, success = solver(rhs.address, y0, grid, data, float(rtol), float(atol),
                             int(MAX_STEPS))
    return states, bool(success), data


def _run_numbalsoda(compiled: CompiledODE, method: str, y0, grid, rtol, atol):
    """(states N x 2n, cpu s, wall s, counts) of one timed call; numba's compilation of the
    solver for this signature happens in an untimed warm-up run first."""
    solver = _numbalsoda_solver(method)
    rhs = numba_rhs(compiled)
    if method not in rhs.warmed:
        _numbalsoda_call(solver, rhs, y0, np.array([0.0, 1e-9]), rtol, atol)
        rhs.warmed.add(method)
    cpu_start, wall_start = time.process_time(), time.perf_counter()
    states, success, data = _numbalsoda_call(solver, rhs, y0, grid, rtol, atol)
    wall_time = time.perf_counter() - wall_start
    cpu_time = time.process_time() - cpu_start
    calls, not_finite_at = _read_counts(data)
    if not_finite_at is not None:
        raise ScipyPeerError(f"ydot is not finite at t = {not_finite_at!r}")
    if not success:
        raise ScipyPeerError(f"did not reach t_end = {grid[-1]:g} s (more than {MAX_STEPS} "
                             "steps, or a step size too small; numbalsoda gives no reason)")
    return states, cpu_time, wall_time, dict(nfev=calls, njev=0, nlu=0, n_steps=0)


# --------------------------------------------------------------------------------------------
# CVODES through CasADi: the ODE and its Jacobian as a compiled external
# --------------------------------------------------------------------------------------------

_EXTERNAL: dict[tuple[str, str], ca.Function] = {}


def cvodes_sources(compiled: CompiledODE, prefix: str) -> dict[str, str]:
    """{file name: C text}: the ODE in CasADi's DAE scheme (t, x, z, p, u) -> (ode, alg, quad,
    zero), x = y, ode = (w, solve(M, f)), and its Jacobian `jac_<prefix>`, which
    casadi.external finds by that name. Symbols exported by CasADi's own attribute."""
    n = compiled.n
    functions = ode_functions(compiled.ode, prefix)
    y = ca.SX.sym("y", 2 * n)
    mass, forces = functions.mass_force(y)
    empty = ca.SX(0, 1)
    ode = ca.Function(prefix, [ca.SX.sym("t"), y, empty, empty, empty],
                      [ca.vertcat(y[n:], ca.solve(mass, forces)), empty, empty, empty],
                      ca.dyn_in(), ca.dyn_out(), {"cse": True})
    generator = ca.CodeGenerator(f"{prefix}.c", {"prefix": f"{prefix}_", "with_header": False,
                                                 "with_export": True,
                                                 "casadi_int": "long long int"})
    generator.add(ode)
    generator.add(ode.jacobian())
    export = '#define CASADI_SYMBOL_EXPORT __attribute__((visibility("default")))\n'
    return {f"{prefix}.c": export + mark_parameters_used(generator.dump())}


def external_ode(compiled: CompiledODE, directory: Path) -> ca.Function:
    """The CVODES peer's ODE of `compiled`'s scene, built once per process per scene content
    (the library itself once per content, in `directory`)."""
    key = (compiled.code_hash, str(directory))
    if key not in _EXTERNAL:
        digest = hashlib.sha256(f"cvodes {compiled.code_hash}".encode()).hexdigest()
        prefix = f"cvodes_{compiled.ode.scene.c_name}_{digest[:12]}"
        files = cvodes_sources(compiled, prefix)
        path = build_shared_library(prefix, files, list(files), cache=directory).path
        _EXTERNAL[key] = ca.external(prefix, str(path))
    return _EXTERNAL[key]


def _run_cvodes(compiled: CompiledODE, method: str, y0, grid, rtol, atol, directory: Path):
    """(states N x 2n, cpu s, wall s, counts) of one timed CVODES call over `grid`."""
    options = {"abstol": float(atol), "reltol": float(rtol), "max_num_steps": MAX_STEPS,
               **_CVODES_OPTIONS[method]}
    integrator = ca.integrator(f"peer_{method.replace('-', '_')}", "cvodes",
                               external_ode(compiled, directory), 0.0, grid, options)
    cpu_start, wall_start = time.process_time(), time.perf_counter()
    try:
        states = integrator(x0=y0)["xf"]
    except RuntimeError as error:
        reason = [line.strip() for line in str(error).splitlines() if line.strip()]
        raise ScipyPeerError(f"CVODES failed: {reason[-1] if reason else 'no reason'}") \
            from None
    wall_time = time.perf_counter() - wall_start
    cpu_time = time.process_time() - cpu_start
    states = np.asarray(states, dtype=float).T
    if not np.all(np.isfinite(states)):
        raise ScipyPeerError("the state is not finite")
    stats = integrator.stats()
    counts = dict(nfev=int(stats["nfevals"]), njev=int(stats.get("n_call_jacF", 0)),
                  nlu=int(stats["nlinsetups"]), n_steps=int(stats["nsteps"]))
    if method == "CVODES-Adams":
        counts.update(njev=0, nlu=0)
    return states, cpu_time, wall_time, counts


# --------------------------------------------------------------------------------------------
# Runs
# --------------------------------------------------------------------------------------------

def sample_grid(t_end: float, sample_times=None) -> tuple[np.ndarray, np.ndarray]:
    """(grid, where): the integrator's output times (0, the samples, t_end; ascending, no
    repeats) and the index in grid of each sample. Default samples: every
    DEFAULT_SAMPLE_INTERVAL from 0 to t_end, and t_end."""
    if sample_times is None:
        count = max(round(t_end / DEFAULT_SAMPLE_INTERVAL), 1)
        samples = np.linspace(0.0, t_end, count + 1)
    else:
        samples = np.asarray(sample_times, dtype=float).reshape(-1)
        if (not samples.size or not np.all(np.isfinite(samples)) or samples[0] < 0
                or samples[-1] > t_end or np.any(np.diff(samples) < 0)):
            raise ScipyPeerError(f"sample_times: must be non-empty and ascending within "
                                 f"[0, t_end = {t_end}], got {sample_times!r}")
    grid = np.unique(np.concatenate(([0.0], samples, [t_end])))
    return grid, np.searchsorted(grid, samples)


def simulate_compiled(scene: Scene, method: str, rtol: float, atol: float, t_end: float,
                      sample_times=None, *, directory: str | Path | None = None) -> ScipyRun:
    """Integrate `scene` from its initial state to t_end with a compiled peer (METHODS).

    The record is simulate_scipy's: cpu_time (time.process_time) and wall_time cover the one
    integrator call alone (not the builds, numba's compilation, the warm-up or the energies);
    the counts are those of the module docstring (0: not reported); sample_times are the
    requested ones (default: every DEFAULT_SAMPLE_INTERVAL and t_end), energies H at them,
    max_energy_error = max |H(t_k) - H(0)|; final_angles and final_velocities the state at
    t_end. Builds go to `directory`, else chaingen's cache. Raises ScipyPeerError (one line)
    for an unknown method, bad tolerances or times, a missing numbalsoda, or a failed run.
    """
    if method not in METHODS:
        raise ScipyPeerError(f"method {method!r}: not a compiled peer; choose one of "
                             f"{', '.join(METHODS)}")
    for name, value in (("rtol", rtol), ("atol", atol), ("t_end", t_end)):
        if not (value > 0 and np.isfinite(value)):
            raise ScipyPeerError(f"{name}: must be > 0 and finite, got {value!r}")
    grid, where = sample_grid(float(t_end), sample_times)
    if method in NUMBALSODA_METHODS:
        _numbalsoda()     # before any build: a missing extra is named first
    directory = Path(directory) if directory is not None else cache_directory()
    compiled = compile_ode(scene, directory)
    y0 = np.array(scene.initial_angles + scene.initial_velocities, dtype=float)
    try:
        if method in NUMBALSODA_METHODS:
            states, cpu_time, wall_time, counts = _run_numbalsoda(compiled, method, y0, grid,
                                                                  rtol, atol)
        else:
            states, cpu_time, wall_time, counts = _run_cvodes(compiled, method, y0, grid,
                                                              rtol, atol, directory)
    except ScipyPeerError as error:
        raise ScipyPeerError(f"{scene.name}: {method} (rtol={rtol}, atol={atol}): "
                             f"{error}") from None
    n = scene.n
    initial_energy = float(compiled.energies(y0)[0])
    energies = compiled.energies(states[where].T)
    return ScipyRun(
        method=method, rtol=float(rtol), atol=float(atol), t_end=float(t_end),
        cpu_time=cpu_time, wall_time=wall_time, **counts,
        final_angles=read_only_array(states[-1, :n]),
        final_velocities=read_only_array(states[-1, n:]),
        sample_times=read_only_array(grid[where]), energies=read_only_array(energies),
        initial_energy=initial_energy,
        max_energy_error=float(np.abs(energies - initial_energy).max()),
        status=0, message="reached t_end")
