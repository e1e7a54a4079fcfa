"""Errors of the synthetic-human simulator.

Both are ``ValueError`` subclasses (bad input, not a runtime failure) and both
sit under :class:`drivers.errors.DriverError` so callers of ``sim://`` can catch
the driver tree as a whole.
"""
from __future__ import annotations

from drivers.errors import RigConfigError


class SimConfigError(RigConfigError):
    """A simulator config value is out of range; the message names the field.

    Attributes:
        field: dotted name of the offending field (``"SceneConfig.speed"``).
    """

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field}: {message}")
        self.field = field


class BvhError(RigConfigError):
    """A BVH file is malformed or cannot drive the body; the message names the file and line.

    Attributes:
        path: the file (or ``"<string>"`` for text parsed from memory).
        line: 1-based line number, or ``None`` when the problem is not tied to one line.
    """

    def __init__(self, path: str, line: int | None, message: str) -> None:
        where = f"{path}:{line}" if line is not None else str(path)
        super().__init__(f"{where}: {message}")
        self.path = str(path)
        self.line = line
