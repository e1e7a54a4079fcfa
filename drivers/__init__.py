"""Camera drivers: ``open_rig(url)`` gives synchronised frame pairs from a calibrated two-camera rig.

Backends (imported only when chosen): ``sim://`` (simulated rig filming a synthetic person),
``replay://DIR`` (a recording), ``record+<url>`` (record while passing through),
``depthai://[device-id]`` (Luxonis OAK through depthai 3.x), ``opencv://?first=..&second=..``
(two cameras OpenCV opens: USB webcams, video files, streams).
"""
from drivers.base import RigSource
from drivers.clock import ManualClock, MonotonicClock
from drivers.errors import (
    BackendNotAvailableError,
    DriverError,
    EndOfStream,
    FrameSizeError,
    OpenInProgressError,
    RecordingError,
    RigConfigError,
    RigDisconnectedError,
    RigInitializationError,
    RigOperationError,
    RigTimeoutError,
)
from drivers.frames import CameraTruth, Frame, FramePair
from drivers.pairing import DropPolicy, PairingConfig, PairingStats, silent_cameras, why_no_pair
from drivers.registry import BACKENDS, create_rig_source, open_rig

__all__ = [
    "BACKENDS", "BackendNotAvailableError", "CameraTruth", "DriverError", "DropPolicy", "EndOfStream", "Frame",
    "FramePair", "FrameSizeError", "ManualClock", "MonotonicClock", "OpenInProgressError", "PairingConfig",
    "PairingStats", "RecordingError", "RigConfigError", "RigDisconnectedError", "RigInitializationError",
    "RigOperationError", "RigSource", "RigTimeoutError", "create_rig_source", "open_rig", "silent_cameras",
    "why_no_pair",
]
