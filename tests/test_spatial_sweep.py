"""Sweeps of spatial scenes: the spec reads a spatial base scene (its axes the spatial run-time
numbers, chaingen.spatial.parameters, and the per-run ones), refuses its geometry in one line,
judges every run by the spatial reader, and a sweep's rows are the single runs with the same
values (a differential test on hypothesis-drawn values); the Dask engine gives the local rows.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from chaingen.spatial import load_spatial_scene
from chaingen.spatial.parameters import with_values
from chaingen.spatial.values import SPATIAL_SIMULATION_DEFAULTS

from helpers import ROOT, chaingen_in_process

pytest.importorskip("pandas")
from chaingen.studies.sweep import run_sweep, sweep  # noqa: E402
from chaingen.studies.sweep.spec import SweepError, load_spec, parse_spec  # noqa: E402

SPATIAL = ROOT / "scenes" / "spatial_three_link.toml"
SCENE = load_spatial_scene(SPATIAL)


def spec_document(axes: dict, **keys) -> dict:
    return {"scene": str(SPATIAL), **keys, "axes": axes}


# -- the spec --------------------------------------------------------------------------------------

def test_a_spatial_spec_takes_the_spatial_numbers_and_the_run_settings_defaults():
    spec = parse_spec(spec_document({"springs[1].stiffness": [100.0, 200.0],
                                     "gravity[2]": {"from": -9.81, "to": -5.0, "num": 3},
                                     "links[0].damping": [0.0, 0.1],
                                     "initial.angles[1]": [-0.5, 0.1]}))
    assert spec.scene == SCENE and len(spec.runs) == 24
    # The scene file has no [simulation] table: its defaults, midpoint the method.
    assert SCENE.simulation == SPATIAL_SIMULATION_DEFAULTS
    assert spec.method == SPATIAL_SIMULATION_DEFAULTS.method == "midpoint"
    assert spec.t_end == SPATIAL_SIMULATION_DEFAULTS.t_end and spec.n_steps({}) == 1000
    assert spec.parameters == ("springs[1].stiffness", "gravity[2]", "links[0].damping")
    assert spec.solver.parameters == spec.parameters and spec.solver.scene == SCENE


@pytest.mark.parametrize("axes, fragment", [
    ({"links[0].com": [0.0, 0.1]}, 'axes."links[0].com": compiled geometry of a spatial scene'),
    ({"springs[0].route[1]": [0.0]}, "compiled geometry"),
    ({"gravity": [9.81]}, "a vector; name one component"),
    ({"links[1].mass": [1.0, -1.0]}, "axes: run 1 (links[1].mass = -1): links[1].mass: must be "
                                     "> 0 (mass in kg, link 2), got -1.0"),
    ({"springs[0].stiffness": [0.0]}, "springs[0].stiffness: must be > 0"),
])
def test_what_a_spatial_sweep_cannot_vary_is_refused_in_one_line(axes, fragment):
    with pytest.raises(SweepError) as refused:
        parse_spec(spec_document(axes), "sweep.toml")
    message = str(refused.value)
    assert message.startswith("sweep.toml: ") and fragment in message and "\n" not in message


def test_initial_angles_that_collapse_a_spring_segment_are_judged_by_the_reader(tmp_path):
    """A spring from (0.05, 0, 0.1) on the base to (0.05, 0, 0) on link 1 (joint 1 turns about
    the base's z through (0, 0, 0.1)): its segment has zero length at q_1 = 0 alone. The
    scene (q_1 = 0.3) is valid; the run that sets q_1 = 0 is named with the reader's message."""
    text = SPATIAL.read_text().replace(
        "route = [[0, 0.08, 0.0, 0.05], [1, 0.06, 0.04, 0.25]]",
        "route = [[0, 0.05, 0.0, 0.1], [1, 0.05, 0.0, 0.0]]")
    (tmp_path / "arm.toml").write_text(text)
    spec = tmp_path / "sweep.toml"
    spec.write_text('scene = "arm.toml"\n[axes]\n"initial.angles[0]" = [0.3, 0.2, 0.0]\n')
    with pytest.raises(SweepError) as refused:
        load_spec(spec)
    assert str(refused.value).startswith(
        f"{spec}: axes: run 2 (initial.angles[0] = 0): springs[0]: segment 1 (route[0] to "
        "route[1]) has zero length at the initial angles")
    spec.write_text('scene = "arm.toml"\n[axes]\n"initial.angles[0]" = [0.3, 0.2]\n')
    assert len(load_spec(spec).runs) == 2


def test_the_command_line_runs_a_spatial_sweep_and_refuses_its_geometry(tmp_path):
    spec = tmp_path / "sweep.toml"
    spec.write_text(f'scene = "{SPATIAL}"\n[axes]\n"links[0].inertia" = [0.1]\n')
    result = chaingen_in_process("sweep", spec, "-o", "out", cwd=tmp_path)
    assert result.returncode == 2 and not (tmp_path / "out").exists()
    assert result.stderr.splitlines() == [
        f'chaingen: error: {spec}: axes."links[0].inertia": compiled geometry of a spatial '
        "scene (it shapes the generated code); its run-time numbers: "
        "gravity[0..2], links[i].mass, links[i].damping, springs[i].stiffness, "
        "springs[i].rest_length"]


# -- rows = single runs ----------------------------------------------------------------------------

@pytest.mark.compile
@settings(max_examples=3, deadline=None, derandomize=True, database=None)
@given(values=st.lists(st.tuples(st.floats(20.0, 400.0), st.floats(0.0, 0.4),
                                 st.floats(-12.0, -6.0), st.floats(0.3, 3.0),
                                 st.floats(-1.0, 1.0)), min_size=2, max_size=2))
@pytest.mark.slow
def test_a_sweeps_rows_are_the_single_runs_with_the_same_values(values):
    """Drawn stiffness, rest length, gravity, mass and initial angle, zipped into runs: each
    row's final state and summaries are those of the run of a solver built from the scene with
    the run's values compiled in (with_values) to round-off, and those of the sweep's own
    solver called alone bit for bit."""
    from chaingen.simulation import build_solver

    paths = ("springs[1].stiffness", "springs[0].rest_length", "gravity[2]", "links[2].mass",
             "initial.angles[1]")
    axes = {path: [float(run[k]) for run in values] for k, path in enumerate(paths)}
    spec = parse_spec(spec_document(axes, mode="zip", t_end=0.2))
    runs = sweep(spec)
    solver = build_solver(spec.solver)
    for index, row in runs.iterrows():
        run = spec.runs[index]
        angles = list(SCENE.initial_angles)
        angles[1] = run["initial.angles[1]"]
        alone = solver.simulate(angles, SCENE.initial_velocities, dt=0.01, n_steps=20,
                                parameters={path: run[path] for path in spec.parameters})
        final = np.concatenate([alone.phi[-1], alone.omega[-1]])
        assert row["status"] == "ok" and row["steps"] == 20
        assert [row[f"phi{i}"] for i in (1, 2, 3)] + [row[f"omega{i}"] for i in (1, 2, 3)] \
            == final.tolist()
        scene = with_values(SCENE, {path: run[path] for path in spec.parameters})
        compiled = build_solver(scene, "midpoint", sensitivities=False).simulate(
            angles, SCENE.initial_velocities, dt=0.01, n_steps=20)
        np.testing.assert_allclose(final, np.concatenate([compiled.phi[-1], compiled.omega[-1]]),
                                   rtol=0, atol=1e-12)
        assert row["max_energy_error"] == np.abs(alone.balance_error).max()
        assert row["max_energy_error"] == pytest.approx(np.abs(compiled.balance_error).max(),
                                                        rel=1e-9, abs=1e-13)


@pytest.mark.compile
def test_the_dask_engine_gives_the_local_rows_of_a_spatial_sweep(tmp_path):
    import pandas as pd
    import xarray as xr

    spec = parse_spec(spec_document({"springs[1].stiffness": [100.0, 300.0],
                                     "links[1].mass": [1.0, 2.5], "gravity[0]": [0.0, 2.0]},
                                    t_end=0.5, every=5))
    run_sweep(spec, tmp_path / "local")
    outcome = run_sweep(spec, tmp_path / "dask", engine="dask", dask_local=2)
    assert outcome.computed == 8

    def rows(out):
        return pd.read_parquet(out / "runs.parquet").drop(columns=["cpu_seconds"])

    pd.testing.assert_frame_equal(rows(tmp_path / "dask"), rows(tmp_path / "local"),
                                  check_exact=True)
    assert (rows(tmp_path / "local")["status"] == "ok").all()
    xr.testing.assert_identical(
        xr.open_zarr(tmp_path / "dask" / "trajectories.zarr", consolidated=False).load(),
        xr.open_zarr(tmp_path / "local" / "trajectories.zarr", consolidated=False).load())
