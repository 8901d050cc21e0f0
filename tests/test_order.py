"""The time-step study (thesis 5.1.5, model.md section 8): measured orders of the schemes, at
every order option (model.md section 14)."""
from __future__ import annotations

import sys
from functools import cache

import pytest

from chaingen.errors import ChaingenError, OrderStudyError
from chaingen.runtime import NewtonOptions
from chaingen.studies.order import (
    DEFAULT_DTS,
    ROUND_OFF_NEWTON,
    allowed_orders,
    format_summary,
    format_table,
    order_dts,
    order_studies,
    order_study,
)
from chaingen.views.order_plot import plot_order

from helpers import chaingen_in_process, load, scene_path, solver_for

pytestmark = pytest.mark.compile

MONO = "three_link_mono"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
#: Gauss points of es in the studies of every order: its quadrature error is then below the
#: 1e-12 J the energy is held to (K = 3 leaves ~1e-6 J at dt = 0.2 s, see test_energy_order).
ES_QUADRATURE = 7


@cache
def study(name: str, method: str, quadrature: int, gradient: str = "exact", **kwargs):
    """The default study (dt 0.001 ... 0.2 s, t_end 10 s, dt_ref 1e-4 s), run once.
    gradient: es's discrete gradient of the springs ("quadrature": the thesis's scheme, whose
    energy error has an order)."""
    return order_study(load(name), method, quadrature, gradient=gradient,
                       solver=solver_for(name, method, quadrature, gradient=gradient), **kwargs)


@cache
def composed_solver(name: str, method: str, order: int, quadrature: int):
    """A solver of any order, built once per session (order 2: helpers' solver)."""
    if order == 2:
        return solver_for(name, method, quadrature)
    from chaingen.simulation import build_solver
    return build_solver(load(name), method, quadrature, sensitivities=False, order=order)


@cache
def every_order(name: str, method: str):
    """The study of every order `method` takes, each on its default step sizes, run once."""
    quadrature = ES_QUADRATURE if method == "es" else 3
    solvers = {order: composed_solver(name, method, order, quadrature)
               for order in allowed_orders(method)}
    return order_studies(load(name), method, quadrature, solvers=solvers)


@pytest.mark.parametrize("method, quadrature, order", [
    ("es", 1, 2), ("es", 3, 6), ("vi", 3, 2), ("midpoint", 3, 2)])
def test_energy_order(method, quadrature, order):
    """The energy error's order: es's with its springs' gradient by the quadrature alone
    (the thesis's; the exact gradient has none, test_the_exact_gradient_has_no_energy_order)."""
    result = study(MONO, method, quadrature, "quadrature" if method == "es" else "exact")
    assert result.failed_dts == ()
    tolerance = 0.5 if order == 6 else 0.3
    assert result.energy_order == pytest.approx(order, abs=tolerance), format_table(result)
    assert len(result.energy_fit_dts) >= 3


def test_the_exact_gradient_has_no_energy_order():
    """es's default gradient holds the energy to round-off at every dt of the study, K = 1 and
    K = 3 alike: there is no order to fit."""
    for quadrature in (1, 3):
        result = study(MONO, "es", quadrature)
        assert result.gradient == "exact" and result.failed_dts == ()
        assert all(row.mean_balance_error < 1e-12 * result.energy_scale for row in result.rows)
        assert result.energy_order is None


def test_gauss3_energy_error_is_sixth_order_until_round_off():
    result = study(MONO, "es", 3, "quadrature")
    energy = {row.dt: row.mean_balance_error for row in result.rows}
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
    assert result.rate_order == pytest.approx(2.0, abs=0.3), format_table(result)
    assert len(result.trajectory_fit_dts) >= 5 and len(result.rate_fit.dts) >= 5
    assert result.dt_ref == pytest.approx(1e-4) and result.t_end == 10.0
    assert result.newton_settings == ()      # order 2: the package's Newton defaults


def test_the_chain_rule_gradient_is_second_order_and_exact():
    """es with the chain rule's gradient of the springs: the trajectory's order is 2, and the
    energy is held to round-off at every dt (no order to fit)."""
    result = study(MONO, "es", 3, "chain")
    assert result.gradient == "chain" and result.failed_dts == ()
    assert result.trajectory_order == pytest.approx(2.0, abs=0.3), format_table(result)
    assert result.rate_order == pytest.approx(2.0, abs=0.3), format_table(result)
    assert all(row.mean_balance_error < 1e-12 * result.energy_scale for row in result.rows)
    assert result.energy_order is None


def test_energy_exact_without_springs_has_no_order():
    """es with gravity only conserves energy exactly: every point is at round-off."""
    result = study("three_link_gravity", "es", 3)
    assert result.quadrature is None
    assert all(row.mean_balance_error < 1e-12 * result.energy_scale for row in result.rows)
    assert result.energy_order is None and "usable" in result.energy_fit.reason
    assert result.trajectory_order == pytest.approx(2.0, abs=0.3)
    assert "energy order      --" in format_table(result)


# --- failures, validation, output ------------------------------------------------------------

def failing_study():
    """dt = 10 s is far too large for the springs: even as 16 substeps of 0.625 s (the split
    steps' limit) a spring segment turns through its fastening and the run stops there. (dt =
    2 s no longer fails: its 0.125 s substeps converge.)"""
    return study(MONO, "midpoint", 3, dts=(0.05, 0.1, 0.2, 10.0), sample_interval=10.0)


def test_a_failing_dt_is_recorded_not_raised():
    result = failing_study()
    assert result.failed_dts == (10.0,)
    row = result.rows[-1]
    assert row.failed and row.mean_balance_error is None and row.trajectory_error is None
    assert row.rate_error is None
    assert "failed" in row.failure
    assert 10.0 not in result.energy_fit_dts + result.trajectory_fit_dts
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
    result = study(MONO, "es", 3, "quadrature")
    table = format_table(result)
    lines = table.splitlines()
    assert len(lines) == 3 + len(DEFAULT_DTS) + 3
    for dt, line in zip(DEFAULT_DTS, lines[3:]):
        assert line.split()[0] == f"{dt:g}"
    assert f"energy order      {result.energy_order:.2f}" in table
    assert (f"fit over dt = {min(result.energy_fit_dts):g} ... "
            f"{max(result.energy_fit_dts):g} s") in table
    assert "trajectory order" in table
    assert "method es, quadrature 3 (gradient by the quadrature alone), order 2" in table
    assert f"rate order        {result.rate_order:.2f}" in table
    assert "rate error [rad/s]" in lines[2] and "Newton: the package's defaults" in lines[1]
    assert "0.001, 0.002, 0.005, 0.01, 0.02, 0.05, 0.1, 0.2 s" in lines[1]


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


# --- every order option ----------------------------------------------------------------------

@pytest.mark.parametrize("method", ["es", "vi", "midpoint"])
def test_every_allowed_order_is_studied_and_summarised(method):
    studies = every_order(MONO, method)
    assert tuple(study.order for study in studies) == allowed_orders(method)
    assert allowed_orders(method) == (2, 4, 6)
    summary = format_summary(studies).splitlines()
    assert "angle order" in summary[1] and "rate order" in summary[1]
    assert "energy order" in summary[1]
    rows = summary[2:]
    assert [int(row.split()[0]) for row in rows] == list(allowed_orders(method))
    for study, row in zip(studies, rows):
        assert study.failed_dts == ()
        assert study.dts == order_dts(method, study.order)
        assert row.split()[1:3] == [f"{study.trajectory_order:.2f}", f"{study.rate_order:.2f}"]
    assert ("max constraint error [m^2]" in summary[1]) == (method == "es")


@pytest.mark.parametrize("method, order, tolerance", [
    ("es", 4, 0.2), ("vi", 4, 0.2), ("vi", 6, 0.3), ("midpoint", 4, 0.2),
    ("midpoint", 6, 0.3)])
def test_composed_steps_reach_their_order_in_angles_and_rates(method, order, tolerance):
    """The issue's must-show: order 4 and 6 in the angles and in the rates (model.md 14)."""
    result = {study.order: study for study in every_order(MONO, method)}[order]
    table = format_table(result)
    assert result.trajectory_order == pytest.approx(order, abs=tolerance), table
    assert result.rate_order == pytest.approx(order, abs=tolerance), table
    assert len(result.trajectory_fit_dts) >= 4 and len(result.rate_fit.dts) >= 4
    # every fitted point is well above the round-off floor of the reference
    fitted = [row for row in result.rows if row.dt in result.trajectory_fit_dts]
    assert min(row.trajectory_error for row in fitted) > 10 * result.trajectory_floor
    assert result.dt_ref == pytest.approx(min(order_dts(method, order)) / 10)
    # Newton to round-off, and said so in the header
    assert dict(result.newton_settings)["residual_tol"] == ROUND_OFF_NEWTON["residual_tol"]
    assert "residual_tol 1e-14" in table.splitlines()[1]
    if method != "es":         # vi and midpoint: the energy error has the order of the step
        assert result.energy_order == pytest.approx(order, abs=tolerance), table


def test_es_keeps_its_energy_and_constraints_at_every_order():
    for result in every_order(MONO, "es"):
        assert result.quadrature == ES_QUADRATURE
        assert result.max_balance_error <= 1e-12, format_table(result)
        assert result.max_constraint_error <= 1e-13, format_table(result)
        assert result.energy_order is None      # at round-off: nothing to fit
    summary = format_summary(every_order(MONO, "es"))
    assert "max energy error [J]" in summary and "quadrature 7" in summary


def test_a_damped_scene_reports_the_balance_error(tmp_path):
    """four_link_actuated has joint damping and torques: its energy error is the balance."""
    name = "four_link_actuated"
    solver = composed_solver(name, "midpoint", 2, 3)
    result = order_study(load(name), "midpoint", 3, solver=solver, dts=(0.05, 0.1, 0.2),
                         t_end=2.0)
    assert result.energy_flows and result.energy_name == "balance"
    table = format_table(result)
    assert "balance error [J]" in table and "balance order" in table
    assert "energy error" not in table and "energy order" not in table
    summary = format_summary([result])
    assert "balance order" in summary and "energy order" not in summary
    pytest.importorskip("matplotlib")
    assert plot_order([result], tmp_path / "order.png").read_bytes()[:8] == PNG_SIGNATURE


def test_the_command_runs_every_order_or_the_one_asked(tmp_path):
    """Without --order: a table per order and the summary; with --order 4: that table only."""
    scene = scene_path(MONO)
    for order in (4, 2):                      # the solvers the tests above built are reused
        composed_solver(MONO, "es", order, ES_QUADRATURE)
    plot = tmp_path / "order.png"
    result = chaingen_in_process("order", scene, "--method", "es", "--quadrature", "7",
                                 "--plot", plot, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    tables = result.stdout.split("\n\n")
    assert len(tables) == 4
    assert "order 2;" in tables[0] and "order 4;" in tables[1] and "order 6;" in tables[2]
    assert tables[3].splitlines()[1].split()[:2] == ["order", "option"]
    assert plot.read_bytes()[:8] == PNG_SIGNATURE
    one = chaingen_in_process("order", scene, "--method", "es", "--quadrature", "7",
                              "--order", "4", cwd=tmp_path)
    assert one.returncode == 0, one.stderr
    assert "order 4;" in one.stdout and "order 2;" not in one.stdout
    assert "order option" not in one.stdout


@pytest.mark.parametrize("t_end", ["0.3", "1e-300"])
def test_order_names_a_t_end_off_its_sample_grid_by_its_option(tmp_path, t_end):
    """Before: 'chaingen: error: t_end must be a multiple of the sample interval: 0.2 s does
    not divide 1e-300 s', naming t_end but not its option --t-end."""
    result = chaingen_in_process("order", scene_path("three_link_mono"), "--method", "midpoint",
                                 "--order", "2", "--t-end", t_end, cwd=tmp_path)
    assert result.returncode == 2
    assert result.stderr.strip() == (
        "chaingen: error: --t-end: must be a whole multiple of the study's sample interval, "
        f"0.2 s, got {float(t_end):g}")
    assert not list(tmp_path.iterdir())
