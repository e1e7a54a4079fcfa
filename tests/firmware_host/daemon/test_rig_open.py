"""firmware_host.daemon.rig_open: the rig's open on its own thread, abandoned at a stop and closed once it returns."""
from __future__ import annotations

import threading
from typing import Optional

import pytest

import drivers
from firmware_host.daemon.rig_open import open_unless_stopped
from tests.firmware_host.joint_stream_helpers import wait_until


class _SlowSource:
    """Stands in for a RigSource: ``open`` waits for ``release``, then raises ``error`` or opens."""

    def __init__(self, error: Optional[Exception] = None) -> None:
        self.release, self.entered = threading.Event(), threading.Event()
        self.error, self.opened, self.closed = error, False, False

    def open(self) -> "_SlowSource":
        self.entered.set()
        self.release.wait(60)
        if self.error is not None:
            raise self.error
        self.opened = True
        return self

    def close(self) -> None:
        self.closed = True


def test_an_open_that_returns_first_is_the_callers():
    source, stop = _SlowSource(), threading.Event()
    source.release.set()
    assert open_unless_stopped(source, stop) is True
    assert source.opened and not source.closed


def test_an_open_that_fails_first_raises_its_error():
    source, stop = _SlowSource(drivers.RigInitializationError("no device")), threading.Event()
    source.release.set()
    with pytest.raises(drivers.RigInitializationError, match="no device"):
        open_unless_stopped(source, stop)
    assert not source.closed  # the caller closes it, as after any failed open


@pytest.mark.parametrize("error", [None, drivers.RigInitializationError("device gone")])
def test_a_stop_abandons_the_open_and_its_thread_closes_the_source(error):
    source, stop = _SlowSource(error), threading.Event()
    stopper = threading.Thread(target=lambda: (source.entered.wait(30), stop.set()), daemon=True)
    stopper.start()
    try:
        assert open_unless_stopped(source, stop) is False  # returned while the open still blocks
        assert not source.release.is_set() and not source.closed
    finally:
        source.release.set()
    wait_until(lambda: source.closed, timeout=30, what="the abandoned open's source closed")
