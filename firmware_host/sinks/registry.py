"""``open_sink(url)``: choose a backend by URL scheme, importing it only when chosen; ``check_sink_url(url)``:
refuse a bad URL as ``open_sink`` would, opening nothing.

Like python-can's interface table: a plain mapping of scheme to (module, class),
so ``import firmware_host.sinks`` loads neither pyserial nor pyusb.
"""
from __future__ import annotations

import importlib
from collections.abc import Mapping
from types import MappingProxyType
from typing import Any, Optional

from firmware_host.errors import SinkConfigError
from firmware_host.sinks.base import Sink
from firmware_host.sinks.url import parse_url

BACKENDS: Mapping[str, tuple[str, str]] = MappingProxyType(
    {
        "serial": ("firmware_host.sinks.serial_sink", "SerialSink"),
        "usb": ("firmware_host.sinks.usb_sink", "UsbSink"),
        "udp": ("firmware_host.sinks.udp_sink", "UdpSink"),
        "vmc": ("firmware_host.sinks.vmc_sink", "VmcSink"),
        "file": ("firmware_host.sinks.file_sink", "FileSink"),
        "memory": ("firmware_host.sinks.memory_sink", "MemorySink"),
    }
)

#: Camera names for :func:`check_sink_url` before the rig, and so its cameras' names, is known (the daemon and the
#: demo announce the rig's own, a keyword that wins over a ``cameras=`` in the URL).
STAND_IN_CAMERAS = ("first", "second")


def sink_class(url: str, backends: Optional[Mapping[str, tuple[str, str]]] = None) -> type[Sink]:
    """The backend class for ``url``'s scheme (imports its module)."""
    table = BACKENDS if backends is None else backends
    scheme = parse_url(url).scheme
    if scheme not in table:
        raise SinkConfigError(url, "scheme", scheme, f"known schemes: {', '.join(sorted(table))}")
    module_name, class_name = table[scheme]
    cls = getattr(importlib.import_module(module_name), class_name)
    assert issubclass(cls, Sink)
    return cls


def check_sink_url(url: str, *, backends: Optional[Mapping[str, tuple[str, str]]] = None, **kw: Any) -> None:
    """Refuse what :func:`open_sink` would refuse for ``url`` and ``kw``, opening nothing: the sink is built, not
    started (no device, socket or file is touched; a serial port busy now may be free by the run). The daemon's
    config check and the demo's ``--sink`` check, before a rig opens or a model loads.

    :raises SinkConfigError: bad scheme, parameter or value (named in the message, the URL without passwords).
    """
    sink_class(url, backends).from_url(url, **kw)  # type: ignore[attr-defined]


def open_sink(url: str, *, backends: Optional[Mapping[str, tuple[str, str]]] = None, **kw: Any) -> Sink:
    """Create and start the sink for ``url``.

    Keyword arguments override query parameters of the same name; other
    keywords are backend objects (``backend=`` for usb) or ``SinkOptions``
    fields (``backoff=``, ``clock_us=``, ``rig_id=``...). A device that is not
    there yet is not an error: the sink keeps trying in its worker.

    :raises SinkConfigError: bad scheme, parameter or value (named in the message).

    >>> sink = open_sink("memory://?queue=8")
    >>> sink.close().dropped
    0
    """
    cls = sink_class(url, backends)
    return cls.from_url(url, **kw).start()  # type: ignore[attr-defined,no-any-return]
