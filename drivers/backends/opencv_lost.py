"""``opencv://``: a camera's runs of lost frames, each said once, as ``stats.camera_gaps`` does (or does not) count it.

A frame lost to a failed grab tried again, or grabbed and not decoded, moves the camera's frame index on, so the
pairer counts it in ``stats.camera_gaps`` as the gap between the camera's frames on either side of it. That
count needs the frame after the run to reach the pairer, after a frame of the camera before it: the run is said
when the reader takes that frame (:meth:`UnreadRuns.read`), not when the camera's thread queues it, since a frame
queued and never read before the close never shows the gap (the warning said "counted" of a run no counter
held). A run whose frame after it is still queued at the close is said by :meth:`UnreadRuns.closed`; one that no
frame follows, by the camera's thread as it ends (:data:`RUN_ENDED`, :data:`RUN_CLOSED`).
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

    @property
    def frames(self) -> int:
        return self.failed_grabs + self.undecodable

    def words(self, next_index: int, ending: str = RUN_COUNTED, *, read: int | None = None) -> str | None:
        """What was lost before frame ``next_index``, why, and ``ending`` (a ``RUN_*``; ``read``: the frame read
        that ended the run, ``next_index`` or, where the full queue dropped that one, a later one); None: nothing."""
        lost = self.frames
        if not lost:
            return None
        first = next_index - lost
        frames = f"frame {first}" if lost == 1 else f"frames {first} to {next_index - 1}"
        why = [f"{n} {what}" for n, what in ((self.failed_grabs, "failed grab(s), tried again"),
                                            (self.undecodable, "grabbed frame(s) that did not decode, skipped")) if n]
        read = next_index if read is None else read
        return f"{frames} ({'; '.join(why)})" + ending.format(next=next_index, read=read)


class UnreadRuns:
    """The runs whose frame after them is queued for the reader, per camera; used under the source's lock.

    A run whose frame the full queue dropped (an overrun) is said with the camera's next frame read: the gap from
    the frame read before it to that one holds the run too."""

    def __init__(self) -> None:
        self._queued: dict[str, deque[tuple[int, LostRun]]] = {}
        self._cameras_read: set[str] = set()

    def queued(self, camera: str, index: int, run: LostRun) -> None:
        """Camera ``camera`` queued frame ``index``, the first after ``run`` (not empty)."""
        self._queued.setdefault(camera, deque()).append((index, run))

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
