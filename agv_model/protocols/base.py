"""The one interface every vehicle protocol implements: a codec and a virtual device.

A protocol module (``agv_model/protocols/<name>.py``) defines a `Codec` subclass and a `Device`
subclass and registers them with `register`. The fleet model and the tools look protocols up by
name (`get_codec("carriro")`) and never import a concrete module.

Host side: `Codec.encode(command)` -> bytes on the wire; `Codec.unframe(buffer)` cuts complete
frames off a receive buffer; `Codec.decode(frame)` -> `Reply`.
Vehicle side: `Codec.parse_command(frame)` -> `Command`; `Codec.encode_reply(reply)` -> bytes.
A malformed frame raises `ProtocolError` naming the protocol, the bytes and what was expected.

A `Device` is a stateful virtual vehicle driven by simulated time: `receive(data, now_s)` hands it
bytes; `poll(now_s)` returns the (time_s, bytes) it has sent by `now_s` (replies, and unsolicited
messages such as TABO's FIN); `next_output_s()` tells when it will next send, for schedulers.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, Literal


class ProtocolError(ValueError):
    """Bytes that do not follow the protocol."""

    def __init__(self, protocol: str, data: bytes | str, expected: str) -> None:
        self.protocol = protocol
        self.data = data
        self.expected = expected
        super().__init__(f"{protocol}: got {data!r}; expected {expected}")


def ascii_text(protocol: str, frame: bytes, expected: str = "ASCII text") -> str:
    """The frame as text, for the ASCII protocols; anything else is a ProtocolError."""
    try:
        return frame.decode("ascii")
    except UnicodeDecodeError as err:
        raise ProtocolError(protocol, frame, expected) from err


@dataclass(frozen=True)
class Command:
    """A host -> vehicle command. `kind` says whether it reads, writes or acts."""

    name: str
    args: tuple[Any, ...] = ()
    kind: Literal["get", "set", "action"] = "action"


@dataclass(frozen=True)
class Reply:
    """A vehicle -> host message. `status` is the protocol's own word (ack, nak, fin, value,
    error...), `args` its decoded values."""

    name: str
    status: str
    args: tuple[Any, ...] = ()


class Codec(ABC):
    name: ClassVar[str]

    @abstractmethod
    def encode(self, command: Command) -> bytes: ...

    @abstractmethod
    def parse_command(self, frame: bytes) -> Command: ...

    @abstractmethod
    def encode_reply(self, reply: Reply) -> bytes: ...

    @abstractmethod
    def decode(self, frame: bytes) -> Reply: ...

    @abstractmethod
    def unframe(self, buffer: bytearray) -> list[bytes]:
        """Remove and return every complete frame at the start of `buffer`."""


class Device(ABC):
    name: ClassVar[str]

    @abstractmethod
    def receive(self, data: bytes, now_s: float) -> None: ...

    @abstractmethod
    def poll(self, now_s: float) -> list[tuple[float, bytes]]: ...

    @abstractmethod
    def next_output_s(self) -> float | None: ...


_CODECS: dict[str, Callable[[], Codec]] = {}
_DEVICES: dict[str, Callable[..., Device]] = {}


def register(name: str, codec: Callable[[], Codec], device: Callable[..., Device]) -> None:
    _CODECS[name] = codec
    _DEVICES[name] = device
