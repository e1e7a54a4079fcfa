"""Vendor usage telemetry off unless the device's owner asks for it: depthai's and onnxruntime's.

Both libraries ship "opt-out" product telemetry. depthai 3.x (3.12 checked) tries to upload to Luxonis from
``import depthai`` on and keeps an id file under ``~/.cache/depthai/telemetry``; onnxruntime's Linux wheels (1.31
checked) write ``~/.cache/Microsoft/DeveloperTools/.onnxruntime/deviceid`` and an event cache on import. This
device runs on robots, often offline, and nothing here should report to a vendor without its owner choosing so.

Each library reads its switch once, when it is first imported, so the switch is set before that import and a
later change (or ``onnxruntime.disable_telemetry_events()``, which leaves the id file written) is too late.
``setdefault``: a value the user set, ``DEPTHAI_TELEMETRY=1`` say, is kept. docs/depthai.md, "Telemetry".

Standard library only.
"""
from __future__ import annotations

import os
from collections.abc import MutableMapping

__all__ = ["DEPTHAI_SWITCH", "DEPTHAI_OFF", "ONNXRUNTIME_SWITCH", "ONNXRUNTIME_OFF",
           "default_depthai_telemetry_off", "default_onnxruntime_telemetry_off"]

#: depthai's switch and the value that turns its telemetry off ("Telemetry disabled via DEPTHAI_TELEMETRY").
DEPTHAI_SWITCH = "DEPTHAI_TELEMETRY"
DEPTHAI_OFF = "0"
#: onnxruntime's switch on Linux and macOS (its 1DS provider) and the value that turns it off.
ONNXRUNTIME_SWITCH = "ORT_DISABLE_TELEMETRY"
ONNXRUNTIME_OFF = "1"


def default_depthai_telemetry_off(environ: MutableMapping[str, str] | None = None) -> None:
    """``DEPTHAI_TELEMETRY=0`` in ``environ`` (the process's by default) unless it is set already."""
    (os.environ if environ is None else environ).setdefault(DEPTHAI_SWITCH, DEPTHAI_OFF)


def default_onnxruntime_telemetry_off(environ: MutableMapping[str, str] | None = None) -> None:
    """``ORT_DISABLE_TELEMETRY=1`` in ``environ`` (the process's by default) unless it is set already."""
    (os.environ if environ is None else environ).setdefault(ONNXRUNTIME_SWITCH, ONNXRUNTIME_OFF)
