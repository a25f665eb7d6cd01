"""The comparison report's figures (matplotlib, Agg): the forest plot of paired differences,
the KPIs of every variant side by side, and where congestion moved. Axes carry each KPI's name
and unit from the KPI catalogue (fleet_sim.analysis.kpis), never a raw key."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.colors import TwoSlopeNorm
from matplotlib.figure import Figure

from fleet_sim.analysis.kpis import kpi_label
from fleet_sim.config.layout import Layout
from fleet_sim.report.layout_plot import finish_floor_plan

VERDICT_COLOURS = {"better": "#188038", "worse": "#d93025", "higher": "#1a73e8",
                   "lower": "#1a73e8", "no_difference": "#5f6368", "undecided": "#f9ab00"}
VARIANT_COLOURS = ["#5f6368", "#1a73e8", "#d93025", "#188038", "#f9ab00", "#a142f4",
                   "#12b5cb", "#e37400"]


def forest(rows: Sequence[Mapping[str, Any]], kpis: Sequence[str], level: float) -> Figure:
    """One panel per KPI: each variant's paired difference from the baseline (dot) with its
    interval (bar), zero dashed; coloured by verdict. `rows`: compare.json comparisons."""
    labels = list(dict.fromkeys(_row_label(r) for r in rows))
    fig, axes = plt.subplots(1, len(kpis), figsize=(max(6.0, 4.2 * len(kpis)),
                                                    1.2 + 0.45 * len(labels)), squeeze=False)
    for ax, kpi in zip(axes[0], kpis, strict=True):
        for r in (r for r in rows if r["kpi"] == kpi):
            y = labels.index(_row_label(r))
            mean, low, high = r["difference"], r["ci_low"], r["ci_high"]
            if mean is None:
                continue
            colour = VERDICT_COLOURS.get(r["verdict"], "#202124")
            if low is not None and high is not None:
                ax.plot([low, high], [y, y], color=colour, lw=2.2, solid_capstyle="butt")
            ax.plot([mean], [y], "o", color=colour, ms=6)
        ax.axvline(0, color="#202124", lw=0.8, ls="--")
        ax.set_yticks(range(len(labels)))
        ax.set_yticklabels(labels if ax is axes[0][0] else [""] * len(labels), fontsize=8)
        ax.set_ylim(len(labels) - 0.5, -0.5)
        ax.set_xlabel("variant - baseline: " + kpi_label(kpi), fontsize=8)
        ax.grid(axis="x", color="#e8eaed")
    fig.suptitle(f"Paired differences from the baseline ({level:.2%} intervals, "
                 "Bonferroni-adjusted)\ngreen better, red worse, grey no difference, "
                 "amber undecided, blue higher/lower", fontsize=9)
    fig.tight_layout()
    return fig


def _row_label(row: Mapping[str, Any]) -> str:
    point = row.get("point") or {}
    where = ", ".join(f"{k}={v}" for k, v in point.items())
    return f"{row['variant']} ({where})" if where else str(row["variant"])


def kpis_side_by_side(means: Mapping[str, Mapping[str, tuple[float, float]]],
                      kpis: Sequence[str], variants: Sequence[str]) -> Figure:
    """One panel per KPI: every variant's mean (bar) and 95 % interval (whisker) side by side.
    `means`: KPI -> variant -> (mean, half-width)."""
    fig, axes = plt.subplots(1, len(kpis), figsize=(max(6.0, 4.0 * len(kpis)), 3.6),
                             squeeze=False)
    for ax, kpi in zip(axes[0], kpis, strict=True):
        values = [means.get(kpi, {}).get(v, (np.nan, np.nan)) for v in variants]
        x = np.arange(len(variants))
        colours = [VARIANT_COLOURS[i % len(VARIANT_COLOURS)] for i in range(len(variants))]
        ax.bar(x, [m for m, _ in values], color=colours, alpha=0.85,
               yerr=[0.0 if np.isnan(h) else h for _, h in values], capsize=4)
        ax.set_xticks(x)
        ax.set_xticklabels(variants, rotation=30, ha="right", fontsize=8)
        ax.set_ylabel(kpi_label(kpi), fontsize=8)
        ax.grid(axis="y", color="#e8eaed")
    fig.suptitle("Each variant's mean with its 95 % interval", fontsize=9)
    fig.tight_layout()
    return fig


def wait_difference(layout: Layout, baseline: Layout, diff_per_node: Mapping[str, float],
                    title: str) -> Figure:
    """The variant's track in grey; each node coloured by the change of AGV waiting there
    (variant minus baseline, s per hour): red more, blue less; size by its magnitude."""
    graph = layout.graph
    pos = {n: layout.position(n) for n in graph.nodes}
    for n in baseline.graph.nodes:
        pos.setdefault(n, baseline.position(n))
    xs = [p[0] for p in pos.values()]
    ys = [p[1] for p in pos.values()]
    span_x = (max(xs) - min(xs)) or 1.0
    span_y = (max(ys) - min(ys)) or 1.0
    width = min(12.0, max(6.0, span_x / 8))
    fig, ax = plt.subplots(figsize=(width, max(3.0, width * span_y / span_x) + 1.2))
    for u, v in graph.edges():
        (x0, y0), (x1, y1) = pos[u], pos[v]
        ax.plot([x0, x1], [y0, y1], color="#dadce0", lw=1.0, zorder=1)
    nodes = [n for n, d in diff_per_node.items() if n in pos and d != 0]
    if nodes:
        values = np.array([diff_per_node[n] for n in nodes], dtype=float)
        top = float(np.abs(values).max())
        pts = np.array([pos[n] for n in nodes])
        sc = ax.scatter(pts[:, 0], pts[:, 1], c=values, s=10 + 200 * np.abs(values) / top,
                        cmap="RdBu_r", norm=TwoSlopeNorm(0.0, -top, top), zorder=3,
                        edgecolors="#202124", linewidths=0.3)
        fig.colorbar(sc, ax=ax, shrink=0.8,
                     label="AGV waiting, variant - baseline [s per hour]")
    else:
        ax.text(0.5, 0.5, "AGVs waited exactly where and as long as in the baseline",
                transform=ax.transAxes, ha="center")
    return finish_floor_plan(fig, ax, title)


def close(fig: Any) -> None:
    plt.close(fig)
