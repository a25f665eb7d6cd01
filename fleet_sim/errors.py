"""One error family for the project, so the command line can print one clear line and exit.

`InputError` (a user file holds a value the program cannot use) is the one input error of both
packages; it is defined in `agv_model.inputs`, the lowest layer, because vehicle profiles and
link settings are read there and agv_model never imports fleet_sim. It is re-exported here.
"""

from __future__ import annotations

from agv_model.inputs import InputError

__all__ = ["FleetSimError", "InputError", "SimulationError"]


class FleetSimError(Exception):
    """Base class of every error fleet_sim raises on purpose (input errors are `InputError`)."""


class SimulationError(FleetSimError):
    """The model reached a state it must never reach (a broken invariant)."""
