"""Issue 30's sweep points, as an adversarial review of the first fix found them open.

1. Every t_end and dt of a row is the one its run used: a t_end (the spec's, or of an axis)
   that is not a whole number of steps of dt is refused, naming the whole-step values near it,
   and the runs' step counts are those `chaingen simulate` takes for the same numbers.
2. A resumed sweep (and assembly) finds a lost or garbled trajectory chunk of a run marked done:
   one line naming the part file to remove, exit 2; removed, the chunk is computed again.
3. A rerun deletes only its own staged leftovers (named by the store id), never a user's file.
4. A spec's run count is known before any range's values are made: bounded time and memory.
5. docs/sweeps.md says run-time values are refused; an OUT inside another sweep's OUT is refused.
"""
from __future__ import annotations

import json
import os
import shutil
import time
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from test_sweep_trust import MONO, document, refused

from chaingen.simulation import run_settings
from chaingen.studies.sweep import load_spec, parse_spec, run_sweep
from chaingen.studies.sweep.store import StoreError, SweepStore

from helpers import ROOT, chaingen_in_process

# -- point 1: t_end and dt are whole steps -----------------------------------------------------

def test_a_t_end_axis_between_steps_is_refused_naming_the_whole_step_values():
    message = refused(t_end=1.0, axes={"simulation.t_end": [0.015, 0.025, 0.035]})
    assert message.startswith('<sweep>: axes."simulation.t_end": run 0: t_end = 0.015 s is 1.5 '
                              "steps of dt = 0.01 s, not a whole number"), message
    assert "0.01 (1 step)" in message and "0.02 (2 steps)" in message


def test_a_dt_axis_that_does_not_divide_t_end_is_refused_naming_the_dividing_values():
    message = refused(t_end=1.0, axes={"simulation.dt": [0.01, 0.003]})
    assert message.startswith('<sweep>: axes."simulation.dt": run 1: t_end = 1 s is 333.333 '
                              "steps of dt = 0.003 s"), message
    assert "0.003003003003 (333 steps)" in message and "(334 steps)" in message


@pytest.mark.parametrize("t_end", [0.015, 0.004, 0.1234])
def test_a_spec_t_end_between_steps_is_refused(t_end):
    message = refused(t_end=t_end)
    assert message.startswith(f"<sweep>: t_end: t_end = {t_end:g} s is "), message
    assert "not a whole number" in message


def test_whole_step_values_take_the_steps_simulate_takes():
    """Values whole to round-off only (0.3 / 0.1 is 2.9999999999999996) are accepted, and each
    run's step count is the one `chaingen simulate` takes for the same dt and t_end."""
    spec = parse_spec(document(t_end=0.3, mode="product", axes={
        "simulation.dt": [0.1, 0.01, 0.001, 0.0001, 0.05, 0.025],
        "simulation.t_end": [0.3, 0.7, 2.1]}))
    for index in range(len(spec.runs)):
        run = spec.runs[index]
        settings = run_settings(spec.scene, dt=run["simulation.dt"],
                                t_end=run["simulation.t_end"])
        assert spec.steps[index] == settings.n_steps
        assert spec.steps[index] * run["simulation.dt"] == pytest.approx(
            run["simulation.t_end"], rel=1e-12)


# -- point 4: the run count before any value is made -------------------------------------------

EIGHT = ("links[0].mass", "links[1].mass", "links[2].mass", "links[0].inertia",
         "links[1].inertia", "links[2].inertia", "links[0].length", "links[1].length")


def test_many_long_ranges_are_refused_in_bounded_time_and_memory():
    tracemalloc.start()
    try:
        started = time.perf_counter()
        message = refused(axes={"links[0].mass": {"from": 0.5, "to": 2.0, "num": 10 ** 6},
                                "links[1].mass": {"from": 0.5, "to": 2.0, "num": 10 ** 6}})
        _, peak = tracemalloc.get_traced_memory()
        assert "1000000000000 runs" in message
        assert peak < 8 * 2 ** 20, f"{peak / 2 ** 20:.0f} MiB to refuse the spec"
        message = refused(axes={path: {"from": 0.5, "to": 2.0, "num": 10 ** 7}
                                for path in EIGHT})
        _, peak = tracemalloc.get_traced_memory()
        assert "more than 10000000" in message
        assert peak < 8 * 2 ** 20, f"{peak / 2 ** 20:.0f} MiB to refuse the spec"
        assert time.perf_counter() - started < 2
    finally:
        tracemalloc.stop()


def test_ranges_still_make_their_values():
    spec = parse_spec(document(mode="zip", axes={
        "links[0].mass": {"from": 0.5, "to": 2.0, "num": 4},
        "springs[0].stiffness": {"from": 1.0, "to": 100.0, "num": 4, "spacing": "log"}}))
    np.testing.assert_array_equal(spec.runs.column("links[0].mass"), np.linspace(0.5, 2.0, 4))
    np.testing.assert_array_equal(spec.runs.column("springs[0].stiffness"),
                                  np.geomspace(1.0, 100.0, 4))


# -- point 3: a rerun removes only its own leftovers -------------------------------------------

def opened(out: Path, spec) -> SweepStore:
    """OUT set up for `spec` (no runs: the store alone, no build)."""
    store = SweepStore(out, spec, spec.chunk)
    with store.writing():
        store.open("0" * 64, "local")
    return store


@pytest.mark.parametrize("name", [".sweep.json.bak", ".runs.parquet.old.parquet",
                                  "parts/.runs-000000000.parquet.mine_1.parquet"])
def test_a_rerun_never_deletes_a_user_file_named_like_a_leftover(tmp_path, name):
    spec = parse_spec(document())
    out = tmp_path / "out"
    opened(out, spec)
    (out / name).write_text("the user's")
    with pytest.raises(StoreError, match="was not written by this sweep"):
        opened(out, spec)
    assert (out / name).read_text() == "the user's"


def test_a_rerun_removes_the_leftovers_named_by_its_store_id(tmp_path):
    spec = parse_spec(document())
    out = tmp_path / "out"
    store_id = opened(out, spec).store_id
    ours = [out / f".sweep.json.{store_id}.0123456789abcdef",
            out / f".runs.parquet.{store_id}.fedcba9876543210.parquet",
            out / "parts" / f".runs-000000001.parquet.{store_id}.00112233445566ff.parquet"]
    for path in ours:
        path.write_bytes(b"half")
    opened(out, spec)
    assert not any(path.exists() for path in ours)
    assert sorted(os.listdir(out)) == ["parts", "sweep.json"]


# -- point 5: the docs, and an OUT inside another sweep's OUT ----------------------------------

def test_sweeps_md_says_run_time_values_are_refused():
    text = " ".join((ROOT / "docs" / "sweeps.md").read_text().split())
    assert "a negative mass gives a failed step" not in text
    assert "BAD_PARAMETER" in text


@pytest.mark.parametrize("inside", ["parts/inner", "trajectories.zarr/x/y", "deeper/inner"])
def test_an_out_inside_another_sweep_s_out_is_refused(tmp_path, inside):
    spec = parse_spec(document())
    outer = tmp_path / "outer"
    opened(outer, spec)
    (outer / "deeper").mkdir()
    spec_file = tmp_path / "spec.toml"
    spec_file.write_text(f'scene = "{MONO}"\nt_end = 0.2\n[axes]\n'
                         '"springs[0].stiffness" = [5.0]\n')
    before = sorted(str(path.relative_to(outer)) for path in outer.rglob("*"))
    result = chaingen_in_process("sweep", spec_file, "-o", outer / inside, cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert len(result.stderr.splitlines()) == 1
    assert f"lies inside the sweep directory {outer}" in result.stderr
    assert sorted(str(path.relative_to(outer)) for path in outer.rglob("*")) == before


def test_an_out_holding_another_sweep_s_out_is_refused(tmp_path):
    spec = parse_spec(document())
    opened(tmp_path / "outer" / "inner", spec)
    with pytest.raises(StoreError, match="holds no sweep.json"):
        run_sweep(spec, tmp_path / "outer")


# -- point 2: the trajectories of every run marked done are there -------------------------------

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
    (directory / "spec.toml").write_text(SMALL)
    spec = load_spec(directory / "spec.toml")
    run_sweep(spec, directory / "out")
    return spec, directory / "out"


def phi_of(out: Path) -> np.ndarray:
    import zarr

    return zarr.open_group(out / "trajectories.zarr", mode="r")["phi"][...]


@pytest.mark.compile
@pytest.mark.parametrize("damage", ["lost", "garbled", "zeroed"])
def test_a_resumed_sweep_finds_a_damaged_trajectory_chunk(finished, tmp_path, damage):
    _, done = finished
    out = tmp_path / "out"
    shutil.copytree(done, out, symlinks=True)
    chunk = out / "trajectories.zarr" / "phi" / "c" / "1" / "0" / "0"
    assert chunk.is_file()
    if damage == "lost":
        chunk.unlink()
    elif damage == "garbled":
        chunk.write_bytes(b"\x00garbage" * 7)
    else:
        # decodes, but not to what was written: a zarr chunk of the same size from run 2
        shutil.copyfile(chunk.parent.parent.parent / "2" / "0" / "0", chunk)
    (tmp_path / "spec.toml").write_text(SMALL)
    result = chaingen_in_process("sweep", tmp_path / "spec.toml", "-o", out, cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    assert len(result.stderr.splitlines()) == 1, result.stderr
    part = out / "parts" / "runs-000000001.parquet"
    assert "trajectories of runs 1..1" in result.stderr
    assert f"remove {part} and run the sweep again" in result.stderr
    part.unlink()                       # as told: the chunk is computed and written again
    result = chaingen_in_process("sweep", tmp_path / "spec.toml", "-o", out, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "12 runs (1 computed now)" in result.stdout
    np.testing.assert_array_equal(phi_of(out), phi_of(done))
    assert not np.isnan(phi_of(out)[1, 0]).any()


@pytest.mark.compile
def test_assembly_finds_a_lost_trajectory_chunk(finished, tmp_path):
    spec, done = finished
    out = tmp_path / "out"
    shutil.copytree(done, out, symlinks=True)
    record = json.loads((out / "sweep.json").read_text())
    (out / "trajectories.zarr" / "omega" / "c" / "4" / "0" / "0").unlink()
    (out / "runs.parquet").unlink()
    store = SweepStore(out, spec, spec.chunk, record["store"])
    with pytest.raises(StoreError, match=r"trajectories of runs 4\.\.4 are not those"):
        store.assemble()
    assert not (out / "runs.parquet").exists()
