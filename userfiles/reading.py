"""Reading the files users write: text, YAML and JSON, each refused in one `InputError` naming
the file (and the line) when it is missing, unreadable, oversized, not UTF-8, malformed, holds a
key twice, an alias bomb or absurdly deep nesting."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any, Final

import yaml

from userfiles.checking import InputError

MAX_FILE_BYTES: Final = 20 * 1024 * 1024
"""The largest input file read (20 MB): the biggest real layout or trace is far below it, and a
larger file is a mistake (a binary, a log) that would only exhaust memory."""
MAX_YAML_NODES: Final = 1_000_000
"""The most YAML nodes a file may stand for once its aliases are expanded: a real layout of
10,000 nodes is ~100,000; an alias bomb ("billion laughs") is refused before it is expanded."""
MAX_YAML_ALIASES: Final = 1_000
"""The most aliases (``*name``) a file may use: plenty for shared defaults."""


class _Refused(Exception):
    """Raised by `_Loader` while parsing: the element, the value and what was expected."""

    def __init__(self, element: str, value: object, expected: str) -> None:
        super().__init__(element)
        self.element = element
        self.value = value
        self.expected = expected


class Checks:
    """What a safe loader adds to refuse duplicate keys and alias bombs.

    The document is composed (an alias is the node it names, not a copy), then its size with
    its aliases expanded and the number of aliases are computed (each node once) before
    anything is constructed, so a bomb costs nothing. A duplicate key in one mapping (not one
    brought in by a ``<<`` merge) is an error naming the key and both lines."""

    def get_single_node(self) -> Any:
        node = super().get_single_node()  # type: ignore[misc]
        if node is not None:
            _check_expanded_size(node)
        return node

    def construct_mapping(self, node: Any, deep: bool = False) -> Any:
        if isinstance(node, yaml.MappingNode):
            seen: dict[Any, int] = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)  # type: ignore[attr-defined]
                line = key_node.start_mark.line + 1
                try:
                    first = seen.get(key)
                except TypeError:  # an unhashable key: SafeLoader says so itself
                    continue
                if first is not None:
                    raise _Refused(f"line {line}", key,
                                   f"each key once per mapping (key {key!r} is already on "
                                   f"line {first})")
                seen[key] = line
        return super().construct_mapping(node, deep=deep)  # type: ignore[misc]


_Loader: Any = type("_Loader", (Checks, getattr(yaml, "CSafeLoader", yaml.SafeLoader)), {})
"""A safe loader with the `Checks`, on libyaml's parser where PyYAML was built with it (about
ten times faster on a large layout, bench/layout_loading.py), else on PyYAML's own: both give
the same data, and the checks run on either."""


def _check_expanded_size(root: Any) -> None:
    """Refuse a document whose aliases expand to more than MAX_YAML_NODES nodes (or to itself).
    Iterative, so deep nesting cannot overflow the stack here."""
    size: dict[int, int] = {}
    on_path: set[int] = set()
    stack: list[tuple[Any, bool]] = [(root, False)]
    _count_aliases(root)
    while stack:
        node, done = stack.pop()
        key = id(node)
        if done:
            on_path.discard(key)
            children = _children(node)
            total = 1 + sum(size[id(c)] for c in children)
            if total > MAX_YAML_NODES:
                raise _Refused(f"line {node.start_mark.line + 1}", f"{total} nodes or more",
                               f"at most {MAX_YAML_NODES} YAML nodes with aliases expanded "
                               "(is this an alias bomb?)")
            size[key] = total
            continue
        if key in size:
            continue
        if key in on_path:
            raise _Refused(f"line {node.start_mark.line + 1}", "an alias inside itself",
                           "no recursive aliases")
        on_path.add(key)
        stack.append((node, True))
        stack.extend((c, False) for c in _children(node) if id(c) not in size)


def _count_aliases(root: Any) -> None:
    """Refuse more than MAX_YAML_ALIASES aliases: in the composed document an alias is one
    more reference to a node already referred to."""
    seen = {id(root)}
    stack = [root]
    aliases = 0
    while stack:
        for child in _children(stack.pop()):
            if id(child) not in seen:
                seen.add(id(child))
                stack.append(child)
                continue
            aliases += 1
            if aliases > MAX_YAML_ALIASES:
                raise _Refused(f"line {child.start_mark.line + 1}",
                               f"alias number {aliases} (of the node on this line)",
                               f"at most {MAX_YAML_ALIASES} aliases (*name) in one file")


def _children(node: Any) -> list[Any]:
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    if isinstance(node, yaml.MappingNode):
        return [n for pair in node.value for n in pair]
    return []


def read_text(path: Path, what: str = "file") -> str:
    """A user file as text: at most MAX_FILE_BYTES, UTF-8; otherwise an InputError naming it."""
    file = str(path)
    try:
        with path.open("rb") as handle:
            raw = handle.read(MAX_FILE_BYTES + 1)
    except FileNotFoundError:
        raise InputError(file, what, file, "an existing file") from None
    except IsADirectoryError:
        raise InputError(file, what, file, "a file, not a directory") from None
    except OSError as exc:
        raise InputError(file, what, file, f"a readable file ({exc.strerror})") from None
    if len(raw) > MAX_FILE_BYTES:
        raise InputError(file, what, f"more than {MAX_FILE_BYTES} bytes",
                         f"a file of at most {MAX_FILE_BYTES // (1024 * 1024)} MB")
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise InputError(file, what, f"byte 0x{raw[exc.start]:02x} at offset {exc.start}",
                         "a readable file (not UTF-8 text)") from None
    if "\x00" in text:
        raise InputError(file, what, f"a NUL byte at offset {text.index(chr(0))}",
                         "a readable file (not UTF-8 text: binary)")
    return text.removeprefix("\ufeff")


def read_yaml(path: Path) -> Any:
    """Read one YAML file; a missing, unreadable, oversized or non-UTF-8 file, bad syntax,
    a duplicate key, an alias bomb or absurdly deep nesting is an InputError naming the file
    (and the line)."""
    file = str(path)
    text = read_text(path)
    loader: Any = None
    try:
        loader = _Loader(text)  # checks the characters at once
        return loader.get_single_data()
    except _Refused as exc:
        raise InputError(file, exc.element, exc.value, exc.expected) from None
    except RecursionError:
        raise InputError(file, "document", "nesting too deep for Python's stack",
                         "YAML nested at most a few hundred levels deep") from None
    except yaml.reader.ReaderError as exc:
        raise InputError(file, f"character {exc.position}", f"#x{exc.character:04x}"
                         if isinstance(exc.character, int) else exc.character,
                         "printable YAML text (no control characters)") from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark is not None else "document"
        problem = getattr(exc, "problem", None) or "invalid YAML"
        raise InputError(file, where, problem, "valid YAML") from None
    finally:
        if loader is not None:
            loader.dispose()


def read_json(path: Path) -> Any:
    """Read one JSON file (RFC 8259); a missing, unreadable, oversized or non-UTF-8 file, bad
    syntax (named by line and column), a key written twice in one object, NaN or Infinity
    (not JSON, though Python writes them) or absurdly deep nesting is an InputError naming the
    file."""
    file = str(path)
    text = read_text(path)

    def refuse_constant(name: str) -> Any:
        raise _Refused("document", name, "finite numbers (NaN and Infinity are not JSON)")

    def one_key_each(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
        result: dict[str, Any] = {}
        for key, value in pairs:
            if key in result:
                raise _Refused("document", f"key {key!r} twice in one object",
                               "each key once per JSON object")
            result[key] = value
        return result

    try:
        return json.loads(text, parse_constant=refuse_constant, object_pairs_hook=one_key_each)
    except _Refused as exc:
        raise InputError(file, exc.element, exc.value, exc.expected) from None
    except RecursionError:
        raise InputError(file, "document", "nesting too deep for Python's stack",
                         "JSON nested at most a few hundred levels deep") from None
    except json.JSONDecodeError as exc:
        raise InputError(file, f"line {exc.lineno} column {exc.colno}", exc.msg,
                         "valid JSON") from None
