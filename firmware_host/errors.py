"""Typed errors for firmware_host.

Vendor exceptions (pyserial, pyusb, OSError) are converted at the boundary
with ``raise ... from e`` so callers only need to catch these.
"""
from __future__ import annotations

from drivers.url import REDACTED, is_secret_key, redact_location, redact_url, shown_url
from ghnerf_runtime.path_check import shown


class FirmwareHostError(Exception):
    """Base class of every error raised by firmware_host."""


class SinkError(FirmwareHostError):
    """A joint-stream output failed."""


def shown_value(field: str, value: object) -> object:
    """A refused sink (or ``ghnerf-listen``) URL field's ``value`` as a message shows it: a secret option's as
    ``***``, a URL or a location (``user:password@host``, the user info before the ``@``) without its password;
    anything else as it is."""
    if is_secret_key(field):
        return REDACTED
    if not isinstance(value, str):
        return value
    if "://" in value:
        return redact_url(value)
    if field == "user info":  # what came before the '@': user[:password]
        return redact_location(value + "@")[:-1]
    return redact_location(value)


class SinkConfigError(SinkError, ValueError):
    """A sink URL or keyword is invalid; the message names the URL, field and value, without the passwords the
    URL may carry (``drivers.url.redact_url``: messages reach logs and the journal), on one line (``shown_url``: a
    control character escaped). ``url`` and ``value`` keep what was given."""

    def __init__(self, url: str, field: str, value: object, reason: str) -> None:
        self.url = url
        self.field = field
        self.value = value
        super().__init__(f"{shown_url(url)}: invalid {field}={shown_value(field, value)!r}: {reason}")


class SinkUnavailableError(SinkError):
    """The link is absent or went away (unplugged, refused); the sink retries with backoff. The message names the
    URL without its passwords; ``url`` keeps it as given, ``reason`` what went wrong without the URL (for a line
    that names the URL already: the sink's "link lost")."""

    def __init__(self, url: str, reason: str) -> None:
        self.url = url
        # on one line: a path the URL's %1B decoded into (or pyserial's words quoting it) reached the log raw
        self.reason = shown(reason)
        super().__init__(f"{shown_url(url)}: unavailable: {self.reason}")


class SinkWriteError(SinkError):
    """One write failed but the link is still up (endpoint stall, timeout): the frame is dropped. The message names
    the URL without its passwords; ``url`` keeps it as given, ``reason`` what went wrong without the URL."""

    def __init__(self, url: str, reason: str) -> None:
        self.url = url
        self.reason = shown(reason)  # on one line, as the link's reason
        super().__init__(f"{shown_url(url)}: write failed: {self.reason}")


class SinkPartialWriteError(SinkWriteError):
    """A frame's write failed after part of it went out (a vmc:// frame's first bundle sent, a later one not; a
    frame's JOINTS out, a JOINTS_2D not): the receiver has that part, so the frame counts as ``sent`` and
    ``partial``, not dropped. ``sent`` and ``total``: the ``parts`` (datagrams, packets) that went out, of how many."""

    def __init__(self, url: str, reason: str, sent: int, total: int, parts: str = "datagrams") -> None:
        self.sent, self.total = sent, total
        super().__init__(url, f"{reason} (after {sent} of the frame's {total} {parts} went out)")


class SinkClosedError(SinkError):
    """A frame was sent to a sink after ``close()``."""


class CaptureTimeError(FirmwareHostError, ValueError):
    """A pair's capture time that the joint stream cannot carry (its header's ``capture_us`` is an unsigned 64-bit
    count of microseconds): names the camera, the frame and the stamp."""


class ProtocolError(FirmwareHostError, ValueError):
    """Base class of joint-protocol encoding and decoding errors."""


class EncodeError(ProtocolError):
    """A message field cannot be represented on the wire; names the field and value."""

    def __init__(self, field: str, value: object, reason: str) -> None:
        self.field = field
        self.value = value
        super().__init__(f"cannot encode {field}={value!r}: {reason}")


class FrameError(ProtocolError):
    """A received frame was rejected. ``code`` is one of the decoder error codes
    (``oversize``, ``cobs``, ``short``, ``crc``, ``version``, ``malformed``)
    documented in docs/protocol.md."""

    def __init__(self, code: str, detail: str) -> None:
        self.code = code
        super().__init__(f"{code}: {detail}")


class UnknownMessageType(ProtocolError):
    """A well-formed packet of a type this decoder does not know; decoders skip it."""

    def __init__(self, msg_type: int) -> None:
        self.msg_type = msg_type
        super().__init__(f"unknown message type 0x{msg_type:02x}")
