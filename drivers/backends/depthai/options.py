"""URL options of ``depthai://``, validated once into :class:`DepthaiOptions`.

``depthai://[device-id]?left=CAM_B&right=CAM_C&fps=30&width=640&height=400``

* target: a device id (MX id / serial) or XLink name (USB port path such as ``1.3``, or IP);
  empty = the first free device found (a warning names the others when several are free). A
  device in use by another process, a name shared by several devices and a device that is not
  connected are errors naming the connected devices.
* ``left``, ``right``: board sockets of the stereo pair (``CAM_A`` .. ``CAM_J``);
  the first is the rig's first camera. Default ``CAM_B`` / ``CAM_C`` (OAK-D mono pair).
* ``fps`` (30, 1 to 240), ``width`` (640), ``height`` (400): output stream, an even number of
  pixels each way (16 to 8192); the sensor image is centre-cropped to the output aspect ratio,
  then scaled. At open they are checked against the device's sensors (no larger, no faster; the
  sockets must have cameras). Under ``policy=latest`` a stream that delivers under 80 % of ``fps``
  (a USB2 link) is logged once as a warning with the measured rate.
* ``mount_height``: height of the cameras above the floor, metres (default 1.0,
  logged as an assumption): places the rig frame's origin on the floor (see
  :mod:`.calibration`). ``height`` is the image height, hence the name.
* ``mount_roll``: degrees the device is turned about its viewing direction, counterclockwise
  as seen from behind it (default 0: level; 180: upside down, as hung from a ceiling; 90 or
  -90: on its side). The device calibration cannot know it; the rig frame keeps gravity down
  and the runtime shows the model upright crops (``roi.upright``).
* ``rig``: path to a rig file to use instead of the device's calibration.
* ``tolerance_ms``, ``policy``, ``max_pending``: pairing (:mod:`drivers.pairing_options`); the Sync
  node's threshold is ``tolerance_ms``. The Sync node delivers both frames of a group together, so
  ``max_pending`` (frames held per camera while waiting for the other's) has nothing to hold here.
* ``queue``: depth of the host output queue (default 4, at most 64; older groups are dropped).
  Under ``policy=latest`` each read drains all of it and returns the newest group (the rest
  count as ``pairs_dropped``); under ``policy=all`` it is how far a slow reader may fall behind.
  A group the full queue dropped, or a frame one camera lost (Sync then discards its partner),
  shows as both cameras' indices jumping together: a pair the reader never got, counted in
  ``pairs_dropped`` (sequence gaps), not in ``camera_gaps`` (which keeps gaps of one camera only).
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import depthai as dai

from drivers.errors import RigConfigError
from drivers.pairing import PairingConfig
from drivers.pairing_options import take_pairing_options
from drivers.url import RigUrl

DEFAULT_MOUNT_HEIGHT_M = 1.0
# Sorted: depthai's enum lists CAM_I and CAM_J first, which an error message listing the choices should not.
_SOCKETS = tuple(sorted(name for name in dai.CameraBoardSocket.__members__ if name.startswith("CAM_")))


def board_socket(name: str) -> dai.CameraBoardSocket:
    """The ``dai.CameraBoardSocket`` called ``name`` (``CAM_B``...)."""
    return dai.CameraBoardSocket.__members__[name]


@dataclass(frozen=True)
class DepthaiOptions:
    """Validated ``depthai://`` options (see the module docstring)."""

    device_id: str | None = None
    left: str = "CAM_B"
    right: str = "CAM_C"
    fps: float = 30.0
    width: int = 640
    height: int = 400
    mount_height_m: float | None = None  # None: not given (DEFAULT_MOUNT_HEIGHT_M is assumed)
    mount_roll_deg: float = 0.0
    rig_path: Path | None = None
    queue_size: int = 4
    pairing: PairingConfig = PairingConfig()
    url: str = ""  # the URL these came from, for error messages

    @classmethod
    def from_url(cls, url: RigUrl) -> "DepthaiOptions":
        ids = url.target.split(",") if url.target else []
        if "" in ids:  # depthai://, opened the first device found, depthai://ID, the device ID: a device never named
            raise RigConfigError(f"rig URL {url.url!r}: device {url.target!r} has an empty name around ','; give one "
                                 "device id, or none for the first device found")
        if len(ids) > 1:
            raise RigConfigError(
                f"rig URL {url.url!r}: two-device rigs (depthai://ID1,ID2) are not supported by this build; "
                "use one device's stereo pair"
            )
        left = url.take_str("left", "CAM_B", choices=_SOCKETS) or "CAM_B"
        right = url.take_str("right", "CAM_C", choices=_SOCKETS) or "CAM_C"
        if left == right:
            raise RigConfigError(f"rig URL {url.url!r}: options left and right name the same socket {left}")
        fps = url.take_float("fps", 30.0, lo=1.0, hi=240.0)
        width = url.take_int("width", 640, lo=16, hi=8192)
        height = url.take_int("height", 400, lo=16, hi=8192)
        for name, value in (("width", width), ("height", height)):
            if value % 2:  # NV12 (the Camera node's colour output) has one chroma sample per 2x2 pixels
                raise RigConfigError(f"rig URL {url.url!r}: option {name}={value} must be even (NV12 images are)")
        mount = url.options.get("mount_height")
        mount_height = url.take_float("mount_height", DEFAULT_MOUNT_HEIGHT_M, lo=0.0, hi=10.0)
        roll = url.options.get("mount_roll")
        mount_roll = url.take_float("mount_roll", 0.0, lo=-360.0, hi=360.0)
        rig = url.take_str("rig")
        for given, name in ((mount, "mount_height"), (roll, "mount_roll")):
            if rig is not None and given is not None:
                raise RigConfigError(
                    f"rig URL {url.url!r}: give rig= (a rig file) or {name}= (with the device calibration), not both"
                )
        pairing = take_pairing_options(url, max_tolerance_ms=1000.0)
        queue_size = url.take_int("queue", 4, lo=1, hi=64)
        url.finish()
        return cls(
            device_id=ids[0] if ids else None,
            left=left,
            right=right,
            fps=fps,
            width=width,
            height=height,
            mount_height_m=mount_height if mount is not None else None,
            mount_roll_deg=mount_roll,
            rig_path=Path(rig) if rig else None,
            queue_size=queue_size,
            pairing=pairing.config(),
            url=url.url,
        )
