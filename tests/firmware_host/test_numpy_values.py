"""Sinks called from a user's own code with NumPy values: keyword options and JointFrame fields as numpy scalars,
joints arrays of other dtypes and layouts (docs/protocol.md, "NumPy values")."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from firmware_host.errors import SinkConfigError
from firmware_host.protocol import Joints, Joints2D
from firmware_host.protocol.messages import JointFrame
from firmware_host.sinks import open_sink
from firmware_host.sinks.backoff import BackoffPolicy
from firmware_host.sinks.registry import sink_class
from tests.firmware_host.joint_stream_helpers import messages_of


def _joints(seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    return np.column_stack([rng.uniform(-1.0, 1.0, (25, 3)), rng.uniform(0.2, 1.0, 25)])


def _wire_joints(frame: JointFrame, **kw) -> list:
    """The JOINTS and JOINTS_2D rows a memory:// sink sends for ``frame``."""
    sink = open_sink("memory://", **kw)
    sink.send(frame)
    sink.close()
    return [m.to_json()["joints"] for m in messages_of(sink.read()) if isinstance(m, (Joints, Joints2D))]


@pytest.mark.parametrize("url, key, value, plain", [
    ("serial:///dev/null", "baud", np.int64(921600), 921600),
    ("serial:///dev/null", "baud", np.uint32(9600), 9600),
    ("memory://", "queue", np.int64(8), 8),
    ("memory://", "max_fps", np.float32(30.0), 30.0),
    ("memory://", "status_s", np.float32(0.5), 0.5),
    ("memory://", "send_2d", np.True_, True),
    ("serial:///dev/null", "baud", np.array(9600), 9600),  # a 0-d array: the value it holds
    ("memory://", "max_fps", np.array(30.0, np.float32), 30.0),
    ("memory://", "send_2d", np.array(True), True),
    ("serial:///dev/null", "baud", np.str_("9600"), 9600),  # NumPy text is read as text is
    ("memory://", "send_2d", np.array("yes"), True),
])
def test_a_numpy_keyword_is_taken_as_the_python_value_it_holds(url, key, value, plain) -> None:
    kw = {key: value, "cameras": ("left", "right")} if key == "send_2d" else {key: value}
    sink = sink_class(url).from_url(url, **kw)
    got = getattr(sink, key, None) if key == "baud" else getattr(sink.options, key)
    assert got == plain and type(got) is type(plain)


@pytest.mark.parametrize("url, key, value, why", [
    ("serial:///dev/null", "baud", np.int64(-5), "without a sign"),
    ("serial:///dev/null", "baud", np.float32(921600.5), "whole number"),  # not truncated to 921600
    ("serial:///dev/null", "baud", np.True_, "not true/false"),  # not a baud of 1
    ("memory://", "queue", np.float32(8.5), "whole number"),
    ("memory://", "queue", np.True_, "not true/false"),
    ("memory://", "fps", np.float32(np.inf), "finite"),
    ("memory://", "max_bytes", np.int64(0), "> 0"),
    # a 0-d array or a complex number was taken as an object and skipped every check
    ("serial:///dev/null", "baud", np.array(-5), "without a sign"),
    ("memory://", "queue", np.array(True), "not true/false"),
    ("serial:///dev/null", "baud", np.complex128(9600), "must be a real number, not complex"),
    ("serial:///dev/null", "baud", 9600 + 0j, "must be a real number, not complex"),
    ("memory://", "fps", np.array(30 + 0j), "must be a real number, not complex"),
    # bytes, Python's or NumPy's, were taken as objects too: queue=b"8" failed later with a bare TypeError,
    # max_bytes=np.bytes_(b"5") failed every write, send_2d=b"no" was read as yes (a non-empty object)
    ("memory://", "queue", b"8", "not bytes"),
    ("memory://", "max_bytes", np.bytes_(b"5"), "not bytes"),
    ("memory://", "send_2d", np.array(b"no"), "not bytes"),
    ("serial:///dev/null", "baud", bytearray(b"9600"), "not bytes"),
])
def test_a_numpy_keyword_is_checked_as_a_python_one(url, key, value, why) -> None:
    # such values were taken as objects and skipped every check: baud=np.int64(-5) reached the serial port
    with pytest.raises(SinkConfigError, match=why) as err:
        sink_class(url).from_url(url, **{key: value})
    assert err.value.field == key


def test_a_keyword_of_a_0d_array_holding_none_is_not_given() -> None:
    # None counts as not given; the same None in a 0-d array came back as the value, unchecked (baud None)
    url = "serial:///dev/null?baud=19200"
    assert sink_class(url).from_url(url, baud=np.array(None, dtype=object)).baud == 19200


def test_joints_of_another_dtype_or_layout_go_out_as_float64_ones() -> None:
    joints = _joints()
    sent = _wire_joints(JointFrame(0, 0, 0, joints))
    wide = np.zeros((25, 8))
    wide[:, ::2] = joints
    read_only = joints.copy()
    read_only.setflags(write=False)
    for layout in (joints.astype(np.float32), wide[:, ::2], np.asfortranarray(joints), read_only, joints.tolist()):
        assert _wire_joints(JointFrame(0, 0, 0, layout)) == sent


def test_nan_and_inf_joints_go_out_missing() -> None:
    joints = _joints()
    joints[3, 0], joints[4, 1], joints[5, 2], joints[6, 3] = np.nan, np.inf, -np.inf, np.nan
    rows = _wire_joints(JointFrame(0, 0, 0, joints.astype(np.float32)))[0]
    assert [row[-1] for row in rows[3:7]] == [1, 1, 1, 1] and all(row[:4] == [0, 0, 0, 0] for row in rows[3:7])
    assert rows[7][-1] == 0


def test_numpy_integer_fields_are_kept_as_python_ints(tmp_path: Path) -> None:
    # np.int64 kept as given failed the file:// sink's json.dumps in its worker: the frame was lost
    frame = JointFrame(np.int64(7), np.uint64(1_000), np.uint8(0), _joints().astype(np.float32),
                       joints_2d={np.int64(1): _joints()[:, :3]}, scene_flags=np.int64(0))
    assert all(type(v) is int for v in (frame.sequence, frame.capture_time_us, frame.joint_set, frame.scene_flags))
    path = tmp_path / "joints.jsonl"
    sink = open_sink(f"file://{path}", send_2d=True, cameras=("left", "right"))
    sink.send(frame)
    stats = sink.close()
    assert stats.sent == 1 and stats.dropped_error == 0
    lines = [json.loads(line) for line in path.read_text().splitlines()]
    assert [(m["type"], m["seq"]) for m in lines if m["type"].startswith("JOINTS")] == [("JOINTS", 7), ("JOINTS_2D", 7)]


@pytest.mark.parametrize("field", ["sequence", "capture_time_us", "joint_set", "scene_flags"])
@pytest.mark.parametrize("flag", [True, np.True_])
def test_true_is_no_frame_field(field, flag) -> None:
    args = {"sequence": 0, "capture_time_us": 0, "joint_set": 0, "joints_3d": _joints(), field: flag}
    with pytest.raises(ValueError, match=rf"JointFrame\.{field} must be a whole number, not true/false"):
        JointFrame(**args)


def test_true_is_no_camera_key() -> None:
    # True indexed camera 1: its joints went out as the second camera's
    with pytest.raises(ValueError, match=r"joints_2d key True: a camera name or index, not true/false"):
        JointFrame(0, 0, 0, _joints(), joints_2d={True: _joints()[:, :3]})


@pytest.mark.parametrize("joints, dtype", [
    (np.ones((25, 4), bool), "bool"),  # went out as 1 m joints of confidence 1
    (np.array([[None] * 4] * 25), "object"),
    (np.full((25, 4), "1"), "<U1"),
    (_joints().astype(complex), "complex128"),  # its imaginary part dropped with a warning
])
def test_joints_that_are_not_real_numbers_are_refused(joints, dtype) -> None:
    with pytest.raises(ValueError, match=rf"JointFrame\.joints_3d must hold real numbers .*got dtype {dtype}"):
        JointFrame(0, 0, 0, joints)
    with pytest.raises(ValueError, match=r"JointFrame\.joints_2d\['left'\] must hold real numbers"):
        JointFrame(0, 0, 0, _joints(), joints_2d={"left": joints[:, :3]})


def test_a_backoff_policy_takes_numpy_numbers_and_refuses_true() -> None:
    policy = BackoffPolicy(initial_s=np.float32(0.5), factor=np.int64(3), max_s=np.float64(4.0))
    assert (policy.initial_s, policy.factor, policy.max_s) == (0.5, 3.0, 4.0)
    assert all(type(v) is float for v in (policy.initial_s, policy.factor, policy.max_s))
    for name, value in (("initial_s", True), ("factor", np.True_), ("max_s", "2")):  # True was a 1 s wait
        with pytest.raises(ValueError, match=rf"{name} must be a number, got {re.escape(repr(value))}"):
            BackoffPolicy(**{name: value})


@pytest.mark.parametrize("policy", [dict(initial_s=10**400), dict(max_s=10**400), dict(initial_s=-10**400),
                                    dict(factor=10**400)])
def test_a_backoff_policy_past_the_float_range_is_refused_by_name(policy: dict) -> None:
    """An integer past the float range is refused as out of bounds, a ValueError naming the policy; kept as floats,
    the fields raised a bare OverflowError from float() (and factor from math.isfinite before that)."""
    with pytest.raises(ValueError, match=r"invalid backoff policy BackoffPolicy\(.*inf"):
        BackoffPolicy(**policy)
