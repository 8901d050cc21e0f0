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

from .errors import ChaingenError, RunFailedError


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


def write_directory(target: str | os.PathLike, files: dict[str, str], *,
                    written_before=None, last: str | None = None) -> Path:
    """Write `files` ({name: text}) as the directory `target`, all or nothing. Writers of one
    parent directory take turns (directory_lock).

    A new or empty `target` is written into a temporary sibling, which then takes its place:
    a reader never sees a partly written directory. With `written_before` (a function of the
    existing directory giving the names an earlier write put there), an existing `target` is
    updated instead (update_directory): files it did not write are kept.
    Without it, an existing `target` is replaced whole: moved aside (a rename) and deleted
    only after the new one is in place; if anything fails before that, it is moved back.
    """
    target = Path(target)
    parent = target.parent if str(target.parent) else Path(".")
    parent.mkdir(parents=True, exist_ok=True)
    with directory_lock(parent):
        if (written_before is not None and target.is_dir() and not target.is_symlink()
                and any(target.iterdir())):
            return update_directory(target, files, set(written_before(target)), last=last)
        return _replace_directory(target, parent, files)


def update_directory(target: Path, files: dict[str, str], written_before: set[str], *,
                     last: str | None = None) -> Path:
    """Update the directory `target` to hold `files`, keeping what an earlier write did not
    put there: every new file is staged in `target` first, then each is renamed over its old
    version (`last` the last of them), then the files of `written_before` that `files` no
    longer has are removed. A failed write (a full disk) leaves the old files as they were.

    ChaingenError (nothing written) when a name of `files` is already taken by something the
    earlier write did not put there (a user's file is never overwritten) or by a directory."""
    for name in files:
        existing = target / name
        if not os.path.lexists(existing):
            continue
        if existing.is_dir() and not existing.is_symlink():
            raise ChaingenError(f"{existing}: is a directory where the package writes a file; "
                                "move it away or choose another directory")
        if name not in written_before:
            raise ChaingenError(f"{existing}: exists and was not written by the package there "
                                "(its manifest does not list it); move it away or choose "
                                "another directory")
    order = sorted(files, key=lambda name: name == last)
    staged: dict[str, Path] = {}
    try:
        for name in order:
            handle, temporary = tempfile.mkstemp(prefix=f".{name}.", dir=target)
            os.close(handle)
            staged[name] = Path(temporary)
            staged[name].write_text(files[name])
            os.chmod(temporary, 0o666 & ~current_umask())
        for name in order:
            os.replace(staged.pop(name), target / name)
    finally:
        for temporary in staged.values():
            temporary.unlink(missing_ok=True)
    for name in sorted(written_before - set(files)):
        stale = target / name
        if (name == Path(name).name and name not in ("", ".", "..")
                and (stale.is_symlink() or stale.is_file())):
            stale.unlink(missing_ok=True)
    return target


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
    (exit status 2) naming the option and saying why not. Every output file of every command
    goes through this check (the README's list of what the commands refuse).

    Refused: a symbolic link (the write would replace the link, not what it points to); a
    directory; a missing or unwritable parent directory; an existing node that is not a regular
    file (a device, a FIFO, a socket: replacing it would be wrong, writing to it is not a
    file); any of `inputs` (the same file, by inode too: a hard link or another spelling of
    its path) and any path inside an input that is a directory, which would be overwritten.
    An existing regular file that is none of these is replaced whole: the new file is staged
    beside it and renamed over it (staged_file), never written into. An OSError of these
    checks (a name too long, a loop of links) is bad input too: ChaingenError, one line.
    """
    path = Path(path)
    with _path_checked(path, option):
        _check_output_file(path, option, inputs)
    return path


def _check_output_file(path: Path, option: str, inputs) -> None:
    parent = path.parent if str(path.parent) else Path(".")
    if path.is_symlink():
        raise ChaingenError(f"{option}: {path} is a symbolic link; writing would replace the "
                            "link, not what it points to: give another file name")
    if path.is_dir():
        raise ChaingenError(f"{option}: {path} is a directory; give a file name")
    if not parent.is_dir():
        if os.path.lexists(parent):
            os.stat(parent)          # a loop of links: OSError, reported as such
        raise ChaingenError(f"{option}: directory {parent} does not exist")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ChaingenError(f"{option}: directory {parent} is not writable")
    if os.path.lexists(path):
        status = os.stat(path)
        if not stat_module.S_ISREG(status.st_mode):
            raise ChaingenError(f"{option}: {path} exists and is not a regular file (a device, "
                                "FIFO or socket); give a file name")
    _refuse_inputs(path, option, inputs)


@contextlib.contextmanager
def _path_checked(path: Path, option: str) -> Iterator[None]:
    """An OSError of a check of `path` (a name too long, a loop of links, a file where a
    directory is wanted, no permission to look) as the bad input it is: ChaingenError."""
    shown = str(path) if len(str(path)) <= 80 else str(path)[:77] + "..."
    try:
        yield
    except RuntimeError:                # pathlib's resolve() of a loop of links
        raise ChaingenError(f"{option}: {shown}: cannot be used as an output: a loop of "
                            "symbolic links") from None
    except OSError as error:
        raise ChaingenError(f"{option}: {shown}: cannot be used as an output: "
                            f"{error.strerror or error}") from None


def check_output_directory(path: str | os.PathLike, option: str, inputs=()) -> Path:
    """An output directory a command writes (a generated package), checked like
    check_output_file: refused when it is a symbolic link, an existing node that is not a
    directory, an input, inside an input directory, or holds an input (which replacing it
    would delete). What else it may hold is the writer's rule (check_package_target,
    write_package). An OSError of these checks (a name too long) is bad input too."""
    path = Path(path)
    with _path_checked(path, option):
        _check_output_directory(path, option, inputs)
    return path


def _check_output_directory(path: Path, option: str, inputs) -> None:
    if path.is_symlink():
        raise ChaingenError(f"{option}: {path} is a symbolic link; replacing it would replace "
                            "the link, not what it points to: give another directory")
    if os.path.lexists(path) and not path.is_dir():
        raise ChaingenError(f"{option}: {path} exists and is not a directory")
    _refuse_inputs(path, option, inputs)
    if path.is_dir():
        inside = path.resolve()
        for source in inputs:
            source_path = Path(source).resolve()
            if os.path.lexists(source) and inside in source_path.parents:
                raise ChaingenError(f"{option}: {path} holds the input {source}; replacing it "
                                    "would delete the input")


def _refuse_inputs(path: Path, option: str, inputs) -> None:
    """ChaingenError when `path` is one of `inputs` or lies inside one that is a directory."""
    resolved = path.resolve()
    for source in inputs:
        source = Path(source)
        if not os.path.lexists(source):
            continue
        try:
            same = os.path.lexists(path) and os.path.samefile(path, source)
        except OSError:
            same = False
        if same or resolved == source.resolve():
            raise ChaingenError(f"{option}: {path} is the input {source}; writing it would "
                                "overwrite the input")
        if source.is_dir() and source.resolve() in resolved.parents:
            raise ChaingenError(f"{option}: {path} is inside the input {source}; writing there "
                                "would change the input")


@contextlib.contextmanager
def reported_write(path: str | os.PathLike, what: str = "the file") -> Iterator[None]:
    """An OSError while writing `path` (a full disk, an I/O error, a file system gone
    read-only) as one line, RunFailedError (exit status 1): the input was good, the write
    failed, and the staged write left nothing behind."""
    try:
        yield
    except OSError as error:
        raise RunFailedError(f"{path}: cannot write {what}: {error.strerror or error}; nothing "
                             "written") from None
