"""The time-step study (thesis 5.1.5, model.md section 8): measured orders of the schemes."""
from __future__ import annotations

import sys
from functools import cache

import pytest

from chaingen.errors import ChaingenError, OrderStudyError
from chaingen.runtime import NewtonOptions
from chaingen.studies.order import DEFAULT_DTS, format_table, order_study
from chaingen.views.order_plot import plot_order

from helpers import load, solver_for

pytestmark = pytest.mark.compile

MONO = "three_link_mono"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


@cache
def study(name: str, method: str, quadrature: int, **kwargs):
    """The default study (dt 0.001 ... 0.2 s, t_end 10 s, dt_ref 1e-4 s), run once."""
    return order_study(load(name), method, quadrature,
                       solver=solver_for(name, method, quadrature), **kwargs)


@pytest.mark.parametrize("method, quadrature, order", [
    ("es", 1, 2), ("es", 3, 6), ("vi", 3, 2), ("midpoint", 3, 2)])
def test_energy_order(method, quadrature, order):
    result = study(MONO, method, quadrature)
    assert result.failed_dts == ()
    tolerance = 0.5 if order == 6 else 0.3
    assert result.energy_order == pytest.approx(order, abs=tolerance), format_table(result)
    assert len(result.energy_fit_dts) >= 3


def test_gauss3_energy_error_is_sixth_order_until_round_off():
    result = study(MONO, "es", 3)
    energy = {row.dt: row.energy_error for row in result.rows}
    # the largest steps are in the asymptotic regime: halving dt divides the error by ~2^6
    assert 2 ** 5.5 < energy[0.2] / energy[0.1] < 2 ** 6.5
    # the small steps are at round-off, and the fit leaves them out
    floor_dts = [dt for dt, error in energy.items() if error < result.energy_floor]
    assert floor_dts and max(floor_dts) <= 0.01
    assert all(energy[dt] < 1e-12 * result.energy_scale for dt in floor_dts)
    assert not set(floor_dts) & set(result.energy_fit_dts)
    assert {0.05, 0.1, 0.2} <= set(result.energy_fit_dts)


@pytest.mark.parametrize("method, quadrature", [
    ("es", 1), ("es", 3), ("vi", 3), ("midpoint", 3)])
def test_trajectory_order_is_two(method, quadrature):
    result = study(MONO, method, quadrature)
    assert result.trajectory_order == pytest.approx(2.0, abs=0.3), format_table(result)
    assert len(result.trajectory_fit_dts) >= 5
    assert result.dt_ref == pytest.approx(1e-4) and result.t_end == 10.0


def test_energy_exact_without_springs_has_no_order():
    """es with gravity only conserves energy exactly: every point is at round-off."""
    result = study("three_link_gravity", "es", 3)
    assert result.quadrature is None
    assert all(row.energy_error < 1e-12 * result.energy_scale for row in result.rows)
    assert result.energy_order is None and "usable" in result.energy_fit.reason
    assert result.trajectory_order == pytest.approx(2.0, abs=0.3)
    assert "energy order      --" in format_table(result)


# --- failures, validation, output ------------------------------------------------------------

def failing_study():
    """dt = 2 s is far too large for the springs: the run stops at a failed step."""
    return study(MONO, "midpoint", 3, dts=(0.05, 0.1, 0.2, 2.0), sample_interval=2.0)


def test_a_failing_dt_is_recorded_not_raised():
    result = failing_study()
    assert result.failed_dts == (2.0,)
    row = result.rows[-1]
    assert row.failed and row.energy_error is None and row.trajectory_error is None
    assert "failed" in row.failure
    assert 2.0 not in result.energy_fit_dts + result.trajectory_fit_dts
    assert result.trajectory_order == pytest.approx(2.0, abs=0.3)
    assert all(not row.failed for row in result.rows[:-1])
    table = format_table(result)
    assert f"failed: {row.failure}" in table


def test_a_failing_reference_raises():
    with pytest.raises(OrderStudyError, match="reference run"):
        order_study(load(MONO), "es", 3, solver=solver_for(MONO, "es", 3), dts=(0.1, 0.2),
                    options=NewtonOptions(max_iterations=1))


@pytest.mark.parametrize("kwargs, message", [
    ({"dts": (0.003, 0.01)}, "does not divide"),
    ({"t_end": 1.1}, "multiple of the sample interval"),
    ({"dts": (0.01, 0.02), "dt_ref": 0.01}, "dt_ref"),
    ({"dts": (0.01, 0.01)}, "repeat"),
])
def test_bad_settings_are_refused(kwargs, message):
    with pytest.raises(OrderStudyError, match=message):
        order_study(load(MONO), "es", 3, solver=solver_for(MONO, "es", 3), **kwargs)


def test_a_solver_of_another_scheme_is_refused():
    with pytest.raises(OrderStudyError, match="given solver"):
        order_study(load(MONO), "es", 1, solver=solver_for(MONO, "es", 3), dts=(0.1, 0.2))


def test_table_lists_every_dt_and_the_fits():
    result = study(MONO, "es", 3)
    table = format_table(result)
    lines = table.splitlines()
    assert len(lines) == 2 + len(DEFAULT_DTS) + 2
    for dt, line in zip(DEFAULT_DTS, lines[2:]):
        assert line.split()[0] == f"{dt:g}"
    assert f"energy order      {result.energy_order:.2f}" in table
    assert (f"fit over dt = {min(result.energy_fit_dts):g} ... "
            f"{max(result.energy_fit_dts):g} s") in table
    assert "trajectory order" in table and "method es, quadrature 3" in table


@pytest.mark.parametrize("which", ["mono", "failing"])
def test_plot_writes_a_png(tmp_path, which):
    pytest.importorskip("matplotlib")
    result = study(MONO, "es", 3) if which == "mono" else failing_study()
    path = plot_order(result, tmp_path / "order.png")
    assert path.read_bytes()[:8] == PNG_SIGNATURE
    assert path.stat().st_size > 10_000


def test_plot_without_matplotlib_is_a_clear_error(tmp_path, monkeypatch):
    for module in ("matplotlib", "matplotlib.figure", "matplotlib.backends.backend_agg"):
        monkeypatch.setitem(sys.modules, module, None)
    with pytest.raises(ChaingenError, match="needs matplotlib"):
        plot_order(study(MONO, "es", 3), tmp_path / "order.png")
    assert not (tmp_path / "order.png").exists()
