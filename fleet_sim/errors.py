"""One error family for the project, so the command line can print one clear line and exit.

`InputError` (a user file holds a value the program cannot use) is the one input error of both
packages; it is defined in `userfiles.checking`, the ground floor under fleet_sim and agv_model
(vehicle profiles and link settings are read in agv_model, which never imports fleet_sim). It
is re-exported here.

The heavy parts are extras of the package (pyproject's optional-dependencies): a command that
needs one that is not installed ends in one line naming the extra and the install line
(`MissingExtra`), raised by `optional_import` or `require_extra`, the one way fleet_sim imports
an optional module. Decision: the test is "can Python find/import the module", not "is the
distribution installed" (a SUMO built from source, on PYTHONPATH, counts as installed).
"""

from __future__ import annotations

import importlib
import importlib.util
from types import ModuleType
from typing import Final

from userfiles.checking import InputError

__all__ = ["EXTRAS", "FleetSimError", "InputError", "MissingExtra", "SimulationError",
           "optional_import", "require_extra"]


class FleetSimError(Exception):
    """Base class of every error fleet_sim raises on purpose (input errors are `InputError`)."""


class SimulationError(FleetSimError):
    """The model reached a state it must never reach (a broken invariant)."""


EXTRAS: Final = {"sumo": "SUMO", "cluster": "cluster (Dask)", "export": "export"}
"""The package's extras (pyproject's optional-dependencies but dev), by name: their labels."""


class MissingExtra(FleetSimError):
    """A command needs a module of an extra that is not installed: `needed_by` (the command,
    option or file element that asks for it) needs the extra; one line, with the install line:
    ``motion: sumo needs the SUMO extra (libsumo is not installed): pip install
    'fleet-sim[sumo]'``."""

    def __init__(self, needed_by: str, extra: str, module: str, why: str = "is not installed"
                 ) -> None:
        self.needed_by = needed_by
        self.extra = extra
        self.module = module
        self.why = why
        super().__init__(f"{needed_by} needs the {EXTRAS[extra]} extra ({module} {why}): "
                         f"pip install 'fleet-sim[{extra}]'")

    def __reduce__(self) -> tuple[object, ...]:  # picklable across worker processes
        return (type(self), (self.needed_by, self.extra, self.module, self.why))


def require_extra(module: str, extra: str, needed_by: str) -> None:
    """Raise `MissingExtra` unless `module` can be found; does not import it (a check before
    work starts, in a process that must not load it, such as libsumo's one per process)."""
    try:
        found = importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):  # a parent package missing; a module set to None
        found = False
    if not found:
        raise MissingExtra(needed_by, extra, module)


def optional_import(module: str, extra: str, needed_by: str) -> ModuleType:
    """Import `module` of extra `extra`, or raise `MissingExtra` naming it."""
    try:
        return importlib.import_module(module)
    except ImportError as exc:
        top = module.partition(".")[0]
        missing = exc.name is None or exc.name == module or exc.name.partition(".")[0] == top
        raise MissingExtra(needed_by, extra, module, "is not installed" if missing
                           else f"cannot be imported: {exc}") from None
