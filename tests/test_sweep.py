"""chaingen sweep: one compiled solver for many runs, results that equal single runs, stores that
survive interruption, and the Dask engine (also with a worker killed mid-sweep)."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import chaingen
from chaingen.scene.parameters import with_values
from chaingen.simulation import build_solver
from chaingen.studies.sweep import load_spec, run_sweep

from helpers import ROOT, load

pytestmark = pytest.mark.compile

MONO = ROOT / "scenes" / "three_link_mono.toml"


def write_spec(directory: Path, text: str, name: str = "spec.toml") -> Path:
    path = directory / name
    path.write_text(text)
    return path


SMALL = f"""
scene = "{MONO}"
t_end = 1.0
every = 10
[axes]
"springs[0].stiffness" = [2.0, 5.0, 20.0]
"links[1].mass" = {{ from = 0.5, to = 2.0, num = 4 }}
"initial.angles[0]" = [0.3, 0.6]
"""


def runs_without_timing(out: Path) -> pd.DataFrame:
    return pd.read_parquet(out / "runs.parquet").drop(columns=["cpu_seconds"])


@pytest.fixture(scope="module")
def small_sweep(tmp_path_factory):
    directory = tmp_path_factory.mktemp("small")
    spec = load_spec(write_spec(directory, SMALL))
    outcome = run_sweep(spec, directory / "out")
    return spec, outcome, directory / "out"


def test_sweep_stores_every_run_with_one_solver(small_sweep):
    spec, outcome, out = small_sweep
    runs = pd.read_parquet(out / "runs.parquet")
    assert outcome.runs == outcome.computed == len(runs) == 24
    assert list(runs["run"]) == list(range(24))
    assert runs["solver"].nunique() == 1 and runs["solver"].iloc[0] == outcome.build_hash
    assert (runs["status"] == "ok").all() and (runs["steps"] == 100).all()
    for column in ("springs[0].stiffness", "links[1].mass", "initial.angles[0]", "message",
                   "max_energy_error", "max_constraint_error", "newton_mean", "newton_max",
                   "cpu_seconds", "phi1", "phi3", "omega1", "omega3"):
        assert column in runs.columns
    assert runs["max_energy_error"].max() < 1e-11
    assert (runs["cpu_seconds"] > 0).all()
    record = json.loads((out / "sweep.json").read_text())
    assert record["runs"] == 24 and record["parameters"] == ["springs[0].stiffness",
                                                             "links[1].mass"]
    assert "finished" in record and record["versions"]["chaingen"] == chaingen.__version__


def test_a_sweep_run_is_the_single_run_with_those_numbers(small_sweep):
    spec, _, out = small_sweep
    runs = pd.read_parquet(out / "runs.parquet")
    row = runs.iloc[17]
    scene = with_values(load("three_link_mono"), {
        "springs[0].stiffness": row["springs[0].stiffness"],
        "links[1].mass": row["links[1].mass"]})
    solver = build_solver(scene, "es", 3, sensitivities=False)
    angles = list(scene.initial_angles)
    angles[0] = row["initial.angles[0]"]
    single = solver.simulate(angles, scene.initial_velocities, dt=scene.simulation.dt,
                             n_steps=100)
    np.testing.assert_allclose([row[f"phi{i}"] for i in (1, 2, 3)], single.phi[-1], atol=1e-10,
                               rtol=0)
    np.testing.assert_allclose([row[f"omega{i}"] for i in (1, 2, 3)], single.omega[-1],
                               atol=1e-10, rtol=0)


def test_trajectories_are_an_xarray_dataset(small_sweep):
    import xarray as xr

    _, _, out = small_sweep
    data = xr.open_zarr(out / "trajectories.zarr", consolidated=False)
    runs = pd.read_parquet(out / "runs.parquet")
    assert dict(data.sizes) == {"run": 24, "t": 11, "joint": 3}
    assert np.allclose(data["t"].values, np.arange(11) * 0.1)
    assert np.array_equal(data["springs[0].stiffness"].values, runs["springs[0].stiffness"])
    last = data["phi"].isel(t=-1).values
    assert np.array_equal(last, runs[["phi1", "phi2", "phi3"]].to_numpy())
    assert np.isfinite(data["energy"].values).all()
    assert float(np.abs(data["constraint_error"]).max()) < 1e-12


def test_rerun_of_a_complete_sweep_computes_nothing(small_sweep):
    spec, _, out = small_sweep
    before = {path.name: path.stat().st_mtime_ns for path in (out / "parts").iterdir()}
    again = run_sweep(spec, out)
    assert again.computed == 0
    assert {path.name: path.stat().st_mtime_ns for path in (out / "parts").iterdir()} == before


def test_python_api_returns_tables(tmp_path):
    runs, data = chaingen.sweep({"scene": str(MONO), "t_end": 0.2, "every": 5,
                                 "axes": {"springs[0].stiffness": [3.0, 4.0]}},
                                trajectories=True)
    assert list(runs["springs[0].stiffness"]) == [3.0, 4.0]
    assert data["phi"].shape == (2, 5, 3)
    only = chaingen.sweep({"scene": str(MONO), "t_end": 0.2,
                           "axes": {"springs[0].stiffness": [3.0]}}, out=tmp_path / "o")
    assert len(only) == 1 and (tmp_path / "o" / "runs.parquet").exists()


def test_an_adaptive_sweep_run_is_the_single_adaptive_run(tmp_path):
    """rtol/atol in the spec: each run adapts its steps exactly as simulate does with them."""
    runs = chaingen.sweep({"scene": str(MONO), "t_end": 1.0, "rtol": 1e-7, "atol": 1e-7,
                           "axes": {"springs[0].stiffness": [3.0, 8.0]}})
    fixed = chaingen.sweep({"scene": str(MONO), "t_end": 1.0,
                            "axes": {"springs[0].stiffness": [3.0, 8.0]}})
    scene = with_values(load("three_link_mono"), {"springs[0].stiffness": 8.0})
    solver = build_solver(scene, "es", 3, sensitivities=False)
    single = solver.simulate(scene.initial_angles, scene.initial_velocities,
                             dt=scene.simulation.dt, n_steps=100,
                             options={"rtol": 1e-7, "atol": 1e-7})
    assert single.accepted_steps > 100
    row = runs.iloc[1]
    np.testing.assert_allclose([row[f"phi{i}"] for i in (1, 2, 3)], single.phi[-1], atol=1e-12,
                               rtol=0)
    assert np.abs(runs[["phi1", "phi2", "phi3"]].to_numpy()
                  - fixed[["phi1", "phi2", "phi3"]].to_numpy()).max() > 1e-9


def test_a_failing_run_is_a_row_and_the_sweep_goes_on(tmp_path):
    scene = ROOT / "scenes" / "collapsing_spring.toml"
    spec = load_spec(write_spec(tmp_path, f"""
scene = "{scene}"
[axes]
"springs[0].stiffness" = [0.5, 1.0]
"initial.velocities[0]" = [0.0, 8.0]
"""))
    run_sweep(spec, tmp_path / "out")
    runs = pd.read_parquet(tmp_path / "out" / "runs.parquet")
    assert len(runs) == 4
    failed = runs[runs["status"] != "ok"]
    assert len(failed) >= 1, runs[["status", "message"]]
    assert set(failed["status"]) <= {"segment_collapsed", "not_converged"}
    assert failed["message"].str.len().min() > 0
    assert failed["phi1"].isna().all()
    assert (failed["steps"] < spec.n_steps(spec.runs[0])).all()


RESUMABLE = f"""
scene = "{MONO}"
t_end = 100.0
every = 100
[axes]
"springs[0].stiffness" = {{ from = 1.0, to = 30.0, num = 20 }}
"links[1].mass" = {{ from = 0.5, to = 2.0, num = 20 }}
"""


def _sweep_process(spec: Path, out: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "chaingen", "sweep", str(spec), "-o",
                             str(out), "--quiet"], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _wait_for_parts(out: Path, count: int, process: subprocess.Popen, timeout: float = 120):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        parts = list((out / "parts").glob("runs-*.parquet")) if (out / "parts").exists() else []
        if len(parts) >= count:
            return
        assert process.poll() is None, process.communicate()
        time.sleep(0.01)
    raise AssertionError("no chunk finished in time")


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory):
    directory = tmp_path_factory.mktemp("whole")
    spec = write_spec(directory, RESUMABLE)
    run_sweep(load_spec(spec), directory / "out")
    return directory / "out"


@pytest.mark.parametrize("kill", [signal.SIGINT, signal.SIGKILL], ids=["SIGINT", "SIGKILL"])
def test_killed_sweep_resumes_without_running_finished_runs(tmp_path, uninterrupted, kill):
    spec = write_spec(tmp_path, RESUMABLE)
    out = tmp_path / "out"
    process = _sweep_process(spec, out)
    _wait_for_parts(out, 2, process)
    process.send_signal(kill)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == (130 if kill == signal.SIGINT else -signal.SIGKILL), stderr
    if kill == signal.SIGINT:
        assert "interrupted" in stderr and "Traceback" not in stderr
    assert not (out / "runs.parquet").exists()
    finished = {path.name: (path.stat().st_ino, path.stat().st_mtime_ns)
                for path in (out / "parts").glob("runs-*.parquet")}
    assert 2 <= len(finished) < 40
    stored = sum(len(pd.read_parquet(out / "parts" / name)) for name in finished)
    again = run_sweep(load_spec(spec), out)
    assert again.computed == 400 - stored
    # the finished chunks were not run again: their files are the ones written before the kill
    for name, identity in finished.items():
        path = out / "parts" / name
        assert (path.stat().st_ino, path.stat().st_mtime_ns) == identity
    pd.testing.assert_frame_equal(runs_without_timing(out), runs_without_timing(uninterrupted))
    assert not list((out / "parts").glob(".*"))   # no staged leftovers counted as parts


def _equal_trajectories(first: Path, second: Path) -> None:
    import xarray as xr

    a = xr.open_zarr(first / "trajectories.zarr", consolidated=False).load()
    b = xr.open_zarr(second / "trajectories.zarr", consolidated=False).load()
    xr.testing.assert_identical(a, b)


def test_killed_sweep_trajectories_equal_uninterrupted(tmp_path, uninterrupted):
    spec = write_spec(tmp_path, RESUMABLE)
    out = tmp_path / "out"
    process = _sweep_process(spec, out)
    _wait_for_parts(out, 3, process)
    process.kill()
    process.communicate(timeout=60)
    run_sweep(load_spec(spec), out)
    _equal_trajectories(out, uninterrupted)


DASK = f"""
scene = "{MONO}"
t_end = 5.0
every = 50
[axes]
"springs[0].stiffness" = {{ from = 1.0, to = 30.0, num = 8 }}
"links[1].mass" = {{ from = 0.5, to = 2.0, num = 8 }}
"""


def test_dask_local_equals_local(tmp_path):
    spec = load_spec(write_spec(tmp_path, DASK))
    run_sweep(spec, tmp_path / "local")
    outcome = run_sweep(spec, tmp_path / "dask", engine="dask", dask_local=2)
    assert outcome.computed == 64
    pd.testing.assert_frame_equal(runs_without_timing(tmp_path / "dask"),
                                  runs_without_timing(tmp_path / "local"), check_exact=True)
    _equal_trajectories(tmp_path / "dask", tmp_path / "local")


DASK_LONG = f"""
scene = "{MONO}"
t_end = 100.0
every = 100
[axes]
"springs[0].stiffness" = {{ from = 1.0, to = 30.0, num = 12 }}
"links[1].mass" = {{ from = 0.5, to = 2.0, num = 10 }}
"""


def test_dask_sweep_survives_a_killed_worker(tmp_path):
    from distributed import Client, LocalCluster

    spec = load_spec(write_spec(tmp_path, DASK_LONG))
    run_sweep(spec, tmp_path / "local")
    out = tmp_path / "dask"
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address="127.0.0.1:0") as cluster, Client(cluster) as client:
        pids = list(client.run(os.getpid).values())
        finished: list = []
        thread = threading.Thread(target=lambda: finished.append(
            run_sweep(spec, out, engine="dask", scheduler=cluster.scheduler_address)))
        thread.start()
        deadline = time.monotonic() + 120
        while not list(out.glob("parts/runs-*.parquet")):
            assert time.monotonic() < deadline and thread.is_alive()
            time.sleep(0.01)
        assert len(list(out.glob("parts/runs-*.parquet"))) < 40     # mid-sweep
        os.kill(pids[0], signal.SIGKILL)
        thread.join(timeout=300)
        assert not thread.is_alive() and finished, "the sweep did not complete"
    runs = pd.read_parquet(out / "runs.parquet")
    assert list(runs["run"]) == list(range(120))     # every run, exactly once
    parts = sorted((out / "parts").glob("runs-*.parquet"))
    assert sum(len(pd.read_parquet(path)) for path in parts) == 120
    pd.testing.assert_frame_equal(runs_without_timing(out),
                                  runs_without_timing(tmp_path / "local"), check_exact=True)


def test_sweep_command_with_plot(tmp_path):
    spec = write_spec(tmp_path, SMALL.replace('"initial.angles[0]" = [0.3, 0.6]\n', ""))
    result = subprocess.run([sys.executable, "-m", "chaingen", "sweep", str(spec), "-o",
                             str(tmp_path / "out"), "--plot", "amplitude_phi2"],
                            capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert result.returncode == 0, result.stderr
    assert "12 runs (12 computed now), 0 failed" in result.stdout
    figure = tmp_path / "out" / "amplitude_phi2.png"
    assert figure.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    result = subprocess.run([sys.executable, "-m", "chaingen", "plot", str(tmp_path / "out"),
                             "--metric", "max_energy_error", "-o", str(tmp_path / "e.png")],
                            capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "e.png").stat().st_size > 1000


def test_a_stop_signal_ends_runs_in_other_threads():
    from chaingen.errors import NewtonError
    from chaingen.runtime import StopSignal, contract

    solver = build_solver(load("three_link_mono"), "es", 3, sensitivities=False)
    scene = load("three_link_mono")
    stop = StopSignal()
    outcome: list = []

    def run():
        try:
            solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                            n_steps=50_000_000, every=1_000_000, stop=stop)
        except NewtonError as error:
            outcome.append(error)

    thread = threading.Thread(target=run)
    thread.start()
    time.sleep(0.3)
    started = time.monotonic()
    stop.stop()
    thread.join(timeout=10)
    assert not thread.is_alive() and time.monotonic() - started < 1.0
    assert outcome and outcome[0].status == contract.STATUS_CODES["INTERRUPTED"]
    assert 0 < outcome[0].step < 50_000_000
    # a run given a stopped signal does not start
    with pytest.raises(NewtonError) as stopped:
        solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01, n_steps=10,
                        stop=stop)
    assert stopped.value.step == 1
