"""A virtual CarriRo AD+ on its serial port, driven by simulated time.

It answers like the vehicle of the API reference: the start-up banner, one command at a time with
further input ignored until the reply is sent (処理), error 1/2/3 (エラーコード), the modes of
Appendix G, get-only and settable commands, status_cmd and the periodic `status?` of comm:. The
readings where the document is unclear are listed in `agv_model.protocols.carriro`.

Motion is not modelled here: whoever owns the device (the fleet model, `agv_model.dynamics`, a
test) writes speed, distance, battery, landmark and attachments into `device.state`; the device
changes state only where a command says so (mode:, ad_action:, action:, ad_speed_limit: ...).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection
from dataclasses import dataclass, field, replace
from typing import ClassVar, Final

from agv_model.protocols.base import Command, Device, ProtocolError, Reply
from agv_model.protocols.carriro_codec import (
    BANNER,
    BANNER_NAME,
    DEFAULT_STATUS_CMDS,
    DONE,
    ERROR,
    PROTOCOL,
    VALUE,
    CarriroCodec,
    CarriroError,
)
from agv_model.protocols.carriro_tables import (
    AD_ACTIONS,
    BANNER_VERSION,
    CARRIRO_ACTIONS,
    ERROR_INVALID_DATA,
    ERROR_INVALID_STATE,
    ERROR_UNKNOWN_COMMAND,
    LANDMARK_UNSET,
    LANDMARKS,
    MAX_LINE_CHARS,
    MODE_AUTONOMOUS,
    MODE_ERROR,
    MODE_PARKING,
    MODE_WARNING,
    MODEL_NAME,
    MODES,
    NO_CODE,
    TERMINATOR,
    Value,
    default_params,
    describe_code,
)

# Assumed timings; the document gives none for the vehicle (see carriro.py).
DEFAULT_PROCESSING_S: Final = 0.005
DEFAULT_QUIET_AFTER_REPLY_S: Final = 0.010  # 処理: the host waits 10 ms after a reply
DEFAULT_STARTUP_S: Final = 1.0
DEFAULT_UNIT_ID: Final = "0012f337e03c"  # id? レスポンス例
STRAIGHT_3_KMH: Final = 3.0  # Appendix B, action 4 直進3: 30 at 倍率 10

_SETTABLE: Final = frozenset(m for m, (_, settable) in MODES.items() if settable)
# mode: which targets each current mode accepts (Appendix G reading, see carriro.py).
MODE_TARGETS: Final[dict[int, frozenset[int]]] = {
    **{m: _SETTABLE for m in _SETTABLE},
    **{m: frozenset({MODE_PARKING}) for m in (2, MODE_WARNING, 6, 7)},
    **{m: frozenset() for m in (0, 1, MODE_ERROR, 12)},
}
# reboot:, shutdown: 注記: "パーキングモードと、エラーモードの時のみ利用可能"
POWER_COMMAND_MODES: Final = frozenset({MODE_PARKING, MODE_ERROR})


@dataclass
class CarriroState:
    """What the vehicle reports, in the document's units. The owner writes the physical values."""

    mode: int = MODE_PARKING
    speed_kmh: float = 0.0
    dist_m: float = 0.0
    battery_pct: int = 100
    ad_status: int = 1  # Appendix D: 1 自律モードではない
    ad_pattern: int = 0  # ad_pattern: 0 未設定
    ad_action: int = 0
    ad_action_params: tuple[Value, ...] = ()
    landmark_id: int = LANDMARK_UNSET
    landmark_dist_m: float = 0.0
    speed_limit_kmh: float = 3.0  # ad_speed_limit: デフォルト値 30
    comm_period_s: float = 0.0  # comm: デフォルト値 0
    status_cmds: tuple[str, ...] = DEFAULT_STATUS_CMDS
    error_code: str = NO_CODE
    warning_code: str = NO_CODE
    pallet_option: int = 0
    pallet_attached: int = 0
    trolley_option: int = 0
    trolley_attached: int = 0
    resume_kmh: float = field(default=0.0, repr=False)


def _floor_to(value: float, scale: int) -> float:
    """A counter as the vehicle reports it: whole steps of 1/scale, rounded down."""
    return math.floor(value * scale + 1e-6) / scale


class CarriroDevice(Device):
    """The vehicle end of the serial line. Every time is simulated (`now_s`), never wall clock.

    Settings: `processing_s` from a command's LF to its reply; `quiet_after_reply_s` after a reply
    during which input is still ignored (0 to model a vehicle that listens at once);
    `startup_s` from power-on or reboot to the banner; `powered_on_s` when it is switched on;
    `action_ids` the IDs `action:` accepts (Appendix A); `speed_limit_alias` whether
    `speed_limit` is accepted for `ad_speed_limit` as in that command's examples.
    """

    name: ClassVar[str] = PROTOCOL

    def __init__(self, *, processing_s: float = DEFAULT_PROCESSING_S,
                 quiet_after_reply_s: float = DEFAULT_QUIET_AFTER_REPLY_S,
                 startup_s: float = DEFAULT_STARTUP_S, powered_on_s: float = 0.0,
                 model: str = MODEL_NAME, version: str = BANNER_VERSION,
                 unit_id: str = DEFAULT_UNIT_ID,
                 action_ids: Collection[int] = tuple(CARRIRO_ACTIONS),
                 speed_limit_alias: bool = True, state: CarriroState | None = None) -> None:
        for label, value in (("processing_s", processing_s), ("startup_s", startup_s),
                             ("quiet_after_reply_s", quiet_after_reply_s)):
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{label} must be a finite time >= 0, not {value!r}")
        self.processing_s = processing_s
        self.quiet_after_reply_s = quiet_after_reply_s
        self.startup_s = startup_s
        self.model = model
        self.version = version
        self.unit_id = unit_id
        self.action_ids = frozenset(action_ids)
        self.speed_limit_alias = speed_limit_alias
        self.state = state if state is not None else CarriroState()
        self.ignored_bytes = 0  # bytes dropped because the vehicle was not listening
        self._codec = CarriroCodec(self.state.status_cmds)
        self._check_identity()
        self._clock_s = powered_on_s
        self._on = True
        self._banner_s: float | None = powered_on_s + startup_s
        self._busy_until_s = -math.inf
        self._line = bytearray()
        self._pending: tuple[float, bytes] | None = None
        self._next_status_s: float | None = None
        self._outbox: list[tuple[float, bytes]] = []
        self._power_after: str | None = None
        self._handlers: dict[str, Callable[[Command, float], Reply]] = {
            "action": self._action, "ad_action": self._ad_action, "ad_pattern": self._set_pattern,
            "ad_speed_limit": self._set_speed_limit, "speed_limit": self._set_speed_limit,
            "comm": self._set_comm, "echo": self._echo, "mode": self._set_mode,
            "reboot": self._power, "shutdown": self._power, "status_cmd": self._set_status_cmd,
        }

    def _check_identity(self) -> None:
        if not all(isinstance(a, int) and a >= 0 for a in self.action_ids):
            raise ValueError(f"action_ids must be non-negative integers, not {self.action_ids!r}")
        try:
            self._codec.encode_reply(Reply(BANNER_NAME, BANNER, (self.model, self.version)))
            self._codec.encode_reply(Reply("version", VALUE, (self.version,)))
            self._codec.encode_reply(Reply("id", VALUE, (self.unit_id,)))
        except ProtocolError as exc:
            raise ValueError(f"not a valid CarriRo identity: {exc.expected}") from exc

    # -- the Device interface ----------------------------------------------------------------
    def receive(self, data: bytes, now_s: float) -> None:
        self._run_until(now_s)
        for byte in data:
            if not self.listening(now_s):
                self.ignored_bytes += 1
            elif byte == TERMINATOR[0]:
                self._pending = (now_s + self.processing_s, bytes(self._line))
                self._line.clear()
                self._run_until(now_s)
            elif len(self._line) <= MAX_LINE_CHARS:  # keep one more than allowed: "too long"
                self._line.append(byte)

    def poll(self, now_s: float) -> list[tuple[float, bytes]]:
        self._run_until(now_s)
        sent, self._outbox = self._outbox, []
        return sent

    def next_output_s(self) -> float | None:
        times = [t for t, _ in self._outbox] + [t for t in self._event_times() if t is not None]
        return min(times, default=None)

    # -- simulation hooks --------------------------------------------------------------------
    def listening(self, now_s: float) -> bool:
        """Whether a byte arriving at `now_s` is taken (処理, スタートアップ)."""
        return (self._on and self._banner_s is None and self._pending is None
                and now_s >= self._busy_until_s)

    def power_on(self, now_s: float) -> None:
        """Switch a shut-down vehicle on again; the banner follows after `startup_s`."""
        self._run_until(now_s)
        if not self._on:
            self._restart(now_s)

    def raise_code(self, code: str, now_s: float) -> None:
        """An Appendix E error or warning occurs: error mode (4) or warning mode (3)."""
        self._run_until(now_s)
        described = describe_code(code)
        if described is None or described[0] not in ("Error", "Warning"):
            raise ValueError(f"{code!r} is not an Error or Warning code of Appendix E")
        state = self.state
        autonomous = state.mode == MODE_AUTONOMOUS
        if described[0] == "Error":
            state.error_code, state.mode = code, MODE_ERROR
            state.ad_status = 7 if autonomous else state.ad_status
        else:
            state.warning_code, state.mode = code, MODE_WARNING
            state.ad_status = 6 if autonomous else state.ad_status
        state.speed_kmh = 0.0

    def pass_landmark(self, landmark_id: int, now_s: float, output: str | None = None) -> None:
        """The vehicle detects a landmark; a serial-output landmark sends `ad_output? <output>`."""
        self._run_until(now_s)
        if landmark_id not in LANDMARKS:
            raise ValueError(f"landmark {landmark_id} is not in Appendix F")
        self.state.landmark_id, self.state.landmark_dist_m = landmark_id, 0.0
        if output is not None and self._on and self._banner_s is None:
            self._emit(now_s, Reply("ad_output", VALUE, (output,)))

    # -- time --------------------------------------------------------------------------------
    def _event_times(self) -> tuple[float | None, float | None, float | None]:
        pending = self._pending[0] if self._pending else None
        status = self._next_status_s if self._on and self._banner_s is None else None
        return self._banner_s, pending, status

    def _run_until(self, now_s: float) -> None:
        if now_s < self._clock_s:
            raise ValueError(f"now_s ({now_s}) must not be earlier than the device's last time "
                             f"({self._clock_s})")
        self._clock_s = now_s
        while True:
            banner_s, pending_s, status_s = self._event_times()
            due = [(t, i) for i, t in enumerate((banner_s, pending_s, status_s))
                   if t is not None and t <= now_s]
            if not due:
                return
            t, which = min(due)
            if which == 0:
                self._banner_s = None
                self._emit(t, Reply(BANNER_NAME, BANNER, (self.model, self.version)))
            elif which == 1:
                self._reply(t)
            else:
                self._next_status_s = t + self.state.comm_period_s
                self._emit(t, Reply("status", VALUE, self._status_values()))

    def _reply(self, t: float) -> None:
        assert self._pending is not None
        frame, self._pending = self._pending[1], None
        self._busy_until_s = t + self.quiet_after_reply_s
        self._emit(t, self._answer(frame, t))
        self._after_reply(t)

    def _current_codec(self) -> CarriroCodec:
        """The codec for the status_cmd list in force (the owner may also set it in `state`)."""
        if self._codec.status_cmds != self.state.status_cmds:
            self._codec = CarriroCodec(self.state.status_cmds)
        return self._codec

    def _emit(self, t: float, reply: Reply) -> None:
        self._outbox.append((t, self._current_codec().encode_reply(reply)))

    def _restart(self, now_s: float) -> None:
        """Power-on state: settings back to defaults, counters from zero (reboot:, comm:,
        ad_pattern:, status_cmd: 注記; dist?: "起動後"); the physical options are kept."""
        old = self.state
        self.state = replace(CarriroState(), battery_pct=old.battery_pct,
                             pallet_option=old.pallet_option, pallet_attached=old.pallet_attached,
                             trolley_option=old.trolley_option,
                             trolley_attached=old.trolley_attached)
        self._on, self._banner_s, self._next_status_s = True, now_s + self.startup_s, None
        self._line.clear()

    def _after_reply(self, t: float) -> None:
        """reboot: and shutdown: take effect once their `OK` is sent."""
        power, self._power_after = self._power_after, None
        if power == "reboot":
            self._restart(t)
        elif power == "shutdown":
            self._on, self._banner_s, self._next_status_s = False, None, None

    # -- answering ---------------------------------------------------------------------------
    def _answer(self, frame: bytes, t: float) -> Reply:
        try:
            command = self._current_codec().parse_command(frame)
            if command.name == "speed_limit" and not self.speed_limit_alias:
                raise CarriroError(ERROR_UNKNOWN_COMMAND, command.name, frame,
                                   "ad_speed_limit (the speed_limit alias is switched off)")
            if command.kind == "get":
                return Reply(command.name, VALUE, self._values(command.name, bool(command.args)))
            return self._handlers[command.name](command, t)
        except CarriroError as exc:
            return Reply(self._error_name(exc.command, exc.code), ERROR, (exc.code,))

    @staticmethod
    def _error_name(name: str, code: int) -> str:
        printable = name.encode("unicode_escape").decode("ascii").replace(" ", "")
        return printable[: MAX_LINE_CHARS - len(f": error {code}")]

    def _values(self, name: str, with_params: bool = False) -> tuple[Value, ...]:
        s = self.state
        speed = round(s.speed_kmh, 1)
        values: dict[str, Callable[[], tuple[Value, ...]]] = {
            "ad_action": lambda: self._action_values(with_params),
            "ad_landmark": lambda: (s.landmark_id, _floor_to(s.landmark_dist_m, 100)),
            "ad_pattern": lambda: (s.ad_pattern,),
            "ad_speed_limit": lambda: (s.speed_limit_kmh,),
            "speed_limit": lambda: (s.speed_limit_kmh,),
            "ad_status": lambda: (s.ad_status,),
            "battery": lambda: (s.battery_pct,),
            "comm": lambda: (s.comm_period_s,),
            "dist": lambda: (_floor_to(s.dist_m, 100),),
            "error": lambda: (s.error_code,),
            "id": lambda: (self.unit_id,),
            "mode": lambda: (s.mode,),
            "pallet": lambda: (s.pallet_option, s.pallet_attached),
            "speed": lambda: (0.0 if speed < 0.5 else speed,),  # speed? 範囲 0, 5-30
            "status": self._status_values,
            "status_cmd": lambda: s.status_cmds,
            "trolley": lambda: (s.trolley_option, s.trolley_attached),
            "version": lambda: (self.version,),
            "warning": lambda: (s.warning_code,),
        }
        return values[name]()

    def _action_values(self, with_params: bool) -> tuple[Value, ...]:
        s = self.state
        if not with_params or not AD_ACTIONS[s.ad_action].params:
            return (s.ad_action,)
        return (s.ad_action, *(s.ad_action_params or default_params(s.ad_action)))

    def _status_values(self) -> tuple[Value, ...]:
        return tuple(v for cmd in self.state.status_cmds for v in self._values(cmd[:-1]))

    # -- set commands ------------------------------------------------------------------------
    @staticmethod
    def _refuse(command: Command, why: str) -> CarriroError:
        return CarriroError(ERROR_INVALID_STATE, command.name, repr(command), why)

    def _action(self, command: Command, t: float) -> Reply:
        action_id = int(command.args[0])
        if action_id not in self.action_ids:
            raise CarriroError(ERROR_INVALID_DATA, command.name, repr(command),
                               f"an action of Appendix A: {sorted(self.action_ids)}")
        if action_id == 1:  # 緊急停止
            self.state.speed_kmh = 0.0
            if self.state.mode == MODE_AUTONOMOUS:
                self._run_action(0)
        return Reply(command.name, DONE, command.args)

    def _ad_action(self, command: Command, t: float) -> Reply:
        if self.state.mode != MODE_AUTONOMOUS:
            raise self._refuse(command, "autonomous mode (11) for ad_action:")
        self._run_action(int(command.args[0]))
        return Reply(command.name, DONE, command.args)

    def _run_action(self, action_id: int) -> None:
        """Appendix C: 0 緊急停止, 9 一時停止, 14 一時停止からの再開, 16 後退."""
        s = self.state
        if action_id in (0, 9):
            s.resume_kmh = s.speed_kmh or s.resume_kmh
            s.speed_kmh, s.ad_status = 0.0, 4
        elif action_id == 14:
            s.speed_kmh = min(s.resume_kmh or STRAIGHT_3_KMH, s.speed_limit_kmh)
            s.ad_status = 2
        elif action_id == 16:
            s.ad_status = 3
        s.ad_action, s.ad_action_params = action_id, default_params(action_id)

    def _set_pattern(self, command: Command, t: float) -> Reply:
        self.state.ad_pattern = int(command.args[0])
        return Reply(command.name, DONE, command.args)

    def _set_speed_limit(self, command: Command, t: float) -> Reply:
        limit = float(command.args[0])
        self.state.speed_limit_kmh = limit
        self.state.speed_kmh = min(self.state.speed_kmh, limit)  # 注記: 0 stops the vehicle
        return Reply(command.name, DONE, command.args)

    def _set_comm(self, command: Command, t: float) -> Reply:
        period = float(command.args[0])
        self.state.comm_period_s = period
        self._next_status_s = t + period if period > 0 else None
        return Reply(command.name, DONE, command.args)

    def _echo(self, command: Command, t: float) -> Reply:
        return Reply(command.name, DONE, command.args)

    def _set_mode(self, command: Command, t: float) -> Reply:
        s, target = self.state, int(command.args[0])
        if target not in MODE_TARGETS[s.mode]:
            raise self._refuse(command, f"a mode reachable from mode {s.mode}: "
                               f"{sorted(MODE_TARGETS[s.mode])}")
        if target == MODE_AUTONOMOUS:
            if s.mode != MODE_AUTONOMOUS:
                s.speed_kmh = min(STRAIGHT_3_KMH, s.speed_limit_kmh)
                s.ad_status, s.ad_action, s.ad_action_params = 2, 4, default_params(4)
        else:
            s.speed_kmh, s.ad_status = 0.0, 1
        if target == MODE_PARKING:
            s.warning_code = NO_CODE  # warning? 注記: parking clears the warning
        s.mode = target
        return Reply(command.name, DONE, command.args)

    def _power(self, command: Command, t: float) -> Reply:
        if self.state.mode not in POWER_COMMAND_MODES:
            raise self._refuse(command, f"parking (5) or error (4) mode for {command.name}:")
        self._power_after = command.name
        return Reply(command.name, DONE, ("OK",))

    def _set_status_cmd(self, command: Command, t: float) -> Reply:
        self.state.status_cmds = tuple(str(a) for a in command.args)
        return Reply(command.name, DONE, command.args)
