"""Small helpers shared by the writers of files a planner reads: tidy YAML for layouts and
profiles imported from LIF files and VDA 5050 factsheets, and atomic writes for every file the
program leaves behind.

Every file fleet_sim writes for a planner (run tables, kpis.json, summaries, the DuckDB file,
reports, exports, replay pages) is written under a temporary name in the same folder, flushed
to disk (fsync) and renamed into place (`atomic_path`): a full disk, a kill or a crash leaves
the previous file or none under the final name, never a part of one. The temporaries of a
process that was killed are removed by the next process that takes the folder
(`clean_temporaries`).
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from userfiles.checking import InputError


def tidy_numbers(value: Any) -> Any:
    """Whole numbers written without a decimal point (0, not 0.0), as a planner writes them;
    the value read back is equal."""
    if isinstance(value, float) and value.is_integer() and abs(value) < 1e15:
        return int(value)
    if isinstance(value, dict):
        return {k: tidy_numbers(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [tidy_numbers(v) for v in value]
    return value


def comment_lines(lines: Any) -> str:
    """`lines` as YAML comments; characters YAML may not hold become '?'."""
    return "".join("# " + "".join(c if c.isprintable() else "?" for c in line).rstrip() + "\n"
                   if line else "#\n" for line in lines)


# ---- files written whole or not at all -----------------------------------------------------

TEMP_SUFFIX = ".tmp"
"""Temporaries are named ``.<final name>.<pid>.tmp`` beside the file they become."""


def temp_path(path: Path) -> Path:
    """The temporary name `path` is written under before it is renamed into place."""
    return path.with_name(f".{path.name}.{os.getpid()}{TEMP_SUFFIX}")


def fsync_path(path: Path) -> None:
    """Flush a written file (or a folder's entries) to the disk."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextmanager
def atomic_path(path: Path) -> Iterator[Path]:
    """A temporary path beside `path` for the block to write; when the block ends normally
    the file is flushed to disk and renamed to `path` (then the folder's entry flushed), so
    `path` holds the old file or the whole new one, never a part. When the block raises, the
    temporary is removed and `path` is left as it was."""
    tmp = temp_path(path)
    try:
        yield tmp
        fsync_path(tmp)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise
    with contextlib.suppress(OSError):  # not every file system syncs a folder
        fsync_path(path.parent)


def write_text_atomic(path: Path, text: str) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_json_atomic(path: Path, data: Any) -> None:
    write_text_atomic(path, json.dumps(data, indent=2, default=str) + "\n")


def copy_atomic(source: Path, path: Path) -> None:
    with atomic_path(path) as tmp:
        shutil.copyfile(source, tmp)


TEMPORARY_PATTERNS = (f".*{TEMP_SUFFIX}", ".*.partial", ".partial")
"""What a writer leaves behind when it is killed: atomic writes' temporaries, the tables of a
run that had not finished (fleet_sim.analysis.tables) and a study run's folder of them."""


def clean_temporaries(folder: Path, patterns: tuple[str, ...] = TEMPORARY_PATTERNS) -> int:
    """Remove temporaries a killed process left anywhere under `folder` (called by the
    process that holds the folder, at its start); returns how many."""
    removed = 0
    if not folder.is_dir():
        return 0
    for pattern in patterns:
        for item in folder.rglob(pattern):
            with contextlib.suppress(OSError):
                if item.is_dir():
                    shutil.rmtree(item)
                else:
                    item.unlink()
                removed += 1
    return removed


def check_out_dir(out: Path, argument: str, element: str = "out") -> None:
    """Refuse, before any work, a run or results directory that cannot be written: an existing
    file in its place, or a place where it cannot be made or written (tried: the directory is
    made and a probe file written and removed)."""
    if out.exists() and not out.is_dir():
        raise InputError(argument, element, str(out), "a directory (or a new path), not a file")
    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as exc:
        raise InputError(argument, element, str(out),
                         f"a writable directory ({exc.strerror or exc})") from None
