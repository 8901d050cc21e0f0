"""Property-based guards of sweeps (hypothesis).

Compile tier: random sweep specs over the reference scenes (axes, modes, every, t_end, orders,
adaptive steps), each row of runs.parquet and each kept trajectory checked against a single
`simulate` of the same numbers with a solver built the same way: the final state, the metrics
and the samples, bitwise. Durations are drawn in whole steps (a t_end between steps is refused,
docs/sweep-format.md section 5), now and then one between steps, which must be refused. The
solvers are few (SOLVERS: scene, method, order, parameters), built once each and shared by the
examples, and every run is short, so 200 examples take about a minute. Fast tier: the numpy
screen of a spec's runs (checks.py) passes no run that the scene reader refuses.
"""
from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from chaingen.errors import NewtonError, SceneError
from chaingen.scene.parameters import number_path, with_values
from chaingen.studies.sweep import SweepError, parse_spec, run_sweep
from chaingen.studies.sweep.checks import suspects

from helpers import ROOT, load

#: Examples of the compile-tier property (CHAINGEN_SWEEP_EXAMPLES overrides, e.g. for a soak).
EXAMPLES = int(os.environ.get("CHAINGEN_SWEEP_EXAMPLES", "200"))

#: The solvers the examples share: (scene, method, order, compiled axis or None).
SOLVERS = (("three_link_mono", "es", 2, None), ("three_link_mono", "es", 4, None),
           ("three_link_mono", "es", 2, "springs[0].stiffness"),
           ("three_link_gravity", "midpoint", 2, None), ("four_link_actuated", "vi", 2, None))

RUN_AXES = {"initial.angles[0]": (-1.0, 1.0), "initial.velocities[1]": (-1.0, 1.0),
            "simulation.dt": (0.004, 0.02), "simulation.t_end": (0.04, 0.2)}
#: dt and t_end values of whole steps: every dt here divides every t_end, and the midpoints of
#: the t_ends (a range's values) too. OFF_GRID divides none and is divided by none.
DTS = (0.004, 0.005, 0.01, 0.02)
T_ENDS = (0.04, 0.08, 0.12, 0.2)
OFF_GRID = 0.013

_SINGLE: dict = {}


def single_solver(scene_name: str, method: str, order: int, parameters: tuple):
    from chaingen.simulation import build_solver

    key = (scene_name, method, order, parameters)
    if key not in _SINGLE:
        scene = load(scene_name)
        _SINGLE[key] = build_solver(scene, method, scene.simulation.quadrature,
                                    sensitivities=False, parameters=parameters, order=order)
    return _SINGLE[key]


@st.composite
def sweep_specs(draw):
    scene_name, method, order, compiled = draw(st.sampled_from(SOLVERS))
    mode = draw(st.sampled_from(["product", "zip", "sample"]))
    names = draw(st.lists(st.sampled_from(sorted(RUN_AXES)), min_size=0, max_size=2,
                          unique=True))
    if compiled:
        names = [compiled] + names
    if not names:
        names = ["initial.angles[0]"]
    bounds = {**RUN_AXES, "springs[0].stiffness": (1.0, 30.0)}
    value = st.floats(0.0, 1.0)
    count = draw(st.integers(1, 3))
    axes = {}
    off_grid = draw(st.integers(0, 9)) == 0        # one spec in ten: a duration between steps
    for name in names:
        low, high = bounds[name]
        if name in ("simulation.dt", "simulation.t_end"):
            grid = DTS if name == "simulation.dt" else T_ENDS
            values = [draw(st.sampled_from(grid)) for _ in range(count)]
            if off_grid and not {"simulation.dt", "simulation.t_end"} & set(axes):
                values[0] = OFF_GRID        # one axis only (0.013 s of 0.013 s is one step)
            if mode == "sample":
                axes[name] = {"from": values[0], "to": values[0]}
            elif name == "simulation.t_end" and not off_grid and draw(st.booleans()):
                axes[name] = {"from": values[0], "to": high,
                              "num": count if mode == "zip" else draw(st.integers(1, 2))}
            else:
                axes[name] = values if mode == "zip" else values[:draw(st.integers(1, count))]
            continue
        if mode == "sample":
            axes[name] = {"from": low, "to": low + draw(value) * (high - low)}
        elif draw(st.booleans()):
            axes[name] = [low + draw(value) * (high - low) for _ in range(count)]
        else:
            axes[name] = {"from": low + draw(value) * (high - low), "to": high,
                          "num": count if mode == "zip" else draw(st.integers(1, 2))}
    document = {"scene": str(ROOT / "scenes" / f"{scene_name}.toml"), "method": method,
                "order": order, "mode": mode, "axes": axes,
                "t_end": OFF_GRID if off_grid and not ({"simulation.dt", "simulation.t_end"}
                                                       & set(axes))
                else draw(st.sampled_from((0.02,) + T_ENDS)),
                "every": draw(st.sampled_from([0, 1, 2, 3, 7, 40]))}
    if mode == "sample":
        document.update(samples=draw(st.integers(1, 4)),
                        sampler=draw(st.sampled_from(["sobol", "latin-hypercube"])),
                        seed=draw(st.integers(0, 99)))
    if draw(st.booleans()):
        document.update(rtol=1e-6, atol=1e-6)
    return document, off_grid


def check_row(spec, row, data, index: int) -> None:
    """Row `index` and its trajectory against a single simulate of the same numbers."""
    run = spec.runs[index]
    scene = spec.scene
    solver = single_solver(spec.scene_path.stem, spec.method, spec.order, spec.parameters)
    assert row["solver"] == solver.build_hash
    phi0, omega0 = list(scene.initial_angles), list(scene.initial_velocities)
    if "initial.angles[0]" in run:
        phi0[0] = run["initial.angles[0]"]
    if "initial.velocities[1]" in run:
        omega0[1] = run["initial.velocities[1]"]
    dt = run.get("simulation.dt", scene.simulation.dt)
    steps = max(1, round(run.get("simulation.t_end", spec.t_end) / dt))
    parameters = {path: run[path] for path in spec.parameters} or None
    try:
        single, failed = solver.simulate(phi0, omega0, dt=dt, n_steps=steps,
                                         options=spec.options, parameters=parameters), False
    except NewtonError as error:
        single, failed = error.result, True
    for path, value in run.items():
        assert row[path] == value
    assert (row["status"] == "ok") is not failed
    assert row["steps"] == single.n_steps
    error = single.balance_error if "dissipated" in single.columns else single.energy_error
    assert row["max_energy_error"] == np.abs(error).max()
    assert row["max_constraint_error"] == np.abs(single.constraint_error).max()
    assert row["newton_max"] == single.max_newton_iterations
    assert row["newton_mean"] == single.mean_newton_iterations
    final = [row[f"phi{i + 1}"] for i in range(scene.n)] + \
        [row[f"omega{i + 1}"] for i in range(scene.n)]
    if failed:
        assert all(math.isnan(value) for value in final)
    else:
        assert final == list(single.phi[-1]) + list(single.omega[-1])
    if spec.every:
        kept = single.samples[::spec.every]
        phi = data["phi"].values[index]
        np.testing.assert_array_equal(phi[:len(kept)], single.phi[::spec.every])
        np.testing.assert_array_equal(data["energy"].values[index][:len(kept)],
                                      single.energy[::spec.every])
        assert np.isnan(phi[len(kept):]).all()
        times = data["time"].values[index] if "time" in data else data["t"].values
        np.testing.assert_allclose(times[:len(kept)], single.t[::spec.every], rtol=1e-12,
                                   atol=1e-15)


@pytest.mark.compile
@settings(max_examples=EXAMPLES, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(drawn=sweep_specs())
@pytest.mark.slow
def test_every_sweep_row_is_the_single_run_of_its_numbers(drawn):
    import xarray as xr

    document, off_grid = drawn
    try:
        spec = parse_spec(document)
    except SweepError as error:
        # a drawn value the scene format refuses (a spring segment of zero length), or a
        # duration drawn between steps
        assert "zero length" in str(error) or (off_grid and "not a whole number" in str(error)), \
            error
        assume(False)
    assert not off_grid, f"a duration between steps was accepted: {document}"
    with tempfile.TemporaryDirectory(prefix="chaingen-sweep-property-") as directory:
        out = Path(directory) / "out"
        run_sweep(spec, out, workers=1)
        runs = pd.read_parquet(out / "runs.parquet")
        data = (xr.open_zarr(out / "trajectories.zarr", consolidated=False).load()
                if spec.every else None)
    assert list(runs["run"]) == list(range(len(spec.runs)))
    for index in range(len(spec.runs)):
        check_row(spec, runs.iloc[index], data, index)


# -- fast: the numpy screen passes nothing the reader refuses ---------------------------------

GEOMETRY = ("initial.angles[0]", "initial.angles[1]", "links[0].length", "links[1].length",
            "links[1].fastening", "base.fastening", "links[0].mass", "links[2].inertia",
            "springs[0].rest_length", "springs[0].stiffness", "gravity", "links[1].com")


def names_a_number(scene, path: str) -> bool:
    try:
        number_path(scene, path)
    except SceneError:
        return False
    return True


@settings(max_examples=300, deadline=None, derandomize=True)
@given(values=st.dictionaries(st.sampled_from(GEOMETRY),
                              st.one_of(st.sampled_from([0.0, -0.0, 1e-12, -1e-12, 0.3, -0.3,
                                                         math.pi, 1.0, 1e155, -1e200, 1e300,
                                                         -2.0 ** 20, 1e10, 1e-300, 5e-324]),
                                        st.floats(-3.0, 3.0)), min_size=1, max_size=4),
       scene_name=st.sampled_from(["three_link_mono", "three_link_multi", "collapsing_spring"]))
def test_the_screen_passes_no_run_the_reader_refuses(values, scene_name):
    scene = load(scene_name)
    values = {path: value for path, value in values.items() if names_a_number(scene, path)}
    assume(values)
    columns = {path: np.array([value]) for path, value in values.items()}
    try:
        with_values(scene, values, where="run")
        refused = False
    except SceneError:
        refused = True
    if refused:
        assert list(suspects(scene, columns, 0, 1)) == [0], values
