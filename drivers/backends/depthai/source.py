"""The ``depthai://`` backend: a device link, its calibration as our rig, its Sync groups as frames."""
from __future__ import annotations

import logging
import threading
from collections import deque
from collections.abc import Callable
from typing import TYPE_CHECKING

from drivers.backends.depthai.calibration import rig_from_calibration
from drivers.backends.depthai.convert import depthai_errors, frames_from_group
from drivers.backends.depthai.link import DaiDeviceLink, DeviceLink, StereoRequest
from drivers.backends.depthai.options import DEFAULT_MOUNT_HEIGHT_M, DepthaiOptions, board_socket
from drivers.base import RigSource, load_rig_option, naming_rig_option
from drivers.clock import Clock
from drivers.errors import (FrameSizeError, RigConfigError, RigDisconnectedError, RigInitializationError,
                            RigOperationError)
from drivers.frames import Frame
from drivers.pairing import DropPolicy, PairingConfig
from drivers.url import RigUrl
from ghnerf_runtime.geometry import Rig
from ghnerf_runtime.path_check import shown

if TYPE_CHECKING:
    import depthai as dai

log = logging.getLogger(__name__)

#: A stream delivering less than this share of the requested fps is reported (once per source).
SLOW_SHARE = 0.8
#: Capture time one measurement of the delivered rate spans.
RATE_WINDOW_S = 2.0


class DeliveryRate:
    """Groups per second the device delivers, on their capture timestamps, over windows of ``window_s``.

    Only groups that arrived one after another in the host queue count: the caller restarts the
    window (:meth:`restart`) where the queue may have dropped some because the reader fell behind,
    so a slow reader is not mistaken for a slow link.
    """

    def __init__(self, window_s: float = RATE_WINDOW_S) -> None:
        self.window_ns = int(window_s * 1e9)
        self.first_ns: int | None = None
        self.count = 0

    def restart(self, t_ns: int) -> None:
        self.first_ns, self.count = t_ns, 1

    def add(self, t_ns: int) -> float | None:
        """Count a group captured at ``t_ns``; the rate once a window is complete, else ``None``."""
        if self.first_ns is None:
            self.restart(t_ns)
            return None
        self.count += 1
        span = t_ns - self.first_ns
        if span < self.window_ns:
            return None
        rate = (self.count - 1) * 1e9 / span
        self.restart(t_ns)
        return rate


class _ClosedDuringOpen(Exception):
    """A check in :meth:`DepthaiRigSource._open` found the source closed; the open raises, worded, once the link is
    closed."""


class DepthaiRigSource(RigSource):
    """One OAK device's stereo pair (options: :mod:`drivers.backends.depthai.options`).

    The rig comes from the device EEPROM at :meth:`open` (see
    :mod:`drivers.backends.depthai.calibration`) unless a rig file is given.

    Args:
        options: validated URL options.
        rig: a rig to use instead of the device calibration (its first two cameras
            must have the output size).
        link_factory: builds the :class:`DeviceLink` (default: a real device).
    """

    scheme = "depthai"

    def __init__(
        self,
        options: DepthaiOptions,
        *,
        rig: Rig | None = None,
        link_factory: Callable[[], DeviceLink] = DaiDeviceLink,
        pairing: PairingConfig | None = None,
        clock: Clock | None = None,
    ) -> None:
        if rig is not None:
            for cam in rig.pair:
                if (cam.width, cam.height) != (options.width, options.height):
                    raise RigConfigError(
                        f"rig {rig.rig_id!r} camera {cam.name!r} is {cam.width}x{cam.height} but the stream is "
                        f"{options.width}x{options.height}; set width=/height= to match the rig file"
                    )
        super().__init__(rig, pairing=pairing or options.pairing, clock=clock)
        self.options = options
        self._fixed_rig = rig
        self._link_factory = link_factory
        self._link: DeviceLink | None = None
        self._starting: DeviceLink | None = None  # the link _open is starting, for a close meanwhile to cancel
        # The link _open made, until it is closed (by _open as it fails, or by _close): lingering() after a close
        # that cancelled the open names the device while the opening thread still holds it
        self._unreleased: DeviceLink | None = None
        # Set by close(), also one landing during open(): the open stops at its next step, a read refuses its frame
        self._closing = threading.Event()
        self._pending: deque[Frame] = deque()
        # Frames the reader holds: the first group's second frame and up to ``queue`` groups taken after it.
        self.drain_limit = 2 * options.queue_size + 2
        self._device_id = ""  # kept from start(): a lost device no longer says
        self._device_name = ""
        # Measured under LATEST only: there a read shows whether the host queue could have overflowed.
        self._rate = DeliveryRate() if self.pairing.policy is DropPolicy.LATEST else None
        self._rate_warned = False
        self._last_indices: tuple[int, int] | None = None  # the last group's (first, second) frame indices
        self._lost_before: dict[Frame, int] = {}  # a group's first frame -> whole groups lost just before it
        self._lost = 0  # for _pairs_lost: before the frame _read_frame returned last

    @classmethod
    def from_url(
        cls,
        url: RigUrl,
        *,
        rig: Rig | None = None,
        link_factory: Callable[[], DeviceLink] = DaiDeviceLink,
        pairing: PairingConfig | None = None,
        clock: Clock | None = None,
    ) -> "DepthaiRigSource":
        options = DepthaiOptions.from_url(url)
        if rig is None and options.rig_path is not None:
            rig = load_rig_option(url, options.rig_path)
            with naming_rig_option(url, options.rig_path):  # the rig file's size against the stream's
                source = cls(options, rig=rig, link_factory=link_factory, pairing=pairing, clock=clock)
            source._rig_read_from(options.rig_path)
            return source
        return cls(options, rig=rig, link_factory=link_factory, pairing=pairing, clock=clock)

    def _request(self) -> StereoRequest:
        o = self.options
        return StereoRequest(o.device_id, o.left, o.right, o.fps, o.width, o.height, self.pairing.tolerance_ms, o.queue_size)

    def _open(self) -> None:
        link = self._link_factory()
        self._unreleased = link
        self._starting = link  # before the first check: a close from now on is seen by a check or by link.cancel()
        try:
            starting = f"starting depthai device {self.options.device_id or '(first found)'}"
            with depthai_errors(starting, RigInitializationError):
                self._stop_if_closed()
                link.start(self._request())
                self._stop_if_closed()  # closed while the device booted: its EEPROM is not read for nothing
                rig = self._fixed_rig or self._rig_from_device(link)
                self._stop_if_closed()
                # Asked here, guarded: a device lost just after start fails this call too, and the link
                # must then be closed (open() failing leaves no source to close it later).
                device_id = link.device_id()
                device_name = link.device_name()
        except BaseException as e:
            try:
                link.close()
            except Exception as closing:  # noqa: BLE001 - the start failure is the error to report
                log.debug("depthai: closing after a failed start also failed: %s", closing)
            finally:
                self._unreleased = None
            if isinstance(e, Exception) and self._closing.is_set():  # a check saw the close, or link.cancel() cut in
                raise self._closed_during_open() from (None if isinstance(e, _ClosedDuringOpen) else e)
            raise
        finally:
            self._starting = None
        self._set_rig(rig, built=self._fixed_rig is None)
        self._link = link
        self._device_id = device_id
        self._device_name = device_name

    def _stop_if_closed(self) -> None:
        if self._closing.is_set():
            raise _ClosedDuringOpen()

    def _closed_during_open(self) -> RigInitializationError:
        """What open() raises when another thread closes the source while the device starts."""
        return RigInitializationError(f"{self._where()}: closed while open() started the device: the open was "
                                      "cancelled")

    def _closed_while_reading(self) -> RigOperationError:
        """What a read raises when another thread closes the source under it (worded as sim:// and replay://)."""
        return RigOperationError(f"{self._where()}: source closed while a read waited for its frame")

    def _cancel_open(self) -> None:
        self._closing.set()  # first: an open past its link's cancel sees it at its next check
        link = self._starting
        if link is not None:
            link.cancel()  # a start still connecting goes no further than connecting

    def _rig_from_device(self, link: DeviceLink) -> Rig:
        o = self.options
        if o.mount_height_m is None:
            log.warning(
                "depthai: mount_height not given; assuming the cameras are %.2f m above the floor", DEFAULT_MOUNT_HEIGHT_M
            )
        return rig_from_calibration(
            link.calibration(),
            board_socket(o.left),
            board_socket(o.right),
            (o.width, o.height),
            DEFAULT_MOUNT_HEIGHT_M if o.mount_height_m is None else o.mount_height_m,
            mount_roll_deg=o.mount_roll_deg,
            rig_id=f"oak-{link.device_id() or 'device'}",
        )

    def _where(self) -> str:
        """The device (id, URL, XLink name) and its cameras: with two OAKs, which one to look at."""
        o = self.options
        # the device's id and XLink name, a rig file's camera names: escaped where one holds a control character
        where = f"depthai device {shown(self._device_id or o.device_id or '(first found)')}"
        if o.url:
            where += f" ({o.url})"
        if self._device_name:
            where += f" at {shown(self._device_name)}"
        names = tuple(shown(c.name) for c in self._rig.pair) if self._rig is not None else ("left", "right")
        return f"{where}, cameras {names[0]} ({o.left}) and {names[1]} ({o.right})"

    def _read_frame(self, timeout_s: float) -> Frame | None:
        try:
            frame: Frame | None = self._pending.popleft()
        except IndexError:  # none pending (or a close from another thread emptied them just now)
            frame = self._read_from_link(timeout_s)
        if frame is None:
            return None
        if self._closing.is_set():  # closed while the read had the frame in hand: a closed source hands out none
            self._pending.clear()
            raise self._closed_while_reading()
        return self._served(frame)

    def _read_from_link(self, timeout_s: float) -> Frame | None:
        """The first frame of the link's next group, its second (and, under LATEST, the groups queued behind it)
        left pending; ``None`` after ``timeout_s``."""
        link = self._link
        if link is None:  # read() refuses a source not open: closed by another thread since the read began
            raise self._closed_while_reading()
        deadline = self.clock.now_ns() + int(timeout_s * 1e9)
        try:
            with depthai_errors(f"reading from {self._where()}", RigDisconnectedError):
                group = link.next_group(timeout_s)
                if group is None:
                    if not link.is_running():
                        raise RigDisconnectedError(
                            f"{self._where()}: both cameras stopped: the device was lost or its pipeline ended"
                        )
                    self.clock.sleep_until(deadline)  # the timeout has passed on our clock too (a ManualClock jumps)
                    return None
                first, second = self._frames(group)
        except RigDisconnectedError:
            if self._link is not link:  # closed by another thread meanwhile: no device was lost, nothing to reopen
                raise self._closed_while_reading() from None
            raise
        self._pending.append(second)
        if self.pairing.policy is DropPolicy.LATEST:
            self._measure_rate([first.timestamp_ns] + self._take_queued_groups(link))
        return first

    def _measure_rate(self, stamps: list[int]) -> None:
        """Warn once when the device delivers well under the requested fps (a USB2 link, a cable).

        ``stamps``: the capture times of the groups one read took from the host queue, in order.
        Taking ``queue`` or more means the queue may have been full, and so may have dropped groups
        while the reader was busy (it only drops when full, and only the reader empties it): the
        measurement then restarts at the first of them.
        """
        rate = self._rate
        if rate is None or self._rate_warned:
            return
        if len(stamps) >= self.options.queue_size:
            rate.restart(stamps[0])
            stamps = stamps[1:]
        for t_ns in stamps:
            measured = rate.add(t_ns)
            if measured is not None and measured < SLOW_SHARE * self.options.fps:
                self._rate_warned = True
                o = self.options
                log.warning(
                    "%s: %.1f pairs/s arrive of the %g fps requested (over %.1f s or more of capture time). A USB2 "
                    "link "
                    "or cable (the USB speed is logged at open) cannot carry two %dx%d streams at that rate, and "
                    "frames that do not pair within tolerance_ms=%g are discarded: use USB3, or lower "
                    "fps/width/height", self._where(), measured, o.fps, rate.window_ns / 1e9, o.width, o.height,
                    self.pairing.tolerance_ms,
                )
                return

    def _frames(self, group: dai.MessageGroup) -> tuple[Frame, Frame]:
        """A group's frames; whole groups lost before it (both indices jumped by as many) are noted on the first.

        :raises FrameSizeError: a frame of another size than its rig camera's, naming the device, the camera, the rig
            file (or the device's calibration) and both sizes, as ``opencv://`` names them.
        """
        try:
            first, second = frames_from_group(group, self.rig)
        except FrameSizeError as e:
            raise FrameSizeError(self._size_message(e), e.camera, e.expected, e.delivered) from None
        if self._last_indices is not None:
            lost = min(first.index - self._last_indices[0], second.index - self._last_indices[1]) - 1
            if lost > 0:  # the non-blocking host queue dropped them (or Sync found no partner for either)
                self._lost_before[first] = lost
        self._last_indices = (first.index, second.index)
        return first, second

    def _size_message(self, error: FrameSizeError) -> str:
        """Why ``error``'s frame does not fit, and what to do. The stream was asked for the rig's size (a rig file of
        another size than width=/height= is refused when the URL is read; the device's calibration is converted to
        the size asked), so the device did not deliver what it was asked for: no rig file is rescaled here."""
        (dw, dh), (rw, rh) = error.delivered, error.expected
        rig_path = self.options.rig_path
        origin = f"in {rig_path}" if rig_path else "(the device's calibration, at the width=/height= asked)"
        remedy = (f"ask for a size its sensors deliver (width=/height=) with a rig file calibrated at it (ghcal, "
                  f"docs/calibration.md)" if rig_path else "ask for another width=/height=, one its sensors deliver")
        return (f"{self._where()}: camera {error.camera!r} delivered {dw}x{dh}, but its rig camera {origin} is "
                f"{rw}x{rh}, the size the device was asked for (width={rw}&height={rh}): {remedy}")

    def _served(self, frame: Frame) -> Frame:
        self._lost = self._lost_before.pop(frame, 0)
        return frame

    def _pairs_lost(self) -> int:
        return self._lost

    def _take_queued_groups(self, link: DeviceLink) -> list[int]:
        """Move the groups already waiting in the host queue into ``_pending``: read() drains them under
        the LATEST policy, so a reader slower than the cameras gets the newest pair (older ones counted in
        pairs_dropped) rather than one up to ``queue=`` groups old. Through ``next_group(0)``, which
        releases the GIL: depthai's ``has()``/``isClosed()`` wait on the queue's lock holding it, and a
        host node that needs the GIL to hand over a message then deadlocks with them. Returns the capture
        times of the groups it took (their first frames')."""
        stamps: list[int] = []
        for _ in range(max(self.options.queue_size, 1)):
            try:
                group = link.next_group(0.0)
                if group is None:
                    break
                frames = self._frames(group)
            except Exception as e:  # noqa: BLE001 - a closed queue: the next read raises it, typed
                log.debug("depthai: no more queued groups (%s)", e)
                break
            self._pending.extend(frames)
            stamps.append(frames[0].timestamp_ns)
        return stamps

    def _frame_available(self) -> bool:
        return bool(self._pending)  # frames already taken from the link; the link itself is not polled

    def _close(self) -> None:
        self._closing.set()  # first: a read with a frame in hand refuses it
        link, self._link = self._link, None
        self._pending.clear()
        self._lost_before.clear()
        try:
            if link is not None:
                with depthai_errors(f"closing {self._where()}", RigOperationError):
                    link.close()
        finally:
            self._unreleased = None

    def lingering(self) -> tuple[str, ...]:
        """After a close that cancelled an open: the device, while the opening thread still holds it (depthai's
        connect, which boots it, cannot be cut short: the open closes the device once that returns). Empty once it
        is closed, and after any other close, which closes the device itself before it returns."""
        if self._closing.is_set() and self._unreleased is not None:
            return (self._where(),)
        return ()
