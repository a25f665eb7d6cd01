"""KTM-02 codec and virtual device (KTM-02 command list, last update 2011-02-08)."""

from __future__ import annotations

from typing import Any

import pytest

from agv_model.protocols import Command, ProtocolError, Reply, get_codec, get_device
from agv_model.protocols.ktm02 import (
    Direction,
    ErrorKind,
    ImageSize,
    Ktm02Codec,
    Ktm02Device,
    KtmCommand,
    KtmReply,
    ResetTarget,
    RobotState,
    VerifyCodeError,
    pad_last_package,
    sum16,
)

from .conftest import golden_hex

HOST_GOLDEN = [
    ("host_go_straight_full_speed", KtmCommand("GoStraightAlongLineCmd", (255,), frame_id=1)),
    ("host_move_freely", KtmCommand("MoveFreelyCmd", (128, Direction.FORWARD, 64, Direction.BACK),
                                    frame_id=5)),
    ("host_take_picture_defaults", KtmCommand("TakePictureCmd", (ImageSize.S320X240, 506),
                                              frame_id=6)),
    ("host_request_status", KtmCommand("RequestStatusCmd", (), "get", frame_id=1)),
    ("host_reset_averaged_speed", KtmCommand("ResetCmd", (ResetTarget.AVERAGED_SPEED,),
                                             frame_id=1)),
    ("host_emergency_stop_id255", KtmCommand("EmergencyStopCmd", frame_id=255)),
]

DEVICE_GOLDEN = [
    ("device_ack", KtmReply("ControllerAckCmd", "ack", (1,), frame_id=1)),
    ("device_nak_verify_error", KtmReply("ControllerNakCmd", "nak", (7, ErrorKind.VERIFY_ERROR),
                                         frame_id=2)),
    ("device_nak_unknown_id", KtmReply("ControllerNakCmd", "nak",
                                       (0, ErrorKind.UNKNOWN_COMMAND_ERROR), frame_id=3)),
    ("device_status_taking_picture", KtmReply("SendStatusCmd", "value",
                                              (RobotState.TAKING_PICTURE,), frame_id=9)),
    ("device_speed", KtmReply("SendSpeedCmd", "value", (300, 65535), frame_id=10)),
    ("device_distance", KtmReply("SendDistanceCmd", "value", (254,), frame_id=11)),
    ("device_moving_finish", KtmReply("MovingFinishCmd", "fin", (), frame_id=12)),
    ("device_package_count", KtmReply("SendImagePackageNumCmd", "value", (300,), frame_id=13)),
    ("device_last_package_padded", KtmReply(
        "SendImagePackageCmd", "value", (2, bytes(range(1, 11)) + b"0" * 246), frame_id=6)),
]


def run(device: Ktm02Device, frames: list[bytes], until_s: float, start_s: float = 0.0,
        ) -> list[tuple[float, KtmReply]]:
    """Send each frame at start_s, then collect every decoded output up to until_s."""
    for frame in frames:
        device.receive(frame, start_s)
    codec = Ktm02Codec()
    return [(t, codec.decode(data)) for t, data in device.poll(until_s)]


def names(outputs: list[tuple[float, KtmReply]]) -> list[str]:
    return [reply.name for _, reply in outputs]


@pytest.fixture
def host() -> Ktm02Codec:
    return Ktm02Codec()


# -- codec: golden frames from the document ------------------------------------------------


@pytest.mark.parametrize(("name", "command"), HOST_GOLDEN)
def test_host_golden_frames_encode_and_parse(name: str, command: KtmCommand) -> None:
    frame = golden_hex("ktm02", name)
    assert Ktm02Codec().encode(command) == frame
    assert Ktm02Codec().parse_command(frame) == command


@pytest.mark.parametrize(("name", "reply"), DEVICE_GOLDEN)
def test_device_golden_frames_encode_and_decode(name: str, reply: KtmReply) -> None:
    frame = golden_hex("ktm02", name)
    assert Ktm02Codec().encode_reply(reply) == frame
    assert Ktm02Codec().decode(frame) == reply


def test_two_byte_fields_are_low_byte_first(host: Ktm02Codec) -> None:
    frame = host.encode(KtmCommand("TakePictureCmd", (ImageSize.S640X480, 0x0123), frame_id=9))
    assert frame[2:4] == bytes([10, 0])
    assert frame[-2:] == bytes([0x23, 0x01])
    assert frame[5] | frame[6] << 8 == sum16(frame[:5] + frame[7:])


# -- codec: round trips, numbering, replaceable verify -------------------------------------

ROUND_TRIP_COMMANDS: list[tuple[str, tuple[Any, ...]]] = [
    ("ControllerAckCmd", (9,)),
    ("ControllerNakCmd", (0, ErrorKind.TIMEOUT_ERROR)),
    ("GoStraightAlongLineCmd", (0,)),
    ("RotateRightAlongLineCmd", (100,)),
    ("RotateLeftAlongLineCmd", (255,)),
    ("EmergencyStopCmd", ()),
    ("MoveFreelyCmd", (1, Direction.BACK, 2, Direction.FORWARD)),
    ("TakePictureCmd", (ImageSize.S80X64, 58)),
    ("RequestStatusCmd", ()),
    ("ResetCmd", (ResetTarget.CAMERA,)),
    ("RequestMomentarySpeedCmd", ()),
    ("RequestDistanceCmd", ()),
    ("RequestImagePackageCmd", ()),
    ("StopCmd", ()),
    ("RequestAveragedSpeedCmd", ()),
]


@pytest.mark.parametrize(("name", "args"), ROUND_TRIP_COMMANDS)
def test_every_host_command_round_trips(name: str, args: tuple[Any, ...]) -> None:
    codec = Ktm02Codec()
    parsed = codec.parse_command(codec.encode(Command(name, args)))
    assert (parsed.name, parsed.args) == (name, args)


@pytest.mark.parametrize(("name", "args"), [
    ("SendStatusCmd", (RobotState.ROTATE_LEFT_ALONG_LINE,)),
    ("SendSpeedCmd", (0, 1234)),
    ("SendImagePackageCmd", (65535, b"\xff\xd8" * 10)),
    ("SendImagePackageNumCmd", (1,)),
    ("SendDistanceCmd", (0,)),
    ("MovingFinishCmd", ()),
])
def test_every_device_message_round_trips(name: str, args: tuple[Any, ...]) -> None:
    codec = Ktm02Codec()
    decoded = codec.decode(codec.encode_reply(Reply(name, "value", args)))
    assert (decoded.name, decoded.args) == (name, args)


def test_take_picture_parameters_may_be_left_out(host: Ktm02Codec) -> None:
    bare = host.frame(0x0B, 4, b"")
    size_only = host.frame(0x0B, 4, bytes([ImageSize.S160X128]))
    assert host.parse_command(bare).args == (ImageSize.S320X240, 506)
    assert host.parse_command(size_only).args == (ImageSize.S160X128, 506)
    with pytest.raises(ProtocolError, match="0 or 1 or 3 parameter bytes"):
        host.parse_command(host.frame(0x0B, 4, b"\x05\xfa"))


def test_frame_ids_count_1_to_255_and_skip_0(host: Ktm02Codec) -> None:
    ids = [host.encode(Command("StopCmd"))[4] for _ in range(256)]
    assert ids[:2] == [1, 2]
    assert ids[254:] == [255, 1]
    assert 0 not in ids


def test_verify_code_is_replaceable() -> None:
    def xor16(data: bytes) -> int:
        code = 0
        for byte in data:
            code ^= byte
        return code

    custom = Ktm02Codec(verify=xor16)
    frame = custom.encode(KtmCommand("GoStraightAlongLineCmd", (255,), frame_id=1))
    assert frame != golden_hex("ktm02", "host_go_straight_full_speed")
    assert custom.parse_command(frame).args == (255,)
    with pytest.raises(VerifyCodeError):
        Ktm02Codec().parse_command(frame)


# -- codec: malformed input ----------------------------------------------------------------


def test_bad_verify_code_names_the_bytes_and_the_expected_code(host: Ktm02Codec) -> None:
    frame = bytearray(golden_hex("ktm02", "host_request_status"))
    frame[5] = 0x00
    with pytest.raises(VerifyCodeError) as err:
        host.parse_command(bytes(frame))
    assert "verify code 0x00bf, got 0x0000" in str(err.value)
    assert repr(bytes(frame)) in str(err.value)


@pytest.mark.parametrize(("frame", "expected"), [
    (b"\x55\x0d\x07\x00\x01\xbf\x00", "starting with 0xaa"),
    (b"\xaa\x0d\x08\x00\x01\xbf\x00", "packet size field 8 to equal the frame length 7"),
    (b"\xaa\x0d", "at least 7 bytes"),
])
def test_malformed_frames_raise_protocol_error(host: Ktm02Codec, frame: bytes,
                                               expected: str) -> None:
    with pytest.raises(ProtocolError, match=expected):
        host.parse_command(frame)


def test_unknown_command_code_and_bad_parameters_are_rejected(host: Ktm02Codec) -> None:
    with pytest.raises(ProtocolError, match="command code in"):
        host.parse_command(host.frame(0x0C, 1, b""))
    with pytest.raises(ProtocolError, match="right direction one of FORWARD"):
        host.parse_command(host.frame(0x0A, 1, b"\x10\x02\x10\x00"))
    with pytest.raises(ProtocolError, match=r"image package size in 58\.\.506"):
        host.parse_command(host.frame(0x0B, 1, b"\x05\x39\x00"))
    with pytest.raises(ProtocolError, match=r"command id in 1\.\.255"):
        host.parse_command(host.frame(0x16, 0, b""))
    with pytest.raises(ProtocolError, match=r"speed in 0\.\.255"):
        host.encode(Command("GoStraightAlongLineCmd", (256,)))
    with pytest.raises(ProtocolError, match="command class"):
        host.encode(Command("GoBackCmd"))  # deleted on 2010/12/15


def test_unframe_cuts_frames_and_keeps_a_partial_one(host: Ktm02Codec) -> None:
    a = golden_hex("ktm02", "host_request_status")
    b = golden_hex("ktm02", "host_move_freely")
    buffer = bytearray(a + b + b[:3])
    assert host.unframe(buffer) == [a, b]
    assert buffer == bytearray(b[:3])


def test_unframe_reports_junk_after_returning_good_frames(host: Ktm02Codec) -> None:
    a = golden_hex("ktm02", "host_request_status")
    buffer = bytearray(a + b"\x01\x02" + a)
    assert host.unframe(buffer) == [a]
    with pytest.raises(ProtocolError, match=r"got b'\\x01\\x02'; expected start byte 0xaa"):
        host.unframe(buffer)
    assert host.unframe(buffer) == [a]


def test_unframe_rejects_an_impossible_packet_size(host: Ktm02Codec) -> None:
    buffer = bytearray(b"\xaa\x06\x03\x00\x01")
    with pytest.raises(ProtocolError, match=r"packet size 7\.\.515"):
        host.unframe(buffer)
    assert buffer == bytearray(b"\x06\x03\x00\x01")


def test_padding_follows_the_documented_example() -> None:
    packages = pad_last_package(bytes(256 + 10), 256, 0x30)
    assert [len(p) for p in packages] == [256, 256]
    assert packages[1] == bytes(10) + b"0" * 246


# -- device --------------------------------------------------------------------------------


def test_registered_by_name() -> None:
    assert isinstance(get_codec("ktm02"), Ktm02Codec)
    assert isinstance(get_device("ktm02", reply_delay_s=0.02), Ktm02Device)


def test_device_acks_then_answers_a_request(host: Ktm02Codec) -> None:
    device = Ktm02Device(reply_delay_s=0.005)
    out = run(device, [host.encode(KtmCommand("RequestStatusCmd", kind="get", frame_id=42))], 1.0)
    assert [(t, r.name, r.args) for t, r in out] == [
        (0.005, "ControllerAckCmd", (42,)),
        (0.005, "SendStatusCmd", (RobotState.IDLE,)),
    ]


def test_device_naks_a_bad_verify_code_with_the_frame_id(host: Ktm02Codec) -> None:
    frame = bytearray(host.encode(KtmCommand("StopCmd", frame_id=7)))
    frame[5] ^= 0xFF
    out = run(Ktm02Device(), [bytes(frame)], 1.0)
    assert [r.args for _, r in out] == [(7, ErrorKind.VERIFY_ERROR)]


def test_device_naks_an_unknown_command(host: Ktm02Codec) -> None:
    out = run(Ktm02Device(), [host.frame(0x0C, 8, b""), host.frame(0x16, 0, b"")], 1.0)
    assert [r.args for _, r in out] == [(8, ErrorKind.UNKNOWN_COMMAND_ERROR),
                                         (0, ErrorKind.UNKNOWN_COMMAND_ERROR)]


def test_device_naks_junk_with_id_0_and_carries_on(host: Ktm02Codec) -> None:
    out = run(Ktm02Device(), [b"\x00\x11" + host.encode(KtmCommand("StopCmd", frame_id=3))], 1.0)
    assert [(r.name, r.args) for _, r in out] == [
        ("ControllerNakCmd", (0, ErrorKind.UNKNOWN_COMMAND_ERROR)),
        ("ControllerAckCmd", (3,)),
    ]


def test_a_junk_run_gets_one_nak_however_its_bytes_arrive(host: Ktm02Codec) -> None:
    """Found by the property tests: junk fed one byte at a time (as `fleet-sim emulate` feeds
    the device) was NAKed once per byte, junk in one piece once."""
    junk = b"\x00\x11\x22"
    stop = host.encode(KtmCommand("StopCmd", frame_id=3))
    whole, bytewise = Ktm02Device(), Ktm02Device()
    whole.receive(junk + stop, 0.0)
    for i, byte in enumerate(junk + stop):
        bytewise.receive(bytes([byte]), i * 0.0001)
    for device in (whole, bytewise):
        out = [Ktm02Codec().decode(d) for _, d in device.poll(1.0)]
        assert [(r.name, r.args) for r in out] == [
            ("ControllerNakCmd", (0, ErrorKind.UNKNOWN_COMMAND_ERROR)),
            ("ControllerAckCmd", (3,)),
        ]


def test_junk_after_a_pause_is_a_new_run(host: Ktm02Codec) -> None:
    device = Ktm02Device(frame_timeout_s=0.1)
    device.receive(b"\x00", 0.0)
    device.receive(b"\x01", 0.05)  # within the frame timeout: the same run
    device.receive(b"\x02", 0.5)  # later: a new run
    out = [Ktm02Codec().decode(d) for _, d in device.poll(1.0)]
    assert [r.args for r in out] == [(0, ErrorKind.UNKNOWN_COMMAND_ERROR)] * 2


def test_device_naks_a_frame_that_does_not_complete_in_time(host: Ktm02Codec) -> None:
    device = Ktm02Device(frame_timeout_s=0.1)
    device.receive(host.encode(KtmCommand("StopCmd", frame_id=4))[:5], 2.0)
    assert device.next_output_s() == pytest.approx(2.1)
    assert device.poll(2.09) == []
    out = [(t, Ktm02Codec().decode(d)) for t, d in device.poll(2.2)]
    assert [(t, r.args) for t, r in out] == [(pytest.approx(2.1), (4, ErrorKind.TIMEOUT_ERROR))]


def test_a_frame_split_across_chunks_is_assembled(host: Ktm02Codec) -> None:
    device = Ktm02Device()
    frame = host.encode(KtmCommand("RequestDistanceCmd", kind="get", frame_id=2))
    device.receive(frame[:3], 0.0)
    device.receive(frame[3:], 0.05)
    out = [Ktm02Codec().decode(d) for _, d in device.poll(1.0)]
    assert [(r.name, r.args) for r in out] == [("ControllerAckCmd", (2,)),
                                               ("SendDistanceCmd", (254,))]


def test_host_ack_is_not_answered_and_host_nak_is_recorded(host: Ktm02Codec) -> None:
    device = Ktm02Device()
    out = run(device, [host.encode(Command("ControllerAckCmd", (3,))),
                       host.encode(Command("ControllerNakCmd", (4, ErrorKind.VERIFY_ERROR)))], 1)
    assert out == []
    assert device.host_naks == [(4, ErrorKind.VERIFY_ERROR)]


def test_rotation_reports_state_and_finishes_in_simulated_time(host: Ktm02Codec) -> None:
    device = Ktm02Device(reply_delay_s=0.01, rotate_time_s=2.0, full_speed_mmps=510.0)
    run(device, [host.encode(Command("RotateRightAlongLineCmd", (100,)))], 0.5)
    out = run(device, [host.encode(Command("RequestStatusCmd", kind="get")),
                       host.encode(Command("RequestMomentarySpeedCmd", kind="get"))], 1.0,
              start_s=0.5)
    assert [r.args for _, r in out][1::2] == [(RobotState.ROTATE_RIGHT_ALONG_LINE,), (200, 200)]
    assert device.next_output_s() == pytest.approx(2.01)
    out = run(device, [], 3.0, start_s=3.0)
    assert [(t, r.name) for t, r in out] == [(pytest.approx(2.01), "MovingFinishCmd")]
    assert device.state is RobotState.IDLE


def test_stop_ends_a_straight_run_with_moving_finish(host: Ktm02Codec) -> None:
    device = Ktm02Device(straight_time_s=None)
    run(device, [host.encode(Command("GoStraightAlongLineCmd", (50,)))], 5.0)
    assert device.next_output_s() is None
    out = run(device, [host.encode(Command("StopCmd"))], 6.0, start_s=5.0)
    assert names(out) == ["ControllerAckCmd", "MovingFinishCmd"]
    assert device.tyre_speeds_mmps == (0.0, 0.0)


def test_move_freely_sets_each_tyre(host: Ktm02Codec) -> None:
    device = Ktm02Device(full_speed_mmps=255.0)
    run(device, [host.encode(Command("MoveFreelyCmd", (10, Direction.FORWARD, 20,
                                                        Direction.BACK)))], 1.0)
    assert device.tyre_speeds_mmps == (10.0, 20.0)
    assert device.state is RobotState.MOVING_FREELY


def test_averaged_speed_is_time_weighted_since_reset(host: Ktm02Codec) -> None:
    device = Ktm02Device(reply_delay_s=0.0, full_speed_mmps=255.0, straight_time_s=None)
    run(device, [host.encode(Command("ResetCmd", (ResetTarget.AVERAGED_SPEED,)))], 0.0)
    run(device, [host.encode(Command("GoStraightAlongLineCmd", (100,)))], 0.0)
    run(device, [host.encode(Command("StopCmd"))], 10.0, start_s=10.0)
    out = run(device, [host.encode(Command("RequestAveragedSpeedCmd", kind="get"))], 20.0,
              start_s=20.0)
    assert out[-1][1].args == (50, 50)  # 100 mm/s for 10 s of 20 s


def test_picture_packages_are_counted_padded_and_sent_one_per_request(host: Ktm02Codec) -> None:
    image = bytes(range(1, 11)) * 27  # 270 bytes: one full package of 256 and 14 bytes
    device = Ktm02Device(reply_delay_s=0.01, picture_time_s=0.5, image_source=lambda _: image)
    run(device, [host.encode(Command("TakePictureCmd", (ImageSize.S80X64, 256)))], 0.1)
    assert device.state is RobotState.TAKING_PICTURE
    out = run(device, [], 1.0, start_s=0.1)
    assert [(t, r.name, r.args) for t, r in out] == [
        (pytest.approx(0.51), "SendImagePackageNumCmd", (2,))]
    request = [host.encode(Command("RequestImagePackageCmd", kind="get"))]
    first = run(device, request, 2.0, start_s=1.0)[1][1]
    second = run(device, request, 3.0, start_s=2.0)[1][1]
    assert first.args == (1, image[:256])
    assert second.args == (2, image[256:] + b"0" * 242)
    nak = run(device, request, 4.0, start_s=3.0)[0][1]
    assert nak.args == (2, ErrorKind.UNKNOWN_COMMAND_ERROR)  # frame id 2 of the host codec


def test_device_reproduces_the_documented_last_package(host: Ktm02Codec) -> None:
    image = bytes(256) + bytes(range(1, 11))
    device = Ktm02Device(picture_time_s=0.1, image_source=lambda _: image)
    requests = [host.encode(Command("TakePictureCmd", (ImageSize.S80X64, 256)))]
    device.receive(requests[0], 0.0)
    device.poll(1.0)
    for t in (1.0, 2.0):
        device.receive(host.encode(Command("RequestImagePackageCmd", kind="get")), t)
    frames = [data for _, data in device.poll(3.0)]
    assert frames[-1] == golden_hex("ktm02", "device_last_package_padded")


def test_reset_all_stops_and_clears_the_picture(host: Ktm02Codec) -> None:
    device = Ktm02Device(image_source=lambda _: b"x" * 100)
    run(device, [host.encode(Command("GoStraightAlongLineCmd", (9,))),
                 host.encode(Command("TakePictureCmd", ()))], 1.0)
    out = run(device, [host.encode(Command("ResetCmd", (ResetTarget.ALL,))),
                       host.encode(Command("RequestImagePackageCmd", kind="get"))], 2.0,
              start_s=1.0)
    assert names(out) == ["ControllerAckCmd", "MovingFinishCmd", "ControllerNakCmd"]
    assert device.state is RobotState.IDLE


def test_zero_speed_means_stop(host: Ktm02Codec) -> None:
    device = Ktm02Device()
    run(device, [host.encode(Command("GoStraightAlongLineCmd", (9,)))], 1.0)
    out = run(device, [host.encode(Command("GoStraightAlongLineCmd", (0,)))], 2.0, start_s=1.0)
    assert names(out) == ["ControllerAckCmd", "MovingFinishCmd"]


def test_simulated_time_must_not_go_back() -> None:
    device = Ktm02Device()
    device.poll(5.0)
    with pytest.raises(ValueError, match=r"now_s \(4.0\) must not be earlier"):
        device.receive(b"", 4.0)


def test_exchange_over_a_pseudo_terminal(pty_link: Any, host: Ktm02Codec) -> None:
    link = pty_link(Ktm02Device(reply_delay_s=0.02))
    request = golden_hex("ktm02", "host_request_status")
    answer = link.exchange(request, lambda got: len(got) >= 16)
    codec = Ktm02Codec()
    frames = codec.unframe(bytearray(answer))
    assert [codec.decode(f).args for f in frames] == [(1,), (RobotState.IDLE,)]
    assert frames[0] == golden_hex("ktm02", "device_ack")


def test_output_frame_ids_rise_in_send_order(host: Ktm02Codec) -> None:
    device = Ktm02Device(reply_delay_s=0.005, rotate_time_s=0.001)
    bad = bytearray(host.encode(KtmCommand("StopCmd", frame_id=9)))
    bad[5] ^= 1
    device.receive(host.encode(Command("RotateLeftAlongLineCmd", (10,))) + bytes(bad), 0.0)
    out = [(t, Ktm02Codec().decode(d)) for t, d in device.poll(1.0)]
    assert [(t, r.name, r.frame_id) for t, r in out] == [
        (pytest.approx(0.005), "ControllerAckCmd", 1),
        (pytest.approx(0.006), "MovingFinishCmd", 2),
        (pytest.approx(0.010), "ControllerNakCmd", 3),
    ]


def test_frame_timeout_counts_from_the_frame_s_own_first_byte(host: Ktm02Codec) -> None:
    device = Ktm02Device(frame_timeout_s=0.1)
    a = host.encode(KtmCommand("StopCmd", frame_id=1))
    b = host.encode(KtmCommand("StopCmd", frame_id=2))
    device.receive(a[:3], 0.0)
    device.receive(a[3:] + b[:3], 0.09)
    device.receive(b[3:], 0.15)
    out = [Ktm02Codec().decode(d) for _, d in device.poll(1.0)]
    assert [(r.name, r.args) for r in out] == [("ControllerAckCmd", (1,)),
                                               ("ControllerAckCmd", (2,))]
