"""A solved pose -> one VMC OSC bundle (python-osc builds the OSC bytes).

Bundle contents, in order: /VMC/Ext/OK, /VMC/Ext/T, /VMC/Ext/Root/Pos, then
one /VMC/Ext/Bone/Pos per solved bone. Floats are OSC float32.
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


def _msg(address: str, *args: tuple[str, Any]) -> OscMessage:
    b = OscMessageBuilder(address)
    for arg_type, value in args:
        b.add_arg(value, arg_type)
    return b.build()


def _pose7(name: str, position: Iterable[float], rotation: Iterable[float]) -> tuple[tuple[str, Any], ...]:
    """A VMC pose argument list: name, then position x y z and rotation x y z w as float32."""
    return (("s", name), *(("f", float(v)) for v in position), *(("f", float(v)) for v in rotation))


def build_bundle(pose: Optional[VmcPose], time_s: float) -> bytes:
    """Datagram for one frame. ``pose=None`` (hips not seen) sends only OK (tracking lost) and T."""
    bundle = OscBundleBuilder(IMMEDIATELY)
    tracked = 1 if pose is not None else 0
    bundle.add_content(_msg("/VMC/Ext/OK", ("i", _LOADED), ("i", _CALIBRATED), ("i", _MODE_NORMAL), ("i", tracked)))
    bundle.add_content(_msg("/VMC/Ext/T", ("f", float(time_s))))
    if pose is not None:
        bundle.add_content(_msg("/VMC/Ext/Root/Pos", *_pose7("root", pose.root_position, (0.0, 0.0, 0.0, 1.0))))
        for bone in pose.bones.values():
            bundle.add_content(_msg("/VMC/Ext/Bone/Pos", *_pose7(bone.name, bone.local_position, bone.local_rotation)))
    return bundle.build().dgram
