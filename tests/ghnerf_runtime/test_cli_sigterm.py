"""``ghnerf_runtime.cli.sigterm``: the SIGTERM handling ghnerf-run, ghnerf-listen, ghcal and ghnerf-demo share."""
from __future__ import annotations

import os
import signal
import threading
import time

import pytest

from ghnerf_runtime.cli.sigterm import Terminated, closed_with_stops_deferred, exit_status, sigterm_as_interrupt, \
    stop_signal, stop_signals_deferred, stop_signals_noted, stop_words

WAIT_S = 30.0  # generous: only a hang reaches it (the worker's thread waits its turn on a loaded host)


def _outer(signum, frame):  # stands for whatever handler the caller had (the default would end pytest)
    raise AssertionError("SIGTERM reached the handler outside the block")


def _deliver_sigterm() -> None:
    os.kill(os.getpid(), signal.SIGTERM)
    time.sleep(5)  # the handler runs here, in the main thread
    pytest.fail("SIGTERM was not delivered")


def test_sigterm_raises_terminated_inside_the_block_and_the_handler_before_is_put_back():
    previous = signal.signal(signal.SIGTERM, _outer)
    try:
        with pytest.raises(Terminated) as caught:
            with sigterm_as_interrupt():
                assert signal.getsignal(signal.SIGTERM) is not _outer  # installed
                _deliver_sigterm()
        assert signal.getsignal(signal.SIGTERM) is _outer  # put back after the signal
        with sigterm_as_interrupt():
            pass
        assert signal.getsignal(signal.SIGTERM) is _outer  # and after a block that ended as usual
        with pytest.raises(ValueError):
            with sigterm_as_interrupt():
                raise ValueError("any error")
        assert signal.getsignal(signal.SIGTERM) is _outer
    finally:
        signal.signal(signal.SIGTERM, previous)
    e = caught.value
    assert isinstance(e, KeyboardInterrupt)  # every `except KeyboardInterrupt` written for Ctrl-C catches it
    assert (stop_signal(e), exit_status(e), stop_words(e)) == (signal.SIGTERM, 143, "SIGTERM")


def test_a_plain_keyboard_interrupt_is_ctrl_c():
    e = KeyboardInterrupt()
    assert (stop_signal(e), exit_status(e), stop_words(e)) == (signal.SIGINT, 130, "Ctrl-C")


def test_nothing_is_installed_outside_the_main_thread():
    """signal.signal raises ValueError outside the main thread: a tool's main() run from a worker must still run,
    leaving the process's handler as it was."""
    previous = signal.signal(signal.SIGTERM, _outer)
    seen: list[object] = []
    errors: list[BaseException] = []

    def worker() -> None:
        try:
            with sigterm_as_interrupt():
                seen.append(signal.getsignal(signal.SIGTERM))
        except BaseException as e:  # noqa: BLE001 - reported to the test's thread
            errors.append(e)

    try:
        thread = threading.Thread(target=worker)
        thread.start()
        thread.join(WAIT_S)
        after = signal.getsignal(signal.SIGTERM)
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert not thread.is_alive(), f"the worker did not finish in {WAIT_S} s"
    assert not errors and seen == [_outer] and after is _outer


def test_a_deferred_sigterm_lets_the_block_finish_then_raises():
    previous = signal.signal(signal.SIGTERM, _outer)
    finished = []
    try:
        with pytest.raises(Terminated):
            with sigterm_as_interrupt():
                with stop_signals_deferred():
                    os.kill(os.getpid(), signal.SIGTERM)
                    time.sleep(0.2)  # the handler runs here: noted, not raised
                    finished.append("block")
                finished.append("after")  # not reached: raised as the block ended
        assert signal.getsignal(signal.SIGTERM) is _outer
        with stop_signals_deferred():  # no signal: nothing raised, the handler put back
            pass
        assert signal.getsignal(signal.SIGTERM) is _outer
    finally:
        signal.signal(signal.SIGTERM, previous)
    assert finished == ["block"]


def _outer_int(signum, frame):
    raise AssertionError("SIGINT reached the handler outside the block")


@pytest.mark.parametrize(("first", "raised"), [(signal.SIGINT, KeyboardInterrupt), (signal.SIGTERM, Terminated)])
def test_stop_signals_deferred_holds_ctrl_c_and_sigterm_over_the_block(first, raised):
    """A stopped run's outputs are written under it: a Ctrl-C pressed again lands there and is held, not raised
    into the write; the first held is raised after the block, or not at all with then_raise=False."""
    previous = {signal.SIGINT: signal.signal(signal.SIGINT, _outer_int),
                signal.SIGTERM: signal.signal(signal.SIGTERM, _outer)}
    finished = []
    try:
        with pytest.raises(raised) as e:
            with stop_signals_deferred():
                for signum in (first, signal.SIGINT, signal.SIGTERM):
                    os.kill(os.getpid(), signum)
                    time.sleep(0.1)  # each handler runs here: noted, not raised
                finished.append("block")
        assert stop_signal(e.value) == first
        with stop_signals_deferred(then_raise=False):  # a stop already on its way: nothing more raised
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(0.1)
            finished.append("quiet")
        assert signal.getsignal(signal.SIGINT) is _outer_int and signal.getsignal(signal.SIGTERM) is _outer
    finally:
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    assert finished == ["block", "quiet"]


class _OuterTerm(Exception):
    """The caller's own SIGTERM handler ran: the block left it alone."""


def _outer_term(signum, frame):
    raise _OuterTerm


def test_only_raising_holds_only_the_stops_that_would_raise():
    """A library's step that must finish (convert_zju's swap) holds Ctrl-C under Python's own handler and SIGTERM
    inside sigterm_as_interrupt, raised after the block; a caller's own SIGTERM handling is left in place."""
    previous_int = signal.signal(signal.SIGINT, signal.default_int_handler)
    previous_term = signal.signal(signal.SIGTERM, _outer_term)
    finished = []
    try:
        with pytest.raises(KeyboardInterrupt):
            with stop_signals_deferred(only_raising=True):
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.1)  # noted, not raised
                finished.append("held")
        with pytest.raises(_OuterTerm):
            with stop_signals_deferred(only_raising=True):
                assert signal.getsignal(signal.SIGTERM) is _outer_term
                _deliver_sigterm()
        with sigterm_as_interrupt(), pytest.raises(Terminated):
            with stop_signals_deferred(only_raising=True):
                os.kill(os.getpid(), signal.SIGTERM)
                time.sleep(0.1)
                finished.append("held too")
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
        assert signal.getsignal(signal.SIGTERM) is _outer_term
    finally:
        signal.signal(signal.SIGINT, previous_int)
        signal.signal(signal.SIGTERM, previous_term)
    assert finished == ["held", "held too"]


def test_a_stop_in_a_close_is_handed_back_once_the_close_is_done():
    """ghnerf-demo and ghcal capture check a record+ take's failure before they say a stop that landed in its close."""
    closed = []

    def close() -> None:
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.1)  # the handler runs here: noted, not raised
        closed.append("whole")

    assert isinstance(closed_with_stops_deferred(close, then_raise=True), KeyboardInterrupt) and closed == ["whole"]
    assert closed_with_stops_deferred(close, then_raise=False) is None and closed == ["whole", "whole"]
    assert closed_with_stops_deferred(lambda: None, then_raise=True) is None


@pytest.fixture
def handlers_put_back():
    """A failing test must not leave a noting handler on Ctrl-C for the rest of the run."""
    before = {signum: signal.getsignal(signum) for signum in (signal.SIGINT, signal.SIGTERM)}
    yield
    for signum, handler in before.items():
        signal.signal(signum, handler)


@pytest.mark.usefixtures("handlers_put_back")
@pytest.mark.parametrize("raised_after", [False, True])
def test_a_sigterm_landing_while_the_handlers_go_in_is_held_and_the_close_still_runs(monkeypatch, raised_after):
    """SIGTERM after SIGINT's noting handler is set, before SIGTERM's: its handler then (sigterm_as_interrupt's)
    raises out of the set-up, as signal.signal runs the signals pending before (or the call's return after) it
    sets one. It must be held like a stop a moment later, the close run, and both handlers put back."""
    real_signal = signal.signal
    landed = []

    def signal_with_a_sigterm_landing(signum, handler):
        if signum == signal.SIGTERM and not landed and handler is not signal.SIG_DFL:
            landed.append(signum)
            if raised_after:
                real_signal(signum, handler)
            raise Terminated("SIGTERM")  # what sigterm_as_interrupt's handler raises when it runs there
        return real_signal(signum, handler)

    closed = []
    with sigterm_as_interrupt():
        installed_term = signal.getsignal(signal.SIGTERM)
        monkeypatch.setattr(signal, "signal", signal_with_a_sigterm_landing)
        stop = closed_with_stops_deferred(lambda: closed.append("whole"), then_raise=True)
        monkeypatch.undo()
        assert signal.getsignal(signal.SIGTERM) is installed_term
    assert landed and closed == ["whole"]
    assert isinstance(stop, Terminated)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


@pytest.mark.usefixtures("handlers_put_back")
def test_another_error_while_the_handlers_go_in_puts_the_handlers_back(monkeypatch):
    real_signal = signal.signal

    def signal_failing_for_sigterm(signum, handler):
        if signum == signal.SIGTERM:
            raise OSError("refused")
        return real_signal(signum, handler)

    monkeypatch.setattr(signal, "signal", signal_failing_for_sigterm)
    with pytest.raises(OSError):
        with stop_signals_deferred():
            pytest.fail("the block ran without its handlers")
    monkeypatch.undo()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


@pytest.mark.usefixtures("handlers_put_back")
@pytest.mark.parametrize("then_raise", [True, False])
def test_a_stop_landing_as_the_close_s_handlers_are_entered_still_lets_the_close_run(monkeypatch, then_raise):
    """A SIGTERM run by sigterm_as_interrupt's handler before the held handlers go in (here as the ones before are
    read) raised out of the deferral's entry: the stop was returned and the close never ran."""
    real_getsignal = signal.getsignal
    landed = []

    def getsignal_with_a_sigterm_landing(signum):
        if not landed:
            landed.append(signum)
            raise Terminated("SIGTERM")  # what sigterm_as_interrupt's handler raises when it runs there
        return real_getsignal(signum)

    closed = []
    with sigterm_as_interrupt():
        monkeypatch.setattr(signal, "getsignal", getsignal_with_a_sigterm_landing)
        stop = closed_with_stops_deferred(lambda: closed.append("whole"), then_raise=then_raise)
        monkeypatch.undo()
    assert landed and closed == ["whole"]
    assert isinstance(stop, Terminated) if then_raise else stop is None
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


@pytest.mark.usefixtures("handlers_put_back")
def test_stops_noted_are_handed_over_as_their_stops_and_never_raised():
    """ghnerf-demo and ghcal capture note a first stop between their reading and the take's close, and raise it
    once the take is closed and checked."""
    stops: list[KeyboardInterrupt] = []
    with sigterm_as_interrupt():
        with stop_signals_noted(stops):
            os.kill(os.getpid(), signal.SIGTERM)
            os.kill(os.getpid(), signal.SIGINT)  # each handler runs here, in the main thread, at once
        assert [type(stop) for stop in stops] == [Terminated, KeyboardInterrupt]
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler  # put back


@pytest.mark.usefixtures("handlers_put_back")
def test_a_ctrl_c_ignored_before_stays_ignored_through_every_hold():
    """A tool started with Ctrl-C ignored (a script's background job, ``ghnerf-demo ... &``, which the script's own
    Ctrl-C reaches too) goes on past it. One landing in a hold (the sink's or the take's close, the stretch from the
    reading to the close) was noted and raised after it: the run ended 130, its summary skipped."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    stops: list[KeyboardInterrupt] = []
    try:
        with stop_signals_deferred():
            os.kill(os.getpid(), signal.SIGINT)  # its handler runs here, in the main thread, at once
        returned = closed_with_stops_deferred(lambda: os.kill(os.getpid(), signal.SIGINT), then_raise=True)
        with stop_signals_noted(stops):
            os.kill(os.getpid(), signal.SIGINT)
    except KeyboardInterrupt:
        pytest.fail("an ignored Ctrl-C was raised after the hold")
    assert returned is None and stops == []
    assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN  # put back
