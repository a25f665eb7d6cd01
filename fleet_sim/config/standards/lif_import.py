"""A VDMA LIF 1.0.0 file as a fleet_sim layout: `fleet-sim layout import`. One layout of the
file, for one vehicle type (or every type, `--all-types`); what is dropped on the way in is
noted (`Imported.notes`). The mapping is tabled in docs/reference/standards.md; the choices
where the format was silent: docs/background/decisions/config.md."""

from __future__ import annotations

import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from fleet_sim.config.layout_spec import LayoutDefaults, LayoutSpec
from fleet_sim.config.standards.lif import (
    LIF_VERSION,
    Layout,
    LifFile,
    TextNumber,
    read_lif_noting,
    text_number_warnings,
)
from fleet_sim.config.standards.lif_import_edges import segments_of
from fleet_sim.config.standards.lif_import_nodes import (
    node_entries,
    open_nodes,
    open_nodes_any,
    place_types,
    places_of,
    vehicle_types,
)
from fleet_sim.config.standards.lif_notes import Note, Notes, extra_keys
from fleet_sim.errors import InputError
from userfiles.checking import validate


@dataclass(frozen=True)
class Imported:
    """A layout read from a LIF file, and what of the file it does not keep."""

    spec: LayoutSpec
    file: str
    lif_version: str
    layout_id: str
    vehicle_type: str
    notes: tuple[Note, ...]
    text_numbers: tuple[TextNumber, ...] = ()
    """Numbers the file writes as texts, read as numbers (`warnings` tells them)."""

    def warnings(self) -> list[str]:
        """The lines the command prints on stderr: each kind of text number, once."""
        return text_number_warnings(self.file, self.text_numbers)

    def comments(self) -> list[str]:
        """The first lines of the layout file written from it."""
        lines = [f"Imported by `fleet-sim layout import` from {self.file}: LIF {self.lif_version}"
                 f", layout {self.layout_id}, vehicle type {self.vehicle_type}."]
        dropped = [n for n in self.notes if not n.kept]
        read_as = [n for n in self.notes if n.kept]
        if dropped:
            lines.append("Not kept (no place for it in a fleet_sim layout):")
            lines += [f"  - {n.line()}" for n in dropped]
        if read_as:
            lines.append("Read as:")
            lines += [f"  - {n.line()}" for n in read_as]
        if not dropped:
            lines.append("Nothing of the file was left out.")
        return lines


def import_lif(path: Path, layout_id: str | None = None,
               vehicle_type: str | None = None, all_types: bool = False) -> Imported:
    """Read a LIF file and turn one of its layouts into a layout spec (not yet checked as a
    graph: `layout_from_spec` does that). `all_types`: every vehicle type, as allowed_types
    (see the module docstring); `vehicle_type` is then the main one."""
    lif, text_numbers = read_lif_noting(path)
    return lif_to_layout(lif, str(path), layout_id, vehicle_type, all_types, text_numbers)


def lif_to_layout(lif: LifFile, file: str, layout_id: str | None = None,
                  vehicle_type: str | None = None, all_types: bool = False,
                  text_numbers: tuple[TextNumber, ...] = ()) -> Imported:
    notes = Notes()
    for number in text_numbers:
        notes.add(number.pattern, number.element, "numbers written as texts, read as the "
                  "numbers", kept=True)
    index = _choose_layout(lif, file, layout_id)
    layout = lif.layouts[index]
    at = f"layouts[{index}]"
    for i, other in enumerate(lif.layouts):
        if i != index:
            notes.add(f"layouts[{i}]", f"layouts[{i}]", f"layout {other.layoutId} not imported "
                      "(one layout per fleet_sim layout file; --layout-id chooses)")
    types: tuple[str, ...] | None = None
    if all_types:
        types = vehicle_types(layout)
        type_id = _choose_vehicle_type(layout, file, at, vehicle_type) \
            if vehicle_type is not None else types[0] if types else \
            _choose_vehicle_type(layout, file, at, None)
        types = (type_id, *(t for t in types if t != type_id))
    else:
        type_id = _choose_vehicle_type(layout, file, at, vehicle_type)
    for what, example in extra_keys(lif, "", ""):
        notes.add(what, example, "not a LIF 1.0.0 key")
    kept = open_nodes(layout, type_id, at, notes) if types is None \
        else open_nodes_any(layout, types, at, notes)
    claimed, places = places_of(layout, kept, at, notes)
    if types is not None:
        place_types(layout, places, types, at, notes)
    spec_nodes, map_ids = node_entries(kept, claimed, at, notes)
    extension = layout.fleetSim
    defaults = extension.defaults if extension is not None and extension.defaults is not None \
        else LayoutDefaults()
    segments = segments_of(layout.edges, kept, type_id, extension is not None, at, notes,
                         defaults, types)

    name = layout.layoutName if layout.layoutName is not None else layout.layoutId
    meta = lif.metaInformation
    lif_info: dict[str, Any] = {
        "project": meta.projectIdentification if meta.projectIdentification != name else None,
        "creator": meta.creator, "export_timestamp": meta.exportTimestamp,
        "layout_id": layout.layoutId if layout.layoutId != name else None,
        "layout_version": layout.layoutVersion, "level_id": layout.layoutLevelId,
        "vehicle_type_id": type_id}
    if len(map_ids) > 1:
        notes.add(f"{at}.nodes[*].mapId", f"{at}.nodes", f"nodes on {len(map_ids)} maps "
                  f"({', '.join(map_ids)}): a fleet_sim layout is one plane; mapId "
                  f"{map_ids[0]} kept")
    if map_ids and map_ids[0] != layout.layoutId:
        lif_info["map_id"] = map_ids[0]
    if meta.lifVersion != LIF_VERSION:
        notes.add("metaInformation.lifVersion", "metaInformation.lifVersion",
                  f"{meta.lifVersion}: an export writes {LIF_VERSION}", kept=True)
    data: dict[str, Any] = {"name": name}
    if layout.layoutDescription:
        data["description"] = layout.layoutDescription
    if extension is not None and extension.defaults is not None:
        data["defaults"] = extension.defaults.model_dump(mode="json")
    if extension is not None and extension.zones:
        data["zones"] = [z.model_dump(mode="json", exclude_none=True) for z in extension.zones]
    if extension is not None and extension.traffic_zones:
        data["traffic_zones"] = [z.model_dump(mode="json", exclude_defaults=True)
                                 for z in extension.traffic_zones]
    data |= {"nodes": spec_nodes, "segments": segments, **places,
             "lif": {k: v for k, v in lif_info.items() if v is not None}}
    spec = validate(LayoutSpec, data, file, at)
    return Imported(spec, file, meta.lifVersion, layout.layoutId, type_id, notes.notes(),
                    text_numbers)



def _choose_layout(lif: LifFile, file: str, layout_id: str | None) -> int:
    ids = [layout.layoutId for layout in lif.layouts]
    if not ids:
        raise InputError(file, "layouts", [], "at least one layout")
    if layout_id is not None:
        if layout_id not in ids:
            raise InputError(file, "layouts", layout_id,
                             f"the layoutId of one of its layouts: {', '.join(ids) or 'none'}")
        return ids.index(layout_id)
    if len(ids) != 1:
        choices = " or ".join(f"--layout-id {shlex.quote(layout.layoutId)} ({_size(layout)})"
                              for layout in lif.layouts)
        raise InputError(file, "layouts", ids, f"one layout; choose one with {choices}")
    return 0


def _size(layout: Layout) -> str:
    """``level 1, 12 nodes``: what tells one layout of a file from another."""
    nodes = len(layout.nodes)
    level = f"level {layout.layoutLevelId}, " if layout.layoutLevelId else ""
    return f"{level}{nodes} node{'' if nodes == 1 else 's'}"


def _choose_vehicle_type(layout: Layout, file: str, at: str, vehicle_type: str | None) -> str:
    types = vehicle_types(layout)
    if vehicle_type is not None:
        if vehicle_type not in types:
            raise InputError(file, f"{at}.nodes", vehicle_type,
                             f"a vehicleTypeId the layout uses: {', '.join(types) or 'none'}")
        return vehicle_type
    if len(types) != 1:
        choices = " or ".join(f"--vehicle-type {shlex.quote(t)}" for t in types)
        raise InputError(file, f"{at}.nodes", list(types),
                         f"one vehicle type; choose one with {choices} (or every one with "
                         "--all-types)" if types else "a vehicle type (no node names one)")
    return next(iter(types))
