"""Draw a layout to PNG (matplotlib, Agg backend): never called inside a simulation."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from fleet_sim.config.layout import Layout

KIND_STYLE = {
    "tag": ("#9aa0a6", 8),
    "junction": ("#5f6368", 14),
    "station": ("#1a73e8", 40),
    "charger": ("#f9ab00", 40),
    "parking": ("#188038", 40),
}
PLACE_COLOUR = {"pickup": "#1a73e8", "dropoff": "#d93025", "charger": "#f9ab00",
                "parking": "#188038"}


def draw_layout(layout: Layout, path: Path, title: str | None = None) -> Path:
    graph = layout.graph
    xs = [d["x"] for _, d in graph.nodes(data=True)]
    ys = [d["y"] for _, d in graph.nodes(data=True)]
    span_x = max(xs) - min(xs) or 1.0
    span_y = max(ys) - min(ys) or 1.0
    width = min(24.0, max(6.0, span_x / 6))
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
