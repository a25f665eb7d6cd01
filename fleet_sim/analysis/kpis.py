"""The KPIs of a run: the one place that names them, says what they mean, and computes them.

KPIs are computed from what a run recorded and its scenario, the same way for `fleet-sim run`,
every run of a sweep and every run of a sizing search; nothing is read back from disk. The
records pass once through `KpiSums`, which keeps the running sums (a state's seconds per AGV,
busy seconds, the queue's integral, the seconds Idle while orders waited...): while a streamed
run goes (it is one of its record sinks), or at the end for a run kept in memory. `KpiSums` is
the one definition of each KPI; the per-type KPIs of a mixed fleet are the same definitions
over the type's AGVs. Unless said otherwise a KPI is measured over the window from the end of
the warm-up to the end of the run. `CATALOGUE` lists them with unit and meaning, without running
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
* Stalls (issue 33, item 7): `gridlock_at_h` is traffic only; a standstill behind AGVs
  held by their batteries or out of service is not one (fleet_sim.sim.gridlock). Charging
  starvation (`charging_starvation_h`, `_at_h`, `_peak_agvs`, the note
  `charging_starvation_worst`) and a fleet out of service (`out_of_service_h`, `_at_h`) are
  read from the spells the run's `StallMeter` kept (fleet_sim.model.stalls, which says why
  starvation is measured by the AGVs waiting for a charger); hand-made records have no meter
  and none of these figures.
* A layout with mutex or same-direction zones adds `zone_wait_s` last: zone id -> AGV-seconds
  spent in the window waiting to enter it (``zone_wait_s.<zone>``, s; also counted in
  blocked_time_pct).
* Memory (`KpiSums`): fixed but for the lead times of the orders delivered in the window, kept
  one float and one AGV id each (16 bytes an order: 13 MB for a year of 90 orders/h) because
  their 95th percentile needs them all, and for the Idle and waiting spells not yet matched
  (those between the newest event and the newest queue change handed over: a batch's worth).
  Everything else is a running sum or count per AGV. Float sums therefore run in the order the
  records come (events in time order; orders in the order they finished, then the open ones)
  and per AGV, where the in-memory computation before streaming summed in order id or AGV
  order: a figure may differ from that in its last bits, which kpis.json's 6 decimals hide
  unless a value falls on a rounding boundary (kpis.json came out byte-identical on the
  bundled scenarios, a mixed fleet, a mutex zone with admission and multi-stop orders when
  this was merged). The seconds Idle while orders waited are matched spell by spell exactly
  as before (the same pieces, summed in the same order), so they are the same to the last bit.
"""

from __future__ import annotations

import math
from array import array
from bisect import bisect_right
from collections import Counter, deque
from collections.abc import Callable, Collection, Mapping, Sequence
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from fleet_sim.analysis.paired import number_text
from fleet_sim.config.experiment import Target
from fleet_sim.config.scenario import Scenario, setup_warnings
from fleet_sim.model.error_codes import CODES
from fleet_sim.model.not_dispatched import NOT_DISPATCHED, NOT_DISPATCHED_END, NotDispatched
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

DOWN_STATES = (VehicleState.ERROR, VehicleState.MAINTENANCE, VehicleState.SAFE_MODE)
"""States in which an AGV is not available (availability_pct)."""

RUN_FIELDS = ("scenario", "layout", "agvs", "seed", "duration_h", "warmup_h",
              "setup_warnings")
"""What kpis.json says about the run before its KPIs (not KPIs themselves)."""

NOTE_FIELDS = ("gridlock_where", "charging_starvation_worst")
"""What kpis.json says beside a KPI, as text, not a KPI: gridlock_where (after gridlock_at_h:
``agvs 3 5 at nodes M007 M008 (wait-for cycle)``, none if no gridlock) and
charging_starvation_worst (``9 of 10 AGVs: 3 charging, 4 waiting for a charger or on the way
to one, 2 at or below the 30 % threshold``: the starvation at its deepest, none if none)."""

NOTE_MEANINGS: Mapping[str, str] = {
    "gridlock_where": "where the fleet locked solid",
    "charging_starvation_worst": "what held the AGVs when charging starvation was deepest",
}
"""Each note's meaning, for exports beside its value."""


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
        "in the window (none if none was); orders not delivered are not in it: see "
        "open_order_age_*, which a lead-time target also holds to its bound"),
    Kpi("lead_time_p95_s", "s", "95th percentile of the same lead times (delivered orders "
        "only)"),
    Kpi("agv_utilisation_pct", "%", "share of AGV time busy with an order (assigned to "
        "delivered, or to failed; an order still open is busy to the end)"),
    Kpi("blocked_time_pct", "%", "share of AGV time spent waiting for a node, corridor or zone "
        "held by another AGV (a wait still open at the end counts to the end)"),
    Kpi("deadlocks_detected", "count", "wait-for cycles found (each also an event; resolved "
        "or not)"),
    Kpi("distance_km", "km", "distance driven in the window, all AGVs (each hop counted when "
        "it ends: a hop under way at the end, at most one per AGV, is not)"),
    Kpi("order_wait_mean_s", "s", "mean time from creation to assignment, orders assigned "
        "(orders never assigned: order_wait_incl_unassigned_mean_s)"),
    Kpi("order_wait_incl_unassigned_mean_s", "s", "mean time from creation to assignment over "
        "every order created, those never assigned counted to the end of the run"),
    Kpi("order_queue_mean", "orders", "time-average number of orders waiting for an AGV (to "
        "the end)"),
    *_state_kpis(),
    Kpi("availability_pct", "%", "share of AGV time not in Error, Maintenance or SafeMode"),
    Kpi("idle_with_orders_waiting_pct", "%", "share of AGV time in state Idle while at least "
        "one order waited unassigned (each such moment has a reason below; spells open at "
        "the end count to the end)"),
    *_reason_kpis(),
    Kpi("orders_failed", "orders", "loaded orders lost with a failed AGV, whole run"),
    Kpi("orders_reassigned", "orders", "times an order went back to the queue, whole run"),
    Kpi("charges", "count", "charging stops, whole run"),
    Kpi("charging_queue_wait_mean_s", "s", "mean time from asking for a charger to getting one, "
        "requests still waiting at the end counted to the end (none if no AGV asked)"),
    Kpi("charger_waits_open_at_end", "count", "AGVs still waiting for a charger at the end"),
    Kpi("energy_used_kwh", "kWh", "energy the fleet drew from its batteries in the window (each "
        "fall of the state of charge between two state changes x the battery's capacity, the "
        "part inside the window; none without a battery model)"),
    Kpi("commands_sent", "count", "commands the fleet manager sent, whole run"),
    Kpi("command_retries", "count", "commands sent again after no answer, whole run"),
    Kpi("obstacle_pauses", "count", "obstacle pauses (RSS-AGV-001 4.2.3) for people, "
        "forklifts and blocks, whole run"),
    Kpi("agv_obstacle_pauses", "count", "pauses behind an AGV standing ahead in a queue "
        "(4.2.3, rules.agv_ahead: lds), whole run"),
    Kpi("comm_losses", "count", "FMS and internal link losses noticed, whole run"),
    *_code_kpis(),
    Kpi("demand_per_hour", "orders/h", "orders created in the window, per hour"),
    Kpi("throughput_pct_of_demand", "%", "throughput_per_hour over demand_per_hour (none "
        "without demand)"),
    Kpi("orders_open_at_end", "orders", "orders created and neither delivered nor failed by "
        "the end"),
    Kpi("open_order_age_mean_s", "s", "mean age at the end of the orders open at the end (none "
        "if none is)"),
    Kpi("open_order_age_p95_s", "s", "95th percentile of the same ages"),
    Kpi("open_order_age_max_s", "s", "age at the end of the oldest order open at the end"),
    Kpi("orders_unassigned_at_end", "orders", "orders open at the end never assigned to an "
        "AGV"),
    Kpi("gridlock_at_h", "h", "when the fleet locked solid (an unresolved wait-for cycle, or "
        "no AGV moving while orders waited and AGVs waited for locks, for "
        "traffic.gridlock_after_s), hours from the start; none if it never did. A standstill "
        "behind AGVs held by their batteries or out of service is not a gridlock: see the two "
        "stalls below"),
    Kpi("charging_starvation_h", "h", "time in the window during which orders waited for an "
        "AGV while AGVs stood waiting for a charger (every charger taken): no AGV was free to "
        "take an order and those that could were held by their batteries (synchronised "
        "charging); 0 if never"),
    Kpi("charging_starvation_at_h", "h", "when the first such time in the window began, hours "
        "from the start; none if there was none"),
    Kpi("charging_starvation_peak_agvs", "AGVs", "most AGVs held by their batteries at once "
        "during it (charging, waiting for a charger or on the way to one, at or below the "
        "charging threshold); none if there was none"),
    Kpi("out_of_service_h", "h", "time in the window during which orders waited while every "
        "AGV was in Error, Maintenance or SafeMode; 0 if never"),
    Kpi("out_of_service_at_h", "h", "when the first such time in the window began, hours from "
        "the start; none if there was none"),
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


BETTER: Mapping[str, Literal["higher", "lower"]] = {
    "orders_completed": "higher", "throughput_per_hour": "higher",
    "throughput_pct_of_demand": "higher", "availability_pct": "higher",
    "lead_time_mean_s": "lower", "lead_time_p95_s": "lower", "blocked_time_pct": "lower",
    "deadlocks_detected": "lower", "order_wait_mean_s": "lower", "order_queue_mean": "lower",
    "idle_with_orders_waiting_pct": "lower", "orders_failed": "lower",
    "orders_reassigned": "lower", "charging_queue_wait_mean_s": "lower",
    "command_retries": "lower", "orders_open_at_end": "lower", "distance_km": "lower",
    "energy_used_kwh": "lower", "charging_starvation_h": "lower", "out_of_service_h": "lower",
}
"""Which way a KPI is better, where a planner would agree without knowing the study
(utilisation, charges, time per state: neither); `kpi_better` adds the per-code counts
(fewer errors are better). Used to put a comparison's verdict in words."""

SHORT_NAMES: Mapping[str, str] = {
    "throughput_per_hour": "throughput", "throughput_pct_of_demand": "throughput",
    "lead_time_mean_s": "mean lead time", "lead_time_p95_s": "p95 lead time",
    "agv_utilisation_pct": "AGV utilisation", "blocked_time_pct": "time blocked by traffic",
    "deadlocks_detected": "deadlocks", "order_wait_mean_s": "mean wait for an AGV",
    "order_queue_mean": "orders waiting", "distance_km": "distance driven",
    "availability_pct": "availability", "charging_queue_wait_mean_s": "wait for a charger",
    "idle_with_orders_waiting_pct": "AGVs idle while orders wait",
    "orders_open_at_end": "orders open at the end",
    "open_order_age_mean_s": "mean age of open orders",
    "open_order_age_p95_s": "p95 age of open orders", "open_order_age_max_s": "oldest open order",
    "energy_used_kwh": "energy used", "wall_s": "wall-clock time",
}
"""A KPI's name in a planner's words, for sentences and axes (else its key, spaced)."""


def kpi_better(name: str) -> Literal["higher", "lower"] | None:
    """Which way KPI `name` is better (None: neither, by itself)."""
    if name.startswith(("errors_by_code.", "warnings_by_code.")):
        return "lower"
    return BETTER.get(name)


def kpi_unit(name: str) -> str:
    """The unit of KPI `name` in the catalogue (per-type ones: the BY_TYPE unit); "" if none."""
    family, _, rest = name.partition(".")
    if family == "by_type":
        base = rest.rpartition(".")[2]
        return next((k.unit for k in BY_TYPE if k.name == base), "")
    if family == "zone_wait_s":
        return "s"
    return next((k.unit for k in CATALOGUE if k.name == name), "")


STATE_OF_KPI: Mapping[str, str] = {f"state_{s.key}_pct": s.value for s in VehicleState}
"""The time-in-state KPIs: name -> the state (``state_charging_pct`` -> ``Charging``)."""


def kpi_short(name: str) -> str:
    """KPI `name` in a planner's words, without its unit: ``p95 lead time``."""
    if name in STATE_OF_KPI:
        return f"time in state {STATE_OF_KPI[name]}"
    if name in SHORT_NAMES:
        return SHORT_NAMES[name]
    family, dot, rest = name.partition(".")
    if dot and family == BY_REASON:
        return "AGVs idle while orders wait, " + rest.replace("_", " ")
    if dot and family == "by_type":
        kind, _, base = rest.rpartition(".")
        return f"{kind} AGVs: {kpi_short(base)}"
    if dot and family == "zone_wait_s":
        return f"wait to enter zone {rest}"
    if dot and family in ("errors_by_code", "warnings_by_code"):
        return f"{family.split('_')[0]} {rest}"
    for suffix in ("_per_hour", "_pct", "_s", "_km", "_h"):  # the unit says it
        if name.endswith(suffix) and "." not in name:
            name = name.removesuffix(suffix)
            break
    return name.replace("_", " ")


def kpi_label(name: str) -> str:
    """Name and unit for an axis or a table: ``p95 lead time [s]``; a share says of what
    (``[% of AGV time]``, ``[% of demand]``), as its meaning in the catalogue does."""
    unit = kpi_unit(name)
    if unit == "%":
        meaning = next((k.meaning for k in CATALOGUE if k.name == name), "")
        if name == "throughput_pct_of_demand":
            unit = "% of demand"
        elif meaning.startswith("share of AGV time"):
            unit = "% of AGV time"
    return f"{kpi_short(name)} [{unit}]" if unit else kpi_short(name)


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

IDLE = VehicleState.IDLE.value
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


Spell = list[float]
"""[start_s, end_s] of a spell."""


class IdleWhileWaiting:
    """AGV-seconds in state Idle while at least one order waited unassigned, and the part of
    them under each not_dispatched reason, from the events and the queue lengths as they come.

    Per AGV, its Idle spells are matched with the spells in which orders waited (the queue
    above zero, clipped to the window, touching spells joined) and each piece in common with
    the AGV's reason spells (not_dispatched opens or changes a reason, not_dispatched_end
    closes it). The two kinds of records come as independent streams, so a piece is counted
    only once both have gone past its end; what is not matched yet waits here. Pieces are
    summed per AGV in time order, and the AGVs in the order their first Idle spell ended
    (those Idle at the end last, in the order they became Idle)."""

    def __init__(self, start_s: float, end_s: float) -> None:
        self.start_s, self.end_s = start_s, end_s
        self.event_s = -math.inf
        """The time of the newest event: every Idle and reason spell before it is known."""
        self.waiting: list[Spell] = []
        """Closed spells in which orders waited, from `offset` on (the last may still grow)."""
        self.offset = 0
        self.queue_last: tuple[float, int] | None = None
        """The newest change of the queue length."""
        self.idle_since: dict[int, float] = {}
        """AGVs Idle now, since when (in the order they became Idle)."""
        self.idle: dict[int, deque[tuple[float, float | None]]] = {}
        """Per AGV, Idle spells not fully matched yet (end None: still Idle)."""
        self.cursor: dict[int, int] = {}
        """Per AGV with Idle spells to match, the waiting spell it has reached."""
        self.reasons: dict[int, deque[tuple[NotDispatched, float, float]]] = {}
        """Per AGV, closed reason spells that may still meet an Idle spell."""
        self.reason_open: dict[int, tuple[NotDispatched, float]] = {}
        self.order: dict[int, None] = {}
        """AGVs in the order their first Idle spell ended."""
        self.total_s: dict[int, float] = {}
        self.by_reason_s: dict[int, dict[NotDispatched, float]] = {}
        self.closed = False

    # ---- the streams --------------------------------------------------------------------------
    def events(self, rows: Sequence[EventRecord]) -> None:
        for e in rows:
            if e.event == NOT_DISPATCHED:
                if e.agv in self.reason_open:
                    self._close_reason(e.agv, e.time_s)
                self.reason_open[e.agv] = (NotDispatched(e.detail), e.time_s)
            elif e.event == NOT_DISPATCHED_END and e.agv in self.reason_open:
                self._close_reason(e.agv, e.time_s)
            if e.from_state == e.to_state:
                continue
            if e.agv in self.idle_since:
                self._close_idle(e.agv, e.time_s)
            if e.to_state == IDLE:
                self._open_idle(e.agv, e.time_s)
        if rows:
            self.event_s = rows[-1].time_s
        self._match()

    def queue_lengths(self, rows: Sequence[QueueLength]) -> None:
        for t1, value in rows:
            if self.queue_last is not None:
                self._step_ended(*self.queue_last, t1)
            self.queue_last = (t1, value)
        self._match()

    def close(self) -> None:
        """The run is over: the queue's last step, the Idle spells and the reasons still open
        last to its end."""
        if self.closed:
            return
        if self.queue_last is not None:
            self._step_ended(*self.queue_last, self.end_s)
            self.queue_last = None
        for agv in list(self.idle_since):
            self._close_idle(agv, self.end_s)
        for agv in list(self.reason_open):
            self._close_reason(agv, self.end_s)
        self.closed = True
        self.event_s = math.inf
        self._match()

    def seconds(self) -> tuple[float, dict[NotDispatched, float]]:
        """The total and the part under each reason, once closed."""
        total = 0.0
        by_reason = dict.fromkeys(NotDispatched, 0.0)
        for agv in self.order:
            total += self.total_s.get(agv, 0.0)
            for reason, seconds in self.by_reason_s.get(agv, {}).items():
                by_reason[reason] += seconds
        return total, by_reason

    # ---- spells -------------------------------------------------------------------------------
    def _step_ended(self, t0: float, value: int, t1: float) -> None:
        a, b = max(t0, self.start_s), min(t1, self.end_s)
        if value > 0 and b > a:
            if self.waiting and self.waiting[-1][1] == a:
                self.waiting[-1][1] = b
            else:
                self.waiting.append([a, b])

    def _open_idle(self, agv: int, time_s: float) -> None:
        self.idle_since[agv] = time_s
        spells = self.idle.setdefault(agv, deque())
        if not spells:  # from the first waiting spell that may meet this Idle spell
            first = bisect_right(self.waiting, time_s, key=lambda w: w[1])
            if first == len(self.waiting) and self._may_grow():
                first -= 1  # the last one may still grow past time_s
            self.cursor[agv] = self.offset + first
        spells.append((time_s, None))

    def _close_idle(self, agv: int, time_s: float) -> None:
        since = self.idle_since.pop(agv)
        spells = self.idle[agv]
        assert spells[-1] == (since, None)
        spells[-1] = (since, time_s)
        self.order.setdefault(agv, None)

    def _close_reason(self, agv: int, time_s: float) -> None:
        reason, since = self.reason_open.pop(agv)
        self.reasons.setdefault(agv, deque()).append((reason, since, time_s))

    # ---- matching ------------------------------------------------------------------------------
    def _waiting_at(self, j: int) -> tuple[float, float, bool] | None:
        """Waiting spell `j` (absolute index) and whether its end is final, or None if it is
        not known yet."""
        k = j - self.offset
        if k >= len(self.waiting):
            return None
        a, b = self.waiting[k]
        final = self.closed or k < len(self.waiting) - 1 or not self._may_grow()
        return a, b, final

    def _may_grow(self) -> bool:
        """Can the last waiting spell still grow (the queue's open step joins it)?"""
        if self.queue_last is None or not self.waiting:
            return False
        t0, value = self.queue_last
        return value > 0 and self.waiting[-1][1] == max(t0, self.start_s)

    def _next_waiting_from(self) -> float:
        """Waiting spells not known yet start at or after this."""
        if self.closed:
            return math.inf
        if self.queue_last is None:
            return -math.inf
        return max(self.queue_last[0], self.start_s)

    def _match(self) -> None:
        for agv, spells in self.idle.items():
            if spells:
                self._match_agv(agv, spells)
        self._forget()

    def _match_agv(self, agv: int, spells: deque[tuple[float, float | None]]) -> None:
        j = self.cursor[agv]
        while spells:
            s, e = spells[0]
            spell = self._waiting_at(j)
            if spell is None:  # every known waiting spell is behind
                if e is not None and e <= self._next_waiting_from():
                    spells.popleft()
                    continue
                break
            a, b, final = spell
            if e is not None and (final or e <= b):
                hi, idle_first = min(e, b), e <= b
            elif final and b <= self.event_s:  # Idle goes on at least to the newest event
                hi, idle_first = b, False
            else:
                break
            lo = max(s, a)
            if hi > lo:
                self._piece(agv, lo, hi)
            if idle_first:
                spells.popleft()
            else:
                j += 1
        self.cursor[agv] = j

    def _piece(self, agv: int, lo: float, hi: float) -> None:
        """[lo, hi]: Idle while orders waited; and its part under each reason."""
        self.total_s[agv] = self.total_s.get(agv, 0.0) + (hi - lo)
        held = self.reasons.get(agv)
        spells: list[tuple[NotDispatched, float, float]] = list(held) if held else []
        if agv in self.reason_open:  # open: lasts at least to the newest event, past hi
            reason, since = self.reason_open[agv]
            spells.append((reason, since, math.inf))
        for reason, ra, rb in spells:
            if ra >= hi:
                break
            piece = min(hi, rb) - max(lo, ra)
            if piece > 0:
                sums = self.by_reason_s.setdefault(agv, {})
                sums[reason] = sums.get(reason, 0.0) + piece
        while held and held[0][2] <= hi:  # no later piece (they start at hi or after) meets it
            held.popleft()

    def _forget(self) -> None:
        """Drop what no Idle spell can meet any more: waiting spells before every AGV's cursor
        (and, for AGVs not Idle, before the newest event); reasons of AGVs not Idle that ended
        before the newest event."""
        keep_from = self.offset + bisect_right(self.waiting, self.event_s, key=lambda w: w[1])
        for agv, spells in self.idle.items():
            if spells:
                keep_from = min(keep_from, self.cursor[agv])
        keep_from = min(keep_from, self.offset + max(0, len(self.waiting) - 1))
        drop = keep_from - self.offset
        if drop > 64 and drop * 2 > len(self.waiting):
            del self.waiting[:drop]
            self.offset = keep_from
        for agv, held in self.reasons.items():
            if not self.idle.get(agv):
                while held and held[0][2] <= self.event_s:
                    held.popleft()


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
    to the end (none open: the sum of the charges alone, to the last bit as before)."""
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
        f"{fmt(figures['lead_time_p95_s'], ' s')}"
        + (" (delivered orders only)" if figures.get("orders_open_at_end") else ""),
        *_open_orders_text(figures, fmt),
        f"  AGV utilisation             {fmt(figures['agv_utilisation_pct'], ' %')}",
        f"  blocked by traffic          {fmt(figures['blocked_time_pct'], ' %')}",
        f"  deadlocks detected          {figures['deadlocks_detected']}",
        f"  distance driven             {fmt(figures['distance_km'], ' km')}",
        f"  availability                {fmt(figures['availability_pct'], ' %')}",
        f"  idle with orders waiting    {fmt(figures['idle_with_orders_waiting_pct'], ' %')}"
        + _reasons_text(figures[BY_REASON]),
        f"  charges / queue wait        {figures['charges']} / "
        f"{fmt(figures['charging_queue_wait_mean_s'], ' s')}",
        f"  incidents                   {figures['obstacle_pauses']} obstacle pauses "
        f"(+ {figures['agv_obstacle_pauses']} behind AGVs), "
        f"{figures['comm_losses']} link losses, errors {figures['errors_by_code'] or 'none'}, "
        f"{figures['orders_failed']} orders failed",
    ]
    by_type = figures.get("by_type") or {}
    lines += gridlock_text(figures)
    lines += stall_text(figures)
    for kind in dict.fromkeys(key.rpartition(".")[0] for key in by_type):
        lines.append(
            f"  type {kind:<22}{by_type[f'{kind}.agvs']} AGVs, "
            f"{fmt(by_type[f'{kind}.throughput_per_hour'], ' orders/h')}, utilisation "
            f"{fmt(by_type[f'{kind}.agv_utilisation_pct'], ' %')}, lead time "
            f"{fmt(by_type[f'{kind}.lead_time_mean_s'], ' s')}")
    return "\n".join(lines)


def _open_orders_text(figures: Mapping[str, Any], fmt: Callable[..., str]) -> list[str]:
    """The orders open at the end and their age, when there are any."""
    if not figures.get("orders_open_at_end"):
        return []
    return [f"  open at the end             {figures['orders_open_at_end']} orders "
            f"({figures.get('orders_unassigned_at_end', 0)} never assigned), age mean / p95 "
            f"/ max {fmt(figures['open_order_age_mean_s'], ' s')} / "
            f"{fmt(figures['open_order_age_p95_s'], ' s')} / "
            f"{fmt(figures['open_order_age_max_s'], ' s')}"]


def gridlock_text(figures: Mapping[str, Any]) -> list[str]:
    """The summary's warning when the run locked solid (none when it did not)."""
    at_h = figures.get("gridlock_at_h")
    if at_h is None:
        return []
    return [f"  WARNING: gridlock at {at_h:.2f} h: {figures.get('gridlock_where') or ''}; "
            "nothing moved there from then on. Limit the AGVs on the floor (admission, "
            "dispatch.max_active_agvs) or run fewer AGVs."]


CHARGING_ADVICE = ("Spread the charging: more chargers, opportunity charging "
                   "(charging.opportunity) or staggered charge thresholds.")
"""What to do about charging starvation (the summary's, the sweep's and the report's)."""

OUT_OF_SERVICE_ADVICE = ("Bring AGVs back sooner or lose fewer: operators and repairs "
                         "(incidents.operator_response, incidents.repair, incidents.rescue), "
                         "the faults behind it (errors_by_code), or spare AGVs.")
"""What to do about a fleet out of service."""


def stall_text(figures: Mapping[str, Any]) -> list[str]:
    """The summary's lines for charging starvation and a fleet out of service (none when the
    run had neither)."""
    lines = []
    if starved(figures):
        worst = figures.get("charging_starvation_worst")
        lines.append(
            f"  CHARGING STARVATION for {_hours(figures['charging_starvation_h'])} from "
            f"{figures['charging_starvation_at_h']:.2f} h: orders waited, no AGV free to take "
            "them, while AGVs waited for a charger"
            + (f" (at worst {worst})" if worst else "") + f". {CHARGING_ADVICE}")
    if out_of_service(figures):
        lines.append(
            f"  OUT OF SERVICE for {_hours(figures['out_of_service_h'])} from "
            f"{figures['out_of_service_at_h']:.2f} h: orders waited while every AGV was in "
            f"Error, Maintenance or SafeMode. {OUT_OF_SERVICE_ADVICE}")
    return lines


def starved(figures: Mapping[str, Any]) -> bool:
    """Did orders wait while AGVs waited for a charger? (kpis.json, or a summary row.)"""
    return _positive(figures.get("charging_starvation_h"))


def out_of_service(figures: Mapping[str, Any]) -> bool:
    """Did orders wait while every AGV was out of service? (kpis.json, or a summary row.)"""
    return _positive(figures.get("out_of_service_h"))


def _hours(value: float) -> str:
    """``0.61 h``; under 36 s, in seconds (``12 s``), so that a short spell does not read 0."""
    return f"{value:.2f} h" if value >= 0.01 else f"{value * 3600:.0f} s"


def _positive(value: Any) -> bool:
    return isinstance(value, (int, float)) and not math.isnan(value) and value > 0


def gridlocked(figures: Mapping[str, Any]) -> bool:
    """Did the run lock solid? (kpis.json, or a sweep summary row as a mapping.)"""
    at_h = figures.get("gridlock_at_h")
    return at_h is not None and not (isinstance(at_h, float) and math.isnan(at_h))


OPEN_AGE_OF = {"lead_time_mean_s": "open_order_age_mean_s",
               "lead_time_p95_s": "open_order_age_p95_s"}
"""A target on a lead-time KPI is held against the larger of it and the same statistic of
the open orders' age at the end (`target_value`)."""


def target_value(figures: Mapping[str, Any], name: str) -> Any:
    """The value a target on KPI `name` is judged by: `kpi_value`, but for a lead time the
    larger of it and the open orders' age of the same statistic (`OPEN_AGE_OF`), so that a
    fleet leaving a growing backlog cannot meet a lead-time target on the few orders it did
    deliver; with no order delivered, the open orders' age alone."""
    value = kpi_value(figures, name)
    age_name = OPEN_AGE_OF.get(name)
    age = None if age_name is None else figures.get(age_name)
    if age is None or (isinstance(age, float) and math.isnan(age)):
        return value
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return age
    return max(value, age)


def _reasons_text(by_reason: Mapping[str, float]) -> str:
    """`` (waiting_for_charger 61.2 %, link_lost 0.1 %)``: the reasons above zero."""
    shown = [f"{reason} {value:,.1f} %" for reason, value in by_reason.items() if value > 0]
    return f" ({', '.join(shown)})" if shown else ""


def target_words(target: Target) -> str:
    """A target in words, its unit from the catalogue: ``throughput at least 95 % of demand``."""
    name, _, unit = kpi_label(target.kpi).partition(" [")
    unit = unit.removesuffix("]")
    relation = "at least" if target.higher_is_better else "at most"
    return f"{name} {relation} {number_text(target.bound)}" + (f" {unit}" if unit else "")
