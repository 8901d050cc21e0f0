"""The order fit of the time-step study (chaingen.studies.order.fit_order) and its output, on
synthetic data (no compiler)."""
from __future__ import annotations

import numpy as np
import pytest

from chaingen.errors import OrderStudyError
from chaingen.scene import ORDERS
from chaingen.studies.order import (
    DEFAULT_DTS,
    ENERGY_FLOOR,
    ORDER_DTS,
    ORDER_NEWTON_OPTIONS,
    RATE_FLOOR,
    ROUND_OFF_NEWTON,
    SAMPLE_INTERVAL,
    TRAJECTORY_FLOOR,
    OrderRow,
    OrderStudy,
    allowed_orders,
    fit_order,
    format_summary,
    format_table,
    study_newton_options,
)
from chaingen.symbolic.composition import order_error


def test_fit_finds_the_power_law_between_floor_and_saturation():
    dts = np.array(DEFAULT_DTS)
    errors = 3.0 * dts ** 4
    errors[:2] = [2e-14, 7e-15]          # round-off floor at the small steps
    errors[-1] = 2e-4                    # saturated: no longer grows at dt = 0.2
    fit = fit_order(dts, errors, floor=1e-12)
    assert fit.order == pytest.approx(4.0, abs=1e-9)
    assert fit.coefficient == pytest.approx(3.0, rel=1e-9)
    assert fit.dts == (0.005, 0.01, 0.02, 0.05, 0.1)
    np.testing.assert_allclose(fit.predict(0.01), 3e-8, rtol=1e-9)


def test_fit_leaves_out_a_bending_end_and_failed_points():
    dts = np.array(DEFAULT_DTS)
    errors = list(0.5 * dts ** 2)
    errors[-2] = errors[-3] * 1.2        # slope ~0.3 against ~2 below: out of the regime
    errors[-1] = None                    # failed
    fit = fit_order(dts, errors)
    assert fit.order == pytest.approx(2.0, abs=1e-9)
    assert fit.dts == DEFAULT_DTS[:6]


def test_fit_prefers_the_small_dt_end_on_ties_and_needs_three_points():
    dts = [1.0, 2.0, 4.0, 8.0, 16.0, 32.0]
    logs = np.log2(dts)
    # slope 2 over the first three, 3 between the third and fourth, 4 over the last three
    y = np.array([0, 2, 4, 7, 11, 15], dtype=float)
    fit = fit_order(dts, 2.0 ** y)
    assert fit.order == pytest.approx(2.0) and fit.dts == (1.0, 2.0, 4.0)
    assert np.allclose(np.diff(y) / np.diff(logs), [2, 2, 3, 4, 4])
    short = fit_order([0.1, 0.2, 0.4], [1e-3, 4e-3, None])
    assert short.order is None and short.dts == () and "only 2 of 3" in short.reason
    zigzag = fit_order([0.1, 0.2, 0.4, 0.8], [1e-3, 1e-2, 1e-2, 1e-1])
    assert zigzag.order is None and "slopes" in zigzag.reason


# --- the schemes' orders on three_link_mono (springs: the es energy error is not exact) ------



# --- order options and the output of a study, on synthetic studies ---------------------------

def synthetic_study(method: str, order: int, *, flows: bool = False, quadrature=None,
                    newton=()) -> OrderStudy:
    """A study whose errors are exactly C dt^order (energy at round-off for es)."""
    dts = ORDER_DTS[order]
    rows = tuple(OrderRow(
        dt=dt, n_steps=round(10 / dt),
        mean_balance_error=1e-15 if method == "es" else 0.1 * dt ** order,
        trajectory_error=0.3 * dt ** order, mean_newton_iterations=3.0,
        max_newton_iterations=4, wall_time=1e-3, rate_error=0.5 * dt ** order,
        max_balance_error=2e-15, max_constraint_error=3e-15) for dt in dts)
    fit = {name: fit_order(dts, [getattr(row, attribute) for row in rows], floor=floor)
           for name, attribute, floor in (
               ("energy", "mean_balance_error", ENERGY_FLOOR),
               ("trajectory", "trajectory_error", TRAJECTORY_FLOOR),
               ("rate", "rate_error", RATE_FLOOR))}
    return OrderStudy(
        scene="synthetic", method=method, quadrature=quadrature, t_end=10.0,
        dt_ref=min(dts) / 10, sample_interval=SAMPLE_INTERVAL, rows=rows,
        energy_fit=fit["energy"], trajectory_fit=fit["trajectory"], rate_fit=fit["rate"],
        energy_scale=1.0, energy_floor=ENERGY_FLOOR, trajectory_floor=TRAJECTORY_FLOOR,
        rate_floor=RATE_FLOOR, reference_wall_time=0.1, order=order, energy_flows=flows,
        newton_settings=newton)


@pytest.mark.parametrize("method", ["es", "vi", "midpoint"])
def test_allowed_orders_are_those_the_composition_takes(method):
    orders = allowed_orders(method)
    assert orders == tuple(order for order in ORDERS if order_error(method, order) is None)
    assert orders == (2, 4, 6)


def test_every_order_has_step_sizes_on_the_sample_grid_and_newton_settings():
    assert set(ORDER_DTS) == set(ORDERS) == set(ORDER_NEWTON_OPTIONS)
    assert ORDER_DTS[2] == DEFAULT_DTS
    for dts in ORDER_DTS.values():
        assert len(dts) >= 4 and list(dts) == sorted(dts)
        for dt in dts:
            assert abs(SAMPLE_INTERVAL / dt - round(SAMPLE_INTERVAL / dt)) < 1e-9, dt
    assert study_newton_options(2) == {}
    assert study_newton_options(4) == ROUND_OFF_NEWTON
    assert study_newton_options(6, {"max_iterations": 9})["max_iterations"] == 9
    assert study_newton_options(6, {"max_iterations": 9})["residual_tol"] == 1e-14
    with pytest.raises(OrderStudyError, match="order 3"):
        study_newton_options(3)


@pytest.mark.parametrize("method", ["es", "vi", "midpoint"])
def test_the_summary_has_a_row_per_allowed_order(method):
    quadrature = 7 if method == "es" else None
    studies = [synthetic_study(method, order, quadrature=quadrature)
               for order in allowed_orders(method)]
    lines = format_summary(studies).splitlines()
    assert lines[0].startswith("synthetic: method " + method)
    assert lines[1].split()[:8] == ["order", "option", "angle", "order", "rate", "order",
                                    "energy", "order"]
    rows = lines[2:]
    assert len(rows) == len(allowed_orders(method))
    for order, row in zip(allowed_orders(method), rows):
        cells = row.split()
        assert cells[:3] == [str(order), f"{order:.2f}", f"{order:.2f}"]
        if method == "es":      # energy at round-off: no order, but its largest errors
            assert cells[3:] == ["--", "2.00e-15", "3.00e-15"]
        else:
            assert cells[3:] == [f"{order:.2f}"]
    assert ("max constraint error [m^2]" in lines[1]) == (method == "es")


def test_with_energy_flows_the_energy_error_is_called_the_balance_error():
    study = synthetic_study("es", 2, flows=True, quadrature=3)
    table, summary = format_table(study), format_summary([study])
    assert "balance error [J]" in table and "balance order" in table
    assert "max balance error [J]" in summary and "balance order" in summary
    assert "energy" not in table.split("\n", 2)[2] and "energy" not in summary
    plain = format_table(synthetic_study("vi", 4))
    assert "energy error [J]" in plain and "balance" not in plain


def test_the_header_names_the_step_sizes_and_the_newton_settings():
    tight = tuple((name, value) for name, value in ROUND_OFF_NEWTON.items()
                  if name != "reuse_jacobian") + (("reuse_jacobian", 0),)
    header = format_table(synthetic_study("vi", 6, newton=tight)).splitlines()[1]
    assert "step sizes of order 6: 0.025, 0.04, 0.05, 0.1 s" in header
    assert "residual_tol 1e-14" in header and "reuse_jacobian every-iterate" in header
    plain = format_table(synthetic_study("vi", 2)).splitlines()[1]
    assert plain.endswith("Newton: the package's defaults")


def test_a_summary_of_different_schemes_is_refused():
    with pytest.raises(ValueError, match="different"):
        format_summary([synthetic_study("vi", 2), synthetic_study("midpoint", 4)])
