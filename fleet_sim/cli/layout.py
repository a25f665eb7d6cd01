"""The commands of the files a planner writes: `layout check|import|export` (a layout, VDMA
LIF), `profile import` (a VDA 5050 factsheet) and `schema` (the JSON Schema of a file kind).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from fleet_sim.cli.arguments import MAX_SPEED, SCHEMA_KINDS, identifier, timestamp
from fleet_sim.cli.registry import arg, command, group
from fleet_sim.cli.shared import check_out_file, write
from fleet_sim.errors import InputError

group("layout", "check a layout file and draw it to PNG (`layout FILE` is `layout check "
      "FILE`); `layout import` / `layout export` read and write VDMA LIF files",
      default="check")


@command(
    "layout check", "check a layout file and draw it to PNG (the default: `fleet-sim layout "
    "FILE`)",
    arg("layout", type=Path, help="layout YAML file"),
    arg("--png", type=Path, help="where to draw it (default: results/<name>.png)"),
    arg("--labels", action="store_true",
        help="write every node's id on the drawing, to find an aisle's nodes"),
    MAX_SPEED,
    arg("--sumo", type=Path, metavar="DIR",
        help="also export it as a SUMO network (plain XML, net.xml, vType) to DIR"))
def _layout(args: argparse.Namespace) -> int:
    from fleet_sim.config.layout import load_layout
    from fleet_sim.report.console import layout_lines
    from fleet_sim.report.layout_plot import draw_layout

    if args.png is not None:
        check_out_file(args.png, "--png")
    layout = load_layout(args.layout, max_speed_mps=args.max_speed)
    print(layout_lines(args.layout, layout))
    png = args.png or Path("results") / f"{layout.name}.png"
    check_out_file(png, "--png" if args.png else "results folder")
    draw_layout(layout, png, labels=args.labels)
    print(f"  drawing      {png}")
    if args.sumo is not None:
        from fleet_sim.sim.sumo.network import export

        network = export(layout, args.sumo)
        print(f"  SUMO network {network.net_file} (+ plain .nod/.edg/.con.xml, "
              f"{network.vtype_file.name})")
    return 0


@command(
    "layout import", "read a VDMA LIF 1.0.0 file and write a fleet_sim layout",
    arg("lif", type=Path, metavar="FILE.lif.json", help="LIF file"),
    arg("--out", type=Path, required=True, help="layout YAML file to write"),
    arg("--layout-id", type=identifier, metavar="ID",
        help="which layout of the file (needed if it has several)"),
    arg("--vehicle-type", type=identifier, metavar="ID",
        help="which vehicleTypeId's nodes, edges and speeds (needed if the layout is for "
             "several)"),
    arg("--all-types", action="store_true",
        help="import every vehicle type: segments and stations open to some types only get "
             "allowed_types (--vehicle-type: the type whose speeds and lengths are kept)"),
    description="Read a VDMA LIF 1.0.0 file and write a fleet_sim layout; what the layout "
                "cannot hold is listed.")
def _layout_import(args: argparse.Namespace) -> int:
    """LIF -> layout file. The layout is written even if it does not check as a graph yet (a
    LIF without parking, say): the planner completes it; the problem is named, exit status 1."""
    from fleet_sim.config.layout import layout_from_spec
    from fleet_sim.config.layout_yaml import layout_yaml
    from fleet_sim.config.standards.lif_import import import_lif
    from fleet_sim.report.console import lif_import_lines

    check_out_file(args.out, "--out")
    imported = import_lif(args.lif, args.layout_id, args.vehicle_type, args.all_types)
    for line in imported.warnings():
        print(f"fleet-sim: warning: {line}", file=sys.stderr)
    write(args.out, layout_yaml(imported.spec, imported.comments()), "--out")
    print(lif_import_lines(args.lif, args.out, imported))
    try:
        layout_from_spec(imported.spec, str(args.out))
    except InputError as exc:
        print(f"fleet-sim: warning: {exc} (written; complete the layout and check it with "
              "`fleet-sim layout`)", file=sys.stderr)
        return 1
    return 0


@command(
    "layout export", "write a fleet_sim layout as a VDMA LIF 1.0.0 file",
    arg("layout", type=Path, metavar="NAME.yaml", help="layout YAML file"),
    arg("--lif", type=Path, required=True, metavar="FILE.json", help="LIF file to write"),
    arg("--timestamp", type=timestamp, metavar="ISO|now",
        help="exportTimestamp (default: the layout's lif.export_timestamp, else "
             "1970-01-01T00:00:00.00Z, so the same layout gives the same file)"),
    arg("--vehicle-type", type=identifier, metavar="ID",
        help="vehicleTypeId to write (default: the layout's lif.vehicle_type_id, else "
             "fleet-sim)"),
    MAX_SPEED,
    description="Write a fleet_sim layout as a VDMA LIF 1.0.0 file.")
def _layout_export(args: argparse.Namespace) -> int:
    from fleet_sim.config.layout import load_layout
    from fleet_sim.config.standards.lif_export import layout_to_lif, lif_json
    from fleet_sim.report.console import lif_export_lines

    check_out_file(args.lif, "--lif")
    layout = load_layout(args.layout, max_speed_mps=args.max_speed)
    data = layout_to_lif(layout.spec, args.timestamp, args.vehicle_type)
    write(args.lif, lif_json(data), "--lif")
    print(lif_export_lines(args.layout, args.lif, layout.name, data, args.timestamp is not None))
    return 0


group("profile", "vehicle profiles: `profile import` makes one of a VDA 5050 factsheet")


@command(
    "profile import", "make a vehicle profile of a VDA 5050 2.1.0 factsheet",
    arg("factsheet", type=Path, metavar="FACTSHEET.json", help="factsheet file"),
    arg("--out", type=Path, required=True, help="profile YAML file to write"),
    arg("--base", default="rss-agv-001", metavar="PROFILE",
        help="bundled profile name or profile file giving the figures a factsheet lacks: turn "
             "speed, battery, link (default: rss-agv-001)"),
    description="Make a vehicle profile of a VDA 5050 2.1.0 factsheet: speeds, accelerations "
                "and length from the factsheet, the rest from a base profile; what is not used "
                "is listed.")
def _profile_import(args: argparse.Namespace) -> int:
    from fleet_sim.config.standards.factsheet_profile import import_factsheet
    from fleet_sim.report.console import profile_import_lines

    check_out_file(args.out, "--out")
    imported = import_factsheet(args.factsheet, args.base)
    write(args.out, imported.text(), "--out")
    print(profile_import_lines(args.factsheet, args.out, imported))
    return 0


@command("schema", "print the JSON Schema of a file kind, for editors",
         arg("kind", choices=SCHEMA_KINDS, help="which file"),
         arg("--out", type=Path, help="write it to this file instead"))
def _schema(args: argparse.Namespace) -> int:
    import json

    from fleet_sim.config.schemas import json_schema

    text = json.dumps(json_schema(args.kind), indent=2, ensure_ascii=False) + "\n"
    if args.out is None:
        sys.stdout.write(text)
        return 0
    write(args.out, text, "--out")
    print(f"{args.kind} schema: {args.out}")
    return 0
