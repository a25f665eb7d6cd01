"""Checking the files users write: one way to turn parsed YAML or JSON into a frozen model, and
one error for everything a user file can get wrong.

Each file (layouts, scenarios, experiments, order traces, vehicle profiles, link settings, VDMA
LIF layouts, VDA 5050 factsheets) is a pydantic model built on `StrictModel`; `validate` turns
the first problem pydantic finds into one `InputError` whose message names the file, the
element (a dotted path such as ``segments[12].to`` or ``fleet.vehicle.accel_mps2``), the value
and what was expected. How strict the types are, and why, is in the docs
(docs/background/decisions/files.md).
"""

from __future__ import annotations

import difflib
import types
import typing
from collections.abc import Iterable, Mapping
from typing import Annotated, Any, Final, Literal, TypeVar, get_args, get_origin

import annotated_types
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
