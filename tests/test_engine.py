"""The engine itself (fleet_sim.sim.engine): building the model from a scenario, the run's
records adding up, determinism (same seed, same bytes), the progress callback."""

from __future__ import annotations

from pathlib import Path

import pytest

from fleet_sim.analysis.kpis import run_kpis
from fleet_sim.analysis.tables import orders_table, write_run
from fleet_sim.config.layout import Layout
from fleet_sim.sim.engine import build_model, simulate

from .conftest import HALF_LOOP_S, make_scenario

__all__ = ["HALF_LOOP_S"]  # test_sizing imports it from here; it lives in conftest now


def test_the_fleet_starts_in_parking_or_on_its_start_nodes(warehouse_layout: Layout,
                                                           tiny_layout: Layout) -> None:
    """Without start nodes, AGVs fill the parking places in layout order (tiny loop: PARK at K,
    4 places); with them, each AGV stands on its node, holding it."""
    scenario = make_scenario(duration_h=0.1, warmup_h=0, fleet={"size": 3},
                             demand={"rate_per_hour": 0})
    model = build_model(scenario, tiny_layout)
    assert [v.id for v in model.vehicles] == [0, 1, 2]
    assert [(v.node, v.parked_in.id if v.parked_in else None) for v in model.vehicles] == \
        [("K", "PARK")] * 3
    assert model.fleet.parking_free == {"PARK": 1}
    assert model.traffic.node_locks["K"].is_free  # parked AGVs are off the track
    placed = build_model(make_scenario(duration_h=0.1, warmup_h=0, demand={"rate_per_hour": 0},
                                       fleet={"size": 2, "start_nodes": ["S1", "N3"]}),
                         tiny_layout)
    assert [(v.node, v.parked_in) for v in placed.vehicles] == [("S1", None), ("N3", None)]
    assert not placed.traffic.node_locks["S1"].is_free
    assert not placed.traffic.node_locks["N3"].is_free
    assert placed.fleet.parking_free == {"PARK": 4}


def test_progress_is_reported_twenty_times_up_to_the_end(tiny_layout: Layout) -> None:
    scenario = make_scenario(duration_h=0.5, warmup_h=0, fleet={"size": 1},
                             demand={"rate_per_hour": 30})
    calls: list[tuple[float, float]] = []
    simulate(scenario, tiny_layout, progress=lambda now, end: calls.append((now, end)))
    assert calls == [(90.0 * k, 1800.0) for k in range(1, 21)]


def test_throughput_equals_completed_orders_over_time(warehouse_layout: Layout) -> None:
    scenario = make_scenario("warehouse.yaml", duration_h=3, warmup_h=0.5, seed=3,
                             fleet={"size": 8}, demand={"rate_per_hour": 60})
    run = simulate(scenario, warehouse_layout)
    orders = orders_table(run.recorder)
    figures = run_kpis(run)
    done = orders["delivered_s"].between(1800.0, 3 * 3600.0)
    assert done.sum() > 50
    assert figures["throughput_per_hour"] == pytest.approx(done.sum() / 2.5, rel=1e-9)
    assert figures["orders_completed"] == int(orders["delivered_s"].notna().sum())
    lead = orders.loc[done, "delivered_s"] - orders.loc[done, "created_s"]
    assert figures["lead_time_mean_s"] == pytest.approx(lead.mean(), rel=1e-6)
    # every AGV's time in states adds up to the window
    shares = sum(v for k, v in figures.items() if k.startswith("state_"))
    assert shares == pytest.approx(100.0, abs=1e-4)  # each share is rounded to 1e-6


def test_same_seed_same_bytes_other_seed_other_results(tmp_path: Path,
                                                        warehouse_layout: Layout) -> None:
    def run_to(folder: str, seed: int) -> Path:
        scenario = make_scenario("warehouse.yaml", duration_h=1.5, warmup_h=0.25, seed=seed,
                                 fleet={"size": 10}, demand={"rate_per_hour": 100})
        out = tmp_path / folder
        run = simulate(scenario, warehouse_layout)
        write_run(run, out, run_kpis(run))
        return out

    a, b, c = run_to("a", 21), run_to("b", 21), run_to("c", 22)
    for name in ("events.parquet", "orders.parquet", "kpis.json", "config.resolved.yaml"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    assert (a / "orders.parquet").read_bytes() != (c / "orders.parquet").read_bytes()
