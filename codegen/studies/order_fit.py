"""The fitted order of an error curve (model.md section 8, "Fitted order"): the slope of
log(error) against log(dt) over the part of the curve where it is linear, for the time-step
study (chaingen.studies.order)."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Consecutive log-log slopes of a fitted range may differ by at most this much.
SLOPE_TOLERANCE = 0.5
#: The fewest points an order is fitted on.
MIN_FIT_POINTS = 3


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

    def line(self, name: str, unit: str, floor: float) -> str:
        """The fit as a line of text: `name`, the order, its range and the floor (in `unit`)."""
        if self.order is None:
            return f"{name:<18}--    ({self.reason})"
        return (f"{name:<18}{self.order:.2f}  (fit over dt = {min(self.dts):g} ... "
                f"{max(self.dts):g} s, {len(self.dts)} points; floor {floor:.1e} {unit})")


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
