"""The build cache removes only the build directories chaingen made and whose build is over.

runtime/build.py removes a directory left by a killed build when the next build starts. Before,
it removed every `build-*` directory older than a minute in the cache directory, a user's
`build-release/` included (and created its lock file inside first). Now only a directory named
as chaingen names it, a real directory (no link followed), holding chaingen's marker file (a
regular file with its text), unlocked and more than a minute old.
"""
from __future__ import annotations

import fcntl
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from chaingen.runtime.build import (
    BUILD_MARKER,
    BUILD_PREFIX,
    BUILD_SUFFIX,
    MARKER_TEXT,
    build_directory,
    remove_stale_builds,
)

from helpers import ROOT

HOURS_AGO = time.time() - 2 * 3600


def age(path: Path) -> None:
    os.utime(path, (HOURS_AGO, HOURS_AGO), follow_symlinks=False)


def left_by_a_killed_build(cache: Path, name: str) -> Path:
    """A build directory as build_directory makes it, its build gone, two hours old."""
    directory = cache / f"{BUILD_PREFIX}{name}-abc123{BUILD_SUFFIX}"
    directory.mkdir()
    (directory / BUILD_MARKER).write_bytes(MARKER_TEXT)
    (directory / f"{name}.c").write_text("int x;\n")
    age(directory)
    return directory


def contents(directory: Path) -> dict[str, bytes]:
    return {path.name: path.read_bytes() for path in directory.iterdir()}


def test_a_users_directories_in_the_cache_are_left_alone(tmp_path):
    cache = tmp_path / "cache"
    cache.mkdir()
    release = cache / "build-release"             # the issue's: a user's build tree
    release.mkdir()
    (release / "app.o").write_text("x\n")
    unmarked = cache / f"{BUILD_PREFIX}mine-abc123{BUILD_SUFFIX}"   # chaingen's name, no marker
    unmarked.mkdir()
    (unmarked / "notes.txt").write_text("mine\n")
    foreign = cache / f"{BUILD_PREFIX}other-abc123{BUILD_SUFFIX}"   # a marker of other text
    foreign.mkdir()
    (foreign / BUILD_MARKER).write_text("not chaingen's\n")
    elsewhere = tmp_path / "elsewhere"            # a marked directory outside the cache ...
    elsewhere.mkdir()
    (elsewhere / BUILD_MARKER).write_bytes(MARKER_TEXT)
    (elsewhere / "keep.c").write_text("int y;\n")
    linked = cache / f"{BUILD_PREFIX}linked-abc123{BUILD_SUFFIX}"   # ... a link to it inside
    linked.symlink_to(elsewhere, target_is_directory=True)
    marker_link = cache / f"{BUILD_PREFIX}marklink-abc123{BUILD_SUFFIX}"
    marker_link.mkdir()                           # its marker a link to a marked file
    (marker_link / BUILD_MARKER).symlink_to(elsewhere / BUILD_MARKER)
    fifo = cache / f"{BUILD_PREFIX}fifo-abc123{BUILD_SUFFIX}"
    fifo.mkdir()
    os.mkfifo(fifo / BUILD_MARKER)                # a marker that is no regular file
    kept = [release, unmarked, foreign, elsewhere, marker_link, fifo]
    before = {path: contents(path) for path in kept if path != fifo}
    for path in (*kept, linked):
        age(path)
    stale = left_by_a_killed_build(cache, "pkg")

    remove_stale_builds(cache)

    assert not stale.exists()                     # chaingen's own, its build over: removed
    for path in kept:
        assert path.is_dir() and not path.is_symlink(), path
    assert {path: contents(path) for path in kept if path != fifo} == before   # nothing added
    assert linked.is_symlink() and linked.resolve() == elsewhere.resolve()
    assert sorted(os.listdir(fifo)) == [BUILD_MARKER]


def test_a_running_or_young_build_is_left_alone(tmp_path):
    cache = tmp_path / "cache"
    cache.mkdir()
    with build_directory(cache, "running") as workdir:
        assert workdir.name.startswith(f"{BUILD_PREFIX}running-")
        assert workdir.name.endswith(BUILD_SUFFIX)
        assert (workdir / BUILD_MARKER).read_bytes() == MARKER_TEXT
        age(workdir)                              # old, but its build holds the marker's lock
        remove_stale_builds(cache)
        assert workdir.is_dir()
    assert not workdir.exists()                   # removed by its own build on leaving
    young = left_by_a_killed_build(cache, "young")
    os.utime(young)                               # a minute has not passed: its build may not
    remove_stale_builds(cache)                    # have taken the lock yet
    assert young.is_dir()
    age(young)
    with open(young / BUILD_MARKER) as handle:    # another process's lock
        fcntl.flock(handle, fcntl.LOCK_EX)
        code = ("import sys; from pathlib import Path; "
                "from chaingen.runtime.build import remove_stale_builds; "
                "remove_stale_builds(Path(sys.argv[1]))")
        subprocess.run([sys.executable, "-c", code, str(cache)], check=True)
        assert young.is_dir()
    remove_stale_builds(cache)
    assert not young.exists()


@pytest.mark.compile
def test_a_build_in_the_cache_keeps_a_users_build_directory(tmp_path):
    """The issue's session: `mkdir -p P/build-release; echo x > P/build-release/app.o; touch -d
    '2 hours ago' P/build-release; CHAINGEN_CACHE_DIR=P chaingen simulate ...` removed it."""
    cache = tmp_path / "P"
    release = cache / "build-release"
    release.mkdir(parents=True)
    (release / "app.o").write_text("x\n")
    age(release)
    stale = left_by_a_killed_build(cache, "killed")
    result = subprocess.run([sys.executable, "-m", "chaingen", "simulate",
                             str(ROOT / "scenes" / "collapsing_spring.toml"), "--t-end", "0.1",
                             "--out", str(tmp_path / "run.csv")],
                            capture_output=True, text=True,
                            env={**os.environ, "CHAINGEN_CACHE_DIR": str(cache)})
    assert result.returncode in (0, 1), result.stderr     # the spring may collapse: exit 1
    assert list(cache.glob("lib*.so")), result.stderr     # a build ran in the cache
    assert contents(release) == {"app.o": b"x\n"}
    assert not stale.exists()
    assert not list(cache.glob(f"{BUILD_PREFIX}*{BUILD_SUFFIX}"))
