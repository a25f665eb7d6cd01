"""The replay: the moves the engine records (and that they change nothing), positions at any
time against the engine's own traversals and kinematics, lock waits against the engine's blocked
time, the timeline and the lead-time breakdown, re-simulation of a run without moves, and the
page itself in a real headless Chromium (positions drawn, a screenshot, no network request)."""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import subprocess
import typing
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest
import yaml

from fleet_sim.analysis.kpi_sums import run_kpis
from fleet_sim.analysis.replay import (
    LEAD_PARTS,
    MOVES_FILE,
    hop_pieces,
    lead_times,
    load_run,
    moves_table,
    positions_at,
    state_spells,
    zone_holders_at,
)
from fleet_sim.analysis.tables import events_table, orders_table
from fleet_sim.cli import main
from fleet_sim.config.scenario import load_layout_for, load_scenario
from fleet_sim.errors import InputError
from fleet_sim.model.kinematics import distance_at, traverse
from fleet_sim.report import replay_payload
from fleet_sim.report.replay import page_data, write_replay
from fleet_sim.sim.engine import RunOutput, simulate

from .conftest import DATA, LAYOUTS, ROOT, write_yaml

STATIC = ROOT / "fleet_sim" / "report" / "static"
HOURS = 1.5


def _scenario_file(tmp: Path) -> Path:
    """The warehouse with every incident that moves or stops an AGV: obstacles (pauses mid
    segment), a scripted block, random and scripted faults, charging early enough to queue."""
    return write_yaml(tmp / "incidents.yaml", {
        "name": "replay_incidents", "layout": str(LAYOUTS / "warehouse_wifi.yaml"),
        "duration_h": HOURS, "warmup_h": 0.25, "seed": 7, "start_h": 6,
        "fleet": {"size": 12}, "demand": {"rate_per_hour": 90},
        "charging": {"threshold_pct": 88},
        "incidents": {
            "obstacle_rate_per_km": 4.0,
            "obstacle_duration": {"dist": "exponential", "mean_s": 4},
            "blocks": [{"from": "M011", "to": "A05_04", "at_s": 1800, "duration_s": 600}],
            "mtbf_h": 4, "faults": [{"agv": 2, "at_s": 2000, "code": "E_999"}],
            "line_loss_per_km": 0.2, "transfer_failure_prob": 0.005}})


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, RunOutput]:
    """`fleet-sim run --replay` into a run directory, and the same run in memory with the
    engine's occupancy trace (node holds and segment traversals) as well."""
    tmp = tmp_path_factory.mktemp("replay")
    scenario_file = _scenario_file(tmp)
    run_dir = tmp / "run"
    assert main(["run", str(scenario_file), "--out", str(run_dir), "--replay", "--quiet"]) == 0
    scenario = load_scenario(scenario_file)
    run = simulate(scenario, load_layout_for(scenario, str(scenario_file)),
                   record_occupancy=True, record_moves=True)
    return run_dir, run


# ---- what the engine records -------------------------------------------------------------------


def test_run_with_replay_writes_its_files(recorded: tuple[Path, RunOutput]) -> None:
    run_dir, run = recorded
    assert (run_dir / MOVES_FILE).is_file() and (run_dir / "replay.html").is_file()
    on_disk = pd.read_parquet(run_dir / MOVES_FILE)
    assert on_disk.equals(moves_table(run.recorder))
    kinds = set(on_disk["kind"])
    assert kinds == {"drive", "wait", "track", "parking", "off", "charger_wait"}


def test_recording_moves_changes_nothing(recorded: tuple[Path, RunOutput]) -> None:
    """The same run without moves and occupancy: the same events, orders and KPIs."""
    run_dir, traced = recorded
    plain = simulate(traced.scenario, traced.layout)
    assert events_table(plain.recorder).equals(events_table(traced.recorder))
    assert orders_table(plain.recorder).equals(orders_table(traced.recorder))
    assert run_kpis(plain) == run_kpis(traced)
    assert json.loads((run_dir / "kpis.json").read_text()) == json.loads(
        json.dumps(run_kpis(plain)))


def test_lock_waits_are_the_engines_blocked_time(recorded: tuple[Path, RunOutput]) -> None:
    _, run = recorded
    recorder = run.recorder
    waits = [m for m in recorder.moves if m.kind == "wait"]
    # a wait still going on at the end counts up to the end, in the engine as here
    total = sum(recorder.window(m.start_s, m.end_s) for m in waits)
    assert total > 100.0
    assert total == pytest.approx(recorder.blocked_s, rel=1e-9)


def test_each_drive_reproduces_the_engines_hop_time(recorded: tuple[Path, RunOutput]) -> None:
    """The recorded profile (pieces, entry and exit speed) gives back the hop's closed-form time
    and exit speed, and a hop driven without a stop takes exactly that time."""
    _, run = recorded
    vehicle = run.scenario.fleet.vehicle
    graph = run.layout.graph
    whole = 0
    for m in (m for m in run.recorder.moves if m.kind == "drive"):
        pieces = hop_pieces(graph.edges[m.u, m.v]["length_m"], m.curve_m, m.curve_mps,
                            m.limit_mps)
        assert (m.accel_mps2, m.decel_mps2) == (vehicle.accel_mps2, vehicle.decel_mps2)
        time_s, v_end = traverse(pieces, m.v_in_mps, m.v_out_mps, vehicle.accel_mps2,
                                 vehicle.decel_mps2)
        assert time_s == pytest.approx(m.hop_s, rel=1e-12, abs=1e-12)
        assert v_end == pytest.approx(m.v_out_mps, rel=1e-12, abs=1e-12)
        assert m.driven_s + (m.end_s - m.start_s) <= m.hop_s + 1e-6
        if m.driven_s == 0.0 and m.end_s - m.start_s == pytest.approx(m.hop_s, abs=1e-9):
            whole += 1
    assert whole > 1000


def test_positions_follow_the_engines_segment_traversals(
        recorded: tuple[Path, RunOutput]) -> None:
    """At the start of every traversal the engine records (its occupancy trace, kept apart from
    the moves) the AGV is at the segment's first node, at its end at the second; in between it
    is on the segment, as far along as the closed-form profile says."""
    _, run = recorded
    moves = moves_table(run.recorder)
    vehicle = run.scenario.fleet.vehicle
    layout = run.layout
    spells = [o for o in run.recorder.occupancy if o.kind == "segment"]
    rng = np.random.default_rng(3)
    for k in rng.choice(len(spells), size=60, replace=False):
        spell = spells[int(k)]
        u, v = spell.key.split(">")
        mine = moves[moves["agv"] == spell.agv]
        start = positions_at(mine, layout, spell.start_s)[spell.agv]
        end = positions_at(mine, layout, spell.end_s)[spell.agv]
        assert (start.x_m, start.y_m) == pytest.approx(layout.position(u), abs=1e-9)
        assert (end.x_m, end.y_m) == pytest.approx(layout.position(v), abs=1e-9)
        assert end.node == v  # at v, or setting off from it when it passes through
        drives = mine[(mine["kind"] == "drive") & (mine["u"] == u) & (mine["v"] == v)
                      & (mine["start_s"] >= spell.start_s - 1e-9)
                      & (mine["end_s"] <= spell.end_s + 1e-9)]
        assert len(drives) >= 1
        row = drives.iloc[0]
        t = float(row["start_s"]) + 0.5 * (float(row["end_s"]) - float(row["start_s"]))
        mid = positions_at(mine, layout, t)[spell.agv]
        pieces = hop_pieces(layout.graph.edges[u, v]["length_m"], float(row["curve_m"]),
                            float(row["curve_mps"]), float(row["limit_mps"]))
        along = distance_at(pieces, float(row["v_in_mps"]), float(row["v_out_mps"]),
                            vehicle.accel_mps2, vehicle.decel_mps2,
                            float(row["driven_s"]) + t - float(row["start_s"]))
        assert mid.node == u and mid.to_node == v
        assert mid.along_m == pytest.approx(along, abs=1e-9)
        assert 0.0 < along < layout.graph.edges[u, v]["length_m"]


def test_an_obstacle_pause_holds_the_agv_mid_segment(recorded: tuple[Path, RunOutput]) -> None:
    """Paused (4.2.3) on a segment: the AGV stands where it stopped until it drives on."""
    _, run = recorded
    moves = moves_table(run.recorder)
    events = events_table(run.recorder)
    paused = events[events["to_state"] == "Paused"]
    resumed = events[(events["from_state"] == "Paused") & (events["to_state"] != "Paused")]
    mid_segment = 0
    for agv, t in zip(paused["agv"], paused["time_s"], strict=True):
        later = resumed[(resumed["agv"] == agv) & (resumed["time_s"] >= t)]["time_s"]
        if later.empty:  # paused still at the end of the run
            continue
        until = float(later.iloc[0])
        mine = moves[moves["agv"] == agv]
        here = [positions_at(mine, run.layout, float(s))[int(agv)]
                for s in np.linspace(t, until, 4)]
        assert len({(p.x_m, p.y_m) for p in here}) == 1  # it does not move
        if here[0].to_node:
            length = run.layout.graph.edges[here[0].node, here[0].to_node]["length_m"]
            assert 0.0 < here[0].along_m < length
            mid_segment += 1
    assert mid_segment >= 10


def test_a_fault_stops_the_agv_where_it_is(recorded: tuple[Path, RunOutput]) -> None:
    """Error: the AGV stays where it stopped; taken off the track (Maintenance) it is drawn
    there, off the track, until it is put back."""
    _, run = recorded
    moves = moves_table(run.recorder)
    events = events_table(run.recorder)
    checked = 0
    for agv, t in zip(events[events["event"] == "Event_Critical_Error"]["agv"],
                      events[events["event"] == "Event_Critical_Error"]["time_s"], strict=True):
        mine = moves[moves["agv"] == agv]
        off = mine[(mine["kind"] == "off") & (mine["start_s"] >= t)]
        at_fault = positions_at(mine, run.layout, float(t))[int(agv)]
        if off.empty or at_fault.where != "track":
            continue
        taken = float(off["start_s"].iloc[0])
        later = positions_at(mine, run.layout, taken + 1.0)[int(agv)]
        assert later.where == "off"
        assert (later.x_m, later.y_m) == pytest.approx((at_fault.x_m, at_fault.y_m), abs=1e-9)
        checked += 1
    assert checked >= 2


# ---- timeline and lead times -------------------------------------------------------------------


def test_the_timeline_covers_each_agvs_run(recorded: tuple[Path, RunOutput]) -> None:
    run_dir, run = recorded
    duration = run.scenario.duration_s
    spells = state_spells(pd.read_parquet(run_dir / "events.parquet"), 0.0, duration)
    assert set(spells["agv"]) == set(range(run.scenario.fleet.size))
    for _, mine in spells.groupby("agv"):
        assert float((mine["end_s"] - mine["start_s"]).sum()) == pytest.approx(duration)
        assert np.allclose(mine["start_s"].to_numpy()[1:], mine["end_s"].to_numpy()[:-1])
    window = state_spells(pd.read_parquet(run_dir / "events.parquet"), 1000.0, 2500.0)
    assert np.allclose(window.groupby("agv").apply(
        lambda g: (g["end_s"] - g["start_s"]).sum()), 1500.0)
    loaded = spells[spells["loaded"]]
    assert set(loaded["state"]) <= {"Moving", "Paused", "Unloading", "Error"}
    assert (loaded["order_id"] >= 0).all()


def test_lead_time_parts_add_up_to_the_kpi(recorded: tuple[Path, RunOutput]) -> None:
    run_dir, run = recorded
    scenario = run.scenario
    leads = lead_times(pd.read_parquet(run_dir / "orders.parquet"),
                       pd.read_parquet(run_dir / MOVES_FILE), scenario.warmup_s,
                       scenario.duration_s)
    assert len(leads) > 50
    parts = leads[list(LEAD_PARTS)]
    assert (parts >= -1e-9).all().all()
    assert np.allclose(parts.sum(axis=1), leads["lead_time_s"], atol=1e-6)
    kpis = json.loads((run_dir / "kpis.json").read_text())
    assert leads["lead_time_s"].mean() == pytest.approx(kpis["lead_time_mean_s"], abs=1e-5)
    assert leads["blocked_s"].sum() > 0
    unknown = lead_times(pd.read_parquet(run_dir / "orders.parquet"), None,
                         scenario.warmup_s, scenario.duration_s)
    assert unknown["blocked_s"].isna().all()
    assert np.allclose(unknown[list(LEAD_PARTS[:-1])].sum(axis=1), unknown["lead_time_s"])


# ---- a run without moves ------------------------------------------------------------------------


def test_a_run_without_moves_is_simulated_again(recorded: tuple[Path, RunOutput],
                                                tmp_path: Path) -> None:
    run_dir, _ = recorded
    copy = tmp_path / "copy"
    shutil.copytree(run_dir, copy)
    (copy / MOVES_FILE).unlink()
    (copy / "replay.html").unlink()
    again = load_run(copy)
    assert again.resimulated
    assert again.moves.equals(pd.read_parquet(run_dir / MOVES_FILE))
    assert not (copy / MOVES_FILE).exists()  # re-simulating costs no disk
    events = pd.read_parquet(copy / "events.parquet")
    events.iloc[:-1].to_parquet(copy / "events.parquet", index=False)
    with pytest.raises(InputError, match="cannot be reproduced"):
        load_run(copy)


# ---- the kinematics twin -------------------------------------------------------------------------


def _kinematics_js() -> str:
    return (STATIC / "replay_kinematics.js").read_text(encoding="utf-8")


def test_the_pages_kinematics_are_the_pythons() -> None:
    """The JavaScript twin of distance_at (node), on random hops, to the last bits."""
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed")
    rng = np.random.default_rng(11)
    cases: list[dict[str, Any]] = []
    for _ in range(200):
        length = float(rng.uniform(0.3, 8.0))
        curve = float(rng.choice([0.0, min(1.0, length)]))
        limit, curve_mps = float(rng.choice([0.5, 1.0, 2.0])), 0.3
        pieces = hop_pieces(length, curve, curve_mps, limit)
        v_in = float(rng.choice([0.0, 0.3, min(limit, 0.7)]))
        if curve > 0:
            v_in = min(v_in, curve_mps)
        hop_s, v_out = traverse(pieces, v_in, float(rng.choice([0.0, 0.3, 1.0])), 0.5, 0.4)
        t = float(rng.uniform(-1.0, hop_s + 1.0))
        cases.append({"l": length, "c": curve, "cv": curve_mps, "lim": limit, "vin": v_in,
                      "vout": v_out, "t": t,
                      "py": distance_at(pieces, v_in, v_out, 0.5, 0.4, t)})
    script = _kinematics_js() + (
        "\nconst cases = JSON.parse(require('fs').readFileSync(0, 'utf8'));\n"
        "console.log(JSON.stringify(cases.map(c => FleetKinematics.distanceAt("
        "FleetKinematics.hopPieces(c.l, c.c, c.cv, c.lim), c.vin, c.vout, 0.5, 0.4, c.t))));\n")
    result = subprocess.run([node, "-e", script], input=json.dumps(cases), capture_output=True,
                            text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    js = json.loads(result.stdout)
    assert js == pytest.approx([c["py"] for c in cases], abs=1e-12)


# ---- the page's script and its payload ---------------------------------------------------------


@pytest.mark.parametrize("script", ["replay.js", "replay_kinematics.js"])
def test_the_pages_scripts_are_valid_javascript(script: str) -> None:
    """`node --check` on each plain script file the page inlines."""
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed")
    result = subprocess.run([node, "--check", str(STATIC / script)], capture_output=True,
                            text=True, timeout=60)
    assert result.returncode == 0, result.stderr


def test_the_scripts_payload_typedefs_are_generated_from_the_payload_types() -> None:
    """replay.js's JSDoc typedefs are those of fleet_sim.report.replay_payload today (rewrite
    them with `python -m fleet_sim.report.replay_payload`)."""
    text = (STATIC / "replay.js").read_text(encoding="utf-8")
    assert replay_payload.script_typedefs(text) == replay_payload.jsdoc()
    assert "@type {ReplayPayload}" in text


def _declared(cls: type) -> set[str]:
    return set(cls.__annotations__)


def test_the_script_reads_only_declared_payload_fields() -> None:
    """Every field the script reads off the payload's objects (through the names it gives
    them) is declared in the payload's types: a field renamed in Python fails here."""
    text = (STATIC / "replay.js").read_text(encoding="utf-8")
    p = replay_payload
    aliases = {"D": p.ReplayPayload, "M": p.Meta, "NODES": p.Nodes, "SEGS": p.Segs,
               "PROF": p.Profiles, "PLACES": p.Places, "ZONES": p.Zones, "ZH": p.ZoneHolds,
               "INC": p.Incidents, "LEADS": p.Leads, "D.chargerWaits": p.ChargerWaits}
    for alias, cls in aliases.items():
        if alias != "D":
            assert re.search(rf"\b{re.escape(alias)}\b", text), alias
        read = set(re.findall(rf"(?<![\w.]){re.escape(alias)}\.([A-Za-z_]\w*)", text))
        assert read, alias
        assert read - _declared(cls) == set(), alias


def _keys_match(value: Any, cls: type, where: str) -> None:
    assert set(value) == _declared(cls), where
    hints = typing.get_type_hints(cls)
    for name, hint in hints.items():
        if hint in replay_payload.PAYLOAD_TYPES:
            _keys_match(value[name], hint, f"{where}.{name}")
        elif typing.get_origin(hint) is list and typing.get_args(hint)[0] in \
                replay_payload.PAYLOAD_TYPES:
            for i, item in enumerate(value[name]):
                _keys_match(item, typing.get_args(hint)[0], f"{where}.{name}[{i}]")


def test_the_payload_is_what_its_types_declare(recorded: tuple[Path, RunOutput]) -> None:
    """page_data's objects have exactly the fields of their types, the lead parts too, and the
    columns of one object have one length (a row per index)."""
    run = load_run(recorded[0])
    data = page_data(run, 0.0, run.scenario.duration_s)
    _keys_match(data, replay_payload.ReplayPayload, "payload")
    assert set(LEAD_PARTS) <= _declared(replay_payload.Leads)
    for name in ("nodes", "segs", "places", "profiles", "chargerWaits", "zoneHolds",
                 "incidents"):
        assert len({len(column) for column in data[name].values()}) == 1, name
    assert len(data["agv"]) == run.scenario.fleet.size and len(data["meta"]) > 0


# ---- the page ---------------------------------------------------------------------------------


def test_the_page_is_the_same_bytes_every_time(recorded: tuple[Path, RunOutput],
                                               tmp_path: Path) -> None:
    run_dir, _ = recorded
    copy = tmp_path / "copy"
    shutil.copytree(run_dir, copy)
    first = write_replay(copy).read_bytes()
    assert first == (run_dir / "replay.html").read_bytes()
    assert write_replay(copy).read_bytes() == first
    window = write_replay(copy, 0.5, 0.75).read_bytes()
    assert window != first and len(window) < len(first)


def test_the_page_asks_for_nothing_from_the_network(recorded: tuple[Path, RunOutput]) -> None:
    html = (recorded[0] / "replay.html").read_text(encoding="utf-8")
    assert re.findall(r"(?i)(?:https?|ftp|wss?)://", html) == []
    csp = re.search(r'<meta http-equiv="Content-Security-Policy" content="([^"]+)">', html)
    assert csp and "default-src 'none'" in csp.group(1)
    assert "connect-src" not in csp.group(1)  # falls back to 'none'
    scripts = re.findall(r"<script\b[^>]*>", html)
    assert scripts == ['<script type="application/json" id="replay-data">', "<script>"]
    assert "<link" not in html and "<iframe" not in html and "src=" not in html


def chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


def _browser(args: list[str], url: str, profile: Path) -> subprocess.CompletedProcess[str]:
    browser = chromium()
    if browser is None:
        if os.environ.get("CI"):
            pytest.fail("chromium is missing (.ci/run installs it)")
        pytest.skip("chromium is not installed (apt-get install chromium)")
    return subprocess.run(
        [browser, "--headless", "--no-sandbox", "--disable-gpu", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--hide-scrollbars", "--force-device-scale-factor=1", "--window-size=1400,1100",
         f"--user-data-dir={profile}", "--virtual-time-budget=8000", *args, url],
        capture_output=True, text=True, timeout=180, stdin=subprocess.DEVNULL)


def _page_state(run_dir: Path, t: float, profile: Path, more: str = "") -> dict[str, Any]:
    import html as html_lib

    url = (run_dir / "replay.html").as_uri() + f"#t={t}{more}"
    result = _browser(["--dump-dom"], url, profile)
    assert result.returncode == 0, result.stderr[-2000:]
    found = re.search(r'<pre id="replay-check">(.*?)</pre>', result.stdout, re.S)
    assert found, result.stdout[-2000:]
    state: dict[str, Any] = json.loads(html_lib.unescape(found.group(1)))
    return state


def test_the_page_draws_every_agv_where_the_engine_had_it(
        recorded: tuple[Path, RunOutput], tmp_path: Path) -> None:
    """Headless Chromium seeks to chosen times (an AGV mid-hop, AGVs paused by an obstacle or
    waiting for a charger) and reads back positionsAt(t) and what it drew: every AGV within
    0.1 m of the engine's record; parked AGVs beside their parking node; the timeline's spells
    add up to the window for every AGV; no request made, no policy violated."""
    run_dir, run = recorded
    moves = pd.read_parquet(run_dir / MOVES_FILE)
    vehicle = run.scenario.fleet.vehicle
    events = pd.read_parquet(run_dir / "events.parquet")
    paused_at = float(events[events["to_state"] == "Paused"]["time_s"].iloc[5]) + 0.2
    waits = moves[(moves["kind"] == "charger_wait") & (moves["end_s"] - moves["start_s"] > 60)]
    queued_at = float(waits["start_s"].iloc[0]) + 30.0
    drive = moves[(moves["kind"] == "drive") & (moves["end_s"] - moves["start_s"] > 4)]
    mid_hop = float(drive["start_s"].iloc[200] + 1.7)
    window = run.scenario.duration_s
    for t in (mid_hop, paused_at, queued_at):
        state = _page_state(run_dir, t, tmp_path / "profile", "&agv=3")
        assert state["t"] == pytest.approx(t)
        assert state["resources"] == 0 and state["violations"] == []
        assert {int(k): v for k, v in state["totals"].items()} == pytest.approx(
            dict.fromkeys(range(run.scenario.fleet.size), window), abs=0.01)
        truth = positions_at(moves, run.layout, t)
        shown = {int(k): v for k, v in state["positions"].items()}
        drawn = {d["agv"]: d for d in state["drawn"]}
        assert set(shown) == set(truth) == set(drawn) == set(range(run.scenario.fleet.size))
        moving = 0
        for agv, where in truth.items():
            assert math.hypot(shown[agv]["x"] - where.x_m, shown[agv]["y"] - where.y_m) <= 0.1
            assert shown[agv]["where"] == drawn[agv]["where"] == where.where
            if where.where == "parking":  # drawn side by side beside the node
                assert math.hypot(drawn[agv]["x"] - where.x_m,
                                  drawn[agv]["y"] - where.y_m) <= 20 * vehicle.length_m
            else:
                assert math.hypot(drawn[agv]["x"] - where.x_m, drawn[agv]["y"] - where.y_m) \
                    <= 0.1
            moving += bool(where.to_node)
        assert moving >= 2
        # AGV 3 selected through the address: its state, order and SOC in the side panel
        spells = state_spells(events, 0.0, window)
        now = spells[(spells["agv"] == 3) & (spells["start_s"] <= t) & (spells["end_s"] > t)]
        info = state["info"]
        assert info.startswith(f"AGV 3  {now['state'].iloc[0]} since ")
        order = int(now["order_id"].iloc[0])
        assert f"order  {order if order >= 0 else 'none'}" in info
        soc = pd.read_parquet(run_dir / "soc.parquet")
        last = soc[(soc["agv"] == 3) & (soc["time_s"] <= t)]["soc_pct"].iloc[-1]
        assert f"SOC    {last:.1f} %" in info
    # the charger queue at queued_at names the AGV that waits
    waiting = waits.iloc[0]
    assert f"AGV {waiting['agv']} (" in state["chargers"].split("queue: ")[1]


def test_a_screenshot_shows_the_agvs_in_their_state_colours(
        recorded: tuple[Path, RunOutput], tmp_path: Path) -> None:
    import matplotlib.image

    run_dir, _ = recorded
    t = 2400.0
    state = _page_state(run_dir, t, tmp_path / "profile")
    shot = tmp_path / "shot.png"
    result = _browser([f"--screenshot={shot}"], (run_dir / "replay.html").as_uri() + f"#t={t}",
                      tmp_path / "profile")
    assert result.returncode == 0, result.stderr[-2000:]
    image = (matplotlib.image.imread(shot)[:, :, :3] * 255).round().astype(int)
    assert image.shape[:2] == (1100, 1400)
    colours = {tuple(px) for px in image[::4, ::4].reshape(-1, 3)}
    assert len(colours) > 50  # not blank
    assert (image.sum(axis=2) < 700).mean() > 0.05  # a good part of it is drawn on
    hits = 0
    for agv in state["drawn"]:
        if agv["where"] != "track":
            continue
        want = np.array([int(agv["colour"][i:i + 2], 16) for i in (1, 3, 5)])
        r = agv["r"] * 0.7
        found = False
        for dx, dy in ((r, 0), (-r, 0), (0, r), (0, -r)):
            x = round(state["floor"]["x"] + agv["sx"] + dx)
            y = round(state["floor"]["y"] + agv["sy"] + dy)
            found = found or bool(np.abs(image[y, x] - want).max() <= 3)
        hits += found
    assert hits >= 5


# ---- the command ------------------------------------------------------------------------------


@pytest.mark.parametrize(("args", "message"), [
    (["--from", "1", "--to", "0.5"], "--from: window of {run}: got 1.0; expected less than --to"),
    (["--to", "99"], "--to: window of {run}: got 99.0; expected a finite number of hours within "
                     "the run (0 to 1.5)"),
    (["--from", "1.5"], "--from: window of {run}: got 1.5; expected less than --to (1.5 h)"),
])
def test_a_bad_window_is_one_line_and_exit_2(recorded: tuple[Path, RunOutput],
                                             capsys: pytest.CaptureFixture[str],
                                             args: list[str], message: str) -> None:
    run_dir, _ = recorded
    before = (run_dir / "replay.html").stat().st_mtime_ns
    assert main(["replay", str(run_dir), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"fleet-sim: error: {message.format(run=run_dir)}"] or (
        len(err) == 1 and err[0].startswith(f"fleet-sim: error: {message.format(run=run_dir)}"))
    assert (run_dir / "replay.html").stat().st_mtime_ns == before  # nothing written


@pytest.mark.parametrize("value", ["nan", "inf", "-1", "x"])
def test_a_window_that_is_no_number_of_hours_is_refused(tmp_path: Path, value: str,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stop:
        main(["replay", str(tmp_path), "--from", value])
    assert stop.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"fleet-sim: error: argument --from: got '{value}'")


def test_not_a_run_directory(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["replay", str(tmp_path)]) == 2
    assert "expected a run directory" in capsys.readouterr().err


def test_any_sweep_run_can_be_replayed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A sweep keeps no moves: `fleet-sim replay` simulates the run again, writes the page and
    leaves no moves.parquet behind."""
    from fleet_sim.config.experiment import load_experiment
    from fleet_sim.study.run_folder import OK
    from fleet_sim.study.worker import execute_run

    scenario = write_yaml(tmp_path / "s.yaml", {
        "name": "tiny", "layout": str(LAYOUTS / "tiny_loop.yaml"), "duration_h": 0.5,
        "warmup_h": 0.1, "demand": {"rate_per_hour": 40}})
    experiment = load_experiment(write_yaml(tmp_path / "e.yaml", {
        "name": "e", "scenario": str(scenario), "factors": {"fleet.size": [2]},
        "replications": 1, "master_seed": 3}))
    spec = experiment.runs()[0]
    assert execute_run(spec, str(tmp_path / "runs")).status == OK
    run_dir = tmp_path / "runs" / spec.run_id
    assert not (run_dir / MOVES_FILE).exists()
    assert main(["replay", str(run_dir), "--quiet"]) == 0
    out = capsys.readouterr().out
    assert "replay.html" in out and "MB" in out
    assert (run_dir / "replay.html").stat().st_size > 10_000
    assert not (run_dir / MOVES_FILE).exists()
    assert '"resimulated":true' in (run_dir / "replay.html").read_text(encoding="utf-8")


def test_run_replay_with_sumo_motion_is_refused_before_the_run(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenario = write_yaml(tmp_path / "s.yaml", {
        "name": "tiny", "layout": str(LAYOUTS / "tiny_loop.yaml"), "duration_h": 0.2,
        "warmup_h": 0.1, "motion": "sumo"})
    out = tmp_path / "run"
    assert main(["run", str(scenario), "--out", str(out), "--replay", "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "motion: got 'sumo'; expected closed_form with --replay" in err[0]
    assert not out.exists()


def test_a_window_of_the_run_draws_the_same_positions(recorded: tuple[Path, RunOutput],
                                                      tmp_path: Path) -> None:
    """--from/--to keep what the window needs: where each AGV stands when it opens (even if it
    got there long before), its state, and every move inside it."""
    run_dir, run = recorded
    copy = tmp_path / "copy"
    shutil.copytree(run_dir, copy)
    write_replay(copy, 0.5, 0.75)
    moves = pd.read_parquet(run_dir / MOVES_FILE)
    for t in (1800.0, 2222.2):
        state = _page_state(copy, t, tmp_path / "profile")
        assert state["window"] == [1800.0, 2700.0]
        totals = list(state["totals"].values())
        assert len(totals) == run.scenario.fleet.size
        assert totals == pytest.approx([900.0] * len(totals), abs=0.01)
        truth = positions_at(moves, run.layout, t)
        for agv, where in truth.items():
            shown = state["positions"][str(agv)]
            assert math.hypot(shown["x"] - where.x_m, shown["y"] - where.y_m) <= 0.1
            assert shown["where"] == where.where


def test_a_mixed_fleet_moves_each_agv_on_its_own_profile(tmp_path: Path) -> None:
    """Two vehicle types with different accelerations and lengths: each drive carries its
    AGV's own motion limits, and the page draws each AGV with its own size."""
    scenario_file = write_yaml(tmp_path / "mixed.yaml", {
        "name": "mixed", "layout": str(LAYOUTS / "warehouse.yaml"), "duration_h": 0.5,
        "warmup_h": 0.1, "demand": {"rate_per_hour": 90},
        "fleet": {"vehicles": [
            {"type": "quick", "count": 3, "vehicle": {"accel_mps2": 0.8, "decel_mps2": 0.7}},
            {"type": "slow", "count": 2, "vehicle": {"accel_mps2": 0.3, "decel_mps2": 0.25,
                                                     "length_m": 1.6}}]}})
    run_dir = tmp_path / "run"
    assert main(["run", str(scenario_file), "--out", str(run_dir), "--replay", "--quiet"]) == 0
    moves = pd.read_parquet(run_dir / MOVES_FILE)
    drives = moves[moves["kind"] == "drive"]
    limits = drives.groupby("agv")[["accel_mps2", "decel_mps2"]].agg(set)
    assert limits.loc[0, "accel_mps2"] == {0.8} and limits.loc[4, "decel_mps2"] == {0.25}
    layout = load_layout_for(load_scenario(scenario_file), str(scenario_file))
    t = float(drives[drives["agv"] == 4]["start_s"].iloc[10]) + 1.0
    where = positions_at(moves, layout, t)[4]
    row = drives[(drives["agv"] == 4) & (drives["start_s"] <= t)].iloc[-1]
    pieces = hop_pieces(layout.graph.edges[row["u"], row["v"]]["length_m"], row["curve_m"],
                        row["curve_mps"], row["limit_mps"])
    assert where.along_m == pytest.approx(distance_at(
        pieces, row["v_in_mps"], row["v_out_mps"], 0.3, 0.25,
        row["driven_s"] + t - row["start_s"]), abs=1e-9)
    html = (run_dir / "replay.html").read_text(encoding="utf-8")
    found = re.search(r'id="replay-data">(.*?)</script>', html, re.S)
    assert found
    data = json.loads(found.group(1))
    assert [a["length_m"] for a in data["agv"]] == [1.0, 1.0, 1.0, 1.6, 1.6]
    assert set(data["profiles"]["acc"]) == {0.8, 0.3}


# ---- traffic zones on the page ------------------------------------------------------------------


@pytest.fixture(scope="module")
def zoned_run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """`fleet-sim run --replay` on tests/data/aisle_crossing.yaml with a zone of each kind: the
    aisle same-direction, the east side a mutex zone, a ban zone round DROP2."""
    tmp = tmp_path_factory.mktemp("zones")
    layout: dict[str, Any] = yaml.safe_load((DATA / "aisle_crossing.yaml").read_text("utf-8"))
    layout["traffic_zones"] = [
        {"id": "AISLE", "kind": "same_direction", "nodes": ["B", "A1", "A2", "A3", "T"]},
        {"id": "EAST", "kind": "mutex", "nodes": ["E1", "E2"]},
        {"id": "DOCK", "kind": "ban", "nodes": ["D2"], "banned_types": ["wide"]}]
    write_yaml(tmp / "crossing.yaml", layout)
    scenario = write_yaml(tmp / "zones.yaml", {
        "name": "zones", "layout": "crossing.yaml", "duration_h": 1.5, "warmup_h": 0.25,
        "seed": 5, "fleet": {"size": 6},
        "demand": {"rate_per_hour": 90, "flows": [
            {"from": "PICK1", "to": "DROP1"}, {"from": "PICK2", "to": "DROP2"},
            {"from": "PICK1", "to": "MID", "weight": 0.3}]},
        "charging": {"enabled": False}})
    run_dir = tmp / "run"
    assert main(["run", str(scenario), "--out", str(run_dir), "--replay", "--quiet"]) == 0
    return run_dir


def _page_data(run_dir: Path) -> dict[str, Any]:
    html = (run_dir / "replay.html").read_text(encoding="utf-8")
    found = re.search(r'<script type="application/json" id="replay-data">(.*?)</script>', html,
                      re.S)
    assert found
    data: dict[str, Any] = json.loads(found.group(1))
    return data


def test_the_page_carries_every_traffic_zone_and_who_held_it(zoned_run: Path,
                                                             tmp_path: Path) -> None:
    data = _page_data(zoned_run)
    zones = data["zones"]
    assert zones["id"] == ["AISLE", "EAST", "DOCK"]
    assert zones["kind"] == ["same_direction", "mutex", "ban"]
    assert zones["rule"] == ["same direction; forward B \u2192 T", "max 1", "no wide"]
    nodes = data["nodes"]["id"]
    assert [nodes[n] for n in zones["path"][0]] == ["B", "A1", "A2", "A3", "T"]
    assert len(set(zones["colour"])) == 3  # told apart by kind
    moves = pd.read_parquet(zoned_run / MOVES_FILE)
    held = moves[moves["kind"] == "zone"]
    assert set(held["v"]) == {"forward", "backward", ""}
    holds = data["zoneHolds"]
    assert len(holds["agv"]) == len(held) > 100
    assert sorted(zip(holds["agv"], [zones["id"][z] for z in holds["z"]], holds["dir"],
                      strict=True)) == sorted(
        zip(held["agv"], held["u"], [{"forward": 1, "backward": -1, "": 0}[v]
                                     for v in held["v"]], strict=True))
    html = (zoned_run / "replay.html").read_text(encoding="utf-8")
    assert re.findall(r"(?i)(?:https?|ftp|wss?)://", html) == []
    copy = tmp_path / "copy"
    shutil.copytree(zoned_run, copy)
    assert write_replay(copy).read_bytes() == (zoned_run / "replay.html").read_bytes()
    assert write_replay(copy).read_bytes() == (zoned_run / "replay.html").read_bytes()


def test_a_screenshot_shows_the_zones_and_their_holders_now(zoned_run: Path,
                                                           tmp_path: Path) -> None:
    """Headless Chromium at a moment when two AGVs share the aisle one way and one holds the
    mutex zone: the page's holders are the engine's (zone_holders_at), the side panel names
    them, and the screenshot has each zone drawn in its kind's colour with its badge."""
    import matplotlib.image

    moves = pd.read_parquet(zoned_run / MOVES_FILE)
    starts = sorted(set(moves[moves["kind"] == "zone"]["start_s"]))
    t = next(s + 0.5 for s in starts
             if len(zone_holders_at(moves, s + 0.5).get("AISLE", [])) >= 2
             and zone_holders_at(moves, s + 0.5).get("EAST"))
    truth = zone_holders_at(moves, t)
    state = _page_state(zoned_run, t, tmp_path / "profile")
    assert state["resources"] == 0 and state["violations"] == []
    shown = {z["id"]: z for z in state["zones"]}
    way = {"forward": 1, "backward": -1}
    for zone_id in ("AISLE", "EAST"):
        assert shown[zone_id]["holders"] == [agv for agv, _ in truth[zone_id]]
    aisle_way = {d for _, d in truth["AISLE"]}
    assert len(aisle_way) == 1 and shown["AISLE"]["dir"] == way[aisle_way.pop()]
    assert shown["DOCK"]["holders"] == []
    agvs = ", ".join(str(agv) for agv, _ in truth["AISLE"])
    assert f"AISLE (same direction; forward B \u2192 T): AGV {agvs} " in state["zonePanel"]
    shot = tmp_path / "shot.png"
    result = _browser([f"--screenshot={shot}"], (zoned_run / "replay.html").as_uri() + f"#t={t}",
                      tmp_path / "profile")
    assert result.returncode == 0, result.stderr[-2000:]
    image = (matplotlib.image.imread(shot)[:, :, :3] * 255).round().astype(int)
    left, top = round(state["floor"]["x"]), round(state["floor"]["y"])
    assert [z["id"] for z in state["drawnZones"]] == ["AISLE", "EAST", "DOCK"]
    for zone in state["drawnZones"]:
        want = np.array([int(zone["colour"][i:i + 2], 16) for i in (1, 3, 5)])
        x0, y0 = left + round(zone["x"]), top + round(zone["y"])
        x1, y1 = x0 + round(zone["w"]), y0 + round(zone["h"])
        if zone["kind"] == "same_direction":  # a band along the (upright) aisle, tinted
            band = _tint(image[y0 + 20:y1 - 20, (x0 + x1) // 2 + 8], want)
            assert (band > 0.15).mean() > 0.8, zone["id"]
        else:  # a dashed outline in its colour: along its bottom edge
            edge = _tint(image[y1 - 2:y1 + 3, x0 + 4:x1 - 4], want)
            assert (edge > 0.3).any(axis=0).mean() > 0.3, zone["id"]
        if zone["kind"] != "ban":  # the live badge, filled with the zone's colour
            bx, by = left + round(zone["bx"]), top + round(zone["by"])
            assert np.abs(image[by, bx] - want).max() <= 3, zone["id"]


def _tint(pixels: Any, colour: Any) -> Any:
    """How much of `colour` over white each pixel is (0: none or another colour; 1: it)."""
    weight = 255 - colour
    share = ((255 - pixels) * weight).sum(axis=-1) / (weight * weight).sum()
    made = 255 - np.clip(share, 0, 1)[..., None] * weight
    return np.where(np.abs(pixels - made).max(axis=-1) <= 20, share, 0.0)
