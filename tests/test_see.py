"""Plots, the animation and progress (issue 7).

The drawn geometry is checked against the symbolic model (chaingen.symbolic.com_model, COM
coordinates), a path independent of the numpy kinematics the drawing uses. Figures and animations
are checked for what a reader gets: the file exists, is a PNG/GIF of the expected pixel size
and frame count, and carries content.
"""
from __future__ import annotations

import io
import json
import subprocess
import sys

import numpy as np
import pytest
import sympy as sp

from chaingen.errors import PlotError
from chaingen.progress import Progress, progress_enabled, set_quiet
from chaingen.runtime import write_trajectory
from chaingen.runtime.trajectory import metadata_path, read_trajectory
from chaingen.simulation import run_settings, simulate_scene
from chaingen.symbolic.com_model import com_model, joint_space_positions
from chaingen.views.animate import ChainDrawing, animate, frame_plan
from chaingen.views.plots import DPI, FIGURE_SIZE, broken_at_wraps, load_run, plot_files

from helpers import chaingen_in_process, load, require_tools, scene_path

PIL = pytest.importorskip("PIL.Image")
PNG_SIZE = (int(FIGURE_SIZE[0] * DPI), int(FIGURE_SIZE[1] * DPI))


def model_points(scene, phi):
    """Joints, COMs, chain fastenings and every spring's fastenings from the symbolic model."""
    model = com_model(scene)
    xs, ys = joint_space_positions(scene, [sp.Float(value, 30) for value in phi])
    values = dict(zip(model.q, [*xs, *ys]))
    point = lambda expression: np.array([float(sp.N(c.xreplace(values), 20))  # noqa: E731
                                         for c in expression])
    joints = np.array([point(joint) for joint in model.joints])
    coms = np.array([point(model.com_position(i)) for i in range(scene.n)])
    fastenings = np.array([point(fastening) for fastening in model.fastenings])
    springs = []
    for spring in scene.springs:
        offsets = scene.spring_fastenings(spring)
        normals = [sp.Matrix([0, 1])] + list(model.normals)
        springs.append(np.array([point(model.joints[j - 1] + sp.Float(r) * normals[j - 1])
                                 for j, r in zip(range(spring.first, spring.last + 2), offsets)]))
    return joints, coms, fastenings, springs


@pytest.mark.parametrize("name", ["three_link_multi", "five_link_biarticular",
                                  "four_link_antagonist"])
def test_the_drawing_puts_every_point_where_the_model_has_it(name):
    scene = load(name)
    phi = np.linspace(0.4, -0.9, scene.n) + 0.05 * np.arange(scene.n) ** 2
    drawing = ChainDrawing(scene)
    drawing.draw(phi, 1.25)
    drawn = drawing.drawn()
    joints, coms, fastenings, springs = model_points(scene, phi)
    np.testing.assert_allclose(drawn["joints"], joints, atol=1e-12)
    np.testing.assert_allclose(drawn["links"], joints, atol=1e-12)
    np.testing.assert_allclose(drawn["coms"], coms, atol=1e-12)
    np.testing.assert_allclose(drawn["fastenings"], fastenings, atol=1e-12)
    for stalk, joint, fastening in zip(drawn["stalks"], joints, fastenings):
        np.testing.assert_allclose(stalk, [joint, fastening], atol=1e-12)
    assert len(drawn["springs"]) == len(scene.springs) == len(springs)
    for line, points in zip(drawn["springs"], springs):
        np.testing.assert_allclose(line, points, atol=1e-12)
    assert drawing.clock.get_text() == "t =    1.25 s"


@pytest.mark.parametrize("pixels", [400, 480])
@pytest.mark.parametrize("name", ["three_link_multi", "three_link_gravity"])
def test_the_frame_keeps_its_labels_inside_and_names_units(name, pixels):
    """Every tick label (minus signs included) and axis label lies inside the frame at the
    README's 400 px and the default 480 px, and the axes carry their unit."""
    drawing = ChainDrawing(load(name), pixels=pixels, title="a title")
    drawing.draw(np.full(drawing.scene.n, -2.5), 12.5)
    renderer = drawing.figure.canvas.get_renderer()
    drawing.figure.canvas.draw()
    width, height = drawing.figure.canvas.get_width_height()
    axes = drawing.axes
    labels = [label for label in axes.get_xticklabels() + axes.get_yticklabels()
              if label.get_visible() and label.get_text()]
    labels += [axes.xaxis.label, axes.yaxis.label]
    if drawing.scene.springs:                        # the colour bar's ticks and label too
        labels += [label for label in drawing.bar.ax.get_yticklabels() if label.get_text()]
        labels.append(drawing.bar.ax.yaxis.label)
    assert any(label.get_text().startswith(("-", "\u2212")) for label in labels)
    for label in labels:
        box = label.get_window_extent(renderer)
        assert box.x0 >= 0 and box.y0 >= 0 and box.x1 <= width and box.y1 <= height, \
            (label.get_text(), box, width, height)
    assert axes.get_xlabel() == "x [m]" and axes.get_ylabel() == "y [m]"


def test_the_multi_articular_spring_runs_through_all_four_fastenings():
    scene = load("three_link_multi")
    (spring,) = scene.springs
    drawing = ChainDrawing(scene)
    drawing.draw(scene.initial_angles, 0.0)
    (line,) = drawing.drawn()["springs"]
    assert line.shape == (4, 2) and (spring.first, spring.last) == (1, 3)
    # The chain's fastenings P_1..P_4: the spring's polyline goes through each of them.
    np.testing.assert_allclose(line, drawing.drawn()["fastenings"], atol=1e-12)


def test_springs_are_coloured_by_their_stretch():
    scene = load("three_link_multi")
    drawing = ChainDrawing(scene, stretch_limit=5.0)
    colours = []
    for phi in ([0.0, 0.0, 0.0], [0.0, 1.5, 1.5]):   # straight: long spring; folded: short
        geometry = drawing.draw(phi, 0.0)
        colours.append(np.array(drawing.springs[0].get_color()))
        expected = drawing.colormap(drawing.norm(geometry.stretch[0]))
        np.testing.assert_allclose(colours[-1], expected)
    assert np.abs(colours[0] - colours[1]).max() > 0.1


# -- plots --------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Short runs of three_link_multi with each scheme, written by write_trajectory."""
    directory = tmp_path_factory.mktemp("runs")
    scene = load("three_link_multi")
    paths = {}
    for method in ("es", "vi", "midpoint"):
        result = simulate_scene(scene, run_settings(scene, method=method, t_end=2.0))
        paths[method] = write_trajectory(result, directory / f"{method}.csv")
    return paths


def png_size(path):
    with PIL.open(path) as image:
        assert image.format == "PNG"
        return image.size


@pytest.mark.compile
def test_plot_of_one_run_is_a_png_of_the_expected_size(runs, tmp_path):
    out = plot_files([runs["es"]], tmp_path)
    assert out == tmp_path / "es.png"
    assert png_size(out) == PNG_SIZE
    assert out.stat().st_size > 30_000   # three panels of curves, not an empty canvas


@pytest.mark.compile
def test_plot_overlays_several_runs_in_one_figure(runs, tmp_path):
    single = plot_files([runs["es"]], tmp_path / "one.png")
    overlay = plot_files([runs["es"], runs["vi"], runs["midpoint"]], tmp_path)
    assert overlay.name == "es_vs_vi_vs_midpoint.png"
    assert png_size(overlay) == PNG_SIZE
    assert overlay.stat().st_size > single.stat().st_size   # more curves drawn


@pytest.mark.compile
def test_plot_labels_come_from_the_metadata(runs):
    meta = json.loads(metadata_path(runs["es"]).read_text())
    assert meta["method"] == "es" and meta["quadrature"] == 3 and meta["dt"] == 0.01
    run = load_run(runs["es"])
    assert run.label == "es K=3, dt = 0.01 s" and run.scene == "three-link-multi"
    assert load_run(runs["vi"]).label == "vi, dt = 0.01 s"


@pytest.mark.compile
def test_a_trajectory_without_metadata_still_plots(runs, tmp_path):
    bare = tmp_path / "bare.csv"
    bare.write_text(runs["es"].read_text())
    run = load_run(bare)
    assert run.method is None and run.scene is None and run.dt == pytest.approx(0.01)
    assert run.label.startswith("bare")
    assert png_size(plot_files([bare], tmp_path)) == PNG_SIZE


@pytest.mark.compile
def test_the_csv_keeps_exactly_the_contract_columns(runs):
    columns, rows = read_trajectory(runs["es"])
    assert columns == ("t", "phi1", "phi2", "phi3", "omega1", "omega2", "omega3", "energy",
                       "constraint_error")
    assert rows.shape == (201, 9)


@pytest.mark.parametrize("text, message", [
    ("t,phi1,omega1,energy\n0,0,0,0\n0.1,0,0,0\n",
     "header must start with the columns t, phi1, omega1, energy, constraint_error"),
    ("t,phi1,omega1,energy,constraint_error\n0,0,0,0,0\n", "at least two samples"),
    ("t,phi1,omega1,energy,constraint_error\n0,0,0,0,0\n0,0,0,0,0\n", "time column must increase"),
    ("t,phi1,omega1,energy,constraint_error\n0,0,0,0,0\n1,nan,0,0,0\n",
     "row 3 holds a value that is not finite"),
    ("t,x\n0,a\n", "not a trajectory file"),
])
def test_bad_trajectory_files_are_refused_by_name(tmp_path, text, message):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(PlotError, match=message) as error:
        plot_files([path], tmp_path)
    assert str(path) in str(error.value)
    assert not list(tmp_path.glob("*.png"))


def test_wrapped_angles_break_the_line_instead_of_striking_across():
    angle = np.array([3.0, 3.1, -3.1, -3.0])
    shown = broken_at_wraps(angle)
    assert np.isnan(shown[2]) and np.array_equal(shown[[0, 1, 3]], angle[[0, 1, 3]])


# -- animation -----------------------------------------------------------------------------

def test_frame_plan_plays_in_real_time_by_default():
    t = np.arange(0, 2.0 + 1e-9, 0.01)
    plan = frame_plan(t)
    assert plan.every == 4 and plan.fps == 25.0 and plan.playback_speed == pytest.approx(1.0)
    assert plan.indices[0] == 0 and plan.indices.size == 51
    sparse = frame_plan(np.arange(0, 10.0, 0.1))   # samples sparser than 25 fps: every one
    assert sparse.every == 1 and sparse.fps == pytest.approx(10.0)
    chosen = frame_plan(t, fps=10, every=2)
    assert chosen.every == 2 and chosen.fps == 10.0
    with pytest.raises(PlotError, match="--every: must be >= 1"):
        frame_plan(t, every=0)


def test_frame_plan_of_an_every_beyond_the_samples_is_the_first_sample_at_a_gif_rate():
    """--every 99999999999 on 101 samples (an internal OverflowError before: the GIF frame of
    1 / (every dt) fps lasted more than a 16-bit count of hundredths), or beyond int64 (an
    IndexError): one frame, the first sample, at a rate a GIF can hold."""
    t = np.arange(0, 1.0 + 1e-9, 0.01)
    for every in (99_999_999_999, 10 ** 20):
        plan = frame_plan(t, every=every)
        assert plan.indices.tolist() == [0] and plan.every == every
        assert 0.01 <= plan.fps and 1000.0 / plan.fps / 10 <= 65535
    # The slowest --fps on samples far apart: a frame every 100 s, every sample.
    slow = frame_plan(np.arange(0, 1000.0, 100.0), fps=0.01)
    assert slow.every == 1 and slow.fps == pytest.approx(0.01)


@pytest.mark.compile
def test_animation_of_a_short_run_is_a_gif_of_the_expected_frames(runs, tmp_path):
    scene = load("three_link_multi")
    out, plan = animate(scene, load_run(runs["es"]), tmp_path / "chain.gif", pixels=240)
    with PIL.open(out) as image:
        assert image.format == "GIF" and image.size == (240, 240)
        assert image.n_frames == plan.indices.size == 51
        assert image.info["duration"] == 40
        first = np.asarray(image.convert("RGB")).copy()
        image.seek(50)
        last = np.asarray(image.convert("RGB"))
    assert np.abs(first.astype(int) - last).max() > 0   # the chain moved
    assert out.stat().st_size > 20_000


@pytest.mark.compile
def test_animation_refuses_a_trajectory_of_another_scene(runs, tmp_path):
    with pytest.raises(PlotError, match="written for scene 'three-link-multi'"):
        animate(load("three_link_mono"), load_run(runs["es"]), tmp_path / "x.gif")
    with pytest.raises(PlotError, match="5 links"):
        animate(load("five_link_biarticular"), load_run(runs["es"]), tmp_path / "x.gif")
    with pytest.raises(PlotError, match="give a .gif or .mp4"):
        animate(load("three_link_multi"), load_run(runs["es"]), tmp_path / "x.avi")
    assert not list(tmp_path.iterdir())


# -- progress ------------------------------------------------------------------------------

class Terminal(io.StringIO):
    def isatty(self):
        return True


def test_progress_draws_on_a_terminal_and_erases_itself(monkeypatch):
    monkeypatch.delenv("CI", raising=False)
    monkeypatch.delenv("CHAINGEN_QUIET", raising=False)
    stream = Terminal()
    assert progress_enabled(stream)
    with Progress("simulate", total=10, unit="steps", stream=stream) as progress:
        progress.update(10)
    text = stream.getvalue()
    assert "simulate [" in text and "10/10 steps" in text
    assert text.endswith("\r")   # erased: the terminal keeps only the work's own output


def test_quiet_holds_for_one_command_only(tmp_path, monkeypatch):
    """--quiet of a command run in this process (tests, a notebook) does not silence the
    progress of what runs after it: it once did, and a later progress test in the same worker
    saw nothing drawn."""
    monkeypatch.delenv("CI", raising=False)
    monkeypatch.delenv("CHAINGEN_QUIET", raising=False)
    result = chaingen_in_process("-q", "simulate", tmp_path / "missing.toml", cwd=tmp_path)
    assert result.returncode == 2
    assert progress_enabled(Terminal())


@pytest.mark.parametrize("setting", ["not a terminal", "CI", "CHAINGEN_QUIET", "--quiet"])
def test_progress_is_silent_in_logs_ci_and_quiet(monkeypatch, setting):
    monkeypatch.delenv("CI", raising=False)
    monkeypatch.delenv("CHAINGEN_QUIET", raising=False)
    stream = io.StringIO() if setting == "not a terminal" else Terminal()
    if setting == "CI":
        monkeypatch.setenv("CI", "true")
    if setting == "CHAINGEN_QUIET":
        monkeypatch.setenv("CHAINGEN_QUIET", "1")
    set_quiet(setting == "--quiet")
    try:
        with Progress("work", total=3, stream=stream) as progress:
            for done in range(4):
                progress.update(done)
    finally:
        set_quiet(False)
    assert stream.getvalue() == ""


# -- command line --------------------------------------------------------------------------

def chaingen(*args, cwd):
    return subprocess.run([sys.executable, "-m", "chaingen", *map(str, args)], cwd=cwd,
                          capture_output=True, text=True)


@pytest.mark.compile
def test_simulate_plot_and_animate_from_the_command_line(tmp_path):
    scene = scene_path("three_link_multi")
    run = chaingen("simulate", scene, "--t-end", "1", "--out", "multi.csv", "--plot", cwd=tmp_path)
    assert run.returncode == 0, run.stderr
    assert "\r" not in run.stderr   # not a terminal: no progress bar
    assert png_size(tmp_path / "multi.png") == PNG_SIZE
    plot = chaingen("plot", "multi.csv", "-o", "figures", cwd=tmp_path)
    assert plot.returncode == 0, plot.stderr
    assert png_size(tmp_path / "figures" / "multi.png") == PNG_SIZE
    gif = chaingen("animate", scene, "multi.csv", "-o", "chain.gif", "--size", "200",
                   cwd=tmp_path)
    assert gif.returncode == 0, gif.stderr
    with PIL.open(tmp_path / "chain.gif") as image:
        assert image.size == (200, 200) and image.n_frames == 26


@pytest.mark.compile
def test_animate_straight_from_a_scene(tmp_path):
    result = chaingen("animate", scene_path("three_link_gravity"), "--t-end", "0.4",
                      "-o", "gravity.gif", "--size", "160", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    with PIL.open(tmp_path / "gravity.gif") as image:
        assert image.size == (160, 160) and image.n_frames == 11


@pytest.mark.parametrize("args, message", [
    (["plot", "missing.csv"], "missing.csv: no such trajectory file"),
    (["animate", "SCENE", "-o", "x.webm"], "give a .gif or .mp4"),
    (["animate", "SCENE", "--fps", "0", "-o", "x.gif"], "--fps: must be from 0.01"),
    # A frame every 1e300 s: every sample 1e302 apart would not index (IndexError before).
    (["animate", "SCENE", "--fps", "1e-300", "-o", "x.gif"],
     "--fps: must be from 0.01 (a frame every 100 s) to 100, got 1e-300"),
])
def test_bad_plot_and_animate_input_exits_2_without_traceback(tmp_path, args, message):
    args = [str(scene_path("three_link_gravity")) if arg == "SCENE" else arg for arg in args]
    result = chaingen(*args, "--t-end", "0.1", cwd=tmp_path) if args[0] == "animate" \
        else chaingen(*args, cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert message in result.stderr and "Traceback" not in result.stderr
    assert not [p for p in tmp_path.iterdir() if p.suffix in (".gif", ".png", ".mp4")]


@pytest.mark.compile
def test_the_readme_figures_are_written_by_their_script(tmp_path):
    from chaingen.views.readme_figures import write_figures

    written = write_figures(tmp_path, t_end=0.4)
    assert sorted(path.name for path in written) == [
        "three_link_gravity.png", "three_link_mono.png", "three_link_multi.gif",
        "three_link_multi.png"]
    assert png_size(tmp_path / "three_link_mono.png") == PNG_SIZE
    with PIL.open(tmp_path / "three_link_multi.gif") as image:
        assert image.n_frames == 11      # 0.4 s at 25 frames a second, and t = 0


# -- the observed simulation ---------------------------------------------------------------

@pytest.mark.compile
def test_observing_a_simulation_does_not_change_it():
    from helpers import solver_for
    scene = load("three_link_mono")
    solver = solver_for("three_link_mono", "es")
    seen = []
    plain = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                            n_steps=1000, every=3)
    observed = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                               n_steps=1000, every=3, progress=seen.append)
    assert np.array_equal(plain.samples, observed.samples)
    assert seen == sorted(seen) and seen[-1] == 1000   # polled while it runs, and at its end


@pytest.mark.compile
@pytest.mark.parametrize("raised", [KeyboardInterrupt, ZeroDivisionError])
def test_an_exception_in_the_progress_callback_stops_the_run_and_propagates(raised):
    """Ctrl-C in a progress callback, or any error of its own, ends the run promptly (10^8
    steps would take minutes) and arrives as itself."""
    import time

    from helpers import solver_for
    scene = load("three_link_mono")
    solver = solver_for("three_link_mono", "es")

    def interrupt(steps):
        if steps > 0:
            raise raised("from the callback")

    started = time.perf_counter()
    with pytest.raises(raised, match="from the callback"):
        solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                        n_steps=10 ** 8, every=10 ** 6, progress=interrupt)
    assert time.perf_counter() - started < 2.0


def test_generation_reports_its_stages():
    from chaingen.generate.package import GENERATE_STAGES, generate_package
    notes = []

    class Recorder(Progress):
        def update(self, done, note=None):
            notes.append((done, note))
            super().update(done, note)

    with Recorder("generate", total=GENERATE_STAGES, enabled=False) as progress:
        generate_package(load("three_link_gravity"), "es", 1, sensitivities=False,
                         progress=progress)
    assert [done for done, _ in notes] == [0, 1, 2, GENERATE_STAGES]
    assert "SymPy" in notes[0][1] and "CasADi" in notes[1][1]


@pytest.mark.tools
def test_animation_as_mp4_with_ffmpeg(runs, tmp_path):
    require_tools("ffmpeg")    # .ci/run installs it: there a missing ffmpeg fails, not skips
    out, plan = animate(load("three_link_multi"), load_run(runs["es"]), tmp_path / "chain.mp4",
                        pixels=240)
    assert out.read_bytes()[4:8] == b"ftyp" and plan.indices.size == 51


@pytest.mark.compile
def test_mp4_without_ffmpeg_is_refused_with_the_way_out(runs, tmp_path, monkeypatch):
    monkeypatch.setenv("PATH", str(tmp_path))   # no ffmpeg here
    with pytest.raises(PlotError, match="MP4 needs ffmpeg on the PATH.*write a .gif instead"):
        animate(load("three_link_multi"), load_run(runs["es"]), tmp_path / "chain.mp4")
    assert not list(tmp_path.iterdir())


@pytest.mark.compile
@pytest.mark.parametrize("where", ["before", "after"])
def test_quiet_is_taken_before_or_after_the_command(tmp_path, where):
    scene = scene_path("three_link_gravity")
    args = (["--quiet", "simulate", scene] if where == "before"
            else ["simulate", scene, "--quiet"])
    result = chaingen(*args, "--t-end", "0.1", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "three-link-gravity: method es" in result.stdout
