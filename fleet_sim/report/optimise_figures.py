"""The optimise report's figure (matplotlib, Agg): price against each target's KPI, every
design that was run as a point with its 95 % interval, marked by its verdict, the bound and
its tolerance drawn, the answer ringed. Axes carry each KPI's name and unit from the KPI
catalogue (fleet_sim.analysis.kpis), never a raw key.

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.ticker import FuncFormatter

from fleet_sim.analysis.kpis import kpi_label

VERDICT_STYLE: dict[str, tuple[str, str]] = {
    "meets": ("#188038", "o"), "fails": ("#d93025", "X"), "undecided": ("#f9ab00", "D"),
    "not needed": ("#5f6368", "s"), "ruled out": ("#9aa0a6", "v"),
    "refused": ("#9aa0a6", "^"), "not examined": ("#9aa0a6", "."),
}
"""Verdict -> (colour, marker) of a design's point."""
ANSWER_COLOUR = "#1a73e8"


@dataclass(frozen=True)
class DesignPoint:
    """One design that was run, as the chart shows it."""

    price: float
    verdict: str
    values: Sequence[tuple[float | None, float | None, float | None]]
    """Per target: (mean, 95 % interval low, high); None where there is no value."""
    highlight: str = ""
    """Words to ring the point with: "the answer", or "closest" when no design meets."""


@dataclass(frozen=True)
class TargetLine:
    """A target as the chart draws it."""

    kpi: str
    bound: float
    at_least: bool
    tolerance: float | None


def price_against_targets(points: Sequence[DesignPoint], targets: Sequence[TargetLine],
                          currency: str) -> Figure:
    """One panel per target: every design run at its price (y) and its KPI (x: mean dot,
    95 % interval bar), marked by verdict; the bound dashed, its tolerance band shaded; the
    answer (else the closest design) ringed and named."""
    cols = max(1, len(targets))
    fig, axes = plt.subplots(1, cols, figsize=(max(6.0, 4.8 * cols), 4.4), squeeze=False,
                             sharey=True)
    seen: dict[str, None] = {}
    for k, (ax, target) in enumerate(zip(axes[0], targets, strict=True)):
        if target.tolerance:
            ax.axvspan(target.bound - target.tolerance, target.bound + target.tolerance,
                       color="#e8eaed", lw=0, zorder=0)
        ax.axvline(target.bound, color="#202124", lw=1.2, ls="--", zorder=1)
        for p in points:
            mean, low, high = p.values[k]
            if mean is None:
                continue
            colour, marker = VERDICT_STYLE.get(p.verdict, ("#202124", "o"))
            seen[p.verdict] = None
            if low is not None and high is not None:
                ax.plot([low, high], [p.price, p.price], color=colour, lw=2.0, alpha=0.8,
                        solid_capstyle="butt", zorder=2)
            ax.plot([mean], [p.price], marker=marker, color=colour, ms=7, ls="none",
                    zorder=3, markeredgecolor="white", markeredgewidth=0.5)
            if p.highlight:
                ax.plot([mean], [p.price], marker="o", ms=16, mfc="none", ls="none",
                        mec=ANSWER_COLOUR, mew=2.0, zorder=4)
                ax.annotate(p.highlight, (mean, p.price), xytext=(0, 11),
                            textcoords="offset points", fontsize=7, color=ANSWER_COLOUR,
                            ha="center", va="bottom", zorder=5)
        side = "at least" if target.at_least else "at most"
        ax.set_xlabel(kpi_label(target.kpi), fontsize=8)
        unit = kpi_label(target.kpi).partition(" [")[2].removesuffix("]")
        unit = f" {unit}" if unit and unit != "count" else ""
        ax.set_title(f"target: {side} {target.bound:g}{unit}", fontsize=9)
        ax.margins(y=0.12)
        ax.grid(color="#f1f3f4", zorder=0)
        ax.tick_params(labelsize=8)
    axes[0][0].set_ylabel(f"price [{currency}]", fontsize=8)
    axes[0][0].yaxis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:,.0f}"))
    handles = [Line2D([], [], color=VERDICT_STYLE.get(v, ("#202124", "o"))[0],
                      marker=VERDICT_STYLE.get(v, ("#202124", "o"))[1], ls="none", label=v)
               for v in seen]
    handles += [Line2D([], [], marker="o", ms=11, mfc="none", mec=ANSWER_COLOUR, mew=2.0,
                       ls="none", label=words)
                for words in dict.fromkeys(p.highlight for p in points if p.highlight)]
    handles.append(Line2D([], [], color="#202124", ls="--", label="target"))
    handles.append(Line2D([], [], color="#e8eaed", lw=6, label="target ± tolerance"))
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 7), fontsize=7,
               frameon=False)
    fig.suptitle("Price against each target's KPI: every design run (dot: mean; bar: 95 % "
                 "interval)", fontsize=9)
    fig.tight_layout(rect=(0.0, 0.08, 1.0, 1.0))
    return fig


def close(fig: Figure) -> None:
    plt.close(fig)
