"""A close() from another thread that lands while open() runs, after the backend's _open has made what it holds:
the close saw a source not yet open and skipped _close, and open() returned a closed source still holding it (camera
threads, a device, a loop). Now open() releases it (_close, once) and raises. The record+ wrapper passes such a
close on to its inner source, whose open it cancels the same way."""
from __future__ import annotations

import threading

import pytest

from drivers import OpenInProgressError, RigInitializationError, RigOperationError
from drivers.backends.record import RecordingRigSource, RecordOptions
from drivers.base import RigSource
from drivers.sim import RigPlacement

from tests.drivers.contract import opened_in_a_thread

WAIT_S = 30.0  # generous: only a hang reaches it


class _HeldOpen(RigSource):
    """``_open`` makes its "device", then waits for ``go_on`` before returning: a close lands in between."""

    scheme = "held"

    def __init__(self) -> None:
        super().__init__(RigPlacement(width=16, height=16).build("held"))
        self.in_open = threading.Event()
        self.go_on = threading.Event()
        self.device_made = False
        self.closes = 0

    @classmethod
    def from_url(cls, url, **kwargs):  # pragma: no cover - built directly
        raise NotImplementedError

    def _open(self) -> None:
        self.device_made = True
        self.in_open.set()
        assert self.go_on.wait(WAIT_S)

    def _read_frame(self, timeout_s):  # pragma: no cover - never read
        return None

    def _close(self) -> None:
        self.closes += 1


class _ReleasedByItsClose(_HeldOpen):
    """Its ``_open`` also goes on once its own close() returned (as sim's pre-render stops at a close): a close a
    wrapper passes on reaches it."""

    def close(self) -> None:
        super().close()
        self.go_on.set()


def test_a_close_landing_as_open_finishes_releases_what_open_made_and_open_raises():
    source = _HeldOpen()
    thread, outcome = opened_in_a_thread(source)
    assert source.in_open.wait(WAIT_S)
    source.close()  # returns at once: the source is not open yet
    source.go_on.set()  # _open returns after the close
    thread.join(WAIT_S)
    assert not thread.is_alive()
    assert source.device_made and source.closes == 1  # released by open(), once
    assert len(outcome) == 1 and isinstance(outcome[0], RigInitializationError), outcome
    assert str(outcome[0]) == "_HeldOpen closed while it opened (a close() from another thread): the open was cancelled"
    assert not source.is_open
    with pytest.raises(RigOperationError, match="_HeldOpen was closed; open a new source"):
        source.open()
    source.close()  # nothing more to release
    assert source.closes == 1


def test_a_close_after_open_finished_releases_once():
    source = _HeldOpen()
    source.go_on.set()
    assert source.open() is source and source.is_open
    source.close()
    source.close()
    assert source.closes == 1 and not source.is_open


def test_a_record_wrapper_passes_a_close_during_open_to_its_inner_source(tmp_path):
    inner = _ReleasedByItsClose()
    out = tmp_path / "take"
    source = RecordingRigSource(inner, RecordOptions(out=out))
    thread, outcome = opened_in_a_thread(source)
    assert inner.in_open.wait(WAIT_S)
    closer = threading.Thread(target=source.close, name="test close")
    closer.start()
    closer.join(WAIT_S)
    inner.go_on.set()  # (already, where the close reached the inner source)
    thread.join(WAIT_S)
    assert not thread.is_alive() and not closer.is_alive()
    assert inner.closes == 1  # what the inner open made is released
    assert len(outcome) == 1 and isinstance(outcome[0], RigInitializationError), outcome
    assert "_ReleasedByItsClose closed while it opened" in str(outcome[0])
    assert not out.exists()  # no take started
    assert not source.is_open and not inner.is_open


class _ClosedOnFirstRelease:
    """Stands in for a source's state lock (``_open_state``): as ``open()`` lets go of it the first time, having
    found the source neither open nor closed, another thread closes the source, and ``open()`` goes on once that
    close returned: a close landing before the backend's ``_open`` began."""

    def __init__(self, source: RigSource) -> None:
        self._lock = threading.Lock()
        self._source: RigSource | None = source

    def __enter__(self) -> None:
        self._lock.acquire()

    def __exit__(self, *exc) -> None:
        self._lock.release()
        source, self._source = self._source, None
        if source is not None:
            closer = threading.Thread(target=source.close, name="test close")
            closer.start()
            closer.join(WAIT_S)
            assert not closer.is_alive()


def test_a_record_wrapper_closed_before_its_inner_open_began_cancels_its_open(tmp_path):
    # the inner source, closed by the wrapper's close, refused its open as a RigOperationError "_HeldOpen was
    # closed; open a new source": not the cancelled open the docs say, and of a source the caller never closed
    inner = _HeldOpen()
    inner.go_on.set()
    out = tmp_path / "take"
    source = RecordingRigSource(inner, RecordOptions(out=out))
    source._open_state = _ClosedOnFirstRelease(source)
    with pytest.raises(RigInitializationError) as raised:
        source.open()
    assert str(raised.value) == (f"record+ source closed while it opened (a close() from another thread): the open "
                                 f"was cancelled, no take started in {out}")
    assert not inner.device_made and inner.closes == 0  # the inner open never began
    assert not out.exists()
    assert not source.is_open and not inner.is_open


class _CountsOpens(_HeldOpen):
    """Counts its ``_open`` calls; only the first waits for ``go_on`` (a second would start a second device)."""

    def __init__(self) -> None:
        super().__init__()
        self.opens = 0

    def _open(self) -> None:
        self.opens += 1
        if self.opens == 1:
            super()._open()


def test_a_second_open_while_the_first_runs_is_refused_naming_the_source():
    # it ran the backend's _open a second time: a second set of cameras, the first never closed
    source = _CountsOpens()
    thread, outcome = opened_in_a_thread(source)
    assert source.in_open.wait(WAIT_S)
    with pytest.raises(OpenInProgressError, match="_CountsOpens is already being opened by another call to open"):
        source.open()
    source.go_on.set()
    thread.join(WAIT_S)
    assert not thread.is_alive()
    assert outcome == [source] and source.is_open and source.opens == 1
    assert source.open() is source and source.opens == 1  # open already: nothing more to start
    source.close()
    assert source.closes == 1


class _InterruptedOnSecondEntry:
    """Stands in for a source's state lock (``_open_state``): the second time ``open()`` takes it, to mark the source
    open after the backend's ``_open`` returned, a Ctrl-C lands first."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self._entries = 0

    def __enter__(self) -> None:
        self._entries += 1
        if self._entries == 2:
            raise KeyboardInterrupt
        self._lock.acquire()

    def __exit__(self, *exc) -> None:
        self._lock.release()


def _interrupted_as_it_is_marked_open(source: _HeldOpen) -> None:
    source._open_state = _InterruptedOnSecondEntry()


def _interrupted_as_it_warns_of_its_rig(source: _HeldOpen) -> None:
    def interrupted() -> None:
        raise KeyboardInterrupt

    source._rig_built = True  # open() warns of a rig the backend built
    source._warn_of_rig = interrupted


@pytest.mark.parametrize("interrupt", [_interrupted_as_it_is_marked_open, _interrupted_as_it_warns_of_its_rig])
def test_an_interrupt_after_the_backend_opened_releases_what_it_opened(interrupt):
    # the cameras ran on until the process exited: open() raised, so the caller had no source to close
    source = _HeldOpen()
    source.go_on.set()
    interrupt(source)
    with pytest.raises(KeyboardInterrupt):
        source.open()
    assert source.device_made and source.closes == 1
    assert not source.is_open
    source._open_state = threading.Lock()
    source.close()  # released already: not again
    assert source.closes == 1


def test_a_close_landing_before_a_failed_open_releases_once():
    """The source was marked open, a close from another thread released it, then open() failed (its rig warning):
    open() must not run _close a second time."""
    source = _HeldOpen()
    source.go_on.set()

    def closed_by_another_thread_then_failing() -> None:
        closer = threading.Thread(target=source.close, name="test close")
        closer.start()
        closer.join(WAIT_S)
        assert not closer.is_alive()
        raise RuntimeError("warning failed")

    source._rig_built = True
    source._warn_of_rig = closed_by_another_thread_then_failing
    with pytest.raises(RuntimeError, match="warning failed"):
        source.open()
    assert source.closes == 1 and not source.is_open
