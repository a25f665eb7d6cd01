"""CarriRo AD+ codec: ASCII lines `name?` / `name: args` ending in LF (コマンド形式).

The readings of the document that this code relies on are listed in `agv_model.protocols.carriro`.
Values in `Command.args` and `Reply.args` are in the document's units (km/h, m, s, cm, %): the
codec multiplies by each field's 倍率 on the way out and divides on the way in, so
`Command("ad_speed_limit", (2.0,), "set")` is `ad_speed_limit: 20`.
"""

from __future__ import annotations

import re
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar, Final, Literal

from agv_model.protocols.base import Codec, Command, ProtocolError, Reply
from agv_model.protocols.carriro_tables import (
    AD_ACTIONS,
    AD_STATUSES,
    ERROR_INVALID_DATA,
    ERROR_UNKNOWN_COMMAND,
    LANDMARKS,
    MAX_LINE_CHARS,
    MODES,
    SETTABLE_AD_ACTIONS,
    STATUS_CMD_MAX,
    TERMINATOR,
    Field,
    FieldError,
    IntField,
    TextField,
    Value,
    check_action_params,
)

PROTOCOL: Final = "carriro"

# Reply.status words: a get reply (`name? ...`), a set reply (`name: ...`), an error reply
# (`name: error N`), and the start-up banner (スタートアップ).
VALUE: Final = "value"
DONE: Final = "done"
ERROR: Final = "error"
BANNER: Final = "banner"
BANNER_NAME: Final = "startup"


class CarriroError(ProtocolError):
    """A command line the vehicle answers with `<command>: error <code>` (エラーコード)."""

    def __init__(self, code: int, command: str, data: bytes | str, expected: str) -> None:
        self.code = code
        self.command = command
        super().__init__(PROTOCOL, data, expected)


def _ranges(values: Sequence[int]) -> tuple[tuple[int, int], ...]:
    return tuple((v, v) for v in sorted(values))


# The fields of the command list, each with the section it comes from.
_ACTION_ID = IntField("action_id", ((0, 2**31 - 1),))  # action: (Appendix A; see carriro.py)
_AD_ACTION_ID = IntField("ad_action_id", _ranges(list(AD_ACTIONS)))  # Appendix B
_SETTABLE_AD_ACTION = IntField("ad_action_id", _ranges(list(SETTABLE_AD_ACTIONS)))  # Appendix C
_LANDMARK_ID = IntField("landmark_id", _ranges(list(LANDMARKS)))  # Appendix F
_DISTANCE_M = ((0, 2_147_483_648),)  # ad_landmark?, dist?: 範囲 0-2147483648, 倍率 100
_LANDMARK_DIST = IntField("landmark_distance_m", _DISTANCE_M, scale=100, unit="m")
_OUTPUT = TextField("output", r"[!-~]{1,4}", "the PIPPI string, 1-4 printable characters")
_PATTERN = IntField("pattern_id", ((0, 90),))  # ad_pattern: 0 未設定, 1-90
_SPEED = IntField("speed_kmh", ((0, 0), (5, 30)), scale=10, unit="km/h")  # speed?, ad_speed_limit
_AD_STATUS = IntField("ad_status", _ranges(list(AD_STATUSES)))  # Appendix D
_BATTERY = IntField("battery_pct", ((0, 100),), unit="%")  # battery?
_PERIOD = IntField("comm_period_s", ((0, 100),), scale=10, unit="s")  # comm
_DIST = IntField("dist_m", _DISTANCE_M, scale=100, unit="m")  # dist?
_CODE = TextField("code", r"[0-9A-F]{8}", "an Appendix E code, 8 hex digits")  # error?, warning?
_UNIT_ID = TextField("id", r"[!-~]{12}", "12 printable characters")  # id?: Length 12 文字
_MODE = IntField("mode", _ranges(list(MODES)))  # Appendix G
_SETTABLE_MODE = IntField("mode", _ranges([m for m, (_, s) in MODES.items() if s]))  # Get / Set
_FLAG = IntField("flag", ((0, 1),))  # pallet?, trolley?: 0 or 1
_VERSION = TextField("version", r"[0-9]+(\.[0-9]+)*", "a dotted version such as 1.12.0.0")
_OK = TextField("result", r"OK", "OK")  # reboot:, shutdown:
_BANNER_RE: Final = re.compile(r"(.+) ([0-9]+(?:\.[0-9]+)+)")
_PRINTABLE_RE: Final = re.compile(r"[ -~]*")
# `command_name: error <コード>` (エラーコード); the name is whatever the vehicle could not use.
_ERROR_NAME_RE: Final = re.compile(r"(?:(?![?:])[!-~])*")
_ERROR_RE: Final = re.compile(r"([^?: ]*): error ([123])")


class Shape(ABC):
    """How the tokens after `name?` or `name:` map to argument values."""

    def split(self, rest: str) -> list[str]:
        """`rest` is what follows `?` or `:`; runs of spaces separate parameters."""
        return rest.split()

    @abstractmethod
    def decode(self, tokens: list[str]) -> tuple[Value, ...]: ...

    @abstractmethod
    def encode(self, args: tuple[Any, ...]) -> list[str]: ...


@dataclass(frozen=True)
class Fixed(Shape):
    fields: tuple[Field, ...] = ()

    def _expected(self) -> str:
        if not self.fields:
            return "no parameters"
        return f"{len(self.fields)} value(s): " + "; ".join(f.expected() for f in self.fields)

    def decode(self, tokens: list[str]) -> tuple[Value, ...]:
        if len(tokens) != len(self.fields):
            raise FieldError(self._expected())
        return tuple(f.decode(t) for f, t in zip(self.fields, tokens, strict=True))

    def encode(self, args: tuple[Any, ...]) -> list[str]:
        if len(args) != len(self.fields):
            raise FieldError(self._expected())
        return [f.encode(a) for f, a in zip(self.fields, args, strict=True)]


@dataclass(frozen=True)
class Option(Shape):
    """`ad_action? [-p]`: nothing, or the one option word."""

    word: str

    def decode(self, tokens: list[str]) -> tuple[Value, ...]:
        if tokens not in ([], [self.word]):
            raise FieldError(f"nothing or the option {self.word}")
        return tuple(tokens)

    def encode(self, args: tuple[Any, ...]) -> list[str]:
        if args not in ((), (self.word,)):
            raise FieldError(f"nothing or the option {self.word}")
        return list(args)


class AdActionReply(Shape):
    """`ad_action? <id> [parameters]`: the ID alone, or with all its Appendix B parameters."""

    def _fields(self, action_id: int, count: int) -> tuple[Field, ...]:
        params = AD_ACTIONS[action_id].params
        if count not in (0, len(params)):
            raise FieldError(f"action {action_id} alone or with its {len(params)} parameter(s) "
                             "(Appendix B)")
        return params if count else ()

    def decode(self, tokens: list[str]) -> tuple[Value, ...]:
        if not tokens:
            raise FieldError(_AD_ACTION_ID.expected())
        action_id = int(_AD_ACTION_ID.decode(tokens[0]))
        fields = self._fields(action_id, len(tokens) - 1)
        params = tuple(f.decode(t) for f, t in zip(fields, tokens[1:], strict=True))
        check_action_params(action_id, params)
        return (action_id, *params)

    def encode(self, args: tuple[Any, ...]) -> list[str]:
        if not args:
            raise FieldError(_AD_ACTION_ID.expected())
        head = _AD_ACTION_ID.encode(args[0])
        fields = self._fields(int(args[0]), len(args) - 1)
        check_action_params(int(args[0]), tuple(args[1:]))
        return [head, *(f.encode(a) for f, a in zip(fields, args[1:], strict=True))]


@dataclass(frozen=True)
class CommandList(Shape):
    """`status_cmd`: 1-15 get commands, each written with its `?` (status_cmd:)."""

    allowed: frozenset[str]

    def _expected(self) -> str:
        return f"1-{STATUS_CMD_MAX} of: " + " ".join(sorted(self.allowed))

    def decode(self, tokens: list[str]) -> tuple[Value, ...]:
        if not 1 <= len(tokens) <= STATUS_CMD_MAX or not set(tokens) <= self.allowed:
            raise FieldError(self._expected())
        return tuple(tokens)

    def encode(self, args: tuple[Any, ...]) -> list[str]:
        if not all(isinstance(a, str) for a in args):
            raise FieldError(self._expected())
        return [str(a) for a in self.decode(list(args))]


class FreeText(Shape):
    """`echo: [parameters]`: returned as received, so split on single spaces only."""

    def split(self, rest: str) -> list[str]:
        return rest[1:].split(" ") if rest else []

    def decode(self, tokens: list[str]) -> tuple[Value, ...]:
        return tuple(tokens)

    def encode(self, args: tuple[Any, ...]) -> list[str]:
        if not all(isinstance(a, str) and " " not in a for a in args):
            raise FieldError("echo parameters: strings without spaces")
        return list(args)


@dataclass(frozen=True)
class CommandSpec:
    """One command of the コマンドリスト: its get form, its set form, and what they carry."""

    section: str
    get_reply: Shape | None = None  # None: there is no `name?`
    get_params: Shape = Fixed()
    set_params: Shape | None = None  # None: there is no `name:`
    set_reply: Shape | None = None  # None: the reply echoes the parameters
    set_kind: Literal["set", "action"] = "set"
    from_host: bool = True  # False: ad_output?, sent by the vehicle only

    def reply_shape(self, kind: str) -> Shape | None:
        if kind == "?":
            return self.get_reply
        return self.set_reply or self.set_params


_SPEED_LIMIT = CommandSpec("ad_speed_limit", get_reply=Fixed((_SPEED,)),
                           set_params=Fixed((_SPEED,)))
SPECS: Final[dict[str, CommandSpec]] = {
    "action": CommandSpec("action:", set_params=Fixed((_ACTION_ID,)), set_kind="action"),
    "ad_action": CommandSpec("ad_action", get_reply=AdActionReply(), get_params=Option("-p"),
                             set_params=Fixed((_SETTABLE_AD_ACTION,)), set_kind="action"),
    "ad_landmark": CommandSpec("ad_landmark?", get_reply=Fixed((_LANDMARK_ID, _LANDMARK_DIST))),
    "ad_output": CommandSpec("ad_output?", get_reply=Fixed((_OUTPUT,)), from_host=False),
    "ad_pattern": CommandSpec("ad_pattern", get_reply=Fixed((_PATTERN,)),
                              set_params=Fixed((_PATTERN,))),
    "ad_speed_limit": _SPEED_LIMIT,
    "speed_limit": _SPEED_LIMIT,  # the spelling of the ad_speed_limit examples
    "ad_status": CommandSpec("ad_status?", get_reply=Fixed((_AD_STATUS,))),
    "battery": CommandSpec("battery?", get_reply=Fixed((_BATTERY,))),
    "comm": CommandSpec("comm", get_reply=Fixed((_PERIOD,)), set_params=Fixed((_PERIOD,))),
    "dist": CommandSpec("dist?", get_reply=Fixed((_DIST,))),
    "echo": CommandSpec("echo:", set_params=FreeText(), set_kind="action"),
    "error": CommandSpec("error?", get_reply=Fixed((_CODE,))),
    "id": CommandSpec("id?", get_reply=Fixed((_UNIT_ID,))),
    "mode": CommandSpec("mode", get_reply=Fixed((_MODE,)), set_params=Fixed((_SETTABLE_MODE,))),
    "pallet": CommandSpec("pallet?", get_reply=Fixed((_FLAG, _FLAG))),
    "reboot": CommandSpec("reboot:", set_params=Fixed(), set_reply=Fixed((_OK,)),
                          set_kind="action"),
    "shutdown": CommandSpec("shutdown:", set_params=Fixed(), set_reply=Fixed((_OK,)),
                            set_kind="action"),
    "speed": CommandSpec("speed?", get_reply=Fixed((_SPEED,))),
    "status": CommandSpec("status?", get_reply=Fixed()),  # shape from the codec's status_cmds
    "status_cmd": CommandSpec("status_cmd", get_reply=Fixed(), set_params=Fixed()),  # ditto
    "trolley": CommandSpec("trolley?", get_reply=Fixed((_FLAG, _FLAG))),
    "version": CommandSpec("version?", get_reply=Fixed((_VERSION,))),
    "warning": CommandSpec("warning?", get_reply=Fixed((_CODE,))),
}

# status_cmd: 範囲: get commands other than status? and status_cmd? (and ad_output?, no command).
STATUS_CMD_CHOICES: Final = frozenset(
    f"{name}?" for name, spec in SPECS.items()
    if spec.get_reply is not None and spec.from_host and name not in ("status", "status_cmd"))
# status?: the default output, 返却値 1-8.
DEFAULT_STATUS_CMDS: Final = ("mode?", "speed?", "dist?", "battery?", "ad_status?",
                              "ad_pattern?", "ad_action?", "ad_landmark?")
_STATUS_CMD_SHAPE: Final = CommandList(STATUS_CMD_CHOICES)


def status_fields(status_cmds: Sequence[str]) -> tuple[Field, ...]:
    """The values of a `status?` reply for a status_cmd list; ad_action? gives its ID only."""
    _STATUS_CMD_SHAPE.decode(list(status_cmds))
    fields: list[Field] = []
    for cmd in status_cmds:
        shape = SPECS[cmd[:-1]].get_reply
        fields.extend(shape.fields if isinstance(shape, Fixed) else (_AD_ACTION_ID,))
    return tuple(fields)


@dataclass(frozen=True)
class Line:
    """A line cut into command name, type character (`?` or `:`) and the text after it."""

    name: str
    kind: str
    rest: str


def leading_name(text: str) -> str:
    """The command name as the error reply names it: up to the first `?`, `:` or space."""
    return re.split(r"[?: ]", text, maxsplit=1)[0]


def _text(frame: bytes) -> str:
    return frame[:-1].decode("latin-1") if frame.endswith(TERMINATOR) else frame.decode("latin-1")


class CarriroCodec(Codec):
    """Host and vehicle sides of the CarriRo AD+ line protocol.

    `status_cmds` is the status_cmd list the vehicle currently uses: a `status?` reply can only be
    cut into values knowing it (status?, status_cmd:).
    """

    name: ClassVar[str] = PROTOCOL

    def __init__(self, status_cmds: Sequence[str] = DEFAULT_STATUS_CMDS) -> None:
        try:
            self._status = Fixed(status_fields(status_cmds))
        except FieldError as exc:
            raise ProtocolError(PROTOCOL, " ".join(status_cmds), str(exc)) from exc
        self.status_cmds: tuple[str, ...] = tuple(status_cmds)

    # -- shapes ------------------------------------------------------------------------------
    def _reply_shape(self, name: str, kind: str) -> Shape | None:
        if name == "status" and kind == "?":
            return self._status
        if name == "status_cmd":
            return _STATUS_CMD_SHAPE
        return SPECS[name].reply_shape(kind)

    @staticmethod
    def _params_shape(name: str, kind: str) -> Shape | None:
        spec = SPECS[name]
        if kind == "?":
            return spec.get_params if spec.get_reply is not None else None
        if name == "status_cmd":
            return _STATUS_CMD_SHAPE
        return spec.set_params

    # -- host side ---------------------------------------------------------------------------
    def encode(self, command: Command) -> bytes:
        spec = SPECS.get(command.name)
        kind = "?" if command.kind == "get" else ":"
        shape = self._params_shape(command.name, kind) if spec and spec.from_host else None
        if shape is None:
            raise ProtocolError(PROTOCOL, repr(command), "a command of the API reference "
                                "(コマンドリスト) in its get (?) or set (:) form")
        try:
            tokens = shape.encode(tuple(command.args))
        except FieldError as exc:
            raise ProtocolError(PROTOCOL, repr(command), str(exc)) from exc
        return self._line(command.name + kind, tokens, repr(command))

    def decode(self, frame: bytes) -> Reply:
        text = self._checked_text(frame)
        if not re.search(r"[?:]", text):
            banner = _BANNER_RE.fullmatch(text)
            if banner is None:
                raise ProtocolError(PROTOCOL, frame, "a reply `name? ...` or `name: ...`, or "
                                    "the start-up banner `CarriRo AD+ <version>`")
            return Reply(BANNER_NAME, BANNER, (banner[1], banner[2]))
        error = _ERROR_RE.fullmatch(text)
        if error:
            return Reply(error[1], ERROR, (int(error[2]),))
        line = self._split(text, frame)
        shape = self._reply_shape(line.name, line.kind) if line.name in SPECS else None
        if shape is None:
            raise ProtocolError(PROTOCOL, frame, "a reply of a command of the API reference")
        try:
            args = shape.decode(shape.split(line.rest))
        except FieldError as exc:
            raise ProtocolError(PROTOCOL, frame, str(exc)) from exc
        return Reply(line.name, VALUE if line.kind == "?" else DONE, args)

    def unframe(self, buffer: bytearray) -> list[bytes]:
        frames: list[bytes] = []
        while (end := buffer.find(TERMINATOR)) >= 0:
            frames.append(bytes(buffer[:end]))
            del buffer[: end + 1]
        return frames

    # -- vehicle side ------------------------------------------------------------------------
    def parse_command(self, frame: bytes) -> Command:
        """The command on one line; `CarriroError` carries the code the vehicle answers with."""
        text = _text(frame)
        name = leading_name(text)
        spec = SPECS.get(name)
        known = spec is not None and spec.from_host
        code = ERROR_INVALID_DATA if known else ERROR_UNKNOWN_COMMAND
        if len(text) > MAX_LINE_CHARS:
            raise CarriroError(code, name, frame, f"at most {MAX_LINE_CHARS} characters")
        if not _PRINTABLE_RE.fullmatch(text):
            raise CarriroError(code, name, frame, "printable ASCII ending in one LF")
        kind = text[len(name): len(name) + 1]
        if not known or kind not in ("?", ":"):
            raise CarriroError(ERROR_UNKNOWN_COMMAND, name, frame,
                               "a command of the API reference: `name?` or `name: ...`")
        shape = self._params_shape(name, kind)
        if shape is None:
            form = "get-only (no `:`)" if kind == ":" else "set-only (no `?`)"
            raise CarriroError(ERROR_UNKNOWN_COMMAND, name, frame, f"{name} is {form}")
        rest = text[len(name) + 1:]
        if rest and not rest.startswith(" "):
            raise CarriroError(ERROR_INVALID_DATA, name, frame,
                               "a space (0x20) between the command and its parameters")
        try:
            args = shape.decode(shape.split(rest))
        except FieldError as exc:
            raise CarriroError(ERROR_INVALID_DATA, name, frame, str(exc)) from exc
        command_kind = "get" if kind == "?" else SPECS[name].set_kind
        return Command(name, args, command_kind)

    def encode_reply(self, reply: Reply) -> bytes:
        """One reply line. A `status?` reply longer than 255 characters is cut (status_cmd: 注記);
        any other over-long reply raises."""
        where = repr(reply)
        if reply.status == BANNER:
            if len(reply.args) != 2 or not all(isinstance(a, str) for a in reply.args):
                raise ProtocolError(PROTOCOL, where, "banner args (model, version)")
            return self._line(f"{reply.args[0]} {reply.args[1]}", [], where)
        if reply.status == ERROR:
            if reply.args not in ((1,), (2,), (3,)) or not _ERROR_NAME_RE.fullmatch(reply.name):
                raise ProtocolError(PROTOCOL, where, "an error reply: a name and code 1, 2 or 3")
            return self._line(f"{reply.name}:", [f"error {reply.args[0]}"], where)
        kind = {VALUE: "?", DONE: ":"}.get(reply.status)
        shape = self._reply_shape(reply.name, kind) if kind and reply.name in SPECS else None
        if shape is None or kind is None:
            raise ProtocolError(PROTOCOL, where, "a reply of a command of the API reference, "
                                f"status {VALUE!r}, {DONE!r}, {ERROR!r} or {BANNER!r}")
        try:
            tokens = shape.encode(tuple(reply.args))
        except FieldError as exc:
            raise ProtocolError(PROTOCOL, where, str(exc)) from exc
        cut = reply.name == "status" and kind == "?"
        return self._line(reply.name + kind, tokens, where, cut=cut)

    # -- helpers -----------------------------------------------------------------------------
    @staticmethod
    def _line(head: str, tokens: list[str], where: str, cut: bool = False) -> bytes:
        text = head + "".join(" " + t for t in tokens)
        if cut:
            text = text[:MAX_LINE_CHARS].rstrip(" ")
        if len(text) > MAX_LINE_CHARS or not _PRINTABLE_RE.fullmatch(text):
            raise ProtocolError(PROTOCOL, where,
                                f"a line of at most {MAX_LINE_CHARS} printable ASCII characters")
        return text.encode("ascii") + TERMINATOR

    @staticmethod
    def _checked_text(frame: bytes) -> str:
        text = _text(frame)
        if len(text) > MAX_LINE_CHARS or not _PRINTABLE_RE.fullmatch(text):
            raise ProtocolError(PROTOCOL, frame,
                                f"one line of at most {MAX_LINE_CHARS} printable ASCII characters")
        return text

    @staticmethod
    def _split(text: str, frame: bytes) -> Line:
        match = re.match(r"([a-z_]+)([?:])", text)
        if match is None:
            raise ProtocolError(PROTOCOL, frame, "a command name followed by `?` or `:`")
        rest = text[match.end():]
        if rest and not rest.startswith(" "):
            raise ProtocolError(PROTOCOL, frame, "a space between the name and the values")
        return Line(match[1], match[2], rest)
