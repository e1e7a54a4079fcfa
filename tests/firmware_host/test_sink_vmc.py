"""vmc:// on 127.0.0.1, parsed by python-osc's own parser."""
from __future__ import annotations

import socket

import numpy as np
from pythonosc.osc_bundle import OscBundle
from pythonosc.osc_packet import OscPacket

from firmware_host.sinks import open_sink
from firmware_host.sinks.vmc_pose import BONE_PARENTS
from ghnerf_runtime.body25 import JOINT_INDEX as J
from tests.firmware_host.joint_stream_helpers import FAST_BACKOFF, make_frame, t_pose_rig


def _receive(frames: list) -> list[bytes]:
    rx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    rx.bind(("127.0.0.1", 0))
    rx.settimeout(5)
    sink = open_sink(f"vmc://127.0.0.1:{rx.getsockname()[1]}?queue=8", backoff=FAST_BACKOFF)
    try:
        assert sink.wait_connected(5)
        for f in frames:
            sink.send(f)
        got = [rx.recv(65536) for _ in frames]
    finally:
        stats = sink.close()
        rx.close()
    assert stats.sent == len(frames)
    return got


def test_one_bundle_per_frame_with_ok_time_root_and_bones() -> None:
    j = t_pose_rig(facing_camera=True)
    j[J["LWrist"], :3] = j[J["LElbow"], :3] + [0, -0.25, 0]  # forearm raised
    dgram, second = _receive([make_frame(0, joints=j), make_frame(1, joints=j)])
    assert OscBundle.dgram_is_bundle(dgram)
    msgs = [m.message for m in OscPacket(dgram).messages]
    addresses = [m.address for m in msgs]
    assert addresses[:3] == ["/VMC/Ext/OK", "/VMC/Ext/T", "/VMC/Ext/Root/Pos"]
    assert addresses[3:] == ["/VMC/Ext/Bone/Pos"] * len(BONE_PARENTS)
    assert msgs[0].params == [1, 3, 0, 1]
    assert msgs[1].params == [0.0]
    root = msgs[2].params
    assert root[0] == "root" and np.allclose(root[1:4], [0.0, 0.0, 3.0]) and np.allclose(root[4:], [0, 0, 0, 1])
    bones = {m.params[0]: np.array(m.params[1:], dtype=float) for m in msgs[3:]}
    assert set(bones) == set(BONE_PARENTS)
    # Facing the cameras: the hips turn half way round (q = +-(0, 1, 0, 0)).
    assert np.allclose(np.abs(bones["Hips"][3:]), [0, 1, 0, 0], atol=1e-6)
    # The person's left forearm points up (Unity +y) instead of along the upper arm.
    assert not np.allclose(bones["LeftLowerArm"][3:], [0, 0, 0, 1], atol=1e-3)
    assert np.allclose(bones["RightLowerArm"][3:], [0, 0, 0, 1], atol=1e-6)
    assert all(len(v) == 7 for v in bones.values())
    t1 = [m.message for m in OscPacket(second).messages][1].params[0]
    assert abs(t1 - 0.033333) < 1e-5  # seconds since the first frame


def test_lost_hips_sends_tracking_lost_only() -> None:
    j = t_pose_rig()
    j[J["MidHip"], 3] = 0.0
    (dgram,) = _receive([make_frame(0, joints=j)])
    msgs = [m.message for m in OscPacket(dgram).messages]
    assert [m.address for m in msgs] == ["/VMC/Ext/OK", "/VMC/Ext/T"]
    assert msgs[0].params[3] == 0
