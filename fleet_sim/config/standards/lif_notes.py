"""What of a LIF file an import does not keep, or reads in a way worth saying: LIF 8.1.1 asks
an importer to warn, so nothing is dropped silently."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

from pydantic import BaseModel

from fleet_sim.config.standards.lif import LifModel


@dataclass(frozen=True)
class Note:
    """Something of the LIF file the layout does not keep (or reads in a way worth saying)."""

    what: str
    """The JSON path, with [*] for every item of a list: ``layouts[0].nodes[*].nodeName``."""
    why: str
    count: int
    example: str
    """The JSON path of the first one."""
    kept: bool = False
    """True: read, but as `why` says; False: not kept."""

    def line(self) -> str:
        if self.count > 1:
            return f"{self.what} ({self.count}x, e.g. {self.example}): {self.why}"
        if self.example != self.what:
            return f"{self.what} ({self.example}): {self.why}"
        return f"{self.what}: {self.why}"


@dataclass
class Notes:
    """The notes of one import, counted by what they are about and why."""

    found: dict[tuple[str, str, bool], list[Any]] = field(default_factory=dict)

    def add(self, what: str, example: str, why: str, kept: bool = False) -> None:
        entry = self.found.setdefault((what, why, kept), [0, example])
        entry[0] += 1

    def notes(self) -> tuple[Note, ...]:
        return tuple(Note(what, why, count, example, kept)
                     for (what, why, kept), (count, example) in self.found.items())



def extra_keys(model: BaseModel, path: str, pattern: str) -> Iterator[tuple[str, str]]:
    """(pattern, path) of every key LIF does not name, anywhere in `model`."""
    for key in model.model_extra or {}:
        yield _dot(pattern, key), _dot(path, key)
    for name in type(model).model_fields:
        value = getattr(model, name)
        if isinstance(value, LifModel):
            yield from extra_keys(value, _dot(path, name), _dot(pattern, name))
        elif isinstance(value, tuple):
            for i, item in enumerate(value):
                if isinstance(item, LifModel):
                    keep = name == "layouts"
                    yield from extra_keys(item, f"{_dot(path, name)}[{i}]",
                                           f"{_dot(pattern, name)}[{i if keep else '*'}]")


def _dot(path: str, key: str) -> str:
    return f"{path}.{key}" if path else key
