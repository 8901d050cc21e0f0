"""Compile a generated package with the system C compiler into a content-addressed cache.

The library's file name carries the hash of its sources and flags: a shared library loaded once
from a path is never reloaded from it (CasADi issues 1361/2185, acados 905), so a changed
package must get a new path, and an unchanged one is reused without compiling.
"""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

#: Flags of every build: the generated code must stay clean under all of them.
STRICT_FLAGS = ("-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic")
DEFAULT_OPTIMISATION = ("-O2",)


class BuildError(RuntimeError):
    """The C compiler failed; the message carries its command and stderr."""


def cache_directory() -> Path:
    """$CHAINGEN_CACHE_DIR, else $XDG_CACHE_HOME/chaingen, else ~/.cache/chaingen."""
    explicit = os.environ.get("CHAINGEN_CACHE_DIR")
    if explicit:
        return Path(explicit)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "chaingen"


def compiler() -> str:
    return os.environ.get("CC", "cc")


def build_hash(files: dict[str, str], flags: tuple[str, ...], cc: str) -> str:
    digest = hashlib.sha256()
    for name in sorted(files):
        digest.update(name.encode() + b"\0" + files[name].encode() + b"\0")
    digest.update(" ".join((cc,) + flags).encode())
    return digest.hexdigest()[:20]


def build_shared_library(prefix: str, files: dict[str, str], sources: list[str], *,
                         flags: tuple[str, ...] = DEFAULT_OPTIMISATION,
                         cache: Path | None = None) -> Path:
    """Path of lib<prefix>-<hash>.so built from `files` (reused when it already exists)."""
    cc = compiler()
    # Hidden visibility: only the header's API (marked <PREFIX>_API) is exported.
    all_flags = STRICT_FLAGS + tuple(flags) + ("-fPIC", "-fvisibility=hidden", "-shared")
    cache = Path(cache) if cache is not None else cache_directory()
    library = cache / f"lib{prefix}-{build_hash(files, all_flags, cc)}.so"
    if library.exists():
        return library
    cache.mkdir(parents=True, exist_ok=True)
    workdir = Path(tempfile.mkdtemp(prefix=f"build-{prefix}-", dir=cache))
    try:
        for name, text in files.items():
            (workdir / name).write_text(text)
        output = workdir / library.name
        command = [cc, *all_flags, "-o", str(output), *sources, "-lm"]
        result = subprocess.run(command, cwd=workdir, capture_output=True, text=True)
        if result.returncode != 0:
            raise BuildError(f"compiling {prefix} failed: {' '.join(command)}\n{result.stderr}")
        os.replace(output, library)   # atomic: a concurrent loader sees all or nothing
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    return library
