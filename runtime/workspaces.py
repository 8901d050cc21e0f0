"""Who may use a C workspace: the call that is running owns its workspace.

A C workspace holds a step's scratch space and its Newton history (warm start, kept Jacobian):
two calls at once in one workspace overwrite each other's, a segfault or a wrong result with no
error. Each thread has a home workspace, made on its first call, so a thread's steps see their
own Newton history. A call holds its workspace until it returns: a call made while it runs (from
a progress callback on the waiting thread, from a controller inside the C loop, on any thread)
finds the home workspace taken and gets a spare of its own, with no Newton history, returned to
the pool when it ends. The outer call's workspace is never touched, so its results are those of
the same call made alone.
"""
from __future__ import annotations

import ctypes
import threading


class Workspaces:
    """The workspaces of one loaded package: a home one per thread and a pool of spares.

    `lease()` returns (workspace, home); `release(workspace, home)` gives it back. Every
    `lease` is paired with a `release` in a finally clause."""

    def __init__(self, size: int, initialise) -> None:
        self._size = size
        self._initialise = initialise       # initialise(workspace): no Newton history
        self._threads = threading.local()
        self._spares: list = []
        self._lock = threading.Lock()

    def home(self):
        """The calling thread's home workspace (made and initialised on first use)."""
        workspace = getattr(self._threads, "workspace", None)
        if workspace is None:
            workspace = self._threads.workspace = ctypes.create_string_buffer(self._size)
            self._initialise(workspace)
        return workspace

    def home_busy(self) -> bool:
        """Whether the calling thread's home workspace is held by a call that is running."""
        return getattr(self._threads, "busy", False)

    def lease(self):
        """(a workspace the caller holds alone until `release`, whether it is the thread's
        home one): the home workspace when free, else a spare with no Newton history."""
        threads = self._threads
        if not getattr(threads, "busy", False):
            threads.busy = True
            return self.home(), True
        with self._lock:
            workspace = self._spares.pop() if self._spares else None
        if workspace is None:
            workspace = ctypes.create_string_buffer(self._size)
        self._initialise(workspace)
        return workspace, False

    def serve(self) -> None:
        """Mark the calling thread as one that runs a call for another (simulate's worker):
        the calls of its callbacks get spares, as on any other thread."""
        self._threads.busy = True

    def release(self, workspace, home: bool) -> None:
        if home:
            self._threads.busy = False
        else:
            with self._lock:
                self._spares.append(workspace)
