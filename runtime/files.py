"""Writing files and directories all or nothing.

Every file chaingen writes for a user (trajectories and their metadata, figures, animations,
reports, generated packages) is staged beside its target and renamed into place once it is
complete: an interrupted or failed write leaves the previous file (or none), never a half-written
one. Staged files get the permissions of an ordinary new file (0666 or 0777 less the umask), not
the 0600 of a temporary file.
"""
from __future__ import annotations

import contextlib
import fcntl
import os
import shutil
import stat as stat_module
import tempfile
from collections.abc import Iterator
from pathlib import Path

from .errors import ChaingenError


def current_umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def staged_file(path: str | os.PathLike, *, suffix: str = "") -> Iterator[Path]:
    """A temporary path beside `path` to write to; renamed onto `path` when the block ends
    without an exception, removed when it raises.

        with staged_file(out) as temporary:
            figure.savefig(temporary)
    """
    path = Path(path)
    handle, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix,
                                    dir=path.parent if str(path.parent) else ".")
    os.close(handle)
    temporary = Path(name)
    try:
        yield temporary
        os.chmod(temporary, 0o666 & ~current_umask())
        os.replace(temporary, path)
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Write `text` to `path` all or nothing."""
    path = Path(path)
    with staged_file(path) as temporary:
        temporary.write_text(text)
    return path


@contextlib.contextmanager
def staged_files(paths) -> Iterator[list[Path]]:
    """Temporary paths beside each of `paths`, renamed into place together (in reverse order,
    so the first path, the main file, appears last) when the block ends without an exception."""
    paths = [Path(path) for path in paths]
    temporaries: list[Path] = []
    try:
        for path in paths:
            handle, name = tempfile.mkstemp(prefix=f".{path.name}.",
                                            dir=path.parent if str(path.parent) else ".")
            os.close(handle)
            temporaries.append(Path(name))
        yield list(temporaries)
        for temporary in temporaries:
            os.chmod(temporary, 0o666 & ~current_umask())
        for temporary, path in reversed(list(zip(temporaries, paths, strict=True))):
            os.replace(temporary, path)
    except BaseException:
        for temporary in temporaries:
            temporary.unlink(missing_ok=True)
        raise


@contextlib.contextmanager
def directory_lock(directory: str | os.PathLike, *, wait: bool = True):
    """An exclusive lock on `directory` itself (flock on its descriptor): writers of its entries
    take turns; nothing is left behind. With wait=False, BlockingIOError if another holds it."""
    handle = os.open(directory, os.O_RDONLY)
    try:
        fcntl.flock(handle, fcntl.LOCK_EX | (0 if wait else fcntl.LOCK_NB))
        yield
    finally:
        os.close(handle)


def write_directory(target: str | os.PathLike, files: dict[str, str]) -> Path:
    """Write `files` ({name: text}) as the directory `target`, all or nothing. Writers of one
    parent directory take turns (directory_lock), so concurrent writers of one target each
    replace it whole.

    The files are written into a temporary sibling, which then takes the place of `target`.
    An existing `target` is first moved aside (a rename) and deleted only after the new one is
    in place; if anything fails before that, it is moved back. A reader never sees a partly
    written directory, only the old one, the new one or, for the moment between the two
    renames, none.
    """
    target = Path(target)
    parent = target.parent if str(target.parent) else Path(".")
    parent.mkdir(parents=True, exist_ok=True)
    with directory_lock(parent):
        return _replace_directory(target, parent, files)


def _replace_directory(target: Path, parent: Path, files: dict[str, str]) -> Path:
    staging = Path(tempfile.mkdtemp(prefix=f".{target.name}.", dir=parent))
    old = None
    try:
        staging.chmod(0o777 & ~current_umask())
        for name, text in files.items():
            (staging / name).write_text(text)
        if target.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{target.name}.old.", dir=parent))
            os.replace(target, old / target.name)
        os.replace(staging, target)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        if old is not None and (old / target.name).exists() and not target.exists():
            os.replace(old / target.name, target)
        raise
    finally:
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    return target


def check_output_file(path: str | os.PathLike, option: str, inputs=()) -> Path:
    """An output file a command may write, checked before any work is done; ChaingenError
    (exit status 2) naming the option and saying why not.

    Refused: a directory; a missing or unwritable parent directory; an existing node that is
    not a regular file (a device, a FIFO, a socket: replacing it would be wrong, writing to it
    is not a file); and any of `inputs` (the same file, by inode too: a hard link or another
    spelling of its path), which would be overwritten.
    """
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise ChaingenError(f"{option}: {path} is a directory; give a file name")
    if not parent.is_dir():
        raise ChaingenError(f"{option}: directory {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ChaingenError(f"{option}: directory {parent} is not writable")
    if os.path.lexists(path):
        status = os.stat(path)
        if not stat_module.S_ISREG(status.st_mode):
            raise ChaingenError(f"{option}: {path} exists and is not a regular file (a device, "
                                "FIFO or socket); give a file name")
        for source in inputs:
            try:
                if os.path.samefile(path, source):
                    raise ChaingenError(f"{option}: {path} is the input {source}; writing it "
                                        "would overwrite the input")
            except FileNotFoundError:
                continue
    return path
