"""Backend registry: URL scheme -> (module, class), imported only when chosen.

A wrapper's prefix wraps any other URL's source in its own: ``record+<url>`` in the recorder. The prefixes are
:mod:`drivers.wrappers`' table, which builds them here; a caller that asks what a URL plays (``ghcal capture``'s
two video files or live cameras?) imports :func:`drivers.wrappers.innermost_url` from there, the one import path.
"""
from __future__ import annotations

import importlib

from drivers.base import RigSource
from drivers.errors import BackendNotAvailableError, RigConfigError
from drivers.url import RigUrl
from drivers.url_paths import check_url_paths
from drivers.wrappers import WRAPPERS, wrapper_prefix

__all__ = ["BACKENDS", "backend_class", "create_rig_source", "open_rig"]

#: scheme -> (module, class name). Extend by adding an entry; nothing is imported until chosen.
BACKENDS: dict[str, tuple[str, str]] = {
    "sim": ("drivers.backends.sim", "SimRigSource"),
    "replay": ("drivers.backends.replay", "ReplayRigSource"),
    "depthai": ("drivers.backends.depthai", "DepthaiRigSource"),
    "opencv": ("drivers.backends.opencv", "OpenCVRigSource"),
}


def _import_class(what: str, module_name: str, class_name: str) -> type:
    try:
        module = importlib.import_module(module_name)
    except ImportError as e:
        raise BackendNotAvailableError(f"rig backend {what!r} cannot be loaded: {e}") from e
    return getattr(module, class_name)


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
    if not isinstance(url, str):  # the checks below read it as text: an AttributeError from str.startswith
        raise RigConfigError(f"rig URL must be text, 'scheme://target?options', got {url!r}")
    check_url_paths(url)  # a NUL byte or a name too long: one line, not a traceback from the backend
    prefix = wrapper_prefix(url)
    if prefix is not None:
        wrapper = _import_class(prefix, *WRAPPERS[prefix])
        return wrapper.wrap(RigUrl.parse(url[len(prefix):]), create_rig_source, **kwargs)
    parsed = RigUrl.parse(url)
    return backend_class(parsed.scheme).from_url(parsed, **kwargs)
