"""A run's KPIs as a short text for the terminal (`fleet-sim run`), with a warning for a
gridlock and for each stall and what to do about it."""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Any

from fleet_sim.analysis.kpis import (
    BY_REASON,
    CHARGING_ADVICE,
    OUT_OF_SERVICE_ADVICE,
    out_of_service,
    starved,
)


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


def _hours(value: float) -> str:
    """``0.61 h``; under 36 s, in seconds (``12 s``), so that a short spell does not read 0."""
    return f"{value:.2f} h" if value >= 0.01 else f"{value * 3600:.0f} s"


def _reasons_text(by_reason: Mapping[str, float]) -> str:
    """`` (waiting_for_charger 61.2 %, link_lost 0.1 %)``: the reasons above zero."""
    shown = [f"{reason} {value:,.1f} %" for reason, value in by_reason.items() if value > 0]
    return f" ({', '.join(shown)})" if shown else ""
