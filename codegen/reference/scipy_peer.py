"""The SciPy peer of the benchmark: `solve_ivp` on the chain's minimal-coordinate ODE.

State y = (phi, w), 2n entries: the relative joint angles, then the joint rates. The ODE is
docs/model.md, section 6, solved for the accelerations,

    phidot = w,    wdot = M(phi)^-1 f(phi, w),    f = tau - Coriolis(phi, w) - grad V(phi),

with tau = -d_i w_i the joint damping (model.md 7) and no input torques. M, the Coriolis terms
and V are derived by SymPy exactly as for the "midpoint" scheme (chaingen.symbolic.joint_model,
chaingen.symbolic.joint_model.coriolis), translated to CasADi SX and compiled to C, so that the
peer's right-hand side costs what compiled code costs and SciPy's own overhead is what is
compared.

M is not inverted symbolically. CasADi's `solve` on SX is affordable for the right-hand side
(on a dense symbolic n x n matrix: 2.6e3 instructions at n = 10, 1.9e4 at n = 20) but its
Jacobian is not (4.8e4 and 7.0e5). The generated code returns M and f, and a small
hand-written C wrapper factors M (symmetric positive definite) by Cholesky and solves. For the
Jacobian, differentiating M a = f at a = M^-1 f gives

    d wdot / dy = M^-1 K,    K = d(f - M a)/dy at fixed a,

so one more generated function returns K (n x 2n) and the wrapper reuses the factor of M.

The wrapper is benchmark code, not part of the shipped package: static work arrays, so its
functions are not reentrant and must not be called from several threads. It is rendered here
rather than from a template because it is a few fixed lines around the CasADi code.
"""
from __future__ import annotations

import ctypes
import dataclasses
import hashlib
import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np
import sympy as sp
from scipy import integrate
from sympy import ImmutableMatrix

from ..errors import ScipyPeerError
from ..generate.casadi_source import casadi_c_source, work_sizes
from ..generate.translation import SympyToCasadi, check_free_symbols
from ..runtime.build import build_shared_library, cache_directory
from ..scene import Scene
from ..symbolic.joint_model import angle_directions, coriolis, joint_space_model
from ..version import VERSION

#: solve_ivp's methods by name; the implicit ones get the compiled Jacobian.
SOLVERS = {"RK23": integrate.RK23, "RK45": integrate.RK45, "DOP853": integrate.DOP853,
           "Radau": integrate.Radau, "BDF": integrate.BDF, "LSODA": integrate.LSODA}
IMPLICIT_METHODS = ("Radau", "BDF", "LSODA")

#: Tolerances of `reference_solution`: rtol at SciPy's floor for DOP853, 100 machine epsilons
#: (a smaller rtol is raised to it with a warning), and atol the same for states of order 1.
REFERENCE_RTOL = 100 * float(np.finfo(float).eps)
REFERENCE_ATOL = REFERENCE_RTOL


class NonFiniteDerivativeError(ScipyPeerError):
    """The compiled right-hand side or Jacobian is not finite at a state (e.g. a spring
    segment of zero length, or overflow)."""

    def __init__(self, what: str, t: float, y):
        super().__init__(f"{what} is not finite at t = {t!r}, y = {np.asarray(y).tolist()}")


# --------------------------------------------------------------------------------------------
# The ODE, symbolically
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class JointSpaceODE:
    """ydot = (w, M(phi)^-1 forces) in SymPy, over the symbols `angles` and `rates`."""

    scene: Scene
    angles: ImmutableMatrix         # phi_1 .. phi_n
    rates: ImmutableMatrix          # w_1 .. w_n
    mass_matrix: ImmutableMatrix    # M(phi), T = 1/2 w^T M w
    forces: ImmutableMatrix         # f = -d w - Coriolis(phi, w) - grad V(phi)
    energy: sp.Expr                 # H = T + V (model.md 3)

    @property
    def state(self) -> ImmutableMatrix:
        return ImmutableMatrix.vstack(self.angles, self.rates)


def joint_space_ode(scene: Scene) -> JointSpaceODE:
    """M, f and H of model.md 6 with tau = joint damping only (model.md 7)."""
    n = scene.n
    angles = ImmutableMatrix(sp.symbols(f"phi1:{n + 1}", real=True))
    rates = ImmutableMatrix(sp.symbols(f"w1:{n + 1}", real=True))
    model = joint_space_model(scene, angle_directions(angles), rates)
    forces = -(coriolis(model, angles) + ImmutableMatrix([model.potential]).jacobian(angles).T)
    if any(link.damping for link in scene.links):
        forces = forces + model.damping_torques(rates)
    return JointSpaceODE(scene=scene, angles=angles, rates=rates,
                         mass_matrix=model.mass_matrix, forces=ImmutableMatrix(forces),
                         energy=model.energy)


@dataclass(frozen=True)
class ODEFunctions:
    """The CasADi Functions of the peer, named with its prefix; y is the (2n,) state."""

    mass_force: ca.Function              # y -> (M dense n x n, f (n,))
    acceleration_jacobian: ca.Function   # (y, a) -> K = d(f - M a)/dy, dense n x 2n
    energy: ca.Function                  # y -> H


def ode_functions(ode: JointSpaceODE, prefix: str) -> ODEFunctions:
    """M and f, K of the module docstring, and H as CasADi Functions of y (SX, with CSE)."""
    n = ode.scene.n
    check_free_symbols("mass_force", list(ode.mass_matrix) + list(ode.forces), ode.state)
    check_free_symbols("energy", [ode.energy], ode.state)
    y, a = ca.SX.sym("y", 2 * n), ca.SX.sym("a", n)
    translate = SympyToCasadi(dict(zip(ode.state, ca.vertsplit(y))))
    mass = ca.densify(ca.vertcat(*[ca.horzcat(*[translate(e) for e in row])
                                   for row in ode.mass_matrix.tolist()]))
    forces = ca.vertcat(*[translate(e) for e in ode.forces])
    options = {"cse": True}
    return ODEFunctions(
        mass_force=ca.Function(f"{prefix}_mass_force", [y], [mass, forces], ["y"],
                               ["M", "f"], options),
        acceleration_jacobian=ca.Function(
            f"{prefix}_acceleration_jacobian", [y, a],
            [ca.densify(ca.jacobian(forces - ca.mtimes(mass, a), y))], ["y", "a"], ["K"],
            options),
        energy=ca.Function(f"{prefix}_energy", [y], [translate(ode.energy)], ["y"], ["H"],
                           options),
    )


# --------------------------------------------------------------------------------------------
# C code and the compiled library
# --------------------------------------------------------------------------------------------

_WRAPPER = """\
/* {banner} */
/* The SciPy peer's right-hand side and Jacobian (codegen/scipy_peer.py).
 * y = (phi_1..phi_{n}, w_1..w_{n}): relative joint angles (rad), joint rates (rad/s).
 * peer_rhs:      ydot = (w, M^-1 f), {ny} entries.
 * peer_jacobian: d ydot / dy, {ny} x {ny}, ROW-major: jac[i * {ny} + j] = d ydot_i / d y_j.
 * Both return the number of entries written that are not finite (0: all finite).
 * Static work arrays: not reentrant, not thread-safe (benchmark code). */
#include <math.h>
#include "{prefix}_model.h"

#define N_JOINTS {n}
#define N_STATE {ny}
#define PEER_API __attribute__((visibility("default")))

PEER_API int peer_rhs(const double *y, double *ydot);
PEER_API int peer_jacobian(const double *y, double *jac);

static const double *arg[{sz_arg}];
static double *res[{sz_res}];
static long long int iw[{sz_iw}];
static double w[{sz_w}];
static double mass[N_JOINTS * N_JOINTS];      /* M, then its Cholesky factor; column-major */
static double acceleration[N_JOINTS];
static double acceleration_jacobian[N_JOINTS * N_STATE];   /* column-major */

/* Lower Cholesky factor L of the SPD matrix m, in place (m = L L^T). M is SPD for any scene
 * with positive masses; a non-positive pivot gives NaN, which the callers report. */
static void cholesky(double *m) {{
  int i, j, k;
  for (j = 0; j < N_JOINTS; ++j) {{
    double pivot = m[j + j * N_JOINTS];
    for (k = 0; k < j; ++k) pivot -= m[j + k * N_JOINTS] * m[j + k * N_JOINTS];
    pivot = sqrt(pivot);
    m[j + j * N_JOINTS] = pivot;
    for (i = j + 1; i < N_JOINTS; ++i) {{
      double s = m[i + j * N_JOINTS];
      for (k = 0; k < j; ++k) s -= m[i + k * N_JOINTS] * m[j + k * N_JOINTS];
      m[i + j * N_JOINTS] = s / pivot;
    }}
  }}
}}

/* b := (L L^T)^-1 b. */
static void cholesky_solve(const double *l, double *b) {{
  int i, k;
  for (i = 0; i < N_JOINTS; ++i) {{
    double s = b[i];
    for (k = 0; k < i; ++k) s -= l[i + k * N_JOINTS] * b[k];
    b[i] = s / l[i + i * N_JOINTS];
  }}
  for (i = N_JOINTS - 1; i >= 0; --i) {{
    double s = b[i];
    for (k = i + 1; k < N_JOINTS; ++k) s -= l[k + i * N_JOINTS] * b[k];
    b[i] = s / l[i + i * N_JOINTS];
  }}
}}

static int count_not_finite(const double *x, int size) {{
  int i, count = 0;
  for (i = 0; i < size; ++i) count += !isfinite(x[i]);
  return count;
}}

/* M(phi) into `mass` (factored) and f(phi, w) into `force`. */
static void factored_mass_and_force(const double *y, double *force) {{
  arg[0] = y;
  res[0] = mass;
  res[1] = force;
  {prefix}_mass_force(arg, res, iw, w, 0);
  cholesky(mass);
}}

int peer_rhs(const double *y, double *ydot) {{
  int i;
  for (i = 0; i < N_JOINTS; ++i) ydot[i] = y[N_JOINTS + i];
  factored_mass_and_force(y, ydot + N_JOINTS);
  cholesky_solve(mass, ydot + N_JOINTS);
  return count_not_finite(ydot, N_STATE);
}}

int peer_jacobian(const double *y, double *jac) {{
  int i, j;
  factored_mass_and_force(y, acceleration);
  cholesky_solve(mass, acceleration);
  arg[0] = y;
  arg[1] = acceleration;
  res[0] = acceleration_jacobian;
  {prefix}_acceleration_jacobian(arg, res, iw, w, 0);
  for (j = 0; j < N_STATE; ++j) cholesky_solve(mass, acceleration_jacobian + j * N_JOINTS);
  for (i = 0; i < N_STATE * N_STATE; ++i) jac[i] = 0.0;
  for (i = 0; i < N_JOINTS; ++i) {{
    jac[i * N_STATE + N_JOINTS + i] = 1.0;
    for (j = 0; j < N_STATE; ++j)
      jac[(N_JOINTS + i) * N_STATE + j] = acceleration_jacobian[i + j * N_JOINTS];
  }}
  return count_not_finite(jac, N_STATE * N_STATE);
}}
"""


def scene_code_hash(scene: Scene) -> str:
    """sha256 of what the peer's code depends on: the scene without its initial state and
    simulation defaults, and the tool versions."""
    code_relevant = dataclasses.asdict(scene)
    for key in ("initial_angles", "initial_velocities", "simulation"):
        code_relevant.pop(key)
    payload = {"scene": code_relevant, "peer": "scipy", "chaingen": VERSION,
               "sympy": sp.__version__, "casadi": ca.__version__}
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()


def render_peer_sources(functions: ODEFunctions, prefix: str, n: int,
                        digest: str) -> dict[str, str]:
    """{file name: text} of the peer's C code: CasADi's model and the wrapper."""
    generated = (functions.mass_force, functions.acceleration_jacobian)
    source, header = casadi_c_source(generated, prefix)
    sizes = work_sizes(generated)
    banner = (f"Generated by chaingen {VERSION} (chaingen.reference.scipy_peer). Do not edit. "
              f"chaingen_input_hash={digest}")
    wrapper = _WRAPPER.format(banner=banner, prefix=prefix, n=n, ny=2 * n,
                              sz_arg=max(sizes.arg, 1), sz_res=max(sizes.res, 1),
                              sz_iw=max(sizes.iw, 1), sz_w=max(sizes.w, 1))
    return {f"{prefix}_model.c": f"/* {banner} */\n{source}",
            f"{prefix}_model.h": header, f"{prefix}_peer.c": wrapper}


@dataclass(frozen=True, eq=False)
class CompiledODE:
    """The compiled peer of one scene's content (`ode.scene` is the first scene compiled with
    it: its initial state and simulation defaults need not be those of later ones).

    fun(t, y) -> ydot (2n,) and jac(t, y) -> (2n, 2n) take any float64 state y (t is unused:
    the chain is autonomous) and return a fresh array on each call, as solve_ivp may keep
    references to what they return.
    """

    ode: JointSpaceODE
    code_hash: str
    library_path: Path
    fun: Callable[[float, np.ndarray], np.ndarray]
    jac: Callable[[float, np.ndarray], np.ndarray]
    energy_function: ca.Function

    @property
    def n(self) -> int:
        return self.ode.scene.n

    def energies(self, states) -> np.ndarray:
        """H at each column of `states` (2n x N), by CasADi's own evaluation (not timed)."""
        states = np.asarray(states, dtype=float).reshape(2 * self.n, -1)
        mapped = self.energy_function.map(states.shape[1])
        return np.asarray(mapped(states), dtype=float).reshape(-1)


def _bind(library: ctypes.CDLL, n: int) -> tuple[Callable, Callable]:
    """fun and jac over the library's peer_rhs and peer_jacobian.

    The state is copied into a buffer whose address is bound once, and the result out of one:
    cheaper from Python than asking numpy for each call's array addresses (`ndarray.ctypes`)
    and safe for any layout of y. The copy of the output is what solve_ivp may keep.
    A result that is not finite raises NonFiniteDerivativeError: solve_ivp's step-size control
    would turn it into a NaN step size and loop for ever (SciPy 1.17, RK methods).
    """
    ny = 2 * n
    state = np.empty(ny)
    derivative = np.empty(ny)
    jacobian = np.empty((ny, ny))
    state_address = ctypes.c_void_p(state.ctypes.data)
    rhs, jac_c = library.peer_rhs, library.peer_jacobian
    rhs.restype = jac_c.restype = ctypes.c_int
    rhs_args = (state_address, ctypes.c_void_p(derivative.ctypes.data))
    jac_args = (state_address, ctypes.c_void_p(jacobian.ctypes.data))

    def fun(t, y):
        state[:] = y
        if rhs(*rhs_args):
            raise NonFiniteDerivativeError("ydot", t, y)
        return derivative.copy()

    def jac(t, y):
        state[:] = y
        if jac_c(*jac_args):
            raise NonFiniteDerivativeError("d ydot / dy", t, y)
        return jacobian.copy()

    return fun, jac


_COMPILED: dict[tuple[str, str], CompiledODE] = {}


def compile_ode(scene: Scene, directory: str | Path | None = None) -> CompiledODE:
    """Derive, generate, build and load the peer of `scene`, once per process per scene content.

    The library goes to `directory`, else to chaingen's build cache (chaingen.runtime.build:
    content-addressed file names, an existing build is reused).
    """
    directory = Path(directory) if directory is not None else cache_directory()
    digest = scene_code_hash(scene)
    key = (digest, str(directory))
    if key in _COMPILED:
        return _COMPILED[key]
    prefix = f"peer_{scene.c_name}_{digest[:12]}"
    ode = joint_space_ode(scene)
    functions = ode_functions(ode, prefix)
    files = render_peer_sources(functions, prefix, scene.n, digest)
    path = build_shared_library(prefix, files, [f"{prefix}_model.c", f"{prefix}_peer.c"],
                                cache=directory).path
    fun, jac = _bind(ctypes.CDLL(str(path)), scene.n)
    compiled = CompiledODE(ode=ode, code_hash=digest, library_path=path, fun=fun, jac=jac,
                           energy_function=functions.energy)
    _COMPILED[key] = compiled
    return compiled


# --------------------------------------------------------------------------------------------
# Runs
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class ScipyRun:
    """One solve_ivp run of a scene from its initial state; arrays are read-only.

    cpu_time (time.process_time) and wall_time (time.perf_counter) cover the solve_ivp call
    alone: not the build, not the energies. nfev, njev, nlu are solve_ivp's counts (with
    sample_times, DOP853's nfev includes the extra evaluations of its interpolant). n_steps
    is the number of accepted steps, counted by the solver itself (a subclass of the method's
    class whose step counts successful `_step_impl` calls), so it is the same with or without
    sample_times; without them it equals len(sol.t) - 1.

    sample_times are the times of the samples (the requested ones, else t = 0 and every
    accepted step), energies H at each sample, max_energy_error = max |H(t_k) - H(0)| over
    them, H(0) from the initial state. final_angles and final_velocities are the solver's
    state at t_end (not wrapped), whatever the samples.
    """

    method: str
    rtol: float
    atol: float
    t_end: float
    cpu_time: float
    wall_time: float
    nfev: int
    njev: int
    nlu: int
    n_steps: int
    final_angles: np.ndarray       # (n,)
    final_velocities: np.ndarray   # (n,)
    sample_times: np.ndarray       # (N,)
    energies: np.ndarray           # (N,)
    initial_energy: float
    max_energy_error: float
    status: int
    message: str


def _step_counting(solver_class, solvers: list):
    """`solver_class` counting its accepted steps; each instance is appended to `solvers`."""

    class StepCounting(solver_class):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            self.accepted_steps = 0
            solvers.append(self)

        def _step_impl(self):
            success, message = super()._step_impl()
            self.accepted_steps += bool(success)
            return success, message

    StepCounting.__name__ = solver_class.__name__
    return StepCounting


def read_only_array(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


def simulate_scipy(scene: Scene, method: str, rtol: float, atol: float, t_end: float,
                   sample_times=None, *, directory: str | Path | None = None) -> ScipyRun:
    """Integrate `scene` from its initial state to t_end with solve_ivp(method, rtol, atol).

    The compiled Jacobian is passed to the implicit methods (IMPLICIT_METHODS) only. Raises
    ScipyPeerError for an unknown method, bad times, or a run solve_ivp does not finish.
    """
    if method not in SOLVERS:
        raise ScipyPeerError(f"method {method!r}: not a solve_ivp method; choose one of "
                             f"{', '.join(SOLVERS)}")
    if not (t_end > 0 and np.isfinite(t_end)):
        raise ScipyPeerError(f"t_end: must be > 0 and finite, got {t_end!r}")
    t_eval = None
    if sample_times is not None:
        t_eval = np.asarray(sample_times, dtype=float).reshape(-1)
        if not t_eval.size or t_eval[0] < 0 or t_eval[-1] > t_end or np.any(np.diff(t_eval) < 0):
            raise ScipyPeerError(f"sample_times: must be non-empty and ascending within "
                                 f"[0, t_end = {t_end}], got {sample_times!r}")
    compiled = compile_ode(scene, directory)
    y0 = np.array(scene.initial_angles + scene.initial_velocities, dtype=float)
    options = {"jac": compiled.jac} if method in IMPLICIT_METHODS else {}
    solvers: list = []
    solver_class = _step_counting(SOLVERS[method], solvers)

    cpu_start, wall_start = time.process_time(), time.perf_counter()
    try:
        solution = integrate.solve_ivp(compiled.fun, (0.0, t_end), y0, method=solver_class,
                                       rtol=rtol, atol=atol, dense_output=False,
                                       t_eval=t_eval, **options)
    except NonFiniteDerivativeError as error:
        raise ScipyPeerError(f"{scene.name}: solve_ivp {method} (rtol={rtol}, atol={atol}): "
                             f"{error}") from None
    wall_time = time.perf_counter() - wall_start
    cpu_time = time.process_time() - cpu_start

    if solution.status != 0:
        raise ScipyPeerError(f"{scene.name}: solve_ivp {method} (rtol={rtol}, atol={atol}) "
                             f"stopped at t = {solvers[0].t} of {t_end}: {solution.message}")
    solver = solvers[0]
    n = scene.n
    initial_energy = float(compiled.energies(y0)[0])
    energies = compiled.energies(solution.y)
    return ScipyRun(
        method=method, rtol=float(rtol), atol=float(atol), t_end=float(t_end),
        cpu_time=cpu_time, wall_time=wall_time, nfev=int(solution.nfev),
        njev=int(solution.njev), nlu=int(solution.nlu), n_steps=solver.accepted_steps,
        final_angles=read_only_array(solver.y[:n]), final_velocities=read_only_array(solver.y[n:]),
        sample_times=read_only_array(solution.t), energies=read_only_array(energies),
        initial_energy=initial_energy,
        max_energy_error=float(np.abs(energies - initial_energy).max()),
        status=int(solution.status), message=str(solution.message))


def reference_solution(scene: Scene, t_end: float) -> tuple[np.ndarray, np.ndarray]:
    """(phi, phidot) at t_end by DOP853 at SciPy's tightest tolerances (REFERENCE_RTOL), the
    reference for the trajectory errors of all integrators.

    How good it is depends on t_end, because the chains are chaotic: on three_link_mono and
    three_link_gravity a change of 1e-12 rad in the initial angles grows to 5e-12 at 3 s but
    to 1e-5 and 1e-4 rad at 50 s. Measured against MuJoCo RK4 at dt = 1e-4, the reference
    agrees to 1e-14 rad at 3 s and to 4e-8 (mono) and 6e-7 rad (gravity) at 50 s; rtol = 1e-13
    differs from it by as much. Trajectory errors below that level at such t_end say nothing.
    """
    run = simulate_scipy(scene, "DOP853", REFERENCE_RTOL, REFERENCE_ATOL, t_end)
    return run.final_angles, run.final_velocities
