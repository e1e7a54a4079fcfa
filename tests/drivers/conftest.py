"""Shared fixtures of the driver tests."""
from __future__ import annotations

import threading
import time

import pytest

# Threads our backends start (render pool, recorder); none may outlive a test.
_OUR_THREADS = ("sim-render", "rig-recorder", "opencv ")


@pytest.fixture(scope="session")
def sim_cache(tmp_path_factory):
    """One pre-render cache for the whole run, so each sim loop is rendered once."""
    return tmp_path_factory.mktemp("sim-cache")


@pytest.fixture(autouse=True)
def no_leaked_backend_threads():
    """python-can's leak check, for threads: a closed source leaves nothing running."""
    yield
    # generous: a thread a close (or a test's teardown) let go needs the CPU to end, seconds on a loaded host;
    # a leaked one never ends
    deadline = time.monotonic() + 30.0
    while True:
        leaked = [t.name for t in threading.enumerate() if t.name.startswith(_OUR_THREADS)]
        if not leaked or time.monotonic() > deadline:
            break
        time.sleep(0.01)
    assert not leaked, f"backend threads still running after the test: {leaked}"
