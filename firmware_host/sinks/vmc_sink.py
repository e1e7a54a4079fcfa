"""vmc://host:39539 - the VMC protocol (OSC over UDP) for VSeeFace / Unity-style receivers.

Per frame, OSC bundles of at most 1232 bytes (two for all bones, so no path
fragments them): /VMC/Ext/OK, /VMC/Ext/T, Root/Pos (hip position) and
Bone/Pos (local rotations) solved by ``vmc_pose``. T is seconds since the first frame and never goes back, even
when the capture stamps do, nor follows one glitched stamp far off (``vmc_time``). VMC has no sequence
numbers, so receivers cannot count gaps; the sink's own counters (``stats()``)
report what it decimated or dropped, and as ``partial`` the frames sent whose second bundle was lost (a full send
buffer): the receiver applied the first. ``max_fps`` caps the rate (receivers
render at display rate; 60 is plenty). Host names are resolved like udp://
(IPv4 first, looked up again every ``resolve_s``, default 30, at least 1). ``facing`` (``away``, the default, or
``camera``) and ``mirror`` (0, the default, or 1) choose how the avatar shows the person (``vmc_view``).

A frame the daemon flags CALIBRATION_SUSPECT (its ``scene_flags``: the rig's calibration no longer fits) also
carries ``/ghnerf/calibration_suspect 1`` after /VMC/Ext/OK, whose calibration state stays 3 (``vmc_osc`` says
why); ``calibration_flag=0`` leaves it out, for a receiver that refuses addresses it does not know (EVMC4U's
StrictMode stops receiving at the first one).

A frame of another joint set than BODY_25, or of fewer than its 25 joints, has no bones here: it goes out as one
whose hips are not seen (/VMC/Ext/OK tracking 0 and T), with one WARNING per sink. Before, one of fewer joints
was dropped with a logged traceback per frame, and one of another set with 25 or more was solved as BODY_25.

The binary protocol's options (``send_2d``, ``status_s``, ``joint_count``, ``rig_id``, ``cameras``)
mean nothing to VMC: in the URL they are errors, so no one expects them to work. As keywords they are
accepted and unused, because the daemon hands every sink the rig's id and camera names.
"""
from __future__ import annotations

import logging
from typing import Any, Optional

import numpy as np

from firmware_host.errors import SinkConfigError
from firmware_host.protocol.constants import Flags, JointSet
from firmware_host.protocol.messages import JointFrame
from firmware_host.sinks.base import Sink
from firmware_host.sinks.options import SinkOptions, reject_unknown_kw
from firmware_host.sinks.udp_sink import RESOLVE_S, DatagramLink, take_resolve_s
from firmware_host.sinks.url import SinkUrl, boolean, host_port, one_of, parse_url
from firmware_host.sinks.vmc_osc import build_datagrams
from firmware_host.sinks.vmc_pose import keep_hemisphere, solve_pose
from firmware_host.sinks.vmc_time import VmcClock, nominal_step_us
from firmware_host.sinks.vmc_view import FACINGS, AvatarView
from ghnerf_runtime.body25 import NUM_JOINTS

_log = logging.getLogger(__name__)

VMC_DEFAULT_PORT = 39539  # the Marionette (receiver) port

#: SinkOptions fields only the binary-protocol sinks use (HELLO, STATUS, JOINTS_2D, their link budget).
PROTOCOL_ONLY = ("cameras", "joint_count", "rig_id", "send_2d", "status_s")


def _reject_protocol_options(u: SinkUrl) -> None:
    given = [key for key in PROTOCOL_ONLY if key in u.query]
    if given:
        raise SinkConfigError(u.url, given[0], u.query[given[0]],
                              f"vmc:// sends no HELLO, STATUS or 2D joints, so {', '.join(given)} would be "
                              "ignored; remove it")


class VmcSink(Sink):
    scheme = "vmc"

    def __init__(self, url: str, host: str, port: int, options: SinkOptions, resolve_s: float = RESOLVE_S,
                 view: AvatarView = AvatarView(), calibration_flag: bool = True) -> None:
        super().__init__(url, options)
        self.view = view
        self.calibration_flag = calibration_flag  # send /ghnerf/calibration_suspect with a suspect frame
        self._link = DatagramLink(url, host, port, resolve_s)
        # /VMC/Ext/T: never goes back, whatever the capture stamps do; the rates given stand for the frame interval
        # until the stamps show one
        self._clock = VmcClock(self.shown, nominal_step_us(options.fps, options.max_fps))
        self._last_rotations: dict[str, np.ndarray] = {}  # by bone name: the sign sent last (keep_hemisphere)
        self._warned_not_body25 = False  # a frame without BODY_25 joints is said once per sink

    @classmethod
    def from_url(cls, url: str, **kw: Any) -> "VmcSink":
        u: SinkUrl = parse_url(url)
        host, port = host_port(u, VMC_DEFAULT_PORT)
        resolve_s = take_resolve_s(u, kw)
        view = AvatarView(facing=u.take("facing", one_of(*FACINGS), FACINGS[0], kw),
                          mirror=u.take("mirror", boolean, False, kw))
        calibration_flag = u.take("calibration_flag", boolean, True, kw)
        _reject_protocol_options(u)
        options = SinkOptions.take(u, kw)
        u.reject_leftovers()
        reject_unknown_kw(url, kw)
        return cls(url, host, port, options, resolve_s, view, calibration_flag)

    def _connect(self) -> None:
        self._link.open()

    def _disconnect(self) -> None:
        self._link.close()

    def _receiver_refusing(self, now: float) -> Optional[tuple[float, str]]:
        return self._link.refusing()

    def _deliver(self, frame: JointFrame, flags: int) -> None:
        t = self._clock.seconds(frame.capture_time_us)
        pose = None  # no bones: tracking lost, as a frame whose hips are not seen
        if self._has_body25_joints(frame):
            pose = keep_hemisphere(solve_pose(self.view.apply(frame.joints_3d)), self._last_rotations)
        suspect = self.calibration_flag and bool(frame.scene_flags & Flags.CALIBRATION_SUSPECT)
        # two bundles, one would fragment; the second cut: the receiver applied the first (OK, T, the root, the first
        # bones), the rest hold their last pose: a frame sent in part, not a lost one (it was counted dropped)
        self._link.send_in_turn(build_datagrams(pose, t, calibration_suspect=suspect))

    def _has_body25_joints(self, frame: JointFrame) -> bool:
        """Whether ``frame`` holds the BODY_25 joints the bones are solved from; a WARNING, once, where not."""
        count = len(frame.joints_3d)
        if frame.joint_set == JointSet.BODY_25 and count >= NUM_JOINTS:
            return True
        if not self._warned_not_body25:
            self._warned_not_body25 = True
            _log.warning("%s: frame %d has joint_set %d with %d joints; VMC bones are solved from BODY_25's %d "
                         "(joint_set %d): sent as tracking lost (later ones are not logged)", self.shown,
                         frame.sequence, frame.joint_set, count, NUM_JOINTS, JointSet.BODY_25)
        return False
