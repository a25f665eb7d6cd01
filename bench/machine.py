"""One line about the machine a benchmark ran on: cores and load averages, printed by every
timing bench at its start and end, so a figure is never quoted without the load it was taken
under (these machines are shared and noisy)."""

from __future__ import annotations

import os
import platform


def machine_line(when: str = "") -> str:
    """`machine: 2 cores, load 0.47 / 0.93 / 0.97 (1/5/15 min)`, with `when` before the load."""
    one, five, fifteen = os.getloadavg()
    label = f" {when}" if when else ""
    return (f"machine: {os.cpu_count()} cores ({platform.machine()}), load{label} "
            f"{one:.2f} / {five:.2f} / {fifteen:.2f} (1/5/15 min)")
