"""The KPI catalogue: the one place that names each KPI, says what it measures and in what unit,
and reads it back from a run's figures.

`KpiSums` (fleet_sim.analysis.kpi_sums) computes every KPI listed here, the same way for
`fleet-sim run`, every run of a sweep and every run of a sizing search; unless said otherwise a
KPI is measured over the window from the end of the warm-up to the end of the run. `CATALOGUE`
lists them with unit and meaning without running anything, so that an experiment's targets can
be checked before its runs start. Beside it: a KPI's name in a planner's words (`kpi_label`),
which way it is better (`kpi_better`), its value in a kpis.json (`kpi_value`, `target_value`)
and the advice that goes with a stall.

The choices where the issue was silent: docs/background/decisions/analysis-and-studies.md.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

from fleet_sim.analysis.paired import number_text
from fleet_sim.config.experiment import Target
from fleet_sim.model.error_codes import CODES
from fleet_sim.model.not_dispatched import NotDispatched
from fleet_sim.model.states import VehicleState

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


# ---- reading a run's figures ----------------------------------------------------------------


def starved(figures: Mapping[str, Any]) -> bool:
    """Did orders wait while AGVs waited for a charger? (kpis.json, or a summary row.)"""
    return _positive(figures.get("charging_starvation_h"))


def out_of_service(figures: Mapping[str, Any]) -> bool:
    """Did orders wait while every AGV was out of service? (kpis.json, or a summary row.)"""
    return _positive(figures.get("out_of_service_h"))


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


def target_words(target: Target) -> str:
    """A target in words, its unit from the catalogue: ``throughput at least 95 % of demand``."""
    name, _, unit = kpi_label(target.kpi).partition(" [")
    unit = unit.removesuffix("]")
    relation = "at least" if target.higher_is_better else "at most"
    return f"{name} {relation} {number_text(target.bound)}" + (f" {unit}" if unit else "")


CHARGING_ADVICE = ("Spread the charging: more chargers, opportunity charging "
                   "(charging.opportunity) or staggered charge thresholds.")
"""What to do about charging starvation (the summary's, the sweep's and the report's)."""

OUT_OF_SERVICE_ADVICE = ("Bring AGVs back sooner or lose fewer: operators and repairs "
                         "(incidents.operator_response, incidents.repair, incidents.rescue), "
                         "the faults behind it (errors_by_code), or spare AGVs.")
"""What to do about a fleet out of service."""
