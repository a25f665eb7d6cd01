"""Computing a run's KPIs: the running sums every KPI of the catalogue
(fleet_sim.analysis.kpis) is computed from, and the figures of kpis.json read from them.

KPIs are computed from what a run recorded and its scenario; nothing is read back from disk.
The records pass once through `KpiSums`, which keeps the running sums (a state's seconds per
AGV, busy seconds, the queue's integral, the seconds Idle while orders waited...): while a
streamed run goes (it is one of its record sinks), or at the end for a run kept in memory. The
per-type KPIs of a mixed fleet are the same sums over the type's AGVs.

The choices where the issue was silent (what the sums keep in memory, the order floats are
summed in): docs/background/decisions/analysis-and-studies.md.
"""

from __future__ import annotations

import math
from array import array
from collections import Counter
from collections.abc import Collection, Sequence
from typing import Any

import numpy as np

from fleet_sim.analysis.idle_waiting import IdleWhileWaiting
from fleet_sim.analysis.kpis import BY_REASON, BY_TYPE, DOWN_STATES
from fleet_sim.config.scenario import Scenario, setup_warnings
from fleet_sim.model.not_dispatched import NotDispatched
from fleet_sim.model.records import (
    ChargeWait,
    ErrorRecord,
    EventRecord,
    MoveRecord,
    Order,
    QueueLength,
    Recorder,
    SocSample,
)
from fleet_sim.model.stalls import Spell as StallSpell
from fleet_sim.model.stalls import Stall
from fleet_sim.model.states import VehicleState
from fleet_sim.sim.engine import RunOutput

NO_AGV = -1
"""The AGV of an order recorded without one (hand-made records only: a run's delivered and
assigned orders have their AGV)."""


class KpiSums:
    """The running sums every KPI is computed from, fed with a run's records as they come: a
    `RecordSink` (fleet_sim.model.records). A streamed run feeds it batch by batch while it
    runs; an in-memory run is handed over to it at the end (`compute_kpis`), in the same
    batches and order, so both give the same figures to the last bit. `figures` reads the
    KPIs once the sink is closed."""

    def __init__(self, start_s: float, end_s: float) -> None:
        self.start_s, self.end_s = start_s, end_s
        self.orders_created = 0
        self.orders_failed = 0
        self.orders_reassigned = 0
        self.created_in_window = 0
        self.delivered: Counter[int] = Counter()
        """Orders delivered over the whole run, per AGV."""
        self.lead_s = array("d")
        """Creation to delivery, for the orders delivered in the window ..."""
        self.lead_agv = array("q")
        """... and the AGV that delivered each."""
        self.busy_s: dict[int, float] = {}
        """Per AGV, seconds in the window with an order (assigned to delivered or failed)."""
        self.wait_sum_s = 0.0
        self.waits = 0
        self.unassigned_wait_sum_s = 0.0
        """Orders never assigned: creation to the end of the run."""
        self.unassigned = 0
        self.open_age_s = array("d")
        """Orders open at the end (neither delivered nor failed): their age at the end."""
        self.state_s: dict[int, dict[str, float]] = {}
        """Per AGV, seconds in the window in each state."""
        self._state_since: dict[int, tuple[str, float]] = {}
        """Per AGV, the state it last changed to and when."""
        self.queue_integral = 0.0
        self._queue_last: tuple[float, int] | None = None
        self.charges = 0
        self.charge_wait_sum_s = 0.0
        self.soc_used_pct: dict[int, float] = {}
        """Per AGV, the falls of its state of charge in the window, in percentage points."""
        self._soc_last: dict[int, tuple[float, float]] = {}
        self.errors_by_code: Counter[str] = Counter()
        self.idle_waiting = IdleWhileWaiting(start_s, end_s)
        self.closed = False

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
                spent = self.state_s.get(e.agv)
                if spent is None:
                    spent = self.state_s[e.agv] = _no_state_time()
                spent[last[0]] += _clip(e.time_s, start, end) - _clip(last[1], start, end)
            since[e.agv] = (e.to_state, e.time_s)
        self.idle_waiting.events(rows)

    def orders(self, rows: Sequence[Order]) -> None:
        """Each order once, with its final timestamps. Busy: from its assignment to its
        delivery, or its failure, or the end of the run. Orders neither delivered nor failed
        are open at the end (they come last): their age then, and their wait for an AGV if
        they never got one."""
        start, end = self.start_s, self.end_s
        for o in rows:
            self.orders_created += 1
            if start <= o.created_s <= end:
                self.created_in_window += 1
            self.orders_reassigned += o.reassigned
            if o.failed_s is not None:
                self.orders_failed += 1
            agv = NO_AGV if o.agv is None else o.agv
            if o.delivered_s is not None:
                self.delivered[agv] += 1
                if start <= o.delivered_s <= end:
                    self.lead_s.append(o.delivered_s - o.created_s)
                    self.lead_agv.append(agv)
            if o.delivered_s is None and o.failed_s is None:
                self.open_age_s.append(end - o.created_s)
                if o.assigned_s is None:
                    self.unassigned += 1
                    self.unassigned_wait_sum_s += end - o.created_s
            if o.assigned_s is not None:
                self.wait_sum_s += o.assigned_s - o.created_s
                self.waits += 1
                done = o.delivered_s if o.delivered_s is not None else o.failed_s
                self.busy_s[agv] = self.busy_s.get(agv, 0.0) \
                    + _clip(end if done is None else done, start, end) \
                    - _clip(o.assigned_s, start, end)

    def soc_samples(self, rows: Sequence[SocSample]) -> None:
        """energy_used_kwh: each fall of an AGV's state of charge between two of its samples
        (its state changes), the share of that time inside the window."""
        start, end = self.start_s, self.end_s
        for t1, agv, soc in rows:
            last = self._soc_last.get(agv)
            self._soc_last[agv] = (t1, soc)
            if last is None:
                self.soc_used_pct.setdefault(agv, 0.0)
                continue
            t0, before = last
            if before > soc and t1 > t0:
                inside = max(0.0, min(t1, end) - max(t0, start)) / (t1 - t0)
                self.soc_used_pct[agv] = self.soc_used_pct.get(agv, 0.0) \
                    + (before - soc) * inside

    def queue_lengths(self, rows: Sequence[QueueLength]) -> None:
        """The integral of the waiting-order count over the window (a step function, zero
        before its first change), and when orders waited (idle_with_orders_waiting_pct)."""
        start, end = self.start_s, self.end_s
        last = self._queue_last
        for t1, value in rows:
            if last is not None:
                t0, held = last
                self.queue_integral += held * max(0.0, min(t1, end) - max(t0, start))
            last = (t1, value)
        self._queue_last = last
        self.idle_waiting.queue_lengths(rows)

    def charge_waits(self, rows: Sequence[ChargeWait]) -> None:
        for asked, assigned in rows:
            self.charges += 1
            self.charge_wait_sum_s += assigned - asked

    def errors(self, rows: Sequence[ErrorRecord]) -> None:
        self.errors_by_code.update(e.code for e in rows)

    def moves(self, rows: Sequence[MoveRecord]) -> None:
        """No KPI reads the moves (they are the replay's)."""

    def close(self) -> None:
        """Every record is in: what was open lasts to the end of the run."""
        if not self.closed:
            self.closed = True
            self.idle_waiting.close()

    # ---- the KPIs --------------------------------------------------------------------------
    def state_seconds(self, agv: int) -> dict[str, float]:
        """AGV-seconds of `agv` in each state within the window (its last state lasts to the
        end of the run)."""
        spent = dict(self.state_s.get(agv, _no_state_time()))
        last = self._state_since.get(agv)
        if last is not None:
            spent[last[0]] += self.end_s - _clip(last[1], self.start_s, self.end_s)
        return spent

    def group(self, agvs: Collection[int], whole_fleet: bool = False) -> dict[str, Any]:
        """The KPIs that are sums over AGVs (`BY_TYPE` and the states), over `agvs`; for the
        `whole_fleet` orders recorded without an AGV count too (hand-made records only)."""
        start, end = self.start_s, self.end_s
        window_h = (end - start) / 3600.0
        agv_s = len(agvs) * (end - start)
        members = sorted(agvs)
        orders_of = [*members, NO_AGV] if whole_fleet else members
        states = _no_state_time()
        for agv in members:
            for state, seconds in self.state_seconds(agv).items():
                states[state] += seconds
        lead = np.frombuffer(self.lead_s, dtype=float)[
            np.isin(np.frombuffer(self.lead_agv, dtype=np.int64), orders_of)] \
            if self.lead_s else np.empty(0)
        down = sum(states[s.value] for s in DOWN_STATES)
        return {
            "agvs": len(agvs),
            "orders_completed": sum(self.delivered[agv] for agv in orders_of),
            "throughput_per_hour": _round(len(lead) / window_h),
            "lead": lead,
            "lead_time_mean_s": _round(float(lead.mean())) if len(lead) else None,
            "agv_utilisation_pct": _round(100.0 * sum(self.busy_s.get(agv, 0.0)
                                                      for agv in orders_of) / agv_s),
            "availability_pct": _round(100.0 * (1.0 - down / agv_s)),
            "states": states,
            "agv_s": agv_s,
        }

    def figures(self, recorder: Recorder, scenario: Scenario, layout_name: str,
                warnings: Sequence[str] = ()) -> dict[str, Any]:
        """The run fields and every KPI of the catalogue but wall_s, from these sums and the
        recorder's running totals, once every record has been fed (the sink closed)."""
        if not self.closed:
            raise ValueError("the KPIs are read once every record is in (close the sums)")
        start, end = self.start_s, self.end_s
        window_h = (end - start) / 3600.0
        n_agvs = scenario.fleet.size
        fleet = self.group(range(n_agvs), whole_fleet=True)
        agv_s = fleet["agv_s"]
        lead = fleet["lead"]
        queue = self.queue_integral
        if self._queue_last is not None:
            t0, held = self._queue_last
            queue += held * max(0.0, end - max(t0, start))
        throughput = fleet["throughput_per_hour"]
        out: dict[str, Any] = {
            "scenario": scenario.name,
            "layout": layout_name,
            "agvs": n_agvs,
            "seed": scenario.seed,
            "duration_h": scenario.duration_h,
            "warmup_h": scenario.warmup_h,
            "setup_warnings": list(warnings),
            "orders_created": self.orders_created,
            "orders_completed": fleet["orders_completed"],
            "throughput_per_hour": throughput,
            "lead_time_mean_s": fleet["lead_time_mean_s"],
            "lead_time_p95_s": _round(float(np.percentile(lead, 95))) if len(lead) else None,
            "agv_utilisation_pct": fleet["agv_utilisation_pct"],
            "blocked_time_pct": _round(100.0 * recorder.blocked_s / agv_s),
            "deadlocks_detected": recorder.deadlocks,
            "distance_km": _round(recorder.distance_m / 1000.0),
            "order_wait_mean_s": _round(self.wait_sum_s / self.waits) if self.waits else None,
            "order_wait_incl_unassigned_mean_s": _round(
                (self.wait_sum_s + self.unassigned_wait_sum_s) / (self.waits + self.unassigned))
            if self.waits + self.unassigned else None,
            "order_queue_mean": _round(queue / (end - start)),
        }
        states = fleet["states"]
        for state in VehicleState:
            out[f"state_{state.key}_pct"] = _round(100.0 * states[state.value] / agv_s)
        demand = self.created_in_window / window_h
        idle_waiting, by_reason = self.idle_waiting.seconds()
        out.update({
            "availability_pct": fleet["availability_pct"],
            "idle_with_orders_waiting_pct": _round(100.0 * idle_waiting / agv_s),
            BY_REASON: {reason.value: _round(100.0 * by_reason[reason] / agv_s)
                        for reason in NotDispatched},
            "orders_failed": self.orders_failed,
            "orders_reassigned": self.orders_reassigned,
            "charges": self.charges,
            "charging_queue_wait_mean_s": _charge_wait_mean(
                self.charge_wait_sum_s, self.charges, recorder.charger_waits_open, end),
            "charger_waits_open_at_end": len(recorder.charger_waits_open),
            "energy_used_kwh": self._energy_kwh(scenario),
            "commands_sent": recorder.commands_sent,
            "command_retries": recorder.command_retries,
            "obstacle_pauses": recorder.obstacle_pauses,
            "agv_obstacle_pauses": recorder.agv_obstacle_pauses,
            "comm_losses": recorder.comm_losses,
            "errors_by_code": dict(sorted(self.errors_by_code.items())),
            "warnings_by_code": dict(sorted(recorder.warnings.items())),
            "demand_per_hour": _round(demand),
            "throughput_pct_of_demand": _round(100.0 * throughput / demand) if demand > 0
            else None,
            "orders_open_at_end": len(self.open_age_s),
            **_ages(self.open_age_s),
            "orders_unassigned_at_end": self.unassigned,
            "gridlock_at_h": None if recorder.gridlock is None
            else _round(recorder.gridlock.since_s / 3600.0),
            "gridlock_where": None if recorder.gridlock is None else recorder.gridlock.where(),
            **stall_figures(recorder, start, end),
        })
        if scenario.fleet.vehicles:
            out["by_type"] = self.by_type(scenario)
        if recorder.zone_wait_s:
            out["zone_wait_s"] = {z: _round(s) for z, s in recorder.zone_wait_s.items()}
        return out

    def _energy_kwh(self, scenario: Scenario) -> float | None:
        """energy_used_kwh from the falls of charge and each AGV's battery capacity."""
        profiles = scenario.fleet.agv_profiles
        if all(p.battery is None for p in profiles):
            return None
        wh = 0.0
        for agv, used_pct in sorted(self.soc_used_pct.items()):
            battery = profiles[agv].battery if agv < len(profiles) else None
            if battery is not None:
                wh += used_pct / 100.0 * battery.capacity_wh
        return _round(wh / 1000.0)

    def by_type(self, scenario: Scenario) -> dict[str, Any]:
        """`BY_TYPE` for each type of a mixed fleet, keyed ``<type>.<kpi>``, in fleet order."""
        agv_types = scenario.fleet.agv_types
        out: dict[str, Any] = {}
        for kind in scenario.fleet.type_profiles:
            group = self.group([i for i, t in enumerate(agv_types) if t == kind])
            out.update({f"{kind}.{k.name}": group[k.name] for k in BY_TYPE})
        return out


def run_kpis(run: RunOutput, sums: KpiSums | None = None) -> dict[str, Any]:
    """The KPIs of a finished run (see compute_kpis), with its setup warnings."""
    warnings = [w.text for w in setup_warnings(run.scenario, run.layout)]
    return compute_kpis(run.recorder, run.scenario, run.layout.name, warnings, sums)


def compute_kpis(recorder: Recorder, scenario: Scenario, layout_name: str,
                 warnings: Sequence[str] = (), sums: KpiSums | None = None) -> dict[str, Any]:
    """The run fields and every KPI of the catalogue but wall_s. A streamed run passes the
    `sums` its sink fed; an in-memory recorder is handed over to fresh ones here."""
    if sums is None:
        sums = KpiSums(scenario.warmup_s, scenario.duration_s)
        recorder.hand_over(sums)
    return sums.figures(recorder, scenario, layout_name, warnings)


def stall_figures(recorder: Recorder, start_s: float, end_s: float) -> dict[str, Any]:
    """charging_starvation_h, _at_h, _peak_agvs, _worst (a note) and out_of_service_h, _at_h
    from the recorder's `StallMeter` (fleet_sim.model.stalls), over the window [start_s,
    end_s]; every figure none for a recorder without one (hand-made records)."""
    meter = recorder.stalls
    keys = ("charging_starvation_h", "charging_starvation_at_h", "charging_starvation_peak_agvs",
            "charging_starvation_worst", "out_of_service_h", "out_of_service_at_h")
    if meter is None:
        return dict.fromkeys(keys)
    starved = _in_window(meter.spells_to(Stall.CHARGING_STARVATION, end_s), start_s, end_s)
    down = _in_window(meter.spells_to(Stall.OUT_OF_SERVICE, end_s), start_s, end_s)
    worst = max(starved, key=lambda s: s.agvs_held(), default=None)
    return dict(zip(keys, (
        _round(sum(s.end_s - s.start_s for s in starved) / 3600.0),
        _round(starved[0].start_s / 3600.0) if starved else None,
        None if worst is None else worst.agvs_held(),
        None if worst is None else meter.words(worst.held),
        _round(sum(s.end_s - s.start_s for s in down) / 3600.0),
        _round(down[0].start_s / 3600.0) if down else None), strict=True))


def _in_window(spells: Sequence[StallSpell], start_s: float, end_s: float
               ) -> list[StallSpell]:
    """The spells' parts inside [start_s, end_s] (none of no length)."""
    return [StallSpell(max(s.start_s, start_s), min(s.end_s, end_s), s.held) for s in spells
            if min(s.end_s, end_s) > max(s.start_s, start_s)]


def _charge_wait_mean(closed_sum_s: float, closed: int, open_asked_s: Sequence[float],
                      end_s: float) -> float | None:
    """Mean wait for a charger: the charges made, then the requests open at the end, counted
    to the end (none open: exactly the charges' sum over their count)."""
    count = closed + len(open_asked_s)
    if not count:
        return None
    total = closed_sum_s
    for asked in open_asked_s:
        total += end_s - asked
    return _round(total / count)


def _ages(ages_s: array[float]) -> dict[str, float | None]:
    """open_order_age_mean_s, _p95_s, _max_s (None without open orders)."""
    if not ages_s:
        return {"open_order_age_mean_s": None, "open_order_age_p95_s": None,
                "open_order_age_max_s": None}
    ages = np.frombuffer(ages_s, dtype=float)
    return {"open_order_age_mean_s": _round(float(ages.mean())),
            "open_order_age_p95_s": _round(float(np.percentile(ages, 95))),
            "open_order_age_max_s": _round(float(ages.max()))}


def _no_state_time() -> dict[str, float]:
    return {s.value: 0.0 for s in VehicleState}


def _clip(value: float, low: float, high: float) -> float:
    return min(max(value, low), high)


def _round(value: float) -> float:
    return float(round(value, 6)) if math.isfinite(value) else value
