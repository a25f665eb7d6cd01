"""Serial and radio link timing: how long one command and its reply take on the real wire.

A `LinkSettings` says what the wire is (baud, data bits, parity, stop bits -> bits per
character), how long the vehicle takes to answer (`processing_s`), how long the host waits after
a reply before it sends again (`host_gap_s`), how long the host waits for an answer
(`reply_timeout_s`), the one-way delay of a radio hop (`latency_s`) and a random `Jitter` on
each answer. A `Link` puts a protocol's codec and virtual device behind those settings: for any
`Command` it encodes the real bytes, feeds them to the device one character at a time in
simulated time, takes the device's real reply bytes and returns an `Exchange`, the breakdown of
the time from the first byte sent to the reply fully received.

Readings (documented here; the profiles in `agv_model/profiles/` carry the figures):

- A character is one start bit, the data bits, one parity bit unless parity is "none", and the
  stop bits: CarriRo's 8E1 is 11 bits (インターフェイス仕様), so 11 / 19200 s a character.
- The host sends the command's characters back to back; the device receives each one when its
  last stop bit has arrived (plus `latency_s` on a radio link); the reply's characters follow
  back to back from the moment the device sends it, delayed by the drawn jitter and `latency_s`.
- The reply is everything the device sends at the first instant at or after the command's last
  character arrived: CarriRo's line, KTM-02's ACK together with the data frame a request asks
  for, every line of an AGV-3 chain. Later messages (TABO's FIN:m, a KTM-02 MovingFinishCmd at
  the end of a motion) are not part of the reply; output before the command arrived (a periodic
  CarriRo `status?`) is unsolicited and kept in `Link.unsolicited`.
- The reply timeout is read as AGV-3 writes it ("Om inget returneras inom 0.25s"): the time
  from the command's last character leaving the host to the reply's first character being
  received. A reply later than that, or none at all, is a timeout; the host gives up after
  `reply_timeout_s`, waits `host_gap_s` and may send again. Where a document gives no timeout
  the profile's figure is an assumption and says so. A reply that comes after the host gave up
  stays on the wire, as on a real line: the next exchange takes it as its answer if it arrives
  after that command, which is the stale-reply hazard a real host has to handle.
- `host_gap_s` follows each reply (CarriRo 処理: 10 ms after the reply is received); it is not
  part of the reply time but delays the next command (`Exchange.ready_s`).
- Settings are a pydantic model (`userfiles.checking`): a bad setting, in a profile file or in
  code, is an InputError naming the setting, the value and what was expected.
- `processing_s` is handed to the virtual device, which is where the time is spent (CarriRo's
  `processing_s`, the others' `reply_delay_s`); None keeps the device's own default.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Final, Literal

import numpy as np
from pydantic import Field, field_validator, model_validator

from agv_model.protocols import Command, Device, get_codec, get_device, names
from userfiles.checking import NonNegative, Problem, StrictModel

Parity = Literal["none", "even", "odd", "mark", "space"]
JitterDistribution = Literal["none", "uniform", "normal", "exponential"]

# The device setting that holds each protocol's answer time (see the protocol modules).
PROCESSING_SETTING: Final[Mapping[str, str]] = {
    "carriro": "processing_s", "ktm02": "reply_delay_s", "tabo": "reply_delay_s",
    "agv3": "reply_delay_s",
}
STOP_BITS: Final = (1, 1.5, 2)
SETTLE_LIMIT_S: Final = 60.0  # how long a new device may take to send its start-up output


class Jitter(StrictModel):
    """Random extra delay on each reply, drawn from a seeded `numpy.random.Generator`.

    uniform: between `low_s` and `high_s`; normal: `mean_s`, `sd_s`, cut at 0;
    exponential: mean `mean_s`; none: always 0 and no draw.
    """

    distribution: JitterDistribution = "none"
    low_s: NonNegative = 0.0
    high_s: NonNegative = 0.0
    mean_s: NonNegative = 0.0
    sd_s: NonNegative = 0.0

    @model_validator(mode="after")
    def _ordered(self) -> Jitter:
        if self.high_s < self.low_s:
            raise Problem("high_s", self.high_s, f"at least low_s ({self.low_s!r})")
        return self

    def draw_s(self, rng: np.random.Generator) -> float:
        if self.distribution == "uniform":
            return float(rng.uniform(self.low_s, self.high_s))
        if self.distribution == "normal":
            return max(0.0, float(rng.normal(self.mean_s, self.sd_s)))
        if self.distribution == "exponential":
            return float(rng.exponential(self.mean_s)) if self.mean_s > 0 else 0.0
        return 0.0


class LinkSettings(StrictModel):
    """One wire between host and vehicle. Every time is in seconds."""

    baud: int = Field(gt=0)
    """Bits per second."""
    data_bits: Literal[5, 6, 7, 8] = 8
    parity: Parity = "none"
    stop_bits: float = Field(default=1, json_schema_extra={"enum": list(STOP_BITS)})
    processing_s: NonNegative | None = None
    """The vehicle's answer time; none: the virtual device's own default."""
    host_gap_s: NonNegative = 0.0
    """How long the host waits after a reply before it sends again."""
    reply_timeout_s: NonNegative = 1.0
    latency_s: NonNegative = 0.0
    """One-way delay of a radio hop."""
    jitter: Jitter = Jitter()

    @field_validator("stop_bits")
    @classmethod
    def _real_stop_bits(cls, stop_bits: float) -> float:
        if stop_bits not in STOP_BITS:
            raise Problem("", stop_bits, "1, 1.5 or 2")
        return stop_bits

    @property
    def bits_per_char(self) -> float:
        """Start bit + data bits + parity bit + stop bits."""
        return 1 + self.data_bits + (0 if self.parity == "none" else 1) + self.stop_bits

    @property
    def char_s(self) -> float:
        return self.bits_per_char / self.baud

    def transfer_s(self, n_bytes: int) -> float:
        """Time to send `n_bytes` characters back to back."""
        return n_bytes * self.bits_per_char / self.baud


@dataclass(frozen=True)
class Exchange:
    """One command and its reply on the link. Times are simulated seconds.

    `reply_s` runs from the command's first character leaving the host to the reply's last
    character received (or to the host giving up, on a timeout). `processing_s` is the device's
    own time, from the command's last character received to the reply being sent; it is `inf`
    when the device sent nothing before the host gave up. `reply` holds what the device sent,
    even when its first character came too late (`timed_out`).
    """

    command: bytes
    reply: bytes
    sent_s: float
    tx_s: float
    latency_s: float
    processing_s: float
    jitter_s: float
    rx_s: float
    gap_s: float
    reply_timeout_s: float
    timed_out: bool

    @property
    def tx_bytes(self) -> int:
        return len(self.command)

    @property
    def rx_bytes(self) -> int:
        return len(self.reply)

    @property
    def reply_s(self) -> float:
        if self.timed_out:
            return self.tx_s + self.reply_timeout_s
        return self.tx_s + 2 * self.latency_s + self.processing_s + self.jitter_s + self.rx_s

    @property
    def ready_s(self) -> float:
        """When the host may send its next command: after the reply and the host gap."""
        return self.sent_s + self.reply_s + self.gap_s

    def breakdown(self) -> dict[str, float | int | bool]:
        return {"tx_bytes": self.tx_bytes, "tx_s": self.tx_s, "latency_s": self.latency_s,
                "processing_s": self.processing_s, "jitter_s": self.jitter_s,
                "rx_bytes": self.rx_bytes, "rx_s": self.rx_s, "gap_s": self.gap_s,
                "reply_s": self.reply_s, "timed_out": self.timed_out}


def device_settings(protocol: str, settings: LinkSettings) -> dict[str, Any]:
    """The keyword settings that give `protocol`'s virtual device the link's processing time."""
    if protocol not in PROCESSING_SETTING:
        raise KeyError(f"unknown protocol {protocol!r}; expected one of {', '.join(names())}")
    if settings.processing_s is None:
        return {}
    return {PROCESSING_SETTING[protocol]: settings.processing_s}


class Link:
    """A host talking to one virtual vehicle over a timed wire, in simulated time.

    The device keeps its state from one exchange to the next (a mode set stays set). A new
    device's start-up output (CarriRo's banner) is drained first. `rng` draws the jitter; give
    each link its own stream (`SeedSequence.spawn`) for repeatable runs. A `device` passed in
    keeps its own processing time (`settings.processing_s` only configures a new one) and must
    not have been driven past simulated time 0.
    """

    def __init__(self, protocol: str, settings: LinkSettings, *,
                 rng: np.random.Generator | None = None, device: Device | None = None) -> None:
        self.protocol = protocol
        self.settings = settings
        self.codec = get_codec(protocol)
        self.device = device if device is not None else get_device(
            protocol, **device_settings(protocol, settings))
        self.rng = rng if rng is not None else np.random.default_rng()
        self.unsolicited: list[tuple[float, bytes]] = []
        self.ready_s = 0.0
        self._settle()

    def _settle(self) -> None:
        while (due_s := self.device.next_output_s()) is not None and due_s <= SETTLE_LIMIT_S:
            for time_s, data in self.device.poll(due_s):
                self.unsolicited.append((time_s, data))
                end_s = time_s + self.settings.latency_s + self.settings.transfer_s(len(data))
                self.ready_s = max(self.ready_s, end_s + self.settings.host_gap_s)

    def exchange(self, command: Command | bytes, at_s: float | None = None) -> Exchange:
        """Send one command at `at_s` (or as soon as the host may) and time its reply."""
        s = self.settings
        data = command if isinstance(command, bytes) else self.codec.encode(command)
        sent_s = max(self.ready_s, at_s if at_s is not None else self.ready_s)
        self.unsolicited += self.device.poll(sent_s)
        for i in range(len(data)):
            self.device.receive(data[i:i + 1], sent_s + s.latency_s + s.transfer_s(i + 1))
        tx_s = s.transfer_s(len(data))
        arrived_s = sent_s + s.latency_s + tx_s
        give_up_s = sent_s + tx_s + s.reply_timeout_s
        reply_at_s, reply = self._first_output(arrived_s, give_up_s)
        if reply_at_s is None:
            result = Exchange(data, b"", sent_s, tx_s, s.latency_s, math.inf, 0.0, 0.0,
                              s.host_gap_s, s.reply_timeout_s, True)
        else:
            jitter_s = s.jitter.draw_s(self.rng)
            first_char_s = reply_at_s + jitter_s + s.latency_s + s.char_s
            result = Exchange(data, reply, sent_s, tx_s, s.latency_s, reply_at_s - arrived_s,
                              jitter_s, s.transfer_s(len(reply)), s.host_gap_s,
                              s.reply_timeout_s, first_char_s > give_up_s)
        self.ready_s = result.ready_s
        return result

    def _first_output(self, arrived_s: float, give_up_s: float) -> tuple[float | None, bytes]:
        """The device's first output at or after `arrived_s`, if it comes by `give_up_s`."""
        while (due_s := self.device.next_output_s()) is not None and due_s <= give_up_s:
            out = self.device.poll(max(due_s, arrived_s))
            self.unsolicited += [(t, b) for t, b in out if t < arrived_s]
            answer = [(t, b) for t, b in out if t >= arrived_s]
            if answer:
                first_s = answer[0][0]
                self.unsolicited += [(t, b) for t, b in answer if t > first_s]
                return first_s, b"".join(b for t, b in answer if t == first_s)
        return None, b""


def exchange_once(protocol: str, command: Command | bytes, settings: LinkSettings, *,
                  seed: int | None = None) -> Exchange:
    """Time one command against a fresh device (after its start-up output)."""
    return Link(protocol, settings, rng=np.random.default_rng(seed)).exchange(command)
