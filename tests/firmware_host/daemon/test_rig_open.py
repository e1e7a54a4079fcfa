"""firmware_host.daemon.rig_open: the rig's open on its own thread, abandoned at a stop, which closes the source at
once (cancelling the open) rather than once the open returns."""
from __future__ import annotations

import threading
from typing import Optional

import pytest

import drivers
from drivers.base import RigSource
from drivers.sim import RigPlacement
from firmware_host.daemon.rig_open import open_unless_stopped
from tests.firmware_host.joint_stream_helpers import wait_until

WAIT_S = 30.0  # generous: only a hang reaches it


class _SlowSource:
    """Stands in for a RigSource: ``open`` waits for ``release``, then raises ``error`` or opens."""

    def __init__(self, error: Optional[Exception] = None) -> None:
        self.release, self.entered = threading.Event(), threading.Event()
        self.returned = threading.Event()
        self.error, self.opened, self.closes = error, False, 0

    def open(self) -> "_SlowSource":
        self.entered.set()
        self.release.wait(60)
        self.returned.set()
        if self.error is not None:
            raise self.error
        self.opened = True
        return self

    def close(self) -> None:
        self.closes += 1


def test_an_open_that_returns_first_is_the_callers():
    source, stop = _SlowSource(), threading.Event()
    source.release.set()
    assert open_unless_stopped(source, stop) is True
    assert source.opened and source.closes == 0


def test_an_open_that_fails_first_raises_its_error():
    source, stop = _SlowSource(drivers.RigInitializationError("no device")), threading.Event()
    source.release.set()
    with pytest.raises(drivers.RigInitializationError, match="no device"):
        open_unless_stopped(source, stop)
    assert source.closes == 0  # the caller closes it, as after any failed open


@pytest.mark.parametrize("error", [None, drivers.RigInitializationError("device gone")])
def test_a_stop_abandons_the_open_and_closes_the_source_before_the_open_returns(error):
    """Before, the source was closed by the open's thread once the open returned (an OAK's: up to
    health.open_allowance_s later), its cameras held meanwhile; the stop now closes it at once, which cancels the
    open (drivers.base), and the open's thread closes nothing more."""
    source, stop = _SlowSource(error), threading.Event()
    stopper = threading.Thread(target=lambda: (source.entered.wait(WAIT_S), stop.set()), daemon=True)
    stopper.start()
    try:
        assert open_unless_stopped(source, stop) is False  # returned while the open still blocks
        assert not source.release.is_set() and source.closes == 1
    finally:
        source.release.set()
    for thread in threading.enumerate():
        if thread.name == "rig-open":
            thread.join(WAIT_S)  # the abandoned open's thread, done with its source
    assert source.returned.is_set() and source.closes == 1


class _CloseFails(_SlowSource):
    def close(self) -> None:
        super().close()
        raise drivers.RigOperationError("device half booted")


def test_a_stop_whose_close_fails_still_returns_stopped(caplog: pytest.LogCaptureFixture):
    """The stop's close of a source still opening may fail (a device half booted): the stop goes on, the daemon
    exits as after any stop, and the failure is a WARNING, not an exception out of the wait."""
    source, stop = _CloseFails(), threading.Event()
    stopper = threading.Thread(target=lambda: (source.entered.wait(WAIT_S), stop.set()), daemon=True)
    stopper.start()
    try:
        with caplog.at_level("WARNING", logger="ghnerf.daemon"):
            assert open_unless_stopped(source, stop) is False
    finally:
        source.release.set()
    assert source.closes == 1
    assert any("device half booted" in r.getMessage() for r in caplog.records)


class _CancelledByItsClose(RigSource):
    """A source whose ``_open`` holds its "device" until :meth:`_cancel_open` (a close during the open) lets it go
    on: an OAK's boot, which depthai:// cuts short at its next step."""

    scheme = "cancelled"

    def __init__(self) -> None:
        super().__init__(RigPlacement(width=16, height=16).build("cancelled"))
        self.in_open, self.cancelled, self.released = threading.Event(), threading.Event(), threading.Event()

    @classmethod
    def from_url(cls, url, **kwargs):  # pragma: no cover - built directly
        raise NotImplementedError

    def _open(self) -> None:
        self.in_open.set()
        assert self.cancelled.wait(WAIT_S)

    def _cancel_open(self) -> None:
        self.cancelled.set()

    def _read_frame(self, timeout_s):  # pragma: no cover - never read
        return None

    def _close(self) -> None:
        self.released.set()


def test_a_stop_during_a_rig_sources_open_cancels_it_and_the_open_releases_its_device():
    """With a real RigSource: the stop's close cancels the open at once, and the open, returning, releases what it
    made (its _close); nothing waits for an open that would otherwise block until its allowance ran out."""
    source, stop = _CancelledByItsClose(), threading.Event()
    stopper = threading.Thread(target=lambda: (source.in_open.wait(WAIT_S), stop.set()), daemon=True)
    stopper.start()
    assert open_unless_stopped(source, stop) is False
    assert source.cancelled.is_set()  # by the stop's close, not by a timeout
    assert source.released.wait(WAIT_S), "the cancelled open did not release its device"
    assert not source.is_open
