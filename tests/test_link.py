"""Link timing against hand computation from the documents' physical settings.

Every time here is simulated; the expected figures are worked out by hand in the comments.
"""

from __future__ import annotations

import subprocess
import sys
from typing import Any

import numpy as np
import pytest
from pydantic import ValidationError

from agv_model.link import Exchange, Jitter, Link, LinkSettings, exchange_once
from agv_model.profile import load_profile
from agv_model.protocols import Command
from agv_model.protocols.carriro import CarriroDevice, CarriroState
from userfiles.checking import InputError, validate

from .conftest import golden_bytes

CARRIRO = LinkSettings(baud=19200, data_bits=8, parity="even", stop_bits=1, processing_s=0.005,
                       host_gap_s=0.010)
CHAR_S = 11 / 19200  # CarriRo インターフェイス仕様: start + 8 data + even parity + 1 stop


def carriro_link(settings: LinkSettings = CARRIRO, battery_pct: int = 73) -> Link:
    device = CarriroDevice(processing_s=0.005, state=CarriroState(battery_pct=battery_pct))
    return Link("carriro", settings, device=device)


@pytest.mark.parametrize(("data_bits", "parity", "stop_bits", "bits"), [
    (8, "even", 1, 11), (8, "none", 1, 10), (7, "odd", 2, 11), (8, "none", 1.5, 10.5),
    (5, "mark", 1, 8),
])
def test_bits_per_character(data_bits: int, parity: Any, stop_bits: float, bits: float) -> None:
    settings = LinkSettings(baud=9600, data_bits=data_bits, parity=parity, stop_bits=stop_bits)
    assert settings.bits_per_char == bits
    assert settings.transfer_s(3) == pytest.approx(3 * bits / 9600, abs=1e-15)


def test_carriro_profile_is_11_bits_at_19200_baud() -> None:
    link = load_profile("carriro-ad-plus").link
    assert (link.baud, link.bits_per_char, link.host_gap_s) == (19200, 11, 0.010)
    assert link.char_s == CHAR_S


def test_carriro_battery_example_takes_the_hand_computed_time() -> None:
    # battery? example (battery?): 9 bytes out, "battery? 73\n" 12 bytes back.
    # (9 + 12) * 11 / 19200 = 0.01203125 s on the wire, + 5 ms processing = 0.01703125 s.
    request = golden_bytes("carriro", "battery.request")
    link = carriro_link()
    exchange = link.exchange(Command("battery", (), "get"))
    assert exchange.command == request == b"battery?\n"
    assert exchange.reply == golden_bytes("carriro", "battery.reply") == b"battery? 73\n"
    assert (exchange.tx_bytes, exchange.rx_bytes) == (9, 12)
    assert exchange.tx_s == 9 * CHAR_S
    assert exchange.rx_s == 12 * CHAR_S
    assert exchange.processing_s == pytest.approx(0.005, abs=1e-12)
    assert exchange.reply_s == pytest.approx(0.01703125, abs=1e-12)
    assert not exchange.timed_out
    assert exchange.breakdown()["reply_s"] == exchange.reply_s


def test_the_device_start_up_banner_is_drained_before_the_first_command() -> None:
    link = carriro_link()
    assert link.unsolicited == [(1.0, b"CarriRo AD+ 1.16.0.2\n")]
    # the banner's 21 characters, then the 10 ms gap
    assert link.ready_s == pytest.approx(1.0 + 21 * CHAR_S + 0.010, abs=1e-12)


def test_the_host_waits_10_ms_after_each_reply() -> None:
    link = carriro_link()
    first = link.exchange(b"comm?\n")
    second = link.exchange(b"battery?\n")
    assert first.gap_s == 0.010
    assert second.sent_s == pytest.approx(first.sent_s + first.reply_s + 0.010, abs=1e-12)
    assert first.ready_s == pytest.approx(second.sent_s, abs=1e-12)
    assert (first.reply, second.reply) == (b"comm? 0\n", b"battery? 73\n")


def test_a_host_that_skips_the_gap_loses_the_start_of_its_next_command() -> None:
    # 処理: the vehicle ignores input until the reply is out; it still ignores it 10 ms later.
    link = carriro_link(LinkSettings(baud=19200, data_bits=8, parity="even", stop_bits=1,
                                     processing_s=0.005, host_gap_s=0.0))
    assert link.exchange(b"battery?\n").reply == b"battery? 73\n"
    late = link.exchange(b"battery?\n")
    assert late.reply.endswith(b": error 1\n") and late.reply != b"battery? 73\n"
    assert isinstance(link.device, CarriroDevice) and link.device.ignored_bytes > 0


def test_a_command_sent_early_waits_for_the_host_gap() -> None:
    link = carriro_link()
    first = link.exchange(b"comm?\n")
    second = link.exchange(b"comm?\n", at_s=first.sent_s)
    assert second.sent_s == pytest.approx(first.ready_s, abs=1e-12)


AGV3 = LinkSettings(baud=9600, processing_s=0.010, reply_timeout_s=0.25)


def test_agv3_reply_inside_the_timeout() -> None:
    exchange = exchange_once("agv3", b"*IDN?\r\n", AGV3)
    # 7 + 7 characters of 10 bits at 9600 baud, + 10 ms
    assert exchange.reply == b"AGV-3\r\n"
    assert exchange.reply_s == pytest.approx(14 * 10 / 9600 + 0.010, abs=1e-12)
    assert not exchange.timed_out


@pytest.mark.parametrize("settings", [
    LinkSettings(baud=9600, processing_s=0.3, reply_timeout_s=0.25),
    LinkSettings(baud=9600, processing_s=0.010, reply_timeout_s=0.25, latency_s=0.13),
    LinkSettings(baud=9600, processing_s=0.010, reply_timeout_s=0.25,
                 jitter=Jitter(distribution="uniform", low_s=0.3, high_s=0.4)),
])
def test_agv3_reply_slower_than_0_25_s_is_a_timeout(settings: LinkSettings) -> None:
    # Syntax: "Om inget returneras inom 0.25s så får det antas som ett fel"
    exchange = exchange_once("agv3", b"*IDN?\r\n", settings, seed=1)
    assert exchange.timed_out
    assert exchange.reply_s == pytest.approx(7 * 10 / 9600 + 0.25, abs=1e-12)
    assert exchange.ready_s == pytest.approx(exchange.sent_s + exchange.reply_s, abs=1e-12)


def test_agv3_profile_carries_the_documented_timeout() -> None:
    link = load_profile("agv-3").link
    assert link.reply_timeout_s == 0.25
    assert not exchange_once("agv3", b"*IDN?\r\n", link).timed_out


def test_no_reply_at_all_is_a_timeout() -> None:
    # TABO answers nothing to an unknown command (tabo.py decision 9).
    exchange = exchange_once("tabo", b"FOO\n", LinkSettings(baud=115200, reply_timeout_s=1.0))
    assert exchange.timed_out and exchange.reply == b""
    assert exchange.processing_s == float("inf")
    assert exchange.reply_s == pytest.approx(4 * 10 / 115200 + 1.0, abs=1e-12)


def test_the_reply_is_what_the_device_sends_at_once_not_a_later_fin() -> None:
    # TABO MLL: ACK:m now, FIN:m when the distance is done (10 s later): only ACK:m counts.
    settings = LinkSettings(baud=115200, processing_s=0.02)
    exchange = exchange_once("tabo", b"MLL:100,1000\n", settings)
    assert exchange.reply == b"ACK:m\n"
    assert exchange.reply_s == pytest.approx((13 + 6) * 10 / 115200 + 0.02, abs=1e-12)


def test_ktm02_request_gets_ack_and_data_frame_in_one_reply() -> None:
    settings = LinkSettings(baud=115200, processing_s=0.005)
    exchange = exchange_once("ktm02", Command("RequestStatusCmd"), settings)
    assert exchange.command[0] == 0xAA and exchange.tx_bytes == 7
    assert exchange.reply[0] == 0xAA and exchange.rx_bytes == 16  # ACK (8) + SendStatusCmd (8)
    assert exchange.reply_s == pytest.approx((7 + 16) * 10 / 115200 + 0.005, abs=1e-12)


def test_radio_latency_counts_once_each_way() -> None:
    settings = LinkSettings(baud=115200, processing_s=0.02, latency_s=0.0075)
    exchange = exchange_once("tabo", b"GBI\n", settings)
    assert exchange.reply == b"gbi:100\n"
    assert exchange.reply_s == pytest.approx((4 + 8) * 10 / 115200 + 0.02 + 0.015, abs=1e-12)


def jittered_times(seed: int, count: int = 6) -> list[float]:
    settings = LinkSettings(baud=115200, processing_s=0.02,
                            jitter=Jitter(distribution="uniform", low_s=0.0, high_s=0.030))
    link = Link("tabo", settings, rng=np.random.default_rng(seed))
    return [link.exchange(b"GBI\n").jitter_s for _ in range(count)]


def test_jitter_is_reproducible_with_a_seed() -> None:
    assert jittered_times(7) == jittered_times(7)
    assert jittered_times(7) != jittered_times(8)
    assert all(0.0 <= j <= 0.030 for j in jittered_times(7))
    assert len(set(jittered_times(7))) > 1


@pytest.mark.parametrize("jitter", [
    Jitter(distribution="normal", mean_s=0.001, sd_s=0.01),
    Jitter(distribution="exponential", mean_s=0.005),
    Jitter(distribution="uniform", low_s=0.002, high_s=0.004),
])
def test_jitter_draws_are_never_negative(jitter: Jitter) -> None:
    rng = np.random.default_rng(3)
    draws = [jitter.draw_s(rng) for _ in range(200)]
    assert min(draws) >= 0 and max(draws) > 0


def test_no_jitter_draws_nothing() -> None:
    rng = np.random.default_rng(5)
    assert Jitter().draw_s(rng) == 0.0
    assert rng.random() == np.random.default_rng(5).random()


@pytest.mark.parametrize(("settings", "element", "value", "expected"), [
    ({"baud": 0}, "baud", 0, "an integer > 0"),
    ({"baud": -9600}, "baud", -9600, "an integer > 0"),
    ({"baud": 9600.5}, "baud", 9600.5, "an integer"),
    ({"baud": "19200"}, "baud", "19200", "an integer"),
    ({"baud": True}, "baud", True, "an integer"),
    ({}, "baud", None, "a value for required key 'baud'"),
    ({"baud": 9600, "data_bits": 9}, "data_bits", 9, "one of 5, 6, 7, 8"),
    ({"baud": 9600, "parity": "E"}, "parity", "E", "one of 'none', 'even', 'odd', 'mark', 'space'"),
    ({"baud": 9600, "stop_bits": 3}, "stop_bits", 3.0, "1, 1.5 or 2"),
    ({"baud": 9600, "stop_bits": True}, "stop_bits", True, "a number"),
    ({"baud": 9600, "latency_s": -0.1}, "latency_s", -0.1, "a number >= 0"),
    ({"baud": 9600, "processing_s": float("nan")}, "processing_s", None, "a finite number"),
    ({"baud": 9600, "reply_timeout_s": float("inf")}, "reply_timeout_s", float("inf"),
     "a finite number"),
    ({"baud": 9600, "host_gap_s": "10ms"}, "host_gap_s", "10ms", "a number"),
    ({"baud": 9600, "jitter": {"distribution": "gauss"}}, "jitter.distribution", "gauss",
     "one of 'none', 'uniform', 'normal', 'exponential'"),
    ({"baud": 9600, "jitter": {"distribution": "uniform", "low_s": 0.2, "high_s": 0.1}},
     "jitter.high_s", 0.1, "at least low_s (0.2)"),
    ({"baud": 9600, "jitter": {"distribution": "normal", "sd_s": -1}}, "jitter.sd_s", -1,
     "a number >= 0"),
    ({"baud": 9600, "jitter": {"spread_s": 1}}, "jitter.spread_s", 1,
     "no such key here: did you mean 'sd_s'? (known keys: distribution, low_s, high_s, mean_s, "
     "sd_s)"),
])
def test_bad_settings_are_rejected(settings: dict[str, Any], element: str, value: object,
                                   expected: str) -> None:
    with pytest.raises(InputError) as info:
        validate(LinkSettings, settings, "link.yaml")
    assert (info.value.file, info.value.element, info.value.expected) == (
        "link.yaml", element, expected)
    if value is not None:  # nan != nan
        assert info.value.value == value and type(info.value.value) is type(value)
    assert str(info.value).startswith(f"link.yaml: {element}: got ")


def test_settings_built_in_code_are_checked_too() -> None:
    with pytest.raises(ValidationError, match="baud"):
        LinkSettings(baud=0)
    with pytest.raises(ValidationError, match="high_s"):
        Jitter(distribution="uniform", low_s=0.2, high_s=0.1)


def test_unknown_protocol_is_rejected() -> None:
    with pytest.raises(KeyError, match="unknown protocol 'modbus'"):
        Link("modbus", CARRIRO)


def test_exchange_is_frozen() -> None:
    exchange = exchange_once("agv3", b"*IDN?\r\n", AGV3)
    assert isinstance(exchange, Exchange)
    with pytest.raises(AttributeError):
        exchange.tx_s = 0.0  # type: ignore[misc]


def test_agv_model_never_imports_fleet_sim() -> None:
    code = ("import sys, agv_model.link, agv_model.profile, agv_model.emulate; "
            "print([m for m in sys.modules if m.split('.')[0] == 'fleet_sim'])")
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                            check=True, timeout=60)
    assert result.stdout.strip() == "[]"
