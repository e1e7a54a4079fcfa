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


class RigTimeoutError(DriverError, TimeoutError):
    """No frame pair arrived within the requested timeout."""


class EndOfStream(RigDisconnectedError):
    """A finite source (a recording) has no more frames."""
