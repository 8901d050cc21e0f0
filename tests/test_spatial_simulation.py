"""A spatial scene's [simulation] table (docs/scene-format.md 13.4): the planar table's keys,
rules and messages (one definition, chaingen.scene.values.Simulation, read by the planar
reader's method), with midpoint as the default method; written by the spatial writer, read
back exactly; taken by generate, simulate, check and order where the command line leaves a
value unset, and by build_solver / SolverSpec.create without a method.

Fast but the one run marked compile."""
from __future__ import annotations

import dataclasses

import pytest

from chaingen.scene import Simulation, SolverSpec
from chaingen.scene.reader import SceneReader
from chaingen.spatial import parse_spatial_scene
from chaingen.spatial.reader import SpatialSceneReader
from chaingen.spatial.values import SPATIAL_DEFAULT_METHOD, SPATIAL_SIMULATION_DEFAULTS
from chaingen.spatial.writer import scene_text

from helpers import ROOT, chaingen, chaingen_in_process

SPATIAL = ROOT / "scenes" / "spatial_three_link.toml"
TABLE = '[simulation]\nmethod = "vi"\norder = 4\ndt = 0.005\nt_end = 0.3\n'


def with_table(tmp_path, table: str = TABLE, name: str = "arm.toml"):
    path = tmp_path / name
    path.write_text(SPATIAL.read_text() + "\n" + table)
    return path


def test_the_table_is_the_planar_one_with_midpoint_as_its_method():
    assert SPATIAL_DEFAULT_METHOD == "midpoint"
    assert SPATIAL_SIMULATION_DEFAULTS == dataclasses.replace(Simulation(),
                                                              method=SPATIAL_DEFAULT_METHOD)
    assert SpatialSceneReader.simulation is SceneReader.simulation   # no copy of the rules
    scene = parse_spatial_scene(SPATIAL.read_text(), "arm.toml")
    assert scene.simulation == SPATIAL_SIMULATION_DEFAULTS


def test_every_key_is_read_and_the_ones_left_out_take_the_spatial_defaults():
    text = SPATIAL.read_text() + "\n" + TABLE
    scene = parse_spatial_scene(text, "arm.toml")
    assert scene.simulation == Simulation(method="vi", order=4, dt=0.005, t_end=0.3)
    everything = ('[simulation]\nmethod = "es"\nquadrature = 2\norder = 2\ngradient = '
                  '"quadrature"\ndt = 0.002\nt_end = 1.5\nrtol = 1e-6\natol = 1e-9\n')
    scene = parse_spatial_scene(SPATIAL.read_text() + "\n" + everything, "arm.toml")
    assert scene.simulation == Simulation(method="es", quadrature=2, order=2,
                                          gradient="quadrature", dt=0.002, t_end=1.5,
                                          rtol=1e-6, atol=1e-9)
    # A table without a method: midpoint, not the planar table's es.
    scene = parse_spatial_scene(SPATIAL.read_text() + "\n[simulation]\ndt = 0.02\n", "arm.toml")
    assert scene.simulation == dataclasses.replace(SPATIAL_SIMULATION_DEFAULTS, dt=0.02)


@pytest.mark.parametrize("table, expected", [
    ("dt = 0.0", "simulation.dt: must be > 0 (step in s), got 0.0"),
    ("dt = nan", "simulation.dt: must be finite (step in s), got nan"),
    ("t_end = inf", "simulation.t_end: must be finite (duration in s), got inf"),
    ("t_end = -1.0", "simulation.t_end: must be > 0 (duration in s), got -1.0"),
    ('dt = "0.01"', "simulation.dt: must be a number (step in s), not a string"),
    ('method = "rk4"', 'simulation.method: must be one of "es", "vi", "midpoint"'),
    ("order = 3", "simulation.order: must be one of 2, 4, 6"),
    ("quadrature = 0", "simulation.quadrature: must be an integer from 1 to 20"),
    ('gradient = "x"', 'simulation.gradient: must be one of "exact", "quadrature", "chain"'),
    ("rtol = -1.0", "simulation.rtol: must be 0 (fixed steps) or from 1e-14 up"),
    ("dtt = 0.1", "simulation.dtt: unknown key (did you mean 'dt'?"),
    ('method = "es"\norder = 6\nquadrature = 1', "simulation.quadrature: "),
])
def test_a_bad_value_is_one_line_exit_2_and_nothing_written(tmp_path, table, expected):
    scene = with_table(tmp_path, f"[simulation]\n{table}\n")
    for command in (["simulate", scene, "--out", "run.csv"], ["generate", scene, "-o", "out"],
                    ["check", scene], ["order", scene], ["export", scene, "--mjcf", "a.xml"]):
        result = chaingen_in_process(*command, cwd=tmp_path)
        lines = result.stderr.splitlines()
        assert result.returncode == 2 and result.stdout == "" and len(lines) == 1, result
        assert lines[0].startswith(f"chaingen: error: {scene}: {expected}"), lines[0]
    assert sorted(path.name for path in tmp_path.iterdir()) == ["arm.toml"]


def test_es_at_order_6_in_the_table_takes_its_galerkin_step_and_refuses_k_1(tmp_path):
    """Spatial es takes every order (order 6: its k = 1 Galerkin step, docs/model.md 16), so
    the table's es at order 6 is taken, with the table's K; K = 1, which its Gauss-Lobatto rule
    cannot take, is the reader's one line, exit 2, and nothing is written."""
    from chaingen.scene import SolverSpec
    from chaingen.symbolic.schemes import build_scheme, orders_taken

    scene = parse_spatial_scene(SPATIAL.read_text(), "arm.toml")
    assert orders_taken(scene, "es") == (2, 4, 6)
    taken = parse_spatial_scene(SPATIAL.read_text() + '\n[simulation]\nmethod = "es"\n'
                                'order = 6\nquadrature = 4\n', "arm.toml")
    assert build_scheme(SolverSpec.create(taken)).quadrature == 4
    scene = with_table(tmp_path, '[simulation]\nmethod = "es"\norder = 6\nquadrature = 1\n')
    result = chaingen_in_process("generate", scene, "-o", "out", cwd=tmp_path)
    assert result.returncode == 2 and len(result.stderr.splitlines()) == 1, result
    assert "simulation.quadrature: es at order 6 takes its k = 1 Galerkin step" in result.stderr
    assert not (tmp_path / "out").exists()


def test_the_writer_writes_the_table_and_it_reads_back_exactly():
    scene = parse_spatial_scene(SPATIAL.read_text() + "\n" + TABLE, "arm.toml")
    text = scene_text(scene)
    assert '[simulation]' in text and 'method = "vi"' in text and "order = 4" in text
    assert parse_spatial_scene(text, "arm.toml") == scene
    odd = dataclasses.replace(scene, simulation=Simulation(
        method="es", quadrature=7, gradient="chain", dt=1 / 3, t_end=0.1 + 0.2, rtol=1e-7,
        atol=3e-10))
    assert parse_spatial_scene(scene_text(odd), "arm.toml") == odd


class Stop(BaseException):
    """Ends a command once its settings are known (main lets a BaseException through)."""


@pytest.fixture
def settings_taken(monkeypatch):
    """The RunSettings (and the order command's study arguments) a command runs with."""
    import chaingen.simulation
    import chaingen.studies.order

    taken = {}
    real = chaingen.simulation.run_settings

    def recording(*args, **kwargs):
        taken["settings"] = real(*args, **kwargs)
        return taken["settings"]

    def studies(scene, method, quadrature, orders, t_end, **kwargs):
        taken["study"] = (method, quadrature, orders, t_end)
        raise Stop

    def scheme(spec, *args, **kwargs):
        taken["spec"] = spec
        raise Stop

    monkeypatch.setattr(chaingen.simulation, "run_settings", recording)
    monkeypatch.setattr(chaingen.studies.order, "order_studies", studies)
    monkeypatch.setattr(chaingen.simulation, "simulate_scene",
                        lambda *args, **kwargs: (_ for _ in ()).throw(Stop()))
    import chaingen.generate.package
    import chaingen.symbolic.schemes
    monkeypatch.setattr(chaingen.generate.package, "generate_package", scheme)
    monkeypatch.setattr(chaingen.symbolic.schemes, "build_scheme", scheme)
    return taken


@pytest.mark.parametrize("command", ["simulate", "generate", "check", "order"])
def test_the_commands_take_the_tables_values_where_the_command_line_leaves_them(
        tmp_path, settings_taken, command):
    scene = with_table(tmp_path)
    with pytest.raises(Stop):
        chaingen_in_process(command, scene, cwd=tmp_path)
    settings = settings_taken["settings"]
    assert settings.method == "vi"
    if command in ("simulate", "check"):
        assert settings.dt == 0.005
    if command == "simulate":
        assert (settings.t_end, settings.order) == (0.3, 4)
    if command == "generate":
        assert (settings_taken["spec"].method, settings_taken["spec"].order) == ("vi", 4)
    if command == "order":   # without --order: every order the scheme takes, as planar
        assert settings_taken["study"][0] == "vi" and settings_taken["study"][2] == (2, 4, 6)
    # The command line's values win.
    settings_taken.clear()
    override = ["--method", "midpoint", "--order", "2"] + (
        ["--dt", "0.01"] if command in ("simulate", "check") else [])
    with pytest.raises(Stop):
        chaingen_in_process(command, scene, *override, cwd=tmp_path)
    settings = settings_taken["settings"]
    assert (settings.method, settings.order) == ("midpoint", 2)
    if command in ("simulate", "check"):
        assert settings.dt == 0.01


def test_build_solver_and_solver_spec_take_the_scenes_method():
    """build_solver(scene) makes its SolverSpec with SolverSpec.create: without a method a
    spatial scene's own, midpoint when its file names none."""
    from chaingen.simulation import solver_spec

    plain = parse_spatial_scene(SPATIAL.read_text(), "arm.toml")
    assert SolverSpec.create(plain).method == "midpoint"
    assert solver_spec(plain).method == "midpoint"
    table = parse_spatial_scene(SPATIAL.read_text() + "\n" + TABLE, "arm.toml")
    assert (solver_spec(table).method, solver_spec(table).order) == ("vi", 4)
    assert solver_spec(table, "es", order=2).method == "es"


def test_export_takes_the_tables_step(tmp_path):
    scene = with_table(tmp_path)
    result = chaingen_in_process("export", scene, "--mjcf", "arm.xml", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert 'timestep="0.005"' in (tmp_path / "arm.xml").read_text()


@pytest.mark.compile
def test_simulate_runs_the_tables_step_and_duration(tmp_path):
    scene = with_table(tmp_path, "[simulation]\ndt = 0.004\nt_end = 0.02\n")
    result = chaingen("simulate", scene, "--out", "run.csv", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("spatial-three-link: method midpoint, dt 0.004 s, "
                                    "t_end 0.02 s"), result.stdout
    rows = (tmp_path / "run.csv").read_text().splitlines()
    assert len(rows) == 1 + 6 and rows[-1].startswith("0.02")


# -- chaingen order without --order: the orders the scheme takes for the scene -----------------

@pytest.mark.parametrize("method", ["es", "vi", "midpoint"])
def test_order_studies_each_order_the_spatial_scheme_takes(tmp_path, settings_taken, method):
    """Asked of the scheme (chaingen.symbolic.schemes.orders_taken), not restated: spatial es
    may take fewer orders than vi and midpoint; an order it does not take is refused by its
    builder before any SymPy work, one it takes is studied."""
    from chaingen.errors import UnsupportedSceneError
    from chaingen.symbolic.schemes import SPATIAL_BUILDERS, orders_taken

    scene = parse_spatial_scene(SPATIAL.read_text(), "arm.toml")
    taken = orders_taken(scene, method)
    assert 2 in taken and set(taken) <= {2, 4, 6}
    if method != "es":
        assert taken == (2, 4, 6)
    for order in {2, 4, 6} - set(taken):
        with pytest.raises(UnsupportedSceneError, match=f"order {order}"):
            SPATIAL_BUILDERS[method](scene, 3, order)
    with pytest.raises(Stop):
        chaingen_in_process("order", SPATIAL, "--method", method, cwd=tmp_path)
    assert settings_taken["study"][2] == taken
    # The planar scene's orders are the rules' alone.
    settings_taken.clear()
    with pytest.raises(Stop):
        chaingen_in_process("order", ROOT / "scenes" / "three_link_mono.toml", "--method",
                            method, cwd=tmp_path)
    assert settings_taken["study"][2] == (2, 4, 6)


def test_the_docs_give_each_keys_message_as_the_reader_prints_it():
    """scene-format.md 13.4: each `# line` of the [simulation] block, then the message the
    reader prints for the shipped scene with that table; every key of the table has one."""
    import re

    from chaingen.errors import SceneError

    doc = (ROOT / "docs" / "scene-format.md").read_text(encoding="utf-8")
    section = doc.split("### 13.4")[1].split("### 13.5")[0]
    block = re.search(r"```\n(# method = .*?)```", section, re.DOTALL).group(1)
    pairs = re.findall(r"^# (.*)\n(arm\.toml: .*)$", block, re.MULTILINE)
    assert {line.split(" = ")[0] for line, _ in pairs} >= {
        field.name for field in dataclasses.fields(Simulation)}
    for line, message in pairs:
        with pytest.raises(SceneError) as caught:
            parse_spatial_scene(SPATIAL.read_text() + f"\n[simulation]\n{line}\n", "arm.toml")
        assert str(caught.value) == message


def test_a_run_too_long_is_named_by_where_its_numbers_came_from(tmp_path):
    """t_end / dt beyond the steps a run may take: named simulation.dt/t_end with the file when
    both came from the table, --dt/--t-end when an option gave one."""
    scene = with_table(tmp_path, "[simulation]\ndt = 1e-300\n")
    line = chaingen_in_process("simulate", scene, cwd=tmp_path).stderr.strip()
    assert line.startswith(f"chaingen: error: {scene}: simulation.dt/t_end: t_end / dt = 1e+301 "
                           "steps, more than the 1e+12 a run may take"), line
    line = chaingen_in_process("simulate", scene, "--t-end", "1", cwd=tmp_path).stderr.strip()
    assert line.startswith("chaingen: error: --dt/--t-end: t_end / dt = 1e+300 steps"), line
