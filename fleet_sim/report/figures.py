"""The report's figures (matplotlib, Agg): each function returns a Figure the report saves as
PNG (embedded in the HTML) and as a PDF page. Never called inside a simulation."""

from __future__ import annotations

import io
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pandas as pd
from matplotlib.figure import Figure
from matplotlib.patches import Rectangle

from fleet_sim.analysis.kpis import kpi_label
from fleet_sim.config.experiment import Target
from fleet_sim.config.layout import Layout
from fleet_sim.model.states import VehicleState
from fleet_sim.report.layout_plot import finish_floor_plan

STATE_COLOURS = {
    "booting": "#9aa0a6", "idle": "#dadce0", "moving": "#1a73e8", "loading": "#34a853",
    "unloading": "#0f9d58", "charging": "#f9ab00", "paused": "#e37400", "error": "#d93025",
    "maintenance": "#a142f4", "safe_mode": "#5f6368",
}
SERIES_COLOURS = ["#1a73e8", "#d93025", "#188038", "#f9ab00", "#a142f4", "#12b5cb"]
LEAD_COLOURS = {"wait_assign_s": "#bdc1c6", "drive_empty_s": "#8ab4f8", "load_s": "#34a853",
                "drive_loaded_s": "#1a73e8", "unload_s": "#0f9d58", "blocked_s": "#d93025"}
"""The parts of an order's lead time (fleet_sim.analysis.replay.LEAD_PARTS), here and in the
replay page."""


def label(kpi: str) -> str:
    """A KPI's name and unit from the KPI catalogue, for an axis: ``p95 lead time [s]``."""
    return kpi_label(kpi)


def png_bytes(fig: Figure, dpi: int = 110) -> bytes:
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi)
    return buffer.getvalue()


Series = Mapping[str, pd.DataFrame]
"""Series label -> stats rows (x, kpi, mean, ci_low, ci_high) of one combination of the other
factors."""


def kpi_panels(series: Series, x: str, kpis: Sequence[str], targets: Sequence[Target],
               recommended: Mapping[str, int | None]) -> Figure:
    """One panel per KPI: mean against the x factor with its 95 % CI band, targets dashed."""
    cols = min(3, len(kpis))
    rows = (len(kpis) + cols - 1) // cols
    fig, axes = plt.subplots(rows, cols, figsize=(4.6 * cols, 3.6 * rows), squeeze=False)
    for ax, kpi in zip(axes.flat, kpis, strict=False):
        for i, (name, frame) in enumerate(series.items()):
            rows_k = frame[frame["kpi"] == kpi].sort_values(x)
            if rows_k.empty:
                continue
            colour = SERIES_COLOURS[i % len(SERIES_COLOURS)]
            xs = rows_k[x].to_numpy(dtype=float)
            ax.plot(xs, rows_k["mean"], marker="o", ms=3, color=colour, label=name or "mean")
            low = rows_k["ci_low"].to_numpy(dtype=float)
            high = rows_k["ci_high"].to_numpy(dtype=float)
            ax.fill_between(xs, low, high, color=colour, alpha=0.18, lw=0,
                            label="95 % CI" if i == 0 else None)
            rec = recommended.get(name)
            if rec is not None:
                ax.axvline(rec, color=colour, lw=1, ls=":", alpha=0.9)
        for target in targets:
            if target.kpi == kpi:
                ax.axhline(target.bound, color="#202124", lw=1.2, ls="--",
                           label=f"target {target.describe().split(' ', 1)[1]}")
        ax.set_xlabel(x)
        ax.set_ylabel(label(kpi))
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, loc="best")
    for ax in list(axes.flat)[len(kpis):]:
        ax.set_visible(False)
    fig.suptitle("KPIs against " + x + " (dotted: recommended fleet)", fontsize=10)
    fig.tight_layout()
    return fig


def state_bars(means: pd.DataFrame, x: str, title: str) -> Figure:
    """Stacked bars: mean share of AGV time in each state at each level of x."""
    states = [c for c in means.columns if c.startswith("state_") and c.endswith("_pct")
              and float(means[c].fillna(0).max()) > 0.0]
    fig, ax = plt.subplots(figsize=(9, 3.8))
    xs = [str(v) for v in means[x]]
    bottom = np.zeros(len(means))
    for col in states:
        key = col[len("state_"):-len("_pct")]
        values = means[col].fillna(0).to_numpy(dtype=float)
        ax.bar(xs, values, bottom=bottom, color=STATE_COLOURS.get(key, "#80868b"), label=key,
               edgecolor="white", lw=0.5)
        bottom += values
    ax.set_xlabel(x)
    ax.set_ylabel("share of AGV time [%]")
    ax.set_ylim(0, max(100.0, float(bottom.max()) if len(bottom) else 100.0))
    ax.set_title(title, fontsize=10)
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=8, frameon=False)
    fig.tight_layout()
    return fig


def heat_map(layout: Layout, waits: pd.DataFrame, title: str) -> Figure:
    """The layout's track in grey; each node coloured and sized by AGV waiting there (s/h)."""
    graph = layout.graph
    xs = [d["x"] for _, d in graph.nodes(data=True)]
    ys = [d["y"] for _, d in graph.nodes(data=True)]
    span_x = (max(xs) - min(xs)) or 1.0
    span_y = (max(ys) - min(ys)) or 1.0
    width = min(14.0, max(6.0, span_x / 8))
    fig, ax = plt.subplots(figsize=(width, max(3.0, width * span_y / span_x) + 1.2))
    for u, v in graph.edges():
        (x0, y0), (x1, y1) = layout.position(u), layout.position(v)
        ax.plot([x0, x1], [y0, y1], color="#bdc1c6", lw=1.2, zorder=1)
    for place in layout.places.values():
        px, py = layout.position(place.nodes[0])
        ax.annotate(place.id, (px, py), xytext=(3, 3), textcoords="offset points", fontsize=5,
                    color="#5f6368", zorder=2)
    known = waits[waits["node"].isin(list(graph.nodes))]
    if not known.empty and float(known["wait_s_per_h"].max()) > 0:
        pts = np.array([layout.position(n) for n in known["node"]])
        values = known["wait_s_per_h"].to_numpy(dtype=float)
        top = float(values.max())
        sizes = 8 + 220 * values / top
        sc = ax.scatter(pts[:, 0], pts[:, 1], c=values, s=sizes, cmap="inferno_r", vmin=0,
                        vmax=top, zorder=3, edgecolors="#202124", linewidths=0.3)
        fig.colorbar(sc, ax=ax, shrink=0.8, label="AGV waiting [s per hour]")
    else:
        ax.text(0.5, 0.5, "no AGV waited anywhere", transform=ax.transAxes, ha="center")
    return finish_floor_plan(fig, ax, title)


def incidents(counts: pd.DataFrame, x: str) -> Figure:
    """Mean incidents per run (deadlocks and the traffic manoeuvres that resolve blocking)."""
    kinds = [c for c in counts.columns if c != x]
    fig, ax = plt.subplots(figsize=(8, 3.4))
    for i, kind in enumerate(kinds):
        ax.plot(counts[x].to_numpy(dtype=float), counts[kind], marker="o", ms=3,
                color=SERIES_COLOURS[i % len(SERIES_COLOURS)], label=kind)
    ax.set_xlabel(x)
    ax.set_ylabel("events per run (mean)")
    ax.set_yscale("symlog", linthresh=1)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Incidents: deadlocks and traffic manoeuvres", fontsize=10)
    fig.tight_layout()
    return fig


def soc_curves(curves: pd.DataFrame, title: str) -> Figure:
    """State of charge over time of a few AGVs (columns time_s, agv, soc_pct)."""
    fig, ax = plt.subplots(figsize=(9, 3.4))
    for i, (agv, group) in enumerate(curves.groupby("agv")):
        ax.plot(group["time_s"] / 3600.0, group["soc_pct"], lw=1,
                color=SERIES_COLOURS[i % len(SERIES_COLOURS)], label=f"AGV {agv}")
    ax.set_xlabel("time [h]")
    ax.set_ylabel("state of charge [%]")
    ax.set_ylim(0, 100)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return fig


def gantt(spells: pd.DataFrame, agvs: Sequence[int], title: str) -> Figure:
    """One row per AGV, a bar per spell in a state (columns agv, start_s, end_s, state)."""
    keys = {s.value: s.key for s in VehicleState}
    fig, ax = plt.subplots(figsize=(11, max(2.5, 0.22 * len(agvs) + 1.2)))
    for row, agv in enumerate(agvs):
        mine = spells[spells["agv"] == agv]
        for state, group in mine.groupby("state", sort=True):
            starts = group["start_s"].to_numpy(dtype=float) / 3600.0
            widths = group["end_s"].to_numpy(dtype=float) / 3600.0 - starts
            ax.broken_barh(list(zip(starts, widths, strict=True)), (row - 0.4, 0.8),
                           facecolors=STATE_COLOURS.get(keys.get(str(state), ""), "#80868b"),
                           linewidth=0)
    ax.set_yticks(range(len(agvs)), [f"AGV {a}" for a in agvs], fontsize=6)
    ax.invert_yaxis()
    ax.set_xlabel("time [h]")
    handles = [Rectangle((0, 0), 1, 1, color=STATE_COLOURS[s.key]) for s in VehicleState]
    ax.legend(handles, [s.value for s in VehicleState], loc="upper left",
              bbox_to_anchor=(1.0, 1.0), fontsize=7, frameon=False)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return fig


def lead_breakdown(leads: pd.DataFrame, labels: Mapping[str, str], title: str) -> Figure:
    """One stacked bar per order (in order of creation): the parts of its lead time."""
    fig, ax = plt.subplots(figsize=(11, 3.6))
    xs = np.arange(len(leads))
    bottom = np.zeros(len(leads))
    for part, label_text in labels.items():
        values = leads[part].fillna(0).to_numpy(dtype=float)
        ax.bar(xs, values, bottom=bottom, width=1.0, color=LEAD_COLOURS[part],
               label=label_text, linewidth=0)
        bottom += values
    ax.set_xlabel("orders delivered after the warm-up, in order of creation")
    ax.set_ylabel("lead time [s]")
    ax.set_xlim(-0.5, max(len(leads), 1) - 0.5)
    ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize=7, frameon=False)
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return fig


def image_page(png: bytes, title: str) -> Figure:
    """A PNG (the layout drawing) as a figure, for the PDF."""
    image = plt.imread(io.BytesIO(png), format="png")
    height, width = image.shape[:2]
    fig, ax = plt.subplots(figsize=(11, max(3.0, 11 * height / width)))
    ax.imshow(image)
    ax.axis("off")
    ax.set_title(title, fontsize=10)
    fig.tight_layout()
    return fig


def text_page(title: str, lines: Sequence[str]) -> Figure:
    """A page of wrapped text for the PDF."""
    import textwrap

    fig = plt.figure(figsize=(8.27, 11.69))
    fig.text(0.06, 0.96, title, fontsize=14, weight="bold", va="top")
    y = 0.92
    for line in lines:
        for part in textwrap.wrap(line, 100) or [""]:
            fig.text(0.06, y, part, fontsize=8, va="top", family="monospace")
            y -= 0.016
            if y < 0.04:
                return fig
    return fig


def layout_png(layout: Layout, title: str | None = None) -> bytes:
    """The layout drawing of fleet_sim.report.layout_plot, as PNG bytes."""
    import tempfile

    from fleet_sim.report.layout_plot import draw_layout

    with tempfile.TemporaryDirectory() as tmp:
        path = draw_layout(layout, Path(tmp) / "layout.png", title)
        return path.read_bytes()


def close(fig: Any) -> None:
    plt.close(fig)
