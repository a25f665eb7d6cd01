"""A virtual vehicle on a real pseudo-terminal, answering in real time with its link's timing.

`serve` opens a pty, prints the slave's path as the first line of stdout and then plays the
vehicle end of the wire: what the host writes reaches the virtual device one character at a
time, each when its last bit would have arrived at the profile's baud rate and framing (plus
the radio latency); the device runs in simulated time, which here is the wall clock since
start; its replies go back character by character, none earlier than the link model says
(`agv_model.link`: bits per character, processing in the device, jitter, latency). An external
controller opens the path with pyserial and talks to it as to the real vehicle.

The pty carries bytes, not bits: the emulator never garbles a character the way a wrong baud
rate would. It warns once on stderr when the host's baud rate or stop bits differ from the
profile's. Parity and data bits cannot be checked: Linux ptys force 8 data bits and no parity
whatever the host asks for (pyserial's 8E1 is accepted and reads back as 8N1).
It runs until Ctrl-C or SIGTERM and then returns 0.
"""

from __future__ import annotations

import os
import select
import signal
import sys
import termios
import time
import tty
from collections import deque
from collections.abc import Callable
from types import FrameType
from typing import Final, TextIO

import numpy as np

from agv_model.link import LinkSettings, device_settings
from agv_model.profile import Profile, load_profile, profile_for, profile_names
from agv_model.protocols import Device, get_device, names
from userfiles.checking import InputError

IDLE_WAKE_S: Final = 0.05  # longest sleep, so that a stop request is seen promptly
_BAUDS: Final = {getattr(termios, f"B{b}"): b for b in (
    1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600,
    1000000) if hasattr(termios, f"B{b}")}


class EmulateError(ValueError):
    """The emulator cannot start: unknown protocol or profile, or no pseudo-terminal."""


def choose_profile(protocol: str, profile_name: str | None = None) -> Profile:
    """The named profile, or the bundled one for `protocol`; it must speak `protocol`."""
    if protocol not in names():
        raise EmulateError(f"unknown protocol {protocol!r}; expected one of "
                           f"{', '.join(names())}")
    try:
        profile = profile_for(protocol) if profile_name is None else load_profile(profile_name)
    except InputError as exc:
        raise EmulateError(str(exc)) from None
    if profile.protocol != protocol:
        speakers = [n for n in profile_names() if load_profile(n).protocol == protocol]
        raise EmulateError(f"profile {profile.name!r} speaks {profile.protocol!r}, not "
                           f"{protocol!r}; expected one of {', '.join(speakers)}")
    return profile


def describe(settings: LinkSettings) -> str:
    """`19200 8E1, 11 bits per character` style."""
    stop = f"{settings.stop_bits:g}"
    return (f"{settings.baud} {settings.data_bits}{settings.parity[0].upper()}{stop}, "
            f"{settings.bits_per_char:g} bits per character")


class _Wire:
    """One direction of the line: characters queued with the time their last bit arrives."""

    def __init__(self, settings: LinkSettings) -> None:
        self.char_s = settings.char_s
        self.latency_s = settings.latency_s
        self.free_s = 0.0  # when the line is free for the next character
        self.queue: deque[tuple[float, int]] = deque()

    def send(self, data: bytes, from_s: float) -> None:
        start_s = max(from_s, self.free_s)
        for i, byte in enumerate(data):
            self.queue.append((start_s + (i + 1) * self.char_s + self.latency_s, byte))
        self.free_s = start_s + len(data) * self.char_s

    def due(self, now_s: float) -> list[tuple[float, int]]:
        out: list[tuple[float, int]] = []
        while self.queue and self.queue[0][0] <= now_s:
            out.append(self.queue.popleft())
        return out

    def next_s(self) -> float | None:
        return self.queue[0][0] if self.queue else None


def _host_settings(fd: int) -> tuple[int | None, int]:
    """(baud, stop bits) the host set on the slave side; None for a baud not in `_BAUDS`."""
    attrs = termios.tcgetattr(fd)
    return _BAUDS.get(attrs[5]), 2 if attrs[2] & termios.CSTOPB else 1


class Emulator:
    """The device and both directions of the wire; `step` does everything due by `now_s`."""

    def __init__(self, profile: Profile, device: Device, master_fd: int,
                 rng: np.random.Generator) -> None:
        self.link = profile.link
        self.device = device
        self.master_fd = master_fd
        self.rng = rng
        self.to_device = _Wire(self.link)
        self.to_host = _Wire(self.link)
        self.dropped_bytes = 0

    def heard(self, data: bytes, now_s: float) -> None:
        """The host wrote `data`; it started down the line at `now_s`."""
        self.to_device.send(data, now_s)

    def step(self, now_s: float) -> None:
        for time_s, byte in self.to_device.due(now_s):
            self.device.receive(bytes([byte]), time_s)
        for time_s, data in self.device.poll(now_s):
            self.to_host.send(data, time_s + self.link.jitter.draw_s(self.rng))
        out = bytes(byte for _, byte in self.to_host.due(now_s))
        if out:
            try:
                written = os.write(self.master_fd, out)
            except BlockingIOError:
                written = 0
            self.dropped_bytes += len(out) - written  # nobody reading: lost, as on a wire

    def next_s(self, now_s: float) -> float:
        times = [t for t in (self.to_device.next_s(), self.to_host.next_s(),
                             self.device.next_output_s()) if t is not None]
        return min([now_s + IDLE_WAKE_S, *times])


def serve(profile: Profile, *, seed: int | None = None, out: TextIO | None = None,
          stop: Callable[[], bool] | None = None) -> int:
    """Serve `profile`'s virtual device on a new pty until interrupted; return 0."""
    out = out if out is not None else sys.stdout
    protocol = profile.protocol
    if protocol is None:
        raise EmulateError(f"profile {profile.name!r} has no protocol to emulate")
    try:
        master_fd, slave_fd = os.openpty()
    except OSError as exc:
        raise EmulateError(f"cannot open a pseudo-terminal: {exc.strerror}") from None
    stopping = False

    def on_term(signum: int, frame: FrameType | None) -> None:
        nonlocal stopping
        stopping = True

    old_term = signal.signal(signal.SIGTERM, on_term)
    # Ctrl-C stops it even when started by a process that ignores SIGINT (a child inherits an
    # ignored SIGINT, and Python then installs no KeyboardInterrupt handler of its own).
    old_int = signal.signal(signal.SIGINT, on_term)
    try:
        tty.setraw(slave_fd)  # no echo, no line editing until the host sets its own modes
        os.set_blocking(master_fd, False)
        path = os.ttyname(slave_fd)
        out.write(path + "\n")
        out.flush()
        print(f"fleet-sim emulate: {profile.title} ({protocol}, profile {profile.name}) on "
              f"{path}: {describe(profile.link)}; Ctrl-C to stop", file=sys.stderr, flush=True)
        device = get_device(protocol, **device_settings(protocol, profile.link))
        emulator = Emulator(profile, device, master_fd, np.random.default_rng(seed))
        _run(emulator, slave_fd, lambda: stopping or (stop is not None and stop()))
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGTERM, old_term)
        signal.signal(signal.SIGINT, old_int)
        os.close(master_fd)
        os.close(slave_fd)
    return 0


def _run(emulator: Emulator, slave_fd: int, stopped: Callable[[], bool]) -> None:
    start = time.monotonic()
    expected = emulator.link
    want = (expected.baud, 2 if expected.stop_bits == 2 else 1)
    warned: set[tuple[int | None, int]] = set()
    while not stopped():
        now_s = time.monotonic() - start
        emulator.step(now_s)
        wait_s = max(0.0, emulator.next_s(now_s) - (time.monotonic() - start))
        ready, _, _ = select.select([emulator.master_fd], [], [], wait_s)
        if ready:
            try:
                data = os.read(emulator.master_fd, 4096)
            except BlockingIOError:
                continue
            emulator.heard(data, time.monotonic() - start)
            host = _host_settings(slave_fd)
            if host != want and host not in warned:
                warned.add(host)
                print(f"fleet-sim emulate: warning: the host's port is {host[0]} baud, "
                      f"{host[1]} stop bits; the vehicle expects {describe(expected)}",
                      file=sys.stderr, flush=True)
