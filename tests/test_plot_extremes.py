"""chaingen plot of a sweep, or of a trajectory file, whose axis, metric or error reaches the
ends of a double's range, and of a sweep whose failed runs carry the metrics of the steps they
completed (docs/sweep-format.md, section 6). Before: an axis from 1 to 1e300 drew an empty
figure on 1..10 (matplotlib's log axis fell back), a failed run's max_energy_error of 0 was
drawn as a result."""
from __future__ import annotations

import json

import numpy as np
import pytest

from chaingen.views import sweep_plot

pd = pytest.importorskip("pandas")
pytest.importorskip("pyarrow")
pytest.importorskip("matplotlib")


def sweep_dir(tmp_path, columns: dict, axes: list[str], mode: str = "product"):
    out = tmp_path / "out"
    out.mkdir()
    (out / "sweep.json").write_text(json.dumps({
        "axes": axes, "method": "es", "spec": {"mode": mode},
        "spacing": {axis: "linear" for axis in axes},
        "units": {axis: "kg" for axis in axes}}))
    pd.DataFrame({"run": np.arange(len(next(iter(columns.values())))), **columns}).to_parquet(
        out / "runs.parquet")
    return out


@pytest.fixture
def drawn(monkeypatch):
    """The figure plot_sweep saves, kept for its axes and data."""
    figures = []
    monkeypatch.setattr(sweep_plot, "save_png", lambda figure, target: figures.append(figure)
                        or target)
    return figures


def shown(axis, x, y):
    left, right = axis.get_xlim()
    bottom, top = axis.get_ylim()
    return bool(np.all((left <= x) & (x <= right) & (bottom <= y) & (y <= top)))


def test_an_axis_and_a_metric_reaching_1e300_are_drawn_as_their_log10(tmp_path, drawn):
    mass = np.array([1.0, 1e300, 1.7e308, 1e-310])
    error = np.array([1.3e-6, 2.0e294, 3.5e302, 4.0e-15])
    out = sweep_dir(tmp_path, {"links[0].mass": mass, "status": ["ok"] * 4,
                               "max_energy_error": error, "phi1": np.zeros(4)},
                    ["links[0].mass"])
    sweep_plot.plot_sweep(out, "max_energy_error")
    axis = drawn[0].axes[0]
    (line,) = axis.get_lines()
    x, y = line.get_data()
    assert np.allclose(sorted(x), sorted(np.log10(mass))) and np.all(np.isfinite(y))
    assert axis.get_xscale() == axis.get_yscale() == "linear"
    assert axis.get_xlabel() == "log10 links[0].mass (kg)"
    assert axis.get_ylabel() == "log10 max_energy_error"
    drawn[0].canvas.draw()
    assert shown(axis, x, y)


def test_values_within_the_log_axis_keep_it(tmp_path, drawn):
    mass = np.array([1.0, 1e3, 1e6])
    out = sweep_dir(tmp_path, {"links[0].mass": mass, "status": ["ok"] * 3,
                               "max_energy_error": [1e-15, 1e-10, 1e-5], "phi1": np.zeros(3)},
                    ["links[0].mass"])
    sweep_plot.plot_sweep(out, "max_energy_error")
    axis = drawn[0].axes[0]
    assert axis.get_xscale() == axis.get_yscale() == "log"
    assert axis.get_xlabel() == "links[0].mass (kg)"


def test_failed_runs_are_not_drawn_and_the_title_says_how_many(tmp_path, drawn):
    out = sweep_dir(tmp_path, {"links[0].mass": [1.0, 2.0, 3.0],
                               "status": ["ok", "nonfinite", "ok"],
                               "max_energy_error": [2.7e-15, 0.0, 3.1e-15],
                               "phi1": [0.4, np.nan, 0.5]}, ["links[0].mass"])
    sweep_plot.plot_sweep(out, "max_energy_error")
    axis = drawn[0].axes[0]
    x, y = axis.get_lines()[0].get_data()
    assert np.isnan(y[1]) and np.all(np.isfinite(y[[0, 2]]))
    assert axis.get_title() == "es: max_energy_error over 3 runs, 1 failed (not drawn)"


def test_a_heat_map_reaching_1e300_is_drawn_in_log10(tmp_path, drawn):
    mass = np.repeat([1.0, 1e300], 2)
    stiffness = np.tile([1e-300, 1.0], 2)
    out = sweep_dir(tmp_path, {"links[0].mass": mass, "springs[0].stiffness": stiffness,
                               "status": ["ok"] * 4, "max_energy_error": [1e-15, 1e-14,
                                                                          1e290, 1e-300],
                               "phi1": np.zeros(4)},
                    ["links[0].mass", "springs[0].stiffness"])
    sweep_plot.plot_sweep(out, "max_energy_error")
    axis = drawn[0].axes[0]
    assert axis.get_xlabel() == "log10 links[0].mass (kg)"
    assert axis.get_ylabel() == "log10 springs[0].stiffness (kg)"
    assert drawn[0].axes[1].get_ylabel() == "log10 max_energy_error"
    drawn[0].canvas.draw()
    assert shown(axis, np.log10(mass), np.log10(stiffness))


# -- chaingen plot of a trajectory file --------------------------------------------------------

def test_a_trajectory_error_from_1e_300_to_1e300_is_drawn_as_its_log10(tmp_path, monkeypatch):
    """A constraint_error column from 1e-300 to 1e300 (a file edited by hand: every number
    finite): before, the log axis fell back to 1..10 and the panel showed no curve (exit 0)."""
    from chaingen.views import plots

    figures = []
    monkeypatch.setattr(plots, "save_png", lambda figure, target: figures.append(figure)
                        or target)
    errors = [0.0, 1e-300, 1e300, 1e-15, 1.0]
    rows = [f"{0.3 * k!r},0.1,0.2,0.3,0,0,0,4.19,{error!r}" for k, error in enumerate(errors)]
    path = tmp_path / "run.csv"
    path.write_text("t,phi1,phi2,phi3,omega1,omega2,omega3,energy,constraint_error\n"
                    + "\n".join(rows) + "\n")
    plots.plot_files([path], tmp_path / "run.png")
    axis = figures[0].axes[2]
    assert axis.get_yscale() == "linear" and axis.get_ylabel() == "log10 constraint error"
    (line,) = axis.get_lines()
    np.testing.assert_allclose(line.get_ydata()[1:], np.log10(errors[1:]))
    figures[0].canvas.draw()
    bottom, top = axis.get_ylim()
    assert bottom <= -300 and top >= 300
