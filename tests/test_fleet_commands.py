"""Fleet commands on the real link: the messages per protocol, their base times checked by hand,
jitter draws, timeouts and the polling delay. Simulated time only, no wall clock."""

from __future__ import annotations

import math

import numpy as np
import pytest

from agv_model.fleet_commands import (
    GENERIC_MESSAGE_BYTES,
    KINDS,
    MESSAGES,
    Attempt,
    CommandTiming,
    timeout_margin_s,
)
from agv_model.link import Jitter, Link
from agv_model.profile import load_profile, profile_names
from agv_model.protocols import get_codec, names

PROTOCOL_PROFILES = [n for n in profile_names() if load_profile(n).protocol is not None]


def test_carriro_status_round_trip_by_hand() -> None:
    # インターフェイス仕様: 19200 bps, 8 data bits, even parity, 1 stop bit = 11 bits a character;
    # 処理: the host waits 10 ms after the reply; 5 ms processing is the profile's assumption.
    link = load_profile("carriro-ad-plus").link
    assert (link.baud, link.bits_per_char, link.processing_s, link.host_gap_s) == (
        19200, 11, 0.005, 0.010)
    timing = CommandTiming.for_profile("carriro-ad-plus")
    (exchange,) = timing.exchanges["status"]
    request, reply = b"status?\n", b"status? 11 30 0 100 2 1 4 255 0\n"  # while driving
    assert (exchange.command, exchange.reply) == (request, reply)
    char_s = 11 / 19200
    reply_s = len(request) * char_s + 0.005 + len(reply) * char_s  # 8 + 32 characters
    assert timing.reply_s("status") == pytest.approx(reply_s)
    assert timing.round_trip_s("status") == pytest.approx(reply_s + 0.010)
    assert timing.round_trip_s("status") == pytest.approx(0.0379167, abs=1e-7)


def test_carriro_assign_sums_both_messages() -> None:
    timing = CommandTiming.for_profile("carriro-ad-plus")
    char_s = 11 / 19200
    lines = [b"ad_pattern: 1\n", b"mode: 11\n"]  # each reply repeats its line
    assert [e.command for e in timing.exchanges["assign"]] == lines
    by_hand = sum(2 * len(line) * char_s + 0.005 + 0.010 for line in lines)
    assert timing.round_trip_s("assign") == pytest.approx(by_hand)


def test_generic_profile_uses_its_wifi_link_and_assumed_sizes() -> None:
    timing = CommandTiming.for_profile("rss-agv-001")
    assert timing.protocol is None
    s = timing.settings
    for kind in KINDS:
        tx, rx = GENERIC_MESSAGE_BYTES[kind]
        by_hand = (tx + rx) * 10 / 1_000_000 + 2 * 0.005 + 0.010  # 8N1 at 1 Mbit/s, latency x2
        assert (s.baud, s.bits_per_char, s.latency_s, s.processing_s) == (1_000_000, 10, 0.005,
                                                                          0.010)
        assert timing.round_trip_s(kind) == pytest.approx(by_hand)


@pytest.mark.parametrize("name", profile_names())
def test_slower_baud_rate_stretches_the_byte_time_in_proportion(name: str) -> None:
    profile = load_profile(name)
    fast = CommandTiming(profile.protocol, profile.link)
    slow = CommandTiming(profile.protocol,
                         profile.link.model_copy(update={"baud": profile.link.baud // 2}))
    for kind in KINDS:
        fixed_s = sum(2 * e.latency_s + e.processing_s + e.gap_s for e in fast.exchanges[kind])
        assert [e.command for e in slow.exchanges[kind]] == [
            e.command for e in fast.exchanges[kind]]
        assert slow.round_trip_s(kind) - fixed_s == pytest.approx(
            2 * (fast.round_trip_s(kind) - fixed_s))
        assert slow.round_trip_s(kind) > fast.round_trip_s(kind)


def test_every_protocol_has_every_kind() -> None:
    assert set(MESSAGES) == set(names())
    for protocol in names():
        assert set(MESSAGES[protocol]) == set(KINDS)
        assert all(MESSAGES[protocol][kind] for kind in KINDS)


@pytest.mark.parametrize("name", PROTOCOL_PROFILES)
def test_every_message_encodes_and_gets_a_non_error_reply(name: str) -> None:
    timing = CommandTiming.for_profile(name)
    assert timing.protocol is not None
    codec = get_codec(timing.protocol)
    for kind in KINDS:
        messages = MESSAGES[timing.protocol][kind]
        assert len(timing.exchanges[kind]) == len(messages)
        for message, exchange in zip(messages, timing.exchanges[kind], strict=True):
            frames = codec.unframe(bytearray(exchange.command))
            assert len(frames) == 1  # one complete frame or line
            if isinstance(message, bytes):
                assert exchange.command == message
            else:  # the bytes sent are the codec's encoding of the message
                sent = codec.parse_command(frames[0])
                fresh = get_codec(timing.protocol)
                encoded = codec.parse_command(fresh.unframe(bytearray(fresh.encode(message)))[0])
                assert (sent.name, sent.args) == (encoded.name, encoded.args)
            assert not exchange.timed_out
            received = bytearray(exchange.reply)
            frames = codec.unframe(received)
            assert frames and not received, f"{name} {kind}: reply {exchange.reply!r}"
            for frame in frames:
                assert codec.decode(frame).status not in ("error", "nak"), (name, kind, frame)


def test_agv3_assign_is_one_chained_line_with_three_answers() -> None:
    timing = CommandTiming.for_profile("agv-3")
    (exchange,) = timing.exchanges["assign"]
    assert exchange.reply == b"\r\n\r\nStarting...\r\n"  # PICKUp, DROPOff, STArt
    char_s = 10 / 9600
    assert timing.round_trip_s("assign") == pytest.approx(
        (len(exchange.command) + len(exchange.reply)) * char_s + 0.010)


@pytest.mark.parametrize("name", profile_names())
def test_jitter_draws_are_reproducible_and_never_negative(name: str) -> None:
    timing = CommandTiming.for_profile(name)
    for kind in KINDS:
        first = [timing.seconds(kind, np.random.default_rng(7)) for _ in range(3)]
        rng_a, rng_b = np.random.default_rng(11), np.random.default_rng(11)
        draws_a = [timing.seconds(kind, rng_a) for _ in range(200)]
        draws_b = [timing.seconds(kind, rng_b) for _ in range(200)]
        assert first[0] == first[1] == first[2]
        assert draws_a == draws_b
        assert min(draws_a) >= timing.round_trip_s(kind)
        if timing.settings.jitter.distribution == "none":
            assert set(draws_a) == {timing.round_trip_s(kind)}


def test_tabo_jitter_is_one_draw_per_exchange() -> None:
    timing = CommandTiming.for_profile("tabo")  # uniform 0-30 ms, assign is two MLL
    rng, same = np.random.default_rng(3), np.random.default_rng(3)
    extra_s = timing.seconds("assign", rng) - timing.round_trip_s("assign")
    assert extra_s == pytest.approx(same.uniform(0, 0.030) + same.uniform(0, 0.030))


def test_normal_jitter_is_cut_at_zero() -> None:
    profile = load_profile("agv-3")
    wide = profile.link.model_copy(
        update={"jitter": Jitter(distribution="normal", mean_s=0.0, sd_s=0.05)})
    timing = CommandTiming(profile.protocol, wide)
    rng = np.random.default_rng(5)
    assert min(timing.seconds("stop", rng) for _ in range(500)) >= timing.round_trip_s("stop")


def test_mean_notice_delay_is_half_a_period_plus_the_status_reply() -> None:
    timing = CommandTiming.for_profile("carriro-ad-plus")
    status_reply_s = timing.reply_s("status")
    assert status_reply_s == pytest.approx(0.0279167, abs=1e-7)
    for period_s in (0.1, 0.5, 1.0, 5.0):
        assert timing.mean_notice_delay_s(period_s) == pytest.approx(period_s / 2
                                                                     + status_reply_s)
    # Polls cannot come faster than one status round trip (reply and host gap).
    assert timing.mean_notice_delay_s(0.001) == pytest.approx(
        timing.round_trip_s("status") / 2 + status_reply_s)
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(ValueError, match="poll_period_s"):
            timing.mean_notice_delay_s(bad)


def test_a_reply_later_than_agv3_timeout_is_reported() -> None:
    profile = load_profile("agv-3")
    assert profile.link.reply_timeout_s == 0.25  # AGV-3 protocol, Syntax
    slow = profile.link.model_copy(update={"processing_s": 0.3})
    timing = CommandTiming(profile.protocol, slow)
    assert timing.timed_out("status")
    (exchange,) = timing.exchanges["status"]
    attempt = timing.attempt("status", np.random.default_rng(0))
    assert attempt == Attempt(exchange.tx_s + 0.25, True)
    assert timing.seconds("status", np.random.default_rng(0)) == attempt.seconds
    assert not CommandTiming.for_profile("agv-3").timed_out("status")


@pytest.mark.parametrize("over", [False, True])
def test_jitter_past_the_margin_times_out_as_the_link_says(over: bool) -> None:
    profile = load_profile("agv-3")
    timing = CommandTiming.for_profile("agv-3")
    (exchange,) = timing.exchanges["stop"]
    margin_s = timeout_margin_s(exchange, profile.link)
    assert margin_s == pytest.approx(0.25 - 0.010 - 10 / 9600)
    jitter_s = margin_s + (0.001 if over else -0.001)
    fixed = profile.link.model_copy(
        update={"jitter": Jitter(distribution="uniform", low_s=jitter_s, high_s=jitter_s)})
    jittery = CommandTiming(profile.protocol, fixed)
    attempt = jittery.attempt("stop", np.random.default_rng(1))
    on_link = Link("agv3", fixed).exchange(exchange.command)
    assert attempt.timed_out is on_link.timed_out is over
    assert attempt.seconds == pytest.approx(on_link.reply_s + on_link.gap_s)


def test_a_timeout_stops_a_multi_message_command_at_that_message() -> None:
    profile = load_profile("carriro-ad-plus")
    late = profile.link.model_copy(  # timeout 1 s
        update={"jitter": Jitter(distribution="uniform", low_s=2.0, high_s=2.0)})
    timing = CommandTiming(profile.protocol, late)
    first, _ = timing.exchanges["assign"]
    attempt = timing.attempt("assign", np.random.default_rng(2))
    assert attempt == Attempt(first.tx_s + 1.0 + 0.010, True)
