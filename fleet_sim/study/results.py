"""The results of many runs: the summary (one row per run), the statistics per design point
and the DuckDB database over both and every run's tables; what report and export read.

Files in a results folder::

    summary.parquet            one row per run: status, factors, replication, seed, every KPI
    stats.parquet              per design point: mean and 95 % CI of every KPI (analysis.stats)
    sweep.duckdb               DuckDB: table summary, stats; views orders, events, node_waits
                               over every run's Parquet files (with run_id)

The choices where the issues were silent: docs/background/decisions/analysis-and-studies.md.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Any

import pandas as pd

from fleet_sim.config.experiment import BASE_VARIANT, Experiment
from fleet_sim.study.progress import Progress
from fleet_sim.study.run_folder import CRASHED, DAMAGED, FAILED, MANIFEST, OK, run_problem
from fleet_sim.study.study_folder import SweepError
from userfiles.writing import atomic_path, fsync_path, temp_path


@contextmanager
def tables_written(experiment: Experiment, out_dir: Path,
                   columns: Sequence[str] | None = None, stream: IO[str] | None = None,
                   quiet: bool = False) -> Iterator[PlannedRuns]:
    """Write the summary tables when the block ends, also when an exception (Ctrl-C, a run
    function that fails to report) ends it, so the tables keep up with the runs finished;
    then account for every run the block planned (why: the decisions of this module, in
    docs/background/decisions/analysis-and-studies.md): a line on `stream` (unless `quiet`)
    when each is in the summary, else SweepError naming those that are not. `columns`: what
    sets a run apart (default: the experiment's factors)."""
    planned = PlannedRuns()
    try:
        yield planned
    except BaseException:
        with contextlib.suppress(Exception):  # the exception that ended the block matters more
            write_tables(experiment, out_dir, columns)
        raise
    summary = write_tables(experiment, out_dir, columns)
    verdict = planned.account(summary, out_dir)
    if verdict:
        Progress(stream=stream, quiet=quiet).note(verdict)


MAX_NAMED = 10
"""How many runs missing from a summary its error names (then how many more)."""


class PlannedRuns:
    """The runs a study asked for, in the order it asked, and the one check that each is in
    the summary it wrote (`account`)."""

    def __init__(self) -> None:
        self.run_ids: dict[str, None] = {}

    def add(self, run_ids: Iterable[str]) -> None:
        self.run_ids.update(dict.fromkeys(run_ids))

    def account(self, summary: pd.DataFrame, out_dir: Path) -> str:
        """The line that says every planned run is in `summary`, finished or failed with its
        reason ("" when none was planned); SweepError naming each that is not."""
        rows: dict[str, tuple[str, str]] = {}
        if len(summary):
            errors = summary["error"] if "error" in summary.columns \
                else pd.Series([None] * len(summary), index=summary.index)
            rows = {str(run): (str(status), "" if pd.isna(error) else str(error))
                    for run, status, error in zip(summary["run_id"], summary["status"],
                                                  errors, strict=True)}
        finished = failed = 0
        missing: list[str] = []
        for run_id in self.run_ids:
            status, error = rows.get(run_id, ("", ""))
            if status == OK:
                finished += 1
            elif status in (FAILED, CRASHED) and error.strip():
                failed += 1
            elif not status:
                missing.append(f"{run_id} (no row)")
            else:
                missing.append(f"{run_id} ({status}{'' if error.strip() else ', no reason'})")
        total = len(self.run_ids)
        if missing:
            named = ", ".join(missing[:MAX_NAMED]) + (
                f" and {len(missing) - MAX_NAMED} more" if len(missing) > MAX_NAMED else "")
            raise SweepError(
                f"{out_dir / 'summary.parquet'}: {len(missing)} of the {total} planned runs "
                f"{'is' if len(missing) == 1 else 'are'} not in the summary as finished or "
                f"failed with a reason: {named}; the tables and every run folder are kept, "
                "run the study again to make or read them again")
        if not total:
            return ""
        counts = f"{finished} finished" + (f", {failed} failed" if failed else "")
        if total == 1:
            return f"the one planned run is in the summary ({counts})"
        return f"all {total} planned runs are in the summary ({counts})"



# ---- tables --------------------------------------------------------------------------------


RunStatus = tuple[str, str | None, float | None]
"""A run folder's status (ok, damaged, failed, crashed, incomplete), its error text (None for
a run not yet finished) and, for a failed run, the wall time error.json records."""


def run_status(run_dir: Path) -> RunStatus:
    """The status of one run folder: a finished run only if it checks out (`run_problem`,
    which reads its files once)."""
    if (run_dir / "kpis.json").exists() or (run_dir / MANIFEST).exists():
        problem = run_problem(run_dir)
        if problem is None:
            return OK, "", None
        return DAMAGED, f"{problem}; run the study again to make this run again", None
    if (run_dir / "error.json").exists():
        try:
            error = json.loads((run_dir / "error.json").read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError):
            return FAILED, "error.json cannot be read", None
        return str(error.get("status", FAILED)), str(error.get("error", "")), \
            error.get("wall_s")
    return "incomplete", None, None


def collect_summary(out_dir: Path, factor_names: Sequence[str],
                    variant_column: bool = False,
                    statuses: Mapping[str, RunStatus] | None = None) -> pd.DataFrame:
    """One row per run folder: status, (variant,) factors, replication, seed, KPIs, runtime,
    error. `variant`: the run's variant (BASE_VARIANT for the base scenario's runs), when
    `variant_column` or any run belongs to a named variant. `statuses`: each folder's
    `run_status`, where the caller has them already (else they are found here)."""
    rows: list[dict[str, Any]] = []
    runs_dir = out_dir / "runs"
    for run_dir in sorted(p for p in runs_dir.iterdir() if p.is_dir()) if runs_dir.exists() \
            else []:
        spec_file = run_dir / "spec.json"
        if not spec_file.exists():
            continue
        spec = json.loads(spec_file.read_text(encoding="utf-8"))
        row: dict[str, Any] = {"run_id": spec["run_id"], "status": "incomplete",
                               "replication": spec["replication"], "seed": spec["seed"]}
        if "variant" in spec or variant_column:
            row["variant"] = spec.get("variant") or BASE_VARIANT
        for name in factor_names:
            row[name] = spec["factors"].get(name)
        status, error, wall_s = statuses[run_dir.name] if statuses is not None \
            and run_dir.name in statuses else run_status(run_dir)
        row["status"] = status
        if status == OK:
            figures = json.loads((run_dir / "kpis.json").read_text(encoding="utf-8"))
            for key, value in figures.items():
                if isinstance(value, dict):  # errors_by_code -> errors_by_code.E_101, ...
                    row.update({f"{key}.{k}": v for k, v in value.items()})
                elif isinstance(value, list):  # setup_warnings: one line each
                    row[key] = "\n".join(str(v) for v in value)
                elif key not in row:
                    row[key] = value
        if error is not None:
            row["error"] = error
        if wall_s is not None:
            row["wall_s"] = wall_s
        rows.append(row)
    frame = pd.DataFrame(rows)
    if "variant" in frame.columns:  # the base scenario's runs keep the spec.json they had
        frame["variant"] = frame["variant"].fillna(BASE_VARIANT)
    counts = [c for c in frame.columns if c.startswith(("errors_by_code.", "warnings_by_code."))]
    frame[counts] = frame[counts].fillna(0)  # a code a run never raised: zero times
    if frame.empty:
        return pd.DataFrame({"run_id": pd.Series(dtype="string"),
                             "status": pd.Series(dtype="string")})
    for column in frame.columns:
        if frame[column].dtype == object:
            values = frame[column].dropna()
            if len(values) and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                   for v in values):
                frame[column] = pd.to_numeric(frame[column])
            elif len(values) and all(isinstance(v, str) for v in values):
                frame[column] = frame[column].astype("string")
    return frame


def run_statuses(out_dir: Path) -> dict[str, RunStatus]:
    """Per run folder (with spec.json): its `run_status`."""
    runs_dir = out_dir / "runs"
    return {run_dir.name: run_status(run_dir)
            for run_dir in (runs_dir.iterdir() if runs_dir.exists() else [])
            if (run_dir / "spec.json").exists()}


def read_summary(out_dir: Path, factor_names: Sequence[str]) -> tuple[pd.DataFrame, bool]:
    """The results folder's summary and whether it had to be rebuilt: summary.parquet if its
    runs and their statuses are those of the run folders, else one collected from them."""
    summary_file = out_dir / "summary.parquet"
    statuses = run_statuses(out_dir)
    if summary_file.exists():
        summary = pd.read_parquet(summary_file)
        if {"run_id", "status"} <= set(summary.columns):
            recorded = dict(zip(summary["run_id"].astype(str), summary["status"].astype(str),
                                strict=True))
            if len(recorded) == len(summary) \
                    and recorded == {run: s[0] for run, s in statuses.items()}:
                return summary, False
    return collect_summary(out_dir, factor_names, statuses=statuses), True


def write_tables(experiment: Experiment, out_dir: Path,
                 columns: Sequence[str] | None = None) -> pd.DataFrame:
    """summary.parquet, stats.parquet and sweep.duckdb from the run folders on disk (with a
    `variant` column, and statistics per variant, when the folder holds a comparison).
    `columns`: what sets a run apart (default: the experiment's factors; a design search's
    decisions)."""
    from fleet_sim.analysis.stats import point_stats

    names = list(experiment.factor_names if columns is None else columns)
    summary = collect_summary(out_dir, names)
    with atomic_path(out_dir / "summary.parquet") as tmp:
        summary.to_parquet(tmp, index=False)
    by = ["variant", *names] if "variant" in summary.columns else names
    stats = point_stats(summary, by)
    with atomic_path(out_dir / "stats.parquet") as tmp:
        stats.to_parquet(tmp, index=False)
    write_duckdb(out_dir)
    return summary


def write_duckdb(out_dir: Path) -> Path:
    """sweep.duckdb: tables summary and stats, views over every run's Parquet tables."""
    import duckdb

    db_path = out_dir / "sweep.duckdb"
    tmp = temp_path(db_path)
    tmp.unlink(missing_ok=True)
    runs = (out_dir / "runs").resolve()
    try:
        con = duckdb.connect(str(tmp))
    except duckdb.Error as exc:
        raise _as_os_error(exc, db_path) from None
    try:
        for table in ("summary", "stats"):
            source = (out_dir / f"{table}.parquet").resolve()
            if source.exists():
                con.execute(f"CREATE TABLE {table} AS SELECT * FROM read_parquet('{_sql(source)}')")
        for view in ("orders", "events", "node_waits"):
            query = runs_table_sql(runs, view)
            if query is not None:
                con.execute(f"CREATE VIEW {view} AS {query}")
        # everything into the database file itself: the write-ahead log is deleted on close,
        # and a disk too full for the checkpoint must fail here, not leave an empty database
        con.execute("CHECKPOINT")
    except BaseException as exc:
        with contextlib.suppress(Exception):
            con.close()
        tmp.unlink(missing_ok=True)
        tmp.with_name(tmp.name + ".wal").unlink(missing_ok=True)
        if isinstance(exc, duckdb.Error):
            raise _as_os_error(exc, db_path) from None
        raise
    con.close()
    wal = tmp.with_name(tmp.name + ".wal")
    if wal.exists() and wal.stat().st_size:
        tmp.unlink(missing_ok=True)
        wal.unlink(missing_ok=True)
        raise OSError(errno.EIO, "DuckDB could not write its tables into the database file",
                      str(db_path))
    wal.unlink(missing_ok=True)
    fsync_path(tmp)
    os.replace(tmp, db_path)
    return db_path


def _as_os_error(exc: Exception, path: Path) -> OSError:
    """DuckDB's error for a file it cannot write, as the OSError it stands for (DuckDB raises
    its own exception types, with the system's message in the text)."""
    text = str(exc)
    for code in (errno.ENOSPC, errno.EROFS, errno.EACCES, errno.EDQUOT):
        if os.strerror(code) in text:
            return OSError(code, os.strerror(code), str(path))
    return OSError(errno.EIO, f"DuckDB could not write the database ({text.splitlines()[0]})",
                   str(path))


def runs_table_sql(runs_dir: Path, name: str, row_numbers: bool = False) -> str | None:
    """DuckDB SQL for table `name` of every run under `runs_dir`, with its `run_id` first
    (and `file_row_number`, the row's place in its file, with `row_numbers`); None when no run
    has it. The one reader of the runs' tables side by side (sweep.duckdb's views, export,
    the report): a run folder is named `factor=level__r00`, which DuckDB would otherwise
    read as a Hive partition and add as a column holding 'level__r00'."""
    if not any(runs_dir.glob(f"*/{name}.parquet")):
        return None
    pattern = _sql(runs_dir.resolve() / "*" / f"{name}.parquet")
    numbers = ", file_row_number = true" if row_numbers else ""
    return (f"SELECT regexp_extract(filename, '([^/]+)/{name}.parquet$', 1) AS run_id, "
            f"* EXCLUDE (filename) FROM read_parquet('{pattern}', filename = true{numbers}, "
            "union_by_name = true, hive_partitioning = false)")


def _sql(path: Path) -> str:
    return str(path).replace("'", "''")

