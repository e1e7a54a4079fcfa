"""Backend registry: URL scheme -> (module, class), imported only when chosen.

A wrapper's prefix wraps any other URL's source in its own: ``record+<url>`` in the recorder (pyserial's
``spy://`` idea). :data:`WRAPPERS` lists them; :func:`innermost_url` is the URL of the backend that delivers the
frames, for a caller that asks what a URL plays (``ghcal capture``: two video files or live cameras?).
"""
from __future__ import annotations

import importlib

from drivers.base import RigSource
from drivers.errors import BackendNotAvailableError
from drivers.url import RigUrl
from drivers.url_paths import check_url_paths

#: scheme -> (module, class name). Extend by adding an entry; nothing is imported until chosen.
BACKENDS: dict[str, tuple[str, str]] = {
    "sim": ("drivers.backends.sim", "SimRigSource"),
    "replay": ("drivers.backends.replay", "ReplayRigSource"),
    "depthai": ("drivers.backends.depthai", "DepthaiRigSource"),
    "opencv": ("drivers.backends.opencv", "OpenCVRigSource"),
}

RECORD_PREFIX = "record+"

#: URL prefix -> (module, class name) of the sources that wrap another URL's source; each class has
#: ``wrap(inner_url, factory, **kwargs)``. Nothing is imported until chosen.
WRAPPERS: dict[str, tuple[str, str]] = {
    RECORD_PREFIX: ("drivers.backends.record", "RecordingRigSource"),
}


def _import_class(what: str, module_name: str, class_name: str) -> type:
    try:
        module = importlib.import_module(module_name)
    except ImportError as e:
        raise BackendNotAvailableError(f"rig backend {what!r} cannot be loaded: {e}") from e
    return getattr(module, class_name)


def wrapper_prefix(url: str) -> str | None:
    """The prefix of :data:`WRAPPERS` that ``url`` starts with; None for a URL no wrapper wraps."""
    return next((prefix for prefix in WRAPPERS if url.startswith(prefix)), None)


def innermost_url(url: str) -> str:
    """``url`` without the prefixes of the wrappers around it (``record+opencv://?first=a.mp4&out=take`` ->
    ``opencv://?first=a.mp4&out=take``): the URL of the backend that delivers the frames, the wrappers' own
    options still in its query. A URL no wrapper wraps comes back as given."""
    while (prefix := wrapper_prefix(url)) is not None:
        url = url[len(prefix):]
    return url


def backend_class(scheme: str, backends: dict[str, tuple[str, str]] | None = None) -> type[RigSource]:
    """Import and return the class for ``scheme``."""
    table = BACKENDS if backends is None else backends
    if scheme not in table:
        wrapped = ", ".join(f"{prefix}<url>" for prefix in WRAPPERS)
        raise BackendNotAvailableError(f"unknown rig backend {scheme!r}; known: {sorted(table)} (and {wrapped})")
    return _import_class(scheme, *table[scheme])


def open_rig(url: str, **kwargs) -> RigSource:
    """Open a rig source by URL and return it (already opened; use it as a context manager).

    Examples: ``sim://``, ``sim://?fps=30&seed=3&motion=wave``, ``replay:///data/take1``,
    ``record+sim://?out=/tmp/take1``, ``depthai://`` (first device) or ``depthai://<device-id>``,
    ``opencv://?first=/dev/video0&second=/dev/video2&rig=rig.json`` (two webcams).
    Keyword arguments (``clock=``, ``pairing=``, ``rig=`` ...) go to the backend.
    """
    return create_rig_source(url, **kwargs).open()


def create_rig_source(url: str, **kwargs) -> RigSource:
    """Like :func:`open_rig` but returns the source unopened."""
    check_url_paths(url)  # a NUL byte or a name too long: one line, not a traceback from the backend
    prefix = wrapper_prefix(url)
    if prefix is not None:
        wrapper = _import_class(prefix, *WRAPPERS[prefix])
        return wrapper.wrap(RigUrl.parse(url[len(prefix):]), create_rig_source, **kwargs)
    parsed = RigUrl.parse(url)
    return backend_class(parsed.scheme).from_url(parsed, **kwargs)
