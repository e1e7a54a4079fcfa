"""``wait_until``: the clocks' sleep that a close from another thread ends (sim:// and replay:// wait on it)."""
import threading
import time

from drivers.clock import ManualClock, MonotonicClock


def test_the_real_clock_waits_until_the_deadline_not_before():
    # the sources' pacing: a frame is never handed out before its time, as with time.sleep
    clock, wake = MonotonicClock(), threading.Event()
    deadline = clock.now_ns() + 50_000_000
    assert clock.wait_until(deadline, wake) is False
    assert clock.now_ns() >= deadline


def test_the_real_clock_is_woken_by_the_event_set_in_another_thread():
    clock, wake = MonotonicClock(), threading.Event()
    threading.Timer(0.1, wake.set).start()
    t0 = time.monotonic()
    assert clock.wait_until(clock.now_ns() + 30 * 10**9, wake) is True
    assert time.monotonic() - t0 < 5.0


def test_a_wait_longer_than_an_event_takes_is_waited_in_parts():
    # Event.wait(1e12) is an OverflowError; a read's timeout may be that long
    clock, wake = MonotonicClock(), threading.Event()
    threading.Timer(0.1, wake.set).start()
    assert clock.wait_until(clock.now_ns() + 10**21, wake) is True


def test_the_manual_clock_jumps_unless_woken():
    clock, wake = ManualClock(100), threading.Event()
    assert clock.wait_until(500, wake) is False and clock.now_ns() == 500
    wake.set()
    assert clock.wait_until(900, wake) is True and clock.now_ns() == 500
