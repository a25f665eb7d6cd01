"""Progress: plain lines at a modest rate off a terminal, a live bar on one, nothing when quiet."""

from __future__ import annotations

import io

import pytest

from fleet_sim.study.progress import Progress


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_plain_lines_at_each_step_and_the_end() -> None:
    stream = io.StringIO()
    with Progress(100, stream=stream, plain_lines=4) as progress:
        for done in range(5, 101, 5):  # 20 updates
            progress.update(done, f"{done} of 100")
    lines = stream.getvalue().splitlines()
    assert [line.split(",")[0] for line in lines] == ["  25 of 100", "  50 of 100",
                                                      "  75 of 100", "  100 of 100"]
    assert lines[-1].endswith("s elapsed, ~0 s left")


def test_work_done_before_does_not_count_as_progress() -> None:
    stream = io.StringIO()
    with Progress(10, done_before=8, stream=stream) as progress:
        progress.note("8 of 10 runs already finished: skipped")
        progress.update(9, "runs 9/10 done")  # half of the work left to do
        progress.update(10, "runs 10/10 done")
    assert stream.getvalue().splitlines()[0] == "  8 of 10 runs already finished: skipped"
    assert [line.split(",")[0] for line in stream.getvalue().splitlines()[1:]] == [
        "  runs 9/10 done", "  runs 10/10 done"]


def test_quiet_shows_nothing() -> None:
    stream = Terminal()
    with Progress(10, stream=stream, quiet=True) as progress:
        progress.note("a failed run")
        progress.update(10, "runs 10/10 done")
    assert stream.getvalue() == ""


def test_a_terminal_gets_a_live_bar_and_notes_above_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("TERM", "xterm")
    stream = Terminal()
    with Progress(8 * 3600.0, stream=stream) as progress:
        progress.update(3600.0, "simulated 1.00 of 8.00 h (12%)")
        progress.note("run r01 failed: boom")
        progress.update(8 * 3600.0, "simulated 8.00 of 8.00 h (100%)")
    text = stream.getvalue()
    assert "\x1b[" in text  # drawn in place with terminal control codes
    assert "run r01 failed: boom" in text
    assert "simulated 8.00 of 8.00 h (100%)" in text and "left" in text
