"""`generate -o PKG` into an existing package (issue 30's review): the files the old package's
manifest lists are replaced or removed, the manifest last, and nothing else in PKG is touched
(a user's controller source, the build/ of the package's own CMake commands); a user's file in
the way of a new package file is refused in one line; a failed write (a full disk) is exit
status 1 and leaves the old package as it was."""
from __future__ import annotations

import errno
import json
import os
import pathlib
from pathlib import Path

import pytest

from chaingen.generate.package import generate_package
from chaingen.runtime import contract
from chaingen.scene import load_scene

from helpers import chaingen_in_process, scene_path

MONO = scene_path("three_link_mono")


@pytest.fixture(scope="module")
def packages():
    """three_link_mono's es and vi packages, generated once (SymPy, no compiler)."""
    scene = load_scene(MONO)
    return {method: generate_package(scene, method, 3) for method in ("es", "vi")}


def generate(tmp_path, monkeypatch, package, *options):
    """`chaingen generate SCENE -o pkg`, its package the one given (generated once above)."""
    import chaingen.generate.package

    monkeypatch.setattr(chaingen.generate.package, "generate_package",
                        lambda *_, **__: package)
    return chaingen_in_process("generate", MONO, "--method", package.manifest["method"],
                               "-o", tmp_path / "pkg", "--quiet", *options, cwd=tmp_path)


def tree(directory: Path) -> dict[str, bytes | None]:
    """Every entry under `directory`: its bytes, None for a directory."""
    return {str(path.relative_to(directory)): None if path.is_dir() else path.read_bytes()
            for path in sorted(directory.rglob("*"))}


def user_files(package: Path) -> dict[str, bytes | None]:
    """What a user adds to a package: a controller source and a CMake build directory."""
    (package / "my_controller.c").write_text("/* my controller */\nint gain = 3;\n")
    (package / "build").mkdir()
    (package / "build" / "CMakeCache.txt").write_text("CMAKE_BUILD_TYPE:STRING=Release\n")
    (package / "notes.txt").write_text("runs of Tuesday\n")
    return {name: content for name, content in tree(package).items()
            if name.split("/")[0] in ("my_controller.c", "build", "notes.txt")}


def test_regenerating_a_package_keeps_the_files_it_did_not_write(tmp_path, monkeypatch,
                                                                   packages):
    es, vi = packages["es"], packages["vi"]
    assert generate(tmp_path, monkeypatch, es).returncode == 0
    package = tmp_path / "pkg"
    mine = user_files(package)
    result = generate(tmp_path, monkeypatch, vi)
    assert result.returncode == 0, result.stderr
    after = tree(package)
    for name, content in mine.items():             # the user's files, as they were
        assert after.get(name) == content, name
    for name, text in vi.files.items():            # the new package, whole
        assert after[name] == text.encode(), name
    for name in set(es.files) - set(vi.files):     # the old package's own files, gone
        assert name not in after, name
    assert set(after) == set(mine) | set(vi.files)
    listed = json.loads((package / contract.MANIFEST).read_text())["files"]
    assert sorted(listed) == sorted(vi.files)


def test_a_user_file_in_the_way_of_a_new_package_file_is_refused(tmp_path, monkeypatch,
                                                                  packages):
    """The vi package writes three_link_mono_vi.c; the user has a file of that name in the es
    package's directory, which its manifest does not list: refused, naming it, nothing
    changed."""
    es, vi = packages["es"], packages["vi"]
    assert generate(tmp_path, monkeypatch, es).returncode == 0
    package = tmp_path / "pkg"
    user_files(package)
    (package / "three_link_mono_vi.c").write_text("/* the user's own */\n")
    before = tree(package)
    result = generate(tmp_path, monkeypatch, vi)
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "three_link_mono_vi.c" in lines[0], result.stderr
    assert "not written by the package" in lines[0]
    assert tree(package) == before


@pytest.mark.parametrize("existing", [False, True], ids=["new directory", "existing package"])
def test_a_full_disk_during_generate_is_a_failed_write(tmp_path, monkeypatch, packages,
                                                       existing):
    """A write that fails (the disk fills after two files) is a failed run, exit status 1
    (not bad input, 2), one line; a new directory is not left behind, an existing package
    keeps its files, the user's included, and no staged file remains."""
    es, vi = packages["es"], packages["vi"]
    package = tmp_path / "pkg"
    if existing:
        assert generate(tmp_path, monkeypatch, es).returncode == 0
        user_files(package)
    before = tree(tmp_path)
    real_write_text = pathlib.Path.write_text
    written = []

    def full(path, text, *args, **kwargs):
        if len(written) >= 2:
            real_write_text(path, text[:100], *args, **kwargs)
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        written.append(path)
        return real_write_text(path, text, *args, **kwargs)
    monkeypatch.setattr(pathlib.Path, "write_text", full)
    result = generate(tmp_path, monkeypatch, vi)
    monkeypatch.undo()
    assert result.returncode == 1, result.stdout + result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "No space left on device" in lines[0], result.stderr
    assert str(package) in lines[0]
    assert tree(tmp_path) == before
