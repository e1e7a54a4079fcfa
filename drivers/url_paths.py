"""Relative file paths inside a rig URL written in a config file, read from the file's folder.

A config file reads its plain paths (``session.model_dir``, ``health.status_file``) from its own folder
(``ghnerf_runtime.config_paths``); its rig URL must name files the same way, not from the daemon's
current directory (``/`` under systemd). :data:`FILE_PARTS` says which parts of each scheme's URL name a
file; :func:`rig_url_from_folder` makes the relative ones absolute and leaves every other byte as written.
A URL typed on a command line never comes here: there a relative path stays relative to the current
directory, as the backends read it.
"""
from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from urllib.parse import quote, unquote

from drivers.errors import RigConfigError
from drivers.url import RigUrl, dropped_characters, shown_url, unquote_keeping_bytes
from drivers.wrappers import WRAPPER_FILE_OPTIONS, innermost_url, wrapper_prefixes
from ghnerf_runtime.path_check import path_problem, shown

__all__ = ["FileParts", "FILE_PARTS", "check_url_paths", "rig_url_from_folder", "url_files", "url_path_problem"]


def _any_path(value: str) -> bool:
    return True


def _not_off(value: str) -> bool:
    return value != "off"  # sim://?cache=off turns the cache off; any other value is its folder


def _video_file(value: str) -> bool:
    # opencv:// also takes device indices, /dev nodes, stream URLs and GStreamer pipelines: only a file is a path.
    # Imported here, as the registry imports a backend: only for a URL of that scheme.
    try:
        from drivers.backends.opencv import is_video_file
    except ImportError:  # no OpenCV: the URL is left as written, and opening it reports the backend missing
        return False
    return is_video_file(value)


@dataclass(frozen=True)
class FileParts:
    """The parts of one scheme's URL that name files.

    Attributes:
        target: what follows ``scheme://`` up to ``?`` is a path (``replay://takes/walk``).
        options: option name -> whether a value of it names a file (``cache=off`` does not).
    """

    target: bool = False
    options: Mapping[str, Callable[[str], bool]] = field(default_factory=dict)


#: Every scheme of ``drivers.registry.BACKENDS`` (a test keeps the two in step). Wrapped URLs (:mod:`drivers.wrappers`)
#: are not here: the daemon, the one program whose config file holds a rig URL, refuses the recorder's.
FILE_PARTS: Mapping[str, FileParts] = {
    "replay": FileParts(target=True),
    "sim": FileParts(options={"bvh": _any_path, "cache": _not_off}),
    "opencv": FileParts(options={"rig": _any_path, "first": _video_file, "second": _video_file}),
    "depthai": FileParts(options={"rig": _any_path}),
}


def url_files(url: str) -> list[tuple[str, str]]:
    """The files (and folders) ``url`` names (:data:`FILE_PARTS`), as its backend reads them: ``(part, path)``,
    ``part`` being ``"target"`` (``replay://takes/walk``) or the option's name (``rig``, ``bvh``, ``cache``). None
    for a URL that does not parse (the rig's own check reports it) or of a scheme naming no file."""
    try:
        parsed = RigUrl.parse(url)
    except RigConfigError:
        return []
    parts = FILE_PARTS.get(parsed.scheme)
    if parts is None:
        return []
    files = [("target", parsed.target)] if parts.target and parsed.target else []
    return files + [(name, value) for name, value in parsed.options.items()
                    if name in parts.options and value and parts.options[name](value)]


def _files_of_any(url: str) -> list[tuple[str, str]]:
    """:func:`url_files`, and for a wrapped URL (``record+...``) also the files its wrappers' options name
    (:data:`drivers.wrappers.WRAPPER_FILE_OPTIONS`: the recorder's ``out=`` folder), each wrapper's, however many
    wrap it."""
    prefixes = wrapper_prefixes(url)
    inner = innermost_url(url)
    if not prefixes:
        return url_files(url)
    try:
        options = RigUrl.parse(inner).options
    except RigConfigError:
        return []
    names = dict.fromkeys(name for prefix in prefixes for name in WRAPPER_FILE_OPTIONS.get(prefix, ()))
    return [(name, options[name]) for name in names if options.get(name)] + url_files(inner)


def check_url_paths(url: str) -> None:
    """:class:`RigConfigError` naming the part of ``url`` (the path after ``://``, or an option such as ``rig=``,
    ``first=``, ``out=``) whose file path no file can have (:func:`ghnerf_runtime.path_check.path_problem`): said
    before the backend opens it, where a NUL byte raised ``ValueError``, a name past 255 bytes ``ENAMETOOLONG``
    (tracebacks) and a path that is not UTF-8 crashed OpenCV."""
    problem = url_path_problem(url)
    if problem is not None:
        # redacted as every other rig URL error is: a stream's password beside the file would reach the log
        raise RigConfigError(f"rig URL {shown_url(url)}: {problem}")


def url_path_problem(url: str) -> str | None:
    """Why a file path in ``url`` cannot be one (:func:`ghnerf_runtime.path_check.path_problem`), naming its part
    and value (``option rig= 'a\\x00b': holds a NUL byte``): the first such, None where there is none. One
    wording for a rig URL on a command line (:func:`check_url_paths`) and in the daemon's config file."""
    for part, value in _files_of_any(url):
        problem = path_problem(value)
        if problem is not None:
            where = "the path after ://" if part == "target" else f"option {part}="
            return f"{where} {shown(value)}: {problem}"
    return None


def _absolute(value: str, folder: Path) -> str | None:
    """``value`` read from ``folder`` as :func:`ghnerf_runtime.config_paths.paths_from_file` reads a plain path;
    None when it is empty or already absolute (kept as written)."""
    if not value or os.path.isabs(value):
        return None
    return str(folder / value)


def _requoted(path: str) -> str:
    """``path`` percent-encoded for a rig URL, a byte that is not UTF-8 written back as the escape it came from
    (``RigUrl.parse`` refuses it, naming it): it became ``%EF%BF%BD``, U+FFFD, another file's name."""
    return quote(path, safe="/", errors="surrogateescape")


def rig_url_from_folder(url: str, folder: str | os.PathLike) -> str:
    """``url`` with each relative file path in it (:data:`FILE_PARTS`) made absolute against ``folder``.

    The new path is percent-encoded (a space, ``#``, ``%``, ``&`` or ``+`` in the folder or the path reads
    back as itself through :class:`drivers.url.RigUrl`); the rest of the URL, the other options and their
    encoding included, is kept byte for byte. A URL of an unknown scheme, or one its parser refuses
    (no ``://``, a ``#``, a control character), is returned as it is, for the backend to report.

    >>> rig_url_from_folder("opencv://?first=0&second=/dev/video2&rig=rigs/a%20b.json", "/etc/ghnerf")
    'opencv://?first=0&second=/dev/video2&rig=/etc/ghnerf/rigs/a%20b.json'
    >>> rig_url_from_folder("replay://takes/walk?loop=1", "/etc/ghnerf")
    'replay:///etc/ghnerf/takes/walk?loop=1'
    """
    if not isinstance(url, str) or "://" not in url or "#" in url or dropped_characters(url) is not None:
        return url  # a control character too: requoted, a raw ESC or tab in a relative path passed as %1B or %09
    scheme, _, rest = url.partition("://")
    parts = FILE_PARTS.get(scheme.lower())
    if parts is None:
        return url
    folder = Path(os.path.abspath(folder))
    target, question, query = rest.partition("?")  # urlsplit's netloc + path: everything before the '?'
    if parts.target:
        new = _absolute(unquote_keeping_bytes(target), folder)
        if new is not None:  # absolute, so scheme:///path: an empty host, as replay:///data/take1
            target = _requoted(new)
    if query and parts.options:
        pieces = []
        for piece in query.split("&"):  # as parse_qsl splits it; '+' is a plus there (drivers.url)
            key, equals, value = piece.partition("=")
            names_file = parts.options.get(unquote(key))
            plain = unquote_keeping_bytes(value)
            new = _absolute(plain, folder) if equals and names_file is not None and names_file(plain) else None
            pieces.append(piece if new is None else f"{key}={_requoted(new)}")
        query = "&".join(pieces)
    return f"{scheme}://{target}{question}{query}"
