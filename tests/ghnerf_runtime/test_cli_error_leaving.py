"""``ghnerf_runtime.cli.error_leaving``: the error that ended ghnerf-demo's or ghcal capture's run, said in place of
a Ctrl-C or SIGTERM landing as it leaves."""
from __future__ import annotations

import contextlib
import os
import signal

import pytest

from ghnerf_runtime.cli.error_leaving import status_keeping_the_error
from ghnerf_runtime.cli.sigterm import Terminated, sigterm_as_interrupt


class _CameraGone(Exception):
    pass


@pytest.fixture
def stops_raise():
    """Ctrl-C and SIGTERM raise, as in a tool's main; the handlers before put back."""
    before = {signum: signal.getsignal(signum) for signum in (signal.SIGINT, signal.SIGTERM)}
    signal.signal(signal.SIGINT, signal.default_int_handler)
    with sigterm_as_interrupt():
        yield
    for signum, handler in before.items():
        signal.signal(signum, handler)


def _stop(signum: signal.Signals) -> None:
    os.kill(os.getpid(), signum)  # its handler runs here, in the main thread, at once


@pytest.mark.usefixtures("stops_raise")
@pytest.mark.parametrize("stop", [signal.SIGINT, signal.SIGTERM])
@pytest.mark.parametrize("where", ["while held", "after the hold"])
def test_an_error_noted_as_it_leaves_is_raised_whatever_stop_lands_after_it(where, stop):
    """A stop landing while the run closes (held) is dropped; one after the close takes the error's place on the
    way out, and the error is raised again in its place."""
    def run(leaving):
        stops = contextlib.ExitStack()
        try:
            raise _CameraGone("camera 'right' vanished")
        except Exception as error:
            leaving.held(error, stops)
            raise
        finally:
            with stops:  # the close
                if where == "while held":
                    _stop(stop)
            if where == "after the hold":
                _stop(stop)

    with pytest.raises(_CameraGone, match="vanished"):
        status_keeping_the_error(run)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # put back


@pytest.mark.usefixtures("stops_raise")
def test_a_status_that_came_back_in_place_of_a_noted_error_gives_way_to_the_error():
    """A failed take's 2, returned where a stop hid the error (status_saying_a_failed_take), is the error's."""
    def run(leaving):
        leaving.error = _CameraGone("camera 'right' vanished")
        return 2

    with pytest.raises(_CameraGone):
        status_keeping_the_error(run)


@pytest.mark.usefixtures("stops_raise")
def test_a_run_with_no_error_keeps_its_status_and_its_stop():
    assert status_keeping_the_error(lambda leaving: 0) == 0

    def stopped(leaving):
        _stop(signal.SIGTERM)

    with pytest.raises(Terminated):
        status_keeping_the_error(stopped)
