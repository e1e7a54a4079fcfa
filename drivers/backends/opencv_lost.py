"""``opencv://``: a camera's runs of lost frames, each said once, as ``stats.camera_gaps`` does (or does not) count it.

A frame lost to a failed grab tried again, or grabbed and not decoded, moves the camera's frame index on, so the
pairer counts it in ``stats.camera_gaps`` as the gap between the camera's frames on either side of it. That
count needs the frame after the run to reach the pairer, after a frame of the camera before it: the run is said
when the reader takes that frame (:meth:`UnreadRuns.read`), not when the camera's thread queues it, since a frame
queued and never read before the close never shows the gap (the warning said "counted" of a run no counter
held). A run whose frame after it is still queued at the close is said by :meth:`UnreadRuns.closed`; one that no
frame follows, by the camera's thread as it ends (:data:`RUN_ENDED`, :data:`RUN_CLOSED`).

The runs held are bounded: those whose frame after them the full queue dropped (a reader that does not read while a
flaky camera loses frame after frame) are merged into one, said as one warning with the camera's next frame read
(:meth:`UnreadRuns.dropped`), so a camera holds at most one run per frame it has queued, plus that one.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass

#: How a run's warning ends (``{next}``: the frame after it; ``{read}``: the frame read that ended it): counted, or
#: why not.
RUN_COUNTED = ": a gap in its frame index, counted in stats.camera_gaps"
RUN_ENDED = ", its last: no frame followed"
RUN_CLOSED = ", still going at close: no frame followed"
RUN_UNREAD = ", then frame {next}, not read before the close: not counted in stats.camera_gaps"
RUN_BEFORE_FIRST_READ = (", before frame {read}, the camera's first frame read: no frame before the gap, so not "
                         "counted in stats.camera_gaps")


@dataclass
class LostRun:
    """A camera's frames lost in a row, each a gap in its frame index: failed grabs tried again and grabbed frames
    that did not decode. Said once as the run ends, not once per frame (every undecodable frame logged was a flood
    at 30 fps)."""

    failed_grabs: int = 0
    undecodable: int = 0
    #: More than 1: runs merged (:meth:`merged`), the frames between them dropped unread from the full queue.
    runs: int = 1
    #: Where runs are merged: the first frame lost, of the first run (one run's is its frames before its next).
    first: int | None = None

    @property
    def frames(self) -> int:
        return self.failed_grabs + self.undecodable

    def merged(self, next_index: int, later: LostRun) -> LostRun:
        """This run, before frame ``next_index``, and a ``later`` one, as one (a new object: neither is changed)."""
        return LostRun(self.failed_grabs + later.failed_grabs, self.undecodable + later.undecodable,
                       runs=self.runs + later.runs, first=self._first(next_index))

    def _first(self, next_index: int) -> int:
        return next_index - self.frames if self.first is None else self.first

    def words(self, next_index: int, ending: str = RUN_COUNTED, *, read: int | None = None) -> str | None:
        """What was lost before frame ``next_index``, why, and ``ending`` (a ``RUN_*``; ``read``: the frame read
        that ended the run, ``next_index`` or, where the full queue dropped that one, a later one); None: nothing."""
        lost = self.frames
        if not lost:
            return None
        first = self._first(next_index)
        frames = f"frame {first}" if first == next_index - 1 else f"frames {first} to {next_index - 1}"
        why = [f"{n} {what}" for n, what in ((self.failed_grabs, "failed grab(s), tried again"),
                                            (self.undecodable, "grabbed frame(s) that did not decode, skipped")) if n]
        if self.runs > 1:
            frames += f" in {self.runs} runs"
            why.append("the frames between the runs dropped unread from the full queue")
        read = next_index if read is None else read
        return f"{frames} ({'; '.join(why)})" + ending.format(next=next_index, read=read)


class UnreadRuns:
    """The runs whose frame after them is queued for the reader, per camera; used under the source's lock.

    A run whose frame the full queue dropped (an overrun) is said with the camera's next frame read: the gap from
    the frame read before it to that one holds the run too."""

    def __init__(self) -> None:
        self._queued: dict[str, deque[tuple[int, LostRun]]] = {}
        self._cameras_read: set[str] = set()

    def __len__(self) -> int:
        """The runs held, every camera's (merged ones counted as one)."""
        return sum(len(runs) for runs in self._queued.values())

    def queued(self, camera: str, index: int, run: LostRun) -> None:
        """Camera ``camera`` queued frame ``index``, the first after ``run`` (not empty)."""
        self._queued.setdefault(camera, deque()).append((index, run))

    def dropped(self, camera: str, index: int) -> None:
        """The full queue dropped camera ``camera``'s frame ``index`` unread (and every frame of it before): the runs
        up to it are said together, with the camera's next frame read, so they are held as one. Without this a
        reader that does not read while the camera keeps losing frames held a run for every one it lost."""
        runs = self._queued.get(camera)
        if not runs or len(runs) < 2 or runs[1][0] > index:
            return  # one run at most to merge: held as it is, said in its own words
        next_index, run = runs.popleft()
        while runs and runs[0][0] <= index:
            later_next, later = runs.popleft()
            run, next_index = run.merged(next_index, later), later_next
        runs.appendleft((next_index, run))

    def read(self, camera: str, index: int) -> list[str]:
        """The reader took frame ``index`` of ``camera`` (the pairer gets it): the words of each run it ends."""
        runs = self._queued.get(camera, deque())
        ending = RUN_COUNTED if camera in self._cameras_read else RUN_BEFORE_FIRST_READ
        self._cameras_read.add(camera)
        said = []
        while runs and runs[0][0] <= index:
            next_index, run = runs.popleft()
            said.append(run.words(next_index, ending, read=index))
        return said

    def closed(self) -> list[tuple[str, str]]:
        """The source closed: ``(camera, words)`` of each run whose frame after it was never read; forgets them."""
        said = [(camera, run.words(next_index, RUN_UNREAD))
                for camera, runs in self._queued.items() for next_index, run in runs]
        self._queued.clear()
        return said
