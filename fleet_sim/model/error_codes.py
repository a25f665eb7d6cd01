"""Error codes of RSS-AGV-001 6.1, with their levels. E_301 is the model's own (assumed) code
for a communication timeout, which 4.2.11 and Req.Err.011 send to Error but 6.1 does not list."""

from __future__ import annotations

CODES: dict[str, tuple[str, str]] = {
    "E_001": ("Warning", "route deviation (minor), automatic recovery"),
    "E_002": ("Warning", "Wi-Fi signal weak"),
    "E_101": ("Error", "obstacle timeout (5 minutes paused)"),
    "E_102": ("Error", "load transfer failed"),
    "E_201": ("Critical", "battery voltage critical"),
    "E_202": ("Critical", "magnetic sensor total loss (line lost)"),
    "E_999": ("Fatal", "CPU exception, watchdog reset"),
    "E_301": ("Error", "communication timeout (assumed code, not in 6.1)"),
}


def describe(code: str) -> tuple[str, str]:
    """(level, description) of an error code."""
    return CODES.get(code, ("Error", "unknown error code"))
