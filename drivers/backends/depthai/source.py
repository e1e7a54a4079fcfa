"""The ``depthai://`` backend: a device link, its calibration as our rig, its Sync groups as frames."""
from __future__ import annotations

import logging
from collections import deque
from collections.abc import Callable

from drivers.backends.depthai.calibration import rig_from_calibration
from drivers.backends.depthai.convert import depthai_errors, frames_from_group
from drivers.backends.depthai.link import DaiDeviceLink, DeviceLink, StereoRequest
from drivers.backends.depthai.options import DEFAULT_MOUNT_HEIGHT_M, DepthaiOptions, board_socket
from drivers.base import RigSource
from drivers.clock import Clock
from drivers.errors import RigConfigError, RigDisconnectedError, RigInitializationError, RigOperationError
from drivers.frames import Frame
from drivers.pairing import DropPolicy, PairingConfig
from drivers.url import RigUrl
from ghnerf_runtime.errors import RigFileError
from ghnerf_runtime.geometry import Rig
from ghnerf_runtime.rig_file import load_rig

log = logging.getLogger(__name__)


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
        self._pending: deque[Frame] = deque()

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
            try:
                rig = load_rig(options.rig_path)
            except RigFileError as e:
                raise RigConfigError(f"rig URL {url.url!r}: option rig={options.rig_path}: {e}") from e
        return cls(options, rig=rig, link_factory=link_factory, pairing=pairing, clock=clock)

    def _request(self) -> StereoRequest:
        o = self.options
        return StereoRequest(o.device_id, o.left, o.right, o.fps, o.width, o.height, self.pairing.tolerance_ms, o.queue_size)

    def _open(self) -> None:
        link = self._link_factory()
        try:
            with depthai_errors(f"starting depthai device {self.options.device_id or '(first found)'}", RigInitializationError):
                link.start(self._request())
                rig = self._fixed_rig or self._rig_from_device(link)
        except BaseException:
            try:
                link.close()
            except Exception as e:  # noqa: BLE001 - the start failure is the error to report
                log.debug("depthai: closing after a failed start also failed: %s", e)
            raise
        self._set_rig(rig)
        self._link = link

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

    def _read_frame(self, timeout_s: float) -> Frame | None:
        if self._pending:
            return self._pending.popleft()
        link = self._link
        if link is None:
            raise RigOperationError("depthai link is not open")
        deadline = self.clock.now_ns() + int(timeout_s * 1e9)
        with depthai_errors("reading from the depthai device", RigDisconnectedError):
            group = link.next_group(timeout_s)
            if group is None:
                self.clock.sleep_until(deadline)  # the timeout has passed on our clock too (a ManualClock jumps)
                return None
            first, second = frames_from_group(group, self.rig)
        self._pending.append(second)
        if self.pairing.policy is DropPolicy.LATEST:
            self._take_queued_groups(link)
        return first

    def _take_queued_groups(self, link: DeviceLink) -> None:
        """Move the groups already waiting in the host queue into ``_pending``: read() drains them under
        the LATEST policy, so a reader slower than the cameras gets the newest pair (older ones counted in
        pairs_dropped) rather than one up to ``queue=`` groups old. Through ``next_group(0)``, which
        releases the GIL: depthai's ``has()``/``isClosed()`` wait on the queue's lock holding it, and a
        host node that needs the GIL to hand over a message then deadlocks with them."""
        for _ in range(max(self.options.queue_size, 1)):
            try:
                group = link.next_group(0.0)
                if group is None:
                    return
                self._pending.extend(frames_from_group(group, self.rig))
            except Exception as e:  # noqa: BLE001 - a closed queue: the next read raises it, typed
                log.debug("depthai: no more queued groups (%s)", e)
                return

    def _frame_available(self) -> bool:
        return bool(self._pending)  # frames already taken from the link; the link itself is not polled

    def _close(self) -> None:
        link, self._link = self._link, None
        self._pending.clear()
        if link is not None:
            with depthai_errors("closing the depthai device", RigOperationError):
                link.close()
