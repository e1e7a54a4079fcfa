"""``opencv://``'s runs of lost frames held for the reader (drivers.backends.opencv_lost): bounded however long the
reader does not read, as the source calls them (a frame queued after each run, the full queue dropping the oldest)."""
from __future__ import annotations

from collections import deque

from drivers.backends.opencv_lost import LostRun, UnreadRuns

QUEUE = 4  # frames the source's queue holds per camera


def _lose_every_other_frame(runs: UnreadRuns, frames: range) -> deque[int]:
    """Camera 'right' loses each odd frame of ``frames`` (one failed grab) and queues each even one, the full
    queue dropping its oldest as the source does; nothing is read. Returns the frames still queued."""
    queue: deque[int] = deque()
    for index in frames:
        if index % 2:
            continue
        if len(queue) == QUEUE:
            runs.dropped("right", queue.popleft())
        queue.append(index)
        runs.queued("right", index, LostRun(failed_grabs=1))
    return queue


def test_runs_whose_frames_the_full_queue_dropped_are_held_as_one():
    runs = UnreadRuns()
    assert runs.read("right", 0) == []  # the camera read before: the gaps after count
    queue = _lose_every_other_frame(runs, range(2, 2002))  # 1000 runs: frames 1 to 1999 lost
    assert list(queue) == [1994, 1996, 1998, 2000]
    assert len(runs) == 1 + QUEUE  # not 1000: the runs the queue's dropped frames ended, merged
    assert runs.read("right", 1994) == [  # the queue's oldest
        "frames 1 to 1991 in 996 runs (996 failed grab(s), tried again; the frames between the runs dropped unread "
        "from the full queue): a gap in its frame index, counted in stats.camera_gaps",
        "frame 1993 (1 failed grab(s), tried again): a gap in its frame index, counted in stats.camera_gaps",
    ]
    assert runs.closed() == [
        ("right", f"frame {n - 1} (1 failed grab(s), tried again), then frame {n}, not read before the close: not "
                  "counted in stats.camera_gaps") for n in (1996, 1998, 2000)
    ]
    assert len(runs) == 0


def test_a_single_run_whose_frame_was_dropped_keeps_its_own_words():
    runs = UnreadRuns()
    runs.queued("right", 7, LostRun(failed_grabs=2, undecodable=1))  # frames 4 to 6 lost
    runs.queued("right", 12, LostRun(undecodable=1))
    runs.dropped("right", 7)  # one run up to it: nothing to merge
    assert len(runs) == 2
    assert runs.read("right", 9) == [
        "frames 4 to 6 (2 failed grab(s), tried again; 1 grabbed frame(s) that did not decode, skipped), before "
        "frame 9, the camera's first frame read: no frame before the gap, so not counted in stats.camera_gaps",
    ]
    runs.dropped("right", 12)
    assert runs.read("right", 13) == [
        "frame 11 (1 grabbed frame(s) that did not decode, skipped): a gap in its frame index, counted in "
        "stats.camera_gaps",
    ]
