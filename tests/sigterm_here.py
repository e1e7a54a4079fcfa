"""A real SIGTERM sent to the test's own process from inside a tool's work, as ``timeout`` or ``kill`` sends one:
for the tests that check a command line stops on it as on Ctrl-C (``ghnerf_runtime.cli.sigterm``)."""
from __future__ import annotations

import os
import signal
import time

import pytest

from ghnerf_runtime.cli.sigterm import sigterm_raises


def sigterm_here(work: str) -> None:
    """Send this process a SIGTERM and wait for its handler to raise ``Terminated`` (at the next bytecode). ``work``
    names what runs, for the failure where the tool left SIGTERM's default action in place (a kill ends it
    silently; here it would end pytest)."""
    if not sigterm_raises():
        pytest.fail(f"{work} under SIGTERM's default action: a kill ends it silently")
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(5)  # (the handler raises at the next bytecode)
    pytest.fail("SIGTERM was not delivered")
