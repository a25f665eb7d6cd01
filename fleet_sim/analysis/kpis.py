"""The KPIs of a run: the one place that names them, says what they mean, and computes them.

KPIs are computed in memory from what a run recorded (its `Recorder`) and its scenario, the same
way for `fleet-sim run`, every run of a sweep and every run of a sizing search; nothing is read
back from disk. Unless said otherwise a KPI is measured over the window from the end of the
warm-up to the end of the run. `CATALOGUE` lists them with unit and meaning, without running
anything, so that an experiment's targets can be checked before its runs start.

Decisions, where the issue is silent:

* The figures describing the run (`RUN_FIELDS`: scenario, layout, agvs, seed, duration_h,
  warmup_h) head kpis.json but are not KPIs: no target can be set on them.
* `errors_by_code` and `warnings_by_code` are mappings in kpis.json (only the codes that
  happened); a sweep summary flattens them to one column per code (`errors_by_code.E_101`,
  zero where a run never raised it). Those flattened names are KPIs, one per code of
  fleet_sim.model.error_codes (Warning-level codes under warnings_by_code, the others under
  errors_by_code); `kpi_value` reads them from a kpis.json mapping the same way.
* `throughput_pct_of_demand` divides the rounded `throughput_per_hour` by the demand before
  rounding, as the sweep has always done, so the figures of earlier sweeps stay.
* `wall_s` (the run's wall-clock time) is added by the sweep to each run's kpis.json: it is in
  the catalogue so that a summary column can be named in a target, though it is not a result.
* Every float is rounded to 6 decimals (kpis.json stays readable and byte-identical per seed).
* Work conservation: `idle_with_orders_waiting_pct` is the share of AGV time in state Idle while
  at least one order waited unassigned (the fleet manager's queue not empty), from the state
  changes and the queue lengths; `idle_with_orders_waiting_pct_by_reason` splits it by the
  reason the fleet manager recorded (fleet_sim.model.not_dispatched), every reason listed, zero
  included, flattened like errors_by_code (``idle_with_orders_waiting_pct_by_reason
  .waiting_for_charger``). The reasons add up to the total: the fleet manager records one for
  every such moment.
* `setup_warnings` (a run field, not a KPI): the battery and charging traps of the run's
  settings (fleet_sim.config.scenario.setup_warnings), one line each, so that a report can
  show them; a sweep summary joins them with newlines.
* A mixed fleet (`fleet.vehicles`) adds `by_type` last in kpis.json: one mapping whose keys are
  ``<type>.<kpi>`` (`BY_TYPE`: agvs, orders_completed, throughput_per_hour, lead_time_mean_s,
  agv_utilisation_pct, availability_pct, each over the type's AGVs only), so the sweep summary
  flattens it as it does errors_by_code, to ``by_type.heavy.throughput_per_hour``. Type names
  are the scenario's, so these names are not in `CATALOGUE`; `is_kpi_name` accepts them. A
  one-type fleet's kpis.json has no `by_type` (it stays as it was).
* A layout with mutex or same-direction zones adds `zone_wait_s` last: zone id -> AGV-seconds
  spent in the window waiting to enter it (``zone_wait_s.<zone>``, s; also counted in
  blocked_time_pct).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fleet_sim.config.scenario import Scenario, setup_warnings
from fleet_sim.model.error_codes import CODES
from fleet_sim.model.not_dispatched import NOT_DISPATCHED, NOT_DISPATCHED_END, NotDispatched
from fleet_sim.model.records import EventRecord, Order, Recorder
from fleet_sim.model.states import VehicleState
from fleet_sim.sim.engine import RunOutput

DOWN_STATES = (VehicleState.ERROR, VehicleState.MAINTENANCE, VehicleState.SAFE_MODE)
"""States in which an AGV is not available (availability_pct)."""

RUN_FIELDS = ("scenario", "layout", "agvs", "seed", "duration_h", "warmup_h",
              "setup_warnings")
"""What kpis.json says about the run before its KPIs (not KPIs themselves)."""


@dataclass(frozen=True)
class Kpi:
    """One KPI: its key in kpis.json and the sweep summary, its unit, what it measures."""

    name: str
    unit: str
    meaning: str


def _state_kpis() -> tuple[Kpi, ...]:
    return tuple(Kpi(f"state_{s.key}_pct", "%", f"share of AGV time in state {s.value}")
                 for s in VehicleState)


def _code_kpis() -> tuple[Kpi, ...]:
    out = []
    for code, (level, description) in CODES.items():
        family = "warnings_by_code" if level == "Warning" else "errors_by_code"
        out.append(Kpi(f"{family}.{code}", "count", f"{level} {code} ({description}), whole run"))
    return tuple(out)


BY_REASON = "idle_with_orders_waiting_pct_by_reason"


def _reason_kpis() -> tuple[Kpi, ...]:
    return tuple(Kpi(f"{BY_REASON}.{reason.value}", "%",
                     f"share of AGV time Idle with orders waiting because {reason.meaning}")
                 for reason in NotDispatched)


COUNTS_BY_CODE = frozenset(k.name for k in _code_kpis())
"""The per-code KPIs (errors_by_code.E_101, ...): a code a run never raised counts zero."""

CATALOGUE: tuple[Kpi, ...] = (
    Kpi("orders_created", "orders", "orders created over the whole run"),
    Kpi("orders_completed", "orders", "orders delivered over the whole run"),
    Kpi("throughput_per_hour", "orders/h", "orders delivered in the window, per hour"),
    Kpi("lead_time_mean_s", "s", "mean time from creation to delivery of the orders delivered "
        "in the window (none if none was)"),
    Kpi("lead_time_p95_s", "s", "95th percentile of the same lead times"),
    Kpi("agv_utilisation_pct", "%", "share of AGV time busy with an order (assigned to "
        "delivered, or to failed)"),
    Kpi("blocked_time_pct", "%", "share of AGV time spent waiting for a node or corridor held "
        "by another AGV"),
    Kpi("deadlocks_detected", "count", "wait-for cycles found (each also an event)"),
    Kpi("distance_km", "km", "distance driven in the window, all AGVs"),
    Kpi("order_wait_mean_s", "s", "mean time from creation to assignment, orders assigned"),
    Kpi("order_queue_mean", "orders", "time-average number of orders waiting for an AGV"),
    *_state_kpis(),
    Kpi("availability_pct", "%", "share of AGV time not in Error, Maintenance or SafeMode"),
    Kpi("idle_with_orders_waiting_pct", "%", "share of AGV time in state Idle while at least "
        "one order waited unassigned (each such moment has a reason below)"),
    *_reason_kpis(),
    Kpi("orders_failed", "orders", "loaded orders lost with a failed AGV, whole run"),
    Kpi("orders_reassigned", "orders", "times an order went back to the queue, whole run"),
    Kpi("charges", "count", "charging stops, whole run"),
    Kpi("charging_queue_wait_mean_s", "s", "mean time from asking for a charger to getting one "
        "(none if no AGV charged)"),
    Kpi("commands_sent", "count", "commands the fleet manager sent, whole run"),
    Kpi("command_retries", "count", "commands sent again after no answer, whole run"),
    Kpi("obstacle_pauses", "count", "obstacle pauses (RSS-AGV-001 4.2.3), whole run"),
    Kpi("comm_losses", "count", "FMS and internal link losses noticed, whole run"),
    *_code_kpis(),
    Kpi("demand_per_hour", "orders/h", "orders created in the window, per hour"),
    Kpi("throughput_pct_of_demand", "%", "throughput_per_hour over demand_per_hour (none "
        "without demand)"),
    Kpi("orders_open_at_end", "orders", "orders created but not delivered by the end"),
    Kpi("wall_s", "s", "wall-clock time of the run (sweeps only; not a result)"),
)
"""Every KPI a run reports, in the order of kpis.json (per-code ones flattened)."""


BY_TYPE: tuple[Kpi, ...] = (
    Kpi("agvs", "AGVs", "AGVs of the type"),
    Kpi("orders_completed", "orders", "orders the type's AGVs delivered over the whole run"),
    Kpi("throughput_per_hour", "orders/h", "orders the type's AGVs delivered in the window, "
        "per hour"),
    Kpi("lead_time_mean_s", "s", "mean time from creation to delivery of the orders the "
        "type's AGVs delivered in the window (none if none was)"),
    Kpi("agv_utilisation_pct", "%", "share of the type's AGV time busy with an order"),
    Kpi("availability_pct", "%", "share of the type's AGV time not in Error, Maintenance or "
        "SafeMode"),
)
"""The per-type KPIs of a mixed fleet, named ``by_type.<type>.<name>`` (see the module)."""


def is_kpi_name(name: str) -> bool:
    """A KPI of the catalogue, or a per-type one (``by_type.<type>.<name of BY_TYPE>``)."""
    family, _, rest = name.partition(".")
    if family == "by_type":
        kind, _, kpi = rest.rpartition(".")
        return bool(kind) and kpi in {k.name for k in BY_TYPE}
    if family == "zone_wait_s":
        return bool(rest)
    return name in kpi_names()


def kpi_names() -> frozenset[str]:
    """The names a target may use: every KPI of the catalogue."""
    return frozenset(k.name for k in CATALOGUE)


def kpi_value(figures: Mapping[str, Any], name: str) -> Any:
    """KPI `name` from a kpis.json mapping, a flattened per-code name included (zero for a
    code the run never raised); None where the run has no value."""
    family, dot, code = name.partition(".")
    if dot and family == "by_type":
        by_type = figures.get(family)
        return by_type.get(code) if isinstance(by_type, Mapping) else None
    if dot and isinstance(figures.get(family), Mapping):
        return figures[family].get(code, 0)
    return figures.get(name)


# ---- computing them ------------------------------------------------------------------------


def run_kpis(run: RunOutput) -> dict[str, Any]:
    """The KPIs of a finished run (see compute_kpis), with its setup warnings."""
    warnings = [w.text for w in setup_warnings(run.scenario, run.layout)]
    return compute_kpis(run.recorder, run.scenario, run.layout.name, warnings)


def compute_kpis(recorder: Recorder, scenario: Scenario, layout_name: str,
                 warnings: Sequence[str] = ()) -> dict[str, Any]:
    """The run fields and every KPI of the catalogue but wall_s, from the run's records."""
    start, end = scenario.warmup_s, scenario.duration_s
    window_h = (end - start) / 3600.0
    n_agvs = scenario.fleet.size
    agv_s = n_agvs * (end - start)
    orders = recorder.orders
    delivered = [o for o in orders if o.delivered_s is not None]
    lead = np.array([o.delivered_s - o.created_s for o in delivered
                     if o.delivered_s is not None and start <= o.delivered_s <= end],
                    dtype=float)
    waits = np.array([_nan(o.assigned_s) - o.created_s for o in orders], dtype=float)
    states = state_seconds(recorder.events, start, end)
    throughput = _round(len(lead) / window_h)
    out: dict[str, Any] = {
        "scenario": scenario.name,
        "layout": layout_name,
        "agvs": n_agvs,
        "seed": scenario.seed,
        "duration_h": scenario.duration_h,
        "warmup_h": scenario.warmup_h,
        "setup_warnings": list(warnings),
        "orders_created": len(orders),
        "orders_completed": len(delivered),
        "throughput_per_hour": throughput,
        "lead_time_mean_s": _round(float(lead.mean())) if len(lead) else None,
        "lead_time_p95_s": _round(float(np.percentile(lead, 95))) if len(lead) else None,
        "agv_utilisation_pct": _round(100.0 * busy_seconds(orders, start, end) / agv_s),
        "blocked_time_pct": _round(100.0 * recorder.blocked_s / agv_s),
        "deadlocks_detected": recorder.deadlocks,
        "distance_km": _round(recorder.distance_m / 1000.0),
        "order_wait_mean_s": _round(float(np.nanmean(waits)))
        if not np.isnan(waits).all() else None,
        "order_queue_mean": _round(queue_mean(recorder.queue_lengths, start, end)),
    }
    for state in VehicleState:
        out[f"state_{state.key}_pct"] = _round(100.0 * states[state.value] / agv_s)
    down = sum(states[s.value] for s in DOWN_STATES)
    charge_waits = [got - asked for asked, got in recorder.charge_waits]
    errors: dict[str, int] = {}
    for error in recorder.errors:
        errors[error.code] = errors.get(error.code, 0) + 1
    created = sum(1 for o in orders if start <= o.created_s <= end)
    demand = created / window_h
    idle_waiting, by_reason = idle_with_orders_waiting_s(recorder.events, recorder.queue_lengths,
                                                         start, end)
    out.update({
        "availability_pct": _round(100.0 * (1.0 - down / agv_s)),
        "idle_with_orders_waiting_pct": _round(100.0 * idle_waiting / agv_s),
        BY_REASON: {reason.value: _round(100.0 * by_reason[reason] / agv_s)
                    for reason in NotDispatched},
        "orders_failed": sum(1 for o in orders if o.failed_s is not None),
        "orders_reassigned": sum(o.reassigned for o in orders),
        "charges": len(charge_waits),
        "charging_queue_wait_mean_s": _round(float(np.mean(charge_waits))) if charge_waits
        else None,
        "commands_sent": recorder.commands_sent,
        "command_retries": recorder.command_retries,
        "obstacle_pauses": recorder.obstacle_pauses,
        "comm_losses": recorder.comm_losses,
        "errors_by_code": dict(sorted(errors.items())),
        "warnings_by_code": dict(sorted(recorder.warnings.items())),
        "demand_per_hour": _round(demand),
        "throughput_pct_of_demand": _round(100.0 * throughput / demand) if demand > 0 else None,
        "orders_open_at_end": len(orders) - len(delivered),
    })
    if scenario.fleet.vehicles:
        out["by_type"] = by_type_kpis(recorder, scenario)
    if recorder.zone_wait_s:
        out["zone_wait_s"] = {z: _round(s) for z, s in recorder.zone_wait_s.items()}
    return out


def by_type_kpis(recorder: Recorder, scenario: Scenario) -> dict[str, Any]:
    """`BY_TYPE` for each type of a mixed fleet, keyed ``<type>.<kpi>``, in fleet order."""
    start, end = scenario.warmup_s, scenario.duration_s
    window_h = (end - start) / 3600.0
    agv_types = scenario.fleet.agv_types
    out: dict[str, Any] = {}
    for kind in scenario.fleet.type_profiles:
        agvs = {i for i, t in enumerate(agv_types) if t == kind}
        agv_s = len(agvs) * (end - start)
        orders = [o for o in recorder.orders if o.agv in agvs]
        delivered = [o for o in orders if o.delivered_s is not None]
        lead = [o.delivered_s - o.created_s for o in delivered
                if o.delivered_s is not None and start <= o.delivered_s <= end]
        states = state_seconds([e for e in recorder.events if e.agv in agvs], start, end)
        down = sum(states[s.value] for s in DOWN_STATES)
        out.update({
            f"{kind}.agvs": len(agvs),
            f"{kind}.orders_completed": len(delivered),
            f"{kind}.throughput_per_hour": _round(len(lead) / window_h),
            f"{kind}.lead_time_mean_s": _round(float(np.mean(lead))) if lead else None,
            f"{kind}.agv_utilisation_pct": _round(100.0 * busy_seconds(orders, start, end)
                                                  / agv_s),
            f"{kind}.availability_pct": _round(100.0 * (1.0 - down / agv_s)),
        })
    return out


def state_seconds(events: Sequence[EventRecord], start_s: float,
                  end_s: float) -> dict[str, float]:
    """Total AGV-seconds in each state within [start_s, end_s], from the state changes: each
    AGV is in the state it last changed to until its next change (or the end)."""
    changes: dict[int, list[EventRecord]] = {}
    for e in events:
        if e.from_state != e.to_state:
            changes.setdefault(e.agv, []).append(e)
    totals = {s.value: 0.0 for s in VehicleState}
    for agv in sorted(changes):
        spells = changes[agv]
        for change, until in zip(spells, [*(e.time_s for e in spells[1:]), end_s], strict=True):
            totals[change.to_state] += _clip(until, start_s, end_s) \
                - _clip(change.time_s, start_s, end_s)
    return totals


Spells = list[tuple[float, float]]
"""Disjoint time intervals [start_s, end_s) in time order."""


def idle_with_orders_waiting_s(events: Sequence[EventRecord],
                               queue_lengths: Sequence[tuple[float, int]], start_s: float,
                               end_s: float) -> tuple[float, dict[NotDispatched, float]]:
    """AGV-seconds within [start_s, end_s] in state Idle while at least one order waited
    unassigned, and the part of them under each not_dispatched reason."""
    waiting = waiting_spells(queue_lengths, start_s, end_s)
    total = 0.0
    by_reason = dict.fromkeys(NotDispatched, 0.0)
    idle = state_spells(events, VehicleState.IDLE.value, end_s)
    reasons = not_dispatched_spells(events, end_s)
    for agv, spells in idle.items():
        idle_waiting = overlap(spells, waiting)
        total += sum(b - a for a, b in idle_waiting)
        for reason, held in reasons.get(agv, {}).items():
            by_reason[reason] += sum(b - a for a, b in overlap(held, idle_waiting))
    return total, by_reason


def waiting_spells(queue_lengths: Sequence[tuple[float, int]], start_s: float,
                   end_s: float) -> Spells:
    """When at least one order waited (a step function of (time, value) changes), within
    [start_s, end_s]."""
    out: Spells = []
    for (t0, value), (t1, _) in zip(queue_lengths, [*queue_lengths[1:], (end_s, 0)],
                                    strict=False):
        a, b = max(t0, start_s), min(t1, end_s)
        if value > 0 and b > a:
            if out and out[-1][1] == a:
                out[-1] = (out[-1][0], b)
            else:
                out.append((a, b))
    return out


def state_spells(events: Sequence[EventRecord], state: str, end_s: float) -> dict[int, Spells]:
    """Per AGV, when it was in `state` (from its changes of state; the last lasts to end_s)."""
    since: dict[int, float] = {}
    out: dict[int, Spells] = {}
    for e in events:
        if e.from_state == e.to_state:
            continue
        if e.agv in since:
            out.setdefault(e.agv, []).append((since.pop(e.agv), e.time_s))
        if e.to_state == state:
            since[e.agv] = e.time_s
    for agv, t in since.items():
        out.setdefault(agv, []).append((t, end_s))
    return out


def not_dispatched_spells(events: Sequence[EventRecord],
                          end_s: float) -> dict[int, dict[NotDispatched, Spells]]:
    """Per AGV and reason, the spells the fleet manager recorded (not_dispatched opens or
    changes a reason, not_dispatched_end closes it; one still open lasts to end_s)."""
    open_: dict[int, tuple[NotDispatched, float]] = {}
    out: dict[int, dict[NotDispatched, Spells]] = {}

    def close(agv: int, t: float) -> None:
        reason, since = open_.pop(agv)
        out.setdefault(agv, {}).setdefault(reason, []).append((since, t))

    for e in events:
        if e.event == NOT_DISPATCHED:
            if e.agv in open_:
                close(e.agv, e.time_s)
            open_[e.agv] = (NotDispatched(e.detail), e.time_s)
        elif e.event == NOT_DISPATCHED_END and e.agv in open_:
            close(e.agv, e.time_s)
    for agv in list(open_):
        close(agv, end_s)
    return out


def overlap(a: Spells, b: Spells) -> Spells:
    """The intersection of two lists of disjoint spells in time order."""
    out: Spells = []
    i = j = 0
    while i < len(a) and j < len(b):
        lo, hi = max(a[i][0], b[j][0]), min(a[i][1], b[j][1])
        if hi > lo:
            out.append((lo, hi))
        if a[i][1] < b[j][1]:
            i += 1
        else:
            j += 1
    return out


def busy_seconds(orders: Sequence[Order], start_s: float, end_s: float) -> float:
    """AGV-seconds within [start_s, end_s] spent on an order: from its assignment to its
    delivery, or its failure, or the end of the run."""
    assigned = np.array([_nan(o.assigned_s) for o in orders], dtype=float)
    done = np.array([_nan(o.delivered_s if o.delivered_s is not None else o.failed_s)
                     for o in orders], dtype=float)
    done = np.where(np.isnan(done), end_s, done)
    busy = np.clip(done, start_s, end_s) - np.clip(assigned, start_s, end_s)
    return float(np.nansum(busy))


def queue_mean(lengths: Sequence[tuple[float, int]], start_s: float, end_s: float) -> float:
    """Time-average of a step function given as (time, value) changes, over [start_s, end_s];
    zero before its first change."""
    total = 0.0
    for (t0, value), (t1, _) in zip(lengths, [*lengths[1:], (end_s, 0)], strict=False):
        total += value * max(0.0, min(t1, end_s) - max(t0, start_s))
    return total / (end_s - start_s)


def _clip(value: float, low: float, high: float) -> float:
    return min(max(value, low), high)


def _nan(value: float | None) -> float:
    return math.nan if value is None else value


def _round(value: float) -> float:
    return float(round(value, 6)) if math.isfinite(value) else value


# ---- the terminal summary ------------------------------------------------------------------


def summary_text(figures: Mapping[str, Any]) -> str:
    """A short text summary of a run's KPIs for the terminal."""
    def fmt(value: Any, unit: str = "") -> str:
        if value is None:
            return "n/a"
        return f"{value:,.1f}{unit}" if isinstance(value, float) else f"{value}{unit}"

    lines = [
        f"{figures['scenario']} on {figures['layout']}: {figures['agvs']} AGVs, "
        f"{figures['duration_h']} h (warm-up {figures['warmup_h']} h), seed {figures['seed']}",
        f"  orders created / completed  {figures['orders_created']} / "
        f"{figures['orders_completed']}",
        f"  throughput                  {fmt(figures['throughput_per_hour'], ' orders/h')}",
        f"  throughput / demand         {fmt(figures['throughput_pct_of_demand'], ' %')} "
        f"(demand {fmt(figures['demand_per_hour'], ' orders/h')})",
        f"  lead time mean / p95        {fmt(figures['lead_time_mean_s'], ' s')} / "
        f"{fmt(figures['lead_time_p95_s'], ' s')}",
        f"  AGV utilisation             {fmt(figures['agv_utilisation_pct'], ' %')}",
        f"  blocked by traffic          {fmt(figures['blocked_time_pct'], ' %')}",
        f"  deadlocks detected          {figures['deadlocks_detected']}",
        f"  distance driven             {fmt(figures['distance_km'], ' km')}",
        f"  availability                {fmt(figures['availability_pct'], ' %')}",
        f"  idle with orders waiting    {fmt(figures['idle_with_orders_waiting_pct'], ' %')}"
        + _reasons_text(figures[BY_REASON]),
        f"  charges / queue wait        {figures['charges']} / "
        f"{fmt(figures['charging_queue_wait_mean_s'], ' s')}",
        f"  incidents                   {figures['obstacle_pauses']} obstacle pauses, "
        f"{figures['comm_losses']} link losses, errors {figures['errors_by_code'] or 'none'}, "
        f"{figures['orders_failed']} orders failed",
    ]
    by_type = figures.get("by_type") or {}
    for kind in dict.fromkeys(key.rpartition(".")[0] for key in by_type):
        lines.append(
            f"  type {kind:<22}{by_type[f'{kind}.agvs']} AGVs, "
            f"{fmt(by_type[f'{kind}.throughput_per_hour'], ' orders/h')}, utilisation "
            f"{fmt(by_type[f'{kind}.agv_utilisation_pct'], ' %')}, lead time "
            f"{fmt(by_type[f'{kind}.lead_time_mean_s'], ' s')}")
    return "\n".join(lines)


def _reasons_text(by_reason: Mapping[str, float]) -> str:
    """`` (waiting_for_charger 61.2 %, link_lost 0.1 %)``: the reasons above zero."""
    shown = [f"{reason} {value:,.1f} %" for reason, value in by_reason.items() if value > 0]
    return f" ({', '.join(shown)})" if shown else ""
