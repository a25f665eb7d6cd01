"""Vehicle protocols, looked up by name: `get_codec("ktm02")`, `get_device("tabo")`."""

from __future__ import annotations

import importlib
from typing import Any

from agv_model.protocols.base import (
    _CODECS,
    _DEVICES,
    Codec,
    Command,
    Device,
    ProtocolError,
    Reply,
)

KNOWN = ("carriro", "ktm02", "tabo", "agv3")

__all__ = ["KNOWN", "Codec", "Command", "Device", "ProtocolError", "Reply", "get_codec",
           "get_device", "names"]


def _load(name: str) -> None:
    if name not in KNOWN:
        raise KeyError(f"unknown protocol {name!r}; expected one of {', '.join(KNOWN)}")
    if name not in _CODECS:
        importlib.import_module(f"agv_model.protocols.{name}")


def get_codec(name: str) -> Codec:
    _load(name)
    return _CODECS[name]()


def get_device(name: str, **settings: Any) -> Device:
    _load(name)
    return _DEVICES[name](**settings)


def names() -> tuple[str, ...]:
    return KNOWN
