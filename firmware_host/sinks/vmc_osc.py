"""A solved pose -> one VMC OSC bundle (python-osc builds the OSC bytes).

Bundle contents, in order: /VMC/Ext/OK, /ghnerf/calibration_suspect (only while the
frame is flagged CALIBRATION_SUSPECT), /VMC/Ext/T, /VMC/Ext/Root/Pos, then one
/VMC/Ext/Bone/Pos per solved bone. Floats are OSC float32.

A suspect calibration gets a message of its own rather than another /VMC/Ext/OK
calibration state: the VMC states (0 uncalibrated, 1 waiting for calibration,
2 calibrating, 3 calibrated) describe a sender's own calibration procedure, and
none says "calibrated, but the joints may be off". 0-2 tell a receiver the pose
is not usable yet (VirtualMotionCapture's own avatar before its calibration), and
the tracking status 0 reads "lost": either could stop or hide an avatar that is
still tracked, only less accurately. So OK stays ``1 3 0 tracked``; a receiver
passes over an address it does not handle (EVMC4U does, unless its StrictMode
is on: the sink's ``calibration_flag=0`` is for those; docs/protocol.md section 8).

All 17 bones make a bundle of about 1460 bytes: over the 1452 an IPv6 packet
carries on Ethernet, and over what a VPN or PPPoE link (MTU 1400-1420) carries
at all, so it went out in IP fragments, and losing either one lost the frame (many
Wi-Fi paths and firewalls drop fragments outright). ``build_datagrams`` splits
a frame's messages, in order, over bundles of at most ``MAX_DATAGRAM`` bytes;
VMC receivers apply each message as it comes, whatever bundle it is in.
"""
from __future__ import annotations

from collections.abc import Iterable
from typing import Any, Optional

from pythonosc.osc_bundle_builder import IMMEDIATELY, OscBundleBuilder
from pythonosc.osc_message import OscMessage
from pythonosc.osc_message_builder import OscMessageBuilder

from firmware_host.sinks.vmc_pose import VmcPose

# /VMC/Ext/OK arguments: loaded=1, calibration state 3 (calibrated), calibration
# mode 0 (normal), then the v2.7 tracking status (1 = tracked, 0 = lost).
_LOADED, _CALIBRATED, _MODE_NORMAL = 1, 3, 0

#: Sent after /VMC/Ext/OK while the frame's calibration is suspect (int 1): outside the /VMC/ namespace, which
#: belongs to the VMC protocol's authors, and lower case like an OSC path of this project's own.
CALIBRATION_SUSPECT_ADDRESS = "/ghnerf/calibration_suspect"

#: Largest datagram sent: IPv6's minimum MTU (1280) less its 40 + 8 bytes of headers, so no path fragments it.
MAX_DATAGRAM = 1232
_BUNDLE_HEAD = 16  # "#bundle\0" and the time tag; each element adds its 4-byte size


def _msg(address: str, *args: tuple[str, Any]) -> OscMessage:
    b = OscMessageBuilder(address)
    for arg_type, value in args:
        b.add_arg(value, arg_type)
    return b.build()


def _pose7(name: str, position: Iterable[float], rotation: Iterable[float]) -> tuple[tuple[str, Any], ...]:
    """A VMC pose argument list: name, then position x y z and rotation x y z w as float32."""
    return (("s", name), *(("f", float(v)) for v in position), *(("f", float(v)) for v in rotation))


def _messages(pose: Optional[VmcPose], time_s: float, calibration_suspect: bool = False) -> list[OscMessage]:
    tracked = 1 if pose is not None else 0
    msgs = [_msg("/VMC/Ext/OK", ("i", _LOADED), ("i", _CALIBRATED), ("i", _MODE_NORMAL), ("i", tracked))]
    if calibration_suspect:  # only then: a frame that fits is sent byte for byte as before
        msgs.append(_msg(CALIBRATION_SUSPECT_ADDRESS, ("i", 1)))
    msgs.append(_msg("/VMC/Ext/T", ("f", float(time_s))))
    if pose is not None:
        msgs.append(_msg("/VMC/Ext/Root/Pos", *_pose7("root", pose.root_position, (0.0, 0.0, 0.0, 1.0))))
        for bone in pose.bones.values():
            msgs.append(_msg("/VMC/Ext/Bone/Pos", *_pose7(bone.name, bone.local_position, bone.local_rotation)))
    return msgs


def _bundle(msgs: list[OscMessage]) -> bytes:
    bundle = OscBundleBuilder(IMMEDIATELY)
    for m in msgs:
        bundle.add_content(m)
    return bundle.build().dgram


def build_bundle(pose: Optional[VmcPose], time_s: float, calibration_suspect: bool = False) -> bytes:
    """One frame as a single bundle, whatever its size (see ``build_datagrams`` for what the sink sends).
    ``pose=None`` (hips not seen) sends only OK (tracking lost) and T (and the calibration message when
    ``calibration_suspect``)."""
    return _bundle(_messages(pose, time_s, calibration_suspect))


def build_datagrams(pose: Optional[VmcPose], time_s: float, max_bytes: int = MAX_DATAGRAM,
                    calibration_suspect: bool = False) -> list[bytes]:
    """One frame as bundles of at most ``max_bytes`` each, its messages in order (OK, the calibration message
    when ``calibration_suspect``, and T in the first)."""
    groups: list[list[OscMessage]] = [[]]
    size = _BUNDLE_HEAD
    for m in _messages(pose, time_s, calibration_suspect):
        need = 4 + m.size
        if groups[-1] and size + need > max_bytes:
            groups.append([])
            size = _BUNDLE_HEAD
        groups[-1].append(m)
        size += need
    return [_bundle(g) for g in groups]
