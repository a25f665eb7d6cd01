"""Layout -> SUMO network: plain node/edge/connection files, converted with `netconvert`.

The export is what a SUMO user would build by hand for tape-guided AGVs:

* One SUMO node per layout node (type ``unregulated``: who may enter a node is decided by the
  fleet model's node locks, not by SUMO's right-of-way rules), at the layout's coordinates
  (``--offset.disable-normalization``).
* One SUMO edge with one lane per direction of a segment (a two-way segment gives two edges),
  with the segment's speed limit and its length carried over exactly (an explicit ``length``
  attribute and ``--precision 6``; `check_network` reads the result back and compares).
* No internal junction lanes (``--no-internal-links``): a vehicle leaves one edge and is on the
  next, so the distance driven is the sum of the layout's segment lengths. The slow branch curve
  after a turn (Req.Nav.005) is not geometry here; the motion backend (fleet_sim.sim.sumo.backend)
  makes it a waypoint at the turn speed over the first ``turn_length_m`` of the edge.
* Every turn a layout allows is a connection, U-turns included (AGVs reverse at dead ends).
* The vehicle type comes from the vehicle profile: length, top speed, acceleration and
  deceleration, minimum gap; ``sigma=0`` (no driver imperfection: runs are deterministic) and
  ``tau`` (time headway; 1.0 s by default, so that at 1 m/s the following gap is
  min_gap_m + 1.0 m = 1.5 m, P_005's detection distance).
* Mixed fleets (`vehicle_classes`): one SUMO vType per vehicle type of the fleet (``agv0_carrier``,
  ``agv1_heavy``: its length, top speed, acceleration, deceleration and gap), each with a SUMO
  vehicle class of its own (``custom1``, ``custom2``, then other road classes SUMO lets drive
  everywhere), so that a segment's per-type speed limits (``speed_limit_mps_by_type``) are
  SUMO's vClass-specific speed limits: an edge type with a ``<restriction vClass speed>`` per
  limited type (SUMO brakes ahead of a lane slower for the vehicle's class as it does for any
  slower lane). A one-type fleet whose type the layout gives no limit of its own has the
  single ``agv`` vType without a class and the plain network.
* Segments open to some types only (``allowed_types``, ban zones) are not lane permissions: the
  fleet model's routes already keep each type off them and SUMO only drives the hops it is
  given, and netconvert would drop the turns between lanes that share no class, making a
  network that differs from the layout where `check_network` does not look.

Edge ids are ``<from>~<to>``; node ids must be valid SUMO ids (no spaces, no ``~``, none of
``|\\'";<>&``), which every bundled layout satisfies; others get an InputError naming the node.
"""

from __future__ import annotations

import math
import shutil
import subprocess
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Final

from fleet_sim.config.layout import Layout
from fleet_sim.config.vehicle import VehicleProfile
from fleet_sim.errors import FleetSimError, InputError, MissingExtra, optional_import

VTYPE_ID = "agv"
VCLASSES: Final = ("custom1", "custom2", "delivery", "truck", "trailer", "bus", "coach", "taxi",
                   "hov", "emergency", "authority", "army", "vip", "private", "evehicle",
                   "motorcycle", "moped")
"""SUMO vehicle classes given to a mixed fleet's types, in fleet order: the two custom
classes, then road classes that every edge allows by default (their other defaults are
overridden by the vType's explicit attributes)."""
EDGE_SEP = "~"
BAD_ID_CHARS = frozenset(" \t\n\r|\\'\";<>&" + EDGE_SEP)
LENGTH_TOLERANCE_M = 1e-5
"""Edge lengths read back from the network must match the layout within this."""


def edge_id(u: str, v: str) -> str:
    """The SUMO edge of segment u -> v."""
    return f"{u}{EDGE_SEP}{v}"


@dataclass(frozen=True)
class SumoNetwork:
    """The files of an exported layout."""

    net_file: Path
    vtype_file: Path
    nodes_file: Path
    edges_file: Path
    connections_file: Path
    types_file: Path | None = None
    """The edge types carrying per-type speed limits, if any segment has one."""


@dataclass(frozen=True)
class VehicleClass:
    """A vehicle type of the fleet as SUMO sees it."""

    name: str
    """The fleet's type (fleet.vehicles[].type, or a one-type fleet's vehicle.name)."""
    vtype_id: str
    vclass: str | None
    """SUMO's vehicle class; None: SUMO's default (a one-type fleet, no limits of its own)."""
    profile: VehicleProfile


def vehicle_classes(type_profiles: Mapping[str, VehicleProfile],
                    layout: Layout) -> tuple[VehicleClass, ...]:
    """The SUMO vType and class of each vehicle type (see the module docstring)."""
    if len(type_profiles) == 1 and not layout.speed_limited_types & set(type_profiles):
        ((name, profile),) = type_profiles.items()
        return (VehicleClass(name, VTYPE_ID, None, profile),)
    if len(type_profiles) > len(VCLASSES):
        raise FleetSimError(f"motion: sumo drives at most {len(VCLASSES)} vehicle types (one "
                            f"SUMO vehicle class each); the fleet has {len(type_profiles)}")
    return tuple(VehicleClass(name, f"{VTYPE_ID}{i}_{_safe_id(name)}", VCLASSES[i], profile)
                 for i, (name, profile) in enumerate(type_profiles.items()))


def _safe_id(name: str) -> str:
    return "".join("_" if c in BAD_ID_CHARS else c for c in name)


def class_limits(layout: Layout, classes: Sequence[VehicleClass]
                 ) -> dict[tuple[str, str], dict[str, float]]:
    """Segment -> SUMO class -> its speed limit there, for the segments that give a type of
    `classes` a limit of its own."""
    by_name = {c.name: c.vclass for c in classes if c.vclass is not None}
    out: dict[tuple[str, str], dict[str, float]] = {}
    for u, v, data in layout.graph.edges(data=True):
        limits = {by_name[name]: layout.speed_limit_mps(u, v, name)
                  for name in data["speed_limit_mps_by_type"] if name in by_name}
        if limits:
            out[u, v] = limits
    return out


def sumo_binary(name: str, needed_by: str = "layout --sumo") -> str:
    """Path of a SUMO tool (`netconvert`, `sumo`) from the eclipse-sumo package, else PATH."""
    try:
        sumo = optional_import("sumo", "sumo", needed_by)  # the eclipse-sumo wheel
    except MissingExtra as missing:  # a SUMO installed otherwise will do
        found = shutil.which(name)
        if found is None:
            raise MissingExtra(needed_by, "sumo", "eclipse-sumo",
                               f"is not installed and {name} is not on PATH") from missing
        return found
    candidate = Path(sumo.SUMO_HOME) / "bin" / name
    if candidate.exists():
        return str(candidate)
    found = shutil.which(name)
    if found is None:
        raise FleetSimError(f"{needed_by}: SUMO's {name} is neither in the eclipse-sumo "
                            f"package ({candidate}) nor on PATH: reinstall 'fleet-sim[sumo]'")
    return found


def _check_ids(layout: Layout) -> None:
    for node, data in layout.graph.nodes(data=True):
        if not node or any(c in BAD_ID_CHARS for c in node):
            raise InputError(layout.file, f"nodes[{data['index']}].id", node,
                             "an id SUMO accepts for export (no spaces, '~' or any of "
                             "|\\'\";<>&)")


def write_plain(layout: Layout, out_dir: Path,
                classes: Sequence[VehicleClass] = ()) -> tuple[Path, Path, Path]:
    """Write the plain node, edge and connection files (and, where `classes` have per-type
    speed limits, the edge types: `write_edge_types`); returns the three paths."""
    _check_ids(layout)
    edge_types = _edge_types(layout, classes)
    graph = layout.graph
    out_dir.mkdir(parents=True, exist_ok=True)
    nodes = ET.Element("nodes")
    for node, data in graph.nodes(data=True):
        ET.SubElement(nodes, "node", id=node, x=_num(data["x"]), y=_num(data["y"]),
                      type="unregulated")
    edges = ET.Element("edges")
    for u, v, data in graph.edges(data=True):
        element = ET.SubElement(edges, "edge", id=edge_id(u, v), attrib={
            "from": u, "to": v, "numLanes": "1", "speed": _num(data["speed_limit_mps"]),
            "length": _num(data["length_m"]), "spreadType": "center"})
        if (u, v) in edge_types:
            element.set("type", edge_types[u, v][0])
    connections = ET.Element("connections")
    for node in graph.nodes:
        for t in graph.predecessors(node):
            for v in graph.successors(node):
                ET.SubElement(connections, "connection", attrib={
                    "from": edge_id(t, node), "to": edge_id(node, v),
                    "fromLane": "0", "toLane": "0"})
    paths = []
    for root, suffix in ((nodes, "nod"), (edges, "edg"), (connections, "con")):
        path = out_dir / f"{layout.name}.{suffix}.xml"
        ET.indent(root)
        ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)
        paths.append(path)
    return paths[0], paths[1], paths[2]


def _edge_types(layout: Layout, classes: Sequence[VehicleClass]
                ) -> dict[tuple[str, str], tuple[str, dict[str, float]]]:
    """Segment -> (its edge type id, class -> speed), one edge type per distinct set of
    per-class limits."""
    ids: dict[tuple[tuple[str, float], ...], str] = {}
    out: dict[tuple[str, str], tuple[str, dict[str, float]]] = {}
    for segment, limits in class_limits(layout, classes).items():
        key = tuple(sorted(limits.items()))
        type_id = ids.setdefault(key, f"limits{len(ids)}")
        out[segment] = (type_id, limits)
    return out


def write_edge_types(layout: Layout, out_dir: Path,
                     classes: Sequence[VehicleClass]) -> Path | None:
    """The edge types file of the per-type speed limits (None: no segment has one)."""
    edge_types = _edge_types(layout, classes)
    if not edge_types:
        return None
    root = ET.Element("types")
    written: set[str] = set()
    for type_id, limits in edge_types.values():
        if type_id in written:
            continue
        written.add(type_id)
        element = ET.SubElement(root, "type", id=type_id, numLanes="1", priority="-1")
        for vclass, speed in limits.items():
            ET.SubElement(element, "restriction", vClass=vclass, speed=_num(speed))
    path = out_dir / f"{layout.name}.typ.xml"
    ET.indent(root)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)
    return path


def write_vtype(profile: VehicleProfile | Sequence[VehicleClass], path: Path,
                tau_s: float = 1.0) -> Path:
    """A SUMO additional file with the AGV vehicle type of `profile`, or one per class."""
    root = ET.Element("additional")
    classes = profile if not isinstance(profile, VehicleProfile) else \
        (VehicleClass(profile.name, VTYPE_ID, None, profile),)
    for item in classes:
        attrib = vtype_attributes(item.profile, tau_s) | {"id": item.vtype_id}
        if item.vclass is not None:
            attrib["vClass"] = item.vclass
        ET.SubElement(root, "vType", attrib=attrib)
    ET.indent(root)
    path.parent.mkdir(parents=True, exist_ok=True)
    ET.ElementTree(root).write(path, encoding="utf-8", xml_declaration=True)
    return path


def vtype_attributes(profile: VehicleProfile, tau_s: float) -> dict[str, str]:
    return {
        "id": VTYPE_ID, "length": _num(profile.length_m), "minGap": _num(profile.min_gap_m),
        "maxSpeed": _num(profile.max_speed_mps), "accel": _num(profile.accel_mps2),
        "decel": _num(profile.decel_mps2),
        "emergencyDecel": _num(2.0 * profile.decel_mps2), "sigma": "0", "tau": _num(tau_s),
        "speedFactor": "1", "speedDev": "0", "carFollowModel": "Krauss",
    }


def export(layout: Layout, out_dir: Path, profile: VehicleProfile | None = None,
           tau_s: float = 1.0, classes: Sequence[VehicleClass] = ()) -> SumoNetwork:
    """Write the plain files, the vehicle type and the converted `<name>.net.xml` to out_dir,
    and check the network against the layout. `classes` (`vehicle_classes`): a vType per
    vehicle type and their per-type speed limits instead of the one `profile`."""
    netconvert = sumo_binary("netconvert")  # before any file is written
    out_dir = Path(out_dir)
    nodes_file, edges_file, connections_file = write_plain(layout, out_dir, classes)
    types_file = write_edge_types(layout, out_dir, classes)
    net_file = out_dir / f"{layout.name}.net.xml"
    cmd = [netconvert, "--node-files", str(nodes_file),
           "--edge-files", str(edges_file), "--connection-files", str(connections_file),
           *(["--type-files", str(types_file)] if types_file is not None else []),
           "--output-file", str(net_file), "--no-internal-links", "true",
           "--offset.disable-normalization", "true", "--precision", "6",
           "--junctions.join", "false", "--geometry.remove", "false",
           "--no-turnarounds", "false", "--no-warnings", "true"]
    result = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if result.returncode != 0:
        raise FleetSimError(f"netconvert failed on layout {layout.name}: "
                            f"{(result.stderr or result.stdout).strip()}")
    vtype_file = write_vtype(classes or profile or VehicleProfile(),
                             out_dir / f"{layout.name}.vtype.xml", tau_s)
    check_network(layout, net_file, classes)
    return SumoNetwork(net_file, vtype_file, nodes_file, edges_file, connections_file,
                       types_file)


def read_edges(net_file: Path) -> dict[str, tuple[float, float]]:
    """Edge id -> (length_m, speed_mps) of the non-internal edges of a SUMO network."""
    out: dict[str, tuple[float, float]] = {}
    for edge in ET.parse(net_file).getroot().iter("edge"):
        if edge.get("function") == "internal":
            continue
        lanes = edge.findall("lane")
        if len(lanes) != 1:
            raise FleetSimError(f"{net_file}: edge {edge.get('id')} has {len(lanes)} lanes; "
                                "expected 1")
        lane = lanes[0]
        out[str(edge.get("id"))] = (float(lane.get("length", "nan")),
                                    float(lane.get("speed", "nan")))
    return out


def read_class_limits(net_file: Path) -> dict[str, dict[str, float]]:
    """Edge id -> SUMO class -> speed, from the edge types' restrictions of a network."""
    root = ET.parse(net_file).getroot()
    types = {str(t.get("id")): {str(r.get("vClass")): float(r.get("speed", "nan"))
                                for r in t.iter("restriction")} for t in root.iter("type")}
    return {str(edge.get("id")): types[str(edge.get("type"))] for edge in root.iter("edge")
            if edge.get("function") != "internal" and types.get(str(edge.get("type")))}


def check_network(layout: Layout, net_file: Path, classes: Sequence[VehicleClass] = ()) -> None:
    """Every segment is an edge of the same length and speed limit, and nothing else is; each
    per-type speed limit is its class's speed limit on that edge."""
    expected_limits = {edge_id(u, v): limits
                       for (u, v), limits in class_limits(layout, classes).items()}
    got_limits = read_class_limits(net_file)
    for eid in sorted(set(expected_limits) | set(got_limits)):
        want, got = expected_limits.get(eid, {}), got_limits.get(eid, {})
        if set(want) != set(got) or any(not math.isclose(got[c], want[c],
                                                         abs_tol=LENGTH_TOLERANCE_M)
                                        for c in want):
            raise FleetSimError(f"{net_file}: edge {eid} has class speed limits {got}; the "
                                f"layout says {want}")
    edges = read_edges(net_file)
    expected = {edge_id(u, v): (d["length_m"], d["speed_limit_mps"])
                for u, v, d in layout.graph.edges(data=True)}
    if set(edges) != set(expected):
        missing = sorted(set(expected) - set(edges))[:5]
        extra = sorted(set(edges) - set(expected))[:5]
        raise FleetSimError(f"{net_file}: edges differ from layout {layout.name} "
                            f"(missing {missing}, extra {extra})")
    for eid, (length, speed) in expected.items():
        got_length, got_speed = edges[eid]
        if not math.isclose(got_length, length, abs_tol=LENGTH_TOLERANCE_M) \
                or not math.isclose(got_speed, speed, abs_tol=LENGTH_TOLERANCE_M):
            raise FleetSimError(f"{net_file}: edge {eid} is {got_length} m at {got_speed} m/s; "
                                f"the layout says {length} m at {speed} m/s")


def _num(value: float) -> str:
    return repr(float(value))
