"""Typed errors of the runtime package.

Every message names what was wrong (the file, the field, the value) so that a
user reading a log on a headless device can fix it without a debugger.
"""
from __future__ import annotations


class RuntimeErrorBase(Exception):
    """Root of every error raised by ``ghnerf_runtime``."""


class GeometryError(RuntimeErrorBase, ValueError):
    """Invalid camera or rig parameters, or degenerate geometric input."""


class ShapeError(GeometryError):
    """An array argument does not have the documented shape."""


class RigFileError(RuntimeErrorBase, ValueError):
    """A rig file (or imported calibration file) is malformed.

    ``path`` and ``field`` say where; the message repeats both.
    """

    def __init__(self, message: str, *, path: str | None = None, field: str | None = None):
        where = ", ".join(p for p in (f"file {path}" if path else "", f"field {field!r}" if field else "") if p)
        super().__init__(f"{where}: {message}" if where else message)
        self.path = path
        self.field = field
