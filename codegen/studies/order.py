"""The time-step study of the reference thesis (section 5.1.5; model.md section 8).

For each step size dt the scene is simulated to t_end and compared, at common sample times
(every `sample_interval`, 0.2 s by default), with

- its own initial energy: the average energy error mean_k |H(t_k) - H(0)|;
- a reference run of the same scheme with a much smaller step (min(dts) / 10 by default): the
  average trajectory error mean_k max_i |wrap(phi_i(t_k) - phi_ref_i(t_k))|.

The order of each error is the slope of log(error) against log(dt) over the part of the curve
where it is linear (`fit_order`): points at the round-off floor and points where the scheme has
left its asymptotic regime are left out, and the fit reports which step sizes it used. A dt at
which Newton's method fails is recorded as failed (with the solver's message), not raised.

For a scene with joint damping or torques the "energy error" is the energy-balance error
H - H_0 - (input work) + (dissipated energy) (model.md section 7), which is H - H_0 when there
are no energy flows.

`order_study` runs a study, `format_table` prints it; chaingen.views.order_plot draws it.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from ..errors import NewtonError, OrderStudyError
from ..progress import Progress
from ..runtime import NewtonOptions, SimulationResult, Solver
from ..scene import METHODS, Scene, load_scene, quadrature_used

#: The thesis's step sizes (s), model.md section 8.
DEFAULT_DTS = (0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2)
#: Errors are compared at multiples of this time (s); every dt must divide it.
SAMPLE_INTERVAL = 0.2
#: Energy errors below this fraction of the run's energy scale are round-off, not scheme error.
#: Accumulated round-off over 10^4..10^5 steps is ~1e-15..1e-14 of the energy scale, so this
#: leaves a margin of about ten.
ENERGY_FLOOR = 1e-13
#: Trajectory errors (rad) below this are round-off.
TRAJECTORY_FLOOR = 1e-12
#: Consecutive log-log slopes of a fitted range may differ by at most this much.
SLOPE_TOLERANCE = 0.5
#: The fewest points an order is fitted on.
MIN_FIT_POINTS = 3

#: Relative tolerance of "dt divides the sample interval" and "the interval divides t_end".
_DIVIDES_RTOL = 1e-9


@dataclass(frozen=True)
class OrderRow:
    """One step size of a study. The errors are None when the run failed."""

    dt: float
    n_steps: int
    energy_error: float | None             # mean over the sample times of |H - H_0| (J)
    trajectory_error: float | None         # mean over the sample times of max_i |dphi_i| (rad)
    mean_newton_iterations: float | None   # per step (of the steps done, if it failed)
    max_newton_iterations: int | None
    wall_time: float | None                # seconds in the C loop
    failure: str | None = None             # the solver's message when the run failed

    @property
    def failed(self) -> bool:
        return self.failure is not None


@dataclass(frozen=True)
class OrderFit:
    """A fitted order: error ~ coefficient * dt^order over the step sizes `dts`.

    order is None (and dts empty) when no range of at least MIN_FIT_POINTS points is linear;
    `reason` then says why.
    """

    order: float | None
    coefficient: float | None = None
    dts: tuple[float, ...] = ()
    reason: str | None = None

    def predict(self, dt) -> np.ndarray:
        if self.order is None:
            raise ValueError("no fitted order")
        return self.coefficient * np.asarray(dt, dtype=float) ** self.order


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
    energy_scale: float           # J: max of |H|, |T|, |V| along the reference run
    energy_floor: float           # J: energy errors below it were not fitted
    trajectory_floor: float       # rad: trajectory errors below it were not fitted
    reference_wall_time: float
    order: int = 2                # of the step (4 and 6: composed)

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
    def energy_fit_dts(self) -> tuple[float, ...]:
        return self.energy_fit.dts

    @property
    def trajectory_fit_dts(self) -> tuple[float, ...]:
        return self.trajectory_fit.dts

    @property
    def failed_dts(self) -> tuple[float, ...]:
        return tuple(row.dt for row in self.rows if row.failed)


# --------------------------------------------------------------------------------------------
# Fitting
# --------------------------------------------------------------------------------------------

def fit_order(dts, errors, *, floor: float = 0.0, tolerance: float = SLOPE_TOLERANCE,
              min_points: int = MIN_FIT_POINTS) -> OrderFit:
    """The slope of log(error) against log(dt) over the linear part of the curve.

    Points whose error is None, not finite, or <= floor (round-off) are left out and split the
    curve. Among the remaining runs of neighbouring step sizes, the longest range of at least
    `min_points` points whose consecutive slopes all lie within `tolerance` of each other
    (max - min <= tolerance) is taken, the one at the small-dt end on ties; the order is the
    least-squares slope over it.
    """
    if min_points < 2:
        raise ValueError(f"fit_order: min_points must be >= 2, got {min_points}")
    pairs = sorted(zip((float(dt) for dt in dts), errors), key=lambda pair: pair[0])
    if len({dt for dt, _ in pairs}) != len(pairs):
        raise ValueError("fit_order: step sizes must be distinct")
    usable = [error is not None and math.isfinite(error) and error > floor and error > 0
              for _, error in pairs]
    logs = [(math.log(dt), math.log(error)) if ok else None
            for (dt, error), ok in zip(pairs, usable)]
    best: tuple[int, int] | None = None       # [start, stop) into pairs
    start = 0
    while start < len(pairs):
        if not usable[start]:
            start += 1
            continue
        stop = start
        while stop < len(pairs) and usable[stop]:
            stop += 1
        slopes = [(logs[k + 1][1] - logs[k][1]) / (logs[k + 1][0] - logs[k][0])
                  for k in range(start, stop - 1)]
        for first in range(start, stop):
            for last in range(first + min_points - 1, stop):
                window = slopes[first - start:last - start]
                if max(window) - min(window) > tolerance:
                    break          # longer windows from `first` only spread further
                length = last - first + 1
                if best is None or length > best[1] - best[0]:
                    best = (first, last + 1)   # strictly longer: ties keep the smaller dts
        start = stop
    if best is None:
        kept = sum(usable)
        if kept < min_points:
            reason = (f"only {kept} of {len(pairs)} points usable (the others failed, are not "
                      f"finite or are at the floor {floor:.2g})")
        else:
            reason = (f"no {min_points} neighbouring points with slopes within "
                      f"{tolerance:g} of each other")
        return OrderFit(order=None, reason=reason)
    x = np.array([logs[k][0] for k in range(*best)])
    y = np.array([logs[k][1] for k in range(*best)])
    slope, intercept = np.polyfit(x, y, 1)
    return OrderFit(order=float(slope), coefficient=float(math.exp(intercept)),
                    dts=tuple(pairs[k][0] for k in range(*best)))


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
                dts=DEFAULT_DTS, t_end: float = 10.0, dt_ref: float | None = None,
                solver: Solver | None = None, sample_interval: float = SAMPLE_INTERVAL,
                energy_floor: float = ENERGY_FLOOR, trajectory_floor: float = TRAJECTORY_FLOOR,
                slope_tolerance: float = SLOPE_TOLERANCE,
                options: NewtonOptions | dict | None = None, order: int = 2) -> OrderStudy:
    """Run the time-step study of `scene` (a Scene or a scene file) with one scheme.

    The solver is built once (without step sensitivities) unless given; a given solver must be
    the scene's, of `method` (and `quadrature` where the scheme uses one). dt_ref defaults to
    min(dts) / 10. energy_floor is relative to the energy scale of the reference run;
    trajectory_floor is in rad. options: Newton settings of every run, the reference's too.
    order: of the step (2, or 4 and 6 composed), of the built solver and of a given one.
    Raises OrderStudyError for step sizes that do not fit the sample grid and when the
    reference run fails; a failing dt is recorded in its row.
    """
    if not isinstance(scene, Scene):
        scene = load_scene(scene)
    if method not in METHODS:
        raise OrderStudyError(f"method {method!r} is not available (available: "
                              f"{', '.join(METHODS)})")
    quadrature_in_use = quadrature_used(scene, method, quadrature)
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
        solver = build_solver(scene, method, quadrature, sensitivities=False, order=order)
    else:
        manifest = solver.manifest
        if manifest.get("order", 2) != order:
            raise OrderStudyError(f"the given solver is of order {manifest.get('order', 2)}, "
                                  f"not {order}")
        if manifest.get("method") != method or manifest.get("quadrature") != quadrature_in_use:
            raise OrderStudyError(
                f"the given solver is method {manifest.get('method')!r}, quadrature "
                f"{manifest.get('quadrature')}, not {method!r}, quadrature {quadrature_in_use}")
        if manifest.get("scene") != scene.name:
            raise OrderStudyError(f"the given solver is for scene {manifest.get('scene')!r}, "
                                  f"not {scene.name!r}")

    bar = Progress(f"order {scene.name} ({method})", total=len(dts) + 1, unit="runs")

    def run(dt: float) -> SimulationResult:
        bar.update(bar.done, f"dt = {dt:g} s")
        try:
            return solver.simulate(scene.initial_angles, scene.initial_velocities, dt=dt,
                                   n_steps=round(t_end / dt), every=every[dt], options=options,
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
                dt=dt, n_steps=round(t_end / dt), energy_error=None, trajectory_error=None,
                mean_newton_iterations=partial.mean_newton_iterations if partial else None,
                max_newton_iterations=partial.max_newton_iterations if partial else None,
                wall_time=partial.wall_time if partial else None, failure=str(error)))
            continue
        index = _sample_indices(result, sample_interval)
        _, mine, theirs = np.intersect1d(index[index >= 0], reference_index[reference_index >= 0],
                                         assume_unique=True, return_indices=True)
        mine = np.flatnonzero(index >= 0)[mine]
        theirs = np.flatnonzero(reference_index >= 0)[theirs]
        energy = float(np.mean(np.abs(result.balance_error[mine])))
        difference = result.phi[mine] - reference.phi[theirs]
        wrapped = (difference + np.pi) % (2 * np.pi) - np.pi
        trajectory = float(np.mean(np.max(np.abs(wrapped), axis=1)))
        failure = None
        if not (math.isfinite(energy) and math.isfinite(trajectory)):
            failure = "non-finite state in the samples (the run blew up)"
        rows.append(OrderRow(
            dt=dt, n_steps=result.n_steps, energy_error=energy, trajectory_error=trajectory,
            mean_newton_iterations=result.mean_newton_iterations,
            max_newton_iterations=result.max_newton_iterations, wall_time=result.wall_time,
            failure=failure))

    scale = _energy_scale(solver, reference)
    # A failed dt counts as a gap: a fitted range never spans it.
    energies = [None if row.failed else row.energy_error for row in rows]
    trajectories = [None if row.failed else row.trajectory_error for row in rows]
    energy_fit = fit_order(dts, energies, floor=energy_floor * scale, tolerance=slope_tolerance)
    trajectory_fit = fit_order(dts, trajectories, floor=trajectory_floor,
                               tolerance=slope_tolerance)
    bar.close()
    return OrderStudy(
        scene=scene.name, method=method, quadrature=quadrature_in_use, t_end=float(t_end),
        dt_ref=dt_ref, sample_interval=float(sample_interval), rows=tuple(rows),
        energy_fit=energy_fit, trajectory_fit=trajectory_fit, energy_scale=scale,
        energy_floor=energy_floor * scale, trajectory_floor=trajectory_floor,
        reference_wall_time=reference.wall_time, order=order)


# --------------------------------------------------------------------------------------------
# Output
# --------------------------------------------------------------------------------------------

def study_label(study: OrderStudy) -> str:
    label = f"method {study.method}"
    if study.quadrature is not None:
        label += f", quadrature {study.quadrature}"
    if study.order != 2:
        label += f", order {study.order}"
    return label


def _fit_line(name: str, fit: OrderFit, unit: str, floor: float) -> str:
    if fit.order is None:
        return f"{name:<18}--    ({fit.reason})"
    return (f"{name:<18}{fit.order:.2f}  (fit over dt = {min(fit.dts):g} ... {max(fit.dts):g} s, "
            f"{len(fit.dts)} points; floor {floor:.1e} {unit})")


def format_table(study: OrderStudy) -> str:
    """The study as plain text: one row per dt ('*' marks the fitted points), then the orders."""
    lines = [
        f"{study.scene}: {study_label(study)}; t_end {study.t_end:g} s; reference: same method, "
        f"dt_ref {study.dt_ref:g} s ({study.reference_wall_time:.3g} s); errors averaged over "
        f"samples every {study.sample_interval:g} s",
        f"{'dt [s]':>8}  {'energy error [J]':>17}  {'trajectory error [rad]':>23}  "
        f"{'Newton mean/max':>15}  {'wall [s]':>9}",
    ]
    for row in study.rows:
        if row.failed and row.energy_error is None:
            lines.append(f"{row.dt:>8g}  failed: {row.failure}")
            continue
        energy_mark = "*" if row.dt in study.energy_fit.dts else " "
        trajectory_mark = "*" if row.dt in study.trajectory_fit.dts else " "
        newton = f"{row.mean_newton_iterations:.2f} / {row.max_newton_iterations}"
        line = (f"{row.dt:>8g}  {row.energy_error:>15.3e} {energy_mark}  "
                f"{row.trajectory_error:>21.3e} {trajectory_mark}  {newton:>15}  "
                f"{row.wall_time:>9.2e}")
        if row.failed:
            line += f"  ({row.failure})"
        lines.append(line)
    lines += [
        _fit_line("energy order", study.energy_fit, "J", study.energy_floor),
        _fit_line("trajectory order", study.trajectory_fit, "rad", study.trajectory_floor),
    ]
    return "\n".join(lines)
