"""The errors chaingen raises for people, by what the person can do about them.

Every error a user can cause is a ChaingenError: its message is one line that names what is wrong
and where, and `exit_status` is what the command line exits with, 2 for bad input (fix the
input and run again) and 1 for a run that failed (the input was valid; the build or the
simulation did not succeed).
"""
from __future__ import annotations


class ChaingenError(Exception):
    """An error meant for people: the command line prints its message and exits with
    `exit_status`: 2 (bad input) unless a subclass says otherwise."""

    exit_status = 2


class RunFailedError(ChaingenError):
    """Valid input, and the work did not succeed (exit status 1)."""

    exit_status = 1


class BuildError(RunFailedError, RuntimeError):
    """The C compiler failed; the message carries its command and stderr."""


class NewtonError(RunFailedError, RuntimeError):
    """A step failed; carries where and why, and the samples written before the failure."""

    def __init__(self, message: str, *, status: int, step: int | None = None,
                 time: float | None = None, result=None):
        super().__init__(message)
        self.status = status
        self.step = step
        self.time = time
        self.result = result
