"""Rig URLs: ``scheme://target?option=value&...`` with typed, validated options.

Every option a backend reads is taken through a typed getter; whatever is left
afterwards is an unknown option and :meth:`RigUrl.finish` rejects it by name,
so a typo such as ``sim://?fsp=60`` fails loudly instead of being ignored.
A ``#`` would start a fragment, which URL parsing drops: it is refused (write ``%23``). So is a tab, CR or LF
anywhere, which URL parsing removes (write ``%09``, ``%0D``, ``%0A``; since session 73), and any other control
character (C0, DEL, C1), which reached log and status lines raw (write its %XX escape; since session 74), and
a line or paragraph separator or a bidirectional-text control, which break or reorder the line that shows the URL.

:func:`redact_url` is how a URL is shown (messages, logs, a recording's manifest): without the passwords
it may carry (a stream URL ``rtsp://user:pass@host/...`` inside an option, a ``token=``).
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from urllib.parse import parse_qsl, quote, unquote, urlsplit

from drivers.errors import RigConfigError
from ghnerf_runtime.path_check import NOT_UTF8, shown

_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"0", "false", "no", "off"}
#: What :func:`whole_number` takes, ASCII only (``[0-9]``, not ``\d``, which matches other scripts' digits);
#: "00" is 0 in every reading, so it is not refused as a leading zero.
_WHOLE = re.compile(r"0+|[1-9][0-9]*|0[xX][0-9a-fA-F]+|0[oO][0-7]+|0[bB][01]+")
_LEADING_ZERO = re.compile(r"0+[1-9][0-9]*")
#: What :func:`decimal_number` takes: strtod's plain decimals (no hex floats, no nan/inf words).
_DECIMAL = re.compile(r"[+-]?([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]+)?")
#: Query keys whose values are secrets (lower-cased): a password or token given as an option.
_SECRET_KEY = re.compile(r"(.*[_-])?(password|passwd|pass|pwd|token|secret|api[_-]?key|access[_-]?key|auth|credentials?)")
#: What a secret is shown as.
REDACTED = "***"


def unquote_keeping_bytes(text: str) -> str:
    """``text`` with its %XX escapes decoded as UTF-8, a byte that is not UTF-8 kept as Python keeps one in
    ``sys.argv`` (a surrogate, :func:`not_utf8_escapes` finds it): ``unquote``'s default turned it into U+FFFD, so
    ``replay:///take%FF`` opened ``/take\ufffd`` and the error named a file the user never wrote."""
    return unquote(text, errors="surrogateescape")


class UrlPartError(ValueError):
    """A part of a URL refused: ``field`` (the path after ://, the host, the device...), its ``value`` as written,
    and ``why``. Raised here, where the rule is, without a package's error type: each parser (rig URLs, sink URLs,
    the listener) converts it to its own error, naming its URL."""

    def __init__(self, field: str, value: str, why: str) -> None:
        super().__init__(f"{field} {why}")
        self.field, self.value, self.why = field, value, why


def decode_url_part(field: str, raw: str) -> str:
    """``raw``, the part ``field`` of a URL, percent-decoded as UTF-8 (:func:`unquote_keeping_bytes`): the one rule
    for every URL parser's paths, devices and hosts.

    :raises UrlPartError: naming ``field``, ``raw`` and its escapes that are no UTF-8 byte sequence (decoded to
        U+FFFD, they named another file, device or host than the one written).
    """
    decoded = unquote_keeping_bytes(raw)
    problem = not_utf8_escapes(raw, decoded)
    if problem is not None:
        raise UrlPartError(field, raw, problem)
    return decoded


def not_utf8_escapes(raw: str, decoded: str) -> str | None:
    """Why ``decoded`` (``raw`` through :func:`unquote_keeping_bytes`) cannot be used: the %XX escapes of ``raw``
    that are not UTF-8, written as escapes again (``holds %FF, which is not UTF-8 ...``); None when it has none.
    A byte that ``raw`` holds itself, unescaped, is left to the checks that met it before (the path check)."""
    bad = "".join(_escape_kept_byte(c) for c in decoded if _is_kept_byte(c))
    if not bad or any(_is_kept_byte(c) for c in raw):
        return None
    return f"holds {bad}, which {NOT_UTF8}"


def with_kept_bytes_escaped(decoded: str) -> str:
    """``decoded`` (from :func:`unquote_keeping_bytes`) as a message shows it: each byte that is not UTF-8 written
    back as its %XX escape, the rest as decoded."""
    return "".join(_escape_kept_byte(c) if _is_kept_byte(c) else c for c in decoded)


def _is_kept_byte(char: str) -> bool:
    # how errors="surrogateescape" keeps the bytes 0x80-0xFF that are not UTF-8: U+DC80-U+DCFF
    return "\udc80" <= char <= "\udcff"


def _escape_kept_byte(char: str) -> str:
    return f"%{ord(char) - 0xDC00:02X}"


def redact_url(text: str) -> str:
    """``text`` as it may be shown: the password of any ``user:password@`` (kept: the user and host) and the
    value of any secret query key (``password=``, ``token=``, ``api_key=``...) replaced by ``***``, also in
    URLs nested in option values (``opencv://?first=rtsp%3A%2F%2Fuser%3Apass%40cam``). Anything else is
    returned as written, so text without a secret comes back unchanged.
    """
    if not isinstance(text, str):
        return text
    # "://" as urlsplit reads it: it drops a tab, CR or LF first, so "rtsp:/<TAB>/user:pass@cam" holds a password
    scheme_sep = _SCHEME_SEP.search(text)
    if scheme_sep is None:
        return text
    head, sep, rest = text[:scheme_sep.start()], scheme_sep.group(), text[scheme_sep.end():]
    netloc = re.match(r"[^/?#]*", rest).group()  # as urlsplit takes it, without its ValueErrors (a broken host)
    rest = redact_location(netloc) + rest[len(netloc):]
    before, question, query = rest.partition("?")
    if not question:
        return head + sep + rest
    query, hash_, fragment = query.partition("#")
    pieces = []
    for piece in query.split("&"):
        key, eq, value = piece.partition("=")
        plain = unquote(value)
        if eq and is_secret_key(unquote(_without_dropped(key))):  # "pass<TAB>word=" is read as password=
            value = REDACTED
        elif _SCHEME_SEP.search(plain) and redact_url(plain) != plain:
            value = quote(redact_url(plain), safe="*")
        pieces.append(key + eq + value)
    return head + sep + before + question + "&".join(pieces) + hash_ + fragment


#: A URL's "://", with the tabs, CRs and LFs urlsplit drops (:data:`_DROPPED`) allowed inside it.
_SCHEME_SEP = re.compile(r":[\t\r\n]*/[\t\r\n]*/")


def _without_dropped(text: str) -> str:
    """``text`` without the tabs, CRs and LFs ``urlsplit`` drops: the key it reads."""
    return text.translate({ord(char): None for char in _DROPPED})


def shown_url(text: str) -> str:
    """``text`` as a one-line message shows it: :func:`redact_url`'s form, written as ``repr`` where it holds a
    character a terminal or log would hide, mangle or break the line at (a tab, CR, LF, NUL, a byte that is not
    UTF-8: :func:`ghnerf_runtime.path_check.shown`). The sinks' and ``ghnerf-listen``'s messages name URLs so."""
    return shown(redact_url(text))


def redact_location(netloc: str) -> str:
    """A URL's location (``user:password@host:port``) as it may be shown: the password replaced by ``***``,
    the user and host kept; a location without a password comes back unchanged. :func:`redact_url` shows a
    whole URL's location through it; a message that names only the location (a sink's refused host or
    user info) calls it directly."""
    userinfo, at, host = netloc.rpartition("@")
    if not (at and ":" in userinfo):
        return netloc
    return f"{userinfo.split(':', 1)[0]}:{REDACTED}@{host}"


def is_secret_key(key: str) -> bool:
    """Whether an option named ``key`` holds a secret (``password``, ``token``, ``api_key``...): its value is
    shown as ``***`` (:func:`redact_url`, and a sink's message naming the option)."""
    return isinstance(key, str) and _SECRET_KEY.fullmatch(key.lower()) is not None


def whole_number(raw: str) -> int:
    """A whole number as a URL writes it: ASCII decimal digits, or hex, octal or binary with its prefix (``0x10``,
    ``0o17``, ``0b101``), and nothing else: no sign (no whole-number option is negative), no spaces, no ``_``, no
    other script's digits, all of which Python's ``int`` takes (``queue=%205`` and ``queue=1_0`` were read as 5
    and 10). A leading zero (``08``, ``010``) is refused with that said, not
    guessed at: C reads 010 as octal 8, and a user who typed 08 meant something. Camera URLs (here) and sink URLs
    (``firmware_host.sinks.url.integer``) share this rule. Raises ValueError with the reason."""
    if _WHOLE.fullmatch(raw):
        return int(raw, 0)
    raise ValueError(_not_whole(raw))


def _not_whole(raw: str) -> str:
    """Why ``raw`` is not a whole number :func:`whole_number` takes, what to write instead where that is clear."""
    if raw != raw.strip() or any(ch.isspace() for ch in raw):
        return "decimal digits expected, without spaces (a space is not part of a number)"
    if "_" in raw:
        return "decimal digits expected, without '_' (a separator Python takes; C and the docs do not)"
    if not raw.isascii():
        odd = next(ch for ch in raw if not ch.isascii())
        return f"ASCII digits 0-9 expected, not {odd!r}"
    if raw[:1] in ("+", "-") and raw[1:2].isdigit():
        rest = raw[1:]
        plain = rest if _WHOLE.fullmatch(rest) else rest.lstrip("0") if _LEADING_ZERO.fullmatch(rest) else ""
        write = f" (write {plain})" if raw[0] == "+" and plain else ""
        return f"decimal digits expected, without a sign: no whole-number option is negative{write}"
    if _LEADING_ZERO.fullmatch(raw):
        return f"decimal digits expected, without a leading zero (write {raw.lstrip('0')}; hex as 0x..)"
    return "expected a whole number: decimal digits, or hex as 0x.."


def decimal_number(raw: str) -> float:
    """A number with a fraction as a URL writes it: ASCII digits with one optional ``.``, an optional sign and
    exponent (``-2.5``, ``.05``, ``1e-3``; ``str(float)`` writes a keyword's 1e-05 so), as C's ``strtod`` reads
    them, a leading zero as decimal (``fps=030`` is 30). Python's ``float`` also takes spaces around it, ``_``
    between digits and other scripts' digits (``fps=3_0`` ran at 30 without a word): those are refused, as are
    the words nan and inf (no option takes them). Raises ValueError with the reason."""
    if _DECIMAL.fullmatch(raw):
        return float(raw)
    # worded to follow "option fps='3_0' ", as take_float and the sinks' messages show it
    if raw != raw.strip() or any(ch.isspace() for ch in raw):
        raise ValueError("must be a number, without spaces (a space is not part of a number)")
    if "_" in raw:
        raise ValueError("must be a number, without '_' (a fraction is written with '.', e.g. 3.0)")
    if not raw.isascii():
        odd = next(ch for ch in raw if not ch.isascii())
        raise ValueError(f"must be a number in ASCII digits 0-9 (not {odd!r})")
    if raw.lstrip("+-").lower() in ("nan", "inf", "infinity"):
        raise ValueError("must be a finite number")
    raise ValueError("must be a number: digits, with one '.' and an exponent if need be (e.g. 2.5, 1e-3)")


def yes_no(raw: str) -> bool:
    """A yes/no option's word: 1/0, true/false, yes/no or on/off, in any case (``Yes`` is plain), nothing around
    it (``send_2d=%20yes`` was read as yes in sink URLs, refused in rig URLs: both refuse it now).
    Raises ValueError with the reason."""
    if raw.isascii() and raw.lower() in _TRUE:
        return True
    if raw.isascii() and raw.lower() in _FALSE:
        return False
    spaces = " (without spaces)" if raw != raw.strip() else ""
    raise ValueError(f"expected a boolean: 1/0, true/false, yes/no or on/off{spaces}")


def _refuse_not_utf8(url: str, where: str, raw: str, decoded: str) -> None:
    """:class:`RigConfigError` naming ``where`` in ``url`` when ``decoded`` holds escapes of bytes that are not UTF-8
    (OpenCV crashes on such a path, and a JSON manifest cannot hold it)."""
    problem = not_utf8_escapes(raw, decoded)
    if problem is not None:
        raise RigConfigError(f"rig URL {redact_url(url)!r}: {where} {problem}")


#: The characters ``urlsplit`` removes from anywhere in a URL without a word, and how a message names each.
_DROPPED = {"\t": "a tab", "\r": "a carriage return", "\n": "a line feed"}


def dropped_characters(url: str) -> str | None:
    """Why ``url`` is not read as written where it holds a control character (the first, named with its place),
    None where it holds none. The one rule for rig, sink and listen URLs. A tab, CR or LF: ``urlsplit`` drops them,
    so ``replay:///data/ta<TAB>ke`` played ``/data/take`` and ``fps=3<LF>0`` ran at 30 (a value pasted from a file).
    Any other C0 control, DEL or C1 control (U+0080-U+009F; since session 74): kept, it reached log and status lines,
    where an ESC rewrites a terminal. A line or paragraph separator (U+2028, U+2029) or a bidirectional-text control
    (:data:`_BIDI_CONTROLS`): kept too, the first broke the line that shows the URL (editors, log viewers), the
    second showed its characters in another order than the one opened (``replay:///data/<RLO>lmth.take`` showed as
    ``replay:///data/ekat.html``).
    Printable text that is not ASCII (a UTF-8 folder name) is not refused."""
    char = next((char for char in url if is_refused_character(char)), None)
    if char is None:
        return None
    # its place in the URL as messages show it: a password before it is *** there (none where it is in one)
    at = redact_url(url).find(char)
    where = f" at character {at + 1}" if at >= 0 else ""
    escape = _percent_escape(char)
    if char in _DROPPED:
        return f"holds {_DROPPED[char]}{where}, which URL parsing drops; remove it, or write it as {escape}"
    if char in _SEPARATORS:
        return (f"holds {_SEPARATORS[char]} (U+{ord(char):04X}){where}, which logs and editors break the line at; "
                f"remove it, or write it as {escape}")
    if char in _BIDI_CONTROLS:
        return (f"holds a bidirectional-text control (U+{ord(char):04X}){where}, which makes logs and terminals show "
                f"the characters after it in another order; remove it, or write it as {escape}")
    return (f"holds a control character (U+{ord(char):04X}){where}, which logs and terminals would act on or hide; "
            f"remove it, or write it as {escape}")


#: The line and paragraph separators: no C0/C1 control, yet a line break to editors and log viewers.
_SEPARATORS = {"\u2028": "a line separator", "\u2029": "a paragraph separator"}
#: Unicode's bidirectional-text controls (UAX #9): the marks ALM, LRM, RLM, the embeddings and overrides
#: LRE, RLE, PDF, LRO, RLO, and the isolates LRI, RLI, FSI, PDI. Each reorders how the text after it is shown.
_BIDI_CONTROLS = frozenset("\u061c\u200e\u200f\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069")


def is_refused_character(char: str) -> bool:
    """Whether :func:`dropped_characters` refuses ``char`` in a URL: a C0 control (tab, CR and LF among them), DEL or
    a C1 control, none of which is text (an ESC, or a C1 CSI, starts a terminal's command), a line or paragraph
    separator, or a bidirectional-text control."""
    return char < " " or "\x7f" <= char <= "\x9f" or char in _SEPARATORS or char in _BIDI_CONTROLS


def _percent_escape(char: str) -> str:
    """``char`` as a URL writes it: its UTF-8 bytes as %XX escapes (U+0085 is %C2%85)."""
    return "".join(f"%{byte:02X}" for byte in char.encode("utf-8"))


def _refuse_dropped_characters(url: str) -> None:
    """:class:`RigConfigError` naming the first control character in ``url`` (:func:`dropped_characters`)."""
    problem = dropped_characters(url)
    if problem is not None:
        raise RigConfigError(f"rig URL {redact_url(url)!r}: {problem}")


@dataclass
class RigUrl:
    """A parsed rig URL.

    Attributes:
        url: the text as given, for messages: passwords redacted (:func:`redact_url`).
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
        if isinstance(url, str):  # first: urlsplit reads "sim:/<TAB>/" as a URL, so name the tab, not the form
            _refuse_dropped_characters(url)
        if not isinstance(url, str) or "://" not in url:
            # redacted: urlsplit reads "rtsp:/<TAB>/user:pass@cam" as a URL with a password
            raise RigConfigError(f"rig URL must look like 'scheme://target?options', got {redact_url(url)!r}")
        try:
            parts = urlsplit(url)
        except ValueError as e:  # e.g. an unclosed '[' reads as a broken IPv6 host
            raise RigConfigError(f"rig URL {redact_url(url)!r} cannot be parsed: {e}") from None
        if "#" in url:  # urlsplit would drop the fragment: record into, or play, another directory
            raise RigConfigError(
                f"rig URL {redact_url(url)!r}: '#' starts a URL fragment ({'#' + parts.fragment!r}), which rig URLs do not "
                "use; write a '#' in a path or option value as %23"
            )
        try:
            target = decode_url_part("the path after ://", parts.netloc + parts.path)
        except UrlPartError as e:
            raise RigConfigError(f"rig URL {redact_url(url)!r}: {e}") from None
        options: dict[str, str] = {}
        # '+' is a plus here, as in the path (a form's '+' for a space turned out=/data/take+1 into '/data/take 1');
        # a space is %20
        for key, value in parse_qsl(parts.query.replace("+", "%2B"), keep_blank_values=True,
                                    strict_parsing=False, errors="surrogateescape"):
            _refuse_not_utf8(url, "an option name", parts.query, key)
            _refuse_not_utf8(url, f"option {key}=", parts.query, value)
            if key in options:
                raise RigConfigError(f"rig URL {redact_url(url)!r}: option {key!r} given twice")
            options[key] = value
        return cls(url=redact_url(url), scheme=parts.scheme.lower(), target=target, options=options)

    def _error(self, name: str, value: str, expected: str) -> RigConfigError:
        return RigConfigError(f"rig URL {self.url!r}: option {name}={value!r} must be {expected}")

    def take_str(self, name: str, default: str | None = None, choices: tuple[str, ...] | None = None) -> str | None:
        """The option's text, ``default`` when it is absent. An empty value (``rig=``) is refused: backends read
        it as absent, so depthai://?rig= ran on the device's own calibration and sim://?cache= on the default
        cache, without a word that the file or folder meant was never named."""
        value = self.options.pop(name, None)
        if value is None:
            return default
        if value == "":
            raise RigConfigError(f"rig URL {self.url!r}: option {name}= is empty: give a value, or leave the option out")
        if choices is not None and value not in choices:
            raise self._error(name, value, f"one of {list(choices)}")
        return value

    def take_float(self, name: str, default: float, lo: float | None = None, hi: float | None = None) -> float:
        raw = self.options.pop(name, None)
        if raw is None:
            return default
        try:
            value = decimal_number(raw)
        except ValueError as e:  # the reason names what is wrong (fps=3_0: a '_', not a fraction)
            raise RigConfigError(f"rig URL {self.url!r}: option {name}={raw!r} {e}") from None
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
        if raw == "":  # a bare key (?loop) means yes
            return True
        try:
            return yes_no(raw)
        except ValueError as e:
            raise RigConfigError(f"rig URL {self.url!r}: option {name}={raw!r}: {e}") from None

    def finish(self) -> None:
        """Raise if options remain that no one consumed."""
        if self.options:
            raise RigConfigError(f"rig URL {self.url!r}: unknown option(s) {sorted(self.options)}")
