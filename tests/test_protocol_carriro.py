"""CarriRo AD+ serial API v1.4: codec and virtual device against the document's examples and rules.

Golden files (tests/golden/carriro/) hold the document's examples, typed from it by hand. Time is
simulated throughout: the device only ever sees the `now_s` the tests hand it.
"""

from __future__ import annotations

import os
import random
import select
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest
import serial

from agv_model.protocols import get_codec, get_device
from agv_model.protocols.base import Command, ProtocolError, Reply
from agv_model.protocols.carriro import (
    BANNER,
    DONE,
    ERROR,
    VALUE,
    CarriroCodec,
    CarriroDevice,
    CarriroError,
)
from agv_model.protocols.carriro_tables import (
    AD_ACTIONS,
    AD_STATUSES,
    CODES,
    LANDMARKS,
    MODES,
    SETTABLE_AD_ACTIONS,
    TextField,
    describe_code,
)

GOLDEN = Path(__file__).parent / "golden" / "carriro"
EXAMPLES = sorted(p.stem for p in GOLDEN.glob("*.request"))
STATUS_CMD_EXAMPLE = ("battery?", "error?", "warning?")  # status_cmd: 要求例
HOST_GAP_S = 0.010  # 処理: the host waits 10 ms after each reply


def golden(name: str) -> bytes:
    return (GOLDEN / name).read_bytes()


def codec_for(example: str) -> CarriroCodec:
    if example == "status_after_status_cmd":
        return CarriroCodec(STATUS_CMD_EXAMPLE)
    return CarriroCodec()


class Host:
    """A well-behaved host: one command, wait for the reply, then 10 ms before the next."""

    def __init__(self, device: CarriroDevice, now_s: float = 0.0) -> None:
        self.device = device
        self.now_s = now_s
        self.banner = self.wait()

    def wait(self) -> bytes:
        due = self.device.next_output_s()
        assert due is not None, "the device has nothing to send"
        self.now_s = max(self.now_s, due)
        sent = b"".join(data for _, data in self.device.poll(self.now_s))
        self.now_s += HOST_GAP_S
        return sent

    def ask(self, line: bytes) -> bytes:
        self.device.receive(line, self.now_s)
        return self.wait()


def rounded(sent: list[tuple[float, bytes]]) -> list[tuple[float, bytes]]:
    """Send times to the microsecond, so that float sums such as 1.2 + 0.005 compare."""
    return [(round(t, 6), data) for t, data in sent]


def booted(**settings: Any) -> Host:
    return Host(CarriroDevice(**settings))


# -- the document's examples ----------------------------------------------------------------------

def test_every_documented_example_has_a_golden_file() -> None:
    assert len(EXAMPLES) == 30
    assert (GOLDEN / "startup.message").exists() and (GOLDEN / "ad_output.message").exists()


EXPECTED_COMMANDS: dict[str, Command] = {
    "action": Command("action", (2,), "action"),
    "ad_action_get": Command("ad_action", (), "get"),
    "ad_action_get_p": Command("ad_action", ("-p",), "get"),
    "ad_action_set": Command("ad_action", (9,), "action"),
    "ad_landmark": Command("ad_landmark", (), "get"),
    "ad_pattern_get": Command("ad_pattern", (), "get"),
    "ad_pattern_set": Command("ad_pattern", (2,), "set"),
    "ad_speed_limit_get": Command("speed_limit", (), "get"),
    "ad_speed_limit_set": Command("speed_limit", (2.0,), "set"),
    "ad_status": Command("ad_status", (), "get"),
    "battery": Command("battery", (), "get"),
    "comm_get": Command("comm", (), "get"),
    "comm_set": Command("comm", (2.0,), "set"),
    "dist": Command("dist", (), "get"),
    "echo": Command("echo", ("a", "b", "c", "123"), "action"),
    "error": Command("error", (), "get"),
    "id": Command("id", (), "get"),
    "mode_get": Command("mode", (), "get"),
    "mode_set": Command("mode", (10,), "set"),
    "pallet": Command("pallet", (), "get"),
    "reboot": Command("reboot", (), "action"),
    "shutdown": Command("shutdown", (), "action"),
    "speed": Command("speed", (), "get"),
    "status": Command("status", (), "get"),
    "status_after_status_cmd": Command("status", (), "get"),
    "status_cmd_get": Command("status_cmd", (), "get"),
    "status_cmd_set": Command("status_cmd", STATUS_CMD_EXAMPLE, "set"),
    "trolley": Command("trolley", (), "get"),
    "version": Command("version", (), "get"),
    "warning": Command("warning", (), "get"),
}

EXPECTED_REPLIES: dict[str, Reply] = {
    "action": Reply("action", DONE, (2,)),
    "ad_action_get": Reply("ad_action", VALUE, (4,)),
    "ad_action_get_p": Reply("ad_action", VALUE, (4, 3.0)),  # 直進3, 3.0 km/h
    "ad_action_set": Reply("ad_action", DONE, (9,)),
    "ad_landmark": Reply("ad_landmark", VALUE, (8, 2.57)),  # 一時停止, 2.57 m
    "ad_pattern_get": Reply("ad_pattern", VALUE, (1,)),
    "ad_pattern_set": Reply("ad_pattern", DONE, (2,)),
    "ad_speed_limit_get": Reply("speed_limit", VALUE, (3.0,)),
    "ad_speed_limit_set": Reply("speed_limit", DONE, (2.0,)),
    "ad_status": Reply("ad_status", VALUE, (2,)),
    "battery": Reply("battery", VALUE, (73,)),
    "comm_get": Reply("comm", VALUE, (0.0,)),
    "comm_set": Reply("comm", DONE, (2.0,)),
    "dist": Reply("dist", VALUE, (3141.59,)),
    "echo": Reply("echo", DONE, ("a", "b", "c", "123")),
    "error": Reply("error", VALUE, ("10020000",)),
    "id": Reply("id", VALUE, ("0012f337e03c",)),
    "mode_get": Reply("mode", VALUE, (5,)),
    "mode_set": Reply("mode", DONE, (10,)),
    "pallet": Reply("pallet", VALUE, (1, 0)),
    "reboot": Reply("reboot", DONE, ("OK",)),
    "shutdown": Reply("shutdown", DONE, ("OK",)),
    "speed": Reply("speed", VALUE, (2.0,)),
    "status": Reply("status", VALUE, (10, 2.0, 3141.59, 65, 2, 1, 4, 20, 0.32)),
    "status_after_status_cmd": Reply("status", VALUE, (73, "00000000", "00000000")),
    "status_cmd_get": Reply("status_cmd", VALUE, STATUS_CMD_EXAMPLE),
    "status_cmd_set": Reply("status_cmd", DONE, STATUS_CMD_EXAMPLE),
    "trolley": Reply("trolley", VALUE, (1, 0)),
    "version": Reply("version", VALUE, ("1.12.0.0",)),
    "warning": Reply("warning", VALUE, ("1B010000",)),
}


@pytest.mark.parametrize("example", EXAMPLES)
def test_documented_request_parses_and_round_trips(example: str) -> None:
    codec, request = CarriroCodec(), golden(f"{example}.request")
    command = codec.parse_command(request)
    assert command == EXPECTED_COMMANDS[example]
    assert codec.encode(command) == request


@pytest.mark.parametrize("example", EXAMPLES)
def test_documented_reply_decodes_and_round_trips(example: str) -> None:
    codec, reply_bytes = codec_for(example), golden(f"{example}.reply")
    [frame] = codec.unframe(bytearray(reply_bytes))
    reply = codec.decode(frame)
    assert reply == EXPECTED_REPLIES[example]
    assert codec.encode_reply(reply) == reply_bytes


def test_documented_messages_round_trip() -> None:
    codec = CarriroCodec()
    banner = golden("startup.message")
    assert codec.decode(banner) == Reply("startup", BANNER, ("CarriRo AD+", "1.16.0.2"))
    assert codec.encode_reply(codec.decode(banner)) == banner
    output = golden("ad_output.message")
    assert codec.decode(output) == Reply("ad_output", VALUE, ("ELV1",))
    assert codec.encode_reply(codec.decode(output)) == output


def _autonomous(host: Host) -> None:
    assert host.ask(b"mode: 11\n") == b"mode: 11\n"


def _state(**values: Any) -> Callable[[Host], None]:
    def setup(host: Host) -> None:
        for key, value in values.items():
            setattr(host.device.state, key, value)
    return setup


def _status_cmd_set(host: Host) -> None:
    host.device.state.battery_pct = 73
    assert host.ask(golden("status_cmd_set.request")) == golden("status_cmd_set.reply")


DEVICE_SETUPS: dict[str, tuple[dict[str, Any], Callable[[Host], None]]] = {
    "action": ({"action_ids": (1, 2)}, _state()),
    "ad_action_get": ({}, _autonomous),
    "ad_action_get_p": ({}, _autonomous),
    "ad_action_set": ({}, _autonomous),
    "ad_landmark": ({}, _state(landmark_id=8, landmark_dist_m=2.57)),
    "ad_pattern_get": ({}, _state(ad_pattern=1)),
    "ad_status": ({}, _autonomous),
    "battery": ({}, _state(battery_pct=73)),
    "dist": ({}, _state(dist_m=3141.59)),
    "error": ({}, lambda host: host.device.raise_code("10020000", host.now_s)),
    "pallet": ({}, _state(pallet_option=1)),
    "speed": ({}, _state(speed_kmh=2.0)),
    "status": ({}, _state(mode=10, speed_kmh=2.0, dist_m=3141.59, battery_pct=65, ad_status=2,
                          ad_pattern=1, ad_action=4, landmark_id=20, landmark_dist_m=0.32)),
    "status_cmd_get": ({}, _status_cmd_set),
    "status_after_status_cmd": ({}, _status_cmd_set),
    "trolley": ({}, _state(trolley_option=1)),
    "version": ({"version": "1.12.0.0"}, _state()),
    "warning": ({}, lambda host: host.device.raise_code("1B010000", host.now_s)),
}


@pytest.mark.parametrize("example", EXAMPLES)
def test_device_answers_each_documented_example(example: str) -> None:
    settings, setup = DEVICE_SETUPS.get(example, ({}, _state()))
    host = booted(**settings)
    setup(host)
    assert host.ask(golden(f"{example}.request")) == golden(f"{example}.reply")


def test_device_sends_the_documented_banner_after_start_up() -> None:
    device = CarriroDevice(startup_s=2.0, powered_on_s=10.0)
    assert device.poll(11.0) == []
    assert device.next_output_s() == 12.0
    assert device.poll(12.0) == [(12.0, golden("startup.message"))]


def test_device_sends_ad_output_when_it_passes_a_serial_output_landmark() -> None:
    host = booted()
    host.device.pass_landmark(20, host.now_s, output="ELV1")
    assert host.wait() == golden("ad_output.message")
    assert host.ask(b"ad_landmark?\n") == b"ad_landmark? 20 0\n"


# -- error replies --------------------------------------------------------------------------------

@pytest.mark.parametrize(("line", "reply"), [
    (b"foo?\n", b"foo: error 1"),
    (b"BATTERY?\n", b"BATTERY: error 1"),
    (b"battery\n", b"battery: error 1"),  # no ? or :
    (b"battery: 50\n", b"battery: error 1"),  # get-only
    (b"reboot?\n", b"reboot: error 1"),  # set-only
    (b"ad_output?\n", b"ad_output: error 1"),  # a vehicle message, not a command
    (b"\n", b": error 1"),
])
def test_unknown_command_is_error_1(line: bytes, reply: bytes) -> None:
    assert booted().ask(line) == reply + b"\n"


def test_speed_limit_alias_can_be_refused() -> None:
    host = booted(speed_limit_alias=False)
    assert host.ask(b"speed_limit?\n") == b"speed_limit: error 1\n"
    assert host.ask(b"ad_speed_limit?\n") == b"ad_speed_limit? 30\n"


@pytest.mark.parametrize(("line", "reply"), [
    (b"mode: 6\n", b"mode: error 2"),  # ドライブ is Get only
    (b"mode: 13\n", b"mode: error 2"),
    (b"mode:\n", b"mode: error 2"),
    (b"mode: 5 5\n", b"mode: error 2"),
    (b"mode: five\n", b"mode: error 2"),
    (b"comm: 101\n", b"comm: error 2"),  # 範囲 0-100
    (b"comm: -1\n", b"comm: error 2"),
    (b"comm:20\n", b"comm: error 2"),  # no space between name and parameter
    (b"ad_pattern: 91\n", b"ad_pattern: error 2"),  # 範囲 0-90
    (b"ad_speed_limit: 4\n", b"ad_speed_limit: error 2"),  # 範囲 0, 5-30
    (b"ad_speed_limit: 31\n", b"ad_speed_limit: error 2"),
    (b"ad_speed_limit: 2.0\n", b"ad_speed_limit: error 2"),  # raw integers only
    (b"battery? 1\n", b"battery: error 2"),
    (b"ad_action? -q\n", b"ad_action: error 2"),
    (b"battery?\r\n", b"battery: error 2"),  # LF ends a line, CR is no part of it
    (b"action: 2\n", b"action: error 2"),  # Appendix A has only 1
    (b"reboot: now\n", b"reboot: error 2"),
    (b"ad_action: 5\n", b"ad_action: error 2"),  # not in Appendix C (and data before state)
    (b"status_cmd: foo?\n", b"status_cmd: error 2"),
    (b"status_cmd: status?\n", b"status_cmd: error 2"),
    (b"status_cmd: ad_action? -p\n", b"status_cmd: error 2"),
    (b"status_cmd:\n", b"status_cmd: error 2"),
    (b"status_cmd: " + b"battery? " * 16 + b"\n", b"status_cmd: error 2"),  # at most 15
])
def test_invalid_data_is_error_2(line: bytes, reply: bytes) -> None:
    assert booted().ask(line) == reply + b"\n"


def test_status_cmd_error_leaves_the_list_unchanged() -> None:
    host = booted()
    host.ask(b"status_cmd: battery? mode?\n")
    assert host.ask(b"status_cmd: battery? nothing?\n") == b"status_cmd: error 2\n"
    assert host.ask(b"status_cmd?\n") == b"status_cmd? battery? mode?\n"
    assert host.ask(b"status?\n") == b"status? 100 5\n"


def test_fifteen_status_commands_are_allowed() -> None:
    host = booted()
    line = b"status_cmd:" + b" battery?" * 15 + b"\n"
    assert host.ask(line) == line
    assert host.ask(b"status?\n") == b"status?" + b" 100" * 15 + b"\n"


@pytest.mark.parametrize(("setup", "line", "reply"), [
    (b"mode: 11\n", b"reboot:\n", b"reboot: error 3"),  # 注記: parking or error mode only
    (b"mode: 8\n", b"shutdown:\n", b"shutdown: error 3"),
    (b"mode: 5\n", b"ad_action: 9\n", b"ad_action: error 3"),  # autonomous actions
])
def test_command_in_the_wrong_state_is_error_3(setup: bytes, line: bytes, reply: bytes) -> None:
    host = booted()
    host.ask(setup)
    assert host.ask(line) == reply + b"\n"


# -- modes ----------------------------------------------------------------------------------------

def test_settable_modes_are_those_of_appendix_g() -> None:
    assert {m for m, (_, settable) in MODES.items() if settable} == {5, 8, 9, 10, 11}
    host = booted()
    for mode in range(13):
        expected = f"mode: {mode}" if mode in (5, 8, 9, 10, 11) else "mode: error 2"
        assert host.ask(f"mode: {mode}\n".encode()) == f"{expected}\n".encode()


def test_error_mode_refuses_mode_changes_until_reboot() -> None:
    host = booted()
    host.ask(b"mode: 11\n")
    host.device.raise_code("0B010000", host.now_s)  # IMU初期化エラー
    assert host.ask(b"mode?\n") == b"mode? 4\n"
    assert host.ask(b"ad_status?\n") == b"ad_status? 7\n"
    assert host.ask(b"error?\n") == b"error? 0B010000\n"
    assert host.ask(b"mode: 5\n") == b"mode: error 3\n"
    assert host.ask(b"reboot:\n") == b"reboot: OK\n"
    assert host.wait() == golden("startup.message")
    assert host.ask(b"error?\n") == b"error? 00000000\n"
    assert host.ask(b"mode?\n") == b"mode? 5\n"


def test_warning_mode_accepts_only_parking_which_clears_the_warning() -> None:
    host = booted()
    host.ask(b"mode: 11\n")
    host.device.raise_code("1B030000", host.now_s)  # 緊急停止ランドマークが検出されました
    assert host.ask(b"ad_status?\n") == b"ad_status? 6\n"
    assert host.ask(b"mode: 11\n") == b"mode: error 3\n"
    assert host.ask(b"reboot:\n") == b"reboot: error 3\n"
    assert host.ask(b"mode: 5\n") == b"mode: 5\n"
    assert host.ask(b"warning?\n") == b"warning? 00000000\n"
    assert host.ask(b"ad_status?\n") == b"ad_status? 1\n"


def test_autonomous_actions_and_speed_limit() -> None:
    host = booted()
    host.ask(b"mode: 11\n")
    assert host.ask(b"speed?\n") == b"speed? 30\n"
    assert host.ask(b"ad_speed_limit: 20\n") == b"ad_speed_limit: 20\n"
    assert host.ask(b"speed?\n") == b"speed? 20\n"
    assert host.ask(b"ad_action: 9\n") == b"ad_action: 9\n"
    assert host.ask(b"ad_action? -p\n") == b"ad_action? 9 130\n"  # デフォルト 130 cm
    assert host.ask(b"ad_status?\n") == b"ad_status? 4\n"
    assert host.ask(b"speed?\n") == b"speed? 0\n"
    assert host.ask(b"ad_action: 14\n") == b"ad_action: 14\n"
    assert host.ask(b"ad_action? -p\n") == b"ad_action? 14\n"
    assert host.ask(b"speed?\n") == b"speed? 20\n"
    assert host.ask(b"ad_speed_limit: 0\n") == b"ad_speed_limit: 0\n"  # 0 stops the vehicle
    assert host.ask(b"speed?\n") == b"speed? 0\n"
    assert host.ask(b"action: 1\n") == b"action: 1\n"
    assert host.ask(b"ad_action?\n") == b"ad_action? 0\n"


# -- the 255-character limit ----------------------------------------------------------------------

def test_a_line_of_255_characters_is_accepted_and_256_is_an_error() -> None:
    host = booted()
    longest = b"echo: " + b"x" * 249
    assert len(longest) == 255
    assert host.ask(longest + b"\n") == longest + b"\n"
    assert host.ask(longest + b"x\n") == b"echo: error 2\n"
    assert host.ask(b"y" * 400 + b"\n") == b"y" * 246 + b": error 1\n"  # reply cut to 255


def test_codec_refuses_lines_over_255_characters() -> None:
    codec = CarriroCodec()
    with pytest.raises(ProtocolError, match="at most 255"):
        codec.encode(Command("echo", ("x" * 250,), "action"))
    with pytest.raises(ProtocolError, match="at most 255"):
        codec.decode(b"echo: " + b"x" * 250)
    with pytest.raises(CarriroError) as caught:
        codec.parse_command(b"echo: " + b"x" * 250 + b"\n")
    assert (caught.value.code, caught.value.command) == (2, "echo")


def test_status_reply_over_255_characters_is_cut() -> None:
    version = ".".join(["1234"] * 9)  # 44 characters
    host = booted(version=version)
    host.ask(b"status_cmd:" + b" version?" * 15 + b"\n")
    full = "status?" + f" {version}" * 15
    reply = host.ask(b"status?\n")
    assert reply == full[:255].encode() + b"\n"


# -- input while busy, start-up, restart ----------------------------------------------------------

def test_input_is_ignored_until_the_reply_is_sent() -> None:
    device = CarriroDevice(processing_s=0.005, startup_s=0.0)
    device.poll(0.0)
    device.receive(b"battery?\nmode?\n", 1.0)  # the second command arrives while busy
    device.receive(b"id?\n", 1.004)  # still before the reply
    assert device.ignored_bytes == len(b"mode?\n") + len(b"id?\n")
    assert rounded(device.poll(1.1)) == [(1.005, b"battery? 100\n")]
    assert device.next_output_s() is None


def test_input_within_10_ms_of_a_reply_is_ignored_by_default() -> None:
    device = CarriroDevice(processing_s=0.005, startup_s=0.0)
    device.poll(0.0)
    device.receive(b"battery?\n", 1.0)
    assert rounded(device.poll(1.005)) == [(1.005, b"battery? 100\n")]
    device.receive(b"mode?\n", 1.010)  # 5 ms after the reply: the host broke the 10 ms rule
    assert device.poll(1.1) == []
    device.receive(b"mode?\n", 1.2)
    assert rounded(device.poll(1.3)) == [(1.205, b"mode? 5\n")]


def test_a_device_without_the_quiet_time_listens_right_after_its_reply() -> None:
    device = CarriroDevice(processing_s=0.005, quiet_after_reply_s=0.0, startup_s=0.0)
    device.poll(0.0)
    device.receive(b"battery?\n", 1.0)
    device.receive(b"mode?\n", 1.005)
    assert [data for _, data in device.poll(1.1)] == [b"battery? 100\n", b"mode? 5\n"]


def test_input_before_the_banner_is_ignored() -> None:
    device = CarriroDevice(startup_s=1.0)
    device.receive(b"battery?\n", 0.5)
    assert device.poll(1.0) == [(1.0, golden("startup.message"))]
    assert device.ignored_bytes == len(b"battery?\n")
    assert device.next_output_s() is None


def test_reboot_restarts_with_the_banner_and_default_settings() -> None:
    host = booted(startup_s=3.0)
    for line in (b"ad_pattern: 7\n", b"comm: 100\n", b"status_cmd: id?\n", b"speed_limit: 5\n"):
        host.ask(line)
    host.device.state.dist_m = 12.0
    assert host.ask(b"reboot:\n") == b"reboot: OK\n"
    reply_s = host.now_s - HOST_GAP_S
    host.device.receive(b"battery?\n", host.now_s)  # during the restart: ignored
    assert host.wait() == golden("startup.message")
    assert host.now_s - HOST_GAP_S == pytest.approx(reply_s + 3.0)
    assert host.ask(b"status?\n") == b"status? 5 0 0 100 1 0 0 255 0\n"
    assert host.ask(b"comm?\n") == b"comm? 0\n"
    assert host.ask(b"ad_speed_limit?\n") == b"ad_speed_limit? 30\n"


def test_shutdown_is_silent_until_power_on() -> None:
    host = booted()
    assert host.ask(b"shutdown:\n") == b"shutdown: OK\n"
    host.device.receive(b"battery?\n", host.now_s)
    assert host.device.poll(host.now_s + 100.0) == []
    assert host.device.next_output_s() is None
    host.device.power_on(host.now_s + 100.0)
    assert host.device.poll(host.now_s + 102.0) == [(host.now_s + 101.0, golden("startup.message"))]


def test_comm_sends_status_periodically_in_simulated_time() -> None:
    host = booted()
    host.device.state.battery_pct = 80
    assert host.ask(b"comm: 20\n") == b"comm: 20\n"
    t0 = host.now_s - HOST_GAP_S
    sent = host.device.poll(t0 + 6.5)
    assert [t - t0 for t, _ in sent] == pytest.approx([2.0, 4.0, 6.0])
    assert {data for _, data in sent} == {b"status? 5 0 0 80 1 0 0 255 0\n"}
    host.now_s = t0 + 6.5
    assert host.ask(b"comm: 0\n") == b"comm: 0\n"
    assert host.device.poll(host.now_s + 60.0) == []


def test_time_must_not_run_backwards() -> None:
    device = CarriroDevice()
    device.poll(5.0)
    with pytest.raises(ValueError, match=r"now_s \(4.0\) must not be earlier"):
        device.receive(b"battery?\n", 4.0)


def test_settings_and_hooks_validate() -> None:
    with pytest.raises(ValueError, match="processing_s"):
        CarriroDevice(processing_s=-1.0)
    with pytest.raises(ValueError, match="12 printable"):
        CarriroDevice(unit_id="0012f337e03")
    with pytest.raises(ValueError, match="dotted version"):
        CarriroDevice(version="v1")
    device = CarriroDevice()
    with pytest.raises(ValueError, match="Error or Warning"):
        device.raise_code("01010000", 0.0)  # Info: キャリロ電源オン
    with pytest.raises(ValueError, match="Appendix F"):
        device.pass_landmark(98, 0.0)


def test_device_survives_any_bytes_and_every_line_it_sends_decodes() -> None:
    rng = random.Random(20220920)
    alphabet = b"abcdemosty_?: -0123456789\n\r\xff"
    device = CarriroDevice(startup_s=0.0, quiet_after_reply_s=0.0)
    codec, now_s, sent = CarriroCodec(), 0.0, []
    for _ in range(3000):
        now_s += rng.choice((0.0, 0.002, 0.02))
        device.receive(bytes(rng.choice(alphabet) for _ in range(rng.randint(1, 12))), now_s)
        sent += device.poll(now_s)
    assert len(sent) > 100
    for _, data in sent:
        [frame] = codec.unframe(bytearray(data))
        assert isinstance(codec.decode(frame), Reply)


# -- codec details --------------------------------------------------------------------------------

@pytest.mark.parametrize("command, line", [
    (Command("ad_speed_limit", (2.0,), "set"), b"ad_speed_limit: 20\n"),
    (Command("ad_speed_limit", (0,), "set"), b"ad_speed_limit: 0\n"),
    (Command("comm", (0.5,), "set"), b"comm: 5\n"),
    (Command("echo", (), "action"), b"echo:\n"),
    (Command("echo", ("a", "", "b"), "action"), b"echo: a  b\n"),
])
def test_codec_scales_values_to_raw_integers(command: Command, line: bytes) -> None:
    codec = CarriroCodec()
    assert codec.encode(command) == line
    assert codec.parse_command(line).args == command.args


@pytest.mark.parametrize("command", [
    Command("ad_speed_limit", (2.05,), "set"),  # not a multiple of 0.1 km/h
    Command("ad_speed_limit", (0.4,), "set"),  # 範囲 0, 5-30
    Command("battery", (50,), "set"),  # get-only
    Command("reboot", (), "get"),  # set-only
    Command("ad_output", (), "get"),  # vehicle message
    Command("status_cmd", ("status?",), "set"),
    Command("mode", (True,), "set"),
    Command("nothing", (), "get"),
])
def test_codec_refuses_to_encode_what_the_vehicle_would_refuse(command: Command) -> None:
    with pytest.raises(ProtocolError):
        CarriroCodec().encode(command)


@pytest.mark.parametrize(("frame", "expected"), [
    (b"speed? 31", "speed_kmh"),
    (b"speed? 2.0", "an integer"),
    (b"ad_action? 4 20", "ad_action"),  # 直進3 is fixed at 30
    (b"ad_action? 17 130 1 12 0", "後退"),  # backwards needs 17-50
    (b"ad_action? 20", "ad_action_id"),  # no action 20 in Appendix B
    (b"ad_action? 5 130", "parameter"),  # all parameters or none
    (b"mode? 13", "mode"),
    (b"error? 1002000", "8 hex digits"),
    (b"status? 10 20", "9 value"),
    (b"hello", "start-up banner"),
    (b"foo? 1", "API reference"),
    (b"battery?73", "space"),
    (b"battery? \xb7", "printable"),
])
def test_codec_decode_names_the_bytes_and_what_was_expected(frame: bytes, expected: str) -> None:
    with pytest.raises(ProtocolError, match=expected) as caught:
        CarriroCodec().decode(frame)
    assert caught.value.data == frame
    assert repr(frame) in str(caught.value)


def test_appendix_b_actions_decode_with_their_parameters() -> None:
    codec = CarriroCodec()
    assert codec.decode(b"ad_action? 13 10101 00001 25 255").args == (13, "10101", "00001", 2.5,
                                                                         255)
    assert codec.decode(b"ad_action? 30 130 0 -50 4").args == (30, 130, 0, -5.0, 4)
    assert codec.decode(b"ad_action? 34 13 1 100 0").args == (34, 1.3, 1, 10.0, 0)
    assert codec.decode(b"ad_action? 19 255 8").args == (19, 25.5, 8)
    assert codec.decode(b"ad_action? 37").args == (37,)


def test_codec_decodes_error_replies_of_any_command() -> None:
    codec = CarriroCodec()
    assert codec.decode(b"mode: error 3") == Reply("mode", ERROR, (3,))
    assert codec.decode(b"\\xffx: error 1") == Reply("\\xffx", ERROR, (1,))
    with pytest.raises(ProtocolError):
        codec.decode(b"mode: error 4")


def test_unframe_cuts_complete_lines_and_keeps_the_rest() -> None:
    buffer = bytearray(b"battery? 73\nmode? 5\nspe")
    assert CarriroCodec().unframe(buffer) == [b"battery? 73", b"mode? 5"]
    assert buffer == bytearray(b"spe")


def test_status_layout_must_be_a_valid_status_cmd_list() -> None:
    with pytest.raises(ProtocolError):
        CarriroCodec(("status?",))
    assert CarriroCodec(("pallet?", "id?")).decode(b"status? 1 0 0012f337e03c").args == (
        1, 0, "0012f337e03c")


# -- tables and registry --------------------------------------------------------------------------

def test_appendix_tables() -> None:
    assert set(SETTABLE_AD_ACTIONS) == {0, 9, 14, 16}
    assert set(SETTABLE_AD_ACTIONS) <= set(AD_ACTIONS)
    assert {20, 22, 23}.isdisjoint(AD_ACTIONS) and set(range(35, 40)) <= set(AD_ACTIONS)
    assert (LANDMARKS[8], LANDMARKS[20], LANDMARKS[46], LANDMARKS[97]) == ("一時停止", "A",
                                                                            "A1", "Z2")
    assert len(LANDMARKS) == 99
    assert len(CODES) == 132
    assert describe_code("10020000") == ("Error", "リモートIMU通信タイムアウト")
    assert describe_code("258100AB") == ("Error", "BMS CPU自己診断エラー")
    assert describe_code("1B010000") == ("Warning", "ランドマークが検出されませんでした")
    assert describe_code("7FFFFFFF") is None


_CM = (1, ((50, 255),), 130)  # 停止距離 (単位: センチメートル), 範囲 50-255, デフォルト 130
_ACT = (1, ((0, 4),), None)  # アクション 0-4
_DIR = (1, ((0, 1),), None)  # 方向 0 前進, 1 後退
_TEXT = "text"
APPENDIX_B: dict[int, tuple[Any, ...]] = {  # action ID -> (倍率, 範囲, デフォルト) per parameter
    0: (), 1: ((10, ((5, 30),), None),), 2: ((10, ((10, 10),), None),),
    3: ((10, ((20, 20),), None),), 4: ((10, ((30, 30),), None),),
    5: (_CM, (1, ((10, 180),), 90)), 6: (_CM, (1, ((10, 180),), 90)),
    7: (_CM, (1, ((180, 180),), None)), 8: (_CM, (1, ((180, 180),), None)),
    9: (_CM,), 10: ((1, ((5, 60),), None),),
    11: ((10, ((10, 30),), 10),), 12: ((10, ((10, 30),), 10),),
    13: (_TEXT, _TEXT, (10, ((0, 255),), None), (1, ((0, 255),), None)),
    14: (), 15: (), 16: (),
    17: (_CM, _DIR, (10, ((12, 50),), None), _ACT),
    18: (_CM, _DIR, (10, ((0, 50),), None), _ACT),
    19: ((10, ((0, 255),), None), (1, ((0, 19), (255, 255)), None)),
    21: (_CM,), 24: (), 25: (), 26: (), 27: (), 28: (),
    29: (_CM, (1, ((1, 4),), None), (1, ((0, 7),), None), (1, ((0, 250),), None)),
    30: (_CM, _ACT, (10, ((-50, 50),), None), _ACT),
    31: ((10, ((-50, 50),), None), _ACT, (10, ((-80, 80),), None), _ACT),
    32: (), 33: ((1, ((50, 5000),), None),),
    34: ((10, ((5, 80),), 13), _DIR, (10, ((12, 100),), None), _ACT),
    35: (), 36: (), 37: (), 38: (), 39: (),
}


def test_appendix_b_action_table_matches_the_document() -> None:
    assert set(AD_ACTIONS) == set(APPENDIX_B)
    for action_id, expected in APPENDIX_B.items():
        actual = tuple(_TEXT if isinstance(f, TextField) else (f.scale, f.ranges, f.default)
                       for f in AD_ACTIONS[action_id].params)
        assert actual == expected, f"Appendix B action {action_id}"


def test_appendix_d_and_g_codes() -> None:
    assert list(AD_STATUSES) == list(range(1, 8))
    assert (AD_STATUSES[2], AD_STATUSES[7]) == ("移動中", "エラーモード")
    assert list(MODES) == list(range(13))
    assert (MODES[5][0], MODES[10][0], MODES[11][0]) == ("パーキング", "右Uターン", "自律")


def test_owner_may_set_the_status_list_in_state() -> None:
    host = booted()
    host.device.state.status_cmds = ("pallet?", "speed_limit?")
    assert host.ask(b"status?\n") == b"status? 0 0 30\n"


def test_registered_by_name() -> None:
    assert isinstance(get_codec("carriro"), CarriroCodec)
    device = get_device("carriro", startup_s=0.0)
    assert isinstance(device, CarriroDevice)
    assert device.poll(0.0) == [(0.0, golden("startup.message"))]


def test_agv_model_never_imports_fleet_sim() -> None:
    code = ("import sys, agv_model.protocols.carriro; "
            "sys.exit(any(m.split('.')[0] == 'fleet_sim' for m in sys.modules))")
    assert subprocess.run([sys.executable, "-c", code], check=False).returncode == 0


# -- over a real pseudo-terminal ------------------------------------------------------------------

def _serve(master: int, device: CarriroDevice, now_s: float, steps: int) -> float:
    """Drive the device in simulated 1 ms steps, moving bytes to and from the pty master, until it
    has sent something or `steps` run out. select() only bounds the wait for the host's bytes."""
    for _ in range(steps):
        readable, _, _ = select.select([master], [], [], 0.01)
        if readable:
            device.receive(os.read(master, 1024), now_s)
        sent = device.poll(now_s)
        for _, data in sent:
            os.write(master, data)
        now_s += 0.001
        if sent:
            return now_s
    raise AssertionError("the device sent nothing")


def test_command_and_reply_over_a_pseudo_terminal() -> None:
    master, slave = os.openpty()
    port = serial.Serial(os.ttyname(slave), baudrate=19200, bytesize=serial.EIGHTBITS,
                         parity=serial.PARITY_EVEN, stopbits=serial.STOPBITS_ONE, timeout=5.0)
    try:
        device = CarriroDevice(startup_s=0.0)
        device.state.battery_pct = 73
        now_s = _serve(master, device, 0.0, steps=10)
        assert port.readline() == golden("startup.message")
        port.write(golden("battery.request"))
        port.flush()
        now_s = _serve(master, device, now_s, steps=500)
        assert port.readline() == golden("battery.reply")
        codec = CarriroCodec()
        port.write(codec.encode(Command("status_cmd", STATUS_CMD_EXAMPLE, "set")))
        now_s = _serve(master, device, now_s + HOST_GAP_S, steps=500)
        assert codec.decode(port.readline()) == EXPECTED_REPLIES["status_cmd_set"]
    finally:
        port.close()
        os.close(master)
        os.close(slave)
