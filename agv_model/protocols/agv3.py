"""AGV-3 SCPI-like protocol: codec and virtual device.

Source: the AGV-3 protocol document ("Grupp 3 AGV protokoll", revision 1.1), cited by its
headings: Syntax, Kommandon, Revision.

Syntax: ``"cmd(?) (args...)\\r\\n"``; identifiers have levels separated by ':', upper-case letters
are required and lower-case ones optional, case does not matter; ``?`` makes a get; arguments are
separated by one or more spaces, extra ones are ignored; ';' chains commands on the same level,
a leading ':' goes back to the root, ``*`` commands have no level.

The readings where the document is silent, damaged or contradicts itself, numbered as the
code cites them ("decision 3"): docs/background/decisions/protocols.md.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

from agv_model.protocols._sim import Outbox, SimClock, earliest
from agv_model.protocols.agv3_vehicle import (
    PASSENGERS_DEFAULT,
    Agv3Vehicle,
    Agv3World,
    Order,
)
from agv_model.protocols.base import (
    Codec,
    Command,
    Device,
    ProtocolError,
    Reply,
    ascii_text,
    register,
)

PROTOCOL = "agv3"
TERMINATOR = b"\r\n"  # Syntax, footnote 1
REPLY_TIMEOUT_S = 0.25  # Syntax: "Om inget returneras inom 0.25s så får det antas som ett fel"
IDENTITY = "AGV-3"  # *IDN
ERROR_PREFIX = "ERROR: "
STATION_MAX = 3  # PICKUp <station, 0-3 = 0>
COUNT_MAX = 10  # PICKUp <antal, 0-10 = 0>
ROLES = ("LEAD", "FOLLOW")  # ROLe <roll, LEAD|FOLLOW=LEAD>
# Decision 10. The document sets no line or reply length; its only bound is time: "Om inget
# returneras inom 0.25s så får det antas som ett fel" (Syntax).
LINE_LIMIT_BYTES = 256  # longest line read, terminator not counted; longer ones are dropped
QUOTE_LIMIT_CHARS = 32  # longest quotation of received text in an error, quotes and '...' included
ERROR_LINE_MAX_BYTES = 128  # longest error line, terminator included


def _quote(received: bytes | str) -> str:
    """`received` quoted as ASCII (``ascii()``), cut to QUOTE_LIMIT_CHARS ending ``...'``."""
    text = ascii(received)
    if len(text) <= QUOTE_LIMIT_CHARS:
        return text
    return text[: QUOTE_LIMIT_CHARS - 4] + "...'"


@dataclass(frozen=True)
class Node:
    """One identifier of the command tree, e.g. ``NAVigation``; upper case is the short form."""

    long: str
    get: bool = False
    set: bool = False
    children: tuple[Node, ...] = ()

    @property
    def short(self) -> str:
        return self.long.rstrip("abcdefghijklmnopqrstuvwxyz")

    def matches(self, token: str) -> bool:
        token = token.upper()
        return len(token) >= len(self.short) and self.long.upper().startswith(token)

    def child(self, token: str) -> Node | None:
        return next((c for c in self.children if c.matches(token)), None)


ROOT = Node("", children=(
    Node("NAVigation", children=(
        Node("STArt", set=True),
        Node("STOp", set=True),
        Node("PICKUp", get=True, set=True),
        Node("DROPOff", get=True, set=True),
        Node("ROLe", get=True, set=True),
        Node("PASSengers", get=True, set=True),
        Node("STATus", get=True),
    )),
    Node("SYStem", children=(
        Node("EStop", get=True, set=True),
        Node("BATtery", get=True),
    )),
    Node("*IDN", get=True),
))


class UnknownCommandError(ProtocolError):
    """An identifier that names no command of the tree."""


class LineTooLongError(ProtocolError):
    """A line longer than LINE_LIMIT_BYTES; `data` holds its first bytes only (decision 10)."""

    def __init__(self, start: bytes) -> None:
        super().__init__(PROTOCOL, start, f"a line of at most {LINE_LIMIT_BYTES} bytes")


def find(name: str) -> Node:
    """The node of a full identifier such as ``NAVigation:STArt`` or ``nav:sta``."""
    node = ROOT
    for token in name.lstrip(":").split(":"):
        found = node.child(token)
        if found is None:
            raise UnknownCommandError(PROTOCOL, name, "a command of the AGV-3 tree")
        node = found
    return node


class Agv3Codec(Codec):
    """AGV-3 lines both ways."""

    name = PROTOCOL

    def __init__(self, terminator: bytes = TERMINATOR) -> None:
        self.terminator = terminator

    # -- host side -------------------------------------------------------------------------

    def encode(self, command: Command) -> bytes:
        return self.encode_chain([command])

    def encode_chain(self, commands: list[Command]) -> bytes:
        """One line for several commands, each written from the root (``:NAV:STA;:SYS:BAT?``
        is always right, whatever the level)."""
        parts: list[str] = []
        for command in commands:
            find(command.name)
            mark = "?" if command.kind == "get" else ""
            root = ":" if parts and not command.name.startswith("*") else ""
            words = [root + command.name.lstrip(":") + mark, *map(str, command.args)]
            parts.append(" ".join(words))
        return ";".join(parts).encode("ascii") + self.terminator

    def decode(self, frame: bytes) -> Reply:
        text = self._text(frame)
        if text.startswith(ERROR_PREFIX):
            return Reply("", "error", (text[len(ERROR_PREFIX):],))
        return Reply("", "value" if text else "ok", tuple(text.split()))

    # -- vehicle side ----------------------------------------------------------------------

    def parse_command(self, frame: bytes) -> Command:
        """One command; a ';' chain raises (use `parse_line`)."""
        parsed = self.parse_line(frame)
        if len(parsed) != 1:
            raise ProtocolError(PROTOCOL, frame, "exactly one command (use parse_line for ';')")
        if isinstance(parsed[0], ProtocolError):
            raise parsed[0]
        return parsed[0]

    def parse_line(self, frame: bytes) -> list[Command | ProtocolError]:
        """Every command of a line, in order; a segment that cannot be read becomes its error,
        so the rest of the chain still runs."""
        text = self._text(frame)
        level: tuple[Node, ...] = ()
        out: list[Command | ProtocolError] = []
        for segment in text.split(";"):
            words = segment.split()
            if not words:
                continue
            header, args = words[0], tuple(words[1:])
            kind: Literal["get", "set"] = "get" if header.endswith("?") else "set"
            path = header.removesuffix("?")
            try:
                nodes = self._resolve(path, level)
            except ProtocolError as err:
                out.append(err)
                continue
            if not path.startswith("*"):
                level = nodes[:-1]
            out.append(Command(":".join(n.long for n in nodes), args, kind))
        return out

    def _resolve(self, path: str, level: tuple[Node, ...]) -> tuple[Node, ...]:
        """Walk `path` from the root (leading ':' or '*') or from `level`; return the full node
        path from the root."""
        start = () if path.startswith((":", "*")) else level
        tokens = path.removeprefix(":").split(":")
        if not all(tokens):
            raise ProtocolError(PROTOCOL, path, "identifiers separated by single ':'")
        nodes = list(start)
        for token in tokens:
            child = (nodes[-1] if nodes else ROOT).child(token)
            if child is None:
                raise UnknownCommandError(PROTOCOL, path, "a command of the AGV-3 tree")
            nodes.append(child)
        return tuple(nodes)

    def encode_reply(self, reply: Reply) -> bytes:
        if reply.status == "error":
            text = ERROR_PREFIX + " ".join(map(str, reply.args))
        else:
            text = " ".join(map(str, reply.args))
        return text.encode("ascii") + self.terminator

    def unframe(self, buffer: bytearray) -> list[bytes]:
        """Cut complete lines at the terminator (removed)."""
        frames: list[bytes] = []
        while (end := buffer.find(self.terminator)) >= 0:
            frames.append(bytes(buffer[:end]))
            del buffer[: end + len(self.terminator)]
        return frames

    @staticmethod
    def _text(frame: bytes) -> str:
        return ascii_text(PROTOCOL, frame, "ASCII text (Syntax, footnote 1)")


# -- virtual device ----------------------------------------------------------------------------


class LineReader:
    """The device's line buffer: cuts lines at `terminator` and never holds more than `limit`
    bytes of one line (plus a partial terminator). A longer line is dropped up to its terminator
    and comes out once, as a `LineTooLongError` holding its first bytes (decision 10)."""

    def __init__(self, terminator: bytes = TERMINATOR, limit: int = LINE_LIMIT_BYTES) -> None:
        self.terminator = terminator
        self.limit = limit
        self._buffer = bytearray()
        self._dropping: bytes | None = None  # the start of the over-long line being dropped

    def feed(self, data: bytes) -> list[bytes | LineTooLongError]:
        """Every line `data` completes, in order, terminators removed."""
        self._buffer += data
        lines: list[bytes | LineTooLongError] = []
        while (end := self._buffer.find(self.terminator)) >= 0:
            if self._dropping is not None:
                lines.append(LineTooLongError(self._dropping))
                self._dropping = None
            elif end > self.limit:
                lines.append(LineTooLongError(bytes(self._buffer[:QUOTE_LIMIT_CHARS])))
            else:
                lines.append(bytes(self._buffer[:end]))
            del self._buffer[: end + len(self.terminator)]
        partial = self._partial_terminator()
        if len(self._buffer) - partial > self.limit or self._dropping is not None:
            if self._dropping is None:
                self._dropping = bytes(self._buffer[:QUOTE_LIMIT_CHARS])
            del self._buffer[: len(self._buffer) - partial]
        return lines

    def _partial_terminator(self) -> int:
        """How many bytes at the end of the buffer could begin the terminator."""
        for size in range(len(self.terminator) - 1, 0, -1):
            if self._buffer.endswith(self.terminator[:size]):
                return size
        return 0


class Agv3Device(Device):
    """A virtual AGV-3 answering lines in simulated time.

    The vehicle behind it (`Agv3Vehicle`, its own module) drives, stops at stations, follows
    and faults by itself; STATus, PICKUp?, DROPOff?, PASSengers? and BATtery? read its state
    at the time of the answer (decision 8). Settings (assumed defaults): ``reply_delay_s``
    0.01 s per line; ``reply_terminator`` "\\r\\n" (decision 2); any other keyword is a field
    of `Agv3World` (``line_search_s``, ``battery_v``, ``station_gap_s``, ``leader_id``...).
    """

    name = PROTOCOL

    def __init__(
        self,
        *,
        reply_delay_s: float = 0.01,
        reply_terminator: bytes = TERMINATOR,
        **world: Any,
    ) -> None:
        self.reply_delay_s = reply_delay_s
        self.vehicle = Agv3Vehicle(Agv3World(**world))
        self.codec = Agv3Codec()
        self.reply_codec = Agv3Codec(reply_terminator)
        self.estop = False
        self._clock = SimClock(PROTOCOL)
        self._outbox = Outbox()
        self._lines = LineReader()
        self._busy_until_s = 0.0

    # -- Device interface ------------------------------------------------------------------

    def receive(self, data: bytes, now_s: float) -> None:
        self._clock.advance(now_s)
        for line in self._lines.feed(data):
            done_s = max(now_s, self._busy_until_s) + self.reply_delay_s
            parsed: list[Command | ProtocolError]
            if isinstance(line, LineTooLongError):
                parsed = [line]
            else:
                try:
                    parsed = self.codec.parse_line(line)
                except ProtocolError as err:
                    parsed = [err]
            if not parsed:
                continue
            self._busy_until_s = done_s
            replies = b"".join(self.reply_codec.encode_reply(self._run(p, done_s))
                               for p in parsed)
            self._outbox.put(done_s, replies)

    def poll(self, now_s: float) -> list[tuple[float, bytes]]:
        self._clock.advance(now_s)
        self.vehicle.advance(now_s)
        return self._outbox.due(now_s)

    def next_output_s(self) -> float | None:
        return earliest(self._outbox.next_time_s())

    # -- simulation-facing -----------------------------------------------------------------

    def set_status(self, state: str, info: str = "") -> None:
        """Put the AGV in a STATus state (e.g. FOLLOWING 4, FAULT line lost); it drives on
        from there by itself (`Agv3Vehicle.set_status`)."""
        self.vehicle.set_status(state, info)

    def release_estop(self) -> None:
        self.estop = False

    def arrive_at_station(self, station: int) -> None:
        """Carry out the drop-off and pick-up orders for `station`, then pause there."""
        self.vehicle.arrive_at_station(station)

    # -- internals -------------------------------------------------------------------------

    def _run(self, parsed: Command | ProtocolError, at_s: float) -> Reply:
        self.vehicle.advance(at_s)
        if isinstance(parsed, LineTooLongError):
            return _error("", f"line longer than {LINE_LIMIT_BYTES} bytes {_quote(parsed.data)}")
        if isinstance(parsed, ProtocolError):
            what = "unknown command" if isinstance(parsed, UnknownCommandError) else "bad syntax"
            return _error("", f"{what} {_quote(parsed.data)}")
        command = parsed
        node = find(command.name)
        allowed = node.get if command.kind == "get" else node.set
        if not allowed:
            return _error(command.name, f"{command.name} has no {command.kind}")
        try:
            text = (self._get(command.name, at_s) if command.kind == "get"
                    else self._set(command.name, command.args, at_s))
        except ValueError as err:
            return _error(command.name, f"{command.name}: {err}")
        return Reply(command.name, "value" if text else "ok", (text,) if text else ())

    def _get(self, name: str, at_s: float) -> str:
        vehicle = self.vehicle
        if name == "NAVigation:STATus":
            return " ".join(vehicle.status(at_s)).rstrip()
        if name == "SYStem:BATtery":
            return f"{vehicle.battery_v(at_s):.6f}V"
        values = {
            "NAVigation:PICKUp": vehicle.pickup.text(),
            "NAVigation:DROPOff": vehicle.dropoff.text(),
            "NAVigation:ROLe": vehicle.role,
            "NAVigation:PASSengers": str(vehicle.passengers),
            "SYStem:EStop": "TRUE" if self.estop else "FALSE",
            "*IDN": IDENTITY,
        }
        return values[name]

    def _set(self, name: str, args: tuple[str, ...], at_s: float) -> str:
        vehicle = self.vehicle
        if name == "NAVigation:STArt":
            if self.estop:
                raise ValueError("emergency stop is active")
            vehicle.start(at_s)
            return "Starting..."
        if name == "NAVigation:STOp":
            vehicle.stop(at_s)
            return "Stopping..."
        if name in ("NAVigation:PICKUp", "NAVigation:DROPOff"):
            station = _whole(args, 0, 0, STATION_MAX, "station")
            count = _whole(args, 1, 0, COUNT_MAX, "count")
            order = Order(station, count) if count else Order()
            vehicle.set_order("pickup" if name == "NAVigation:PICKUp" else "dropoff", order, at_s)
        elif name == "NAVigation:ROLe":
            role = args[0] if args else "LEAD"
            if role not in ROLES:
                raise ValueError(f"role {_quote(role)} must be LEAD or FOLLOW (case-sensitive)")
            vehicle.set_role(role, at_s)
        elif name == "NAVigation:PASSengers":
            vehicle.max_passengers = _whole(args, 0, 0, None, "max", PASSENGERS_DEFAULT)
        elif name == "SYStem:EStop":
            self.estop = True
            vehicle.stop(at_s)
        return ""


def _error(name: str, text: str) -> Reply:
    """An error reply whose line (prefix and terminator included) fits ERROR_LINE_MAX_BYTES."""
    room = ERROR_LINE_MAX_BYTES - len(ERROR_PREFIX) - len(TERMINATOR)
    if len(text) > room:
        text = text[: room - 3] + "..."
    return Reply(name, "error", (text,))


def _whole(args: tuple[str, ...], index: int, low: int, high: int | None, what: str,
           default: int = 0) -> int:
    """Argument `index` as a whole number in low..high, or `default` when absent."""
    if len(args) <= index:
        return default
    text = args[index]
    span = f"{low}-{high}" if high is not None else f">= {low}"
    if not text.lstrip("+-").isdigit():
        raise ValueError(f"{what} {_quote(text)} must be a whole number {span}")
    value = int(text)
    if value < low or (high is not None and value > high):
        shown = str(value) if len(str(value)) < QUOTE_LIMIT_CHARS else _quote(text)
        raise ValueError(f"{what} {shown} must be {span}")
    return value


register(PROTOCOL, Agv3Codec, Agv3Device)
