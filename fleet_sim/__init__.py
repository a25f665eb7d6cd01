"""fleet_sim: discrete-event AGV fleet throughput simulator for warehouse fleet sizing.

`import fleet_sim` stays light: the Python API (`run`, `sweep`, `size`, `compare`, `optimise`,
fleet_sim.api) and `InputError` are loaded on first use (PEP 562), so the `fleet-sim` command
and worker processes that import a submodule never pay for pandas here.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

__version__ = "0.1.0"

__all__ = ["InputError", "__version__", "compare", "optimise", "run", "size", "sweep"]

_API = frozenset({"compare", "optimise", "run", "size", "sweep"})

if TYPE_CHECKING:
    from fleet_sim.api import compare, optimise, run, size, sweep
    from fleet_sim.errors import InputError


def __getattr__(name: str) -> Any:
    if name in _API:
        import fleet_sim.api

        return getattr(fleet_sim.api, name)
    if name == "InputError":
        from fleet_sim.errors import InputError

        return InputError
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
