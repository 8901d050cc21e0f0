"""A tool that holds under faults: one Solver from many threads, Ctrl-C in every mode, outputs that
never overwrite an input or a device, one-line errors instead of tracebacks, and a build cache
that never loads a broken library."""
from __future__ import annotations

import os
import pty
import select
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from chaingen.generate.package import generate_package
from chaingen.runtime import Solver
from chaingen.runtime.build import build_shared_library, side_file

from helpers import chaingen_in_process, load, scene_path, solver_for

MONO = scene_path("three_link_mono")


# -- threads ---------------------------------------------------------------------------------

@pytest.mark.compile
def test_one_solver_from_eight_threads_equals_the_single_threaded_results():
    """Each thread gets its own workspace: simulations and warm-started step sequences on one
    shared Solver equal, bit for bit, the same calls made alone; 20 repetitions."""
    scene = load("three_link_mono")
    solver = solver_for("three_link_mono", "es")
    rng = np.random.default_rng(14)
    starts = [(np.asarray(scene.initial_angles) + rng.uniform(-0.3, 0.3, 3),
               rng.uniform(-0.5, 0.5, 3)) for _ in range(8)]

    def work(phi, omega):
        run = solver.simulate(phi, omega, dt=0.01, n_steps=400, every=50)
        solver.reset()
        x = solver.initial_state(phi, omega)
        for _ in range(50):           # chained steps: the warm start uses this thread's history
            x = solver.step(x, dt=0.01).x1
        return run.samples, x

    alone = [work(*start) for start in starts]
    for _ in range(20):
        results = [None] * len(starts)

        def run(index, results=results):
            results[index] = work(*starts[index])

        threads = [threading.Thread(target=run, args=(index,)) for index in range(len(starts))]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join()
        for (samples, x), (samples_alone, x_alone) in zip(results, alone):
            assert np.array_equal(samples, samples_alone)
            assert np.array_equal(x, x_alone)


# -- Ctrl-C ----------------------------------------------------------------------------------

LONG_RUN = ["--dt", "0.01", "--t-end", "1e6", "--every", "1000000"]   # 10^8 steps: minutes


def interrupted_within(process: subprocess.Popen, seconds: float) -> float:
    """Send SIGINT, wait for the process to end, return how long it took."""
    sent = time.perf_counter()
    process.send_signal(signal.SIGINT)
    process.wait(timeout=10)
    return time.perf_counter() - sent


@pytest.fixture(scope="module")
def warm_cache():
    """The solver of the long runs, built before any of them is timed."""
    solver_for("three_link_mono", "es")


@pytest.mark.compile
@pytest.mark.parametrize("mode", ["not a terminal", "quiet"])
def test_ctrl_c_stops_simulate_at_once_and_writes_nothing(tmp_path, warm_cache, mode):
    out = tmp_path / "run.csv"
    environment = {**os.environ, **({"CHAINGEN_QUIET": "1"} if mode == "quiet" else {})}
    process = subprocess.Popen([sys.executable, "-m", "chaingen", "simulate", MONO, *LONG_RUN,
                                "--out", out], cwd=tmp_path, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True, env=environment)
    time.sleep(4.0)       # past start-up, generation from the cache and into the C loop
    assert process.poll() is None, process.communicate()
    elapsed = interrupted_within(process, 10)
    _, stderr = process.communicate()
    assert process.returncode == 130, stderr
    assert elapsed < 0.5, elapsed
    assert stderr.strip().splitlines() == ["chaingen: interrupted"]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.compile
def test_ctrl_c_stops_simulate_on_a_terminal(tmp_path, warm_cache):
    """With stderr a terminal the progress bar is drawn; SIGINT once it shows stops the run."""
    out = tmp_path / "run.csv"
    leader, follower = pty.openpty()
    environment = {key: value for key, value in os.environ.items()
                   if key not in ("CI", "CHAINGEN_QUIET")}
    process = subprocess.Popen([sys.executable, "-m", "chaingen", "simulate", MONO, *LONG_RUN,
                                "--out", out], cwd=tmp_path, stdout=subprocess.PIPE,
                               stderr=follower, env=environment)
    os.close(follower)
    shown, deadline = b"", time.monotonic() + 60
    while b"simulate three-link-mono" not in shown and time.monotonic() < deadline:
        ready, _, _ = select.select([leader], [], [], 1.0)
        if ready:
            shown += os.read(leader, 4096)
    assert b"simulate three-link-mono" in shown, shown
    elapsed = interrupted_within(process, 10)
    os.close(leader)
    process.communicate()
    assert process.returncode == 130
    assert elapsed < 0.5, elapsed
    assert list(tmp_path.iterdir()) == []


@pytest.mark.compile
def test_ctrl_c_stops_the_python_api_within_half_a_second():
    scene = load("three_link_mono")
    solver = solver_for("three_link_mono", "es")
    main = threading.main_thread().ident
    sent = []

    def interrupt():
        time.sleep(0.5)
        sent.append(time.perf_counter())
        signal.pthread_kill(main, signal.SIGINT)

    threading.Thread(target=interrupt).start()
    with pytest.raises(KeyboardInterrupt):
        solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                        n_steps=10 ** 8, every=10 ** 6)
    assert time.perf_counter() - sent[0] < 0.5


# -- outputs ---------------------------------------------------------------------------------

def test_out_onto_the_scene_file_is_refused_and_the_scene_kept(tmp_path):
    scene = tmp_path / "scene.toml"
    shutil.copy(MONO, scene)
    os.link(scene, tmp_path / "alias.toml")
    for out in (scene, tmp_path / "alias.toml", tmp_path / "." / "scene.toml"):
        result = chaingen_in_process("simulate", scene, "--out", out, cwd=tmp_path)
        assert result.returncode == 2, result.stderr
        assert "would overwrite the input" in result.stderr
    assert scene.read_text() == MONO.read_text()


@pytest.mark.parametrize("target", ["fifo", "device"])
def test_out_onto_a_device_or_fifo_is_refused(tmp_path, target):
    if target == "fifo":
        out = tmp_path / "pipe"
        os.mkfifo(out)
    else:
        out = Path("/dev/null")
    result = chaingen_in_process("simulate", MONO, "--out", out, cwd=tmp_path)
    assert result.returncode == 2 and "not a regular file" in result.stderr, result.stderr
    assert out.exists() and not out.is_file()


def test_an_unwritable_output_directory_is_found_before_simulating(tmp_path, monkeypatch):
    """(As root every directory is writable, so the check is made to see one that is not.)"""
    real_access = os.access
    locked = tmp_path / "locked"
    locked.mkdir()
    monkeypatch.setattr(os, "access", lambda path, mode: False if Path(path) == locked
                        else real_access(path, mode))
    result = chaingen_in_process("simulate", MONO, "--out", locked / "run.csv", cwd=tmp_path)
    assert result.returncode == 2 and "not writable" in result.stderr, result.stderr


@pytest.mark.heavy
def test_concurrent_generates_into_one_directory_each_replace_it_whole(tmp_path):
    processes = [subprocess.Popen([sys.executable, "-m", "chaingen", "generate", MONO,
                                   "--no-sensitivities", "-o", "pkg"], cwd=tmp_path,
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
                 for _ in range(3)]
    for process in processes:
        _, stderr = process.communicate(timeout=300)
        assert process.returncode == 0, stderr
    assert sorted(path.name for path in tmp_path.iterdir()) == ["pkg"]
    reference = generate_package(load("three_link_mono"), "es", 3, sensitivities=False)
    assert {path.name for path in (tmp_path / "pkg").iterdir()} == set(reference.files)


# -- one line instead of a traceback ---------------------------------------------------------

def one_line(result: subprocess.CompletedProcess, status: int, *fragments: str) -> str:
    assert result.returncode == status, result.stderr
    assert "Traceback" not in result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("chaingen: error: "), result.stderr
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    return lines[0]


@pytest.mark.compile
def test_a_failed_compile_is_one_line_with_the_log(tmp_path):
    compiler = tmp_path / "broken-cc"
    compiler.write_text("#!/bin/sh\necho 'model.c:1:1: error: the compiler broke' >&2\nexit 1\n")
    compiler.chmod(0o755)
    result = subprocess.run([sys.executable, "-m", "chaingen", "simulate", MONO, "--t-end",
                             "0.1"], cwd=tmp_path, capture_output=True, text=True,
                            env={**os.environ, "CC": str(compiler),
                                 "CHAINGEN_CACHE_DIR": str(tmp_path / "cache")})
    line = one_line(result, 1, "compiling three_link_mono_es failed", "the compiler broke",
                    "output is in")
    assert Path(line.rsplit("output is in ", 1)[1].rstrip(")")).is_file()


@pytest.mark.parametrize("case", ["missing compiler", "cache is a file", "every too large",
                                  "deep TOML"])
def test_environment_and_input_faults_are_one_line(tmp_path, case):
    environment = dict(os.environ)
    arguments = ["simulate", MONO, "--t-end", "0.1"]
    status, fragment = 2, ""
    if case == "missing compiler":
        environment["CC"] = str(tmp_path / "no-such-cc")
        environment["CHAINGEN_CACHE_DIR"] = str(tmp_path / "cache")
        status, fragment = 1, "not found"
    elif case == "cache is a file":
        (tmp_path / "cache").write_text("")
        environment["CHAINGEN_CACHE_DIR"] = str(tmp_path / "cache")
        fragment = "not a directory"
    elif case == "every too large":
        arguments += ["--every", str(2 ** 63)]
        fragment = "--every"
    else:
        scene = tmp_path / "deep.toml"
        scene.write_text(MONO.read_text().replace("gravity = 1.0", "gravity = "
                                                  + "[" * 3000 + "]" * 3000))
        arguments[1] = scene
        fragment = "nested too deeply"
    result = subprocess.run([sys.executable, "-m", "chaingen", *map(str, arguments)],
                            cwd=tmp_path, capture_output=True, text=True, env=environment)
    if case == "every too large":   # argparse: its usage lines, then one error line
        assert result.returncode == 2 and "Traceback" not in result.stderr
        assert fragment in result.stderr.splitlines()[-1]
    else:
        one_line(result, status, fragment)


@pytest.mark.compile
def test_a_closed_stdout_is_not_a_traceback(tmp_path):
    process = subprocess.Popen([sys.executable, "-m", "chaingen", "simulate", MONO,
                                "--t-end", "0.1"], cwd=tmp_path, stdout=subprocess.PIPE,
                               stderr=subprocess.PIPE, text=True)
    process.stdout.close()            # the reader went away (`... | head -0`)
    _, stderr = process.communicate(timeout=120)
    assert "Traceback" not in stderr, stderr
    assert process.returncode in (0, 1)


def test_an_unexpected_error_is_one_line_unless_debugging(tmp_path, monkeypatch):
    import chaingen.cli

    def broken(args):
        raise AssertionError("a bug")

    monkeypatch.setattr(chaingen.cli, "command_plot", broken)
    result = chaingen_in_process("plot", "x.csv", cwd=tmp_path)
    one_line(result, 1, "internal error: AssertionError: a bug", "--debug")
    with pytest.raises(AssertionError):
        chaingen_in_process("--debug", "plot", "x.csv", cwd=tmp_path)


# -- the build cache -------------------------------------------------------------------------

def package_files():
    return generate_package(load("three_link_gravity"), "es", 1, sensitivities=False).files


@pytest.mark.compile
@pytest.mark.parametrize("damage", ["truncated", "altered", "swapped", "side file lost"])
def test_a_damaged_library_in_the_cache_is_rebuilt_not_loaded(tmp_path, damage):
    files = package_files()
    scene = load("three_link_gravity")
    clean = Solver.from_files(files, cache=tmp_path / "clean")
    expected = clean.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                              n_steps=200).samples
    cache = tmp_path / "cache"
    built = build_shared_library("three_link_gravity_es", files,
                                 ["three_link_gravity_es.c", "three_link_gravity_es_model.c"],
                                 source_flags={"three_link_gravity_es.c": ("-O3",)}, cache=cache)
    library = built.path
    if damage == "truncated":
        library.write_bytes(library.read_bytes()[:4096])
    elif damage == "altered":
        data = bytearray(library.read_bytes())
        data[len(data) // 2] ^= 0xFF
        library.write_bytes(bytes(data))
    elif damage == "swapped":
        other = build_shared_library("three_link_gravity_es_other", files,
                                     ["three_link_gravity_es.c",
                                      "three_link_gravity_es_model.c"], cache=cache).path
        library.unlink()
        library.symlink_to(other)
    else:
        side_file(library).unlink()
    solver = Solver.from_files(files, cache=cache)
    assert solver.library_path == library and library.is_file() and not library.is_symlink()
    result = solver.simulate(scene.initial_angles, scene.initial_velocities, dt=0.01,
                             n_steps=200).samples
    assert np.array_equal(result, expected)


@pytest.mark.compile
def test_a_killed_build_leaves_nothing_that_survives_the_next(tmp_path):
    cache = tmp_path / "cache"
    files = package_files()
    child = subprocess.Popen(
        [sys.executable, "-c", "import sys, json; from chaingen.runtime import Solver; "
         "Solver.from_files(json.load(sys.stdin))"], stdin=subprocess.PIPE, text=True,
        env={**os.environ, "CHAINGEN_CACHE_DIR": str(cache)})
    import json
    child.stdin.write(json.dumps(files))
    child.stdin.close()
    deadline = time.monotonic() + 60
    while not list(cache.glob("build-*/*.c")) and time.monotonic() < deadline:
        time.sleep(0.02)
    assert list(cache.glob("build-*")), "the build never started"
    child.kill()
    child.wait()
    time.sleep(0.5)
    assert not [line for line in subprocess.run(["ps", "-eo", "args"], capture_output=True,
                                                text=True).stdout.splitlines()
                if "three_link_gravity_es" in line and "cc1" in line]
    for directory in cache.glob("build-*"):     # old enough to be recognised as stale
        old = time.time() - 3600
        os.utime(directory, (old, old))
    Solver.from_files(files, cache=cache)
    assert not list(cache.glob("build-*"))
