"""Compile a generated package with the system C compiler into a content-addressed cache.

The library's file name carries the hash of its sources and flags: a shared library loaded once
from a path is never reloaded from it (CasADi issues 1361/2185, acados 905), so a changed
package must get a new path, and an unchanged one is reused without compiling.

The cache trusts nothing by its name alone:

- every library has a side file (`lib...so.json`) with its size, its sha256 and its build hash,
  written after the library is complete; a library whose bytes do not match it (truncated,
  altered, replaced by a link to another) is removed and built again, never loaded;
- the library exports the build hash it was compiled with (`<prefix>_build_hash()`), which the
  loader compares with the one it asked for;
- an index entry (build_solver's lookup by inputs) records the sha256 of its manifest, and is
  used only when the manifest it holds still has it: a manifest altered in the cache, which the
  loader would trust for the sizes of every buffer, is a broken entry, generated again;
- builders of one library take turns (a lock file beside it): the first compiles, the others
  wait and load its result;
- each build works in a directory of its own (`build-<prefix>-<random>.chaingen`), whose
  marker file, written first, is locked while it runs; a directory left by a build that was
  killed is removed by the next build, and only such a directory: the name chaingen gives, a
  real directory (not a link), its marker a regular file with chaingen's text, unlocked, and
  more than a minute old. Anything else in the cache directory (a user's `build-release/`) is
  left alone;
- the compiler processes die with the process that started them (Linux: PR_SET_PDEATHSIG).
"""
from __future__ import annotations

import contextlib
import ctypes
import fcntl
import hashlib
import json
import os
import shutil
import signal
import stat
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

from . import contract
from .errors import BuildError, ChaingenError
from .files import write_text

#: Flags of every build: the generated code must stay clean under all of them (the contract's).
STRICT_FLAGS = contract.STRICT_FLAGS
DEFAULT_OPTIMISATION = ("-O2",)
#: A build directory's name: BUILD_PREFIX + the package prefix + "-" + random + BUILD_SUFFIX.
BUILD_PREFIX = "build-"
BUILD_SUFFIX = ".chaingen"
#: The marker of a build directory, created first in it and locked while its build runs; only a
#: directory holding it (a regular file with MARKER_TEXT) is ever removed as stale.
BUILD_MARKER = ".chaingen-build"
MARKER_TEXT = b"chaingen build directory: removed once its build is over\n"


class CacheError(ChaingenError):
    """The build cache cannot be used (not a directory, not writable): bad set-up, exit 2."""


@dataclass(frozen=True)
class BuiltLibrary:
    """A verified library in the cache and the build hash it was compiled with."""

    path: Path
    build_hash: str


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


def file_digest(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for block in iter(lambda: stream.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def side_file(library: Path) -> Path:
    return library.with_name(library.name + ".json")


def verified(library: Path, expected_hash: str) -> bool:
    """Whether `library` is a complete, unaltered file of build `expected_hash`: a regular file
    (not a link), with the size and sha256 its side file records."""
    try:
        record = json.loads(side_file(library).read_text())
        status = library.lstat()
    except (OSError, ValueError):
        return False
    if not isinstance(record, dict) or record.get("build_hash") != expected_hash:
        return False
    if not (library.is_file() and not library.is_symlink()):
        return False
    return status.st_size == record.get("size") and file_digest(library) == record.get("sha256")


def ready_cache(cache: Path) -> Path:
    """The cache directory, created if needed; CacheError when it cannot be used."""
    try:
        cache.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise CacheError(f"build cache {cache}: exists and is not a directory (set "
                         "CHAINGEN_CACHE_DIR to a directory)") from None
    except OSError as error:
        raise CacheError(f"build cache {cache}: cannot be created: "
                         f"{error.strerror or error} (set CHAINGEN_CACHE_DIR)") from None
    if not cache.is_dir():
        raise CacheError(f"build cache {cache}: not a directory (set CHAINGEN_CACHE_DIR)")
    if not os.access(cache, os.W_OK | os.X_OK):
        raise CacheError(f"build cache {cache}: not writable (set CHAINGEN_CACHE_DIR to a "
                         "writable directory)")
    return cache


#: The cache's index from a solver's inputs (codegen/generate/key.py solver_key) to its
#: library and manifest: build_solver's lookup before any SymPy or CasADi work.
INDEX = "inputs"


def manifest_digest(manifest: dict) -> str:
    """sha256 of a manifest's content (its canonical JSON), as an index entry records it."""
    text = json.dumps(manifest, sort_keys=True, separators=(",", ":"))
    return hashlib.sha256(text.encode()).hexdigest()


def indexed_library(key: str, cache: Path | None = None) -> tuple[BuiltLibrary, dict] | None:
    """The verified library and manifest the index holds for `key`, or None: no entry, or an
    entry that is unreadable, whose manifest is not the one it recorded (manifest_digest), or
    whose library is missing or not the one it names (then the caller generates and builds as if
    there were none, and `remember` replaces the entry)."""
    cache = Path(cache) if cache is not None else cache_directory()
    try:
        entry = json.loads((cache / INDEX / f"{key}.json").read_text())
        library = cache / entry["library"]
        built, manifest = entry["build_hash"], entry["manifest"]
        intact = entry["manifest_sha256"] == manifest_digest(manifest)
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if (not intact or not isinstance(manifest, dict) or library.parent != cache
            or not verified(library, built)):
        return None
    return BuiltLibrary(library, built), manifest


def remember(key: str, library: BuiltLibrary, manifest: dict, cache: Path | None = None) -> None:
    """Record in the index that `key` builds `library` with `manifest`: written to a temporary
    file and renamed, so that a reader sees the old entry or the new, never half of one (two
    processes remembering the same key write the same text)."""
    cache = ready_cache(Path(cache) if cache is not None else cache_directory())
    folder = cache / INDEX
    folder.mkdir(exist_ok=True)
    text = json.dumps({"library": library.path.name, "build_hash": library.build_hash,
                       "manifest": manifest, "manifest_sha256": manifest_digest(manifest)},
                      sort_keys=True)
    handle, temporary = tempfile.mkstemp(prefix=f".{key}-", suffix=".json", dir=folder)
    try:
        with os.fdopen(handle, "w") as stream:
            stream.write(text)
        os.replace(temporary, folder / f"{key}.json")
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(temporary)
        raise


@contextlib.contextmanager
def locked(path: Path):
    """An exclusive lock on the file `path` (created if needed), released on leaving."""
    with open(path, "a") as handle:
        fcntl.flock(handle, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


#: A build directory younger than this is left alone even when its lock is free: its build may
#: not have taken the lock yet.
STALE_AFTER_SECONDS = 60.0


@contextlib.contextmanager
def build_directory(cache: Path, prefix: str):
    """A new build directory in `cache`, its marker written and locked first; removed on
    leaving."""
    workdir = Path(tempfile.mkdtemp(prefix=f"{BUILD_PREFIX}{prefix}-", suffix=BUILD_SUFFIX,
                                    dir=cache))
    try:
        marker = os.open(workdir / BUILD_MARKER,
                         os.O_RDWR | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW, 0o600)
        try:
            fcntl.flock(marker, fcntl.LOCK_EX)
            os.write(marker, MARKER_TEXT)
            yield workdir
        finally:
            os.close(marker)     # releases the lock
    finally:
        shutil.rmtree(workdir, ignore_errors=True)


def remove_stale_builds(cache: Path) -> None:
    """Remove the build directories chaingen made whose build is no longer running: named as
    build_directory names them, a directory itself (no link is followed), more than
    STALE_AFTER_SECONDS old, holding the marker (a regular file with MARKER_TEXT) unlocked.
    Nothing is created in a directory that is not removed."""
    now = time.time()
    for directory in cache.glob(f"{BUILD_PREFIX}*{BUILD_SUFFIX}"):
        try:
            status = os.lstat(directory)
            if (not stat.S_ISDIR(status.st_mode)
                    or now - status.st_mtime < STALE_AFTER_SECONDS):
                continue
            marker = os.open(directory / BUILD_MARKER,
                             os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
        except OSError:
            continue     # no marker: not chaingen's; or removed meanwhile
        try:
            if not stat.S_ISREG(os.fstat(marker).st_mode):
                continue
            fcntl.flock(marker, fcntl.LOCK_EX | fcntl.LOCK_NB)
            if os.pread(marker, len(MARKER_TEXT) + 1, 0) != MARKER_TEXT:
                continue
            if stat.S_ISDIR(os.lstat(directory).st_mode):
                shutil.rmtree(directory, ignore_errors=True)
        except OSError:
            continue     # running (locked), or removed meanwhile
        finally:
            os.close(marker)


def _die_with_parent() -> None:
    """In the compiler's process before exec: be killed when our process dies."""
    libc = ctypes.CDLL(None, use_errno=True)
    libc.prctl(1, signal.SIGKILL)   # PR_SET_PDEATHSIG


def _start(command: list[str], cwd: Path) -> subprocess.Popen:
    try:
        return subprocess.Popen(command, cwd=cwd, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, text=True,
                                preexec_fn=_die_with_parent if sys.platform == "linux" else None)
    except FileNotFoundError:
        raise BuildError(f"C compiler {command[0]!r} not found: install one or set CC to "
                         "a C compiler") from None
    except PermissionError:
        raise BuildError(f"C compiler {command[0]!r} cannot be run (permission denied): set CC "
                         "to a C compiler") from None


def _failure(what: str, command: list[str], returncode: int, stderr: str,
             log: Path) -> BuildError:
    """A BuildError of one line (the compiler's first error line and where its whole output
    went); the full output is kept in the log file and on the error (`details`)."""
    details = f"$ {' '.join(command)}\n{stderr}"
    with contextlib.suppress(OSError):
        write_text(log, details)
    lines = [line for line in stderr.splitlines() if "error" in line] or stderr.splitlines()
    first = lines[0].strip() if lines else f"exit status {returncode}"
    error = BuildError(f"{what} failed (exit status {returncode}): {first} (the compiler's "
                       f"output is in {log})")
    error.details = details
    return error


def build_shared_library(prefix: str, files: dict[str, str], sources: list[str], *,
                         flags: tuple[str, ...] = DEFAULT_OPTIMISATION,
                         source_flags: dict[str, tuple[str, ...]] | None = None,
                         cache: Path | None = None) -> BuiltLibrary:
    """The verified library lib<prefix>-<hash>.so built from `files` (reused when a verified
    one is in the cache).

    Each source is compiled in its own compiler process, all at once (a large model file and
    the solver build side by side), with `flags`, or `source_flags[name]` in their place for
    the sources it lists (a very large generated model is compiled with -O1: gcc's -O2 takes
    minutes on it for no speed, see docs/benchmarks.md).
    """
    cc = compiler()
    source_flags = {name: tuple(value) for name, value in (source_flags or {}).items()}
    # Hidden visibility: only the header's API (marked <PREFIX>_API) is exported.
    common = STRICT_FLAGS + ("-fPIC", "-fvisibility=hidden")
    cache = ready_cache(Path(cache) if cache is not None else cache_directory())
    signature = common + tuple(flags) + tuple(
        f"{name}:{' '.join(value)}" for name, value in sorted(source_flags.items()))
    digest = build_hash(files, signature, cc)
    library = cache / f"lib{prefix}-{digest}.so"
    if verified(library, digest):
        return BuiltLibrary(library, digest)
    with locked(cache / f"lib{prefix}-{digest}.lock"):
        if verified(library, digest):     # built by another process while we waited
            return BuiltLibrary(library, digest)
        for stale in (library, side_file(library)):
            with contextlib.suppress(FileNotFoundError):
                stale.unlink()
        remove_stale_builds(cache)
        _compile(prefix, files, sources, cc, common, flags, source_flags, digest, cache,
                 library)
    return BuiltLibrary(library, digest)


def _compile(prefix, files, sources, cc, common, flags, source_flags, digest, cache,
             library) -> None:
    log = cache / f"lib{prefix}-{digest}.log"
    with build_directory(cache, prefix) as workdir:
        for name, text in files.items():
            (workdir / name).write_text(text)
        define = f'-D{prefix.upper()}_BUILD_HASH="{digest}"'
        commands = [[cc, *common, *source_flags.get(source, flags), define, "-c", source,
                     "-o", f"{source}.o"] for source in sources]
        processes = []
        try:
            for command in commands:
                processes.append(_start(command, workdir))
            errors = [process.communicate()[1] for process in processes]
        finally:
            for process in processes:
                if process.poll() is None:
                    process.kill()
                    process.wait()
        for command, process, stderr in zip(commands, processes, errors):
            if process.returncode != 0:
                raise _failure(f"compiling {prefix}", command, process.returncode, stderr,
                               log)
        output = workdir / library.name
        command = [cc, "-shared", "-o", str(output),
                   *(f"{source}.o" for source in sources), "-lm"]
        linker = _start(command, workdir)
        _, stderr = linker.communicate()
        if linker.returncode != 0:
            raise _failure(f"linking {prefix}", command, linker.returncode, stderr, log)
        record = {"build_hash": digest, "size": output.stat().st_size,
                  "sha256": file_digest(output)}
        os.replace(output, library)   # atomic: a concurrent loader sees all or nothing
        write_text(side_file(library), json.dumps(record) + "\n")
