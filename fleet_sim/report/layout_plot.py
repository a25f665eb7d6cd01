"""Draw a layout to PNG (matplotlib, Agg backend): never called inside a simulation.

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from fleet_sim.config.layout import Layout, TrafficZone
from fleet_sim.config.layout_changes import LayoutDiff

KIND_STYLE = {
    "tag": ("#9aa0a6", 8),
    "junction": ("#5f6368", 14),
    "station": ("#1a73e8", 40),
    "charger": ("#f9ab00", 40),
    "parking": ("#188038", 40),
}
PLACE_COLOUR = {"pickup": "#1a73e8", "dropoff": "#d93025", "charger": "#f9ab00",
                "parking": "#188038"}


ZONE_COLOUR = {"mutex": "#a142f4", "ban": "#d93025", "same_direction": "#12b5cb"}
"""Traffic zones by kind (the replay page draws them in the same colours)."""
LABEL_PT = (4.0, 9.0)
"""Smallest and largest font of node labels (points)."""
LABELLED_WIDEST_IN = 60.0
"""The widest labelled drawing (7,800 pixels at 130 dpi): beyond it labels may overlap."""
CHAR_WIDTH_EM = 0.62
"""Width of an average character of the label font, in ems (DejaVu Sans, digits and capitals)."""
ZONE_MARGIN_M = 0.8
"""How far a traffic zone's outline stands off its nodes."""


def zone_rule(zone: TrafficZone) -> str:
    """A zone's rule in a few words: what the drawings print beside its id."""
    if zone.kind == "mutex":
        return f"max {zone.capacity}"
    if zone.kind == "ban":
        return "no " + ", ".join(sorted(zone.banned_types))
    limit = f", max {zone.capacity}" if zone.capacity is not None else ""
    return f"same direction{limit}; forward {zone.path[0]} \u2192 {zone.path[-1]}"


def _draw_traffic_zones(ax: Any, layout: Layout) -> None:
    """Each mutex or ban zone as a dashed rectangle round its nodes, each same-direction zone
    as a band along its aisle with an arrow the forward way (from its first node listed
    towards its last), all labelled with their id and rule."""
    for zone in layout.traffic_zones:
        colour = ZONE_COLOUR[zone.kind]
        if zone.kind == "same_direction":
            xs, ys = zip(*(layout.position(n) for n in zone.path), strict=True)
            ax.plot(xs, ys, color=colour, lw=9, alpha=0.25, solid_capstyle="round", zorder=0)
            ax.annotate("", xy=(xs[-1], ys[-1]), xytext=(xs[0], ys[0]), zorder=1,
                        arrowprops={"arrowstyle": "-|>", "color": colour, "lw": 1.6,
                                    "shrinkA": 6, "shrinkB": 6, "mutation_scale": 14,
                                    "ls": "--"})
            angle = math.degrees(math.atan2(ys[-1] - ys[0], xs[-1] - xs[0]))
            if not -90 < angle <= 90:
                angle -= math.copysign(180, angle)  # text reads left to right or upwards
            ax.annotate(f"{zone.id} ({zone_rule(zone)})",
                        ((xs[0] + xs[-1]) / 2, (ys[0] + ys[-1]) / 2), xytext=(0, 5),
                        textcoords="offset points", rotation=angle, rotation_mode="anchor",
                        ha="center", va="bottom", fontsize=6, color=colour, zorder=3)
            continue
        pts = [layout.position(n) for n in sorted(zone.nodes)]
        x0 = min(p[0] for p in pts) - ZONE_MARGIN_M
        y0 = min(p[1] for p in pts) - ZONE_MARGIN_M
        x1 = max(p[0] for p in pts) + ZONE_MARGIN_M
        y1 = max(p[1] for p in pts) + ZONE_MARGIN_M
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, fill=True, alpha=0.08,
                               facecolor=colour, edgecolor=colour, lw=1.2, ls="--", zorder=0))
        ax.annotate(f"{zone.id} ({zone_rule(zone)})", (x0, y1), xytext=(2, 2),
                    textcoords="offset points", fontsize=6, color=colour, zorder=3)


def _node_gap_m(layout: Layout) -> float:
    """The median distance from a node to the nearest other node (metres)."""
    import numpy as np
    from scipy.spatial import cKDTree

    points = np.array([layout.position(n) for n in layout.graph.nodes])
    if len(points) < 2:
        return 1.0
    distances, _ = cKDTree(points).query(points, k=2)
    gaps = distances[:, 1][distances[:, 1] > 0]
    return float(np.median(gaps)) if len(gaps) else 1.0


def label_size(layout: Layout, width_in: float, span_x: float) -> tuple[float, float]:
    """(figure width in inches, font size in points) for labelled node ids: the font fills
    about 60 % of the gap between nodes, within LABEL_PT; the figure widens if the smallest
    font would not fit."""
    longest = max((len(str(n)) for n in layout.graph.nodes), default=1)
    em_per_label = CHAR_WIDTH_EM * longest + 0.5
    gap_m = _node_gap_m(layout)

    def gap_pt(width: float) -> float:
        return gap_m * width / span_x * 72

    smallest, largest = LABEL_PT
    needed = smallest * em_per_label / 0.6
    if gap_pt(width_in) < needed:
        width_in = min(LABELLED_WIDEST_IN, width_in * needed / gap_pt(width_in))
    font = min(largest, max(smallest, 0.6 * gap_pt(width_in) / em_per_label))
    return width_in, font


def _draw_node_labels(ax: Any, layout: Layout, font_pt: float) -> None:
    from matplotlib import patheffects

    halo = [patheffects.withStroke(linewidth=2, foreground="white")]
    for node in layout.graph.nodes:
        x, y = layout.position(node)
        ax.annotate(str(node), (x, y), xytext=(2, -2), textcoords="offset points",
                    fontsize=font_pt, color="#202124", ha="left", va="top", zorder=4,
                    path_effects=halo)


def draw_layout(layout: Layout, path: Path, title: str | None = None,
                labels: bool = False) -> Path:
    """The layout as a PNG at `path`; `labels` writes every node's id."""
    graph = layout.graph
    xs = [d["x"] for _, d in graph.nodes(data=True)]
    ys = [d["y"] for _, d in graph.nodes(data=True)]
    span_x = max(xs) - min(xs) or 1.0
    span_y = max(ys) - min(ys) or 1.0
    width = min(24.0, max(6.0, span_x / 6))
    font_pt = 0.0
    if labels:
        width, font_pt = label_size(layout, width, span_x)
    fig, ax = plt.subplots(figsize=(width, max(3.0, width * span_y / span_x) + 1))
    drawn: set[frozenset[str]] = set()
    for u, v, data in graph.edges(data=True):
        (x0, y0), (x1, y1) = layout.position(u), layout.position(v)
        if data["two_way"]:
            key = frozenset((u, v))
            if key in drawn:
                continue
            drawn.add(key)
            ax.plot([x0, x1], [y0, y1], color="#34a853", lw=2.2, alpha=0.7, zorder=1)
        else:
            ax.annotate("", xy=(x1, y1), xytext=(x0, y0), zorder=1,
                        arrowprops={"arrowstyle": "-|>", "color": "#5f6368", "lw": 1.0,
                                    "shrinkA": 2, "shrinkB": 2, "mutation_scale": 8})
    for kind, (colour, size) in KIND_STYLE.items():
        pts = [layout.position(n) for n, d in graph.nodes(data=True) if d["kind"] == kind]
        if pts:
            ax.scatter([p[0] for p in pts], [p[1] for p in pts], s=size, c=colour, zorder=2,
                       label=kind, edgecolors="none")
    for place in layout.places.values():
        x, y = layout.position(place.nodes[0])
        label = place.id if place.kind != "parking" else f"{place.id} ({place.capacity})"
        ax.annotate(label, (x, y), xytext=(3, 3), textcoords="offset points", fontsize=6,
                    color=PLACE_COLOUR[place.kind], zorder=3)
    _draw_traffic_zones(ax, layout)
    if labels:
        _draw_node_labels(ax, layout, font_pt)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title or f"{layout.name}: {graph.number_of_nodes()} nodes, "
                 f"{layout.total_length_m:.0f} m of track (arrows one-way, green two-way)")
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=7, frameon=False)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=130)
    plt.close(fig)
    return path


CHANGE_COLOUR = "#d93025"
"""What a variant changes, drawn over its layout (fleet_sim.report.compare_figures)."""


def variant_figure(layout: Layout, baseline: Layout, diff: LayoutDiff, title: str) -> Any:
    """`layout` (a variant's) in grey, with what it changes against `baseline` in red: changed
    or new hops (arrows where one-way, thick where two-way), changed nodes and places ringed;
    what it removes dashed, at the baseline's positions. Returns the matplotlib Figure."""
    graph = layout.graph
    pos = {n: layout.position(n) for n in graph.nodes}
    old = {n: baseline.position(n) for n in baseline.graph.nodes}
    xs = [p[0] for p in [*pos.values(), *old.values()]]
    ys = [p[1] for p in [*pos.values(), *old.values()]]
    span_x = (max(xs) - min(xs)) or 1.0
    span_y = (max(ys) - min(ys)) or 1.0
    width = min(12.0, max(6.0, span_x / 8))
    fig, ax = plt.subplots(figsize=(width, max(3.0, width * span_y / span_x) + 1.0))
    changed = set(diff.changed_segments)
    for u, v in graph.edges():
        if (u, v) in changed:
            continue
        (x0, y0), (x1, y1) = pos[u], pos[v]
        ax.plot([x0, x1], [y0, y1], color="#bdc1c6", lw=1.0, zorder=1)
    for u, v in diff.removed_segments:
        if u in old and v in old and not graph.has_edge(u, v) and not graph.has_edge(v, u):
            (x0, y0), (x1, y1) = old[u], old[v]
            ax.plot([x0, x1], [y0, y1], color=CHANGE_COLOUR, lw=1.2, ls="--", zorder=2)
    for u, v in changed:
        (x0, y0), (x1, y1) = pos[u], pos[v]
        if graph.edges[u, v].get("two_way"):
            ax.plot([x0, x1], [y0, y1], color=CHANGE_COLOUR, lw=3.0, zorder=3)
        else:
            ax.annotate("", xy=(x1, y1), xytext=(x0, y0), zorder=3,
                        arrowprops={"arrowstyle": "-|>", "color": CHANGE_COLOUR, "lw": 2.0,
                                    "shrinkA": 1, "shrinkB": 1, "mutation_scale": 12})
    for place in layout.places.values():
        x, y = pos[place.nodes[0]]
        ax.annotate(place.id, (x, y), xytext=(3, 3), textcoords="offset points", fontsize=5,
                    color=PLACE_COLOUR[place.kind], zorder=4)
    rings = set(diff.changed_nodes) | {n for p in diff.changed_places if p in layout.places
                                       for n in layout.places[p].nodes}
    if rings:
        pts = [pos[n] for n in sorted(rings) if n in pos]
        ax.scatter([p[0] for p in pts], [p[1] for p in pts], s=90, facecolors="none",
                   edgecolors=CHANGE_COLOUR, linewidths=1.6, zorder=5)
        for n in sorted(rings):
            if n in pos:
                ax.annotate(n, pos[n], xytext=(4, -8), textcoords="offset points", fontsize=6,
                            color=CHANGE_COLOUR, zorder=5)
    gone = [old[n] for n in diff.removed_nodes if n in old]
    if gone:
        ax.scatter([p[0] for p in gone], [p[1] for p in gone], s=60, marker="x",
                   color=CHANGE_COLOUR, zorder=5)
    if diff.empty:
        ax.text(0.5, 0.02, "no change to the layout (the variant changes settings only)",
                transform=ax.transAxes, ha="center", fontsize=8, color="#5f6368")
    return finish_floor_plan(fig, ax, title)


def finish_floor_plan(fig: Figure, ax: Any, title: str) -> Figure:
    """A figure of the floor (layout, congestion, a variant's changes) finished alike: metres
    on both axes at the same scale, the title, a tight layout."""
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return fig
