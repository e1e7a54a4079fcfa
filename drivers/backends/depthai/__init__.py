"""``depthai://[device-id]``: one Luxonis OAK device's stereo pair through depthai 3.x.

This package is the only place that imports ``depthai`` (the registry loads it
only when a ``depthai://`` URL is opened). Its parts:

* :mod:`.options`: URL options, validated once.
* :mod:`.calibration`: the device's ``CalibrationHandler`` -> our :class:`~ghnerf_runtime.geometry.Rig`.
* :mod:`.convert`: depthai messages -> :class:`~drivers.frames.Frame`, depthai errors -> ours.
* :mod:`.pipeline`: the host-side ``Sync`` stage that pairs the two camera outputs.
* :mod:`.link`: :class:`~.link.DeviceLink`, the small interface behind which sits
  everything that needs a device, and :class:`~.link.DaiDeviceLink`, its depthai implementation.
* :mod:`.source`: :class:`DepthaiRigSource`, the backend.

Importing it sets ``DEPTHAI_TELEMETRY=0`` unless the user set it (:mod:`ghnerf_runtime.vendor_telemetry`).
"""
from ghnerf_runtime.vendor_telemetry import default_depthai_telemetry_off

# Before the modules below import depthai: it reads DEPTHAI_TELEMETRY on import and uploads from then on.
default_depthai_telemetry_off()

from drivers.backends.depthai.source import DepthaiRigSource  # noqa: E402  (after the switch, on purpose)

__all__ = ["DepthaiRigSource"]
