"""Typed errors of the training data package; every message names the file or the field."""
from __future__ import annotations

from pathlib import Path


class DataError(Exception):
    """Root of every error raised by :mod:`training.data`."""


class DataConfigError(DataError, ValueError):
    """A data config value is invalid; ``field`` is its dotted name (``"SyntheticConfig.resolution"``)."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field}: {message}")
        self.field = field
        self.message = message

    def __reduce__(self):
        # pickled from a generate worker to its parent: the default (cls, args) would call __init__ with the
        # one formatted string, and the pool's result thread, failing to unpickle it, would hang the run
        return type(self), (self.field, self.message)


class DatasetError(DataError, ValueError):
    """A dataset on disk is missing, incomplete or malformed; ``path`` is the offending file or folder."""

    def __init__(self, path: str | Path, message: str) -> None:
        super().__init__(f"{path}: {message}")
        self.path = str(path)
        self.message = message

    def __reduce__(self):  # see DataConfigError.__reduce__
        return type(self), (self.path, self.message)
