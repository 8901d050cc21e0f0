"""Adaptive steps (options rtol/atol, scene keys simulation.rtol/atol, docs/model.md section 15):
the error control, es's energy on a varying step, the landing on the sample intervals, steps
that Newton fails refused and retried shorter, and the bad inputs."""
from __future__ import annotations

import json
import math
from functools import cache

import numpy as np
import pytest

from chaingen.errors import NewtonError, SceneError
from chaingen.runtime import NewtonOptions
from chaingen.runtime.contract import STATUS_CODES
from chaingen.scene import parse_scene

from helpers import chaingen_in_process, load, scene_path


@cache
def solver(name: str, method: str, order: int = 2, quadrature: int = 3):
    from chaingen.simulation import build_solver
    return build_solver(load(name), method, quadrature, order=order, sensitivities=False)


@cache
def reference_at_3s(name: str):
    from chaingen.reference.scipy_peer import reference_solution
    return reference_solution(load(name), 3.0)[0]


def angle_error(phi, reference) -> float:
    return float(np.abs((np.asarray(phi) - reference + math.pi) % (2 * math.pi) - math.pi).max())


def adaptive_run(name, method, rtol, *, dt=0.05, t_end=10.0, order=2, **options):
    scene = load(name)
    return solver(name, method, order).simulate(
        scene.initial_angles, scene.initial_velocities, dt=dt, n_steps=round(t_end / dt),
        options={"rtol": rtol, "atol": rtol, **options})


# -- no compiler ------------------------------------------------------------------------------

def test_the_scene_keys_are_read_and_bad_ones_refused():
    text = scene_path("three_link_multi").read_text()
    scene = parse_scene(text.replace("[simulation]", "[simulation]\nrtol = 1e-8\natol = 1e-9"),
                        "s.toml", "s")
    assert (scene.simulation.rtol, scene.simulation.atol) == (1e-8, 1e-9)
    for bad in ("-1e-8", '"tight"', "true", "inf", "1e-20"):
        with pytest.raises(SceneError, match=r"^s\.toml: simulation\.rtol: must be 0 \(fixed "):
            parse_scene(text.replace("[simulation]", f"[simulation]\nrtol = {bad}"), "s.toml", "s")


def test_bad_tolerances_are_refused_in_python_and_on_the_command_line(tmp_path):
    for name in ("rtol", "atol"):
        with pytest.raises(ValueError, match=f"NewtonOptions.{name}: must be 0"):
            NewtonOptions(**{name: -1.0})
    result = chaingen_in_process("simulate", str(scene_path("three_link_multi")),
                                 "--rtol=-1e-8", cwd=tmp_path)
    assert result.returncode == 2 and "--rtol: must be 0 (fixed steps) or from" in result.stderr
    assert "Traceback" not in result.stderr
    # chaingen order fits fixed steps: adaptive tolerances there are a mistake, said so.
    result = chaingen_in_process("order", str(scene_path("three_link_multi")), "--rtol", "1e-8",
                                 cwd=tmp_path)
    assert result.returncode == 2 and "chaingen order fits the error of fixed steps" in (
        result.stderr)
    assert list(tmp_path.iterdir()) == []


# -- compiled ---------------------------------------------------------------------------------

@pytest.mark.compile
@pytest.mark.parametrize("order", [2, 4])
def test_adaptive_es_keeps_its_energy_and_meets_its_tolerance(order):
    """The step adapts (its length varies), the energy stays at round-off, the constraints at
    round-off, and the trajectory error at t = 3 s shrinks with the tolerance."""
    reference = reference_at_3s("three_link_multi")
    errors = {}
    loose, tight = {2: (1e-5, 1e-8), 4: (1e-8, 1e-11)}[order]
    for rtol in (loose, tight):
        result = adaptive_run("three_link_multi", "es", rtol, order=order)
        assert result.adaptive and result.n_steps == 200
        assert result.smallest_dt <= result.largest_dt <= 0.025
        assert result.accepted_steps >= 2 * result.n_steps
        if rtol == tight:
            assert result.smallest_dt < result.largest_dt
        assert np.abs(result.energy_error).max() <= 1e-12
        assert result.constraint_error.max() <= 1e-13
        errors[rtol] = angle_error(result.phi[60], reference)
    # The tolerance bounds each step's local error; over the 3 s (about 1500 steps at order 2,
    # 300 at order 4) the global error is larger, by the error's growth along the orbit.
    assert errors[tight] < {2: 1e-5, 4: 1e-9}[order]
    assert errors[tight] < errors[loose] / 10


@pytest.mark.compile
@pytest.mark.parametrize("method", ["vi", "midpoint"])
def test_vi_and_midpoint_adapt_too(method):
    result = adaptive_run("three_link_multi", method, 1e-8, t_end=3.0)
    assert result.rejected_steps >= 0 and result.smallest_dt < result.largest_dt
    assert angle_error(result.phi[-1], reference_at_3s("three_link_multi")) < 1e-5
    assert result.constraint_error.max() <= 1e-13


@pytest.mark.compile
def test_fixed_steps_report_their_step():
    scene = load("three_link_multi")
    result = solver("three_link_multi", "es").simulate(
        scene.initial_angles, scene.initial_velocities, dt=0.01, n_steps=50)
    assert not result.adaptive
    assert (result.accepted_steps, result.rejected_steps) == (50, 0)
    assert result.smallest_dt == result.largest_dt == 0.01


@pytest.mark.compile
def test_a_step_newton_fails_is_refused_and_retried_shorter():
    """With two Newton iterations a step, fixed steps of 0.05 s stop; adaptive ones refuse the
    failing steps, shorten them, and finish with es's energy."""
    scene = load("three_link_multi")
    options = {"max_iterations": 2, "warm_start": False}
    with pytest.raises(NewtonError):
        solver("three_link_multi", "es").simulate(
            scene.initial_angles, scene.initial_velocities, dt=0.05, n_steps=100,
            options=options)
    result = adaptive_run("three_link_multi", "es", 1e-3, t_end=5.0, **options)
    assert result.rejected_steps > 0
    assert result.n_steps == 100
    assert np.abs(result.energy_error).max() <= 1e-12


@pytest.mark.compile
def test_a_failure_at_every_step_length_stops_with_its_own_status():
    """collapsing_spring reaches a zero-length segment at t = 0.25 s: every shorter step
    collapses it too, down to the floor of 1e-12 dt, and the run says why it stopped."""
    from chaingen.scene import load_reference_scene
    scene = load_reference_scene("collapsing_spring")
    from chaingen.simulation import build_solver
    collapsing = build_solver(scene, "es", 3, sensitivities=False)
    with pytest.raises(NewtonError, match="spring segment") as caught:
        collapsing.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                            n_steps=100, options={"rtol": 1e-8, "atol": 1e-8})
    assert caught.value.status == STATUS_CODES["SEGMENT_COLLAPSED"]
    assert caught.value.result.n_steps == 25
    assert caught.value.result.rejected_steps >= 20
    assert caught.value.result.smallest_dt < 1e-12


def test_tolerances_below_round_off_are_refused():
    for value in (1e-15, 1e-30):
        with pytest.raises(ValueError, match="must be 0 .fixed steps. or from 1e-14 up"):
            NewtonOptions(rtol=value)


@pytest.mark.compile
def test_the_command_line_and_the_scene_run_adaptive_steps(tmp_path):
    text = scene_path("three_link_multi").read_text()
    scene = tmp_path / "adaptive.toml"
    scene.write_text(text.replace("[simulation]", "[simulation]\nrtol = 1e-7\natol = 1e-7"))
    result = chaingen_in_process("simulate", str(scene), "--t-end", "2", "--dt", "0.05",
                                 "--out", str(tmp_path / "run.csv"), cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "adaptive steps" in result.stdout and "rtol 1e-07" in result.stdout
    assert "intervals" in result.stdout
    metadata = json.loads((tmp_path / "run.csv.json").read_text())
    steps = metadata["adaptive_steps"]
    assert steps["accepted"] >= 80 and steps["smallest_dt"] <= steps["largest_dt"] <= 0.025
    # --rtol 0 --atol 0 on the command line turns the scene's adaptive steps off.
    result = chaingen_in_process("simulate", str(scene), "--t-end", "2", "--rtol", "0",
                                 "--atol", "0", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "adaptive steps" not in result.stdout


@pytest.mark.compile
def test_adaptive_es_completes_a_stiff_chain_at_rtol_1e_12():
    """The stiff chain of docs/extremes.md (k = 1e6 N/m) at rtol 1e-12 with atol 0: a joint
    angle passes near zero at t = 0.026 s, where rtol |phi| fell below the round-off of the two
    results' difference (1e-16 rad: the angles come from coordinates). Every step was refused
    down to 1e-12 dt and the run stopped at t = 0.04 s. With the estimate's floor at the
    round-off of its block (docs/model.md section 15) it completes, with es's energy."""
    from chaingen.simulation import build_solver
    from chaingen.studies.extremes import chain

    scene = chain(3, stiffness=1e6)
    stiff = build_solver(scene, "es", 3, sensitivities=False)
    result = stiff.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01, n_steps=10,
                            options={"rtol": 1e-12, "atol": 0.0})
    assert result.n_steps == 10
    assert result.smallest_dt > 1e-9 and result.rejected_steps < 20
    assert np.abs(result.energy_error).max() <= 1e-12 * abs(result.energy[0])
    assert result.constraint_error.max() <= 1e-12
