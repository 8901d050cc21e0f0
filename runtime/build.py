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

from .errors import BuildError

#: Flags of every build: the generated code must stay clean under all of them.
STRICT_FLAGS = ("-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic")
DEFAULT_OPTIMISATION = ("-O2",)


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
                         source_flags: dict[str, tuple[str, ...]] | None = None,
                         cache: Path | None = None) -> Path:
    """Path of lib<prefix>-<hash>.so built from `files` (reused when it already exists).

    Each source is compiled in its own compiler process, all at once (a large model file and
    the solver build side by side), with `flags`, or `source_flags[name]` in their place for
    the sources it lists (a very large generated model is compiled with -O1: gcc's -O2 takes
    minutes on it for no speed, see docs/benchmarks.md).
    """
    cc = compiler()
    source_flags = {name: tuple(value) for name, value in (source_flags or {}).items()}
    # Hidden visibility: only the header's API (marked <PREFIX>_API) is exported.
    common = STRICT_FLAGS + ("-fPIC", "-fvisibility=hidden")
    cache = Path(cache) if cache is not None else cache_directory()
    signature = common + tuple(flags) + tuple(
        f"{name}:{' '.join(value)}" for name, value in sorted(source_flags.items()))
    library = cache / f"lib{prefix}-{build_hash(files, signature, cc)}.so"
    if library.exists():
        return library
    cache.mkdir(parents=True, exist_ok=True)
    workdir = Path(tempfile.mkdtemp(prefix=f"build-{prefix}-", dir=cache))
    try:
        for name, text in files.items():
            (workdir / name).write_text(text)
        commands = [[cc, *common, *source_flags.get(source, flags), "-c", source, "-o",
                     f"{source}.o"] for source in sources]
        processes = [subprocess.Popen(command, cwd=workdir, stdout=subprocess.PIPE,
                                      stderr=subprocess.PIPE, text=True)
                     for command in commands]
        errors = [process.communicate()[1] for process in processes]
        for command, process, stderr in zip(commands, processes, errors):
            if process.returncode != 0:
                raise BuildError(f"compiling {prefix} failed: {' '.join(command)}\n{stderr}")
        output = workdir / library.name
        command = [cc, "-shared", "-o", str(output), *(f"{source}.o" for source in sources),
                   "-lm"]
        result = subprocess.run(command, cwd=workdir, capture_output=True, text=True)
        if result.returncode != 0:
            raise BuildError(f"linking {prefix} failed: {' '.join(command)}\n{result.stderr}")
        os.replace(output, library)   # atomic: a concurrent loader sees all or nothing
    finally:
        shutil.rmtree(workdir, ignore_errors=True)
    return library
