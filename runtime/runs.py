"""A simulate call's C run, watched: progress, Ctrl-C, and stops asked from other threads.

`Solver.simulate` runs the C loop in a worker thread when called from the main thread or with a
progress callback, and waits for it there, so Ctrl-C (KeyboardInterrupt) and exceptions of a
progress callback arrive promptly; the loop is told to stop through its control block and stops
after the current step. Runs in other threads (a pool running a study) are stopped from outside
with a StopSignal passed to their simulate calls: `signal.stop()` ends every run that holds it
after its current step.
"""
from __future__ import annotations

import threading

from .interface import ControlStruct

#: Seconds between two looks of the waiting thread at a running simulate: progress, Ctrl-C.
POLL_SECONDS = 0.05


class StopSignal:
    """Stops the simulate calls given it, from any thread: each running one ends after its
    current step (NewtonError with status INTERRUPTED), and a later one does not start."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._blocks: dict[int, ControlStruct] = {}
        self.stopped = False

    def stop(self) -> None:
        with self._lock:
            self.stopped = True
            for block in self._blocks.values():
                block.stop = 1

    def _attach(self, block: ControlStruct) -> None:
        with self._lock:
            if self.stopped:
                block.stop = 1
            self._blocks[id(block)] = block

    def _detach(self, block: ControlStruct) -> None:
        with self._lock:
            self._blocks.pop(id(block), None)


def check_watchers(progress, stop) -> None:
    """A one-line TypeError for a progress that is not callable or a stop that is no
    StopSignal (they failed once the run had started: "'int' object is not callable",
    "'bool' object has no attribute '_attach'")."""
    if progress is not None and not callable(progress):
        raise TypeError(f"progress: must be a callable progress(steps_done) or None, got "
                        f"{type(progress).__name__}")
    if stop is not None and not isinstance(stop, StopSignal):
        raise TypeError(f"stop: must be a StopSignal or None, got {type(stop).__name__}")


def run_watched(call, control, progress, name: str) -> int:
    """call() (the C run, whose control block is `control`): in this thread, or, from the
    main thread or with a progress callback, in a worker thread `name` while this thread
    waits, reports progress and stays interruptible; an exception here (Ctrl-C, progress's
    own) stops the loop through `control` and propagates once the worker has returned (it
    holds its workspace until then)."""
    if progress is None and threading.current_thread() is not threading.main_thread():
        return call()
    outcome: list = []

    def run() -> None:
        try:
            outcome.append(call())
        except BaseException as error:    # raised again in the waiting thread
            outcome.append(error)

    worker = threading.Thread(target=run, name=name, daemon=True)
    worker.start()
    try:
        while worker.is_alive():
            worker.join(POLL_SECONDS)
            if progress is not None:
                progress(int(control.steps))
    except BaseException:
        control.stop = 1
        while worker.is_alive():
            try:
                worker.join()
            except KeyboardInterrupt:    # a second Ctrl-C: the run stops after this step
                pass
        raise
    if isinstance(outcome[0], BaseException):
        raise outcome[0]
    if progress is not None:
        progress(int(control.steps))     # the end, also of a run shorter than one look
    return outcome[0]
