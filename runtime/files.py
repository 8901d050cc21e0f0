"""Writing files and directories all or nothing.

Every file chaingen writes for a user (trajectories and their metadata, figures, animations,
reports, generated packages) is staged beside its target and renamed into place once it is
complete: an interrupted or failed write leaves the previous file (or none), never a half-written
one. Staged files get the permissions of an ordinary new file (0666 or 0777 less the umask), not
the 0600 of a temporary file.
"""
from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path


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


def write_directory(target: str | os.PathLike, files: dict[str, str]) -> Path:
    """Write `files` ({name: text}) as the directory `target`, all or nothing.

    The files are written into a temporary sibling, which then takes the place of `target`.
    An existing `target` is first moved aside (a rename) and deleted only after the new one is
    in place; if anything fails before that, it is moved back. A reader never sees a partly
    written directory, only the old one, the new one or, for the moment between the two
    renames, none.
    """
    target = Path(target)
    parent = target.parent if str(target.parent) else Path(".")
    parent.mkdir(parents=True, exist_ok=True)
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
