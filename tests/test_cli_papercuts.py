"""Help, docs and views that disagree with the program (issue 30, point 16), and bad input that
ended in an internal error (point 11: `check --seed -5`, wrongly typed trajectory metadata)."""
from __future__ import annotations

import importlib.resources
import io
import json
import re
import shutil
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from chaingen.cli import parser
from chaingen.scene import METHODS, ORDERS
from chaingen.studies.order import allowed_orders
from chaingen.symbolic.composition import quadrature_error

from helpers import ROOT, chaingen_in_process, scene_path

MONO = scene_path("three_link_mono")


def help_of(command: str) -> str:
    subparsers = next(action for action in parser()._actions
                      if action.dest == "command")
    return " ".join(subparsers.choices[command].format_help().split())


# -- the orders the help promises are the orders the program takes -----------------------------

def test_the_order_help_says_what_the_program_takes():
    """es reaches order 6 (its Galerkin step, K >= 2): no help says '4 at most' or '2 and 4'."""
    for method in METHODS:
        assert allowed_orders(method) == ORDERS
    assert quadrature_error("es", 6, 1) and quadrature_error("es", 6, 2) is None
    for command in ("simulate", "generate", "check", "animate", "order"):
        text = help_of(command)
        assert "4 at most" not in text and "es: 2 and 4" not in text, command
        assert "every method: 2, 4 and 6" in text and "K >= 2" in text, command


def test_order_offers_no_adaptive_tolerances():
    """order fits fixed steps: --rtol and --atol are not offered (and not taken)."""
    text = help_of("order")
    assert "--rtol" not in text and "--atol" not in text
    assert "--rtol" in help_of("simulate")
    result = chaingen_in_process("order", MONO, "--rtol", "1e-6", cwd=ROOT)
    assert result.returncode == 2 and "--rtol" in result.stderr


# -- check --seed ------------------------------------------------------------------------------

@pytest.mark.parametrize("seed", ["-5", str(2 ** 64), "x"])
def test_check_refuses_a_seed_numpy_cannot_take(tmp_path, seed):
    """Refused by the argument parser, before SymPy or a build."""
    started = time.perf_counter()
    result = chaingen_in_process("check", MONO, "--seed", seed, cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert "--seed" in result.stderr.strip().splitlines()[-1]
    assert time.perf_counter() - started < 5


# -- the trajectory's metadata: written in full, documented, read strictly ----------------------

def fake_result(**changes):
    from chaingen.runtime.results import SimulationResult

    columns = ("t", "phi1", "phi2", "phi3", "omega1", "omega2", "omega3", "energy",
               "constraint_error")
    rows = np.zeros((4, len(columns)))
    rows[:, 0] = np.arange(4) * 0.01
    rows[:, 1] = [0.1, 0.2, 0.3, 0.4]
    values = dict(scene="three_link_mono", method="es", quadrature=3, dt=0.01, n_steps=3,
                  every=1, columns=columns, samples=rows, wall_time=0.01,
                  newton_iterations=3, max_newton_iterations=1)
    return SimulationResult(**{**values, **changes})


def test_the_metadata_records_the_tolerances_and_the_docs_every_key():
    from chaingen.runtime.trajectory import run_metadata

    meta = run_metadata(fake_result(adaptive=True, rtol=1e-6, atol=1e-8, accepted_steps=5,
                                    rejected_steps=1, smallest_dt=0.001, largest_dt=0.005))
    assert (meta["rtol"], meta["atol"]) == (1e-6, 1e-8)
    fixed = run_metadata(fake_result())
    assert (fixed["rtol"], fixed["atol"]) == (0.0, 0.0) and "adaptive_steps" not in fixed
    section = (ROOT / "docs" / "scene-format.md").read_text().split("## 12.")[1]
    documented = set(re.findall(r"^\| `(\w+)` \|", section, re.MULTILINE))
    assert set(meta) <= documented, set(meta) - documented
    for counter in meta["adaptive_steps"]:
        assert f"`{counter}`" in section, counter


def write_trajectory_with(tmp_path, metadata: dict):
    from chaingen.runtime.trajectory import write_trajectory

    path = write_trajectory(fake_result(), tmp_path / "run.csv")
    (tmp_path / "run.csv.json").write_text(json.dumps(metadata))
    return path


@pytest.mark.parametrize("key, value", [("dt", "fast"), ("quadrature", "3"), ("scene", 5),
                                        ("method", ["es"]), ("order", 5), ("dt", -0.01),
                                        ("order", True)])
def test_wrongly_typed_metadata_is_one_line_naming_the_key_and_file(tmp_path, key, value):
    path = write_trajectory_with(tmp_path, {"scene": "three_link_mono", "method": "es",
                                            key: value})
    result = chaingen_in_process("plot", path, "-o", tmp_path / "figure.png", cwd=tmp_path)
    assert result.returncode == 2, result.stdout + result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and f"'{key}'" in lines[0] and "run.csv.json" in lines[0], lines
    assert not (tmp_path / "figure.png").exists()


def test_metadata_that_is_not_an_object_is_refused(tmp_path):
    path = write_trajectory_with(tmp_path, {})
    (tmp_path / "run.csv.json").write_text("[1, 2]")
    result = chaingen_in_process("plot", path, "-o", tmp_path / "figure.png", cwd=tmp_path)
    assert result.returncode == 2 and "JSON object" in result.stderr


# -- simulate --plot without matplotlib writes nothing; the hint names the source tree ----------

def test_simulate_plot_without_matplotlib_writes_nothing(tmp_path, monkeypatch):
    import chaingen.simulation

    def simulated(scene, settings, **_):
        return fake_result(scene=scene.name)
    monkeypatch.setattr(chaingen.simulation, "simulate_scene", simulated)
    for module in [name for name in sys.modules if name.split(".")[0] == "matplotlib"]:
        monkeypatch.delitem(sys.modules, module)
    monkeypatch.setitem(sys.modules, "matplotlib", None)     # import matplotlib fails
    shutil.copy(MONO, tmp_path / "scene.toml")
    result = chaingen_in_process("simulate", "scene.toml", "--out", "run.csv", "--plot",
                                 cwd=tmp_path)
    assert result.returncode == 2, result.stdout + result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "matplotlib" in lines[0]
    assert "source tree" in lines[0] and "pip install 'chaingen[plot]'" not in lines[0]
    assert sorted(path.name for path in tmp_path.iterdir()) == ["scene.toml"]


# -- shipped scenes by name, from any directory ---------------------------------------------------

def test_a_shipped_scene_is_named_from_any_directory(tmp_path):
    from chaingen.scene import load_reference_scene, load_scene
    from chaingen.scene.shipped import scene_file

    shipped = importlib.resources.files("chaingen.scenes") / "three_link_mono.toml"
    assert scene_file("three_link_mono") == shipped == scene_file("three_link_mono.toml")
    assert load_scene("three_link_mono") == load_reference_scene("three_link_mono")
    result = chaingen_in_process("export", "three_link_mono", "--mjcf", "mono.xml",
                                 cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert 'model="three-link-mono"' in (tmp_path / "mono.xml").read_text()
    (tmp_path / "three_link_mono.toml").write_text("not toml [")   # a file of that name wins
    result = chaingen_in_process("export", "three_link_mono.toml", "--mjcf", "x.xml",
                                 cwd=tmp_path)
    assert result.returncode == 2 and "TOML syntax error" in result.stderr


# -- the overlay draws every joint ----------------------------------------------------------------

def test_the_overlay_draws_every_joint_distinctly(tmp_path, monkeypatch):
    """Two runs of a 5-link chain: each run's five angle curves have five different line
    styles, and the legend names phi1 .. phi5."""
    from chaingen.views import plots

    columns = (["t"] + [f"phi{i}" for i in range(1, 6)] + [f"omega{i}" for i in range(1, 6)]
               + ["energy", "constraint_error"])
    paths = []
    for name in ("a", "b"):
        rows = np.zeros((5, len(columns)))
        rows[:, 0] = np.arange(5) * 0.01
        rows[:, 1:6] = np.arange(1, 6) * 0.1
        path = tmp_path / f"{name}.csv"
        path.write_text(",".join(columns) + "\n" + "\n".join(",".join(map(str, row))
                                                            for row in rows) + "\n")
        paths.append(path)
    drawn = []
    monkeypatch.setattr(plots, "save_png", lambda figure, out: drawn.append(figure) or out)
    plots.plot_files(paths, tmp_path / "overlay.png")
    angles = drawn[0].axes[0]
    lines = [line for line in angles.get_lines() if len(line.get_xdata())]
    assert len(lines) == 10
    for run in range(2):
        # matplotlib keeps a custom dash pattern only here (get_linestyle says '--' for all)
        patterns = {line._unscaled_dash_pattern for line in lines[5 * run:5 * run + 5]}
        assert len(patterns) == 5
    labels = [text.get_text() for text in angles.get_legend().get_texts()]
    assert [label for label in labels if label.startswith("phi")] == [
        f"phi{i}" for i in range(1, 6)]


def test_an_overlays_legend_tells_every_run_apart():
    """Runs whose labels coincide (two scenes with one scheme and dt: the legend said
    'es K=3, dt = 0.01 s' twice) are named by their scene, and runs of one scene by their
    file (and the title names their scheme once); runs whose labels differ keep them."""
    from chaingen.views.plots import TrajectoryRun, named_parameters, title_of

    def run(path, scene, method="es", dt=0.01):
        return TrajectoryRun(path=Path(path), columns=("t",), rows=np.zeros((1, 1)), n=1,
                             scene=scene, method=method, quadrature=3, dt=dt)

    scenes = named_parameters([run("a.csv", "three_link_mono"), run("b.csv", "three_link_multi")])
    assert [r.legend for r in scenes] == ["three_link_mono: es K=3, dt = 0.01 s",
                                          "three_link_multi: es K=3, dt = 0.01 s"]
    files = named_parameters([run("x/a.csv", "mono"), run("y/a.csv", "mono")])
    assert [r.legend for r in files] == ["x/a.csv: es K=3, dt = 0.01 s",
                                         "y/a.csv: es K=3, dt = 0.01 s"]
    assert title_of(scenes) == "three_link_mono, three_link_multi: es K=3, dt = 0.01 s"
    plain = named_parameters([run("a.csv", "mono"), run("b.csv", "multi", dt=0.05)])
    assert [r.legend for r in plain] == ["es K=3, dt = 0.01 s", "es K=3, dt = 0.05 s"]


# -- the progress bar through the compile ---------------------------------------------------------

class Terminal(io.StringIO):
    def isatty(self):
        return True


@pytest.mark.heavy
def test_the_progress_bar_shows_the_compile_with_no_time_left(monkeypatch):
    """While the C compiles (here 1.2 s, after a generate that reported its stages quickly),
    the bar names the compile, its running time is redrawn, and no time left is shown."""
    import chaingen.generate.package as package
    import chaingen.runtime.build as build
    import chaingen.simulation as simulation
    from chaingen.scene import load_reference_scene

    terminal = Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    monkeypatch.delenv("CI", raising=False)
    monkeypatch.delenv("CHAINGEN_QUIET", raising=False)
    monkeypatch.setattr(build, "indexed_library", lambda key: None)
    monkeypatch.setattr(build, "remember", lambda *arguments: None)

    def generate(scene, method, quadrature, *, progress, **_):
        for stage in range(package.GENERATE_STAGES):
            progress.update(stage, f"stage {stage}")
            time.sleep(0.15)
        return type("Package", (), {"files": {}})()
    monkeypatch.setattr(package, "generate_package", generate)
    seen = {}

    class Compiling:
        @staticmethod
        def from_files(files):
            start = len(terminal.getvalue())
            time.sleep(1.2)
            seen["during"] = terminal.getvalue()[start:]
            return type("Built", (), {"library_path": "", "build_hash": "", "manifest": {}})()
    monkeypatch.setattr(simulation, "Solver", Compiling)
    simulation.build_solver(load_reference_scene("three_link_mono"), "es", 3)
    draws = [draw for draw in seen["during"].split("\r") if draw.strip()]
    assert len(draws) >= 2, seen          # redrawn while the compile runs
    assert all("compiling" in draw and " left" not in draw for draw in draws), draws
    assert threading.active_count() == 1 or not any(
        thread.name.startswith("progress") for thread in threading.enumerate())


# -- the exported MJCF starts where the scene does -------------------------------------------------

def test_the_exported_mjcf_has_the_scene_s_initial_state_as_keyframe(tmp_path):
    mujoco = pytest.importorskip("mujoco")
    from chaingen.scene import load_scene

    scene_file = scene_path("five_link_biarticular")
    scene = load_scene(scene_file)
    out = tmp_path / "chain.xml"
    result = chaingen_in_process("export", scene_file, "--mjcf", out, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    model = mujoco.MjModel.from_xml_path(str(out))
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    assert model.nkey == 1
    np.testing.assert_array_equal(data.qpos, scene.initial_angles)
    np.testing.assert_array_equal(data.qvel, scene.initial_velocities)
    assert any(scene.initial_velocities)


@pytest.mark.compile
def test_an_adaptive_run_records_its_tolerances(tmp_path):
    """simulate --rtol: the metadata holds the tolerances the C loop took, beside its counters."""
    result = chaingen_in_process("simulate", MONO, "--rtol", "1e-6", "--atol", "1e-7",
                                 "--t-end", "0.2", "--out", tmp_path / "run.csv", "--quiet",
                                 cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    meta = json.loads((tmp_path / "run.csv.json").read_text())
    assert (meta["rtol"], meta["atol"]) == (1e-6, 1e-7)
    assert meta["adaptive_steps"]["accepted"] >= meta["n_steps"]


# -- a path no file can have, given as an input: bad input, one line -------------------------------

LONG = "b" * 300
PATH_INPUTS = [
    ("simulate", f"{LONG}.toml"), ("simulate", LONG), ("check", f"{LONG}.toml"),
    ("generate", f"{LONG}.toml"), ("export", f"{LONG}.toml", "--mjcf", "x.xml"),
    ("plot", f"{LONG}.csv"), ("animate", "SCENE", f"{LONG}.csv", "-o", "x.gif"),
    ("bench", "--skip-reference", "--skip-scaling", "--skip-sweep", "--out", "r.md",
     "--figures", LONG),
    ("simulate", "loop/scene.toml"), ("plot", "loop/run.csv"),
]


@pytest.mark.parametrize("command", PATH_INPUTS, ids=[" ".join(command)[:40] + ("..." if
                                                      LONG in " ".join(command) else "")
                                                      for command in PATH_INPUTS])
def test_a_path_no_file_can_have_is_bad_input(tmp_path, monkeypatch, command):
    """A name too long (ENAMETOOLONG) or a loop of links (ELOOP) met where an input is read
    or checked was an internal error (exit 1) or a traceback (a scene's name, looked up among
    the shipped scenes): now one line, exit status 2, nothing written."""
    import chaingen.studies.bench

    def refused(*_, **__):
        raise AssertionError("the command started its work")
    monkeypatch.setattr(chaingen.studies.bench, "run_bench", refused)
    (tmp_path / "loop").symlink_to("loop")
    arguments = [str(MONO) if argument == "SCENE" else argument for argument in command]
    result = chaingen_in_process(*arguments, "--quiet", cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("chaingen: error: "), result.stderr
    assert "internal error" not in lines[0]
    assert ("File name too long" in lines[0] or "symbolic links" in lines[0]
            or "no such" in lines[0].lower() or "cannot read" in lines[0]), lines[0]
    assert sorted(path.name for path in tmp_path.iterdir()) == ["loop"]


@pytest.mark.parametrize("command", ["simulate", "animate"])
@pytest.mark.parametrize("flag", ["--rtol", "--atol", "scene"])
def test_adaptive_steps_of_the_sampled_law_exit_2_in_one_line(command, flag, tmp_path):
    """A sampled law (held over the step) with adaptive steps, from the command line or the
    scene's [simulation]: exit 2, one line naming where the tolerance came from and why, no
    traceback, nothing written. animate passed --rtol to the run without this check before
    (a sampled four_link_pbc animated at exit 0 on 1e-8's adaptive steps)."""
    text = scene_path("four_link_pbc").read_text()
    assert text.count('\nlaw = "discrete"\n') == 1
    text = text.replace('\nlaw = "discrete"\n', '\nlaw = "sampled"\n')
    if flag == "scene":
        text = text.replace("\ndt = 0.01\n", "\ndt = 0.01\nrtol = 1e-8\n")
    scene = tmp_path / "pbc.toml"
    scene.write_text(text)
    output = ["-o", tmp_path / "pbc.gif"] if command == "animate" else []
    options = [] if flag == "scene" else [flag, "1e-8"]
    result = chaingen_in_process(command, scene, *options, *output, cwd=tmp_path)
    where = f"{scene}: simulation.rtol" if flag == "scene" else flag
    assert result.returncode == 2, result
    assert result.stdout == "" and "Traceback" not in result.stderr
    assert result.stderr.splitlines() == [
        f"chaingen: error: {where}: adaptive steps would hold the sampled law (control.law = "
        '"sampled") over each adaptive step instead of the sample period dt; take fixed steps, '
        "got 1e-08"]
    assert sorted(path.name for path in tmp_path.iterdir()) == ["pbc.toml"]
