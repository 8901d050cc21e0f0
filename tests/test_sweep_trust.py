"""Issue 30's sweep points: what a sweep writes can be trusted, and OUT never loses a file.

The final state is the state after the last step and the metrics are taken at the promised
stride (point 2); two sweeps on one Dask scheduler keep their own tasks and assembly checks that
every chunk is there (5); an OUT holding anything the sweep did not write is refused (8); step
counts, sizes and 10^6 samples are checked before anything is built, in bounded time (9); a
read-only OUT, a damaged store, a full disk and Ctrl-C on --dask-local end in one line (11);
the documented paths warn nothing (16). The fast tests stop before the build (CC is nothing)."""
from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
import warnings
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from chaingen.studies.sweep import SweepError, load_spec, parse_spec, run_sweep
from chaingen.studies.sweep.runs import MAX_ROWS, METRIC_SAMPLES, metric_stride, sampling
from chaingen.studies.sweep.store import IncompleteSweepError, StoreError, SweepStore

from helpers import ROOT, chaingen_in_process, load

MONO = ROOT / "scenes" / "three_link_mono.toml"


def document(**entries) -> dict:
    found = {"scene": str(MONO), "t_end": 0.2, "axes": {"springs[0].stiffness": [5.0, 10.0]}}
    found.update(entries)
    return found


def refused(**entries) -> str:
    with pytest.raises(SweepError) as error:
        parse_spec(document(**entries))
    message = str(error.value)
    assert "\n" not in message
    return message


# -- point 2: the runs' sampling --------------------------------------------------------------

@pytest.mark.parametrize("steps", [1, 99_999, 100_000, 100_003, 200_000, 10 ** 9 + 7,
                                   2 ** 40 + 1])
@pytest.mark.parametrize("every", [0, 1, 3, 7, 1000, 999_983])
def test_a_run_s_calls_serve_every_stride_it_needs(steps, every):
    """Each need (the metrics at metric_stride, the trajectory at every, the final state) is a
    multiple of its call's stride, and no call holds more than MAX_ROWS samples beyond the
    trajectory's own."""
    wanted = {"metrics": metric_stride(steps), "final": steps}
    if every:
        wanted["trajectory"] = every
    calls = sampling(steps, wanted)
    served = [what for _, covers in calls for what in covers]
    assert sorted(served) == sorted(wanted)
    for stride, covers in calls:
        assert all(wanted[what] % stride == 0 for what in covers)
        assert steps // stride + 1 <= MAX_ROWS or stride == every
    assert metric_stride(steps) == max(1, -(-steps // METRIC_SAMPLES))
    if steps <= METRIC_SAMPLES:
        assert [stride for stride, _ in calls] == [1]


# -- point 9: step counts, sizes, ranges, samples, before anything is built -------------------

def test_step_counts_beyond_simulate_s_limit_are_refused():
    assert "1e+15 steps" in refused(t_end=1e13) and "t_end" in refused(t_end=1e13)
    message = refused(axes={"simulation.dt": [0.01, 1e-300]})
    assert "run 1" in message and "2e+299 steps, more than the 1e+12" in message


def test_trajectories_beyond_the_sample_limit_are_refused():
    message = refused(t_end=1e6, every=1)          # 10^8 samples a run
    assert message.split(": ")[1] == "every" and "GiB" in message
    parse_spec(document(t_end=10.0, every=1))       # a small one passes


def test_a_long_range_is_refused_before_it_is_made():
    started = time.perf_counter()
    message = refused(axes={"links[1].mass": {"from": 0.5, "to": 2.0, "num": 10 ** 12}})
    assert "num" in message and "10000000" in message
    message = refused(axes={"links[1].mass": {"from": 0.5, "to": 2.0, "num": 10 ** 4},
                            "links[0].mass": {"from": 0.5, "to": 2.0, "num": 10 ** 4}})
    assert "100000000 runs" in message
    assert time.perf_counter() - started < 5


def test_a_million_samples_are_checked_in_seconds():
    started = time.perf_counter()
    spec = parse_spec(document(mode="sample", samples=10 ** 6, axes={
        "springs[0].stiffness": {"from": 1.0, "to": 50.0},
        "links[1].mass": {"from": 0.1, "to": 10.0, "spacing": "log"},
        "initial.angles[0]": {"from": -1.0, "to": 1.0}}))
    assert len(spec.runs) == 10 ** 6
    assert time.perf_counter() - started < 30
    # ... and the one bad run among them is still found, with the reader's message
    masses = [1.0 + k / 1000 for k in range(999)] + [-0.5]
    started = time.perf_counter()
    with pytest.raises(SweepError, match=r"axes: run 999000 \(links\[1\]\.mass = -0\.5, "
                                         r"springs\[0\]\.stiffness = 1\): links\[1\]\.mass: "
                                         r"must be > 0"):
        parse_spec(document(axes={"links[1].mass": masses,
                                  "springs[0].stiffness": {"from": 1.0, "to": 50.0,
                                                           "num": 1000}}))
    assert time.perf_counter() - started < 30


def test_one_number_named_twice_is_refused():
    """links[01].mass is links[1].mass: refused as a second spelling (the canonical path) or
    as the same number twice, never two axes that write one number."""
    message = refused(axes={"links[1].mass": [1.0], "links[01].mass": [2.0]})
    assert "links[01].mass" in message


def test_sobol_samples_draw_without_a_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        spec = parse_spec(document(mode="sample", samples=100, axes={
            "springs[0].stiffness": {"from": 1.0, "to": 50.0}}))
    from scipy.stats import qmc

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        expected = 1.0 + qmc.Sobol(1, scramble=True, seed=0).random(100)[:, 0] * 49.0
    np.testing.assert_array_equal(spec.runs.column("springs[0].stiffness"), expected)


# -- point 8: OUT never loses a file the sweep did not write ----------------------------------

def small_spec():
    return parse_spec(document(every=5))


def fake_record(out: Path, spec, store: str = "0" * 32) -> None:
    """A sweep.json of `spec` as the sweep writes it (what check() reads of it)."""
    out.mkdir(parents=True, exist_ok=True)
    (out / "sweep.json").write_text(json.dumps({"digest": spec.digest, "chunk": spec.chunk,
                                                "store": store, "source": "x"}))


def test_trajectories_without_a_record_are_not_wiped(tmp_path):
    out = tmp_path / "out"
    (out / "trajectories.zarr").mkdir(parents=True)
    (out / "trajectories.zarr" / "mine.txt").write_text("keep me")
    with pytest.raises(StoreError, match="holds no sweep.json"):
        run_sweep(small_spec(), out)
    assert (out / "trajectories.zarr" / "mine.txt").read_text() == "keep me"


@pytest.mark.parametrize("name", ["parts", "trajectories.zarr"])
def test_symlinks_in_out_are_refused(tmp_path, name):
    spec = small_spec()
    out = tmp_path / "out"
    fake_record(out, spec)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "runs-000000000.parquet").write_text("not yours")
    (out / name).symlink_to(elsewhere, target_is_directory=True)
    with pytest.raises(StoreError, match="symbolic link"):
        run_sweep(spec, out)
    assert (elsewhere / "runs-000000000.parquet").read_text() == "not yours"


@pytest.mark.parametrize("where", ["notes.txt", "parts/.runs-notes", "parts/mine.parquet"])
def test_files_the_sweep_did_not_write_are_refused(tmp_path, where):
    spec = small_spec()
    out = tmp_path / "out"
    fake_record(out, spec)
    (out / "parts").mkdir()
    (out / where).write_text("mine")
    with pytest.raises(StoreError, match="was not written by this sweep"):
        run_sweep(spec, out)
    assert (out / where).read_text() == "mine"


def test_the_sweep_command_refuses_a_foreign_out_in_one_line(tmp_path):
    spec_file = tmp_path / "spec.toml"
    spec_file.write_text(f'scene = "{MONO}"\nt_end = 0.2\n[axes]\n'
                         '"springs[0].stiffness" = [5.0]\n')
    out = tmp_path / "out"
    out.mkdir()
    (out / "data.csv").write_text("1,2\n")
    result = chaingen_in_process("sweep", spec_file, "-o", out, cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert len(result.stderr.splitlines()) == 1 and "not empty" in result.stderr
    assert (out / "data.csv").read_text() == "1,2\n" and sorted(os.listdir(out)) == ["data.csv"]


# -- point 11: a read-only OUT is found before the build ---------------------------------------

@pytest.fixture
def read_only_directory(tmp_path):
    """A directory on a read-only file system (a tmpfs mounted ro), where even root cannot
    write; skipped where mounting is not allowed."""
    mount = tmp_path / "ro"
    mount.mkdir()
    made = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m,ro", "tmpfs", str(mount)],
                          capture_output=True)
    if made.returncode:
        pytest.skip("cannot mount a read-only tmpfs here (needs root and mount rights)")
    try:
        yield mount
    finally:
        subprocess.run(["umount", str(mount)], check=False)


def test_a_read_only_out_is_refused_before_the_build(read_only_directory):
    for out in (read_only_directory, read_only_directory / "new"):
        with pytest.raises(StoreError, match="writable"):
            run_sweep(small_spec(), out)


# -- compiled: what the runs hold ---------------------------------------------------------------

def write_spec(directory: Path, text: str, name: str = "spec.toml") -> Path:
    path = directory / name
    path.write_text(text)
    return path


@pytest.mark.compile
def test_a_long_run_s_final_state_and_metrics_are_the_promised_ones(tmp_path):
    """100 003 steps kept every 3rd: the metrics over every 2nd step (the stride that keeps at
    most 100 000 samples), the final state after step 100 003, the trajectory every 3rd step,
    each equal to a single simulate's (bitwise)."""
    from chaingen.simulation import build_solver

    spec = load_spec(write_spec(tmp_path, f"""
scene = "{MONO}"
t_end = 1000.03
every = 3
[axes]
"initial.angles[0]" = [0.3, 0.5]
"""))
    assert int(spec.steps[0]) == 100_003 and metric_stride(100_003) == 2
    run_sweep(spec, tmp_path / "out")
    runs = pd.read_parquet(tmp_path / "out" / "runs.parquet")
    import xarray as xr

    data = xr.open_zarr(tmp_path / "out" / "trajectories.zarr", consolidated=False).load()
    scene = load("three_link_mono")
    solver = build_solver(scene, "es", 3, sensitivities=False)
    for index, angle in enumerate((0.3, 0.5)):
        single = solver.simulate([angle, *scene.initial_angles[1:]], scene.initial_velocities,
                                 dt=scene.simulation.dt, n_steps=100_003)
        row = runs.iloc[index]
        assert [row[f"phi{i}"] for i in (1, 2, 3)] == list(single.phi[-1])
        assert [row[f"omega{i}"] for i in (1, 2, 3)] == list(single.omega[-1])
        assert row["max_energy_error"] == np.abs(single.energy_error[::2]).max()
        assert row["max_constraint_error"] == np.abs(single.constraint_error[::2]).max()
        assert row["steps"] == 100_003
        np.testing.assert_array_equal(data["phi"].values[index], single.phi[::3])


SMALL = f"""
scene = "{MONO}"
t_end = 0.5
every = 10
[axes]
"springs[0].stiffness" = [2.0, 5.0, 20.0]
"links[1].mass" = {{ from = 0.5, to = 2.0, num = 4 }}
"""


@pytest.fixture(scope="module")
def finished(tmp_path_factory):
    """A finished sweep of 12 runs in chunks of 1 (12 parts), to copy and damage."""
    directory = tmp_path_factory.mktemp("finished")
    spec = load_spec(write_spec(directory, SMALL))
    run_sweep(spec, directory / "out")
    return spec, directory / "out"


def copy_of(finished, tmp_path) -> Path:
    out = tmp_path / "out"
    shutil.copytree(finished[1], out, symlinks=True)
    return out


@pytest.mark.compile
def test_assembly_refuses_a_missing_or_foreign_chunk(finished, tmp_path):
    spec, _ = finished
    out = copy_of(finished, tmp_path)
    record = json.loads((out / "sweep.json").read_text())
    store = SweepStore(out, spec, spec.chunk, record["store"])
    (out / "parts" / "runs-000000005.parquet").unlink()
    (out / "runs.parquet").unlink()
    with pytest.raises(IncompleteSweepError, match=r"1 of 12 chunks are not stored .*runs 5\.\.5"):
        store.assemble()
    assert not (out / "runs.parquet").exists()
    # a part of the same spec written for another OUT does not count as this OUT's
    other = SweepStore(out, spec, spec.chunk, "f" * 32)
    from chaingen.studies.sweep.runs import ChunkResult

    rows = pd.read_parquet(finished[1] / "parts" / "runs-000000005.parquet").to_dict("records")
    other.commit(ChunkResult(5, rows))
    with pytest.raises(StoreError, match="written for another OUT"):
        store.assemble()


@pytest.mark.compile
def test_a_resumed_sweep_names_a_damaged_part_to_remove(finished, tmp_path):
    out = copy_of(finished, tmp_path)
    part = out / "parts" / "runs-000000007.parquet"
    part.write_bytes(part.read_bytes()[:100])
    result = chaingen_in_process("sweep", write_spec(tmp_path, SMALL), "-o", out, cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert len(result.stderr.splitlines()) == 1
    assert f"{part}: damaged" in result.stderr and "remove it" in result.stderr
    part.unlink()                       # as told: the sweep computes it again
    result = chaingen_in_process("sweep", tmp_path / "spec.toml", "-o", out, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "12 runs (1 computed now)" in result.stdout
    pd.testing.assert_frame_equal(
        pd.read_parquet(out / "runs.parquet").drop(columns="cpu_seconds"),
        pd.read_parquet(finished[1] / "runs.parquet").drop(columns="cpu_seconds"))


@pytest.mark.compile
@pytest.mark.parametrize("damage", ["metadata", "shape"])
def test_a_resumed_sweep_names_a_damaged_store_to_remove(finished, tmp_path, damage):
    out = copy_of(finished, tmp_path)
    if damage == "metadata":
        (out / "trajectories.zarr" / "phi" / "zarr.json").write_text("{")
    else:
        meta = json.loads((out / "trajectories.zarr" / "energy" / "zarr.json").read_text())
        meta["shape"] = [5, 6]
        (out / "trajectories.zarr" / "energy" / "zarr.json").write_text(json.dumps(meta))
    result = chaingen_in_process("sweep", write_spec(tmp_path, SMALL), "-o", out, cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert len(result.stderr.splitlines()) == 1
    assert "trajectories.zarr: damaged" in result.stderr
    assert f"remove {out / 'trajectories.zarr'} and {out / 'parts'}" in result.stderr


@pytest.mark.compile
def test_a_full_disk_ends_the_sweep_in_one_line_leaving_nothing_half_written(tmp_path,
                                                                          monkeypatch):
    import pyarrow.parquet as pq

    written = []
    original = pq.write_table

    def full_disk(table, where, *args, **kwargs):
        if len(written) >= 2:
            Path(where).write_bytes(b"PAR1 half")    # what a full disk leaves of a write
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        written.append(where)
        return original(table, where, *args, **kwargs)

    monkeypatch.setattr(pq, "write_table", full_disk)
    spec_file = write_spec(tmp_path, SMALL)
    result = chaingen_in_process("sweep", spec_file, "-o", tmp_path / "out", "--jobs", "1",
                                 cwd=tmp_path)
    assert result.returncode == 1, result.stderr
    assert len(result.stderr.splitlines()) == 1
    assert "No space left on device" in result.stderr and "internal error" not in result.stderr
    out = tmp_path / "out"
    assert not (out / "runs.parquet").exists()
    assert sorted(path.name for path in (out / "parts").iterdir()) == \
        sorted(Path(path).name.split(".", 2)[1] + ".parquet" for path in written)
    monkeypatch.setattr(pq, "write_table", original)
    result = chaingen_in_process("sweep", spec_file, "-o", out, cwd=tmp_path)   # space again
    assert result.returncode == 0, result.stderr
    assert "12 runs (10 computed now)" in result.stdout


# -- point 5: Dask -----------------------------------------------------------------------------

DASK = f"""
scene = "{MONO}"
t_end = 20.0
every = 100
[axes]
"springs[0].stiffness" = {{ from = 1.0, to = 30.0, num = 8 }}
"links[1].mass" = {{ from = 0.5, to = 2.0, num = 10 }}
"""


@pytest.mark.compile
def test_two_sweeps_of_one_spec_on_one_scheduler_each_get_every_run(tmp_path):
    from distributed import Client, LocalCluster

    spec = load_spec(write_spec(tmp_path, DASK))
    outcomes: dict = {}
    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                      dashboard_address="127.0.0.1:0") as cluster, Client(cluster):
        def sweep(name):
            try:
                outcomes[name] = run_sweep(spec, tmp_path / name, engine="dask",
                                           scheduler=cluster.scheduler_address)
            except Exception as error:      # reported below
                outcomes[name] = error
        threads = [threading.Thread(target=sweep, args=(name,)) for name in ("a", "b")]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(timeout=300)
    assert all(not isinstance(outcome, Exception) for outcome in outcomes.values()), outcomes
    tables = []
    for name in ("a", "b"):
        parts = sorted((tmp_path / name / "parts").glob("runs-*.parquet"))
        assert len(parts) == 40
        runs = pd.read_parquet(tmp_path / name / "runs.parquet")
        assert list(runs["run"]) == list(range(80))
        tables.append(runs.drop(columns="cpu_seconds"))
    pd.testing.assert_frame_equal(*tables)


# -- point 11 and 16: Ctrl-C on --dask-local; no warnings on the documented paths --------------

@pytest.mark.compile
def test_ctrl_c_on_dask_local_is_one_line(tmp_path):
    spec = write_spec(tmp_path, f"""
scene = "{MONO}"
t_end = 100.0
every = 100
[axes]
"springs[0].stiffness" = {{ from = 1.0, to = 30.0, num = 20 }}
"links[1].mass" = {{ from = 0.5, to = 2.0, num = 20 }}
""")
    out = tmp_path / "out"
    # a terminal's Ctrl-C: SIGINT to the whole process group (the sweep and its workers)
    process = subprocess.Popen([sys.executable, "-m", "chaingen", "sweep", str(spec), "-o",
                                str(out), "--dask-local", "2", "--quiet"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               start_new_session=True)
    deadline = time.monotonic() + 180
    while not list(out.glob("parts/runs-*.parquet")):
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.02)
    os.killpg(process.pid, signal.SIGINT)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 130
    assert stderr == "chaingen: interrupted\n"


@pytest.mark.compile
def test_the_documented_sweep_paths_warn_nothing(tmp_path):
    """The local and --dask-local sweeps, with the dashboard's usual port taken, and the
    docs' reading of the results, with every warning shown."""
    spec = write_spec(tmp_path, SMALL)
    with socket.socket() as taken:
        try:
            taken.bind(("127.0.0.1", 8787))
            taken.listen()
        except OSError:
            pass                                 # already in use: as the test wants
        for engine in ([], ["--dask-local", "2"]):
            out = tmp_path / f"out{len(engine)}"
            result = subprocess.run([sys.executable, "-W", "always", "-m", "chaingen", "sweep",
                                     str(spec), "-o", str(out), "--quiet", *engine],
                                    capture_output=True, text=True, timeout=300,
                                    env={**os.environ, "PYTHONWARNINGS": "always"})
            assert result.returncode == 0, result.stderr
            assert result.stderr == "", result.stderr
    import xarray as xr

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        data = xr.open_zarr(tmp_path / "out0" / "trajectories.zarr", consolidated=False)
        one = data.isel(run=int(((data["springs[0].stiffness"] - 7.0) ** 2).argmin("run")))
        assert float(one["springs[0].stiffness"]) == 5.0
        runs = pd.read_parquet(tmp_path / "out0" / "runs.parquet")
        runs.groupby("springs[0].stiffness")["max_energy_error"].max()
        assert abs(data.phi.sel(joint=2)).max("t").values.shape == (12,)
        assert data.phi.sel(joint=3).std("t").values.shape == (12,)


@pytest.fixture
def small_file_system(tmp_path):
    """A tmpfs of 3 MB (root and mount rights; skipped elsewhere), made larger by `grow`."""
    mount = tmp_path / "small"
    mount.mkdir()
    made = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=3m", "tmpfs", str(mount)],
                          capture_output=True)
    if made.returncode:
        pytest.skip("cannot mount a tmpfs here (needs root and mount rights)")

    def grow():
        subprocess.run(["mount", "-o", "remount,size=64m", str(mount)], check=True)

    try:
        yield mount, grow
    finally:
        subprocess.run(["umount", str(mount)], check=False)


@pytest.mark.compile
def test_a_really_full_disk_is_one_line_and_the_sweep_resumes(tmp_path, small_file_system):
    mount, grow = small_file_system
    spec = write_spec(tmp_path, f"""
scene = "{MONO}"
t_end = 20.0
every = 1
[axes]
"springs[0].stiffness" = {{ from = 1.0, to = 30.0, num = 40 }}
""")
    out = mount / "out"
    result = chaingen_in_process("sweep", spec, "-o", out, "--quiet", cwd=tmp_path)
    assert result.returncode == 1, result.stderr
    assert len(result.stderr.splitlines()) == 1 and "No space left on device" in result.stderr
    assert "internal error" not in result.stderr and f"{out}" in result.stderr
    assert not (out / "runs.parquet").exists()
    stored = len(list((out / "parts").glob("runs-*.parquet")))
    assert 0 < stored < 40
    hidden = [path for path in (*out.iterdir(), *(out / "parts").iterdir())
              if path.name.startswith(".")]
    assert hidden == []
    grow()
    result = chaingen_in_process("sweep", spec, "-o", out, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert f"40 runs ({40 - stored} computed now)" in result.stdout
    assert list(pd.read_parquet(out / "runs.parquet")["run"]) == list(range(40))


@pytest.mark.compile
def test_a_resumed_sweep_removes_its_own_leftovers_and_nothing_else(finished, tmp_path):
    """The staged files of writes a kill cut short are the sweep's own: removed on resume."""
    out = copy_of(finished, tmp_path)
    record = json.loads((out / "sweep.json").read_text())
    (out / "parts" / "runs-000000003.parquet").unlink()
    store = record["store"]
    leftovers = [out / "parts" / f".runs-000000003.parquet.{store}.0a1b2c3d4e5f6789.parquet",
                 out / f".runs.parquet.{store}.a8b03f00aa11bb22.parquet",
                 out / f".sweep.json.{store}.00ff00ff00ff00ff"]
    for path in leftovers:
        path.write_bytes(b"half")
    staging = out / f".trajectories.zarr.{record['store']}.staging"
    (staging / "phi").mkdir(parents=True)
    result = chaingen_in_process("sweep", write_spec(tmp_path, SMALL), "-o", out, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "12 runs (1 computed now)" in result.stdout
    assert not any(path.exists() for path in leftovers) and not staging.exists()
    assert sorted(path.name for path in out.iterdir()) == \
        ["parts", "runs.parquet", "sweep.json", "trajectories.zarr"]
