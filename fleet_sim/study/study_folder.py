"""A study's results folder: the lock that keeps one study in it at a time (who holds it, is
one running now), the plan of the runs the study set out to make, and `SweepError`, what
stops a study.

The lock is an ``fcntl.flock`` because the kernel releases it when its process dies, however
it dies, so a lock is never left stale.

The choices where the issues were silent: docs/background/decisions/analysis-and-studies.md.
"""

from __future__ import annotations

import json
import os
import socket
import sys
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

from fleet_sim.errors import FleetSimError
from userfiles.writing import clean_temporaries, write_json_atomic


class SweepError(FleetSimError):
    """The sweep cannot go on (such as a results folder holding another experiment)."""


class FolderBusy(SweepError):
    """Another sweep or sizing search is writing into the results folder."""


# ---- one sweep per folder ------------------------------------------------------------------

LOCK_FILE = ".fleet-sim.lock"

try:
    import fcntl
except ImportError:  # not POSIX
    fcntl = None  # type: ignore[assignment]


@contextmanager
def folder_lock(out_dir: Path, stream: IO[str] | None = None) -> Iterator[None]:
    """Hold the results folder for this process (see the module docstring), or raise
    FolderBusy naming the owner; `stream` gets the note when a stale lock is taken over."""
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / LOCK_FILE
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    try:
        owner = _lock_owner(fd)
        if fcntl is not None:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                raise _busy(out_dir, _lock_owner(fd) or owner) from None
        elif owner and owner.get("pid") != os.getpid() and pid_alive(int(owner["pid"])):
            raise _busy(out_dir, owner)
        if owner:
            print(f"fleet-sim: note: {out_dir}: taking over the lock of pid {owner.get('pid')} "
                  f"(host {owner.get('host')}, started {owner.get('started')}), which is no "
                  "longer running", file=stream or sys.stderr)
        os.ftruncate(fd, 0)
        mine = {"pid": os.getpid(), "host": socket.gethostname(),
                "started": time.strftime("%Y-%m-%dT%H:%M:%S")}
        os.pwrite(fd, (json.dumps(mine) + "\n").encode(), 0)
        clean_temporaries(out_dir)  # what a killed study left half-written
        try:
            yield
        finally:
            os.ftruncate(fd, 0)  # released: an empty lock file names no owner
    finally:
        os.close(fd)  # releases the flock


def study_running(out_dir: Path) -> bool:
    """Is a study (sweep, size, compare) writing into `out_dir` now? Asked of the lock itself:
    a shared lock cannot be had while a study holds the exclusive one."""
    path = out_dir / LOCK_FILE
    if not path.exists():
        return False
    if fcntl is None:
        owner = study_owner(out_dir)
        return owner is not None and pid_alive(int(json.loads(owner).get("pid", 0)))
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)  # releases the shared lock if it was had
    return False


PLAN_FILE = "plan.json"
"""What the study in a results folder set out to do: its kind and the runs it planned."""


def write_plan(out_dir: Path, study: str, run_ids: Sequence[str] | None) -> None:
    """Record the runs a study plans (None: a search that decides as it goes), so a report
    on an unfinished study can say how many of how many have finished."""
    write_json_atomic(out_dir / PLAN_FILE, {"study": study, "runs": None if run_ids is None
                                            else list(run_ids)})


def read_plan(out_dir: Path) -> dict[str, Any] | None:
    try:
        plan = json.loads((out_dir / PLAN_FILE).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return plan if isinstance(plan, dict) else None


def _lock_owner(fd: int) -> dict[str, Any] | None:
    try:
        owner = json.loads(os.pread(fd, 4096, 0).decode() or "null")
    except (OSError, ValueError):
        return None
    return owner if isinstance(owner, dict) and "pid" in owner else None


def _busy(out_dir: Path, owner: dict[str, Any] | None) -> FolderBusy:
    who = (f"pid {owner.get('pid')} on {owner.get('host')}, started {owner.get('started')}"
           if owner else "pid unknown")
    return FolderBusy(f"{out_dir}: the results folder is in use by another sweep or size "
                      f"({who}); wait for it to finish or use --out for another folder")


def study_owner(out_dir: Path) -> str | None:
    """Who holds the results folder now (the lock file's content), or None when nobody
    does (a run made outside a study)."""
    try:
        text = (out_dir / LOCK_FILE).read_text(encoding="utf-8").strip()
    except OSError:
        return None
    return text or None


def process_start(pid: int) -> str | None:
    """The process's start time (field 22 of /proc/<pid>/stat), "Z" for a zombie, or None
    where /proc cannot tell (not Linux, no such process)."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text(encoding="ascii", errors="replace")
    except OSError:
        return None
    fields = stat[stat.rfind(")") + 2:].split()
    return "Z" if fields[0] in ("Z", "X") else fields[19]


def pid_alive(pid: int, start: str | None = None) -> bool:
    """True if process `pid` runs (and, given its /proc start time `start`, is that process)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    now = process_start(pid)
    return now != "Z" and (start is None or now is None or now == start)
