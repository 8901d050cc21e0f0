"""The time-step study of the reference thesis (section 5.1.5; model.md section 8).

For each step size dt the scene is simulated to t_end and compared, at common sample times
(every `sample_interval`, 0.2 s by default), with

- its own initial energy: the average balance error mean_k |e_B(t_k)| (mean_balance_error);
- a reference run of the same scheme and order with a much smaller step (min(dts) / 10 by
  default): the average trajectory (angle) error mean_k max_i |wrap(phi_i(t_k) - phi_ref_i(t_k))|
  and the average rate error mean_k max_i |omega_i(t_k) - omega_ref_i(t_k)|.

The order of each error is the slope of log(error) against log(dt) over the part of the curve
where it is linear (`fit_order`, from chaingen.studies.order_fit): points at the round-off floor
and points where the scheme has left its asymptotic regime are left out, and the fit reports
which step sizes it used. A dt at which Newton's method fails is recorded as failed (with the
solver's message), not raised.

e_B = H - H_0 - (input work) + (dissipated energy) (model.md sections 7 and 8) is H - H_0
without energy flows: the output then calls it the energy error, else the balance error.

Every order option of the step (2, and 4 and 6 composed, model.md section 14) has its own
step sizes and Newton settings (ORDER_DTS, ORDER_NEWTON_OPTIONS): at orders 4 and 6 most of the
thesis's step sizes sit at the round-off floor, and the package's Newton tolerances would be the
floor of the reference run.

`order_study` runs a study of one order, `order_studies` one per order the method takes;
`format_table` and `format_summary` print them; chaingen.views.order_plot draws them.
"""
from __future__ import annotations

import dataclasses
import math
import os
from dataclasses import dataclass

import numpy as np

from ..errors import NewtonError, OrderStudyError
from ..progress import Progress
from ..runtime import NewtonOptions, SimulationResult, Solver
from ..runtime.contract import JACOBIAN_EVERY_ITERATE, JACOBIAN_MODES
from ..scene import METHODS, ORDERS, Scene, SolverSpec, SolverSpecError, load_scene
from ..scene.labels import scheme_label
from ..scene.solver_rules import request_refusal
from .order_fit import MIN_FIT_POINTS as MIN_FIT_POINTS
from .order_fit import SLOPE_TOLERANCE as SLOPE_TOLERANCE
from .order_fit import OrderFit as OrderFit
from .order_fit import fit_order as fit_order

#: The thesis's step sizes (s), model.md section 8.
DEFAULT_DTS = (0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2)
#: Errors are compared at multiples of this time (s); every dt must divide it.
SAMPLE_INTERVAL = 0.2
#: Energy errors below this fraction of the run's energy scale are round-off, not scheme error.
#: Accumulated round-off over 10^4..10^5 steps is ~1e-15..1e-14 of the energy scale, so this
#: leaves a margin of about ten.
ENERGY_FLOOR = 1e-13
#: Trajectory errors (rad) below this are round-off. The reference run's own round-off, from
#: 10^4..10^5 stages, is ~5e-13 rad (measured against a run at 2 dt_ref, orders 4 and 6).
TRAJECTORY_FLOOR = 1e-12
#: Rate errors (rad/s) below this are round-off: the rates of the reference scenes are O(1)
#: rad/s like the angles, and their reference's round-off is the same ~5e-13.
RATE_FLOOR = 1e-12

#: The step sizes (s) of each order option, chosen where the error is above the round-off
#: floor and the scheme in its asymptotic regime (measured on three_link_mono and
#: three_link_multi, t_end 10 s, with ORDER_NEWTON_OPTIONS). Order 4: angle errors from
#: ~3e-10 rad at 0.01 s, slope 4.0 up to 0.2 s. Order 6: from ~1e-11 rad at 0.025 s, slope 6.0
#: up to 0.1 s. Below 0.025 s the round-off of the runs shows (vi: slope 6.3..6.5 from 0.02 to
#: 0.025 s); from 0.1 to 0.2 s vi on three_link_mono bends to 5.5, and at 0.4 s to 7.3.
ORDER_DTS = {
    2: DEFAULT_DTS,
    4: (0.01, 0.02, 0.025, 0.04, 0.05, 0.1, 0.2),
    6: (0.025, 0.04, 0.05, 0.1),
}
#: A method whose steps at an order are too accurate for ORDER_DTS: es at order 6 is at the
#: reference's floor (1e-12 rad) at dt = 0.04 s on three_link_mono.
METHOD_ORDER_DTS = {("es", 6): (0.05, 0.2 / 3, 0.1, 0.2)}


def order_dts(method: str, order: int) -> tuple[float, ...]:
    """The study's step sizes of `method` at `order`."""
    return METHOD_ORDER_DTS.get((method, order), ORDER_DTS[order])
#: Newton iterated to round-off: full Newton, every tolerance at 1e-14.
ROUND_OFF_NEWTON = {"reuse_jacobian": JACOBIAN_EVERY_ITERATE, "residual_tol": 1e-14,
                    "update_rtol": 1e-14, "update_atol": 1e-14, "max_iterations": 50}
#: The Newton settings of each order option, over the package's defaults. At order 2 the
#: package's suffice. At orders 4 and 6 they do not: with them the vi reference run (dt_ref
#: 0.001 s at order 4) is 2e-8 rad off the round-off one on three_link_mono, more than the
#: scheme's error at dt = 0.01 s (3e-10 rad).
ORDER_NEWTON_OPTIONS = {2: {}, 4: ROUND_OFF_NEWTON, 6: ROUND_OFF_NEWTON}

#: Relative tolerance of "dt divides the sample interval" and "the interval divides t_end".
_DIVIDES_RTOL = 1e-9


@dataclass(frozen=True)
class OrderRow:
    """One step size of a study. The errors are None when the run failed."""

    dt: float
    n_steps: int
    mean_balance_error: float | None       # mean over the sample times of |e_B| (J, model.md 8)
    trajectory_error: float | None         # mean over the sample times of max_i |dphi_i| (rad)
    mean_newton_iterations: float | None   # per step (of the steps done, if it failed)
    max_newton_iterations: int | None
    wall_time: float | None                # seconds in the C loop
    failure: str | None = None             # the solver's message when the run failed
    rate_error: float | None = None        # mean over the sample times of max_i |domega_i| (rad/s)
    max_balance_error: float | None = None  # max over the sample times of |e_B| (J)
    max_constraint_error: float | None = None   # max over the sample times (model.md 8)

    @property
    def failed(self) -> bool:
        return self.failure is not None


@dataclass(frozen=True)
class OrderStudy:
    scene: str
    method: str
    quadrature: int | None        # None when the scheme has no quadrature (vi, midpoint, ...)
    t_end: float
    dt_ref: float
    sample_interval: float
    rows: tuple[OrderRow, ...]    # ascending dt
    energy_fit: OrderFit
    trajectory_fit: OrderFit
    rate_fit: OrderFit
    energy_scale: float           # J: max of |H|, |T|, |V| along the reference run
    energy_floor: float           # J: energy errors below it were not fitted
    trajectory_floor: float       # rad: trajectory errors below it were not fitted
    rate_floor: float             # rad/s: rate errors below it were not fitted
    reference_wall_time: float
    order: int = 2                # of the step (4 and 6: composed)
    energy_flows: bool = False    # damping or torques: the energy error is the balance error
    #: The Newton settings of the runs that differ from the package's defaults (empty: none).
    newton_settings: tuple[tuple[str, float], ...] = ()
    gradient: str | None = None   # es's discrete gradient of the springs (None: plays no role)

    @property
    def dts(self) -> tuple[float, ...]:
        return tuple(row.dt for row in self.rows)

    @property
    def energy_order(self) -> float | None:
        return self.energy_fit.order

    @property
    def trajectory_order(self) -> float | None:
        return self.trajectory_fit.order

    @property
    def rate_order(self) -> float | None:
        return self.rate_fit.order

    @property
    def energy_fit_dts(self) -> tuple[float, ...]:
        return self.energy_fit.dts

    @property
    def trajectory_fit_dts(self) -> tuple[float, ...]:
        return self.trajectory_fit.dts

    @property
    def failed_dts(self) -> tuple[float, ...]:
        return tuple(row.dt for row in self.rows if row.failed)

    @property
    def max_balance_error(self) -> float | None:
        """The largest |e_B| (model.md 8) at a sample time of any run that did not fail."""
        return _largest(row.max_balance_error for row in self.rows if not row.failed)

    @property
    def max_constraint_error(self) -> float | None:
        """The largest constraint error at a sample time of any run that did not fail."""
        return _largest(row.max_constraint_error for row in self.rows if not row.failed)

    @property
    def energy_name(self) -> str:
        """What the energy error is: "balance" with energy flows (model.md 7), else "energy"."""
        return "balance" if self.energy_flows else "energy"


def _largest(values) -> float | None:
    values = [value for value in values if value is not None]
    return max(values) if values else None


def allowed_orders(method: str, scene=None) -> tuple[int, ...]:
    """The orders `method` takes for `scene` (chaingen.symbolic.schemes.orders_taken)."""
    from ..symbolic.schemes import orders_taken as scheme_orders_taken
    return scheme_orders_taken(scene, method)


def study_newton_options(order: int, overrides=None) -> dict:
    """The Newton settings of a study of `order` (ORDER_NEWTON_OPTIONS), with `overrides` (a
    dict of option fields, e.g. from the command line) taking precedence."""
    if refused := request_refusal({"order": order}):
        raise OrderStudyError(refused.stated)
    return {**ORDER_NEWTON_OPTIONS[order], **(overrides or {})}


def study_solver_spec(scene: Scene, method: str, quadrature: int, order: int,
                      gradient: str = "exact") -> SolverSpec:
    """A study's solver request (no step sensitivities), or OrderStudyError: order 3: ..."""
    try:
        return SolverSpec(scene, method, quadrature, order=order, sensitivities=False,
                          gradient=gradient)
    except SolverSpecError as error:
        raise OrderStudyError(error.refusal.stated) from None


# --------------------------------------------------------------------------------------------
# The study
# --------------------------------------------------------------------------------------------

def _divisions(whole: float, part: float, what: str) -> int:
    count = round(whole / part)
    if count < 1 or abs(count * part - whole) > _DIVIDES_RTOL * whole:
        raise OrderStudyError(f"{what}: {part:g} s does not divide {whole:g} s")
    return count


def _sample_indices(result: SimulationResult, interval: float) -> np.ndarray:
    """The sample rows' times as multiples of the interval (-1 where a row is off the grid)."""
    k = np.rint(result.t / interval)
    on_grid = np.abs(result.t - k * interval) <= 1e-9 * np.maximum(1.0, np.abs(result.t))
    return np.where(on_grid, k, -1).astype(np.int64)


def _energy_scale(solver: Solver, reference: SimulationResult) -> float:
    """max |H|, |V|, |T| along the reference samples (V at zero velocity, T = H - V)."""
    energy = reference.energy
    potential = np.array([solver.outputs(solver.initial_state(phi, np.zeros(solver.n)))[2]
                          for phi in reference.phi])
    scale = float(np.max(np.abs(np.concatenate([energy, potential, energy - potential]))))
    return scale if math.isfinite(scale) and scale > 0 else 1.0


def order_study(scene: Scene | str | os.PathLike, method: str, quadrature: int, *,
                dts=None, t_end: float = 10.0, dt_ref: float | None = None,
                solver: Solver | None = None, sample_interval: float = SAMPLE_INTERVAL,
                energy_floor: float = ENERGY_FLOOR, trajectory_floor: float = TRAJECTORY_FLOOR,
                rate_floor: float = RATE_FLOOR, slope_tolerance: float = SLOPE_TOLERANCE,
                options: NewtonOptions | dict | None = None, order: int = 2,
                gradient: str = "exact") -> OrderStudy:
    """Run the time-step study of `scene` (a Scene or a scene file) with one scheme and order.

    The solver is built once (without step sensitivities) unless given; a given solver must be
    the scene's, of `method` (and `quadrature` where the scheme uses one). dts default to
    order_dts(method, order), dt_ref to min(dts) / 10. energy_floor is relative to the energy
    scale of the reference run; trajectory_floor is in rad, rate_floor in rad/s. options:
    Newton settings of every run, the reference's too (a dict is taken over the package's
    defaults); default ORDER_NEWTON_OPTIONS[order]. order: of the step (2, or 4 and 6
    composed), of the built solver and of a given one. gradient: es's discrete gradient of the
    springs ("exact", "quadrature" or "chain"), of the built solver and of a given one.
    Raises OrderStudyError for step sizes that do not fit the sample grid and when the
    reference run fails; a failing dt is recorded in its row.
    """
    if isinstance(scene, (str, os.PathLike)):     # a file; a SpatialScene is taken as it is
        scene = load_scene(scene)
    spec = study_solver_spec(scene, method, quadrature, order, gradient)
    quadrature_in_use = spec.quadrature_used
    if dts is None:
        dts = order_dts(method, order)
    if options is None:
        options = study_newton_options(order)
    dts = tuple(sorted(float(dt) for dt in dts))
    if not dts:
        raise OrderStudyError("dts: no step sizes")
    if len(set(dts)) != len(dts):
        raise OrderStudyError(f"dts: step sizes repeat: {', '.join(f'{dt:g}' for dt in dts)}")
    for name, value in (("dt", min(dts)), ("t_end", t_end), ("sample_interval", sample_interval)):
        if not (math.isfinite(value) and value > 0):
            raise OrderStudyError(f"{name}: must be > 0 and finite, got {value}")
    if not math.isfinite(max(dts)):
        raise OrderStudyError(f"dt: must be finite, got {max(dts)}")
    dt_ref = float(dt_ref) if dt_ref is not None else dts[0] / 10
    if not (math.isfinite(dt_ref) and 0 < dt_ref < dts[0]):
        raise OrderStudyError(f"dt_ref: must be > 0 and below the smallest dt {dts[0]:g} s, "
                              f"got {dt_ref:g}")
    _divisions(t_end, sample_interval, "t_end must be a multiple of the sample interval")
    every = {dt: _divisions(sample_interval, dt, f"dt {dt:g} s: every dt must divide the "
                                                 f"sample interval") for dt in (dt_ref, *dts)}

    if solver is None:
        from ..simulation import build_solver
        solver = build_solver(spec)
    else:
        manifest = solver.manifest
        if manifest.get("order", 2) != order:
            raise OrderStudyError(f"the given solver is of order {manifest.get('order', 2)}, "
                                  f"not {order}")
        if manifest.get("method") != method or manifest.get("quadrature") != quadrature_in_use:
            raise OrderStudyError(
                f"the given solver is method {manifest.get('method')!r}, quadrature "
                f"{manifest.get('quadrature')}, not {method!r}, quadrature {quadrature_in_use}")
        if manifest.get("gradient") != spec.gradient_used:
            raise OrderStudyError(f"the given solver's gradient is {manifest.get('gradient')!r}, "
                                  f"not {spec.gradient_used!r}")
        if manifest.get("scene") != scene.name:
            raise OrderStudyError(f"the given solver is for scene {manifest.get('scene')!r}, "
                                  f"not {scene.name!r}")

    resolved = solver.newton_options(options)
    newton_settings = tuple(
        (name, value) for name, value in dataclasses.asdict(resolved).items()
        if value != getattr(solver.default_options, name))
    bar = Progress(f"order {scene.name} ({method}, order {order})", total=len(dts) + 1,
                   unit="runs")

    def run(dt: float) -> SimulationResult:
        bar.update(bar.done, f"dt = {dt:g} s")
        try:
            return solver.simulate(scene.initial_angles, scene.initial_velocities, dt=dt,
                                   n_steps=round(t_end / dt), every=every[dt], options=resolved,
                                   scene=scene.name)
        finally:
            bar.advance()

    try:
        reference = run(dt_ref)
    except NewtonError as error:
        bar.close()
        raise OrderStudyError(f"{scene.name}: the reference run ({method}, dt_ref {dt_ref:g} s) "
                              f"failed: {error}") from error
    if not np.all(np.isfinite(reference.samples)):
        bar.close()
        raise OrderStudyError(f"{scene.name}: the reference run ({method}, dt_ref {dt_ref:g} s) "
                              "has non-finite samples")
    reference_index = _sample_indices(reference, sample_interval)

    rows = []
    for dt in dts:
        try:
            result = run(dt)
        except NewtonError as error:
            partial = error.result
            rows.append(OrderRow(
                dt=dt, n_steps=round(t_end / dt), mean_balance_error=None, trajectory_error=None,
                mean_newton_iterations=partial.mean_newton_iterations if partial else None,
                max_newton_iterations=partial.max_newton_iterations if partial else None,
                wall_time=partial.wall_time if partial else None, failure=str(error)))
            continue
        index = _sample_indices(result, sample_interval)
        _, mine, theirs = np.intersect1d(index[index >= 0], reference_index[reference_index >= 0],
                                         assume_unique=True, return_indices=True)
        mine = np.flatnonzero(index >= 0)[mine]
        theirs = np.flatnonzero(reference_index >= 0)[theirs]
        balance = np.abs(result.balance_error[mine])
        energy = float(np.mean(balance))
        difference = result.phi[mine] - reference.phi[theirs]
        wrapped = (difference + np.pi) % (2 * np.pi) - np.pi
        trajectory = float(np.mean(np.max(np.abs(wrapped), axis=1)))
        rate = float(np.mean(np.max(np.abs(result.omega[mine] - reference.omega[theirs]),
                                    axis=1)))
        failure = None
        if not all(map(math.isfinite, (energy, trajectory, rate))):
            failure = "non-finite state in the samples (the run blew up)"
        rows.append(OrderRow(
            dt=dt, n_steps=result.n_steps, mean_balance_error=energy, trajectory_error=trajectory,
            mean_newton_iterations=result.mean_newton_iterations,
            max_newton_iterations=result.max_newton_iterations, wall_time=result.wall_time,
            failure=failure, rate_error=rate, max_balance_error=float(np.max(balance)),
            max_constraint_error=float(np.max(np.abs(result.constraint_error[mine])))))

    scale = _energy_scale(solver, reference)
    # A failed dt counts as a gap: a fitted range never spans it.
    energies = [None if row.failed else row.mean_balance_error for row in rows]
    trajectories = [None if row.failed else row.trajectory_error for row in rows]
    rates = [None if row.failed else row.rate_error for row in rows]
    energy_fit = fit_order(dts, energies, floor=energy_floor * scale, tolerance=slope_tolerance)
    trajectory_fit = fit_order(dts, trajectories, floor=trajectory_floor,
                               tolerance=slope_tolerance)
    rate_fit = fit_order(dts, rates, floor=rate_floor, tolerance=slope_tolerance)
    bar.close()
    return OrderStudy(
        scene=scene.name, method=method, quadrature=quadrature_in_use, t_end=float(t_end),
        dt_ref=dt_ref, sample_interval=float(sample_interval), rows=tuple(rows),
        energy_fit=energy_fit, trajectory_fit=trajectory_fit, energy_scale=scale,
        energy_floor=energy_floor * scale, trajectory_floor=trajectory_floor,
        reference_wall_time=reference.wall_time, order=order, rate_fit=rate_fit,
        gradient=spec.gradient_used,
        rate_floor=rate_floor, energy_flows=solver.energy_flows,
        newton_settings=newton_settings)


def order_studies(scene: Scene | str | os.PathLike, method: str, quadrature: int, *,
                  orders=None, t_end: float = 10.0, solvers=None, overrides=None,
                  gradient: str = "exact", **settings) -> tuple[OrderStudy, ...]:
    """The study of every order option `method` takes (allowed_orders), ascending, each with
    its own step sizes and Newton settings (ORDER_DTS, study_newton_options(order, overrides)).

    orders: a subset of them instead. solvers: {order: Solver}, built where missing.
    overrides: Newton option fields over every order's settings. settings: further keywords of
    order_study (sample_interval, floors, slope_tolerance) for every order.
    """
    if isinstance(scene, (str, os.PathLike)):     # a file; a SpatialScene is taken as it is
        scene = load_scene(scene)
    available = allowed_orders(method, scene) if method in METHODS else ORDERS
    orders = available if orders is None else tuple(sorted(set(orders)))
    for order in orders:
        study_solver_spec(scene, method, quadrature, order, gradient)
    return tuple(order_study(scene, method, quadrature, t_end=t_end, order=order,
                             solver=(solvers or {}).get(order), gradient=gradient,
                             options=study_newton_options(order, overrides), **settings)
                 for order in orders)


# --------------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------------

def newton_label(study: OrderStudy) -> str:
    """The Newton settings of the study's runs, as far as they are not the package's."""
    if not study.newton_settings:
        return "Newton: the package's defaults"
    settings = ", ".join(f"{name} {_option_text(name, value)}"
                         for name, value in study.newton_settings)
    return f"Newton: {settings} (the package's defaults otherwise)"


def _option_text(name: str, value) -> str:
    if name == "reuse_jacobian":      # the mode's name, as the command line spells it
        for mode in JACOBIAN_MODES:
            if mode.value == value:
                return mode.name.removeprefix("JACOBIAN_").lower().replace("_", "-")
    return f"{value:g}"


def format_table(study: OrderStudy) -> str:
    """The study as plain text: one row per dt ('*' marks the fitted points), then the orders.

    With energy flows the energy column and its order are the balance error's."""
    energy = study.energy_name
    label = scheme_label(study.method, study.quadrature, study.order, style="study",
                         gradient=study.gradient)
    lines = [
        f"{study.scene}: {label}; t_end {study.t_end:g} s; reference: same method "
        f"and order, dt_ref {study.dt_ref:g} s ({study.reference_wall_time:.3g} s); errors "
        f"averaged over samples every {study.sample_interval:g} s",
        f"step sizes of order {study.order}: {', '.join(f'{dt:g}' for dt in study.dts)} s; "
        f"{newton_label(study)}",
        f"{'dt [s]':>8}  {f'{energy} error [J]':>17}  {'trajectory error [rad]':>23}  "
        f"{'rate error [rad/s]':>19}  {'Newton mean/max':>15}  {'wall [s]':>9}",
    ]
    for row in study.rows:
        if row.failed and row.mean_balance_error is None:
            lines.append(f"{row.dt:>8.4g}  failed: {row.failure}")
            continue
        marks = ["*" if row.dt in fit.dts else " "
                 for fit in (study.energy_fit, study.trajectory_fit, study.rate_fit)]
        newton = f"{row.mean_newton_iterations:.2f} / {row.max_newton_iterations}"
        line = (f"{row.dt:>8.4g}  {row.mean_balance_error:>15.3e} {marks[0]}  "
                f"{row.trajectory_error:>21.3e} {marks[1]}  {row.rate_error:>17.3e} {marks[2]}  "
                f"{newton:>15}  {row.wall_time:>9.2e}")
        if row.failed:
            line += f"  ({row.failure})"
        lines.append(line)
    lines += [
        study.energy_fit.line(f"{energy} order", "J", study.energy_floor),
        study.trajectory_fit.line("trajectory order", "rad", study.trajectory_floor),
        study.rate_fit.line("rate order", "rad/s", study.rate_floor),
    ]
    return "\n".join(lines)


def _cell(value: float | None, width: int, spec: str) -> str:
    return f"{value:>{width}{spec}}" if value is not None else f"{'--':>{width}}"


def format_summary(studies) -> str:
    """One row per order option: the fitted orders of the angles (the trajectory error), the
    rates and the energy (the balance with energy flows); for es also the largest energy
    (balance) and constraint errors at the sample times of all its runs, which the scheme keeps
    at round-off at every order (model.md sections 4 and 14)."""
    studies = tuple(studies)
    if not studies:
        raise ValueError("format_summary: no studies")
    first = studies[0]
    if len({(study.scene, study.method, study.quadrature) for study in studies}) > 1:
        raise ValueError("format_summary: the studies are of different scenes or schemes")
    energy, conserving = first.energy_name, first.method == "es"
    header = (f"{'order option':>12}  {'angle order':>11}  {'rate order':>10}  "
              f"{f'{energy} order':>13}")
    if conserving:    # es's constraints c_i(q) are in m^2 (model.md section 8)
        header += f"  {f'max {energy} error [J]':>21}  {'max constraint error [m^2]':>26}"
    label = scheme_label(first.method, first.quadrature, gradient=first.gradient)
    lines = [f"{first.scene}: {label}; t_end {first.t_end:g} s; fitted orders "
             "(slope of log error against log dt; --: no linear range above the floor)", header]
    for study in studies:
        line = (f"{study.order:>12}  {_cell(study.trajectory_order, 11, '.2f')}  "
                f"{_cell(study.rate_order, 10, '.2f')}  {_cell(study.energy_order, 13, '.2f')}")
        if conserving:
            line += (f"  {_cell(study.max_balance_error, 21, '.2e')}  "
                     f"{_cell(study.max_constraint_error, 26, '.2e')}")
        if study.failed_dts:
            line += f"  (failed at dt = {', '.join(f'{dt:g}' for dt in study.failed_dts)} s)"
        lines.append(line)
    return "\n".join(lines)
