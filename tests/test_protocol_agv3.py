"""AGV-3 codec and virtual device ("Grupp 3 AGV protokoll", revision 1.1)."""

from __future__ import annotations

import contextlib
import os
from typing import Any

import numpy as np
import pytest

from agv_model.emulate import Emulator
from agv_model.link import device_settings
from agv_model.profile import load_profile
from agv_model.protocols import Command, ProtocolError, Reply, get_codec, get_device
from agv_model.protocols.agv3 import (
    ERROR_LINE_MAX_BYTES,
    LINE_LIMIT_BYTES,
    QUOTE_LIMIT_CHARS,
    REPLY_TIMEOUT_S,
    Agv3Codec,
    Agv3Device,
    find,
)

from .conftest import GOLDEN, golden_bytes

CASES = sorted(p.stem for p in (GOLDEN / "agv3").glob("*.in"))


def ask(device: Agv3Device, line: str, at_s: float = 0.0) -> list[str]:
    """Send one line at at_s; return the reply lines sent within the 0.25 s limit."""
    device.receive(line.encode("ascii") + b"\r\n", at_s)
    sent = b"".join(data for _, data in device.poll(at_s + REPLY_TIMEOUT_S))
    assert sent.endswith(b"\r\n") or not sent
    return sent.decode("ascii").split("\r\n")[:-1]


# -- golden exchanges from the document ----------------------------------------------------


@pytest.mark.parametrize("case", CASES)
def test_documented_example_exchange(case: str) -> None:
    terminator = b"\n\r" if case == "chain_example" else b"\r\n"
    device = Agv3Device(reply_terminator=terminator)
    device.receive(golden_bytes("agv3", f"{case}.in"), 0.0)
    sent = b"".join(data for _, data in device.poll(REPLY_TIMEOUT_S))
    assert sent == golden_bytes("agv3", f"{case}.out")


def test_chain_example_with_the_footnote_line_ending() -> None:
    device = Agv3Device()
    device.receive(golden_bytes("agv3", "chain_example.in"), 0.0)
    sent = b"".join(data for _, data in device.poll(1.0))
    assert sent == golden_bytes("agv3", "chain_example.out").replace(b"\n\r", b"\r\n")


def test_chain_example_parses_with_levels_kept() -> None:
    (frame,) = Agv3Codec().unframe(bytearray(golden_bytes("agv3", "chain_example.in")))
    assert Agv3Codec().parse_line(frame) == [
        Command("NAVigation:STArt", ("1", "2", "3"), "set"),
        Command("NAVigation:STOp", ("hammertime",), "set"),
        Command("SYStem:BATtery", (), "get"),
    ]


# -- grammar -------------------------------------------------------------------------------


@pytest.mark.parametrize(("header", "name"), [
    ("NAVigation:STArt", "NAVigation:STArt"),
    ("NAV:STA", "NAVigation:STArt"),
    ("nav:sta", "NAVigation:STArt"),
    ("NaV:StA", "NAVigation:STArt"),
    ("navi:star", "NAVigation:STArt"),
    (":NAV:STAT", "NAVigation:STATus"),
    ("NAV:PICKU", "NAVigation:PICKUp"),
    ("nav:pickup", "NAVigation:PICKUp"),
    ("SYS:ES", "SYStem:EStop"),
    ("*idn", "*IDN"),
])
def test_short_long_and_any_case_forms(header: str, name: str) -> None:
    assert Agv3Codec().parse_command(header.encode() + b"?").name == name


@pytest.mark.parametrize("header", ["NA:STA", "NAV:ST", "NAV:PICK", "NAVX:STA", "NAV:STARTX",
                                    "STA", "SYS:STA", "NAV::STA"])
def test_headers_that_are_not_commands(header: str) -> None:
    with pytest.raises(ProtocolError) as err:
        Agv3Codec().parse_command(header.encode())
    assert header.lstrip(":") in str(err.value)


def test_chaining_keeps_the_level_and_colon_returns_to_root() -> None:
    parsed = Agv3Codec().parse_line(b"SYS:ES?;BAT?;*IDN?;ES;:NAV:ROL FOLLOW;PASS?")
    assert [(c.name, c.kind) for c in parsed if isinstance(c, Command)] == [
        ("SYStem:EStop", "get"), ("SYStem:BATtery", "get"), ("*IDN", "get"),
        ("SYStem:EStop", "set"), ("NAVigation:ROLe", "set"), ("NAVigation:PASSengers", "get"),
    ]


def test_a_bad_segment_does_not_stop_the_chain() -> None:
    parsed = Agv3Codec().parse_line(b"NAV:STA; FOO; STO")
    assert isinstance(parsed[1], ProtocolError)
    assert parsed[2] == Command("NAVigation:STOp", (), "set")


def test_parse_command_refuses_a_chain() -> None:
    with pytest.raises(ProtocolError, match="exactly one command"):
        Agv3Codec().parse_command(b"NAV:STA;STO")


def test_non_ascii_is_refused() -> None:
    with pytest.raises(ProtocolError, match="ASCII"):
        Agv3Codec().parse_line("NAV:STÅ".encode())


def test_encode_and_chain_round_trip() -> None:
    codec = Agv3Codec()
    assert codec.encode(Command("NAV:PICKU", ("2", "5"), "set")) == b"NAV:PICKU 2 5\r\n"
    line = codec.encode_chain([Command("NAVigation:STArt"), Command("SYStem:BATtery", (), "get"),
                               Command("*IDN", (), "get")])
    assert line == b"NAVigation:STArt;:SYStem:BATtery?;*IDN?\r\n"
    assert [c.name for c in codec.parse_line(line[:-2]) if isinstance(c, Command)] == [
        "NAVigation:STArt", "SYStem:BATtery", "*IDN"]
    with pytest.raises(ProtocolError):
        codec.encode(Command("NAV:FLY"))


def test_replies_encode_and_decode() -> None:
    codec = Agv3Codec()
    assert codec.encode_reply(Reply("NAVigation:PICKUp", "value", ("2 5",))) == b"2 5\r\n"
    assert codec.encode_reply(Reply("NAVigation:ROLe", "ok")) == b"\r\n"
    assert codec.decode(b"FOLLOWING -1") == Reply("", "value", ("FOLLOWING", "-1"))
    assert codec.decode(b"") == Reply("", "ok")
    assert codec.decode(b"ERROR: x") == Reply("", "error", ("x",))


def test_unframe_needs_crlf() -> None:
    buffer = bytearray(b"*IDN?\r\nNAV:STA\n*IDN?\r")
    assert Agv3Codec().unframe(buffer) == [b"*IDN?"]
    assert buffer == bytearray(b"NAV:STA\n*IDN?\r")


def test_registered_by_name() -> None:
    assert isinstance(get_codec("agv3"), Agv3Codec)
    assert isinstance(get_device("agv3", reply_delay_s=0.1), Agv3Device)
    assert find("nav:stat").long == "STATus"


# -- commands, defaults and errors ---------------------------------------------------------


def test_pickup_and_dropoff_get_set_defaults_and_cancel() -> None:
    device = Agv3Device()
    assert ask(device, "NAV:PICKU 2 5;PICKU?;DROPO 3 1 extra;DROPO?") == ["", "2 5", "", "3 1"]
    assert ask(device, "NAV:PICKU 3 0;PICKU?", 1.0) == ["", "0 0"]  # antal 0 cancels
    assert ask(device, "NAV:DROPO;DROPO?", 2.0) == ["", "0 0"]  # defaults 0 0


@pytest.mark.parametrize("line", ["NAV:PICKU 4 1", "NAV:PICKU 1 11", "NAV:DROPO x 1",
                                  "NAV:DROPO -1 1"])
def test_order_out_of_range_is_an_error_and_keeps_the_order(line: str) -> None:
    device = Agv3Device()
    ask(device, "NAV:PICKU 1 1;DROPO 1 1")
    (reply,) = ask(device, line, 1.0)
    assert reply.startswith("ERROR: NAVigation:")
    assert ask(device, "NAV:PICKU?;DROPO?", 2.0) == ["1 1", "1 1"]


def test_role_default_case_sensitive_arguments() -> None:
    device = Agv3Device()
    assert ask(device, "nav:rol FOLLOW;rol?") == ["", "FOLLOW"]
    assert ask(device, "NAV:ROL follow", 1.0)[0].startswith("ERROR:")
    assert ask(device, "NAV:ROL;ROL?", 2.0) == ["", "LEAD"]


def test_passengers_sets_max_but_reads_onboard() -> None:
    device = Agv3Device()
    assert ask(device, "NAV:PASS 2;PASS?") == ["", "0"]
    ask(device, "NAV:PICKU 1 5", 1.0)
    device.arrive_at_station(1)
    assert ask(device, "NAV:PASS?;PICKU?;STAT?", 2.0) == ["2", "0 0", "STATION STOPPED"]


def test_status_follows_start_line_search_role_and_stop() -> None:
    device = Agv3Device(reply_delay_s=0.01, line_search_s=2.0)
    assert ask(device, "NAV:STAT?") == ["STOPPED"]
    assert ask(device, "NAV:STA;STAT?", 1.0) == ["Starting...", "STARTED"]
    assert ask(device, "NAV:STAT?", 2.5) == ["STARTED"]
    assert ask(device, "NAV:STAT?", 3.02) == ["LEADING"]  # found at 1.01 + 2
    assert ask(device, "NAV:ROL FOLLOW;STAT?", 4.0) == ["", "FOLLOWING -1"]
    device.set_status("FAULT", "line lost")
    assert ask(device, "NAV:STAT?", 5.0) == ["FAULT line lost"]
    assert ask(device, "NAV:STO;STAT?", 6.0) == ["Stopping...", "STOPPED"]


def test_estop_latches_and_refuses_start() -> None:
    device = Agv3Device()
    ask(device, "NAV:STA")
    assert ask(device, "SYS:ES;ES?;:NAV:STAT?;STA", 1.0) == [
        "", "TRUE", "STOPPED", "ERROR: NAVigation:STArt: emergency stop is active"]
    device.release_estop()
    assert ask(device, "NAV:STA", 2.0) == ["Starting..."]


@pytest.mark.parametrize(("line", "error"), [
    ("NAV:FOO", "ERROR: unknown command 'NAV:FOO'"),
    ("NAV:STA?", "ERROR: NAVigation:STArt has no get"),
    ("NAV:STAT", "ERROR: NAVigation:STATus has no set"),
    ("SYS:BAT 12", "ERROR: SYStem:BATtery has no set"),
    ("*IDN", "ERROR: *IDN has no set"),
    ("NAV?", "ERROR: NAVigation has no get"),
])
def test_unknown_commands_and_missing_operations_answer_an_error(line: str, error: str) -> None:
    assert ask(Agv3Device(), line) == [error]


def test_extra_arguments_are_ignored() -> None:
    device = Agv3Device(battery_v=24.5)
    assert ask(device, "*IDN? please;:SYS:BAT? now") == ["AGV-3", "24.500000V"]


def test_reply_comes_within_the_timeout_in_simulated_time() -> None:
    device = Agv3Device(reply_delay_s=0.01)
    device.receive(b"*IDN?\r\n", 10.0)
    assert device.next_output_s() == pytest.approx(10.01)
    assert device.next_output_s() - 10.0 < REPLY_TIMEOUT_S  # type: ignore[operator]
    assert device.poll(10.005) == []


def test_empty_line_is_not_answered() -> None:
    device = Agv3Device()
    device.receive(b"\r\n ; \r\n", 0.0)
    assert device.next_output_s() is None


def test_exchange_over_a_pseudo_terminal(pty_link: Any) -> None:
    link = pty_link(Agv3Device(reply_delay_s=0.02))
    answer = link.exchange(b"*IDN?;:nav:sta;STAT?\r\n", lambda got: got.count(b"\r\n") >= 3)
    assert answer == b"AGV-3\r\nStarting...\r\nSTARTED\r\n"


# -- line noise: bounded input, bounded errors ------------------------------------------------

NOISE_BYTES = 100_000
NOISE_SEED = 3


def noise(n_bytes: int = NOISE_BYTES, seed: int = NOISE_SEED) -> bytes:
    """Seeded random bytes, as a wrong baud rate or a loose connector would give."""
    return np.random.default_rng(seed).bytes(n_bytes)


def sent_lines(device: Agv3Device, until_s: float) -> list[bytes]:
    sent = b"".join(data for _, data in device.poll(until_s))
    assert sent.endswith(b"\r\n")
    return sent.split(b"\r\n")[:-1]


def test_idn_is_answered_within_the_limit_after_100_kb_of_noise() -> None:
    """On the AGV-3 profile's wire (9600 8N1, both directions timed as `fleet-sim emulate` does,
    stepped in simulated time), the whole answer to `*IDN?` is in at the host within 0.25 s of
    the command's last character arriving, whatever error the noise before it got."""
    profile = load_profile("agv-3")
    link = profile.link
    device = get_device("agv3", **device_settings("agv3", link))
    read_fd, write_fd = os.pipe()
    os.set_blocking(read_fd, False)
    os.set_blocking(write_fd, False)
    try:
        emu = Emulator(profile, device, write_fd, np.random.default_rng(0))
        data = noise() + b"\r\n" + b"*IDN?\r\n"
        emu.heard(data, 0.0)
        arrived_s = len(data) * link.char_s  # the command's LF is in
        emu.step(arrived_s + REPLY_TIMEOUT_S)
        received = b""
        with contextlib.suppress(BlockingIOError):
            while chunk := os.read(read_fd, 1 << 16):
                received += chunk
        assert received.endswith(b"\r\nAGV-3\r\n")
        assert emu.dropped_bytes == 0
    finally:
        os.close(read_fd)
        os.close(write_fd)


def test_error_output_for_noise_is_bounded() -> None:
    """One error line for each line of noise, none longer than ERROR_LINE_MAX_BYTES: here the
    noise holds a few CR LF by chance, so at most (that count + 1) x 128 bytes; fed in 1000
    pieces of 100 bytes, as a serial port hands them over."""
    junk = noise()
    device = Agv3Device()
    for i in range(0, len(junk), 100):
        device.receive(junk[i:i + 100], i / 1000)
    device.receive(b"\r\n", 100.0)
    lines = sent_lines(device, 101.0)
    assert len(lines) == junk.count(b"\r\n") + 1
    assert all(line.startswith(b"ERROR: ") for line in lines)
    assert max(len(line) + 2 for line in lines) <= ERROR_LINE_MAX_BYTES
    assert sum(len(line) + 2 for line in lines) <= (junk.count(b"\r\n") + 1) * 128


def test_an_over_long_line_is_dropped_with_exactly_one_error() -> None:
    """A line of LINE_LIMIT_BYTES is still read; one byte more and the whole line is dropped
    and answered with one error, however it is cut into pieces (here one byte at a time, the
    terminator split too); the next line is read as usual."""
    device = Agv3Device()
    at_limit = b"*IDN?;" + b" " * (LINE_LIMIT_BYTES - 6)
    assert ask(device, at_limit.decode()) == ["AGV-3"]
    every = Agv3Codec().encode_chain([  # each command once, long form, longest arguments
        Command("NAVigation:STArt"), Command("NAVigation:STOp"),
        Command("NAVigation:PICKUp", ("3", "10"), "set"),
        Command("NAVigation:DROPOff", ("3", "10"), "set"),
        Command("NAVigation:ROLe", ("FOLLOW",), "set"),
        Command("NAVigation:PASSengers", ("10",), "set"), Command("NAVigation:STATus", (), "get"),
        Command("SYStem:EStop", (), "get"), Command("SYStem:BATtery", (), "get"),
        Command("*IDN", (), "get")])
    assert len(every) - 2 <= LINE_LIMIT_BYTES
    assert len(ask(device, every[:-2].decode(), 0.5)) == 10
    over = b"*IDN?;" * (LINE_LIMIT_BYTES // 6 + 1) + b"\r\n*IDN?\r\n"
    for i in range(len(over)):
        device.receive(over[i:i + 1], 1.0 + i / 1000)
    lines = sent_lines(device, 3.0)
    assert len(lines) == 2
    assert lines[0].startswith(b"ERROR: line longer than 256 bytes b'*IDN?;*IDN?;")
    assert lines[0].endswith(b"...'") and len(lines[0]) + 2 <= ERROR_LINE_MAX_BYTES
    assert lines[1] == b"AGV-3"


@pytest.mark.parametrize(("line", "start"), [
    ("X" * 200, "ERROR: unknown command 'XXXX"),
    ("NAV:" + "Y" * 200 + "?", "ERROR: unknown command 'NAV:YYYY"),
    ("NAV:PICKU " + "9" * 200, "ERROR: NAVigation:PICKUp: station '9999"),
    ("NAV:DROPO 1 x" + "9" * 200, "ERROR: NAVigation:DROPOff: count 'x999"),
    ("NAV:ROL " + "F" * 200, "ERROR: NAVigation:ROLe: role 'FFFF"),
    ("NAV:PASS " + "z" * 200, "ERROR: NAVigation:PASSengers: max 'zzzz"),
])
def test_quoted_junk_is_cut_to_the_quote_limit(line: str, start: str) -> None:
    """Junk quoted in an error is cut to QUOTE_LIMIT_CHARS characters ending '...'."""
    (reply,) = ask(Agv3Device(), line)
    assert reply.startswith(start)
    quoted = reply[reply.index("'"):reply.rindex("'") + 1]
    assert len(quoted) == QUOTE_LIMIT_CHARS and quoted.endswith("...'")
    assert len(reply) + 2 <= ERROR_LINE_MAX_BYTES


# -- STATus from the vehicle's own state (agv_model.protocols.agv3_vehicle) -------------------
# Default world: the line is found 2 s after STArt, half a gap before station 0's turn-off;
# turn-offs 10 s apart; 3 s ramps; 5 s at the platform; a follower catches up in 5 s; the AGV
# ahead shows id 1. STArt sent at 0 acts at 0.01 (reply delay), so the line is found at 2.01.


def changes(device: Agv3Device, until_s: float, *, line: str = "NAV:STAT?",
            from_s: float = 0.25, step_s: float = 0.5) -> list[tuple[float, str]]:
    """`line` asked every `step_s` (answered 0.01 s later); each new answer with the time of
    the question that first got it. The samples fall between the model's changes, which come
    at whole hundredths past 0.01."""
    seen: list[tuple[float, str]] = []
    at_s = from_s
    while at_s <= until_s:
        answer = ";".join(ask(device, line, at_s))
        if not seen or seen[-1][1] != answer:
            seen.append((at_s, answer))
        at_s = round(at_s + step_s, 6)
    return seen


def test_a_station_order_takes_it_through_enter_stopped_exit_by_itself() -> None:
    """Station 1 is 1.5 gaps (15 s) past where the line is found: it turns off at 17.01, stands
    at the platform 20.01-25.01 (where the pick-up is carried out) and is back on the main
    road at 28.01, with no call but the commands a host sends."""
    device = Agv3Device()
    assert ask(device, "NAV:STA;PICKU 1 2", 0.0) == ["Starting...", ""]
    assert changes(device, 40.0, line="NAV:STAT?;PICKU?;PASS?") == [
        (0.25, "STARTED;1 2;0"),
        (2.25, "LEADING;1 2;0"),
        (17.25, "STATION ENTER;1 2;0"),
        (20.25, "STATION STOPPED;0 0;2"),
        (25.25, "STATION EXIT;0 0;2"),
        (28.25, "LEADING;0 0;2"),
    ]


def test_without_an_order_it_drives_past_every_station() -> None:
    device = Agv3Device()
    ask(device, "NAV:STA", 0.0)
    assert changes(device, 60.0) == [(0.25, "STARTED"), (2.25, "LEADING")]


def test_the_first_ordered_station_ahead_comes_first() -> None:
    """Drop-off at 3, pick-up at 1 (its turn-off first, 15 s after the line is found): the
    pick-up is done at station 1, the drop-off two gaps on from there (back on the main road
    at 28.01): turn-off at 48.01, platform at 51.01."""
    device = Agv3Device()
    ask(device, "NAV:STA;DROPO 3 1;PICKU 1 2", 0.0)
    assert ask(device, "NAV:PICKU?;DROPO?;PASS?", 24.0) == ["0 0", "3 1", "2"]
    assert ask(device, "NAV:STAT?", 47.5) == ["LEADING"]
    assert ask(device, "NAV:STAT?", 48.5) == ["STATION ENTER"]
    assert ask(device, "NAV:STAT?;PICKU?;DROPO?;PASS?", 51.5) == [
        "STATION STOPPED", "0 0", "0 0", "1"]


def test_an_order_for_a_station_just_passed_waits_a_lap() -> None:
    """The line is found at 2.01 half a gap before station 0's turn-off (passed at 7.01); an
    order for station 0 comes at 10.0, 0.3 gap past it: 3.7 gaps to go, the turn-off at
    47.01."""
    device = Agv3Device()
    ask(device, "NAV:STA", 0.0)
    ask(device, "NAV:PICKU 0 1", 9.99)
    assert ask(device, "NAV:STAT?", 46.5) == ["LEADING"]
    assert ask(device, "NAV:STAT?", 47.5) == ["STATION ENTER"]


def test_a_follower_reads_minus_one_until_it_has_caught_up_with_its_leader() -> None:
    """FOLLOWING -1 from the line found (2.01) until it has caught up (7.01), then the id on
    the leader's sign; a station visit loses the leader: -1 again from the main road (28.01)
    to 33.01."""
    device = Agv3Device()
    ask(device, "NAV:ROL FOLLOW;STA;PICKU 1 1", 0.0)
    assert changes(device, 40.0) == [
        (0.25, "STARTED"),
        (2.25, "FOLLOWING -1"),
        (7.25, "FOLLOWING 1"),
        (17.25, "STATION ENTER"),
        (20.25, "STATION STOPPED"),
        (25.25, "STATION EXIT"),
        (28.25, "FOLLOWING -1"),
        (33.25, "FOLLOWING 1"),
    ]


@pytest.mark.parametrize(("leader_id", "after"), [(7, "FOLLOWING 7"), (None, "FOLLOWING -1")])
def test_the_leader_id_is_the_one_ahead_or_minus_one_with_nobody_ahead(
        leader_id: int | None, after: str) -> None:
    device = Agv3Device(leader_id=leader_id)
    ask(device, "NAV:STA", 0.0)
    assert ask(device, "NAV:STAT?;ROL FOLLOW;STAT?", 3.0) == ["LEADING", "", "FOLLOWING -1"]
    assert ask(device, "NAV:STAT?", 7.5) == ["FOLLOWING -1"]  # ROLe at 3.01, caught up 8.01
    assert ask(device, "NAV:STAT?", 8.5) == [after]
    assert ask(device, "NAV:ROL LEAD;STAT?", 9.0) == ["", "LEADING"]


def test_an_empty_battery_is_a_fault_it_finds_itself() -> None:
    """0.01 Wh at 8 W is 4.5 s of driving: from 200.01 to 204.51. The reading falls from full to
    0.75 x full; standing (before STArt, in FAULT) draws nothing; a new STArt faults at once."""
    device = Agv3Device(battery_v=8.0, battery_wh=0.01)
    assert ask(device, ":SYS:BAT?", 100.0) == ["8.000000V"]  # standing: no draw
    ask(device, "NAV:STA", 200.0)
    assert ask(device, "NAV:STAT?", 201.0) == ["STARTED"]
    assert ask(device, ":SYS:BAT?", 202.25) == ["7.000000V"]  # 2.25 s of 4.5 driven: halfway
    assert ask(device, "NAV:STAT?", 204.0) == ["LEADING"]
    assert ask(device, "NAV:STAT?;:SYS:BAT?", 204.6) == ["FAULT battery low", "6.000000V"]
    assert ask(device, "NAV:STAT?;:SYS:BAT?", 300.0) == ["FAULT battery low", "6.000000V"]
    assert ask(device, "NAV:STO;STAT?;STA;STAT?", 301.0) == [
        "Stopping...", "STOPPED", "Starting...", "FAULT battery low"]


def test_the_default_battery_lasts_two_hours_of_driving() -> None:
    """16 Wh at 8 W: STArt at 0.01, empty at 7200.01, reading 0.75 x 1.092556 V."""
    device = Agv3Device()
    ask(device, "NAV:STA", 0.0)
    assert ask(device, "NAV:STAT?", 7199.5) == ["LEADING"]
    assert ask(device, "NAV:STAT?;:SYS:BAT?", 7200.5) == ["FAULT battery low", "0.819417V"]


@pytest.mark.parametrize("line_search_s", [None, 12.0])
def test_a_line_not_found_within_the_limit_is_a_fault(line_search_s: float | None) -> None:
    """The search gives up after line_search_limit_s (10 s): STArt at 0.01, FAULT at 10.01."""
    device = Agv3Device(line_search_s=line_search_s)
    ask(device, "NAV:STA", 0.0)
    assert ask(device, "NAV:STAT?", 9.7) == ["STARTED"]
    assert ask(device, "NAV:STAT?", 10.1) == ["FAULT line not found"]
    assert ask(device, "NAV:STAT?", 20.0) == ["FAULT line not found"]
    assert ask(device, "NAV:STO;STAT?", 21.0) == ["Stopping...", "STOPPED"]


def test_stop_and_start_again_drive_on_from_where_it_stopped() -> None:
    """Stopped at 10.01 (0.8 gap past where the line was found), started at 20.01, line found
    at 22.01: station 1 is 0.7 gap on, its turn-off at 29.01."""
    device = Agv3Device()
    ask(device, "NAV:STA;PICKU 1 1", 0.0)
    assert ask(device, "NAV:STO;STAT?", 10.0) == ["Stopping...", "STOPPED"]
    assert ask(device, "NAV:STAT?", 19.0) == ["STOPPED"]
    ask(device, "NAV:STA", 20.0)
    assert ask(device, "NAV:STAT?", 28.5) == ["LEADING"]
    assert ask(device, "NAV:STAT?", 29.5) == ["STATION ENTER"]


def test_the_owners_status_is_a_starting_point_it_drives_on_from() -> None:
    device = Agv3Device()
    ask(device, "NAV:STA", 0.0)
    device.set_status("FOLLOWING", "4")  # at 0.25, the device's time
    assert ask(device, "NAV:STAT?;ROL?", 1.0) == ["FOLLOWING 4", "FOLLOW"]
    device.set_status("STATION", "STOPPED")  # at 1.25, at the next turn-off ahead
    assert ask(device, "NAV:STAT?", 6.0) == ["STATION STOPPED"]
    assert ask(device, "NAV:STAT?", 6.5) == ["STATION EXIT"]  # 5 s at the platform
    assert ask(device, "NAV:STAT?", 9.5) == ["FOLLOWING -1"]  # main road at 9.25
    with pytest.raises(ValueError, match="STATION info 'PARKED'"):
        device.set_status("STATION", "PARKED")
    with pytest.raises(ValueError, match="FOLLOWING info 'x'"):
        device.set_status("FOLLOWING", "x")


def test_world_settings_are_checked() -> None:
    with pytest.raises(ValueError, match=r"station_gap_s \(0\) must be greater than 0"):
        Agv3Device(station_gap_s=0)
    with pytest.raises(ValueError, match=r"battery_empty_v \(9.0\) must be between 0"):
        Agv3Device(battery_v=8.0, battery_empty_v=9.0)
    with pytest.raises(TypeError, match="station_gap"):
        Agv3Device(station_gap=3.0)
