"""Typed errors of the calibration tool (``ghcal``); each message names the file, key or view at fault."""
from __future__ import annotations


class CalibrationError(Exception):
    """Root of the errors raised by ``calibration`` (the formats raise ``ghnerf_runtime``'s RigFileError)."""


class BoardError(CalibrationError, ValueError):
    """A board definition is invalid: ``key`` names the field (``"marker_m"``), the message the value."""

    def __init__(self, message: str, *, key: str | None = None, path: str | None = None) -> None:
        where = ": ".join(p for p in (path, key) if p)
        super().__init__(f"{where}: {message}" if where else message)
        self.detail = message  # without the place, for re-raising it with the file's
        self.key = key
        self.path = path


class CaptureError(CalibrationError):
    """The calibration images cannot be read or paired (a missing folder, an unreadable image, sizes that differ)."""


class SolveError(CalibrationError):
    """The views do not determine the calibration (too few views or corners, a degenerate board pose)."""
