"""Run records -> tables (pandas) -> KPIs, and the run directory on disk.

KPIs are measured over the window from the end of the warm-up to the end of the run:

* throughput_per_hour: orders delivered in the window, per hour of window.
* lead_time_mean_s / lead_time_p95_s: creation to delivery, of orders delivered in the window.
* agv_utilisation_pct: share of AGV time in the window busy with an order (assignment to delivery).
* blocked_time_pct: share of AGV time in the window spent waiting for a node or corridor.
* state_<name>_pct: share of AGV time in the window spent in each state of RSS-AGV-001.
* distance_km: distance driven in the window. orders_created / orders_completed count the run.
* availability_pct: share of AGV time in the window not in Error, Maintenance or SafeMode.
* orders_failed (lost with a failed AGV), orders_reassigned, charges, charging_queue_wait_mean_s
  (asking for a charger to getting one), obstacle_pauses, comm_losses, errors_by_code and
  warnings_by_code count the whole run.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import yaml

from fleet_sim.config.scenario import resolved
from fleet_sim.model.records import EVENT_COLUMNS
from fleet_sim.model.states import VehicleState
from fleet_sim.sim.engine import RunOutput

ORDER_COLUMNS = ("order_id", "created_s", "pickup", "dropoff", "pickup_node", "dropoff_node",
                 "agv", "assigned_s", "pickup_arrival_s", "picked_s", "dropoff_arrival_s",
                 "delivered_s", "pickup_handling_s", "dropoff_handling_s", "lead_time_s",
                 "failed_s", "failure", "reassigned")
DOWN_STATES = (VehicleState.ERROR, VehicleState.MAINTENANCE, VehicleState.SAFE_MODE)
"""States in which an AGV is not available (availability_pct)."""


def events_table(run: RunOutput) -> pd.DataFrame:
    frame = pd.DataFrame(run.recorder.events, columns=list(EVENT_COLUMNS))
    return frame.astype({"time_s": "float64", "agv": "int64", "event": "string",
                         "from_state": "string", "to_state": "string", "node": "string",
                         "detail": "string"})


def orders_table(run: RunOutput) -> pd.DataFrame:
    rows = [
        (o.id, o.created_s, o.pickup, o.dropoff, o.pickup_node, o.dropoff_node, o.agv,
         o.assigned_s, o.pickup_arrival_s, o.picked_s, o.dropoff_arrival_s, o.delivered_s,
         o.pickup_handling_s, o.dropoff_handling_s,
         None if o.delivered_s is None else o.delivered_s - o.created_s,
         o.failed_s, o.failure, o.reassigned)
        for o in run.recorder.orders
    ]
    frame = pd.DataFrame(rows, columns=list(ORDER_COLUMNS))
    floats = [c for c in ORDER_COLUMNS if c.endswith("_s")]
    frame[floats] = frame[floats].astype("float64")
    frame["agv"] = frame["agv"].astype("Int64")
    frame["reassigned"] = frame["reassigned"].astype("int64")
    for column in ("pickup", "dropoff", "pickup_node", "dropoff_node", "failure"):
        frame[column] = frame[column].astype("string")
    return frame


def soc_table(run: RunOutput) -> pd.DataFrame:
    """State of charge of every AGV at each of its state changes (for battery plots)."""
    frame = pd.DataFrame(run.recorder.soc_samples, columns=["time_s", "agv", "soc_pct"])
    return frame.astype({"time_s": "float64", "agv": "int64", "soc_pct": "float64"})


def state_seconds(events: pd.DataFrame, n_agvs: int, start_s: float,
                  end_s: float) -> dict[str, float]:
    """Total AGV-seconds in each state within [start_s, end_s], from the transition events."""
    totals = {s.value: 0.0 for s in VehicleState}
    changes = events[events["from_state"] != events["to_state"]]
    for _, group in changes.groupby("agv", sort=True):
        times = group["time_s"].to_numpy()
        states = group["to_state"].to_numpy()
        ends = np.append(times[1:], end_s)
        starts = np.clip(times, start_s, end_s)
        stops = np.clip(ends, start_s, end_s)
        for state, span in zip(states, stops - starts, strict=True):
            totals[str(state)] += float(span)
    return totals


def kpis(run: RunOutput, events: pd.DataFrame, orders: pd.DataFrame) -> dict[str, Any]:
    scenario = run.scenario
    rec = run.recorder
    start, end = scenario.warmup_s, scenario.duration_s
    window_h = (end - start) / 3600.0
    n_agvs = len(run.vehicles)
    agv_s = n_agvs * (end - start)
    delivered = orders[orders["delivered_s"].notna()]
    in_window = delivered[(delivered["delivered_s"] >= start) & (delivered["delivered_s"] <= end)]
    lead = in_window["lead_time_s"].to_numpy()
    busy_from = orders["assigned_s"].to_numpy(dtype=float, na_value=np.nan)
    busy_to = orders["delivered_s"].to_numpy(dtype=float, na_value=np.nan)
    failed = orders["failed_s"].to_numpy(dtype=float, na_value=np.nan)
    busy_to = np.where(np.isnan(busy_to), failed, busy_to)
    busy_to = np.where(np.isnan(busy_to), end, busy_to)
    busy = np.clip(busy_to, start, end) - np.clip(busy_from, start, end)
    busy_s = float(np.nansum(busy))
    waits = orders["assigned_s"] - orders["created_s"]
    states = state_seconds(events, n_agvs, start, end)
    out: dict[str, Any] = {
        "scenario": scenario.name,
        "layout": run.layout.name,
        "agvs": n_agvs,
        "seed": scenario.seed,
        "duration_h": scenario.duration_h,
        "warmup_h": scenario.warmup_h,
        "orders_created": len(orders),
        "orders_completed": len(delivered),
        "throughput_per_hour": _round(len(in_window) / window_h),
        "lead_time_mean_s": _round(float(lead.mean())) if len(lead) else None,
        "lead_time_p95_s": _round(float(np.percentile(lead, 95))) if len(lead) else None,
        "agv_utilisation_pct": _round(100.0 * busy_s / agv_s),
        "blocked_time_pct": _round(100.0 * rec.blocked_s / agv_s),
        "deadlocks_detected": rec.deadlocks,
        "distance_km": _round(rec.distance_m / 1000.0),
        "order_wait_mean_s": _round(float(waits.mean())) if waits.notna().any() else None,
        "order_queue_mean": _round(queue_mean(rec.queue_lengths, start, end)),
    }
    for state in VehicleState:
        out[f"state_{state.key}_pct"] = _round(100.0 * states[state.value] / agv_s)
    down = sum(states[s.value] for s in DOWN_STATES)
    charge_waits = [b - a for a, b in rec.charge_waits]
    errors: dict[str, int] = {}
    for _, _, code, _ in rec.errors:
        errors[code] = errors.get(code, 0) + 1
    out.update({
        "availability_pct": _round(100.0 * (1.0 - down / agv_s)),
        "orders_failed": int(orders["failed_s"].notna().sum()),
        "orders_reassigned": int(orders["reassigned"].sum()),
        "charges": len(charge_waits),
        "charging_queue_wait_mean_s": _round(float(np.mean(charge_waits))) if charge_waits
        else None,
        "commands_sent": rec.commands_sent,
        "command_retries": rec.command_retries,
        "obstacle_pauses": rec.obstacle_pauses,
        "comm_losses": rec.comm_losses,
        "errors_by_code": dict(sorted(errors.items())),
        "warnings_by_code": dict(sorted(rec.warnings.items())),
    })
    return out


def queue_mean(trace: list[tuple[float, int]], start_s: float, end_s: float) -> float:
    """Time-average of a step function given as (time, value) changes, over [start_s, end_s]."""
    total = 0.0
    for (t0, value), (t1, _) in zip(trace, [*trace[1:], (end_s, 0)], strict=True):
        total += value * max(0.0, min(t1, end_s) - max(t0, start_s))
    return total / (end_s - start_s)


def _round(value: float) -> float:
    return float(round(value, 6)) if math.isfinite(value) else value


def write_run(run: RunOutput, out_dir: Path) -> dict[str, Any]:
    """Write the run directory; returns the KPIs."""
    out_dir.mkdir(parents=True, exist_ok=True)
    events = events_table(run)
    orders = orders_table(run)
    figures = kpis(run, events, orders)
    (out_dir / "config.resolved.yaml").write_text(
        yaml.safe_dump(resolved(run.scenario), sort_keys=False, allow_unicode=True),
        encoding="utf-8")
    (out_dir / "kpis.json").write_text(json.dumps(figures, indent=2) + "\n", encoding="utf-8")
    events.to_parquet(out_dir / "events.parquet", index=False)
    orders.to_parquet(out_dir / "orders.parquet", index=False)
    soc_table(run).to_parquet(out_dir / "soc.parquet", index=False)
    info = {"wall_s": round(run.wall_s, 3), "sim_events": run.sim_events,
            "sim_hours_per_wall_s": round(run.scenario.duration_h / max(run.wall_s, 1e-9), 3)}
    (out_dir / "run_info.json").write_text(json.dumps(info, indent=2) + "\n", encoding="utf-8")
    return figures


def summary(figures: dict[str, Any]) -> str:
    """A short text summary of the KPIs for the terminal."""
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
