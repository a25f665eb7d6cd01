"""The fleet manager's commands cost the real link's time (issue 4 item 6)."""

from __future__ import annotations

import itertools

import pytest

from agv_model.fleet_commands import CommandTiming
from fleet_sim.analysis.kpi_sums import run_kpis
from fleet_sim.config.layout import Layout
from fleet_sim.config.scenario import load_layout_for, load_scenario
from fleet_sim.config.trace import TraceOrder
from fleet_sim.errors import InputError
from fleet_sim.sim.engine import RunOutput, simulate

from .conftest import DROP_S, HALF_LOOP_S, K_TO_P_S, PICK_S, ROOT, make_scenario

ONE_ORDER = [TraceOrder(100.0, "PICK", "DROP")]


def lead_time(layout: Layout, **fleet: object) -> float:
    scenario = make_scenario(duration_h=0.2, warmup_h=0.0, fleet={"size": 1, **fleet},
                             demand={"kind": "trace", "trace_csv": "x.csv"})
    order = simulate(scenario, layout, ONE_ORDER).recorder.orders[0]
    assert order.delivered_s is not None
    return order.delivered_s - order.created_s


HAND_S = K_TO_P_S + PICK_S + HALF_LOOP_S + DROP_S
"""The lead time of ONE_ORDER by hand, commands taking no time."""


@pytest.mark.parametrize(("profile", "starts"), [("carriro-ad-plus", 0), ("ktm-02", 2),
                                                 ("agv-3", 0)])
def test_an_assignment_costs_one_assign_round_trip(tiny_layout: Layout, profile: str,
                                                   starts: int) -> None:
    """One assign round trip; and where the protocol's vehicle is granted its route hop by
    hop (KTM-02; traffic.grants auto), one permission (resume) round trip at each of
    the two starts from a standstill (out of parking, out of the pickup): every other hop's
    permission travels while the AGV drives the hop before."""
    assert lead_time(tiny_layout) == pytest.approx(HAND_S, abs=1e-9)
    timing = CommandTiming.for_profile(profile)
    assign_s, resume_s = timing.round_trip_s("assign"), timing.round_trip_s("resume")
    assert assign_s > 0.005
    assert lead_time(tiny_layout, command_profile=profile) == pytest.approx(
        HAND_S + assign_s + starts * resume_s, abs=1e-9)


@pytest.mark.parametrize(("profile", "grants", "starts"), [
    ("ktm-02", "whole_route", 0), ("carriro-ad-plus", "per_hop", 2)])
def test_the_grants_switch_overrides_the_protocols_reading(
        tiny_layout: Layout, profile: str, grants: str, starts: int) -> None:
    timing = CommandTiming.for_profile(profile)
    scenario = make_scenario(duration_h=0.2, warmup_h=0.0,
                             fleet={"size": 1, "command_profile": profile},
                             traffic={"grants": grants},
                             demand={"kind": "trace", "trace_csv": "x.csv"})
    order = simulate(scenario, tiny_layout, ONE_ORDER).recorder.orders[0]
    assert order.delivered_s is not None
    assert order.delivered_s - order.created_s == pytest.approx(
        HAND_S + timing.round_trip_s("assign") + starts * timing.round_trip_s("resume"),
        abs=1e-9)


def test_status_polling_delays_what_the_fleet_manager_knows(tiny_layout: Layout) -> None:
    """One AGV with orders always waiting: each new order reaches it only after the next poll
    has shown it free, then one assign round trip."""
    timing = CommandTiming.for_profile("carriro-ad-plus")
    poll_s = 20.0
    scenario = make_scenario(duration_h=1.0, warmup_h=0.0,
                             fleet={"size": 1, "command_profile": "carriro-ad-plus",
                                    "status_poll_s": poll_s},
                             demand={"kind": "trace", "trace_csv": "x.csv"})
    run = simulate(scenario, tiny_layout, [TraceOrder(0.0, "PICK", "DROP")] * 12)
    done = sorted(o.delivered_s for o in run.recorder.orders if o.delivered_s is not None)
    gaps = [b - a for a, b in itertools.pairwise(done)]
    assert len(gaps) >= 5
    cycle = 2 * HALF_LOOP_S + PICK_S + DROP_S
    least = cycle + timing.reply_s("status") + timing.round_trip_s("assign")
    for gap in gaps:
        assert least - 1e-9 <= gap <= least + poll_s + 1e-9
    assert sum(gaps) / len(gaps) > least + 1.0  # waiting for polls costs time on average
    figures = run_kpis(run)
    assert figures["commands_sent"] == len(run.recorder.orders) + 1  # an assign each, boot
    assert figures["command_retries"] == 0


def test_polling_period_shows_in_lead_times(tiny_layout: Layout) -> None:
    def mean_lead(poll_s: float) -> float:
        scenario = make_scenario(duration_h=6, warmup_h=0.5, seed=4, fleet={
            "size": 2, "command_profile": "rss-agv-001", "status_poll_s": poll_s},
            demand={"rate_per_hour": 45})
        run = simulate(scenario, tiny_layout)
        value = run_kpis(run)["lead_time_mean_s"]
        assert isinstance(value, float)
        return value

    assert mean_lead(0.0) < mean_lead(10.0) < mean_lead(60.0)


def test_unknown_command_profile_is_an_input_error() -> None:
    with pytest.raises(InputError, match=r"fleet.command_profile: got 'carrot'; expected one "
                                         r"of .*carriro-ad-plus"):
        make_scenario(fleet={"command_profile": "carrot"})


# ---- every vehicle over its own protocol (issue 33, item 4) ---------------------------------
MIXED = [{"type": "carriro", "count": 1, "profile": "carriro-ad-plus"},
         {"type": "ktm", "count": 1, "profile": "ktm-02"}]
"""AGV 0 a CarriRo AD+, AGV 1 a KTM-02."""


def mixed_run(layout: Layout, vehicles: list[dict[str, object]], trace: list[TraceOrder],
              **settings: object) -> RunOutput:
    fleet = {"vehicles": vehicles, **settings.pop("fleet", {})}  # type: ignore[dict-item]
    scenario = make_scenario(duration_h=0.5, warmup_h=0.0, fleet=fleet,
                             demand={"kind": "trace", "trace_csv": "x.csv"}, **settings)
    return simulate(scenario, layout, trace)


def assign_delays(run: RunOutput) -> dict[int, set[float]]:
    """AGV -> the times from the fleet manager's decision (order.assigned_s) to the AGV
    having the order (its order_assigned event), rounded to the microsecond."""
    got = {e.detail.split()[1]: e.time_s for e in run.recorder.events
           if e.event == "order_assigned"}
    out: dict[int, set[float]] = {}
    for order in run.recorder.orders:
        if order.assigned_s is not None and order.agv is not None:
            out.setdefault(order.agv, set()).add(
                round(got[str(order.id)] - order.assigned_s, 6))
    return out


ORDERS = [TraceOrder(100.0 + 60.0 * i, "PICK", "DROP") for i in range(6)]


def test_each_type_is_timed_on_its_own_protocol_and_link(tiny_layout: Layout) -> None:
    """A CarriRo AD+ and a KTM-02 in one fleet: each order reaches its AGV one assign round
    trip of that AGV's own protocol after the fleet manager decided (CarriRo: two ASCII
    exchanges at 19200 bit/s with 10 ms host gaps; KTM-02: one binary frame at 115200)."""
    carriro = round(CommandTiming.for_profile("carriro-ad-plus").round_trip_s("assign"), 6)
    ktm = round(CommandTiming.for_profile("ktm-02").round_trip_s("assign"), 6)
    assert carriro > 5 * ktm > 0
    assert assign_delays(mixed_run(tiny_layout, MIXED, ORDERS)) == {0: {carriro}, 1: {ktm}}


def test_the_switch_turns_command_timing_off(tiny_layout: Layout) -> None:
    for off in ("off", False):  # YAML reads `off` as false
        run = mixed_run(tiny_layout, MIXED, ORDERS, fleet={"command_timing": off})
        assert assign_delays(run) == {0: {0.0}, 1: {0.0}}
        assert run_kpis(run)["commands_sent"] == 0


def test_a_type_without_a_protocol_keeps_instant_commands(tiny_layout: Layout) -> None:
    """The generic RSS-AGV-001 profile (protocol null) and a type without a profile."""
    plain = [{"type": "generic", "count": 1, "profile": "rss-agv-001"},
             {"type": "plain", "count": 1}]
    run = mixed_run(tiny_layout, plain, ORDERS)
    assert assign_delays(run) == {0: {0.0}, 1: {0.0}}
    assert run_kpis(run)["commands_sent"] == 0


def test_the_boot_report_costs_a_status_round_trip(tiny_layout: Layout) -> None:
    """RSS-AGV-001 4.2.1: Idle at Event_Init_Complete (5 s), the fleet manager learns it when
    the boot report is through (one status round trip); the AGV stands Idle meanwhile, not
    dispatched for command_in_transit. An order waiting from t=0 is decided then."""
    status_s = CommandTiming.for_profile("carriro-ad-plus").round_trip_s("status")
    at_start = [TraceOrder(0.0, "PICK", "DROP")]
    run = mixed_run(tiny_layout, MIXED[:1], at_start)
    assert run.recorder.orders[0].assigned_s == pytest.approx(5.0 + status_s, abs=1e-9)
    assert run_kpis(run)["commands_sent"] == 2  # the boot report, the assign
    assert [(e.time_s, e.detail) for e in run.recorder.events
            if e.event == "not_dispatched"] == [(5.0, "command_in_transit")]
    off = mixed_run(tiny_layout, MIXED[:1], at_start, fleet={"command_timing": "off"})
    assert off.recorder.orders[0].assigned_s == 5.0


@pytest.mark.parametrize("grants", ["auto", "per_hop", "whole_route"])
def test_each_hop_granted_hop_by_hop_costs_a_message(tiny_layout: Layout, grants: str) -> None:
    """A KTM-02 (hop by hop under auto): one permission per hop it drives (the loop's
    segments are 4 m each), beside the boot report and the assign."""
    run = mixed_run(tiny_layout, MIXED[1:], ONE_ORDER, traffic={"grants": grants})
    hops = run.recorder.distance_total_m / 4.0
    assert hops == 12  # parking -> pickup 3, pickup -> drop-off 6, back to parking 3
    per_hop = 0 if grants == "whole_route" else hops
    assert run_kpis(run)["commands_sent"] == 2 + per_hop


@pytest.mark.parametrize(("fleet", "message"), [
    ({"vehicles": MIXED, "command_profile": "ktm-02"},
     r"fleet.command_profile: got 'ktm-02'; expected no command_profile with fleet.vehicles"),
    ({"size": 2, "command_profile": "ktm-02", "command_timing": False},
     r"fleet.command_timing: got 'off'; expected auto with fleet.command_profile"),
    ({"size": 2, "command_timing": "sometimes"}, r"fleet.command_timing: got 'sometimes'"),
])
def test_contradictory_command_settings_are_refused(fleet: dict[str, object],
                                                    message: str) -> None:
    with pytest.raises(InputError, match=message):
        make_scenario(fleet=fleet)


def test_the_bundled_mixed_fleet_talks_over_each_types_protocol() -> None:
    """experiments/warehouse_mixed.yaml: CarriRo AD+ and KTM-02 from their real profiles, on by
    default; the generic carriers' commands take no time."""
    path = ROOT / "experiments" / "warehouse_mixed.yaml"
    scenario = load_scenario(path, {"duration_h": 2.0, "warmup_h": 0.1})
    assert scenario.fleet.command_timing == "auto"
    kinds = {t.type: t.profile for t in scenario.fleet.vehicles}
    assert kinds == {"carrier": "rss-agv-001", "carriro": "carriro-ad-plus", "ktm02": "ktm-02"}
    run = simulate(scenario, load_layout_for(scenario, str(path)))
    delays = assign_delays(run)
    by_type: dict[str, set[float]] = {}
    for agv, spans in delays.items():
        by_type.setdefault(scenario.fleet.agv_types[agv], set()).update(spans)
    assert by_type["carrier"] == {0.0}
    assert by_type["carriro"] == {round(CommandTiming.for_profile("carriro-ad-plus")
                                        .round_trip_s("assign"), 6)}
    assert by_type["ktm02"] == {round(CommandTiming.for_profile("ktm-02")
                                      .round_trip_s("assign"), 6)}
