"""How the report words numbers and names: numbers for tables, units after numbers, factors in
words, lists joined with "and".

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from fleet_sim.analysis.kpis import kpi_unit


def fmt(value: Any, digits: int = 4) -> str:
    """Numbers for tables: no exponents for the sizes a planner reads."""
    if value is None:
        return "n/a"
    if isinstance(value, (float, np.floating)):
        if np.isnan(value):
            return "n/a"
        if abs(value) >= 10 ** (digits - 1):
            return f"{value:,.0f}"
        return f"{value:.{digits}g}"
    return str(value)


def unit_after(kpi: str, difference: bool = False) -> str:
    """The unit after a number; a difference of percentages is in percentage points."""
    unit = kpi_unit(kpi)
    if unit == "%" and difference:
        return " points"
    return f" {unit}" if unit and unit != "count" else ""


def factor_words(name: str) -> str:
    """A factor (a dotted scenario path) in words: ``demand.rate_per_hour`` -> ``demand rate
    per hour``."""
    return name.replace(".", " ").replace("_", " ")


def and_words(parts: list[str]) -> str:
    """Parts joined with commas and a last "and": ``a, b and c``."""
    return parts[0] if len(parts) == 1 else ", ".join(parts[:-1]) + " and " + parts[-1]
