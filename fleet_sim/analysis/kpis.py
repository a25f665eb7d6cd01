"""The KPIs of a run: the one place that names them, says what they mean, and computes them.

KPIs are computed from what a run recorded and its scenario, the same way for `fleet-sim run`,
every run of a sweep and every run of a sizing search; nothing is read back from disk. The
records pass once through `KpiSums`, which keeps the running sums (a state's seconds, busy
seconds, the queue's integral...): while a streamed run goes (it is one of its record sinks),
or at the end for a run kept in memory. `KpiSums` is the one definition of each KPI. Unless
said otherwise a KPI is measured over the window from the end of the warm-up to the end of the
run. `CATALOGUE` lists them with unit and meaning, without running anything, so that an
experiment's targets can be checked before its runs start.

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
"""

from __future__ import annotations

import math
from array import array
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from fleet_sim.config.scenario import Scenario
from fleet_sim.model.error_codes import CODES
from fleet_sim.model.records import (
    ChargeWait,
    ErrorRecord,
    EventRecord,
    Order,
    QueueLength,
    Recorder,
    SocSample,
)
from fleet_sim.model.states import VehicleState
from fleet_sim.sim.engine import RunOutput

DOWN_STATES = (VehicleState.ERROR, VehicleState.MAINTENANCE, VehicleState.SAFE_MODE)
"""States in which an AGV is not available (availability_pct)."""

RUN_FIELDS = ("scenario", "layout", "agvs", "seed", "duration_h", "warmup_h")
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


def kpi_names() -> frozenset[str]:
    """The names a target may use: every KPI of the catalogue."""
    return frozenset(k.name for k in CATALOGUE)


def kpi_value(figures: Mapping[str, Any], name: str) -> Any:
    """KPI `name` from a kpis.json mapping, a flattened per-code name included (zero for a
    code the run never raised); None where the run has no value."""
    family, dot, code = name.partition(".")
    if dot and isinstance(figures.get(family), Mapping):
        return figures[family].get(code, 0)
    return figures.get(name)


# ---- computing them ------------------------------------------------------------------------


class KpiSums:
    """The running sums every KPI is computed from, fed with a run's records as they come: a
    `RecordSink` (fleet_sim.model.records). A streamed run feeds it batch by batch while it
    runs; an in-memory run is handed over to it at the end (`compute_kpis`), in the same
    order, so both give the same figures to the last bit.

    Memory: fixed but for the lead times of the orders delivered in the window, kept one float
    each (an `array('d')`, 8 bytes an order: 6 MB for a year of 90 orders/h) because their 95th
    percentile needs them all. Everything else is a running sum or count, so a KPI's float
    sums run in the order the records come (events in time order; orders in the order they
    finished, then the open ones) rather than, as before streaming, in order id or AGV order:
    figures may differ from those in the last bits, never in kpis.json's 6 decimals (checked
    on the bundled scenarios when this was introduced)."""

    def __init__(self, start_s: float, end_s: float) -> None:
        self.start_s, self.end_s = start_s, end_s
        self.orders_created = 0
        self.orders_delivered = 0
        self.orders_failed = 0
        self.orders_reassigned = 0
        self.created_in_window = 0
        self.lead_s = array("d")
        """Creation to delivery, for the orders delivered in the window."""
        self.busy_s = 0.0
        self.wait_sum_s = 0.0
        self.waits = 0
        self.state_s = {s.value: 0.0 for s in VehicleState}
        self._state_since: dict[int, tuple[str, float]] = {}
        """Per AGV, the state it last changed to and when."""
        self.queue_integral = 0.0
        self._queue_last: tuple[float, int] | None = None
        self.charges = 0
        self.charge_wait_sum_s = 0.0
        self.errors_by_code: Counter[str] = Counter()

    # ---- RecordSink ------------------------------------------------------------------------
    def events(self, rows: Sequence[EventRecord]) -> None:
        """Time in each state: an AGV is in the state it last changed to until its next change
        (or the end of the run); events that change no state do not count."""
        start, end = self.start_s, self.end_s
        since = self._state_since
        for e in rows:
            if e.from_state == e.to_state:
                continue
            last = since.get(e.agv)
            if last is not None:
                self.state_s[last[0]] += _clip(e.time_s, start, end) - _clip(last[1], start, end)
            since[e.agv] = (e.to_state, e.time_s)

    def orders(self, rows: Sequence[Order]) -> None:
        """Each order once, with its final timestamps. Busy: from its assignment to its
        delivery, or its failure, or the end of the run."""
        start, end = self.start_s, self.end_s
        for o in rows:
            self.orders_created += 1
            if start <= o.created_s <= end:
                self.created_in_window += 1
            self.orders_reassigned += o.reassigned
            if o.failed_s is not None:
                self.orders_failed += 1
            if o.delivered_s is not None:
                self.orders_delivered += 1
                if start <= o.delivered_s <= end:
                    self.lead_s.append(o.delivered_s - o.created_s)
            if o.assigned_s is not None:
                self.wait_sum_s += o.assigned_s - o.created_s
                self.waits += 1
                done = o.delivered_s if o.delivered_s is not None else o.failed_s
                self.busy_s += _clip(end if done is None else done, start, end) \
                    - _clip(o.assigned_s, start, end)

    def soc_samples(self, rows: Sequence[SocSample]) -> None:
        """No KPI reads the state of charge (soc.parquet is for plots)."""

    def queue_lengths(self, rows: Sequence[QueueLength]) -> None:
        """The integral of the waiting-order count over the window (a step function, zero
        before its first change)."""
        start, end = self.start_s, self.end_s
        last = self._queue_last
        for t1, value in rows:
            if last is not None:
                t0, held = last
                self.queue_integral += held * max(0.0, min(t1, end) - max(t0, start))
            last = (t1, value)
        self._queue_last = last

    def charge_waits(self, rows: Sequence[ChargeWait]) -> None:
        for asked, assigned in rows:
            self.charges += 1
            self.charge_wait_sum_s += assigned - asked

    def errors(self, rows: Sequence[ErrorRecord]) -> None:
        self.errors_by_code.update(e.code for e in rows)

    def close(self) -> None:
        """Nothing to release: the figures are read with `figures`."""

    # ---- the KPIs --------------------------------------------------------------------------
    def figures(self, recorder: Recorder, scenario: Scenario,
                layout_name: str) -> dict[str, Any]:
        """The run fields and every KPI of the catalogue but wall_s, from these sums and the
        recorder's running totals, once every record has been fed."""
        start, end = self.start_s, self.end_s
        window_h = (end - start) / 3600.0
        n_agvs = scenario.fleet.size
        agv_s = n_agvs * (end - start)
        states = dict(self.state_s)
        for agv in sorted(self._state_since):  # each AGV's last state lasts to the end
            last, since = self._state_since[agv]
            states[last] += end - _clip(since, start, end)
        queue = self.queue_integral
        if self._queue_last is not None:
            t0, held = self._queue_last
            queue += held * max(0.0, end - max(t0, start))
        lead = np.frombuffer(self.lead_s, dtype=float) if self.lead_s else np.empty(0)
        throughput = _round(len(lead) / window_h)
        out: dict[str, Any] = {
            "scenario": scenario.name,
            "layout": layout_name,
            "agvs": n_agvs,
            "seed": scenario.seed,
            "duration_h": scenario.duration_h,
            "warmup_h": scenario.warmup_h,
            "orders_created": self.orders_created,
            "orders_completed": self.orders_delivered,
            "throughput_per_hour": throughput,
            "lead_time_mean_s": _round(float(lead.mean())) if len(lead) else None,
            "lead_time_p95_s": _round(float(np.percentile(lead, 95))) if len(lead) else None,
            "agv_utilisation_pct": _round(100.0 * self.busy_s / agv_s),
            "blocked_time_pct": _round(100.0 * recorder.blocked_s / agv_s),
            "deadlocks_detected": recorder.deadlocks,
            "distance_km": _round(recorder.distance_m / 1000.0),
            "order_wait_mean_s": _round(self.wait_sum_s / self.waits) if self.waits else None,
            "order_queue_mean": _round(queue / (end - start)),
        }
        for state in VehicleState:
            out[f"state_{state.key}_pct"] = _round(100.0 * states[state.value] / agv_s)
        down = sum(states[s.value] for s in DOWN_STATES)
        demand = self.created_in_window / window_h
        out.update({
            "availability_pct": _round(100.0 * (1.0 - down / agv_s)),
            "orders_failed": self.orders_failed,
            "orders_reassigned": self.orders_reassigned,
            "charges": self.charges,
            "charging_queue_wait_mean_s": _round(self.charge_wait_sum_s / self.charges)
            if self.charges else None,
            "commands_sent": recorder.commands_sent,
            "command_retries": recorder.command_retries,
            "obstacle_pauses": recorder.obstacle_pauses,
            "comm_losses": recorder.comm_losses,
            "errors_by_code": dict(sorted(self.errors_by_code.items())),
            "warnings_by_code": dict(sorted(recorder.warnings.items())),
            "demand_per_hour": _round(demand),
            "throughput_pct_of_demand": _round(100.0 * throughput / demand) if demand > 0
            else None,
            "orders_open_at_end": self.orders_created - self.orders_delivered,
        })
        return out


def run_kpis(run: RunOutput, sums: KpiSums | None = None) -> dict[str, Any]:
    """The KPIs of a finished run (see compute_kpis)."""
    return compute_kpis(run.recorder, run.scenario, run.layout.name, sums)


def compute_kpis(recorder: Recorder, scenario: Scenario, layout_name: str,
                 sums: KpiSums | None = None) -> dict[str, Any]:
    """The run fields and every KPI of the catalogue but wall_s. A streamed run passes the
    `sums` its sink fed; an in-memory recorder is handed over to fresh ones here."""
    if sums is None:
        sums = KpiSums(scenario.warmup_s, scenario.duration_s)
        recorder.hand_over(sums)
    return sums.figures(recorder, scenario, layout_name)


def _clip(value: float, low: float, high: float) -> float:
    return min(max(value, low), high)


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
        f"  charges / queue wait        {figures['charges']} / "
        f"{fmt(figures['charging_queue_wait_mean_s'], ' s')}",
        f"  incidents                   {figures['obstacle_pauses']} obstacle pauses, "
        f"{figures['comm_losses']} link losses, errors {figures['errors_by_code'] or 'none'}, "
        f"{figures['orders_failed']} orders failed",
    ]
    return "\n".join(lines)
