"""`chaingen check`: the generated C against numbers computed independently of it.

For users' CI: every generated derivative against central finite differences of the generated
function it differentiates, and every generated function against its SymPy expression
evaluated numerically (lambdify), at random admissible states. One row per quantity with the
worst relative error over all samples; the check fails when any row exceeds its tolerance.

- residual Jacobian dF/dz vs central differences of F (C);
- step sensitivities d s1/d s0, d s1/d u vs central differences of the joint-space step map;
- residual F, next state, initial state, energy, joint angles and rates, constraint residuals
  vs SymPy (the expressions the code was generated from);
- a scene's [control] law (control_torques): the torque tau each actuated joint applies over
  the step, and the step's x1, vs the SymPy law at the step the reference solves.

The states are random joint-space states near the scene's initial one, mapped by the generated
initial_state; the SymPy comparisons also use states pushed off the constraint manifold, where
the constraint residuals are not round-off.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..runtime import NewtonError, NewtonOptions, Solver
from ..scene.labels import scheme_label
from ..symbolic.schemes import DiscreteScheme

#: Newton settings for the differenced step map: tight, so solver noise stays below the
#: differences' own error.
TIGHT = NewtonOptions(max_iterations=50, update_rtol=1e-14, update_atol=1e-14,
                      residual_tol=1e-12)
#: Worst relative error allowed: finite differences (O(h^2) plus round-off / h), and numeric
#: SymPy evaluations (round-off of two different expression graphs).
DERIVATIVE_TOLERANCE = 1e-6
VALUE_TOLERANCE = 1e-9
#: The reference Newton stops at the round-off floor once its updates are below this of the
#: unknowns and stop shrinking (_converged_unknowns): far below VALUE_TOLERANCE.
ROUND_OFF_GATE = 1e-10
#: The most random states a check takes. Nothing is kept per state (only the worst error of
#: each row), so the bound is time: a state takes 4.2 ms (three_link_mono, es K = 3), 12.8 ms
#: (panda_springs) to 150 ms (panda_springs --order 6) to check, measured over 200 states on a
#: shared 2-core machine; 100000 of them are 7 min to 4 h, and --samples 10**9 (which ran,
#: silently, before this bound) 49 days on the cheapest of them.
MAX_SAMPLES = 100_000


@dataclass(frozen=True)
class CheckRow:
    quantity: str
    reference: str      # what the generated function is compared with
    worst: float        # worst relative error over the samples
    tolerance: float

    @property
    def passed(self) -> bool:
        return bool(self.worst <= self.tolerance)   # NaN fails


@dataclass(frozen=True)
class CheckReport:
    scene: str
    method: str
    quadrature: int | None
    samples: int
    rows: tuple[CheckRow, ...] = field(default=())

    @property
    def passed(self) -> bool:
        return all(row.passed for row in self.rows)

    def table(self) -> str:
        label = scheme_label(self.method, self.quadrature)
        lines = [f"{self.scene}: {label}, {self.samples} random states",
                 f"  {'quantity':<22} {'against':<22} {'worst rel. error':>16} "
                 f"{'tolerance':>10}  result"]
        for row in self.rows:
            lines.append(f"  {row.quantity:<22} {row.reference:<22} {row.worst:>16.2e} "
                         f"{row.tolerance:>10.0e}  {'ok' if row.passed else 'MISMATCH'}")
        lines.append("  passed" if self.passed else "  FAILED: a generated function disagrees")
        return "\n".join(lines)


def relative_error(computed, reference) -> float:
    """max |computed - reference| / max(max |reference|, 1e-300); NaN anywhere gives NaN."""
    computed, reference = np.asarray(computed, float), np.asarray(reference, float)
    if computed.shape != reference.shape:
        return float("nan")
    if not (np.all(np.isfinite(computed)) and np.all(np.isfinite(reference))):
        return float("nan")
    if computed.size == 0:
        return 0.0
    return float(np.abs(computed - reference).max() / max(np.abs(reference).max(), 1e-300))


def central_differences(f, point, steps) -> np.ndarray:
    columns = []
    for j, h in enumerate(steps):
        e = np.zeros(len(point))
        e[j] = h
        # inf - inf (a residual beyond a double's range at an extreme dt): NaN, which the
        # row reports as a failed comparison, without a RuntimeWarning on stderr.
        with np.errstate(invalid="ignore", over="ignore"):
            columns.append((np.asarray(f(point + e)) - np.asarray(f(point - e))) / (2 * h))
    return np.column_stack(columns) if columns else np.zeros((0, 0))


class _SympyFunctions:
    """The scheme's expressions, lambdified over the same inputs as the C functions."""

    def __init__(self, scheme: DiscreteScheme):
        self.residual = scheme.step_function(scheme.step.residual)
        self.next_state = scheme.step_function(scheme.step.next_state)
        self.composition = scheme.metadata.composition
        torques = scheme.flows.applied_torques    # a control law's (None without one)
        self.applied = None if torques is None else scheme.step_function(torques)
        self.initial_state = scheme.initial_function()
        maps = scheme.maps
        self.outputs = scheme.state_function(list(maps.joint_angles) + list(maps.joint_velocities)
                                             + [maps.energy] + list(maps.constraint_residuals))
        self.n = scheme.scene.n
        self.nconstraint = scheme.maps.constraint_residuals.shape[0]

    def evaluate_outputs(self, x, p) -> np.ndarray:
        return np.array(self.outputs(*x, *p), float)


def check_solver(scheme: DiscreteScheme, solver: Solver, *, samples: int = 5,
                 seed: int = 0, dt: float | None = None) -> CheckReport:
    """Compare `solver` (the C built from `scheme`) with differences and with SymPy, at
    `samples` random states, 1 to MAX_SAMPLES (ValueError otherwise: no states, no check)."""
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) \
            or not 1 <= samples <= MAX_SAMPLES:
        raise ValueError(f"samples: must be an integer from 1 to {MAX_SAMPLES} (random states "
                         f"to check at), got {samples!r}")
    scene = scheme.scene
    n, nu = scene.n, solver.nu
    dt = dt if dt is not None else scene.simulation.dt
    rng = np.random.default_rng(seed)
    reference = _SympyFunctions(scheme)
    worst: dict[str, float] = {}

    def record(name: str, error: float) -> None:
        previous = worst.get(name, 0.0)
        worst[name] = error if (np.isnan(error) or np.isnan(previous)) else max(previous, error)

    for _ in range(samples):
        s0 = np.concatenate([np.asarray(scene.initial_angles) + rng.uniform(-0.5, 0.5, n),
                             rng.uniform(-1.0, 1.0, n)])
        u = rng.uniform(-1.0, 1.0, nu) if nu else None
        u_list = list(u) if nu else []
        # Parameters (if any) 10 % around the scene's own values; a zero one (no damping, no
        # gravity) around 0.1, so that its central differences stay within its range (>= 0).
        defaults = solver.default_parameters
        p = np.where(defaults == 0, 0.1, defaults) * (1 + 0.1 * rng.uniform(-1, 1, len(defaults)))
        p_list = list(p)
        x0 = solver.initial_state(s0[:n], s0[n:], p)
        z = 0.01 * rng.standard_normal(solver.nz)

        # The residual Jacobian against central differences of the C residual.
        _, jacobian = solver.residual_jacobian(z, x0, u, dt, parameters=p)
        steps = 1e-6 * np.maximum(1.0, np.abs(z))
        numeric = central_differences(
            lambda v, x0=x0, u=u, p=p: solver.residual(v, x0, u, dt, parameters=p), z, steps)
        record("residual Jacobian", relative_error(jacobian, numeric))

        # The step sensitivities against central differences of the joint-space step map.
        if solver.has_sensitivities:
            def step_map(s, v, q):
                x = solver.initial_state(s[:n], s[n:], q)
                x1 = solver.step(x, v, dt, options=TIGHT, parameters=q).x1
                phi, omega, _, _ = solver.outputs(x1, q)
                return np.concatenate([phi, omega])

            sens = solver.step_sensitivities(x0, u, dt, parameters=p)
            record("d s1 / d s0", relative_error(sens.ds_ds, central_differences(
                lambda s, u=u, p=p: step_map(s, u, p), s0, np.full(2 * n, 1e-4))))
            if nu:
                record("d s1 / d u", relative_error(sens.ds_du, central_differences(
                    lambda v, s0=s0, p=p: step_map(s0, v, p), u, np.full(nu, 1e-3))))
            if len(p):
                # A parameter acts on s1 through one step only (ds1/dp ~ dt): relative steps of
                # 1e-3 keep the differences' noise (solved steps, 1e-12 / h) below 1e-8 of it,
                # and its truncation (h^2) as small. Relative to the parameter itself: an
                # absolute step of 1e-3 on an inertia of 0.05 kg m^2 is 2 % of it, whose
                # truncation error (4e-4 of the derivative) the check would report.
                record("d s1 / d p", relative_error(sens.ds_dp, central_differences(
                    lambda q, s0=s0, u=u: step_map(s0, u, q), p,
                    1e-4 * np.where(p != 0, np.abs(p), 1.0))))

        # Generated functions against their SymPy expressions.
        args = list(z) + list(x0) + u_list + p_list + [dt]
        record("residual", relative_error(solver.residual(z, x0, u, dt, parameters=p),
                                          reference.residual(*args)))
        record("initial state", relative_error(x0, reference.initial_state(*s0, *p_list)))
        x1 = solver.step(x0, u, dt, parameters=p).x1
        # The step of order 4 or 6 is a composition: its stages in turn.
        expected = x0
        for fraction in reference.composition:
            converged = _converged_unknowns(reference, expected, fraction * dt, u_list,
                                            p_list, solver.nz)
            if converged is None:   # no reference: the row fails rather than vanish
                expected = np.full(len(x1), np.nan)
                break
            expected = np.asarray(reference.next_state(*converged, *expected, *u_list,
                                                       *p_list, fraction * dt), float)
        record("next state", relative_error(x1, expected))
        if reference.applied is not None and solver.has_entry_point("control_torques"):
            record("control torques", _control_error(reference, solver, x0, u, p, dt,
                                                     converged, expected, u_list))
        # Off the constraint manifold too, where the constraint residuals are O(1e-3).
        off = x0 + 1e-3 * rng.standard_normal(len(x0)) * np.maximum(1.0, np.abs(x0))
        for x in (x0, off):
            phi, omega, energy, _ = solver.outputs(x, p)
            expected = reference.evaluate_outputs(x, p_list)
            record("joint angles", relative_error(phi, expected[:n]))
            record("joint rates", relative_error(omega, expected[n:2 * n]))
            record("energy", relative_error(energy, expected[2 * n]))
        if reference.nconstraint:   # on the manifold both are round-off: compare off it
            record("constraint error", relative_error(
                solver.outputs(off, p)[3],
                np.abs(reference.evaluate_outputs(off, p_list)[2 * n + 1:]).max()))

    against = {"residual Jacobian": "central differences", "d s1 / d s0": "central differences",
               "d s1 / d u": "central differences", "d s1 / d p": "central differences"}
    rows = tuple(CheckRow(name, against.get(name, "SymPy"), error,
                          DERIVATIVE_TOLERANCE if name in against else VALUE_TOLERANCE)
                 for name, error in worst.items())
    quadrature = solver.manifest.get("quadrature")
    return CheckReport(scene=scene.name, method=scheme.metadata.method, quadrature=quadrature,
                       samples=samples, rows=rows)


def _control_error(reference: _SympyFunctions, solver: Solver, x0, u, p, dt, converged,
                   expected, u_list) -> float:
    """The worse of control_torques' tau and x1 against the SymPy law at `converged` (the
    reference's z of the step, None if it failed) and the reference's x1 `expected`; NaN
    where either side has none (a step the C refuses, a reference Newton that failed)."""
    try:
        controlled = solver.control_torques(x0, u, dt, parameters=p)
    except NewtonError:
        return float("nan")
    if converged is None or len(reference.composition) != 1:
        return float("nan")
    tau = np.asarray(reference.applied(*converged, *x0, *u_list, *p, dt), float).ravel()
    return float(np.max([relative_error(controlled.tau, tau),        # NaN if either is
                         relative_error(controlled.x1, expected)]))


def _converged_unknowns(reference: _SympyFunctions, x0, dt, u, p, nz: int):
    """z of the stage from x0 (dt < 0 for a backward stage of a composition, which the C
    entry points refuse), by Newton on the SymPy residual with a central-difference Jacobian,
    from zero; None if it fails. Independent of the C it checks.

    Converged when an update is below 1e-14 of z, or at the round-off floor: an update no
    smaller than half the one before, which was below ROUND_OFF_GATE of z. There the residual
    is round-off and the updates are its noise through the inverse Jacobian, which no absolute
    tolerance bounds (spatial es: ~3e-14 of z, the residual at 2e-16); Newton's updates
    shrink quadratically until then."""
    def residual(z):
        return np.asarray(reference.residual(*z, *x0, *u, *p, dt), float).ravel()

    z = np.zeros(nz)
    previous = np.inf
    for _ in range(50):
        f = residual(z)
        steps = 1e-7 * np.maximum(1.0, np.abs(z))
        jacobian = central_differences(residual, z, steps)
        update = np.linalg.solve(jacobian, -f)
        z = z + update
        size, scale = np.abs(update).max(), max(1.0, np.abs(z).max())
        if size <= 1e-14 * scale or (previous <= ROUND_OFF_GATE * scale and size > previous / 2):
            return z
        previous = size
    return None
