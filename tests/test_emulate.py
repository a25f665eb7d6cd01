"""`fleet-sim emulate`: a virtual vehicle on a real pseudo-terminal.

The subprocess tests talk to it with pyserial as a controller would; their timeouts only guard
against hangs. The pacing itself is checked in simulated time by stepping an `Emulator` by hand.
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
import tty
from collections.abc import Callable, Iterator
from typing import IO

import numpy as np
import pytest
import serial

from agv_model.emulate import Emulator, _Wire, choose_profile, describe
from agv_model.link import LinkSettings, device_settings
from agv_model.profile import load_profile
from agv_model.protocols import get_device
from fleet_sim.cli import main

from .conftest import ROOT, golden_bytes, golden_hex

GUARD_S = 15.0  # against hangs only
PORT_TIMEOUT_S = 5.0  # set once: changing a setting later makes pyserial re-apply parity,
# which a Linux pty refuses (EINVAL)
BANNER = b"CarriRo AD+ 1.16.0.2\n"  # スタートアップ


def first_line(stream: IO[str]) -> str:
    ready, _, _ = select.select([stream], [], [], GUARD_S)
    assert ready, "the emulator printed no path"
    return stream.readline().strip()


@pytest.fixture
def start_emulator() -> Iterator[Callable[[str], subprocess.Popen[str]]]:
    """Starts `fleet-sim emulate PROTOCOL` as a subprocess; kills whatever is left at the end."""
    procs: list[subprocess.Popen[str]] = []

    def start(protocol: str) -> subprocess.Popen[str]:
        procs.append(subprocess.Popen(
            [sys.executable, "-m", "fleet_sim.cli", "emulate", protocol], cwd=ROOT,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True))
        return procs[-1]

    yield start
    for proc in procs:
        if proc.poll() is None:
            proc.kill()
            proc.wait(GUARD_S)
        assert proc.stdout is not None and proc.stderr is not None
        proc.stdout.close()
        proc.stderr.close()


@pytest.fixture
def emulator(start_emulator: Callable[[str], subprocess.Popen[str]]) -> subprocess.Popen[str]:
    return start_emulator("carriro")


def carriro_port(path: str) -> serial.Serial:
    return serial.Serial(path, baudrate=19200, bytesize=serial.EIGHTBITS,
                         parity=serial.PARITY_EVEN, stopbits=serial.STOPBITS_ONE,
                         timeout=PORT_TIMEOUT_S)


@pytest.mark.parametrize("stop", [signal.SIGTERM, signal.SIGINT])
def test_carriro_over_a_pseudo_terminal(emulator: subprocess.Popen[str],
                                        stop: signal.Signals) -> None:
    assert emulator.stdout is not None and emulator.stderr is not None
    path = first_line(emulator.stdout)
    assert path.startswith("/dev/")
    with carriro_port(path) as port:
        # The banner comes 1 s (assumed startup_s) after start; a port opened later than that
        # would have flushed it (pyserial clears input on open), so it may be missing.
        assert BANNER.endswith(port.readline())
        for name in ("comm_get", "echo"):
            port.write(golden_bytes("carriro", f"{name}.request"))
            assert port.readline() == golden_bytes("carriro", f"{name}.reply")
            select.select([], [], [], 0.02)  # the host's 10 ms after a reply (処理)
    emulator.send_signal(stop)
    assert emulator.wait(GUARD_S) == 0
    errors = emulator.stderr.read()
    assert "Traceback" not in errors
    assert "19200 8E1, 11 bits per character" in errors


PARITY = {"none": serial.PARITY_NONE, "even": serial.PARITY_EVEN, "odd": serial.PARITY_ODD}


def profile_port(path: str, protocol: str) -> serial.Serial:
    """The port opened as a controller would for `protocol`'s default profile."""
    link = choose_profile(protocol).link
    return serial.Serial(path, baudrate=link.baud, bytesize=link.data_bits,
                         parity=PARITY[link.parity], stopbits=link.stop_bits,
                         timeout=PORT_TIMEOUT_S)


# One documented command per protocol and the exact bytes it is answered with.
KTM02_STATUS_IDLE = bytes([0xAA, 0x03, 0x08, 0x00,  # SendStatusCmd 0x03, 8 bytes
                           0x02,  # the device's second frame (the ACK was its first)
                           0xB7, 0x00,  # verify: aa+03+08+00+02+00 = 0xb7 (sum16)
                           0x00])  # robot state IDLE
EXCHANGES = {
    # RequestStatusCmd -> ACK of frame 1, then SendStatusCmd (ktm02.py, decision 3)
    "ktm02": (golden_hex("ktm02", "host_request_status"),
              golden_hex("ktm02", "device_ack") + KTM02_STATUS_IDLE),
    # GBI -> gbi:NNN, battery 100 % by default
    "tabo": (golden_bytes("tabo", "GBI_100.in"), golden_bytes("tabo", "GBI_100.out")),
    # *IDN? -> AGV-3
    "agv3": (golden_bytes("agv3", "idn.in"), golden_bytes("agv3", "idn.out")),
}
WIRE = {"ktm02": "115200 8N1, 10 bits per character", "tabo": "115200 8N1, 10 bits per character",
        "agv3": "9600 8N1, 10 bits per character"}


@pytest.mark.parametrize("protocol", sorted(EXCHANGES))
def test_each_protocol_over_a_pseudo_terminal(
        start_emulator: Callable[[str], subprocess.Popen[str]], protocol: str) -> None:
    emulator = start_emulator(protocol)
    assert emulator.stdout is not None and emulator.stderr is not None
    path = first_line(emulator.stdout)
    assert path.startswith("/dev/")
    request, reply = EXCHANGES[protocol]
    with profile_port(path, protocol) as port:
        port.write(request)
        assert port.read(len(reply)) == reply
        assert port.in_waiting == 0
    emulator.send_signal(signal.SIGTERM)
    assert emulator.wait(GUARD_S) == 0
    errors = emulator.stderr.read()
    assert "Traceback" not in errors
    assert f"({protocol}, profile {choose_profile(protocol).name})" in errors
    assert WIRE[protocol] in errors
    assert "warning" not in errors  # the port was opened with the profile's settings


def test_unknown_protocol_is_one_line_and_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["emulate", "modbus"]) == 2
    err = capsys.readouterr().err
    assert err == ("fleet-sim: error: unknown protocol 'modbus'; expected one of carriro, "
                   "ktm02, tabo, agv3\n")


def test_profile_of_another_protocol_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["emulate", "carriro", "--profile", "tabo"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "profile 'tabo' speaks 'tabo', not 'carriro'" in err


def test_unknown_profile_is_refused(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["emulate", "agv3", "--profile", "nope"]) == 2
    assert "got 'nope'; expected one of agv-3" in capsys.readouterr().err


def test_default_profile_per_protocol() -> None:
    assert {p: choose_profile(p).name for p in ("carriro", "ktm02", "tabo", "agv3")} == {
        "carriro": "carriro-ad-plus", "ktm02": "ktm-02", "tabo": "tabo", "agv3": "agv-3"}
    assert describe(load_profile("carriro-ad-plus").link) == "19200 8E1, 11 bits per character"
    odd = LinkSettings(baud=9600, data_bits=7, parity="odd", stop_bits=1.5)
    assert describe(odd) == "9600 7O1.5, 10.5 bits per character"


def test_wire_delivers_each_character_when_its_last_bit_is_in() -> None:
    wire = _Wire(LinkSettings(baud=10000, data_bits=8, parity="none", stop_bits=1,
                              latency_s=0.5))  # 1 ms a character
    wire.send(b"ab", 1.0)
    wire.send(b"c", 1.0)  # queued behind "ab": the line is busy until 1.002
    assert [t for t, _ in wire.queue] == pytest.approx([1.501, 1.502, 1.503])
    assert wire.due(1.5015) == [(pytest.approx(1.501), ord("a"))]
    assert wire.next_s() == pytest.approx(1.502)


def read_all(fd: int) -> bytes:
    data = b""
    while select.select([fd], [], [], 0)[0]:
        data += os.read(fd, 4096)
    return data


def test_reply_bytes_are_never_early() -> None:
    """Step the emulator in simulated time: each reply character appears on the host side only
    once the link model says it has arrived."""
    profile = load_profile("carriro-ad-plus")
    char_s = profile.link.char_s
    master, slave = os.openpty()
    try:
        tty.setraw(slave)
        os.set_blocking(master, False)
        device = get_device("carriro", **device_settings("carriro", profile.link))
        emu = Emulator(profile, device, master, np.random.default_rng(0))
        emu.step(1.0 + 21 * char_s)  # the banner, sent at 1.0, fully delivered
        assert read_all(slave) == BANNER
        sent_s = 1.1
        emu.heard(b"comm?\n", sent_s)
        arrived_s = sent_s + 6 * char_s  # the LF's last bit is in
        reply_s = arrived_s + 0.005  # processing (assumed 5 ms)
        emu.step(arrived_s)
        emu.step(reply_s + 3 * char_s - 1e-9)
        assert read_all(slave) == b"co"
        emu.step(reply_s + 8 * char_s - 1e-9)
        assert read_all(slave) == b"mm? 0"
        emu.step(reply_s + 8 * char_s)
        assert read_all(slave) == b"\n"
        assert emu.dropped_bytes == 0
    finally:
        os.close(master)
        os.close(slave)


class SteppedAgv3:
    """`fleet-sim emulate agv3` as `serve` builds it (default profile, its device and wire) on
    a real pseudo-terminal, stepped in simulated time; the host talks through pyserial with
    the profile's port settings."""

    def __init__(self) -> None:
        profile = choose_profile("agv3")
        self.master, self.slave = os.openpty()
        tty.setraw(self.slave)
        os.set_blocking(self.master, False)
        device = get_device("agv3", **device_settings("agv3", profile.link))
        self.emu = Emulator(profile, device, self.master, np.random.default_rng(0))
        self.port = profile_port(os.ttyname(self.slave), "agv3")

    def ask(self, line: str, at_s: float) -> list[str]:
        """Write `line` at `at_s`; the reply lines that have reached the host 0.25 s later (the
        AGV-3 reply limit)."""
        self.port.write(line.encode("ascii") + b"\r\n")
        self.port.flush()
        sent = b""
        while not sent.endswith(b"\r\n"):
            assert select.select([self.master], [], [], GUARD_S)[0], "the host's line is lost"
            sent += os.read(self.master, 4096)
        self.emu.heard(sent, at_s)
        self.emu.step(at_s + 0.25)
        replies = [self.port.readline() for _ in range(line.count(";") + 1)]
        assert all(r.endswith(b"\r\n") for r in replies), replies
        return [r[:-2].decode("ascii") for r in replies]

    def statuses(self, until_s: float, from_s: float = 0.5) -> list[str]:
        """STATus? every 0.5 s up to `until_s`: each answer that differs from the one before."""
        seen: list[str] = []
        for i in range(round((until_s - from_s) / 0.5) + 1):
            (status,) = self.ask("NAV:STAT?", from_s + 0.5 * i)
            if not seen or seen[-1] != status:
                seen.append(status)
        return seen

    def close(self) -> None:
        self.port.close()
        os.close(self.master)
        os.close(self.slave)


@pytest.fixture
def agv3() -> Iterator[SteppedAgv3]:
    emulated = SteppedAgv3()
    yield emulated
    emulated.close()


def test_agv3_status_follows_its_own_drive_through_a_station(agv3: SteppedAgv3) -> None:
    """Started with a pick-up order, the emulated AGV-3 finds the line, drives to the station,
    enters, stops, exits and drives on; the host only asks."""
    assert agv3.ask("NAV:STA;PICKU 2 3", 0.0) == ["Starting...", ""]
    assert agv3.statuses(45.0) == ["STARTED", "LEADING", "STATION ENTER", "STATION STOPPED",
                                   "STATION EXIT", "LEADING"]
    assert agv3.ask("NAV:PICKU?;PASS?", 45.5) == ["0 0", "3"]


def test_agv3_follower_reports_its_leader_once_caught_up(agv3: SteppedAgv3) -> None:
    agv3.ask("NAV:ROL FOLLOW;STA", 0.0)
    assert agv3.statuses(10.0) == ["STARTED", "FOLLOWING -1", "FOLLOWING 1"]


def test_agv3_faults_by_itself_when_its_battery_runs_out(agv3: SteppedAgv3) -> None:
    """16 Wh at 8 W (the AGV-3 profile's figures): two hours of driving, then FAULT battery low."""
    agv3.ask("NAV:STA", 0.0)
    assert agv3.ask("NAV:STAT?", 7199.0) == ["LEADING"]
    assert agv3.ask("NAV:STAT?;:SYS:BAT?", 7201.0) == ["FAULT battery low", "0.819417V"]
    assert agv3.ask("NAV:STA;STAT?", 7202.0) == ["Starting...", "FAULT battery low"]
