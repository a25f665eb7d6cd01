"""TABO ASCII commands: codec and virtual device.

Source: the TABO robot command table, a spreadsheet export with OCR damage; rows are cited by
their command ("MLL row") and column (コマンド返信, 引数補足, メモ).

Wire format: ``NAME`` or ``NAME:arg,arg...`` (the コマンド column), replies ``ACK:x``, ``ACK:c``,
``ACK:m``/``NAK:m``/``FIN:m``, ``ACK:b``/``NAK:b``, ``ACK:l``/``FIN:l``, ``ACK:s``,
``gbi:NNN``, ``gsv:a,b`` and ``vAA.BB.CC (YY/MM/DD)`` (the コマンド返信 column). A reply names
only its group letter, so `Reply.name` is that letter ("m") for ACK/NAK/FIN and the command
name ("GBI") for values.

The readings where the document is silent, damaged or contradicts itself, numbered as the
code cites them ("decision 3"): docs/background/decisions/protocols.md.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from typing import Any, Literal

from agv_model.protocols._sim import Outbox, SimClock, earliest
from agv_model.protocols.base import (
    Codec,
    Command,
    Device,
    ProtocolError,
    Reply,
    ascii_text,
    register,
)

PROTOCOL = "tabo"
TERMINATOR = b"\n"
WHEEL_MAX_MMPS = 410  # MLI/MLL/MDD/BDL 引数補足: 最小値 -410, 最大値 410
TURN_MAX_DPS = 1080  # MTI/MTL 引数補足: 最小値 -1080, 最大値 1080
STEP_LIMIT_MMPS = 300  # メモ: "現在速度との差が300以上"
LED_MAX = 255  # LSI/LAI/LAL 引数補足: 0-255
CORRECTION_MAX = 99  # SLV/STV 引数補足: 最小値 -99, 最大値 99 (x0.1 %)
NAME_MAX = 15  # SDN: "最大15文字(+ヌル文字)"
GETTER_PREFIX = {"GLV": "gsv", "GTV": "gtv", "GLD": "gsd", "GTD": "gtd"}  # コマンド返信

Group = Literal["x", "c", "m", "b", "l", "s"]


@dataclass(frozen=True)
class Spec:
    """One command row: argument count, reply group letter (None: no reply) and kind."""

    args: int
    group: Group | None
    kind: Literal["get", "set", "action"] = "action"


COMMANDS: dict[str, Spec] = {
    "X": Spec(0, "x"),
    "CES": Spec(0, None),
    "CER": Spec(0, None),
    "CMR": Spec(0, "c"),
    "MLI": Spec(1, "m"),
    "MLL": Spec(2, "m"),
    "MTI": Spec(1, "m"),
    "MTL": Spec(2, "m"),
    "MDD": Spec(2, "m"),
    "BWT": Spec(1, "b"),
    "BDL": Spec(3, "m"),
    "BHL": Spec(0, "b"),
    "LSI": Spec(4, "l"),
    "LAI": Spec(3, "l"),
    "LAL": Spec(4, "l"),
    "SLV": Spec(2, "s", "set"),
    "STV": Spec(2, "s", "set"),
    "SLD": Spec(2, "s", "set"),
    "STD": Spec(2, "s", "set"),
    "SDN": Spec(1, "s", "set"),
    "SBK": Spec(1, "s", "set"),
    "GVI": Spec(0, None, "get"),
    "GBI": Spec(0, None, "get"),
    "GLV": Spec(0, None, "get"),
    "GTV": Spec(0, None, "get"),
    "GLD": Spec(0, None, "get"),
    "GTD": Spec(0, None, "get"),
}

_INT = re.compile(r"[+-]?\d+")
_DIGITS3 = re.compile(r"\d{3}")
_VERSION = re.compile(r"v(\d{2})\.(\d{2})\.(\d{2}) \((\d{2}/\d{2}/\d{2})\)")


class UnknownCommandError(ProtocolError):
    """A line naming no command of the sheet."""


class ArgumentError(ProtocolError):
    """A known command with arguments the sheet does not allow; `group` picks the NAK."""

    def __init__(self, data: bytes | str, expected: str, command: str) -> None:
        super().__init__(PROTOCOL, data, expected)
        self.command = command


def clamp(value: int, limit: int) -> int:
    """Values beyond -limit..limit become the limit ("最小値、最大値に丸められる")."""
    return max(-limit, min(limit, value))


class TaboCodec(Codec):
    """TABO lines both ways."""

    name = PROTOCOL

    def __init__(self, terminator: bytes = TERMINATOR) -> None:
        self.terminator = terminator

    # -- host side -------------------------------------------------------------------------

    def encode(self, command: Command) -> bytes:
        spec = COMMANDS.get(command.name)
        if spec is None:
            raise ProtocolError(PROTOCOL, command.name, f"a command in {', '.join(COMMANDS)}")
        if len(command.args) != spec.args:
            raise ProtocolError(PROTOCOL, repr(command.args),
                                f"{spec.args} arguments for {command.name}")
        args = [self._format_arg(command.name, i, a) for i, a in enumerate(command.args)]
        text = command.name + (":" + ",".join(args) if args else "")
        return text.encode("ascii") + self.terminator

    @staticmethod
    def _format_arg(name: str, index: int, value: Any) -> str:
        if name == "SDN":
            return f"{value}\0"
        if name == "BDL" and index == 2:
            return "".join(str(int(v)) for v in value)
        return str(int(value))

    def decode(self, frame: bytes) -> Reply:
        text = self._text(frame)
        status, _, rest = text.partition(":")
        if status in ("ACK", "NAK", "FIN") and rest in ("x", "c", "m", "b", "l", "s"):
            return Reply(rest, status.lower())
        if status == "gbi" and _DIGITS3.fullmatch(rest):
            return Reply("GBI", "value", (int(rest),))
        getter = {v: k for k, v in GETTER_PREFIX.items()}.get(status)
        values = rest.split(",")
        if getter and len(values) == 2 and all(_INT.fullmatch(v) for v in values):
            return Reply(getter, "value", (int(values[0]), int(values[1])))
        version = _VERSION.fullmatch(text)
        if version:
            major, minor, micro, date = version.groups()
            return Reply("GVI", "value", (int(major), int(minor), int(micro), date))
        raise ProtocolError(PROTOCOL, frame, "ACK:/NAK:/FIN: and a group letter, gbi:NNN, "
                            "gsv:a,b (gtv, gsd, gtd) or vAA.BB.CC (YY/MM/DD)")

    # -- vehicle side ----------------------------------------------------------------------

    def parse_command(self, frame: bytes) -> Command:
        text = self._text(frame)
        if text.startswith("X"):  # "先頭文字が X であれば…当コマンドと認識"
            return Command("X")
        name, colon, rest = text.partition(":")
        spec = COMMANDS.get(name)
        if spec is None:
            raise UnknownCommandError(PROTOCOL, frame, f"a command in {', '.join(COMMANDS)}")
        raw = rest.split(",") if colon else []
        if len(raw) != spec.args:
            raise ArgumentError(frame, f"{spec.args} arguments for {name}", name)
        args: list[Any] = []
        for index, value in enumerate(raw):
            if name == "SDN":
                args.append(value.split("\0", 1)[0])
            elif name == "BDL" and index == 2:
                if not _DIGITS3.fullmatch(value):
                    raise ArgumentError(frame, "three digits R, G, B 0-9 for the BDL colour",
                                        name)
                args.append(tuple(int(d) for d in value))
            elif _INT.fullmatch(value):
                args.append(int(value))
            else:
                raise ArgumentError(frame, f"an integer for {name} argument {index + 1}", name)
        return Command(name, tuple(args), spec.kind)

    def encode_reply(self, reply: Reply) -> bytes:
        if reply.status in ("ack", "nak", "fin"):
            text = f"{reply.status.upper()}:{reply.name}"
        elif reply.name == "GBI":
            text = f"gbi:{int(reply.args[0]):03d}"
        elif reply.name in GETTER_PREFIX:
            text = f"{GETTER_PREFIX[reply.name]}:{int(reply.args[0])},{int(reply.args[1])}"
        elif reply.name == "GVI":
            major, minor, micro, date = reply.args
            text = f"v{major:02d}.{minor:02d}.{micro:02d} ({date})"
        else:
            raise ProtocolError(PROTOCOL, repr(reply), "an ack/nak/fin or a getter's value")
        return text.encode("ascii") + self.terminator

    def unframe(self, buffer: bytearray) -> list[bytes]:
        """Cut complete lines (terminator removed, a CR before an LF dropped, empty lines
        skipped)."""
        frames: list[bytes] = []
        while (end := buffer.find(self.terminator)) >= 0:
            line = bytes(buffer[:end])
            del buffer[: end + len(self.terminator)]
            if self.terminator == b"\n" and line.endswith(b"\r"):
                line = line[:-1]
            if line:
                frames.append(line)
        return frames

    @staticmethod
    def _text(frame: bytes) -> str:
        return ascii_text(PROTOCOL, frame, "ASCII text")


# -- virtual device ----------------------------------------------------------------------------

RGB = tuple[int, int, int]
OFF: RGB = (0, 0, 0)


@dataclass(frozen=True)
class Settings:
    """What lives in TABO's memory (設定 rows). Corrections are x0.1 %. The factory name
    "TABO" and brake off are assumptions; the sheet gives no factory values."""

    line_speed: tuple[int, int] = (0, 0)  # SLV: forward, backward
    turn_speed: tuple[int, int] = (0, 0)  # STV: clockwise, counter-clockwise
    line_distance: tuple[int, int] = (0, 0)  # SLD: forward, backward
    turn_distance: tuple[int, int] = (0, 0)  # STD: clockwise, counter-clockwise
    name: str = "TABO"
    brake: bool = False  # SBK; "ブレーキ:オフ" is listed first


FACTORY = Settings()


@dataclass
class _Fade:
    """An LAL fade of both LEDs."""

    start_s: float
    end_s: float
    start: tuple[RGB, RGB]
    target: RGB


@dataclass
class _Robot:
    wheels_mmps: tuple[int, int] = (0, 0)  # left, right
    turn_dps: int = 0
    fin_s: float | None = None  # FIN:m of an MLL/MTL in progress
    leds: tuple[RGB, RGB] = (OFF, OFF)  # right, left
    fade: _Fade | None = None
    waiting: bool = False  # BWT


class TaboDevice(Device):
    """A virtual TABO answering lines in simulated time.

    Settings (assumed defaults; the sheet gives no timings): ``reply_delay_s`` 0.02 s from a
    line's arrival (or the previous answer) to its answer and effect; ``reboot_time_s`` 3 s
    for CER; ``step_rule_reply`` "ack" (see decision 5); ``battery_pct`` 100;
    ``version`` (1, 0, 0, "17/01/01"), a placeholder: the sheet shows only the format.
    """

    name = PROTOCOL

    def __init__(
        self,
        *,
        reply_delay_s: float = 0.02,
        reboot_time_s: float = 3.0,
        step_rule_reply: Literal["ack", "nak"] = "ack",
        battery_pct: int = 100,
        version: tuple[int, int, int, str] = (1, 0, 0, "17/01/01"),
        stored: Settings = FACTORY,
        terminator: bytes = TERMINATOR,
    ) -> None:
        self.reply_delay_s = reply_delay_s
        self.reboot_time_s = reboot_time_s
        self.step_rule_reply = step_rule_reply
        self.battery_pct = battery_pct
        self.version = version
        self.codec = TaboCodec(terminator)
        self.ignored: list[tuple[float, bytes]] = []
        self.asleep = False
        self._stored = stored  # non-volatile memory
        self._factory_reset_pending = False
        self._clock = SimClock(PROTOCOL)
        self._outbox = Outbox()
        self._buffer = bytearray()
        self._busy_until_s = 0.0
        self._booting_until_s: float | None = None
        self._robot = _Robot()
        self._boot()

    # -- Device interface ------------------------------------------------------------------

    def receive(self, data: bytes, now_s: float) -> None:
        self._clock.advance(now_s)
        self._buffer += data
        for line in self.codec.unframe(self._buffer):
            self._advance(now_s)
            if self.asleep or self._booting_until_s is not None:
                self.ignored.append((now_s, line))
                continue
            done_s = max(now_s, self._busy_until_s) + self.reply_delay_s
            self._busy_until_s = done_s
            self._advance(done_s)
            reply = self._handle(line, now_s, done_s)
            if reply is not None:
                self._outbox.put(done_s, self.codec.encode_reply(reply))

    def poll(self, now_s: float) -> list[tuple[float, bytes]]:
        self._clock.advance(now_s)
        self._advance(now_s)
        return self._outbox.due(now_s)

    def next_output_s(self) -> float | None:
        fade_s = self._robot.fade.end_s if self._robot.fade else None
        return earliest(self._outbox.next_time_s(), self._robot.fin_s, fade_s)

    # -- simulation-facing state -----------------------------------------------------------

    @property
    def wheels_mmps(self) -> tuple[int, int]:
        """(left, right) wheel speeds the motors follow now."""
        return self._robot.wheels_mmps

    @property
    def turn_dps(self) -> int:
        return self._robot.turn_dps

    @property
    def waiting(self) -> bool:
        return self._robot.waiting

    @property
    def settings(self) -> Settings:
        """The values in effect now (volatile memory)."""
        return self._volatile

    @property
    def stored(self) -> Settings:
        """Non-volatile memory."""
        return self._stored

    @property
    def advertised_name(self) -> str:
        """The BLE name shown since the last boot."""
        return self._boot_settings.name

    def led_rgb(self, now_s: float) -> tuple[RGB, RGB]:
        """(right, left) LED colours at now_s, following an LAL fade."""
        fade = self._robot.fade
        if fade is None or now_s <= fade.start_s:
            return self._robot.leds
        share = min(1.0, (now_s - fade.start_s) / (fade.end_s - fade.start_s or 1.0))

        def mix(start: RGB) -> RGB:
            r, g, b = (round(s + (t - s) * share) for s, t in zip(start, fade.target,
                                                                  strict=True))
            return r, g, b

        return mix(fade.start[0]), mix(fade.start[1])

    def wake(self, now_s: float) -> None:
        """Press the power switch of a sleeping TABO."""
        self._clock.advance(now_s)
        if self.asleep:
            self.asleep = False
            self._boot()

    # -- internals -------------------------------------------------------------------------

    def _boot(self) -> None:
        self._boot_settings = self._stored
        self._volatile = self._stored
        self._robot = _Robot()

    def _power_off(self) -> None:
        """Stop everything and write memory ("電源OFF前に不揮発性メモリーに書き込みを行う")."""
        self._stored = FACTORY if self._factory_reset_pending else self._volatile
        self._factory_reset_pending = False
        self._robot = _Robot()

    def _advance(self, now_s: float) -> None:
        robot = self._robot
        if robot.fin_s is not None and robot.fin_s <= now_s:
            self._outbox.put(robot.fin_s, self.codec.encode_reply(Reply("m", "fin")))
            robot.fin_s = None
            robot.wheels_mmps, robot.turn_dps = (0, 0), 0
        if robot.fade is not None and robot.fade.end_s <= now_s:
            self._outbox.put(robot.fade.end_s, self.codec.encode_reply(Reply("l", "fin")))
            robot.leds = (robot.fade.target, robot.fade.target)
            robot.fade = None
        if self._booting_until_s is not None and self._booting_until_s <= now_s:
            self._booting_until_s = None
            self._boot()

    def _handle(self, line: bytes, now_s: float, done_s: float) -> Reply | None:
        try:
            command = self.codec.parse_command(line)
        except ArgumentError as err:
            group = COMMANDS[err.command].group
            if group is None:
                self.ignored.append((now_s, line))
                return None
            return Reply(group, "nak")
        except ProtocolError:
            self.ignored.append((now_s, line))
            return None
        return self._act(command, done_s)

    def _act(self, command: Command, at_s: float) -> Reply | None:
        name, args = command.name, command.args
        robot = self._robot
        group = COMMANDS[name].group or ""
        if name == "X":
            self._robot = _Robot()
        elif name in ("CES", "CER"):
            self._power_off()
            if name == "CES":
                self.asleep = True
            else:
                self._booting_until_s = at_s + self.reboot_time_s
            return None
        elif name == "CMR":
            self._factory_reset_pending = True
        elif name in ("MLI", "MLL", "MDD", "BDL"):
            return self._drive(name, args, at_s)
        elif name in ("MTI", "MTL"):
            return self._turn(name, args, at_s)
        elif name == "BWT":
            robot.waiting = args[0] != 0
        elif name == "BHL":
            if robot.fin_s is None and robot.fade is None:
                return Reply(group, "nak")
            if robot.fin_s is not None:
                robot.fin_s, robot.wheels_mmps, robot.turn_dps = None, (0, 0), 0
            if robot.fade is not None:
                robot.leds, robot.fade = self.led_rgb(at_s), None
        elif name in ("LSI", "LAI", "LAL"):
            return self._light(name, args, at_s)
        elif name in ("SLV", "STV", "SLD", "STD", "SDN", "SBK"):
            self._volatile = self._set(name, args)
        else:
            return self._get(name)
        return Reply(group, "ack")

    def _drive(self, name: str, args: tuple[Any, ...], at_s: float) -> Reply:
        robot = self._robot
        if name in ("MLI", "MLL"):
            speed = clamp(args[0], WHEEL_MAX_MMPS)
            target = (speed, speed)
        else:
            target = (clamp(args[0], WHEEL_MAX_MMPS), clamp(args[1], WHEEL_MAX_MMPS))
        fin_s = None
        if name == "MLL":
            distance = args[1]
            if target[0] == 0 or distance == 0 or (target[0] > 0) != (distance > 0):
                return Reply("m", "nak")
            correction = self._volatile.line_distance[0 if distance > 0 else 1]
            fin_s = at_s + abs(distance) * (1 + correction / 1000) / abs(target[0])
        if any(t != 0 and abs(t - c) >= STEP_LIMIT_MMPS
               for t, c in zip(target, robot.wheels_mmps, strict=True)):
            if self.step_rule_reply == "nak":
                return Reply("m", "nak")
        else:
            robot.wheels_mmps, robot.turn_dps, robot.fin_s = target, 0, fin_s
        if name == "BDL":
            red, green, blue = (round(d * LED_MAX / 9) for d in args[2])
            robot.leds, robot.fade = ((red, green, blue), (red, green, blue)), None
        return Reply("m", "ack")

    def _turn(self, name: str, args: tuple[Any, ...], at_s: float) -> Reply:
        robot = self._robot
        rate = clamp(args[0], TURN_MAX_DPS)
        fin_s = None
        if name == "MTL":
            angle = args[1]
            if rate == 0 or angle == 0 or (rate > 0) != (angle > 0):
                return Reply("m", "nak")
            correction = self._volatile.turn_distance[0 if angle > 0 else 1]
            fin_s = at_s + abs(angle) * (1 + correction / 1000) / abs(rate)
        robot.wheels_mmps, robot.turn_dps, robot.fin_s = (0, 0), rate, fin_s
        return Reply("m", "ack")

    def _light(self, name: str, args: tuple[Any, ...], at_s: float) -> Reply:
        robot = self._robot
        level = [max(0, min(LED_MAX, v)) for v in args]
        if name == "LSI":
            if args[0] not in (1, 2):  # "1:右側LED 2:左側LED"
                return Reply("l", "nak")
            colour = (level[1], level[2], level[3])
            leds = self.led_rgb(at_s)
            robot.leds = (colour, leds[1]) if args[0] == 1 else (leds[0], colour)
            robot.fade = None
        elif name == "LAI":
            colour = (level[0], level[1], level[2])
            robot.leds, robot.fade = (colour, colour), None
        else:
            if args[0] < 0:
                return Reply("l", "nak")
            target = (level[1], level[2], level[3])
            robot.fade = _Fade(at_s, at_s + args[0] / 1000, self.led_rgb(at_s), target)
        return Reply("l", "ack")

    def _set(self, name: str, args: tuple[Any, ...]) -> Settings:
        now = self._volatile
        if name == "SDN":
            return replace(now, name=str(args[0])[:NAME_MAX])
        if name == "SBK":
            return replace(now, brake=args[0] != 0)
        pair = (clamp(args[0], CORRECTION_MAX), clamp(args[1], CORRECTION_MAX))
        if name == "SLV":
            return replace(now, line_speed=pair)
        if name == "STV":
            return replace(now, turn_speed=pair)
        if name == "SLD":
            return replace(now, line_distance=pair)
        return replace(now, turn_distance=pair)

    def _get(self, name: str) -> Reply:
        if name == "GBI":
            return Reply("GBI", "value", (max(0, min(100, self.battery_pct)),))
        if name == "GVI":
            return Reply("GVI", "value", self.version)
        boot = self._boot_settings
        pair = {"GLV": boot.line_speed, "GTV": boot.turn_speed, "GLD": boot.line_distance,
                "GTD": boot.turn_distance}[name]
        return Reply(name, "value", pair)


register(PROTOCOL, TaboCodec, TaboDevice)
