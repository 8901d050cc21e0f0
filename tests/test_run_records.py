"""What a run's summary and records say is what they are (issue 30's review).

- `simulate --every N` prints maxima of the energy and constraint errors taken over the kept
  samples only (the C loop tracks no error of its own): with N > 1 each says so, naming the
  samples and the stride; with N = 1 it is the maximum over every step, unlabelled.
- A trajectory's metadata records the run-time parameters' values the run took; `animate`
  draws the scene with them, and `plot`'s overlay names those that differ between runs.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from chaingen.runtime.results import SimulationResult
from chaingen.runtime.trajectory import metadata_path, write_trajectory

from helpers import chaingen_in_process, scene_path

MONO = scene_path("three_link_mono")
COLUMNS = ("t", "phi1", "phi2", "phi3", "omega1", "omega2", "omega3", "energy",
           "constraint_error")


def result_of(rows: np.ndarray, *, every: int = 1, n_steps: int | None = None,
              parameters: dict | None = None) -> SimulationResult:
    return SimulationResult(scene="three-link-mono", method="vi", quadrature=None, dt=0.01,
                            n_steps=n_steps if n_steps is not None else
                            (rows.shape[0] - 1) * every,
                            every=every, columns=COLUMNS, samples=rows, wall_time=0.01,
                            newton_iterations=10, max_newton_iterations=3,
                            parameters=parameters or {})


def fake_rows(count: int, dt: float = 0.01, every: int = 1) -> np.ndarray:
    rows = np.zeros((count, len(COLUMNS)))
    rows[:, 0] = np.arange(count) * dt * every
    rows[:, 1] = 0.1 * np.sin(rows[:, 0])
    rows[:, 7] = 1.0 + 1e-5 * np.arange(count)          # energy
    rows[:, 8] = 1e-15
    return rows


def summary_lines(stdout: str) -> dict[str, str]:
    return {line[2:25].strip(): line[25:].strip() for line in stdout.splitlines()[1:]}


# -- point 1: maxima over the kept samples say so --------------------------------------------

def test_summary_maxima_over_kept_samples_say_over_what(tmp_path, monkeypatch):
    """5000 steps kept every 997: six samples. The maxima are over those six, and the lines
    say so (not a bare "max |energy error|", which reads as the run's maximum)."""
    import chaingen.simulation

    def fake(scene, settings, **_):
        assert settings.every == 997
        return result_of(fake_rows(6, every=997), every=997, n_steps=5000)
    monkeypatch.setattr(chaingen.simulation, "simulate_scene", fake)
    result = chaingen_in_process("simulate", MONO, "--method", "vi", "--every", "997",
                                 "--quiet", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    fields = summary_lines(result.stdout)
    over = "over the 6 samples kept (every 997 steps)"
    for name in ("max |energy error|", "max |constraint error|"):
        assert fields[name].endswith(over), (name, fields[name])
    assert fields["max |energy error|"].startswith("5.000e-05 J")


def test_summary_maxima_of_every_step_are_unlabelled(tmp_path, monkeypatch):
    import chaingen.simulation

    monkeypatch.setattr(chaingen.simulation, "simulate_scene",
                        lambda scene, settings, **_: result_of(fake_rows(11)))
    result = chaingen_in_process("simulate", MONO, "--quiet", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    fields = summary_lines(result.stdout)
    assert fields["max |energy error|"] == "1.000e-04 J"
    assert fields["max |constraint error|"] == "1.000e-15"


@pytest.mark.compile
def test_a_coarse_summary_states_its_samples_and_every_step_gives_the_true_maximum(tmp_path):
    """The review's case: vi on three_link_mono. Every 997 steps the kept samples miss the
    run's largest energy error; the line says over which samples, and --every 1 gives the
    maximum over every step, larger."""
    coarse = chaingen_in_process("simulate", MONO, "--method", "vi", "--every", "997",
                                 "--quiet", cwd=tmp_path)
    every = chaingen_in_process("simulate", MONO, "--method", "vi", "--quiet", cwd=tmp_path)
    assert coarse.returncode == 0 and every.returncode == 0, coarse.stderr + every.stderr
    coarse_line = summary_lines(coarse.stdout)["max |energy error|"]
    every_line = summary_lines(every.stdout)["max |energy error|"]
    assert coarse_line.endswith("over the 6 samples kept (every 997 steps)"), coarse_line
    assert every_line.endswith(" J"), every_line
    assert float(coarse_line.split()[0]) < float(every_line.split()[0])


# -- point 5: run-time parameters in the metadata, used by animate and plot --------------------

def write_run(path, rows, parameters) -> None:
    write_trajectory(result_of(rows, parameters=parameters), path)


def test_the_metadata_records_the_run_time_parameters(tmp_path):
    path = tmp_path / "run.csv"
    write_run(path, fake_rows(3), {"links[0].length": 2.0, "gravity": 9.81})
    meta = json.loads(metadata_path(path).read_text())
    assert meta["parameters"] == {"links[0].length": 2.0, "gravity": 9.81}
    write_run(tmp_path / "plain.csv", fake_rows(3), {})
    assert "parameters" not in json.loads(metadata_path(tmp_path / "plain.csv").read_text())


def drawn_joints(tmp_path, monkeypatch, trajectory) -> list[np.ndarray]:
    """The joints of every frame `chaingen animate MONO trajectory` draws."""
    from chaingen.views import animate

    frames = []
    real_draw = animate.ChainDrawing.draw

    def draw(self, phi, t):
        geometry = real_draw(self, phi, t)
        frames.append(geometry.joints)
        return geometry
    monkeypatch.setattr(animate.ChainDrawing, "draw", draw)
    result = chaingen_in_process("animate", MONO, trajectory, "-o", "run.gif", "--size", "200",
                                 "--quiet", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    return frames


def test_animate_draws_the_geometry_the_run_had(tmp_path, monkeypatch):
    """A run with links[0].length = 2 (the scene file says 1 m): its first link is drawn 2 m
    long in every frame."""
    pytest.importorskip("matplotlib")
    pytest.importorskip("PIL")
    write_run(tmp_path / "long.csv", fake_rows(4), {"links[0].length": 2.0,
                                                    "links[1].mass": 1.5})
    frames = drawn_joints(tmp_path, monkeypatch, "long.csv")
    assert frames
    for joints in frames:
        assert np.linalg.norm(joints[1] - joints[0]) == pytest.approx(2.0, rel=1e-12)
        assert np.linalg.norm(joints[2] - joints[1]) == pytest.approx(1.0, rel=1e-12)


@pytest.mark.parametrize("parameters, fragment", [
    ({"links[7].length": 2.0}, "links[7]"),           # no such link in this scene
    ({"links[0].length": -1.0}, "links[0].length"),   # a length the scene format refuses
])
def test_animate_refuses_parameters_the_scene_cannot_take(tmp_path, parameters, fragment):
    write_run(tmp_path / "run.csv", fake_rows(4), parameters)
    result = chaingen_in_process("animate", MONO, "run.csv", "-o", "run.gif", "--quiet",
                                 cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and fragment in lines[0] and "run.csv.json" in lines[0], lines
    assert not (tmp_path / "run.gif").exists()


def test_plot_names_the_parameters_that_differ_between_overlaid_runs(tmp_path, monkeypatch):
    """Two runs of one solver, links[0].mass 1 and 2, gravity equal: the legend tells them
    apart by the mass (and does not list gravity)."""
    pytest.importorskip("matplotlib")
    from chaingen.views import plots

    write_run(tmp_path / "light.csv", fake_rows(5), {"links[0].mass": 1.0, "gravity": 9.81})
    write_run(tmp_path / "heavy.csv", fake_rows(5), {"links[0].mass": 2.0, "gravity": 9.81})
    legends = []
    real_save = plots.save_png

    def save(figure, path):
        for axes in figure.axes:
            legend = axes.get_legend()
            if legend is not None:
                legends.append([text.get_text() for text in legend.get_texts()])
        return real_save(figure, path)
    monkeypatch.setattr(plots, "save_png", save)
    result = chaingen_in_process("plot", "light.csv", "heavy.csv", "-o", "both.png",
                                 cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    texts = [text for legend in legends for text in legend]
    assert any(text.endswith("links[0].mass = 1") for text in texts), texts
    assert any(text.endswith("links[0].mass = 2") for text in texts), texts
    assert not any("gravity" in text for text in texts), texts


def test_plot_refuses_wrongly_typed_parameters(tmp_path):
    path = tmp_path / "run.csv"
    write_run(path, fake_rows(3), {})
    meta = json.loads(metadata_path(path).read_text())
    meta["parameters"] = {"links[0].mass": "heavy"}
    metadata_path(path).write_text(json.dumps(meta))
    result = chaingen_in_process("plot", "run.csv", "-o", "run.png", cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert "'parameters'" in result.stderr and "run.csv.json" in result.stderr


def test_a_frame_too_small_for_the_springs_colour_bar_is_bad_input(tmp_path):
    """--size 100 was accepted for a scene with springs, whose colour bar takes 104 pixels:
    an internal error (a negative width). Now one line naming --size, exit status 2."""
    pytest.importorskip("matplotlib")
    write_run(tmp_path / "run.csv", fake_rows(4), {})
    result = chaingen_in_process("animate", MONO, "run.csv", "-o", "run.gif", "--size", "100",
                                 "--quiet", cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert result.stderr.startswith("chaingen: error: --size: must be between 200 and 4000")
    assert not (tmp_path / "run.gif").exists()
