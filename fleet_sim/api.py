"""The Python API: the `fleet-sim` commands `run`, `sweep`, `size`, `compare` and `optimise` as
functions, for notebooks and scripts.

```python
import fleet_sim

result = fleet_sim.run("experiments/tiny_loop.yaml", agvs=3, hours=2)
result.kpis["throughput_per_hour"]      # every KPI of kpis.json, as a dict
result.orders.head()                    # the orders table, a pandas DataFrame
```

Each function takes a file path or an already loaded object (a `Scenario` of
`fleet_sim.config.scenario`, an `Experiment` of `fleet_sim.config.experiment`) and the
command's overrides as keyword arguments, and returns a result object: KPIs as dicts, tables as
pandas DataFrames, the files written as paths. Bad input raises `InputError` with the message
the command prints (`fleet-sim: error: ...` without the prefix).

The choices where the issues were silent: docs/background/decisions/analysis-and-studies.md.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pandas as pd

from fleet_sim.config.experiment import Experiment
from fleet_sim.config.scenario import Scenario
from fleet_sim.errors import InputError
from userfiles.writing import check_out_dir

if TYPE_CHECKING:
    from fleet_sim.config.layout import Layout
    from fleet_sim.sim.engine import RunOutput
    from fleet_sim.study.compare import CompareOutcome
    from fleet_sim.study.optimise import OptimiseOutcome
    from fleet_sim.study.runner import SweepOutcome
    from fleet_sim.study.sizing import GroupResult

__all__ = ["CompareResult", "InputError", "OptimiseResult", "RunResult", "SizeResult",
           "StudyResult", "SweepResult", "compare", "optimise", "run", "size", "sweep"]

PathLike = str | os.PathLike[str]
Settings = Mapping[str, object] | Sequence[tuple[str, object]] | None
"""`set=`: dotted scenario field -> value (``{"demand.rate_per_hour": 60}``), or the
command's list of (field, value) pairs."""
Agvs = int | Mapping[str, int] | None
"""`agvs=`: a fleet size, or a mixed fleet's counts of some of its types (``{"heavy": 3}``)."""

SET = "--set"
DASK_TIMEOUT_S = 120.0


# --- results ----------------------------------------------------------------------------------

@dataclass(frozen=True)
class RunResult:
    """One run: its KPIs and tables (what the run directory holds)."""

    scenario: Scenario
    """The scenario as run, overrides applied."""
    kpis: dict[str, Any]
    """Every run field and KPI, as kpis.json holds them (docs/reference/kpi-catalogue.md)."""
    orders: pd.DataFrame
    """One row per order with its timestamps (orders.parquet)."""
    events: pd.DataFrame
    """One row per state transition and incident (events.parquet)."""
    soc: pd.DataFrame
    """Battery state of charge samples (soc.parquet)."""
    run_dir: Path | None
    """The run directory (`out`), or None: the run was made in a temporary one."""
    replay_page: Path | None
    """replay.html with `replay=True`, else None."""
    wall_s: float
    """How long the simulation took."""
    sim_events: int
    """SimPy events simulated."""
    warnings: tuple[str, ...]
    """Setup warnings: battery and charging traps of the settings (the run goes on)."""


@dataclass(frozen=True)
class StudyResult:
    """What every study (sweep, size, compare, optimise) writes into its results folder."""

    experiment: Experiment
    """The experiment as run (settings applied)."""
    out: Path
    """The results folder."""
    summary: pd.DataFrame
    """One row per run: status, factors, replication, seed, every KPI (summary.parquet)."""
    stats: pd.DataFrame
    """Per design point: mean and 95 % confidence interval of every KPI (stats.parquet)."""
    warnings: tuple[str, ...]
    """Setup warnings of the design points, each kind once."""

    @property
    def database(self) -> Path:
        """sweep.duckdb: the summary, the statistics and every run's tables for DuckDB."""
        return self.out / "sweep.duckdb"


@dataclass(frozen=True)
class SweepResult(StudyResult):
    """Every run of an experiment's design."""

    outcome: SweepOutcome
    """The runner's account: runs made, skipped (already finished), failed."""

    @property
    def failed(self) -> list[str]:
        """The run ids of the runs that failed (each has an error.json in its folder)."""
        return [r.run_id for r in self.outcome.failed]


@dataclass(frozen=True)
class SizeResult(StudyResult):
    """The smallest fleet that meets the targets, for every combination of the other factors."""

    groups: list[GroupResult]
    """One search per combination of the factors other than the fleet's."""
    document: dict[str, Any]
    """sizing.json."""

    @property
    def recommended(self) -> int | None:
        """The smallest fleet that meets the targets (None: none within the search's limits),
        for an experiment whose only factor is the fleet."""
        if len(self.groups) != 1:
            raise ValueError(f"{len(self.groups)} searches (one per combination of the other "
                             "factors): read each group's `recommended`")
        return self.groups[0].recommended

    @property
    def statements(self) -> list[str]:
        """Each search's answer in a planner's words, with its confidence."""
        return [g.statement() for g in self.groups]


@dataclass(frozen=True)
class CompareResult(StudyResult):
    """Every variant against the baseline, with common random numbers."""

    outcome: CompareOutcome
    document: dict[str, Any]
    """compare.json."""
    comparisons: pd.DataFrame
    """One row per variant, design point and KPI: the paired difference, its interval and the
    verdict."""

    @property
    def statements(self) -> list[str]:
        """The selection of the best variant at each design point, in words."""
        return [s.statement() for s in self.outcome.selections]


@dataclass(frozen=True)
class OptimiseResult(StudyResult):
    """The cheapest design that meets the targets, with a guarantee."""

    outcome: OptimiseOutcome
    document: dict[str, Any]
    """optimise.json."""
    designs: pd.DataFrame
    """One row per design: label, price, verdict, replications."""

    @property
    def answer(self) -> dict[str, Any] | None:
        """The cheapest design that meets the targets (its choices, price, target values), or
        None."""
        answer: dict[str, Any] | None = self.document["answer"]
        return answer

    @property
    def statement(self) -> str:
        """The answer in words, with its guarantee."""
        return self.outcome.statement


# --- run --------------------------------------------------------------------------------------

def run(scenario: PathLike | Scenario, *, agvs: Agvs = None, hours: float | None = None,
        seed: int | None = None, set: Settings = None, out: PathLike | None = None,
        replay: bool = False, progress: bool = False) -> RunResult:
    """Run one scenario (`fleet-sim run`).

    Args:
        scenario: a scenario file, or a loaded `Scenario`.
        agvs: fleet size (overrides fleet.size); a mixed fleet: a mapping of some of its types
            to their counts.
        hours: run length in hours (overrides duration_h).
        seed: random seed (overrides seed).
        set: scenario fields to set, dotted path -> value (`--set`), applied before `agvs`,
            `hours` and `seed`.
        out: the run directory to write and keep; None: a temporary one, removed.
        replay: also record every AGV's motion and write replay.html (needs `out`).
        progress: show the progress display on stderr.

    Raises:
        InputError: bad input, with the command's message.
    """
    from fleet_sim.analysis.tables import read_tables
    from fleet_sim.config.scenario import load_layout_for, setup_warnings

    loaded, file = _scenario(scenario, _settings(set), agvs, hours, seed)
    check_replay(loaded, file, replay)
    if replay and out is None:
        raise InputError("--replay", "", True, "a run directory (out=...) to write "
                         "replay.html into")
    layout = load_layout_for(loaded, file)
    if out is not None:
        check_out_dir(Path(out), "--out")
    with _run_dir(out) as run_dir:
        output, kpis = simulate_into(loaded, layout, run_dir, replay=replay, quiet=not progress)
        tables = read_tables(run_dir)
    page = None
    if replay:
        from fleet_sim.report.replay import write_replay

        page = write_replay(run_dir)
    return RunResult(loaded, kpis, tables.orders, tables.events, tables.soc,
                     None if out is None else run_dir, page, output.wall_s, output.sim_events,
                     tuple(w.text for w in setup_warnings(loaded, layout)))


def check_replay(scenario: Scenario, file: str, replay: bool) -> None:
    """A replay needs the closed-form motion (`run`, `fleet-sim run --replay`)."""
    if replay and scenario.motion != "closed_form":
        raise InputError(file, "motion", scenario.motion,
                         "closed_form with --replay: a replay draws the closed-form speed "
                         "profile; with SUMO moving the AGVs their positions between nodes are "
                         "not recorded")


def simulate_into(scenario: Scenario, layout: Layout, run_dir: Path, *, replay: bool,
                  quiet: bool) -> tuple[RunOutput, dict[str, Any]]:
    """Simulate `scenario` on `layout` (its order trace read, if it has one), its tables and
    kpis.json streamed into `run_dir`, with the progress display unless `quiet`: the run of
    `run` and of `fleet-sim run`. Returns the run and its KPIs."""
    from fleet_sim.analysis.tables import stream_run
    from fleet_sim.config.trace import load_trace
    from fleet_sim.study.progress import Progress

    trace = []
    if scenario.demand.kind == "trace":
        assert scenario.demand.trace_csv is not None
        trace = load_trace(scenario.path(scenario.demand.trace_csv), layout)
    with Progress(scenario.duration_s, quiet=quiet, plain_lines=4) as bar:
        def simulated(now_s: float, end_s: float) -> None:
            bar.update(now_s, f"simulated {now_s / 3600:.2f} of {end_s / 3600:.2f} h "
                              f"({now_s / end_s:.0%})")

        return stream_run(scenario, layout, run_dir, trace, progress=simulated,
                          record_moves=replay)


@contextmanager
def _run_dir(out: PathLike | None) -> Iterator[Path]:
    if out is not None:
        yield Path(out)
        return
    with tempfile.TemporaryDirectory(prefix="fleet-sim-run-") as where:
        yield Path(where)


# --- the studies ------------------------------------------------------------------------------

def sweep(experiment: PathLike | Experiment, *, out: PathLike, workers: int = 0,
          scheduler: str | None = None, dask_timeout: float = DASK_TIMEOUT_S,
          set: Settings = None, progress: bool = False) -> SweepResult:
    """Run every run of an experiment (`fleet-sim sweep`), resumable: a run finished in `out`
    is not made again.

    Args:
        experiment: an experiment file, or a loaded `Experiment`.
        out: the results folder.
        workers: worker processes (0: one per core).
        scheduler: a Dask cluster's address (tcp://host:8786), or 'local'.
        dask_timeout: with a scheduler, give up when the cluster has had no worker this long.
        set: scenario fields to set in every run, dotted path -> value (`--set`).
        progress: show the progress display on stderr.

    Raises:
        InputError: bad input, with the command's message.
    """
    from fleet_sim.study.sweep import sweep as run_sweep

    loaded = _experiment(experiment, _settings(set))
    folder = Path(out)
    outcome = run_sweep(loaded, folder, workers, scheduler, not progress,
                        dask_timeout_s=dask_timeout)
    return SweepResult(**_study(loaded, folder), outcome=outcome)


def size(experiment: PathLike | Experiment, *, out: PathLike, workers: int = 0,
         scheduler: str | None = None, dask_timeout: float = DASK_TIMEOUT_S,
         set: Settings = None, progress: bool = False) -> SizeResult:
    """The smallest fleet that meets the experiment's targets (`fleet-sim size`); arguments as
    `sweep`'s.

    Raises:
        InputError: bad input, with the command's message.
    """
    from fleet_sim.study.sizing import size_fleet

    loaded = _experiment(experiment, _settings(set))
    folder = Path(out)
    groups = size_fleet(loaded, folder, workers, scheduler, not progress,
                        dask_timeout_s=dask_timeout)
    return SizeResult(**_study(loaded, folder), groups=groups,
                      document=_read_json(folder / "sizing.json"))


def compare(experiment: PathLike | Experiment, *, out: PathLike, workers: int = 0,
            scheduler: str | None = None, dask_timeout: float = DASK_TIMEOUT_S,
            set: Settings = None, max_replications: int | None = None,
            progress: bool = False) -> CompareResult:
    """Every variant against the baseline (`fleet-sim compare`): paired differences with
    common random numbers, replications added until decided, the best variant selected;
    arguments as `sweep`'s, and `max_replications` (default: the file's
    compare.max_replications).

    Raises:
        InputError: bad input, with the command's message.
    """
    from fleet_sim.study.compare import COMPARE_FILE, check_compare
    from fleet_sim.study.compare import compare as run_compare

    loaded = _experiment(experiment, _settings(set))
    check_compare(loaded, max_replications)
    folder = Path(out)
    outcome = run_compare(loaded, folder, workers, scheduler, not progress, max_replications,
                          dask_timeout_s=dask_timeout)
    document = _read_json(folder / COMPARE_FILE)
    return CompareResult(**_study(loaded, folder), outcome=outcome, document=document,
                         comparisons=pd.DataFrame(document["comparisons"]))


def optimise(experiment: PathLike | Experiment, *, out: PathLike, workers: int = 0,
             scheduler: str | None = None, dask_timeout: float = DASK_TIMEOUT_S,
             set: Settings = None, progress: bool = False) -> OptimiseResult:
    """The cheapest design (fleet, chargers, policies, layout changes) that meets the
    experiment's targets, with a guarantee (`fleet-sim optimise`); the experiment needs an
    optimise section; arguments as `sweep`'s.

    Raises:
        InputError: bad input, with the command's message.
    """
    from fleet_sim.config.decisions import design_space
    from fleet_sim.study.optimise import optimise as run_optimise

    loaded = _experiment(experiment, _settings(set))
    space = design_space(loaded)  # refuses a file without an optimise section
    folder = Path(out)
    outcome = run_optimise(loaded, folder, workers, scheduler, not progress,
                           dask_timeout_s=dask_timeout, space=space)
    designs = pd.DataFrame([{k: v for k, v in d.items() if k not in ("check", "targets")}
                            for d in outcome.document["designs"]])
    return OptimiseResult(**_study(loaded, folder), outcome=outcome,
                          document=outcome.document, designs=designs)


def _study(experiment: Experiment, out: Path) -> dict[str, Any]:
    """The fields every study result has, read from the results folder."""
    from fleet_sim.config.experiment import experiment_warnings

    return {"experiment": experiment, "out": out,
            "summary": pd.read_parquet(out / "summary.parquet"),
            "stats": pd.read_parquet(out / "stats.parquet"),
            "warnings": tuple(experiment_warnings(experiment))}


def _read_json(path: Path) -> dict[str, Any]:
    document: dict[str, Any] = json.loads(path.read_text(encoding="utf-8"))
    return document


# --- inputs: files or loaded objects, and the command's overrides -----------------------------

def _settings(given: Settings) -> dict[str, object]:
    if given is None:
        return {}
    return dict(given.items() if isinstance(given, Mapping) else given)


def _experiment(source: PathLike | Experiment, sets: dict[str, object]) -> Experiment:
    """The experiment with the settings in every run, its targets' KPIs checked."""
    from fleet_sim.config.experiment import load_experiment
    from fleet_sim.study.targets import check_targets_known

    if isinstance(source, Experiment):
        experiment = load_experiment(source.file, sets, SET) if sets else source
    else:
        experiment = load_experiment(Path(source), sets, SET)
    check_targets_known(experiment)
    return experiment


def _scenario(source: PathLike | Scenario, sets: dict[str, object], agvs: Agvs,
              hours: float | None, seed: int | None) -> tuple[Scenario, str]:
    """The scenario with the settings, then `agvs`, `hours` and `seed`, and the name its
    errors give it (fleet_sim.config.overrides: which step names which problem, as `fleet-sim
    run` does)."""
    from fleet_sim.config.overrides import load_scenario, scenario_of
    from fleet_sim.config.scenario import resolved

    counts = agvs if agvs is None or isinstance(agvs, int) else dict(agvs)
    if not isinstance(source, Scenario):
        path = Path(source)
        return load_scenario(path, sets, agvs=counts, hours=hours, seed=seed), str(path)
    name = f"<scenario {source.name}>"
    if not sets and agvs is None and hours is None and seed is None:
        return source, name
    return scenario_of(resolved(source), name, source.base_dir, sets, agvs=counts,
                       hours=hours, seed=seed), name
