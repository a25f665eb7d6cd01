"""Layout changes: a short list of edits a what-if variant makes to a layout, so that nobody
copies a 478-line layout file to change ten lines of it (docs/how-to/whatif.md shows every kind).

A change is a mapping with one key, its kind::

    layout_changes:
      - {one_way: [M007, A03_04, D11, A03_12]}     # each hop one-way, in the order listed
      - {two_way: [M007, A03_04]}                  # each hop two-way
      - {close_segment: [A03_16, D03]}             # the segment between two nodes goes
      - {close_node: A05_24}                       # the node and every segment at it go
      - {speed_limit: {chain: [M003, M004, M005], speed_mps: 0.8}}
      - {add_node: {id: C05, x: -4, y: 0, kind: charger}}
      - {add_segment: {from: M000, to: C05, direction: two_way}}
      - {add_charger: {id: CHG05, node: C05, power_kw: 3.0}}
      - {move_charger: {id: CHG01, node: C05}}     # move_station takes `nodes: [...]`
      - {remove_parking: PARK2}                    # remove_station, remove_charger too
      - {station_handling: {id: DROP03, handling: {dist: fixed, mean_s: 40}}}
      - {parking_capacity: {id: PARK1, capacity: 20}}

Changes apply in order to the layout file's own model, and the result goes through the same
validation as a layout file: nothing here re-implements a layout rule. The choices where the
issues were silent: docs/background/decisions/config.md.
"""

from __future__ import annotations

import difflib
import itertools
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Annotated, Any, ClassVar, Final

from pydantic import Discriminator, Field, Strict, Tag, ValidationError

from fleet_sim.config.distributions import TimeDistribution
from fleet_sim.config.layout import Layout, layout_from_spec
from fleet_sim.config.layout_spec import (
    ChargerSpec,
    LayoutSpec,
    NodeSpec,
    ParkingSpec,
    SegmentSpec,
    StationSpec,
)
from fleet_sim.errors import InputError
from userfiles.checking import Items, Positive, Problem, StrictModel, Text, input_error

Chain = Annotated[tuple[Text, ...], Strict(False), Field(min_length=2)]
"""Nodes in order, each joined to the next by a segment."""
Pair = Annotated[tuple[Text, Text], Strict(False)]


class Change(StrictModel):
    """A layout change: a mapping whose one key is its kind (KIND)."""

    KIND: ClassVar[str] = ""


class OneWay(Change):
    """Make every hop of a chain one-way, in the order the nodes are listed."""

    KIND: ClassVar[str] = "one_way"
    one_way: Chain


class TwoWay(Change):
    """Make every hop of a chain two-way."""

    KIND: ClassVar[str] = "two_way"
    two_way: Chain


class CloseSegment(Change):
    """Remove the segment between two nodes (both ways of a two-way segment)."""

    KIND: ClassVar[str] = "close_segment"
    close_segment: Pair


class CloseNode(Change):
    """Remove a node and every segment at it."""

    KIND: ClassVar[str] = "close_node"
    close_node: Text


class ChainSpeed(StrictModel):
    chain: Chain
    """Nodes in order; every hop's segment gets the limit."""
    speed_mps: Positive


class SpeedLimit(Change):
    """Set the speed limit of every segment along a chain."""

    KIND: ClassVar[str] = "speed_limit"
    speed_limit: ChainSpeed


class AddNode(Change):
    KIND: ClassVar[str] = "add_node"
    add_node: NodeSpec


class AddSegment(Change):
    KIND: ClassVar[str] = "add_segment"
    add_segment: SegmentSpec


class AddCharger(Change):
    KIND: ClassVar[str] = "add_charger"
    add_charger: ChargerSpec


class AddStation(Change):
    KIND: ClassVar[str] = "add_station"
    add_station: StationSpec


class AddParking(Change):
    KIND: ClassVar[str] = "add_parking"
    add_parking: ParkingSpec


class RemoveCharger(Change):
    KIND: ClassVar[str] = "remove_charger"
    remove_charger: Text


class RemoveStation(Change):
    KIND: ClassVar[str] = "remove_station"
    remove_station: Text


class RemoveParking(Change):
    KIND: ClassVar[str] = "remove_parking"
    remove_parking: Text


class PlaceAt(StrictModel):
    id: Text
    """The charger's or parking area's id."""
    node: Text
    """Its new node."""


class StationAt(StrictModel):
    id: Text
    """The station's id."""
    nodes: Items[Text]
    """Its new docking nodes."""


class MoveCharger(Change):
    KIND: ClassVar[str] = "move_charger"
    move_charger: PlaceAt


class MoveParking(Change):
    KIND: ClassVar[str] = "move_parking"
    move_parking: PlaceAt


class MoveStation(Change):
    KIND: ClassVar[str] = "move_station"
    move_station: StationAt


class Handling(StrictModel):
    id: Text
    """The station's id."""
    handling: TimeDistribution
    """Its new handling time."""


class StationHandling(Change):
    KIND: ClassVar[str] = "station_handling"
    station_handling: Handling


class Capacity(StrictModel):
    id: Text
    """The parking area's id."""
    capacity: int = Field(ge=1)
    """AGVs it holds."""


class ParkingCapacity(Change):
    KIND: ClassVar[str] = "parking_capacity"
    parking_capacity: Capacity


CHANGE_KINDS: Final[dict[str, type[Change]]] = {c.KIND: c for c in (
    OneWay, TwoWay, CloseSegment, CloseNode, SpeedLimit, AddNode, AddSegment, AddCharger,
    AddStation, AddParking, RemoveCharger, RemoveStation, RemoveParking, MoveCharger,
    MoveStation, MoveParking, StationHandling, ParkingCapacity)}
"""Every kind of layout change, by its key."""


def _kind_of(value: Any) -> str | None:
    if isinstance(value, dict):
        return next(iter(value), None) if len(value) == 1 else None
    return getattr(value, "KIND", None)


LayoutChange = Annotated[
    Annotated[OneWay, Tag("one_way")] | Annotated[TwoWay, Tag("two_way")]
    | Annotated[CloseSegment, Tag("close_segment")] | Annotated[CloseNode, Tag("close_node")]
    | Annotated[SpeedLimit, Tag("speed_limit")] | Annotated[AddNode, Tag("add_node")]
    | Annotated[AddSegment, Tag("add_segment")] | Annotated[AddCharger, Tag("add_charger")]
    | Annotated[AddStation, Tag("add_station")] | Annotated[AddParking, Tag("add_parking")]
    | Annotated[RemoveCharger, Tag("remove_charger")]
    | Annotated[RemoveStation, Tag("remove_station")]
    | Annotated[RemoveParking, Tag("remove_parking")]
    | Annotated[MoveCharger, Tag("move_charger")] | Annotated[MoveStation, Tag("move_station")]
    | Annotated[MoveParking, Tag("move_parking")]
    | Annotated[StationHandling, Tag("station_handling")]
    | Annotated[ParkingCapacity, Tag("parking_capacity")],
    Discriminator(_kind_of),
]
"""One layout change, chosen by its one key."""


def parse_changes(value: Any) -> Any:
    """A variant's `layout_changes` as written -> Change models, each checked against the
    model of its kind, so a problem names the change and the key inside it
    (``layout_changes[2].speed_limit.speed_mps``) through `Problem`; an unknown kind gets
    "did you mean". Anything but a list is left to pydantic."""
    if not isinstance(value, list | tuple):
        return value
    kinds = ", ".join(CHANGE_KINDS)
    out: list[Any] = []
    for i, change in enumerate(value):
        if isinstance(change, Change):
            out.append(change)
            continue
        if not isinstance(change, dict) or len(change) != 1:
            raise Problem(f"[{i}]", change, f"a mapping with one key, the kind of change "
                                            f"({kinds})")
        key = next(iter(change))
        if key not in CHANGE_KINDS:
            close = difflib.get_close_matches(str(key), list(CHANGE_KINDS), n=1)
            hint = f"; did you mean {close[0]}?" if close else ""
            raise Problem(f"[{i}]", key, f"a kind of layout change ({kinds}){hint}")
        model = CHANGE_KINDS[key]
        try:
            out.append(model.model_validate(change))
        except ValidationError as exc:
            error = input_error(exc, model, "")
            raise Problem(f"[{i}].{error.element}", error.value, error.expected) from None
    return tuple(out)


@dataclass(frozen=True)
class ChangeSite:
    """Where a variant's changes are written: names the change in every refusal."""

    file: str
    """The experiment file."""
    variant: str

    def element(self, index: int, change: Change) -> str:
        return f"variants.{self.variant}.layout_changes[{index}] ({change.KIND})"

    def refuse(self, index: int, change: Change, value: object, expected: str) -> InputError:
        return InputError(self.file, self.element(index, change), value, expected)


def _hop(a: str, b: str) -> str:
    return f"{a} -> {b}"


WHOLE: Final = "*"
"""A claim on a whole element (closing, adding or removing it): it conflicts with any other."""


@dataclass
class _Editor:
    """A layout spec taken apart for editing, with who changed what."""

    base: LayoutSpec
    site: ChangeSite
    nodes: dict[str, NodeSpec] = field(default_factory=dict)
    segments: list[SegmentSpec | None] = field(default_factory=list)
    stations: dict[str, StationSpec] = field(default_factory=dict)
    chargers: dict[str, ChargerSpec] = field(default_factory=dict)
    parking: dict[str, ParkingSpec] = field(default_factory=dict)
    claims: dict[tuple[str, str, str], int] = field(default_factory=dict)
    touched_nodes: dict[str, int] = field(default_factory=dict)
    touched_pairs: dict[frozenset[str], int] = field(default_factory=dict)
    touched_places: dict[str, int] = field(default_factory=dict)
    index: int = 0
    change: Change = field(default_factory=Change)
    changes: Sequence[Change] = ()

    def __post_init__(self) -> None:
        spec = self.base
        self.nodes = {n.id: n for n in spec.nodes}
        self.segments = list(spec.segments)
        self.stations = {s.id: s for s in spec.stations}
        self.chargers = {c.id: c for c in spec.chargers}
        self.parking = {p.id: p for p in spec.parking}

    # ---- bookkeeping

    def refuse(self, value: object, expected: str) -> InputError:
        return self.site.refuse(self.index, self.change, value, expected)

    def claim(self, kind: str, key: str, attribute: str, shown: str,
              again: bool = False) -> None:
        """Change `self.index` sets `attribute` of element (kind, key): refused if another
        change of the variant set it already (or owns the whole element), or if this change
        names it twice (unless `again`)."""
        mine = (kind, key, attribute)
        if again and self.claims.get(mine) == self.index:
            return
        clashes = [(k, i) for k, i in self.claims.items() if k[:2] == mine[:2]
                   and (k[2] == attribute or WHOLE in (k[2], attribute))]
        for (_, _, other_attr), other in clashes:
            if other == self.index:
                raise self.refuse(shown, f"each {kind} once in the change ({shown} comes "
                                         "twice)")
            other_change = self.changes[other]
            what = "the whole" if WHOLE in (other_attr, attribute) else f"the {attribute} of"
            raise self.refuse(shown, f"a {kind} no other change of variant "
                              f"{self.site.variant} sets: layout_changes[{other}] "
                              f"({other_change.KIND}) changes {what} {kind} {shown}")
        self.claims[mine] = self.index

    def node(self, node: str) -> str:
        if node not in self.nodes:
            closed = self.claims.get(("node", node, WHOLE))
            if closed is not None:
                raise self.refuse(node, f"a node of the layout (layout_changes[{closed}] "
                                        f"({self.changes[closed].KIND}) closes it)")
            close = difflib.get_close_matches(node, list(self.nodes), n=1)
            hint = f"; did you mean {close[0]}?" if close else ""
            raise self.refuse(node, f"the id of a node of layout {self.base.name}{hint}")
        self.touched_nodes[node] = self.index
        return node

    def between(self, a: str, b: str) -> list[int]:
        """Indices of the segments joining a and b (either way); refused if none."""
        self.node(a)
        self.node(b)
        found = [i for i, s in enumerate(self.segments) if s is not None
                 and {s.from_node, s.to_node} == {a, b}]
        if not found:
            raise self.refuse(_hop(a, b), f"two nodes joined by a segment of layout "
                              f"{self.base.name} (no segment joins {a} and {b})")
        self.touched_pairs[frozenset((a, b))] = self.index
        return found

    def hops(self, chain: Sequence[str], attribute: str) -> list[tuple[str, str, list[int]]]:
        out = []
        for a, b in itertools.pairwise(chain):
            self.claim("segment", "|".join(sorted((a, b))), attribute, _hop(a, b))
            found = self.between(a, b)
            out.append((a, b, found))
        return out

    def place_of(self, node: str) -> str | None:
        for s in self.stations.values():
            if node in s.nodes:
                return s.id
        for c in self.chargers.values():
            if c.node == node:
                return c.id
        for p in self.parking.values():
            if p.node == node:
                return p.id
        return None

    def place_ids(self) -> set[str]:
        return set(self.stations) | set(self.chargers) | set(self.parking)

    def take_node(self, node: str, kind: str, place_id: str) -> None:
        """`node` becomes a node of place `place_id` (kind charger, station or parking)."""
        self.node(node)
        owner = self.place_of(node)
        if owner is not None and owner != place_id:
            raise self.refuse(node, f"a node no other place uses ({owner} uses it)")
        current = self.nodes[node]
        if current.kind in ("tag", "junction"):
            self.nodes[node] = current.model_copy(update={"kind": kind})
        elif current.kind != kind:
            raise self.refuse(node, f"a tag, junction or {kind} node (it is a {current.kind} "
                                    "node)")

    def free_node(self, node: str) -> None:
        """`node` no longer belongs to a place: a tag again."""
        if node in self.nodes and self.place_of(node) is None:
            self.nodes[node] = self.nodes[node].model_copy(update={"kind": "tag"})
            self.touched_nodes[node] = self.index

    def existing(self, table: dict[str, Any], place_id: str, what: str) -> None:
        if place_id not in table:
            names = ", ".join(table) or "none"
            raise self.refuse(place_id, f"the id of a {what} of layout {self.base.name} "
                                        f"({names})")
        self.touched_places[place_id] = self.index

    def new_place(self, place_id: str) -> None:
        if place_id in self.place_ids():
            raise self.refuse(place_id, "an id no station, charger or parking area of layout "
                                        f"{self.base.name} has")
        self.claim("place", place_id, WHOLE, place_id)
        self.touched_places[place_id] = self.index

    # ---- the changes

    def apply(self, changes: Sequence[Change], skip: int | None = None) -> LayoutSpec:
        self.changes = changes
        for i, change in enumerate(changes):
            if i == skip:
                continue
            self.index, self.change = i, change
            getattr(self, f"_{change.KIND}")(change)
        segments = tuple(s for s in self.segments if s is not None)
        return self.base.model_copy(update={
            "nodes": tuple(self.nodes.values()), "segments": segments,
            "stations": tuple(self.stations.values()),
            "chargers": tuple(self.chargers.values()),
            "parking": tuple(self.parking.values())})

    def _one_way(self, change: OneWay) -> None:
        for a, b, found in self.hops(change.one_way, "direction"):
            forward = [i for i in found if getattr(self.segments[i], "from_node", "") == a]
            keep = forward[0] if forward else found[0]
            seg = self.segments[keep]
            assert seg is not None
            if seg.from_node != a:
                seg = seg.model_copy(update={"from_node": a, "to_node": b, "branch": "auto"})
            self.segments[keep] = seg.model_copy(update={"direction": "one_way"})
            for i in found:
                if i != keep:
                    self.segments[i] = None

    def _two_way(self, change: TwoWay) -> None:
        for _a, _b, found in self.hops(change.two_way, "direction"):
            keep = found[0]
            seg = self.segments[keep]
            assert seg is not None
            self.segments[keep] = seg.model_copy(update={"direction": "two_way"})
            for i in found[1:]:
                self.segments[i] = None

    def _speed_limit(self, change: SpeedLimit) -> None:
        for _a, _b, found in self.hops(change.speed_limit.chain, "speed limit"):
            for i in found:
                seg = self.segments[i]
                assert seg is not None
                self.segments[i] = seg.model_copy(
                    update={"speed_limit_mps": change.speed_limit.speed_mps})

    def _close_segment(self, change: CloseSegment) -> None:
        a, b = change.close_segment
        self.claim("segment", "|".join(sorted((a, b))), WHOLE, _hop(a, b))
        for i in self.between(a, b):
            self.segments[i] = None

    def _close_node(self, change: CloseNode) -> None:
        node = self.node(change.close_node)
        owner = self.place_of(node)
        if owner is not None:
            raise self.refuse(node, f"a node no station, charger or parking area uses ({owner} "
                                    "does: remove or move it in an earlier change)")
        self.claim("node", node, WHOLE, node)
        for i, seg in enumerate(self.segments):
            if seg is not None and node in (seg.from_node, seg.to_node):
                pair = (seg.from_node, seg.to_node)
                self.claim("segment", "|".join(sorted(pair)), WHOLE, _hop(*pair), again=True)
                self.touched_pairs[frozenset(pair)] = self.index
                self.touched_nodes[seg.to_node if seg.from_node == node else seg.from_node] \
                    = self.index
                self.segments[i] = None
        del self.nodes[node]

    def _add_node(self, change: AddNode) -> None:
        new = change.add_node
        if new.id in self.nodes:
            raise self.refuse(new.id, f"a node id layout {self.base.name} does not have yet")
        self.claim("node", new.id, WHOLE, new.id)
        self.nodes[new.id] = new
        self.touched_nodes[new.id] = self.index

    def _add_segment(self, change: AddSegment) -> None:
        seg = change.add_segment
        a, b = seg.from_node, seg.to_node
        self.node(a)
        self.node(b)
        self.claim("segment", "|".join(sorted((a, b))), WHOLE, _hop(a, b))
        if any(s is not None and {s.from_node, s.to_node} == {a, b} for s in self.segments):
            raise self.refuse(_hop(a, b), "two nodes no segment joins yet (change the one "
                                          "there with one_way, two_way or speed_limit)")
        self.segments.append(seg)
        self.touched_pairs[frozenset((a, b))] = self.index

    def _add_charger(self, change: AddCharger) -> None:
        new = change.add_charger
        self.new_place(new.id)
        self.take_node(new.node, "charger", new.id)
        self.chargers[new.id] = new

    def _add_parking(self, change: AddParking) -> None:
        new = change.add_parking
        self.new_place(new.id)
        self.take_node(new.node, "parking", new.id)
        self.parking[new.id] = new

    def _add_station(self, change: AddStation) -> None:
        new = change.add_station
        self.new_place(new.id)
        for node in new.nodes:
            self.take_node(node, "station", new.id)
        self.stations[new.id] = new

    def _remove(self, table: dict[str, Any], place_id: str, what: str) -> None:
        self.existing(table, place_id, what)
        self.claim("place", place_id, WHOLE, place_id)
        place = table.pop(place_id)
        for node in getattr(place, "nodes", None) or (place.node,):
            self.free_node(node)

    def _remove_charger(self, change: RemoveCharger) -> None:
        self._remove(self.chargers, change.remove_charger, "charger")

    def _remove_station(self, change: RemoveStation) -> None:
        self._remove(self.stations, change.remove_station, "station")

    def _remove_parking(self, change: RemoveParking) -> None:
        self._remove(self.parking, change.remove_parking, "parking area")

    def _move(self, table: dict[str, Any], place_id: str, nodes: Sequence[str], what: str,
              kind: str) -> None:
        self.existing(table, place_id, what)
        self.claim("place", place_id, "nodes", place_id)
        place = table[place_id]
        old = tuple(getattr(place, "nodes", None) or (place.node,))
        for node in nodes:
            self.take_node(node, kind, place_id)
        moved = place.model_copy(update={"nodes": tuple(nodes)} if kind == "station"
                                 else {"node": nodes[0]})
        table[place_id] = moved
        for node in old:
            if node not in nodes:
                self.free_node(node)

    def _move_charger(self, change: MoveCharger) -> None:
        to = change.move_charger
        self._move(self.chargers, to.id, (to.node,), "charger", "charger")

    def _move_parking(self, change: MoveParking) -> None:
        to = change.move_parking
        self._move(self.parking, to.id, (to.node,), "parking area", "parking")

    def _move_station(self, change: MoveStation) -> None:
        to = change.move_station
        if not to.nodes:
            raise self.refuse([], "at least one docking node")
        self._move(self.stations, to.id, to.nodes, "station", "station")

    def _station_handling(self, change: StationHandling) -> None:
        new = change.station_handling
        self.existing(self.stations, new.id, "station")
        self.claim("place", new.id, "handling", new.id)
        self.stations[new.id] = self.stations[new.id].model_copy(
            update={"handling": new.handling})

    def _parking_capacity(self, change: ParkingCapacity) -> None:
        new = change.parking_capacity
        self.existing(self.parking, new.id, "parking area")
        self.claim("place", new.id, "capacity", new.id)
        self.parking[new.id] = self.parking[new.id].model_copy(
            update={"capacity": new.capacity})

    # ---- blame

    def suspects(self, exc: InputError, spec: LayoutSpec) -> list[int]:
        """The changes that touched what the validation error `exc` names, latest first."""
        found: list[int] = []
        names: list[str] = []
        match = re.match(r"(nodes|segments|stations|chargers|parking)\[(\d+)\]", exc.element)
        if match:
            table = getattr(spec, match.group(1))
            i = int(match.group(2))
            if i < len(table):
                item = table[i]
                if isinstance(item, SegmentSpec):
                    names.append(_hop(item.from_node, item.to_node))
                else:
                    names.append(item.id)
        for value in (exc.value, *re.findall(r"\(([^()\s]+)\)", exc.element)):
            if isinstance(value, str):
                names.append(value)
        for name in names:
            ends = name.split(" -> ")
            if len(ends) == 2 and frozenset(ends) in self.touched_pairs:
                found.append(self.touched_pairs[frozenset(ends)])
            if name in self.touched_places:
                found.append(self.touched_places[name])
            if name in self.touched_nodes:
                found.append(self.touched_nodes[name])
        return sorted(set(found), reverse=True)


def apply_changes(base: LayoutSpec, changes: Sequence[Change], site: ChangeSite,
                  skip: int | None = None) -> LayoutSpec:
    """`base` with `changes` applied in order (the one at index `skip` left out); a change
    that names a missing element or conflicts with another is refused. Not validated."""
    return _Editor(base, site).apply(changes, skip)


def changed_layout(base: Layout, changes: Sequence[Change], site: ChangeSite,
                   max_speed_mps: float | None = None,
                   check: Callable[[Layout], None] | None = None) -> Layout:
    """The layout `base` with `changes` applied and validated as a layout file is, then held
    against `check` (the scenario's checks); every problem is a refusal of one change."""
    if not changes:
        return base
    editor = _Editor(base.spec, site)
    spec = editor.apply(changes)
    try:
        layout = layout_from_spec(spec, base.file, max_speed_mps)
        if check is not None:
            check(layout)
    except InputError as exc:
        raise _blame(exc, editor, spec, base, changes, site, max_speed_mps, check) from None
    return layout


def _blame(exc: InputError, editor: _Editor, spec: LayoutSpec, base: Layout,
           changes: Sequence[Change], site: ChangeSite, max_speed_mps: float | None,
           check: Callable[[Layout], None] | None) -> InputError:
    suspects = editor.suspects(exc, spec)
    if not suspects:
        for k in reversed(range(len(changes))):
            try:
                trial = layout_from_spec(apply_changes(base.spec, changes, site, skip=k),
                                         base.file, max_speed_mps)
                if check is not None:
                    check(trial)
            except InputError:
                continue
            suspects = [k]
            break
    index = suspects[0] if suspects else len(changes) - 1
    where = "the scenario" if exc.file != base.file else f"layout {base.name}"
    return site.refuse(index, changes[index], exc.value,
                       f"changes that leave {where} valid (after them, {exc.element}: "
                       f"{exc.expected})")


@dataclass(frozen=True)
class LayoutDiff:
    """What differs between two layouts (a variant's against its baseline's), for drawing a
    variant with its changes highlighted."""

    changed_nodes: tuple[str, ...]
    """Nodes of the new layout that are new, moved, of another kind or at a changed place."""
    removed_nodes: tuple[str, ...]
    """Nodes only the old layout has."""
    changed_segments: tuple[tuple[str, str], ...]
    """Directed hops (from, to) of the new layout that are new or changed (direction, speed
    limit, length, anything)."""
    removed_segments: tuple[tuple[str, str], ...]
    """Directed hops only the old layout has (a two-way segment made one-way loses one)."""
    changed_places: tuple[str, ...]
    """Stations, chargers and parking areas that are new or changed."""
    removed_places: tuple[str, ...]

    @property
    def empty(self) -> bool:
        return not (self.changed_nodes or self.removed_nodes or self.changed_segments
                    or self.removed_segments or self.changed_places or self.removed_places)


SEGMENT_FIELDS: Final = ("length_m", "speed_limit_mps", "two_way", "branch", "rssi_dbm",
                         "obstacle_rate_per_km", "obstacle_duration", "allowed_types",
                         "speed_limit_mps_by_type")
"""What the layout says about a hop (graph edge data; the segment's place in the file and
what the engine caches on the graph, such as free_time_s, are not compared)."""
NODE_FIELDS: Final = ("x", "y", "kind")


def layout_diff(old: Layout, new: Layout) -> LayoutDiff:
    """What `new` changes against `old` (the segments' order in the file is not compared)."""
    def edge(layout: Layout, u: str, v: str) -> dict[str, Any]:
        data = layout.graph.edges[u, v]
        return {k: data.get(k) for k in SEGMENT_FIELDS}

    def node(layout: Layout, n: str) -> dict[str, Any]:
        data = layout.graph.nodes[n]
        return {k: data.get(k) for k in NODE_FIELDS}

    old_places, new_places = old.places, new.places
    changed_places = sorted(p for p in new_places if old_places.get(p) != new_places[p])
    removed_places = sorted(p for p in old_places if p not in new_places)
    place_nodes = {n for p in changed_places for n in new_places[p].nodes} \
        | {n for p in (*changed_places, *removed_places) if p in old_places
           for n in old_places[p].nodes}
    changed_nodes = sorted(n for n in new.graph.nodes if n not in old.graph
                           or node(old, n) != node(new, n) or n in place_nodes)
    removed_nodes = sorted(n for n in old.graph.nodes if n not in new.graph)
    changed_segments = sorted((u, v) for u, v in new.graph.edges
                              if not old.graph.has_edge(u, v)
                              or edge(old, u, v) != edge(new, u, v))
    removed_segments = sorted((u, v) for u, v in old.graph.edges
                              if not new.graph.has_edge(u, v))
    return LayoutDiff(tuple(changed_nodes), tuple(removed_nodes), tuple(changed_segments),
                      tuple(removed_segments), tuple(changed_places), tuple(removed_places))

