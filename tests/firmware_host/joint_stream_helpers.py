"""Shared helpers for the joint-stream tests (frames, poses, waiting, decoding, a take recorded on a given clock)."""
from __future__ import annotations

import socket
import time
from typing import Callable

import numpy as np

import drivers
from drivers.clock import Clock
from firmware_host.protocol import JointFrame, decode_stream
from firmware_host.protocol.messages import Message
from firmware_host.sinks.backoff import BackoffPolicy
from ghnerf_runtime.body25 import JOINT_INDEX

# Fast retries so reconnect tests take milliseconds, not seconds.
FAST_BACKOFF = BackoffPolicy(initial_s=0.005, factor=2.0, max_s=0.05)
FRAME_US = 33_333  # 30 fps


def t_pose_rig(facing_camera: bool = False) -> np.ndarray:
    """(25, 4) T-pose in the rig frame (x right, y down, z forward), metres, standing 3 m away.

    By default the person faces away from the cameras (rig +z), which is the
    avatar's rest orientation; ``facing_camera`` turns them 180 degrees about
    the vertical axis.
    """
    p = {
        "MidHip": (0.0, 0.0, 0.0), "Neck": (0.0, -0.5, 0.0), "Nose": (0.0, -0.63, 0.1),
        "RShoulder": (0.18, -0.5, 0.0), "RElbow": (0.45, -0.5, 0.0), "RWrist": (0.70, -0.5, 0.0),
        "LShoulder": (-0.18, -0.5, 0.0), "LElbow": (-0.45, -0.5, 0.0), "LWrist": (-0.70, -0.5, 0.0),
        "RHip": (0.1, 0.0, 0.0), "RKnee": (0.1, 0.45, 0.0), "RAnkle": (0.1, 0.9, 0.0),
        "LHip": (-0.1, 0.0, 0.0), "LKnee": (-0.1, 0.45, 0.0), "LAnkle": (-0.1, 0.9, 0.0),
        "REye": (0.035, -0.66, 0.08), "LEye": (-0.035, -0.66, 0.08),
        "REar": (0.08, -0.63, 0.0), "LEar": (-0.08, -0.63, 0.0),
        "LBigToe": (-0.09, 0.95, 0.15), "LSmallToe": (-0.13, 0.95, 0.13), "LHeel": (-0.11, 0.95, -0.04),
        "RBigToe": (0.09, 0.95, 0.15), "RSmallToe": (0.13, 0.95, 0.13), "RHeel": (0.11, 0.95, -0.04),
    }
    j = np.zeros((25, 4))
    for name, xyz in p.items():
        j[JOINT_INDEX[name], :3] = xyz
        j[JOINT_INDEX[name], 3] = 0.9
    if facing_camera:
        j[:, 0] *= -1
        j[:, 2] *= -1
    j[:, 2] += 3.0
    return j


def make_frame(seq: int, t0_us: int = 10_000_000, period_us: int = FRAME_US, joints: np.ndarray | None = None,
               joints_2d: dict | None = None) -> JointFrame:
    j = t_pose_rig() if joints is None else joints
    return JointFrame(seq, t0_us + seq * period_us, 0, j, joints_2d or {})


def record_take(url: str, clock: Clock, pairs: int) -> list[int]:
    """Read ``pairs`` pairs from ``url`` (a ``record+`` URL: the take is written as they pass) on ``clock``; the
    first camera's stamps, as the take holds them."""
    with drivers.open_rig(url, clock=clock) as rig:
        return [rig.read(timeout_s=5.0).frames[0].timestamp_ns for _ in range(pairs)]


def wait_until(predicate: Callable[[], bool], timeout: float = 5.0, what: str = "condition") -> None:
    """Poll until ``predicate()``; fail the test with ``what`` if it never holds.

    This waits for events in other threads; it never asserts how long they took.
    """
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
        time.sleep(0.002)


def messages_of(data: bytes) -> list[Message]:
    events, stats = decode_stream(data)
    assert sum(stats.errors.values()) == 0, f"decode errors: {stats.to_json()}"
    return [e.message for e in events if e.message is not None]


def joints_seqs(messages: list[Message]) -> list[int]:
    return [m.header.seq for m in messages if type(m).__name__ == "Joints"]


def queued_datagrams(sock: socket.socket) -> list[bytes]:
    """Every datagram already queued on ``sock`` (left non-blocking): on loopback a sent datagram is queued on the
    receiver within ``sendto``, so once the sender is drained all of them are here."""
    sock.setblocking(False)
    datagrams: list[bytes] = []
    while True:
        try:
            datagrams.append(sock.recv(65536))
        except BlockingIOError:
            return datagrams


def mask_rules_packet() -> bytes:
    """A JOINTS packet no encoder makes, for the mask rules of docs/protocol.md, "JOINTS (0x10)": 3 joints, joint 1's
    mask bit set over non-zero coordinates, padding bits 3-7 of the mask byte set, joint 2 present with
    confidence 0. Decoders take the mask bit as it is and ignore the padding."""
    from firmware_host.protocol.encoder import seal

    header = bytes([1, 0x10, 0]) + (7).to_bytes(4, "little") + (1).to_bytes(8, "little") + (2).to_bytes(8, "little")
    joints = b"".join(v.to_bytes(2, "little") * 3 + bytes([c]) for v, c in ((10, 128), (5, 0), (20, 0)))
    return seal(header + bytes([0, 3, 0b1111_1010]) + joints)


MASK_RULES_JOINTS = [[10, 10, 10, 128, 0], [5, 5, 5, 0, 1], [20, 20, 20, 0, 0]]
