"""Third adversarial pass over the newest surfaces (passivity-based control, `chaingen import`,
the command line): each test is an input that once gave a wrong answer, an error in the wrong
words or place, or a file that chaingen itself could not read; it fails on the code before
its fix.
"""
from __future__ import annotations

import pytest
from test_output_paths import snapshot

from helpers import ROOT, chaingen, require_module

# -- chaingen import: URDFs the importer once turned into wrong or unreadable scenes ----------


def robot_urdf(second_joint: str = "", second_inertia: str = 'ixx="0.01"',
               first_extra: str = "") -> str:
    """Two massive links on two revolute joints about y; the second joint's axis, mimic tag
    and the second link's ixx given."""
    def link(name, ixx='ixx="0.01"'):
        return (f'<link name="{name}"><inertial><origin xyz="0 0 0.1"/><mass value="1.0"/>'
                f'<inertia {ixx} iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>'
                "</link>")
    limit = '<limit lower="-1" upper="1" effort="1" velocity="1"/>'
    second_joint = second_joint or '<axis xyz="0 1 0"/>'
    return ('<robot name="r">' + link("base") + link("upper") + link("lower", second_inertia)
            + '<joint name="shoulder" type="revolute"><parent link="base"/>'
              f'<child link="upper"/><origin xyz="0 0 0.2"/><axis xyz="0 1 0"/>{limit}'
              f'{first_extra}</joint>'
            + '<joint name="elbow" type="revolute"><parent link="upper"/>'
              f'<child link="lower"/><origin xyz="0 0 0.2"/>{second_joint}{limit}</joint>'
            + "</robot>")


ODD_URDFS = {
    # A zero axis: the importer divided by its norm and wrote NaN (internal error, exit 1).
    "zero axis": (robot_urdf('<axis xyz="0 0 0"/>'),
                  "joint 'elbow' has no axis (Pinocchio holds (0.0, 0.0, 0.0) of its <axis xyz>"),
    # A mimic joint was imported as an independent joint: a different robot, exit 0.
    "mimic joint": (robot_urdf('<axis xyz="0 1 0"/><mimic joint="shoulder" multiplier="2"/>'),
                    "joint 'elbow' on the chain to 'lower' is a mimic joint"),
    # Inertias no rigid body has, and a negative damping: written (exit 0) as scenes that
    # every other command then refused.
    "negative principal moment": (robot_urdf(second_inertia='ixx="-0.01"'),
                                  "link 'lower' (joint 'elbow'): a scene cannot take it: "
                                  "links[1].inertia: must be a physically valid inertia"),
    "triangle inequality": (robot_urdf(second_inertia='ixx="0.05"'),
                            "link 'lower' (joint 'elbow'): a scene cannot take it: "
                            "links[1].inertia: must be a physically valid inertia"),
    # An inertia urdfdom cannot parse (NaN, numpy's repr of a float) was read as none: the
    # link became a point mass (inertia 0), exit 0.
    "nan inertia": (robot_urdf(second_inertia='ixx="nan"'),
                    "the URDF parser could not read part of it (and would leave it out): "
                    "Inertial: inertia element ixx is not a valid double; Could not parse "
                    "inertial element for Link [lower]"),
    "malformed inertia": (robot_urdf(second_inertia='ixx="np.float64(0.01)"'),
                          "the URDF parser could not read part of it"),
    "negative damping": (robot_urdf(first_extra='<dynamics damping="-1"/>'),
                         "link 'upper' (joint 'shoulder'): a scene cannot take it: "
                         "links[0].damping: must be >= 0"),
}


@pytest.mark.parametrize("case", sorted(ODD_URDFS))
def test_odd_urdfs_are_refused_in_one_line_and_write_nothing(case, tmp_path):
    require_module("pinocchio", "robots")
    text, expected = ODD_URDFS[case]
    (tmp_path / "robot.urdf").write_text(text)
    before = snapshot(tmp_path)
    result = chaingen("import", "robot.urdf", "-o", "scene.toml", cwd=tmp_path)
    lines = result.stderr.splitlines()
    assert result.returncode == 2 and len(lines) == 1, (case, result.stderr)
    assert lines[0].startswith(f"chaingen: error: robot.urdf: {expected}"), lines[0]
    assert result.stdout == "" and snapshot(tmp_path) == before


def test_a_well_formed_robot_still_imports_and_reads_back(tmp_path):
    """The well-formed two-link robot still imports, and its scene reads back."""
    require_module("pinocchio", "robots")
    from chaingen.spatial.reader import load_spatial_scene

    (tmp_path / "robot.urdf").write_text(robot_urdf())
    result = chaingen("import", "robot.urdf", "-o", "scene.toml", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert load_spatial_scene(tmp_path / "scene.toml").n == 2


def test_a_point_mass_link_with_a_hand_beyond_the_tip_reads_back(tmp_path):
    """A link whose inertia is zero (a point mass) with a massive hand fixed beyond the tip:
    taking the hand out again left round-off of either sign in the link's inertia (1e-17 of
    0.1 kg m^2), and the file written was refused by the scene reader (a principal moment
    < 0 or past the sum of the other two). Within that round-off it is a point mass."""
    require_module("pinocchio", "robots")
    from chaingen.spatial.reader import load_spatial_scene

    def inertial(ixx, mass="1.3", origin='xyz="0.03 -0.02 0.05" rpy="0.3 -1.1 2.0"'):
        return (f'<inertial><origin {origin}/><mass value="{mass}"/><inertia ixx="{ixx}" '
                f'iyy="{ixx}" izz="{ixx}" ixy="0" ixz="0" iyz="0"/></inertial>')
    limit = '<limit lower="-1" upper="1" effort="1" velocity="1"/>'
    text = ('<robot name="r"><link name="base"/>'
            f'<link name="upper">{inertial("0.02")}</link>'
            f'<link name="lower">{inertial("0")}</link>'
            f'<link name="hand">{inertial("0.1", "2.7")}</link>'
            '<joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>'
            f'<origin xyz="0 0 0.2"/><axis xyz="0 1 0"/>{limit}</joint>'
            '<joint name="elbow" type="revolute"><parent link="upper"/><child link="lower"/>'
            f'<origin xyz="0.1 0 0.3" rpy="0.2 0.4 -0.7"/><axis xyz="0.6 0 0.8"/>{limit}'
            '</joint>'
            '<joint name="wrist" type="fixed"><parent link="lower"/><child link="hand"/>'
            '<origin xyz="0.31 -0.17 0.23" rpy="1.3 -0.4 2.9"/></joint></robot>')
    (tmp_path / "robot.urdf").write_text(text)
    result = chaingen("import", "robot.urdf", "-o", "scene.toml", "--tip", "lower",
                      cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    scene = load_spatial_scene(tmp_path / "scene.toml")
    assert scene.links[1].mass == pytest.approx(1.3, rel=1e-12)
    assert max(map(abs, scene.links[1].inertia)) <= 1e-15


# -- a controlled scene's refused method or order, named where the value came from ------------

PBC = ROOT / "scenes" / "four_link_pbc.toml"


def pbc_variant(tmp_path, old: str, new: str, name: str = "scene.toml"):
    text = PBC.read_text()
    assert old in text
    (tmp_path / name).write_text(text.replace(old, new))
    return name


CONTROL_REFUSALS = {
    # A value from the scene's [simulation] was named as the option --method / --order, which
    # the user had not given.
    "scene method, simulate": (
        ('method = "es"', 'method = "vi"'), ("simulate", "scene.toml", "--t-end", "0.01"),
        "chaingen: error: scene.toml: simulation.method: 'vi' has no controlled step"),
    "scene order, check": (
        ("quadrature = 3\n", "quadrature = 3\norder = 4\n"), ("check", "scene.toml"),
        "chaingen: error: scene.toml: simulation.order: a controlled scene's step is the "
        "scheme's own (order 2)"),
    "scene method, generate": (
        ('method = "es"', 'method = "vi"'), ("generate", "scene.toml", "-o", "package"),
        "chaingen: error: scene.toml: simulation.method: 'vi' has no controlled step"),
    "option still named": (
        ('method = "es"', 'method = "es"'),
        ("simulate", "scene.toml", "--method", "vi", "--t-end", "0.01"),
        "chaingen: error: --method: 'vi' has no controlled step"),
}


@pytest.mark.parametrize("case", sorted(CONTROL_REFUSALS))
def test_a_controlled_scenes_refusal_names_where_the_value_came_from(case, tmp_path):
    (old, new), arguments, expected = CONTROL_REFUSALS[case]
    pbc_variant(tmp_path, old, new)
    before = snapshot(tmp_path)
    result = chaingen(*arguments, cwd=tmp_path)
    lines = result.stderr.splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert lines[0].startswith(expected), lines[0]
    assert snapshot(tmp_path) == before


SWEEP_REFUSALS = {
    # The sweep spec's own `method` / `order` were named --method / --order.
    "spec method": ('method = "vi"\n', ("", ""),
                    "chaingen: error: spec.toml: method: 'vi' has no controlled step"),
    "spec order": ("order = 4\n", ("", ""),
                   "chaingen: error: spec.toml: order: a controlled scene's step"),
    "scene method": ("", ('method = "es"', 'method = "vi"'),
                     "chaingen: error: spec.toml: scene: "),
}


@pytest.mark.parametrize("case", sorted(SWEEP_REFUSALS))
def test_a_sweeps_control_refusal_names_its_spec_key_or_the_scene(case, tmp_path):
    key, (old, new), expected = SWEEP_REFUSALS[case]
    pbc_variant(tmp_path, old, new)
    (tmp_path / "spec.toml").write_text(f'scene = "scene.toml"\nt_end = 0.5\n{key}'
                                        '[axes]\n"control.target[0]" = [1.0]\n')
    before = snapshot(tmp_path)
    result = chaingen("sweep", "spec.toml", "-o", "out", cwd=tmp_path)
    lines = result.stderr.splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert lines[0].startswith(expected), lines[0]
    if case == "scene method":
        assert lines[0].endswith("scene.toml: simulation.method: 'vi' has no controlled step: "
                                 "scene 'four-link-pbc' has a [control] table, which es and "
                                 "midpoint take"), lines[0]
    assert snapshot(tmp_path) == before


# -- python -m chaingen.studies.control: bad input is one line, exit 2; its flags are heard --

STUDY_REFUSALS = {
    # Each ran: -1 and nan raised from deep inside (tracebacks), 0 printed a table of
    # "unstable (lost)" rows and "nan J" with exit 0, 0.3 ran dt = 0.2 s for 0.4 s.
    "negative": (["--t-end", "-1"], "--t-end: must be > 0 and finite (s), got -1.0"),
    "nan": (["--t-end", "nan"], "--t-end: must be > 0 and finite (s), got nan"),
    "zero": (["--t-end", "0"], "--t-end: must be > 0 and finite (s), got 0.0"),
    "not whole steps": (["--t-end", "0.3"],
                        "--t-end: 0.3 s is not a whole number of steps of dt = 0.2 s"),
    "too long": (["--t-end", "1e9"], "--t-end: 1000000000.0 s at dt = 0.001 s is"),
    "no scene": (["missing.toml"], "missing.toml: cannot read scene file"),
    "no control": ([str(ROOT / "scenes" / "three_link_mono.toml")],
                   "the scene has no [control] table"),
}


@pytest.mark.parametrize("case", sorted(STUDY_REFUSALS))
def test_the_control_studys_bad_input_is_one_line_exit_2(case, capsys, monkeypatch):
    from chaingen.studies import control

    def no_runs(*arguments, **keywords):
        raise AssertionError("the study ran with bad input")
    monkeypatch.setattr(control, "run_table", no_runs)
    arguments, expected = STUDY_REFUSALS[case]
    assert control.main(arguments) == 2
    captured = capsys.readouterr()
    assert captured.out == "" and len(captured.err.splitlines()) == 1, captured.err
    assert captured.err.startswith("python -m chaingen.studies.control: error: "), captured.err
    assert expected in captured.err, captured.err


@pytest.mark.parametrize("arguments, t_end, dts", [
    (["--quick", "--t-end", "0.2"], 0.2, (0.01, 0.1)),   # --t-end was ignored: ran 2 s
    (["--quick"], 2.0, (0.01, 0.1)),
    ([], 20.0, (0.001, 0.01, 0.05, 0.1, 0.2)),
])
def test_the_control_study_runs_the_t_end_it_is_given(arguments, t_end, dts, capsys,
                                                        monkeypatch):
    from chaingen.studies import control

    asked = []
    monkeypatch.setattr(control, "run_table",
                        lambda scene, dts, scales, t_end: asked.append((dts, t_end)) or [])
    assert control.main(arguments) == 0
    assert asked == [(dts, t_end)]
    output = capsys.readouterr().out
    assert f"t_end {t_end:g} s" in output
    assert "of the discrete law in es: no run of it took a step" in output


# -- chaingen plot names a controlled run's energy as its summary does: H_d -----------------

def write_run(directory, name: str, energy: str | None, n: int = 2, scene: str = "arm"):
    """An n-joint trajectory with energy flows, and its metadata (with `energy` as a
    controlled package's run records it, or without)."""
    import json

    import numpy as np
    header = ",".join(["t", *(f"phi{i}" for i in range(1, n + 1)),
                       *(f"omega{i}" for i in range(1, n + 1)),
                       "energy", "constraint_error", "input_work", "dissipated"])
    rows = [[k * 0.01, *(0.1 * i for i in range(1, n + 1)), *([0.0] * n), 5.0 - 0.1 * k, 0.0,
             0.0, 0.1 * k + 1e-9 * k] for k in range(4)]
    np.savetxt(directory / name, rows, delimiter=",", header=header, comments="")
    meta = {"scene": scene, "method": "es", "quadrature": 3, "order": 2, "dt": 0.01}
    if energy is not None:
        meta["energy"] = energy
    (directory / f"{name}.json").write_text(json.dumps(meta))
    return directory / name


@pytest.mark.parametrize("energies, label", [
    # A controlled run's axis said |H - H0 - W + D| while its summary and metadata said H_d.
    (["H_d = T + V + V_s: the closed loop's storage"], "|H_d - H_d0 - W + D| [J]"),
    ([None], "|H - H0 - W + D| [J]"),
    # Overlaid, one line each: as one line the label ran past its panel, over the others'.
    ([None, "H_d = T + V + V_s"], "|H - H0 - W + D|,\n|H_d - H_d0 - W + D| [J]"),
])
def test_plot_names_the_energy_the_run_recorded(energies, label, tmp_path, monkeypatch):
    """...and every panel's y label, as drawn, lies within its panel's height and within the
    figure."""
    from chaingen.views import plots

    figures = []
    monkeypatch.setattr(plots, "save_png", lambda figure, path: figures.append(figure) or path)
    runs = [plots.load_run(write_run(tmp_path, f"run{index}.csv", energy))
            for index, energy in enumerate(energies)]
    plots.plot_runs(runs, tmp_path / "figure.png")
    figure = figures[0]
    assert figure.axes[1].get_ylabel() == label
    figure.canvas.draw()
    renderer = figure.canvas.get_renderer()
    for axis in figure.axes:
        panel = axis.get_window_extent(renderer)
        drawn = axis.yaxis.label.get_window_extent(renderer)
        assert panel.y0 <= drawn.y0 and drawn.y1 <= panel.y1, (axis.get_ylabel(), drawn, panel)
        assert drawn.x0 >= 0.0, (axis.get_ylabel(), drawn)


def test_plot_refuses_an_energy_key_that_is_not_a_string(tmp_path):
    from chaingen.errors import PlotError
    from chaingen.views import plots

    path = write_run(tmp_path, "run.csv", None)
    (tmp_path / "run.csv.json").write_text('{"scene": "arm", "energy": 5}')
    with pytest.raises(PlotError, match="key 'energy' must be a string, got 5"):
        plots.load_run(path)


# -- chaingen animate of a run already made: an option of the run is refused, never ignored --

@pytest.mark.parametrize("options, flags", [
    # Each was ignored (exit 0, the animation written); only --method/--quadrature/--dt were
    # refused.
    (["--order", "4"], "--order"),
    (["--gradient", "chain"], "--gradient"),
    (["--rtol", "1e-6"], "--rtol"),
    (["--max-iterations", "3", "--warm-start", "off"], "--max-iterations/--warm-start"),
    (["--method", "es", "--dt", "0.1"], "--method/--dt"),
])
def test_animate_of_a_trajectory_refuses_the_options_of_a_run(options, flags, tmp_path):
    from helpers import chaingen_in_process

    (tmp_path / "scene.toml").write_text((ROOT / "scenes" / "three_link_mono.toml").read_text())
    write_run(tmp_path, "run.csv", None, n=3, scene="three-link-mono")
    before = snapshot(tmp_path)
    result = chaingen_in_process("animate", "scene.toml", "run.csv", *options, "-o", "a.gif",
                                 cwd=tmp_path)
    lines = result.stderr.splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert lines[0] == (f"chaingen: error: {flags}: only when animate simulates; the "
                        "trajectory run.csv is already a run"), lines[0]
    assert snapshot(tmp_path) == before


# -- a sweep of a controlled scene says that its energy is H_d -------------------------------

@pytest.mark.compile
def test_a_controlled_sweep_records_that_its_energy_is_h_d(tmp_path):
    """The trajectories' energy and runs.parquet's max_energy_error of a controlled scene are
    the closed loop's H_d (and its balance), as `simulate`'s metadata says; the sweep's
    record and trajectories named nothing of it. A row is also a single run's, bit for bit."""
    import json

    import numpy as np
    import pandas as pd
    import zarr

    from chaingen import build_solver, load_scene

    (tmp_path / "spec.toml").write_text(
        f'scene = "{PBC}"\nt_end = 0.2\nevery = 5\n'
        '[axes]\n"control.target[0]" = [4.0, -3.5]\n')
    result = chaingen("sweep", "-q", "spec.toml", "-o", "out", "--jobs", "1",
                          cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    record = json.loads((tmp_path / "out" / "sweep.json").read_text())
    assert record.get("energy", "").startswith("H_d = T + V + V_s"), record
    store = zarr.open_group(tmp_path / "out" / "trajectories.zarr", mode="r")
    assert store.attrs.get("energy") == record["energy"]
    runs = pd.read_parquet(tmp_path / "out" / "runs.parquet")
    scene = load_scene(PBC)
    single = build_solver(scene, parameters=["control.target[0]"], sensitivities=False)
    for _, row in runs.iterrows():
        alone = single.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                                n_steps=20, parameters=[row["control.target[0]"]])
        assert np.array_equal(alone.phi[-1], row[["phi1", "phi2", "phi3", "phi4"]].to_numpy(
            dtype=float))
        stored = np.asarray(store["energy"][int(row["run"])])
        assert np.array_equal(stored, alone.energy[::5])


# -- chaingen plot: --metric with trajectory files is refused, not ignored ---------------------

@pytest.mark.parametrize("arguments, expected", [
    # Drew the trajectory's figure (exit 0), --metric ignored.
    (["run.csv", "--metric", "newton_mean", "-o", "a.png"],
     "chaingen: error: --metric: only for a sweep's result directory; run.csv is a trajectory "
     "file"),
    # Said "sweep: no such trajectory file" of a directory.
    (["sweep", "run.csv", "-o", "a.png"],
     "chaingen: error: sweep: a directory: a sweep's results are drawn alone"),
])
def test_plot_of_trajectory_files_takes_no_sweep_option(arguments, expected, tmp_path):
    from helpers import chaingen_in_process

    write_run(tmp_path, "run.csv", None)
    (tmp_path / "sweep").mkdir()
    before = snapshot(tmp_path)
    result = chaingen_in_process("plot", *arguments, cwd=tmp_path)
    lines = result.stderr.splitlines()
    assert result.returncode == 2 and len(lines) == 1, result.stderr
    assert lines[0].startswith(expected), lines[0]
    assert snapshot(tmp_path) == before
