"""A layout spec written as a layout file: one line per node, segment and place, as the bundled
layouts are written (`fleet-sim layout import` writes its layouts so)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import yaml

from fleet_sim.config.layout_spec import LayoutSpec
from userfiles.writing import comment_lines, tidy_numbers


def layout_yaml(spec: LayoutSpec, comments: Sequence[str] = ()) -> str:
    """The layout file of `spec`, one line per node, segment and place as the bundled layouts
    are written, `comments` as its first lines; loading it gives `spec` back."""
    lines = [comment_lines(comments).rstrip("\n")] if comments else []
    lines.append(_flow({"name": spec.name}))
    if spec.description:
        lines.append(_flow({"description": spec.description}))
    lines.append(_flow({"defaults": spec.defaults.model_dump(mode="json")}))
    sections: list[tuple[str, list[dict[str, Any]]]] = [
        ("nodes", [{"id": n.id, "x": n.x, "y": n.y, "kind": n.kind}
                   | ({"marker": n.marker} if n.marker is not None else {}) for n in spec.nodes]),
        ("segments", [s.model_dump(mode="json", by_alias=True, exclude_defaults=True)
                      for s in spec.segments]),
        ("stations", [{"id": s.id, "kind": s.kind, "nodes": list(s.nodes),
                       "handling": s.handling.model_dump(mode="json")}
                      | ({"allowed_types": list(s.allowed_types)} if s.allowed_types else {})
                      for s in spec.stations]),
        ("chargers", [c.model_dump(mode="json") for c in spec.chargers]),
        ("parking", [p.model_dump(mode="json") for p in spec.parking]),
        ("zones", [z.model_dump(mode="json", exclude_none=True) for z in spec.zones]),
        ("traffic_zones", [z.model_dump(mode="json", exclude_defaults=True)
                           for z in spec.traffic_zones]),
    ]
    for key, items in sections:
        if items or key in ("nodes", "segments", "stations", "parking"):
            lines.append(f"{key}:" if items else f"{key}: []")
            lines += [f"- {_flow(item)}" for item in items]
    lif = spec.lif.model_dump(mode="json", exclude_defaults=True)
    if lif:
        lines.append(_flow({"lif": lif}))
    return "\n".join(lines) + "\n"


def _flow(data: dict[str, Any]) -> str:
    """One mapping on one line (a top-level key's value in flow style)."""
    if len(data) == 1:
        (key, value), = data.items()
        if not isinstance(value, dict | list):
            return yaml.safe_dump(tidy_numbers(data), sort_keys=False, allow_unicode=True,
                                  width=1 << 30).rstrip("\n")
        return f"{key}: {_flow_value(value)}"
    return _flow_value(data)


def _flow_value(value: Any) -> str:
    text = yaml.safe_dump(tidy_numbers(value), default_flow_style=True, sort_keys=False,
                          allow_unicode=True, width=1 << 30)
    return text.rstrip("\n").removesuffix("\n...").rstrip("\n")


