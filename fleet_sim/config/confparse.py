"""Build frozen dataclasses from parsed YAML, strictly.

Unknown keys, missing keys and wrong types are errors that name the file, the dotted path of the
element, the value and what was expected. Defaults come from the dataclass fields, so the resolved
config (every default written out) is simply `to_plain(config)`.
"""

from __future__ import annotations

import dataclasses
import types
import typing
from collections.abc import Mapping
from pathlib import Path
from typing import Any, Literal, TypeVar, get_args, get_origin, get_type_hints

import yaml

from fleet_sim.errors import InputError

T = TypeVar("T")


def read_yaml(path: Path) -> Any:
    """Read one YAML file; a missing file or bad syntax is an InputError naming the file."""
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(str(path), "file", str(path), "an existing file") from None
    except OSError as exc:
        raise InputError(str(path), "file", str(path),
                         f"a readable file ({exc.strerror})") from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f"line {mark.line + 1}" if mark is not None else "document"
        problem = getattr(exc, "problem", None) or "invalid YAML"
        raise InputError(str(path), where, problem, "valid YAML") from None


def _describe(tp: Any) -> str:
    origin = get_origin(tp)
    if tp is float:
        return "a number"
    if tp is int:
        return "an integer"
    if tp is str:
        return "a string"
    if tp is bool:
        return "true or false"
    if origin is Literal:
        return "one of " + ", ".join(repr(a) for a in get_args(tp))
    if origin in (tuple, list):
        return "a list"
    if dataclasses.is_dataclass(tp):
        return "a mapping"
    if origin in (typing.Union, types.UnionType):
        return " or ".join(_describe(a) for a in get_args(tp) if a is not type(None)) + " or null"
    return str(tp)


def _convert(tp: Any, value: Any, file: str, path: str) -> Any:
    origin = get_origin(tp)
    if tp is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        args = get_args(tp)
        if value is None and type(None) in args:
            return None
        errors: list[InputError] = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _convert(arg, value, file, path)
            except InputError as exc:
                errors.append(exc)
        if len(errors) == 1:
            raise errors[0]
        raise InputError(file, path, value, _describe(tp))
    if origin is Literal:
        if value in get_args(tp):
            return value
        raise InputError(file, path, value, _describe(tp))
    if tp is bool:
        if isinstance(value, bool):
            return value
        raise InputError(file, path, value, "true or false")
    if tp is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
        raise InputError(file, path, value, "a number")
    if tp is int:
        if isinstance(value, int) and not isinstance(value, bool):
            return value
        raise InputError(file, path, value, "an integer")
    if tp is str:
        if isinstance(value, str):
            return value
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return str(value)  # ids such as 12 are fine as strings
        raise InputError(file, path, value, "a string")
    if origin is tuple:
        args = get_args(tp)
        if not isinstance(value, list):
            raise InputError(file, path, value, "a list")
        if len(args) == 2 and args[1] is Ellipsis:
            return tuple(_convert(args[0], v, file, f"{path}[{i}]") for i, v in enumerate(value))
        if len(value) != len(args):
            raise InputError(file, path, value, f"a list of {len(args)} items")
        pairs = enumerate(zip(args, value, strict=True))
        return tuple(_convert(a, v, file, f"{path}[{i}]") for i, (a, v) in pairs)
    if origin is dict:
        key_tp, val_tp = get_args(tp)
        if not isinstance(value, Mapping):
            raise InputError(file, path, value, "a mapping")
        return {
            _convert(key_tp, k, file, f"{path}"): _convert(val_tp, v, file, f"{path}.{k}")
            for k, v in value.items()
        }
    if dataclasses.is_dataclass(tp) and isinstance(tp, type):
        return build(tp, value, file, path)
    raise TypeError(f"confparse cannot build {tp!r}")  # a programming error, not user input


def build(cls: type[T], data: Any, file: str, path: str = "") -> T:
    """Build dataclass `cls` from `data`; every problem names `file` and the dotted `path`."""
    where = path or "top level"
    if data is None:
        data = {}
    if not isinstance(data, Mapping):
        raise InputError(file, where, data, "a mapping")
    hints = get_type_hints(cls)
    fields = {f.metadata.get("key", f.name): f for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
    for key in data:
        if key not in fields:
            known = ", ".join(sorted(k for k in fields if not k.startswith("_")))
            raise InputError(file, f"{path + '.' if path else ''}{key}", data[key],
                             f"no such key here (known keys: {known})")
    kwargs: dict[str, Any] = {}
    for name, field in fields.items():
        sub = f"{path}.{name}" if path else name
        if name in data:
            kwargs[field.name] = _convert(hints[field.name], data[name], file, sub)
        elif field.default is dataclasses.MISSING and field.default_factory is dataclasses.MISSING:
            raise InputError(file, sub, None, f"a value for required key {name!r}")
    obj = cls(**kwargs)
    check = getattr(obj, "check", None)
    if callable(check):
        check(file, where)
    return obj


def to_plain(obj: Any) -> Any:
    """Dataclasses, tuples and dicts to plain YAML-able data (the resolved config)."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return {
            f.metadata.get("key", f.name): to_plain(getattr(obj, f.name))
            for f in dataclasses.fields(obj)
        }
    if isinstance(obj, (tuple, list)):
        return [to_plain(v) for v in obj]
    if isinstance(obj, dict):
        return {str(k): to_plain(v) for k, v in obj.items()}
    return obj


def positive(file: str, element: str, value: float, *, allow_zero: bool = False) -> None:
    """Raise InputError unless value > 0 (or >= 0)."""
    if value < 0 or (value == 0 and not allow_zero):
        raise InputError(file, element, value, "a number >= 0" if allow_zero else "a number > 0")
