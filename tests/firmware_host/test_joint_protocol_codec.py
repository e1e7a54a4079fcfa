"""Encoder, quantisation and streaming decoder of the joint protocol."""
from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from firmware_host.errors import EncodeError
from firmware_host.protocol import (
    Flags,
    Hello,
    JointFrame,
    Joints,
    Joints2D,
    MsgType,
    Status,
    StreamDecoder,
    decode_stream,
    encode,
    encode_packet,
    joints_message,
    joints_packet_len,
    make_header,
    parse_packet,
    wire_len,
)
from firmware_host.protocol.constants import U32_MAX
from firmware_host.protocol.from_frame import joints2d_messages
from firmware_host.protocol.quantize import quantise_joints_2d, quantise_joints_3d, xyz_fits_the_wire

header = st.builds(
    make_header,
    st.sampled_from([MsgType.JOINTS]),
    st.integers(0, U32_MAX),
    st.integers(0, 2**64 - 1),
    st.integers(0, 2**64 - 1),
    st.integers(0, 255),
)


@st.composite
def joints_messages(draw: st.DrawFn) -> Joints:
    n = draw(st.integers(0, 64))
    xyz = draw(hnp.arrays(np.int16, (n, 3)))
    conf = draw(hnp.arrays(np.uint8, (n,)))
    missing = draw(hnp.arrays(np.bool_, (n,)))
    return Joints(draw(header), draw(st.integers(0, 255)), xyz, conf, missing)


@settings(max_examples=200, deadline=None)
@given(joints_messages())
def test_joints_round_trip(msg: Joints) -> None:
    wire = encode(msg)
    assert wire.endswith(b"\x00") and wire.count(0) == 1  # COBS leaves one zero: the delimiter
    events, stats = decode_stream(wire)
    assert stats.messages == 1
    assert events[0].message == msg


def test_every_message_type_round_trips() -> None:
    hello = Hello(make_header(MsgType.HELLO, 3, 10, 11), 1, 0, 25, 0, 0, "rig 7", ("left", "right"))
    status = Status(make_header(MsgType.STATUS, 4, 12, 13), 2997, 41000, 2, 30, 1)
    frame = JointFrame(5, 14, 0, np.random.default_rng(0).random((25, 4)),
                       {"right": np.full((25, 3), 100.25), 0: np.full((25, 3), 7.5)})
    msgs = [hello, status, joints_message(frame, 15), *joints2d_messages(frame, 15, ("left", "right"))]
    events, _ = decode_stream(b"".join(encode(m) for m in msgs))
    assert [e.message for e in events] == msgs
    assert [m.camera for m in msgs[3:]] == [0, 1]  # sorted by announced index


def test_body25_frame_is_206_bytes_and_208_on_the_wire() -> None:
    frame = JointFrame(1, 2, 0, np.random.default_rng(1).random((25, 4)))
    packet = encode_packet(joints_message(frame, 3))
    assert len(packet) == joints_packet_len(25) == 206
    assert len(encode(joints_message(frame, 3))) == wire_len(206) == 208


def test_quantisation_rules() -> None:
    j = np.array(
        [
            [1.0004, -0.0006, 2.5, 1.0],  # rounds to mm
            [np.nan, 0.0, 1.0, 0.9],  # NaN coordinate -> missing
            [0.1, 0.1, 0.1, 0.0],  # confidence 0 -> missing
            [0.1, 0.1, 0.1, np.nan],  # NaN confidence -> missing
            [40.0, 0.0, 1.0, 0.9],  # beyond int16 mm (32.767 m) -> missing
            [0.0, 0.0, 0.0, 0.0001],  # tiny confidence stays present: 1, never 0
        ]
    )
    xyz, conf, missing = quantise_joints_3d(j)
    assert xyz[0].tolist() == [1000, -1, 2500] and conf[0] == 255
    assert missing.tolist() == [False, True, True, True, True, False]
    assert (xyz[missing] == 0).all() and (conf[missing] == 0).all()
    assert conf[5] == 1
    uv, conf2, missing2 = quantise_joints_2d(np.array([[10.1, 20.9, 0.5], [9000.0, 0.0, 1.0]]))
    assert uv[0].tolist() == [40, 84] and conf2[0] == 128 and missing2.tolist() == [False, True]



def test_absurd_values_quantise_by_the_rules_without_numpy_warnings() -> None:
    # 1e308 m scaled to mm overflows to inf: numpy warned "overflow encountered in multiply" (raised under
    # -W error) although the rules already make such a joint missing, and cap the confidence at 255.
    j = np.array(
        [
            [1e308, 0.0, 1.0, 0.9],  # coordinate overflows when scaled -> missing
            [-np.inf, 0.0, 1.0, 0.9],  # infinite coordinate -> missing
            [0.1, 0.2, 0.3, 1e308],  # confidence overflows when scaled -> 255
            [0.1, 0.2, 0.3, np.inf],  # infinite confidence -> 255
            [0.1, 0.2, 0.3, 2.0],  # above 1 -> 255
        ]
    )
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        xyz, conf, missing = quantise_joints_3d(j)
        uv, conf2, missing2 = quantise_joints_2d(np.array([[1e308, 0.0, 1.0], [5.0, 6.0, 1e308]]))
    assert missing.tolist() == [True, True, False, False, False]
    assert conf.tolist() == [0, 0, 255, 255, 255] and xyz[2].tolist() == [100, 200, 300]
    assert missing2.tolist() == [True, False] and conf2.tolist() == [0, 255] and uv[1].tolist() == [20, 24]


def _reference_quantised(row: list[float], scale: float) -> tuple[list[int], int, bool]:
    """One joint as the wire's rule says it, one value at a time in plain Python: each coordinate times ``scale``,
    rounded half to even (as ``np.rint``), must be a number within int16, and the confidence above 0; a missing
    joint goes out as zeros, a present one's confidence as round(255 c) within 1..255."""
    coords, conf = row[:-1], row[-1]
    scaled = [v * scale for v in coords]
    fits = all(math.isfinite(s) and -32768 <= round(s) <= 32767 for s in scaled)
    if not (fits and conf > 0):
        return [0] * len(coords), 0, True
    c = conf * 255
    return [round(s) for s in scaled], 255 if c >= 255 else max(1, round(c)), False


def _edge_rows(rng: np.random.Generator, n: int, dims: int, scale: float) -> np.ndarray:
    """``n`` joints of ``dims`` coordinates and a confidence, each value drawn from the wire's edges: ties half a
    unit either side of its ends (32767.5 mm: 32.7675 m), the ends themselves, ties anywhere, NaN, inf, overflow
    when scaled, -0.0, the smallest subnormal, and plain values within and beyond the range."""
    ends = np.array([-32768.5, -32768.0, -32767.5, 32766.5, 32767.0, 32767.5, 32768.0, -32769.5]) / scale
    specials = np.array([np.nan, np.inf, -np.inf, 1e305, -1e305, 1e308, -1e308, -0.0, 5e-324])
    confs = np.array([np.nan, -1.0, 0.0, 5e-324, 1e-4, 0.5, 254.5 / 255, 2.0, 1e308, np.inf])

    def draw(size: int, pool: np.ndarray, span: float) -> np.ndarray:
        kind = rng.integers(0, 4, size)
        ties = (rng.integers(-33000, 33000, size) + 0.5) / scale
        return np.select([kind == 0, kind == 1, kind == 2], [rng.choice(pool, size), ties,
                                                            rng.uniform(-span, span, size)], rng.choice(specials, size))

    coords = draw(n * dims, ends, 40000 / scale).reshape(n, dims)
    conf = np.where(rng.random(n) < 0.5, rng.choice(confs, n), (rng.integers(0, 256, n) + 0.5) / 255)
    return np.column_stack([coords, conf])


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
@pytest.mark.parametrize("seed", range(8))
def test_quantisation_is_the_plain_rule_value_by_value_at_the_wire_s_edges(seed: int, dtype: type) -> None:
    # Session 72 moved the rule into xyz_fits_the_wire, shared with the VMC sink: the encoder's output must stay
    # what the rule says for every value, ties at +-32.7675 m, NaN and inf included (the frame's bytes are these).
    rng = np.random.default_rng(7200 + seed)
    for quantise, dims, scale in ((quantise_joints_3d, 3, 1000.0), (quantise_joints_2d, 2, 4.0)):
        with np.errstate(over="ignore"):  # float64 values past float32's range are inf there
            rows = _edge_rows(rng, 400, dims, scale).astype(dtype)
        with warnings.catch_warnings():
            warnings.simplefilter("error")
            q, c, missing = quantise(rows)
        expected = [_reference_quantised([float(v) for v in row], scale) for row in rows]
        assert (q.dtype, c.dtype, missing.dtype) == (np.int16, np.uint8, np.bool_)
        assert q.tolist() == [e[0] for e in expected]
        assert c.tolist() == [e[1] for e in expected]
        assert missing.tolist() == [e[2] for e in expected]
        if dims == 3:  # the VMC sink's rule: the coordinates alone
            fits = [_reference_quantised([float(v) for v in row[:3]] + [1.0], scale)[2] is False for row in rows]
            assert xyz_fits_the_wire(rows[:, :3]).tolist() == fits


def test_sequence_wraps_modulo_2_32() -> None:
    frame = JointFrame(2**32 + 5, 0, 0, np.zeros((25, 4)))
    assert joints_message(frame, 0).header.seq == 5


@pytest.mark.parametrize(
    ("msg", "field"),
    [
        (Hello(make_header(MsgType.HELLO, 0, 0, 0), 1, 0, 25, 0, 0, "caf\u00e9", ()), "hello.rig_id"),
        (Hello(make_header(MsgType.HELLO, 0, 0, 0), 1, 0, 25, 0, 0, "x" * 33, ()), "hello.rig_id"),
        (Hello(make_header(MsgType.HELLO, 0, 0, 0), 1, 0, 25, 0, 0, "r", ("c",) * 9), "hello.cameras"),
        (Status(make_header(MsgType.STATUS, 0, 0, 0), 70000, 0, 0, 0, 0), "status.fps_centi"),
        (Status(make_header(MsgType.STATUS, 0, -1, 0), 0, 0, 0, 0, 0), "header.capture_us"),
        (Joints(make_header(MsgType.JOINTS, 0, 0, 0), 0, np.zeros((65, 3), np.int16), np.zeros(65, np.uint8),
                np.zeros(65, bool)), "joints.count"),
        # values that numpy's cast wrapped (40000 mm went out as -25536) and a mask of another length (a
        # packet every decoder refused)
        (Joints(make_header(MsgType.JOINTS, 0, 0, 0), 0, np.array([[40000, 0, 0]]), np.array([200]),
                np.array([False])), "joints.xyz_mm"),
        (Joints(make_header(MsgType.JOINTS, 0, 0, 0), 0, np.array([[1.5, 0, 0]]), np.array([200]),
                np.array([False])), "joints.xyz_mm"),
        (Joints(make_header(MsgType.JOINTS, 0, 0, 0), 0, np.zeros((1, 3), np.int16), np.array([300]),
                np.array([False])), "joints.conf"),
        (Joints(make_header(MsgType.JOINTS, 0, 0, 0), 0, np.zeros((25, 3), np.int16), np.zeros(25, np.uint8),
                np.zeros(8, bool)), "joints.missing"),
        # a mask of integers other than 0/1, or of floats (was numpy's ValueError, naming no field)
        (Joints(make_header(MsgType.JOINTS, 0, 0, 0), 0, np.zeros((2, 3), np.int16), np.zeros(2, np.uint8),
                np.array([0, 2])), "joints.missing"),
        (Joints2D(make_header(MsgType.JOINTS_2D, 0, 0, 0), 0, 0, np.zeros((2, 2), np.int16), np.zeros(2, np.uint8),
                  np.array([0.0, 1.0])), "joints_2d.missing"),
        (Joints2D(make_header(MsgType.JOINTS_2D, 0, 0, 0), 0, 0, np.zeros((2, 3), np.int16), np.zeros(2, np.uint8),
                  np.zeros(2, bool)), "joints_2d.uv_q"),
        (Joints2D(make_header(MsgType.JOINTS_2D, 0, 0, 0), 0, 0, np.zeros((2, 2), np.int16), np.full(2, -1),
                  np.zeros(2, bool)), "joints_2d.conf"),
    ],
)
def test_encode_errors_name_the_field(msg: object, field: str) -> None:
    with pytest.raises(EncodeError, match=field.replace(".", r"\.")) as info:
        encode(msg)  # type: ignore[arg-type]
    assert info.value.field == field


def test_integer_missing_mask_encodes_as_bits() -> None:
    msg = Joints(make_header(MsgType.JOINTS, 0, 0, 0), 0, np.zeros((9, 3), np.int16), np.ones(9, np.uint8),
                 np.array([0, 1, 0, 0, 0, 0, 0, 0, 1]))
    decoded = decode_stream(encode(msg))[0][0].message
    assert decoded is not None and np.flatnonzero(decoded.missing).tolist() == [1, 8]


def test_joint_frame_checks_shapes() -> None:
    with pytest.raises(ValueError, match=r"joints_3d must have shape \(J, 4\)"):
        JointFrame(0, 0, 0, np.zeros((25, 3)))
    with pytest.raises(ValueError, match=r"joints_2d\['left'\]"):
        JointFrame(0, 0, 0, np.zeros((25, 4)), {"left": np.zeros((25, 2))})


def test_a_frame_of_more_joints_than_a_packet_carries_is_refused_when_made() -> None:
    # 65 joints: made and sent without a word, then an EncodeError (a logged traceback) in a protocol sink's worker
    # thread for every frame, none of them sent
    with pytest.raises(ValueError, match=r"JointFrame\.joints_3d has 65 joints: .* at most 64 per frame \(MAX_JOINTS"):
        JointFrame(0, 0, 0, np.zeros((65, 4)))
    with pytest.raises(ValueError, match=r"JointFrame\.joints_2d\[1\] has 70 joints: .* at most 64"):
        JointFrame(0, 0, 0, np.zeros((25, 4)), {1: np.zeros((70, 3))})
    frame = JointFrame(0, 0, 0, np.zeros((64, 4)), {0: np.zeros((64, 3))})  # the most a packet carries: sent
    assert decode_stream(encode(joints_message(frame, 0, 0)))[0][0].message.xyz_mm.shape == (64, 3)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        # time.monotonic() * 1e6 is a float: it failed in the sink's worker and poisoned every later HELLO/STATUS
        ({"capture_time_us": 1_000_000.5}, "capture_time_us"),
        ({"capture_time_us": -1}, "capture_time_us"),
        ({"capture_time_us": 2**64}, "capture_time_us"),
        ({"sequence": 3.0}, "sequence"),
        ({"joint_set": 256}, "joint_set"),
    ],
)
def test_joint_frame_checks_its_wire_integers(kwargs: dict, field: str) -> None:
    args = {"sequence": 0, "capture_time_us": 0, "joint_set": 0, **kwargs}
    with pytest.raises(ValueError, match=rf"JointFrame\.{field} must be"):
        JointFrame(joints_3d=np.zeros((25, 4)), **args)
    # numpy integers are whole numbers too (a driver's timestamp_ns // 1000)
    assert JointFrame(np.int64(7), np.uint64(2**63), np.uint8(0), np.zeros((25, 4))).capture_time_us == 2**63


def test_unknown_camera_name_is_a_clear_error() -> None:
    frame = JointFrame(0, 0, 0, np.zeros((25, 4)), {"middle": np.zeros((25, 3))})
    with pytest.raises(KeyError, match="middle"):
        joints2d_messages(frame, 0, ("left", "right"))


def test_parse_packet_reports_codes() -> None:
    good = encode_packet(Status(make_header(MsgType.STATUS, 1, 2, 3), 1, 2, 3, 4, 5))
    assert isinstance(parse_packet(good), Status)
    from firmware_host.errors import FrameError, UnknownMessageType

    with pytest.raises(FrameError) as e:
        parse_packet(good[:-1] + bytes([good[-1] ^ 1]))
    assert e.value.code == "crc"
    with pytest.raises(FrameError) as e:
        parse_packet(good[:10])
    assert e.value.code == "short"
    from firmware_host.protocol.encoder import seal

    with pytest.raises(UnknownMessageType) as u:
        parse_packet(seal(bytes([1, 0x55]) + good[2:-2]))
    assert u.value.msg_type == 0x55


@settings(max_examples=100, deadline=None)
@given(st.lists(st.integers(1, 300), min_size=1, max_size=30), st.binary(max_size=200))
def test_chunking_does_not_change_the_result(cuts: list[int], garbage: bytes) -> None:
    frames = [JointFrame(i, i * 1000, 0, np.full((25, 4), 0.5)) for i in range(4)]
    data = garbage + b"".join(encode(joints_message(f, 0, Flags.DROPPED)) for f in frames) + garbage
    whole, _ = decode_stream(data)
    d = StreamDecoder()
    pieces, pos, i = [], 0, 0
    while pos < len(data):
        step = cuts[i % len(cuts)]
        pieces += d.feed(data[pos : pos + step])
        pos, i = pos + step, i + 1
    assert [e.to_json() for e in pieces] == [e.to_json() for e in whole]
    # The four frames survive whatever garbage surrounds them, except one glued to garbage.
    seqs = [e.message.header.seq for e in whole if e.message is not None]
    assert set(seqs) >= {1, 2, 3}


def test_decoder_memory_is_bounded() -> None:
    d = StreamDecoder()
    for _ in range(100):
        assert d.feed(b"\x41" * 10_000) == []
    assert len(d._buf) == 0  # discarded, not accumulated
    assert [e.code for e in d.feed(b"\x00")] == ["oversize"]


def test_worked_example_in_docs_encodes_exactly() -> None:
    # docs/protocol.md, "Worked example": the same STATUS message, header to delimiter.
    msg = Status(make_header(MsgType.STATUS, 42, 1_000_000, 1_031_656), 3000, 42000, 3, 120, 1)
    assert encode_packet(msg).hex(" ") == (
        "01 02 00 2a 00 00 00 40 42 0f 00 00 00 00 00 e8 bd 0f 00 00 00 00 00 "
        "b8 0b 10 a4 00 00 03 00 00 00 78 00 00 00 01 00 d5 f8"
    )
    assert encode(msg).hex(" ") == (
        "03 01 02 02 2a 01 01 04 40 42 0f 01 01 01 01 04 e8 bd 0f 01 01 01 01 05 "
        "b8 0b 10 a4 01 02 03 01 01 02 78 01 01 02 01 03 d5 f8 00"
    )
