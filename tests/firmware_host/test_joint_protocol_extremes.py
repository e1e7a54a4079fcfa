"""The joint protocol at its extremes: a decoder fed hostile bytes (seeded numpy random, many cases, fast), and an
encoder fed NaN / inf / -0.0 / 1e30 joints, timestamps at 0 and 2^64 - 1, sequence numbers at the wrap, and
fields of the wrong kind. The hypothesis tests in test_joint_protocol_codec.py draw well-formed messages; these
draw what a noisy link or a careless caller makes."""
from __future__ import annotations

import struct

import numpy as np
import pytest

from firmware_host.errors import EncodeError
from firmware_host.protocol import (
    Hello,
    JointFrame,
    Joints,
    Joints2D,
    MsgType,
    Status,
    StreamDecoder,
    decode_stream,
    encode,
    joints_message,
    make_header,
)
from firmware_host.protocol.constants import ERROR_CODES, MAX_FRAME_LEN, U32_MAX, U64_MAX
from firmware_host.protocol.encoder import frame_packet, seal
from firmware_host.protocol.from_frame import joints2d_messages
from tests.firmware_host.hostile_stream import SENTINEL, SENTINEL_WIRE, hostile_stream, sealed_nonsense

def _check_stats(d: StreamDecoder, events: list) -> None:
    s = d.stats
    assert s.frames == len(events) == s.messages + s.skipped + sum(s.errors.values())
    assert set(s.errors) == set(ERROR_CODES)
    assert all(e.kind in ("message", "skipped", "error") for e in events)
    assert all(e.code in ERROR_CODES for e in events if e.kind == "error")


def test_hostile_streams_give_events_only_and_resynchronise() -> None:
    """Random bytes, long runs, cut and flipped frames, valid CRCs around nonsense: the decoder returns events
    (never raises), holds at most one frame's bytes, and decodes the next good frame after a delimiter."""
    rng = np.random.default_rng(54)
    for case in range(400):
        d = StreamDecoder()
        stream = hostile_stream(rng, int(rng.integers(1, 6)))
        events = d.feed(stream)
        assert len(d._buf) <= MAX_FRAME_LEN, f"case {case}: holds {len(d._buf)} bytes"
        # A leading 0x00 (what a sender writes after a break) ends whatever partial frame was held.
        tail = d.feed(b"\x00" + SENTINEL_WIRE)
        assert tail[-1].message == SENTINEL, f"case {case}: {tail[-1]}"
        _check_stats(d, events + tail)


def test_a_stream_split_at_every_byte_boundary_decodes_as_whole() -> None:
    """Each two-read split of a stream of garbage and every message type gives the events of the whole."""
    rng = np.random.default_rng(7)
    frame = JointFrame(U32_MAX, U64_MAX, 0, rng.random((25, 4)), {0: rng.random((25, 3)) * 640})
    messages = [Hello(make_header(MsgType.HELLO, U32_MAX, 0, 0), 1, 0, 25, 0, 0, "rig", ("left", "right")),
                joints_message(frame, U64_MAX), *joints2d_messages(frame, U64_MAX, ("left", "right")), SENTINEL]
    stream = b"\x17garbage\x00" + b"".join(encode(m) for m in messages) + sealed_nonsense(rng)
    whole, _ = decode_stream(stream)
    assert [e.message for e in whole[1:5]] == messages
    want = [e.to_json() for e in whole]
    for cut in range(len(stream) + 1):
        d = StreamDecoder()
        got = d.feed(stream[:cut]) + d.feed(stream[cut:])
        assert [e.to_json() for e in got] == want, f"split at byte {cut}"


@pytest.mark.parametrize(("msg_type", "payload", "code"), [
    (0x10, bytes([0, 65]) + bytes(9 + 7 * 65), "malformed"),  # one more joint than allowed, all its bytes there
    (0x10, bytes([0, 255]), "malformed"),  # the largest count a byte holds, with nothing behind it
    (0x10, bytes([0, 0]), None),  # 0 joints: no mask byte, a message
    (0x11, bytes([1, 0, 64]) + bytes(8 + 5 * 63), "malformed"),  # a count that points past the packet's end
    (0x7F, bytes(40), "skipped"),  # a type this decoder does not know: skipped, not an error
])
def test_joint_counts_and_types_behind_a_valid_crc(msg_type: int, payload: bytes, code: str | None) -> None:
    packet = seal(struct.pack("<BBBIQQ", 1, msg_type, 0, 1, 2, 3) + payload)
    events, stats = decode_stream(b"\x00" + frame_packet(packet) + SENTINEL_WIRE)
    assert events[-1].message == SENTINEL and stats.frames == 2
    if code is None:
        assert events[0].kind == "message" and events[0].message.xyz_mm.shape == (0, 3)
    elif code == "skipped":
        assert events[0].kind == "skipped" and events[0].msg_type == msg_type
    else:
        assert events[0].code == code


def test_a_long_run_without_a_delimiter_is_one_oversize_and_holds_no_memory() -> None:
    """70 125 bytes without 0x00 (past any 16-bit length counter), fed 1 to 70 125 at a time: one ``oversize``,
    nothing buffered, and the next frame decodes."""
    run = bytes(range(1, 256)) * 275
    for chunk in (1, 255, 4096, len(run)):
        d = StreamDecoder()
        events = []
        for i in range(0, len(run), chunk):
            events += d.feed(run[i : i + chunk])
            assert len(d._buf) <= MAX_FRAME_LEN
        events += d.feed(b"\x00" + SENTINEL_WIRE)
        assert [e.code for e in events[:-1]] == ["oversize"] and events[-1].message == SENTINEL


# ---- encoder -----------------------------------------------------------------------------------------------

_SPECIALS = np.array([np.nan, np.inf, -np.inf, -0.0, 0.0, 1e30, -1e30, 1e308, 32.767, -32.768, 32.7675, 1e-9])


def _random_joints(rng: np.random.Generator, n: int, dims: int, scale: float) -> np.ndarray:
    j = np.empty((n, dims + 1))
    j[:, :dims] = rng.uniform(-1.2, 1.2, (n, dims)) * scale
    j[:, dims] = rng.uniform(-0.2, 1.3, n)
    specials = rng.random(j.shape) < 0.15
    with np.errstate(over="ignore"):  # 1e308 scaled to pixels is inf: one more special
        j[specials] = rng.choice(_SPECIALS, int(specials.sum())) * (scale / 32.768 if dims == 2 else 1.0)
    return j


def _expect(values: np.ndarray, conf: np.ndarray, per_unit: float) -> tuple[np.ndarray, np.ndarray]:
    """The docs' rules (docs/protocol.md, "Rig frame and quantisation"; JOINTS): missing when a coordinate or the
    confidence is NaN, the confidence <= 0 or a coordinate not in int16 after rounding to the step."""
    with np.errstate(invalid="ignore", over="ignore"):
        rounded = np.rint(values * per_unit)
        missing = (np.isnan(values).any(axis=1) | np.isnan(conf) | ~(conf > 0)
                   | ((rounded < -32768) | (rounded > 32767)).any(axis=1))
        wire_conf = np.where(missing, 0, np.clip(np.rint(conf * 255), 1, 255))
    return missing, wire_conf


def test_extreme_joints_round_trip_within_the_quantisation_step() -> None:
    """decode(encode(x)) is x to within half a millimetre (half a quarter pixel in 2D) for every joint the rules
    keep; every other joint is sent as 0, 0, 0, confidence 0, mask bit set; the header survives at its limits."""
    rng = np.random.default_rng(2026)
    for case in range(300):
        n = int(rng.choice([0, 1, 25, 64]))
        j3 = _random_joints(rng, n, 3, 32.768)
        j2 = _random_joints(rng, n, 2, 8192.0)
        # drawn by index: numpy's choice over these makes floats of them (2^64 - 1 became 2^64)
        seq = (0, U32_MAX, U32_MAX + 1, 2**40 + 3)[int(rng.integers(4))]
        t = (0, 1, U64_MAX)[int(rng.integers(3))]
        frame = JointFrame(seq, t, 0, j3, {0: j2})
        msgs = [joints_message(frame, U64_MAX - t), *joints2d_messages(frame, t, ("cam",))]
        events, stats = decode_stream(b"".join(encode(m) for m in msgs))
        assert stats.messages == 2, f"case {case}"
        for ev, values, per_unit, half_step in ((events[0], j3, 1000.0, 0.5e-3), (events[1], j2, 4.0, 0.125)):
            m = ev.message
            h = m.header
            assert (h.seq, h.capture_us) == (seq % 2**32, t)
            coords = m.xyz_mm if isinstance(m, Joints) else m.uv_q
            missing, wire_conf = _expect(values[:, :-1], values[:, -1], per_unit)
            assert m.missing.tolist() == missing.tolist(), f"case {case}"
            assert m.conf.tolist() == wire_conf.astype(int).tolist(), f"case {case}"
            assert not coords[missing].any()
            sent = coords[~missing] / per_unit
            assert np.all(np.abs(sent - values[~missing, :-1]) <= half_step * (1 + 1e-9)), f"case {case}"


@pytest.mark.parametrize(("msg", "field"), [
    # A float passed the range check and failed in struct.pack ("required argument is not an integer") or
    # bytes(), naming no field; None failed on "<=".
    (Joints(make_header(MsgType.JOINTS, 1, 0, 1e6), 0, np.zeros((1, 3), np.int16), np.ones(1, np.uint8),
            np.zeros(1, bool)), "header.send_us"),
    (Joints(make_header(MsgType.JOINTS, np.float64(3), 0, 0), 0, np.zeros((1, 3), np.int16), np.ones(1, np.uint8),
            np.zeros(1, bool)), "header.seq"),
    (Joints(make_header(MsgType.JOINTS, None, 0, 0), 0, np.zeros((1, 3), np.int16), np.ones(1, np.uint8),  # type: ignore[arg-type]
            np.zeros(1, bool)), "header.seq"),
    (Joints(make_header(MsgType.JOINTS, 1, 0, 0), 1.0, np.zeros((1, 3), np.int16), np.ones(1, np.uint8),
            np.zeros(1, bool)), "joints.joint_set"),
    (Joints2D(make_header(MsgType.JOINTS_2D, 1, 0, 0), 0.0, 0, np.zeros((1, 2), np.int16), np.ones(1, np.uint8),
              np.zeros(1, bool)), "joints_2d.camera"),
    (Status(make_header(MsgType.STATUS, 1, 0, 0), 2997.5, 0, 0, 0, 0), "status.fps_centi"),
    (Status(make_header(MsgType.STATUS, 1, 0, 0), 0, 4.2e4, 0, 0, 0), "status.latency_us"),
    (Hello(make_header(MsgType.HELLO, 1, 0, 0), 1, 0, 25.0, 0, 0, "rig", ()), "hello.joint_count"),
    # One string where a sequence of names belongs went out as one camera per letter: "l", "e", "f", "t".
    (Hello(make_header(MsgType.HELLO, 1, 0, 0), 1, 0, 25, 0, 0, "rig", "left"), "hello.cameras"),
    (Hello(make_header(MsgType.HELLO, 1, 0, 0), 1, 0, 25, 0, 0, "rig", (b"left",)), "hello.cameras"),
    (Hello(make_header(MsgType.HELLO, 1, 0, 0), 1, 0, 25, 0, 0, None, ()), "hello.rig_id"),
])
def test_fields_that_are_not_whole_numbers_or_names_are_refused_naming_them(msg: object, field: str) -> None:
    with pytest.raises(EncodeError) as info:
        encode(msg)  # type: ignore[arg-type]
    assert info.value.field == field


def test_integer_like_fields_still_encode() -> None:
    """numpy integers, bools and IntEnum/IntFlag values are whole numbers: the check must not refuse them."""
    from firmware_host.protocol import Fault, Flags

    msg = Status(make_header(MsgType.STATUS, np.uint32(U32_MAX), np.uint64(U64_MAX), np.int64(0), Flags.DROPPED),
                 np.uint16(3000), np.int64(1), True, 0, Fault.LINK_ERRORS)
    (event,), _ = decode_stream(encode(msg))
    assert event.to_json() == {"type": "STATUS", "version": 1, "flags": 2, "seq": U32_MAX, "capture_us": U64_MAX,
                               "send_us": 0, "fps_centi": 3000, "latency_us": 1, "dropped": 1, "decimated": 0,
                               "fault": 3}
