"""KTM-02 binary frames: codec and virtual device.

Source: the KTM-02 command reference (final update H23-02-08, history to 2011-02-25), cited
below by its section headings.

Frame ("コマンドの書式"): ``[0]`` start byte 0xAA, ``[1]`` command, ``[2..3]`` packet size,
``[4]`` command id, ``[5..6]`` verify code, ``[7..]`` parameters ("パケットサイズ-7" bytes, so the
packet size counts the whole frame). Two-byte fields are low byte first, as the table's
"下位バイト 上位バイト" row says.

The readings where the document is silent, damaged or contradicts itself, numbered as the
code cites them ("decision 3"): docs/background/decisions/protocols.md.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any, Literal

from agv_model.protocols._sim import Outbox, SimClock, earliest
from agv_model.protocols.base import Codec, Command, Device, ProtocolError, Reply, register

PROTOCOL = "ktm02"
START_BYTE = 0xAA  # "1バイト(0xaa)"
HEADER_SIZE = 7  # parameters are "パケットサイズ-7" bytes
PACKAGE_SIZE_MIN = 58  # "画像パッケージサイズ 58～506"
PACKAGE_SIZE_MAX = 506
PACKAGE_SIZE_DEFAULT = 506  # "デフォルトで506"
MAX_PACKET_SIZE = HEADER_SIZE + 2 + PACKAGE_SIZE_MAX  # the largest frame: a full image package


class ErrorKind(IntEnum):
    """NAK parameter 2, "エラー内容"."""

    SENDING_ERROR_NONE = 0x00
    UNKNOWN_COMMAND_ERROR = 0x01
    VERIFY_ERROR = 0x02
    TIMEOUT_ERROR = 0x03


class RobotState(IntEnum):
    """SendStatusCmd parameter, "ロボットの状態"."""

    IDLE = 0x00
    GO_STRAIGHT_ALONG_LINE = 0x01
    ROTATE_RIGHT_ALONG_LINE = 0x02
    ROTATE_LEFT_ALONG_LINE = 0x03
    MOVING_FREELY = 0x04
    TAKING_PICTURE = 0x05


class Direction(IntEnum):
    """MoveFreelyCmd tyre direction, "タイヤの進行方向"."""

    FORWARD = 0x00
    BACK = 0x01


class ImageSize(IntEnum):
    """TakePictureCmd "画像サイズ"; the name gives width x height in pixels."""

    S80X64 = 0x01
    S160X128 = 0x03
    S320X240 = 0x05
    S640X480 = 0x07

    @property
    def pixels(self) -> tuple[int, int]:
        width, height = self.name[1:].split("X")
        return int(width), int(height)


class ResetTarget(IntEnum):
    """ResetCmd "リセット対象物"."""

    ALL = 0x01
    CAMERA = 0x02
    AVERAGED_SPEED = 0x03


class VerifyCodeError(ProtocolError):
    """The verify code does not match the frame (answered NAK VERIFY_ERROR)."""


class UnknownCommandError(ProtocolError):
    """A well-formed frame the receiver cannot understand (NAK UNKNOWN_COMMAND_ERROR)."""

    def __init__(self, data: bytes, expected: str, frame_id: int) -> None:
        super().__init__(PROTOCOL, data, expected)
        self.frame_id = frame_id


@dataclass(frozen=True)
class KtmCommand(Command):
    """A Command with its frame number (byte [4]); 0 lets the codec number it."""

    frame_id: int = 0


@dataclass(frozen=True)
class KtmReply(Reply):
    """A Reply with its frame number (byte [4]); 0 lets the codec number it."""

    frame_id: int = 0


@dataclass(frozen=True)
class Param:
    """One fixed parameter: struct code ("B" one byte, "H" two bytes low first) and its range
    or enum."""

    name: str
    code: Literal["B", "H"]
    low: int = 0
    high: int = 255
    enum: type[IntEnum] | None = None

    def check(self, value: Any, data: bytes | str) -> int:
        allowed = (
            ", ".join(f"{m.name}=0x{m.value:02x}" for m in self.enum)
            if self.enum
            else f"{self.low}..{self.high}"
        )
        if isinstance(value, bool) or not isinstance(value, int):
            raise ProtocolError(PROTOCOL, data, f"{self.name} an integer ({allowed})")
        if self.enum is not None:
            if value not in {m.value for m in self.enum}:
                raise ProtocolError(PROTOCOL, data, f"{self.name} one of {allowed}")
            return self.enum(value)
        if not self.low <= value <= self.high:
            raise ProtocolError(PROTOCOL, data, f"{self.name} in {allowed}, got {value}")
        return value


@dataclass(frozen=True)
class Message:
    """One command class of the document's tables: code, class name and parameter layout."""

    code: int
    name: str
    params: tuple[Param, ...] = ()
    kind: Literal["get", "set", "action"] = "action"
    status: str = "value"
    trailing_data: bool = False  # SendImagePackageCmd: "画像データ(以降, 繰返し)"
    optional_from: int | None = None  # params from this index on may be left out
    defaults: tuple[int, ...] = ()

    @property
    def fixed_size(self) -> int:
        return struct.calcsize("<" + "".join(p.code for p in self.params))

    def pack(self, args: tuple[Any, ...]) -> bytes:
        data = repr(args)
        values = list(args[: len(self.params)])
        if self.optional_from is not None and len(values) < len(self.params):
            values += list(self.defaults[len(values) - self.optional_from :])
        if len(values) != len(self.params):
            raise ProtocolError(PROTOCOL, data, f"{self.name} with {len(self.params)} params")
        checked = [p.check(v, data) for p, v in zip(self.params, values, strict=True)]
        packed = struct.pack("<" + "".join(p.code for p in self.params), *checked)
        if self.trailing_data:
            extra = args[len(self.params)] if len(args) > len(self.params) else b""
            if not isinstance(extra, bytes | bytearray):
                raise ProtocolError(PROTOCOL, data, f"{self.name} image data as bytes")
            packed += bytes(extra)
        elif len(args) > len(self.params):
            raise ProtocolError(PROTOCOL, data, f"{self.name} with {len(self.params)} params")
        return packed

    def unpack(self, params: bytes, frame: bytes) -> tuple[Any, ...]:
        sizes = [struct.calcsize(p.code) for p in self.params]
        counts = [len(sizes)]
        if self.optional_from is not None:
            counts += range(self.optional_from, len(sizes))
        if self.trailing_data:
            present = len(sizes) if len(params) >= sum(sizes) else None
        else:
            present = next((n for n in counts if sum(sizes[:n]) == len(params)), None)
        if present is None:
            allowed = " or ".join(str(sum(sizes[:n])) for n in sorted(counts))
            more = " or more" if self.trailing_data else ""
            raise ProtocolError(PROTOCOL, frame, f"{self.name} with {allowed}{more} parameter "
                                f"bytes, got {len(params)}")
        fixed = sum(sizes[:present])
        codes = "".join(p.code for p in self.params[:present])
        raw = struct.unpack("<" + codes, params[:fixed])
        values: list[Any] = [p.check(v, frame) for p, v in zip(self.params, raw, strict=False)]
        if present < len(sizes):
            values += self.defaults[present - (self.optional_from or 0) :]
        if self.trailing_data:
            values.append(bytes(params[fixed:]))
        return tuple(values)


_FRAME_ID = Param("command id", "B", 1, 255)
_NAK_FRAME_ID = Param("command id", "B", 0, 255)
_SPEED = Param("speed", "B", 0, 255)  # "スピード 0～255の数値"

ACK = Message(0x01, "ControllerAckCmd", (_FRAME_ID,), status="ack")
NAK = Message(0x02, "ControllerNakCmd", (_NAK_FRAME_ID, Param("error", "B", enum=ErrorKind)),
              status="nak")

#: "KTM-02からコントローラへ送信するコマンド"
DEVICE_MESSAGES: dict[int, Message] = {m.code: m for m in (
    ACK,
    NAK,
    Message(0x03, "SendStatusCmd", (Param("state", "B", enum=RobotState),)),
    # "タイヤのスピード 0～65535の数値 [mm/s]"
    Message(0x04, "SendSpeedCmd", (Param("right tyre speed", "H", 0, 65535),
                                   Param("left tyre speed", "H", 0, 65535))),
    Message(0x05, "SendImagePackageCmd", (Param("package id", "H", 1, 65535),),
            trailing_data=True),
    Message(0x12, "SendImagePackageNumCmd", (Param("package count", "H", 1, 65535),)),
    Message(0x14, "SendDistanceCmd", (Param("distance", "B", 0, 254),)),
    Message(0x17, "MovingFinishCmd", status="fin"),
)}

#: "コントローラからKTM-02へ送信するコマンド"
HOST_MESSAGES: dict[int, Message] = {m.code: m for m in (
    ACK,
    NAK,
    Message(0x06, "GoStraightAlongLineCmd", (_SPEED,)),
    Message(0x07, "RotateRightAlongLineCmd", (_SPEED,)),
    Message(0x08, "RotateLeftAlongLineCmd", (_SPEED,)),
    Message(0x09, "EmergencyStopCmd"),
    Message(0x0A, "MoveFreelyCmd", (Param("right speed", "B"),
                                    Param("right direction", "B", enum=Direction),
                                    Param("left speed", "B"),
                                    Param("left direction", "B", enum=Direction))),
    Message(0x0B, "TakePictureCmd", (Param("image size", "B", enum=ImageSize),
                                     Param("image package size", "H", PACKAGE_SIZE_MIN,
                                           PACKAGE_SIZE_MAX)),
            optional_from=0, defaults=(ImageSize.S320X240, PACKAGE_SIZE_DEFAULT)),
    Message(0x0D, "RequestStatusCmd", kind="get"),
    Message(0x0E, "ResetCmd", (Param("reset target", "B", enum=ResetTarget),)),
    Message(0x10, "RequestMomentarySpeedCmd", kind="get"),
    Message(0x13, "RequestDistanceCmd", kind="get"),
    Message(0x15, "RequestImagePackageCmd", kind="get"),
    Message(0x16, "StopCmd"),
    Message(0x18, "RequestAveragedSpeedCmd", kind="get"),
)}

_BY_NAME_HOST = {m.name: m for m in HOST_MESSAGES.values()}
_BY_NAME_DEVICE = {m.name: m for m in DEVICE_MESSAGES.values()}

VerifyFn = Callable[[bytes], int]


def sum16(data: bytes) -> int:
    """KTM-02 verify code, our choice (the document gives none): the low 16 bits of the byte
    sum of the frame without its two verify bytes."""
    return sum(data) & 0xFFFF


def pad_last_package(data: bytes, package_size: int, pad_byte: int) -> list[bytes]:
    """Cut image data into packages of `package_size` bytes, padding the last one
    ("最終送信パッケージ": 10 bytes of data in a 256-byte package get 246 pad bytes)."""
    if not PACKAGE_SIZE_MIN <= package_size <= PACKAGE_SIZE_MAX:
        raise ValueError(f"package_size ({package_size}) must be in "
                         f"{PACKAGE_SIZE_MIN}..{PACKAGE_SIZE_MAX}")
    chunks = [data[i : i + package_size] for i in range(0, len(data), package_size)] or [b""]
    last = chunks[-1]
    chunks[-1] = last + bytes([pad_byte]) * (package_size - len(last))
    return chunks


class Ktm02Codec(Codec):
    """KTM-02 frames both ways; numbers outgoing frames 1..255, wrapping past 0."""

    name = PROTOCOL

    def __init__(self, verify: VerifyFn = sum16) -> None:
        self.verify = verify
        self._next_frame_id = 1

    def next_frame_id(self) -> int:
        frame_id = self._next_frame_id
        self._next_frame_id = frame_id % 255 + 1
        return frame_id

    def frame(self, code: int, frame_id: int, params: bytes) -> bytes:
        size = HEADER_SIZE + len(params)
        if size > MAX_PACKET_SIZE:
            raise ProtocolError(PROTOCOL, params, f"at most {MAX_PACKET_SIZE - HEADER_SIZE} "
                                "parameter bytes")
        head = bytes([START_BYTE, code, size & 0xFF, size >> 8, frame_id])
        code_value = self.verify(head + params) & 0xFFFF
        return head + bytes([code_value & 0xFF, code_value >> 8]) + params

    def _split(self, frame: bytes) -> tuple[int, int, bytes]:
        """Check start byte, size and verify code; return (command code, frame id, params)."""
        if len(frame) < HEADER_SIZE or frame[0] != START_BYTE:
            raise ProtocolError(PROTOCOL, frame, f"a frame of at least {HEADER_SIZE} bytes "
                                "starting with 0xaa")
        size = frame[2] | frame[3] << 8
        if size != len(frame):
            raise ProtocolError(PROTOCOL, frame, f"packet size field {size} to equal the frame "
                                f"length {len(frame)}")
        got = frame[5] | frame[6] << 8
        want = self.verify(frame[:5] + frame[7:]) & 0xFFFF
        if got != want:
            raise VerifyCodeError(PROTOCOL, frame, f"verify code 0x{want:04x}, got 0x{got:04x}")
        return frame[1], frame[4], frame[7:]

    def _parse(self, frame: bytes, table: dict[int, Message]) -> tuple[Message, int, tuple[Any,
                                                                                           ...]]:
        code, frame_id, params = self._split(frame)
        message = table.get(code)
        if message is None:
            known = ", ".join(f"0x{c:02x}" for c in sorted(table))
            raise UnknownCommandError(frame, f"a command code in {known}", frame_id)
        if frame_id == 0:
            raise UnknownCommandError(frame, "a command id in 1..255", 0)
        try:
            args = message.unpack(params, frame)
        except ProtocolError as err:
            raise UnknownCommandError(frame, err.expected, frame_id) from err
        return message, frame_id, args

    def _encode(self, name: str, args: tuple[Any, ...], frame_id: int,
                table: dict[str, Message]) -> bytes:
        message = table.get(name)
        if message is None:
            raise ProtocolError(PROTOCOL, name, f"a command class in {', '.join(table)}")
        _FRAME_ID.check(frame_id or 1, repr(frame_id))
        return self.frame(message.code, frame_id or self.next_frame_id(), message.pack(args))

    def encode(self, command: Command) -> bytes:
        frame_id = command.frame_id if isinstance(command, KtmCommand) else 0
        return self._encode(command.name, command.args, frame_id, _BY_NAME_HOST)

    def parse_command(self, frame: bytes) -> KtmCommand:
        message, frame_id, args = self._parse(frame, HOST_MESSAGES)
        return KtmCommand(message.name, args, message.kind, frame_id)

    def encode_reply(self, reply: Reply) -> bytes:
        frame_id = reply.frame_id if isinstance(reply, KtmReply) else 0
        return self._encode(reply.name, reply.args, frame_id, _BY_NAME_DEVICE)

    def decode(self, frame: bytes) -> KtmReply:
        message, frame_id, args = self._parse(frame, DEVICE_MESSAGES)
        return KtmReply(message.name, message.status, args, frame_id)

    def unframe(self, buffer: bytearray) -> list[bytes]:
        """Cut complete frames; junk before a start byte or an impossible size field raises
        ProtocolError after removing the offending bytes, once the good frames before it have
        been returned."""
        frames: list[bytes] = []
        while buffer:
            if buffer[0] != START_BYTE:
                if frames:
                    break
                end = buffer.find(START_BYTE)
                end = len(buffer) if end < 0 else end
                junk = bytes(buffer[:end])
                del buffer[:end]
                raise ProtocolError(PROTOCOL, junk, "start byte 0xaa")
            if len(buffer) < 4:
                break
            size = buffer[2] | buffer[3] << 8
            if not HEADER_SIZE <= size <= MAX_PACKET_SIZE:
                if frames:
                    break
                head = bytes(buffer[:4])
                del buffer[:1]
                raise ProtocolError(PROTOCOL, head,
                                    f"packet size {HEADER_SIZE}..{MAX_PACKET_SIZE}")
            if len(buffer) < size:
                break
            frames.append(bytes(buffer[:size]))
            del buffer[:size]
        return frames


def synthetic_jpeg(size: ImageSize) -> bytes:
    """A stand-in picture: JPEG start/end markers around deterministic bytes; one byte per
    ten pixels (an assumed JPEG compression ratio, not from the document)."""
    width, height = size.pixels
    body = bytes((i * 7 + 3) % 251 for i in range(width * height // 10 - 4))
    return b"\xff\xd8" + body + b"\xff\xd9"


@dataclass
class _Motion:
    state: RobotState = RobotState.IDLE
    right_mmps: float = 0.0
    left_mmps: float = 0.0
    ends_s: float | None = None


@dataclass
class _Odometer:
    """Time-weighted average of the tyre speeds since the last reset."""

    since_s: float = 0.0
    last_s: float = 0.0
    right_mm: float = 0.0
    left_mm: float = 0.0

    def run(self, now_s: float, right_mmps: float, left_mmps: float) -> None:
        self.right_mm += right_mmps * (now_s - self.last_s)
        self.left_mm += left_mmps * (now_s - self.last_s)
        self.last_s = now_s

    def average(self, now_s: float, right_mmps: float, left_mmps: float) -> tuple[int, int]:
        self.run(now_s, right_mmps, left_mmps)
        span = now_s - self.since_s
        if span <= 0:
            return round(right_mmps), round(left_mmps)
        return round(self.right_mm / span), round(self.left_mm / span)


@dataclass
class _Camera:
    done_s: float | None = None
    packages: list[bytes] = field(default_factory=list)
    sent: int = 0


class Ktm02Device(Device):
    """A virtual KTM-02 answering host frames in simulated time.

    Settings (assumed defaults; the document gives no timings or speeds):
    ``reply_delay_s`` 0.005 s from a frame's arrival (or the end of the previous one) to its
    answer; ``frame_timeout_s`` 0.1 s for a started frame to complete; ``full_speed_mmps``
    500 mm/s for speed 255; ``straight_time_s`` None (run until stopped) and ``rotate_time_s``
    1.5 s for the along-line motions to finish; ``picture_time_s`` 0.3 s to take a picture;
    ``image_source`` makes the picture bytes; ``pad_byte`` pads the last package.
    """

    name = PROTOCOL

    def __init__(
        self,
        *,
        reply_delay_s: float = 0.005,
        frame_timeout_s: float = 0.1,
        full_speed_mmps: float = 500.0,
        straight_time_s: float | None = None,
        rotate_time_s: float | None = 1.5,
        picture_time_s: float = 0.3,
        image_source: Callable[[ImageSize], bytes] = synthetic_jpeg,
        pad_byte: int = 0x30,
        distance_reading: int = 254,
        verify: VerifyFn = sum16,
    ) -> None:
        self.reply_delay_s = reply_delay_s
        self.frame_timeout_s = frame_timeout_s
        self.full_speed_mmps = full_speed_mmps
        self.straight_time_s = straight_time_s
        self.rotate_time_s = rotate_time_s
        self.picture_time_s = picture_time_s
        self.image_source = image_source
        self.pad_byte = pad_byte
        self.distance_reading = distance_reading
        self.codec = Ktm02Codec(verify)
        self.host_naks: list[tuple[int, ErrorKind]] = []
        self._clock = SimClock(PROTOCOL)
        self._outbox = Outbox()
        self._buffer = bytearray()
        self._partial_since_s: float | None = None
        self._junk_until_s: float | None = None  # junk arriving by then continues a NAKed run
        self._busy_until_s = 0.0
        self._motion = _Motion()
        self._odometer = _Odometer()
        self._camera = _Camera()

    # -- Device interface ------------------------------------------------------------------

    def receive(self, data: bytes, now_s: float) -> None:
        self._clock.advance(now_s)
        self._advance(now_s)
        if not self._buffer:
            self._partial_since_s = now_s
        self._buffer += data
        while self._buffer:
            if self._buffer[0] == START_BYTE:
                self._junk_until_s = None
            elif self._junk_until_s is not None and now_s <= self._junk_until_s:
                self._drop_junk(now_s)  # more of a run already answered
                continue
            try:
                frames = self.codec.unframe(self._buffer)
            except ProtocolError:
                self._answer(now_s, 0, ErrorKind.UNKNOWN_COMMAND_ERROR)
                if not self._buffer:  # the junk ran to the end of what has arrived
                    self._junk_until_s = now_s + self.frame_timeout_s
                continue
            if not frames:
                break
            self._partial_since_s = now_s  # what is left started in this chunk
            for frame in frames:
                self._handle(frame, now_s)
        if not self._buffer:
            self._partial_since_s = None

    def poll(self, now_s: float) -> list[tuple[float, bytes]]:
        self._clock.advance(now_s)
        self._advance(now_s)
        return self._outbox.due(now_s)

    def next_output_s(self) -> float | None:
        return earliest(self._outbox.next_time_s(), *self._event_times())

    def _drop_junk(self, now_s: float) -> None:
        end = self._buffer.find(START_BYTE)
        del self._buffer[: end if end >= 0 else len(self._buffer)]
        if not self._buffer:
            self._junk_until_s = now_s + self.frame_timeout_s

    # -- simulation-facing state -----------------------------------------------------------

    @property
    def state(self) -> RobotState:
        if self._camera.done_s is not None:
            return RobotState.TAKING_PICTURE
        return self._motion.state

    @property
    def tyre_speeds_mmps(self) -> tuple[float, float]:
        """(right, left) tyre speeds now."""
        return self._motion.right_mmps, self._motion.left_mmps

    # -- timed events ----------------------------------------------------------------------

    def _timeout_s(self) -> float | None:
        if self._partial_since_s is None or not self._buffer:
            return None
        return self._partial_since_s + self.frame_timeout_s

    def _event_times(self) -> tuple[float | None, ...]:
        return self._motion.ends_s, self._camera.done_s, self._timeout_s()

    def _advance(self, now_s: float) -> None:
        """Run the device's own events (motion end, picture done, frame timeout) up to now_s."""
        while True:
            due = earliest(*self._event_times())
            if due is None or due > now_s:
                break
            if due == self._timeout_s():
                frame_id = self._buffer[4] if len(self._buffer) > 4 else 0
                self._buffer.clear()
                self._partial_since_s = None
                self._outbox.put(due, self._nak(frame_id, ErrorKind.TIMEOUT_ERROR))
            elif due == self._motion.ends_s:
                self._stop_motion(due)
            else:
                self._camera.done_s = None
                count = len(self._camera.packages)
                self._outbox.put(due, self._send("SendImagePackageNumCmd", count))

    # -- frame handling --------------------------------------------------------------------

    def _send(self, name: str, *args: Any) -> bytes:
        return self.codec.encode_reply(Reply(name, "value", args))

    def _nak(self, frame_id: int, kind: ErrorKind) -> bytes:
        return self._send("ControllerNakCmd", frame_id, kind)

    def _answer(self, now_s: float, nak_id: int | None = None,
                nak_kind: ErrorKind = ErrorKind.UNKNOWN_COMMAND_ERROR) -> float:
        """Take the next reply slot after now_s, run events up to it and return its time;
        with `nak_id`, send a NAK in it."""
        done_s = max(now_s, self._busy_until_s) + self.reply_delay_s
        self._busy_until_s = done_s
        self._advance(done_s)
        if nak_id is not None:
            self._outbox.put(done_s, self._nak(nak_id, nak_kind))
        return done_s

    def _handle(self, frame: bytes, now_s: float) -> None:
        try:
            command = self.codec.parse_command(frame)
        except VerifyCodeError:
            frame_id = frame[4] if len(frame) > 4 else 0
            self._answer(now_s, frame_id, ErrorKind.VERIFY_ERROR)
            return
        except UnknownCommandError as err:
            self._answer(now_s, err.frame_id)
            return
        except ProtocolError:
            self._answer(now_s, 0)
            return
        if command.name == "ControllerAckCmd":
            return
        if command.name == "ControllerNakCmd":
            self.host_naks.append((command.args[0], command.args[1]))
            return
        done_s = self._answer(now_s)
        camera = self._camera
        if command.name == "RequestImagePackageCmd" and (
            camera.done_s is not None or camera.sent >= len(camera.packages)
        ):
            self._outbox.put(done_s, self._nak(command.frame_id,
                                               ErrorKind.UNKNOWN_COMMAND_ERROR))
            return
        self._outbox.put(done_s, self._send("ControllerAckCmd", command.frame_id))
        for reply in self._act(command, done_s):
            self._outbox.put(done_s, reply)

    def _act(self, command: KtmCommand, at_s: float) -> list[bytes]:
        """Carry out a command at its completion time; return the data frames that follow
        the ACK."""
        name, args = command.name, command.args
        motion = self._motion
        if name in ("GoStraightAlongLineCmd", "RotateRightAlongLineCmd",
                    "RotateLeftAlongLineCmd"):
            speed = self._mmps(args[0])
            state = {"GoStraightAlongLineCmd": RobotState.GO_STRAIGHT_ALONG_LINE,
                     "RotateRightAlongLineCmd": RobotState.ROTATE_RIGHT_ALONG_LINE,
                     "RotateLeftAlongLineCmd": RobotState.ROTATE_LEFT_ALONG_LINE}[name]
            run_s = (self.straight_time_s if state is RobotState.GO_STRAIGHT_ALONG_LINE
                     else self.rotate_time_s)
            self._start_motion(at_s, state, speed, speed, run_s)
        elif name == "MoveFreelyCmd":
            self._start_motion(at_s, RobotState.MOVING_FREELY, self._mmps(args[0]),
                               self._mmps(args[2]), None)
        elif name in ("StopCmd", "EmergencyStopCmd"):
            self._stop_motion(at_s)
        elif name == "TakePictureCmd":
            image = self.image_source(ImageSize(args[0]))
            self._camera = _Camera(at_s + self.picture_time_s,
                                   pad_last_package(image, args[1], self.pad_byte))
        elif name == "ResetCmd":
            self._reset(ResetTarget(args[0]), at_s)
        elif name == "RequestStatusCmd":
            return [self._send("SendStatusCmd", self.state)]
        elif name == "RequestMomentarySpeedCmd":
            return [self._send("SendSpeedCmd", round(motion.right_mmps),
                               round(motion.left_mmps))]
        elif name == "RequestAveragedSpeedCmd":
            average = self._odometer.average(at_s, motion.right_mmps, motion.left_mmps)
            return [self._send("SendSpeedCmd", *average)]
        elif name == "RequestDistanceCmd":
            return [self._send("SendDistanceCmd", self.distance_reading)]
        elif name == "RequestImagePackageCmd":
            camera = self._camera
            camera.sent += 1
            return [self._send("SendImagePackageCmd", camera.sent,
                               camera.packages[camera.sent - 1])]
        return []

    def _mmps(self, speed: int) -> float:
        return speed * self.full_speed_mmps / 255

    def _start_motion(self, at_s: float, state: RobotState, right_mmps: float,
                      left_mmps: float, run_s: float | None) -> None:
        if right_mmps == 0 and left_mmps == 0:  # "0で停止"
            self._stop_motion(at_s)
            return
        self._odometer.run(at_s, self._motion.right_mmps, self._motion.left_mmps)
        ends_s = None if run_s is None else at_s + run_s
        self._motion = _Motion(state, right_mmps, left_mmps, ends_s)

    def _stop_motion(self, at_s: float) -> None:
        was_moving = self._motion.state is not RobotState.IDLE
        self._odometer.run(at_s, self._motion.right_mmps, self._motion.left_mmps)
        self._motion = _Motion()
        if was_moving:
            self._outbox.put(at_s, self._send("MovingFinishCmd"))

    def _reset(self, target: ResetTarget, at_s: float) -> None:
        if target in (ResetTarget.ALL, ResetTarget.CAMERA):
            self._camera = _Camera()
        if target is ResetTarget.ALL:
            self._stop_motion(at_s)
        if target in (ResetTarget.ALL, ResetTarget.AVERAGED_SPEED):
            self._odometer.run(at_s, self._motion.right_mmps, self._motion.left_mmps)
            self._odometer = _Odometer(at_s, at_s)


register(PROTOCOL, Ktm02Codec, Ktm02Device)
