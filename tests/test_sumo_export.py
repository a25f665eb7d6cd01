"""Layout -> SUMO network: the files netconvert makes load in SUMO, and carry over every
segment's length and speed limit exactly."""

from __future__ import annotations

import json
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml

from fleet_sim.config.layout import Layout, load_layout
from fleet_sim.config.vehicle import VehicleProfile
from fleet_sim.errors import InputError
from fleet_sim.sim.sumo.network import edge_id, export, read_edges

from .conftest import LAYOUTS, ROOT, write_yaml

# Runs in its own process: libsumo allows one simulation per process and a crash would take
# pytest with it. Drives one vehicle from rest over K -> SW -> S1 and stops it at the end.
DRIVE_ONE = """
import contextlib, io, json, sys
with contextlib.redirect_stdout(io.StringIO()):
    import libsumo
net, vtype = sys.argv[1], sys.argv[2]
libsumo.start(["sumo", "-n", net, "-a", vtype, "--step-length", "0.1",
               "--step-method.ballistic", "true", "--no-step-log", "true"])
libsumo.route.add("r", ["K~SW", "SW~S1"])
libsumo.vehicle.add("v", "r", typeID="agv", departPos="0", departSpeed="0")
libsumo.vehicle.setStop("v", "SW~S1", pos=4.0, duration=1e9)
out = {"edges": sorted(e for e in libsumo.edge.getIDList() if not e.startswith(":"))}
for _ in range(1000):
    libsumo.simulationStep()
    if libsumo.vehicle.getRoadID("v") == "SW~S1" and libsumo.vehicle.getSpeed("v") == 0.0:
        break
out.update(time_s=libsumo.simulation.getTime(), distance_m=libsumo.vehicle.getDistance("v"),
           length_m=libsumo.lane.getLength("SW~S1_0"),
           max_speed_mps=libsumo.vehicle.getMaxSpeed("v"))
libsumo.close()
print(json.dumps(out))
"""


@pytest.fixture(scope="module")
def tiny_net(tmp_path_factory: pytest.TempPathFactory, tiny_layout: Layout) -> Path:
    return export(tiny_layout, tmp_path_factory.mktemp("sumo")).net_file


def test_the_network_loads_and_a_vehicle_drives_on_it(tiny_net: Path,
                                                      tiny_layout: Layout) -> None:
    vtype = tiny_net.with_name("tiny_loop.vtype.xml")
    result = subprocess.run([sys.executable, "-c", DRIVE_ONE, str(tiny_net), str(vtype)],
                            capture_output=True, text=True, timeout=120, check=False)
    assert result.returncode == 0, result.stderr
    out = json.loads(result.stdout.strip().splitlines()[-1])
    assert out["edges"] == sorted(edge_id(u, v) for u, v in tiny_layout.graph.edges)
    assert out["length_m"] == pytest.approx(4.0, abs=1e-6)
    assert out["max_speed_mps"] == pytest.approx(1.0)
    # 8 m from rest to rest at 0.5 m/s2 and 1 m/s: 2 s up, 6 m cruise, 2 s down = 10 s,
    # plus the step in which SUMO inserts the vehicle; stops within 0.1 m of the node.
    assert out["distance_m"] == pytest.approx(8.0, abs=0.1)
    assert out["time_s"] == pytest.approx(10.1, abs=0.15)


@pytest.mark.parametrize("name", ["tiny_loop", "warehouse", "warehouse_wifi",
                                  "distribution_centre"])
def test_lengths_and_speed_limits_are_carried_over(tmp_path: Path, name: str) -> None:
    layout = load_layout(LAYOUTS / f"{name}.yaml")
    network = export(layout, tmp_path)
    edges = read_edges(network.net_file)
    assert len(edges) == layout.graph.number_of_edges()
    for u, v, data in layout.graph.edges(data=True):
        length, speed = edges[edge_id(u, v)]
        assert length == pytest.approx(data["length_m"], abs=1e-5)
        assert speed == pytest.approx(data["speed_limit_mps"], abs=1e-9)


def test_explicit_lengths_and_two_way_segments(tmp_path: Path) -> None:
    """A segment longer than the straight line keeps its length; two-way gives two edges."""
    layout_file = write_yaml(tmp_path / "l.yaml", {
        "name": "bent",
        "nodes": [{"id": "A", "x": 0, "y": 0, "kind": "station"},
                  {"id": "B", "x": 3, "y": 4, "kind": "station"},
                  {"id": "C", "x": 6, "y": 0, "kind": "parking"}],
        "segments": [{"from": "A", "to": "B", "length_m": 7.25, "speed_limit_mps": 0.5,
                      "direction": "two_way"},
                     {"from": "B", "to": "C"}, {"from": "C", "to": "A"}],
        "stations": [{"id": "P", "kind": "pickup", "nodes": ["A"]},
                     {"id": "D", "kind": "dropoff", "nodes": ["B"]}],
        "parking": [{"id": "K", "node": "C"}]})
    network = export(load_layout(layout_file), tmp_path / "out")
    edges = read_edges(network.net_file)
    assert edges[edge_id("A", "B")] == (7.25, 0.5)
    assert edges[edge_id("B", "A")] == (7.25, 0.5)
    assert edges[edge_id("B", "C")][0] == pytest.approx(5.0, abs=1e-6)
    # U-turns are connections: an AGV can reverse at B
    connections = {(c.get("from"), c.get("to"))
                   for c in ET.parse(network.net_file).getroot().iter("connection")}
    assert (edge_id("A", "B"), edge_id("B", "A")) in connections


def test_vehicle_type_comes_from_the_profile(tmp_path: Path, tiny_layout: Layout) -> None:
    profile = VehicleProfile(max_speed_mps=1.2, accel_mps2=0.4, decel_mps2=0.6, length_m=1.4,
                             min_gap_m=0.3)
    network = export(tiny_layout, tmp_path, profile, tau_s=0.8)
    vtype = ET.parse(network.vtype_file).getroot().find("vType")
    assert vtype is not None
    got = {k: vtype.get(k) for k in ("length", "maxSpeed", "accel", "decel", "minGap",
                                     "sigma", "tau")}
    assert got == {"length": "1.4", "maxSpeed": "1.2", "accel": "0.4", "decel": "0.6",
                   "minGap": "0.3", "sigma": "0", "tau": "0.8"}


def test_node_ids_sumo_cannot_take_are_named(tmp_path: Path) -> None:
    layout_file = write_yaml(tmp_path / "l.yaml", {
        "name": "odd",
        "nodes": [{"id": "A B", "x": 0, "y": 0, "kind": "station"},
                  {"id": "C", "x": 4, "y": 0, "kind": "station"},
                  {"id": "K", "x": 2, "y": 2, "kind": "parking"}],
        "segments": [{"from": "A B", "to": "C"}, {"from": "C", "to": "K"},
                     {"from": "K", "to": "A B"}],
        "stations": [{"id": "P", "kind": "pickup", "nodes": ["A B"]},
                     {"id": "D", "kind": "dropoff", "nodes": ["C"]}],
        "parking": [{"id": "KK", "node": "K"}]})
    with pytest.raises(InputError, match=r"nodes\[0\]\.id: got 'A B'"):
        export(load_layout(layout_file), tmp_path / "out")


def test_layout_command_writes_the_sumo_files(tmp_path: Path) -> None:
    result = subprocess.run([sys.executable, "-m", "fleet_sim.cli", "layout",
                             "layouts/tiny_loop.yaml", "--png", str(tmp_path / "t.png"),
                             "--sumo", str(tmp_path / "sumo")], cwd=ROOT, capture_output=True,
                            text=True, timeout=120, check=False)
    assert result.returncode == 0, result.stderr
    names = {p.name for p in (tmp_path / "sumo").iterdir()}
    assert names == {"tiny_loop.nod.xml", "tiny_loop.edg.xml", "tiny_loop.con.xml",
                     "tiny_loop.net.xml", "tiny_loop.vtype.xml"}
    assert "SUMO network" in result.stdout


def test_a_mixed_fleet_gets_a_vtype_and_a_class_per_type(tmp_path: Path) -> None:
    """One vType per vehicle type, each with a SUMO class of its own; a segment's per-type
    speed limits are its edge type's class restrictions (the network is read back and
    checked); a one-type fleet the layout gives no limit keeps the plain `agv` vType."""
    from fleet_sim.sim.sumo.network import read_class_limits, vehicle_classes

    data = yaml.safe_load((LAYOUTS / "tiny_loop.yaml").read_text("utf-8"))
    data["segments"][2]["speed_limit_mps_by_type"] = {"heavy": 0.4}
    data["segments"][3]["speed_limit_mps_by_type"] = {"heavy": 0.4, "carrier": 0.7}
    data["segments"][4]["speed_limit_mps_by_type"] = {"heavy": 0.4}
    layout = load_layout(write_yaml(tmp_path / "l.yaml", data))
    heavy = VehicleProfile(max_speed_mps=0.6, length_m=1.5, accel_mps2=0.3)
    classes = vehicle_classes({"carrier": VehicleProfile(), "heavy": heavy}, layout)
    assert [(c.vtype_id, c.vclass) for c in classes] == [("agv0_carrier", "custom1"),
                                                         ("agv1_heavy", "custom2")]
    network = export(layout, tmp_path / "out", classes=classes)
    assert network.types_file is not None
    assert read_class_limits(network.net_file) == {
        edge_id("P", "S3"): {"custom2": 0.4},
        edge_id("S3", "SE"): {"custom2": 0.4, "custom1": 0.7},
        edge_id("SE", "E1"): {"custom2": 0.4}}
    vtypes = {v.get("id"): (v.get("vClass"), v.get("maxSpeed"), v.get("length"))
              for v in ET.parse(network.vtype_file).getroot().iter("vType")}
    assert vtypes == {"agv0_carrier": ("custom1", "1.0", "1.0"),
                      "agv1_heavy": ("custom2", "0.6", "1.5")}
    (plain,) = vehicle_classes({"rss-agv-001": VehicleProfile()}, layout)
    assert (plain.vtype_id, plain.vclass) == ("agv", None)
    (named,) = vehicle_classes({"heavy": heavy}, layout)  # a one-type fleet the layout limits
    assert (named.vtype_id, named.vclass) == ("agv0_heavy", "custom1")
