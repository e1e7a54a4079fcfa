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


class DatasetError(DataError, ValueError):
    """A dataset on disk is missing, incomplete or malformed; ``path`` is the offending file or folder."""

    def __init__(self, path: str | Path, message: str) -> None:
        super().__init__(f"{path}: {message}")
        self.path = str(path)
