"""The rig-source contract: one suite every backend must pass (python-can's back2back idea).

A backend's test module subclasses :class:`RigSourceContract` (the name does not
start with ``Test``, so pytest collects only the subclasses) and provides:

* :meth:`RigSourceContract.make_source`: an unopened source delivering pairs;
* :meth:`RigSourceContract.make_stalling_source`: one whose pairs stop (or come
  slower than ``stall_timeout_s``) after the first pair; on the real clock, 10 s
  apart or more, so that ``slack_s`` tells a read that ended on time from one that
  waited for the next pair.

``realtime`` says whether the source runs on the real clock (then timing checks
get ``slack_s`` of scheduling slack: seconds, as a loaded 2-core host needs) or on
a ``ManualClock`` (exact).
``expected_stats`` gives the exact counters after the shared session where what is
lost does not depend on timing (a seeded simulation on a ``ManualClock``, a recorded
take under ``policy=all``); a hardware backend leaves it ``None`` and is held to the
bounds every backend meets.
"""
from __future__ import annotations

import threading
import time

import numpy as np
import pytest

from drivers import FramePair, RigOperationError, RigSource, RigTimeoutError


class RigSourceContract:
    """Mix into a ``Test...`` class; see the module docstring."""

    #: pairs read by the shared session
    n_pairs = 20
    #: first-read timeout (device start-up)
    first_timeout_s = 5.0
    #: timeout used by the stall test
    stall_timeout_s = 0.25
    #: real clock (True) or ManualClock (False)
    realtime = False
    #: wall-clock slack of the timing checks on the real clock: a loaded host can delay a thread's wake-up past
    #: the quarter second this was (a device that cannot stall 10 s, at 1 fps, sets a smaller one)
    slack_s = 2.0
    #: exact ``frames_in``, ``unpaired``, ``camera_gaps``, ``pairs_dropped`` after reading ``n_pairs``
    #: (deterministic backends only; None: the generic bounds alone)
    expected_stats: dict | None = None

    # --------------------------------------------------------------- hooks
    @classmethod
    def make_source(cls) -> RigSource:  # pragma: no cover - provided by subclasses
        raise NotImplementedError

    @classmethod
    def make_stalling_source(cls) -> RigSource:  # pragma: no cover - provided by subclasses
        raise NotImplementedError

    # ------------------------------------------------------------ fixtures
    @pytest.fixture(scope="class")
    @classmethod
    def session(cls):
        """Open once per backend, read ``n_pairs`` pairs: (source, pairs, stats after reading)."""
        source = cls.make_source()
        with source:
            pairs = [source.read(timeout_s=cls.first_timeout_s if i == 0 else 2.0) for i in range(cls.n_pairs)]
            stats = source.stats
        return source, pairs, stats

    # --------------------------------------------------------------- tests
    def test_pairs_arrive(self, session):
        _, pairs, _ = session
        assert len(pairs) == self.n_pairs
        assert all(isinstance(p, FramePair) for p in pairs)

    def test_pairs_are_the_rigs_stereo_pair_in_order(self, session):
        source, pairs, _ = session
        names = (source.rig.pair[0].name, source.rig.pair[1].name)
        for pair in pairs:
            assert (pair.frames[0].camera, pair.frames[1].camera) == names
            assert pair.rig is source.rig

    def test_sequence_strictly_increases(self, session):
        _, pairs, _ = session
        seqs = [p.sequence for p in pairs]
        assert all(b > a for a, b in zip(seqs, seqs[1:])), seqs

    def test_pair_skew_within_tolerance(self, session):
        source, pairs, _ = session
        tolerance_ns = source.pairing.tolerance_ms * 1e6
        assert all(p.skew_ns <= tolerance_ns for p in pairs), [p.skew_ns for p in pairs]

    def test_timestamps_and_indices_increase_per_camera(self, session):
        _, pairs, _ = session
        for cam in (0, 1):
            stamps = [p.frames[cam].timestamp_ns for p in pairs]
            indices = [p.frames[cam].index for p in pairs]
            assert all(b > a for a, b in zip(stamps, stamps[1:])), stamps
            assert all(b > a for a, b in zip(indices, indices[1:])), indices
            assert all(isinstance(t, int) for t in stamps)

    def test_images_have_the_rig_camera_sizes(self, session):
        source, pairs, _ = session
        for pair in pairs:
            for frame, cam in zip(pair.frames, source.rig.pair):
                assert isinstance(frame.image, np.ndarray)
                assert frame.image.dtype == np.uint8
                assert frame.image.shape == (cam.height, cam.width, 3)

    def test_stats_count_what_was_read(self, session):
        source, pairs, stats = session
        names = source.rig.pair[0].name, source.rig.pair[1].name
        assert stats.pairs_out == len(pairs)
        for name in names:
            # each frame taken in went into a pair that was read, was given up as unpaired, or is still held
            # (waiting for a partner, or in a pair dropped or not yet read)
            assert stats.frames_in[name] >= len(pairs) + stats.unpaired[name], stats
            assert stats.unpaired[name] >= 0 and stats.camera_gaps[name] >= 0
        assert stats.pairs_out + stats.pairs_dropped == pairs[-1].sequence + 1
        if self.expected_stats is not None:
            assert {k: getattr(stats, k) for k in self.expected_stats} == self.expected_stats, stats

    def test_read_times_out_when_frames_stop(self):
        with self.make_stalling_source() as source:
            source.read(timeout_s=self.first_timeout_s)
            t_clock, t_wall = source.clock.now_ns(), time.monotonic()
            with pytest.raises(RigTimeoutError):
                source.read(timeout_s=self.stall_timeout_s)
            waited = (source.clock.now_ns() - t_clock) / 1e9
            wall = time.monotonic() - t_wall
        assert waited >= self.stall_timeout_s - 1e-9
        if self.realtime:
            assert wall <= self.stall_timeout_s + self.slack_s
        else:
            assert waited == pytest.approx(self.stall_timeout_s, abs=1e-6)
            assert wall < 1.0  # the manual clock never really sleeps

    def test_close_from_another_thread_wakes_a_read_waiting_for_frames(self):
        """A daemon's stop and a Ctrl-C close the source while its reader waits: the read must end then, not at
        the next frame's time (sim:// and replay:// slept until it before session 75)."""
        if not self.realtime:
            pytest.skip("on a ManualClock a read never really waits")
        with self.make_stalling_source() as source:
            source.read(timeout_s=self.first_timeout_s)
            got, after_s = closed_while_reading(source, 30.0)  # the next pair is still a stall away
        assert isinstance(got, RigOperationError) and "closed" in str(got), got
        assert after_s <= self.slack_s + 0.25, f"the read returned {after_s:.2f} s after the close"

    def test_a_timeout_that_is_not_a_finite_number_of_seconds_is_refused(self):
        with self.make_source() as source:
            for bad in (float("inf"), float("nan"), -1.0, None):
                with pytest.raises(ValueError, match="timeout_s"):
                    source.read(timeout_s=bad)
            source.read(timeout_s=self.first_timeout_s)  # still usable

    def test_timeout_is_also_a_builtin_timeout_error(self):
        assert issubclass(RigTimeoutError, TimeoutError)

    def test_context_manager_opens_and_closes(self):
        source = self.make_source()
        assert not source.is_open
        with source as entered:
            assert entered is source and source.is_open
            source.read(timeout_s=self.first_timeout_s)
        assert not source.is_open

    def test_close_is_idempotent_and_read_after_close_raises(self):
        source = self.make_source().open()
        source.read(timeout_s=self.first_timeout_s)
        source.close()
        source.close()
        with pytest.raises(RigOperationError):
            source.read(timeout_s=0.1)
        with pytest.raises(RigOperationError):
            source.open()  # a closed source stays closed

    def test_read_before_open_raises(self):
        source = self.make_source()
        try:
            with pytest.raises(RigOperationError):
                source.read(timeout_s=0.1)
        finally:
            source.close()


def opened_in_a_thread(source: RigSource) -> tuple[threading.Thread, list]:
    """``source.open()`` on a thread of its own, for a close from the test's thread to land in; the list gets what
    the open returned or raised."""
    outcome: list = []

    def run() -> None:
        try:
            outcome.append(source.open())
        except Exception as e:  # noqa: BLE001 - handed to the test
            outcome.append(e)

    thread = threading.Thread(target=run, name="test open", daemon=True)
    thread.start()
    return thread, outcome


def closed_while_reading(source, read_timeout_s: float) -> tuple[object, float]:
    """What a read blocked in another thread returned or raised when this thread closed ``source``, and how many
    seconds after the close it did. The close comes once the read is in the backend's ``_read_frame`` (not after a
    sleep): a reader a loaded host started late began its read after the close, which says "was closed; open a
    new source" at once, not what a waiting read says."""
    ended: list[tuple[object, float]] = []
    reading = threading.Event()
    read_frame = source._read_frame

    def reading_then_read_frame(timeout_s: float):
        reading.set()  # past read()'s check that the source is open: the close lands in the read
        return read_frame(timeout_s)

    def reader():
        try:
            got: object = source.read(timeout_s=read_timeout_s)
        except Exception as e:  # noqa: BLE001 - the test looks at what it was
            got = e
        ended.append((got, time.monotonic()))

    source._read_frame = reading_then_read_frame
    try:
        thread = threading.Thread(target=reader, daemon=True)
        thread.start()
        assert reading.wait(60.0), "the reader never reached the backend's read"
        t0 = time.monotonic()
        source.close()
        thread.join(60.0)
    finally:
        del source._read_frame
    assert len(ended) == 1, "the read did not return"
    got, at = ended[0]
    return got, at - t0
