"""One way to read and check every file a user writes: layouts, scenarios, experiments, order
traces, vehicle profiles and link settings, and the JSON files of standards fleet-sim reads
(VDMA LIF layouts, VDA 5050 factsheets).

Each file is a pydantic model built on `StrictModel`; `validate` turns the first problem pydantic
finds into one `InputError` whose message names the file, the element (a dotted path such as
``segments[12].to`` or ``fleet.vehicle.accel_mps2``), the value and what was expected.

Decisions, where the issue is silent:

* Strict types, as the hand-written parser was: a bool is not a number, a number is not a list,
  a text is not a number, 3.0 is not an integer. Two exceptions keep old files loading: lists
  stand for tuples (`Items`), and a number may stand for a text (node ids such as ``12``).
* A non-finite number (``.nan``, ``.inf``) is refused everywhere (`allow_inf_nan=False`), and so
  is a finite one beyond a field's bounds.
* A check that involves several fields (``turn_speed_mps`` at most ``max_speed_mps``) is a
  `model_validator` raising `Problem(key, value, expected)`: the key is added to the element
  path of the model that failed, so the message points at the field, not at the section.
* An unknown key names the known keys of its mapping and, where one is close (difflib's
  `get_close_matches`, ratio >= 0.65, or the one key the word begins or that begins it), the
  key that was probably meant: ``no such key here:
  did you mean 'size'? (known keys: ...)``.
* Within a discriminated union (the time distributions, tagged by ``dist``) the tag is not part
  of the element path; an unknown key says which tag it was checked against.
* Built in code (``LinkSettings(baud=0)``), a model raises pydantic's ValidationError; only
  files go through `validate`. (Overriding ``__init__`` to convert would make pydantic call it
  for every nested model while loading a file.)
* This module lives in agv_model, the lowest layer, because profiles and link settings live
  here and agv_model never imports fleet_sim; fleet_sim.errors re-exports `InputError`.
"""

from __future__ import annotations

import difflib
import json
import types
import typing
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Annotated, Any, Final, Literal, TypeVar, get_args, get_origin

import annotated_types
import yaml
from pydantic import BaseModel, ConfigDict, Field, Strict, ValidationError, WithJsonSchema
from pydantic.fields import FieldInfo

T = TypeVar("T")
M = TypeVar("M", bound=BaseModel)

Items = Annotated[tuple[T, ...], Strict(False)]
"""A list in the file, a tuple in the model (so configs stay hashable)."""
Text = Annotated[str, Strict(False), WithJsonSchema({"type": ["string", "number"]})]
"""A text; a number written where a text is expected (an id such as 12) becomes its text."""
Positive = Annotated[float, Field(gt=0)]
"""A finite number > 0."""
NonNegative = Annotated[float, Field(ge=0)]
"""A finite number >= 0."""
Percent = Annotated[float, Field(ge=0, le=100)]
"""A percentage in [0, 100]."""
Share = Annotated[float, Field(ge=0, le=1)]
"""A share or probability in [0, 1]."""
HourOfDay = Annotated[float, Field(ge=0, lt=24)]
"""A clock hour in [0, 24)."""


class InputError(ValueError):
    """A user file holds a value the program cannot use.

    The message names the file, the element, the bad value and what was expected:
    ``layouts/x.yaml: segments[12].to: got 'ZZ'; expected the id of a node in `nodes```.
    An argument that is itself the element (``--agvs``) has no element: ``--agvs: got 12;
    expected ...``.
    """

    def __init__(self, file: str, element: str, value: object, expected: str) -> None:
        self.file = file
        self.element = element
        self.value = value
        self.expected = expected
        where = f"{file}: {element}" if element else file
        super().__init__(f"{where}: got {value!r}; expected {expected}")

    def __reduce__(self) -> tuple[Any, ...]:  # picklable across worker processes
        return (type(self), (self.file, self.element, self.value, self.expected))


class Problem(ValueError):
    """Raised inside a model's validators: `key` (relative to the model) holds `value`, and
    `expected` says what it should be. `validate` turns it into an InputError."""

    def __init__(self, key: str, value: object, expected: str) -> None:
        self.key = key
        self.value = value
        self.expected = expected
        super().__init__(f"{key}: got {value!r}; expected {expected}")


class StrictModel(BaseModel):
    """The base of every model of a user file: frozen, unknown keys refused, strict types,
    no NaN or infinity, field docstrings as schema descriptions."""

    model_config = ConfigDict(extra="forbid", frozen=True, strict=True, allow_inf_nan=False,
                              coerce_numbers_to_str=True,
                              use_attribute_docstrings=True, validate_default=False)


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


class _Loader(yaml.SafeLoader):
    """SafeLoader that refuses duplicate keys and alias bombs.

    Aliases are counted while composing, and the size of the document with its aliases
    expanded is computed (each node once) before anything is constructed, so a bomb costs
    nothing. A duplicate key in one mapping (not one brought in by a ``<<`` merge) is an error
    naming the key and both lines."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._aliases = 0

    def compose_node(self, parent: Any, index: Any) -> Any:
        if self.check_event(yaml.AliasEvent):
            self._aliases += 1
            if self._aliases > MAX_YAML_ALIASES:
                mark = self.peek_event().start_mark  # type: ignore[no-untyped-call]
                raise _Refused(f"line {mark.line + 1}", f"alias number {self._aliases}",
                               f"at most {MAX_YAML_ALIASES} aliases (*name) in one file")
        return super().compose_node(parent, index)

    def get_single_node(self) -> Any:
        node = super().get_single_node()
        if node is not None:
            _check_expanded_size(node)
        return node

    def construct_mapping(self, node: Any, deep: bool = False) -> Any:
        if isinstance(node, yaml.MappingNode):
            seen: dict[Any, int] = {}
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge":
                    continue
                key = self.construct_object(key_node, deep=True)
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
        return super().construct_mapping(node, deep=deep)


def _check_expanded_size(root: Any) -> None:
    """Refuse a document whose aliases expand to more than MAX_YAML_NODES nodes (or to itself).
    Iterative, so deep nesting cannot overflow the stack here."""
    size: dict[int, int] = {}
    on_path: set[int] = set()
    stack: list[tuple[Any, bool]] = [(root, False)]
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
    loader: _Loader | None = None
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


def validate(model: type[M], data: Any, file: str, element: str = "",
             context: Mapping[str, Any] | None = None) -> M:
    """`model` built from `data` (parsed YAML); the first problem becomes one InputError.

    `element` is the path of `data` inside its file (empty: the whole file)."""
    if data is None:
        data = {}
    try:
        return model.model_validate(data, context=dict(context or {}))
    except ValidationError as exc:
        raise input_error(exc, model, file, element) from None


def input_error(exc: ValidationError, model: type[BaseModel], file: str,
                element: str = "") -> InputError:
    """The first entry of pydantic's `exc` as an InputError (file, element, value, expected)."""
    error = exc.errors()[0]
    walk = _Walk(model, tuple(error["loc"]))
    kind = error["type"]
    value: object = error.get("input")
    ctx = error.get("ctx") or {}
    path = walk.path
    if kind == "value_error" and isinstance(ctx.get("error"), Problem):
        problem = ctx["error"]
        path = _join(path, problem.key)
        return InputError(file, _join(element, path) or "top level", problem.value,
                          problem.expected)
    if kind == "missing" and walk.fixed_length is not None:
        path, expected = walk.parent_path, f"a list of {walk.fixed_length} items"
    elif kind in ("too_long", "too_short") and walk.fixed_length is not None:
        expected = f"a list of {walk.fixed_length} items"
    elif kind == "missing":
        value, expected = None, f"a value for required key {walk.last_key!r}"
    elif kind == "extra_forbidden":
        keys = [k for k in walk.known_keys if not k.startswith("_")]
        where = f" for dist {walk.tag!r}" if walk.tag is not None else " here"
        close = closest(walk.last_key, keys)
        hint = f": did you mean {close!r}?" if close is not None else ""
        expected = f"no such key{where}{hint} (known keys: {', '.join(keys)})"
    elif kind == "union_tag_invalid":
        path, value = _join(path, "dist"), ctx.get("tag")
        expected = f"one of {ctx.get('expected_tags')}"
    else:
        expected = _expectation(kind, walk, ctx, str(error.get("msg", "")))
    return InputError(file, _join(element, path) or "top level", value, expected)


def closest(word: str, choices: Iterable[str]) -> str | None:
    """The choice `word` was most likely meant to be (a misspelt key or type), if one is close
    enough, else None: the one choice that begins the word or that the word begins
    (`from_node` for `from`, `rate` for `rate_per_hour`), else difflib's best match with a
    ratio of at least 0.65 (its default 0.6 offered `mode_s` for `sd_s`)."""
    choices = list(choices)
    if len(word) >= 3:
        prefixed = [c for c in choices if len(c) >= 3 and (c.startswith(word)
                                                           or word.startswith(c))]
        if len(prefixed) == 1:
            return prefixed[0]
    matches = difflib.get_close_matches(word, choices, n=1, cutoff=CLOSE_RATIO)
    return matches[0] if matches else None


CLOSE_RATIO = 0.65


def _join(path: str, key: str) -> str:
    if not key:
        return path
    if not path or key.startswith("["):
        return f"{path}{key}"
    return f"{path}.{key}"


_TYPE_NAMES: Final[Mapping[str, str]] = {
    "float_type": "a number", "float_parsing": "a number", "int_type": "an integer",
    "int_parsing": "an integer", "int_from_float": "an integer", "bool_type": "true or false",
    "bool_parsing": "true or false", "string_type": "a text", "tuple_type": "a list",
    "list_type": "a list", "model_type": "a mapping", "model_attributes_type": "a mapping",
    "dict_type": "a mapping", "finite_number": "a finite number",
    "string_too_short": "a non-empty text",
    "union_tag_not_found": "a mapping such as {dist: fixed, mean_s: 20}",
}


def _expectation(kind: str, walk: _Walk, ctx: Mapping[str, Any], message: str) -> str:
    if kind == "literal_error":
        choices = get_args(walk.annotation) if get_origin(walk.annotation) is Literal else ()
        if choices:
            return "one of " + ", ".join(repr(c) for c in choices)
        return f"one of {ctx.get('expected')}"
    if kind in ("greater_than", "greater_than_equal", "less_than", "less_than_equal"):
        return _bounds(walk)
    if kind in _TYPE_NAMES:
        return _TYPE_NAMES[kind]
    if kind == "too_short" and "min_length" in ctx:
        least = ctx["min_length"]
        return f"a list of at least {least} item{'s' if least != 1 else ''}"
    if kind in ("value_error", "assertion_error") and ctx.get("error") is not None:
        return str(ctx["error"])
    return message


def _bounds(walk: _Walk) -> str:
    """`a number > 0`, `an integer >= 1`, `a number in [0, 100]` from the field's bounds."""
    noun = "an integer" if walk.annotation is int else "a number"
    low = high = ""
    low_value: object = None
    high_value: object = None
    for item in walk.metadata:
        if isinstance(item, annotated_types.Gt):
            low, low_value = "(", item.gt
        elif isinstance(item, annotated_types.Ge):
            low, low_value = "[", item.ge
        elif isinstance(item, annotated_types.Lt):
            high, high_value = ")", item.lt
        elif isinstance(item, annotated_types.Le):
            high, high_value = "]", item.le
    if low and high:
        return f"{noun} in {low}{_number(low_value)}, {_number(high_value)}{high}"
    if low:
        return f"{noun} {'>' if low == '(' else '>='} {_number(low_value)}"
    return f"{noun} {'<' if high == ')' else '<='} {_number(high_value)}"


def _number(value: object) -> str:
    """A bound as written: integers whole (4294967295, not 4.29497e+09), other numbers short."""
    return str(value) if isinstance(value, int) else f"{value:g}"


class _Walk:
    """Follows pydantic's error location through the model's types: the element path as the
    user wrote it (aliases, ``[i]`` for list items, no union tags), and what sits there."""

    def __init__(self, model: type[BaseModel], loc: tuple[int | str, ...]) -> None:
        self.parts: list[str] = []
        self.parent_path = ""
        self.annotation: Any = model
        self.metadata: list[Any] = []
        self.known_keys: list[str] = []
        self.last_key = ""
        self.tag: str | None = None
        self.fixed_length: int | None = None
        tp: Any = model
        for item in loc:
            self.parent_path = "".join(self.parts).lstrip(".")
            tp, metadata = _unwrap(tp)
            self.fixed_length = None
            if isinstance(tp, type) and issubclass(tp, BaseModel):
                fields = tp.model_fields
                self.known_keys = [f.alias or n for n, f in fields.items()]
                name, info = _field(fields, str(item))
                self.last_key = info.alias or name if info is not None else str(item)
                self.parts.append(f".{self.last_key}")
                tp = info.annotation if info is not None else Any
                metadata = list(info.metadata) if info is not None else []
            elif _is_model_union(tp) and isinstance(item, str):
                self.tag = item
                tp = next((m for m in get_args(tp) if _tag_of(m) == item), Any)
                continue
            elif get_origin(tp) in (tuple, list) and isinstance(item, int):
                args = get_args(tp)
                self.parts.append(f"[{item}]")
                if (len(args) == 2 and args[1] is Ellipsis) or get_origin(tp) is list:
                    tp = args[0]
                else:
                    self.fixed_length = len(args)
                    tp = args[item] if item < len(args) else Any
            elif get_origin(tp) in (dict, Mapping) or tp is dict:
                if item == "[key]":
                    continue
                self.parts.append(f".{item}")
                args = get_args(tp)
                tp = args[1] if len(args) == 2 else Any
            else:
                self.parts.append(f"[{item}]" if isinstance(item, int) else f".{item}")
                tp = Any
            self.metadata = metadata
        unwrapped, extra = _unwrap(tp)
        self.annotation = unwrapped
        self.metadata = self.metadata + extra

    @property
    def path(self) -> str:
        return "".join(self.parts).lstrip(".")


def _field(fields: Mapping[str, FieldInfo], key: str) -> tuple[str, FieldInfo | None]:
    for name, info in fields.items():
        if key == (info.alias or name):
            return name, info
    return key, None


def _unwrap(tp: Any) -> tuple[Any, list[Any]]:
    """Strip Annotated and Optional, keeping Annotated's metadata."""
    metadata: list[Any] = []
    while True:
        if get_origin(tp) is Annotated:
            for item in tp.__metadata__:
                metadata += item.metadata if isinstance(item, FieldInfo) else [item]
            tp = tp.__origin__
            continue
        if get_origin(tp) in (typing.Union, types.UnionType):
            args = [a for a in get_args(tp) if a is not type(None)]
            if len(args) == 1:
                tp = args[0]
                continue
            if not _is_model_union(tp):
                return tp, metadata
            members = tuple(_unwrap(a)[0] for a in args)
            return typing.Union[members], metadata  # noqa: UP007
        return tp, metadata


def _is_model_union(tp: Any) -> bool:
    if get_origin(tp) not in (typing.Union, types.UnionType):
        return False
    members = [_unwrap(a)[0] for a in get_args(tp) if a is not type(None)]
    return all(isinstance(m, type) and issubclass(m, BaseModel) for m in members)


def _tag_of(model: Any) -> str | None:
    """The value of the Literal field that tags `model` in a discriminated union."""
    for info in getattr(model, "model_fields", {}).values():
        if get_origin(info.annotation) is Literal and len(get_args(info.annotation)) == 1:
            tag = get_args(info.annotation)[0]
            return str(tag)
    return None
