"""chaingen's errors for people, in one place.

Every error a user can cause is a ChaingenError: one line naming what is wrong and where. Its
`exit_status` is what the command line exits with: 2 for bad input (InputError and the
others below it), 1 for valid input whose run failed (RunFailedError: a build or a simulation).

    ChaingenError
    +-- SceneError              a scene file that cannot be used (file, key, line)
    +-- SettingsError           a command-line value or run setting out of range
    +-- UnsupportedSceneError   a valid scene that the chosen scheme cannot represent
    +-- PackageWriteError       a package directory that cannot be written
    +-- PlotError               a trajectory file that cannot be drawn
    +-- OrderStudyError         a time-step study that cannot run as asked
    +-- BenchError              a bad option of the benchmark
    +-- ScipyPeerError          the SciPy peer cannot run a scene
    +-- RunFailedError          (exit 1)
        +-- BuildError          the C compiler failed
        +-- NewtonError         a step failed (where, why, and the samples before it)

The runtime's errors (chaingen.runtime.errors) are the root and the run failures; they live
there because the runtime imports nothing of the rest of chaingen.
"""
from __future__ import annotations

from .runtime.errors import BuildError, ChaingenError, NewtonError, RunFailedError

__all__ = ["BenchError", "BuildError", "ChaingenError", "NewtonError", "OrderStudyError",
           "PackageWriteError", "PlotError", "RunFailedError", "SceneError", "ScipyPeerError",
           "SettingsError", "UnsupportedSceneError"]


def install_hint(extra: str) -> str:
    """How to install one of chaingen's extras: chaingen is installed from its source tree (it
    is not published on a package index)."""
    return f"in the chaingen source tree: pip install -e '.[{extra}]'"


class SceneError(ChaingenError):
    """A scene file that cannot be used; the message names the file, the key and the line."""


class SettingsError(ChaingenError):
    """A run setting (command-line value or scene default) out of range; names the option."""


class UnsupportedSceneError(ChaingenError):
    """A valid scene that a scheme cannot represent; the message names the key."""


class PackageWriteError(ChaingenError):
    """A generated package that cannot be written where asked."""


class PlotError(ChaingenError):
    """A trajectory file that cannot be read or drawn; names the file and the problem."""


class OrderStudyError(ChaingenError):
    """A time-step study that cannot be run as asked (bad step sizes, a failed reference run)."""


class BenchError(ChaingenError):
    """A bad option of `chaingen bench`; the message names it."""


class ScipyPeerError(ChaingenError):
    """The SciPy peer cannot run a scene (or its derivative turned non-finite)."""
