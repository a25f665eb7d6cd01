"""One error family for the project, so the command line can print one clear line and exit."""

from __future__ import annotations


class FleetSimError(Exception):
    """Base class of every error fleet_sim raises on purpose."""


class InputError(FleetSimError):
    """A user file (layout, scenario, trace) holds a value fleet_sim cannot use.

    The message names the file, the element, the bad value and what was expected.
    """

    def __init__(self, file: str, element: str, value: object, expected: str) -> None:
        self.file = file
        self.element = element
        self.value = value
        self.expected = expected
        super().__init__(f"{file}: {element}: got {value!r}; expected {expected}")


class SimulationError(FleetSimError):
    """The model reached a state it must never reach (a broken invariant)."""
