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


class DepthRangeError(GeometryError):
    """A box reaches farther from a camera than the model's float32 inputs resolve
    (``contract.MAX_DEPTH_M``): no near/far of it can be handed to the graphs. Unlike a box wholly behind
    the camera (nothing to render, an empty view), this is the caller's error."""


class RigFileError(RuntimeErrorBase, ValueError):
    """A rig file (or imported calibration file) is malformed.

    ``path`` and ``field`` say where; the message repeats both.
    """

    def __init__(self, message: str, *, path: str | None = None, field: str | None = None):
        where = ", ".join(p for p in (f"file {path}" if path else "", f"field {field!r}" if field else "") if p)
        super().__init__(f"{where}: {message}" if where else message)
        self.path = path
        self.field = field


class ImageWriteError(RuntimeErrorBase):
    """An image that could not be encoded or written (``ghnerf_runtime.image_write``); ``reason`` is the message
    without the path, for a tool that names the file its own way."""

    def __init__(self, path: str, reason: str):
        super().__init__(f"{path}: {reason}")
        self.path = path
        self.reason = reason


class ConfigError(RuntimeErrorBase, ValueError):
    """A runtime configuration value or key is invalid.

    ``key`` is the dotted path of the offending key (``"joints3d.method"``); the message
    starts with it.
    """

    def __init__(self, message: str, *, key: str | None = None):
        super().__init__(f"{key}: {message}" if key else message)
        self.key = key


class ModelError(RuntimeErrorBase):
    """Root of the errors about model files (loading them, their contract, running them).

    ``path`` names the file (or folder) concerned; the message starts with it.
    """

    def __init__(self, message: str, *, path: str | None = None):
        super().__init__(f"{path}: {message}" if path else message)
        self.path = path


class ModelLoadError(ModelError, OSError):
    """A model file is missing, unreadable or not a valid ONNX model (truncated, corrupt)."""


class ModelContractError(ModelError, ValueError):
    """A model file's contract (metadata, graph I/O) does not match what the runtime needs.

    ``key`` names the metadata key or tensor that is wrong (e.g. ``"ghnerf.contract_version"``,
    ``"images"``); both ``path`` and ``key`` appear in the message.
    """

    def __init__(self, message: str, *, path: str | None = None, key: str | None = None):
        super().__init__(f"{key}: {message}" if key else message, path=path)
        self.key = key


class ModelRunError(ModelError):
    """onnxruntime failed while running a graph (the message names the graph and file)."""


class FrameError(RuntimeErrorBase, ValueError):
    """A frame handed to the estimator has the wrong shape or type for its camera.

    A *bad* frame (black, saturated, noise) is not an error: its joints come back missing.
    """
