"""The SUMO motion backend (`motion: sumo`): SUMO through libsumo (the ``sumo`` extra).

`require_backend` checks, without importing libsumo, that a backend's extra is installed,
so that a command fails in one line before any work (fleet_sim.errors.MissingExtra).
"""

from __future__ import annotations

from typing import Final

from fleet_sim.errors import require_extra

NEEDED_BY: Final = "motion: sumo"
"""What needs the SUMO extra, as the error line says it."""


def require_backend(motion: str, needed_by: str = NEEDED_BY) -> None:
    """Raise MissingExtra unless `motion`'s extra is installed (closed_form needs none):
    libsumo, and netconvert (from the eclipse-sumo wheel, or a SUMO on PATH)."""
    if motion == "sumo":
        from fleet_sim.sim.sumo.network import sumo_binary

        require_extra("libsumo", "sumo", needed_by)
        sumo_binary("netconvert", needed_by)
