"""Spatial scenes on the command line: every command on scenes/spatial_three_link.toml, as a user
runs it, with the rules of bad input (exit status 2, one line naming what and where, nothing
written, no input overwritten), and the animation's drawing checked against the numpy
kinematics of chaingen.spatial.dynamics at the samples it draws.

The fast tests need no compiler (generate writes C without building it, export and the views
read files); the ones that build a solver are marked compile, the MP4 one (ffmpeg) tools.
"""
from __future__ import annotations

import csv
import hashlib
import json
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_spatial_dynamics import random_scene

from chaingen.arguments import SPATIAL_DEFAULT_METHOD, load_command_scene
from chaingen.scene import Scene
from chaingen.spatial import SpatialScene, dynamics, load_spatial_scene

from helpers import ROOT, chaingen, chaingen_in_process, require_module, require_tools

SPATIAL = ROOT / "scenes" / "spatial_three_link.toml"
PLANAR = ROOT / "scenes" / "three_link_multi.toml"
SCENE = load_spatial_scene(SPATIAL)
HEADER = "t,phi1,phi2,phi3,omega1,omega2,omega3,energy,constraint_error"
EXIT_BAD_INPUT = 2


def snapshot(directory) -> dict[str, str]:
    """Every file below `directory` with the hash of its bytes."""
    return {str(path.relative_to(directory)): hashlib.sha256(path.read_bytes()).hexdigest()
            for path in sorted(directory.rglob("*")) if path.is_file()}


def error_line(result) -> str:
    """The one line of a bad-input run, after checking the rules of bad input."""
    report = f"exit {result.returncode}\nstdout:\n{result.stdout}\nstderr:\n{result.stderr}"
    assert result.returncode == EXIT_BAD_INPUT, report
    assert "Traceback" not in result.stderr and result.stdout == "", report
    lines = result.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("chaingen: error: "), report
    return lines[0]


def spatial_copy(tmp_path, text: str | None = None):
    """The spatial scene (or `text`) as a file in tmp_path, so a test can watch it unchanged."""
    path = tmp_path / "arm.toml"
    path.write_text(SPATIAL.read_text() if text is None else text)
    return path


def write_run(path, q: np.ndarray, t: np.ndarray, *, scene: str = SCENE.name) -> None:
    """A trajectory file (scene-format.md) of angles `q` at times `t`, with its metadata: the
    animation and the plots read nothing else of it, so no solver is needed."""
    n = q.shape[1]
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["t", *(f"phi{i}" for i in range(1, n + 1)),
                         *(f"omega{i}" for i in range(1, n + 1)), "energy", "constraint_error"])
        for time, angles in zip(t, q):
            writer.writerow([repr(float(time)), *map(repr, map(float, angles)),
                             *(["0.0"] * n), "1.0", "0.0"])
    path.with_name(path.name + ".json").write_text(json.dumps(
        {"scene": scene, "method": "midpoint", "quadrature": 1, "dt": float(t[1] - t[0])}))


def random_run(seed: int, samples: int = 21, dt: float = 0.05):
    rng = np.random.default_rng(seed)
    t = dt * np.arange(samples)
    q = np.asarray(SCENE.initial_angles) + np.cumsum(rng.uniform(-0.3, 0.3, (samples, 3)),
                                                     axis=0)
    return t, q


# -- one place tells the kinds apart -----------------------------------------------------------

def test_a_command_reads_either_kind_of_scene_file_by_its_keys():
    spatial = load_command_scene(SPATIAL)
    assert isinstance(spatial, SpatialScene) and spatial == SCENE
    assert isinstance(load_command_scene(PLANAR), Scene)
    assert load_command_scene("spatial_three_link") == SCENE     # a shipped scene's name


def test_a_bad_spatial_file_is_one_line_naming_its_key_for_every_command(tmp_path):
    bad = spatial_copy(tmp_path, SPATIAL.read_text().replace(
        "axis = [0.0, 1.0, 0.2]", "axis = [0.0, 0.0, 0.0]"))
    before = snapshot(tmp_path)
    for args in (["simulate", bad], ["generate", bad], ["check", bad], ["order", bad],
                 ["export", bad, "--mjcf", "arm.xml"], ["animate", bad, "-o", "arm.gif"]):
        line = error_line(chaingen_in_process(*args, cwd=tmp_path))
        assert line.startswith(f"chaingen: error: {bad}: links[1].joint"), line
        assert "axis" in line and line.count(str(bad)) == 1, line
    assert snapshot(tmp_path) == before


# -- generate ----------------------------------------------------------------------------------

def test_generate_without_method_writes_the_default_schemes_package(tmp_path):
    result = chaingen("generate", SPATIAL, "--no-sensitivities", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    package = tmp_path / f"spatial_three_link_{SPATIAL_DEFAULT_METHOD}"
    assert result.stdout.startswith(f"wrote {package.name}/"), result.stdout
    manifest = json.loads((package / "chaingen.json").read_text())
    assert manifest["method"] == SPATIAL_DEFAULT_METHOD
    assert manifest["scene"] == SCENE.name


@pytest.mark.parametrize("args, fragments", [
    (["--method", "es", "--order", "6", "--quadrature", "1"],
     ["--quadrature: es at order 6 takes its k = 1 Galerkin step", "K >= 2", "got 1"]),
    (["--order", "3"], ["--order"]),
])
def test_generate_refuses_what_a_spatial_scene_cannot_take_and_writes_nothing(
        tmp_path, args, fragments):
    """es at order 6 takes its Galerkin step for a spatial scene too, whose Gauss-Lobatto
    rule needs K >= 2: the planar rule's one line."""
    scene = spatial_copy(tmp_path)
    before = snapshot(tmp_path)
    result = chaingen_in_process("generate", scene, *args, "-o", "out", cwd=tmp_path)
    if args[0] == "--order":     # argparse's own choice check: usage lines, then the error
        assert result.returncode == EXIT_BAD_INPUT and "--order" in result.stderr
    else:
        line = error_line(result)
        for fragment in fragments:
            assert fragment in line, line
    assert snapshot(tmp_path) == before


# -- export ------------------------------------------------------------------------------------

def test_export_writes_the_spatial_mjcf_that_mujoco_loads(tmp_path):
    mujoco = require_module("mujoco", "test")
    from test_spatial_mjcf import full_mass_matrix

    from chaingen.reference.spatial_mjcf import spatial_mjcf_from_scene

    result = chaingen_in_process("export", SPATIAL, "--mjcf", "arm.xml", "--dt", "0.002",
                                 cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == ("wrote arm.xml: 3 links, 2 spring tendons, motors on "
                                     "joints [3], dt 0.002 s, RK4")
    text = (tmp_path / "arm.xml").read_text()
    assert text == spatial_mjcf_from_scene(SCENE, dt=0.002, integrator="RK4", export=True)
    model = mujoco.MjModel.from_xml_string(text)
    assert (model.nq, model.ntendon, model.nu) == (3, 2, 1)
    assert model.opt.timestep == 0.002
    # The exported model's mass matrix is the scene's (chaingen.spatial.dynamics).
    data = mujoco.MjData(model)
    q = np.array([0.4, -0.7, 1.1])
    data.qpos[:] = q
    mujoco.mj_forward(model, data)
    np.testing.assert_allclose(full_mass_matrix(model, data), dynamics.mass_matrix(SCENE, q),
                               rtol=1e-10, atol=1e-12)


def test_export_never_overwrites_its_scene(tmp_path):
    scene = spatial_copy(tmp_path)
    before = snapshot(tmp_path)
    line = error_line(chaingen_in_process("export", scene, "--mjcf", scene, cwd=tmp_path))
    assert "--mjcf" in line, line
    assert snapshot(tmp_path) == before


# -- the animation -----------------------------------------------------------------------------

@pytest.mark.parametrize("seed", range(3))
def test_the_animation_draws_the_joints_where_link_poses_has_them(tmp_path, seed, monkeypatch):
    """Every frame of a GIF: the joints, COMs and route points each view holds are the
    projections of chaingen.spatial.dynamics' positions at the frame's sample."""
    from PIL import Image

    from chaingen.views import animate_spatial
    from chaingen.views.animate import animate

    t, q = random_run(seed)
    run_file = tmp_path / "run.csv"
    write_run(run_file, q, t)
    drawn = []
    draw = animate_spatial.SpatialDrawing.draw

    def recording(self, angles, time):
        geometry = draw(self, angles, time)
        drawn.append((np.array(angles), self.drawn()))
        return geometry

    monkeypatch.setattr(animate_spatial.SpatialDrawing, "draw", recording)
    from chaingen.views.plots import load_run
    out, plan = animate(SCENE, load_run(run_file), tmp_path / "arm.gif", every=2, pixels=300)
    with Image.open(out) as image:
        assert image.n_frames == plan.indices.size == 11
        assert image.size == animate_spatial.spatial_frame_layout(300, True)[:2]
    assert len(drawn) == plan.indices.size
    for index, (angles, views) in zip(plan.indices, drawn):
        np.testing.assert_array_equal(angles, q[index])
        poses = dynamics.link_poses(SCENE, q[index])
        joints = np.array([origin for _, origin in poses[1:]])
        coms = dynamics.com_positions(SCENE, q[index])
        routes = dynamics.route_positions(SCENE, q[index])
        for name, horizontal, vertical in animate_spatial.VIEWS:
            view = views[name]
            np.testing.assert_allclose(view["joints"], joints[:, [horizontal, vertical]],
                                       atol=1e-12)
            np.testing.assert_allclose(view["coms"], coms[:, [horizontal, vertical]],
                                       atol=1e-12)
            np.testing.assert_allclose(view["links"][:-1], view["joints"], atol=0)
            for line, route in zip(view["springs"], routes):
                np.testing.assert_allclose(line, route[:, [horizontal, vertical]], atol=1e-12)


@settings(max_examples=12, deadline=None, derandomize=True, database=None)
@given(seed=st.integers(0, 2 ** 32 - 1), n=st.integers(1, 7), springs=st.booleans(),
       turns=st.lists(st.floats(-np.pi, np.pi), min_size=7, max_size=7))
def test_random_arms_are_drawn_where_link_poses_has_them_and_inside_the_views(
        seed, n, springs, turns):
    """Random chains (skew axes, off-axis COMs, routed springs): each view holds the
    projections of chaingen.spatial.dynamics' joints, COMs and route points, and every point
    lies inside the view's limits (spatial_reach bounds every posture)."""
    from chaingen.views.animate_spatial import VIEWS, SpatialDrawing

    scene = random_scene(seed, n, springs)
    q = np.asarray(turns[:n])
    drawing = SpatialDrawing(scene, pixels=240)
    drawing.draw(q, 0.0)
    joints = np.array([origin for _, origin in dynamics.link_poses(scene, q)[1:]])
    coms = dynamics.com_positions(scene, q)
    routes = dynamics.route_positions(scene, q)
    for view, (name, horizontal, vertical) in zip(drawing.views, VIEWS):
        drawn = drawing.drawn()[name]
        pick = [horizontal, vertical]
        np.testing.assert_allclose(drawn["joints"], joints[:, pick], rtol=0, atol=1e-12)
        np.testing.assert_allclose(drawn["coms"], coms[:, pick], rtol=0, atol=1e-12)
        assert len(drawn["springs"]) == len(routes)
        for line, route in zip(drawn["springs"], routes):
            np.testing.assert_allclose(line, route[:, pick], rtol=0, atol=1e-12)
        points = np.vstack([drawn["joints"], drawn["coms"], *drawn["springs"]])
        (left, right), (bottom, top) = view.axes.get_xlim(), view.axes.get_ylim()
        assert np.all((points[:, 0] > left) & (points[:, 0] < right))
        assert np.all((points[:, 1] > bottom) & (points[:, 1] < top))


def test_animate_from_the_command_line_of_a_spatial_trajectory(tmp_path):
    t, q = random_run(7, samples=11, dt=0.1)
    write_run(tmp_path / "run.csv", q, t)
    scene = spatial_copy(tmp_path)
    result = chaingen_in_process("animate", scene, "run.csv", "-o", "arm.gif", "--size", "240",
                                 cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("wrote arm.gif: 11 frames"), result.stdout
    assert scene.read_text() == SPATIAL.read_text()


@pytest.mark.tools
def test_animate_a_spatial_run_as_mp4_of_even_size(tmp_path):
    """An odd --size still gives even frame sides (MP4's yuv420p), as ffprobe reads them."""
    require_tools("ffmpeg", "ffprobe")
    import subprocess

    from chaingen.views.animate_spatial import spatial_frame_layout

    t, q = random_run(3, samples=11, dt=0.1)
    write_run(tmp_path / "run.csv", q, t)
    result = chaingen_in_process("animate", SPATIAL, "run.csv", "-o", "arm.mp4", "--size",
                                 "301", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    probe = subprocess.run(["ffprobe", "-v", "error", "-select_streams", "v:0", "-count_frames",
                            "-show_entries", "stream=width,height,nb_read_frames", "-of",
                            "csv=p=0", str(tmp_path / "arm.mp4")],
                           capture_output=True, text=True, check=True)
    width, height, frames = map(int, probe.stdout.strip().split(","))
    assert (width, height) == spatial_frame_layout(302, True)[:2]
    assert width % 2 == 0 and height % 2 == 0 and frames == 11


@pytest.mark.parametrize("case", ["planar run", "other scene", "png", "scene as output",
                                  "method with a run"])
def test_animate_refuses_bad_input_and_writes_nothing(tmp_path, case):
    scene = spatial_copy(tmp_path)
    t, q = random_run(1, samples=5)
    write_run(tmp_path / "run.csv", q, t)
    write_run(tmp_path / "planar.csv", np.zeros((5, 4)), t, scene="four")
    write_run(tmp_path / "other.csv", q, t, scene="another-arm")
    args, fragment = {
        "planar run": (["planar.csv", "-o", "a.gif"], "4 joints (phi1..phi4), but the scene "
                                                      "spatial-three-link has 3 links"),
        "other scene": (["other.csv", "-o", "a.gif"], "written for scene 'another-arm'"),
        "png": (["run.csv", "-o", "a.png"], "give a .gif or .mp4"),
        "scene as output": (["run.csv", "-o", str(scene)], "-o"),
        "method with a run": (["run.csv", "--method", "midpoint", "-o", "a.gif"],
                              "only when animate simulates"),
    }[case]
    before = snapshot(tmp_path)
    line = error_line(chaingen_in_process("animate", scene, *args, cwd=tmp_path))
    assert fragment in line, line
    assert snapshot(tmp_path) == before


# -- runs that build a solver --------------------------------------------------------------------

@pytest.mark.compile
def test_simulate_without_method_agrees_with_mujoco_and_plots(tmp_path):
    """The default scheme's run from the command line: the trajectory file's columns (those of
    a planar run, and the energy flows of an actuated, damped scene), the angles at t = 0.2 s
    against MuJoCo's RK4 on the exported model, and the figure."""
    require_module("mujoco", "test")
    from PIL import Image

    from chaingen.reference.spatial_mujoco import simulate_spatial_mujoco

    scene = spatial_copy(tmp_path)
    result = chaingen("simulate", scene, "--dt", "0.001", "--t-end", "0.2", "--out", "arm.csv",
                      "--plot", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert f"{SPATIAL_DEFAULT_METHOD}" in result.stdout
    header = (tmp_path / "arm.csv").read_text().splitlines()[0]
    assert header.startswith(HEADER + ","), header
    meta = json.loads((tmp_path / "arm.csv.json").read_text())
    assert meta["method"] == SPATIAL_DEFAULT_METHOD and meta["scene"] == SCENE.name
    from chaingen.views.plots import load_run
    run = load_run(tmp_path / "arm.csv")
    assert run.balanced and run.t[-1] == pytest.approx(0.2)
    # simulate applies no torque, and damped joint 2 dissipates from its initial rate on.
    np.testing.assert_array_equal(run.column("input_work"), 0.0)
    assert np.all(np.diff(run.column("dissipated")) > 0)
    reference = simulate_spatial_mujoco(SCENE, dt=1e-4, t_end=0.2)
    np.testing.assert_allclose(run.phi[-1], reference.final_angles, atol=1e-5)
    with Image.open(tmp_path / "arm.png") as image:
        assert image.size == (1500, 1200)
    plot = chaingen("plot", "arm.csv", "-o", "again.png", cwd=tmp_path)
    assert plot.returncode == 0, plot.stderr
    assert (tmp_path / "again.png").stat().st_size > 0
    assert scene.read_text() == SPATIAL.read_text()


@pytest.mark.compile
def test_simulate_with_a_refused_method_writes_nothing(tmp_path):
    scene = spatial_copy(tmp_path)
    before = snapshot(tmp_path)
    line = error_line(chaingen_in_process("simulate", scene, "--method", "es", "--order", "6",
                                          "--quadrature", "1", "--out", "arm.csv", "--plot",
                                          cwd=tmp_path))
    assert "--quadrature: es at order 6 takes its k = 1 Galerkin step" in line, line
    assert snapshot(tmp_path) == before


@pytest.mark.compile
def test_check_passes_for_the_spatial_scene(tmp_path):
    result = chaingen("check", SPATIAL, "--samples", "2", "--dt", "0.01", cwd=tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "midpoint" in result.stdout


@pytest.mark.compile
def test_order_fits_order_2_for_the_spatial_scene(tmp_path):
    """The default scheme's study: its balance, trajectory and rate errors fall as dt^2."""
    result = chaingen("order", SPATIAL, "--order", "2", "--t-end", "0.4", cwd=tmp_path)
    assert result.returncode == 0, result.stdout + result.stderr
    assert result.stdout.startswith(f"{SCENE.name}: method {SPATIAL_DEFAULT_METHOD}, order 2")
    fitted = dict(re.findall(r"^(balance|trajectory|rate) order\s+([0-9.]+)", result.stdout,
                             flags=re.MULTILINE))
    assert set(fitted) == {"balance", "trajectory", "rate"}, result.stdout
    for name, order in fitted.items():
        assert abs(float(order) - 2.0) < 0.1, (name, result.stdout)


@pytest.mark.compile
def test_animate_straight_from_a_spatial_scene(tmp_path):
    from PIL import Image

    result = chaingen("animate", SPATIAL, "--t-end", "0.4", "-o", "arm.gif", "--size", "240",
                      cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    with Image.open(tmp_path / "arm.gif") as image:
        assert image.n_frames == 11
