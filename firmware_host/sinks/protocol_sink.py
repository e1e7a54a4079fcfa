"""Sinks that speak the binary joint protocol (serial, USB, UDP, file, memory).

Per link: a 0x00 and HELLO + STATUS on every (re)connect, then JOINTS (and
JOINTS_2D when asked) per frame, and HELLO + STATUS again every ``status_s``
so receivers that start late learn the stream's parameters.
"""
from __future__ import annotations

import itertools
import logging
from abc import abstractmethod
from dataclasses import replace
from typing import Optional

from firmware_host.errors import EncodeError, SinkConfigError, SinkPartialWriteError, SinkWriteError
from firmware_host.protocol.constants import (
    PROTOCOL_VERSION,
    NO_FRAME_SEQ,
    U32_MAX,
    CoordFrame,
    Fault,
    Flags,
    JointSet,
    MsgType,
    Units,
)
from firmware_host.protocol.encoder import encode, joints2d_packet_len, joints_packet_len, wire_len
from firmware_host.protocol.from_frame import is_announced, joints2d_messages, joints_message, wire_seq
from firmware_host.protocol.messages import Hello, JointFrame, Message, Status, make_header
from firmware_host.sinks.base import Sink, SinkStats
from firmware_host.sinks.options import SinkOptions, scene_flags_mask

_log = logging.getLogger(__name__)

#: After a STATUS that could not be written, how soon (at most) another is tried while no frame comes.
STATUS_RETRY_S = 0.1


def frame_packets(messages: list[Message]) -> int:
    """How many of ``messages`` lead as a frame's own packets (its JOINTS, then its JOINTS_2D); 0 in a write
    without a frame (an idle or first HELLO + STATUS)."""
    frame_types = (MsgType.JOINTS, MsgType.JOINTS_2D)
    return sum(1 for _ in itertools.takewhile(lambda m: m.header.msg_type in frame_types, messages))


def frame_messages(messages: list[Message]) -> int:
    """How many of ``messages`` must go out for a write to count as delivered: its leading frame packets (JOINTS,
    JOINTS_2D; a HELLO + STATUS behind them may be cut and owed), or all of them in a write without a frame."""
    return frame_packets(messages) or len(messages)


def judge_cut_write(url: str, reason: str, messages: list[Message], packet_ends: list[int], written: int) -> bool:
    """What a stream write of ``messages`` (serial, a pipe) cut short after ``written`` bytes delivered: message i
    is out once ``written`` reaches ``packet_ends[i]``. Returns False where the frame's packets all went out (only
    a trailing HELLO + STATUS was cut: that STATUS is owed).

    :raises SinkPartialWriteError: the frame's JOINTS went out, not all its JOINTS_2D: the receiver has the frame's
        seq and 3D joints (counted dropped before, and the next frame's DROPPED named a gap with no seq missing).
    :raises SinkWriteError: not even the JOINTS went out (or a write without a frame was cut).
    """
    needed = frame_messages(messages)
    out = sum(1 for end in packet_ends[:needed] if written >= end)
    if out == needed:
        return False
    if out and frame_packets(messages):
        raise SinkPartialWriteError(url, reason, out, needed, "packets")
    raise SinkWriteError(url, reason)


class ProtocolSink(Sink):
    def __init__(self, url: str, options: SinkOptions) -> None:
        super().__init__(url, options)
        self._joint_set = int(JointSet.BODY_25)
        self._last_seq = NO_FRAME_SEQ
        # None until a frame is sent: a capture time of 0 (a test clock, a synthetic recording replayed with
        # keep_time=1 whose clock starts at 0) is a real one, and as the "no frame yet" mark its STATUS said
        # capture now, latency 0.
        self._last_capture_us: Optional[int] = None
        self._resync = True
        self._fault = int(Fault.OK)
        self._fault_since_status = int(Fault.OK)  # the last non-OK fault set since the previous STATUS
        self._calibration_suspect = False  # STATUS header flag CALIBRATION_SUSPECT (set_calibration_suspect)
        # HELLO's header flags: the options' value as opened, then what announce_scene_flags last said (a reload)
        self._scene_flags = options.scene_flags
        self._faults_set = 0  # non-OK faults set so far: a STATUS clears the latch only if none came since it read it
        self._status_due_us: Optional[int] = None
        self._status_owed = False  # the last STATUS was not written: the next frame carries one
        self._window = (0, 0)  # (time of last STATUS, frames sent by then)
        self._prev_stats: Optional[SinkStats] = None
        self._earlier_totals = (0, 0)  # (dropped, decimated) of the sinks this one replaces: STATUS totals go on
        self._unannounced_warned: set = set()
        if options.send_2d and not options.cameras:
            # JOINTS_2D numbers its camera by HELLO's list, and the link budget counts one packet per camera.
            raise SinkConfigError(url, "cameras", "", "required with send_2d=1: the camera names, in index order "
                                                      "(e.g. cameras=left,right)")
        try:  # validate HELLO fields now, so a bad rig_id fails at open_sink()
            encode(self._hello(0))
        except EncodeError as e:
            raise SinkConfigError(url, e.field.split(".")[-1], e.value, str(e)) from e

    # ---- backend hook -----------------------------------------------------------

    @abstractmethod
    def _write_bytes(self, data: bytes) -> None:
        """Write framed packets. Raise SinkWriteError / SinkUnavailableError like ``_deliver``."""

    def _write_messages(self, messages: list[Message]) -> bool:
        """Write ``messages``; raise like ``_deliver``. False: the write counts as delivered, but a trailing
        HELLO + STATUS was cut (serial), so that STATUS is owed like one whose write failed."""
        data = b"".join(encode(m) for m in messages)
        if self._resync:
            # A leading delimiter ends whatever partial frame the receiver holds.
            data = b"\x00" + data
        self._write_bytes(data)
        self._resync = False
        return True

    # ---- link budget ------------------------------------------------------------

    def frame_bytes(self) -> int:
        """Wire bytes per joint frame (JOINTS, plus JOINTS_2D per camera if enabled)."""
        n = self.options.joint_count
        total = wire_len(joints_packet_len(n))
        if self.options.send_2d:
            total += max(1, len(self.options.cameras)) * wire_len(joints2d_packet_len(n))
        return total

    def set_fault(self, fault: int) -> None:
        """Report a daemon-level fault (e.g. Fault.ESTIMATOR_STALLED) in STATUS; Fault.OK clears it.

        A fault cleared again before the next STATUS is still reported in it, once: a camera that
        vanished and came back between two STATUS packets was never seen by the receiver."""
        with self._cond:  # the worker takes the latch when it writes STATUS
            self._fault = int(fault)
            if self._fault != Fault.OK:
                self._fault_since_status = self._fault
                self._faults_set += 1

    def set_calibration_suspect(self, suspect: bool) -> None:
        """Say in every STATUS (header flag CALIBRATION_SUSPECT) whether the daemon's calibration check finds
        the rig file no longer fits (the views no longer agree, or the feet have left the floor). A flag, not a
        fault code: it lasts until a recalibration, and as fault 6 it would have hidden RATE_LIMITED..CAMERA_FAULT
        all that time (or been hidden by them)."""
        with self._cond:
            self._calibration_suspect = bool(suspect)

    def announce_scene_flags(self, flags: int) -> None:
        """Announce ``flags`` as the scene flags the producer sets (HELLO's header flags) from the next HELLO on:
        a reload that turns the estimator's scan for others on or off changes whether SOMEONE_ELSE means anything.

        :raises SinkConfigError: ``flags`` sets a bit that is no scene flag."""
        mask = scene_flags_mask(self.url, flags)
        with self._cond:
            self._scene_flags = mask

    # ---- Sink hooks --------------------------------------------------------------

    def _on_connected(self) -> None:
        self._resync = True
        now = self.options.clock_us()
        # fps counts this connection only: the frames before an outage, over its length, are no rate.
        self._window = (now, self.stats().sent)
        self._write_with_status([], now)

    def _idle_timeout_s(self) -> Optional[float]:
        # Wake up for the next STATUS even when no frame comes: a stalled estimator is exactly when
        # the receiver needs STATUS (its fault code) and HELLO (a receiver joining late).
        if self._status_due_us is None:
            return None
        return max(0.001, (self._status_due_us - self.options.clock_us()) / 1e6)  # never a hot loop

    def _on_idle(self) -> bool:
        now = self.options.clock_us()
        if self._status_due_us is not None and now >= self._status_due_us:
            return self._write_with_status([], now)
        return False

    def _deliver(self, frame: JointFrame, flags: int) -> None:
        now = self.options.clock_us()
        self._joint_set = frame.joint_set
        self._last_seq = wire_seq(frame.sequence)
        self._last_capture_us = frame.capture_time_us
        messages: list[Message] = [joints_message(frame, now, flags)]
        if self.options.send_2d and frame.joints_2d:
            messages += joints2d_messages(self._announced_2d(frame), now, self.options.cameras, flags)
        if self._status_owed or self._status_due_us is None or now >= self._status_due_us:
            self._write_with_status(messages, now)
        else:
            self._write_messages(messages)

    def _write_with_status(self, messages: list[Message], now: int) -> bool:
        """Write ``messages`` + HELLO + STATUS. The STATUS counts as reported only once written: a failed write
        keeps the latched fault and the interval's counters for the next one, which is then due soon. Returns
        whether the STATUS was written (False: cut)."""
        status, taken = self._status(now)
        try:
            complete = self._write_messages(messages + [self._hello(now), status])
        except Exception:
            self._status_not_written(now)
            raise
        if complete is False:  # the frame went out, the STATUS behind it did not
            self._status_not_written(now)
            return False
        self._status_owed = False
        self._status_due_us = now + int(self.options.status_s * 1e6)
        self._status_written(*taken)
        return True

    def _status_not_written(self, now: int) -> None:
        self._status_owed = True  # the next frame carries it; while none comes, retry shortly
        self._status_due_us = now + int(min(self.options.status_s, STATUS_RETRY_S) * 1e6)

    def _announced_2d(self, frame: JointFrame) -> JointFrame:
        """``frame`` without the 2D joints of cameras HELLO does not name (warned once per camera): they
        cannot be numbered, and they must not cost the frame its 3D joints."""
        cameras = self.options.cameras
        unknown = [k for k in frame.joints_2d if not is_announced(k, cameras)]
        if not unknown:
            return frame
        for key in unknown:
            if key not in self._unannounced_warned:
                self._unannounced_warned.add(key)
                _log.warning("%s: 2D joints of camera %r not sent: not among the announced cameras %s",
                             self.shown, key, list(cameras))
        return replace(frame, joints_2d={k: v for k, v in frame.joints_2d.items() if k not in unknown})

    # ---- messages ------------------------------------------------------------------

    def _hello(self, now: int) -> Hello:
        # HELLO's flags: the scene flags this sender sets on its frames (an older sender's are 0, so a receiver
        # can tell "no second person" from "a sender that cannot say"; SOMEONE_ELSE only while the scan runs).
        with self._cond:
            scene_flags = self._scene_flags
        h = make_header(MsgType.HELLO, self._last_seq, now, now, scene_flags)
        return Hello(
            h, PROTOCOL_VERSION, self._joint_set, self.options.joint_count, int(Units.MILLIMETRES),
            int(CoordFrame.RIG), self.options.rig_id, tuple(self.options.cameras),
        )

    def carry_seq(self, last_sent: int) -> None:
        """Announce ``last_sent``, the producer's last frame (sent by a sink this one replaces, or by the other
        outputs), in HELLO and STATUS until this sink sends a frame: the numbering runs on through a reopened
        or added output, and a HELLO back at the start would read as a producer that restarted."""
        with self._cond:
            self._last_seq = wire_seq(int(last_sent))

    def carry_totals(self, dropped: int, decimated: int) -> None:
        """Count ``dropped`` and ``decimated`` frames of sinks this one replaces (a rebuilt link) in STATUS, whose
        fields are the sender's totals (docs/protocol.md): a receiver must not see them fall back to zero."""
        with self._cond:
            d, k = self._earlier_totals
            self._earlier_totals = (d + int(dropped), k + int(decimated))

    def _status(self, now: int) -> tuple[Status, tuple[int, SinkStats, int]]:
        """STATUS for the interval since the last one written, and what :meth:`_status_written` takes to
        commit it; builds only, so a STATUS that is never written is reported again."""
        s = self.stats()
        t0, sent0 = self._window
        fps_centi = round(100 * (s.sent - sent0) * 1e6 / (now - t0)) if t0 and now > t0 else 0
        with self._cond:
            current, latched, faults_set = self._fault, self._fault_since_status, self._faults_set
            earlier_dropped, earlier_decimated = self._earlier_totals
            status_flags = int(Flags.CALIBRATION_SUSPECT) if self._calibration_suspect else 0
        fault = current if current != Fault.OK else latched
        if fault == Fault.OK:
            fault = self._link_fault(self._prev_stats or s, s)
        last_capture = self._last_capture_us
        h = make_header(MsgType.STATUS, self._last_seq, now if last_capture is None else last_capture, now,
                        status_flags)
        latency = 0 if last_capture is None else max(0, now - last_capture)
        status = Status(
            h,
            fps_centi=min(fps_centi, 0xFFFF),
            latency_us=min(latency, U32_MAX),
            dropped=min(earlier_dropped + s.dropped, U32_MAX),
            decimated=min(earlier_decimated + s.decimated, U32_MAX),
            fault=fault,
        )
        return status, (now, s, faults_set)

    @staticmethod
    def _link_fault(prev: SinkStats, s: SinkStats) -> int:
        """The sink's own fault for the interval, the most severe first: frames lost to the link (in whole or in
        part: a frame sent in part, counted sent, left STATUS saying OK), then to a full queue, then skipped on
        purpose (a deliberate ``max_fps`` must not hide the other two)."""
        if s.dropped_error > prev.dropped_error or s.disconnects > prev.disconnects or s.partial > prev.partial:
            return int(Fault.LINK_ERRORS)
        if s.dropped_queue > prev.dropped_queue:
            return int(Fault.QUEUE_OVERFLOW)
        if s.decimated > prev.decimated:
            return int(Fault.RATE_LIMITED)
        return int(Fault.OK)

    def _status_written(self, now: int, s: SinkStats, faults_set: int) -> None:
        """A STATUS built from ``s`` reached the link: start the next interval, and clear the latched fault
        unless a newer one was set after the STATUS read it."""
        self._window, self._prev_stats = (now, s.sent), s
        with self._cond:
            if self._faults_set == faults_set:
                self._fault_since_status = int(Fault.OK)
