"""The prefixes of rig URLs that wrap another URL's source in their own: ``record+<url>`` records while passing the
frames through (pyserial's ``spy://`` idea).

One table for every reader of a URL: :mod:`drivers.registry` builds the wrapper's source from it,
:mod:`drivers.url_paths` checks the files a wrapper's options name, and a program that asks what a URL plays (the
demo, the daemon's config, ``ghcal capture``) takes the prefixes off with :func:`innermost_url` instead of typing
``record+`` (which missed a second wrapper). This module imports nothing of the drivers, so the registry and
``url_paths`` (which the registry imports) can both import it.
"""
from __future__ import annotations

from collections.abc import Mapping

__all__ = ["RECORD_PREFIX", "WRAPPERS", "WRAPPER_FILE_OPTIONS", "innermost_url", "wrapper_prefix",
           "wrapper_prefixes"]

#: The recorder's prefix (``record+sim://?out=/data/take1``).
RECORD_PREFIX = "record+"

#: URL prefix -> (module, class name) of the sources that wrap another URL's source; each class has
#: ``wrap(inner_url, factory, **kwargs)``. Nothing is imported until chosen.
WRAPPERS: dict[str, tuple[str, str]] = {
    RECORD_PREFIX: ("drivers.backends.record", "RecordingRigSource"),
}

#: URL prefix -> the options a wrapper reads from the wrapped URL's query that name a file or folder (the
#: recorder's take folder), checked as a backend's are (:func:`drivers.url_paths.check_url_paths`).
WRAPPER_FILE_OPTIONS: Mapping[str, tuple[str, ...]] = {
    RECORD_PREFIX: ("out",),
}


def wrapper_prefix(url: str) -> str | None:
    """The prefix of :data:`WRAPPERS` that ``url`` starts with; None for a URL no wrapper wraps."""
    return next((prefix for prefix in WRAPPERS if url.startswith(prefix)), None)


def wrapper_prefixes(url: str) -> list[str]:
    """The prefixes of the wrappers around ``url``, outermost first (``spy+record+sim://`` -> ``['spy+',
    'record+']``); empty for a URL no wrapper wraps."""
    prefixes = []
    while (prefix := wrapper_prefix(url)) is not None:
        prefixes.append(prefix)
        url = url[len(prefix):]
    return prefixes


def innermost_url(url: str) -> str:
    """``url`` without the prefixes of the wrappers around it (``record+opencv://?first=a.mp4&out=take`` ->
    ``opencv://?first=a.mp4&out=take``): the URL of the backend that delivers the frames, the wrappers' own
    options still in its query. A URL no wrapper wraps comes back as given."""
    return url[sum(len(prefix) for prefix in wrapper_prefixes(url)):]
