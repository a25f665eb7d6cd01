"""Study (a): the fleet engine's closed-form hop times against the time-stepped vehicle model.

The engine (fleet_sim.sim.traffic.routing.Routes.hop / pass_speed_mps,
fleet_sim.model.kinematics) times each hop
u -> v with a trapezoidal speed profile: a branch curve of `turn_length_m` (layout default 1.0 m)
at the turn speed, then the segment limit; at an intermediate node it passes no faster than lets
it stop at the next one. Here routes on a small rectangular loop are timed both ways, hop by hop:

* engine: exactly what `Vehicle.drive` does on a free road (every lock granted): v_end_max is
  pass_speed_mps(u, v, w) at an intermediate node, 0 at the goal;
* model: agv_model.dynamics drives the same route as one track (the turn as a 90 degree arc of
  the curve length), cruising at the segment limit, with a TYPE_LOC RFID tag at every node
  (nodes are RFID tags, RSS-AGV-001 3), and stops at the goal. A hop's time is the time between
  the reference point crossing its two nodes (the last hop ends when the vehicle is at rest).

Prints one table (both times, difference in %) and writes PNGs under --out.

    .venv/bin/python bench/dynamics_vs_closed_form.py [--out results/agv_model] [--dt 0.01]
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
from dataclasses import dataclass
from itertools import pairwise
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from agv_model.dynamics import Drive, Trace, VehicleParams, simulate  # noqa: E402
from agv_model.dynamics_plot import plot_trace  # noqa: E402
from agv_model.track import Arc, Marker, Piece, Straight, TagType, Track  # noqa: E402
from fleet_sim.config.layout import Layout, load_layout  # noqa: E402
from fleet_sim.model.kinematics import Motion  # noqa: E402
from fleet_sim.sim.traffic.routing import Routes  # noqa: E402

# Node positions of the study loop (counter-clockwise, so every corner is a left turn). The
# bottom side's hops are 0.5, 1, 2, 5, 10, 20 and 1.5 m; the corners give turn hops of 1 m
# (curve only), 2 m and 4 m.
NODES: list[tuple[str, float, float, str]] = [
    ("B0", 0.0, 0.0, "junction"), ("B1", 0.5, 0.0, "tag"), ("B2", 1.5, 0.0, "tag"),
    ("B3", 3.5, 0.0, "tag"), ("B4", 8.5, 0.0, "tag"), ("B5", 18.5, 0.0, "tag"),
    ("B6", 38.5, 0.0, "tag"), ("SE", 40.0, 0.0, "junction"),
    ("E1", 40.0, 1.0, "tag"), ("E2", 40.0, 3.0, "tag"), ("E3", 40.0, 7.0, "tag"),
    ("NE", 40.0, 12.0, "junction"), ("N1", 38.0, 12.0, "tag"), ("N2", 30.0, 12.0, "station"),
    ("N3", 4.0, 12.0, "tag"), ("NW", 0.0, 12.0, "junction"), ("W1", 0.0, 8.0, "station"),
    ("W2", 0.0, 4.0, "parking"),
]

ROUTES: list[tuple[str, str | None, list[str]]] = [
    # (case, node the AGV came from (for a turn at its first node), route)
    ("straight 0.5 m", None, ["B0", "B1"]),
    ("straight 1 m", None, ["B1", "B2"]),
    ("straight 2 m", None, ["B2", "B3"]),
    ("straight 5 m", None, ["B3", "B4"]),
    ("straight 10 m", None, ["B4", "B5"]),
    ("straight 20 m", None, ["B5", "B6"]),
    ("through 6 nodes", None, ["B0", "B1", "B2", "B3", "B4", "B5", "B6"]),
    ("turn, 1 m curve hop", None, ["B5", "B6", "SE", "E1", "E2", "E3"]),
    ("turn, 2 m hop", None, ["E2", "E3", "NE", "N1", "N2"]),
    ("turn, 4 m hop", None, ["N2", "N3", "NW", "W1"]),
    ("turn from rest", "B6", ["SE", "E1", "E2", "E3"]),
]


def study_layout(directory: Path) -> Layout:
    ids = [n[0] for n in NODES]
    data = {
        "name": "dynamics_study_loop",
        "defaults": {"speed_limit_mps": 1.0, "turn_length_m": 1.0},
        "nodes": [{"id": i, "x": x, "y": y, "kind": k} for i, x, y, k in NODES],
        "segments": [{"from": a, "to": b} for a, b in zip(ids, ids[1:] + ids[:1], strict=True)],
        "stations": [
            {"id": "PICK", "kind": "pickup", "nodes": ["N2"],
             "handling": {"dist": "fixed", "mean_s": 10}},
            {"id": "DROP", "kind": "dropoff", "nodes": ["W1"],
             "handling": {"dist": "fixed", "mean_s": 10}},
        ],
        "parking": [{"id": "PARK", "node": "W2", "capacity": 1}],
    }
    path = directory / "dynamics_study_loop.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding="utf-8")
    return load_layout(path, max_speed_mps=1.0)


@dataclass(frozen=True)
class Hop:
    case: str
    u: str
    v: str
    length_m: float
    turn: str
    v_in_mps: float
    v_out_mps: float
    engine_s: float
    model_s: float

    @property
    def diff_pct(self) -> float:
        return 100.0 * (self.model_s - self.engine_s) / self.engine_s


def engine_hops(traffic: Routes, prev: str | None,
                route: list[str]) -> list[tuple[float, float, float]]:
    """(v_in, v_out, time_s) of each hop, as Vehicle.drive computes them on a free road."""
    out = []
    speed = 0.0
    for i in range(len(route) - 1):
        u, v = route[i], route[i + 1]
        v_end_max = 0.0
        if i + 2 < len(route):
            v_end_max = traffic.pass_speed_mps(u, v, route[i + 2])
        time_s, v_end = traffic.hop(prev, u, v, speed, v_end_max)
        out.append((speed, v_end, time_s))
        prev, speed = u, v_end
    return out


def model_track(layout: Layout, prev: str | None, route: list[str]) -> Track:
    """The route as one track: each hop straight, or an arc of the curve length first where
    the engine sees a left or right turn; a TYPE_LOC tag at every node."""
    pieces: list[Piece] = []
    markers: list[Marker] = []
    at_m = 0.0
    for i in range(len(route) - 1):
        u, v = route[i], route[i + 1]
        length = layout.graph.edges[u, v]["length_m"]
        before = prev if i == 0 else route[i - 1]
        turn = layout.turn(before, u, v)
        curve = min(layout.turn_length_m, length)
        if i > 0:
            markers.append(Marker(at_m, TagType.LOC, i))
        if turn in ("left", "right") and curve > 0 and before is not None:
            pieces.append(Arc(curve, _heading_change(layout, before, u, v)))
            if length > curve:
                pieces.append(Straight(length - curve))
        else:
            pieces.append(Straight(length))
        at_m += length
    return Track(tuple(pieces), tuple(markers))


def _heading_change(layout: Layout, a: str, b: str, c: str) -> float:
    (ax, ay), (bx, by), (cx, cy) = layout.position(a), layout.position(b), layout.position(c)
    h1 = math.atan2(by - ay, bx - ax)
    h2 = math.atan2(cy - by, cx - bx)
    return (h2 - h1 + math.pi) % (2 * math.pi) - math.pi


def model_hop_times(trace: Trace, node_positions: list[float]) -> list[float]:
    assert trace.stop_time_s is not None
    crossings = [trace.time_at(x) for x in node_positions[:-1]] + [trace.stop_time_s]
    crossings[0] = 0.0
    return [b - a for a, b in pairwise(crossings)]


def run(dt_s: float) -> tuple[list[Hop], dict[str, Trace]]:
    with tempfile.TemporaryDirectory() as tmp:
        layout = study_layout(Path(tmp))
    traffic = Routes(layout, Motion(1.0, 0.5, 0.5, 0.3))
    params = VehicleParams()  # P_001-P_004: 1.0 m/s, 0.5 m/s2 both ways, 0.3 m/s turns
    hops: list[Hop] = []
    traces: dict[str, Trace] = {}
    for case, prev, route in ROUTES:
        engine = engine_hops(traffic, prev, route)
        track = model_track(layout, prev, route)
        trace = simulate(track, [Drive(0.0, 1.0)], params, dt_s=dt_s)
        traces[case] = trace
        lengths = [layout.graph.edges[u, v]["length_m"] for u, v in pairwise(route)]
        positions = [sum(lengths[:i]) for i in range(len(lengths) + 1)]
        model = model_hop_times(trace, positions)
        for i, ((v_in, v_out, engine_s), model_s) in enumerate(zip(engine, model, strict=True)):
            u, v = route[i], route[i + 1]
            before = prev if i == 0 else route[i - 1]
            hops.append(Hop(case, u, v, lengths[i], layout.turn(before, u, v) if before
                            else "straight", v_in, v_out, engine_s, model_s))
        if len(route) > 2:
            total_engine = sum(e[2] for e in engine)
            assert trace.stop_time_s is not None
            hops.append(Hop(case, route[0], route[-1], sum(lengths), "route total", 0.0, 0.0,
                            total_engine, trace.stop_time_s))
    return hops, traces


def print_stops(hops: list[Hop], traces: dict[str, Trace]) -> None:
    """Where each route's model run came to rest, against its goal node."""
    goals: dict[str, float] = {}
    for h in hops:
        if h.turn != "route total":
            goals[h.case] = goals.get(h.case, 0.0) + h.length_m
    print(f"\n{'case':<22} {'goal m':>7} {'stopped at m':>13} {'stop error mm':>14}")
    for case, trace in traces.items():
        goal = goals[case]
        error_mm = (trace.final_position_m - goal) * 1000.0
        print(f"{case:<22} {goal:>7.2f} {trace.final_position_m:>13.4f} {error_mm:>+14.1f}")


def print_table(hops: list[Hop]) -> None:
    head = (f"{'case':<22} {'hop':<9} {'length':>7} {'turn':<12} {'v_in':>5} {'v_out':>5} "
            f"{'engine s':>9} {'model s':>9} {'diff %':>7}")
    print(head)
    print("-" * len(head))
    for h in hops:
        name = f"{h.u}>{h.v}"
        print(f"{h.case:<22} {name:<9} {h.length_m:>7.2f} {h.turn:<12} {h.v_in_mps:>5.2f} "
              f"{h.v_out_mps:>5.2f} {h.engine_s:>9.3f} {h.model_s:>9.3f} {h.diff_pct:>+7.2f}")


def plot(hops: list[Hop], traces: dict[str, Trace], out: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    fig, ax = plt.subplots(figsize=(10, 5))
    labels = [f"{h.case}\n{h.u}>{h.v}" if h.turn != "route total" else f"{h.case}\n(total)"
              for h in hops]
    colours = ["tab:orange" if h.turn in ("left", "right") else
               "tab:gray" if h.turn == "route total" else "tab:blue" for h in hops]
    ax.bar(range(len(hops)), [h.diff_pct for h in hops], color=colours)
    ax.axhline(0.0, color="black", linewidth=0.8)
    ax.set_xticks(range(len(hops)), labels, rotation=90, fontsize=6)
    ax.set_ylabel("model - engine (% of engine time)")
    ax.set_title("Hop times: time-stepped model vs the engine's closed form\n"
                 "(blue: straight hop, orange: turn hop, grey: whole route)")
    ax.grid(True, axis="y", alpha=0.3)
    fig.tight_layout()
    bars = out / "dynamics_vs_closed_form.png"
    fig.savefig(bars, dpi=110)
    plt.close(fig)
    turn = plot_trace(traces["turn, 2 m hop"], out / "trace_turn_2m_hop.png",
                      "Route E2>E3>NE>N1>N2: 90 degree left turn at NE, 1 m curve at 0.3 m/s")
    return [bars, turn]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "results" / "agv_model")
    parser.add_argument("--dt", type=float, default=0.01, help="model time step, s")
    args = parser.parse_args()
    hops, traces = run(args.dt)
    print(f"Closed-form hop times (fleet engine) vs time-stepped model, dt = {args.dt * 1000:g} "
          "ms; VEL_MAX 1.0 m/s, VEL_ACC/VEL_DEC 0.5 m/s2, TURN_SPEED 0.3 m/s, curve 1.0 m")
    print_table(hops)
    print_stops(hops, traces)
    straight = [abs(h.diff_pct) for h in hops if h.turn == "straight"]
    turns = [h.diff_pct for h in hops if h.turn in ("left", "right")]
    totals = [h.diff_pct for h in hops if h.turn == "route total"]
    print(f"\nstraight hops: max |diff| {max(straight):.2f} %; turn hops: "
          f"{min(turns):+.2f} to {max(turns):+.2f} %; routes: {min(totals):+.2f} to "
          f"{max(totals):+.2f} %")
    for path in plot(hops, traces, args.out):
        print(f"wrote {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}")


if __name__ == "__main__":
    main()
