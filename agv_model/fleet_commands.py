"""What each fleet-manager command costs on a vehicle's real link, for the fleet simulator.

The fleet manager (FMS) sends an AGV four kinds of command (`KINDS`): "assign" (a transport task:
start driving to a destination), "stop", "resume" and "status" (a status poll). `MESSAGES` says
which protocol messages realise each kind; `CommandTiming` times them once, from their real
encoded bytes and the virtual device's real replies through `agv_model.link.Link`, with the
profile's link settings and the jitter left out, and then draws each command's cost with jitter.

Messages per protocol (the choice and its source; values that only change a digit or two are
named, each character costs `LinkSettings.char_s`):

CarriRo AD+ (CarriRo AD+ External Serial Interface API Reference, version 1.4)
- assign: `ad_pattern: 1` then `mode: 11`. The vehicle follows landmarks along a route taught as
  a landmark pattern (ad_pattern: "アクティブなランドマークパターン", IDs 1-90, pattern 1 here);
  mode 11 自律 (Appendix G, Get / Set) starts autonomous driving from parking or any other
  settable mode. Two exchanges, times summed. A vehicle paused in autonomous mode could instead
  be sent `ad_action: 14` (5 more characters).
- stop: `ad_action: 9`, 一時停止 (Appendix C, settable; ad_action: example "一時停止"), the pause
  that ad_action 14 resumes. Not `action: 1` / `ad_action: 0` (緊急停止, emergency stop).
- resume: `ad_action: 14`, 一時停止からの再開 (Appendix C).
- status: `status?` with the default status_cmd list (status?: mode, speed, dist, battery,
  ad_status, ad_pattern, ad_action, ad_landmark). The reply is timed while driving after assign;
  its length follows the values (the document's example reply is 4 characters, 2.3 ms, longer).
KTM-02 (KTM-02 command list, コントローラからKTM-02へ送信するコマンド)
- assign: GoStraightAlongLineCmd (0x06) at speed 255 (全速力); the robot follows the line.
- stop: StopCmd (0x16), not EmergencyStopCmd (0x09). The device's reply holds its ACK and the
  MovingFinishCmd sent at the same instant (KTM-02 decision 9,
  docs/background/decisions/protocols.md).
- resume: GoStraightAlongLineCmd at 255 again: the document has no resume command.
- status: RequestStatusCmd (0x0d); the reply is ACK + SendStatusCmd (ロボットの状態).
TABO (TABO robot command sheet)
- assign: `MLL:205,1000` then `MLL:410,1000` (距離指定直進, MLL row). The メモ says a target 300
  mm/s or more from the current speed is not followed and to step 0 -> 205 -> 410 for full speed
  (the profile's 410 mm/s), so two exchanges, times summed. 1000 mm is the sheet's example
  distance; each further digit is one character.
- stop: `X` (全停止, X row: stops every running command; ACK:x). BHL only stops MLL/MTL/LAL and
  answers NAK:b when nothing runs.
- resume: the two MLL steps of assign again (the robot stands after X).
- status: `GBI` (バッテリー残量取得, gbi:NNN): the sheet has no motion-state getter; GBI is the
  cheapest "are you there and how is your battery" poll. Motion ends are pushed as FIN:m.
AGV-3 ("Grupp 3 AGV protokoll", revision 1.1, Kommandon)
- assign: `NAV:PICKU 1 1;DROPO 2 1;STA`, one line: PICKUp and DROPOff set the order (station,
  count), STArt starts the AGV ("Startar AGV:n och börjar att köra framåt"). Chaining with ';'
  keeps the level (Syntax), so one exchange answers three lines. Short forms (the required
  upper-case letters, Syntax) throughout: PICKUp's short form is PICKU.
- stop: `NAV:STO` (STOp, "Stoppar AGV:n"), not SYS:ES (EStop latches, nothing releases it).
- resume: `NAV:STA` (STArt).
- status: `NAV:STAT?` (STATus get: "<tillstånd> <info>").
Generic RSS-AGV-001 (protocol null)
- The spec names the messages (4.2.2 搬送指示 with a route, 4.2.3 status to the FMS) but not their
  bytes (that is RSS-AGV-002). The fallback times one message and one reply of an assumed size
  (`GENERIC_MESSAGE_BYTES`) on the profile's Wi-Fi link model, with no device: bytes sent and
  received back to back, 2 x latency, processing, host gap, exactly as `Link` adds them. At the
  profile's effective 1 Mbit/s the sizes weigh 0.6-2.6 ms against 20 ms of latency and
  processing, so the guess matters little.

Timing rules:
- The messages run in `TIMING_ORDER` on one `Link`, so each meets the vehicle in the state it is
  normally sent in (stop while driving, resume after stop); `status` is timed while driving.
- Base time of a kind (`round_trip_s`): for each exchange, first byte sent to the reply fully
  received (`Exchange.reply_s`) plus the host gap (`Exchange.gap_s`, CarriRo's 10 ms 処理), summed
  over the kind's exchanges: the time the link is busy before the FMS may send again.
- `seconds(kind, rng)` adds one draw of the profile's jitter per exchange.
- Reply timeout (`LinkSettings.reply_timeout_s`; AGV-3 0.25 s from its Syntax, the others assumed
  in their profiles) as `agv_model.link` reads it: from the command's last byte sent to the reply's
  first byte received. An exchange whose jitter draw exceeds its `timeout_margin_s` times out:
  the host gives up after the timeout, waits the host gap, and the whole kind is reported as
  `Attempt(timed_out=True)` with the time spent, so the caller counts a retry and sends it again
  (resending set-parameter messages such as ad_pattern or PICKUp is harmless). While the base
  times are computed, the host waits for a late reply before its next message, so no message
  takes another's stale reply as its answer (`Link` keeps late replies on the wire).
- Polling: `mean_notice_delay_s(P)` = P / 2 + the status reply time; see there.

How each vehicle is given its route (`GRANTS_PER_HOP`; the fleet simulator's
`traffic.grants: auto`), a reading of each document:
- CarriRo AD+ (API Reference v1.4): the whole route. The vehicle drives a taught landmark
  pattern (ad_pattern) on its own once mode 11 (自律) is set (Appendix G); the host only pauses
  (ad_action 9) and resumes (ad_action 14) it (Appendix C). Permission node by node would need
  a pause landmark (fixed landmark 8, 一時停止; Appendix F) at every node and an
  `ad_action: 14` to let it on.
- KTM-02 (command list, コントローラからKTM-02へ送信するコマンド): hop by hop. It has motions
  only (GoStraightAlongLineCmd, RotateRight/LeftAlongLineCmd, each ending with MovingFinishCmd,
  移動終了) and no route or destination: the controller commands each stretch of line.
- TABO (command sheet, MLL and MTL rows): hop by hop. Distance-specified straights and turns,
  each ending with FIN:m; no route command.
- AGV-3 ("Grupp 3 AGV protokoll", Kommandon, NAVigation): the whole route. PICKUp and DROPOff
  name the stations and STArt drives the line until them.
- Generic RSS-AGV-001 (4.2.2): the whole route: the transport order carries it and the AGV
  loads the route plan (経路計画をロードし).
A permission to drive one hop is the protocol's `resume` message (the one that sets a standing
vehicle going again): CarriRo `ad_action: 14`, KTM-02 GoStraightAlongLineCmd (a turn along the
line is a frame of the same length), TABO the two MLL steps, AGV-3 `NAV:STA`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Final, Literal

import numpy as np

from agv_model.link import Exchange, Jitter, Link, LinkSettings
from agv_model.profile import load_profile
from agv_model.protocols import Command

Kind = Literal["assign", "stop", "resume", "status"]
Message = Command | bytes

KINDS: Final[tuple[Kind, ...]] = ("assign", "stop", "resume", "status")
PERMISSION: Final[Kind] = "resume"
"""The message that lets a vehicle granted its route hop by hop drive its next hop."""
GRANTS_PER_HOP: Final[frozenset[str]] = frozenset({"ktm02", "tabo"})
"""Protocols whose vehicle has no route command: the host grants its route hop by hop."""
# The order the kinds are timed in on one link: each meets the vehicle in its usual state.
TIMING_ORDER: Final[tuple[Kind, ...]] = ("assign", "status", "stop", "resume")

_MLL_STEPS: Final = (Command("MLL", (205, 1000)), Command("MLL", (410, 1000)))
_KTM_GO: Final = (Command("GoStraightAlongLineCmd", (255,)),)

MESSAGES: Final[Mapping[str, Mapping[Kind, tuple[Message, ...]]]] = {
    "carriro": {
        "assign": (Command("ad_pattern", (1,), "set"), Command("mode", (11,), "set")),
        "stop": (Command("ad_action", (9,), "set"),),
        "resume": (Command("ad_action", (14,), "set"),),
        "status": (Command("status", (), "get"),),
    },
    "ktm02": {
        "assign": _KTM_GO,
        "stop": (Command("StopCmd"),),
        "resume": _KTM_GO,
        "status": (Command("RequestStatusCmd", (), "get"),),
    },
    "tabo": {
        "assign": _MLL_STEPS,
        "stop": (Command("X"),),
        "resume": _MLL_STEPS,
        "status": (Command("GBI", (), "get"),),
    },
    "agv3": {
        "assign": (b"NAV:PICKU 1 1;DROPO 2 1;STA\r\n",),
        "stop": (Command("NAV:STO"),),
        "resume": (Command("NAV:STA"),),
        "status": (Command("NAV:STAT", (), "get"),),
    },
}

# Generic RSS-AGV-001 (protocol null): assumed (request, reply) sizes in bytes per kind, small
# JSON-like messages: an order carries a route (4.2.2), a status reply state, position, SOC and
# error codes; stop, resume and acknowledgements are short.
GENERIC_MESSAGE_BYTES: Final[Mapping[Kind, tuple[int, int]]] = {
    "assign": (256, 64), "stop": (64, 64), "resume": (64, 64), "status": (64, 256),
}


def timeout_margin_s(exchange: Exchange, settings: LinkSettings) -> float:
    """How much jitter this exchange's reply can take before the host's reply timeout: the
    timeout minus (2 x latency + processing + one character). Negative (or -inf when no reply
    came) when it times out even without jitter."""
    if exchange.timed_out:
        return -math.inf
    return exchange.reply_timeout_s - (2 * exchange.latency_s + exchange.processing_s
                                       + settings.char_s)


@dataclass(frozen=True)
class Attempt:
    """One try at a fleet command. `seconds`: the time the link is busy with it (replies, host
    gaps and jitter), or, when `timed_out`, until the host gave up on the exchange that timed out
    and waited its host gap; the caller then counts a retry and may try again."""

    seconds: float
    timed_out: bool


class CommandTiming:
    """The base times of the fleet commands of one vehicle on one link, computed once.

    `CommandTiming.for_profile("carriro-ad-plus")` for a bundled vehicle;
    `CommandTiming(protocol, settings)` for modified link settings (another baud rate).
    `exchanges[kind]` holds each exchange's `Exchange` breakdown, jitter excluded; for the
    generic profile (protocol None) its bytes are zero-filled placeholders of the assumed size.
    """

    def __init__(self, protocol: str | None, settings: LinkSettings) -> None:
        self.protocol = protocol
        self.settings = settings
        base = settings.model_copy(update={"jitter": Jitter()})
        self.exchanges: dict[Kind, tuple[Exchange, ...]]
        if protocol is None:
            self.exchanges = {kind: (_generic_exchange(base, *GENERIC_MESSAGE_BYTES[kind]),)
                              for kind in KINDS}
        else:
            timed = _time_messages(protocol, base)
            self.exchanges = {kind: timed[kind] for kind in KINDS}
        self._margins_s = {kind: tuple(timeout_margin_s(e, base) for e in exchanges)
                           for kind, exchanges in self.exchanges.items()}

    @classmethod
    def for_profile(cls, name: str) -> CommandTiming:
        """The timing of a bundled profile (`agv_model/profiles/<name>.yaml`)."""
        profile = load_profile(name)
        return cls(profile.protocol, profile.link)

    def round_trip_s(self, kind: Kind) -> float:
        """Base time, jitter excluded: first byte sent to the last reply fully received, plus
        the host gap after each reply, summed over the kind's exchanges."""
        return sum(e.reply_s + e.gap_s for e in self.exchanges[kind])

    def reply_s(self, kind: Kind) -> float:
        """Like `round_trip_s` without the host gap after the last reply: when the FMS has the
        answer (the gap only delays its next command)."""
        return self.round_trip_s(kind) - self.exchanges[kind][-1].gap_s

    def timed_out(self, kind: Kind) -> bool:
        """True when an exchange of the kind misses the reply timeout even without jitter: every
        attempt will time out."""
        return any(margin_s < 0 for margin_s in self._margins_s[kind])

    def attempt(self, kind: Kind, rng: np.random.Generator) -> Attempt:
        """One try with one jitter draw per exchange; stops at the first exchange that times
        out (its cost: the command's bytes, the reply timeout and the host gap)."""
        seconds = 0.0
        for exchange, margin_s in zip(self.exchanges[kind], self._margins_s[kind], strict=True):
            jitter_s = self.settings.jitter.draw_s(rng)
            if jitter_s > margin_s:
                return Attempt(seconds + exchange.tx_s + exchange.reply_timeout_s
                               + exchange.gap_s, True)
            seconds += exchange.reply_s + exchange.gap_s + jitter_s
        return Attempt(seconds, False)

    def seconds(self, kind: Kind, rng: np.random.Generator) -> float:
        """`round_trip_s(kind)` plus jitter drawn from `rng` (`attempt(kind, rng).seconds`;
        use `attempt` to see a timeout)."""
        return self.attempt(kind, rng).seconds

    def mean_notice_delay_s(self, poll_period_s: float) -> float:
        """Mean time from an event on the vehicle (finished, ready for a new order) until the FMS
        learns it from a status poll every `poll_period_s`: P / 2 + the status reply time.

        The event falls at a uniformly random point between two polls, so the next poll comes
        P / 2 later on average, and its answer arrives `reply_s("status")` after it is sent (the
        host gap follows the answer, so it is not counted). The vehicle reads its state when the
        poll arrives, so this is an upper bound by the request's transfer (CarriRo `status?`:
        4.6 ms). The host cannot poll faster than one status round trip: a shorter P counts as
        `round_trip_s("status")`. Jitter adds its mean on top (not included).
        """
        if not (math.isfinite(poll_period_s) and poll_period_s > 0):
            raise ValueError(f"poll_period_s must be a time in seconds > 0, got {poll_period_s}")
        period_s = max(poll_period_s, self.round_trip_s("status"))
        return period_s / 2 + self.reply_s("status")


def _time_messages(protocol: str, settings: LinkSettings) -> dict[Kind, tuple[Exchange, ...]]:
    """Every kind's messages in `TIMING_ORDER` on one link. After a timeout the host waits for
    the late reply before it sends again, so that no later message takes it as its answer."""
    link = Link(protocol, settings)
    timed: dict[Kind, tuple[Exchange, ...]] = {}
    at_s: float | None = None
    for kind in TIMING_ORDER:
        exchanges = []
        for message in MESSAGES[protocol][kind]:
            exchange = link.exchange(message, at_s)
            at_s = link.device.next_output_s() if exchange.timed_out else None
            exchanges.append(exchange)
        timed[kind] = tuple(exchanges)
    return timed


def _generic_exchange(settings: LinkSettings, tx_bytes: int, rx_bytes: int) -> Exchange:
    """One message and its reply on a link without a device, timed as `Link` times them."""
    processing_s = settings.processing_s if settings.processing_s is not None else 0.0
    late = 2 * settings.latency_s + processing_s + settings.char_s > settings.reply_timeout_s
    return Exchange(bytes(tx_bytes), bytes(rx_bytes), 0.0, settings.transfer_s(tx_bytes),
                    settings.latency_s, processing_s, 0.0, settings.transfer_s(rx_bytes),
                    settings.host_gap_s, settings.reply_timeout_s, late)
