"""`chaingen bench` (chaingen.studies.bench): its options, its scaling scene, the cost
interpolation of headline c, the timing harness against the runtime, and the document it writes.

Bad options fail before anything runs; the harness builds one small package (compile tier). The
benchmark marker runs the quick benchmark itself (about a minute).
"""
from __future__ import annotations

import dataclasses
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from chaingen.cli import main
from chaingen.generate.package import generate_package
from chaingen.runtime import Solver
from chaingen.scene.kinematics import spring_geometry
from chaingen.studies.bench import bench_config
from chaingen.studies.bench.config import ADAPTIVE_K, VARIANTS
from chaingen.studies.bench.harness import Harness
from chaingen.studies.bench.headlines import (
    adaptive_headlines,
    compiled_peer_headlines,
    equal_error_headline,
    headlines,
    interpolate_cost,
)
from chaingen.studies.bench.report import (
    STIFF_HEADING,
    UNEVEN_HEADING,
    machine_description,
    markdown,
    replace_stiff_section,
    replace_uneven_section,
    uneven_comparison_table,
)
from chaingen.studies.bench.runs import RunRow
from chaingen.studies.bench.scaling import ScalingRow
from chaingen.studies.bench.scenes import scaling_scene, uneven_scene
from chaingen.studies.bench.stiff import StiffRow, cheapest, stiff_scene

from helpers import ROOT, load

HEADLINE_KEYS = ("a", "b", "c", "d", "e", "f", "g", "h")


# -- options ---------------------------------------------------------------------------------

# (id, options, fragments of the message)
BAD_OPTIONS = [
    ("dts not a number", ["--dts", "0.01,abc"], ["--dts", "'abc'"]),
    ("dts zero", ["--dts", "0"], ["--dts", "> 0"]),
    ("dts nan", ["--dts", "nan"], ["--dts", "nan"]),
    ("dts not dividing t_end", ["--dts", "0.03"], ["--dts", "0.03", "divide"]),
    ("scaling-n one", ["--scaling-n", "1"], ["--scaling-n", "1"]),
    ("scaling-n not an integer", ["--scaling-n", "2,2.5"], ["--scaling-n", "'2.5'"]),
    ("timeout zero", ["--timeout", "0"], ["--timeout"]),
    ("timeout negative", ["--timeout", "-5"], ["--timeout"]),
    ("stiff-only and skip-stiff", ["--stiff-only", "--skip-stiff"],
     ["--stiff-only", "--skip-stiff"]),
]


@pytest.mark.parametrize("options, fragments",
                         [pytest.param(*case[1:], id=case[0]) for case in BAD_OPTIONS])
def test_bad_option_is_one_line_and_exit_2(tmp_path, capsys, options, fragments):
    out = tmp_path / "benchmarks.md"
    assert main(["bench", *options, "--out", str(out), "--figures", str(tmp_path / "f")]) == 2
    captured = capsys.readouterr()
    assert captured.out == ""
    lines = captured.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("chaingen: error: "), captured.err
    for fragment in fragments:
        assert fragment in lines[0], (fragment, lines[0])
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("options, option", [
    pytest.param(lambda tmp: ["--out", str(tmp)], "--out", id="out is a directory"),
    pytest.param(lambda tmp: ["--out", str(tmp / "missing" / "b.md")], "--out",
                 id="out in a missing directory"),
    pytest.param(lambda tmp: ["--out", str(tmp / "b.md"), "--figures", str(tmp / "file")],
                 "--figures", id="figures is a file"),
])
def test_bad_output_paths(tmp_path, capsys, options, option):
    (tmp_path / "file").write_text("")
    assert main(["bench", *options(tmp_path)]) == 2
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 1 and option in lines[0], lines
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file"]


def test_bad_option_from_the_command_line(tmp_path):
    """The real command: exit 2, no traceback; a value argparse rejects prints its usage lines
    and then one error line, like the other commands."""
    result = subprocess.run([sys.executable, "-m", "chaingen", "bench", "--timeout", "soon",
                             "--out", str(tmp_path / "b.md")], capture_output=True, text=True,
                            cwd=tmp_path, timeout=120)
    assert result.returncode == 2, result.stderr
    assert "Traceback" not in result.stderr and result.stdout == ""
    assert "--timeout" in result.stderr.splitlines()[-1]
    assert list(tmp_path.iterdir()) == []


# -- the scaling scene -----------------------------------------------------------------------

@pytest.mark.parametrize("n", [2, 3, 5, 20])
def test_scaling_scene(n):
    scene = scaling_scene(n)
    assert scene.n == n
    mono = [spring for spring in scene.springs if not spring.is_multi_articular]
    multi = [spring for spring in scene.springs if spring.is_multi_articular]
    assert sorted(spring.first for spring in mono) == list(range(1, n + 1))
    expected = [(1, min(n, 3))] + ([(n - 2, n)] if n >= 6 else [])
    assert [(spring.first, spring.last) for spring in multi] == expected
    straight = np.zeros(n)
    for spring in scene.springs:   # rest lengths near the straight posture's, a little shorter
        length = spring_geometry(scene, spring, straight).total_length
        assert 0.9 * length <= spring.rest_length < length
    # hanging (phi_1 = -pi/2 is straight down), deflected, every other joint a little bent
    assert 0 < abs(scene.initial_angles[0] + math.pi / 2) < 0.5
    assert all(angle != 0 and abs(angle) < 0.5 for angle in scene.initial_angles[1:])
    assert scene.gravity == 9.81
    link = scene.links[0]
    assert math.isclose(link.inertia, link.mass * link.length ** 2 / 12)


@pytest.mark.parametrize("n", [2, 3, 5, 20])
def test_uneven_scene(n):
    """The uneven sibling: the scaling chain's springs and initial state on links that differ
    from their neighbours, every COM off the link axis."""
    scene, chain = uneven_scene(n), scaling_scene(n)
    assert scene.n == n and scene.gravity == chain.gravity
    assert [(s.first, s.last, s.stiffness) for s in scene.springs] == \
        [(s.first, s.last, s.stiffness) for s in chain.springs]
    assert scene.initial_angles == chain.initial_angles
    assert all(link.com_normal != 0 for link in scene.links)
    for a, b in zip(scene.links, scene.links[1:]):
        assert a.mass != b.mass and a.length != b.length and a.inertia != b.inertia
    straight = np.zeros(n)
    for spring in scene.springs:
        length = spring_geometry(scene, spring, straight).total_length
        assert math.isclose(spring.rest_length, 0.95 * length, rel_tol=1e-12)


def test_uneven_only_runs_es_on_both_chains(tmp_path):
    config = bench_config(uneven_only=True, scaling_n="2,20", out=tmp_path / "b.md")
    assert config.uneven_only and config.run_scaling
    assert not (config.run_reference or config.run_sweep or config.run_stiff)
    assert config.scaling_series == (("identical", "es", 3, "exact"), ("uneven", "es", 3, "exact"),
                                     ("identical", "es", 3, "chain"), ("uneven", "es", 3, "chain"))
    assert config.command == (f"chaingen bench --scaling-n 2,20 --uneven-only --out "
                              f"{tmp_path / 'b.md'}")
    assert ("uneven", "es", 3, "exact") in bench_config(out=tmp_path / "b.md").scaling_series
    for clash in ({"stiff_only": True}, {"skip_scaling": True}):
        with pytest.raises(Exception, match="--uneven-only"):
            bench_config(uneven_only=True, out=tmp_path / "b.md", **clash)


def test_uneven_section_is_replaced_in_place():
    section = f"{UNEVEN_HEADING}\n\nnew\n"
    old = f"# T\n\n## Scaling\n\ns\n\n{UNEVEN_HEADING}\n\nold\n\n## Speed knobs\n\nk\n"
    expected = f"# T\n\n## Scaling\n\ns\n\n{UNEVEN_HEADING}\n\nnew\n\n## Speed knobs\n\nk\n"
    assert replace_uneven_section(old, section) == expected
    # without one: at the end of the scaling section, or at the end
    assert replace_uneven_section("# T\n\n## Scaling\n\ns\n\n## Speed knobs\n\nk\n",
                                  section) == expected
    assert replace_uneven_section("# T\n\nh\n", section) == f"# T\n\nh\n\n{UNEVEN_HEADING}\n\nnew\n"
    assert replace_uneven_section(f"# T\n\n## Scaling\n\n{UNEVEN_HEADING}\n\nold\n", section) \
        == f"# T\n\n## Scaling\n\n{UNEVEN_HEADING}\n\nnew\n"


def test_uneven_comparison_table_pairs_the_chains():
    rows = [ScalingRow("es K=3", 20, variant.label, dt=0.01, step_seconds=step,
                       mujoco_step_seconds=4e-5, newton_iterations=7.0, chain=chain)
            for variant in VARIANTS for chain, step in (("identical", 2e-5), ("uneven", 3e-5))]
    table = uneven_comparison_table(rows)
    assert ("| 20 | es K=3 | default options | 20.00 us | 40.00 us | 0.50 | 30.00 us | 40.00 us "
            "| 0.75 |") in table


# -- headline c: cost at an energy error -----------------------------------------------------

def test_interpolate_cost_on_a_power_law():
    """error = 1e-2 cost^-2 is a straight line in log-log: interpolation is exact on it."""
    points = [(100.0, 1e-6), (1.0, 1e-2), (10.0, 1e-4)]          # any order
    assert interpolate_cost(points, 1e-5) == pytest.approx(10 ** 1.5, rel=1e-12)
    assert interpolate_cost(points, 1e-3) == pytest.approx(10 ** 0.5, rel=1e-12)
    assert interpolate_cost(points, 1e-4) == pytest.approx(10.0, rel=1e-12)   # a measured point
    assert interpolate_cost(points, 1e-2) == pytest.approx(1.0, rel=1e-12)


def test_interpolate_cost_refuses_to_extrapolate():
    points = [(1.0, 1e-2), (10.0, 1e-4), (100.0, 1e-6)]
    assert interpolate_cost(points, 1e-7) is None      # more accurate than any run
    assert interpolate_cost(points, 1e-1) is None      # less accurate than any run
    assert interpolate_cost([(1.0, 1e-2)], 1e-3) is None
    assert interpolate_cost([], 1e-3) is None


def test_interpolate_cost_takes_the_cheapest_crossing():
    """Round-off makes errors rise again at high cost: the target is first reached cheaply."""
    points = [(1.0, 1e-8), (2.0, 1e-12), (4.0, 1e-13), (8.0, 1e-11)]
    assert interpolate_cost(points, 1e-10) == pytest.approx(2 ** 0.5, rel=1e-12)


def _row(method: str, cost: float, error: float) -> RunRow:
    variant = "-" if method.startswith("SciPy") else VARIANTS[0].label
    return RunRow(scene="s", family="x", method=method, variant=variant, setting="", t_end=1.0,
                  run_seconds=cost, energy_error=error)


def test_headline_c_bounds_when_every_es_run_is_more_accurate():
    scipy = [_row("SciPy DOP853", 1.0, 1e-8), _row("SciPy DOP853", 4.0, 1e-12)]
    below = [_row("es K=3", 0.01, 1e-13), _row("es K=3", 0.02, 1e-14)]
    headline = equal_error_headline(scipy + below, VARIANTS[0], "es K=3")
    assert headline.measured.startswith(">= 200.0 (lower bound")
    assert headline.passed is True
    crossing = [_row("es K=3", 0.001, 1e-8), _row("es K=3", 0.1, 1e-12)]
    headline = equal_error_headline(scipy + crossing, VARIANTS[0], "es K=3")
    assert headline.measured.startswith("200.0 (2000.00 ms / 10.00 ms") and headline.passed
    above = [_row("es K=3", 0.01, 1e-6)]
    headline = equal_error_headline(scipy + above, VARIANTS[0], "es K=3")
    assert headline.passed is None and "not measured" in headline.measured


# -- headlines f-h: against the compiled peers -------------------------------------------------

def _held_row(family: str, method: str, cost: float, trajectory: float,
              energy: float) -> RunRow:
    variant = VARIANTS[0].label if family == "chaingen" else "-"
    return RunRow(scene="s", family=family, method=method, variant=variant, setting="x",
                  t_end=50.0, run_seconds=cost, early_trajectory_error=trajectory,
                  energy_error=energy)


HELD_ROWS = [
    _held_row("chaingen", "es K=3", 1e-3, 1e-5, 1e-11),
    _held_row("chaingen", "es K=3", 2e-3, 1e-7, 1e-12),
    _held_row("chaingen", "es K=3", 4e-3, 1e-9, 1e-13),
    _held_row("MuJoCo", "MuJoCo RK4", 1e-2, 1e-7, 1e-11),
    _held_row("compiled", "numbalsoda-DOP853", 3e-3, 5e-7, 5e-11),
    _held_row("compiled", "numbalsoda-DOP853", 5e-3, 1e-9, 1e-12),
    _held_row("compiled", "CVODES-BDF", 1e-3, 1e-4, 1e-6),          # never accurate enough
]


def test_headlines_f_g_take_the_cheapest_runs_holding_both_errors():
    f_mujoco, f_compiled, g, h6, h8 = compiled_peer_headlines(HELD_ROWS)
    assert [h.key for h in (f_mujoco, f_compiled, g, h6, h8)] == ["f", "f", "g", "h", "h"]
    assert f_mujoco.measured.startswith("0.2 (2.00 ms") and f_mujoco.passed is True
    assert f_compiled.measured.startswith("0.667 (2.00 ms") and f_compiled.passed is True
    assert "numbalsoda-DOP853" in f_compiled.measured
    assert g.measured.startswith("0.8 (4.00 ms") and g.passed is True
    slow = [row if row.family != "chaingen" else dataclasses.replace(
        row, run_seconds=row.run_seconds * 10) for row in HELD_ROWS]
    assert compiled_peer_headlines(slow)[1].passed is False          # 20 ms / 3 ms


def test_headline_h_interpolates_each_line():
    h6 = compiled_peer_headlines(HELD_ROWS)[3]
    # ours: between 1e-5 and 1e-7 rad, 1e-6 is half-way in log: sqrt(1 ms * 2 ms)
    assert h6.measured.startswith(f"ours: es K=3 {math.sqrt(2):.3g} ms")
    # the peers' runs are all more accurate: their cheapest bounds the ratio from above
    assert f"MuJoCo RK4 <= {1e-2 / math.sqrt(2e-6):.3g}" in h6.measured
    assert f"numbalsoda-DOP853 <= {3e-3 / math.sqrt(2e-6):.3g}" in h6.measured
    assert "not reaching 1e-06 rad: CVODES-BDF" in h6.measured
    assert h6.target == "none" and h6.mark == "measured"


def test_headlines_f_to_h_without_runs_say_so():
    for found in (compiled_peer_headlines([]),
                  compiled_peer_headlines([row for row in HELD_ROWS
                                           if row.family == "chaingen"]),
                  compiled_peer_headlines([row for row in HELD_ROWS
                                           if row.family != "chaingen"])):
        assert all(h.passed is None and "not" in h.measured for h in found), found
        assert all(h.mark == "not measured" for h in found)
    peers_only = compiled_peer_headlines([row for row in HELD_ROWS
                                          if row.family != "chaingen"])[3]
    assert "the peers at it: MuJoCo RK4 <= 10 ms, numbalsoda-DOP853 <= 3 ms" in peers_only.measured
    only_inaccurate = [HELD_ROWS[0], HELD_ROWS[-1]]
    f_mujoco, f_compiled, *_ = compiled_peer_headlines(only_inaccurate)
    assert "MuJoCo RK4's runs not in this run" in f_mujoco.measured
    assert "no run of ours holds both" in f_compiled.measured


# -- headline i: adaptive es against fixed steps of the same CPU ------------------------------

def _adaptive_rows(adaptive_cost: float, adaptive_error: float, energy: float = 1e-13):
    fixed = [_held_row("chaingen", f"es K={ADAPTIVE_K}", cost, error, 1e-13)
             for cost, error in ((1e-2, 1e-5), (4e-2, 1e-6), (1.6e-1, 1e-7))]
    adaptive = dataclasses.replace(
        _held_row("chaingen", f"es K={ADAPTIVE_K} adaptive", adaptive_cost, adaptive_error,
                  energy),
        setting="rtol = atol = 1e-08, samples every 0.05 s")
    order4 = dataclasses.replace(adaptive, method=f"es K={ADAPTIVE_K} order 4 adaptive",
                                 early_trajectory_error=1e-12)
    return fixed + [order4, adaptive]


def test_headline_i_interpolates_the_fixed_steps_at_the_adaptive_cpu():
    # fixed: error 1e-6 rad at 0.04 s; adaptive: 4e-6 rad there -> ratio 4
    ratio, energy = adaptive_headlines(_adaptive_rows(4e-2, 4e-6))
    assert ratio.key == energy.key == "i"
    assert ratio.measured.startswith("4 (4.00e-06 rad in 40 ms / 1.00e-06 rad") and ratio.passed
    assert energy.passed and energy.measured == "1.00e-13 J"
    worse, too_much = adaptive_headlines(_adaptive_rows(4e-2, 4e-5, energy=1e-11))
    assert worse.passed is False and too_much.passed is False
    outside, _ = adaptive_headlines(_adaptive_rows(1.0, 1e-8))
    assert outside.passed is None and "outside the fixed runs' CPU" in outside.measured
    assert all(h.passed is None for h in adaptive_headlines([]))


# -- the harness counts what the runtime counts ----------------------------------------------

@pytest.mark.compile
@pytest.mark.parametrize("variant", VARIANTS, ids=[v.label for v in VARIANTS])
def test_harness_iterations_agree_with_simulate(variant):
    scene = load("three_link_mono")
    package = generate_package(scene, "es", 1, sensitivities=False)
    solver = Solver.from_files(package.files)
    steps, dt = 400, 0.01
    result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=dt,
                             n_steps=steps, options=variant.newton_options(solver))
    x0 = solver.initial_state(scene.initial_angles, scene.initial_velocities)
    with Harness(package) as harness:
        timings = harness.time(x0, dt, n_steps=steps, repeats=1, options=variant.options)
    assert timings.mean_iterations == pytest.approx(result.mean_newton_iterations, abs=1e-12)
    assert timings.step_ns > 0 and timings.residual_jacobian_ns > 0


# -- the written document --------------------------------------------------------------------

def check_document(path: Path) -> None:
    text = path.read_text()
    headline = text.split("## Headline", 1)[1].split("\n## ", 1)[0]
    keys = {line.split("|")[1].strip() for line in headline.splitlines()
            if line.startswith("| ") and not line.startswith("| |")}
    assert keys >= set(HEADLINE_KEYS), keys
    for variant in VARIANTS:
        assert f"| {variant.label} |" in headline
    assert re.search(r"\| (pass|FAIL|not measured) \|", headline)
    machine = text.split("## Machine", 1)[1].split("\n## ", 1)[0]
    for item in ("- CPU:", "- cores:", "- memory:", "- OS:", "- C compiler:", "- our flags:",
                 "- MuJoCo:", "- SciPy:", "- compiled peers:", "- Python:",
                 "numpy, sympy, casadi"):
        assert item in machine, item
    assert "Written by `chaingen bench" in text
    figures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    assert figures
    for figure in figures:
        assert (path.parent / figure).is_file(), figure
        assert Path(figure).name.startswith("bench_")
    assert "nan" not in text.lower().split()


def test_the_document_has_every_part(tmp_path):
    """The report of a run (rows made up here, none measured) has its headline, machine,
    reference-scene and scaling sections and links its figures."""
    config = bench_config(out=tmp_path / "benchmarks.md")
    reference = {}
    for name in config.scenes:
        rows = [RunRow(scene=name, family="chaingen", method="es K=3", variant=variant.label,
                       setting="dt = 0.01 s", t_end=50.0, dt=0.01, n_steps=5000,
                       step_seconds=1e-6, run_seconds=5e-3, energy_error=1e-13,
                       newton_iterations=2.0, step_over_evaluation=3.0)
                for variant in VARIANTS]
        rows.append(RunRow(scene=name, family="MuJoCo", method="MuJoCo RK4", variant="-",
                           setting="dt = 0.01 s", t_end=50.0, dt=0.01, step_seconds=6e-6,
                           run_seconds=3e-2, energy_error=1e-7))
        reference[name] = rows
    scaling = [ScalingRow("es K=3", 20, variant.label, 3.0, 6.0, 150.0, 380.0, 10 ** 6, 0.01,
                          5e-5, 6.0, 3e-5) for variant in VARIANTS]
    figures = {name: config.figures / f"bench_{name}.png" for name in [*reference, "scaling"]}
    config.figures.mkdir()
    for figure in figures.values():
        figure.write_bytes(b"")
    text = markdown(config, headlines(reference, scaling, config), reference, scaling, figures,
                    machine_description(), 60.0)
    config.out.write_text(text)
    check_document(config.out)
    for name in config.scenes:
        assert f"### {name}" in text
    assert "## Scaling" in text and "Quick mode" not in text


@pytest.mark.benchmark
def test_quick_benchmark_writes_document_and_figures(tmp_path):
    out, figures = tmp_path / "benchmarks.md", tmp_path / "figures"
    result = subprocess.run([sys.executable, "-m", "chaingen", "bench", "--quick", "--out",
                             str(out), "--figures", str(figures)], capture_output=True,
                            text=True, cwd=ROOT, timeout=900)
    assert result.returncode == 0, result.stderr
    check_document(out)
    assert {path.name for path in figures.iterdir()} == {"bench_three_link_mono.png",
                                                         "bench_scaling.png",
                                                         "bench_stiff_chain.png"}
    assert STIFF_HEADING in out.read_text() and "| held errors |" in out.read_text()
    assert "| method | variant | setting |" in result.stdout      # tables printed as it goes
    assert "## Headline" in out.read_text() and "Quick mode" in out.read_text()
    assert not [p for p in tmp_path.rglob(".*")]                 # no temporary files left


@pytest.mark.compile
def test_scaling_point_measures_time_and_memory():
    """One point of the scaling series as its child process computes it (n = 2, cheap)."""
    from chaingen.studies.bench.scaling import measure_scaling_point

    point = measure_scaling_point("midpoint", 3, 2, n_steps=50, repeats=2)
    assert point["generate_seconds"] > 0 and point["build_seconds"] > 0
    assert point["generate_peak_kb"] > 0 and point["model_c_bytes"] > 0
    if Path("/usr/bin/time").exists():
        # the compiler's own peak, not the fork-inherited one of the Python process
        assert 0 < point["compile_peak_kb"] < point["generate_peak_kb"]
    for variant in VARIANTS:
        timing = point["timings"][variant.label]
        assert timing["dt"] == 0.01 and timing["step_ns"] > 0 and not timing["failures"]
        assert timing["mujoco_step_seconds"] > 0      # MuJoCo timed beside it, in the child


@pytest.mark.compile
def test_control_study_measures_every_loop_and_headline_j(tmp_path):
    """The control loops' part: four loops with their peers, and headline j from them."""
    from chaingen.studies.bench.control import control_study, control_table
    from chaingen.studies.bench.headlines import control_headlines

    config = bench_config(quick=True, out=tmp_path / "benchmarks.md")
    rows = control_study(config, lambda message: None)
    assert len(rows) == 4
    assert all(row.seconds > 0 and row.peer_seconds > 0 for row in rows)
    table = control_table(rows, config)
    assert "stepper.step" in table and "PD in C" in table
    found = control_headlines(rows)
    assert [h.key for h in found] == ["j", "j"]
    assert all(h.passed in (True, False) for h in found)
    assert all(h.passed is None for h in control_headlines(None))


@pytest.mark.compile
def test_control_call_study_times_control_torques_beside_step_and_simulate(tmp_path):
    """The embedded controller's call on four_link_pbc, timed in one C program beside step and
    the open-loop simulate: the three loops take the same steps (iterations and final states
    bit for bit), so the table compares the calls' cost alone."""
    from chaingen.studies.bench.control import control_call_study, control_call_table

    config = bench_config(quick=True, out=tmp_path / "benchmarks.md")
    timings = control_call_study(config, lambda message: None)
    assert timings.scene == "four-link-pbc" and timings.dt == 0.01
    assert min(timings.control_torques, timings.step, timings.simulate) > 0
    assert timings.same_end
    assert timings.iterations[0] == timings.iterations[1] == timings.iterations[2] > 1
    table = control_call_table(timings)
    assert "| control_torques (tau and x1) |" in table and "| step (x1) |" in table
    assert "bit for bit equal: yes" in table


# -- the stiff chain's work-precision --------------------------------------------------------

def test_stiff_scene_is_the_scaling_chain_with_stiff_springs():
    scene, chain = stiff_scene(10, 2e4), scaling_scene(10)
    assert scene.name == "stiff-chain-10" and scene.n == 10
    assert [spring.stiffness for spring in scene.springs] == [2e4] * len(chain.springs)
    assert [dataclasses.replace(spring, stiffness=0.0) for spring in scene.springs] == \
        [dataclasses.replace(spring, stiffness=0.0) for spring in chain.springs]
    assert scene.links == chain.links and scene.initial_angles == chain.initial_angles


def test_stiff_only_runs_that_part_alone(tmp_path):
    config = bench_config(stiff_only=True, out=tmp_path / "b.md")
    assert config.run_stiff and config.stiff_only
    assert not (config.run_reference or config.run_scaling or config.run_sweep)
    assert config.command == f"chaingen bench --stiff-only --out {tmp_path / 'b.md'}"
    assert config.stiff.n == 10 and config.stiff.t_end == 0.2
    assert config.stiff.reference_rtol == 1e-13
    full = bench_config(out=tmp_path / "b.md")
    assert full.run_stiff and not full.stiff_only
    assert not bench_config(skip_stiff=True, out=tmp_path / "b.md").run_stiff
    quick = bench_config(quick=True, out=tmp_path / "b.md")
    assert quick.stiff.n < config.stiff.n


def test_stiff_section_is_replaced_in_place():
    section = f"{STIFF_HEADING}\n\nnew\n"
    old = (f"# T\n\n## Headline\n\nh\n\n{STIFF_HEADING}\n\nold\n\n## Scaling\n\ns\n")
    text = replace_stiff_section(old, section)
    assert text == f"# T\n\n## Headline\n\nh\n\n{STIFF_HEADING}\n\nnew\n\n## Scaling\n\ns\n"
    # without one: before the scaling section, or at the end
    assert replace_stiff_section("# T\n\n## Headline\n\nh\n\n## Scaling\n\ns\n", section) \
        == f"# T\n\n## Headline\n\nh\n\n{STIFF_HEADING}\n\nnew\n\n## Scaling\n\ns\n"
    assert replace_stiff_section("# T\n\nh\n", section) == f"# T\n\nh\n\n{STIFF_HEADING}\n\nnew\n"
    # the last section
    assert replace_stiff_section(f"# T\n\n{STIFF_HEADING}\n\nold\n", section) == \
        f"# T\n\n{STIFF_HEADING}\n\nnew\n"


def test_cheapest_run_holds_both_errors():
    rows = [StiffRow("chaingen", "es K=3", "a", run_seconds=1.0, trajectory_error=1e-3,
                     relative_energy_error=1e-14),
            StiffRow("chaingen", "es K=3", "b", run_seconds=3.0, trajectory_error=1e-6,
                     relative_energy_error=1e-14),
            StiffRow("compiled", "CVODES-BDF", "c", run_seconds=0.5, trajectory_error=1e-7,
                     relative_energy_error=1e-8),
            StiffRow("compiled", "CVODES-BDF", "d", failure="failed")]
    assert cheapest(rows, ("chaingen",), 1e-2, None).setting == "a"
    assert cheapest(rows, ("chaingen",), 1e-5, 1e-12).setting == "b"
    assert cheapest(rows, ("compiled",), 1e-5, None).setting == "c"
    assert cheapest(rows, ("compiled",), None, 1e-12) is None


@pytest.mark.compile
@pytest.mark.slow
def test_stiff_part_quick_writes_its_section_in_place(tmp_path):
    """The stiff chain's part in its quick form (three links), run alone into an existing
    report: its table has a row for every run of ours and of the peers, with both errors, and
    replaces the old section only."""
    from chaingen.reference.compiled_peers import numbalsoda_available
    from chaingen.studies.bench import run_bench
    from chaingen.views import bench_figures

    out = tmp_path / "benchmarks.md"
    # a quick run's report: --quick refuses to write into a full one
    out.write_text(f"# Benchmarks: speed against accuracy\n\n**Quick mode**\n\n"
                   f"## Headline\n\nkept\n\n"
                   f"{STIFF_HEADING}\n\nold numbers\n\n## Scaling\n\nkept too\n")
    config = bench_config(quick=True, stiff_only=True, out=out)
    report = run_bench(config, note=lambda message: None, emit=lambda message: None,
                       figures=bench_figures)
    text = out.read_text()
    assert "old numbers" not in text and text.count(STIFF_HEADING) == 1
    assert "kept\n" in text and "kept too" in text
    assert text.index("## Headline") < text.index(STIFF_HEADING) < text.index("## Scaling")
    assert "Written by `chaingen bench --quick --stiff-only" in text
    assert (tmp_path / "figures" / "bench_stiff_chain.png").stat().st_size > 0
    section = text.split(STIFF_HEADING, 1)[1].split("\n## ", 1)[0]
    header = ("| method | setting | steps | per step | run CPU | trajectory error at t_end [rad] "
              "| max energy error [J] | energy error / E_ref | Newton it. | note |")
    assert header in section
    table = section.split(header, 1)[1].strip().splitlines()[1:]
    rows = {row.method: row for row in report.stiff.rows}
    assert len(table) == len(report.stiff.rows)
    assert all(line.count("|") == header.count("|") for line in table)
    summary = section.split("| held errors |", 1)[1].split("\n\n", 1)[0].splitlines()[2:]
    assert len(summary) == len(config.stiff.levels)
    ours = ["es K=3", "es K=3 quadrature", "vi", "midpoint order 4", "es K=3 adaptive"]
    peers = ["CVODES-BDF", "CVODES-Adams", "numbalsoda-LSODA", "numbalsoda-DOP853",
             "MuJoCo RK4"]
    assert set(rows) == set(ours + peers)
    for method in ours + peers:
        assert any(line.startswith(f"| {method} |") for line in table), method
        measured = [row for row in report.stiff.rows if row.method == method]
        if method.startswith("numbalsoda") and not numbalsoda_available():
            assert "not run" in measured[0].failure
            continue
        for row in measured:
            assert not row.failure, (method, row.failure)
            assert row.run_seconds > 0 and 0 < row.trajectory_error < 1.0
            assert row.relative_energy_error >= 0
    # es conserves energy to round-off with the exact gradient, not with the quadrature alone
    assert rows["es K=3"].relative_energy_error < 1e-12
    assert rows["es K=3 adaptive"].relative_energy_error < 1e-12
    exact = [row for row in report.stiff.rows if row.method == "es K=3" and row.dt == 1e-3]
    assert rows["es K=3 quadrature"].relative_energy_error > 100 * \
        exact[0].relative_energy_error
