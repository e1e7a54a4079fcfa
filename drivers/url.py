"""Rig URLs: ``scheme://target?option=value&...`` with typed, validated options.

Every option a backend reads is taken through a typed getter; whatever is left
afterwards is an unknown option and :meth:`RigUrl.finish` rejects it by name,
so a typo such as ``sim://?fsp=60`` fails loudly instead of being ignored.
A ``#`` would start a fragment, which URL parsing drops: it is refused (write ``%23``).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from urllib.parse import parse_qsl, unquote, urlsplit

from drivers.errors import RigConfigError

_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"0", "false", "no", "off"}
_LEADING_ZERO = re.compile(r"[+-]?0[0-9_]*[1-9][0-9_]*")


def whole_number(raw: str) -> int:
    """A whole number as a URL writes it: decimal digits, or hex, octal or binary with its prefix (``0x10``,
    ``0o17``, ``0b101``). A leading zero (``08``, ``010``) is refused with that said, not guessed at: C reads 010
    as octal 8, and a user who typed 08 meant something. Camera URLs (here) and sink URLs
    (``firmware_host.sinks.url.integer``) share this rule. Raises ValueError with the reason."""
    try:
        return int(raw, 0)
    except ValueError:
        pass
    text = raw.strip()
    if _LEADING_ZERO.fullmatch(text):
        sign = text[0] if text[0] in "+-" else ""
        raise ValueError(f"decimal digits expected, without a leading zero (write {sign}{text.lstrip('+-0_')}; "
                         "hex as 0x..)")
    raise ValueError("expected a whole number: decimal digits, or hex as 0x..")


@dataclass
class RigUrl:
    """A parsed rig URL.

    Attributes:
        url: the original text, for error messages.
        scheme: backend name (``sim``, ``replay``, ``depthai``...).
        target: what follows ``scheme://`` up to ``?`` (a path, a device id, or empty).
        options: the query options not consumed yet.
    """

    url: str
    scheme: str
    target: str
    options: dict[str, str] = field(default_factory=dict)

    @classmethod
    def parse(cls, url: str) -> "RigUrl":
        if not isinstance(url, str) or "://" not in url:
            raise RigConfigError(f"rig URL must look like 'scheme://target?options', got {url!r}")
        try:
            parts = urlsplit(url)
        except ValueError as e:  # e.g. an unclosed '[' reads as a broken IPv6 host
            raise RigConfigError(f"rig URL {url!r} cannot be parsed: {e}") from None
        if "#" in url:  # urlsplit would drop the fragment: record into, or play, another directory
            raise RigConfigError(
                f"rig URL {url!r}: '#' starts a URL fragment ({'#' + parts.fragment!r}), which rig URLs do not "
                "use; write a '#' in a path or option value as %23"
            )
        target = unquote(parts.netloc + parts.path)
        options: dict[str, str] = {}
        # '+' is a plus here, as in the path (a form's '+' for a space turned out=/data/take+1 into '/data/take 1');
        # a space is %20
        for key, value in parse_qsl(parts.query.replace("+", "%2B"), keep_blank_values=True,
                                    strict_parsing=False):
            if key in options:
                raise RigConfigError(f"rig URL {url!r}: option {key!r} given twice")
            options[key] = value
        return cls(url=url, scheme=parts.scheme.lower(), target=target, options=options)

    def _error(self, name: str, value: str, expected: str) -> RigConfigError:
        return RigConfigError(f"rig URL {self.url!r}: option {name}={value!r} must be {expected}")

    def take_str(self, name: str, default: str | None = None, choices: tuple[str, ...] | None = None) -> str | None:
        value = self.options.pop(name, None)
        if value is None:
            return default
        if choices is not None and value not in choices:
            raise self._error(name, value, f"one of {list(choices)}")
        return value

    def take_float(self, name: str, default: float, lo: float | None = None, hi: float | None = None) -> float:
        raw = self.options.pop(name, None)
        if raw is None:
            return default
        try:
            value = float(raw)
        except ValueError:
            raise self._error(name, raw, "a number") from None
        if not math.isfinite(value) or (lo is not None and value < lo) or (hi is not None and value > hi):
            raise self._error(name, raw, f"in [{lo}, {hi}]")
        return value

    def take_int(self, name: str, default: int, lo: int | None = None, hi: int | None = None) -> int:
        raw = self.options.pop(name, None)
        if raw is None:
            return default
        try:
            value = whole_number(raw)
        except ValueError as e:  # the reason says what to write instead (seed=010: "write 10")
            raise RigConfigError(f"rig URL {self.url!r}: option {name}={raw!r}: {e}") from None
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise self._error(name, raw, f"an integer in [{lo}, {hi}]")
        return value

    def take_bool(self, name: str, default: bool) -> bool:
        raw = self.options.pop(name, None)
        if raw is None:
            return default
        if raw.lower() in _TRUE or raw == "":
            return True
        if raw.lower() in _FALSE:
            return False
        raise self._error(name, raw, "a boolean (1/0, true/false)")

    def finish(self) -> None:
        """Raise if options remain that no one consumed."""
        if self.options:
            raise RigConfigError(f"rig URL {self.url!r}: unknown option(s) {sorted(self.options)}")
