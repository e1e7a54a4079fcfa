"""Typed errors of the drivers package (python-can style: not available / init / operation / timeout)."""
from __future__ import annotations


class DriverError(Exception):
    """Root of every error raised by ``drivers``."""


class BackendNotAvailableError(DriverError):
    """The URL names an unknown backend, or its library (e.g. depthai) cannot be imported."""


class RigConfigError(DriverError, ValueError):
    """A rig URL or backend option is malformed; the message names the option and value."""


class RigInitializationError(DriverError):
    """The backend was chosen but could not start (no device, unreadable recording...)."""


class RigOperationError(DriverError):
    """A running backend failed."""


class RigDisconnectedError(RigOperationError):
    """A camera vanished (unplugged, device reset, end of a recording)."""


class RecordingError(RigOperationError):
    """A ``record+`` recorder could not write the take (disk full...): raised once from the next read, the
    frames passing through unrecorded after it. Its own type, so that a reader that goes past a frame the rig
    could not deliver (``ghnerf-demo``) can tell a take that stopped being written from a lost frame."""


class RigTimeoutError(DriverError, TimeoutError):
    """No frame pair arrived within the requested timeout."""


class EndOfStream(RigDisconnectedError):
    """A finite source (a recording) has no more frames."""


class FrameSizeError(RigInitializationError, RigOperationError):
    """A camera delivers frames of another size than its rig camera's (the rig file's calibration).

    At :meth:`~drivers.base.RigSource.open` (the first frames) it fails the open; while streaming it is a
    failed read. Both bases, so that code catching either goes on as before; ``camera``, ``expected`` (the rig's
    ``(width, height)``) and ``delivered`` let a caller tell a wrong rig file (the same wrong size at every open)
    from a camera that changed size for a while. ``args`` are all four, so ``type(e)(*e.args)`` copies it.
    """

    def __init__(self, message: str, camera: str, expected: tuple[int, int], delivered: tuple[int, int]) -> None:
        super().__init__(message, camera, tuple(expected), tuple(delivered))
        self.message, self.camera = message, camera
        self.expected, self.delivered = tuple(expected), tuple(delivered)

    def __str__(self) -> str:
        return self.message


class OpenInProgressError(RigOperationError):
    """``open()`` was called while another call's open of the same source had not finished: refused, rather than a
    second start of the backend (a second set of cameras, a second pre-render). The message names the source."""
