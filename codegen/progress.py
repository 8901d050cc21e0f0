"""Progress of long work on a terminal; silence in logs, in CI and with --quiet.

A bar is drawn on stderr only when stderr is a terminal, the environment does not say CI
(`CI` set to anything but "" / "0" / "false", as GitHub Actions, GitLab and most CI systems set
it) and nobody asked for quiet (`--quiet`, or `CHAINGEN_QUIET=1`). Otherwise every call is a
no-op, so the work's output (tables, files) is the same whether or not anyone watches.

    with Progress("simulate", total=n_steps) as progress:
        ...
        progress.update(done)          # absolute count; redrawn at most 10 times a second

    with Progress("generate", total=5) as progress:
        progress.stage("deriving the model")   # one step of a staged job
        with progress.phase("compiling"):      # work that reports nothing until it ends
            compile()

During a phase the bar shows the phase and its running time, redrawn by a thread of its own,
and no time left (the phase's end says nothing about the rest of the work).

A parameter called `progress` means one thing throughout chaingen: a callable told how far the
work is, progress(done) or progress(done, note), `done` an absolute count of the work's units
(steps, stages). A Progress is such a callable (calling it is `update`); so is any function of
one argument where the work reports only counts (Solver.simulate). A status line that takes a
message alone (the bench, the extremes study) is a parameter called `note`.
"""
from __future__ import annotations

import os
import sys
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from typing import TextIO

#: Seconds between redraws: a bar costs nothing measurable at this rate.
REDRAW_SECONDS = 0.1
#: Seconds between redraws of a phase (work that reports nothing until it ends).
PHASE_REDRAW_SECONDS = 0.5
BAR_WIDTH = 28

_quiet = False


def set_quiet(quiet: bool) -> None:
    """Silence (or allow) every progress display of this process (the CLI's --quiet)."""
    global _quiet
    _quiet = bool(quiet)


def quiet() -> bool:
    """Whether set_quiet has silenced the progress displays of this process."""
    return _quiet


def _falsy(value: str | None) -> bool:
    return value is None or value.strip().lower() in ("", "0", "false", "no")


def progress_enabled(stream: TextIO | None = None) -> bool:
    """True when a progress display on `stream` (default stderr) would reach a person."""
    stream = stream if stream is not None else sys.stderr
    if _quiet or not _falsy(os.environ.get("CHAINGEN_QUIET")) or not _falsy(os.environ.get("CI")):
        return False
    isatty = getattr(stream, "isatty", None)
    try:
        return bool(isatty and isatty())
    except ValueError:   # a closed stream
        return False


def _duration(seconds: float) -> str:
    seconds = max(0.0, seconds)
    if seconds < 60:
        return f"{seconds:.0f} s" if seconds >= 10 else f"{seconds:.1f} s"
    minutes, seconds = divmod(int(round(seconds)), 60)
    if minutes < 60:
        return f"{minutes} min {seconds:02d} s"
    hours, minutes = divmod(minutes, 60)
    return f"{hours} h {minutes:02d} min"


class Progress:
    """A progress bar of `total` units (steps, runs, stages) on stderr, when enabled; with
    total = 0, open-ended work shown by its current note and elapsed time."""

    def __init__(self, label: str, total: int, *, unit: str = "", stream: TextIO | None = None,
                 enabled: bool | None = None):
        self.label = label
        self.total = max(int(total), 0)
        self.unit = unit
        self.stream = stream if stream is not None else sys.stderr
        self.enabled = progress_enabled(self.stream) if enabled is None else enabled
        self.done = 0
        self.note = ""
        self.started = time.monotonic()
        self._drawn_at = -1.0
        self._width = 0
        self._phase_started: float | None = None   # a phase runs (no time left is shown)
        self._lock = threading.Lock()

    # -- the work reports -------------------------------------------------------------------

    def update(self, done: int, note: str | None = None) -> None:
        """`done` units of `total` are finished (absolute); redraws at most every 0.1 s."""
        self.done = min(max(int(done), 0), self.total) if self.total else int(done)
        if note is not None:
            self.note = note
        if self.enabled:
            now = time.monotonic()
            if now - self._drawn_at >= REDRAW_SECONDS or self.done >= self.total:
                self._draw(now)

    def __call__(self, done: int, note: str | None = None) -> None:
        """The `progress` callable: the same as update."""
        self.update(done, note)

    def advance(self, count: int = 1, note: str | None = None) -> None:
        self.update(self.done + count, note)

    def stage(self, note: str) -> None:
        """Start the next stage of a staged job: the stages before it are done."""
        self.note = note
        if self.enabled:
            self._draw(time.monotonic())

    @contextmanager
    def phase(self, note: str) -> Iterator[None]:
        """Work that reports nothing until it ends (a C compile): the bar names it with its
        running time, redrawn twice a second, and shows no time left until the block ends."""
        self.note = note
        self._phase_started = time.monotonic()
        stop = threading.Event()
        ticker = None
        if self.enabled:
            self._draw(time.monotonic())

            def tick() -> None:
                while not stop.wait(PHASE_REDRAW_SECONDS):
                    self._draw(time.monotonic())
            ticker = threading.Thread(target=tick, name=f"progress: {note}", daemon=True)
            ticker.start()
        try:
            yield
        finally:
            stop.set()
            if ticker is not None:
                ticker.join()
            self._phase_started = None

    # -- drawing ----------------------------------------------------------------------------

    def line(self, now: float | None = None) -> str:
        """The text of the bar as it would be drawn now."""
        now = time.monotonic() if now is None else now
        elapsed = now - self.started
        if self.total:
            filled = int(round(self.done / self.total * BAR_WIDTH))
            text = f"{self.label} [{'#' * filled}{'.' * (BAR_WIDTH - filled)}] "
            text += f"{self.done}/{self.total}{(' ' + self.unit) if self.unit else ''}"
            text += f"  {_duration(elapsed)}"
        else:   # open-ended work: what it is doing and for how long
            text = f"{self.label} [{_duration(elapsed)}]"
        if self._phase_started is not None:      # a phase: its own time, no time left
            return text + f"  {self.note} ({_duration(now - self._phase_started)})"
        if 0 < self.done < self.total:
            text += f", {_duration(elapsed * (self.total - self.done) / self.done)} left"
        if self.note:
            text += f"  {self.note}"
        return text

    def _draw(self, now: float) -> None:
        with self._lock:      # a phase's thread and the work may both draw
            text = self.line(now)
            padding = " " * max(0, self._width - len(text))
            self.stream.write("\r" + text + padding)
            self.stream.flush()
            self._width = len(text)
            self._drawn_at = now

    def close(self) -> None:
        """Erase the bar: what stays on the terminal is the work's own output."""
        with self._lock:
            if self.enabled and self._width:
                self.stream.write("\r" + " " * self._width + "\r")
                self.stream.flush()
                self._width = 0

    def __enter__(self) -> Progress:
        if self.enabled:
            self._draw(time.monotonic())
        return self

    def __exit__(self, *exc) -> None:
        self.close()
