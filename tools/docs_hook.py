"""MkDocs hook (mkdocs.yml `hooks:`): the reference pages that are generated from the code.

A page asks for a generated part with a marker on a line of its own, which this hook replaces
while the site is built (`make docs`, and tests/test_docs.py with --strict):

    <!-- fleet-sim: kpi-catalogue -->      the KPI catalogue, fleet_sim.analysis.kpis
    <!-- fleet-sim: schema KIND -->        the JSON Schema of a file kind, as tables
                                           (fleet_sim.config.schemas, `fleet-sim schema KIND`)
    <!-- fleet-sim: commands -->           every command's usage and arguments, from the
                                           parser the command registry builds (fleet_sim.cli)

Decisions, where the issue is silent:

* Markers in hand-written pages rather than whole generated pages: the prose around a table
  (what the window of a KPI is, where a format comes from) stays editable Markdown, the page
  exists on disk (links from the README and from GitHub's view resolve), and only the part that
  would drift from the code is generated. On GitHub a marker is an invisible comment.
* Every file kind of `FILE_MODELS` must have its page `reference/formats/KIND.md` with its
  marker, and every marker must name a known part: otherwise the build fails, so a new kind or
  a typo cannot pass the suite unnoticed.
* A schema is shown as one table per model (the root first, then each `$defs` entry in the
  order it is first reached), each with the key paths where it is used; types link to their
  model's table. A default that is an object is not repeated (its model's table gives each
  field's default); a default longer than 60 characters is cut.
* The commands are rendered from the argparse parser itself (`fleet_sim.cli.build_parser`),
  walking its subparsers in the registry's order: a command, an option or a choice added to
  the registry is on the page with nothing else to edit. Each command gets a heading (its
  words, anchor `#run`, `#layout-import`), its description, its usage line at a fixed width of
  100 and a table of its arguments; a group gets its help and the list of its commands.
* This module imports no MkDocs: the rendering is plain functions the test can call.
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path
from typing import Any

from fleet_sim.analysis.kpis import BY_TYPE, CATALOGUE, RUN_FIELDS, Kpi
from fleet_sim.config.schemas import FILE_MODELS, json_schema

MARKER = re.compile(r"^<!-- fleet-sim: ([a-z-]+)(?: ([a-z_-]+))? -->$", re.MULTILINE)
FORMATS_DIR = "reference/formats"


def _cell(text: str) -> str:
    return " ".join(str(text).split()).replace("|", "\\|")


def _anchor(name: str) -> str:
    return "model-" + re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-")


def _ref_name(ref: str) -> str:
    return ref.rsplit("/", 1)[-1]


def _type(schema: dict[str, Any]) -> str:
    """A schema's type in words, models linked to their tables."""
    if "$ref" in schema:
        name = _ref_name(schema["$ref"])
        return f"[{name}](#{_anchor(name)})"
    for key in ("anyOf", "oneOf", "allOf"):
        if key in schema:
            return " or ".join(dict.fromkeys(_type(s) for s in schema[key]))
    if "const" in schema:
        return f"`{json.dumps(schema['const'])}`"
    if "enum" in schema:
        return "one of " + ", ".join(f"`{json.dumps(v)}`" for v in schema["enum"])
    kind = schema.get("type")
    if isinstance(kind, list):
        return " or ".join(kind)
    if kind == "array":
        items = schema.get("items")
        if isinstance(items, dict) and items:
            return f"list of {_type(items)}"
        if "prefixItems" in schema:
            return "list (" + ", ".join(_type(s) for s in schema["prefixItems"]) + ")"
        return "list"
    if kind == "object":
        extra = schema.get("additionalProperties")
        if isinstance(extra, dict) and extra:
            return f"map of name to {_type(extra)}"
        return "object"
    return str(kind) if kind else "any"


_BOUNDS = (("minimum", ">= {}"), ("exclusiveMinimum", "> {}"), ("maximum", "<= {}"),
           ("exclusiveMaximum", "< {}"), ("minLength", "at least {} characters"),
           ("maxLength", "at most {} characters"), ("minItems", "at least {} items"),
           ("maxItems", "at most {} items"), ("pattern", "matches `{}`"),
           ("multipleOf", "a multiple of {}"))


def _constraints(schema: dict[str, Any]) -> str:
    parts = [text.format(schema[key]) for key, text in _BOUNDS if key in schema]
    for key in ("anyOf", "oneOf"):
        for option in schema.get(key, []):
            inner = _constraints(option)
            if inner:
                parts.append(inner)
    if schema.get("type") == "array" and isinstance(schema.get("items"), dict):
        inner = _constraints(schema["items"])
        if inner:
            parts.append(f"each {inner}")
    return "; ".join(dict.fromkeys(parts))


def _default(field: dict[str, Any], required: bool) -> str:
    if required:
        return "required"
    if "default" not in field:
        return ""
    value = field["default"]
    if isinstance(value, dict) and value:
        return "see its fields"
    text = json.dumps(value)
    return f"`{text if len(text) <= 60 else text[:57] + '...'}`"


def _models_in_order(schema: dict[str, Any]) -> list[tuple[str, dict[str, Any], list[str]]]:
    """The root model, then each $defs model as first reached, with the key paths using it."""
    defs: dict[str, Any] = schema.get("$defs", {})
    order: list[str] = []
    used_at: dict[str, list[str]] = {}

    active: list[str] = []

    def walk(node: Any, path: str) -> None:
        if isinstance(node, dict):
            if "$ref" in node:
                name = _ref_name(node["$ref"])
                if name not in used_at:
                    order.append(name)
                    used_at[name] = []
                if path not in used_at[name]:
                    used_at[name].append(path)
                if name not in active:  # a model inside itself: its paths once
                    active.append(name)
                    walk(defs[name], path)
                    active.pop()
                return
            for key, value in node.items():
                if key == "properties" and isinstance(value, dict):
                    for prop, sub in value.items():
                        walk(sub, f"{path}.{prop}" if path else prop)
                elif key == "items":
                    walk(value, f"{path}[]")
                elif key == "additionalProperties":
                    walk(value, f"{path}.<name>")
                elif key in ("anyOf", "oneOf", "allOf", "prefixItems"):
                    for sub in value:
                        walk(sub, path)

    walk({k: v for k, v in schema.items() if k != "$defs"}, "")
    models = [(schema.get("title", "root"), schema, ["(the file)"])]
    models += [(name, defs[name], used_at[name]) for name in order]
    return models


def render_schema(kind: str) -> str:
    """The JSON Schema of file kind `kind` as Markdown tables, one per model."""
    schema = json_schema(kind)
    out: list[str] = []
    for name, model, paths in _models_in_order(schema):
        out.append(f"## {name} {{#{_anchor(name)}}}")
        out.append("")
        shown = [f"`{p}`" if not p.startswith("(") else p for p in paths[:8]]
        where = ", ".join(shown) + (f" and {len(paths) - 8} more" if len(paths) > 8 else "")
        out.append(f"Used at: {where}.")
        if model.get("description"):
            out += ["", _cell(model["description"])]
        props: dict[str, Any] = model.get("properties", {})
        if props:
            required = set(model.get("required", []))
            out += ["", "| key | type | default | allowed | meaning |", "|---|---|---|---|---|"]
            for key, field in props.items():
                out.append(f"| `{key}` | {_cell(_type(field))} | "
                           f"{_cell(_default(field, key in required))} | "
                           f"{_cell(_constraints(field))} | "
                           f"{_cell(field.get('description', ''))} |")
            if model.get("additionalProperties") is False:
                out += ["", "No other keys are allowed."]
        else:
            out += ["", f"A value of type {_type(model)}."]
        out.append("")
    return "\n".join(out)


def _kpi_table(kpis: tuple[Kpi, ...], prefix: str = "") -> list[str]:
    rows = ["| key | unit | meaning |", "|---|---|---|"]
    rows += [f"| `{prefix}{k.name}` | {_cell(k.unit)} | {_cell(k.meaning)} |" for k in kpis]
    return rows


def render_kpis() -> str:
    """The KPI catalogue (fleet_sim.analysis.kpis) as Markdown."""
    out = [f"Generated from `fleet_sim.analysis.kpis.CATALOGUE` ({len(CATALOGUE)} KPIs).", ""]
    out += _kpi_table(CATALOGUE)
    out += ["", "## Per vehicle type {#per-vehicle-type}", "",
            "A mixed fleet (`fleet.vehicles`) adds `by_type`, the same sums over each type's "
            "AGVs (`fleet_sim.analysis.kpis.BY_TYPE`):", ""]
    out += _kpi_table(BY_TYPE, "by_type.<type>.")
    out += ["", "## Zones {#zones}", "",
            "`zone_wait_s.<zone>`: seconds waited to enter each mutex or same-direction "
            "traffic zone of the layout.", "",
            "## What kpis.json says about the run {#run-fields}", "",
            "Not KPIs: " + ", ".join(f"`{f}`" for f in RUN_FIELDS) + ".", ""]
    return "\n".join(out)


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    actions = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(actions[0].choices) if actions else {}


def _text(text: str | None) -> str:
    """Help text for Markdown: one line, `|` and `<` escaped (`results/<name>` is no tag)."""
    return _cell(text or "").replace("<", "&lt;")


def _argument_row(action: argparse.Action) -> str:
    if action.option_strings:
        name = ", ".join(action.option_strings)
        if action.nargs != 0:
            metavar = action.metavar or action.dest.upper()
            name += f" {metavar}" + (f" [{metavar} ...]" if action.nargs == "+" else "")
    else:
        name = str(action.metavar or action.dest)  # as the usage line shows it
    notes = []
    if action.choices is not None:
        notes.append("one of " + ", ".join(f"`{c}`" for c in action.choices))
    if action.required and action.option_strings:
        notes.append("required")
    help_text = " ".join([_text(action.help), *(f"({n})" for n in notes)])
    return f"| `{name}` | {help_text} |"  # a `|` in a code span splits no cell


def _command_lines(words: str, parser: argparse.ArgumentParser) -> list[str]:
    formatter = argparse.HelpFormatter(parser.prog, width=100)
    formatter.add_usage(parser.usage, parser._actions, parser._mutually_exclusive_groups)
    out = [f"### {words} {{#{words.replace(' ', '-')}}}", "", _text(parser.description), "",
           "```", formatter.format_help().strip(), "```", ""]
    arguments = [a for a in parser._actions if not isinstance(a, argparse._HelpAction)]
    if arguments:
        out += ["| argument | meaning |", "|---|---|"]
        out += [_argument_row(a) for a in arguments]
        out.append("")
    for group in parser._mutually_exclusive_groups:
        names = [a.option_strings[0] for a in group._group_actions]
        out += [f"{'Exactly' if group.required else 'At most'} one of "
                f"{', '.join(f'`{n}`' for n in names)}.", ""]
    if parser.epilog:
        out += [_text(parser.epilog), ""]
    return out


def render_commands() -> str:
    """Every command of `fleet-sim`: its usage and arguments, from the registry's parser."""
    from fleet_sim.cli import REGISTRY, Group, build_parser

    parser = build_parser()
    out = ["Generated from the command registry (`fleet_sim.cli`): the same parser "
           "`fleet-sim COMMAND --help` prints.", ""]
    for name, sub in _subcommands(parser).items():
        entry = REGISTRY[name]
        if isinstance(entry, Group):
            out += [f"### {name} {{#{name}}}", "", _text(entry.help), ""]
            out += [f"* [`{name} {word}`](#{name}-{word})"
                    + (f" (the default: `fleet-sim {name} ...` is `fleet-sim {name} {word} ...`)"
                       if word == entry.default else "")
                    for word in entry.commands]
            out.append("")
            for word, command in _subcommands(sub).items():
                out += _command_lines(f"{name} {word}", command)
        else:
            out += _command_lines(name, sub)
    return "\n".join(out)


def expand(markdown: str) -> str:
    """`markdown` with every generated part filled in; an unknown marker is an error."""
    def fill(match: re.Match[str]) -> str:
        part, argument = match.group(1), match.group(2)
        if part == "kpi-catalogue" and argument is None:
            return render_kpis()
        if part == "schema" and argument in FILE_MODELS:
            return render_schema(argument)
        if part == "commands" and argument is None:
            return render_commands()
        raise ValueError(f"unknown generated part {match.group(0)!r}; known: "
                         f"kpi-catalogue, commands, schema {{{','.join(FILE_MODELS)}}}")
    return MARKER.sub(fill, markdown)


def missing_format_pages(docs_dir: Path) -> list[str]:
    """File kinds without their page (reference/formats/KIND.md holding its marker)."""
    missing = []
    for kind in FILE_MODELS:
        page = docs_dir / FORMATS_DIR / f"{kind}.md"
        if not page.is_file() or f"<!-- fleet-sim: schema {kind} -->" not in page.read_text(
                encoding="utf-8"):
            missing.append(kind)
    return missing


# MkDocs hook events (https://www.mkdocs.org/user-guide/configuration/#hooks).

def on_config(config: Any) -> Any:
    missing = missing_format_pages(Path(config["docs_dir"]))
    if missing:
        raise ValueError(f"docs/{FORMATS_DIR}: no page for file kind(s) {', '.join(missing)}: "
                         f"add KIND.md with the line <!-- fleet-sim: schema KIND -->")
    return config


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    return expand(markdown)
