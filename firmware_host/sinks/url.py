"""Sink URL parsing: scheme, location and typed query parameters.

Every error names the URL, the parameter and the value (SinkConfigError).
"""
from __future__ import annotations

import ipaddress
import math
import os
import socket
from dataclasses import dataclass
from typing import Callable, Optional, TypeVar
from urllib.parse import SplitResult, parse_qs, urlsplit

from drivers.url import UrlPartError, decimal_number, decode_url_part, dropped_characters, not_utf8_escapes, \
    whole_number, with_kept_bytes_escaped, yes_no
from firmware_host.errors import SinkConfigError
from ghnerf_runtime.plain_values import plain_scalar

T = TypeVar("T")


@dataclass
class SinkUrl:
    url: str
    scheme: str
    netloc: str
    path: str
    query: dict[str, str]

    def take(self, key: str, convert: Callable[[str], T], default: T, kw: Optional[dict] = None) -> T:
        """Remove ``key`` from the query (and from ``kw``, which wins) and convert it.

        Keyword values that are strings or numbers go through the same check as
        query values (``None`` counts as not given; ``True``/``False`` only for a
        yes/no option); other objects (tuples, policies) are taken as they are.
        NumPy scalars and 0-d arrays count as the Python value they hold
        (:func:`~ghnerf_runtime.plain_values.plain_scalar`): a keyword's np.int64 or np.float32 was taken as an
        object and skipped every check (baud=np.int64(-5) and queue=np.float32(8.5) were accepted, np.True_ was a
        baud of 1); complex numbers and bytes (Python's or NumPy's: text to decode first) are refused.
        """
        raw: object = self.query.pop(key, None)
        # unwrapped before the None test: a 0-d array holding None is not given either (it came back as the value)
        given = plain_scalar(kw.pop(key, None)) if kw is not None else None
        if given is not None:  # else not given: the query's value, else the default
            raw = given
            if isinstance(raw, bool):  # ep=True was endpoint 1
                if convert is boolean:
                    return raw  # type: ignore[return-value]
                raise SinkConfigError(self.url, key, raw, "must be a value, not true/false")
            if isinstance(raw, complex):  # an object skipped every check: a baud of (-5+0j) reached the port
                raise SinkConfigError(self.url, key, raw, "must be a real number, not complex")
            if isinstance(raw, (bytes, bytearray)):  # an object too: send_2d=b"no" was yes, queue=b"8" a TypeError
                raise SinkConfigError(self.url, key, raw, "must be text or a number, not bytes (decode them first)")
            if not isinstance(raw, (str, int, float)):
                return raw  # type: ignore[return-value]
        if raw is None:
            return default
        try:
            return convert(str(raw))
        except (ValueError, TypeError) as e:
            raise SinkConfigError(self.url, key, raw, str(e) or "bad value") from e

    def reject_leftovers(self) -> None:
        """Unknown query keys are an error, so a typo is never silently ignored."""
        if self.query:
            key = sorted(self.query)[0]
            raise SinkConfigError(self.url, key, self.query[key], "unknown parameter")


def _refuse_not_utf8(url: str, field: str, raw: str, decoded: str, value: str) -> None:
    """:class:`SinkConfigError` naming ``field`` and its ``value`` when ``decoded`` (a query key or value, which
    ``parse_qs`` decoded from ``raw``, the query) holds escapes of bytes that are not UTF-8: decoded to U+FFFD, the
    sink took another value than the one given. A path or port is decoded by :func:`unquote_part`."""
    problem = not_utf8_escapes(raw, decoded)
    if problem is not None:
        raise SinkConfigError(url, field, value, problem)


def unquote_part(url: str, field: str, raw: str) -> str:
    """The part ``raw`` of the sink URL ``url`` (a path, a port) percent-decoded as UTF-8, by the rule every URL
    parser shares (:func:`drivers.url.decode_url_part`).

    :raises SinkConfigError: naming ``field`` and the escapes, for one that is no UTF-8 byte sequence.
    """
    try:
        return decode_url_part(field, raw)
    except UrlPartError as e:
        raise SinkConfigError(url, e.field, e.value, e.why) from None


def _refuse_non_text(url: object) -> None:
    """:class:`SinkConfigError` (field ``url``) for a URL that is not a ``str``: bytes or a ``Path`` raised a bare
    TypeError or AttributeError from ``urlsplit``. Named as text, so that its password is redacted like any URL's."""
    if isinstance(url, str):
        return
    if isinstance(url, (bytes, bytearray)):
        as_text, hint = url.decode("utf-8", "backslashreplace"), ": decode it first"
    else:
        as_text = str(url)
        hint = ": a file is file:///path/to/joints.jsonl (Path.as_uri())" if isinstance(url, os.PathLike) else ""
    raise SinkConfigError(as_text, "url", as_text, f"must be text (str), not {type(url).__name__}{hint}")


def parse_url(url: str) -> SinkUrl:
    _refuse_non_text(url)
    dropped = dropped_characters(url)
    if dropped is not None:  # urlsplit removed it: file:///tmp/a<TAB>b.jsonl wrote /tmp/ab.jsonl, baud=96<LF>00 9600;
        raise SinkConfigError(url, "url", url, dropped)  # first, as an ESC sequence's '[' read as a broken IPv6 host
    try:
        parts = urlsplit(url)
    except (ValueError, TypeError) as e:  # e.g. "Invalid IPv6 URL": an unclosed [
        raise SinkConfigError(url, "url", url, f"cannot be parsed: {e}") from e
    if not parts.scheme:
        raise SinkConfigError(url, "scheme", "", "expected e.g. serial://, usb://, udp://, vmc://, file://, memory://")
    if "#" in url:  # urlsplit drops a fragment: file:///tmp/run#2/joints.jsonl would write to /tmp/run
        raise SinkConfigError(url, "fragment", parts.fragment, "a '#' ends the URL; write a '#' in a path or "
                                                               "value as %23")
    query: dict[str, str] = {}
    # '+' is a plus, as in the path (a form's '+' for a space changed a value silently); a space is %20
    for key, values in parse_qs(parts.query.replace("+", "%2B"), keep_blank_values=True,
                                strict_parsing=False, errors="surrogateescape").items():
        _refuse_not_utf8(url, "parameter name", parts.query, key, with_kept_bytes_escaped(key))
        for value in values:
            _refuse_not_utf8(url, key, parts.query, value, with_kept_bytes_escaped(value))
        if len(values) > 1:
            raise SinkConfigError(url, key, values, "given more than once")
        query[key] = values[0]
    return SinkUrl(url, parts.scheme.lower(), parts.netloc, parts.path, query)


# A whole number: ASCII decimal digits, or hex/octal/binary with its prefix, no sign, spaces or '_'; a leading zero
# (08, 010) is refused with that said (C reads 010 as octal 8). One rule for sink and camera URLs, in drivers.url.
integer = whole_number


def positive_int(raw: str) -> int:
    v = integer(raw)  # accepts 0x01 for endpoints
    if v <= 0:
        raise ValueError("must be > 0")
    return v


def int_in(lo: int, hi: int, why: str = "") -> Callable[[str], int]:
    """A converter for an integer in ``[lo, hi]``; ``why`` (the reason for the bounds) ends its message."""
    def convert(raw: str) -> int:
        v = integer(raw)
        if not lo <= v <= hi:
            raise ValueError(f"must be in [{lo}, {hi}]" + (f": {why}" if why else ""))
        return v
    return convert


def positive_float(raw: str) -> float:
    v = decimal_number(raw)  # as camera URLs read it: fps=1_0 or %2010 refused, not read as 10
    if not (v > 0 and math.isfinite(v)):
        raise ValueError("must be a finite number > 0")
    return v


def one_of(*choices: str) -> Callable[[str], str]:
    """A converter for a word from ``choices``, exactly as written there (lower case)."""
    def convert(raw: str) -> str:
        if raw not in choices:
            raise ValueError(f"must be one of {list(choices)}")
        return raw
    return convert


def boolean(raw: str) -> bool:
    """A yes/no option: camera URLs' words (:func:`drivers.url.yes_no`), any case, nothing around them
    (``send_2d=%20yes`` was read as yes). Given empty it is refused (a rig URL's bare ``?loop`` means yes)."""
    return yes_no(raw)


def location_host(parts: SplitResult, scheme: str) -> str:
    """The host of a ``scheme://host:port`` URL as ``getaddrinfo`` takes it, ``""`` when none is given: an IPv6
    zone percent-encoded (``[fe80::1%25eth0]``, RFC 6874) decoded and keeping its case (``hostname`` lowers it).

    :raises UrlPartError: user info or a path, refused rather than ignored (a typo is never silently dropped), or
        a host whose escapes are not UTF-8 (:func:`drivers.url.decode_url_part`; U+FFFD: a lookup of a name never
        given).
    """
    if parts.username is not None or parts.password is not None:
        raise UrlPartError("user info", parts.netloc.rpartition("@")[0],
                            f"{scheme}:// takes no user info (the part before '@')")
    if parts.path not in ("", "/"):
        raise UrlPartError("path", parts.path, f"{scheme}:// takes host:port and no path")
    hostinfo = parts.netloc.rpartition("@")[2]
    raw = hostinfo[1:hostinfo.index("]")] if hostinfo.startswith("[") else parts.hostname or ""
    return decode_url_part("host", raw)


#: Longest host name, written out without a trailing dot (RFC 1035: 255 octets on the wire).
MAX_HOST_NAME = 253


def host_name_problem(host: str) -> str:
    """Why ``host`` can never be looked up, ``""`` when it may be: an IP literal (an IPv6 zone included), or a name
    of labels of 1 to 63 characters (as IDNA encodes it), at most :data:`MAX_HOST_NAME` in all, without spaces or
    control characters. Such a name failed every connect of a udp:// sink, for ever, one of them logged as a
    backend bug with its traceback (getaddrinfo's UnicodeError): a typo is refused when the URL is read."""
    try:
        ipaddress.ip_address(host)
        return ""
    except ValueError:
        pass
    if any(ch.isspace() or not ch.isprintable() for ch in host):
        return "a host name has no spaces or control characters"
    if host.removesuffix(".").rpartition(".")[2].isdecimal():
        return _numeric_host_problem(host)
    try:
        encoded = host.encode("idna")  # what getaddrinfo does with it
    except UnicodeError as e:  # the codec's own reason is on its cause ("label empty or too long")
        return f"not a host name: each dot-separated label is 1 to 63 characters ({e.__cause__ or e})"
    if len(encoded.removesuffix(b".")) > MAX_HOST_NAME:
        return f"not a host name: {len(encoded.removesuffix(b'.'))} characters, at most {MAX_HOST_NAME}"
    return ""


def _numeric_host_problem(host: str) -> str:
    """Why a host of numbers that is no dotted-quad IPv4 address (``ipaddress`` refused it) is refused: no host name
    ends in an all-digit label (RFC 1123), so getaddrinfo either fails it for ever (``192.168.1.300``) or reads it
    the C library's old way and sends elsewhere: leading zeros as octal (``192.168.001.010`` is 192.168.1.8), missing
    parts as zeros (``10.1`` is 10.0.0.1)."""
    try:
        as_read = socket.inet_ntoa(socket.inet_aton(host))
    except OSError:
        return "not an IPv4 address (four numbers 0 to 255) nor a host name (whose last label is not all digits)"
    return (f"not a dotted-quad IPv4 address: it would be read as {as_read} (leading zeros are octal, missing parts "
            f"zeros); write the address meant as four numbers 0 to 255 without leading zeros")


def ipv6_hint(parts: SplitResult, scheme: str, port: int) -> str:
    """A hint for a location with an IPv6 address outside brackets, else ``""``."""
    if parts.netloc.count(":") > 1 and "[" not in parts.netloc:
        return f"; an IPv6 address goes in brackets, e.g. {scheme}://[::1]:{port}"
    return ""


def host_port(u: SinkUrl, default_port: Optional[int] = None) -> tuple[str, int]:
    """``host:port`` from the URL's location (:func:`location_host`); IPv6 hosts in brackets."""
    parts = urlsplit(u.url)
    try:
        host = location_host(parts, u.scheme)
    except UrlPartError as e:
        raise SinkConfigError(u.url, e.field, e.value, e.why) from None
    hint = ipv6_hint(parts, u.scheme, 9000)
    # the port as written, after the host (past an IPv6 literal's brackets): the errors named the whole location
    after_host = parts.netloc.rpartition("]")[2]
    port_text = after_host.rpartition(":")[2] if ":" in after_host else ""
    if not host:
        # udp://:9870 is the listener's form (every interface), copied into a sink's config: say what a sink takes
        listener = " (udp://:PORT, every interface, is how ghnerf-listen listens)" if u.scheme == "udp" else ""
        # the port as written where it is one, else the scheme's own (vmc://'s 39539, not the joint stream's 9870)
        example = port_text if port_text.isascii() and port_text.isdigit() and 0 < int(port_text) <= 65535 \
            else default_port or 9870
        hint = hint or f"; a sink sends to one receiver, e.g. {u.scheme}://127.0.0.1:{example}{listener}"
        raise SinkConfigError(u.url, "host", "", "missing host" + hint)
    problem = host_name_problem(host)
    if problem:
        raise SinkConfigError(u.url, "host", host, problem)
    try:
        port = parts.port
    except ValueError as e:
        raise SinkConfigError(u.url, "port", port_text, str(e) + hint) from e
    if port is None:
        if default_port is None:
            raise SinkConfigError(u.url, "port", port_text,
                                  f"missing port: write {u.scheme}://{parts.netloc.rstrip(':')}:PORT, the receiver's")
        port = default_port
    if port == 0:
        raise SinkConfigError(u.url, "port", port, "must be 1..65535")
    return host, port
