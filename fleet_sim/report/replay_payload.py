"""The replay page's payload, described once: the JSON that `page_data` (fleet_sim.report.replay)
writes into the page and static/replay.js reads (`D`).

Each TypedDict below is one object of the payload; mypy holds `page_data` to them, and the
JSDoc typedefs at the top of static/replay.js are generated from them (`jsdoc()`), with the
docstring under each field as its description. tests/test_replay.py checks that the file's
typedefs are today's and that every field the script reads of the payload is declared here.
To rewrite the typedefs after changing a type: ``python -m fleet_sim.report.replay_payload``.

The choices where the issues were silent: docs/background/decisions/reports.md.
"""

from __future__ import annotations

import ast
import inspect
import itertools
import sys
import types
import typing
from pathlib import Path
from typing import Any, Final, TypedDict, get_args, get_origin, get_type_hints

SCRIPT: Final = Path(__file__).parent / "static" / "replay.js"
BEGIN: Final = "/* ---- the payload: generated from fleet_sim/report/replay_payload.py, do not edit"
END: Final = "---- end of the payload ---- */"


class Meta(TypedDict):
    """The run and the window the page shows."""

    scenario: str
    layout: str
    agvs: int
    """Fleet size."""
    seed: int
    duration_s: float
    warmup_s: float
    start_h: float
    """Clock time at t=0 (hours)."""
    from_s: float
    """Start of the window (s since the run's start)."""
    to_s: float
    """End of the window."""
    resimulated: bool
    """The motion was simulated again from config.resolved.yaml (a sweep's run)."""


class Nodes(TypedDict):
    """The layout's nodes, sorted by id; other objects point at them by index."""

    id: list[str]
    x: list[float]
    """Metres."""
    y: list[float]
    kind: list[str]
    colour: list[str]
    """CSS colour: the place's, else the node kind's."""
    place: list[int]
    """Index into places, -1: none."""


class Segs(TypedDict):
    """The layout's segments (one per direction), sorted by (from, to)."""

    u: list[int]
    """From node (index)."""
    v: list[int]
    """To node (index)."""
    len: list[float]
    """Metres."""
    twoWay: list[int]
    """1 if the reverse segment exists."""


class Places(TypedDict):
    """Stations, chargers and parking areas, sorted by id."""

    id: list[str]
    kind: list[str]
    node: list[int]
    """Its first node (index)."""
    capacity: list[int]


class Profiles(TypedDict):
    """Each distinct hop profile once; drives point at it."""

    seg: list[int]
    """Segment (index)."""
    vin: list[float]
    """Entry speed (m/s)."""
    vout: list[float]
    """Exit speed (m/s)."""
    cm: list[float]
    """Branch curve length (m)."""
    cv: list[float]
    """Branch curve speed (m/s)."""
    lim: list[float]
    """Speed limit (m/s)."""
    acc: list[float]
    """Acceleration (m/s2)."""
    dec: list[float]
    """Deceleration (m/s2)."""


class AgvPlacements(TypedDict):
    """Where an AGV is: its drives and placements in time order."""

    t: list[float]
    """Start (s)."""
    e: list[float]
    """End (s)."""
    k: list[int]
    """Kind: 0 drive, 1 on the track, 2 in parking, 3 off the track."""
    a: list[int]
    """A drive's profile (index), else its node (index)."""
    d: list[float]
    """Seconds of the drive actually driven (less than the hop when paused)."""


class AgvSpells(TypedDict):
    """The AGV's state spells (the timeline)."""

    t: list[float]
    e: list[float]
    st: list[int]
    """State (index into states)."""
    ev: list[int]
    """Event that started it (index into strings)."""
    det: list[int]
    """Its detail (index into strings)."""
    o: list[int]
    """Order held, -1: none."""
    l: list[int]  # noqa: E741 (the page's key)
    """1: loaded."""


class AgvOrders(TypedDict):
    """The order the AGV holds, from each time on."""

    t: list[float]
    id: list[int]
    """Order id, -1: none."""


class AgvSoc(TypedDict):
    """State of charge samples."""

    t: list[float]
    v: list[float]
    """SOC (%)."""


class AgvWaits(TypedDict):
    """The AGV's waits for a lock."""

    t: list[float]
    e: list[float]
    n: list[int]
    """Node it waits at (index)."""
    lock: list[int]
    """The lock (index into strings)."""
    h: list[int]
    """The AGV that held it when the wait began, -1: none."""


class Agv(TypedDict):
    """One AGV, cut to the window."""

    id: int
    length_m: float
    p: AgvPlacements
    s: AgvSpells
    o: AgvOrders
    b: AgvSoc
    w: AgvWaits


class ChargerWaits(TypedDict):
    """AGVs waiting for a charger."""

    agv: list[int]
    t: list[float]
    e: list[float]
    n: list[int]
    """Node it waits at (index)."""
    ch: list[int]
    """The charger (index into places), -1: none."""


class Zones(TypedDict):
    """The layout's traffic zones."""

    id: list[str]
    kind: list[str]
    """mutex, ban or same_direction."""
    rule: list[str]
    colour: list[str]
    nodes: list[list[int]]
    """Nodes inside (indices)."""
    path: list[list[int]]
    """A same-direction zone's path in its forward order (indices)."""


class ZoneHolds(TypedDict):
    """Who held or waited for each mutex and same-direction zone."""

    agv: list[int]
    t: list[float]
    e: list[float]
    z: list[int]
    """Zone (index)."""
    dir: list[int]
    """1 forward, -1 backward, 0 a mutex zone."""


class Block(TypedDict):
    """A segment blocked by an incident."""

    u: int
    v: int
    t: float
    e: float


class Incidents(TypedDict):
    """Deadlocks, errors and other incidents to jump to."""

    t: list[float]
    agv: list[int]
    kind: list[int]
    """Index into strings."""
    code: list[int]
    """Index into strings."""
    det: list[int]
    """Index into strings."""


class Leads(TypedDict):
    """Orders delivered in the window and the parts of their lead times (s; -1: none)."""

    parts: list[str]
    """The part keys below, in order."""
    labels: list[str]
    colours: list[str]
    id: list[int]
    agv: list[int]
    created: list[float]
    lead: list[float]
    wait_assign_s: list[float]
    drive_empty_s: list[float]
    load_s: list[float]
    drive_loaded_s: list[float]
    unload_s: list[float]
    blocked_s: list[float]


class ReplayPayload(TypedDict):
    """Everything the page draws (`page_data`), in the page as JSON (#replay-data)."""

    meta: Meta
    states: list[str]
    """The RSS-AGV-001 states, in index order."""
    stateColours: list[str]
    nodes: Nodes
    segs: Segs
    corridors: dict[str, list[int]]
    """Each single-track corridor's segments (indices)."""
    places: Places
    profiles: Profiles
    agv: list[Agv]
    chargerWaits: ChargerWaits
    zones: Zones
    zoneHolds: ZoneHolds
    blocks: list[Block]
    incidents: Incidents
    leads: Leads
    strings: list[str]
    """Every repeated text once."""


PAYLOAD_TYPES: Final[tuple[type, ...]] = (
    ReplayPayload, Meta, Nodes, Segs, Places, Profiles, Agv, AgvPlacements, AgvSpells,
    AgvOrders, AgvSoc, AgvWaits, ChargerWaits, Zones, ZoneHolds, Block, Incidents, Leads)
"""Every object of the payload, the root first."""


def _field_docs(cls: type) -> dict[str, str]:
    """The docstring under each field of a TypedDict's source."""
    tree = ast.parse(inspect.getsource(cls))
    body = tree.body[0].body if isinstance(tree.body[0], ast.ClassDef) else []
    docs: dict[str, str] = {}
    for field, after in itertools.pairwise(body):
        if (isinstance(field, ast.AnnAssign) and isinstance(field.target, ast.Name)
                and isinstance(after, ast.Expr) and isinstance(after.value, ast.Constant)
                and isinstance(after.value.value, str)):
            docs[field.target.id] = " ".join(after.value.value.split())
    return docs


def _js_type(hint: Any) -> str:
    if hint in PAYLOAD_TYPES:
        return str(hint.__name__)
    if hint is bool:
        return "boolean"
    if hint in (int, float):
        return "number"
    if hint is str:
        return "string"
    origin = get_origin(hint)
    if origin is list:
        inner = _js_type(get_args(hint)[0])
        return f"{inner}[]"
    if origin is dict:
        key, value = get_args(hint)
        return f"Object<{_js_type(key)}, {_js_type(value)}>"
    if origin in (typing.Union, types.UnionType):
        return "(" + "|".join("null" if a is type(None) else _js_type(a)
                              for a in get_args(hint)) + ")"
    raise TypeError(f"no JavaScript type for {hint!r}")


def jsdoc() -> str:
    """The JSDoc typedefs of the payload, between BEGIN and END."""
    lines = [BEGIN, "   (python -m fleet_sim.report.replay_payload rewrites it). */", ""]
    for cls in PAYLOAD_TYPES:
        docs = _field_docs(cls)
        lines.append("/**")
        summary = " ".join((cls.__doc__ or "").split())
        lines.append(f" * {summary}")
        lines.append(f" * @typedef {{Object}} {cls.__name__}")
        for name, hint in get_type_hints(cls).items():
            doc = f" {docs[name]}" if name in docs else ""
            lines.append(f" * @property {{{_js_type(hint)}}} {name}{doc}".rstrip())
        lines.append(" */")
        lines.append("")
    lines.append(f"/* {END}")
    return "\n".join(lines)


def script_typedefs(script: str) -> str:
    """The typedef block of a script's text ('' if it has none)."""
    start = script.find(BEGIN)
    end = script.find(END, start)
    return script[start:end + len(END)] if start >= 0 and end >= 0 else ""


def write_typedefs(path: Path = SCRIPT) -> bool:
    """Rewrite the typedef block of `path` with today's; True if it changed."""
    text = path.read_text(encoding="utf-8")
    old = script_typedefs(text)
    if not old:
        raise ValueError(f"{path}: no typedef block ({BEGIN!r} ... {END!r})")
    new = text.replace(old, jsdoc())
    if new != text:
        path.write_text(new, encoding="utf-8")
    return new != text


if __name__ == "__main__":
    changed = write_typedefs()
    sys.stdout.write(f"{SCRIPT}: {'typedefs rewritten' if changed else 'typedefs up to date'}\n")
