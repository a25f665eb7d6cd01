"""TABO codec and virtual device (TABO robot command sheet)."""

from __future__ import annotations

from typing import Any

import pytest

from agv_model.protocols import Command, ProtocolError, Reply, get_codec, get_device
from agv_model.protocols.tabo import Settings, TaboCodec, TaboDevice

from .conftest import GOLDEN, golden_bytes

CASES = sorted(p.stem for p in (GOLDEN / "tabo").glob("*.in"))


def talk(device: TaboDevice, *lines: str, at_s: float = 0.0, until_s: float | None = None,
         ) -> list[tuple[float, str]]:
    """Send lines at at_s; return what the device sent up to until_s (default at_s + 1)."""
    for line in lines:
        device.receive(line.encode("ascii") + b"\n", at_s)
    end_s = at_s + 1.0 if until_s is None else until_s
    return [(t, data.decode("ascii")) for t, data in device.poll(end_s)]


def texts(outputs: list[tuple[float, str]]) -> list[str]:
    return [text.rstrip("\n") for _, text in outputs]


# -- golden exchanges from the sheet -------------------------------------------------------


@pytest.mark.parametrize("case", CASES)
def test_documented_example_exchange(case: str) -> None:
    battery = int(case.split("_")[1]) if case.startswith("GBI") else 100
    device = TaboDevice(battery_pct=battery)
    device.receive(golden_bytes("tabo", f"{case}.in"), 0.0)
    sent = b"".join(data for _, data in device.poll(1000.0))
    assert sent == golden_bytes("tabo", f"{case}.out")


@pytest.mark.parametrize("case", CASES)
def test_documented_example_parses_and_re_encodes(case: str) -> None:
    codec = TaboCodec()
    wire = golden_bytes("tabo", f"{case}.in")
    (frame,) = codec.unframe(bytearray(wire))
    assert codec.encode(codec.parse_command(frame)) == wire


@pytest.mark.parametrize("case", CASES)
def test_documented_replies_decode_and_re_encode(case: str) -> None:
    codec = TaboCodec()
    wire = golden_bytes("tabo", f"{case}.out")
    frames = codec.unframe(bytearray(wire))
    assert b"".join(codec.encode_reply(codec.decode(f)) for f in frames) == wire


def test_parsed_arguments() -> None:
    codec = TaboCodec()
    assert codec.parse_command(b"MLL:-200,-1000") == Command("MLL", (-200, -1000))
    assert codec.parse_command(b"BDL:20,-20,050") == Command("BDL", (20, -20, (0, 5, 0)))
    assert codec.parse_command(b"SDN:TABO04(04)\0") == Command("SDN", ("TABO04(04)",), "set")
    assert codec.parse_command(b"GBI") == Command("GBI", (), "get")
    assert codec.parse_command(b"Xanything at all") == Command("X")


def test_value_replies_decode() -> None:
    codec = TaboCodec()
    assert codec.decode(b"gbi:005") == Reply("GBI", "value", (5,))
    assert codec.decode(b"gsv:33,-38") == Reply("GLV", "value", (33, -38))
    assert codec.decode(b"gsd:0,33") == Reply("GLD", "value", (0, 33))
    assert codec.decode(b"v01.02.03 (16/04/01)") == Reply("GVI", "value", (1, 2, 3, "16/04/01"))


@pytest.mark.parametrize(("frame", "expected"), [
    (b"ACK:q", "group letter"),
    (b"gbi:50", "gbi:NNN"),
    (b"v1.2.3", "vAA.BB.CC"),
])
def test_bad_replies_raise(frame: bytes, expected: str) -> None:
    with pytest.raises(ProtocolError, match=expected):
        TaboCodec().decode(frame)


@pytest.mark.parametrize(("frame", "expected"), [
    (b"MLX:1", "a command in X, CES"),
    (b"MLI:fast", "an integer for MLI argument 1"),
    (b"MLL:100", "2 arguments for MLL"),
    (b"BDL:1,1,90", "three digits"),
    (b"MLI:\xff", "ASCII text"),
])
def test_malformed_commands_raise_naming_the_bytes(frame: bytes, expected: str) -> None:
    with pytest.raises(ProtocolError, match=expected) as err:
        TaboCodec().parse_command(frame)
    assert repr(frame) in str(err.value)


def test_unframe_accepts_crlf_and_keeps_partial_lines() -> None:
    buffer = bytearray(b"MLI:60\r\nGBI\n\nMTI:")
    assert TaboCodec().unframe(buffer) == [b"MLI:60", b"GBI"]
    assert buffer == bytearray(b"MTI:")


def test_registered_by_name() -> None:
    assert isinstance(get_codec("tabo"), TaboCodec)
    assert isinstance(get_device("tabo", reply_delay_s=0.0), TaboDevice)


# -- clamping and sign rules ---------------------------------------------------------------


@pytest.mark.parametrize(("line", "wheels", "turn"), [
    ("MLI:500", (410, 410), 0),
    ("MDD:-9999,200", (-410, 200), 0),
    ("MTI:2000", (0, 0), 1080),
    ("MTI:-1081", (0, 0), -1080),
])
def test_out_of_range_speeds_are_clamped(line: str, wheels: tuple[int, int], turn: int) -> None:
    device = TaboDevice(step_rule_reply="ack")
    if wheels[0] > 0:
        talk(device, "MLI:200")  # step up first: 0 -> 410 would break the 300 rule
    elif wheels[0] < 0:
        talk(device, "MDD:-200,0")
    at = device.next_output_s() or 0.0
    assert texts(talk(device, line, at_s=at + 1)) == ["ACK:m"]
    assert (device.wheels_mmps, device.turn_dps) == (wheels, turn)


def test_clamped_mll_speed_sets_the_fin_time() -> None:
    device = TaboDevice(reply_delay_s=0.0)
    talk(device, "MLI:200")
    out = talk(device, "MLL:900,820", at_s=1.0, until_s=10.0)  # 900 -> 410 mm/s: 2 s
    assert out == [(1.0, "ACK:m\n"), (pytest.approx(3.0), "FIN:m\n")]


@pytest.mark.parametrize("line", ["MLL:0,100", "MLL:100,0", "MLL:100,-100", "MLL:-100,100",
                                  "MTL:0,90", "MTL:90,0", "MTL:-90,90", "MTL:90,-90"])
def test_zero_or_sign_mismatch_is_refused(line: str) -> None:
    device = TaboDevice()
    assert texts(talk(device, line, until_s=100.0)) == ["NAK:m"]
    assert (device.wheels_mmps, device.turn_dps) == ((0, 0), 0)


def test_settings_are_clamped_to_99() -> None:
    device = TaboDevice()
    talk(device, "SLV:150,-150", "STD:-100,5")
    assert device.settings.line_speed == (99, -99)
    assert device.settings.turn_distance == (-99, 5)


def test_led_levels_are_clamped_and_in_rgb_order() -> None:
    device = TaboDevice(reply_delay_s=0.0)
    talk(device, "LSI:1,0,128,0", "LSI:2,300,-5,7")
    assert device.led_rgb(1.0) == ((0, 128, 0), (255, 0, 7))
    assert texts(talk(device, "LSI:3,0,0,0", at_s=2.0)) == ["NAK:l"]


# -- the 300 mm/s step rule ----------------------------------------------------------------


def test_step_of_300_or_more_is_not_followed_but_acknowledged() -> None:
    device = TaboDevice(reply_delay_s=0.0)
    assert texts(talk(device, "MLI:300")) == ["ACK:m"]
    assert device.wheels_mmps == (0, 0)
    assert texts(talk(device, "MLI:205", "MLI:410", at_s=1.0)) == ["ACK:m", "ACK:m"]
    assert device.wheels_mmps == (410, 410)  # "(0 → 205 → 410) と段階を踏んで加速"


def test_step_rule_can_answer_nak() -> None:
    device = TaboDevice(step_rule_reply="nak")
    assert texts(talk(device, "MLI:299", "MDD:0,2")) == ["ACK:m", "ACK:m"]
    assert texts(talk(device, "MDD:-300,2", "MLL:-400,-10", at_s=1.0)) == ["NAK:m", "NAK:m"]
    assert device.wheels_mmps == (0, 2)


def test_step_rule_blocks_a_distance_run_and_its_fin() -> None:
    device = TaboDevice()
    assert texts(talk(device, "MLL:400,1000", until_s=100.0)) == ["ACK:m"]
    assert device.wheels_mmps == (0, 0)


def test_stop_is_always_followed() -> None:
    device = TaboDevice()
    talk(device, "MLI:205", "MLI:410")
    talk(device, "MLI:0", at_s=1.0)
    assert device.wheels_mmps == (0, 0)


# -- FIN timing in simulated time ----------------------------------------------------------


def test_fin_m_when_the_distance_is_done() -> None:
    device = TaboDevice(reply_delay_s=0.02)
    out = talk(device, "MLL:100,1000", at_s=5.0, until_s=5.5)
    assert out == [(pytest.approx(5.02), "ACK:m\n")]
    assert device.next_output_s() == pytest.approx(15.02)
    assert device.poll(15.01) == []
    assert device.wheels_mmps == (100, 100)
    assert device.poll(15.02) == [(pytest.approx(15.02), b"FIN:m\n")]
    assert device.wheels_mmps == (0, 0)
    assert device.next_output_s() is None


def test_fin_m_for_an_angle_uses_the_turn_distance_correction() -> None:
    device = TaboDevice(reply_delay_s=0.0)
    talk(device, "STD:0,100")  # counter-clockwise +9.9 % (clamped to 99)
    talk(device, "MTL:-10,-100", at_s=1.0, until_s=1.0)
    assert device.next_output_s() == pytest.approx(1.0 + 10 * 1.099)


def test_a_new_motor_command_cancels_the_fin() -> None:
    device = TaboDevice(reply_delay_s=0.0)
    talk(device, "MLL:100,1000")
    assert texts(talk(device, "MLI:50", at_s=2.0, until_s=60.0)) == ["ACK:m"]


def test_bhl_stops_a_distance_run_and_nak_when_idle() -> None:
    device = TaboDevice(reply_delay_s=0.0)
    talk(device, "MLL:100,1000")
    assert texts(talk(device, "BHL", at_s=2.0, until_s=60.0)) == ["ACK:b"]
    assert device.wheels_mmps == (0, 0)
    assert texts(talk(device, "BHL", at_s=61.0)) == ["NAK:b"]


def test_x_stops_everything_and_cancels_fin() -> None:
    device = TaboDevice(reply_delay_s=0.0)
    talk(device, "MLL:100,1000", "LAL:5000,16,0,16", "BWT:1")
    assert texts(talk(device, "Xyz", at_s=1.0, until_s=60.0)) == ["ACK:x"]
    assert (device.wheels_mmps, device.waiting, device.led_rgb(60.0)) == (
        (0, 0), False, ((0, 0, 0), (0, 0, 0)))


def test_lal_fades_linearly_then_sends_fin_l() -> None:
    device = TaboDevice(reply_delay_s=0.0)
    talk(device, "LAI:0,0,0", "LAL:5000,16,0,16")
    assert device.led_rgb(2.5) == ((8, 0, 8), (8, 0, 8))
    assert device.poll(5.0) == [(5.0, b"FIN:l\n")]
    assert device.led_rgb(9.0) == ((16, 0, 16), (16, 0, 16))


# -- memory, sleep and reset ---------------------------------------------------------------


def test_getters_return_boot_values_until_a_restart() -> None:
    device = TaboDevice(reply_delay_s=0.0, reboot_time_s=3.0)
    talk(device, "SLV:33,-38", "SDN:TABO04(04)\0")
    assert texts(talk(device, "GLV", at_s=1.0)) == ["gsv:0,0"]
    assert device.settings.line_speed == (33, -38)
    assert talk(device, "CER", at_s=2.0) == []
    assert texts(talk(device, "GLV", at_s=3.0)) == []  # still rebooting: ignored
    assert texts(talk(device, "GLV", at_s=6.0)) == ["gsv:33,-38"]
    assert device.advertised_name == "TABO04(04)"


def test_cmr_restores_factory_values_at_the_next_restart() -> None:
    stored = Settings(line_distance=(5, 6), name="OLD")
    device = TaboDevice(reply_delay_s=0.0, stored=stored)
    assert texts(talk(device, "GLD", "CMR")) == ["gsd:5,6", "ACK:c"]
    talk(device, "CES", at_s=1.0)
    assert device.asleep
    assert talk(device, "GLD", at_s=2.0) == []
    device.wake(3.0)
    assert texts(talk(device, "GLD", "GTD", at_s=3.0)) == ["gsd:0,0", "gtd:0,0"]
    assert device.advertised_name == "TABO"


def test_version_and_battery() -> None:
    device = TaboDevice(version=(2, 10, 3, "16/04/01"), battery_pct=7)
    assert texts(talk(device, "GVI", "GBI")) == ["v02.10.03 (16/04/01)", "gbi:007"]


def test_unknown_and_malformed_lines() -> None:
    device = TaboDevice(reply_delay_s=0.0)
    out = texts(talk(device, "HELLO", "MLI:abc", "SLV:1", "GBI:3", "LAL:-1,0,0,0"))
    assert out == ["NAK:m", "NAK:s", "NAK:l"]
    assert [line for _, line in device.ignored] == [b"HELLO", b"GBI:3"]


def test_replies_queue_behind_each_other() -> None:
    device = TaboDevice(reply_delay_s=0.02)
    out = talk(device, "GBI", "GBI", "GBI")
    assert [t for t, _ in out] == pytest.approx([0.02, 0.04, 0.06])


def test_exchange_over_a_pseudo_terminal(pty_link: Any) -> None:
    link = pty_link(TaboDevice(reply_delay_s=0.02))
    answer = link.exchange(golden_bytes("tabo", "MLL_100_1000.in"),
                           lambda got: got.count(b"\n") >= 2, step_s=0.05)
    assert answer == golden_bytes("tabo", "MLL_100_1000.out")
    assert link.now_s == pytest.approx(10.07, abs=0.06)  # 1000 mm at 100 mm/s, simulated
