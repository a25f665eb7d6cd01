"""What the `fleet-sim` commands print when they finish: each result as lines of text.

The command line (fleet_sim.cli) only parses arguments, calls the layer that does the work and
prints what this module makes of the result; the wording of every summary lives here, beside
the other ways results are shown (reports, workbooks, the replay page).

Each function returns its text rather than printing it, so tests and other front ends use
the same words.

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from fleet_sim.config.decisions import DesignSpace
    from fleet_sim.config.experiment import Experiment
    from fleet_sim.config.layout import Layout
    from fleet_sim.config.layout_spec import LayoutSpec
    from fleet_sim.config.standards.factsheet_profile import ImportedProfile
    from fleet_sim.config.standards.lif_import import Imported as ImportedLif
    from fleet_sim.report.export import Exported
    from fleet_sim.study.optimise import OptimiseOutcome
    from fleet_sim.study.runner import SweepOutcome
    from fleet_sim.study.sizing import GroupResult as SizingResult

MAX_WARNINGS = 4
"""Target intervals too wide to decide that a sweep names at its end (the rest: the report)."""


def megabytes(path: Path) -> str:
    return f"{path.stat().st_size / 1e6:.1f} MB"


def run_lines(figures: dict[str, Any], out: Path, wall_s: float, sim_events: int) -> str:
    """The KPIs of one run and where its directory is."""
    from fleet_sim.analysis.run_summary import summary_text

    return (f"{summary_text(figures)}\n"
            f"  run directory               {out}  ({wall_s:.1f} s wall, {sim_events:,} events)")


def replay_line(page: Path) -> str:
    """The replay page written at the end of `run --replay`."""
    return f"  replay                      {page}  ({megabytes(page)})"


def sweep_header(experiment: Experiment, runs: int, workers: int, scheduler: str | None) -> str:
    where = f"Dask cluster {scheduler}" if scheduler else \
        f"{workers or 'one per core'} worker processes"
    return (f"sweep {experiment.name}: {len(experiment.points)} design points x "
            f"{experiment.spec.replications} replications = {runs} runs on {where}")


def sweep_lines(experiment: Experiment, outcome: SweepOutcome, out: Path) -> str:
    """What a sweep made, what failed, targets it could not decide, and its tables."""
    import pandas as pd

    from fleet_sim.analysis.stats import check_targets

    summary = pd.read_parquet(out / "summary.parquet")
    done = int((summary["status"] == "ok").sum()) if len(summary) else 0
    lines = [f"  {len(outcome.results)} runs made, {outcome.skipped} already finished; "
             f"{done} finished in all, {len(outcome.failed)} failed in this sweep"]
    lines += [f"  failed: {failure.run_id} ({failure.status}): {failure.error}"
              for failure in outcome.failed]
    lines += stall_lines(summary)
    warnings = [w for w in (c.warning() for c in check_targets(
        summary, experiment.factor_names, experiment.spec.targets)) if w]
    lines += [f"  warning: {warning}" for warning in warnings[:MAX_WARNINGS]]
    if len(warnings) > MAX_WARNINGS:
        lines.append(f"  ... and {len(warnings) - MAX_WARNINGS} more intervals too wide to "
                     "decide (all in the report); `fleet-sim size` adds replications where it "
                     "matters")
    lines += [f"  summary      {out / 'summary.parquet'}  (one row per run)",
              f"  statistics   {out / 'stats.parquet'}  (mean and 95 % CI per design point)",
              f"  SQL          {out / 'sweep.duckdb'}  (tables summary, stats; views orders, "
              "events, node_waits)"]
    table = kpi_table(summary, experiment.factor_names,
                      [t.kpi for t in experiment.spec.targets])
    return "\n".join([*lines, *table])


TABLE_KPIS = ("throughput_per_hour", "lead_time_p95_s")
"""The KPIs of the table that ends a sweep when the experiment has no targets."""


def kpi_table(summary: Any, factor_names: Sequence[str], target_kpis: Sequence[str]) -> list[str]:
    """The lines of a short table, one row per design point: the mean and 95 % interval of the
    targets' KPIs (without targets: throughput and p95 lead time), named with their units from
    the KPI catalogue, and a note where runs locked solid (gridlock), were starved of charging,
    stood out of service or left orders open."""
    import pandas as pd

    from fleet_sim.analysis.kpis import gridlocked, kpi_label, out_of_service, starved
    from fleet_sim.analysis.paired import number_text
    from fleet_sim.analysis.stats import mean_ci
    from fleet_sim.config.experiment import level_text

    if not len(summary) or "status" not in summary.columns:
        return []
    kpis = [k for k in dict.fromkeys(target_kpis or TABLE_KPIS) if k in summary.columns]
    factors = [f for f in factor_names if f in summary.columns]
    header = [*factors, "runs", *(kpi_label(k) for k in kpis), "note"]
    rows: list[list[str]] = []
    groups = summary.groupby(factors, sort=True, dropna=False) if factors \
        else [((), summary)]
    for key, group in groups:
        values = key if isinstance(key, tuple) else (key,)
        ok = group[group["status"] == "ok"]
        cells = [level_text(v) for v in values] + [str(len(ok))]
        for kpi in kpis:
            ci = mean_ci(pd.to_numeric(ok[kpi], errors="coerce").to_numpy(dtype=float))
            cells.append("n/a" if ci.n == 0 else number_text(ci.mean) if ci.n == 1 else
                         f"{number_text(ci.mean)} ± {number_text(ci.half_width)}")
        notes = []
        records = ok.to_dict("records")
        locked = sum(gridlocked(row) for row in records)
        if locked:
            notes.append(f"GRIDLOCK in {locked} of {len(ok)} runs")
        starving = [row for row in records if starved(row)]
        if starving:
            hours = sum(float(row["charging_starvation_h"]) for row in starving) / len(starving)
            notes.append(f"charging starvation in {len(starving)} of {len(ok)} runs "
                         f"({hours:.2f} h each, mean)")
        down = sum(out_of_service(row) for row in records)
        if down:
            notes.append(f"out of service in {down} of {len(ok)} runs")
        if "orders_open_at_end" in ok.columns:
            open_orders = pd.to_numeric(ok["orders_open_at_end"], errors="coerce").fillna(0)
            if (open_orders > 0).any():
                notes.append(f"{open_orders.mean():.1f} orders open at the end (mean)")
        if len(ok) < len(group):
            failed = len(group) - len(ok)
            notes.append(f"{failed} run{'s' if failed > 1 else ''} failed")
        rows.append([*cells, "; ".join(notes)])
    if not any(row[-1] for row in rows):
        header, rows = header[:-1], [row[:-1] for row in rows]
    widths = [max(len(h), *(len(r[i]) for r in rows)) for i, h in enumerate(header)]
    numeric = range(len(factors), len(header) - (1 if header[-1] == "note" else 0))
    def line(cells: Sequence[str]) -> str:
        return "  " + "  ".join(c.rjust(w) if i in numeric else c.ljust(w)
                                for i, (c, w) in enumerate(zip(cells, widths, strict=True))
                                ).rstrip()
    title = "KPIs per design point: mean ± half-width of the 95 % interval over the runs"
    return ["", f"  {title}", line(header), *(line(r) for r in rows)]


def size_header(experiment: Experiment) -> str:
    return (f"size {experiment.name}: targets "
            + ", ".join(t.describe() for t in experiment.spec.targets))


def size_lines(results: Sequence[SizingResult], out: Path) -> str:
    """Per search: the analytic estimate and the simulation's answer; where sizing.json is."""
    lines: list[str] = []
    for result in results:
        est = result.estimate
        lines.append(
            f"  analytic estimate: {est.agvs:.2f} AGVs at the mean demand, "
            f"{est.agvs_at_peak:.2f} at the peak ({est.cycle_s:.1f} s per order: "
            f"{est.empty_travel_s:.1f} s empty + {est.loaded_travel_s:.1f} s loaded travel + "
            f"{est.handling_s:.1f} s handling; {est.demand_per_hour:.1f} orders/h)")
        lines.append(f"  simulation: {result.statement()}")
    if (out / "summary.parquet").is_file():
        import pandas as pd

        lines += stall_lines(pd.read_parquet(out / "summary.parquet"))
    lines.append(f"  sizing       {out / 'sizing.json'}")
    return "\n".join(lines)


def optimise_header(experiment: Experiment, space: DesignSpace) -> str:
    config = space.config
    decisions = [*config.decisions, *config.layout_decisions]
    return (f"optimise {experiment.name}: {len(space.designs)} designs over "
            f"{', '.join(decisions)}; targets "
            + ", ".join(t.describe() for t in experiment.spec.targets)
            + f"; {100 * config.confidence:g} % confidence")


def optimise_lines(outcome: OptimiseOutcome, wall_s: float) -> str:
    """The answer in one paragraph, the runs used against the full grid, where the files
    are."""
    doc = outcome.document
    lines = textwrap.wrap(outcome.statement, width=96, initial_indent="  ",
                          subsequent_indent="  ")
    reps = doc["answer"]["replications"] if doc["answer"] else \
        doc["procedure"]["min_replications"]
    lines.append(f"  runs: {doc['runs_used']} used ({outcome.runs_made} made or reused now, "
                 f"{len(outcome.runs_failed)} failed) against {doc['full_grid_runs']} for the "
                 f"full grid of {doc['procedure']['designs_counted']} designs at "
                 f"{reps} replications; {doc['designs_examined']} designs examined; {wall_s:.0f} s")
    if doc["assumption"]["more_agvs_never_worse"]:
        held = "held" if doc["assumption"]["held"] else "DID NOT HOLD"
        lines.append(f"  assumption more_agvs_never_worse: {held} on the designs next to the "
                     "answer")
    for row in doc["target_costs"]:
        if row["price"] is not None and row["saving"]:
            lines.append(f"  {row['kpi']} relaxed to {row['relaxed_to']:g}: "
                         f"{row['design']} would do, saving {row['saving']:,.0f} "
                         f"{doc['currency']}")
    lines.append(f"  optimise     {outcome.out_dir / 'optimise.json'}  (`fleet-sim report "
                 f"{outcome.out_dir}` for the report)")
    return "\n".join(lines)


def stall_lines(summary: Any) -> list[str]:
    """The lines of a sweep or sizing search whose runs locked solid (gridlock), were starved
    of charging or stood out of service, each with its advice (none if no run did)."""
    from fleet_sim.report.stalls import stall_statements

    return [f"  {statement}" for statement in stall_statements(summary)] if len(summary) \
        else []


def report_lines(html: Path, pdf: Path | None) -> str:
    lines = [f"report: {html.resolve()}"]
    if pdf is not None:
        lines.append(f"        {pdf.resolve()}")
    return "\n".join(lines)


def export_lines(written: Sequence[Exported]) -> str:
    return "\n".join(f"{item.table:8s} {item.rows:>10,} rows  {item.path}" for item in written)


def layout_lines(file: Path, layout: Layout) -> str:
    """What `fleet-sim layout` found in a valid layout."""
    kinds: dict[str, int] = {}
    for _, data in layout.graph.nodes(data=True):
        kinds[data["kind"]] = kinds.get(data["kind"], 0) + 1
    return "\n".join([
        f"{file}: layout {layout.name!r} is valid",
        f"  nodes        {layout.graph.number_of_nodes()} "
        f"({', '.join(f'{n} {k}' for k, n in sorted(kinds.items()))})",
        f"  segments     {layout.graph.number_of_edges()} directed, "
        f"{layout.total_length_m:.0f} m of track, {len(layout.corridors)} two-way corridors",
        f"  stations     {len(layout.pickups)} pickup, {len(layout.dropoffs)} drop-off",
        f"  chargers     {len(layout.chargers)}",
        f"  parking      {len(layout.parking)} areas, "
        f"{sum(p.capacity for p in layout.parking)} AGVs"])


def lif_import_lines(file: Path, out: Path, imported: ImportedLif) -> str:
    spec: LayoutSpec = imported.spec
    lines = [
        f"{file}: LIF {imported.lif_version} layout {imported.layout_id!r}, vehicle type "
        f"{imported.vehicle_type!r} -> {out}",
        f"  nodes        {len(spec.nodes)}",
        f"  segments     {len(spec.segments)} "
        f"({sum(s.direction == 'two_way' for s in spec.segments)} two-way)",
        f"  places       {len(spec.stations)} stations, {len(spec.chargers)} chargers, "
        f"{len(spec.parking)} parking"]
    lines += [f"  {'read as ' if note.kept else 'not kept'}     {note.line()}"
              for note in imported.notes]
    return "\n".join(lines)


def lif_export_lines(file: Path, lif: Path, layout_name: str, data: dict[str, Any],
                     timestamp_given: bool) -> str:
    lif_layout = data["layouts"][0]
    return "\n".join([
        f"{file}: layout {layout_name!r} -> {lif} (LIF "
        f"{data['metaInformation']['lifVersion']})",
        f"  nodes        {len(lif_layout['nodes'])}",
        f"  edges        {len(lif_layout['edges'])} (a two-way segment is two edges)",
        f"  stations     {len(lif_layout['stations'])} (pickup, drop-off, chargers, parking)",
        f"  exported at  {data['metaInformation']['exportTimestamp']}"
        + ("" if timestamp_given else " (--timestamp now for the current time)"),
        "  fleetSim     handling times, charger power, parking capacity, markers, Wi-Fi, "
        "zones and explicit lengths are in the extension key fleetSim"])


def profile_import_lines(file: Path, out: Path, imported: ImportedProfile) -> str:
    lines = [f"{file}: {imported.title} -> {out} (profile {out.stem!r})",
             "  from the factsheet   top speed, acceleration, deceleration, length",
             f"  from {imported.base:<15} turn speed, battery, link (assumed for this vehicle)"]
    lines += [f"  not used             {line}" for line in imported.not_used]
    return "\n".join(lines)
