"""Progress of long work (a run, a sweep, a sizing search) on stderr: the one implementation.

On a terminal, a live bar (rich) with what is done, the time elapsed and the time left; notes
(a failed run, a step of the sizing search) print above it. Anywhere else (a CI log, a pipe, a
test capturing stderr) plain lines: one at each of `plain_lines` equal steps of the work and at
its end, so logs stay short. `quiet` shows nothing at all.

The time left is the time elapsed scaled by the work left over the work done since the start
(the choices where the issues were silent: docs/background/decisions/analysis-and-studies.md).
The simulation core knows nothing of this: the engine calls a plain callback.
"""

from __future__ import annotations

import sys
import time
from types import TracebackType
from typing import IO

from rich.console import Console
from rich.progress import (
    BarColumn,
    TaskID,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)
from rich.progress import Progress as RichProgress

SPEED_ESTIMATE_S = 24 * 3600.0
"""The live bar's time left comes from the pace since the start (rich's default: 30 s only)."""


class Progress:
    """Work from `done_before` to `total` units; `update` says how far it got and how it
    stands in words; `note` adds a line. Use as a context manager (the bar stops on exit)."""

    def __init__(self, total: float | None = None, done_before: int = 0,
                 stream: IO[str] | None = None, quiet: bool = False,
                 plain_lines: int = 10) -> None:
        self.total = total
        self.done_before = done_before
        self.stream = stream if stream is not None else sys.stderr
        self.quiet = quiet
        self.plain_lines = plain_lines
        self.live = not quiet and total is not None and self.stream.isatty()
        self.start = time.perf_counter()
        self._bar: RichProgress | None = None
        self._task = TaskID(0)
        self._plain_step = 0

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, kind: type[BaseException] | None, exc: BaseException | None,
                 trace: TracebackType | None) -> None:
        self.close()

    def update(self, done: float, status: str) -> None:
        """`done` units of `total` are done; `status` says so in words."""
        if self.quiet or self.total is None:
            return
        if self.live:
            self._live_bar().update(self._task, completed=done, description=status)
            return
        share = (done - self.done_before) / max(self.total - self.done_before, 1e-12)
        step = min(int(share * self.plain_lines), self.plain_lines)
        if step > self._plain_step:
            self._plain_step = step
            elapsed = time.perf_counter() - self.start
            left = elapsed * (1.0 - share) / share if share > 0 else 0.0
            self._line(f"{status}, {elapsed:.1f} s elapsed, ~{left:.0f} s left")

    def note(self, text: str) -> None:
        """A line of its own (above the bar on a terminal)."""
        if self.quiet:
            return
        if self._bar is not None:
            self._bar.console.print(f"  {text}", markup=False, highlight=False)
        else:
            self._line(text)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.stop()
            self._bar = None

    def _live_bar(self) -> RichProgress:
        if self._bar is None:
            self._bar = RichProgress(
                TextColumn("  {task.description}"), BarColumn(), TimeElapsedColumn(),
                TextColumn("elapsed,"), TimeRemainingColumn(), TextColumn("left"),
                console=Console(file=self.stream), refresh_per_second=4,
                speed_estimate_period=SPEED_ESTIMATE_S)
            self._task = self._bar.add_task("", total=self.total, completed=self.done_before)
            self._bar.start()
        return self._bar

    def _line(self, text: str) -> None:
        self.stream.write(f"  {text}\n")
        self.stream.flush()
