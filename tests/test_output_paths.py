"""Every output flag of every command goes through one check (runtime.files.check_output_file)
before any work: an input of the command (named directly, or indirectly as a sweep OUT's table,
record, spec and scene), a directory where a file is wanted, a FIFO, a device, a symbolic link
(to an input, a directory, a FIFO or nothing) and a hard link to an input are refused with exit
status 2 and one line, and nothing on disk changes (issue 30, point 7 and Build (c)). A write
that fails half-way (a full disk) is one line, exit status 1, and leaves nothing (point 11)."""
from __future__ import annotations

import contextlib
import errno
import json
import os
import shutil
import signal
import stat
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from helpers import chaingen_in_process, scene_path

MONO = scene_path("three_link_mono")
COLUMNS = ("t", "phi1", "phi2", "phi3", "omega1", "omega2", "omega3", "energy",
           "constraint_error")


def write_inputs(work: Path) -> None:
    """A scene, a trajectory with its metadata, a sweep OUT (record, table, parts, store) with
    its spec, and a report directory, as the commands below read them."""
    shutil.copy(MONO, work / "scene.toml")
    rows = np.zeros((3, len(COLUMNS)))
    rows[:, 0] = [0.0, 0.01, 0.02]
    (work / "traj.csv").write_text(",".join(COLUMNS) + "\n" + "\n".join(
        ",".join(f"{value:.17g}" for value in row) for row in rows) + "\n")
    (work / "traj.csv.json").write_text(json.dumps({"scene": "three_link_mono", "dt": 0.01}))
    (work / "spec.toml").write_text('scene = "scene.toml"\n')
    out = work / "out"
    (out / "parts").mkdir(parents=True)
    (out / "parts" / "runs-000000000.parquet").write_bytes(b"part")
    (out / "trajectories.zarr").mkdir()
    (out / "trajectories.zarr" / "zarr.json").write_text("{}")
    (out / "sweep.json").write_text(json.dumps({"axes": ["springs[0].stiffness"],
                                                "source": "spec.toml", "scene": "scene.toml"}))
    (out / "runs.parquet").write_bytes(b"table")
    (work / "figures").mkdir()


@dataclass(frozen=True)
class Flag:
    """An output flag: the command line writing to TARGET, the name of a fresh target of the
    kind it wants, and the inputs the command reads (relative to the working directory)."""

    name: str
    arguments: tuple[str, ...]
    fresh: str
    inputs: tuple[str, ...]
    kind: str = "file"       # or "directory" (a package)


BENCH = ("bench", "--skip-reference", "--skip-scaling", "--skip-sweep")
FLAGS = (
    Flag("generate -o", ("generate", "scene.toml", "-o", "TARGET"), "package", ("scene.toml",),
         "directory"),
    Flag("export --mjcf", ("export", "scene.toml", "--mjcf", "TARGET"), "model.xml",
         ("scene.toml",)),
    Flag("simulate --out", ("simulate", "scene.toml", "--out", "TARGET"), "run.csv",
         ("scene.toml",)),
    Flag("simulate --out (its metadata)", ("simulate", "scene.toml", "--out", "new.csv"),
         "new.csv.json", ("scene.toml",)),
    Flag("simulate --plot", ("simulate", "scene.toml", "--plot", "TARGET"), "run.png",
         ("scene.toml",)),
    Flag("plot -o", ("plot", "traj.csv", "-o", "TARGET"), "figure.png",
         ("traj.csv", "traj.csv.json")),
    Flag("plot OUT -o", ("plot", "out", "--metric", "max_energy_error", "-o", "TARGET"),
         "figure.png", ("out/runs.parquet", "out/sweep.json", "spec.toml", "scene.toml",
                        "out/parts/runs-000000000.parquet", "out/trajectories.zarr/zarr.json")),
    Flag("plot OUT (default figure)", ("plot", "out", "--metric", "max_energy_error"),
         "out/max_energy_error.png", ("out/runs.parquet", "scene.toml")),
    Flag("animate -o", ("animate", "scene.toml", "traj.csv", "-o", "TARGET"), "chain.gif",
         ("scene.toml", "traj.csv", "traj.csv.json")),
    Flag("order --plot", ("order", "scene.toml", "--plot", "TARGET"), "order.png",
         ("scene.toml",)),
    Flag("bench --out", BENCH + ("--out", "TARGET"), "report.md", ()),
    Flag("bench --figures", BENCH + ("--out", "report.md", "--figures", "figures"),
         "figures/bench_scaling.png", ()),
)

HAZARDS = ("input", "hard link to an input", "directory", "fifo", "device",
           "symlink to an input", "symlink to a directory", "symlink to a fifo",
           "dangling symlink", "name too long", "in a loop of symlinks")
#: Hazards of the path itself: a flag whose output name is fixed cannot be given them.
PATH_HAZARDS = ("name too long", "in a loop of symlinks")


def make_hazard(work: Path, flag: Flag, hazard: str, source: str) -> Path:
    """Put `hazard` where `flag` writes; returns the target path (relative to `work`)."""
    if hazard == "input":
        return Path(source)
    if hazard == "name too long":       # ENAMETOOLONG from the first look at it
        return Path("a" * 300 + Path(flag.fresh).suffix)
    if hazard == "in a loop of symlinks":   # ELOOP
        (work / "loop").symlink_to("loop")
        return Path("loop") / flag.fresh
    target = Path(flag.fresh)
    where = work / target
    if hazard == "hard link to an input":
        os.link(work / source, where)
    elif hazard == "directory":
        where.mkdir()
        (where / "kept.txt").write_text("a file of the user's")
    elif hazard == "fifo":
        os.mkfifo(where)
    elif hazard == "device":
        os.mknod(where, stat.S_IFCHR | 0o600, os.makedev(1, 3))   # as /dev/null
    elif hazard == "symlink to an input":
        where.symlink_to((work / source).resolve())
    elif hazard == "symlink to a directory":
        (work / "elsewhere").mkdir(exist_ok=True)
        where.symlink_to((work / "elsewhere").resolve())
    elif hazard == "symlink to a fifo":
        os.mkfifo(work / "a_fifo")
        where.symlink_to((work / "a_fifo").resolve())
    elif hazard == "dangling symlink":
        where.symlink_to(work / "nothing_here")
    return target


def snapshot(work: Path) -> dict[str, tuple]:
    """Every entry under `work`, not following links: its type and its bytes or link target."""
    found = {}
    for root, directories, files in os.walk(work):
        for name in directories + files:
            path = Path(root) / name
            status = os.lstat(path)
            kind = stat.S_IFMT(status.st_mode)
            if stat.S_ISREG(status.st_mode):
                content = (path.read_bytes(), status.st_ino)
            elif stat.S_ISLNK(status.st_mode):
                content = os.readlink(path)
            else:
                content = None
            found[str(path.relative_to(work))] = (kind, content)
    return found


@contextlib.contextmanager
def time_limit(seconds: int):
    """Fail instead of hanging (a FIFO opened for writing would block)."""
    def expired(*_):
        raise TimeoutError(f"the command ran longer than {seconds} s")
    previous = signal.signal(signal.SIGALRM, expired)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


@pytest.fixture
def no_work(monkeypatch):
    """Any work beyond the checks (generating, simulating, benchmarking) fails the test."""
    import chaingen.generate.package
    import chaingen.simulation
    import chaingen.studies.bench
    import chaingen.studies.order

    def refused(*_, **__):
        raise AssertionError("the command started its work: its output was not refused")
    for module, name in ((chaingen.simulation, "simulate_scene"),
                         (chaingen.simulation, "build_solver"),
                         (chaingen.generate.package, "generate_package"),
                         (chaingen.studies.order, "order_studies"),
                         (chaingen.studies.bench, "run_bench")):
        monkeypatch.setattr(module, name, refused)


def command_for(flag: Flag, target: Path) -> list[str]:
    return [str(target) if argument == "TARGET" else argument for argument in flag.arguments]


#: Files of a sweep's parts/ and trajectories.zarr/: inputs as their directories are (a path
#: inside is refused), not file by file: a hard link to one elsewhere is replaced by rename, and
#: the part keeps its bytes.
IN_INPUT_DIRECTORIES = ("out/parts/", "out/trajectories.zarr/")
CASES = [(flag, hazard, source) for flag in FLAGS for hazard in HAZARDS
         for source in (flag.inputs if hazard in ("input", "hard link to an input",
                                                  "symlink to an input")
                        else ("",))
         if not (hazard in ("input", *PATH_HAZARDS) and "TARGET" not in flag.arguments)
         and not (hazard == "hard link to an input" and source.startswith(IN_INPUT_DIRECTORIES))]


#: Ways to spell the target's path: as is, through ./, through a directory and back, absolute.
SPELLINGS = ("plain", "dot", "down and up", "absolute")


def spelled(target: Path, spelling: str, work: Path) -> Path:
    if spelling == "dot":
        return Path(".") / target if target.parts[0] != "." else target
    if spelling == "down and up":
        (work / "sub").mkdir(exist_ok=True)
        return Path("sub") / ".." / target
    if spelling == "absolute":
        return work / target
    return target


@settings(max_examples=80, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(case=st.sampled_from(CASES), spelling=st.sampled_from(SPELLINGS))
def test_no_output_flag_overwrites_anything(no_work, case, spelling):
    """Drawn from every flag x hazard x input x spelling of the path (80 of them a run;
    test_every_case below takes every case, spelled plainly): exit status 2, one line, and
    every entry of the directory as before."""
    check_case(*case, spelling=spelling)


@pytest.mark.parametrize("flag, hazard, source", CASES,
                         ids=[f"{flag.name}|{hazard}|{source}" for flag, hazard, source in CASES])
def test_every_case(no_work, flag, hazard, source):
    check_case(flag, hazard, source)


def check_case(flag: Flag, hazard: str, source: str, spelling: str = "plain") -> None:
    with tempfile.TemporaryDirectory() as scratch:
        work = Path(scratch)
        write_inputs(work)
        target = spelled(make_hazard(work, flag, hazard, source), spelling, work)
        before = snapshot(work)
        with time_limit(60):
            result = chaingen_in_process(*command_for(flag, target), "--quiet", cwd=work)
        assert result.returncode == 2, (flag, hazard, source, result.stdout, result.stderr)
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("chaingen: error:"), result.stderr
        assert snapshot(work) == before, (flag, hazard, source)


def test_a_package_directory_holding_the_scene_is_not_replaced(tmp_path, no_work):
    """generate -o DIR, where DIR is a package (it has a manifest) that holds the scene read:
    replacing DIR would delete the input."""
    package = tmp_path / "pkg"
    package.mkdir()
    (package / "manifest.json").write_text("{}")
    shutil.copy(MONO, package / "scene.toml")
    before = snapshot(tmp_path)
    result = chaingen_in_process("generate", package / "scene.toml", "-o", package,
                                 cwd=tmp_path)
    assert result.returncode == 2 and "holds the input" in result.stderr, result.stderr
    assert snapshot(tmp_path) == before


def test_a_name_whose_metadata_name_is_too_long_is_bad_input(tmp_path, no_work):
    """simulate --out NAME.csv where NAME.csv fits in 255 bytes but NAME.csv.json does not:
    one line naming --out, exit status 2 (it was an internal error, exit 1), nothing written."""
    shutil.copy(MONO, tmp_path / "scene.toml")
    name = "a" * 250 + ".csv"
    before = snapshot(tmp_path)
    result = chaingen_in_process("simulate", "scene.toml", "--out", name, cwd=tmp_path)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("chaingen: error: --out: "), result.stderr
    assert "File name too long" in lines[0] and "internal error" not in lines[0]
    assert snapshot(tmp_path) == before


def test_an_existing_regular_output_is_replaced_whole(tmp_path):
    """The rule kept for what is not refused: an existing regular file that is no input is
    replaced by rename (a new inode), never written into (a hard link elsewhere keeps the old
    bytes)."""
    out = tmp_path / "model.xml"
    out.write_text("old")
    os.link(out, tmp_path / "other_name")
    result = chaingen_in_process("export", MONO, "--mjcf", out, cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert out.read_text().startswith("<mujoco")
    assert (tmp_path / "other_name").read_text() == "old"


# -- a write that fails: one line, exit status 1, nothing left ----------------------------------

def fake_result(scene, settings, **_):
    """What simulate_scene returns, without a compiler: 20 000 samples (about 4 MB of text)."""
    from chaingen.runtime.results import SimulationResult

    rows = np.full((20_000, len(COLUMNS)), 0.123456789012345678)
    rows[:, 0] = np.arange(rows.shape[0]) * settings.dt
    return SimulationResult(scene=scene.name, method=settings.method, quadrature=3,
                            dt=settings.dt, n_steps=rows.shape[0] - 1, every=1,
                            columns=COLUMNS, samples=rows, wall_time=0.1,
                            newton_iterations=1, max_newton_iterations=1)


def check_full_disk(directory: Path, cwd: Path) -> None:
    shutil.copy(MONO, directory / "scene.toml")
    result = chaingen_in_process("simulate", directory / "scene.toml", "--out",
                                 directory / "run.csv", "--quiet", cwd=cwd)
    assert result.returncode == 1, result.stdout + result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "No space left on device" in lines[0], result.stderr
    assert str(directory / "run.csv") in lines[0]
    assert sorted(path.name for path in directory.iterdir()) == ["scene.toml"]


def test_a_full_disk_on_simulate_out_is_one_line_and_leaves_nothing(tmp_path, monkeypatch):
    import chaingen.simulation

    monkeypatch.setattr(chaingen.simulation, "simulate_scene", fake_result)
    real_savetxt = np.savetxt

    def full(path, *args, **kwargs):    # writes a part, then the disk is full
        real_savetxt(path, np.zeros((10, 2)))
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    monkeypatch.setattr(np, "savetxt", full)
    check_full_disk(tmp_path, tmp_path)


@pytest.fixture
def tiny_file_system(tmp_path):
    """A tmpfs of 64 kB (root and mount rights; skipped elsewhere)."""
    mount = tmp_path / "tiny"
    mount.mkdir()
    made = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mount)],
                          capture_output=True)
    if made.returncode:
        pytest.skip("cannot mount a tmpfs here (needs root and mount rights)")
    try:
        yield mount
    finally:
        subprocess.run(["umount", str(mount)], check=False)


def test_a_really_full_disk_on_simulate_out(tmp_path, tiny_file_system, monkeypatch):
    import chaingen.simulation

    monkeypatch.setattr(chaingen.simulation, "simulate_scene", fake_result)
    check_full_disk(tiny_file_system, tmp_path)
