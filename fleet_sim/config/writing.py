"""Small helpers shared by the writers of files a planner reads and edits (layouts and profiles
imported from LIF files and VDA 5050 factsheets)."""

from __future__ import annotations

from typing import Any


def tidy_numbers(value: Any) -> Any:
    """Whole numbers written without a decimal point (0, not 0.0), as a planner writes them;
    the value read back is equal."""
    if isinstance(value, float) and value.is_integer() and abs(value) < 1e15:
        return int(value)
    if isinstance(value, dict):
        return {k: tidy_numbers(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [tidy_numbers(v) for v in value]
    return value


def comment_lines(lines: Any) -> str:
    """`lines` as YAML comments; characters YAML may not hold become '?'."""
    return "".join("# " + "".join(c if c.isprintable() else "?" for c in line).rstrip() + "\n"
                   if line else "#\n" for line in lines)
